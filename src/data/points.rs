//! Validated point sets and the normalisation shared by training and serving.

use std::borrow::Cow;

use serde::{Deserialize, Serialize};

/// The fewest points a set may have: k-means and every loss need at least two.
pub const MIN_POINTS: usize = 2;

/// Largest accepted magnitude of a coordinate. Pixel coordinates are far below it; beyond it the
/// sums of normalisation could overflow.
pub const MAX_ABS_COORD: f64 = 1e9;

/// What one row of a point set means.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// A 2D point `[x, y]` (lines, circles, ellipses).
    Points2d,
    /// A two-view correspondence `[x1, y1, x2, y2]` in pixels.
    Correspondences,
    /// A feature track over F frames `[x_1, y_1, ..., x_F, y_F]` in pixels.
    Trajectories,
}

impl Kind {
    /// Parses the wire name (`points2d`, `correspondences`, `trajectories`).
    pub fn parse(name: &str) -> Option<Kind> {
        match name {
            "points2d" => Some(Kind::Points2d),
            "correspondences" => Some(Kind::Correspondences),
            "trajectories" => Some(Kind::Trajectories),
            _ => None,
        }
    }

    /// The wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            Kind::Points2d => "points2d",
            Kind::Correspondences => "correspondences",
            Kind::Trajectories => "trajectories",
        }
    }

    /// Whether `dim` is a valid row width for this kind.
    pub fn accepts_dim(self, dim: usize) -> bool {
        match self {
            Kind::Points2d => dim == 2,
            Kind::Correspondences => dim == 4,
            Kind::Trajectories => dim >= 4 && dim.is_multiple_of(2),
        }
    }

    fn expected_dim(self) -> &'static str {
        match self {
            Kind::Points2d => "2",
            Kind::Correspondences => "4",
            Kind::Trajectories => "an even number >= 4 (2 per frame, at least 2 frames)",
        }
    }
}

impl std::fmt::Display for Kind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Why a raw point set was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    #[error("the point set is empty")]
    Empty,
    #[error("{n} points given; at least {min} are needed")]
    TooFewPoints { n: usize, min: usize },
    #[error("row {row} has {found} values but row 0 has {expected}")]
    Ragged {
        row: usize,
        expected: usize,
        found: usize,
    },
    #[error("rows of kind {kind} must have {expected} values, got {found}")]
    WrongDim {
        kind: Kind,
        expected: &'static str,
        found: usize,
    },
    #[error("value at row {row}, column {col} is not a finite number within +-1e9")]
    NonFinite { row: usize, col: usize },
    #[error(
        "a trajectory matrix needs an even number (>= 4) of rows (x and y per frame), got {rows}"
    )]
    BadTrajectoryMatrix { rows: usize },
    #[error("image_size must be two numbers of pixels between 1 and 1e9, got [{w}, {h}]")]
    BadImageSize { w: f64, h: f64 },
    #[error("visible has {rows} rows for {tracks} tracks: one row of 0/1 flags per track")]
    VisibleRows { rows: usize, tracks: usize },
    #[error("visible row {row} has {found} flags for {frames} frames")]
    VisibleWidth {
        row: usize,
        found: usize,
        frames: usize,
    },
    #[error(
        "only {complete} tracks are seen in every frame; a fit needs at least 2 (the others are \
         placed on the motions those tracks give)"
    )]
    TooFewSeenThroughout { complete: usize },
}

/// Width and height of the image the pixel coordinates refer to: of every view, or (`second`)
/// of the first of a correspondence's two views when the second image has another size.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImageSize {
    pub width: f64,
    pub height: f64,
    /// The second view's `[width, height]`, where it differs from the first's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub second: Option<[f64; 2]>,
}

impl ImageSize {
    pub fn new(width: f64, height: f64) -> Result<Self, InputError> {
        // At least a pixel: dividing pixel coordinates by a tinier size overflows the network.
        let valid = |v: f64| (1.0..=MAX_ABS_COORD).contains(&v);
        if valid(width) && valid(height) {
            Ok(Self {
                width,
                height,
                second: None,
            })
        } else {
            Err(InputError::BadImageSize {
                w: width,
                h: height,
            })
        }
    }

    /// The sizes of a correspondence's two images, each checked as by [`ImageSize::new`]; one
    /// size when they are equal.
    pub fn per_view([w1, h1]: [f64; 2], [w2, h2]: [f64; 2]) -> Result<Self, InputError> {
        let mut first = Self::new(w1, h1)?;
        let second = Self::new(w2, h2)?;
        if (w1, h1) != (w2, h2) {
            first.second = Some([second.width, second.height]);
        }
        Ok(first)
    }

