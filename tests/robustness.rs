//! `multifit-train robustness` end to end on tiny models: the LCE grid's cells are the `eval` of
//! the data source they name, the real-data grids subsample, add outliers, rescale and stride
//! as they say, fold models score their own sequences, and bad requests are refused by flag.

mod common;

use std::path::Path;

use common::{Scratch, TINY, ok, run};
use serde_json::Value;

fn temp(tag: &str) -> Scratch {
    Scratch::new(&format!("robustness-{tag}"))
}

fn refused(args: &[&str]) -> String {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{args:?} succeeded");
    assert!(!err.contains("panicked"), "{err}");
    err
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Copies some dataset files into a fresh directory.
fn subset(tag: &str, dir: &str, names: &[&str]) -> Scratch {
    let to = temp(tag);
    for n in names {
        std::fs::copy(
            common::datasets().join(dir).join(format!("{n}.json")),
            to.join(format!("{n}.json")),
        )
        .unwrap();
    }
    to
}

/// Trains a tiny model on `data` into a fresh directory.
fn tiny_model(tag: &str, data: &str, extra: &[&str]) -> Scratch {
    let out = temp(tag);
    let run_dir = temp(&format!("{tag}-run"));
    let mut args = vec![
        "train",
        "--name",
        tag,
        "--data",
        data,
        "--out",
        s(&out),
        "--run-dir",
        s(&run_dir),
    ];
    args.extend(TINY);
    args.extend(extra);
    ok(&args);
    out
}

fn report(dir: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(dir.join("robustness.json")).unwrap()).unwrap()
}

fn cell<'a>(report: &'a Value, name: &str) -> &'a Value {
    report["cells"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == name)
        .unwrap_or_else(|| panic!("no cell {name}"))
}

#[test]
fn lce_cells_are_the_eval_of_the_data_they_name() {
    let model = tiny_model(
        "lce",
        "lce:mixed,count=8,seed=1,points=12",
        &["--batch-size", "4", "--neighbors", "3", "--k-max", "6"],
    );
    let out = temp("lce-out");
    let cells = "sweep-20-s1,outliers-0.5,random-types,similarity";
    let text = ok(&[
        "robustness",
        "--model",
        s(&model),
        "--out",
        s(&out),
        "--sets",
        "2",
        "--cells",
        cells,
    ]);
    assert!(text.contains("robustness.md"), "{text}");
    let r = report(&out);
    assert_eq!(r["kind"], "points2d");
    assert_eq!(r["selection"], "sod");
    assert_eq!(r["k_max"], 6);
    let names: Vec<&str> = r["cells"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        ["sweep-20-s1", "random-types", "outliers-0.5", "similarity"]
    );
    let outliers = cell(&r, "outliers-0.5");
    assert_eq!(outliers["samples"], 2);
    // Each sample's errors, whose mean is the cell's.
    for c in r["cells"].as_array().unwrap() {
        let each = c["per_sample"].as_array().unwrap();
        assert_eq!(each.len(), 2, "{}", c["name"]);
        for (key, summary) in [("known_error", "known"), ("chosen_error", "chosen")] {
            let mean = each.iter().map(|x| x[key].as_f64().unwrap()).sum::<f64>() / 2.0;
            let cell_mean = c[summary]["mean_error"].as_f64().unwrap();
            assert!(
                (mean - cell_mean).abs() < 1e-12,
                "{}: {mean} vs {cell_mean}",
                c["name"]
            );
        }
        assert!(each.iter().all(|x| x["chosen_k"].as_u64().unwrap() >= 1));
    }
    assert_eq!(outliers["mean_k"], 5.0, "the outliers are a fifth group");
    assert_eq!(outliers["mean_points"], 300.0);
    assert_eq!(outliers["factors"]["outliers"], 0.5);
    assert_eq!(
        outliers["data"],
        "lce:mixed,count=2,seed=1000,scale=2,noise=0.05,points=50,outliers=0.5"
    );
    // Every cell is exactly `eval` on the data source it names.
    for c in r["cells"].as_array().unwrap() {
        let data = c["data"].as_str().unwrap();
        let eval: Value = serde_json::from_str(&ok(&[
            "eval",
            "--model",
            s(&model),
            "--data",
            data,
            "--k-max",
            "6",
            "--json",
        ]))
        .unwrap();
        assert_eq!(c["totals"], eval["totals"], "{data}");
        assert_eq!(c["known"], eval["totals"]["known"], "{data}");
        assert_eq!(c["chosen"], eval["totals"]["sod"], "{data}");
    }
    let md = std::fs::read_to_string(out.join("robustness.md")).unwrap();
    assert_eq!(
        md.matches("\n| ").count(),
        1 + 4,
        "header and one row per cell:\n{md}"
    );
    assert!(md.contains("| outliers-0.5 | 50 | 2 | 1 line + 2 ellipses + 1 circle | whole | 0.5 | no | 2 | 300 | 5.00 |"), "{md}");

    // Refusals name the flag, and the cells a model has.
    let err = refused(&[
        "robustness",
        "--model",
        s(&model),
        "--out",
        s(&out),
        "--cells",
        "bogus",
    ]);
    assert!(
        err.contains("--cells") && err.contains("paper-protocol"),
        "{err}"
    );
    let err = refused(&[
        "robustness",
        "--model",
        s(&model),
        "--out",
        s(&out),
        "--sets",
        "0",
    ]);
    assert!(err.contains("--sets 0"), "{err}");
    let err = refused(&[
        "robustness",
        "--model",
        s(&model),
        "--out",
        s(&out),
        "--folds",
        s(&out),
    ]);
    assert!(err.contains("--folds"), "{err}");
}

