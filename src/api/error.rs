//! The one JSON error shape of the API, `{"error": {"code", "message"}}`; [`ErrorCode`], every
//! code the API answers with its status and meaning (openapi.yaml lists the same); and the JSON
//! extractor that uses the shape for every rejection (malformed JSON, wrong content type,
//! oversize body).

use axum::body::Bytes;
use axum::extract::{FromRequest, Request};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::cluster::ClusterError;
use crate::data::InputError;
use crate::pipeline::FitError;

/// Declares [`ErrorCode`] from one table: variant, wire code, HTTP status, meaning.
macro_rules! error_codes {
    ($($variant:ident = $code:literal, $status:ident, $meaning:literal;)+) => {
        /// A stable machine-readable error code: each carries its HTTP status and a one-line
        /// meaning. openapi.yaml (`components.schemas.Error`) lists exactly these.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum ErrorCode {
            $(#[doc = $meaning] $variant,)+
        }

        impl ErrorCode {
            /// Every code, in the order of the table.
            pub const ALL: &'static [ErrorCode] = &[$(Self::$variant),+];

            /// The code as it appears in the JSON body.
            pub const fn as_str(self) -> &'static str {
                match self {
                    $(Self::$variant => $code,)+
                }
            }

            /// The HTTP status every answer with this code has.
            pub const fn status(self) -> StatusCode {
                match self {
                    $(Self::$variant => StatusCode::$status,)+
                }
            }

            /// What the code means, in one line.
            pub const fn meaning(self) -> &'static str {
                match self {
                    $(Self::$variant => $meaning,)+
                }
            }
        }
    };
}

error_codes! {
    MalformedJson = "malformed_json", BAD_REQUEST,
        "The body is not JSON: a syntax error, or not UTF-8.";
    BadRequest = "bad_request", BAD_REQUEST,
        "The request body could not be read.";
    NotFound = "not_found", NOT_FOUND,
        "No such route, model or example.";
    MethodNotAllowed = "method_not_allowed", METHOD_NOT_ALLOWED,
        "The route does not take this method.";
    BodyTooLarge = "body_too_large", PAYLOAD_TOO_LARGE,
        "The body is larger than the server's --body-limit.";
    UnsupportedMediaType = "unsupported_media_type", UNSUPPORTED_MEDIA_TYPE,
        "The content type is not application/json (or application/*+json).";
    InvalidRequest = "invalid_request", UNPROCESSABLE_ENTITY,
        "JSON of the wrong shape: unknown, missing or mistyped fields, or fields that clash.";
    InvalidPoints = "invalid_points", UNPROCESSABLE_ENTITY,
        "Unusable points or image_size: too few rows, wrong widths, non-finite or huge values.";
    InvalidClustering = "invalid_clustering", UNPROCESSABLE_ENTITY,
        "The clustering parameters are inconsistent.";
    InvalidK = "invalid_k", UNPROCESSABLE_ENTITY,
        "k outside 1..=N (the number of points, or those the model reads: repeated points once, far points set apart, a dense set thinned), or k_max outside 1..=--max-k-max.";
    InvalidSelection = "invalid_selection", UNPROCESSABLE_ENTITY,
        "selection is neither sod nor silhouette.";
    UnknownKind = "unknown_kind", UNPROCESSABLE_ENTITY,
        "kind is not points2d, correspondences or trajectories.";
    UnknownModel = "unknown_model", UNPROCESSABLE_ENTITY,
        "No loaded model has that name, or none serves the request's kind.";
    ModelMismatch = "model_mismatch", UNPROCESSABLE_ENTITY,
        "The model takes another kind or row width.";
    TooManyPoints = "too_many_points", UNPROCESSABLE_ENTITY,
        "More points than the server's --max-points.";
    TooManyFrames = "too_many_frames", UNPROCESSABLE_ENTITY,
        "Rows of more than 2 x --max-frames values.";
    TooManyRequestsInBatch = "too_many_requests_in_batch", UNPROCESSABLE_ENTITY,
        "More batch entries than the server's --max-batch.";
    Overloaded = "overloaded", TOO_MANY_REQUESTS,
        "The request queue is full; retry after Retry-After seconds.";
    Internal = "internal", INTERNAL_SERVER_ERROR,
        "An unexpected failure in the server.";
    BodyTimeout = "body_timeout", REQUEST_TIMEOUT,
        "The request body did not arrive within --request-timeout-ms.";
    Timeout = "timeout", SERVICE_UNAVAILABLE,
        "The fit did not finish within --request-timeout-ms, queueing included.";
    NotReady = "not_ready", SERVICE_UNAVAILABLE,
        "The models are still loading, or the server is draining to stop.";
}

