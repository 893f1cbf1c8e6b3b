//! `cv`: leave-one-sequence-out cross-validation ([`crate::train::cv`]) as the command runs it:
//! the run's `spec.json`, then one fold (`--fold`), every unfinished fold in this process, or
//! `--jobs` one-thread child processes of this same command line, each running one fold; and
//! finally the summary of every finished fold, written as `summary.json` and printed.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::Args;

use super::CliError;
use super::options::{DataArgs, TrainArgs, check_symmetries};
use super::provenance::command_line;
use crate::train::cv::{self, CvSpec, FoldResult};
use crate::train::eval::{EvalRow, EvalSettings, Totals, format_table, totals};

/// One cross-validation run: the flags of `cv` but `--json` (what it prints).
#[derive(Args, Debug, Clone)]
pub struct CvJob {
    #[command(flatten)]
    pub data: DataArgs,
    #[command(flatten)]
    pub train: TrainArgs,
    /// Output directory (folds/<name>.json, summary.json).
    #[arg(long)]
    pub out: PathBuf,
    /// Folds trained at once, each in its own one-thread process.
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// Run only this fold (used by --jobs; also handy by hand).
    #[arg(long)]
    pub fold: Option<String>,
    /// Start every fold from this trained model (same architecture; e.g. pretrained on
    /// synthetic data) instead of a fresh initialisation.
    #[arg(long)]
    pub init: Option<PathBuf>,
    #[arg(long, default_value_t = 4)]
    pub restarts: usize,
    /// More training data for every fold, never held out (e.g. `motion:count=300,seed=1`:
    /// synthetic clips mixed into the fine-tuning so that it keeps what pretraining taught).
    /// Repeatable; the same forms as --data.
    #[arg(long)]
    pub train_also: Vec<crate::data::DataSource>,
}

/// Every finished fold of a run, in sequence order, and their totals.
#[derive(Debug, Clone, PartialEq)]
pub struct CvSummary {
    pub rows: Vec<EvalRow>,
    pub totals: Totals,
    /// Training time summed over the folds.
    pub train_seconds: f64,
}

impl CvSummary {
    /// The folds of `names` that have finished in `out` (the others are left out).
    pub fn read(out: &std::path::Path, names: &[String]) -> Self {
        let folds: Vec<FoldResult> = names
            .iter()
            .filter_map(|n| cv::finished_fold(out, n))
            .collect();
        let rows: Vec<EvalRow> = folds.iter().map(|f| f.row.clone()).collect();
        CvSummary {
            totals: totals(&rows),
            train_seconds: folds.iter().map(|f| f.train_seconds).sum(),
            rows,
        }
    }

    /// `summary.json`: the totals, the rows and the summed training time.
    pub fn json(&self) -> Result<String, serde_json::Error> {
        serde_json::to_string_pretty(&serde_json::json!({
            "totals": self.totals, "rows": self.rows, "train_seconds_total": self.train_seconds,
        }))
    }

    /// What `cv` prints: the table and the training time, or with `json` the totals and the
    /// rows (with a newline).
    pub fn output(&self, json: bool) -> Result<String, serde_json::Error> {
        if json {
            let value = serde_json::json!({ "totals": self.totals, "rows": self.rows });
            Ok(serde_json::to_string_pretty(&value)? + "\n")
        } else {
            Ok(format!(
                "{}training time, all folds: {:.0} s\n",
                format_table(&self.rows),
                self.train_seconds
            ))
        }
    }
}

/// Removes `flag VALUE` pairs (the `--flag=VALUE` form is removed by [`child_args`]'s filter).
pub fn strip_flag_value(args: Vec<String>, flag: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut skip = false;
    for a in args {
        if skip {
            skip = false;
            continue;
        }
        if a == flag {
            skip = true;
            continue;
        }
        out.push(a);
    }
    out
}

/// The arguments (without the program) of the child processes that run single folds: this
/// command's own, without `--jobs` in either form (each child adds its `--fold`).
pub fn child_args(args: impl IntoIterator<Item = String>) -> Vec<String> {
    let args = args
        .into_iter()
        .filter(|x| !x.starts_with("--jobs="))
        .collect();
    strip_flag_value(args, "--jobs")
}

/// The line a finished fold prints.
fn fold_line(name: &str, r: &FoldResult) -> String {
    format!(
        "fold {name}: error {:.2}% (known K), {:.0} s",
        100.0 * r.row.known.error,
        r.train_seconds
    )
}

