//! What an answer warns of: inputs that look unlike what the caller meant (points outside the
//! image or in a corner of it, a tracker's lost points at the origin, rows set apart as far
//! from the rest), fewer structures than the k asked, and what the fit saw for the model
//! card's validated range ([`observed`]).

use crate::data::screen;
use crate::data::{ImageSize, Kind, PointSet};
use crate::registry::Observed;

/// The warning of an answer with fewer structures than the k the caller gave (`refined`:
/// refinement dropped the difference; else one learned group was the outliers'); `None` when
/// it has k.
pub(super) fn fewer_than_asked(asked: usize, answered: usize, refined: bool) -> Option<String> {
    let dropped = asked.checked_sub(answered).filter(|&d| d > 0)?;
    if !refined {
        return Some(format!(
            "k = {asked} was given and the answer has {answered} structure{}: one of the \
             {asked} learned groups is the outliers', answered -1 (\"outliers\": false answers \
             the {asked} learned groups)",
            if answered == 1 { "" } else { "s" }
        ));
    }
    let (noun, their) = if dropped == 1 {
        ("group", "its")
    } else {
        ("groups", "their")
    };
    let structures = if answered == 1 {
        "structure"
    } else {
        "structures"
    };
    Some(format!(
        "k = {asked} was given and refinement answers {answered} {structures}: {dropped} learned \
         {noun} followed no model or lost most of {their} points to the others (\"refine\": \
         false answers the {asked} learned groups)"
    ))
}

/// Points that span under this share of the image's longer side sit in a corner of what the
/// network reads (inputs are normalised by the image): [`image_barely_used`].
const MIN_IMAGE_SPAN: f64 = 0.1;

/// The warning of pixel coordinates that span under [`MIN_IMAGE_SPAN`] of the `image` given
/// (along x and along y, over every view or frame; for two images of two sizes, each view in
/// its own image): most often an image size that is not the one the coordinates were measured
/// in. `None` for points2d, without an image, or when the points use the image.
fn image_barely_used(points: &PointSet, image: Option<ImageSize>) -> Option<String> {
    let image = image.filter(|_| points.kind() != Kind::Points2d)?;
    let check = "check that image_size is the size of the image the coordinates were measured in";
    if image.second.is_some() && points.kind() == Kind::Correspondences {
        let words: Vec<String> = (0..2)
            .filter_map(|v| {
                let span = points.view_extent(v);
                let [w, h] = image.view(v);
                let side = w.max(h);
                (span < MIN_IMAGE_SPAN * side).then(|| {
                    format!(
                        "the points of image {} span {} px of its {side} px",
                        v + 1,
                        span.round()
                    )
                })
            })
            .collect();
        return (!words.is_empty()).then(|| format!("{}: {check}", words.join("; ")));
    }
    let span = points.extent();
    let side = image.width.max(image.height);
    (span < MIN_IMAGE_SPAN * side).then(|| {
        format!(
            "the points span {} px of the {side} px image: {check}",
            span.round()
        )
    })
}

/// The warnings of pixel coordinates that do not fit the `image` given: spanning a corner of it
/// ([`image_barely_used`]), or lying outside it ([`outside_image`]).
pub(super) fn image_warnings(
    points: &PointSet,
    image: Option<ImageSize>,
) -> impl Iterator<Item = String> {
    image_barely_used(points, image)
        .into_iter()
        .chain(outside_image(points, image))
}

/// A position outside the image by more than this share of its width or height counts as
/// outside it (tracks and matches may run a little past the border).
const OUTSIDE_MARGIN: f64 = 0.1;
/// The share of positions outside the image past which a fit says so.
const OUTSIDE_SHARE: f64 = 0.05;

