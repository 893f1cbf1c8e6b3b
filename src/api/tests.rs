//! The service in process, through `router(...).oneshot(...)`: the error table (every code's
//! status and body for representative bad requests), rejections counted once each, and, over a
//! real socket, the 413 that a client writing its whole body before reading gets.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use axum::body::{Body, Bytes, HttpBody};
use axum::http::{Method, Request, StatusCode, header};
use axum::response::Response;
use http_body::Frame;
use http_body_util::BodyExt;
use serde_json::{Value, json};
use tower::ServiceExt;

use super::error::ErrorCode;
use super::routes::{AppState, router};
use super::types::Limits;
use crate::data::Kind;
use crate::registry::LoadedModel;

const LIMITS: Limits = Limits {
    max_points: 50,
    max_frames: 4,
    max_k_max: 6,
    max_batch: 3,
};
const BODY_LIMIT: usize = 4096;

/// A one-block network for `kind` on rows of `input_dim` values, embedding in 3 dimensions.
fn tiny(name: &str, kind: Kind, input_dim: usize) -> LoadedModel {
    crate::registry::tests::tiny_model(name, kind, input_dim, 7)
}

/// A state serving `tiny` (2-frame tracks) and `tiny2d` (points2d); no correspondences model.
fn state(workers: usize, queue: usize, timeout: Duration) -> Arc<AppState> {
    let state = Arc::new(AppState::new(LIMITS, workers, queue, timeout));
    state.set_models(BTreeMap::from([
        ("tiny".to_string(), tiny("tiny", Kind::Trajectories, 4)),
        ("tiny2d".to_string(), tiny("tiny2d", Kind::Points2d, 2)),
    ]));
    state
}

fn service(state: &Arc<AppState>) -> Router {
    router(state.clone(), BODY_LIMIT)
}

/// Eight 2-frame tracks in two rigid groups.
fn tracks() -> Value {
    json!([
        [0, 0, 1, 0],
        [1, 0, 2, 0],
        [0, 1, 1, 1],
        [1, 1, 2, 1],
        [5, 5, 5, 6],
        [6, 5, 6, 6],
        [5, 6, 5, 7],
        [6, 6, 6, 7]
    ])
}

fn good() -> Value {
    json!({"kind": "trajectories", "points": tracks(), "k": 2, "seed": 1})
}

/// Tracks set apart as erratic are answered -1 unless the request says `"outliers": false`
/// (the card's `outliers`, false for track models, does not count), refined or not; and
/// `"outliers": true` without refinement is a valid request for tracks.
#[test]
fn tracks_answer_erratic_ones_minus_one_unless_the_request_says_outliers_false() {
    use super::types::FitRequest;
    let mut model = tiny("tiny", Kind::Trajectories, 4);
    // As the track models' cards say.
    model.card.outliers = false;
    let models = BTreeMap::from([("tiny".to_string(), Arc::new(model))]);
    let job = |extra: Value| {
        let mut body = good();
        body.as_object_mut()
            .unwrap()
            .extend(extra.as_object().unwrap().clone());
        let request: FitRequest = serde_json::from_value(body).unwrap();
        request.validate(&models, &LIMITS).unwrap()
    };
    for (extra, erratic) in [
        (json!({}), true),
        (json!({"refine": false}), true),
        (json!({"refine": true}), true),
        (json!({"refine": false, "outliers": true}), true),
        (json!({"refine": true, "outliers": true}), true),
        (json!({"outliers": false}), false),
        (json!({"refine": true, "outliers": false}), false),
    ] {
        let job = job(extra.clone());
        assert_eq!(job.erratic_outliers, erratic, "{extra}");
        if extra.get("refine") == Some(&json!(false)) {
            assert!(job.refine.is_none(), "{extra}");
        }
    }
}

/// A request body of chunks sent without a length, optionally failing after them.
struct Chunks {
    chunks: VecDeque<Bytes>,
    fail: bool,
}

impl HttpBody for Chunks {
    type Data = Bytes;
    type Error = std::io::Error;

