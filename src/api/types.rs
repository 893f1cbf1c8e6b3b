//! Wire types of the API and their parsing into validated domain values.

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::error::{ApiError, ErrorCode};
use crate::cluster::{ClusterParams, Clustering, Selection};
use crate::data::{ImageSize, InputError, Kind, PointSet, Visibility};
use crate::geometry::Model;
use crate::pipeline::FitOutcome;
use crate::refine::RefineParams;
use crate::registry::LoadedModel;

/// Request limits, from the server config.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Limits {
    pub max_points: usize,
    pub max_frames: usize,
    pub max_k_max: usize,
    pub max_batch: usize,
}

/// `POST /v1/fit` body as sent.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitRequest {
    pub kind: String,
    #[serde(default)]
    pub points: Option<Vec<Vec<Coord>>>,
    #[serde(default)]
    pub trajectory_matrix: Option<Vec<Vec<Coord>>>,
    #[serde(default)]
    pub model: Option<String>,
    /// `[width, height]`, or `[[width, height], [width, height]]` for a correspondence's two
    /// images; its shape is checked with the other fields, with a clear message.
    #[serde(default)]
    pub image_size: Option<serde_json::Value>,
    #[serde(default, deserialize_with = "whole")]
    pub k: Option<usize>,
    #[serde(default, deserialize_with = "whole")]
    pub k_max: Option<usize>,
    #[serde(default)]
    pub selection: Option<String>,
    #[serde(default, deserialize_with = "whole")]
    pub seed: Option<u64>,
    #[serde(default)]
    pub return_embeddings: Option<bool>,
    /// False: embed the input alone, skipping the model's test-time symmetries.
    #[serde(default)]
    pub test_symmetries: Option<bool>,
    /// Geometric refinement and structures; default: the model card's.
    #[serde(default)]
    pub refine: Option<bool>,
    /// Whether refinement may label points -1 (outliers); default true.
    #[serde(default)]
    pub outliers: Option<bool>,
    /// A fixed outlier threshold in the caller's units instead of the estimated one.
    #[serde(default)]
    pub outlier_threshold: Option<f64>,
    /// Trajectories: N x F flags, 1 (or true) where track i was seen in frame f, 0 (or false)
    /// where it was not (its values there are ignored).
    #[serde(default)]
    pub visible: Option<Vec<Vec<Seen>>>,
}

/// A count or a seed as sent: a whole number, written `4` or `4.0` (clients that hold every
/// number as a float send the latter), or null for the default. A fraction, a negative number
/// or one past the type's range is refused with its value.
fn whole<'de, D, T>(deserializer: D) -> Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: TryFrom<u64>,
{
    struct Whole<T>(std::marker::PhantomData<T>);
    impl<T: TryFrom<u64>> serde::de::Visitor<'_> for Whole<T> {
        type Value = Option<T>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a whole number >= 0")
        }
        fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Option<T>, E> {
            T::try_from(v).map(Some).map_err(|_| {
                E::custom(format!("{v} is too large: a whole number is expected here"))
            })
        }
        fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Option<T>, E> {
            match u64::try_from(v) {
                Ok(v) => self.visit_u64(v),
                Err(_) => Err(E::custom(format!(
                    "{v} is negative: a whole number is expected here"
                ))),
            }
        }
        fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Option<T>, E> {
            // Past 2^53 a float no longer holds every whole number: refused rather than rounded.
            if v < 0.0 {
                Err(E::custom(format!(
                    "{v} is negative: a whole number is expected here"
                )))
            } else if v.fract() == 0.0 && v < 9_007_199_254_740_992.0 {
                self.visit_u64(v as u64)
            } else {
                Err(E::custom(format!(
                    "{v} has a fraction or is too large: a whole number is expected here"
                )))
            }
        }
        fn visit_unit<E: serde::de::Error>(self) -> Result<Option<T>, E> {
            Ok(None)
        }
        fn visit_none<E: serde::de::Error>(self) -> Result<Option<T>, E> {
            Ok(None)
        }
    }
    deserializer.deserialize_any(Whole(std::marker::PhantomData))
}

