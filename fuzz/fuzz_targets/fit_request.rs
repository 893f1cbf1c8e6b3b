//! Fuzzes request parsing and validation.
//!
//! The input bytes are a request body, as JSON text. The target does what the server does before
//! a fit runs (src/api/routes.rs, `fit` and `fit_batch`): parse into the wire type with the
//! server's own `parse_json` (`FitRequest`, and `BatchRequest` whose entries are parsed one by one
//! with `serde_json::from_value`), then `FitRequest::validate` against the shipped models and the
//! server's default `Limits`. For a request that validates it also runs the normalisation the fit
//! starts with, `LoadedModel::prepare` (normalise + neighbour offsets), but not the network forward
//! or the clustering (too slow for thousands of executions per second).
//!
//! Every failure must come back as an `Err`; a panic is a crash. Besides that, the target checks:
//! - a body that does not parse is a 400 `malformed_json` or a 422 `invalid_request`;
//! - every validation error is a 4xx `ApiError` whose JSON body serialises;
//! - a validated job respects the limits and its model (kind, row width, k within 1..=n,
//!   1 <= k_max <= max_k_max), and `prepare` accepts it with `n * feature_dim` finite values,
//!   a subnormal bounding box included (the seed `subnormal.json`).

#![no_main]

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, LazyLock};

use libfuzzer_sys::fuzz_target;
use multifit::api::error::parse_json;
use multifit::api::types::{BatchRequest, FitRequest, Limits};
use multifit::api::{ApiError, ErrorCode};
use multifit::cluster::Selection;
use multifit::data::points::MAX_ABS_COORD;
use multifit::registry::{LoadedModel, load_all};

/// The shipped models, loaded once and wrapped as the server does (`AppState::set_models`).
static MODELS: LazyLock<BTreeMap<String, Arc<LoadedModel>>> = LazyLock::new(|| {
    let dir = std::env::var_os("MULTIFIT_MODELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models"));
    let models = load_all(&dir)
        .unwrap_or_else(|e| panic!("cannot load the models from {}: {e}", dir.display()));
    models.into_iter().map(|(k, v)| (k, Arc::new(v))).collect()
});

/// The defaults of `multifit-server` (`--max-points`, `--max-frames`, `--max-k-max`,
/// `--max-batch`; src/bin/multifit-server.rs).
const LIMITS: Limits = Limits {
    max_points: 20_000,
    max_frames: 500,
    max_k_max: 20,
    max_batch: 32,
};

fuzz_target!(|data: &[u8]| {
    let models = &*MODELS;
    // POST /v1/fit
    match parse_json::<FitRequest>(data) {
        Ok(request) => fit_one(request, models),
        Err(e) => check_parse_error(&e),
    }
    // POST /v1/fit/batch
    match parse_json::<BatchRequest>(data) {
        Ok(batch) => {
            if batch.requests.len() > LIMITS.max_batch {
                return; // too_many_requests_in_batch before any entry is parsed
            }
            for raw in batch.requests {
                if let Ok(request) = serde_json::from_value::<FitRequest>(raw) {
                    fit_one(request, models);
                }
            }
        }
        Err(e) => check_parse_error(&e),
    }
});

/// Validation and normalisation of one parsed request.
fn fit_one(request: FitRequest, models: &BTreeMap<String, Arc<LoadedModel>>) {
    let job = match request.validate(models, &LIMITS) {
        Ok(job) => job,
        Err(e) => return check_error(&e),
    };
    let model = &job.model;
    let n = job.points.len();
    assert!(
        (2..=LIMITS.max_points).contains(&n),
        "validated set of {n} points"
    );
    assert_eq!(
        job.points.kind(),
        model.card.kind,
        "validated kind differs from the model's"
    );
    assert_eq!(
        job.points.dim(),
        model.card.input_dim,
        "validated row width differs from the model's"
    );
    assert!(job.points.dim() <= 2 * LIMITS.max_frames);
    let k_max = job.params.k_max();
    assert!(
        (1..=LIMITS.max_k_max).contains(&k_max),
        "validated k_max {k_max}"
    );
    if let Selection::Fixed(k) = job.params.selection() {
        assert!((1..=n).contains(&k), "validated k {k} for {n} points");
    }
    if let Some(s) = job.image_size {
        let px = 1.0..=MAX_ABS_COORD;
        assert!(
            px.contains(&s.width) && px.contains(&s.height),
            "validated {s:?}"
        );
    }
    let features = model
        .prepare(&job.points, job.image_size)
        .unwrap_or_else(|e| panic!("prepare rejected a validated job: {e}"));
    assert_eq!(features.len(), n * model.card.architecture.feature_dim());
    if let Some(at) = features.iter().position(|v| !v.is_finite()) {
        panic!(
            "non-finite network input {} at value {at} (model {}, image_size {:?})",
            features[at], model.card.name, job.image_size
        );
    }
}

fn check_parse_error(e: &ApiError) {
    let want = matches!(e.code, ErrorCode::MalformedJson | ErrorCode::InvalidRequest);
    assert!(
        want,
        "unparsable body answered {} {}: {}",
        e.status(),
        e.code,
        e.message
    );
    check_error(e);
}

fn check_error(e: &ApiError) {
    assert!(
        e.status().is_client_error(),
        "validation answered {}: {e:?}",
        e.status()
    );
    assert!(!e.message.is_empty(), "empty message for {}", e.code);
    let body = e.body();
    assert_eq!(body["error"]["code"], e.code.as_str());
}