    /// `[width, height]` of view `v` (0 or 1; every view but a distinct second has the first's).
    pub fn view(&self, v: usize) -> [f64; 2] {
        match self.second {
            Some(size) if v == 1 => size,
            _ => [self.width, self.height],
        }
    }

    /// The move x' = s·x + t that carries a distinct second image's pixels into the first
    /// image's frame (centre to centre, longer side to longer side): `(s, t)`; `None` for one
    /// size.
    pub fn second_view_move(&self) -> Option<(f64, [f64; 2])> {
        let [w2, h2] = self.second?;
        let s = self.width.max(self.height) / w2.max(h2);
        Some((
            s,
            [
                self.width / 2.0 - s * w2 / 2.0,
                self.height / 2.0 - s * h2 / 2.0,
            ],
        ))
    }

    /// [`ImageSize::second_view_move`] for `points` that have a second view (correspondences).
    fn move_for(&self, points: &PointSet) -> Option<(f64, [f64; 2])> {
        self.second_view_move()
            .filter(|_| points.kind() == Kind::Correspondences)
    }

    /// `points` with a distinct second view's coordinates carried into the first image's frame
    /// (its centre to the first's centre, its longer side to the first's longer side), and the
    /// first image's size: the one frame the network, its symmetries and its neighbour
    /// features read both views in. Unchanged for one size.
    pub fn in_first_frame(self, points: &PointSet) -> (Cow<'_, PointSet>, ImageSize) {
        let first = Self {
            second: None,
            ..self
        };
        let Some((scale, shift)) = self.move_for(points) else {
            return (Cow::Borrowed(points), first);
        };
        match points.second_view_mapped(|a, v| v * scale + shift[a]) {
            Ok(moved) => (Cow::Owned(moved), first),
            // Out of the accepted range: read as sent.
            Err(_) => (Cow::Borrowed(points), first),
        }
    }

    /// Whether [`ImageSize::in_first_frame`] keeps `points` within the accepted coordinates
    /// (always, for one size), without moving them.
    pub fn moves_in_range(&self, points: &PointSet) -> bool {
        let Some((scale, shift)) = self.move_for(points) else {
            return true;
        };
        (0..points.len()).all(|i| {
            let row = points.row(i);
            (0..2).all(|a| (row[2 + a] * scale + shift[a]).abs() <= MAX_ABS_COORD)
        })
    }
}

/// A validated point set: `n >= MIN_POINTS` rows of `dim` finite values, `dim` valid for `kind`.
#[derive(Debug, Clone, PartialEq)]
pub struct PointSet {
    kind: Kind,
    dim: usize,
    /// Row-major `[n, dim]`.
    values: Vec<f64>,
}

impl PointSet {
    /// Builds a point set from rows (one row per point).
    pub fn from_rows(kind: Kind, rows: &[Vec<f64>]) -> Result<Self, InputError> {
        let first = rows.first().ok_or(InputError::Empty)?;
        let dim = first.len();
        if !kind.accepts_dim(dim) {
            return Err(InputError::WrongDim {
                kind,
                expected: kind.expected_dim(),
                found: dim,
            });
        }
        let mut values = Vec::with_capacity(rows.len() * dim);
        for (row, r) in rows.iter().enumerate() {
            if r.len() != dim {
                return Err(InputError::Ragged {
                    row,
                    expected: dim,
                    found: r.len(),
                });
            }
            values.extend_from_slice(r);
        }
        Self::from_flat(kind, dim, values)
    }

    /// Builds a trajectory set from a `2F x N` matrix: row `2f` holds the x of frame `f` for every
    /// point, row `2f + 1` its y (the layout of Hopkins155 and MATLAB motion-segmentation tools).
    pub fn from_trajectory_matrix(matrix: &[Vec<f64>]) -> Result<Self, InputError> {
        let first = matrix.first().ok_or(InputError::Empty)?;
        let rows = matrix.len();
        if rows < 4 || !rows.is_multiple_of(2) {
            return Err(InputError::BadTrajectoryMatrix { rows });
        }
        let n = first.len();
        if n == 0 {
            return Err(InputError::Empty);
        }
        for (row, r) in matrix.iter().enumerate() {
            if r.len() != n {
                return Err(InputError::Ragged {
                    row,
                    expected: n,
                    found: r.len(),
                });
            }
        }
        let values = (0..n)
            .flat_map(|i| matrix.iter().map(move |r| r[i]))
            .collect();
        Self::from_flat(Kind::Trajectories, rows, values)
    }

