//! Wire types of the API and their parsing into validated domain values.

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::error::ApiError;
use crate::cluster::{ClusterParams, Clustering, Selection};
use crate::data::{ImageSize, Kind, PointSet};
use crate::registry::{FitOutcome, LoadedModel};

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
    pub points: Option<Vec<Vec<f64>>>,
    #[serde(default)]
    pub trajectory_matrix: Option<Vec<Vec<f64>>>,
    #[serde(default)]
    pub model: Option<String>,
    #[serde(default)]
    pub image_size: Option<[f64; 2]>,
    #[serde(default)]
    pub k: Option<usize>,
    #[serde(default)]
    pub k_max: Option<usize>,
    #[serde(default)]
    pub selection: Option<String>,
    #[serde(default)]
    pub seed: Option<u64>,
    #[serde(default)]
    pub return_embeddings: Option<bool>,
    /// False: embed the input alone, skipping the model's test-time symmetries.
    #[serde(default)]
    pub test_symmetries: Option<bool>,
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
}

/// The shipped model used for a kind when the request names none: the first (by name) whose
/// card has that kind.
pub fn default_model(
    models: &BTreeMap<String, Arc<LoadedModel>>,
    kind: Kind,
) -> Option<&Arc<LoadedModel>> {
    models.values().find(|m| m.card.kind == kind)
}

impl FitRequest {
    /// Checks every field against the limits and the chosen model.
    pub fn validate(
        self,
        models: &BTreeMap<String, Arc<LoadedModel>>,
        limits: &Limits,
    ) -> Result<FitJob, ApiError> {
        let kind = Kind::parse(&self.kind).ok_or_else(|| {
            ApiError::invalid(
                "unknown_kind",
                format!(
                    "kind {:?} is not one of points2d, correspondences, trajectories",
                    self.kind
                ),
            )
        })?;
        let points = match (self.points, self.trajectory_matrix) {
            (Some(_), Some(_)) => {
                return Err(ApiError::invalid(
                    "invalid_request",
                    "give either points or trajectory_matrix, not both",
                ));
            }
            (None, None) => {
                return Err(ApiError::invalid(
                    "invalid_request",
                    "points (or trajectory_matrix) is required",
                ));
            }
            (Some(rows), None) => {
                check_size(rows.len(), rows.first().map_or(0, |r| r.len()), limits)?;
                PointSet::from_rows(kind, &rows)?
            }
            (None, Some(matrix)) => {
                if kind != Kind::Trajectories {
                    return Err(ApiError::invalid(
                        "invalid_request",
                        "trajectory_matrix is only for kind trajectories",
                    ));
                }
                check_size(matrix.first().map_or(0, |r| r.len()), matrix.len(), limits)?;
                PointSet::from_trajectory_matrix(&matrix)?
            }
        };
        let model = match &self.model {
            Some(name) => models.get(name).ok_or_else(|| {
                ApiError::invalid(
                    "unknown_model",
                    format!("no model named {name:?}; see GET /v1/models"),
                )
            })?,
            None => default_model(models, kind).ok_or_else(|| {
                ApiError::invalid("unknown_model", format!("no model serves kind {kind}"))
            })?,
        };
        if model.card.kind != kind {
            return Err(ApiError::invalid(
                "model_mismatch",
                format!(
                    "model {} takes {}, the request has kind {kind}",
                    model.card.name, model.card.kind
                ),
            ));
        }
        if points.dim() != model.card.input_dim {
            return Err(ApiError::invalid(
                "model_mismatch",
                format!(
                    "model {} takes rows of {} values, got {}",
                    model.card.name,
                    model.card.input_dim,
                    points.dim()
                ),
            ));
        }
        let image_size = match self.image_size {
            Some([w, h]) => Some(ImageSize::new(w, h)?),
            None => None,
        };
        let n = points.len();
        let k_max = self.k_max.unwrap_or(model.card.k_max);
        if k_max == 0 || k_max > limits.max_k_max {
            return Err(ApiError::invalid(
                "invalid_k",
                format!("k_max must be between 1 and {}", limits.max_k_max),
            ));
        }
        let selection = match (self.k, self.selection.as_deref()) {
            (Some(k), _) => {
                if k == 0 || k > n {
                    return Err(ApiError::invalid(
                        "invalid_k",
                        format!("k = {k} must be between 1 and the number of points ({n})"),
                    ));
                }
                Selection::Fixed(k)
            }
            (None, None) => model.card.selection,
            (None, Some("sod")) => Selection::Sod,
            (None, Some("silhouette")) => Selection::Silhouette,
            (None, Some(other)) => {
                return Err(ApiError::invalid(
                    "invalid_selection",
                    format!("selection {other:?} is not sod or silhouette"),
                ));
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
            return_embeddings: self.return_embeddings.unwrap_or(false),
            test_symmetries: self.test_symmetries.unwrap_or(true),
        })
    }
}

fn check_size(n: usize, width: usize, limits: &Limits) -> Result<(), ApiError> {
    if n > limits.max_points {
        return Err(ApiError::invalid(
            "too_many_points",
            format!(
                "{n} points; this server takes at most {}",
                limits.max_points
            ),
        ));
    }
    if width > 2 * limits.max_frames {
        return Err(ApiError::invalid(
            "too_many_frames",
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
    pub total: f64,
}

/// `POST /v1/fit` answer.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FitResponse {
    pub model: ModelRef,
    pub labels: Vec<usize>,
    pub k: usize,
    pub selection: String,
    pub residuals: Vec<Residual>,
    pub scores: Vec<KScore>,
    pub cluster_sizes: Vec<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub embeddings: Option<Vec<Vec<f32>>>,
    pub timing_ms: Timing,
}

impl FitResponse {
    pub fn new(job: &FitJob, outcome: FitOutcome, total_ms: f64) -> Self {
        let Clustering {
            labels,
            k,
            selection,
            residuals,
            scores,
            cluster_sizes,
        } = outcome.clustering;
        Self {
            model: ModelRef {
                name: job.model.card.name.clone(),
                version: job.model.card.version.clone(),
                weights_sha256: job.model.weights_sha256().map(str::to_string),
            },
            labels,
            k,
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
                total: total_ms,
            },
        }
    }
}
