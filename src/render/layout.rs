//! Composition of the pictures: a fit's title, plot, legend and side charts; a training run's
//! curves.

use std::collections::BTreeMap;

use super::Picture;
use super::chart::{self, Chart, Series};
use super::palette::{MUTED, OUTLIER, RULE, STRUCTURES, colour};
use super::scene::{self, CLIP_ID};
use super::svg::{Rect, Svg, human};
use crate::data::Kind;

/// Width of a fit's picture.
const WIDTH: f64 = 960.0;
/// Left and right margin.
const MARGIN: f64 = 24.0;
/// Top of the plot, under the title and subtitle.
const TOP: f64 = 76.0;
/// Width of the legend and of each side chart.
const PANEL_W: f64 = 280.0;
/// Legend rows shown before the rest is summarised in one line.
const MAX_ROWS: usize = 10;
/// Data wider than this (height over width below it) is drawn across the whole width, with the
/// legend and the charts under it, instead of beside a square-ish plot.
const WIDE: f64 = 0.55;

/// Where the parts of a fit's picture go.
struct Layout {
    height: f64,
    plot: Rect,
    /// The legend's top left corner; its width is `PANEL_W`.
    legend: (f64, f64),
    /// Beside the plot: charts stacked under the legend. Under a wide plot: charts side by side
    /// right of the legend.
    stacked: bool,
    /// Top of the charts when side by side.
    charts_top: f64,
}

impl Layout {
    fn new(aspect: f64, legend_height: f64) -> Layout {
        if aspect >= WIDE {
            let plot = Rect {
                x: MARGIN,
                y: TOP,
                w: 600.0,
                h: 540.0,
            };
            return Layout {
                height: plot.bottom() + MARGIN,
                plot,
                legend: (plot.right() + 32.0, TOP + 16.0),
                stacked: true,
                charts_top: 0.0,
            };
        }
        let w = WIDTH - 2.0 * MARGIN;
        let plot = Rect {
            x: MARGIN,
            y: TOP,
            w,
            h: (w * aspect * 1.02).clamp(160.0, 420.0).round(),
        };
        let top = plot.bottom() + 24.0;
        Layout {
            height: (top + legend_height.max(230.0) + 12.0).round(),
            plot,
            legend: (MARGIN, top + 16.0),
            stacked: false,
            charts_top: top,
        }
    }
}