    /// Builds a point set from row-major values `[n, dim]`.
    pub fn from_flat(kind: Kind, dim: usize, values: Vec<f64>) -> Result<Self, InputError> {
        if !kind.accepts_dim(dim) {
            return Err(InputError::WrongDim {
                kind,
                expected: kind.expected_dim(),
                found: dim,
            });
        }
        if values.is_empty() {
            return Err(InputError::Empty);
        }
        if let Some(at) = values
            .iter()
            .position(|v| !(v.is_finite() && v.abs() <= MAX_ABS_COORD))
        {
            return Err(InputError::NonFinite {
                row: at / dim,
                col: at % dim,
            });
        }
        let n = values.len() / dim;
        if n < MIN_POINTS {
            return Err(InputError::TooFewPoints { n, min: MIN_POINTS });
        }
        Ok(Self { kind, dim, values })
    }

    pub fn kind(&self) -> Kind {
        self.kind
    }
    pub fn dim(&self) -> usize {
        self.dim
    }
    pub fn len(&self) -> usize {
        self.values.len() / self.dim
    }
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }
    /// Row-major values `[n, dim]`.
    pub fn values(&self) -> &[f64] {
        &self.values
    }
    /// The longer side of the bounding box of every (x, y) pair (over every view or frame):
    /// what [`Normalization::ImageFrame`] scales by when no image size is given.
    pub fn extent(&self) -> f64 {
        2.0 * bounding_frame(self.values.chunks_exact(2)).2
    }
    /// [`PointSet::extent`] of view `v` alone: the (x, y) pairs in columns 2v and 2v + 1.
    pub fn view_extent(&self, v: usize) -> f64 {
        let pairs = self
            .values
            .chunks_exact(self.dim)
            .map(|r| &r[2 * v..2 * v + 2]);
        2.0 * bounding_frame(pairs).2
    }
    /// The set with the second view of each correspondence (columns x2, y2) mapped by
    /// `map(axis, value)`, axis 0 for x and 1 for y (other kinds have no second view: as they
    /// are); `Err` where a mapped value leaves the accepted range.
    pub fn second_view_mapped(&self, map: impl Fn(usize, f64) -> f64) -> Result<Self, InputError> {
        let mut values = self.values.clone();
        if self.kind == Kind::Correspondences {
            for row in values.chunks_exact_mut(self.dim) {
                for (a, v) in row[2..4].iter_mut().enumerate() {
                    *v = map(a, *v);
                }
            }
        }
        Self::from_flat(self.kind, self.dim, values)
    }
    pub fn row(&self, i: usize) -> &[f64] {
        &self.values[i * self.dim..(i + 1) * self.dim]
    }

    /// Keeps the rows at `indices`, in that order.
    pub fn select(&self, indices: &[usize]) -> Result<Self, InputError> {
        let values = indices
            .iter()
            .flat_map(|&i| self.row(i).iter().copied())
            .collect();
        Self::from_flat(self.kind, self.dim, values)
    }
}

/// How pixel or world coordinates are mapped into the frame the network was trained on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Normalization {
    /// Translate to zero mean, scale isotropically to unit RMS distance from the mean.
    /// Used for `points2d`; labels are then invariant to shifting and scaling the input.
    CentroidUnitRms,
    /// Every (x, y) pair: `(p - image centre) / (max(w, h) / 2)` when the image size is given;
    /// otherwise the same with the bounding box of all pairs (over every view or frame) standing in
    /// for the image. Used for correspondences and trajectories.
    ImageFrame,
}

impl Normalization {
    /// The normalisation a kind is trained and served with.
    pub fn for_kind(kind: Kind) -> Self {
        match kind {
            Kind::Points2d => Normalization::CentroidUnitRms,
            Kind::Correspondences | Kind::Trajectories => Normalization::ImageFrame,
        }
    }

    /// Normalised values, row-major `[n, dim]`, as f32 for the network.
    pub fn apply(self, points: &PointSet, image: Option<ImageSize>) -> Vec<f32> {
        let (cx, cy, scale) = match self {
            Normalization::CentroidUnitRms => centroid_rms(points.values()),
            Normalization::ImageFrame => match image {
                Some(s) => (s.width / 2.0, s.height / 2.0, s.width.max(s.height) / 2.0),
                None => bounding_frame(points.values().chunks_exact(2)),
            },
        };
        // A set of (nearly) coincident points has no scale: a zero or subnormal spread, whose
        // inverse would overflow, leaves the values unscaled.
        let inv = if scale >= f64::MIN_POSITIVE {
            1.0 / scale
        } else {
            1.0
        };
        points
            .values()
            .chunks_exact(2)
            .flat_map(|p| [((p[0] - cx) * inv) as f32, ((p[1] - cy) * inv) as f32])
            .collect()
    }
}

