//! The HTTP routes and the shared state behind them.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use axum::extract::rejection::PathRejection;
use axum::extract::{DefaultBodyLimit, MatchedPath, Path, Request, State};
use axum::http::{HeaderMap, HeaderName, HeaderValue, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{MethodRouter, get, post};
use axum::{Json, Router};
use serde_json::json;
use tokio::sync::Semaphore;
use tower_http::request_id::{
    MakeRequestId, PropagateRequestIdLayer, RequestId, SetRequestIdLayer,
};
use tower_http::trace::TraceLayer;

use super::error::{ApiError, ApiJson, ErrorCode};
use super::linger::linger;
use super::telemetry::{EntryErrors, Telemetry};
use super::types::{BatchRequest, FitJob, FitRequest, FitResponse, Limits};
use super::{page, picture};
use crate::pipeline::{self, FitOptions};
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

/// One route: its path and its handlers by method.
pub struct Route {
    /// The path in axum's syntax, also the route's `endpoint` label in the metrics.
    pub path: &'static str,
    methods: fn() -> MethodRouter<Shared>,
    /// Whether requests pass [`admit`] (the fit routes) before their body is read.
    admitted: bool,
}

impl Route {
    const fn open(path: &'static str, methods: fn() -> MethodRouter<Shared>) -> Self {
        Self {
            path,
            methods,
            admitted: false,
        }
    }
    const fn admitted(path: &'static str, methods: fn() -> MethodRouter<Shared>) -> Self {
        Self {
            path,
            methods,
            admitted: true,
        }
    }
}

/// Every route of the service. [`router`] is built from this table alone and [`ENDPOINTS`]
/// lists its paths, so each route the router serves is counted by name in the metrics.
pub const ROUTES: [Route; 10] = [
    Route::open("/", || get(page::index)),
    Route::open("/examples/{file}", || get(page::example)),
    Route::admitted("/v1/fit", || post(fit)),
    Route::admitted("/v1/fit/batch", || post(fit_batch)),
    Route::open("/v1/models", || get(list_models)),
    Route::open("/v1/models/{name}", || get(get_model)),
    Route::open("/health/live", || get(live)),
    Route::open("/health/ready", || get(ready)),
    Route::open("/metrics", || get(metrics)),
    Route::open("/openapi.yaml", || get(openapi)),
];

/// The paths of [`ROUTES`], in order: the endpoints the metrics count by name (any other
/// request is counted as "other").
pub const ENDPOINTS: [&str; ROUTES.len()] = {
    let mut paths = [""; ROUTES.len()];
    let mut i = 0;
    while i < ROUTES.len() {
        paths[i] = ROUTES[i].path;
        i += 1;
    }
    paths
};

/// The server's body limit in bytes, for the 413's message ([`super::error::ApiJson`]).
#[derive(Debug, Clone, Copy)]
pub struct BodyLimit(pub usize);

/// The longest a JSON body may take to arrive (the request timeout): past it, 408
/// ([`super::error::ApiJson`]).
#[derive(Debug, Clone, Copy)]
pub struct BodyDeadline(pub std::time::Duration);

/// The full router with every layer, over `state`: the routes of [`ROUTES`], JSON errors for
/// an unknown route or method, metrics ([`track`]) and the lingering close of request bodies
/// left unread ([`super::linger`]).
pub fn router(state: Shared, body_limit: usize) -> Router {
    let request_id = HeaderName::from_static("x-request-id");
    let prefix = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let ids = Ids {
        prefix,
        next: Arc::new(AtomicU64::new(1)),
    };
    let mut app = Router::new();
    for route in &ROUTES {
        let mut methods = (route.methods)();
        if route.admitted {
            methods = methods.route_layer(middleware::from_fn_with_state(state.clone(), admit));
        }
        app = app.route(route.path, methods);
    }
    app.fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(body_limit))
        .layer(axum::Extension(BodyLimit(body_limit)))
        .layer(axum::Extension(BodyDeadline(state.timeout)))
        .layer(middleware::from_fn_with_state(state.clone(), track))
        .layer(middleware::from_fn_with_state(body_limit, linger))
        .layer(TraceLayer::new_for_http().make_span_with(|req: &axum::http::Request<_>| {
            let id = req.headers().get("x-request-id").and_then(|v| v.to_str().ok()).unwrap_or("-");
            tracing::info_span!("request", method = %req.method(), path = %req.uri().path(), request_id = %id)
        }))
        .layer(PropagateRequestIdLayer::new(request_id.clone()))
        .layer(SetRequestIdLayer::new(request_id, ids))
        .with_state(state)
}

