//! openapi.yaml must describe exactly the routes, methods, error codes and wire types the server
//! has.

mod common;

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use axum::body::Body;
use axum::extract::{MatchedPath, Request};
use axum::http::Method;
use axum::middleware::{self, Next};
use multifit::api::routes::ROUTES;
use multifit::api::telemetry::ENDPOINTS;
use multifit::api::types::{
    FitRequest, FitResponse, KScore, ModelRef, Residual, StructureOut, Timing,
};
use multifit::api::{AppState, ErrorCode, Limits, router};
use multifit::geometry::Model;
use serde_json::Value;
use tower::ServiceExt;
use yaml_rust2::{Yaml, YamlLoader};

/// openapi.yaml as JSON values.
fn spec() -> Value {
    let docs =
        YamlLoader::load_from_str(multifit::api::routes::OPENAPI).expect("openapi.yaml parses");
    assert_eq!(docs.len(), 1, "one YAML document");
    json(&docs[0])
}

fn json(y: &Yaml) -> Value {
    match y {
        Yaml::Real(_) => y
            .as_f64()
            .and_then(serde_json::Number::from_f64)
            .map(Value::Number)
            .unwrap_or_else(|| panic!("not a finite number: {y:?}")),
        Yaml::Integer(i) => Value::from(*i),
        Yaml::String(s) => Value::from(s.as_str()),
        Yaml::Boolean(b) => Value::from(*b),
        Yaml::Array(items) => items.iter().map(json).collect(),
        Yaml::Hash(map) => Value::Object(
            map.iter()
                .map(|(k, v)| {
                    let key = match k {
                        Yaml::String(s) | Yaml::Real(s) => s.clone(),
                        Yaml::Integer(i) => i.to_string(),
                        Yaml::Boolean(b) => b.to_string(),
                        other => panic!("mapping key {other:?}"),
                    };
                    (key, json(v))
                })
                .collect(),
        ),
        Yaml::Null => Value::Null,
        Yaml::Alias(_) | Yaml::BadValue => panic!("unexpected YAML node {y:?}"),
    }
}

fn keys(v: &Value) -> BTreeSet<String> {
    v.as_object().expect("mapping").keys().cloned().collect()
}

fn schema<'a>(spec: &'a Value, name: &str) -> &'a Value {
    &spec["components"]["schemas"][name]
}

#[test]
fn every_route_is_documented_and_every_documented_route_exists() {
    let spec = spec();
    let documented = keys(&spec["paths"]);
    let served: BTreeSet<String> = ENDPOINTS.iter().map(|s| s.to_string()).collect();
    assert_eq!(documented, served);
}

