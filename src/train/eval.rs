//! Evaluation of a model on labelled samples: error rate, NMI and chosen K, with known K and with
//! automatic K (SOD and silhouette), per sample and in total.

use serde::{Deserialize, Serialize};

use crate::cluster::{ClusterParams, Selection};
use crate::data::Sample;
use crate::metrics::{error_rate, mean_median, model_selection_rate, nmi};
use crate::registry::{FitError, LoadedModel};

/// The score of one labelling.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Score {
    pub k: usize,
    pub error: f64,
    pub nmi: f64,
}

/// One evaluated sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalRow {
    pub name: String,
    pub n: usize,
    pub k_true: usize,
    pub known: Score,
    pub sod: Score,
    pub silhouette: Score,
}

/// Totals over rows for one way of choosing K.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub mean_error: f64,
    pub median_error: f64,
    pub mean_nmi: f64,
    /// Share of samples whose K was chosen right (1 for known K).
    pub k_correct: f64,
}

/// Totals for known K, SOD and silhouette.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Totals {
    pub samples: usize,
    pub known: Summary,
    pub sod: Summary,
    pub silhouette: Summary,
}

/// Evaluation settings.
#[derive(Debug, Clone, Copy)]
pub struct EvalSettings {
    pub k_max: usize,
    pub restarts: usize,
    pub seed: u64,
}

fn score(
    sample: &Sample,
    model: &LoadedModel,
    selection: Selection,
    s: &EvalSettings,
) -> Result<Score, FitError> {
    let params = ClusterParams::builder()
        .selection(selection)
        .k_max(s.k_max)
        .restarts(s.restarts)
        .seed(s.seed)
        .build()?;
    let fit = model.fit(&sample.points, sample.image_size, &params)?;
    Ok(Score {
        k: fit.clustering.k,
        error: error_rate(&sample.labels, &fit.clustering.labels),
        nmi: nmi(&sample.labels, &fit.clustering.labels),
    })
}

/// Evaluates one sample with known K, SOD and silhouette.
pub fn evaluate_sample(
    model: &LoadedModel,
    sample: &Sample,
    s: &EvalSettings,
) -> Result<EvalRow, FitError> {
    Ok(EvalRow {
        name: sample.name.clone(),
        n: sample.points.len(),
        k_true: sample.k,
        known: score(sample, model, Selection::Fixed(sample.k), s)?,
        sod: score(sample, model, Selection::Sod, s)?,
        silhouette: score(sample, model, Selection::Silhouette, s)?,
    })
}

fn summarise(rows: &[EvalRow], pick: fn(&EvalRow) -> Score) -> Summary {
    let errors: Vec<f64> = rows.iter().map(|r| pick(r).error).collect();
    let (mean_error, median_error) = mean_median(&errors);
    let nmis: Vec<f64> = rows.iter().map(|r| pick(r).nmi).collect();
    let pairs: Vec<(usize, usize)> = rows.iter().map(|r| (r.k_true, pick(r).k)).collect();
    Summary {
        mean_error,
        median_error,
        mean_nmi: mean_median(&nmis).0,
        k_correct: model_selection_rate(&pairs),
    }
}

/// Totals over evaluated rows.
pub fn totals(rows: &[EvalRow]) -> Totals {
    Totals {
        samples: rows.len(),
        known: summarise(rows, |r| r.known),
        sod: summarise(rows, |r| r.sod),
        silhouette: summarise(rows, |r| r.silhouette),
    }
}

/// A plain-text table: one line per row, then mean and median (errors in %).
pub fn format_table(rows: &[EvalRow]) -> String {
    let mut out = format!(
        "{:<28} {:>6} {:>3} | {:>7} {:>6} | {:>3} {:>7} | {:>3} {:>7}\n",
        "sample", "n", "K", "err%", "NMI", "K", "SOD%", "K", "silh%"
    );
    for r in rows {
        out += &format!(
            "{:<28} {:>6} {:>3} | {:>7.2} {:>6.3} | {:>3} {:>7.2} | {:>3} {:>7.2}\n",
            r.name,
            r.n,
            r.k_true,
            100.0 * r.known.error,
            r.known.nmi,
            r.sod.k,
            100.0 * r.sod.error,
            r.silhouette.k,
            100.0 * r.silhouette.error
        );
    }
    let t = totals(rows);
    out += &format!(
        "mean   ({:>3} samples)               | {:>7.2} {:>6.3} | {:>10.2} | {:>10.2}\n",
        t.samples,
        100.0 * t.known.mean_error,
        t.known.mean_nmi,
        100.0 * t.sod.mean_error,
        100.0 * t.silhouette.mean_error
    );
    out += &format!(
        "median                             | {:>7.2} {:>6} | {:>10.2} | {:>10.2}\n",
        100.0 * t.known.median_error,
        "",
        100.0 * t.sod.median_error,
        100.0 * t.silhouette.median_error
    );
    out += &format!(
        "K correct                          | {:>14} | {:>9.1}% | {:>9.1}%\n",
        "",
        100.0 * t.sod.k_correct,
        100.0 * t.silhouette.k_correct
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(name: &str, k_true: usize, e: [f64; 3], k: [usize; 3]) -> EvalRow {
        let s = |i: usize| Score {
            k: k[i],
            error: e[i],
            nmi: 1.0 - e[i],
        };
        EvalRow {
            name: name.into(),
            n: 10,
            k_true,
            known: s(0),
            sod: s(1),
            silhouette: s(2),
        }
    }

    #[test]
    fn totals_by_hand() {
        let rows = [
            row("a", 2, [0.1, 0.2, 0.3], [2, 2, 3]),
            row("b", 3, [0.3, 0.4, 0.1], [3, 4, 3]),
        ];
        let t = totals(&rows);
        assert!((t.known.mean_error - 0.2).abs() < 1e-12);
        assert!((t.sod.mean_error - 0.3).abs() < 1e-12);
        assert_eq!(t.sod.k_correct, 0.5);
        assert_eq!(t.silhouette.k_correct, 0.5);
        assert_eq!(t.known.k_correct, 1.0);
        let table = format_table(&rows);
        assert!(
            table.contains("a ") && table.contains("20.00") && table.contains("50.0%"),
            "{table}"
        );
    }
}
