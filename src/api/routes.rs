//! The HTTP routes and the shared state behind them.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use axum::extract::rejection::PathRejection;
use axum::extract::{DefaultBodyLimit, MatchedPath, Path, Request, State};
use axum::http::{HeaderName, HeaderValue, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde_json::json;
use tokio::sync::Semaphore;
use tower_http::request_id::{
    MakeRequestId, PropagateRequestIdLayer, RequestId, SetRequestIdLayer,
};
use tower_http::trace::TraceLayer;

use super::error::{ApiError, ApiJson};
use super::telemetry::{ENDPOINTS, Telemetry};
use super::types::{BatchRequest, FitJob, FitRequest, FitResponse, Limits};
use crate::registry::LoadedModel;

/// The OpenAPI description served at `/openapi.yaml`.
pub const OPENAPI: &str = include_str!("../../openapi.yaml");

/// Shared state of the service.
pub struct AppState {
    /// Set once every model is loaded.
    pub models: OnceLock<BTreeMap<String, Arc<LoadedModel>>>,
    /// False while loading and while draining.
    pub ready: AtomicBool,
    pub limits: Limits,
    /// Fit requests admitted (body being read, waiting or running); beyond
    /// `workers + queue_capacity`, 429 before the body is read.
    pub admitted: Arc<Semaphore>,
    /// Fits running at once.
    pub workers: Arc<Semaphore>,
    pub timeout: Duration,
    pub telemetry: Telemetry,
}

impl AppState {
    pub fn new(limits: Limits, workers: usize, queue_capacity: usize, timeout: Duration) -> Self {
        Self {
            models: OnceLock::new(),
            ready: AtomicBool::new(false),
            limits,
            admitted: Arc::new(Semaphore::new(workers + queue_capacity)),
            workers: Arc::new(Semaphore::new(workers)),
            timeout,
            telemetry: Telemetry::new(),
        }
    }

    /// Installs the loaded models and marks the service ready; logs and exports
    /// (`multifit_model_info`) each model's name, version, kind and weights digest.
    pub fn set_models(&self, models: BTreeMap<String, LoadedModel>) {
        for m in models.values() {
            let (card, sha) = (&m.card, m.weights_sha256().unwrap_or_default());
            tracing::info!(
                model = %card.name,
                version = %card.version,
                weights_sha256 = %sha,
                "model loaded"
            );
            self.telemetry
                .model_info
                .with_label_values(&[&card.name, &card.version, card.kind.as_str(), sha])
                .set(1);
        }
        let models = models.into_iter().map(|(k, v)| (k, Arc::new(v))).collect();
        if self.models.set(models).is_ok() {
            self.ready.store(true, Ordering::SeqCst);
        }
    }

    fn models(&self) -> Result<&BTreeMap<String, Arc<LoadedModel>>, ApiError> {
        self.models
            .get()
            .ok_or_else(|| ApiError::not_ready("models are still loading"))
    }
}

type Shared = Arc<AppState>;

/// Request ids: a per-process random prefix and a counter.
#[derive(Clone)]
struct Ids {
    prefix: u32,
    next: Arc<AtomicU64>,
}

impl MakeRequestId for Ids {
    fn make_request_id<B>(&mut self, _: &axum::http::Request<B>) -> Option<RequestId> {
        let n = self.next.fetch_add(1, Ordering::Relaxed);
        HeaderValue::from_str(&format!("{:08x}-{n:06}", self.prefix))
            .ok()
            .map(RequestId::new)
    }
}

/// The full router with every layer, over `state`.
pub fn router(state: Shared, body_limit: usize) -> Router {
    let request_id = HeaderName::from_static("x-request-id");
    let prefix = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let ids = Ids {
        prefix,
        next: Arc::new(AtomicU64::new(1)),
    };
    let fits = Router::new()
        .route("/v1/fit", post(fit))
        .route("/v1/fit/batch", post(fit_batch))
        .route_layer(middleware::from_fn_with_state(
            (state.clone(), body_limit),
            admit,
        ));
    Router::new()
        .merge(fits)
        .route("/v1/models", get(list_models))
        .route("/v1/models/{name}", get(get_model))
        .route("/health/live", get(live))
        .route("/health/ready", get(ready))
        .route("/metrics", get(metrics))
        .route("/openapi.yaml", get(openapi))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(body_limit))
        .layer(middleware::from_fn_with_state(state.clone(), track))
        .layer(TraceLayer::new_for_http().make_span_with(|req: &axum::http::Request<_>| {
            let id = req.headers().get("x-request-id").and_then(|v| v.to_str().ok()).unwrap_or("-");
            tracing::info_span!("request", method = %req.method(), path = %req.uri().path(), request_id = %id)
        }))
        .layer(PropagateRequestIdLayer::new(request_id.clone()))
        .layer(SetRequestIdLayer::new(request_id, ids))
        .with_state(state)
}

