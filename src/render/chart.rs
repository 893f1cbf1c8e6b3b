//! Small line charts: the residual curve r(K) and the score per K of a fit, and a training
//! run's loss and validation curves.

use super::palette::{MUTED, RULE, TEXT};
use super::svg::{Rect, Svg, fixed};

/// One curve of a chart.
pub(super) struct Series<'a> {
    pub name: &'a str,
    pub colour: &'a str,
    /// (x, y) in data units; points with a coordinate that is not finite break the curve.
    pub points: &'a [(f64, f64)],
}

/// A chart to draw into `rect` (title, axes and ticks included).
pub(super) struct Chart<'a> {
    pub rect: Rect,
    pub title: &'a str,
    pub series: &'a [Series<'a>],
    /// x values are integers (K): ticks on integers only.
    pub integer_x: bool,
    /// The y axis starts at zero when every value is positive.
    pub y_from_zero: bool,
    /// A dot on every point (short curves such as r(K)).
    pub dots: bool,
    /// A marked x (the chosen K) and its caption.
    pub mark: Option<(f64, &'a str)>,
    /// Caption under the x axis ("" for none).
    pub x_label: &'a str,
    /// The x range to cover at least (so that charts side by side share their K axis).
    pub x_span: Option<(f64, f64)>,
    /// Font size of the title.
    pub title_size: f64,
}