/// One coordinate as sent: a number, or null (NaN here) for a track's position in a frame
/// `visible` marks unseen ([`fill_unseen`] checks and replaces it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coord(pub f64);

impl<'de> Deserialize<'de> for Coord {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Value;
        impl serde::de::Visitor<'_> for Value {
            type Value = Coord;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a number, or null for a track position not seen")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Coord, E> {
                Ok(Coord(v))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Coord, E> {
                Ok(Coord(v as f64))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Coord, E> {
                Ok(Coord(v as f64))
            }
            fn visit_unit<E: serde::de::Error>(self) -> Result<Coord, E> {
                Ok(Coord(f64::NAN))
            }
            fn visit_none<E: serde::de::Error>(self) -> Result<Coord, E> {
                Ok(Coord(f64::NAN))
            }
        }
        deserializer.deserialize_any(Value)
    }
}

/// Where a coordinate sits: `points` rows (a row per track) or `trajectory_matrix` rows (a row
/// per frame coordinate, a column per track).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Layout {
    Rows,
    Matrix,
}

/// `rows` as numbers, a null (NaN) replaced by 0 where `visible` marks the track unseen in that
/// frame (its value is ignored there). A null anywhere else is refused with its place.
fn fill_unseen(
    rows: Vec<Vec<Coord>>,
    visible: Option<&[Vec<Seen>]>,
    layout: Layout,
    kind: Kind,
) -> Result<Vec<Vec<f64>>, ApiError> {
    let field = match layout {
        Layout::Rows => "points",
        Layout::Matrix => "trajectory_matrix",
    };
    // The mask's shape first: a mask of the wrong shape would otherwise be reported as the
    // nulls it fails to mark.
    if let (Some(flags), Kind::Trajectories) = (visible, kind) {
        let (tracks, frames) = match layout {
            Layout::Rows => (rows.len(), rows.first().map_or(0, |r| r.len() / 2)),
            Layout::Matrix => (rows.first().map_or(0, Vec::len), rows.len() / 2),
        };
        if flags.len() != tracks {
            return Err(InputError::VisibleRows {
                rows: flags.len(),
                tracks,
            }
            .into());
        }
        if let Some((row, f)) = flags.iter().enumerate().find(|(_, f)| f.len() != frames) {
            return Err(InputError::VisibleWidth {
                row,
                found: f.len(),
                frames,
            }
            .into());
        }
    }
    rows.into_iter()
        .enumerate()
        .map(|(r, row)| {
            row.into_iter()
                .enumerate()
                .map(|(c, v)| {
                    if !v.0.is_nan() {
                        return Ok(v.0);
                    }
                    let (track, frame) = match layout {
                        Layout::Rows => (r, c / 2),
                        Layout::Matrix => (c, r / 2),
                    };
                    let unseen = visible
                        .and_then(|v| v.get(track))
                        .and_then(|t| t.get(frame))
                        .is_some_and(|f| !f.0);
                    if unseen && kind == Kind::Trajectories {
                        return Ok(0.0);
                    }
                    let message = if kind != Kind::Trajectories {
                        format!("{field}[{r}][{c}] is null: coordinates are numbers")
                    } else if visible.is_none() {
                        format!(
                            "{field}[{r}][{c}] is null: a track position not seen is null only \
                             with visible, one row of 0/1 flags per track and one flag per \
                             frame, 0 where the track was not seen (here track {track}, frame \
                             {frame})"
                        )
                    } else {
                        format!(
                            "{field}[{r}][{c}] is null, but visible has 1 for track {track}, \
                             frame {frame}: null only marks a position visible marks 0"
                        )
                    };
                    Err(ApiError::new(ErrorCode::InvalidRequest, message))
                })
                .collect()
        })
        .collect()
}

