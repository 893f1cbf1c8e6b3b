//! Tracks seen in some frames only (a `visible` mask): the fit runs on the tracks seen
//! throughout, and every other track is then placed on the motions it found ([`fit_seen`]).
//!
//! A partly seen track goes to the motion whose affine subspace is nearest over the frames it
//! was seen in (the refined structure's, or one fitted on the group's tracks over every frame);
//! a track seen in a run of frames long enough for the network may instead be placed by it,
//! window by window, where the network places the tracks seen throughout better.

use std::collections::BTreeMap;
use std::ops::RangeInclusive;
use std::time::Instant;

use super::{FitError, FitOptions, FitOutcome, embed, fit_counting, fit_sent, image_warnings};
use crate::data::visibility::MIN_SEEN_FRAMES;
use crate::data::{ImageSize, Kind, PointSet, Visibility};
use crate::geometry::subspace::masked_subspace_distance;
use crate::geometry::{self, Model};
use crate::registry::LoadedModel;

/// [`fit`](super::fit) of tracks that were not all seen in every frame ([`Visibility`]): the stages run on
/// the tracks seen throughout, and each other track seen in at least [`MIN_SEEN_FRAMES`] frames
/// then goes to the motion whose subspace (the refined structure's, or one fitted on the
/// group's tracks over every frame) is nearest over the frames it was seen in
/// ([`nearest_motion`]); with the caller's outlier threshold it is an outlier (−1) beyond it.
/// A track seen in enough consecutive frames for the network may then be placed by it instead,
/// window by window, where the network places the tracks seen throughout better
/// ([`Window::place`]). A track seen in fewer frames, or with no motion to join, is −1, and the
/// warnings count both. Structures then count, and measure their RMS over, every track labelled
/// with them (a partly seen one over its seen frames); the placement's time counts as
/// refinement's. The embeddings are those of the tracks seen throughout.
pub fn fit_seen(
    model: &LoadedModel,
    points: &PointSet,
    visibility: &Visibility,
    image: Option<ImageSize>,
    options: &FitOptions,
) -> Result<FitOutcome, FitError> {
    if visibility.len() != points.len() || visibility.frames() != points.dim() / 2 {
        return Err(FitError::Input(format!(
            "a visibility of {} tracks by {} frames for {} tracks of {} frames",
            visibility.len(),
            visibility.frames(),
            points.len(),
            points.dim() / 2
        )));
    }
    if visibility.is_complete() {
        return fit_sent(model, points, image, options, true);
    }
    let complete = visibility.complete();
    let throughout = points
        .select(&complete)
        .map_err(|e| FitError::Input(e.to_string()))?;
    let mut outcome = fit_counting(
        model,
        &throughout,
        image,
        options,
        "tracks seen in every frame",
        Some(&complete),
    )?;
    outcome.warnings.extend(image_warnings(&throughout, image));
    let t0 = Instant::now();
    let motions = motions(&throughout, &outcome);
    let placing = Placing {
        complete: &complete,
        labels: &outcome.labels,
        motions: &motions,
        threshold: options
            .refine
            .filter(|r| r.outliers)
            .and_then(|r| r.threshold),
    };
    let mut placed = place(points, visibility, &placing);
    let window = Window {
        model,
        image,
        options,
    };
    window.place(points, visibility, &complete, &mut placed)?;
    // Per structure: its tracks seen throughout's RMS, and its partly seen tracks' distances.
    let mut fits: Vec<(f64, Vec<f64>)> = Vec::new();
    for s in &mut outcome.structures {
        // A partly seen track's distance over the frames it was seen in.
        let prepared = s.model.prepared();
        let distance = |i: usize| match &s.model {
            Model::Subspace { mean, basis, .. } if !visibility.throughout(i) => {
                masked_subspace_distance(mean, basis, points.row(i), visibility.seen(i))
            }
            _ => prepared.residual(points.row(i)),
        };
        let mine: Vec<usize> = (0..points.len())
            .filter(|&i| placed.labels[i] == s.label as i64)
            .collect();
        let distances: Vec<f64> = mine.iter().map(|&i| distance(i)).collect();
        let of = |throughout: bool| {
            mine.iter()
                .zip(&distances)
                .filter(move |&(&i, _)| visibility.throughout(i) == throughout)
                .map(|(_, &d)| d)
        };
        fits.push((rms(of(true)), of(false).filter(|d| d.is_finite()).collect()));
        s.inliers = distances.len();
        let ms = distances.iter().map(|d| d * d).sum::<f64>() / distances.len().max(1) as f64;
        if ms.is_finite() {
            s.rms = ms.sqrt();
        }
    }
    outcome.warnings.extend(
        outcome
            .structures
            .iter()
            .zip(drifted(&fits))
            .filter_map(|(s, drift)| drift.map(|(n, ratio)| (s.label, n, ratio)))
            .map(|(label, n, ratio)| {
                format!(
                    "the {n} partly seen tracks placed on structure {label} lie {ratio:.1} times \
                     farther from it (median) than the noise of the tracks seen throughout: they \
                     may follow a motion that no track seen throughout shows"
                )
            }),
    );
    let tracks = |n: usize| {
        if n == 1 {
            ("track", "is")
        } else {
            ("tracks", "are")
        }
    };
    if placed.few > 0 {
        let (noun, verb) = tracks(placed.few);
        outcome.warnings.push(format!(
            "{} {noun} seen in fewer than {MIN_SEEN_FRAMES} frames {verb} labelled -1",
            placed.few
        ));
    }
    if placed.homeless > 0 {
        let (noun, verb) = tracks(placed.homeless);
        outcome.warnings.push(format!(
            "{} partly seen {noun} {verb} labelled -1: no structure has a motion subspace to \
             place {} on",
            placed.homeless,
            if placed.homeless == 1 { "it" } else { "them" },
        ));
    }
    outcome.labels = placed.labels;
    outcome.refine_ms += t0.elapsed().as_secs_f64() * 1e3;
    Ok(outcome)
}

