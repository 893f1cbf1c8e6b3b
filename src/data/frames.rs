//! Tracks of any length read at a model's frame count.
//!
//! A trajectory model reads F_m frames (`input_dim = 2 F_m`); a user's tracker gives F ≥ 2.
//! Frame i of the F_m the network reads sits at time t_i on the input's frame axis:
//!
//! - [`FrameSampling::Spread`]: t_i = i (F − 1) / (F_m − 1), frames spread over the whole track
//!   (the first and last frames always read): a long track's motion is seen whole, and at 30 fps a
//!   hand-held camera's motion over 5 consecutive frames is too small to separate motions;
//! - [`FrameSampling::First`]: t_i = i, the first F_m frames, as the model was trained (when
//!   F ≥ F_m).
//! - [`FrameSampling::Windows`]: W = min(⌈F / F_m⌉, [`MAX_WINDOWS`]) windows of F_m consecutive
//!   frames, window w starting at s_w = round(w (F − F_m) / (W − 1)) (the first window at frame 0,
//!   the last ending at the last frame), t_i = s_w + i. The network reads every window and the
//!   fit sets their embeddings side by side, so motion anywhere along a long track is seen at
//!   the frame rate the model was trained on. F ≤ F_m gives the one window `First` reads.
//!
//! A position at a fractional time is interpolated linearly between its two frames; a track of
//! fewer than F_m frames is thus read at interpolated times between its real ones. The tracks read
//! are those seen in every frame; a request's `visible` mask places the others afterwards
//! ([`crate::data::Visibility`]).

use serde::{Deserialize, Serialize};

use super::PointSet;

/// Which frames of a longer (or shorter) track a model reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum FrameSampling {
    /// F_m frames spread evenly from the first frame to the last.
    #[default]
    Spread,
    /// The first F_m frames (interpolated when the track is shorter).
    First,
    /// Windows of F_m consecutive frames spread over the track, each read by the network.
    Windows,
}

/// The most windows [`FrameSampling::Windows`] reads: each costs one forward pass. Four give a
/// lower known-K error than eight on long synthetic tracks (60 frames: 9.85 against 11.34 %;
/// 30 frames: 6.70 against 7.09; docs/RESULTS.md) for two thirds of the network's time on 30
/// frames.
pub const MAX_WINDOWS: usize = 4;

impl FrameSampling {
    /// Time of each of `target` frames on an axis of `frames` frames (both ≥ 2 for `Spread`);
    /// for `Windows`, the first window's.
    pub fn times(self, frames: usize, target: usize) -> Vec<f64> {
        match self {
            FrameSampling::Spread if target > 1 => {
                let step = (frames - 1) as f64 / (target - 1) as f64;
                (0..target).map(|i| i as f64 * step).collect()
            }
            FrameSampling::Spread => vec![0.0],
            // Windows: the first window.
            FrameSampling::First | FrameSampling::Windows if frames >= target => {
                (0..target).map(|i| i as f64).collect()
            }
            // Fewer frames than the model reads: spread them, as nothing else is there.
            FrameSampling::First | FrameSampling::Windows => {
                FrameSampling::Spread.times(frames, target)
            }
        }
    }

    /// The times of each window the network reads, `target` each, on an axis of `frames`
    /// frames: one window for `Spread` and `First` ([`Self::times`]), up to [`MAX_WINDOWS`]
    /// for `Windows`.
    pub fn windows(self, frames: usize, target: usize) -> Vec<Vec<f64>> {
        if self != FrameSampling::Windows || frames <= target {
            return vec![self.times(frames, target)];
        }
        let count = frames.div_ceil(target).min(MAX_WINDOWS);
        let span = (frames - target) as f64;
        (0..count)
            .map(|w| {
                let start = (w as f64 * span / (count - 1) as f64).round();
                (0..target).map(|i| start + i as f64).collect()
            })
            .collect()
    }
}

/// Tracks `[n, 2F]` -> `[n, 2 target]`, read at the times `sampling` gives; the input's width
/// must be even (every trajectory [`PointSet`] is). The result is a trajectory set of the same
/// kind and order.
pub fn resample(points: &PointSet, target: usize, sampling: FrameSampling) -> PointSet {
    read_at(points, &sampling.times(points.dim() / 2, target))
}

/// Tracks `[n, 2F]` -> one `[n, 2 target]` set per window `sampling` reads
/// ([`FrameSampling::windows`]), in window order.
pub fn resample_windows(
    points: &PointSet,
    target: usize,
    sampling: FrameSampling,
) -> Vec<PointSet> {
    let frames = points.dim() / 2;
    let windows = sampling.windows(frames, target);
    windows.iter().map(|t| read_at(points, t)).collect()
}

