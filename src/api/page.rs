//! The page at `/`: one static HTML file (inline CSS and JS, no framework, no network beyond this
//! server) and the examples it can load, all compiled into the binary.

use axum::extract::Path;
use axum::extract::rejection::PathRejection;
use axum::http::header;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;

/// The page (`src/api/page/index.html`).
pub const INDEX: &str = include_str!("page/index.html");

/// The bundled examples by file name, each a `POST /v1/fit` body (`scripts/page-examples.sh`
/// regenerates them; their sources are credited on the page).
pub const EXAMPLES: [(&str, &str); 4] = [
    ("lce.json", include_str!("page/examples/lce.json")),
    (
        "adelaidermf.json",
        include_str!("page/examples/adelaidermf.json"),
    ),
    (
        "two-cameras.json",
        include_str!("page/examples/two-cameras.json"),
    ),
    (
        "kt3dmoseg.json",
        include_str!("page/examples/kt3dmoseg.json"),
    ),
];

/// What the page may load and run: its own inline script and style, requests to this server,
/// and the blob URLs of its downloads; nothing else, and no framing.
const CSP: &str = "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; \
                   connect-src 'self'; img-src 'self' data: blob:; base-uri 'none'; \
                   form-action 'none'; frame-ancestors 'none'";

/// `GET /`.
pub async fn index() -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CONTENT_SECURITY_POLICY, CSP),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        INDEX,
    )
        .into_response()
}

/// `GET /examples/{file}`: one bundled example, or 404 naming the ones there are.
pub async fn example(file: Result<Path<String>, PathRejection>) -> Result<Response, ApiError> {
    let names = || {
        EXAMPLES
            .iter()
            .map(|(n, _)| *n)
            .collect::<Vec<_>>()
            .join(", ")
    };
    let Path(file) = file.map_err(|_| ApiError::not_found(format!("examples: {}", names())))?;
    let (_, body) = EXAMPLES
        .iter()
        .find(|(name, _)| *name == file)
        .ok_or_else(|| {
            ApiError::not_found(format!("no example {file:?}; examples: {}", names()))
        })?;
    Ok(([(header::CONTENT_TYPE, "application/json")], *body).into_response())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn examples_are_fit_requests_and_small() {
        for (name, body) in EXAMPLES {
            assert!(body.len() <= 100_000, "{name}: {} bytes", body.len());
            let v: serde_json::Value = serde_json::from_str(body).expect(name);
            let request: super::super::types::FitRequest =
                serde_json::from_value(v).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(request.points.is_some_and(|p| p.len() >= 50), "{name}");
        }
    }

    #[test]
    fn the_page_is_self_contained() {
        // No framework or CDN: nothing is fetched from another origin.
        for needle in ["http://", "https://", "<script src", "<link"] {
            assert!(!INDEX.contains(needle), "{needle}");
        }
        for (name, _) in EXAMPLES {
            let stem = name.trim_end_matches(".json");
            assert!(
                INDEX.contains(&format!("data-example=\"{stem}\"")),
                "{stem}"
            );
        }
    }
}
