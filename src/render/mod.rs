//! Pictures of fits and training runs as SVG, written by hand with nothing beyond `std`.
//!
//! [`fit_svg`] draws one fit: every point as exactly one mark (`<circle class="pt">`) coloured by
//! its label (outliers grey), correspondences' segments to their image-2 positions and
//! trajectories' tracks, the fitted lines, circles and ellipses, a legend (label, type, count),
//! the title with the model and K, and side charts of the residual curve r(K) with the chosen K
//! and of the score per K. [`curves_svg`] draws a training run's loss and validation curves.
//!
//! Output is deterministic (same input, same bytes), always well-formed XML, and every number in
//! it is finite: coordinates are written with at most one decimal in the picture's own pixel
//! space (which also keeps 20000 points to a few milliseconds and about a megabyte).
//!
//! | module | concern |
//! |---|---|
//! | `svg` | the writer: elements, compact numbers, XML escaping |
//! | `palette` | colour-blind-safe colours and their contrast |
//! | `frame` | the data-to-pixel map, extents, line clipping |
//! | `scene` | marks, segments, tracks and fitted curves |
//! | `chart` | small line charts (r(K), scores, training curves) |
//! | `layout` | the fit picture's title, plot, legend and side panel |

mod chart;
mod frame;
mod layout;
mod palette;
mod scene;
mod svg;
#[cfg(test)]
mod tests;

use crate::data::{ImageSize, PointSet};
use crate::geometry::Model;

/// Everything one fit's picture shows.
#[derive(Debug, Clone)]
pub struct Picture<'a> {
    /// The heading, e.g. `"lce · K = 4 (sod)"`; also the SVG's `<title>`.
    pub title: String,
    /// The points: `points2d` rows `[x, y]` are drawn with y up; correspondences `[x1, y1, x2,
    /// y2]` and trajectories `[x1, y1, ..., xF, yF]` in the image frame, y down.
    pub points: &'a PointSet,
    /// The image the pixel coordinates refer to, drawn as an outline when known.
    pub image_size: Option<ImageSize>,
    /// One label per point; -1 (any negative) is an outlier, drawn grey. A point without a
    /// label is drawn as an outlier.
    pub labels: &'a [i64],
    /// `(label, model)` of the fitted structures; lines, circles and ellipses are drawn as
    /// curves, every type is named in the legend. May be empty.
    pub structures: &'a [(usize, &'a Model)],
    /// `(K, r(K))` for every K clustered; may be empty (fixed K).
    pub residuals: &'a [(usize, f64)],
    /// `(K, score)`: the SOD value or the mean silhouette per candidate K; may be empty.
    pub scores: &'a [(usize, f64)],
    /// The K of the answer.
    pub k: usize,
    /// The K of the learned clustering the answer comes from, marked on the residual and score
    /// charts: the answer's K unless refinement merged or added structures, or an outlier
    /// group was answered -1.
    pub clustered_k: usize,
    /// How K was chosen: `"sod"`, `"silhouette"` or `"fixed"`.
    pub selection: &'a str,
}

/// The SVG picture of a fit (see the module documentation).
pub fn fit_svg(p: &Picture) -> String {
    layout::fit(p)
}

/// A line chart of training curves: each series is a name and its `(x, y)` points (epoch or
/// step, value); points with a value that is not finite break the curve.
pub fn curves_svg(title: &str, series: &[(&str, &[(f64, f64)])]) -> String {
    layout::curves(title, series)
}