/// Tracks `[n, 2F]` -> `[n, 2 times.len()]`, each read at the given (fractional) frame times.
fn read_at(points: &PointSet, times: &[f64]) -> PointSet {
    let frames = points.dim() / 2;
    let target = times.len();
    let mut values = Vec::with_capacity(points.len() * 2 * target);
    for i in 0..points.len() {
        let row = points.row(i);
        for &t in times {
            let lo = (t.floor() as usize).min(frames - 1);
            let hi = (lo + 1).min(frames - 1);
            let w = t - lo as f64;
            for c in 0..2 {
                let (a, b) = (row[2 * lo + c], row[2 * hi + c]);
                values.push(if w == 0.0 { a } else { a + w * (b - a) });
            }
        }
    }
    PointSet::from_flat(points.kind(), 2 * target, values)
        .expect("interpolated finite coordinates stay within the accepted range")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::Kind;

    /// Tracks whose frame f holds (100 i + f, -f).
    fn tracks(n: usize, frames: usize) -> PointSet {
        let values = (0..n)
            .flat_map(|i| (0..frames).flat_map(move |f| [(100 * i + f) as f64, -(f as f64)]))
            .collect();
        PointSet::from_flat(Kind::Trajectories, 2 * frames, values).unwrap()
    }

    #[test]
    fn spread_reads_the_first_and_last_frames_and_evenly_between() {
        let p = resample(&tracks(2, 29), 5, FrameSampling::Spread);
        assert_eq!(p.dim(), 10);
        assert_eq!(
            p.row(1),
            &[100., 0., 107., -7., 114., -14., 121., -21., 128., -28.]
        );
    }

    #[test]
    fn first_reads_the_first_frames() {
        let p = resample(&tracks(2, 29), 5, FrameSampling::First);
        assert_eq!(p.row(0), &[0., 0., 1., -1., 2., -2., 3., -3., 4., -4.]);
    }

    #[test]
    fn short_tracks_are_read_at_interpolated_times() {
        // Two frames read as five: times 0, 0.25, 0.5, 0.75, 1.
        for sampling in [FrameSampling::Spread, FrameSampling::First] {
            let p = resample(&tracks(2, 2), 5, sampling);
            assert_eq!(
                p.row(0),
                &[0., 0., 0.25, -0.25, 0.5, -0.5, 0.75, -0.75, 1., -1.]
            );
        }
    }

    #[test]
    fn the_model_width_reads_every_frame_unchanged() {
        let t = tracks(3, 5);
        for sampling in [FrameSampling::Spread, FrameSampling::First] {
            assert_eq!(resample(&t, 5, sampling), t);
        }
        assert_eq!(resample_windows(&t, 5, FrameSampling::Windows), vec![t]);
    }

    #[test]
    fn windows_cover_the_track_from_first_to_last_frame() {
        let starts = |frames| -> Vec<f64> {
            let w = FrameSampling::Windows.windows(frames, 5);
            for times in &w {
                assert_eq!(times.len(), 5);
                let step = if frames >= 5 {
                    1.0
                } else {
                    (frames - 1) as f64 / 4.0
                };
                assert!(times.windows(2).all(|p| p[1] - p[0] == step), "consecutive");
            }
            w.iter().map(|t| t[0]).collect()
        };
        assert_eq!(starts(8), vec![0., 3.]);
        assert_eq!(starts(10), vec![0., 5.]);
        assert_eq!(starts(15), vec![0., 5., 10.]);
        assert_eq!(starts(16), vec![0., 4., 7., 11.]);
        // A long track: MAX_WINDOWS windows, the last ending at the last frame.
        let long = starts(100);
        assert_eq!(long.len(), MAX_WINDOWS);
        assert_eq!((long[0], long[MAX_WINDOWS - 1]), (0., 95.));
        // Short tracks: the one window First reads, interpolated.
        assert_eq!(starts(3), vec![0.]);
        let p = resample_windows(&tracks(2, 12), 5, FrameSampling::Windows);
        assert_eq!(p.len(), 3);
        assert_eq!(
            p[2].row(0),
            &[7., -7., 8., -8., 9., -9., 10., -10., 11., -11.]
        );
        // Spread and First read one window, as resample does.
        for sampling in [FrameSampling::Spread, FrameSampling::First] {
            let t = tracks(2, 12);
            assert_eq!(
                resample_windows(&t, 5, sampling),
                vec![resample(&t, 5, sampling)]
            );
        }
    }
}