/// Counts every request by endpoint and status, and its duration; and the rejections, once each:
/// the code of an error answer, the codes of a batch answer's failed entries (the rule is in
/// [`super::telemetry`]).
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
    if let Some(&code) = response.extensions().get::<ErrorCode>() {
        t.reject(code);
    }
    if let Some(EntryErrors(codes)) = response.extensions().get::<EntryErrors>() {
        for &code in codes {
            t.reject(code);
        }
    }
    response
}

async fn not_found() -> ApiError {
    ApiError::not_found("no such route; see GET /openapi.yaml")
}

async fn method_not_allowed() -> ApiError {
    ApiError::new(
        ErrorCode::MethodNotAllowed,
        "method not allowed on this route",
    )
}

/// Admission for the fit routes, before the body is parsed: past `workers + queue_capacity`
/// requests in the house the answer is 429 at once, its body left unparsed (the lingering close
/// reads and drops it, so the answer arrives), so a flood of large bodies costs neither parsing
/// nor memory. A request whose client goes away before its answer is counted as abandoned (a fit
/// still queued is then never run).
async fn admit(State(state): State<Shared>, req: Request, next: Next) -> Response {
    let Ok(_permit) = state.admitted.clone().try_acquire_owned() else {
        return ApiError::overloaded().into_response();
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
            let options = FitOptions {
                params: &job.params,
                symmetries,
                refine: job.refine,
                outlier_group: job.outlier_group,
                erratic_outliers: job.erratic_outliers,
            };
            let outcome = match &job.visibility {
                Some(seen) => {
                    pipeline::fit_seen(&job.model, &job.points, seen, job.image_size, &options)
                }
                None => pipeline::fit(&job.model, &job.points, job.image_size, &options),
            };
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
    t.chosen_k.observe(outcome.k as f64);
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

/// `POST /v1/fit`: JSON, or the picture when `Accept` asks for `image/svg+xml`
/// ([`picture::wants_svg`]); errors are JSON either way.
async fn fit(
    State(state): State<Shared>,
    headers: HeaderMap,
    body: Result<ApiJson<FitRequest>, ApiError>,
) -> Result<Response, ApiError> {
    let ApiJson(request) = body?;
    let job = request.validate(state.models()?, &state.limits)?;
    // The picture needs the points, which the fit consumes with the job.
    let drawn = picture::wants_svg(&headers)
        .then(|| (job.points.clone(), job.visibility.clone(), job.image_size));
    let fitted = run_fit(&state, job).await?;
    let Some((points, seen, image_size)) = drawn else {
        return Ok(([(header::VARY, "accept")], Json(fitted)).into_response());
    };
    let svg = tokio::task::spawn_blocking(move || {
        // Tracks not seen in every frame are drawn resting where they were seen.
        let points = match seen {
            Some(seen) => seen.held(&points),
            None => points,
        };
        picture::svg(&points, image_size, &fitted)
    })
    .await
    .map_err(|e| ApiError::internal(format!("picture failed: {e}")))?;
    Ok(picture::response(svg))
}

/// `POST /v1/fit/batch`: every entry parsed, validated and fitted on its own; the answer
/// carries the codes of the failed entries ([`EntryErrors`]) for the metrics.
async fn fit_batch(
    State(state): State<Shared>,
    body: Result<ApiJson<BatchRequest>, ApiError>,
) -> Result<Response, ApiError> {
    let ApiJson(batch) = body?;
    let models = state.models()?;
    if batch.requests.len() > state.limits.max_batch {
        return Err(ApiError::new(
            ErrorCode::TooManyRequestsInBatch,
            format!("at most {} requests per batch", state.limits.max_batch),
        ));
    }
    let mut results = Vec::with_capacity(batch.requests.len());
    let mut failed = EntryErrors::default();
    for raw in batch.requests {
        let one = async {
            if !raw.is_object() {
                return Err(ApiError::not_an_object("each batch entry"));
            }
            let request: FitRequest = serde_json::from_value(raw)
                .map_err(|e| ApiError::new(ErrorCode::InvalidRequest, e.to_string()))?;
            let job = request.validate(models, &state.limits)?;
            run_fit(&state, job).await
        };
        results.push(match one.await {
            Ok(r) => serde_json::to_value(r).map_err(|e| ApiError::internal(e.to_string()))?,
            Err(e) => {
                failed.0.push(e.code);
                e.body()
            }
        });
    }
    let mut response = Json(json!({ "results": results })).into_response();
    response.extensions_mut().insert(failed);
    Ok(response)
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