/// The warning of pixel coordinates outside the `image` given ([`OUTSIDE_MARGIN`]), for more
/// than [`OUTSIDE_SHARE`] of the positions (each view of a correspondence against its own
/// image): an image_size in other units than the points, or swapped. `None` for points2d, no
/// image, or a few such positions.
fn outside_image(points: &PointSet, image: Option<ImageSize>) -> Option<String> {
    let image = image.filter(|_| points.kind() != Kind::Points2d)?;
    let two_views = points.kind() == Kind::Correspondences;
    let (mut outside, mut total) = (0usize, 0usize);
    let off = |x: f64, side: f64| x < -OUTSIDE_MARGIN * side || x > (1.0 + OUTSIDE_MARGIN) * side;
    for i in 0..points.len() {
        for (j, p) in points.row(i).chunks_exact(2).enumerate() {
            let [w, h] = image.view(if two_views { j } else { 0 });
            total += 1;
            outside += usize::from(off(p[0], w) || off(p[1], h));
        }
    }
    (outside as f64 > OUTSIDE_SHARE * total as f64).then(|| {
        format!(
            "{outside} of the {total} positions lie outside the image_size given: check that it \
             is the size of the image the coordinates were measured in, in the same units, width \
             first"
        )
    })
}

/// The warning of track positions at exactly (0, 0), what many trackers write for a point
/// they lost: read as positions, they pull their tracks to the image corner. `None` for other
/// kinds, or when there are none.
pub(super) fn lost_marks(points: &PointSet) -> Option<String> {
    if points.kind() != Kind::Trajectories {
        return None;
    }
    let zeros = points
        .values()
        .chunks_exact(2)
        .filter(|p| p[0] == 0.0 && p[1] == 0.0)
        .count();
    (zeros > 0).then(|| {
        format!(
            "{zeros} track position{} exactly (0, 0): if they mark points the tracker lost, send \
             visible (one row of 0/1 flags per track, 0 where it was not seen) so that they are \
             not read as positions",
            if zeros == 1 { " is" } else { "s are" }
        )
    })
}

/// The warning for rows the network did not read for lying far from the rest
/// ([`crate::data::screen`]), naming the first few by the caller's 0-based row numbers.
pub(super) fn far_apart(far: &[usize], rows: &str) -> Option<String> {
    not_read(far, |count| {
        format!(
            "{count} of the {rows} lie{} far from the rest (more than {} times the spread of \
             the {rows} nearer the centre)",
            if count == 1 { "s" } else { "" },
            screen::FAR_SPREADS,
        )
    })
}

/// The warning for tracks the network did not read for moving erratically
/// ([`screen::erratic_tracks`]), naming the first few by the caller's 0-based row numbers, and
/// saying when they are answered −1 (`minus_one`).
pub(super) fn erratic_apart(erratic: &[usize], minus_one: bool) -> Option<String> {
    let warning = not_read(erratic, |count| {
        format!(
            "{count} of the tracks accelerate{} more than {} times the median track, {} times \
             as fast as tracks move and {} times as fast as {} (a tracker that lost its feature)",
            if count == 1 { "s" } else { "" },
            screen::ERRATIC_ACCELERATIONS,
            screen::ERRATIC_SPEEDS,
            screen::ERRATIC_OWN_SPEED,
            if count == 1 { "it moves" } else { "they move" },
        )
    })?;
    Some(match (minus_one, erratic.len()) {
        (false, _) => warning,
        (true, 1) => format!("{warning}; it is labelled -1"),
        (true, _) => format!("{warning}; they are labelled -1"),
    })
}

/// `why(count)`, then that the network did not read them and the first few of `rows`; `None`
/// when `rows` is empty.
fn not_read(rows: &[usize], why: impl FnOnce(usize) -> String) -> Option<String> {
    const NAMED: usize = 10;
    let count = rows.len();
    (count > 0).then(|| {
        let list: Vec<String> = rows.iter().take(NAMED).map(|i| i.to_string()).collect();
        format!(
            "{}, so the network did not read {}: {}{}{}",
            why(count),
            if count == 1 { "it" } else { "them" },
            if count == 1 { "row " } else { "rows " },
            list.join(", "),
            if count > NAMED { ", ..." } else { "" },
        )
    })
}