impl std::fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An API failure: a code (which fixes the HTTP status) and a human message. As a response it
/// carries its [`ErrorCode`] as an extension, which the metrics middleware counts.
#[derive(Debug, Clone, PartialEq)]
pub struct ApiError {
    pub code: ErrorCode,
    pub message: String,
    /// Seconds for a `Retry-After` header (429).
    pub retry_after: Option<u64>,
}

#[derive(Serialize)]
pub struct ErrorBody<'a> {
    pub error: ErrorDetail<'a>,
}

#[derive(Serialize)]
pub struct ErrorDetail<'a> {
    pub code: &'a str,
    pub message: &'a str,
}

/// The longest message an error answers with, in bytes: a message that quotes the request (an
/// unknown model name, a value of the wrong type) is cut there, so a huge value is not echoed.
pub const MAX_MESSAGE: usize = 512;

/// `message` cut to [`MAX_MESSAGE`] bytes (at a character boundary), saying how much was cut.
fn clip(message: String) -> String {
    if message.len() <= MAX_MESSAGE {
        return message;
    }
    let mut end = MAX_MESSAGE - 48;
    while !message.is_char_boundary(end) {
        end -= 1;
    }
    format!(
        "{}... ({} more bytes cut)",
        &message[..end],
        message.len() - end
    )
}

impl ApiError {
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        Self {
            code,
            message: clip(message.into()),
            retry_after: None,
        }
    }
    /// `what` (the body, a batch entry) is JSON but not the object a fit request is.
    pub fn not_an_object(what: &str) -> Self {
        Self::not_an_object_like(what, FIT_EXAMPLE)
    }
    /// `what` is JSON but not an object; `example` shows one.
    fn not_an_object_like(what: &str, example: &str) -> Self {
        Self::new(
            ErrorCode::InvalidRequest,
            format!("{what} must be a JSON object, such as {example}"),
        )
    }
    pub fn not_found(message: impl Into<String>) -> Self {
        Self::new(ErrorCode::NotFound, message)
    }
    pub fn overloaded() -> Self {
        Self {
            retry_after: Some(1),
            ..Self::new(
                ErrorCode::Overloaded,
                "the request queue is full; retry later",
            )
        }
    }
    pub fn timeout() -> Self {
        Self::new(
            ErrorCode::Timeout,
            "the request did not finish within the server's timeout",
        )
    }
    pub fn not_ready(message: impl Into<String>) -> Self {
        Self::new(ErrorCode::NotReady, message)
    }
    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(ErrorCode::Internal, message)
    }

    /// The HTTP status, the code's.
    pub fn status(&self) -> StatusCode {
        self.code.status()
    }

    /// The JSON body, also used inside batch results.
    pub fn body(&self) -> serde_json::Value {
        serde_json::to_value(ErrorBody {
            error: ErrorDetail {
                code: self.code.as_str(),
                message: &self.message,
            },
        })
        .expect("serialisable")
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut response = (self.status(), axum::Json(self.body())).into_response();
        if let Some(secs) = self.retry_after {
            response
                .headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(secs));
        }
        response.extensions_mut().insert(self.code);
        response
    }
}

impl From<InputError> for ApiError {
    fn from(e: InputError) -> Self {
        Self::new(ErrorCode::InvalidPoints, e.to_string())
    }
}

impl From<ClusterError> for ApiError {
    fn from(e: ClusterError) -> Self {
        let code = match e {
            ClusterError::KOutOfRange { .. } => ErrorCode::InvalidK,
            _ => ErrorCode::InvalidClustering,
        };
        Self::new(code, e.to_string())
    }
}

impl From<FitError> for ApiError {
    fn from(e: FitError) -> Self {
        match e {
            FitError::Cluster(c) => c.into(),
            e @ FitError::KAboveRead { .. } => Self::new(ErrorCode::InvalidK, e.to_string()),
            other => Self::new(ErrorCode::ModelMismatch, other.to_string()),
        }
    }
}

/// `axum::Json`, but every rejection answers with [`ApiError`]'s JSON shape, and the status
/// follows what is wrong: 415 for a content type that is not JSON, 413 past the body limit, 400
/// for a body that is not JSON at all (checked by a syntax-only pass), 422 for JSON of the wrong
/// shape or with a number beyond f64's range (`1e309` is valid JSON but not a finite value).
pub struct ApiJson<T>(pub T);

/// `application/json`, or any `application/*+json`, parameters allowed (as axum's `Json`).
fn is_json(headers: &HeaderMap) -> bool {
    let Some(value) = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
    else {
        return false;
    };
    let mime = value
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    mime == "application/json" || (mime.starts_with("application/") && mime.ends_with("+json"))
}