/// Partly seen tracks placed on a structure draw a warning where their median distance to it
/// exceeds this many times its noise. On generated clips (30-60 frames, 30-60 % of the tracks
/// partly seen) the ratio stayed at or below 1.1 for every structure; with one object's tracks
/// all partly seen it reached 2.6 to 25 on the structures they were placed on.
const DRIFT_RATIO: f64 = 2.0;
/// The fewest partly seen tracks on a structure that the warning weighs.
const DRIFT_MIN_TRACKS: usize = 5;

/// The root mean square of `distances` (NaN for none).
fn rms(distances: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = distances.fold((0.0, 0usize), |(s, n), d| (s + d * d, n + 1));
    (sum / n as f64).sqrt()
}

/// For each structure, given (the RMS distance of its tracks seen throughout, the finite
/// distances of the partly seen tracks placed on it): `Some((count, ratio))` where at least
/// [`DRIFT_MIN_TRACKS`] partly seen tracks were placed and their median distance exceeds
/// [`DRIFT_RATIO`] times the structure's noise, the larger of its own RMS and the median RMS of
/// the structures (a motion held by a handful of tracks seen throughout fits them almost
/// exactly). Partly seen tracks of a motion that no track seen throughout shows are placed on
/// the nearest motion that is shown, and lie far from it.
fn drifted(fits: &[(f64, Vec<f64>)]) -> Vec<Option<(usize, f64)>> {
    let mut levels: Vec<f64> = fits.iter().map(|f| f.0).filter(|r| r.is_finite()).collect();
    levels.sort_by(f64::total_cmp);
    let Some(&typical) = levels.get(levels.len().saturating_sub(1) / 2) else {
        return vec![None; fits.len()];
    };
    fits.iter()
        .map(|(own, partial)| {
            if partial.len() < DRIFT_MIN_TRACKS {
                return None;
            }
            let mut sorted = partial.clone();
            sorted.sort_by(f64::total_cmp);
            let noise = if own.is_finite() {
                own.max(typical)
            } else {
                typical
            };
            let ratio = sorted[sorted.len() / 2] / noise;
            (noise > 0.0 && ratio > DRIFT_RATIO).then_some((partial.len(), ratio))
        })
        .collect()
}