/// One flag of `visible`: 0 or 1 as any JSON number (`1`, `1.0`), or false or true, as a numpy
/// mask's `tolist()` gives it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Seen(pub bool);

impl<'de> Deserialize<'de> for Seen {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Flag;
        impl serde::de::Visitor<'_> for Flag {
            type Value = Seen;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("0 or 1, or false or true")
            }
            fn visit_bool<E: serde::de::Error>(self, v: bool) -> Result<Seen, E> {
                Ok(Seen(v))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Seen, E> {
                self.visit_i64(i64::try_from(v).unwrap_or(i64::MAX))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Seen, E> {
                match v {
                    0 | 1 => Ok(Seen(v == 1)),
                    _ => Err(E::invalid_value(serde::de::Unexpected::Signed(v), &self)),
                }
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Seen, E> {
                if v == 0.0 || v == 1.0 {
                    Ok(Seen(v == 1.0))
                } else {
                    Err(E::invalid_value(serde::de::Unexpected::Float(v), &self))
                }
            }
        }
        deserializer.deserialize_any(Flag)
    }
}

/// `POST /v1/fit/batch` body as sent; entries are parsed one by one so that a bad entry gets
/// its own error.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BatchRequest {
    pub requests: Vec<serde_json::Value>,
}

/// A validated fit: the core never sees an unchecked value.
#[derive(Debug, Clone)]
pub struct FitJob {
    pub model: Arc<LoadedModel>,
    pub points: PointSet,
    pub image_size: Option<ImageSize>,
    pub params: ClusterParams,
    pub return_embeddings: bool,
    /// Whether the fit uses the card's test-time symmetries.
    pub test_symmetries: bool,
    /// Geometric refinement, or `None` for the learned clustering alone.
    pub refine: Option<RefineParams>,
    /// Without refinement, whether the network's outlier group may be answered -1 (with k
    /// given or chosen; see [`crate::pipeline::FitOptions::outlier_group`]).
    pub outlier_group: bool,
    /// Whether tracks set apart as erratic are answered -1 (unless the request says
    /// `outliers: false`; see [`crate::pipeline::FitOptions::erratic_outliers`]).
    pub erratic_outliers: bool,
    /// Which frames each track was seen in, when the request said (trajectories).
    pub visibility: Option<Visibility>,
}

/// The shipped model used for a kind when the request names none: the one whose card says it
/// is the kind's default, else the first (by name) of that kind.
pub fn default_model(
    models: &BTreeMap<String, Arc<LoadedModel>>,
    kind: Kind,
) -> Option<&Arc<LoadedModel>> {
    let mut of_kind = models.values().filter(|m| m.card.kind == kind);
    of_kind
        .clone()
        .find(|m| m.card.default)
        .or_else(|| of_kind.next())
}

/// `image_size` as sent: `[width, height]`, or for correspondences one such pair per image.
fn image_size(value: &serde_json::Value, kind: Kind) -> Result<ImageSize, ApiError> {
    let pair = |v: &serde_json::Value| -> Option<[f64; 2]> {
        match v.as_array()?.as_slice() {
            [w, h] => Some([w.as_f64()?, h.as_f64()?]),
            _ => None,
        }
    };
    let shape = |found: String| {
        ApiError::new(
            ErrorCode::InvalidRequest,
            format!(
                "image_size must be [width, height] in pixels, or for correspondences \
                 [[width, height], [width, height]], one per image; got {found}"
            ),
        )
    };
    if let Some([w, h]) = pair(value) {
        return Ok(ImageSize::new(w, h)?);
    }
    match value.as_array().map(Vec::as_slice) {
        Some([a, b]) if a.is_array() || b.is_array() => match (pair(a), pair(b)) {
            (Some(first), Some(second)) if kind == Kind::Correspondences => {
                Ok(ImageSize::per_view(first, second)?)
            }
            (Some(_), Some(_)) => Err(ApiError::new(
                ErrorCode::InvalidRequest,
                format!(
                    "image_size has one [width, height] per image only for correspondences; \
                     {kind} come from one image: give [width, height]"
                ),
            )),
            _ => Err(shape("a pair that is not two [width, height] pairs".into())),
        },
        Some(items) if items.iter().all(serde_json::Value::is_number) => {
            Err(shape(format!("{} numbers", items.len())))
        }
        _ => {
            let text = value.to_string();
            Err(shape(text.chars().take(60).collect()))
        }
    }
}