/// Counts every request by endpoint and status, and its duration.
async fn track(State(state): State<Shared>, req: Request, next: Next) -> Response {
    let endpoint = req
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_string())
        .filter(|p| ENDPOINTS.contains(&p.as_str()))
        .unwrap_or_else(|| "other".into());
    let start = Instant::now();
    let response = next.run(req).await;
    let t = &state.telemetry;
    t.request_seconds
        .with_label_values(&[&endpoint])
        .observe(start.elapsed().as_secs_f64());
    t.requests
        .with_label_values(&[&endpoint, response.status().as_str()])
        .inc();
    response
}

async fn not_found() -> ApiError {
    ApiError::not_found("no such route; see GET /openapi.yaml")
}

async fn method_not_allowed() -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        "method_not_allowed",
        "method not allowed on this route",
    )
}

/// Admission for the fit routes, before the body is parsed: past `workers + queue_capacity`
/// requests in the house the answer is 429 at once, its body read and dropped unparsed (so the
/// connection stays usable and the answer arrives), so a flood of large bodies costs neither
/// parsing nor memory. A request whose client goes away before its answer is counted as
/// abandoned (a fit still queued is then never run).
async fn admit(
    State((state, body_limit)): State<(Shared, usize)>,
    req: Request,
    next: Next,
) -> Response {
    let Ok(_permit) = state.admitted.clone().try_acquire_owned() else {
        discard_body(req.into_body(), body_limit, state.timeout).await;
        return counted(&state, ApiError::overloaded()).into_response();
    };
    let t = &state.telemetry;
    t.queue_depth.inc();
    let answered = AtomicBool::new(false);
    let _guard = scopeguard(|| {
        t.queue_depth.dec();
        if !answered.load(Ordering::Relaxed) {
            t.abandoned.inc();
        }
    });
    let response = next.run(req).await;
    answered.store(true, Ordering::Relaxed);
    response
}

/// Reads and drops a body of up to `limit` bytes (nothing is buffered or parsed), so that an
/// early answer leaves the connection in step and reaches the client: closing a connection with
/// unread request data can reset it and lose the answer.
async fn discard_body(body: axum::body::Body, limit: usize, timeout: Duration) {
    use http_body_util::BodyExt;
    let drain = async {
        let mut body = body;
        let mut seen = 0usize;
        while let Some(Ok(frame)) = body.frame().await {
            seen += frame.data_ref().map_or(0, |d| d.len());
            if seen > limit {
                break;
            }
        }
    };
    let _ = tokio::time::timeout(timeout, drain).await;
}

/// Waits for a worker and runs one validated fit off the async runtime (the request was
/// admitted by [`admit`]).
async fn run_fit(state: &AppState, job: FitJob) -> Result<FitResponse, ApiError> {
    let t = &state.telemetry;
    let start = Instant::now();
    let work = async {
        let permit = state
            .workers
            .clone()
            .acquire_owned()
            .await
            .map_err(|_| ApiError::not_ready("shutting down"))?;
        t.queue_seconds.observe(start.elapsed().as_secs_f64());
        // If the client goes away while queued, this future is dropped and the fit never runs.
        let handle = tokio::task::spawn_blocking(move || {
            let _permit = permit;
            let symmetries: &[_] = if job.test_symmetries {
                &job.model.card.test_symmetries
            } else {
                &[]
            };
            let outcome = job
                .model
                .fit_with(&job.points, job.image_size, &job.params, symmetries);
            (job, outcome)
        });
        let (job, outcome) = handle
            .await
            .map_err(|e| ApiError::internal(format!("fit worker failed: {e}")))?;
        Ok::<_, ApiError>((job, outcome?))
    };
    let (job, outcome) = tokio::time::timeout(state.timeout, work)
        .await
        .map_err(|_| ApiError::timeout())??;
    t.embed_seconds.observe(outcome.embed_ms / 1e3);
    t.cluster_seconds.observe(outcome.cluster_ms / 1e3);
    t.points.observe(job.points.len() as f64);
    t.chosen_k.observe(outcome.clustering.k as f64);
    Ok(FitResponse::new(
        &job,
        outcome,
        start.elapsed().as_secs_f64() * 1e3,
    ))
}

