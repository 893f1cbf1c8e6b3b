//! Clustering metrics: classification error under the best label matching, normalised mutual
//! information, the model-selection correct rate, and how well outliers (−1) were found.

use pathfinding::prelude::{Matrix, kuhn_munkres};

fn num_labels(labels: &[usize]) -> usize {
    labels.iter().max().map_or(0, |&m| m + 1)
}

/// Contingency table `[truth][pred]`.
fn contingency(truth: &[usize], pred: &[usize]) -> Vec<Vec<i64>> {
    let (kt, kp) = (num_labels(truth), num_labels(pred));
    let mut table = vec![vec![0i64; kp]; kt];
    for (&t, &p) in truth.iter().zip(pred) {
        table[t][p] += 1;
    }
    table
}

/// Fraction of points misclassified under the best one-to-one matching of predicted to true
/// labels (Hungarian algorithm). Predicted and true K may differ: unmatched clusters count as
/// errors. Panics if the slices differ in length; an empty input scores 0.
pub fn error_rate(truth: &[usize], pred: &[usize]) -> f64 {
    assert_eq!(truth.len(), pred.len(), "label vectors differ in length");
    if truth.is_empty() {
        return 0.0;
    }
    let table = contingency(truth, pred);
    let size = table.len().max(table.first().map_or(0, |r| r.len()));
    let mut weights = Matrix::new(size, size, 0i64);
    for (t, row) in table.iter().enumerate() {
        for (p, &c) in row.iter().enumerate() {
            weights[(t, p)] = c;
        }
    }
    let (matched, _) = kuhn_munkres(&weights);
    1.0 - matched as f64 / truth.len() as f64
}

/// Normalised mutual information, `I(T; P) / ((H(T) + H(P)) / 2)` (the arithmetic
/// normalisation, scikit-learn's default). Two single-cluster labellings score 1.
pub fn nmi(truth: &[usize], pred: &[usize]) -> f64 {
    assert_eq!(truth.len(), pred.len(), "label vectors differ in length");
    let n = truth.len() as f64;
    if truth.is_empty() {
        return 1.0;
    }
    let table = contingency(truth, pred);
    let rows: Vec<f64> = table.iter().map(|r| r.iter().sum::<i64>() as f64).collect();
    let cols: Vec<f64> = (0..table[0].len())
        .map(|p| table.iter().map(|r| r[p]).sum::<i64>() as f64)
        .collect();
    let entropy = |m: &[f64]| {
        -m.iter()
            .filter(|&&c| c > 0.0)
            .map(|&c| c / n * (c / n).ln())
            .sum::<f64>()
    };
    let (ht, hp) = (entropy(&rows), entropy(&cols));
    let mut mi = 0.0;
    for (t, row) in table.iter().enumerate() {
        for (p, &c) in row.iter().enumerate() {
            if c > 0 {
                let c = c as f64;
                mi += c / n * (c * n / (rows[t] * cols[p])).ln();
            }
        }
    }
    let denom = (ht + hp) / 2.0;
    if denom <= 0.0 {
        1.0
    } else {
        (mi / denom).clamp(0.0, 1.0)
    }
}

/// Share of samples whose chosen K equals the true K: pairs `(true, chosen)`.
pub fn model_selection_rate(pairs: &[(usize, usize)]) -> f64 {
    if pairs.is_empty() {
        return 0.0;
    }
    pairs.iter().filter(|(t, c)| t == c).count() as f64 / pairs.len() as f64
}

/// How well the points answered −1 match the true outliers.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OutlierScore {
    /// Of the points answered −1, the share that are true outliers (1 when none was answered).
    pub precision: f64,
    /// Of the true outliers, the share answered −1 (1 when there are none).
    pub recall: f64,
}

/// Outlier precision and recall: `outlier[i]` says whether point i is a true outlier, `answer`
/// is the fit's labels (negative = outlier).
pub fn outlier_score(outlier: &[bool], answer: &[i64]) -> OutlierScore {
    assert_eq!(
        outlier.len(),
        answer.len(),
        "label vectors differ in length"
    );
    let flagged = answer.iter().filter(|&&l| l < 0).count();
    let truth = outlier.iter().filter(|&&o| o).count();
    let hits = outlier
        .iter()
        .zip(answer)
        .filter(|&(&o, &l)| o && l < 0)
        .count();
    let share = |a: usize, b: usize| if b == 0 { 1.0 } else { a as f64 / b as f64 };
    OutlierScore {
        precision: share(hits, flagged),
        recall: share(hits, truth),
    }
}

