//! API conformance: Schemathesis (property-based requests generated from openapi.yaml, every check
//! on) against the real server binary, through `scripts/schemathesis.sh`. It runs wherever
//! python3 is available (the script installs Schemathesis from PyPI into target/ on first use);
//! without python3 the script says SKIP and this test has nothing to check.

mod common;

use std::process::Command;

#[test]
fn schemathesis_finds_no_failure() {
    let out = Command::new("bash")
        .arg(common::repo().join("scripts/schemathesis.sh"))
        .args(["--max-examples", "30", "--time-limit", "300", "--server"])
        .arg(env!("CARGO_BIN_EXE_multifit-server"))
        .output()
        .expect("run scripts/schemathesis.sh");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    if stdout.starts_with("SKIP") {
        eprintln!("{stdout}");
        return;
    }
    assert!(
        out.status.success(),
        "schemathesis failed ({}):\n{stdout}\n{stderr}",
        out.status
    );
    assert!(
        stdout.contains("passed") && !stdout.contains("failures"),
        "unexpected report:\n{stdout}"
    );
}