/// Draws the chart.
pub(super) fn draw(svg: &mut Svg, c: &Chart) {
    let r = c.rect;
    svg.label(
        r.x,
        r.y + c.title_size,
        "start",
        &format!(r#" font-size="{}" font-weight="600""#, c.title_size),
        c.title,
    );
    if c.series.len() > 1 {
        legend(svg, c);
    }
    let plot = Rect {
        x: r.x + 46.0,
        y: r.y + c.title_size + 11.0,
        w: (r.w - 54.0).max(1.0),
        h: (r.h - c.title_size - if c.x_label.is_empty() { 31.0 } else { 45.0 }).max(1.0),
    };
    let finite = || {
        c.series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
    };
    let Some((x_lo, x_hi, y_lo, y_hi)) = finite().fold(None, |acc, &(x, y)| {
        let (a, b, cc, d) = acc.unwrap_or((x, x, y, y));
        Some((a.min(x), b.max(x), cc.min(y), d.max(y)))
    }) else {
        svg.rect(plot, &format!(r#" fill="none" stroke="{RULE}""#));
        svg.label(
            plot.x + plot.w / 2.0,
            plot.y + plot.h / 2.0 + 4.0,
            "middle",
            &format!(r#" fill="{MUTED}""#),
            "no data",
        );
        return;
    };
    let (x_lo, x_hi) = match c.mark {
        Some((m, _)) if m.is_finite() => (x_lo.min(m), x_hi.max(m)),
        _ => (x_lo, x_hi),
    };
    let (x_lo, x_hi) = match c.x_span {
        Some((a, b)) if a.is_finite() && b.is_finite() => (x_lo.min(a), x_hi.max(b)),
        _ => (x_lo, x_hi),
    };
    let (y_lo, y_hi) = if c.y_from_zero && y_lo >= 0.0 {
        (0.0, y_hi)
    } else {
        (y_lo, y_hi)
    };
    let y_axis = Axis::nice(y_lo, y_hi, (plot.h / 28.0).clamp(2.0, 6.0) as usize, false);
    let x_axis = Axis::nice(
        x_lo,
        x_hi,
        (plot.w / 48.0).clamp(2.0, 10.0) as usize,
        c.integer_x,
    );
    let px = |x: f64| plot.x + (x - x_axis.lo) / (x_axis.hi - x_axis.lo) * plot.w;
    let py = |y: f64| plot.bottom() - (y - y_axis.lo) / (y_axis.hi - y_axis.lo) * plot.h;

    // Grid, axes and ticks.
    let muted = format!(r#" font-size="11" fill="{MUTED}""#);
    for &t in &y_axis.ticks {
        let y = py(t);
        svg.line(
            (plot.x, y),
            (plot.right(), y),
            &format!(r#" stroke="{RULE}" stroke-width="0.7""#),
        );
        svg.label(
            plot.x - 5.0,
            y + 3.5,
            "end",
            &muted,
            &fixed(t, y_axis.decimals),
        );
    }
    svg.raw("\n");
    for &t in &x_axis.ticks {
        let x = px(t);
        svg.line(
            (x, plot.bottom()),
            (x, plot.bottom() + 4.0),
            &format!(r#" stroke="{MUTED}""#),
        );
        svg.label(
            x,
            plot.bottom() + 16.0,
            "middle",
            &muted,
            &fixed(t, x_axis.decimals),
        );
    }
    svg.line(
        (plot.x, plot.bottom()),
        (plot.right(), plot.bottom()),
        &format!(r#" stroke="{MUTED}""#),
    );
    svg.raw("\n");
    if !c.x_label.is_empty() {
        svg.label(
            plot.x + plot.w / 2.0,
            plot.bottom() + 32.0,
            "middle",
            &format!(r#" font-size="12" fill="{MUTED}""#),
            c.x_label,
        );
    }

    // The marked x, under the curves.
    if let Some((m, caption)) = c.mark.filter(|(m, _)| m.is_finite()) {
        let x = px(m);
        svg.line(
            (x, plot.y),
            (x, plot.bottom()),
            &format!(r#" stroke="{TEXT}" stroke-dasharray="4 3""#),
        );
        let anchor = if x > plot.x + plot.w * 0.7 {
            "end"
        } else {
            "start"
        };
        let dx = if anchor == "end" { -4.0 } else { 4.0 };
        // At the top, unless the first curve passes there at the mark: then at the bottom.
        let high = c
            .series
            .first()
            .and_then(|s| s.points.iter().find(|(px, _)| *px == m))
            .is_some_and(|&(_, y)| y.is_finite() && py(y) < plot.y + 0.3 * plot.h);
        svg.label(
            x + dx,
            if high {
                plot.bottom() - 6.0
            } else {
                plot.y + 11.0
            },
            anchor,
            r#" font-size="12" font-weight="600""#,
            caption,
        );
    }

    for s in c.series {
        // Runs of finite points, each its own polyline.
        for run in s
            .points
            .split(|(x, y)| !(x.is_finite() && y.is_finite()))
            .filter(|run| !run.is_empty())
        {
            svg.polyline(
                run.iter().map(|&(x, y)| (px(x), py(y))),
                &format!(r#" fill="none" stroke="{}" stroke-width="2""#, s.colour),
            );
            // A lone point (its neighbours not finite) has no segment: it gets a dot.
            if (c.dots && run.len() <= 64) || run.len() == 1 {
                for &(x, y) in run {
                    let hit = c.mark.is_some_and(|(m, _)| m == x);
                    svg.raw("<circle");
                    svg.attr("cx", px(x));
                    svg.attr("cy", py(y));
                    svg.attr("r", if hit { 5.0 } else { 3.0 });
                    svg.raw(&if hit {
                        format!(
                            r##" fill="#fff" stroke="{}" stroke-width="2.5"/>"##,
                            s.colour
                        )
                    } else {
                        format!(r#" fill="{}"/>"#, s.colour)
                    });
                }
            }
        }
        svg.raw("\n");
    }
}

/// The series' names and colours along the top right of the chart.
fn legend(svg: &mut Svg, c: &Chart) {
    let mut x = c.rect.right();
    for s in c.series.iter().rev() {
        // An estimate of the text's width (13 px type averages about 7 px per character).
        let w = 7.0 * s.name.chars().count() as f64;
        x -= w;
        svg.label(x, c.rect.y + 13.0, "start", "", s.name);
        x -= 20.0;
        svg.line(
            (x, c.rect.y + 8.5),
            (x + 14.0, c.rect.y + 8.5),
            &format!(r#" stroke="{}" stroke-width="3""#, s.colour),
        );
        x -= 14.0;
    }
}

/// An axis's range, rounded out to whole ticks, and its ticks.
struct Axis {
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
    decimals: usize,
}

impl Axis {
    /// About `count` ticks at 1, 2 or 5 times a power of ten (whole numbers when `integer`),
    /// covering [lo, hi]; a range of zero width is widened.
    fn nice(lo: f64, hi: f64, count: usize, integer: bool) -> Axis {
        let (lo, hi) = if hi - lo > (lo.abs().max(hi.abs())) * 1e-9 && hi > lo {
            (lo, hi)
        } else {
            let pad = if integer {
                1.0
            } else {
                (lo.abs() * 0.1).max(0.5)
            };
            (lo - pad, hi + pad)
        };
        let raw = (hi - lo) / count.max(1) as f64;
        let mag = 10f64.powf(raw.log10().floor());
        let step = [1.0, 2.0, 5.0, 10.0]
            .iter()
            .map(|m| m * mag)
            .find(|s| *s >= raw)
            .unwrap_or(10.0 * mag);
        // Whole numbers: every one of a short range (K = 1..10), else a round step.
        let step = match integer {
            true if hi - lo <= 10.0 => 1.0,
            true => step.max(1.0).round(),
            false => step,
        };
        let (lo, hi) = if integer {
            (lo, hi)
        } else {
            ((lo / step).floor() * step, (hi / step).ceil() * step)
        };
        let first = (lo / step).ceil() as i64;
        let last = (hi / step + 1e-9).floor() as i64;
        let ticks = (first..=last.min(first + 50))
            .map(|i| i as f64 * step)
            .collect();
        let decimals = if step >= 1.0 {
            0
        } else {
            (-step.log10().floor()) as usize
        };
        Axis {
            lo,
            hi,
            ticks,
            decimals,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_axes() {
        let a = Axis::nice(0.0, 0.93, 5, false);
        assert_eq!((a.lo, a.hi), (0.0, 1.0));
        assert_eq!(a.ticks.len(), 6, "{:?}", a.ticks);
        assert_eq!(a.decimals, 1);
        let k = Axis::nice(1.0, 8.0, 10, true);
        assert_eq!(k.ticks, (1..=8).map(f64::from).collect::<Vec<_>>());
        let flat = Axis::nice(3.0, 3.0, 4, false);
        assert!(flat.lo < 3.0 && flat.hi > 3.0 && !flat.ticks.is_empty());
        let one = Axis::nice(1.0, 1.0, 4, true);
        assert!(one.ticks.contains(&1.0));
    }
}