/// What partly seen tracks are placed with.
struct Placing<'a> {
    /// The tracks seen throughout, ascending, and their labels in that order.
    complete: &'a [usize],
    labels: &'a [i64],
    motions: &'a [Motion],
    /// The caller's outlier threshold, when outliers may be answered: a track farther than it
    /// from every motion (over its seen frames) is an outlier. The threshold the refinement
    /// estimates is not used: it is set on the tracks seen throughout, and distances to a
    /// subspace over only some of the frames spread wider (on a clean KT3DMoSeg sequence it
    /// labelled 190 of 503 partly seen tracks −1).
    threshold: Option<f64>,
}

/// Where [`place`] put every track.
struct Placed {
    labels: Vec<i64>,
    /// Partly seen tracks seen in fewer than [`MIN_SEEN_FRAMES`] frames.
    few: usize,
    /// Partly seen tracks with no motion to join (no structure has a subspace, or none
    /// determines the track's coefficients).
    homeless: usize,
}

/// The labels of every track: those of the tracks seen throughout, and for each other track
/// seen in at least [`MIN_SEEN_FRAMES`] frames the label of the nearest motion over its seen
/// frames (−1 beyond the threshold); −1 for the rest. Nearest by the residual per degree of
/// freedom, e² / (2f − r) over f seen frames and a motion of rank r: a motion of higher rank
/// fits a few coordinates more closely whatever the track, and this is each motion's unbiased
/// noise estimate.
fn place(points: &PointSet, visibility: &Visibility, placing: &Placing) -> Placed {
    let n = points.len();
    let mut out = Placed {
        labels: vec![-1; n],
        few: 0,
        homeless: 0,
    };
    for (&i, &l) in placing.complete.iter().zip(placing.labels) {
        out.labels[i] = l;
    }
    for i in 0..n {
        let seen = visibility.seen(i);
        if visibility.throughout(i) {
            continue;
        }
        if seen.iter().filter(|&&s| s).count() < MIN_SEEN_FRAMES {
            out.few += 1;
            continue;
        }
        match nearest_motion(placing.motions, points.row(i), seen) {
            Some((_, d)) if placing.threshold.is_some_and(|tau| d > tau) => {}
            Some((l, _)) => out.labels[i] = l as i64,
            None => out.homeless += 1,
        }
    }
    out
}

/// The motion nearest `row` over its `seen` frames, by the residual per degree of freedom
/// e² / (2f − r) (f frames seen, r the motion's rank: a motion of higher rank fits a few
/// coordinates more closely whatever the track), with its per-frame distance
/// ([`masked_subspace_distance`]); `None` when no motion determines the track's coefficients.
fn nearest_motion(motions: &[Motion], row: &[f64], seen: &[bool]) -> Option<(usize, f64)> {
    let frames = seen.iter().filter(|&&s| s).count() as f64;
    motions
        .iter()
        .map(|m| {
            let d = masked_subspace_distance(&m.mean, &m.basis, row, seen);
            let free = 2.0 * frames - m.basis.len() as f64;
            (m.label, d, d * d * frames / free)
        })
        .filter(|(_, d, _)| d.is_finite())
        .min_by(|a, b| a.2.total_cmp(&b.2))
        .map(|(l, d, _)| (l, d))
}

/// Placement of partly seen tracks by the network, window by window.
struct Window<'a> {
    model: &'a LoadedModel,
    image: Option<ImageSize>,
    options: &'a FitOptions<'a>,
}

