//! Fits answered as pictures (`Accept: image/svg+xml` on `POST /v1/fit`), the page at `/` and its
//! examples, over HTTP against the real server binary with the shipped models.

mod common;

use common::{Response, Server, send_with};
use serde_json::{Value, json};

fn fit(server: &Server, body: &Value, accept: Option<&str>) -> Response {
    let mut headers = vec![("content-type", "application/json")];
    if let Some(a) = accept {
        headers.push(("accept", a));
    }
    send_with(
        server.addr,
        "POST",
        "/v1/fit",
        &headers,
        serde_json::to_vec(body).unwrap(),
    )
    .expect("POST /v1/fit")
}

fn header<'a>(r: &'a Response, name: &str) -> &'a str {
    r.headers
        .get(name)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
}

fn example(server: &Server, name: &str) -> Value {
    let r = server.get(&format!("/examples/{name}.json"));
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(header(&r, "content-type"), "application/json");
    r.json()
}

fn marks(svg: &str) -> usize {
    svg.matches(r#"class="pt""#).count()
}

#[test]
fn svg_pictures_of_every_example_have_one_mark_per_point() {
    let server = Server::start(&[]);
    for (name, model) in [
        ("lce", "lce"),
        ("adelaidermf", "adelaide-fundamental"),
        ("kt3dmoseg", "kt3dmoseg"),
    ] {
        let body = example(&server, name);
        let n = body["points"].as_array().unwrap().len();
        let r = fit(&server, &body, Some("image/svg+xml"));
        assert_eq!(r.status, 200, "{name}: {}", r.text());
        assert_eq!(header(&r, "content-type"), "image/svg+xml");
        assert_eq!(header(&r, "vary"), "accept");
        let svg = r.text();
        assert!(svg.starts_with("<svg xmlns=\"http://www.w3.org/2000/svg\""));
        assert!(svg.trim_end().ends_with("</svg>"));
        assert_eq!(marks(&svg), n, "{name}");
        // The title names the model and the K of the JSON answer to the same request.
        let json = fit(&server, &body, None).json();
        let k = json["k"].as_u64().unwrap();
        let title = format!(
            "<title>{model} · K = {k} ({})</title>",
            json["selection"].as_str().unwrap()
        );
        assert!(svg.contains(&title), "{name}: {title}");
        assert!(
            svg.contains(&format!(">K = {k}</text>")),
            "{name}: the legend's K"
        );
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
        // Same request, same picture.
        assert_eq!(
            fit(&server, &body, Some("image/svg+xml")).body,
            r.body,
            "{name}"
        );
    }
}

#[test]
fn accept_negotiation_and_errors() {
    let server = Server::start(&[]);
    let body = example(&server, "lce");
    for accept in [
        None,
        Some("*/*"),
        Some("application/json"),
        Some("text/html"),
        Some("image/*"),
        Some("image/svg+xml;q=0"),
        Some("application/json, image/svg+xml;q=0.5"),
    ] {
        let r = fit(&server, &body, accept);
        assert_eq!(r.status, 200, "{accept:?}");
        assert_eq!(header(&r, "content-type"), "application/json", "{accept:?}");
        assert!(r.json()["labels"].is_array(), "{accept:?}");
    }
    for accept in ["image/svg+xml", "text/html, image/svg+xml;q=0.9, */*;q=0.8"] {
        let r = fit(&server, &body, Some(accept));
        assert_eq!(header(&r, "content-type"), "image/svg+xml", "{accept}");
    }

    // Bad input: the same JSON error (status and body) whether or not a picture was asked for.
    let bad = [
        json!({"kind": "points2d", "points": [[0, 0], [1, 1]], "k": 5}),
        json!({"kind": "points2d", "points": [[0, 0], [1]]}),
        json!({"kind": "nope", "points": [[0, 0], [1, 1]]}),
        json!({"kind": "points2d", "points": [[0, 0], [1, 1]], "model": "kt3dmoseg"}),
        json!({"kind": "points2d"}),
    ];
    for b in &bad {
        let plain = fit(&server, b, None);
        let svg = fit(&server, b, Some("image/svg+xml"));
        assert!((400..500).contains(&plain.status), "{b}: {}", plain.status);
        assert_eq!(svg.status, plain.status, "{b}");
        assert_eq!(header(&svg, "content-type"), "application/json", "{b}");
        assert_eq!(svg.json(), plain.json(), "{b}");
        svg.error_code();
    }
    let malformed = send_with(
        server.addr,
        "POST",
        "/v1/fit",
        &[
            ("content-type", "application/json"),
            ("accept", "image/svg+xml"),
        ],
        b"{not json".to_vec(),
    )
    .unwrap();
    assert_eq!(malformed.status, 400);
    assert_eq!(malformed.error_code(), "malformed_json");

    // Batch stays JSON.
    let batch = send_with(
        server.addr,
        "POST",
        "/v1/fit/batch",
        &[
            ("content-type", "application/json"),
            ("accept", "image/svg+xml"),
        ],
        serde_json::to_vec(&json!({"requests": [body]})).unwrap(),
    )
    .unwrap();
    assert_eq!(batch.status, 200);
    assert_eq!(header(&batch, "content-type"), "application/json");
    assert!(batch.json()["results"][0]["labels"].is_array());
}

#[test]
fn the_page_and_its_examples_are_served() {
    let server = Server::start(&[]);
    let page = server.get("/");
    assert_eq!(page.status, 200);
    assert_eq!(header(&page, "content-type"), "text/html; charset=utf-8");
    assert!(header(&page, "content-security-policy").contains("connect-src 'self'"));
    let html = page.text();
    assert!(html.starts_with("<!doctype html>") && html.contains("<form"));
    for name in ["lce", "adelaidermf", "kt3dmoseg"] {
        assert!(html.contains(&format!("data-example=\"{name}\"")));
        let body = example(&server, name);
        assert!(body["points"].as_array().unwrap().len() >= 50);
    }
    assert_eq!(
        example(&server, "lce")["points"].as_array().unwrap().len(),
        200
    );
    let missing = server.get("/examples/nope.json");
    assert_eq!(missing.status, 404);
    assert_eq!(missing.error_code(), "not_found");
    assert!(
        missing.json()["error"]["message"]
            .as_str()
            .unwrap()
            .contains("lce.json")
    );
    let traversal = server.get("/examples/..%2FCargo.toml");
    assert_eq!(traversal.status, 404);
    // Counted under their own endpoints.
    let metrics = server.get("/metrics").text();
    assert!(
        metrics.contains(r#"endpoint="/",status="200""#),
        "{metrics}"
    );
    assert!(metrics.contains(r#"endpoint="/examples/{file}",status="404""#));
}
