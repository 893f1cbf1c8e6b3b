//! Start-up faults: a server must refuse to run with a broken model directory, naming the file.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::Scratch;

fn copy_model(name: &str, to: &Path) -> PathBuf {
    let dst = to.join(name);
    std::fs::create_dir_all(&dst).unwrap();
    for f in ["model.json", "weights.safetensors"] {
        std::fs::copy(
            common::repo().join("models").join(name).join(f),
            dst.join(f),
        )
        .unwrap();
    }
    dst
}

fn temp(tag: &str) -> Scratch {
    Scratch::new(&format!("faults-{tag}"))
}

/// Runs the server on `models` and expects a non-zero exit whose log names `needle`.
fn expect_refusal(models: &Path, needle: &str) {
    let out = Command::new(env!("CARGO_BIN_EXE_multifit-server"))
        .args(["--addr", "127.0.0.1:0", "--models"])
        .arg(models)
        .output()
        .expect("run server");
    let log =
        String::from_utf8_lossy(&out.stderr).to_string() + &String::from_utf8_lossy(&out.stdout);
    assert!(
        !out.status.success(),
        "server must exit non-zero; log: {log}"
    );
    assert!(log.contains(needle), "log must name {needle:?}: {log}");
}

#[test]
fn missing_models_directory() {
    let dir = temp("missing").join("nothing-here");
    expect_refusal(&dir, "nothing-here");
}

#[test]
fn empty_models_directory() {
    expect_refusal(&temp("empty"), "no model directories");
}

#[test]
fn truncated_weights() {
    let dir = temp("truncated");
    let m = copy_model("lce", &dir);
    let w = m.join("weights.safetensors");
    let bytes = std::fs::read(&w).unwrap();
    std::fs::write(&w, &bytes[..bytes.len() / 2]).unwrap();
    expect_refusal(&dir, "weights.safetensors");
}

#[test]
fn missing_weights() {
    let dir = temp("noweights");
    let m = copy_model("lce", &dir);
    std::fs::remove_file(m.join("weights.safetensors")).unwrap();
    expect_refusal(&dir, "weights.safetensors");
}

#[test]
fn missing_ensemble_member_weights() {
    let dir = temp("nomember");
    let m = copy_model("lce", &dir);
    let card_path = m.join("model.json");
    let mut card: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&card_path).unwrap()).unwrap();
    card["members"] = serde_json::json!([{
        "weights": "weights-1.safetensors",
        "loss": card["loss"].clone(),
        "training": card["training"].clone(),
    }]);
    std::fs::write(&card_path, serde_json::to_vec(&card).unwrap()).unwrap();
    expect_refusal(&dir, "weights-1.safetensors");
}

#[test]
fn card_that_disagrees_with_the_weights() {
    let dir = temp("mismatch");
    let m = copy_model("lce", &dir);
    let card_path = m.join("model.json");
    let mut card: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&card_path).unwrap()).unwrap();
    let width = card["architecture"]["width"].as_u64().unwrap();
    card["architecture"]["width"] = (width / 2).into();
    std::fs::write(&card_path, serde_json::to_vec(&card).unwrap()).unwrap();
    expect_refusal(&dir, "weights.safetensors");
}

#[test]
fn corrupt_card() {
    let dir = temp("badcard");
    let m = copy_model("lce", &dir);
    std::fs::write(m.join("model.json"), b"{ not json").unwrap();
    expect_refusal(&dir, "model.json");
}

#[test]
fn unreadable_card() {
    let dir = temp("unreadable");
    let m = copy_model("lce", &dir);
    // A directory where the card should be: reading it fails whatever the user's privileges.
    std::fs::remove_file(m.join("model.json")).unwrap();
    std::fs::create_dir(m.join("model.json")).unwrap();
    expect_refusal(&dir, "model.json");
}