    fn poll_frame(
        self: Pin<&mut Self>,
        _: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, std::io::Error>>> {
        let this = self.get_mut();
        Poll::Ready(match this.chunks.pop_front() {
            Some(chunk) => Some(Ok(Frame::data(chunk))),
            None if std::mem::take(&mut this.fail) => {
                Some(Err(std::io::Error::other("connection lost")))
            }
            None => None,
        })
    }
}

fn chunked(total: usize, fail: bool) -> Body {
    let chunks = (0..total.div_ceil(1024))
        .map(|i| Bytes::from(vec![b' '; 1024.min(total - i * 1024)]))
        .collect();
    Body::new(Chunks { chunks, fail })
}

fn request(method: Method, uri: &str, content_type: Option<&str>, body: Body) -> Request<Body> {
    let mut r = Request::builder().method(method).uri(uri);
    if let Some(ct) = content_type {
        r = r.header(header::CONTENT_TYPE, ct);
    }
    r.body(body).unwrap()
}

fn post(value: &Value) -> Request<Body> {
    post_to("/v1/fit", value)
}

fn post_to(uri: &str, value: &Value) -> Request<Body> {
    let body = Body::from(serde_json::to_vec(value).unwrap());
    request(Method::POST, uri, Some("application/json"), body)
}

/// A body that sends `first` and then never another byte: a client stalled mid-request.
fn body_stalled_after(first: &'static [u8]) -> Body {
    struct Stalled(Option<axum::body::Bytes>);
    impl http_body::Body for Stalled {
        type Data = axum::body::Bytes;
        type Error = std::convert::Infallible;
        fn poll_frame(
            mut self: std::pin::Pin<&mut Self>,
            _: &mut std::task::Context<'_>,
        ) -> std::task::Poll<Option<Result<http_body::Frame<Self::Data>, Self::Error>>> {
            match self.0.take() {
                Some(data) => std::task::Poll::Ready(Some(Ok(http_body::Frame::data(data)))),
                None => std::task::Poll::Pending,
            }
        }
    }
    Body::new(Stalled(Some(axum::body::Bytes::from_static(first))))
}

/// `POST /v1/fit` of `body` as it is, with the JSON content type.
fn post_text(body: impl Into<Body>) -> Request<Body> {
    request(
        Method::POST,
        "/v1/fit",
        Some("application/json"),
        body.into(),
    )
}

/// The error message `app` answers `body` with (posted as it is), having checked its status
/// and code.
async fn rejected(app: &Router, body: &str, status: StatusCode, code: ErrorCode) -> String {
    let (got, got_code, answer) = send(app, post_text(body.to_string())).await;
    assert_eq!(got, status, "{body}");
    assert_eq!(got_code, Some(code), "{body}");
    answer["error"]["message"].as_str().unwrap().to_string()
}

fn get(uri: &str) -> Request<Body> {
    request(Method::GET, uri, None, Body::empty())
}

/// Sends `req`; returns the status, the code the response carries for the metrics, and the body.
async fn send(app: &Router, req: Request<Body>) -> (StatusCode, Option<ErrorCode>, Value) {
    read(app.clone().oneshot(req).await.unwrap()).await
}

async fn read(response: Response) -> (StatusCode, Option<ErrorCode>, Value) {
    let status = response.status();
    let code = response.extensions().get::<ErrorCode>().copied();
    let is_json = response
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes() == b"application/json");
    let bytes = response.into_body().collect().await.unwrap().to_bytes();
    let body = if is_json {
        serde_json::from_slice(&bytes).unwrap()
    } else {
        Value::String(String::from_utf8_lossy(&bytes).into_owned())
    };
    (status, code, body)
}

/// Checks an error answer: `code`'s status, and exactly `{"error": {"code", "message"}}`.
fn check_error(what: &str, got: &(StatusCode, Option<ErrorCode>, Value), code: ErrorCode) {
    let (status, carried, body) = got;
    assert_eq!(*status, code.status(), "{what}: {body}");
    assert_eq!(*carried, Some(code), "{what}: the code the metrics count");
    let error = body["error"].as_object();
    let keys: Option<BTreeSet<&str>> = error.map(|e| e.keys().map(String::as_str).collect());
    assert_eq!(
        body.as_object().map(|o| o.len()),
        Some(1),
        "{what}: one key: {body}"
    );
    assert_eq!(
        keys,
        Some(BTreeSet::from(["code", "message"])),
        "{what}: {body}"
    );
    assert_eq!(body["error"]["code"], code.as_str(), "{what}: {body}");
    assert!(
        body["error"]["message"]
            .as_str()
            .is_some_and(|m| !m.is_empty()),
        "{what}: {body}"
    );
}

/// Codes no request can bring about: a fit worker that panics, clustering parameters that the
/// request validation lets through.
const UNREACHABLE: [ErrorCode; 2] = [ErrorCode::Internal, ErrorCode::InvalidClustering];