/// The shortest fit request, for messages.
const FIT_EXAMPLE: &str = r#"{"kind": "points2d", "points": [[x, y], ...]}"#;

/// A request body the API parses: its shape in one line, for the message that a body of
/// another JSON type gets.
pub trait RequestBody: DeserializeOwned {
    const EXAMPLE: &'static str;
}

impl RequestBody for super::types::FitRequest {
    const EXAMPLE: &'static str = FIT_EXAMPLE;
}

impl RequestBody for super::types::BatchRequest {
    const EXAMPLE: &'static str =
        r#"{"requests": [{"kind": "points2d", "points": [[x, y], ...]}, ...]}"#;
}

/// Whether the JSON syntax error at `line` and `column` (1-based, as serde_json counts them)
/// sits on a NaN or an Infinity, which JavaScript and Python's json module write but JSON lacks.
fn not_a_json_number(bytes: &[u8], line: usize, column: usize) -> bool {
    let Some(text) = bytes.split(|&b| b == b'\n').nth(line.saturating_sub(1)) else {
        return false;
    };
    let at = column.saturating_sub(1).min(text.len());
    // serde_json reports the column of the first byte it could not take, or the one after.
    [at, at.saturating_sub(1)].iter().any(|&i| {
        let rest = &text[i.min(text.len())..];
        [&b"NaN"[..], b"Infinity", b"-Infinity"]
            .iter()
            .any(|word| rest.starts_with(word))
    })
}

/// Parses a JSON body into `T`; errors name the path of the offending value.
pub fn parse_json<T: RequestBody>(bytes: &[u8]) -> Result<T, ApiError> {
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let parsed = serde_path_to_error::deserialize(&mut de)
        .map_err(|e| e.to_string())
        .and_then(|v| de.end().map(|()| v).map_err(|e| e.to_string()));
    parsed.map_err(|message| {
        // Not JSON at all (RFC 8259: UTF-8 text of the JSON grammar): 400. JSON of the wrong
        // shape: 422.
        if let Err(e) = std::str::from_utf8(bytes) {
            return ApiError::new(
                ErrorCode::MalformedJson,
                format!("the body is not UTF-8: {e}"),
            );
        }
        if let Err(syntax) = serde_json::from_slice::<serde::de::IgnoredAny>(bytes) {
            let hint = if not_a_json_number(bytes, syntax.line(), syntax.column()) {
                " (NaN and Infinity are not JSON numbers: drop the row, or for tracks send null \
                 where `visible` marks the position unseen; Python's json.dumps writes them \
                 unless allow_nan=False)"
            } else {
                ""
            };
            return ApiError::new(ErrorCode::MalformedJson, format!("{syntax}{hint}"));
        }
        // Every body the API takes is an object: say so rather than name a field of it.
        if bytes.iter().find(|b| !b.is_ascii_whitespace()) != Some(&b'{') {
            return ApiError::not_an_object_like("the body", T::EXAMPLE);
        }
        ApiError::new(ErrorCode::InvalidRequest, message)
    })
}

impl<S, T> FromRequest<S> for ApiJson<T>
where
    T: RequestBody,
    S: Send + Sync,
{
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        if !is_json(req.headers()) {
            return Err(ApiError::new(
                ErrorCode::UnsupportedMediaType,
                "expected a request with `content-type: application/json`",
            ));
        }
        let limit = req
            .extensions()
            .get::<super::routes::BodyLimit>()
            .map(|l| l.0);
        let deadline = req
            .extensions()
            .get::<super::routes::BodyDeadline>()
            .map(|d| d.0);
        let read = Bytes::from_request(req, state);
        let read = match deadline {
            // A client that stalls mid-body is answered, not waited for.
            Some(d) => tokio::time::timeout(d, read).await.map_err(|_| {
                ApiError::new(
                    ErrorCode::BodyTimeout,
                    format!(
                        "the request body did not arrive within the server's timeout of {} ms \
                         (multifit-server --request-timeout-ms)",
                        d.as_millis()
                    ),
                )
            })?,
            None => read.await,
        };
        let bytes = read.map_err(|e| {
            if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
                let message = match limit {
                    Some(n) => format!(
                        "the body is larger than this server's limit of {n} bytes \
                         (multifit-server --body-limit)"
                    ),
                    None => e.body_text(),
                };
                ApiError::new(ErrorCode::BodyTooLarge, message)
            } else {
                ApiError::new(ErrorCode::BadRequest, e.body_text())
            }
        })?;
        parse_json(&bytes).map(Self)
    }
}