/// Runs the folds of `job` (finished ones are kept, never retrained) and summarises them;
/// `None` when `job.fold` asked for one fold only. With `jobs > 1` the folds run in child
/// processes of this executable and command line. Stops between folds when `stop` is set.
pub fn run(job: &CvJob, stop: &AtomicBool) -> Result<Option<CvSummary>, CliError> {
    let seqs = job.data.sequences()?;
    let kind = seqs[0].points.kind();
    let samples = job.train.samples(job.data.clip_len, kind)?;
    let input_dim = samples
        .test_sample(&seqs[0])
        .ok_or(CliError::NoTestSample)?
        .points
        .dim();
    check_symmetries("--test-symmetry", &job.train.test_symmetry, kind)?;
    let config = job.train.config(input_dim)?;
    let init = job
        .init
        .as_deref()
        .map(|dir| super::card::init_card(dir, &config).map(|(weights, _)| weights))
        .transpose()?;
    let mut extra = Vec::new();
    for source in &job.train_also {
        extra.extend(source.sequences(job.data.model_type.as_deref())?);
    }
    let spec = CvSpec {
        train: config,
        init,
        extra,
        samples,
        test_symmetries: job.train.test_symmetry.clone(),
        eval: EvalSettings {
            k_max: job.train.k_max,
            restarts: job.restarts,
            seed: 0,
            refine: None,
            from_truth: false,
        },
        out: job.out.clone(),
    };
    std::fs::create_dir_all(&job.out)?;
    std::fs::write(
        job.out.join("spec.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "command": command_line(), "train": spec.train, "samples": spec.samples,
        }))?,
    )?;
    let names: Vec<String> = seqs.iter().map(|s| s.name.clone()).collect();
    if let Some(fold) = &job.fold {
        let i = names
            .iter()
            .position(|n| n == fold)
            .ok_or_else(|| CliError::NoSuchFold(fold.clone()))?;
        let r = cv::run_fold(&spec, &seqs, i)?;
        eprintln!("{}", fold_line(fold, &r));
        return Ok(None);
    }
    if job.jobs > 1 {
        let exe = std::env::current_exe()?;
        let args = child_args(std::env::args().skip(1));
        let failed = cv::run_in_processes(&exe, &args, &job.out, &names, job.jobs)?;
        if !failed.is_empty() {
            return Err(CliError::FoldsFailed(failed));
        }
    } else {
        for (i, name) in names.iter().enumerate() {
            if stop.load(Ordering::Relaxed) {
                return Err(CliError::Interrupted(job.out.clone()));
            }
            let r = cv::run_fold(&spec, &seqs, i)?;
            eprintln!("{}", fold_line(name, &r));
        }
    }
    let summary = CvSummary::read(&job.out, &names);
    std::fs::write(job.out.join("summary.json"), summary.json()?)?;
    Ok(Some(summary))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::eval::Score;

    fn strings(args: &[&str]) -> Vec<String> {
        args.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn child_args_drop_jobs_in_both_forms() {
        let args = strings(&["cv", "--jobs", "2", "--data", "d", "--jobs=3", "--out", "o"]);
        assert_eq!(
            child_args(args),
            strings(&["cv", "--data", "d", "--out", "o"])
        );
        // Only the flag's value goes with it, not a later value that looks the same.
        let args = strings(&["--jobs", "2", "--epochs", "2"]);
        assert_eq!(
            strip_flag_value(args, "--jobs"),
            strings(&["--epochs", "2"])
        );
        assert_eq!(
            strip_flag_value(strings(&["a", "--jobs"]), "--jobs"),
            strings(&["a"])
        );
    }

    fn fold(name: &str, error: f64, seconds: f64) -> FoldResult {
        let s = |k: usize| Score {
            k,
            error,
            nmi: 1.0 - error,
            outliers: None,
        };
        FoldResult {
            row: EvalRow {
                name: name.into(),
                n: 20,
                k_true: 2,
                known: s(2),
                sod: s(3),
                silhouette: s(2),
                residuals: vec![],
                errors_by_k: vec![],
            },
            train_samples: 4,
            train_seconds: seconds,
            best_epoch: 1,
        }
    }

    /// The summary takes the finished folds in sequence order, skips the unfinished and sums
    /// their training time; `summary.json` and the printed JSON carry the same totals.
    #[test]
    fn summary_of_finished_folds() {
        let tmp = crate::registry::tests::scratch("cv-summary");
        let folds = tmp.path().join("folds");
        std::fs::create_dir_all(&folds).unwrap();
        for f in [fold("b", 0.3, 20.0), fold("a", 0.1, 10.0)] {
            let text = serde_json::to_string(&f).unwrap();
            std::fs::write(folds.join(format!("{}.json", f.row.name)), text).unwrap();
        }
        std::fs::write(folds.join("c.json"), "{ not finished").unwrap();
        let s = CvSummary::read(tmp.path(), &strings(&["a", "b", "c", "d"]));
        let names: Vec<_> = s.rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["a", "b"]);
        assert_eq!(s.train_seconds, 30.0);
        assert_eq!(s.totals.samples, 2);
        assert!((s.totals.known.mean_error - 0.2).abs() < 1e-12);
        assert_eq!(s.totals.sod.k_correct, 0.0);
        let written: serde_json::Value = serde_json::from_str(&s.json().unwrap()).unwrap();
        assert_eq!(written["train_seconds_total"], 30.0);
        assert_eq!(written["rows"].as_array().unwrap().len(), 2);
        let printed: serde_json::Value = serde_json::from_str(&s.output(true).unwrap()).unwrap();
        assert_eq!(printed["totals"], written["totals"]);
        assert!(printed.get("train_seconds_total").is_none());
        let table = s.output(false).unwrap();
        assert!(
            table.ends_with("training time, all folds: 30 s\n"),
            "{table}"
        );
        assert!(table.starts_with(&format_table(&s.rows)));
    }

    #[test]
    fn fold_lines_read_as_before() {
        assert_eq!(
            fold_line("seq", &fold("seq", 0.0512, 61.6)),
            "fold seq: error 5.12% (known K), 62 s"
        );
    }
}
