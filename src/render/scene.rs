//! The data part of a fit's picture: one mark per point coloured by label, correspondences'
//! segments and trajectories' tracks, and the fitted curves (lines, circles, ellipses).

use std::collections::BTreeMap;

use super::frame::{Bounds, Frame};
use super::palette::colour;
use super::svg::{Rect, Svg};
use crate::data::{ImageSize, Kind, PointSet};
use crate::geometry::Model;

/// Id of the clip path of the plot rectangle (curves never leave it).
pub(super) const CLIP_ID: &str = "mf-plot";

/// What the plot shows: every (x, y) of the points and, for the image-frame kinds when it is
/// known, the image.
pub(super) fn bounds(points: &PointSet, image: Option<ImageSize>) -> Bounds {
    let mut b = Bounds::empty();
    for p in points.values().chunks_exact(2) {
        b.add(p[0], p[1]);
    }
    if let (true, Some(size)) = (points.kind() != Kind::Points2d, image) {
        b.add(0.0, 0.0);
        for v in 0..2 {
            let [w, h] = size.view(v);
            b.add(w, h);
        }
    }
    b
}

/// The data-to-pixel map of `bounds` in `plot`: plane points with y up, correspondences and
/// trajectories with y down (image coordinates).
pub(super) fn frame(kind: Kind, bounds: Bounds, plot: Rect) -> Frame {
    Frame::fit(bounds, plot, kind != Kind::Points2d)
}

/// Point indices by label, labels ascending (so outliers, -1, first); a point without a label
/// counts as an outlier.
pub(super) fn groups(n: usize, labels: &[i64]) -> BTreeMap<i64, Vec<usize>> {
    let mut groups: BTreeMap<i64, Vec<usize>> = BTreeMap::new();
    for i in 0..n {
        let l = labels.get(i).copied().unwrap_or(-1).max(-1);
        groups.entry(l).or_default().push(i);
    }
    groups
}

/// The radius of a mark for `n` points: about 3.5 px for 200 points, 1.2 px for 20000.
pub(super) fn mark_radius(n: usize) -> f64 {
    ((12.0 / (n.max(1) as f64).powf(0.23)).clamp(1.0, 4.0) * 10.0).round() / 10.0
}

