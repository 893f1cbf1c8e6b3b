//! The map from data coordinates to picture pixels: an aspect-preserving fit of the data's
//! extent into a plot rectangle, with y pointing up (plane points) or down (image coordinates).

use super::svg::Rect;

/// An axis-aligned box in data coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Bounds {
    pub x0: f64,
    pub y0: f64,
    pub x1: f64,
    pub y1: f64,
}

impl Bounds {
    /// The empty box (grows with [`Bounds::add`]).
    pub fn empty() -> Bounds {
        Bounds {
            x0: f64::INFINITY,
            y0: f64::INFINITY,
            x1: f64::NEG_INFINITY,
            y1: f64::NEG_INFINITY,
        }
    }

    /// Grows the box to hold (x, y); values that are not finite are ignored.
    pub fn add(&mut self, x: f64, y: f64) {
        if x.is_finite() && y.is_finite() {
            self.x0 = self.x0.min(x);
            self.x1 = self.x1.max(x);
            self.y0 = self.y0.min(y);
            self.y1 = self.y1.max(y);
        }
    }

    fn is_empty(&self) -> bool {
        !(self.x0 <= self.x1 && self.y0 <= self.y1)
    }

    /// Height over width, kept within [0.05, 20]; 1 for an empty box or a single point.
    pub fn aspect(&self) -> f64 {
        let (w, h) = (self.x1 - self.x0, self.y1 - self.y0);
        if self.is_empty() || !(w > 0.0 || h > 0.0) {
            return 1.0;
        }
        (h / w).clamp(0.05, 20.0)
    }
}

/// Data-to-pixel map: `px = ox + s * x`, `py = oy -+ s * y`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Frame {
    scale: f64,
    ox: f64,
    oy: f64,
    /// y grows downwards in the data (image coordinates), as on screen.
    y_down: bool,
    /// The part of the data plane the plot shows.
    pub visible: Bounds,
}

impl Frame {
    /// Fits `data` (padded by 4 % of its larger side) into `plot`, centred, one scale for both
    /// axes. A box of zero width or height (one point, collinear points) or an empty one gets a
    /// finite extent, so the map is always finite.
    pub fn fit(data: Bounds, plot: Rect, y_down: bool) -> Frame {
        let data = if data.is_empty() {
            Bounds {
                x0: 0.0,
                y0: 0.0,
                x1: 0.0,
                y1: 0.0,
            }
        } else {
            data
        };
        let (cx, cy) = (data.x0 / 2.0 + data.x1 / 2.0, data.y0 / 2.0 + data.y1 / 2.0);
        let span = (data.x1 - data.x0).max(data.y1 - data.y0);
        // One point (or coincident points) has no extent: show a unit box around it, or a box
        // relative to its magnitude where a unit would be lost in rounding.
        let span = if span.is_finite() && span > cx.abs().max(cy.abs()) * 1e-12 && span > 0.0 {
            span
        } else {
            (cx.abs().max(cy.abs()) * 1e-6).max(1.0)
        };
        let w = (data.x1 - data.x0).max(span * 1e-3) * 1.08;
        let h = (data.y1 - data.y0).max(span * 1e-3) * 1.08;
        let scale = (plot.w / w).min(plot.h / h);
        let (pcx, pcy) = (plot.x + plot.w / 2.0, plot.y + plot.h / 2.0);
        let (half_w, half_h) = (plot.w / scale / 2.0, plot.h / scale / 2.0);
        let visible = Bounds {
            x0: cx - half_w,
            x1: cx + half_w,
            y0: cy - half_h,
            y1: cy + half_h,
        };
        let (ox, oy) = if y_down {
            (pcx - scale * cx, pcy - scale * cy)
        } else {
            (pcx - scale * cx, pcy + scale * cy)
        };
        Frame {
            scale,
            ox,
            oy,
            y_down,
            visible,
        }
    }

    /// Pixels of the data point (x, y).
    pub fn map(&self, x: f64, y: f64) -> (f64, f64) {
        let py = if self.y_down {
            self.oy + self.scale * y
        } else {
            self.oy - self.scale * y
        };
        (self.ox + self.scale * x, py)
    }

    /// Pixels per data unit.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Degrees to rotate (SVG `rotate`, clockwise on screen) for a data angle `theta` (radians,
    /// counter-clockwise from +x in the data's own axes).
    pub fn degrees(&self, theta: f64) -> f64 {
        if self.y_down {
            theta.to_degrees()
        } else {
            -theta.to_degrees()
        }
    }

