//! Symmetries of an input that map every structure to a structure of the same type, used to
//! multiply labelled training sets and, at test time, to embed an input several ways.
//!
//! - Mirroring the image: a line, circle or ellipse mirrored is one again; a rigid scene seen by a
//!   camera, both mirrored, is again a rigid scene seen by a camera, so a homography stays a
//!   homography and a rigid motion a rigid motion.
//! - Reversing the views: a feature track played backwards is the track of the same point under
//!   the reversed camera and object motions; the two images of a correspondence swapped are
//!   related by the inverse homography or the transposed fundamental matrix.
//! - A quarter turn of the plane: lines, circles and ellipses turn into lines, circles and
//!   ellipses. Geometrically valid for every kind, but real camera data is not isotropic (the
//!   sky is up), so it is meant for points2d.
//!
//! Labels are untouched: the i-th point of the image is the i-th point of the original.

use serde::{Deserialize, Serialize};

use super::dataset::Sample;
use super::points::{ImageSize, Kind, PointSet};

/// One structure-preserving transformation of a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Symmetry {
    /// `x -> 2 c_x - x` in every view, about the vertical line through the centre `c` of the
    /// image (of the bounding box of all points when the image size is unknown).
    Mirror,
    /// The views in reverse order: time reversal of trajectories, the two images of
    /// correspondences swapped. Points2d have one view and no such image.
    Reverse,
    /// A quarter turn about the centre `c`: `(x, y) -> (c_x - (y - c_y), c_y + (x - c_x))`.
    /// Applied up to three times, it gives the turns by 90, 180 and 270 degrees.
    Rotate,
}

impl Symmetry {
    /// The image of a point set, `[n, d] -> [n, d]` with the same row order, or `None` when the
    /// symmetry does not apply to its kind. `image` places the centre.
    pub fn apply_points(self, points: &PointSet, image: Option<ImageSize>) -> Option<PointSet> {
        if !self.applies_to(points.kind()) {
            return None;
        }
        let dim = points.dim();
        let (cx, cy) = centre(points, image);
        let pairs = points.values().chunks_exact(2);
        let values: Vec<f64> = match self {
            Symmetry::Mirror => pairs.flat_map(|p| [2.0 * cx - p[0], p[1]]).collect(),
            Symmetry::Rotate => pairs
                .flat_map(|p| [cx - (p[1] - cy), cy + (p[0] - cx)])
                .collect(),
            Symmetry::Reverse => points
                .values()
                .chunks_exact(dim)
                .flat_map(|row| row.chunks_exact(2).rev().flatten().copied())
                .collect(),
        };
        PointSet::from_flat(points.kind(), dim, values).ok()
    }

    /// The image of a labelled sample (labels unchanged), or `None` as for
    /// [`Symmetry::apply_points`].
    pub fn apply(self, sample: &Sample) -> Option<Sample> {
        Some(Sample {
            name: format!("{}~{}", sample.name, self.tag()),
            points: self.apply_points(&sample.points, sample.image_size)?,
            ..sample.clone()
        })
    }

    /// Whether the symmetry has an image for inputs of `kind`.
    pub fn applies_to(self, kind: Kind) -> bool {
        !(self == Symmetry::Reverse && kind == Kind::Points2d)
    }

    /// How many times it applies before it gives the input back (2, or 4 for the quarter turn).
    pub fn order(self) -> usize {
        match self {
            Symmetry::Mirror | Symmetry::Reverse => 2,
            Symmetry::Rotate => 4,
        }
    }

    fn tag(self) -> &'static str {
        match self {
            Symmetry::Mirror => "mirror",
            Symmetry::Reverse => "reverse",
            Symmetry::Rotate => "rotate",
        }
    }
}

