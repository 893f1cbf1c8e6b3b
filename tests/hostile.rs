//! A battery of hostile requests against ONE real server. Every case must get the
//! documented answer (the JSON error shape `{"error": {"code", "message"}}` with the documented
//! 4xx status, or a correct 200 where the input is odd but valid), and after every case the
//! server must still answer a known good fit with the same labels it gave before the battery.
//!
//! Statuses (openapi.yaml, `components.responses.Error`): 400 malformed JSON; 404 unknown route or
//! model; 405 wrong method; 413 body too large; 415 not JSON; 422 well-formed but invalid
//! (including unknown fields: `FitRequest` is `deny_unknown_fields`, `additionalProperties: false`).
//! Codes: src/api/error.rs and src/api/types.rs.
//!
//! The server runs with its default limits (64 MiB body, 20000 points, 500 frames, k_max <= 20,
//! 32 requests per batch), so the battery also checks the documented defaults.
//!
//! The error table of single requests, without a process, is in src/api/tests.rs.

mod common;

use std::fmt::Write as _;
use std::time::Instant;

use common::{Response, Server, send};
use serde_json::{Value, json};

/// What a case must answer.
#[derive(Debug, Clone)]
enum Expect {
    /// The JSON error shape with this status and code.
    Error(u16, &'static str),
    /// A 200 fit answer with one label per point (n points).
    Fit(usize),
    /// A 200 batch answer; per entry a fit of n points (`Ok(n)`) or an error code (`Err`).
    Batch(Vec<Result<usize, &'static str>>),
}

struct Case {
    name: String,
    method: &'static str,
    path: String,
    content_type: Option<&'static str>,
    body: Vec<u8>,
    /// Send the body with `transfer-encoding: chunked` (no content-length).
    chunked: bool,
    expect: Expect,
}

const JSON: Option<&str> = Some("application/json");

/// The known good request sent before, between and after the cases.
fn good() -> Value {
    json!({
        "kind": "points2d",
        "points": [[0, 0], [1, 0.02], [2, 0], [3, 0.01], [0, 5], [1, 5.01], [2, 5], [3, 4.99]],
        "k": 2,
        "seed": 7
    })
}
const GOOD_N: usize = 8;

/// A fit body whose `points` are `rows`, other fields from `extra` (a JSON object).
fn with_points(rows: Value, extra: Value) -> Value {
    let mut body = json!({"kind": "points2d", "points": rows});
    for (k, v) in extra.as_object().unwrap() {
        body[k] = v.clone();
    }
    body
}

/// The good request with some fields replaced (a `null` is sent as `null`; [`without`] drops a
/// field).
fn good_with(changes: Value) -> Value {
    let mut body = good();
    for (k, v) in changes.as_object().unwrap() {
        body[k] = v.clone();
    }
    body
}

fn without(mut body: Value, field: &str) -> Value {
    body.as_object_mut().unwrap().remove(field);
    body
}

/// `{"kind":"points2d","points":[[..],..]` with n rows, then `tail`; built as bytes directly so
/// a million rows cost milliseconds.
fn many_points(n: usize, tail: &str) -> Vec<u8> {
    let mut s = String::with_capacity(n * 10 + 64);
    s.push_str(r#"{"kind":"points2d","points":["#);
    for i in 0..n {
        if i > 0 {
            s.push(',');
        }
        let _ = write!(s, "[{},{}]", i % 97, i % 89);
    }
    s.push(']');
    s.push_str(tail);
    s.into_bytes()
}

/// A body of at least `bytes` bytes: a well-formed fit request with that many rows.
fn body_of_size(bytes: usize) -> Vec<u8> {
    let mut s = String::with_capacity(bytes + 64);
    s.push_str(r#"{"kind":"points2d","points":[[0,0]"#);
    while s.len() < bytes {
        s.push_str(",[12,34]");
    }
    s.push_str("]}");
    s.into_bytes()
}

/// `depth` opening brackets, then (when `balanced`) as many closing ones.
fn nested(depth: usize, balanced: bool) -> String {
    let mut s = "[".repeat(depth);
    if balanced {
        s.push_str(&"]".repeat(depth));
    }
    s
}

/// Eight correspondences `[x1, y1, x2, y2]` in pixels, two motions.
fn correspondences() -> Value {
    let rows: Vec<Vec<f64>> = (0..8)
        .map(|i| {
            let (x, y) = (100.0 + 37.0 * i as f64, 80.0 + 23.0 * (i % 3) as f64);
            if i < 4 {
                vec![x, y, x + 10.0, y + 5.0]
            } else {
                vec![x, y, x - 20.0, y + 15.0]
            }
        })
        .collect();
    json!(rows)
}

/// Eight trajectories over 5 frames (D = 10), as rows.
fn trajectories() -> Vec<Vec<f64>> {
    (0..8)
        .map(|i| {
            let (x, y) = (200.0 + 41.0 * i as f64, 150.0 + 17.0 * (i % 4) as f64);
            let (dx, dy) = if i < 4 { (3.0, 1.0) } else { (-2.0, 4.0) };
            (0..5)
                .flat_map(|f| [x + dx * f as f64, y + dy * f as f64])
                .collect()
        })
        .collect()
}

fn transpose(rows: &[Vec<f64>]) -> Vec<Vec<f64>> {
    (0..rows[0].len())
        .map(|c| rows.iter().map(|r| r[c]).collect())
        .collect()
}

fn raw(
    cases: &mut Vec<Case>,
    name: &str,
    method: &'static str,
    path: &str,
    content_type: Option<&'static str>,
    body: Vec<u8>,
    expect: Expect,
) {
    cases.push(Case {
        name: name.to_string(),
        method,
        path: path.to_string(),
        content_type,
        body,
        chunked: false,
        expect,
    });
}

/// A `POST /v1/fit` case with a JSON content type.
fn fit(cases: &mut Vec<Case>, name: &str, body: Vec<u8>, expect: Expect) {
    raw(cases, name, "POST", "/v1/fit", JSON, body, expect);
}

fn cases() -> Vec<Case> {
    use Expect::{Batch, Error, Fit};
    let mut cases = Vec::new();
    let two = json!([[0, 0], [1, 1]]);
    let traj = trajectories();
    let mut huge_cell = transpose(&traj);
    huge_cell[3][5] = 1e308;
    let mut ragged_matrix = transpose(&traj);
    ragged_matrix[7].pop();

    // ---- Malformed JSON: 400 malformed_json.
    for (name, body) in [
        (
            "truncated JSON",
            r#"{"kind": "points2d", "points": [[0, 0], [1"#.to_string(),
        ),
        ("truncated inside a string", r#"{"kind": "poi"#.to_string()),
        ("empty body", String::new()),
        ("not JSON at all", "hello".to_string()),
        ("trailing garbage", format!("{} xyz", good())),
        ("two documents", format!("{}{}", good(), good())),
        (
            "trailing comma",
            r#"{"kind":"points2d","points":[[0,0],[1,1],]}"#.to_string(),
        ),
        (
            "single quotes",
            r#"{'kind': 'points2d', 'points': [[0,0],[1,1]]}"#.to_string(),
        ),
        (
            "comment",
            r#"{"kind":"points2d", /* hi */ "points":[[0,0],[1,1]]}"#.to_string(),
        ),
        (
            "NaN token in points",
            r#"{"kind":"points2d","points":[[NaN,1],[0,0]]}"#.to_string(),
        ),
        (
            "Infinity token in points",
            r#"{"kind":"points2d","points":[[Infinity,1],[0,0]]}"#.to_string(),
        ),
        (
            "-Infinity token in points",
            r#"{"kind":"points2d","points":[[-Infinity,1],[0,0]]}"#.to_string(),
        ),
        (
            "NaN token in image_size",
            r#"{"kind":"correspondences","points":[[0,0,1,1],[1,1,2,2]],"image_size":[NaN,480]}"#
                .to_string(),
        ),
        (
            "hex number",
            r#"{"kind":"points2d","points":[[0x10,1],[0,0]]}"#.to_string(),
        ),
        (
            "leading plus",
            r#"{"kind":"points2d","points":[[+1,1],[0,0]]}"#.to_string(),
        ),
        (
            "bad escape in a string",
            r#"{"kind":"points\x2d","points":[[0,0],[1,1]]}"#.to_string(),
        ),
    ] {
        fit(
            &mut cases,
            name,
            body.into_bytes(),
            Error(400, "malformed_json"),
        );
    }
    // A lone surrogate escape is valid JSON grammar (RFC 8259 leaves its meaning open) but no
    // Rust string: well-formed, invalid.
    fit(
        &mut cases,
        "lone surrogate in model name",
        br#"{"kind":"points2d","points":[[0,0],[1,1]],"model":"\ud800"}"#.to_vec(),
        Error(422, "invalid_request"),
    );
    let mut invalid_utf8 = br#"{"kind":"points2d","points":[[0,0],[1,1]],"model":""#.to_vec();
    invalid_utf8.extend_from_slice(&[0xff, 0xfe, 0xc3, 0x28]);
    invalid_utf8.extend_from_slice(br#""}"#);
    fit(
        &mut cases,
        "invalid UTF-8 in a string",
        invalid_utf8,
        Error(400, "malformed_json"),
    );
    fit(
        &mut cases,
        "NUL bytes",
        vec![0u8; 64],
        Error(400, "malformed_json"),
    );

    // ---- Deeply nested arrays (100000 levels). serde_json's recursion limit (128) guards the
    // stack; a typed field fails at its first wrong type (422), an untyped one (batch entries are
    // parsed as serde_json::Value) at the recursion limit (400).
    fit(
        &mut cases,
        "100000 nested arrays as points (balanced)",
        format!(
            r#"{{"kind":"points2d","points":{}}}"#,
            nested(100_000, true)
        )
        .into_bytes(),
        Error(422, "invalid_request"),
    );
    fit(
        &mut cases,
        "100000 nested arrays as model (balanced)",
        format!(
            r#"{{"kind":"points2d","points":[[0,0],[1,1]],"model":{}}}"#,
            nested(100_000, true)
        )
        .into_bytes(),
        Error(422, "invalid_request"),
    );
    // Unbalanced: the body is not JSON, but the parser stops at the first type error (a sequence
    // where FitRequest's first field, a string, is expected) before it can see the missing
    // brackets. Either way it is a 4xx JSON error; this records which.
    fit(
        &mut cases,
        "100000 opening brackets as the whole body (unbalanced)",
        nested(100_000, false).into_bytes(),
        Error(400, "malformed_json"),
    );
    fit(
        &mut cases,
        "100000 nested objects under an unknown field",
        format!(
            r#"{{"kind":"points2d","x":{}null{}}}"#,
            r#"{"a":"#.repeat(100_000),
            "}".repeat(100_000)
        )
        .into_bytes(),
        Error(422, "invalid_request"),
    );
    raw(
        &mut cases,
        "batch entry of 100000 nested arrays",
        "POST",
        "/v1/fit/batch",
        JSON,
        format!(r#"{{"requests":[{}]}}"#, nested(100_000, true)).into_bytes(),
        // Well-formed, but nested beyond the parser's depth limit: invalid as a request.
        Error(422, "invalid_request"),
    );
    raw(
        &mut cases,
        "batch entry of 100000 nested objects",
        "POST",
        "/v1/fit/batch",
        JSON,
        format!(
            r#"{{"requests":[{}null{}]}}"#,
            r#"{"a":"#.repeat(100_000),
            "}".repeat(100_000)
        )
        .into_bytes(),
        Error(422, "invalid_request"),
    );

    // ---- Well-formed JSON of the wrong shape or type: 422 invalid_request.
    let invalid_request: Vec<(&str, Value)> = vec![
        ("body is null", json!(null)),
        ("body is an array", json!([])),
        ("body is a string", json!("points2d")),
        ("body is a number", json!(42)),
        ("empty object (kind missing)", json!({})),
        ("kind missing", without(good(), "kind")),
        ("kind is a number", good_with(json!({"kind": 2}))),
        ("points as a string", good_with(json!({"points": "many"}))),
        (
            "points as an object",
            good_with(json!({"points": {"x": [0, 1], "y": [0, 1]}})),
        ),
        (
            "points as a flat list of numbers",
            good_with(json!({"points": [0, 0, 1, 1, 2, 2]})),
        ),
        (
            "null coordinate",
            good_with(json!({"points": [[null, 1], [0, 0]]})),
        ),
        (
            "string coordinate",
            good_with(json!({"points": [["1", 1], [0, 0]]})),
        ),
        (
            "boolean coordinate",
            good_with(json!({"points": [[true, 1], [0, 0]]})),
        ),
        (
            "nested garbage in points",
            good_with(json!({"points": [[{"a": [1, {"b": null}]}, 2], [0, [[[]]]]]})),
        ),
        ("k as a string", good_with(json!({"k": "2"}))),
        ("k as 2.5", good_with(json!({"k": 2.5}))),
        ("k as -1", good_with(json!({"k": -1}))),
        ("k as 1e30", good_with(json!({"k": 1e30}))),
        ("k as a boolean", good_with(json!({"k": true}))),
        ("visible as a string", good_with(json!({"visible": "all"}))),
        (
            "visible flags of -1",
            good_with(json!({"visible": [[-1], [1]]})),
        ),
        ("negative k", good_with(json!({"k": -2}))),
        (
            "k = 2^64 (overflows usize)",
            good_with(json!({"k": 18446744073709551616.0f64})),
        ),
        ("negative k_max", good_with(json!({"k_max": -1}))),
        ("k_max as a string", good_with(json!({"k_max": "8"}))),
        ("negative seed", good_with(json!({"seed": -1}))),
        ("seed as 1.5", good_with(json!({"seed": 1.5}))),
        ("seed as a string", good_with(json!({"seed": "7"}))),
        ("selection as a number", good_with(json!({"selection": 5}))),
        ("model as a number", good_with(json!({"model": 7}))),
        ("model as an array", good_with(json!({"model": ["lce"]}))),
        (
            "return_embeddings as a string",
            good_with(json!({"return_embeddings": "yes"})),
        ),
        (
            "image_size with one value",
            good_with(json!({"image_size": [640]})),
        ),
        // image_size with three values: src/api/tests.rs.
        (
            "image_size as an object",
            good_with(json!({"image_size": {"w": 640, "h": 480}})),
        ),
        (
            "image_size as a string",
            good_with(json!({"image_size": "640x480"})),
        ),
        (
            "image_size NaN as a string",
            good_with(json!({"image_size": ["NaN", 480]})),
        ),
        ("unknown field", good_with(json!({"colour": "red"}))),
        (
            "unknown field differing in case (K)",
            good_with(json!({"K": 2})),
        ),
        (
            "unknown field with an empty name",
            good_with(json!({"": 1})),
        ),
        (
            "points and trajectory_matrix both",
            good_with(json!({"trajectory_matrix": [[0, 1], [0, 1], [0, 1], [0, 1]]})),
        ),
        (
            "neither points nor trajectory_matrix",
            without(good(), "points"),
        ),
        (
            "trajectory_matrix with kind points2d",
            json!({"kind": "points2d", "trajectory_matrix": [[0, 1], [0, 1], [0, 1], [0, 1]]}),
        ),
    ];
    for (name, body) in invalid_request {
        fit(
            &mut cases,
            name,
            serde_json::to_vec(&body).unwrap(),
            Error(422, "invalid_request"),
        );
    }
    // A whole number written as a float (a JavaScript or numpy client) is taken.
    fit(
        &mut cases,
        "k and seed as 2.0 and 7.0",
        serde_json::to_vec(&good_with(json!({"k": 2.0, "seed": 7.0}))).unwrap(),
        Expect::Fit(GOOD_N),
    );
    fit(
        &mut cases,
        "duplicate field",
        br#"{"kind":"points2d","kind":"points2d","points":[[0,0],[1,1]]}"#.to_vec(),
        Error(422, "invalid_request"),
    );

    // ---- Numbers out of range: the documented bound is |v| <= 1e9, finite (422 invalid_points).
    // (1e309, beyond f64's range, is 422 invalid_request: src/api/tests.rs.)
    for (name, v) in [
        ("1e308 coordinate", 1e308),
        ("-1e308 coordinate", -1e308),
        ("f64::MAX coordinate", f64::MAX),
        ("1e9 + 1 coordinate", 1e9 + 1.0),
        ("-1.0000001e9 coordinate", -1.0000001e9),
    ] {
        fit(
            &mut cases,
            name,
            serde_json::to_vec(&good_with(json!({"points": [[0, 0], [v, 1], [2, 2]]}))).unwrap(),
            Error(422, "invalid_points"),
        );
    }
    fit(
        &mut cases,
        "1e308 in a trajectory_matrix",
        serde_json::to_vec(&json!({"kind": "trajectories", "trajectory_matrix": huge_cell}))
            .unwrap(),
        Error(422, "invalid_points"),
    );
    fit(
        &mut cases,
        "1e308 in correspondences",
        serde_json::to_vec(&json!({"kind": "correspondences", "points": [[0, 0, 1, 1], [1e308, 1, 2, 2], [3, 3, 4, 4]]})).unwrap(),
        Error(422, "invalid_points"),
    );
    // Tracks of another length than the model reads, and refinement of degenerate groups
    // (coincident, collinear, too few points for the model): answered 200, never NaN.
    fit(
        &mut cases,
        "trajectories, 2 and 4 frames for the 5-frame model",
        br#"{"kind":"trajectories","points":[[0,0,1,1],[1,1,2,2],[5,5,5,6]],"refine":true}"#
            .to_vec(),
        Fit(3),
    );
    // Tracks seen in some frames: the others are fitted, each partly seen track placed or -1,
    // whatever its values where it was not seen; never NaN.
    let mut seen = vec![vec![1u8; 5]; 8];
    seen[2] = vec![0, 1, 1, 1, 0];
    seen[5] = vec![1, 0, 0, 0, 0];
    seen[6] = vec![0, 0, 0, 0, 0];
    let mut hidden = traj.clone();
    hidden[2][0] = 1e9;
    hidden[5][9] = -1e9;
    fit(
        &mut cases,
        "trajectories seen in some frames, wild values where unseen",
        serde_json::to_vec(
            &json!({"kind": "trajectories", "points": hidden, "visible": seen,
                                   "refine": true, "k": 2}),
        )
        .unwrap(),
        Fit(8),
    );
    fit(
        &mut cases,
        "trajectory_matrix seen in some frames, K chosen, no refinement",
        serde_json::to_vec(
            &json!({"kind": "trajectories", "trajectory_matrix": transpose(&traj),
                                   "visible": seen, "refine": false}),
        )
        .unwrap(),
        Fit(8),
    );
    fit(
        &mut cases,
        "trajectories of 40 identical frames, refined",
        serde_json::to_vec(
            &json!({"kind": "trajectories", "points": [vec![3.0; 80], vec![3.0; 80], vec![4.0; 80]],
                                   "refine": true, "k": 2}),
        )
        .unwrap(),
        Fit(3),
    );
    fit(
        &mut cases,
        "collinear correspondences, refined",
        br#"{"kind":"correspondences","points":[[0,0,1,0],[1,0,2,0],[2,0,3,0],[3,0,4,0],[4,0,5,0]],"refine":true,"k":2}"#.to_vec(),
        Fit(5),
    );
    fit(
        &mut cases,
        "three points in three groups, refined, outlier threshold",
        br#"{"kind":"points2d","points":[[0,0],[1e9,1e9],[-1e9,5]],"refine":true,"k":3,"outlier_threshold":1e-300}"#.to_vec(),
        Fit(3),
    );
    // Sets large enough for refinement's hypotheses (models proposed from neighbourhoods,
    // swapped in or added while K is chosen) made of degenerate pieces.
    let coincident_and_line: Vec<[f64; 2]> = (0..60)
        .map(|_| [1.0, 1.0])
        .chain((0..20).map(|i| [f64::from(i), 2.0 * f64::from(i)]))
        .collect();
    fit(
        &mut cases,
        "60 coincident points and a line of 20, refined, K chosen",
        serde_json::to_vec(
            &json!({"kind": "points2d", "points": coincident_and_line, "refine": true}),
        )
        .unwrap(),
        Fit(80),
    );
    let tiny_and_huge: Vec<[f64; 2]> = (0..60)
        .map(|i| {
            let t = f64::from(i) * 0.37;
            if i % 2 == 0 {
                [1e-7 * t.cos(), 1e-7 * t.sin()]
            } else {
                [1e9 * t.cos(), -1e9 * t.sin()]
            }
        })
        .collect();
    fit(
        &mut cases,
        "a circle of radius 1e-7 inside one of 1e9, refined, K chosen",
        serde_json::to_vec(&json!({"kind": "points2d", "points": tiny_and_huge, "refine": true}))
            .unwrap(),
        Fit(60),
    );
    let pairs: Vec<[f64; 4]> = (0..40)
        .map(|_| [5.0, 5.0, 6.0, 6.0])
        .chain((0..30).map(|i| {
            let x = f64::from(i);
            [x, 0.0, x + 1.0, 0.0]
        }))
        .collect();
    fit(
        &mut cases,
        "40 coincident correspondences and 30 collinear, refined, K chosen",
        serde_json::to_vec(&json!({"kind": "correspondences", "points": pairs, "refine": true}))
            .unwrap(),
        Fit(70),
    );
    // Odd but valid numbers: answered 200.
    fit(
        &mut cases,
        "coordinates at exactly +-1e9",
        serde_json::to_vec(&good_with(
            json!({"points": [[1e9, -1e9], [-1e9, 1e9], [1e9, 1e9], [-1e9, -1e9], [0, 0], [1, 1]]}),
        ))
        .unwrap(),
        Fit(6),
    );
    fit(
        &mut cases,
        "denormal coordinates (5e-324)",
        serde_json::to_vec(&good_with(
            json!({"points": [[5e-324, 0], [0, 5e-324], [5e-324, 5e-324], [0, 0]]}),
        ))
        .unwrap(),
        Fit(4),
    );
    // Copies of a point are one point: no two structures to part.
    fit(
        &mut cases,
        "all points identical, k = 2",
        serde_json::to_vec(&good_with(json!({"points": vec![[3.5, -2.25]; 8]}))).unwrap(),
        Error(422, "invalid_k"),
    );
    fit(
        &mut cases,
        "all points identical, k = 1",
        serde_json::to_vec(&good_with(json!({"points": vec![[3.5, -2.25]; 8], "k": 1}))).unwrap(),
        Fit(8),
    );
    fit(
        &mut cases,
        "1e308 written with a long mantissa is still 1e308",
        br#"{"kind":"points2d","points":[[0,0],[0.99999999999999999999999999999e308,1]]}"#.to_vec(),
        Error(422, "invalid_points"),
    );
    fit(
        &mut cases,
        "1e-400 underflows to 0 and is valid",
        br#"{"kind":"points2d","points":[[0,0],[1e-400,1],[2,2],[3,3]],"k":2}"#.to_vec(),
        Fit(4),
    );

    // ---- k, k_max, seed, selection.
    for (name, changes, code) in [
        ("k = 0", json!({"k": 0}), "invalid_k"),
        ("k = N + 1", json!({"k": GOOD_N + 1}), "invalid_k"),
        ("k = 10^12", json!({"k": 1_000_000_000_000u64}), "invalid_k"),
        ("k = u64::MAX", json!({"k": u64::MAX}), "invalid_k"),
        ("k_max = 0", json!({"k_max": 0}), "invalid_k"),
        (
            "k_max = 21 (over --max-k-max)",
            json!({"k_max": 21}),
            "invalid_k",
        ),
        (
            "k_max = 10^12",
            json!({"k_max": 1_000_000_000_000u64}),
            "invalid_k",
        ),
        (
            "k_max = u64::MAX with k given",
            json!({"k_max": u64::MAX}),
            "invalid_k",
        ),
        (
            "selection bogus",
            json!({"selection": "bogus", "k": null}),
            "invalid_selection",
        ),
        (
            "selection empty",
            json!({"selection": "", "k": null}),
            "invalid_selection",
        ),
        (
            "selection in upper case",
            json!({"selection": "SOD", "k": null}),
            "invalid_selection",
        ),
        (
            "k and k_max",
            json!({"k": 2, "k_max": 3}),
            "invalid_request",
        ),
        (
            "k and selection",
            json!({"k": 2, "selection": "sod"}),
            "invalid_request",
        ),
    ] {
        fit(
            &mut cases,
            name,
            serde_json::to_vec(&good_with(changes)).unwrap(),
            Error(422, code),
        );
    }
    for (name, changes, n) in [
        ("k = N", json!({"k": GOOD_N}), GOOD_N),
        ("k = 1", json!({"k": 1}), GOOD_N),
        ("k null means automatic", json!({"k": null}), GOOD_N),
        ("seed = u64::MAX", json!({"seed": u64::MAX}), GOOD_N),
        ("seed = 0", json!({"seed": 0}), GOOD_N),
        (
            "k_max = 20 > N is capped at N",
            json!({"k": null, "k_max": 20}),
            GOOD_N,
        ),
        (
            "k_max = 20 > N with silhouette",
            json!({"k": null, "k_max": 20, "selection": "silhouette"}),
            GOOD_N,
        ),
        ("k_max = 1", json!({"k": null, "k_max": 1}), GOOD_N),
    ] {
        fit(
            &mut cases,
            name,
            serde_json::to_vec(&good_with(changes)).unwrap(),
            Fit(n),
        );
    }
    fit(
        &mut cases,
        "two points, automatic K",
        serde_json::to_vec(&with_points(two.clone(), json!({}))).unwrap(),
        Fit(2),
    );
    fit(
        &mut cases,
        "seed = 2^64 (overflows u64)",
        br#"{"kind":"points2d","points":[[0,0],[1,1]],"seed":18446744073709551616}"#.to_vec(),
        Error(422, "invalid_request"),
    );
    fit(
        &mut cases,
        "k = 10^30 as an integer literal",
        br#"{"kind":"points2d","points":[[0,0],[1,1]],"k":1000000000000000000000000000000}"#
            .to_vec(),
        Error(422, "invalid_request"),
    );

    // ---- Shapes: 422 invalid_points (or the more precise code).
    for (name, rows, code) in [
        ("empty points", json!([]), "invalid_points"),
        ("empty rows", json!([[], []]), "invalid_points"),
        ("one point", json!([[1, 2]]), "invalid_points"),
        (
            "rows of mixed length (short later)",
            json!([[0, 0], [1, 1], [2]]),
            "invalid_points",
        ),
        (
            "rows of mixed length (long later)",
            json!([[0, 0], [1, 1, 1]]),
            "invalid_points",
        ),
        (
            "rows of mixed length (short first)",
            json!([[0], [1, 1], [2, 2]]),
            "invalid_points",
        ),
        (
            "a trailing empty row",
            json!([[0, 0], [1, 1], []]),
            "invalid_points",
        ),
        (
            "rows of 3 for points2d",
            json!([[0, 0, 0], [1, 1, 1]]),
            "invalid_points",
        ),
        (
            "rows of 1 for points2d",
            json!([[0], [1]]),
            "invalid_points",
        ),
    ] {
        fit(
            &mut cases,
            name,
            serde_json::to_vec(&with_points(rows, json!({}))).unwrap(),
            Error(422, code),
        );
    }
    let traj_rows = json!(traj);
    for (name, body, code) in [
        (
            "correspondences with rows of 2",
            json!({"kind": "correspondences", "points": [[0, 0], [1, 1]]}),
            "invalid_points",
        ),
        (
            "trajectories with odd rows (7 values)",
            json!({"kind": "trajectories", "points": [vec![0.0; 7], vec![1.0; 7]]}),
            "invalid_points",
        ),
        (
            "trajectories with 2 values (one frame)",
            json!({"kind": "trajectories", "points": [[0, 0], [1, 1]]}),
            "invalid_points",
        ),
        (
            "trajectories of 501 frames (over --max-frames)",
            json!({"kind": "trajectories", "points": [vec![0.0; 1002], vec![1.0; 1002]]}),
            "too_many_frames",
        ),
        (
            "trajectory_matrix with odd rows (5)",
            json!({"kind": "trajectories", "trajectory_matrix": transpose(&traj)[..5].to_vec()}),
            "invalid_points",
        ),
        (
            "trajectory_matrix with 2 rows",
            json!({"kind": "trajectories", "trajectory_matrix": [[0, 1, 2], [0, 1, 2]]}),
            "invalid_points",
        ),
        (
            "trajectory_matrix empty",
            json!({"kind": "trajectories", "trajectory_matrix": []}),
            "invalid_points",
        ),
        (
            "trajectory_matrix of empty rows",
            json!({"kind": "trajectories", "trajectory_matrix": vec![Vec::<f64>::new(); 10]}),
            "invalid_points",
        ),
        (
            "trajectory_matrix with one column",
            json!({"kind": "trajectories", "trajectory_matrix": vec![vec![1.0]; 10]}),
            "invalid_points",
        ),
        (
            "trajectory_matrix ragged",
            json!({"kind": "trajectories", "trajectory_matrix": ragged_matrix}),
            "invalid_points",
        ),
        (
            "visible of one track",
            json!({"kind": "trajectories", "points": traj_rows, "visible": [[1, 1, 1, 1, 1]]}),
            "invalid_points",
        ),
        (
            "visible rows of 6 flags for 5 frames",
            json!({"kind": "trajectories", "points": traj_rows, "visible": vec![vec![1; 6]; 8]}),
            "invalid_points",
        ),
        (
            "visible flag 7",
            json!({"kind": "trajectories", "points": traj_rows, "visible": vec![vec![1, 1, 7, 1, 1]; 8]}),
            "invalid_request",
        ),
        (
            "no track seen in every frame",
            json!({"kind": "trajectories", "points": traj_rows, "visible": vec![vec![0, 1, 1, 1, 1]; 8]}),
            "invalid_points",
        ),
        (
            "trajectory_matrix of 1002 rows (over --max-frames)",
            json!({"kind": "trajectories", "trajectory_matrix": vec![vec![1.0, 2.0]; 1002]}),
            "too_many_frames",
        ),
        (
            "image_size zero",
            json!({"kind": "trajectories", "points": traj_rows, "image_size": [0, 480]}),
            "invalid_points",
        ),
        (
            "image_size negative",
            json!({"kind": "trajectories", "points": traj_rows, "image_size": [640, -480]}),
            "invalid_points",
        ),
        (
            "image_size negative zero",
            json!({"kind": "trajectories", "points": traj_rows, "image_size": [-0.0, 480]}),
            "invalid_points",
        ),
        (
            "image_size -1e308",
            json!({"kind": "correspondences", "points": correspondences(), "image_size": [-1e308, 480]}),
            "invalid_points",
        ),
        (
            "unknown model",
            json!({"kind": "points2d", "points": two, "model": "nope"}),
            "unknown_model",
        ),
        (
            "model name is a path traversal",
            json!({"kind": "points2d", "points": two, "model": "../../etc/passwd"}),
            "unknown_model",
        ),
        (
            "model name is an absolute path",
            json!({"kind": "points2d", "points": two, "model": "/work/main/models/lce"}),
            "unknown_model",
        ),
        (
            "model name is a snowman",
            json!({"kind": "points2d", "points": two, "model": "\u{2603}"}),
            "unknown_model",
        ),
        (
            "model name with combining accent and RTL mark",
            json!({"kind": "points2d", "points": two, "model": "lc\u{0065}\u{0301}\u{200f}"}),
            "unknown_model",
        ),
        (
            "model name with a NUL",
            json!({"kind": "points2d", "points": two, "model": "lce\u{0}"}),
            "unknown_model",
        ),
        (
            "model name empty",
            json!({"kind": "points2d", "points": two, "model": ""}),
            "unknown_model",
        ),
        (
            "model name of 1 MB",
            json!({"kind": "points2d", "points": two, "model": "x".repeat(1 << 20)}),
            "unknown_model",
        ),
        (
            "model of another kind",
            json!({"kind": "points2d", "points": two, "model": "kt3dmoseg"}),
            "model_mismatch",
        ),
        (
            "outlier_threshold of -1",
            json!({"kind": "points2d", "points": two, "refine": true, "outlier_threshold": -1.0}),
            "invalid_request",
        ),
        (
            "outlier_threshold without refine",
            json!({"kind": "points2d", "points": two, "refine": false, "outlier_threshold": 2.0}),
            "invalid_request",
        ),
        (
            "outlier_threshold with outliers off",
            json!({"kind": "points2d", "points": two, "refine": true, "outliers": false, "outlier_threshold": 2.0}),
            "invalid_request",
        ),
        (
            "unknown kind",
            json!({"kind": "voxels", "points": two}),
            "unknown_kind",
        ),
        (
            "kind in upper case",
            json!({"kind": "POINTS2D", "points": two}),
            "unknown_kind",
        ),
        (
            "kind empty",
            json!({"kind": "", "points": two}),
            "unknown_kind",
        ),
    ] {
        fit(
            &mut cases,
            name,
            serde_json::to_vec(&body).unwrap(),
            Error(422, code),
        );
    }
    // Valid trajectories in both layouts and valid correspondences, so the cases above are
    // rejected for the reason they name and not for the data.
    fit(
        &mut cases,
        "valid trajectories (rows)",
        serde_json::to_vec(
            &json!({"kind": "trajectories", "points": traj, "image_size": [1280, 720]}),
        )
        .unwrap(),
        Fit(8),
    );
    fit(
        &mut cases,
        "valid trajectories (matrix)",
        serde_json::to_vec(&json!({"kind": "trajectories", "trajectory_matrix": transpose(&traj)}))
            .unwrap(),
        Fit(8),
    );
    fit(
        &mut cases,
        "valid correspondences",
        serde_json::to_vec(&json!({"kind": "correspondences", "points": correspondences()}))
            .unwrap(),
        Fit(8),
    );
    fit(
        &mut cases,
        "image_size 1e308 (beyond 1e9 pixels)",
        serde_json::to_vec(&json!({"kind": "correspondences", "points": correspondences(), "image_size": [1e308, 1e308]})).unwrap(),
        Error(422, "invalid_points"),
    );
    fit(
        &mut cases,
        "image_size 1e9 (the largest allowed)",
        serde_json::to_vec(&json!({"kind": "correspondences", "points": correspondences(), "image_size": [1e9, 1e9]})).unwrap(),
        Fit(8),
    );
    // Normalisation by a tiny image, (p - c) / (max(w, h) / 2), would overflow f32 in the
    // network: image sizes below one pixel are refused up front.
    fit(
        &mut cases,
        "image_size 1e-300 (below one pixel)",
        serde_json::to_vec(&json!({"kind": "correspondences", "points": correspondences(), "image_size": [1e-300, 1e-300]})).unwrap(),
        Error(422, "invalid_points"),
    );

    // ---- Size limits (defaults: 20000 points, 64 MiB body).
    fit(
        &mut cases,
        "20001 points (one over --max-points)",
        many_points(20_001, "}"),
        Error(422, "too_many_points"),
    );
    fit(
        &mut cases,
        "10^6 points",
        many_points(1_000_000, r#","k":2}"#),
        Error(422, "too_many_points"),
    );
    fit(
        &mut cases,
        "trajectory_matrix of 20001 columns",
        serde_json::to_vec(
            &json!({"kind": "trajectories", "trajectory_matrix": vec![vec![1.0; 20_001]; 10]}),
        )
        .unwrap(),
        Error(422, "too_many_points"),
    );
    fit(
        &mut cases,
        "20000 tracks of 100 frames (about 30 MB) are read, not refused for size",
        {
            let mut s = String::from(r#"{"kind":"trajectories","k":0,"points":["#);
            for i in 0..20_000 {
                s.push_str(if i > 0 { ",[" } else { "[" });
                for f in 0..100 {
                    let sep = if f > 0 { "," } else { "" };
                    let _ = write!(
                        s,
                        "{sep}{:.3},{:.3}",
                        100.5 + f as f64,
                        200.25 + i as f64 * 0.01
                    );
                }
                s.push(']');
            }
            s.push_str("]}");
            s.into_bytes()
        },
        Error(422, "invalid_k"),
    );
    fit(
        &mut cases,
        "65 MiB body (just over --body-limit)",
        body_of_size(65 << 20),
        Error(413, "body_too_large"),
    );
    fit(
        &mut cases,
        "100 MB body",
        body_of_size(100_000_000),
        Error(413, "body_too_large"),
    );
    raw(
        &mut cases,
        "100 MB batch body",
        "POST",
        "/v1/fit/batch",
        JSON,
        {
            let mut b = br#"{"requests":["#.to_vec();
            b.extend(std::iter::repeat_n(b' ', 100_000_000));
            b.extend_from_slice(b"]}");
            b
        },
        Error(413, "body_too_large"),
    );

    // Without a content-length the limit applies while the body streams in.
    for (name, body, expect) in [
        (
            "100 MB chunked body",
            body_of_size(100_000_000),
            Expect::Error(413, "body_too_large"),
        ),
        (
            "small chunked body (valid)",
            serde_json::to_vec(&good()).unwrap(),
            Expect::Fit(GOOD_N),
        ),
    ] {
        cases.push(Case {
            name: name.into(),
            method: "POST",
            path: "/v1/fit".into(),
            content_type: JSON,
            body,
            chunked: true,
            expect,
        });
    }

    // ---- Content type: 415 unsupported_media_type, checked before the body.
    let good_bytes = serde_json::to_vec(&good()).unwrap();
    for (name, ct) in [
        ("content type text/plain", Some("text/plain")),
        ("no content type", None),
        (
            "content type form-urlencoded",
            Some("application/x-www-form-urlencoded"),
        ),
        (
            "content type multipart",
            Some("multipart/form-data; boundary=x"),
        ),
        ("content type application/jsonx", Some("application/jsonx")),
        ("content type empty", Some("")),
        ("content type garbage", Some("///;;;")),
        ("content type text/json", Some("text/json")),
    ] {
        raw(
            &mut cases,
            name,
            "POST",
            "/v1/fit",
            ct,
            good_bytes.clone(),
            Error(415, "unsupported_media_type"),
        );
    }
    raw(
        &mut cases,
        "text/plain with a malformed body",
        "POST",
        "/v1/fit",
        Some("text/plain"),
        b"{{{".to_vec(),
        Error(415, "unsupported_media_type"),
    );
    raw(
        &mut cases,
        "batch with text/plain",
        "POST",
        "/v1/fit/batch",
        Some("text/plain"),
        br#"{"requests":[]}"#.to_vec(),
        Error(415, "unsupported_media_type"),
    );
    raw(
        &mut cases,
        "content type with charset",
        "POST",
        "/v1/fit",
        Some("application/json; charset=utf-8"),
        good_bytes.clone(),
        Fit(GOOD_N),
    );
    raw(
        &mut cases,
        "content type +json suffix",
        "POST",
        "/v1/fit",
        Some("application/vnd.multifit+json"),
        good_bytes.clone(),
        Fit(GOOD_N),
    );

    // ---- Routes and model names in the path: 404 not_found (405 for a wrong method).
    for path in [
        "/v1/models/nope",
        "/v1/models/..%2F..%2Fetc%2Fpasswd",
        "/v1/models/%2e%2e%2f%2e%2e%2fetc%2fpasswd",
        "/v1/models/..%5C..%5Cwindows",
        "/v1/models/%2e%2e",
        "/v1/models/../../etc/passwd",
        "/v1/models/lce/../../../etc/passwd",
        "/v1/models/%E2%98%83",
        "/v1/models/%F0%9F%92%A9",
        "/v1/models/lce%00",
        "/v1/models/%00",
        "/v1/models/lce%20",
        "/v1/models/LCE",
        "/v1/models/lce/extra",
        "/v1/models/",
        "/v1/nothing",
        "/etc/passwd",
        "/v1/fit/../models",
        "/v2/fit",
    ] {
        raw(
            &mut cases,
            &format!("GET {path}"),
            "GET",
            path,
            None,
            Vec::new(),
            Error(404, "not_found"),
        );
    }
    let long = format!("/v1/models/{}", "a".repeat(8000));
    raw(
        &mut cases,
        "GET /v1/models/<8000 chars>",
        "GET",
        &long,
        None,
        Vec::new(),
        Error(404, "not_found"),
    );
    raw(
        &mut cases,
        "GET /v1/fit",
        "GET",
        "/v1/fit",
        None,
        Vec::new(),
        Error(405, "method_not_allowed"),
    );
    raw(
        &mut cases,
        "DELETE /v1/fit",
        "DELETE",
        "/v1/fit",
        None,
        Vec::new(),
        Error(405, "method_not_allowed"),
    );
    raw(
        &mut cases,
        "POST /v1/models/lce",
        "POST",
        "/v1/models/lce",
        JSON,
        good_bytes.clone(),
        Error(405, "method_not_allowed"),
    );
    raw(
        &mut cases,
        "PUT /v1/models",
        "PUT",
        "/v1/models",
        JSON,
        b"{}".to_vec(),
        Error(405, "method_not_allowed"),
    );
    raw(
        &mut cases,
        "POST to an unknown route",
        "POST",
        "/v1/fits",
        JSON,
        good_bytes.clone(),
        Error(404, "not_found"),
    );

    // ---- Batch.
    let g = good();
    for (name, body, status, code) in [
        (
            "batch of 33 (over --max-batch)",
            json!({"requests": vec![g.clone(); 33]}),
            422,
            "too_many_requests_in_batch",
        ),
        (
            "batch of 100000 empty entries",
            json!({"requests": vec![json!({}); 100_000]}),
            422,
            "too_many_requests_in_batch",
        ),
        (
            "batch requests not an array",
            json!({"requests": g.clone()}),
            422,
            "invalid_request",
        ),
        ("batch requests missing", json!({}), 422, "invalid_request"),
        (
            "batch with an unknown top-level field",
            json!({"requests": [], "extra": 1}),
            422,
            "invalid_request",
        ),
        (
            "batch body is an array",
            json!([g.clone()]),
            422,
            "invalid_request",
        ),
    ] {
        raw(
            &mut cases,
            name,
            "POST",
            "/v1/fit/batch",
            JSON,
            serde_json::to_vec(&body).unwrap(),
            Error(status, code),
        );
    }
    raw(
        &mut cases,
        "batch truncated",
        "POST",
        "/v1/fit/batch",
        JSON,
        br#"{"requests":[{"kind":"points2d""#.to_vec(),
        Error(400, "malformed_json"),
    );
    raw(
        &mut cases,
        "batch with a NaN token",
        "POST",
        "/v1/fit/batch",
        JSON,
        br#"{"requests":[{"kind":"points2d","points":[[NaN,0],[1,1]]}]}"#.to_vec(),
        Error(400, "malformed_json"),
    );
    raw(
        &mut cases,
        "batch empty",
        "POST",
        "/v1/fit/batch",
        JSON,
        br#"{"requests":[]}"#.to_vec(),
        Batch(vec![]),
    );
    raw(
        &mut cases,
        "batch of mixed good and bad entries",
        "POST",
        "/v1/fit/batch",
        JSON,
        serde_json::to_vec(&json!({"requests": [
            g.clone(),
            {"kind": "points2d", "points": []},
            good_with(json!({"colour": 1})),
            good_with(json!({"model": "../../etc/passwd"})),
            good_with(json!({"k": 0})),
            good_with(json!({"k": 2.5})),
            good_with(json!({"points": [[0, 0], [1e308, 1]]})),
            good_with(json!({"selection": "bogus", "k": null})),
            good_with(json!({"image_size": [640, 480, 3]})),
            "not an object",
            null,
            [1, 2, 3],
            json!({"kind": "trajectories", "trajectory_matrix": transpose(&traj)[..5].to_vec()}),
            g.clone(),
        ]}))
        .unwrap(),
        Batch(vec![
            Ok(GOOD_N),
            Err("invalid_points"),
            Err("invalid_request"),
            Err("unknown_model"),
            Err("invalid_k"),
            Err("invalid_request"),
            Err("invalid_points"),
            Err("invalid_selection"),
            Err("invalid_request"),
            Err("invalid_request"),
            Err("invalid_request"),
            Err("invalid_request"),
            Err("invalid_points"),
            Ok(GOOD_N),
        ]),
    );
    raw(
        &mut cases,
        "batch entry with 20001 points",
        "POST",
        "/v1/fit/batch",
        JSON,
        {
            let mut b = br#"{"requests":["#.to_vec();
            b.extend(many_points(20_001, "}"));
            b.extend_from_slice(b"]}");
            b
        },
        Batch(vec![Err("too_many_points")]),
    );
    cases
}

/// Checks the JSON error shape: exactly `{"error": {"code", "message"}}`, JSON content type.
fn check_error(case: &str, r: &Response, status: u16, code: &str) {
    let body = r.text();
    let shown: String = body.chars().take(300).collect();
    assert_eq!(r.status, status, "{case}: status (body: {shown})");
    let ct = r
        .headers
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    assert!(
        ct.starts_with("application/json"),
        "{case}: content type {ct:?} (body: {shown})"
    );
    let v: Value = serde_json::from_slice(&r.body)
        .unwrap_or_else(|e| panic!("{case}: error body is not JSON ({e}): {shown}"));
    check_error_value(case, &v, code);
}

fn check_error_value(case: &str, v: &Value, code: &str) {
    let obj = v
        .as_object()
        .unwrap_or_else(|| panic!("{case}: error body not an object: {v}"));
    assert_eq!(obj.len(), 1, "{case}: only `error` at the top: {v}");
    let e = v["error"]
        .as_object()
        .unwrap_or_else(|| panic!("{case}: no error object: {v}"));
    assert_eq!(
        e.len(),
        2,
        "{case}: error has exactly code and message: {v}"
    );
    assert_eq!(
        v["error"]["code"].as_str(),
        Some(code),
        "{case}: error code (body: {v})"
    );
    let message = v["error"]["message"]
        .as_str()
        .unwrap_or_else(|| panic!("{case}: message: {v}"));
    assert!(!message.trim().is_empty(), "{case}: empty message");
    assert!(
        message.len() < 2 << 20,
        "{case}: message of {} bytes",
        message.len()
    );
}

/// Checks a fit answer for n points (the FitResponse invariants: labels in -1..k, one size per
/// structure, sizes and outliers adding up to n, one finite structure per label when refined);
/// returns the labels.
fn check_fit_value(case: &str, v: &Value, n: usize) -> Vec<i64> {
    let l: Vec<i64> = v["labels"]
        .as_array()
        .unwrap_or_else(|| panic!("{case}: no labels: {v}"))
        .iter()
        .map(|x| x.as_i64().unwrap_or_else(|| panic!("{case}: label {x}")))
        .collect();
    assert_eq!(l.len(), n, "{case}: one label per point");
    let k = v["k"]
        .as_u64()
        .unwrap_or_else(|| panic!("{case}: no k: {v}")) as usize;
    assert!(k <= n, "{case}: k = {k} out of 0..={n}");
    assert!(
        l.iter().all(|&x| x >= -1 && x < k as i64),
        "{case}: labels in -1..k: {l:?}"
    );
    let outliers = l.iter().filter(|&&x| x < 0).count();
    assert_eq!(
        v["outliers"].as_u64(),
        Some(outliers as u64),
        "{case}: outliers"
    );
    let structures = v["structures"]
        .as_array()
        .unwrap_or_else(|| panic!("{case}: no structures: {v}"));
    if !structures.is_empty() {
        assert_eq!(structures.len(), k, "{case}: one structure per label");
        for (i, s) in structures.iter().enumerate() {
            assert_eq!(s["label"].as_u64(), Some(i as u64), "{case}: structure {i}");
            let rms = s["rms"]
                .as_f64()
                .unwrap_or_else(|| panic!("{case}: rms {s}"));
            assert!(rms.is_finite() && rms >= 0.0, "{case}: rms {rms}");
            assert!(
                !s.to_string().contains("null"),
                "{case}: a null parameter: {s}"
            );
        }
    }
    let sizes: Vec<usize> = v["cluster_sizes"]
        .as_array()
        .unwrap_or_else(|| panic!("{case}: no cluster_sizes: {v}"))
        .iter()
        .map(|s| s.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(sizes.len(), k, "{case}: one size per cluster");
    assert_eq!(
        sizes.iter().sum::<usize>() + outliers,
        n,
        "{case}: sizes and outliers sum to N"
    );
    for (c, &size) in sizes.iter().enumerate() {
        assert_eq!(
            size,
            l.iter().filter(|&&x| x == c as i64).count(),
            "{case}: cluster_sizes match the labels"
        );
    }
    for r in v["residuals"]
        .as_array()
        .unwrap_or_else(|| panic!("{case}: no residuals: {v}"))
    {
        let x = r["r"]
            .as_f64()
            .unwrap_or_else(|| panic!("{case}: residual {r}"));
        assert!(x.is_finite() && x >= 0.0, "{case}: residual {x}");
    }
    l
}

fn check_fit(case: &str, r: &Response, n: usize) -> Vec<i64> {
    let shown: String = r.text().chars().take(300).collect();
    assert_eq!(r.status, 200, "{case}: status (body: {shown})");
    check_fit_value(case, &r.json(), n)
}

/// One request over a fresh connection; a transport failure fails the case by name.
fn request(server: &Server, case: &Case) -> Response {
    if case.body.len() > LARGE || case.chunked {
        return send_large(server.addr, case)
            .unwrap_or_else(|e| panic!("{}: no HTTP answer: {e}", case.name));
    }
    send(
        server.addr,
        case.method,
        &case.path,
        case.content_type,
        case.body.clone(),
    )
    .unwrap_or_else(|e| panic!("{}: no HTTP answer: {e}", case.name))
}

/// Bodies above this go through [`send_large`].
const LARGE: usize = 8 << 20;

/// Sends a large body while reading the answer concurrently. The server answers 413 as soon as
/// the body passes its limit and closes the connection without reading the rest, so a client
/// that only reads after writing everything (hyper's client, curl without `Expect`) may see
/// "connection reset" instead of the 413; reading while writing sees the answer.
fn send_large(addr: std::net::SocketAddr, case: &Case) -> Result<Response, String> {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(addr).map_err(|e| e.to_string())?;
    stream
        .set_read_timeout(Some(std::time::Duration::from_secs(30)))
        .map_err(|e| e.to_string())?;
    let mut head = format!(
        "{} {} HTTP/1.1\r\nhost: {addr}\r\nconnection: close\r\n",
        case.method, case.path
    );
    if case.chunked {
        head.push_str("transfer-encoding: chunked\r\n");
    } else {
        head.push_str(&format!("content-length: {}\r\n", case.body.len()));
    }
    if let Some(ct) = case.content_type {
        head.push_str(&format!("content-type: {ct}\r\n"));
    }
    head.push_str("\r\n");
    let mut writer = stream.try_clone().map_err(|e| e.to_string())?;
    let body = case.body.clone();
    let chunked = case.chunked;
    let written = std::thread::spawn(move || {
        // Errors are expected once the server has answered and closed.
        if writer.write_all(head.as_bytes()).is_ok() {
            for chunk in body.chunks(1 << 16) {
                let ok = if chunked {
                    writer
                        .write_all(format!("{:x}\r\n", chunk.len()).as_bytes())
                        .and_then(|()| writer.write_all(chunk))
                        .and_then(|()| writer.write_all(b"\r\n"))
                } else {
                    writer.write_all(chunk)
                };
                if ok.is_err() {
                    return;
                }
            }
            if chunked {
                let _ = writer.write_all(b"0\r\n\r\n");
            }
        }
    });
    let mut got = Vec::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        match stream.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if got.is_empty() => return Err(format!("read: {e}")),
            Err(_) => break,
        }
        if let Some(r) = parse_response(&got) {
            let _ = stream.shutdown(std::net::Shutdown::Both);
            let _ = written.join();
            return Ok(r);
        }
    }
    let _ = written.join();
    parse_response(&got)
        .ok_or_else(|| format!("incomplete answer: {:?}", String::from_utf8_lossy(&got)))
}

/// A complete HTTP/1.1 answer with a content-length, or None.
fn parse_response(raw: &[u8]) -> Option<Response> {
    let end = raw.windows(4).position(|w| w == b"\r\n\r\n")?;
    let head = std::str::from_utf8(&raw[..end]).ok()?;
    let mut lines = head.split("\r\n");
    let status: u16 = lines.next()?.split(' ').nth(1)?.parse().ok()?;
    let mut headers = hyper::HeaderMap::new();
    for line in lines {
        let (k, v) = line.split_once(':')?;
        headers.append(
            hyper::header::HeaderName::from_bytes(k.trim().as_bytes()).ok()?,
            hyper::header::HeaderValue::from_str(v.trim()).ok()?,
        );
    }
    let len: usize = headers.get("content-length")?.to_str().ok()?.parse().ok()?;
    let body = raw.get(end + 4..end + 4 + len)?.to_vec();
    Some(Response {
        status,
        headers,
        body,
    })
}

fn good_fit(server: &Server, after: &str) -> Vec<i64> {
    let r = server.post_json("/v1/fit", &good());
    check_fit(&format!("good request after case {after:?}"), &r, GOOD_N)
}

fn panic_text(e: Box<dyn std::any::Any + Send>) -> String {
    e.downcast_ref::<String>()
        .cloned()
        .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "panic".into())
}

/// Sends one case and checks its answer; panics with the case's name on a mismatch.
fn run_case(server: &Server, case: &Case, baseline: &[i64]) {
    let r = request(server, case);
    match &case.expect {
        Expect::Error(status, code) => check_error(&case.name, &r, *status, code),
        Expect::Fit(n) => {
            check_fit(&case.name, &r, *n);
        }
        Expect::Batch(entries) => {
            let shown: String = r.text().chars().take(300).collect();
            assert_eq!(r.status, 200, "{}: status (body: {shown})", case.name);
            let v = r.json();
            let results = v["results"]
                .as_array()
                .unwrap_or_else(|| panic!("{}: no results: {shown}", case.name));
            assert_eq!(
                results.len(),
                entries.len(),
                "{}: one result per entry",
                case.name
            );
            for (i, (got, want)) in results.iter().zip(entries).enumerate() {
                let what = format!("{} entry {i}", case.name);
                match want {
                    Ok(n) => {
                        let l = check_fit_value(&what, got, *n);
                        if *n == GOOD_N {
                            assert_eq!(
                                l, baseline,
                                "{what}: the good entry gives the baseline labels"
                            );
                        }
                    }
                    Err(code) => check_error_value(&what, got, code),
                }
            }
        }
    }
}

#[test]
fn hostile_battery_answers_documented_errors_and_the_server_stays_correct() {
    let started = Instant::now();
    let cases = cases();
    let mut names = std::collections::BTreeSet::new();
    for c in &cases {
        assert!(
            names.insert(c.name.clone()),
            "duplicate case name {:?}",
            c.name
        );
    }
    let server = Server::start(&[]);
    let baseline = good_fit(&server, "(none: baseline)");
    // Only determinism is checked: the lce model need not separate these two short lines.
    assert_eq!(
        good_fit(&server, "(none: baseline repeated)"),
        baseline,
        "same seed, same labels"
    );
    // Every case runs even when an earlier one fails; the failures are listed at the end.
    let mut timings = Vec::new();
    let mut failures = Vec::new();
    for case in &cases {
        let t = Instant::now();
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            run_case(&server, case, &baseline)
        }));
        if let Err(e) = outcome {
            failures.push(panic_text(e));
        }
        timings.push((t.elapsed(), case.name.as_str()));
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let again = good_fit(&server, &case.name);
            assert_eq!(
                again, baseline,
                "good request after case {:?}: same seed, same labels",
                case.name
            );
        }));
        if let Err(e) = outcome {
            failures.push(panic_text(e));
        }
    }
    assert!(
        failures.is_empty(),
        "{} failure(s) in {} cases:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
    // After the whole battery: still live, ready, and the same answer as before it.
    assert_eq!(
        server.get("/health/live").status,
        200,
        "live after the battery"
    );
    assert_eq!(
        server.get("/health/ready").status,
        200,
        "ready after the battery"
    );
    let after = server.post_json("/v1/fit", &good());
    assert_eq!(
        check_fit("good request after the battery", &after, GOOD_N),
        baseline
    );
    // The rejections were counted, and nothing answered 500.
    let metrics = server.get("/metrics").text();
    assert!(
        metrics.contains("multifit_rejections_total"),
        "rejections are counted"
    );
    assert!(
        !metrics.contains("status=\"500\""),
        "no 500 in /metrics:\n{metrics}"
    );
    timings.sort();
    eprintln!(
        "{} hostile cases in {:.2} s; slowest: {:?}",
        cases.len(),
        started.elapsed().as_secs_f64(),
        timings.iter().rev().take(5).collect::<Vec<_>>()
    );
}
