//! The page at `/` in a real browser: Debian's headless Chromium opens `/?example=...&fit=1`,
//! which loads a bundled example and fits it; the DOM it dumps must hold the picture with one mark
//! per point and the legend with the fit's K, or, for a request the API rejects, the API's error
//! as a readable message.
//!
//! Without Chromium the tests fail when `CI` is set (`.ci/run` installs it) and otherwise say
//! that they did not run and pass. `MULTIFIT_CHROMIUM` names another binary.

mod common;

use std::io::Read;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{Server, send_with};
use serde_json::Value;

/// The Chromium binary, or `None` (after failing under CI) when there is none.
fn chromium() -> Option<PathBuf> {
    let named = std::env::var_os("MULTIFIT_CHROMIUM").map(PathBuf::from);
    let found = match named {
        Some(path) => Some(path).filter(|p| p.is_file()),
        None => ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
            .iter()
            .map(PathBuf::from)
            .find(|p| p.is_file()),
    };
    if found.is_none() {
        assert!(
            std::env::var_os("CI").is_none(),
            "Chromium is missing (looked for MULTIFIT_CHROMIUM, /usr/bin/chromium, \
             /usr/bin/chromium-browser) and CI is set: install it with \
             `apt-get install -y --no-install-recommends chromium` (.ci/run does)"
        );
        eprintln!("SKIPPED: Chromium is not installed, so the browser test did not run");
    }
    found
}

/// The DOM of `url` after its scripts settled, as headless Chromium dumps it. A fresh profile
/// per run; the process is killed past `limit`.
fn dump_dom(chromium: &PathBuf, url: &str, limit: Duration) -> String {
    let profile = tempfile::Builder::new()
        .prefix("multifit-chromium-")
        .tempdir()
        .expect("a profile directory");
    let mut child = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            // Virtual time stands still while requests are in flight, so the fits finish
            // within it however slow the machine; the budget bounds the page's own timers.
            "--virtual-time-budget=60000",
            "--dump-dom",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(url)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start chromium");
    let mut stdout = child.stdout.take().expect("stdout");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stdout.read_to_string(&mut s);
        s
    });
    let mut stderr = child.stderr.take().expect("stderr");
    let errors = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait for chromium") {
            break status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("chromium did not finish within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let dom = reader.join().unwrap_or_default();
    let errors = errors.join().unwrap_or_default();
    assert!(status.success(), "chromium failed ({status}): {errors}");
    assert!(dom.contains("<body"), "no DOM dumped: {errors}");
    dom
}

/// The text of the first element after `marker` up to its closing `end`.
fn between<'a>(s: &'a str, marker: &str, end: &str) -> &'a str {
    let from = s
        .find(marker)
        .unwrap_or_else(|| panic!("{marker:?} not in the DOM"));
    let rest = &s[from..];
    &rest[..rest.find(end).map_or(rest.len(), |e| e + end.len())]
}

/// The JSON answer the page's own request gets: the example's body, which the page sends as it
/// is (its fields fill the form, and the form sends them back).
fn expected_fit(server: &Server, example: &str) -> Value {
    let body = server.get(&format!("/examples/{example}.json")).json();
    let r = send_with(
        server.addr,
        "POST",
        "/v1/fit",
        &[("content-type", "application/json")],
        serde_json::to_vec(&body).unwrap(),
    )
    .unwrap();
    assert_eq!(r.status, 200, "{}", r.text());
    r.json()
}

#[test]
fn the_page_fits_an_example_in_chromium() {
    let Some(chromium) = chromium() else { return };
    let server = Server::start(&[]);
    // two-cameras sends one image size per image, which the form passes through.
    for example in ["lce", "kt3dmoseg", "two-cameras"] {
        let fit = expected_fit(&server, example);
        let n = fit["labels"].as_array().unwrap().len();
        let k = fit["k"].as_u64().unwrap();
        let url = format!("http://{}/?example={example}&fit=1", server.addr);
        let dom = dump_dom(&chromium, &url, Duration::from_secs(120));
        assert!(
            dom.contains(r#"<body data-state="done">"#),
            "{example}: the fit did not finish: {}",
            between(&dom, "<p id=\"status\"", "</div>")
        );
        let picture = between(&dom, r#"<figure id="picture""#, "</figure>");
        assert_eq!(picture.matches("<svg").count(), 1, "{example}: one picture");
        assert_eq!(
            picture.matches(r#"class="pt""#).count(),
            n,
            "{example}: one mark per point"
        );
        if example == "two-cameras" {
            // Drawn with both sizes, so the page sent both.
            assert!(
                picture.contains("images 682 × 512 and 1023 × 768"),
                "{example}: both image sizes sent"
            );
        }
        let legend = between(picture, r#"<g class="legend">"#, "</g>");
        assert!(
            legend.contains(&format!(">K = {k}</text>")),
            "{example}: the legend shows K = {k}: {legend}"
        );
        let status = between(&dom, r#"<p id="status""#, "</p>");
        assert!(
            status.contains(&format!("K = {k} for {n} points")),
            "{status}"
        );
        assert!(
            between(&dom, r#"<div id="error""#, "</div>").ends_with("\"></div>"),
            "no error shown"
        );
    }
}

#[test]
fn the_page_shows_api_errors_as_messages() {
    let Some(chromium) = chromium() else { return };
    let server = Server::start(&[]);
    // K beyond the number of points: the API answers 422 invalid_k.
    let url = format!("http://{}/?example=lce&fit=1&k=5000", server.addr);
    let dom = dump_dom(&chromium, &url, Duration::from_secs(120));
    assert!(dom.contains(r#"<body data-state="error">"#));
    let error = between(&dom, r#"<div id="error""#, "</div>");
    assert!(error.contains("HTTP 422, invalid_k"), "{error}");
    assert!(
        error.contains("k = 5000 must be between 1 and the number of points (200)"),
        "{error}"
    );
    assert!(!dom.contains("<svg"), "no picture for a failed fit");
}