#[test]
fn correspondence_cells_and_fold_models() {
    let names = ["physics", "bonython"];
    let data = subset("ad", "adelaidermf", &names);
    let model = tiny_model("tiny-homography", s(&data), &["--k-max", "4"]);
    let out = temp("ad-out");
    ok(&[
        "robustness",
        "--model",
        s(&model),
        "--out",
        s(&out),
        "--data",
        s(&data),
        "--model-type",
        "homography",
        "--draws",
        "2",
    ]);
    let r = report(&out);
    assert_eq!(r["reference"], "as-is");
    let as_is = cell(&r, "as-is");
    assert_eq!(as_is["samples"], 2);
    // physics has 106 points, bonython 198.
    assert_eq!(as_is["mean_points"], 152.0);
    assert_eq!(cell(&r, "subsample-50")["samples"], 4, "two draws per pair");
    assert_eq!(cell(&r, "subsample-50")["mean_points"], 76.0);
    assert_eq!(cell(&r, "subsample-25")["mean_points"], (27.0 + 50.0) / 2.0);
    assert_eq!(
        cell(&r, "outliers+20")["mean_points"],
        (106.0 + 21.0 + 198.0 + 40.0) / 2.0
    );
    // Both pairs have outliers, so the added ones join that group: K unchanged.
    assert_eq!(cell(&r, "outliers+20")["mean_k"], as_is["mean_k"]);
    // Rescaling by a power of two changes no normalised input, so no score.
    for name in ["rescale-0.5", "rescale-2"] {
        assert_eq!(cell(&r, name)["totals"], as_is["totals"], "{name}");
    }
    assert!(cell(&r, "no-image-size")["factors"]["image size sent"] == false);
    let notes = r["notes"].to_string();
    assert!(notes.contains("trained on every sequence"), "{notes}");

    // Leave-one-out fold models from a real (tiny) cross-validation score their own pairs.
    let cv = temp("ad-cv");
    let mut args = vec![
        "cv",
        "--data",
        s(&data),
        "--model-type",
        "homography",
        "--out",
        s(&cv),
        "--k-max",
        "4",
    ];
    args.extend(TINY);
    ok(&args);
    let folds_out = temp("ad-folds-out");
    let with_folds = [
        "robustness",
        "--model",
        s(&model),
        "--folds",
        s(&cv),
        "--out",
        s(&folds_out),
        "--data",
        s(&data),
        "--cells",
        "as-is",
    ];
    ok(&with_folds);
    let f = report(&folds_out);
    assert_eq!(f["folds"], s(&cv));
    assert!(
        f["notes"]
            .to_string()
            .contains("fold model that never saw it")
    );
    // The as-is cell with fold models is the cross-validation itself.
    let summary: Value =
        serde_json::from_slice(&std::fs::read(cv.join("summary.json")).unwrap()).unwrap();
    let known = |v: &Value| v["mean_error"].as_f64().unwrap();
    assert!(
        (known(&cell(&f, "as-is")["known"]) - known(&summary["totals"]["known"])).abs() < 1e-12
    );
    // The model card's test symmetries apply to the fold models, as they do in a fit: the as-is
    // cell is then each fold model's eval under them.
    let card_path = model.join("model.json");
    let mut card: Value = serde_json::from_slice(&std::fs::read(&card_path).unwrap()).unwrap();
    card["test_symmetries"] = serde_json::json!(["reverse"]);
    std::fs::write(&card_path, card.to_string()).unwrap();
    let sym_out = temp("ad-folds-sym");
    let mut with_symmetry = with_folds;
    with_symmetry[6] = s(&sym_out);
    ok(&with_symmetry);
    let mean_under_reverse = names
        .iter()
        .map(|name| {
            let fold = cv.join("models").join(name);
            let pair = data.join(format!("{name}.json"));
            let out = run(&[
                "eval",
                "--model",
                s(&fold),
                "--data",
                s(&pair),
                "--k-max",
                "4",
                "--test-symmetry",
                "reverse",
                "--json",
            ]);
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let v: Value = serde_json::from_slice(&out.stdout).unwrap();
            known(&v["totals"]["known"])
        })
        .sum::<f64>()
        / names.len() as f64;
    // The symmetry changes these tiny models' answers, so the check can tell the two apart.
    assert!((mean_under_reverse - known(&summary["totals"]["known"])).abs() > 1e-9);
    let with_reverse = known(&cell(&report(&sym_out), "as-is")["known"]);
    assert!(
        (with_reverse - mean_under_reverse).abs() < 1e-12,
        "{with_reverse} / {mean_under_reverse}"
    );

    // A missing fold model is named.
    std::fs::remove_dir_all(cv.join("models").join("physics")).unwrap();
    let err = refused(&with_folds);
    assert!(err.contains("physics"), "{err}");
}