/// Mean of all (x, y) pairs and their RMS distance to it.
fn centroid_rms(values: &[f64]) -> (f64, f64, f64) {
    let pairs = (values.len() / 2) as f64;
    let (sx, sy) = values
        .chunks_exact(2)
        .fold((0.0, 0.0), |(a, b), p| (a + p[0], b + p[1]));
    let (cx, cy) = (sx / pairs, sy / pairs);
    let ss: f64 = values
        .chunks_exact(2)
        .map(|p| (p[0] - cx).powi(2) + (p[1] - cy).powi(2))
        .sum();
    (cx, cy, (ss / pairs).sqrt())
}

/// Centre and half the longer side of the bounding box of all (x, y) pairs.
fn bounding_frame<'a>(pairs: impl Iterator<Item = &'a [f64]>) -> (f64, f64, f64) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in pairs {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let half = (hi[0] - lo[0]).max(hi[1] - lo[1]) / 2.0;
    ((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, half)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(v: &[[f64; 2]]) -> Vec<Vec<f64>> {
        v.iter().map(|r| r.to_vec()).collect()
    }

    #[test]
    fn rejects_bad_sets() {
        assert_eq!(
            PointSet::from_rows(Kind::Points2d, &[]),
            Err(InputError::Empty)
        );
        assert!(matches!(
            PointSet::from_rows(Kind::Points2d, &[vec![1.0, 2.0]]),
            Err(InputError::TooFewPoints { n: 1, min: 2 })
        ));
        assert!(matches!(
            PointSet::from_rows(Kind::Points2d, &[vec![1.0, 2.0], vec![1.0]]),
            Err(InputError::Ragged {
                row: 1,
                expected: 2,
                found: 1
            })
        ));
        assert!(matches!(
            PointSet::from_rows(Kind::Correspondences, &rows(&[[1.0, 2.0], [3.0, 4.0]])),
            Err(InputError::WrongDim { found: 2, .. })
        ));
        assert!(matches!(
            PointSet::from_rows(Kind::Trajectories, &[vec![0.0; 5], vec![0.0; 5]]),
            Err(InputError::WrongDim { found: 5, .. })
        ));
        assert!(matches!(
            PointSet::from_rows(Kind::Points2d, &rows(&[[1.0, 2.0], [f64::NAN, 4.0]])),
            Err(InputError::NonFinite { row: 1, col: 0 })
        ));
        assert!(matches!(
            PointSet::from_rows(Kind::Points2d, &rows(&[[1.0, 1e308], [3.0, 4.0]])),
            Err(InputError::NonFinite { row: 0, col: 1 })
        ));
        assert!(ImageSize::new(0.0, 10.0).is_err());
        assert!(ImageSize::new(f64::INFINITY, 10.0).is_err());
    }

    #[test]
    fn trajectory_matrix_is_transposed_into_rows() {
        // Two points over two frames: x1 row, y1 row, x2 row, y2 row.
        let m = vec![
            vec![1.0, 10.0],
            vec![2.0, 20.0],
            vec![3.0, 30.0],
            vec![4.0, 40.0],
        ];
        let set = PointSet::from_trajectory_matrix(&m).unwrap();
        assert_eq!(set.dim(), 4);
        assert_eq!(set.row(0), &[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(set.row(1), &[10.0, 20.0, 30.0, 40.0]);
        assert!(matches!(
            PointSet::from_trajectory_matrix(&m[..3]),
            Err(InputError::BadTrajectoryMatrix { rows: 3 })
        ));
    }

    #[test]
    fn unit_rms_normalisation_by_hand() {
        // Square of side 2 around (1, 1): centroid (1, 1), every point at distance sqrt(2).
        let set = PointSet::from_rows(
            Kind::Points2d,
            &rows(&[[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]),
        )
        .unwrap();
        let z = Normalization::CentroidUnitRms.apply(&set, None);
        let s = 1.0 / 2f32.sqrt();
        let want = [-s, -s, s, -s, s, s, -s, s];
        for (a, b) in z.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{z:?}");
        }
    }

    #[test]
    fn subnormal_spread_gives_finite_values() {
        // A bounding box of half-side 5e-324: 1 / scale must stay finite.
        let rows = vec![
            vec![0.0, 0.0, 0.0, 0.0],
            vec![1e-323, 0.0, 0.0, 0.0],
            vec![0.0; 4],
        ];
        let set = PointSet::from_rows(Kind::Correspondences, &rows).unwrap();
        for norm in [Normalization::ImageFrame, Normalization::CentroidUnitRms] {
            let z = norm.apply(&set, None);
            assert!(z.iter().all(|v| v.is_finite()), "{norm:?}: {z:?}");
        }
    }

    #[test]
    fn unit_rms_is_invariant_to_shift_and_scale() {
        let base = rows(&[[0.3, 1.0], [2.0, -0.5], [4.0, 7.0], [-1.0, 2.5]]);
        let moved: Vec<Vec<f64>> = base
            .iter()
            .map(|r| vec![r[0] * 37.5 + 400.0, r[1] * 37.5 - 120.0])
            .collect();
        let a = Normalization::CentroidUnitRms
            .apply(&PointSet::from_rows(Kind::Points2d, &base).unwrap(), None);
        let b = Normalization::CentroidUnitRms
            .apply(&PointSet::from_rows(Kind::Points2d, &moved).unwrap(), None);
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-5);
        }
    }

    #[test]
    fn image_frame_normalisation_by_hand() {
        let set = PointSet::from_rows(
            Kind::Correspondences,
            &[vec![0.0, 0.0, 640.0, 480.0], vec![320.0, 240.0, 320.0, 0.0]],
        )
        .unwrap();
        let z = Normalization::ImageFrame.apply(&set, Some(ImageSize::new(640.0, 480.0).unwrap()));
        assert_eq!(z, vec![-1.0, -0.75, 1.0, 0.75, 0.0, 0.0, 0.0, -0.75]);
        // Without the image size the bounding box (0..640, 0..480) stands in for it.
        let w = Normalization::ImageFrame.apply(&set, None);
        assert_eq!(w, z);
    }

    #[test]
    fn a_second_image_of_another_size_is_read_in_the_first_images_frame() {
        let rows = [vec![0.0, 0.0, 640.0, 480.0], vec![320.0, 240.0, 100.0, 7.0]];
        let set = PointSet::from_rows(Kind::Correspondences, &rows).unwrap();
        let one = ImageSize::new(640.0, 480.0).unwrap();
        // The second photo at twice the resolution: its pixels halved about the centres.
        let doubled: Vec<Vec<f64>> = rows
            .iter()
            .map(|r| vec![r[0], r[1], 2.0 * r[2], 2.0 * r[3]])
            .collect();
        let big = PointSet::from_rows(Kind::Correspondences, &doubled).unwrap();
        let two = ImageSize::per_view([640.0, 480.0], [1280.0, 960.0]).unwrap();
        assert_eq!(two.view(1), [1280.0, 960.0]);
        let (moved, first) = two.in_first_frame(&big);
        assert_eq!(first, one);
        assert_eq!(moved.values(), set.values());
        // The same normalised input as the pair taken in one camera.
        assert_eq!(
            Normalization::ImageFrame.apply(&moved, Some(first)),
            Normalization::ImageFrame.apply(&set, Some(one))
        );
        // A portrait second image: centre to centre, longer side to longer side.
        let tall = ImageSize::per_view([640.0, 480.0], [480.0, 640.0]).unwrap();
        let (moved, _) = tall.in_first_frame(&set);
        assert_eq!(
            moved.row(1),
            &[320.0, 240.0, 100.0 - 240.0 + 320.0, 7.0 - 320.0 + 240.0]
        );
        // Equal sizes are one size, and one size moves nothing.
        assert_eq!(
            ImageSize::per_view([640.0, 480.0], [640.0, 480.0]).unwrap(),
            one
        );
        let (same, _) = one.in_first_frame(&set);
        assert!(matches!(same, Cow::Borrowed(_)));
        // Each view's size is checked.
        assert!(ImageSize::per_view([640.0, 480.0], [0.0, 480.0]).is_err());
        assert!(ImageSize::per_view([640.0, f64::NAN], [640.0, 480.0]).is_err());
        // Tracks come from one camera: a second size moves no frame.
        let tracks = PointSet::from_rows(Kind::Trajectories, &doubled).unwrap();
        let (kept, _) = two.in_first_frame(&tracks);
        assert_eq!(kept.values(), tracks.values());
    }
}
