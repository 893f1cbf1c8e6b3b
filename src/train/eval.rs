//! Evaluation of a model on labelled samples: error rate, NMI and chosen K, with known K and with
//! automatic K (SOD and silhouette), per sample and in total.

use serde::{Deserialize, Serialize};

use crate::cluster::{ClusterParams, Clustering, Selection};
use crate::data::Sample;
use crate::metrics::{
    OutlierScore, error_rate, mean_median, model_selection_rate, nmi, outlier_score,
};
use crate::pipeline::{self, Embedding, FitError};
use crate::refine::{self, RefineParams, Refined};
use crate::registry::LoadedModel;

/// The score of one labelling.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Score {
    pub k: usize,
    pub error: f64,
    pub nmi: f64,
    /// With refinement, on a sample with a gross-outlier group: how well the answer's −1
    /// labels match it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outliers: Option<OutlierScore>,
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
    /// The k-means residual curve r(K), K = 1, 2, ... (one past `k_max`, as SOD reads it), so
    /// that other rules for choosing K can be studied without embedding again. Empty in results
    /// written before it was recorded.
    #[serde(default)]
    pub residuals: Vec<f64>,
    /// The error of the k-means clustering at every K = 1..=`k_max` (the same seeded runs SOD
    /// and silhouette choose among), so that a rule's choice can be scored too. Empty in results
    /// written before it was recorded.
    #[serde(default)]
    pub errors_by_k: Vec<f64>,
}

/// Totals over rows for one way of choosing K.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub mean_error: f64,
    pub median_error: f64,
    pub mean_nmi: f64,
    /// Share of samples whose K was chosen right (1 for known K).
    pub k_correct: f64,
    /// Mean outlier precision and recall over the samples that score them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outliers: Option<OutlierScore>,
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
    /// Geometric refinement after every clustering, or `None` to score the clustering alone.
    pub refine: Option<RefineParams>,
    /// Refinement starts from the sample's true groups (its outlier group included) instead of
    /// the network's clustering: what the geometric stage gives a perfect network, the ceiling
    /// of refinement and outlier detection. Every row then scores that one answer.
    pub from_truth: bool,
}

/// Scores one clustering of the sample's embeddings, K chosen by `selection`; `truth`, when
/// refinement starts from the true groups ([`EvalSettings::from_truth`]), is the score of every
/// clustering.
fn score(
    sample: &Sample,
    model: &LoadedModel,
    embedding: &Embedding,
    selection: Selection,
    s: &EvalSettings,
    truth: Option<Score>,
) -> Result<(Score, Clustering), FitError> {
    let params = ClusterParams::builder()
        .selection(selection)
        .k_max(s.k_max)
        .restarts(s.restarts)
        .seed(s.seed)
        .build()?;
    let clustering = pipeline::cluster(model, embedding, &params)?;
    let score = match (&s.refine, truth) {
        (_, Some(truth)) => truth,
        // Tracks set apart as erratic are answered -1, as a fit answers them by default.
        (None, None) => {
            let mut labels: Vec<i64> = clustering.labels.iter().map(|&l| l as i64).collect();
            pipeline::erratic_as_outliers(&mut labels, &embedding.erratic);
            let (labels, _) = outliers_as_group(&labels, clustering.k);
            Score {
                k: clustering.k,
                error: error_rate(&sample.labels, &labels),
                nmi: nmi(&sample.labels, &labels),
                outliers: None,
            }
        }
        (Some(r), None) => {
            let (_, mut refined) =
                pipeline::refine_chosen(model, &sample.points, embedding, &params, &clustering, r)?;
            pipeline::erratic_as_outliers(&mut refined.labels, &embedding.erratic);
            refined_score(sample, &refined)
        }
    };
    Ok((score, clustering))
}

/// The score of a refined answer on its sample.
fn refined_score(sample: &Sample, refined: &Refined) -> Score {
    let (labels, _) = outliers_as_group(&refined.labels, refined.structures.len());
    Score {
        // The structures found, and the outlier group where the sample has one (its `k` counts
        // it): points flagged on a clean sample cost error, not a K.
        k: refined.structures.len() + usize::from(sample.outliers),
        error: error_rate(&sample.labels, &labels),
        nmi: nmi(&sample.labels, &labels),
        outliers: sample.outliers.then(|| {
            let truth: Vec<bool> = sample.labels.iter().map(|&l| l == 0).collect();
            outlier_score(&truth, &refined.labels)
        }),
    }
}

/// Refined labels scored as a sample's are: the outliers (−1) as one more group, labelled k, as
/// a dataset's outlier label is one group of its own. -> (labels, groups including the outliers').
pub fn outliers_as_group(labels: &[i64], k: usize) -> (Vec<usize>, usize) {
    let any = labels.iter().any(|&l| l < 0);
    let labels = labels
        .iter()
        .map(|&l| usize::try_from(l).unwrap_or(k))
        .collect();
    (labels, k + usize::from(any))
}