/// Draws the image outline (image-frame kinds with a known size), then every point's mark,
/// segment or track, grouped by label.
pub(super) fn draw_points(
    svg: &mut Svg,
    frame: &Frame,
    points: &PointSet,
    image: Option<ImageSize>,
    groups: &BTreeMap<i64, Vec<usize>>,
) {
    let kind = points.kind();
    // One outline per image size (the second view's too, when it has its own).
    let sizes = image
        .filter(|_| kind != Kind::Points2d)
        .map(|s| {
            let mut sizes = vec![s.view(0)];
            sizes.extend(s.second);
            sizes
        })
        .unwrap_or_default();
    for [w, h] in sizes {
        let (x0, y0) = frame.map(0.0, 0.0);
        let (x1, y1) = frame.map(w, h);
        svg.rect(
            Rect {
                x: x0.min(x1),
                y: y0.min(y1),
                w: (x1 - x0).abs(),
                h: (y1 - y0).abs(),
            },
            r##" fill="#f4f4f4" stroke="#c8c8c8" class="image""##,
        );
        svg.raw("\n");
    }
    let n = points.len();
    // Segments (correspondences) or tracks (trajectories), under the marks.
    if kind != Kind::Points2d {
        let width = if n > 2000 { "0.6" } else { "1" };
        for (&label, members) in groups {
            svg.fmt(format_args!(
                r#"<g class="{}" fill="none" stroke="{}" stroke-width="{width}" stroke-opacity="{}">"#,
                if kind == Kind::Correspondences { "segments" } else { "tracks" },
                colour(label),
                if label < 0 { "0.35" } else { "0.6" }
            ));
            for &i in members {
                let row = points.row(i);
                if kind == Kind::Correspondences {
                    svg.line(frame.map(row[0], row[1]), frame.map(row[2], row[3]), "");
                } else {
                    svg.polyline(row.chunks_exact(2).map(|p| frame.map(p[0], p[1])), "");
                }
            }
            svg.raw("</g>\n");
        }
    }
    // One mark per point: the point, the image-1 position, or the track's last position.
    let r = mark_radius(n);
    let outline = if n <= 2000 {
        r##" stroke="#fff" stroke-width="0.7""##
    } else {
        ""
    };
    for (&label, members) in groups {
        svg.fmt(format_args!(
            r#"<g class="marks" data-label="{label}" fill="{}"{outline}>"#,
            colour(label)
        ));
        for &i in members {
            let row = points.row(i);
            let at = match kind {
                Kind::Points2d | Kind::Correspondences => 0,
                Kind::Trajectories => row.len() - 2,
            };
            let (x, y) = frame.map(row[at], row[at + 1]);
            svg.raw(r#"<circle class="pt""#);
            svg.attr("cx", x);
            svg.attr("cy", y);
            svg.attr("r", r);
            svg.raw("/>");
        }
        svg.raw("</g>\n");
    }
}

/// Draws each structure that is a plane curve (line, circle, ellipse) in its label's colour,
/// clipped to the plot; other models (homographies, fundamental matrices, subspaces) have no
/// curve in this view and are only named in the legend.
pub(super) fn draw_structures(svg: &mut Svg, frame: &Frame, structures: &[(usize, &Model)]) {
    let drawable = |m: &Model| {
        matches!(
            m,
            Model::Line { .. } | Model::Circle { .. } | Model::Ellipse { .. }
        )
    };
    if !structures.iter().any(|(_, m)| drawable(m)) {
        return;
    }
    // A curve larger than this (pixels) is too flat to draw as itself; it is skipped.
    const MAX_PX: f64 = 1e5;
    svg.fmt(format_args!(
        r#"<g class="structures" fill="none" stroke-width="2" stroke-opacity="0.9" clip-path="url(#{CLIP_ID})">"#
    ));
    for &(label, model) in structures {
        let stroke = colour(i64::try_from(label).unwrap_or(-1));
        match *model {
            Model::Line { a, b, c } => {
                if let Some((p, q)) = frame.clip_line(a, b, c) {
                    svg.line(
                        frame.map(p.0, p.1),
                        frame.map(q.0, q.1),
                        &format!(r#" stroke="{stroke}" class="curve""#),
                    );
                }
            }
            Model::Circle { cx, cy, r } => {
                let rp = r * frame.scale();
                let (x, y) = frame.map(cx, cy);
                if [x, y, rp].iter().all(|v| v.is_finite()) && rp > 0.0 && rp < MAX_PX {
                    svg.raw("<circle");
                    svg.attr("cx", x);
                    svg.attr("cy", y);
                    svg.attr("r", rp);
                    svg.fmt(format_args!(r#" stroke="{stroke}" class="curve"/>"#));
                }
            }
            Model::Ellipse {
                cx,
                cy,
                a,
                b,
                theta,
            } => {
                let (ra, rb) = (a * frame.scale(), b * frame.scale());
                let (x, y) = frame.map(cx, cy);
                let deg = frame.degrees(theta);
                let ok = [x, y, ra, rb, deg].iter().all(|v| v.is_finite())
                    && ra > 0.0
                    && rb > 0.0
                    && ra.max(rb) < MAX_PX;
                if ok {
                    svg.raw("<ellipse");
                    svg.attr("cx", x);
                    svg.attr("cy", y);
                    svg.attr("rx", ra);
                    svg.attr("ry", rb);
                    svg.raw(" transform=\"rotate(");
                    svg.num(deg % 360.0);
                    svg.raw(" ");
                    svg.num(x);
                    svg.raw(" ");
                    svg.num(y);
                    svg.fmt(format_args!(r#")" stroke="{stroke}" class="curve"/>"#));
                }
            }
            _ => {}
        }
    }
    svg.raw("</g>\n");
}