/// Runs a closure when dropped.
fn scopeguard<F: FnOnce()>(f: F) -> impl Drop {
    struct Guard<F: FnOnce()>(Option<F>);
    impl<F: FnOnce()> Drop for Guard<F> {
        fn drop(&mut self) {
            if let Some(f) = self.0.take() {
                f();
            }
        }
    }
    Guard(Some(f))
}

fn counted(state: &AppState, e: ApiError) -> ApiError {
    state.telemetry.reject(e.code);
    e
}

async fn fit(
    State(state): State<Shared>,
    body: Result<ApiJson<FitRequest>, ApiError>,
) -> Result<Json<FitResponse>, ApiError> {
    let ApiJson(request) = body.map_err(|e| counted(&state, e))?;
    let models = state.models().map_err(|e| counted(&state, e))?;
    let job = request
        .validate(models, &state.limits)
        .map_err(|e| counted(&state, e))?;
    run_fit(&state, job)
        .await
        .map(Json)
        .map_err(|e| counted(&state, e))
}

async fn fit_batch(
    State(state): State<Shared>,
    body: Result<ApiJson<BatchRequest>, ApiError>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let ApiJson(batch) = body.map_err(|e| counted(&state, e))?;
    let models = state.models().map_err(|e| counted(&state, e))?;
    if batch.requests.len() > state.limits.max_batch {
        return Err(counted(
            &state,
            ApiError::invalid(
                "too_many_requests_in_batch",
                format!("at most {} requests per batch", state.limits.max_batch),
            ),
        ));
    }
    let mut results = Vec::with_capacity(batch.requests.len());
    for raw in batch.requests {
        let one = async {
            let request: FitRequest = serde_json::from_value(raw)
                .map_err(|e| ApiError::invalid("invalid_request", e.to_string()))?;
            let job = request.validate(models, &state.limits)?;
            run_fit(&state, job).await
        };
        results.push(match one.await {
            Ok(r) => serde_json::to_value(r).map_err(|e| ApiError::internal(e.to_string()))?,
            Err(e) => counted(&state, e).body(),
        });
    }
    Ok(Json(json!({ "results": results })))
}

async fn list_models(State(state): State<Shared>) -> Result<Json<serde_json::Value>, ApiError> {
    let models = state.models()?;
    let cards = models
        .values()
        .map(|m| model_json(m))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Json(json!({ "models": cards })))
}

/// A model's card with the SHA-256 of the weights it was loaded from beside it.
fn model_json(model: &LoadedModel) -> Result<serde_json::Value, ApiError> {
    let mut value =
        serde_json::to_value(&model.card).map_err(|e| ApiError::internal(e.to_string()))?;
    if let (Some(object), Some(sha)) = (value.as_object_mut(), model.weights_sha256()) {
        object.insert("weights_sha256".into(), sha.into());
    }
    Ok(value)
}

async fn get_model(
    State(state): State<Shared>,
    name: Result<Path<String>, PathRejection>,
) -> Result<Json<serde_json::Value>, ApiError> {
    // A name that is not UTF-8 cannot name a model.
    let Path(name) = name.map_err(|e| ApiError::not_found(e.body_text()))?;
    let models = state.models()?;
    let model = models
        .get(&name)
        .ok_or_else(|| ApiError::not_found(format!("no model named {name:?}")))?;
    model_json(model).map(Json)
}

async fn live() -> Json<serde_json::Value> {
    Json(json!({ "status": "live" }))
}

async fn ready(State(state): State<Shared>) -> Response {
    if state.ready.load(Ordering::SeqCst) {
        Json(json!({ "status": "ready" })).into_response()
    } else {
        let why = if state.models.get().is_some() {
            "draining"
        } else {
            "loading models"
        };
        ApiError::not_ready(why).into_response()
    }
}

async fn metrics(State(state): State<Shared>) -> Response {
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        state.telemetry.render(),
    )
        .into_response()
}

async fn openapi() -> Response {
    ([(header::CONTENT_TYPE, "application/yaml")], OPENAPI).into_response()
}