#[tokio::test]
async fn every_error_code_answers_its_status_and_the_json_shape() {
    use ErrorCode as E;
    let state = state(1, 4, Duration::from_secs(60));
    let app = service(&state);
    let json = Some("application/json");
    let two = json!([[0.0, 0.0], [1.0, 1.0]]);
    let mut seen = BTreeSet::new();
    let raw: Vec<(&str, Option<&str>, Body, ErrorCode)> = vec![
        (
            "truncated",
            json,
            Body::from(r#"{"kind": "points2d", "points": [[0"#),
            E::MalformedJson,
        ),
        ("not JSON", json, Body::from("hello"), E::MalformedJson),
        (
            "NaN literal",
            json,
            Body::from(r#"{"kind":"points2d","points":[[NaN,1],[0,0]]}"#),
            E::MalformedJson,
        ),
        (
            "not UTF-8",
            json,
            Body::from(vec![b'{', 0xff, b'}']),
            E::MalformedJson,
        ),
        ("a body that fails", json, chunked(100, true), E::BadRequest),
        (
            "text/plain",
            Some("text/plain"),
            Body::from(r#"{"kind":"points2d"}"#),
            E::UnsupportedMediaType,
        ),
        (
            "no content type",
            None,
            Body::from(r#"{"kind":"points2d"}"#),
            E::UnsupportedMediaType,
        ),
        (
            "application/jsonx",
            Some("application/jsonx"),
            Body::from("{}"),
            E::UnsupportedMediaType,
        ),
        (
            "too large",
            json,
            Body::from(vec![b' '; BODY_LIMIT + 1]),
            E::BodyTooLarge,
        ),
        (
            "too large, chunked",
            json,
            chunked(3 * BODY_LIMIT, false),
            E::BodyTooLarge,
        ),
        // Well-formed JSON, but a number beyond f64's range or a fixed-size array too long.
        (
            "1e309 coordinate",
            json,
            Body::from(r#"{"kind":"points2d","points":[[0,0],[1e309,1],[2,2]]}"#),
            E::InvalidRequest,
        ),
        (
            "-1e309 coordinate",
            json,
            Body::from(r#"{"kind":"points2d","points":[[0,0],[-1e309,1],[2,2]]}"#),
            E::InvalidRequest,
        ),
        (
            "image_size 1e309",
            json,
            Body::from(r#"{"kind":"points2d","points":[[0,0],[1,1]],"image_size":[1e309,480]}"#),
            E::InvalidRequest,
        ),
        (
            "image_size of three",
            json,
            Body::from(r#"{"kind":"points2d","points":[[0,0],[1,1]],"image_size":[640,480,3]}"#),
            E::InvalidRequest,
        ),
    ];
    for (what, ct, body, code) in raw {
        let got = send(&app, request(Method::POST, "/v1/fit", ct, body)).await;
        check_error(what, &got, code);
        if code == E::BodyTooLarge {
            let message = got.2["error"]["message"].as_str().unwrap();
            let limit = format!("limit of {BODY_LIMIT} bytes");
            assert!(message.contains(&limit), "{what}: {message}");
        }
        seen.insert(code);
    }
    let semantic: Vec<(&str, Value, ErrorCode)> = vec![
        (
            "empty points",
            json!({"kind": "points2d", "points": []}),
            E::InvalidPoints,
        ),
        (
            "one point",
            json!({"kind": "points2d", "points": [[1.0, 2.0]]}),
            E::InvalidPoints,
        ),
        (
            "3 values for points2d",
            json!({"kind": "points2d", "points": [[1, 2, 3], [1, 2, 3]]}),
            E::InvalidPoints,
        ),
        (
            "ragged",
            json!({"kind": "points2d", "points": [[1.0, 2.0], [1.0]]}),
            E::InvalidPoints,
        ),
        (
            "huge value",
            json!({"kind": "points2d", "points": [[1e308, 2.0], [1.0, 1.0]]}),
            E::InvalidPoints,
        ),
        (
            "image size 0",
            json!({"kind": "points2d", "points": two, "image_size": [0.0, 10.0]}),
            E::InvalidPoints,
        ),
        (
            "second view past 1e9 in the first image's frame",
            json!({"kind": "correspondences", "points": [[0, 0, 1, 1], [2, 2, 3, 3], [4, 5, 6, 7]],
                   "image_size": [[1e9, 1e9], [1, 1]]}),
            E::InvalidPoints,
        ),
        (
            "second image size 0",
            json!({"kind": "correspondences", "points": [[0, 0, 1, 1], [2, 2, 3, 3], [4, 5, 6, 7]],
                   "image_size": [[640, 480], [0, 240]]}),
            E::InvalidPoints,
        ),
        (
            "odd track rows",
            json!({"kind": "trajectories", "points": [[0, 0, 1], [1, 1, 2]]}),
            E::InvalidPoints,
        ),
        (
            "unknown field",
            json!({"kind": "points2d", "points": two, "colour": 1}),
            E::InvalidRequest,
        ),
        (
            "wrong type",
            json!({"kind": "points2d", "points": "many"}),
            E::InvalidRequest,
        ),
        (
            "negative k",
            json!({"kind": "points2d", "points": two, "k": -2}),
            E::InvalidRequest,
        ),
        ("no points", json!({"kind": "points2d"}), E::InvalidRequest),
        (
            "outlier_threshold without refine",
            json!({"kind": "points2d", "points": two, "refine": false, "outlier_threshold": 2.0}),
            E::InvalidRequest,
        ),
        (
            "points and matrix",
            json!({"kind": "trajectories", "points": tracks(), "trajectory_matrix": [[0, 1], [0, 1], [0, 1], [0, 1]]}),
            E::InvalidRequest,
        ),
        (
            "matrix for points2d",
            json!({"kind": "points2d", "trajectory_matrix": [[0, 1], [0, 1]]}),
            E::InvalidRequest,
        ),
        (
            "visible for points2d",
            json!({"kind": "points2d", "points": two, "visible": [[1], [1]]}),
            E::InvalidRequest,
        ),
        (
            "visible flags as strings",
            json!({"kind": "trajectories", "points": tracks(), "visible": vec![["1", "1"]; 8]}),
            E::InvalidRequest,
        ),
        (
            "visible rows for other tracks",
            json!({"kind": "trajectories", "points": tracks(), "visible": vec![[1, 1]; 7]}),
            E::InvalidPoints,
        ),
        (
            "visible row of other frames",
            json!({"kind": "trajectories", "points": tracks(), "visible": vec![vec![1, 1, 1]; 8]}),
            E::InvalidPoints,
        ),
        (
            "visible flag 2",
            json!({"kind": "trajectories", "points": tracks(), "visible": vec![[1, 2]; 8]}),
            E::InvalidRequest,
        ),
        (
            "visible flag 0.5",
            json!({"kind": "trajectories", "points": tracks(), "visible": vec![[1.0, 0.5]; 8]}),
            E::InvalidRequest,
        ),
        (
            "one track seen throughout",
            json!({"kind": "trajectories", "points": tracks(),
                   "visible": [[1, 1], [0, 1], [1, 0], [0, 1], [1, 0], [0, 1], [1, 0], [0, 1]]}),
            E::InvalidPoints,
        ),
        (
            "k above the tracks seen throughout",
            json!({"kind": "trajectories", "points": tracks(), "k": 3,
                   "visible": [[1, 1], [1, 1], [0, 1], [0, 1], [1, 0], [0, 1], [1, 0], [0, 1]]}),
            E::InvalidK,
        ),
        (
            "embeddings of partly seen tracks",
            json!({"kind": "trajectories", "points": tracks(), "return_embeddings": true,
                   "visible": [[1, 1], [1, 1], [1, 1], [0, 1], [1, 1], [1, 1], [1, 1], [1, 1]]}),
            E::InvalidRequest,
        ),
        (
            "unknown kind",
            json!({"kind": "voxels", "points": two}),
            E::UnknownKind,
        ),
        (
            "unknown model",
            json!({"kind": "points2d", "points": two, "model": "nope"}),
            E::UnknownModel,
        ),
        (
            "path as model",
            json!({"kind": "points2d", "points": two, "model": "tiny/../../etc"}),
            E::UnknownModel,
        ),
        (
            "no model of the kind",
            json!({"kind": "correspondences", "points": [[0, 0, 1, 1], [1, 1, 2, 2]]}),
            E::UnknownModel,
        ),
        (
            "kind/model mismatch",
            json!({"kind": "points2d", "points": two, "model": "tiny"}),
            E::ModelMismatch,
        ),
        (
            "k > N",
            json!({"kind": "points2d", "points": two, "k": 3}),
            E::InvalidK,
        ),
        (
            "k = 0",
            json!({"kind": "points2d", "points": two, "k": 0}),
            E::InvalidK,
        ),
        (
            "k_max over the limit",
            json!({"kind": "points2d", "points": two, "k_max": 7}),
            E::InvalidK,
        ),
        (
            "k_max = 0",
            json!({"kind": "points2d", "points": two, "k_max": 0}),
            E::InvalidK,
        ),
        (
            "selection elbow",
            json!({"kind": "points2d", "points": two, "selection": "elbow"}),
            E::InvalidSelection,
        ),
        (
            "too many points",
            json!({"kind": "points2d", "points": vec![[0.5, 0.5]; 51]}),
            E::TooManyPoints,
        ),
        (
            "too many frames",
            json!({"kind": "trajectories", "points": [vec![0.0; 10], vec![1.0; 10]]}),
            E::TooManyFrames,
        ),
        (
            "matrix of too many frames",
            json!({"kind": "trajectories", "trajectory_matrix": vec![vec![1.0, 2.0]; 10]}),
            E::TooManyFrames,
        ),
    ];
    for (what, body, code) in semantic {
        check_error(what, &send(&app, post(&body)).await, code);
        seen.insert(code);
    }
    // Shape errors say what was expected.
    for (what, body, expected) in [
        (
            "image_size of three numbers",
            json!({"kind": "points2d", "points": two, "image_size": [1, 2, 3]}),
            "image_size must be [width, height] in pixels, or for correspondences \
             [[width, height], [width, height]], one per image; got 3 numbers",
        ),
        (
            "image_size of a word",
            json!({"kind": "points2d", "points": two, "image_size": [640, "wide"]}),
            "image_size must be [width, height] in pixels, or for correspondences \
             [[width, height], [width, height]], one per image; got [640,\"wide\"]",
        ),
        (
            "image_size per view for points",
            json!({"kind": "points2d", "points": two, "image_size": [[640, 480], [320, 240]]}),
            "image_size has one [width, height] per image only for correspondences; \
             points2d come from one image",
        ),
        (
            "image_size per view of three numbers",
            json!({"kind": "correspondences", "points": [[0, 0, 1, 1], [2, 2, 3, 3], [4, 5, 6, 7]],
                   "image_size": [[640, 480, 1], [320, 240]]}),
            "image_size must be [width, height] in pixels, or for correspondences \
             [[width, height], [width, height]], one per image; got a pair",
        ),
        (
            "an array for a body",
            json!([1, 2, 3]),
            "the body must be a JSON object",
        ),
    ] {
        let got = send(&app, post(&body)).await;
        check_error(what, &got, E::InvalidRequest);
        let message = got.2["error"]["message"].as_str().unwrap();
        assert!(message.starts_with(expected), "{what}: {message}");
    }
    // A batch body that is not an object shows the batch's own shape.
    let got = send(&app, post_to("/v1/fit/batch", &json!([good()]))).await;
    check_error("an array for a batch body", &got, E::InvalidRequest);
    let message = got.2["error"]["message"].as_str().unwrap();
    assert!(message.contains("{\"requests\": ["), "{message}");
    // A message that quotes the request is cut: a long name is not echoed back whole.
    let huge = "x".repeat(4 * crate::api::error::MAX_MESSAGE);
    for (what, body, code) in [
        (
            "huge model name",
            json!({"kind": "points2d", "points": two, "model": huge}),
            E::UnknownModel,
        ),
        (
            "huge kind",
            json!({"kind": huge, "points": two}),
            E::UnknownKind,
        ),
    ] {
        let got = send(&app, post(&body)).await;
        check_error(what, &got, code);
        let message = got.2["error"]["message"].as_str().unwrap();
        assert!(
            message.len() <= crate::api::error::MAX_MESSAGE && message.ends_with("bytes cut)"),
            "{what}: {} bytes",
            message.len()
        );
    }
    // A batch entry that is not an object says so.
    let batch = json!({"requests": [good(), 5]});
    let got = send(&app, post_to("/v1/fit/batch", &batch)).await;
    assert_eq!(got.0, StatusCode::OK, "{}", got.2);
    let entry = &got.2["results"][1]["error"];
    assert_eq!(entry["code"], "invalid_request");
    assert!(
        entry["message"]
            .as_str()
            .unwrap()
            .contains("must be a JSON object"),
        "{entry}"
    );
    let batch = json!({"requests": vec![good(); LIMITS.max_batch + 1]});
    let got = send(&app, post_to("/v1/fit/batch", &batch)).await;
    check_error("batch over --max-batch", &got, E::TooManyRequestsInBatch);
    seen.insert(E::TooManyRequestsInBatch);
    let routes: Vec<(&str, Request<Body>, ErrorCode)> = vec![
        ("no such route", get("/v1/nothing"), E::NotFound),
        ("no such model", get("/v1/models/nope"), E::NotFound),
        (
            "a path as model",
            get("/v1/models/..%2F..%2Fetc%2Fpasswd"),
            E::NotFound,
        ),
        ("non-UTF-8 model name", get("/v1/models/%FF"), E::NotFound),
        (
            "invalid UTF-8 sequence",
            get("/v1/models/%C3%28"),
            E::NotFound,
        ),
        (
            "name with a bad byte",
            get("/v1/models/tiny%80"),
            E::NotFound,
        ),
        ("no such example", get("/examples/nope.json"), E::NotFound),
        ("GET a fit", get("/v1/fit"), E::MethodNotAllowed),
        (
            "DELETE the models",
            request(Method::DELETE, "/v1/models", None, Body::empty()),
            E::MethodNotAllowed,
        ),
    ];
    for (what, req, code) in routes {
        check_error(what, &send(&app, req).await, code);
        seen.insert(code);
    }

    // The queue full: every admission permit held, the next fit is 429 with Retry-After.
    let held = state.admitted.clone().try_acquire_many_owned(5).unwrap();
    let response = app.clone().oneshot(post(&good())).await.unwrap();
    assert_eq!(response.headers()[header::RETRY_AFTER], "1");
    check_error("queue full", &read(response).await, E::Overloaded);
    drop(held);
    seen.insert(E::Overloaded);

    // No worker free within the request timeout.
    let slow = Arc::new(AppState::new(LIMITS, 1, 1, Duration::from_millis(20)));
    slow.set_models(BTreeMap::from([(
        "tiny".to_string(),
        tiny("tiny", Kind::Trajectories, 4),
    )]));
    let busy = slow.workers.clone().try_acquire_owned().unwrap();
    check_error(
        "timeout",
        &send(&service(&slow), post(&good())).await,
        E::Timeout,
    );
    drop(busy);
    seen.insert(E::Timeout);

    // A client that stops sending its body: answered within the timeout, not waited for.
    let stalled = body_stalled_after(b"{\"kind\": \"trajectories\", \"points\": [[0, ");
    let request = request(Method::POST, "/v1/fit", Some("application/json"), stalled);
    let slow_app = service(&slow);
    let answered = tokio::time::timeout(Duration::from_secs(2), send(&slow_app, request));
    let answer = answered
        .await
        .expect("answered before the test's own deadline");
    check_error("stalled body", &answer, E::BodyTimeout);
    seen.insert(E::BodyTimeout);

    // Before the models are loaded.
    let loading = Arc::new(AppState::new(LIMITS, 1, 1, Duration::from_secs(5)));
    let loading_app = service(&loading);
    check_error(
        "fit while loading",
        &send(&loading_app, post(&good())).await,
        E::NotReady,
    );
    check_error(
        "ready while loading",
        &send(&loading_app, get("/health/ready")).await,
        E::NotReady,
    );
    check_error(
        "models while loading",
        &send(&loading_app, get("/v1/models")).await,
        E::NotReady,
    );
    seen.insert(E::NotReady);

    let untested: Vec<_> = ErrorCode::ALL
        .iter()
        .filter(|c| !seen.contains(c) && !UNREACHABLE.contains(c))
        .collect();
    assert!(untested.is_empty(), "codes without a case: {untested:?}");
    for code in UNREACHABLE {
        assert!(
            !seen.contains(&code),
            "{code} has a case now: drop it from UNREACHABLE"
        );
    }

    // The service still answers a good fit.
    let (status, code, body) = send(&app, post(&good())).await;
    assert_eq!((status, code), (StatusCode::OK, None), "{body}");
    assert_eq!(body["labels"].as_array().map(Vec::len), Some(8), "{body}");
}

/// The error codes, statuses and meanings are one table: distinct wire codes, and statuses of
/// errors.
#[test]
fn error_codes_are_distinct_errors() {
    let codes: BTreeSet<&str> = ErrorCode::ALL.iter().map(|c| c.as_str()).collect();
    assert_eq!(codes.len(), ErrorCode::ALL.len());
    for code in ErrorCode::ALL {
        let status = code.status();
        assert!(
            status.is_client_error() || status.is_server_error(),
            "{code}"
        );
        assert!(!code.meaning().is_empty(), "{code}");
    }
}

/// A request that names no model is answered by its kind's default: the card marked `default`,
/// else the first of the kind by name.
#[tokio::test]
async fn a_request_without_a_model_gets_the_kinds_default() {
    for (marked, expected) in [(None, "a-tracks"), (Some("b-tracks"), "b-tracks")] {
        let state = Arc::new(AppState::new(LIMITS, 1, 4, Duration::from_secs(5)));
        let mut models = BTreeMap::new();
        for name in ["a-tracks", "b-tracks"] {
            let mut model = tiny(name, Kind::Trajectories, 4);
            model.card.default = marked == Some(name);
            models.insert(name.to_string(), model);
        }
        state.set_models(models);
        let (status, _, body) = send(&service(&state), post(&good())).await;
        assert_eq!(status, StatusCode::OK, "{body}");
        assert_eq!(body["model"]["name"], expected, "marked {marked:?}");
    }
}

/// A NaN or an Infinity in the body (Python's json.dumps writes them) is malformed JSON, and the
/// message says why; other syntax errors do not carry that hint.
#[tokio::test]
async fn a_nan_in_the_body_is_named_as_not_json() {
    let state = state(1, 4, Duration::from_secs(60));
    let app = service(&state);
    for (body, hinted) in [
        (r#"{"kind":"points2d","points":[[NaN,1],[0,0]]}"#, true),
        (
            "{\"kind\": \"points2d\",\n \"points\": [[0, Infinity], [0, 0]]}",
            true,
        ),
        (
            r#"{"kind":"points2d","points":[[-Infinity,1],[0,0]]}"#,
            true,
        ),
        (r#"{"kind":"points2d","points":[[0"#, false),
        (r#"{"kind":"points2d","points":[[nan,1],[0,0]]}"#, false),
    ] {
        let message = rejected(
            &app,
            body,
            StatusCode::BAD_REQUEST,
            ErrorCode::MalformedJson,
        )
        .await;
        assert_eq!(
            message.contains("NaN and Infinity are not JSON numbers"),
            hinted,
            "{body}: {message}"
        );
    }
}

/// A whole number the API takes (k, k_max, seed) sent too large, negative or with a fraction is
/// named as such; written as a float without a fraction (`4.0`) it is taken.
#[tokio::test]
async fn a_number_that_is_not_a_whole_number_in_range_is_named() {
    let state = state(1, 4, Duration::from_secs(60));
    let app = service(&state);
    for (field, value, hinted) in [
        ("k", "1000000000000000000000000000000", true),
        ("seed", "18446744073709551616", true),
        ("k", "2.5", true),
        ("k", "-1", true),
        ("k_max", "1e30", true),
        ("seed", "-3.0", true),
        ("k", "\"two\"", false),
    ] {
        let body =
            format!(r#"{{"kind":"points2d","points":[[0,0],[1,1],[2,2]],"{field}":{value}}}"#);
        let message = rejected(
            &app,
            &body,
            StatusCode::UNPROCESSABLE_ENTITY,
            ErrorCode::InvalidRequest,
        )
        .await;
        assert!(message.contains(field), "{message}");
        assert_eq!(
            message.contains("a whole number is expected"),
            hinted,
            "{message}"
        );
    }
    // A client that holds every number as a float (JavaScript, numpy) sends 2.0 for 2.
    let points: Vec<[f64; 2]> = (0..12)
        .map(|i| [f64::from(i % 4), f64::from(i / 4)])
        .collect();
    let mut answers = Vec::new();
    for (k, seed) in [(json!(2), json!(7)), (json!(2.0), json!(7.0))] {
        let body = json!({"kind": "points2d", "points": points, "k": k, "seed": seed});
        let (status, _, answer) = send(&app, post(&body)).await;
        assert_eq!(status, StatusCode::OK, "k {k}: {answer}");
        assert_eq!(answer["k"], json!(2), "{answer}");
        answers.push(answer["labels"].clone());
    }
    assert_eq!(answers[0], answers[1]);
    let body = json!({"kind": "points2d", "points": points, "k_max": 3.0});
    let (status, _, answer) = send(&app, post(&body)).await;
    assert_eq!(status, StatusCode::OK, "{answer}");
}

/// Unrefined, a curve or correspondence fit may answer its network's outlier group -1, which
/// the card's `outliers` allows by default: the request may say so, or turn it off.
#[tokio::test]
async fn outliers_may_be_asked_of_an_unrefined_points2d_fit() {
    let state = state(1, 4, Duration::from_secs(60));
    let app = service(&state);
    let points: Vec<[f64; 2]> = (0..12)
        .map(|i| [f64::from(i % 4), f64::from(i / 4)])
        .collect();
    for outliers in [true, false] {
        let body = json!({"kind": "points2d", "points": points, "refine": false,
                          "outliers": outliers, "k": 2});
        let (status, _, answer) = send(&app, post(&body)).await;
        assert_eq!(status, StatusCode::OK, "outliers {outliers}: {answer}");
    }
}

/// `visible` takes 0 and 1 as any JSON number, or false and true (a numpy mask's `tolist()`):
/// the same mask answers the same.
#[tokio::test]
async fn visible_flags_may_be_numbers_or_booleans() {
    let app = service(&state(1, 4, Duration::from_secs(5)));
    let seen = |one: Value, zero: Value| {
        let mut rows = vec![json!([one.clone(), one.clone()]); 8];
        rows[7] = json!([one, zero]);
        json!({"kind": "trajectories", "points": tracks(), "visible": rows})
    };
    let mut answers = Vec::new();
    for (one, zero) in [
        (json!(1), json!(0)),
        (json!(1.0), json!(0.0)),
        (json!(true), json!(false)),
    ] {
        let (status, _, body) = send(&app, post(&seen(one, zero))).await;
        assert_eq!(status, StatusCode::OK, "{body}");
        answers.push(body["labels"].clone());
    }
    assert!(answers.iter().all(|a| *a == answers[0]), "{answers:?}");
    // A flag that is neither says what a flag is.
    let (_, code, body) = send(&app, post(&seen(json!(1), json!(2)))).await;
    assert_eq!(code, Some(ErrorCode::InvalidRequest));
    let message = body["error"]["message"].as_str().unwrap();
    assert!(message.contains("0 or 1, or false or true"), "{message}");
}

/// A position `visible` marks unseen may be sent as null (a tracker's missing value), in
/// `points` or `trajectory_matrix`, and answers as any number there would; a null anywhere
/// else is refused with its place.
#[tokio::test]
async fn unseen_positions_may_be_null() {
    let app = service(&state(1, 4, Duration::from_secs(5)));
    // Ten 4-frame tracks of two motions (one drifts right, one down and left); the last track
    // is not seen in frame 2, and is placed by the three frames it was seen in.
    let rows: Vec<Vec<f64>> = (0..10)
        .map(|i| {
            let (x, y) = (
                f64::from(i % 5) * 3.0,
                f64::from(i % 3) * 2.0 + 40.0 * f64::from(i / 5),
            );
            (0..4)
                .flat_map(|f| {
                    let t = f64::from(f);
                    if i < 5 {
                        [x + 4.0 * t, y + 0.1 * t * t]
                    } else {
                        [x - 2.0 * t, y + 3.0 * t]
                    }
                })
                .collect()
        })
        .collect();
    let mut seen = vec![json!([1, 1, 1, 1]); 10];
    seen[9] = json!([1, 1, 0, 1]);
    let with =
        |rows: Value| json!({"kind": "trajectories", "points": rows, "k": 2, "visible": seen});
    let mut nulled = json!(rows);
    nulled[9][4] = Value::Null;
    nulled[9][5] = Value::Null;
    let (status, _, numbers) = send(&app, post(&with(json!(rows)))).await;
    assert_eq!(status, StatusCode::OK, "{numbers}");
    assert!(numbers["labels"][9].as_i64().unwrap() >= 0, "{numbers}");
    let (status, _, nulls) = send(&app, post(&with(nulled.clone()))).await;
    assert_eq!(status, StatusCode::OK, "{nulls}");
    assert_eq!(nulls["labels"], numbers["labels"]);
    // The same as a 2F x N matrix: row 2f + 1 holds the y of frame f.
    let matrix: Vec<Vec<Value>> = (0..8)
        .map(|c| (0..10).map(|i| json!(rows[i][c])).collect())
        .collect();
    let mut matrix = json!(matrix);
    matrix[4][9] = Value::Null;
    matrix[5][9] = Value::Null;
    let body = json!({"kind": "trajectories", "trajectory_matrix": matrix.clone(), "k": 2, "visible": seen});
    let (status, _, answer) = send(&app, post(&body)).await;
    assert_eq!(status, StatusCode::OK, "{answer}");
    assert_eq!(answer["labels"], numbers["labels"]);
    // Null where the track was seen, or without visible, in either layout: refused, naming
    // the place; in points2d, a null is just not a number.
    let mut wrong = json!(rows);
    wrong[6][1] = Value::Null;
    for (body, place, says) in [
        (
            with(wrong),
            "points[6][1]",
            "but visible has 1 for track 6, frame 0",
        ),
        (
            json!({"kind": "trajectories", "points": nulled.clone()}),
            "points[9][4]",
            "null only with visible, one row of 0/1 flags per track",
        ),
        (
            json!({"kind": "trajectories", "trajectory_matrix": matrix}),
            "trajectory_matrix[4][9]",
            "null only with visible, one row of 0/1 flags per track",
        ),
    ] {
        let got = send(&app, post(&body)).await;
        check_error(place, &got, ErrorCode::InvalidRequest);
        let message = got.2["error"]["message"].as_str().unwrap();
        assert!(
            message.starts_with(&format!("{place} is null")),
            "{message}"
        );
        assert!(message.contains(says), "{message}");
    }
    // A mask of the wrong shape is named as such, not as the nulls it fails to mark.
    let flags: Vec<Value> = seen.clone();
    let transposed: Vec<Vec<i64>> = (0..4).map(|_| vec![1; 10]).collect();
    let short: Vec<Value> = flags
        .iter()
        .map(|f| json!(f.as_array().unwrap()[..3].to_vec()))
        .collect();
    for (mask, says) in [
        (json!(transposed), "visible has 4 rows for 10 tracks"),
        (json!(short), "visible row 0 has 3 flags for 4 frames"),
    ] {
        let body = json!({"kind": "trajectories", "points": nulled.clone(), "visible": mask});
        let got = send(&app, post(&body)).await;
        let message = got.2["error"]["message"]
            .as_str()
            .unwrap_or_default()
            .to_string();
        assert!(message.starts_with(says), "{message}");
    }
    // Track 0 starts at (0, 0): a tracker's lost-point mark without a mask, a position with one.
    let all_seen = vec![json!([1, 1, 1, 1]); 10];
    for (body, warned) in [
        (
            json!({"kind": "trajectories", "points": rows, "k": 2}),
            true,
        ),
        (
            json!({"kind": "trajectories", "points": rows, "k": 2, "visible": all_seen}),
            false,
        ),
    ] {
        let (status, _, answer) = send(&app, post(&body)).await;
        assert_eq!(status, StatusCode::OK, "{answer}");
        let says = answer["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("exactly (0, 0)"));
        assert_eq!(says, warned, "{answer}");
    }
    let curve = json!({"kind": "points2d", "points": [[0, 0], [1, null], [2, 2]]});
    let got = send(&app, post(&curve)).await;
    check_error("null in points2d", &got, ErrorCode::InvalidRequest);
    let message = got.2["error"]["message"].as_str().unwrap();
    assert_eq!(message, "points[1][1] is null: coordinates are numbers");
}

fn rejections(state: &AppState, reason: &str) -> u64 {
    state
        .telemetry
        .rejections
        .with_label_values(&[reason])
        .get()
}

#[tokio::test]
async fn rejections_are_counted_once_each_by_the_middleware() {
    let state = state(1, 4, Duration::from_secs(60));
    let app = service(&state);
    let reasons = [
        "malformed",
        "too_large",
        "unsupported_media_type",
        "invalid",
        "overloaded",
    ];
    let before: Vec<u64> = reasons.iter().map(|r| rejections(&state, r)).collect();
    let json = Some("application/json");
    send(
        &app,
        request(Method::POST, "/v1/fit", json, Body::from("{")),
    )
    .await;
    send(
        &app,
        request(
            Method::POST,
            "/v1/fit",
            json,
            Body::from(vec![b' '; 2 * BODY_LIMIT]),
        ),
    )
    .await;
    send(
        &app,
        request(Method::POST, "/v1/fit", None, Body::from("{}")),
    )
    .await;
    send(
        &app,
        post(&json!({"kind": "voxels", "points": [[0, 0], [1, 1]]})),
    )
    .await;
    // A batch answers 200; its two failed entries count, its good one does not.
    let batch =
        json!({"requests": [good(), {"kind": "points2d", "points": []}, {"nonsense": true}]});
    let (status, _, body) = send(&app, post_to("/v1/fit/batch", &batch)).await;
    assert_eq!(status, StatusCode::OK, "{body}");
    assert_eq!(body["results"][1]["error"]["code"], "invalid_points");
    assert_eq!(body["results"][2]["error"]["code"], "invalid_request");
    let held = state.admitted.clone().try_acquire_many_owned(5).unwrap();
    send(&app, post(&good())).await;
    drop(held);
    // Not rejections: an unknown route, a wrong method, a good fit.
    send(&app, get("/v1/nothing")).await;
    send(&app, get("/v1/fit")).await;
    send(&app, post(&good())).await;
    let counted: Vec<u64> = reasons
        .iter()
        .zip(&before)
        .map(|(r, b)| rejections(&state, r) - b)
        .collect();
    assert_eq!(counted, [1, 1, 1, 3, 1], "{reasons:?}");
    assert_eq!(rejections(&state, "timeout"), 0);
}

/// Raw HTTP/1.1 over a fresh connection: writes the whole request (head, then body) before it
/// reads anything, as Python's `urllib.request` does; returns the status and the JSON body.
fn write_all_then_read(
    addr: std::net::SocketAddr,
    head: &str,
    body: &[u8],
) -> Result<(u16, Value), String> {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(addr).map_err(|e| e.to_string())?;
    stream
        .set_read_timeout(Some(Duration::from_secs(30)))
        .map_err(|e| e.to_string())?;
    stream
        .write_all(head.as_bytes())
        .map_err(|e| format!("writing the head: {e}"))?;
    stream
        .write_all(body)
        .map_err(|e| format!("writing the body: {e}"))?;
    let mut answer = Vec::new();
    stream
        .read_to_end(&mut answer)
        .map_err(|e| format!("reading the answer: {e}"))?;
    let text = String::from_utf8_lossy(&answer);
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| format!("no status line: {text:?}"))?;
    let json = text
        .split_once("\r\n\r\n")
        .and_then(|(_, b)| serde_json::from_str(b).ok())
        .ok_or_else(|| format!("no JSON body: {text:?}"))?;
    Ok((status, json))
}

/// A body over the limit reaches a client that writes it all before reading as the 413 JSON
/// answer (and a 415 likewise): the server reads and drops the rest of the body before it
/// answers; a client that waits for `100 Continue` gets a 415 without sending its body.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_writes_its_whole_body_first_reads_the_answer() {
    let limit = 16 * 1024 * 1024;
    let state = state(1, 4, Duration::from_secs(60));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let app = router(state, limit);
    let server = tokio::spawn(async move { axum::serve(listener, app).await });
    let client = tokio::task::spawn_blocking(move || {
        let big = vec![b' '; 50_000_000];
        let head = |ct: &str, framing: &str| {
            format!(
                "POST /v1/fit HTTP/1.1\r\nhost: t\r\nconnection: close\r\ncontent-type: {ct}\r\n{framing}\r\n"
            )
        };
        let length = format!("content-length: {}\r\n", big.len());
        let mut chunked = Vec::with_capacity(big.len() + 4096);
        for chunk in big.chunks(1 << 20) {
            chunked.extend_from_slice(format!("{:x}\r\n", chunk.len()).as_bytes());
            chunked.extend_from_slice(chunk);
            chunked.extend_from_slice(b"\r\n");
        }
        chunked.extend_from_slice(b"0\r\n\r\n");
        let te = "transfer-encoding: chunked\r\n";
        let cases = [
            (
                "50 MB, content-length",
                head("application/json", &length),
                &big,
                413,
            ),
            (
                "50 MB, chunked",
                head("application/json", te),
                &chunked,
                413,
            ),
            (
                "50 MB of text/plain",
                head("text/plain", &length),
                &big,
                415,
            ),
        ];
        for (what, head, body, status) in cases {
            let (got, json) =
                write_all_then_read(addr, &head, body).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(got, status, "{what}: {json}");
            let code = if status == 413 {
                "body_too_large"
            } else {
                "unsupported_media_type"
            };
            assert_eq!(json["error"]["code"], code, "{what}: {json}");
        }
        // A client waiting for `100 Continue` gets an answer that needs no body at once.
        let expecting = head("text/plain", &format!("expect: 100-continue\r\n{length}"));
        let (got, json) = write_all_then_read(addr, &expecting, &[]).unwrap();
        assert_eq!(
            (got, &json["error"]["code"]),
            (415, &json!("unsupported_media_type"))
        );
    });
    let outcome = client.await;
    server.abort();
    if let Err(e) = outcome {
        std::panic::resume_unwind(e.into_panic());
    }
}
