//! openapi.yaml must describe exactly the routes and wire types the server has.

mod common;

use std::collections::BTreeSet;

use multifit::api::telemetry::ENDPOINTS;
use multifit::api::types::{FitRequest, FitResponse, KScore, ModelRef, Residual, Timing};
use serde_yaml::Value;

fn spec() -> Value {
    serde_yaml::from_str(multifit::api::routes::OPENAPI).expect("openapi.yaml parses")
}

fn keys(v: &Value) -> BTreeSet<String> {
    v.as_mapping()
        .expect("mapping")
        .keys()
        .map(|k| k.as_str().unwrap().to_string())
        .collect()
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
        selection: "sod".into(),
        residuals: vec![Residual { k: 1, r: 1.0 }],
        scores: vec![KScore { k: 2, score: 0.5 }],
        cluster_sizes: vec![1, 1],
        embeddings: Some(vec![vec![1.0, 0.0], vec![0.0, 1.0]]),
        timing_ms: Timing {
            embed: 1.0,
            cluster: 1.0,
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
    for req in s["required"].as_sequence().unwrap() {
        assert!(sent.contains(req.as_str().unwrap()));
    }
}

#[test]
fn shipped_model_cards_match_the_schema() {
    let spec = spec();
    let s = schema(&spec, "ModelCard");
    let props = keys(&s["properties"]);
    let arch = keys(&s["properties"]["architecture"]["properties"]);
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
        for req in s["required"].as_sequence().unwrap() {
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
    }
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