/// What a fit saw, for the card's validated range: the input's size, frames and image, and the
/// answer's structure sizes and outlier share (only when the fit may answer outliers: a fit
/// that cannot flag them says nothing of their share).
pub(super) fn observed(
    points: &PointSet,
    image: Option<ImageSize>,
    labels: &[i64],
    k: usize,
    flags_outliers: bool,
) -> Observed {
    let mut sizes = vec![0usize; k];
    for &l in labels {
        if let Some(s) = usize::try_from(l).ok().and_then(|l| sizes.get_mut(l)) {
            *s += 1;
        }
    }
    let outliers = labels.iter().filter(|&&l| l < 0).count();
    Observed {
        rows: "points",
        points: points.len(),
        points_per_structure: sizes
            .iter()
            .min()
            .zip(sizes.iter().max())
            .map(|(&a, &b)| [a, b]),
        frames: (points.kind() == Kind::Trajectories).then(|| points.dim() / 2),
        image_side: image.map(|s| s.width.max(s.height)),
        outlier_ratio: flags_outliers.then(|| outliers as f64 / points.len().max(1) as f64),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::tests::image;

    #[test]
    fn erratic_tracks_are_named_apart_from_far_rows() {
        assert_eq!(erratic_apart(&[], true), None);
        let one = erratic_apart(&[7], false).unwrap();
        assert!(
            one.starts_with(
                "1 of the tracks accelerates more than 8 times the median track, 2 times"
            ),
            "{one}"
        );
        assert!(one.ends_with("did not read it: row 7"), "{one}");
        let many: Vec<usize> = (0..12).collect();
        let text = erratic_apart(&many, true).unwrap();
        assert!(
            text.ends_with("rows 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, ...; they are labelled -1"),
            "{text}"
        );
        let one = erratic_apart(&[7], true).unwrap();
        assert!(one.ends_with("row 7; it is labelled -1"), "{one}");
    }

    #[test]
    fn tracks_at_the_origin_are_named_as_a_trackers_lost_points() {
        let tracks = |lost: &[usize]| {
            let mut values: Vec<f64> = (0..24).map(|v| f64::from(v) + 1.0).collect();
            for &p in lost {
                values[2 * p] = 0.0;
                values[2 * p + 1] = 0.0;
            }
            PointSet::from_flat(Kind::Trajectories, 6, values).unwrap()
        };
        assert_eq!(lost_marks(&tracks(&[])), None);
        let one = lost_marks(&tracks(&[4])).unwrap();
        assert!(
            one.starts_with("1 track position is exactly (0, 0)"),
            "{one}"
        );
        let two = lost_marks(&tracks(&[4, 11])).unwrap();
        assert!(
            two.starts_with("2 track positions are exactly (0, 0)"),
            "{two}"
        );
        // A pair at the origin is a point like any other.
        let pairs = PointSet::from_flat(Kind::Correspondences, 4, vec![0.0; 8]).unwrap();
        assert_eq!(lost_marks(&pairs), None);
    }

    /// The values 0 to 39, and ten correspondences of them: x from 0 to 38, y from 1 to 39.
    fn forty_values() -> (Vec<f64>, PointSet) {
        let values: Vec<f64> = (0..40).map(f64::from).collect();
        let pairs = PointSet::from_flat(Kind::Correspondences, 4, values.clone()).unwrap();
        (values, pairs)
    }

    #[test]
    fn points_outside_the_image_say_so() {
        // Inside a 40 x 40 image, outside a 20 x 20 one by far.
        let (values, pairs) = forty_values();
        assert_eq!(outside_image(&pairs, None), None);
        assert_eq!(outside_image(&pairs, image(40.0, 40.0)), None);
        // Within a tenth of the size past the border is inside: 36 x 36 holds up to 39.6.
        assert_eq!(outside_image(&pairs, image(36.0, 36.0)), None);
        let w = outside_image(&pairs, image(20.0, 20.0)).unwrap();
        assert!(w.starts_with("9 of the 20 positions lie outside"), "{w}");
        // Each view against its own image: the second view (x 2..38) fits 40 x 40.
        let two = Some(ImageSize::per_view([20.0, 20.0], [40.0, 40.0]).unwrap());
        let w = outside_image(&pairs, two).unwrap();
        assert!(w.starts_with("4 of the 20 positions lie outside"), "{w}");
        // Tracks: every frame in the one image; curves have no image.
        let tracks = PointSet::from_flat(Kind::Trajectories, 4, values.clone()).unwrap();
        assert!(outside_image(&tracks, image(20.0, 20.0)).is_some());
        let curve = PointSet::from_flat(Kind::Points2d, 2, values).unwrap();
        assert_eq!(outside_image(&curve, image(20.0, 20.0)), None);
    }

    #[test]
    fn points_in_a_corner_of_the_image_say_so() {
        let (values, pairs) = forty_values();
        assert_eq!(image_barely_used(&pairs, None), None);
        assert_eq!(image_barely_used(&pairs, image(380.0, 200.0)), None);
        let w = image_barely_used(&pairs, image(4000.0, 3000.0)).unwrap();
        assert!(
            w.starts_with("the points span 38 px of the 4000 px image"),
            "{w}"
        );
        // Two images of two sizes: each view against its own image.
        let two = |second| Some(ImageSize::per_view([300.0, 200.0], second).unwrap());
        assert_eq!(image_barely_used(&pairs, two([320.0, 240.0])), None);
        let w = image_barely_used(&pairs, two([4000.0, 3000.0])).unwrap();
        assert!(
            w.starts_with("the points of image 2 span 36 px of its 4000 px: check"),
            "{w}"
        );
        let big = Some(ImageSize::per_view([4000.0, 3000.0], [5000.0, 3000.0]).unwrap());
        let w = image_barely_used(&pairs, big).unwrap();
        assert!(
            w.starts_with("the points of image 1 span 36 px of its 4000 px; the points of image 2"),
            "{w}"
        );
        // Curves have no image.
        let curve = PointSet::from_flat(Kind::Points2d, 2, values.clone()).unwrap();
        assert_eq!(lost_marks(&curve), None);
        assert_eq!(image_barely_used(&curve, image(4000.0, 3000.0)), None);
    }

    #[test]
    fn an_answer_with_fewer_structures_than_the_k_given_says_so() {
        assert_eq!(fewer_than_asked(3, 3, true), None);
        assert_eq!(fewer_than_asked(3, 4, true), None);
        assert_eq!(fewer_than_asked(3, 3, false), None);
        let unrefined = fewer_than_asked(3, 2, false).unwrap();
        assert!(
            unrefined.starts_with(
                "k = 3 was given and the answer has 2 structures: one of the 3 learned groups is \
                 the outliers'"
            ),
            "{unrefined}"
        );
        let one = fewer_than_asked(3, 2, true).unwrap();
        assert!(
            one.starts_with(
                "k = 3 was given and refinement answers 2 structures: 1 learned group followed"
            ),
            "{one}"
        );
        let two = fewer_than_asked(4, 2, true).unwrap();
        assert!(two.contains("2 learned groups followed no model or lost most of their points"));
        assert!(
            two.ends_with("(\"refine\": false answers the 4 learned groups)"),
            "{two}"
        );
    }

    #[test]
    fn the_outlier_share_is_observed_only_when_the_fit_may_flag_outliers() {
        let values: Vec<f64> = (0..40).map(f64::from).collect();
        let points = PointSet::from_flat(Kind::Correspondences, 4, values).unwrap();
        let labels = [0, 0, 1, 1, 0, 1, 0, 1, 0, 1];
        let range = crate::registry::ValidatedRange {
            outlier_ratio: Some([0.0, 0.25]),
            ..Default::default()
        };
        // A fit that cannot answer -1 (no refinement, or outliers off) says nothing of the share.
        let half = [0, -1, 1, -1, 0, -1, 0, -1, 1, -1];
        let quiet = observed(&points, None, &half, 2, false);
        assert_eq!(quiet.outlier_ratio, None);
        assert!(range.warnings(&quiet).is_empty());
        // One that may is measured: none flagged is within the range, half is above it.
        let clean = observed(&points, None, &labels, 2, true);
        assert_eq!(clean.outlier_ratio, Some(0.0));
        assert!(range.warnings(&clean).is_empty());
        let flagged = observed(&points, None, &half, 2, true);
        assert_eq!(flagged.outlier_ratio, Some(0.5));
        assert_eq!(range.warnings(&flagged).len(), 1);
    }
}