#[test]
fn fit_request_fields_match_the_schema() {
    // serde lists the accepted fields when it meets an unknown one.
    let err = serde_json::from_str::<FitRequest>(r#"{"kind": "points2d", "zzz": 1}"#)
        .unwrap_err()
        .to_string();
    let accepted: BTreeSet<String> = err
        .split("expected one of")
        .nth(1)
        .expect("field list")
        .split(',')
        .map(|f| {
            f.trim()
                .trim_matches(|c: char| c == '`' || c.is_whitespace())
                .split('`')
                .next()
                .unwrap()
                .to_string()
        })
        .filter(|f| !f.is_empty())
        .collect();
    let spec = spec();
    assert_eq!(
        keys(&schema(&spec, "FitRequest")["properties"]),
        accepted,
        "{err}"
    );
}

#[test]
fn fit_response_fields_match_the_schema() {
    let r = FitResponse {
        model: ModelRef {
            name: "m".into(),
            version: "1".into(),
            weights_sha256: Some("0".repeat(64)),
        },
        labels: vec![0, 1],
        k: 2,
        clustered_k: 2,
        selection: "sod".into(),
        residuals: vec![Residual { k: 1, r: 1.0 }],
        scores: vec![KScore { k: 2, score: 0.5 }],
        cluster_sizes: vec![1, 1],
        structures: vec![StructureOut {
            label: 0,
            model: Model::Circle {
                cx: 1.0,
                cy: 2.0,
                r: 3.0,
            },
            inliers: 1,
            rms: 0.1,
        }],
        outliers: 0,
        warnings: vec![
            "points 2 is outside the range the model was validated on (100 to 200)".into(),
        ],
        embeddings: Some(vec![vec![1.0, 0.0], vec![0.0, 1.0]]),
        timing_ms: Timing {
            embed: 1.0,
            cluster: 1.0,
            refine: 0.1,
            total: 2.0,
        },
    };
    let v = serde_json::to_value(&r).unwrap();
    let sent: BTreeSet<String> = v.as_object().unwrap().keys().cloned().collect();
    let spec = spec();
    let s = schema(&spec, "FitResponse");
    assert_eq!(keys(&s["properties"]), sent);
    assert_eq!(
        keys(&s["properties"]["model"]["properties"]),
        v["model"].as_object().unwrap().keys().cloned().collect()
    );
    assert_eq!(
        keys(&s["properties"]["timing_ms"]["properties"]),
        v["timing_ms"]
            .as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect()
    );
    for req in s["required"].as_array().unwrap() {
        assert!(sent.contains(req.as_str().unwrap()));
    }
    // A structure: label, type, params and the counts, as the Structure schema lists them.
    let structure = v["structures"][0].as_object().unwrap();
    assert_eq!(
        keys(&schema(&spec, "Structure")["properties"]),
        structure.keys().cloned().collect()
    );
    assert_eq!(structure["type"], "circle");
    assert_eq!(structure["params"]["r"], 3.0);
}

#[test]
fn shipped_model_cards_match_the_schema() {
    let spec = spec();
    let s = schema(&spec, "ModelCard");
    let props = keys(&s["properties"]);
    let arch = keys(&s["properties"]["architecture"]["properties"]);
    let mut sparse_networks = 0;
    for entry in std::fs::read_dir(common::repo().join("models")).unwrap() {
        let path = entry.unwrap().path().join("model.json");
        let card: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        let have: BTreeSet<String> = card.as_object().unwrap().keys().cloned().collect();
        assert!(
            have.is_subset(&props),
            "{}: undocumented {:?}",
            path.display(),
            have.difference(&props).collect::<Vec<_>>()
        );
        for req in s["required"].as_array().unwrap() {
            assert!(
                have.contains(req.as_str().unwrap()),
                "{}: missing {req:?}",
                path.display()
            );
        }
        let a: BTreeSet<String> = card["architecture"]
            .as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect();
        assert!(
            a.is_subset(&arch),
            "{}: architecture {:?}",
            path.display(),
            a
        );
        let member = keys(&s["properties"]["members"]["items"]["properties"]);
        for m in card["members"].as_array().into_iter().flatten() {
            let have: BTreeSet<String> = m.as_object().unwrap().keys().cloned().collect();
            assert_eq!(have, member, "{}: member {m}", path.display());
        }
        if let Some(sparse) = card.get("sparse") {
            let have: BTreeSet<String> = sparse.as_object().unwrap().keys().cloned().collect();
            let documented = keys(&s["properties"]["sparse"]["properties"]);
            assert_eq!(have, documented, "{}: sparse", path.display());
            sparse_networks += 1;
        }
    }
    // lce reads sparse sets with its second network: the check above ran on it.
    assert!(sparse_networks >= 1);
}

#[test]
fn error_shape_is_documented() {
    let spec = spec();
    let e = schema(&spec, "Error");
    let body = multifit::api::ApiError::not_found("x").body();
    assert_eq!(
        keys(&e["properties"]),
        body.as_object().unwrap().keys().cloned().collect()
    );
    assert_eq!(
        keys(&e["properties"]["error"]["properties"]),
        body["error"].as_object().unwrap().keys().cloned().collect()
    );
}

#[test]
fn every_error_code_is_documented_with_its_status_and_meaning() {
    let spec = spec();
    let code = &schema(&spec, "Error")["properties"]["error"]["properties"]["code"];
    let listed: Vec<&str> = code["enum"]
        .as_array()
        .expect("an enum of codes")
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    let all: Vec<&str> = ErrorCode::ALL.iter().map(|c| c.as_str()).collect();
    assert_eq!(listed, all, "the enum of Error.error.code");
    // The description's table: one row `| code | status | meaning |` per code, in order.
    let rows: Vec<String> = code["description"]
        .as_str()
        .unwrap()
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| code ") && !l.starts_with("| ---"))
        .map(str::to_string)
        .collect();
    let want: Vec<String> = ErrorCode::ALL
        .iter()
        .map(|c| {
            format!(
                "| {} | {} | {} |",
                c.as_str(),
                c.status().as_u16(),
                c.meaning()
            )
        })
        .collect();
    assert_eq!(
        rows,
        want,
        "the table in Error.error.code's description:\n{}",
        want.join("\n")
    );
}

/// The router answers every documented path and method from its own route (axum's
/// `MatchedPath` is that path), and every other method on those paths with 405; the router's
/// table ([`ROUTES`]) is the documented set of paths.
#[tokio::test]
async fn the_router_serves_exactly_the_documented_routes_and_methods() {
    let spec = spec();
    let routed: BTreeSet<String> = ROUTES.iter().map(|r| r.path.to_string()).collect();
    assert_eq!(keys(&spec["paths"]), routed);
    let limits = Limits {
        max_points: 100,
        max_frames: 10,
        max_k_max: 4,
        max_batch: 2,
    };
    let state = Arc::new(AppState::new(limits, 1, 1, Duration::from_secs(5)));
    // Hands the route that answered back with the answer.
    let app =
        router(state, 1 << 16).layer(middleware::from_fn(|req: Request, next: Next| async move {
            let matched = req.extensions().get::<MatchedPath>().cloned();
            let mut response = next.run(req).await;
            if let Some(m) = matched {
                response.extensions_mut().insert(m);
            }
            response
        }));
    let methods = [
        Method::GET,
        Method::POST,
        Method::PUT,
        Method::DELETE,
        Method::PATCH,
    ];
    for (path, operations) in spec["paths"].as_object().unwrap() {
        let uri = path.replace("{name}", "lce").replace("{file}", "lce.json");
        let documented = keys(operations);
        for method in &methods {
            let request = axum::http::Request::builder()
                .method(method.clone())
                .uri(&uri)
                .body(Body::empty())
                .unwrap();
            let response = app.clone().oneshot(request).await.unwrap();
            let matched = response
                .extensions()
                .get::<MatchedPath>()
                .map(|m| m.as_str().to_string());
            let what = format!("{method} {uri}");
            assert_eq!(
                matched.as_deref(),
                Some(path.as_str()),
                "{what}: not routed to {path}"
            );
            let status = response.status().as_u16();
            if documented.contains(&method.as_str().to_ascii_lowercase()) {
                assert_ne!(status, 405, "{what} is documented");
            } else {
                assert_eq!(status, 405, "{what} is not documented");
            }
        }
    }
    // ENDPOINTS, the metrics' names, are the router's paths.
    assert_eq!(
        ENDPOINTS
            .iter()
            .map(|p| p.to_string())
            .collect::<BTreeSet<_>>(),
        routed
    );
}

#[test]
fn every_bundled_example_is_listed() {
    let spec = spec();
    let file = &spec["paths"]["/examples/{file}"]["get"]["parameters"][0];
    assert_eq!(file["name"].as_str(), Some("file"));
    let listed: Vec<&str> = file["schema"]["enum"]
        .as_array()
        .expect("an enum of example files")
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    let served: Vec<&str> = multifit::api::page::EXAMPLES.iter().map(|e| e.0).collect();
    assert_eq!(listed, served, "the enum of /examples/{{file}}");
}