/// The label of the nearest centroid (`sums` of embeddings and counts by label) to `v`.
fn nearest_centroid(sums: &BTreeMap<i64, (Vec<f64>, usize)>, v: &[f32]) -> Option<i64> {
    sums.iter()
        .filter(|(_, (_, n))| *n > 0)
        .map(|(&l, (sum, n))| {
            let d: f64 = sum
                .iter()
                .zip(v)
                .map(|(s, &x)| (s / *n as f64 - f64::from(x)).powi(2))
                .sum();
            (l, d)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(l, _)| l)
}

/// The fewest points that stab every one of `ranges` (a point in each), ascending: the greedy
/// by right end (each range not yet stabbed gives its right end), which is optimal.
/// ranges `[m]` -> points `[p]`, p ≤ m.
fn fewest_stabbing(mut ranges: Vec<RangeInclusive<usize>>) -> Vec<usize> {
    ranges.sort_by_key(|r| (*r.end(), *r.start()));
    let mut points: Vec<usize> = Vec::new();
    for r in ranges {
        if points.last().is_none_or(|p| p < r.start()) {
            points.push(*r.end());
        }
    }
    points
}

/// The frame windows of `width` frames that place `tracks` (index, seen flags per frame): each
/// track seen in a run of at least `width` consecutive frames gets a window inside its longest
/// run (the first, among equally long runs). The starts are the fewest that give every such
/// track one ([`fewest_stabbing`]), and a track takes the one nearest the centre of its run
/// (the earlier of two as near). -> window start -> the tracks it places, ascending.
fn window_starts<'a>(
    tracks: impl Iterator<Item = (usize, &'a [bool])>,
    width: usize,
) -> BTreeMap<usize, Vec<usize>> {
    let width = width.max(1);
    // Each track's valid starts: a run [a, a + L) holds the windows starting at a..=a + L - width.
    let mut valid: Vec<(usize, RangeInclusive<usize>)> = Vec::new();
    for (i, seen) in tracks {
        let (mut best, mut run) = ((0, 0), 0);
        for (f, &s) in seen.iter().enumerate() {
            run = if s { run + 1 } else { 0 };
            if run > best.1 {
                best = (f + 1 - run, run);
            }
        }
        if best.1 >= width {
            valid.push((i, best.0..=best.0 + best.1 - width));
        }
    }
    let starts = fewest_stabbing(valid.iter().map(|(_, r)| r.clone()).collect());
    let mut windows: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (i, range) in valid {
        let centre = (range.start() + range.end()) / 2;
        let inside = starts.iter().copied().filter(|s| range.contains(s));
        if let Some(start) = inside.min_by_key(|&s| (s.abs_diff(centre), s)) {
            windows.entry(start).or_default().push(i);
        }
    }
    windows
}

impl Window<'_> {
    /// Partly seen tracks with a run of at least the network's frame count of consecutive seen
    /// frames: a window of that many frames inside the longest run is embedded with every track
    /// seen in all of it ([`window_starts`]: the fewest windows that give every such track
    /// one). Where the network's label centroids place the tracks seen throughout better than
    /// the motion subspaces do over the window's frames (each half of them judged by both
    /// fitted on the other half), the window's partly seen tracks take the label of the
    /// nearest centroid.
    fn place(
        &self,
        points: &PointSet,
        visibility: &Visibility,
        complete: &[usize],
        placed: &mut Placed,
    ) -> Result<(), FitError> {
        let width = self.model.card.input_dim / 2;
        let frames = visibility.frames();
        if width < 2 || width > frames {
            return Ok(());
        }
        let placeable = (0..points.len())
            .filter(|&i| !visibility.throughout(i) && placed.labels[i] >= 0)
            .map(|i| (i, visibility.seen(i)));
        let windows = window_starts(placeable, width);
        if windows.is_empty() {
            return Ok(());
        }
        let labelled: Vec<usize> = complete
            .iter()
            .copied()
            .filter(|&i| placed.labels[i] >= 0)
            .collect();
        // The judge: each half of the tracks seen throughout placed by both methods fitted on
        // the other half. The halves' motions (fitted over every frame) serve every window.
        let halves: [Vec<usize>; 2] = [
            labelled.iter().copied().step_by(2).collect(),
            labelled.iter().copied().skip(1).step_by(2).collect(),
        ];
        let half_motions = |half: &[usize]| -> Vec<Motion> {
            let mut labels: Vec<i64> = half.iter().map(|&i| placed.labels[i]).collect();
            labels.sort_unstable();
            labels.dedup();
            labels
                .into_iter()
                .filter_map(|l| {
                    let rows: Vec<&[f64]> = half
                        .iter()
                        .filter(|&&i| placed.labels[i] == l)
                        .map(|&i| points.row(i))
                        .collect();
                    Motion::fitted(l as usize, &rows)
                })
                .collect()
        };
        let judges = [
            (&halves[0], &halves[1], half_motions(&halves[0])),
            (&halves[1], &halves[0], half_motions(&halves[1])),
        ];
        for (start, tracks) in windows {
            let rows: Vec<usize> = (0..points.len())
                .filter(|&i| visibility.seen(i)[start..start + width].iter().all(|&s| s))
                .collect();
            let values: Vec<f64> = rows
                .iter()
                .flat_map(|&i| {
                    points.row(i)[2 * start..2 * (start + width)]
                        .iter()
                        .copied()
                })
                .collect();
            let cut = PointSet::from_flat(Kind::Trajectories, 2 * width, values)
                .map_err(|e| FitError::Input(e.to_string()))?;
            let options = self.options;
            let z = embed(
                self.model,
                &cut,
                self.image,
                options.symmetries,
                options.params.seed(),
            )?;
            let e = z.width;
            let z = z.per_point();
            let at = |i: usize| rows.binary_search(&i).ok().map(|r| &z[r * e..(r + 1) * e]);
            let centroids = |tracks: &[usize]| {
                let mut sums: BTreeMap<i64, (Vec<f64>, usize)> = BTreeMap::new();
                for &i in tracks {
                    let Some(v) = at(i) else { continue };
                    let entry = sums
                        .entry(placed.labels[i])
                        .or_insert_with(|| (vec![0.0; e], 0));
                    for (a, &b) in entry.0.iter_mut().zip(v) {
                        *a += f64::from(b);
                    }
                    entry.1 += 1;
                }
                sums
            };
            let seen_in_window: Vec<bool> = (0..frames)
                .map(|f| (start..start + width).contains(&f))
                .collect();
            let (mut network, mut subspaces) = (0, 0);
            for (fitted, judged, motions) in &judges {
                let sums = centroids(fitted);
                for &i in judged.iter() {
                    let l = placed.labels[i];
                    let by_network = at(i).and_then(|v| nearest_centroid(&sums, v));
                    network += usize::from(by_network == Some(l));
                    let by_subspace = nearest_motion(motions, points.row(i), &seen_in_window);
                    subspaces += usize::from(by_subspace.is_some_and(|(m, _)| m as i64 == l));
                }
            }
            if network <= subspaces {
                continue;
            }
            let sums = centroids(&labelled);
            for i in tracks {
                if let Some(l) = at(i).and_then(|v| nearest_centroid(&sums, v)) {
                    placed.labels[i] = l;
                }
            }
        }
        Ok(())
    }
}