/// Evaluates one sample with known K, SOD and silhouette. The sample is embedded once (with the
/// card's test symmetries) and every clustering (each K up to `k_max`, SOD's, silhouette's)
/// shares the embeddings; every K has its own seeded k-means, so each is the clustering a fit
/// with that selection returns.
pub fn evaluate_sample(
    model: &LoadedModel,
    sample: &Sample,
    s: &EvalSettings,
) -> Result<EvalRow, FitError> {
    // Two images of two sizes: scored in the first image's frame, where a fit runs.
    let moved;
    let sample = match sample.image_size.filter(|size| size.second.is_some()) {
        Some(size) => {
            let (points, first) = size.in_first_frame(&sample.points);
            moved = Sample {
                points: points.into_owned(),
                image_size: Some(first),
                ..sample.clone()
            };
            &moved
        }
        None => sample,
    };
    let z = pipeline::embed(
        model,
        &sample.points,
        sample.image_size,
        &model.card.test_symmetries,
        s.seed,
    )?;
    // Refinement from the true groups does not depend on the clustering: done once.
    let truth = s.refine.filter(|_| s.from_truth).map(|r| {
        let family = model.card.family();
        let refined = refine::refine(&sample.points, &sample.labels, sample.k, family, &r, None);
        refined_score(sample, &refined)
    });
    let score = |selection| score(sample, model, &z, selection, s, truth);
    let by_k = (1..=s.k_max.min(sample.points.len()))
        .map(|k| Ok(score(Selection::Fixed(k))?.0))
        .collect::<Result<Vec<Score>, FitError>>()?;
    let known = match sample.k.checked_sub(1).and_then(|i| by_k.get(i)) {
        Some(&known) => known,
        None => score(Selection::Fixed(sample.k))?.0,
    };
    let (sod, curve) = score(Selection::Sod)?;
    let (silhouette, _) = score(Selection::Silhouette)?;
    let errors_by_k = by_k.iter().map(|score| score.error).collect();
    Ok(EvalRow {
        name: sample.name.clone(),
        n: sample.points.len(),
        k_true: sample.k,
        known,
        sod,
        silhouette,
        residuals: curve.residuals.iter().map(|r| r.1).collect(),
        errors_by_k,
    })
}

