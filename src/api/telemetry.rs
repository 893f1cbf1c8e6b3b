//! Prometheus metrics of the service. Every family is registered, and the common label sets
//! initialised, at start, so `/metrics` is never empty.
//!
//! Rejections (`multifit_rejections_total{reason}`) are counted in one place, the `track`
//! middleware of [`super::routes`], from the response: an error answer carries its
//! [`ErrorCode`] as a response extension (set by `ApiError::into_response`) and counts once under
//! [`rejection_reason`]; a batch answer (200) carries the codes of its failed entries
//! ([`EntryErrors`]) and counts each of them once. Handlers never count. Codes without a reason
//! (unknown route or model, wrong method, not ready, internal failure) are not rejections.

use prometheus::{
    Encoder, Histogram, HistogramOpts, HistogramVec, IntCounterVec, IntGauge, IntGaugeVec, Opts,
    Registry, TextEncoder,
};

use super::error::ErrorCode;

/// The endpoints counted by name (anything else is counted as "other"): the paths of the
/// router's table, [`super::routes::ROUTES`].
pub use super::routes::ENDPOINTS;

/// Reasons a request is rejected before computing.
pub const REJECTIONS: [&str; 6] = [
    "malformed",
    "too_large",
    "unsupported_media_type",
    "invalid",
    "overloaded",
    "timeout",
];

pub struct Telemetry {
    registry: Registry,
    pub requests: IntCounterVec,
    pub rejections: IntCounterVec,
    pub request_seconds: HistogramVec,
    pub queue_seconds: Histogram,
    pub embed_seconds: Histogram,
    pub cluster_seconds: Histogram,
    pub points: Histogram,
    pub chosen_k: Histogram,
    pub queue_depth: IntGauge,
    pub abandoned: prometheus::IntCounter,
    pub model_info: IntGaugeVec,
}

fn seconds_buckets() -> Vec<f64> {
    vec![
        0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0,
    ]
}

impl Telemetry {
    pub fn new() -> Self {
        let registry = Registry::new();
        let requests = IntCounterVec::new(
            Opts::new(
                "multifit_requests_total",
                "HTTP requests by endpoint and status code",
            ),
            &["endpoint", "status"],
        )
        .expect("valid metric");
        let rejections = IntCounterVec::new(
            Opts::new(
                "multifit_rejections_total",
                "Requests rejected before computing, by reason",
            ),
            &["reason"],
        )
        .expect("valid metric");
        let request_seconds = HistogramVec::new(
            HistogramOpts::new(
                "multifit_request_duration_seconds",
                "Request duration by endpoint",
            )
            .buckets(seconds_buckets()),
            &["endpoint"],
        )
        .expect("valid metric");
        let hist = |name: &str, help: &str, buckets: Vec<f64>| {
            Histogram::with_opts(HistogramOpts::new(name, help).buckets(buckets))
                .expect("valid metric")
        };
        let queue_seconds = hist(
            "multifit_queue_duration_seconds",
            "Time a fit waited for a worker",
            seconds_buckets(),
        );
        let embed_seconds = hist(
            "multifit_embed_duration_seconds",
            "Network forward time per fit",
            seconds_buckets(),
        );
        let cluster_seconds = hist(
            "multifit_cluster_duration_seconds",
            "K-means and K selection time per fit",
            seconds_buckets(),
        );
        let points = hist(
            "multifit_points_per_request",
            "Points per fit",
            vec![
                10.0, 50.0, 100.0, 250.0, 500.0, 1000.0, 2500.0, 5000.0, 10000.0, 20000.0, 50000.0,
            ],
        );
        let chosen_k = hist(
            "multifit_chosen_k",
            "Number of structures returned per fit",
            (1..=12).map(f64::from).collect(),
        );
        let queue_depth = IntGauge::new(
            "multifit_queue_depth",
            "Fit requests admitted and not yet answered (body being read, waiting or running)",
        )
        .expect("valid metric");
        let abandoned = prometheus::IntCounter::new(
            "multifit_abandoned_total",
            "Admitted fit requests whose client went away before the answer",
        )
        .expect("valid metric");
        let model_info = IntGaugeVec::new(
            Opts::new("multifit_model_info", "Loaded models (value 1)"),
            &["name", "version", "kind", "weights_sha256"],
        )
        .expect("valid metric");
        for c in [
            Box::new(requests.clone()) as Box<dyn prometheus::core::Collector>,
            Box::new(rejections.clone()),
            Box::new(request_seconds.clone()),
            Box::new(queue_seconds.clone()),
            Box::new(embed_seconds.clone()),
            Box::new(cluster_seconds.clone()),
            Box::new(points.clone()),
            Box::new(chosen_k.clone()),
            Box::new(queue_depth.clone()),
            Box::new(abandoned.clone()),
            Box::new(model_info.clone()),
        ] {
            registry.register(c).expect("unique metric names");
        }
        for reason in REJECTIONS {
            rejections.with_label_values(&[reason]);
        }
        for endpoint in ENDPOINTS {
            request_seconds.with_label_values(&[endpoint]);
            requests.with_label_values(&[endpoint, "200"]);
        }
        Self {
            registry,
            requests,
            rejections,
            request_seconds,
            queue_seconds,
            embed_seconds,
            cluster_seconds,
            points,
            chosen_k,
            queue_depth,
            abandoned,
            model_info,
        }
    }

    /// The Prometheus text exposition.
    pub fn render(&self) -> String {
        let mut buf = Vec::new();
        TextEncoder::new()
            .encode(&self.registry.gather(), &mut buf)
            .expect("text encoding");
        String::from_utf8(buf).expect("utf-8")
    }

    /// Counts one rejection with `code`, under its [`rejection_reason`] (if it has one).
    pub fn reject(&self, code: ErrorCode) {
        if let Some(reason) = rejection_reason(code) {
            self.rejections.with_label_values(&[reason]).inc();
        }
    }
}

/// The reason (one of [`REJECTIONS`]) a request answered with `code` counts under, or `None`
/// when the code is no rejection of a request's content or of its admission.
pub fn rejection_reason(code: ErrorCode) -> Option<&'static str> {
    use ErrorCode as E;
    Some(match code {
        E::MalformedJson | E::BadRequest => "malformed",
        E::BodyTooLarge => "too_large",
        E::UnsupportedMediaType => "unsupported_media_type",
        E::Overloaded => "overloaded",
        E::Timeout | E::BodyTimeout => "timeout",
        E::InvalidRequest
        | E::InvalidPoints
        | E::InvalidClustering
        | E::InvalidK
        | E::InvalidSelection
        | E::UnknownKind
        | E::UnknownModel
        | E::ModelMismatch
        | E::TooManyPoints
        | E::TooManyFrames
        | E::TooManyRequestsInBatch => "invalid",
        E::NotFound | E::MethodNotAllowed | E::NotReady | E::Internal => return None,
    })
}

/// Response extension of a batch answer: the codes of its entries that failed, in order.
#[derive(Debug, Clone, Default)]
pub struct EntryErrors(pub Vec<ErrorCode>);

impl Default for Telemetry {
    fn default() -> Self {
        Self::new()
    }
}