/// The picture of a fit.
pub(super) fn fit(p: &Picture) -> String {
    let n = p.points.len();
    let groups = scene::groups(n, p.labels);
    let bounds = scene::bounds(p.points, p.image_size);
    let layout = Layout::new(bounds.aspect(), legend_height(&groups));
    let plot = layout.plot;
    // About 48 bytes per mark, plus segments or tracks.
    let per_point = 60 + 12 * p.points.dim();
    let mut svg = Svg::new(WIDTH, layout.height, &p.title, 4096 + n * per_point);
    svg.label(
        MARGIN,
        34.0,
        "start",
        r#" font-size="20" font-weight="600""#,
        &p.title,
    );
    svg.label(
        MARGIN,
        58.0,
        "start",
        &format!(r#" fill="{MUTED}""#),
        &subtitle(p),
    );

    svg.raw("<defs><clipPath id=\"");
    svg.raw(CLIP_ID);
    svg.raw("\">");
    svg.rect(plot, "");
    svg.raw("</clipPath></defs>\n");
    svg.rect(plot, &format!(r#" fill="none" stroke="{RULE}""#));
    svg.raw("\n");

    let frame = scene::frame(p.points.kind(), bounds, plot);
    scene::draw_points(&mut svg, &frame, p.points, p.image_size, &groups);
    scene::draw_structures(&mut svg, &frame, p.structures);

    let legend_bottom = legend(&mut svg, p, &groups, layout.legend);
    let charts = charts(p);
    let rects: Vec<Rect> = if layout.stacked {
        let top = legend_bottom.max(TOP + 250.0) + 8.0;
        let h = (plot.bottom() - top) / charts.len().max(1) as f64;
        (0..charts.len())
            .map(|i| Rect {
                x: layout.legend.0 - 8.0,
                y: top + i as f64 * h,
                w: PANEL_W + 8.0,
                h: h - 6.0,
            })
            .collect()
    } else {
        (0..charts.len())
            .map(|i| Rect {
                x: WIDTH - MARGIN - (charts.len() - i) as f64 * (PANEL_W + 16.0) + 16.0,
                y: layout.charts_top,
                w: PANEL_W,
                h: 220.0,
            })
            .collect()
    };
    draw_charts(&mut svg, p, &charts, &rects);
    svg.finish()
}

/// "200 points · 12 outliers" and what the marks mean for the kind.
fn subtitle(p: &Picture) -> String {
    let n = p.points.len();
    let what = match p.points.kind() {
        Kind::Points2d => format!("{n} points"),
        Kind::Correspondences => {
            format!("{n} correspondences: dot at image 1, segment to image 2")
        }
        Kind::Trajectories => format!(
            "{n} trajectories over {} frames: dot at the last frame",
            p.points.dim() / 2
        ),
    };
    match p.image_size {
        Some(s) if p.points.kind() != Kind::Points2d => match s.second {
            Some([w2, h2]) => format!(
                "{what} · images {} × {} and {} × {}",
                human(s.width),
                human(s.height),
                human(w2),
                human(h2)
            ),
            None => format!("{what} · image {} × {}", human(s.width), human(s.height)),
        },
        _ => what,
    }
}

/// Legend rows: one per structure up to `MAX_ROWS` (the rest summed in one), and the outliers.
fn legend_rows(groups: &BTreeMap<i64, Vec<usize>>) -> usize {
    let clusters = groups.keys().filter(|l| **l >= 0).count();
    clusters.min(MAX_ROWS) + usize::from(groups.contains_key(&-1))
}

/// Height of the legend drawn by [`legend`].
fn legend_height(groups: &BTreeMap<i64, Vec<usize>>) -> f64 {
    44.0 + 21.0 * legend_rows(groups) as f64
}

/// The legend at `(x, y)` (K and how it was chosen, then one row per label: colour, label, type,
/// count; the outliers last); returns its bottom edge.
fn legend(
    svg: &mut Svg,
    p: &Picture,
    groups: &BTreeMap<i64, Vec<usize>>,
    (x, y): (f64, f64),
) -> f64 {
    let mut y = y;
    svg.raw(r#"<g class="legend">"#);
    let how = match p.selection {
        "sod" => "chosen by SOD",
        "silhouette" => "chosen by silhouette",
        "fixed" => "fixed",
        other => other,
    };
    svg.label(
        x,
        y,
        "start",
        r#" font-size="18" font-weight="600""#,
        &format!("K = {}", p.k),
    );
    svg.label(x + PANEL_W, y, "end", &format!(r#" fill="{MUTED}""#), how);
    let types: BTreeMap<usize, &str> = p
        .structures
        .iter()
        .map(|(l, m)| (*l, m.type_name()))
        .collect();
    let row_text = format!(r#" fill="{MUTED}" font-size="12""#);
    y += 28.0;
    svg.label(x + 18.0, y, "start", &row_text, "label");
    if !types.is_empty() {
        svg.label(x + 76.0, y, "start", &row_text, "type");
    }
    svg.label(x + PANEL_W, y, "end", &row_text, "points");
    let clusters: Vec<(i64, usize)> = groups
        .iter()
        .filter(|(l, _)| **l >= 0)
        .map(|(l, m)| (*l, m.len()))
        .collect();
    let shown = if clusters.len() > MAX_ROWS {
        MAX_ROWS - 1
    } else {
        clusters.len()
    };
    let row = |svg: &mut Svg, y: f64, fill: &str, label: &str, kind: &str, count: usize| {
        svg.raw("<circle");
        svg.attr("cx", x + 6.0);
        svg.attr("cy", y - 4.5);
        svg.raw(" r=\"5.5\" fill=\"");
        svg.raw(fill);
        svg.raw("\"/>");
        svg.label(x + 18.0, y, "start", "", label);
        if !kind.is_empty() {
            svg.label(x + 76.0, y, "start", "", kind);
        }
        svg.label(x + PANEL_W, y, "end", "", &count.to_string());
    };
    for &(label, count) in &clusters[..shown] {
        y += 21.0;
        let kind = usize::try_from(label)
            .ok()
            .and_then(|l| types.get(&l).copied())
            .unwrap_or("");
        row(svg, y, colour(label), &label.to_string(), kind, count);
    }
    if shown < clusters.len() {
        y += 21.0;
        let rest: usize = clusters[shown..].iter().map(|(_, c)| c).sum();
        svg.label(
            x + 18.0,
            y,
            "start",
            &format!(r#" fill="{MUTED}""#),
            &format!("{} more structures", clusters.len() - shown),
        );
        svg.label(x + PANEL_W, y, "end", "", &rest.to_string());
    }
    if let Some(outliers) = groups.get(&-1) {
        y += 21.0;
        row(svg, y, OUTLIER, "outliers", "", outliers.len());
    }
    svg.raw("</g>\n");
    y + 10.0
}

/// One chart of K: its title, its points (K, value), and whether its y axis starts at zero.
struct KChart {
    title: &'static str,
    points: Vec<(f64, f64)>,
    from_zero: bool,
}

/// The charts a fit has data for: r(K), and the SOD or silhouette score per K.
fn charts(p: &Picture) -> Vec<KChart> {
    let as_xy = |v: &[(usize, f64)]| v.iter().map(|&(k, r)| (k as f64, r)).collect::<Vec<_>>();
    let score = match p.selection {
        "silhouette" => "mean silhouette per K",
        _ => "SOD score per K",
    };
    [
        KChart {
            title: "residual r(K)",
            points: as_xy(p.residuals),
            from_zero: true,
        },
        KChart {
            title: score,
            points: as_xy(p.scores),
            from_zero: false,
        },
    ]
    .into_iter()
    .filter(|c| !c.points.is_empty())
    .collect()
}

/// Draws `charts` into `rects`, over one K axis, the chosen K marked.
fn draw_charts(svg: &mut Svg, p: &Picture, charts: &[KChart], rects: &[Rect]) {
    let caption = if p.clustered_k == p.k {
        format!("K = {}", p.k)
    } else {
        format!("K = {} clustered", p.clustered_k)
    };
    let ks = p.residuals.iter().chain(p.scores).map(|&(k, _)| k as f64);
    let span = ks.fold(None, |acc: Option<(f64, f64)>, k| {
        Some(acc.map_or((k, k), |(a, b)| (a.min(k), b.max(k))))
    });
    for (c, &rect) in charts.iter().zip(rects) {
        let series = [Series {
            name: c.title,
            colour: STRUCTURES[0],
            points: &c.points,
        }];
        chart::draw(
            svg,
            &Chart {
                rect,
                title: c.title,
                series: &series,
                integer_x: true,
                y_from_zero: c.from_zero,
                dots: true,
                mark: Some((p.clustered_k as f64, &caption)),
                x_label: "K",
                x_span: span,
                title_size: 13.0,
            },
        );
    }
}

/// A training run's curves on one chart.
pub(super) fn curves(title: &str, series: &[(&str, &[(f64, f64)])]) -> String {
    let (width, height) = (760.0, 440.0);
    let points: usize = series.iter().map(|(_, v)| v.len()).sum();
    let mut svg = Svg::new(width, height, title, 4096 + 16 * points);
    let series: Vec<Series> = series
        .iter()
        .enumerate()
        .map(|(i, (name, points))| Series {
            name,
            colour: STRUCTURES[i % STRUCTURES.len()],
            points,
        })
        .collect();
    chart::draw(
        &mut svg,
        &Chart {
            rect: Rect {
                x: 16.0,
                y: 12.0,
                w: width - 32.0,
                h: height - 24.0,
            },
            title,
            series: &series,
            // Epochs (whole numbers) get whole-number ticks.
            integer_x: series
                .iter()
                .flat_map(|s| s.points.iter())
                .all(|(x, _)| !x.is_finite() || x.fract() == 0.0),
            y_from_zero: false,
            dots: false,
            mark: None,
            x_label: "epoch",
            x_span: None,
            title_size: 16.0,
        },
    );
    svg.finish()
}