impl FitRequest {
    /// Checks every field against the limits and the chosen model.
    pub fn validate(
        self,
        models: &BTreeMap<String, Arc<LoadedModel>>,
        limits: &Limits,
    ) -> Result<FitJob, ApiError> {
        let kind = Kind::parse(&self.kind).ok_or_else(|| {
            ApiError::new(
                ErrorCode::UnknownKind,
                format!(
                    "kind {:?} is not one of points2d, correspondences, trajectories",
                    self.kind
                ),
            )
        })?;
        let points = match (self.points, self.trajectory_matrix) {
            (Some(_), Some(_)) => {
                return Err(ApiError::new(
                    ErrorCode::InvalidRequest,
                    "give either points or trajectory_matrix, not both",
                ));
            }
            (None, None) => {
                return Err(ApiError::new(
                    ErrorCode::InvalidRequest,
                    "points (or trajectory_matrix) is required",
                ));
            }
            (Some(rows), None) => {
                check_size(rows.len(), rows.first().map_or(0, |r| r.len()), limits)?;
                let rows = fill_unseen(rows, self.visible.as_deref(), Layout::Rows, kind)?;
                PointSet::from_rows(kind, &rows)?
            }
            (None, Some(matrix)) => {
                if kind != Kind::Trajectories {
                    return Err(ApiError::new(
                        ErrorCode::InvalidRequest,
                        "trajectory_matrix is only for kind trajectories",
                    ));
                }
                check_size(matrix.first().map_or(0, |r| r.len()), matrix.len(), limits)?;
                let matrix = fill_unseen(matrix, self.visible.as_deref(), Layout::Matrix, kind)?;
                PointSet::from_trajectory_matrix(&matrix)?
            }
        };
        let image_size = self
            .image_size
            .as_ref()
            .map(|v| image_size(v, kind))
            .transpose()?;
        if let Some(size) = image_size
            && !size.moves_in_range(&points)
        {
            return Err(ApiError::new(
                ErrorCode::InvalidPoints,
                "the second image's coordinates, brought to the first image's scale by the two \
                 image_size entries, pass 1e9: check image_size",
            ));
        }
        let model = match &self.model {
            Some(name) => models.get(name).ok_or_else(|| {
                ApiError::new(
                    ErrorCode::UnknownModel,
                    format!("no model named {name:?}; see GET /v1/models"),
                )
            })?,
            None => default_model(models, kind).ok_or_else(|| {
                ApiError::new(
                    ErrorCode::UnknownModel,
                    format!("no model serves kind {kind}"),
                )
            })?,
        };
        if model.card.kind != kind {
            return Err(ApiError::new(
                ErrorCode::ModelMismatch,
                format!(
                    "model {} takes {}, the request has kind {kind}",
                    model.card.name, model.card.kind
                ),
            ));
        }
        // Trajectory models read tracks of any length (the fit pipeline resamples them).
        if points.dim() != model.card.input_dim && kind != Kind::Trajectories {
            return Err(ApiError::new(
                ErrorCode::ModelMismatch,
                format!(
                    "model {} takes rows of {} values, got {}",
                    model.card.name,
                    model.card.input_dim,
                    points.dim()
                ),
            ));
        }
        let n = points.len();
        let k_max = self.k_max.unwrap_or(model.card.k_max);
        if k_max == 0 || k_max > limits.max_k_max {
            return Err(ApiError::new(
                ErrorCode::InvalidK,
                format!("k_max must be between 1 and {}", limits.max_k_max),
            ));
        }
        if self.k.is_some() && (self.k_max.is_some() || self.selection.is_some()) {
            return Err(ApiError::new(
                ErrorCode::InvalidRequest,
                "k gives the number of structures, k_max and selection choose it: send k alone, \
                 or k_max and selection without k",
            ));
        }
        let selection = match (self.k, self.selection.as_deref()) {
            (Some(k), _) => {
                if k == 0 || k > n {
                    return Err(ApiError::new(
                        ErrorCode::InvalidK,
                        format!("k = {k} must be between 1 and the number of points ({n})"),
                    ));
                }
                Selection::Fixed(k)
            }
            (None, None) => model.card.selection,
            (None, Some("sod")) => Selection::Sod,
            (None, Some("silhouette")) => Selection::Silhouette,
            (None, Some(other)) => {
                return Err(ApiError::new(
                    ErrorCode::InvalidSelection,
                    format!("selection {other:?} is not sod or silhouette"),
                ));
            }
        };
        let refine = match (
            self.refine.unwrap_or_else(|| model.card.refines(&points)),
            self.outliers,
            self.outlier_threshold,
        ) {
            (false, _, Some(_)) => {
                return Err(ApiError::new(
                    ErrorCode::InvalidRequest,
                    "outlier_threshold needs refine: true (a threshold applies to the refined \
                     structures' residuals)",
                ));
            }
            // Unrefined, curve and correspondence fits answer the outlier group their network
            // learned -1 (`outlier_group` below); motion networks learned none, and answer -1
            // only the tracks set apart as erratic (`erratic_outliers` below).
            (false, _, None) => None,
            (true, outliers, threshold) => {
                if let Some(t) = threshold
                    && !(t.is_finite() && t > 0.0)
                {
                    return Err(ApiError::new(
                        ErrorCode::InvalidRequest,
                        format!("outlier_threshold {t} must be a positive number"),
                    ));
                }
                if threshold.is_some() && outliers == Some(false) {
                    return Err(ApiError::new(
                        ErrorCode::InvalidRequest,
                        "outlier_threshold needs outliers: true",
                    ));
                }
                Some(RefineParams {
                    outliers: outliers.unwrap_or(threshold.is_some() || model.card.outliers),
                    threshold,
                    ..model.card.refine_params()
                })
            }
        };
        let return_embeddings = self.return_embeddings.unwrap_or(false);
        let visibility = match self.visible {
            None => None,
            Some(_) if kind != Kind::Trajectories => {
                return Err(ApiError::new(
                    ErrorCode::InvalidRequest,
                    "visible is only for kind trajectories",
                ));
            }
            Some(rows) => {
                let rows: Vec<Vec<bool>> = rows
                    .iter()
                    .map(|r| r.iter().map(|f| f.0).collect())
                    .collect();
                let v = Visibility::new(&rows, n, points.dim() / 2)?;
                let complete = v.complete().len();
                if let Selection::Fixed(k) = selection
                    && k > complete
                {
                    return Err(ApiError::new(
                        ErrorCode::InvalidK,
                        format!(
                            "k = {k} exceeds the {complete} tracks seen in every frame, which \
                             the fit clusters"
                        ),
                    ));
                }
                if return_embeddings && !v.is_complete() {
                    return Err(ApiError::new(
                        ErrorCode::InvalidRequest,
                        "return_embeddings needs every track seen in every frame: only those \
                         are embedded",
                    ));
                }
                Some(v)
            }
        };
        let params = ClusterParams::builder()
            .k_max(k_max)
            .selection(selection)
            .seed(self.seed.unwrap_or(0))
            .build()?;
        Ok(FitJob {
            model: model.clone(),
            points,
            image_size,
            params,
            return_embeddings,
            test_symmetries: self.test_symmetries.unwrap_or(true),
            outlier_group: self.outliers.unwrap_or(model.card.outliers),
            erratic_outliers: self.outliers != Some(false),
            refine,
            visibility,
        })
    }
}