/// Mean and median of a list of values (NaN for an empty list).
pub fn mean_median(values: &[f64]) -> (f64, f64) {
    if values.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let mut s = values.to_vec();
    s.sort_by(f64::total_cmp);
    let m = s.len() / 2;
    let median = if s.len() % 2 == 1 {
        s[m]
    } else {
        (s[m - 1] + s[m]) / 2.0
    };
    (mean, median)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outlier_score_by_hand() {
        let truth = [true, true, false, false, false];
        let s = outlier_score(&truth, &[-1, 0, -1, 1, 1]);
        assert_eq!((s.precision, s.recall), (0.5, 0.5));
        let s = outlier_score(&truth, &[-1, -1, 0, 1, 1]);
        assert_eq!((s.precision, s.recall), (1.0, 1.0));
        // Nothing flagged, nothing to find.
        let s = outlier_score(&[false, false], &[0, 1]);
        assert_eq!((s.precision, s.recall), (1.0, 1.0));
        let s = outlier_score(&truth, &[0, 0, 1, 1, 1]);
        assert_eq!((s.precision, s.recall), (1.0, 0.0));
    }

    #[test]
    fn error_rate_by_hand() {
        assert_eq!(error_rate(&[0, 0, 1, 1], &[1, 1, 0, 0]), 0.0);
        assert_eq!(error_rate(&[0, 0, 1, 1], &[0, 1, 1, 1]), 0.25);
        // Predicted K larger than true K: one cluster goes unmatched.
        assert!((error_rate(&[0, 0, 0, 1, 1, 1], &[0, 0, 2, 1, 1, 1]) - 1.0 / 6.0).abs() < 1e-12);
        // Predicted K smaller: everything in one cluster matches only the largest group.
        assert!((error_rate(&[0, 0, 0, 1, 1, 2], &[0; 6]) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn error_rate_needs_a_real_matching_not_greedy() {
        // Greedy majority per predicted cluster would map both to truth 0.
        let truth = [0, 0, 0, 1, 0, 1, 1, 1];
        let pred = [0, 0, 0, 0, 1, 1, 1, 1];
        assert!((error_rate(&truth, &pred) - 0.25).abs() < 1e-12);
    }

    #[test]
    fn invariant_to_renaming_labels() {
        let t = [0, 1, 2, 2, 1, 0, 0, 2];
        let p = [1, 1, 2, 0, 1, 0, 0, 2];
        let p2: Vec<usize> = p.iter().map(|&l| [2, 0, 1][l]).collect();
        assert_eq!(error_rate(&t, &p), error_rate(&t, &p2));
        assert!((nmi(&t, &p) - nmi(&t, &p2)).abs() < 1e-12);
    }

    #[test]
    fn nmi_by_hand() {
        assert!((nmi(&[0, 0, 1, 1], &[1, 1, 0, 0]) - 1.0).abs() < 1e-12);
        // Independent labellings share no information.
        assert!(nmi(&[0, 0, 1, 1], &[0, 1, 0, 1]).abs() < 1e-12);
        // T = [0,0,1,1], P = [0,0,0,1]: H(T) = ln 2, H(P) = -(3/4 ln 3/4 + 1/4 ln 1/4),
        // I = 1/2 ln(2/(3/2)) ... computed: I = 0.5 ln(4/3) + 0.25 ln(2/3) + 0.25 ln 2.
        let i = 0.5 * (4.0f64 / 3.0).ln() + 0.25 * (2.0f64 / 3.0).ln() + 0.25 * 2f64.ln();
        let ht = 2f64.ln();
        let hp = -(0.75 * 0.75f64.ln() + 0.25 * 0.25f64.ln());
        assert!((nmi(&[0, 0, 1, 1], &[0, 0, 0, 1]) - i / ((ht + hp) / 2.0)).abs() < 1e-12);
    }

    #[test]
    fn selection_rate_and_summary() {
        assert_eq!(model_selection_rate(&[(2, 2), (3, 4), (5, 5), (1, 2)]), 0.5);
        assert_eq!(mean_median(&[3.0, 1.0, 2.0, 10.0]), (4.0, 2.5));
        assert_eq!(mean_median(&[3.0, 1.0, 2.0]), (2.0, 2.0));
    }
}