/// A label's motion: the affine subspace its tracks lie in.
struct Motion {
    label: usize,
    mean: Vec<f64>,
    basis: Vec<Vec<f64>>,
}

impl Motion {
    /// The motion of a subspace model; `None` for any other model.
    fn of(label: usize, model: &Model) -> Option<Self> {
        match model {
            Model::Subspace { mean, basis, .. } => Some(Self {
                label,
                mean: mean.clone(),
                basis: basis.clone(),
            }),
            _ => None,
        }
    }

    /// The subspace fitted on `rows` (tracks over every frame); `None` where they determine
    /// none.
    fn fitted(label: usize, rows: &[&[f64]]) -> Option<Self> {
        Self::of(label, &geometry::fit_type("subspace", rows)?.model)
    }
}

/// Each label's motion: the refined structure's subspace, or, without refinement, one fitted on
/// the label's tracks over every frame.
fn motions(points: &PointSet, outcome: &FitOutcome) -> Vec<Motion> {
    if !outcome.structures.is_empty() {
        return outcome
            .structures
            .iter()
            .filter_map(|s| Motion::of(s.label, &s.model))
            .collect();
    }
    (0..outcome.k)
        .filter_map(|l| {
            let rows: Vec<&[f64]> = (0..points.len())
                .filter(|&i| outcome.labels[i] == l as i64)
                .map(|i| points.row(i))
                .collect();
            Motion::fitted(l, &rows)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::{ClusterParams, Selection};
    use crate::pipeline::fit;
    use crate::pipeline::tests::{fixed, image, unrefined};
    use crate::refine::RefineParams;
    use crate::registry::tests::tiny;

    /// 12 tracks over 4 frames, 6 of each of two motions (turning at different rates and
    /// drifting apart), then a track of each seen in frames 0, 1 and 3 only (garbage in frame
    /// 2) and one seen in frames 0 and 3: rows and visibility.
    fn partly_seen_tracks() -> (PointSet, Visibility) {
        let track = |x: f64, y: f64, m: usize| -> Vec<f64> {
            (0..4)
                .flat_map(|f| {
                    let a = f as f64 * [0.05, -0.2][m];
                    let (s, c) = a.sin_cos();
                    let t = f as f64 * [3.0, -2.0][m];
                    [c * x - s * y + t + 32.0, s * x + c * y - t + 32.0]
                })
                .collect()
        };
        let mut rows: Vec<Vec<f64>> = (0..12)
            .map(|i| track((i * 7 % 11) as f64 - 5.0, (i * 5 % 13) as f64 - 6.0, i / 6))
            .collect();
        for (m, x) in [(0, 4.5), (1, -2.5)] {
            let mut t = track(x, 3.0, m);
            t[4] = 900.0;
            t[5] = -900.0;
            rows.push(t);
        }
        // The first is half a pixel off its motion in frame 0.
        rows[12][0] += 0.5;
        rows.push(track(1.0, 1.0, 0));
        let mut seen = vec![vec![true; 4]; 12];
        seen.extend([
            vec![true, true, false, true],
            vec![true, true, false, true],
            vec![true, false, false, true],
        ]);
        let points = PointSet::from_rows(Kind::Trajectories, &rows).unwrap();
        (points, Visibility::new(&seen, 15, 4).unwrap())
    }

    #[test]
    fn the_nearest_centroid_is_that_of_the_nearest_mean() {
        let mut sums = BTreeMap::new();
        // Label 0: mean (1, 0); label 1: mean (0, 2); label 2: no tracks.
        sums.insert(0, (vec![3.0, 0.0], 3));
        sums.insert(1, (vec![0.0, 4.0], 2));
        sums.insert(2, (vec![0.0, 0.0], 0));
        assert_eq!(nearest_centroid(&sums, &[0.9, 0.2]), Some(0));
        assert_eq!(nearest_centroid(&sums, &[0.1, 1.5]), Some(1));
        assert_eq!(nearest_centroid(&BTreeMap::new(), &[0.0, 0.0]), None);
    }

    /// Through the pipeline: the tracks seen throughout are fitted alone (the same labels as
    /// fitting them by themselves), the others take a structure's label or −1 with a warning,
    /// and the structures count every track labelled with them.
    #[test]
    fn a_far_track_is_named_by_the_callers_row_among_partly_seen_tracks() {
        // 24 tracks of two motions seen throughout, one seen in 3 of 4 frames (row 1), and a
        // track far from all of them (row 26), seen throughout: the subset read is rows 0 and
        // 2..=26, where the far track is row 25; the warning names the caller's row.
        let track = |i: usize| -> Vec<f64> {
            let (x, y, m) = ((i * 7 % 11) as f64 - 5.0, (i * 5 % 13) as f64 - 6.0, i % 2);
            (0..4)
                .flat_map(|f| {
                    let t = f as f64 * [3.0, -2.0][m];
                    [x + t + 32.0, y - t + 32.0]
                })
                .collect()
        };
        let mut rows: Vec<Vec<f64>> = (0..26).map(track).collect();
        rows.push(vec![9e4; 8]);
        let mut seen = vec![vec![true; 4]; 27];
        seen[1][2] = false;
        let points = PointSet::from_rows(Kind::Trajectories, &rows).unwrap();
        let visibility = Visibility::new(&seen, 27, 4).unwrap();
        let model = tiny(vec![]);
        let params = fixed(2);
        let options = unrefined(&params);
        let out = fit_seen(&model, &points, &visibility, image(64.0, 64.0), &options).unwrap();
        let far: Vec<&String> = out.warnings.iter().filter(|w| w.contains("far")).collect();
        assert_eq!(far.len(), 1, "{:?}", out.warnings);
        assert!(
            far[0].ends_with("so the network did not read it: row 26"),
            "{}",
            far[0]
        );
    }

    #[test]
    fn each_track_gets_a_window_inside_its_longest_run() {
        let flags = |s: &str| -> Vec<bool> { s.chars().map(|c| c == '1').collect() };
        let tracks = [
            flags("0001111111"), // a run ending at the last frame: starts 3..=5
            flags("1111100000"), // a run exactly the width long: start 0 only
            flags("1111011110"), // two runs of 4: too short for a window of 5
            flags("1111101111"), // runs of 5 and 4: the first, start 0
            flags("0111111000"), // starts 1..=2, centre 1
        ];
        let windows = window_starts(tracks.iter().enumerate().map(|(i, t)| (i, &t[..])), 5);
        let mut got: Vec<(usize, usize)> = windows
            .iter()
            .flat_map(|(&s, ts)| ts.iter().map(move |&t| (t, s)))
            .collect();
        got.sort_unstable();
        // Valid starts by right end: 0..=0 (tracks 1, 3), 1..=2 (track 4), 3..=5 (track 0):
        // the greedy's starts are 0, 2 and 5.
        assert_eq!(got, vec![(0, 5), (1, 0), (3, 0), (4, 2)]);
        for (t, s) in got {
            assert!(tracks[t][s..s + 5].iter().all(|&v| v), "track {t} at {s}");
        }
        // Starts 1 and 3 (tracks 0 and 1 have no other); track 2 (starts 0..=4, centre 2) is
        // as near both and takes the earlier.
        let tie = [flags("011111000"), flags("000111110"), flags("111111111")];
        let windows = window_starts(tie.iter().enumerate().map(|(i, t)| (i, &t[..])), 5);
        assert_eq!(windows.get(&1), Some(&vec![0, 2]));
        assert_eq!(windows.get(&3), Some(&vec![1]));
        let none: [Vec<bool>; 0] = [];
        assert!(window_starts(none.iter().enumerate().map(|(i, t)| (i, &t[..])), 5).is_empty());
    }

    #[test]
    fn fits_of_partly_seen_tracks_fit_the_tracks_seen_throughout() {
        let model = tiny(vec![]);
        let (points, visibility) = partly_seen_tracks();
        let params = ClusterParams::builder()
            .selection(Selection::Fixed(2))
            .seed(1)
            .build()
            .unwrap();
        let options = FitOptions {
            params: &params,
            symmetries: &[],
            refine: Some(RefineParams {
                outliers: false,
                ..RefineParams::default()
            }),
            outlier_group: false,
            erratic_outliers: false,
        };
        let image = Some(ImageSize::new(64.0, 64.0).unwrap());
        let out = fit_seen(&model, &points, &visibility, image, &options).unwrap();
        let throughout = points.select(&visibility.complete()).unwrap();
        let alone = fit(&model, &throughout, image, &options).unwrap();
        assert_eq!(out.labels.len(), 15);
        assert_eq!(&out.labels[..12], &alone.labels[..]);
        assert!(
            out.labels[12..14]
                .iter()
                .all(|&l| (0..out.k as i64).contains(&l))
        );
        assert_eq!(out.labels[14], -1);
        assert!(
            out.warnings
                .iter()
                .any(|w| w == "1 track seen in fewer than 3 frames is labelled -1"),
            "{:?}",
            out.warnings
        );
        for s in &out.structures {
            let n = out.labels.iter().filter(|&&l| l == s.label as i64).count();
            assert_eq!(s.inliers, n);
            assert!(s.rms.is_finite());
        }
        // A mask of other tracks is refused, not a panic.
        let other = Visibility::new(&vec![vec![true; 4]; 3], 3, 4).unwrap();
        assert!(matches!(
            fit_seen(&model, &points, &other, image, &options),
            Err(FitError::Input(_))
        ));
        // Every track seen throughout: the plain fit.
        let all = Visibility::new(&vec![vec![true; 4]; 12], 12, 4).unwrap();
        let plain = fit_seen(&model, &throughout, &all, image, &options).unwrap();
        assert_eq!(plain.labels, alone.labels);
    }

    #[test]
    fn partly_seen_tracks_far_from_their_structure_are_flagged_against_its_noise() {
        let ten = |d: f64| vec![d; 10];
        let fits = [
            // As near as the tracks seen throughout: no warning.
            (1.0, ten(1.0)),
            // Three times farther: flagged, with the count and the ratio.
            (1.0, ten(3.0)),
            // A structure whose few tracks seen throughout fit it exactly: the noise is the
            // median structure's (1.0), and 0.5 is within it.
            (0.001, ten(0.5)),
            // Far, but too few tracks to weigh.
            (1.0, vec![9.0; DRIFT_MIN_TRACKS - 1]),
            // No track seen throughout (RMS NaN): the median structure's noise.
            (f64::NAN, ten(2.5)),
        ];
        let got = drifted(&fits);
        assert_eq!(got, [None, Some((10, 3.0)), None, None, Some((10, 2.5))]);
        // No structure with a finite noise: nothing to weigh against.
        assert_eq!(drifted(&[(f64::NAN, ten(5.0))]), [None]);
        assert!(drifted(&[]).is_empty());
        assert!((rms([3.0, 4.0].into_iter()) - 12.5_f64.sqrt()).abs() < 1e-12);
        assert!(rms(std::iter::empty()).is_nan());
    }

    /// A partly seen track goes to the motion nearest over its seen frames, or is an outlier
    /// beyond the threshold; one seen in too few frames stays −1.
    #[test]
    fn partly_seen_tracks_go_to_the_motion_of_their_seen_frames() {
        let (points, visibility) = partly_seen_tracks();
        let complete = visibility.complete();
        let truth: Vec<i64> = (0..12).map(|i| (i / 6) as i64).collect();
        let motions: Vec<Motion> = (0..2)
            .map(|m| {
                let rows: Vec<&[f64]> = (6 * m..6 * m + 6).map(|i| points.row(i)).collect();
                Motion::fitted(m, &rows).expect("a subspace")
            })
            .collect();
        let mut placing = Placing {
            complete: &complete,
            labels: &truth,
            motions: &motions,
            threshold: None,
        };
        let placed = place(&points, &visibility, &placing);
        let labels = placed.labels.clone();
        assert_eq!(&labels[..12], &truth[..]);
        assert_eq!(&labels[12..], &[0, 1, -1]);
        assert_eq!((placed.few, placed.homeless), (1, 0));
        // No motion to join: every partly seen track is homeless.
        let none = Placing {
            motions: &[],
            ..placing
        };
        let homeless = place(&points, &visibility, &none);
        assert_eq!((homeless.few, homeless.homeless), (1, 2));
        // With an outlier threshold, a partly seen track beyond it from every motion is an
        // outlier (not counted as unplaced); within it, placed as before.
        placing.threshold = Some(0.01);
        let far = place(&points, &visibility, &placing);
        assert_eq!((&far.labels[12..], far.few), (&[-1, 1, -1][..], 1));
        placing.threshold = Some(10.0);
        assert_eq!(place(&points, &visibility, &placing).labels, labels);
    }

    #[test]
    fn the_fewest_window_starts_give_every_track_one() {
        // Brute force over every set of starts in 0..12 for random ranges: the greedy's count is
        // the least that stabs them all, and it stabs them all.
        let mut state = 7u64;
        let mut next = |m: u64| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            ((state >> 33) % m) as usize
        };
        for _ in 0..200 {
            let ranges: Vec<RangeInclusive<usize>> = (0..1 + next(6))
                .map(|_| {
                    let a = next(10);
                    a..=a + next(3)
                })
                .collect();
            let points = fewest_stabbing(ranges.clone());
            assert!(points.windows(2).all(|w| w[0] < w[1]), "{points:?}");
            let stabs = |set: &[usize]| ranges.iter().all(|r| set.iter().any(|p| r.contains(p)));
            assert!(stabs(&points), "{ranges:?} {points:?}");
            let least = (0u32..1 << 12)
                .filter(|mask| {
                    let set: Vec<usize> = (0..12).filter(|b| mask >> b & 1 == 1).collect();
                    stabs(&set)
                })
                .map(u32::count_ones)
                .min()
                .unwrap();
            assert_eq!(points.len(), least as usize, "{ranges:?}");
        }
        assert!(fewest_stabbing(Vec::new()).is_empty());
    }
}