    /// The visible part of the line a·x + b·y + c = 0, as two data points; `None` when the line
    /// misses the plot or is not a line (a = b = 0, values not finite).
    pub fn clip_line(&self, a: f64, b: f64, c: f64) -> Option<((f64, f64), (f64, f64))> {
        let n2 = a * a + b * b;
        if !(n2.is_finite() && n2 > 0.0 && c.is_finite()) {
            return None;
        }
        let n = n2.sqrt();
        // The foot of the perpendicular from the origin, and the unit direction.
        let (px, py) = (-a * c / n2, -b * c / n2);
        let (dx, dy) = (-b / n, a / n);
        let v = &self.visible;
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        for (p, d, lo, hi) in [(px, dx, v.x0, v.x1), (py, dy, v.y0, v.y1)] {
            if d.abs() < 1e-12 {
                if p < lo || p > hi {
                    return None;
                }
            } else {
                let (ta, tb) = ((lo - p) / d, (hi - p) / d);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        if !(t0.is_finite() && t1.is_finite() && t0 < t1) {
            return None;
        }
        Some(((px + t0 * dx, py + t0 * dy), (px + t1 * dx, py + t1 * dy)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PLOT: Rect = Rect {
        x: 10.0,
        y: 20.0,
        w: 200.0,
        h: 100.0,
    };

    fn bounds(points: &[(f64, f64)]) -> Bounds {
        let mut b = Bounds::empty();
        for &(x, y) in points {
            b.add(x, y);
        }
        b
    }

    #[test]
    fn fits_and_flips() {
        let f = Frame::fit(bounds(&[(0.0, 0.0), (1.0, 1.0)]), PLOT, false);
        let (x0, y0) = f.map(0.0, 0.0);
        let (x1, y1) = f.map(1.0, 1.0);
        assert!(x1 > x0 && y1 < y0, "y up");
        for (x, y) in [(x0, y0), (x1, y1)] {
            assert!(x >= PLOT.x && x <= PLOT.right() && y >= PLOT.y && y <= PLOT.bottom());
        }
        let down = Frame::fit(bounds(&[(0.0, 0.0), (1.0, 1.0)]), PLOT, true);
        assert!(down.map(1.0, 1.0).1 > down.map(0.0, 0.0).1, "y down");
    }

    #[test]
    fn degenerate_extents_stay_finite() {
        for pts in [
            vec![],
            vec![(5.0, 5.0)],
            vec![(1e9, -1e9), (1e9, -1e9)],
            vec![(0.0, 1.0), (4.0, 1.0)],
        ] {
            let f = Frame::fit(bounds(&pts), PLOT, false);
            let (x, y) = f.map(
                pts.first().map_or(0.0, |p| p.0),
                pts.first().map_or(0.0, |p| p.1),
            );
            assert!(x.is_finite() && y.is_finite() && f.scale().is_finite() && f.scale() > 0.0);
            assert!(
                (x - 110.0).abs() < 100.0 && (y - 70.0).abs() < 50.0,
                "{pts:?}: {x} {y}"
            );
        }
    }

    #[test]
    fn aspects() {
        assert_eq!(bounds(&[(0.0, 0.0), (4.0, 1.0)]).aspect(), 0.25);
        assert_eq!(bounds(&[(0.0, 0.0), (0.0, 1.0)]).aspect(), 20.0);
        assert_eq!(bounds(&[(2.0, 2.0)]).aspect(), 1.0);
        assert_eq!(Bounds::empty().aspect(), 1.0);
    }

    #[test]
    fn lines_are_clipped_to_the_plot() {
        let f = Frame::fit(bounds(&[(-1.0, -1.0), (1.0, 1.0)]), PLOT, false);
        // y = 0.5: a horizontal line across the whole visible width.
        let ((x0, y0), (x1, y1)) = f.clip_line(0.0, 1.0, -0.5).unwrap();
        assert!((y0 - 0.5).abs() < 1e-9 && (y1 - 0.5).abs() < 1e-9);
        assert!((x0.min(x1) - f.visible.x0).abs() < 1e-9);
        assert!((x0.max(x1) - f.visible.x1).abs() < 1e-9);
        assert!(f.clip_line(0.0, 1.0, -50.0).is_none(), "misses the plot");
        assert!(f.clip_line(0.0, 0.0, 1.0).is_none(), "not a line");
        assert!(f.clip_line(f64::NAN, 1.0, 0.0).is_none());
    }
}