fn check_size(n: usize, width: usize, limits: &Limits) -> Result<(), ApiError> {
    if n > limits.max_points {
        return Err(ApiError::new(
            ErrorCode::TooManyPoints,
            format!(
                "{n} points; this server takes at most {}",
                limits.max_points
            ),
        ));
    }
    if width > 2 * limits.max_frames {
        return Err(ApiError::new(
            ErrorCode::TooManyFrames,
            format!(
                "rows of {width} values; this server takes at most {} frames",
                limits.max_frames
            ),
        ));
    }
    Ok(())
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ModelRef {
    pub name: String,
    pub version: String,
    /// Hex SHA-256 of the weight files that answered ([`LoadedModel::weights_sha256`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weights_sha256: Option<String>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Residual {
    pub k: usize,
    pub r: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct KScore {
    pub k: usize,
    pub score: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Timing {
    pub embed: f64,
    pub cluster: f64,
    pub refine: f64,
    pub total: f64,
}

/// One fitted structure: its label, model type and parameters (caller's units), how many
/// points carry its label and their RMS residual.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct StructureOut {
    pub label: usize,
    #[serde(flatten)]
    pub model: Model,
    pub inliers: usize,
    pub rms: f64,
}

/// `POST /v1/fit` answer.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FitResponse {
    pub model: ModelRef,
    /// One per point: its structure, or -1 for an outlier (with refinement, or the outlier group
    /// of a fit given k) or a track seen in too few frames to place (with `visible`).
    pub labels: Vec<i64>,
    /// Structures, not counting outliers.
    pub k: usize,
    /// The K of the learned clustering the answer comes from (the K chosen, or given; with a
    /// k given to a model that learned an outlier group, k + 1 when that answer was kept).
    pub clustered_k: usize,
    pub selection: String,
    pub residuals: Vec<Residual>,
    pub scores: Vec<KScore>,
    pub cluster_sizes: Vec<usize>,
    /// One per label 0..k with refinement; empty without.
    pub structures: Vec<StructureOut>,
    /// Points labelled -1.
    pub outliers: usize,
    /// Quantities of the input outside the range the model was validated on.
    pub warnings: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub embeddings: Option<Vec<Vec<f32>>>,
    pub timing_ms: Timing,
}

impl FitResponse {
    pub fn new(job: &FitJob, outcome: FitOutcome, total_ms: f64) -> Self {
        let Clustering {
            selection,
            residuals,
            scores,
            k: clustered_k,
            ..
        } = outcome.clustering;
        let k = outcome.k;
        let mut cluster_sizes = vec![0; k];
        for &l in &outcome.labels {
            if let Ok(l) = usize::try_from(l) {
                cluster_sizes[l] += 1;
            }
        }
        Self {
            model: ModelRef {
                name: job.model.card.name.clone(),
                version: job.model.card.version.clone(),
                weights_sha256: job.model.weights_sha256().map(str::to_string),
            },
            outliers: outcome.labels.iter().filter(|&&l| l < 0).count(),
            labels: outcome.labels,
            k,
            clustered_k,
            selection: selection.name().to_string(),
            residuals: residuals
                .into_iter()
                .map(|(k, r)| Residual { k, r })
                .collect(),
            scores: scores
                .into_iter()
                .map(|(k, score)| KScore { k, score })
                .collect(),
            cluster_sizes,
            structures: outcome
                .structures
                .into_iter()
                .map(|s| StructureOut {
                    label: s.label,
                    model: s.model,
                    inliers: s.inliers,
                    rms: s.rms,
                })
                .collect(),
            warnings: outcome.warnings,
            embeddings: job.return_embeddings.then(|| {
                outcome
                    .embeddings
                    .chunks(outcome.embed_dim)
                    .map(|r| r.to_vec())
                    .collect()
            }),
            timing_ms: Timing {
                embed: outcome.embed_ms,
                cluster: outcome.cluster_ms,
                refine: outcome.refine_ms,
                total: total_ms,
            },
        }
    }
}