#[test]
fn trajectory_strides_skip_short_sequences() {
    // Seq070_Clip01 has 10 frames (no stride-3 clip), Seq028_Clip01 15.
    let data = subset("kt", "kt3dmoseg", &["Seq070_Clip01", "Seq028_Clip01"]);
    let model = tiny_model("tiny-kt", s(&data), &[]);
    let out = temp("kt-out");
    ok(&[
        "robustness",
        "--model",
        s(&model),
        "--out",
        s(&out),
        "--data",
        s(&data),
    ]);
    let r = report(&out);
    assert_eq!(cell(&r, "stride-1")["samples"], 2);
    assert_eq!(cell(&r, "stride-2")["samples"], 2);
    let three = cell(&r, "stride-3");
    assert_eq!(three["samples"], 1);
    assert_eq!(three["skipped"], serde_json::json!(["Seq070_Clip01"]));
    assert_eq!(three["factors"]["frames read"], "1, 4, 7, 10, 13");
    let long = cell(&r, "stride-1-long");
    assert_eq!(long["samples"], 1);
    assert_eq!(long["skipped"], serde_json::json!(["Seq070_Clip01"]));
    let md = std::fs::read_to_string(out.join("robustness.md")).unwrap();
    assert!(
        md.contains("Skipped (no sample in the cell): stride-3: Seq070_Clip01"),
        "{md}"
    );
}
