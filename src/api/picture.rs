//! `POST /v1/fit` answered as a picture: the `Accept` rule, and the map from a fit to its SVG
//! ([`crate::render`]).

use axum::http::{HeaderMap, header};
use axum::response::{IntoResponse, Response};

use super::types::FitResponse;
use crate::data::{ImageSize, PointSet};
use crate::render::{Picture, fit_svg};

/// The picture's media type.
pub const SVG: &str = "image/svg+xml";

/// Whether the client asked for the picture: `Accept` lists `image/svg+xml` with a q above zero
/// and not below that of an explicit `application/json`. Wildcards (`*/*`, `image/*`) do not
/// ask for it, and an absent, unknown or malformed `Accept` gets JSON.
pub fn wants_svg(headers: &HeaderMap) -> bool {
    let (mut svg, mut json) = (0.0f32, 0.0f32);
    for value in headers.get_all(header::ACCEPT) {
        let Ok(value) = value.to_str() else { continue };
        for range in value.split(',') {
            let mut parts = range.split(';');
            let mime = parts.next().unwrap_or("").trim().to_ascii_lowercase();
            let q = parts
                .filter_map(|p| p.split_once('='))
                .filter(|(name, _)| name.trim().eq_ignore_ascii_case("q"))
                .find_map(|(_, q)| q.trim().parse::<f32>().ok())
                .filter(|q| q.is_finite())
                .map_or(1.0, |q| q.clamp(0.0, 1.0));
            match mime.as_str() {
                SVG => svg = svg.max(q),
                "application/json" => json = json.max(q),
                _ => {}
            }
        }
    }
    svg > 0.0 && svg >= json
}

/// The SVG of a fit of `points`: the answer's labels, structures, residual curve and scores, the
/// model and K in the title.
pub fn svg(points: &PointSet, image_size: Option<ImageSize>, fit: &FitResponse) -> String {
    let structures: Vec<_> = fit.structures.iter().map(|s| (s.label, &s.model)).collect();
    let residuals: Vec<_> = fit.residuals.iter().map(|r| (r.k, r.r)).collect();
    let scores: Vec<_> = fit.scores.iter().map(|s| (s.k, s.score)).collect();
    fit_svg(&Picture {
        title: format!("{} · K = {} ({})", fit.model.name, fit.k, fit.selection),
        points,
        image_size,
        labels: &fit.labels,
        structures: &structures,
        residuals: &residuals,
        scores: &scores,
        k: fit.k,
        clustered_k: fit.clustered_k,
        selection: &fit.selection,
    })
}

/// The picture as an HTTP answer (`Vary: Accept`, as the same URL also answers JSON).
pub fn response(svg: String) -> Response {
    (
        [
            (header::CONTENT_TYPE, SVG),
            (header::VARY, "accept"),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        svg,
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    fn accept(values: &[&str]) -> bool {
        let mut h = HeaderMap::new();
        for v in values {
            h.append(header::ACCEPT, HeaderValue::from_str(v).unwrap());
        }
        wants_svg(&h)
    }

    #[test]
    fn accept_rule() {
        assert!(accept(&["image/svg+xml"]));
        assert!(accept(&["Image/SVG+XML; charset=utf-8"]));
        assert!(accept(&["text/html, image/svg+xml;q=0.9, */*;q=0.8"]));
        assert!(
            accept(&["image/svg+xml, application/json"]),
            "a tie: the picture"
        );
        assert!(accept(&["application/json;q=0.5", "image/svg+xml"]));
        assert!(!accept(&[]), "absent");
        assert!(!accept(&["*/*"]));
        assert!(!accept(&["image/*"]));
        assert!(!accept(&["text/html"]), "unknown");
        assert!(!accept(&["application/json"]));
        assert!(!accept(&["image/svg+xml;q=0"]));
        assert!(!accept(&["application/json, image/svg+xml;q=0.5"]));
        assert!(!accept(&[";;;,,, q=="]), "malformed");
    }
}
