//! End-to-end runs of `multifit-train` on tiny configs: real data from ../shared/datasets and
//! generated LCE data, seconds not minutes.

mod common;

use std::path::Path;

use common::{Scratch, TINY, ok, run};
use serde_json::Value;

fn temp(tag: &str) -> Scratch {
    Scratch::new(&format!("trainer-{tag}"))
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

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn gen_lce_writes_readable_samples() {
    let dir = temp("gen");
    ok(&[
        "gen-lce",
        "--out",
        s(&dir),
        "--count",
        "3",
        "--seed",
        "5",
        "--variant",
        "unmixed",
    ]);
    let files: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert_eq!(files.len(), 3);
    for f in files {
        let v: Value = serde_json::from_slice(&std::fs::read(f.unwrap().path()).unwrap()).unwrap();
        assert_eq!(v["kind"], "points2d");
        let k = v["num_models"].as_u64().unwrap();
        assert!((2..=4).contains(&k));
        assert_eq!(v["points"].as_array().unwrap().len() as u64, 50 * k);
    }
}

#[test]
fn a_reader_that_leaves_early_ends_the_output_without_a_panic() {
    // `multifit-train eval ... | head -n 0`: the reader is gone when the output comes.
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("CARGO_BIN_EXE_multifit-train"))
        .args([
            "eval",
            "--model",
            "models/lce",
            "--data",
            "lce:mixed,count=30,seed=1,scale=2",
            "--k-max",
            "6",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The reading end is closed before the table is written (the evaluation takes a while).
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{:?}: {stderr}", out.status);
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn overlapping_clips_and_symmetries_multiply_the_training_set() {
    let names = ["Seq028_Clip02", "Seq070_Clip01"];
    let data = subset("kt-sym", "kt3dmoseg", &names);
    // Every 5-frame clip with at least two visible tracks, counted by the library itself.
    let clips: usize = names
        .iter()
        .map(|n| {
            multifit::data::Sequence::load(&data.join(format!("{n}.json")))
                .unwrap()
                .clips(5, 1)
                .len()
        })
        .sum();
    assert!(clips > 2 * names.len(), "sliding clips: {clips}");
    let out = temp("kt-sym-model");
    let run_dir = temp("kt-sym-run");
    let mut args = vec![
        "train",
        "--name",
        "tiny-kt-sym",
        "--data",
        s(&data),
        "--protocol",
        "augment",
        "--clip-stride",
        "1",
        "--symmetry",
        "mirror,reverse",
        "--out",
        s(&out),
        "--run-dir",
        s(&run_dir),
    ];
    args.extend(TINY);
    ok(&args);
    let card: Value =
        serde_json::from_slice(&std::fs::read(out.join("model.json")).unwrap()).unwrap();
    let described = card["training"]["data"].as_str().unwrap();
    assert!(
        described.contains(&format!("{} training samples", 4 * clips))
            && described.contains("clips every 1 frames")
            && described.contains("Mirror, Reverse"),
        "{described}"
    );
    // cv: a fold trains on the other sequence's clips; 'augment-leaky' adds the held-out
    // sequence's clips that start after its test clip (frames 6 on), as the authors' code does.
    let load = |n: &str| multifit::data::Sequence::load(&data.join(format!("{n}.json"))).unwrap();
    let (held, other) = (load(names[0]), load(names[1]));
    let later = held.clips_from(5, 5, 1).len();
    assert!(later > 0 && later < held.clips(5, 1).len());
    for (protocol, want) in [
        ("augment", other.clips(5, 1).len()),
        ("augment-leaky", other.clips(5, 1).len() + later),
    ] {
        let cv_out = temp(&format!("kt-cv-{protocol}"));
        let mut cv = vec![
            "cv",
            "--data",
            s(&data),
            "--protocol",
            protocol,
            "--clip-stride",
            "1",
            "--fold",
            names[0],
            "--out",
            s(&cv_out),
        ];
        cv.extend(TINY);
        ok(&cv);
        let fold: Value = serde_json::from_slice(
            &std::fs::read(cv_out.join("folds").join(format!("{}.json", names[0]))).unwrap(),
        )
        .unwrap();
        assert_eq!(fold["train_samples"], want, "{protocol}");
    }
    // A stride of 0 is refused with a message, before any training.
    let mut bad = args.clone();
    let at = bad.iter().position(|a| *a == "--clip-stride").unwrap();
    bad[at + 1] = "0";
    let out = run(&bad);
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("clip stride must be at least 1"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // A repeated symmetry is refused, not silently dropped.
    let mut bad = args.clone();
    let at = bad.iter().position(|a| *a == "--symmetry").unwrap();
    bad[at + 1] = "mirror,mirror";
    let out = run(&bad);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--symmetry") && err.contains("repeated"),
        "{err}"
    );
}

#[test]
fn train_then_eval_on_kt3dmoseg_clips() {
    let data = subset(
        "kt",
        "kt3dmoseg",
        &["Seq028_Clip02", "Seq028_clip03", "Seq070_Clip01"],
    );
    let out = temp("kt-model");
    let run_dir = temp("kt-run");
    let mut args = vec![
        "train",
        "--name",
        "tiny-kt",
        "--data",
        s(&data),
        "--protocol",
        "augment",
        "--out",
        s(&out),
        "--run-dir",
        s(&run_dir),
    ];
    args.extend(TINY);
    ok(&args);
    let card: Value =
        serde_json::from_slice(&std::fs::read(out.join("model.json")).unwrap()).unwrap();
    assert_eq!(card["kind"], "trajectories");
    assert_eq!(card["input_dim"], 10);
    assert!(
        card["training"]["command"]
            .as_str()
            .unwrap()
            .contains("--protocol augment")
    );
    assert!(out.join("weights.safetensors").is_file());
    let log = std::fs::read_to_string(run_dir.join("train.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 2, "one JSONL line per epoch");

    // eval on the first-5-frame files, JSON output, recorded in the card.
    let first5 = subset(
        "kt5",
        "kt3dmoseg_first5",
        &["Seq028_Clip02", "Seq070_Clip01"],
    );
    let text = ok(&[
        "eval",
        "--model",
        s(&out),
        "--data",
        s(&first5),
        "--json",
        "--record",
        "test_error",
    ]);
    let v: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["rows"].as_array().unwrap().len(), 2);
    let e = v["totals"]["known"]["mean_error"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&e));
    let card: Value =
        serde_json::from_slice(&std::fs::read(out.join("model.json")).unwrap()).unwrap();
    assert!(
        card["metrics"]
            .as_array()
            .unwrap()
            .iter()
            .any(|m| m["name"] == "test_error")
    );
    // The trained model directory loads in the server's registry.
    multifit::registry::LoadedModel::load(&out).expect("servable model directory");

    // A second seed, then both as one ensemble model that eval and the registry take.
    let second = temp("kt-model-seed1");
    let mut args = vec![
        "train",
        "--name",
        "tiny-kt-1",
        "--data",
        s(&data),
        "--protocol",
        "augment",
        "--seed",
        "1",
        "--out",
        s(&second),
        "--run-dir",
        s(&run_dir),
    ];
    args.extend(TINY);
    ok(&args);
    let both = temp("kt-ensemble");
    let text = ok(&[
        "ensemble",
        "--model",
        s(&out),
        "--model",
        s(&second),
        "--out",
        s(&both),
    ]);
    assert!(text.contains("2 networks"), "{text}");
    let card: Value =
        serde_json::from_slice(&std::fs::read(both.join("model.json")).unwrap()).unwrap();
    assert_eq!(card["name"], both.file_name().unwrap().to_str().unwrap());
    assert_eq!(card["members"][0]["training"]["seed"], 1);
    assert_eq!(card["metrics"].as_array().unwrap().len(), 0);
    let text = ok(&["eval", "--model", s(&both), "--data", s(&first5), "--json"]);
    let v: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["rows"].as_array().unwrap().len(), 2);
    let model = multifit::registry::LoadedModel::load(&both).expect("servable ensemble");
    assert_eq!(model.card.members.len(), 1);
    // One model alone is not an ensemble.
    let alone = run(&[
        "ensemble",
        "--model",
        s(&out),
        "--out",
        s(&temp("kt-alone")),
    ]);
    assert!(!alone.status.success());
    assert!(String::from_utf8_lossy(&alone.stderr).contains("at least two"));

    // Refused, each with its reason: a warm start from an ensemble (which network?), a
    // recorded metric measured with other test symmetries than the card's, and the leaky
    // diagnostic protocol outside cross-validation.
    let (warm, leaky) = (temp("kt-warm"), temp("kt-leaky"));
    let refusals: [(Vec<&str>, &str); 4] = [
        (
            [
                &[
                    "train",
                    "--name",
                    "w",
                    "--data",
                    s(&data),
                    "--protocol",
                    "augment",
                ][..],
                &TINY[..],
                &["--init", s(&both), "--out", s(&warm)][..],
            ]
            .concat(),
            "ensemble of 2",
        ),
        (
            vec![
                "eval",
                "--model",
                s(&both),
                "--data",
                s(&first5),
                "--test-symmetry",
                "mirror",
                "--record",
                "x",
            ],
            "--record",
        ),
        (
            vec![
                "eval",
                "--model",
                s(&both),
                "--data",
                s(&first5),
                "--refine-from-truth",
            ],
            "--refine on",
        ),
        (
            [
                &[
                    "train",
                    "--name",
                    "l",
                    "--data",
                    s(&data),
                    "--protocol",
                    "augment-leaky",
                ][..],
                &TINY[..],
                &["--out", s(&leaky)][..],
            ]
            .concat(),
            "cv only",
        ),
    ];
    for (args, reason) in refusals {
        let out = run(&args);
        assert!(!out.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(reason), "{args:?}: {err}");
    }
    let card_after: Value =
        serde_json::from_slice(&std::fs::read(both.join("model.json")).unwrap()).unwrap();
    assert_eq!(card_after, card, "a refused eval leaves the card alone");
}

#[test]
fn train_on_lce_batches_with_validation() {
    let train_dir = temp("lce-train");
    let val_dir = temp("lce-val");
    ok(&[
        "gen-lce",
        "--out",
        s(&train_dir),
        "--count",
        "8",
        "--seed",
        "1",
        "--points-per-shape",
        "12",
    ]);
    ok(&[
        "gen-lce",
        "--out",
        s(&val_dir),
        "--count",
        "2",
        "--seed",
        "2",
        "--points-per-shape",
        "12",
    ]);
    let out = temp("lce-model");
    let run_dir = temp("lce-run");
    let mut args = vec![
        "train",
        "--name",
        "tiny-lce",
        "--data",
        s(&train_dir),
        "--val",
        s(&val_dir),
        "--batch-size",
        "4",
        "--neighbors",
        "3",
        "--out",
        s(&out),
        "--run-dir",
        s(&run_dir),
    ];
    args.extend(TINY);
    ok(&args);
    let card: Value =
        serde_json::from_slice(&std::fs::read(out.join("model.json")).unwrap()).unwrap();
    assert_eq!(card["architecture"]["neighbors"], 3);
    assert_eq!(card["normalization"], "centroid_unit_rms");
    assert!(
        card["metrics"]
            .as_array()
            .unwrap()
            .iter()
            .any(|m| m["name"] == "validation_error_known_k")
    );

    // The same samples generated in memory: evaluated by one model they give the same rows as the
    // files (names, errors, residual curves), and they train the same network, file for file.
    let eval_json = |data: &str| -> Value {
        let text = ok(&[
            "eval",
            "--model",
            s(&out),
            "--data",
            data,
            "--k-max",
            "4",
            "--json",
        ]);
        serde_json::from_str(&text).unwrap()
    };
    let from_disk = eval_json(s(&train_dir));
    let from_memory = eval_json("lce:mixed,count=8,seed=1,points=12");
    assert_eq!(from_disk["rows"].as_array().unwrap().len(), 8);
    assert_eq!(from_disk["rows"], from_memory["rows"]);
    let out2 = temp("lce-model-mem");
    let run_dir2 = temp("lce-run-mem");
    let mut args = vec![
        "train",
        "--name",
        "tiny-lce",
        "--data",
        "lce:mixed,count=8,seed=1,points=12",
        "--val",
        "lce:mixed,count=2,seed=2,points=12",
        "--batch-size",
        "4",
        "--neighbors",
        "3",
        "--out",
        s(&out2),
        "--run-dir",
        s(&run_dir2),
    ];
    args.extend(TINY);
    ok(&args);
    let weights = |dir: &Path| std::fs::read(dir.join("weights.safetensors")).unwrap();
    assert!(
        weights(&out) == weights(&out2),
        "in-memory LCE data trained other weights"
    );
    let card2: Value =
        serde_json::from_slice(&std::fs::read(out2.join("model.json")).unwrap()).unwrap();
    let validated = card2["metrics"].as_array().unwrap().iter().any(|m| {
        m["name"] == "validation_error_known_k"
            && m["protocol"]
                .as_str()
                .unwrap()
                .contains("on 2 validation samples")
    });
    assert!(validated, "{}", card2["metrics"]);
    assert!(
        card2["training"]["data"]
            .as_str()
            .unwrap()
            .contains("lce:mixed,count=8,seed=1,scale=1,noise=0.05,points=12"),
        "{}",
        card2["training"]["data"]
    );

    // A spec it cannot generate stops at the flag, naming what is wrong.
    let bad = run(&["train", "--name", "x", "--data", "lce:triangles,count=8"]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && err.contains("unknown LCE variant") && !err.contains("panicked"),
        "{err}"
    );
}

/// `cv` of a tiny network on three AdelaideRMF fundamental pairs, written to `out`.
fn cv_args<'a>(pairs: &'a Path, out: &'a Path) -> Vec<&'a str> {
    let mut args = vec![
        "cv",
        "--data",
        s(pairs),
        "--model-type",
        "fundamental",
        "--out",
        s(out),
        "--k-max",
        "4",
    ];
    args.extend(TINY);
    args
}

#[test]
fn cv_resumes_and_summarises_on_adelaide() {
    let data = subset("ad", "adelaidermf", &["biscuit", "book", "cube"]);
    let out = temp("cv");
    let base = cv_args(&data, &out);
    let mut one = base.clone();
    one.extend(["--fold", "book"]);
    ok(&one);
    let fold = out.join("folds").join("book.json");
    let before = std::fs::metadata(&fold).unwrap().modified().unwrap();
    let text = ok(&[base.as_slice(), &["--json"][..]].concat());
    // The finished fold was kept, not retrained.
    assert_eq!(
        std::fs::metadata(&fold).unwrap().modified().unwrap(),
        before
    );
    let v: Value = serde_json::from_str(&text).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    assert!(
        rows.iter().all(|r| r["k_true"].as_u64().unwrap() >= 2),
        "outliers count as a group"
    );
    assert!(out.join("summary.json").is_file());
}

#[test]
fn cv_trains_every_fold_on_the_extra_data_too() {
    let pairs = subset("ad-extra", "adelaidermf", &["biscuit", "book", "cube"]);
    let out = temp("cv-extra");
    let mut args = cv_args(&pairs, &out);
    args.extend([
        "--fold",
        "book",
        "--train-also",
        "twoview:fundamental,count=2,seed=1",
    ]);
    ok(&args);
    let card: Value = serde_json::from_slice(
        &std::fs::read(out.join("models").join("book").join("model.json")).unwrap(),
    )
    .unwrap();
    let data = card["training"]["data"].as_str().unwrap();
    assert_eq!(data, "fold without book, plus 2 more sequences");
    assert_eq!(card["geometry"], "fundamental", "the family of the data");
    // A bad spec names the flag's value before anything trains.
    let bad = run(&[
        "cv",
        "--data",
        s(&pairs),
        "--out",
        s(&temp("cv-extra-bad")),
        "--train-also",
        "motion:count=0",
    ]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && !err.contains("panicked"), "{err}");
    assert!(err.contains("count"), "{err}");
}

#[test]
fn bad_data_stops_before_training_naming_the_file() {
    let dir = temp("bad-json");
    std::fs::write(dir.join("broken.json"), b"{ this is not json").unwrap();
    let out = run(&[
        "train",
        "--name",
        "x",
        "--data",
        s(&dir),
        "--out",
        s(&temp("bad-out")),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("broken.json"), "{err}");

    let dir = temp("bad-row");
    let mut v: Value = serde_json::from_slice(
        &std::fs::read(common::datasets().join("adelaidermf/biscuit.json")).unwrap(),
    )
    .unwrap();
    v["points"][3] = serde_json::json!([1.0, 2.0, 3.0]);
    std::fs::write(dir.join("ragged.json"), serde_json::to_vec(&v).unwrap()).unwrap();
    let out = run(&[
        "train",
        "--name",
        "x",
        "--data",
        s(&dir),
        "--out",
        s(&temp("bad-out2")),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("ragged.json") && err.contains("row 3"),
        "{err}"
    );

    let dir = temp("no-labels");
    v = serde_json::from_slice(
        &std::fs::read(common::datasets().join("adelaidermf/biscuit.json")).unwrap(),
    )
    .unwrap();
    v.as_object_mut().unwrap().remove("labels");
    std::fs::write(dir.join("unlabelled.json"), serde_json::to_vec(&v).unwrap()).unwrap();
    let out = run(&[
        "train",
        "--name",
        "x",
        "--data",
        s(&dir),
        "--out",
        s(&temp("bad-out3")),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("unlabelled.json") && err.contains("labels"),
        "{err}"
    );
}