/// The centre of the image, else of the bounding box of all (x, y) pairs.
fn centre(points: &PointSet, image: Option<ImageSize>) -> (f64, f64) {
    if let Some(size) = image {
        return (size.width / 2.0, size.height / 2.0);
    }
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in points.values().chunks_exact(2) {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    ((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0)
}

/// `items` followed by their images under every combination of powers of `symmetries`, each
/// symmetry taken in the order given (duplicates ignored) and applied 0 to `order - 1` times:
/// `prod order` copies of each item at most (4 for mirror and reverse, 8 for mirror and
/// rotate). `image_of` gives `None` where a symmetry does not apply, and that factor is
/// skipped, so no item is repeated.
pub fn closure<T>(
    items: Vec<T>,
    symmetries: &[Symmetry],
    image_of: impl Fn(Symmetry, &T) -> Option<T>,
) -> Vec<T> {
    let mut distinct: Vec<Symmetry> = Vec::new();
    for &s in symmetries {
        if !distinct.contains(&s) {
            distinct.push(s);
        }
    }
    let mut out = items;
    for s in distinct {
        let mut images = Vec::new();
        for x in &out {
            let mut power = image_of(s, x);
            for _ in 1..s.order() {
                let Some(p) = power else { break };
                power = image_of(s, &p);
                images.push(p);
            }
        }
        out.extend(images);
    }
    out
}

/// Why a list of symmetries cannot be used for inputs of a kind ([`check`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SymmetryError {
    /// `symmetry`, one of `list`, is repeated or has no image for inputs of `kind`.
    #[error("symmetries {list:?}: {symmetry:?} is repeated or does not apply to {kind}")]
    Unusable {
        list: Vec<Symmetry>,
        symmetry: Symmetry,
        kind: Kind,
    },
}

/// Checks a list of symmetries for inputs of `kind`: each applies to it and none is repeated.
pub fn check(symmetries: &[Symmetry], kind: Kind) -> Result<(), SymmetryError> {
    for (i, s) in symmetries.iter().enumerate() {
        if !s.applies_to(kind) || symmetries[..i].contains(s) {
            return Err(SymmetryError::Unusable {
                list: symmetries.to_vec(),
                symmetry: *s,
                kind,
            });
        }
    }
    Ok(())
}

/// `samples` followed by their images under every combination of `symmetries` ([`closure`]).
pub fn with_symmetries(samples: Vec<Sample>, symmetries: &[Symmetry]) -> Vec<Sample> {
    closure(samples, symmetries, |s, x| s.apply(x))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(kind: Kind, dim: usize, values: Vec<f64>, image: Option<ImageSize>) -> Sample {
        let n = values.len() / dim;
        Sample {
            name: "s".into(),
            points: PointSet::from_flat(kind, dim, values).unwrap(),
            labels: (0..n).map(|i| i % 2).collect(),
            k: 2,
            image_size: image,
            outliers: false,
        }
    }

    #[test]
    fn mirror_reflects_about_the_image_centre_and_keeps_labels() {
        let image = Some(ImageSize::new(100.0, 40.0).unwrap());
        let s = sample(
            Kind::Correspondences,
            4,
            vec![10.0, 1.0, 30.0, 2.0, 50.0, 3.0, 99.0, 4.0],
            image,
        );
        let m = Symmetry::Mirror.apply(&s).unwrap();
        assert_eq!(
            m.points.values(),
            &[90.0, 1.0, 70.0, 2.0, 50.0, 3.0, 1.0, 4.0]
        );
        assert_eq!(m.labels, s.labels);
        assert_eq!(m.k, 2);
        assert_eq!(m.name, "s~mirror");
        // Twice is the identity.
        assert_eq!(Symmetry::Mirror.apply(&m).unwrap().points, s.points);
    }

    #[test]
    fn mirror_without_image_uses_the_x_range() {
        let s = sample(Kind::Points2d, 2, vec![1.0, 5.0, 3.0, 6.0, 2.0, 7.0], None);
        let m = Symmetry::Mirror.apply(&s).unwrap();
        assert_eq!(m.points.values(), &[3.0, 5.0, 1.0, 6.0, 2.0, 7.0]);
    }

    #[test]
    fn reverse_plays_tracks_backwards_and_swaps_views() {
        let t = sample(
            Kind::Trajectories,
            6,
            vec![
                1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0,
            ],
            None,
        );
        let r = Symmetry::Reverse.apply(&t).unwrap();
        assert_eq!(
            r.points.values(),
            &[
                5.0, 6.0, 3.0, 4.0, 1.0, 2.0, 11.0, 12.0, 9.0, 10.0, 7.0, 8.0
            ]
        );
        assert_eq!(Symmetry::Reverse.apply(&r).unwrap().points, t.points);
        let c = sample(
            Kind::Correspondences,
            4,
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0],
            None,
        );
        let r = Symmetry::Reverse.apply(&c).unwrap();
        assert_eq!(r.points.values(), &[3.0, 4.0, 1.0, 2.0, 7.0, 8.0, 5.0, 6.0]);
        let p = sample(Kind::Points2d, 2, vec![1.0, 2.0, 3.0, 4.0], None);
        assert!(Symmetry::Reverse.apply(&p).is_none());
    }

    #[test]
    fn with_symmetries_adds_every_combination_once() {
        let t = sample(
            Kind::Trajectories,
            4,
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0],
            None,
        );
        let all = with_symmetries(
            vec![t.clone()],
            &[Symmetry::Mirror, Symmetry::Reverse, Symmetry::Mirror],
        );
        let names: Vec<&str> = all.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["s", "s~mirror", "s~reverse", "s~mirror~reverse"]);
        assert!(all.iter().all(|s| s.labels == t.labels));
        // Mirror and reverse commute: the two orders give the same set.
        let other = with_symmetries(vec![t], &[Symmetry::Reverse, Symmetry::Mirror]);
        assert_eq!(other[3].points, all[3].points);
        // Points2d: reversal does not apply, so no duplicate.
        let p = sample(Kind::Points2d, 2, vec![1.0, 2.0, 3.0, 4.0], None);
        assert_eq!(
            with_symmetries(vec![p], &[Symmetry::Mirror, Symmetry::Reverse]).len(),
            2
        );
        assert!(with_symmetries(vec![], &[Symmetry::Mirror]).is_empty());
    }

    #[test]
    fn rotate_turns_about_the_centre_and_has_order_four() {
        let s = sample(Kind::Points2d, 2, vec![0.0, 0.0, 2.0, 0.0, 2.0, 4.0], None);
        // Centre of the bounding box: (1, 2).
        let r = Symmetry::Rotate.apply(&s).unwrap();
        assert_eq!(r.points.values(), &[3.0, 1.0, 3.0, 3.0, -1.0, 3.0]);
        let four = (0..4).fold(s.clone(), |x, _| Symmetry::Rotate.apply(&x).unwrap());
        assert_eq!(four.points, s.points);
        // Mirror and rotate: the 8 elements of the dihedral group, all different.
        let all = with_symmetries(vec![s], &[Symmetry::Mirror, Symmetry::Rotate]);
        assert_eq!(all.len(), 8);
        for i in 0..8 {
            for j in 0..i {
                assert_ne!(
                    all[i].points, all[j].points,
                    "{} = {}",
                    all[i].name, all[j].name
                );
            }
        }
    }

    #[test]
    fn check_refuses_repeats_and_symmetries_of_other_kinds() {
        assert!(check(&[Symmetry::Mirror, Symmetry::Reverse], Kind::Trajectories).is_ok());
        assert!(check(&[], Kind::Points2d).is_ok());
        let repeated = check(&[Symmetry::Mirror, Symmetry::Mirror], Kind::Correspondences);
        assert!(
            repeated
                .unwrap_err()
                .to_string()
                .contains("Mirror is repeated")
        );
        let reverse = check(&[Symmetry::Reverse], Kind::Points2d)
            .unwrap_err()
            .to_string();
        assert!(reverse.contains("does not apply to points2d"), "{reverse}");
    }
}