fn summarise(rows: &[EvalRow], pick: fn(&EvalRow) -> Score) -> Summary {
    let errors: Vec<f64> = rows.iter().map(|r| pick(r).error).collect();
    let (mean_error, median_error) = mean_median(&errors);
    let nmis: Vec<f64> = rows.iter().map(|r| pick(r).nmi).collect();
    let pairs: Vec<(usize, usize)> = rows.iter().map(|r| (r.k_true, pick(r).k)).collect();
    let scored: Vec<OutlierScore> = rows.iter().filter_map(|r| pick(r).outliers).collect();
    let mean =
        |f: fn(&OutlierScore) -> f64| mean_median(&scored.iter().map(f).collect::<Vec<_>>()).0;
    Summary {
        mean_error,
        median_error,
        mean_nmi: mean_median(&nmis).0,
        k_correct: model_selection_rate(&pairs),
        outliers: (!scored.is_empty()).then(|| OutlierScore {
            precision: mean(|o| o.precision),
            recall: mean(|o| o.recall),
        }),
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
            outliers: None,
        };
        EvalRow {
            name: name.into(),
            n: 10,
            k_true,
            known: s(0),
            sod: s(1),
            silhouette: s(2),
            residuals: vec![],
            errors_by_k: vec![],
        }
    }

    /// With refinement, samples with a gross-outlier group score how their −1 labels match it;
    /// others, and evaluations without refinement, do not.
    #[test]
    fn outliers_are_scored_after_refinement_where_the_sample_has_them() {
        use crate::data::motion::MotionSpec;
        let model = crate::registry::tests::tiny(vec![]);
        let sample = |spec: &str| {
            let spec: MotionSpec = spec.parse().unwrap();
            spec.sequences().unwrap()[0].sample()
        };
        let with = sample("count=1,seed=2,frames=2,motions=2,points=30,outliers=0.2");
        let without = sample("count=1,seed=2,frames=2,motions=2,points=30");
        assert!(with.outliers && !without.outliers);
        let s = EvalSettings {
            k_max: 4,
            restarts: 2,
            seed: 1,
            refine: Some(RefineParams::default()),
            from_truth: false,
        };
        let row = evaluate_sample(&model, &with, &s).unwrap();
        let o = row.known.outliers.expect("scored");
        assert!((0.0..=1.0).contains(&o.precision) && (0.0..=1.0).contains(&o.recall));
        let t = totals(std::slice::from_ref(&row));
        assert_eq!(t.known.outliers, Some(o));
        let clean = evaluate_sample(&model, &without, &s).unwrap();
        assert!(clean.known.outliers.is_none());
        // K counts structures: points flagged on a clean sample are not one more group.
        assert!(clean.known.k <= without.k, "{clean:?}");
        let plain = EvalSettings { refine: None, ..s };
        assert!(
            evaluate_sample(&model, &with, &plain)
                .unwrap()
                .known
                .outliers
                .is_none()
        );
    }

    /// Refinement from the true groups does not depend on the network: an untrained one scores
    /// what the geometry alone gives, the same for every selection.
    #[test]
    fn refinement_from_truth_scores_the_geometry_alone() {
        use crate::data::motion::MotionSpec;
        let spec: MotionSpec = "count=1,seed=3,frames=6,motions=2,points=40,outliers=0.2,noise=0.5"
            .parse()
            .unwrap();
        let sample = spec.sequences().unwrap()[0].sample();
        let s = EvalSettings {
            k_max: 4,
            restarts: 2,
            seed: 1,
            refine: Some(RefineParams::default()),
            from_truth: true,
        };
        let rows: Vec<EvalRow> = [1, 2]
            .map(|seed| {
                let model = crate::registry::tests::tiny_model(
                    "t",
                    crate::data::Kind::Trajectories,
                    12,
                    seed,
                );
                evaluate_sample(&model, &sample, &s).unwrap()
            })
            .into();
        for r in &rows {
            assert_eq!(r.known, r.sod);
            assert_eq!(r.known, r.silhouette);
        }
        assert_eq!(rows[0].known, rows[1].known, "no network in it");
        let o = rows[0].known.outliers.expect("scored");
        assert!(o.precision > 0.9 && o.recall > 0.5, "{o:?}");
        let network = EvalSettings {
            from_truth: false,
            ..s
        };
        let model = crate::registry::tests::tiny_model("t", crate::data::Kind::Trajectories, 12, 1);
        let row = evaluate_sample(&model, &sample, &network).unwrap();
        assert!(row.known.error > rows[0].known.error, "{row:?}");
    }

    /// Evaluating embeds once and clusters three times; each score must be what a fit with
    /// that selection gives, and the curve SOD's.
    #[test]
    fn evaluate_sample_matches_three_fits() {
        use crate::data::{ImageSize, Kind, PointSet, Symmetry};
        let model =
            crate::registry::tests::tiny_seeded(vec![Symmetry::Mirror, Symmetry::Reverse], 3);
        // 24 two-frame tracks in three groups moving differently.
        let mut values = Vec::new();
        let mut labels = Vec::new();
        for i in 0..24 {
            let (g, x, y) = (i % 3, (i * 7 % 19) as f64, (i * 5 % 17) as f64);
            let shift = [(0.0, 0.0), (3.0, -1.0), (-2.0, 4.0)][g];
            values.extend([x, x + shift.0, y, y + shift.1]);
            labels.push(g);
        }
        let sample = Sample {
            name: "s".into(),
            points: PointSet::from_flat(Kind::Trajectories, 4, values).unwrap(),
            labels,
            k: 3,
            image_size: Some(ImageSize::new(20.0, 20.0).unwrap()),
            outliers: false,
        };
        let s = EvalSettings {
            k_max: 5,
            restarts: 2,
            seed: 4,
            refine: None,
            from_truth: false,
        };
        let row = evaluate_sample(&model, &sample, &s).unwrap();
        let fit = |selection| {
            let params = ClusterParams::builder()
                .selection(selection)
                .k_max(s.k_max)
                .restarts(s.restarts)
                .seed(s.seed)
                .build()
                .unwrap();
            model
                .fit(&sample.points, sample.image_size, &params)
                .unwrap()
                .clustering
        };
        for (got, selection) in [
            (row.known, Selection::Fixed(3)),
            (row.sod, Selection::Sod),
            (row.silhouette, Selection::Silhouette),
        ] {
            let c = fit(selection);
            assert_eq!(got.k, c.k, "{selection:?}");
            assert_eq!(
                got.error,
                error_rate(&sample.labels, &c.labels),
                "{selection:?}"
            );
            assert_eq!(got.nmi, nmi(&sample.labels, &c.labels), "{selection:?}");
        }
        let curve: Vec<f64> = fit(Selection::Sod).residuals.iter().map(|r| r.1).collect();
        assert_eq!(row.residuals, curve);
        assert_eq!(row.residuals.len(), s.k_max + 1);
        assert_eq!(row.known.k, 3);
        assert_eq!(row.errors_by_k.len(), s.k_max);
        assert_eq!(row.errors_by_k[2], row.known.error);
        assert_eq!(row.errors_by_k[row.sod.k - 1], row.sod.error);
        assert_eq!(row.errors_by_k[row.silhouette.k - 1], row.silhouette.error);
        // One cluster puts every point but the largest group's third wrong: 16 of 24.
        assert!((row.errors_by_k[0] - 16.0 / 24.0).abs() < 1e-12);
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
