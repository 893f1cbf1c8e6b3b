//! The rows a network reads: each distinct row once, and none that lies far from all the rest.
//!
//! **Repeated rows.** Matchers often report one correspondence several times (AdelaideRMF's
//! pairs repeat 5.7 % of their rows, bonhall 11 %), and a caller may send a set twice. A point
//! whose nearest neighbour is itself, at offset 0, is a picture no network was trained on: sent
//! twice, an `lce` set of 200 points fell from 10 % to 37 % error. For a network that reads
//! neighbourhoods each distinct row is read once; its copies take its embedding, and refinement
//! still weighs every row. A network that reads each row alone (`adelaide-homography`) reads
//! repeats as sent: to it a repeat is one more row, and reading it once only moved K on a few
//! AdelaideRMF pairs, both ways.
//!
//! **Far rows.** A row far from the rest moves the normalisation (the centroid and the RMS
//! spread, which it inflates) and the network's context normalisation (each channel's variance
//! over the points), and squeezes every other point together: one point at (20, 20) beside an
//! `lce` set spanning ±2.5 took it from 10 % to 66 % error. Rows are ordered by their distance to
//! the coordinate-wise median m; the row x at place j is far when ‖x − c_j‖ > F · s_j, with c_j
//! the centroid of the j rows nearer m and s_j their RMS distance to c_j, F = [`FAR_SPREADS`],
//! and at least [`FAR_GAP`] · s_j from the nearest of those rows (the outer rows of a long
//! sparse line beside a small dense circle pass the first test, not the second).
//! The first far row, and every row beyond it, is set apart; only the outermost
//! [`MAX_FAR_SHARE`] of the rows are tested. Testing each row against the nearer ones alone keeps
//! a cluster of far rows (several lost points at one place) from hiding itself by inflating the
//! spread. Points on curves, planes or motions of one scene lie within a few spreads of their
//! centroid (uniform clutter over the bounding box within about 2.5), so F = 10 sets apart only
//! what cannot belong to the scene. A far row is not read: it takes the embedding of its
//! nearest read row, and refinement answers it −1 where no structure explains it.

use std::cmp::Ordering;

use super::{MIN_POINTS, PointSet};
use crate::geometry::linalg::median;

/// A row farther than this many RMS spreads of the other rows from their centroid is far.
pub const FAR_SPREADS: f64 = 10.0;
/// A far row is also at least this many of those spreads from the nearest of the rows nearer
/// the median than it: a long sparse structure beside a small dense one runs on, a stray row
/// stands alone.
pub const FAR_GAP: f64 = 2.0;
/// The largest share of the rows that may be set apart as far.
pub const MAX_FAR_SHARE: f64 = 0.05;

/// The rows of a set to read ([`screen`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Screened {
    /// The rows read, ascending; `None`: every row.
    pub read: Option<Vec<usize>>,
    /// The rows set apart as far from the rest, ascending; the erratic tracks among them.
    pub far: Vec<usize>,
    /// The tracks among `far` set apart for moving erratically ([`erratic_tracks`]), ascending.
    pub erratic: Vec<usize>,
}

/// `points` `[n, d]` -> the rows to read: less the far ones ([`far_rows`]) and the erratic
/// tracks ([`erratic_in_windows`] of `windows`, the same rows at each window of frames the
/// network reads: over a whole drive, perspective bends a near point's track far more than the
/// median track's), and,
/// for a network that reads `neighbourhoods`, the first of each group of equal rows only; every
/// row where fewer than [`MIN_POINTS`] rows are distinct.
pub fn screen(points: &PointSet, neighbourhoods: bool, windows: &[PointSet]) -> Screened {
    let distinct = if neighbourhoods {
        distinct_rows(points)
    } else {
        (0..points.len()).collect()
    };
    let mut far = far_rows(points, &distinct);
    let erratic = if windows.iter().all(|w| w.len() == points.len()) {
        erratic_in_windows(windows)
    } else {
        Vec::new()
    };
    for &i in &erratic {
        if let Err(at) = far.binary_search(&i) {
            far.insert(at, i);
        }
    }
    // Fewer distinct rows than a set needs (every row alike): read as sent, as before.
    if (far.is_empty() && distinct.len() == points.len()) || distinct.len() < MIN_POINTS {
        return Screened {
            read: None,
            far,
            erratic,
        };
    }
    let read = distinct
        .into_iter()
        .filter(|i| far.binary_search(i).is_err())
        .collect();
    Screened {
        read: Some(read),
        far,
        erratic,
    }
}

/// The rows 0..n that are not among `far` (ascending), ascending.
pub fn not_far(n: usize, far: &[usize]) -> Vec<usize> {
    (0..n).filter(|i| far.binary_search(i).is_err()).collect()
}

/// How many distinct rows `points` holds, counted up to `limit` (the rows are read in order
/// until `limit` distinct ones are found: O(n · limit) at worst, and O(limit²) where the first
/// rows differ).
pub fn distinct_up_to(points: &PointSet, limit: usize) -> usize {
    let mut seen: Vec<&[f64]> = Vec::with_capacity(limit);
    for i in 0..points.len() {
        if seen.len() >= limit {
            break;
        }
        let row = points.row(i);
        if !seen.contains(&row) {
            seen.push(row);
        }
    }
    seen.len()
}

/// The first row of each group of equal rows of `points`, ascending.
pub fn distinct_rows(points: &PointSet) -> Vec<usize> {
    let n = points.len();
    let cmp = |a: &usize, b: &usize| -> Ordering {
        points
            .row(*a)
            .iter()
            .zip(points.row(*b))
            .map(|(x, y)| x.total_cmp(y))
            .find(|o| o.is_ne())
            .unwrap_or(Ordering::Equal)
            .then(a.cmp(b))
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_unstable_by(cmp);
    let mut keep: Vec<usize> = Vec::with_capacity(n);
    for (pos, &i) in order.iter().enumerate() {
        // Sorted by value then index: the first of a run of equal rows is its lowest index.
        let same = pos > 0 && points.row(order[pos - 1]) == points.row(i);
        if !same {
            keep.push(i);
        }
    }
    keep.sort_unstable();
    keep
}

/// The rows among `among` (ascending) that lie far from the others. Rows are taken in order of
/// their distance to the coordinate-wise median (which a few far rows cannot move); among the
/// outermost [`MAX_FAR_SHARE`] of them, the first that lies farther than [`FAR_SPREADS`] RMS
/// spreads from the centroid of all the rows nearer than it is far, and so is every row beyond
/// it. (Each row tested against the nearer ones alone: a cluster of far rows, such as several
/// lost points at one place, does not hide itself by inflating the spread.) Ascending.
pub fn far_rows(points: &PointSet, among: &[usize]) -> Vec<usize> {
    let d = points.dim();
    let m = among.len();
    let most = (MAX_FAR_SHARE * m as f64).floor() as usize;
    if most == 0 {
        return Vec::new();
    }
    let median: Vec<f64> = (0..d)
        .map(|c| {
            let mut v: Vec<f64> = among.iter().map(|&i| points.row(i)[c]).collect();
            let mid = (m - 1) / 2;
            *v.select_nth_unstable_by(mid, f64::total_cmp).1
        })
        .collect();
    // Each row of `among` centred on the median, once: row p of `centred` is among[p].
    let centred: Vec<f64> = among
        .iter()
        .flat_map(|&i| points.row(i).iter().zip(&median).map(|(x, o)| x - o))
        .collect();
    let row = |p: usize| &centred[p * d..(p + 1) * d];
    let norm2 = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
    let mut order: Vec<(f64, usize)> = (0..m).map(|p| (norm2(row(p)), p)).collect();
    order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    // Sums over the rows nearer than the one tested (centred on the median).
    let (mut sum, mut sum_sq) = (vec![0.0; d], 0.0);
    let add = |v: &[f64], sum: &mut [f64], sum_sq: &mut f64| {
        for (s, x) in sum.iter_mut().zip(v) {
            *s += x;
        }
        *sum_sq += norm2(v);
    };
    for &(_, p) in &order[..m - most] {
        add(row(p), &mut sum, &mut sum_sq);
    }
    for j in m - most..m {
        let v = row(order[j].1);
        let nearer = j as f64;
        let c: Vec<f64> = sum.iter().map(|s| s / nearer).collect();
        let spread2 = (sum_sq / nearer - norm2(&c)).max(0.0);
        let gap2: f64 = v.iter().zip(&c).map(|(x, c)| (x - c).powi(2)).sum();
        let apart = || {
            let nearest2 = order[..j]
                .iter()
                .map(|&(_, q)| {
                    v.iter()
                        .zip(row(q))
                        .map(|(x, y)| (x - y).powi(2))
                        .sum::<f64>()
                })
                .fold(f64::INFINITY, f64::min);
            nearest2 > FAR_GAP * FAR_GAP * spread2
        };
        if spread2 > 0.0 && gap2 > FAR_SPREADS * FAR_SPREADS * spread2 && apart() {
            let mut far: Vec<usize> = order[j..].iter().map(|&(_, p)| among[p]).collect();
            far.sort_unstable();
            return far;
        }
        add(v, &mut sum, &mut sum_sq);
    }
    Vec::new()
}

/// A track whose RMS acceleration is above this many times the median track's is erratic
/// (when it also accelerates faster than tracks move, [`ERRATIC_SPEEDS`]).
pub const ERRATIC_ACCELERATIONS: f64 = 8.0;
/// An erratic track's RMS acceleration per frame is also above this many times the typical
/// track's speed per frame: real motion is smooth at video rates, its acceleration well below
/// its speed, while a wandering track turns within a frame.
pub const ERRATIC_SPEEDS: f64 = 2.0;
/// An erratic track's RMS acceleration is also above this share of its own mean speed: a
/// random walk's is about 1.6 times it (steps of σ per axis: acceleration 2σ RMS, speed 1.25σ
/// on average) and a jump's more, while a smooth track accelerates far less than it moves, the
/// fast tracks of points near a moving camera too (a third of their speed where perspective
/// bends them most).
pub const ERRATIC_OWN_SPEED: f64 = 0.7;

/// The tracks of `points` (trajectories of at least 3 frames) that move erratically, ascending:
/// a tracker that lost its feature and wanders. A track's acceleration at frame t is its second
/// difference x(t+1) − 2 x(t) + x(t−1) less the median of all tracks' at t (a camera's shake
/// moves every track alike), and its velocity x(t+1) − x(t) less the median track's. A track is
/// erratic when the RMS of its acceleration (pixels per frame², over the frames) exceeds
/// [`ERRATIC_ACCELERATIONS`] times the median track's, [`ERRATIC_SPEEDS`] times the typical
/// speed (the median over tracks of each one's mean speed) and [`ERRATIC_OWN_SPEED`] times its
/// own mean speed: a moving object's tracks accelerate more than the background's, but far less
/// than they move. At most [`MAX_FAR_SHARE`] of the
/// tracks, those farthest above their highest bar first; none in other kinds or where the median track does not
/// accelerate at all (noise-free input, where any motion would count as erratic).
pub fn erratic_tracks(points: &PointSet) -> Vec<usize> {
    erratic_in_windows(std::slice::from_ref(points))
}

/// [`erratic_tracks`] over several windows of frames of the same tracks: a track is erratic
/// where it is in some window; where more than [`MAX_FAR_SHARE`] are, those farthest above their
/// highest bar (in any window) are kept. Ascending.
pub fn erratic_in_windows(windows: &[PointSet]) -> Vec<usize> {
    let Some(n) = windows.first().map(PointSet::len) else {
        return Vec::new();
    };
    let most = (MAX_FAR_SHARE * n as f64).floor() as usize;
    let mut above = vec![0.0f64; n];
    for window in windows {
        for (i, ratio) in erratic_ratios(window) {
            above[i] = above[i].max(ratio);
        }
    }
    let mut erratic: Vec<usize> = (0..n).filter(|&i| above[i] > 1.0).collect();
    erratic.sort_unstable_by(|&a, &b| above[b].total_cmp(&above[a]).then(a.cmp(&b)));
    erratic.truncate(most);
    erratic.sort_unstable();
    erratic
}

/// The erratic tracks of one window ([`erratic_tracks`]), each with its RMS acceleration over
/// its highest bar (above 1), in no order.
fn erratic_ratios(points: &PointSet) -> Vec<(usize, f64)> {
    let n = points.len();
    let frames = points.dim() / 2;
    let most = (MAX_FAR_SHARE * n as f64).floor() as usize;
    if points.kind() != crate::data::Kind::Trajectories || frames < 3 || most == 0 {
        return Vec::new();
    }
    // Each track's differences of order 1 (velocity) or 2 (acceleration) less the median
    // track's, frame by frame: [n, 2 (F − order)].
    let relative = |order: usize| -> (Vec<f64>, usize) {
        let width = 2 * (frames - order);
        let diff: Vec<f64> = (0..n)
            .flat_map(|i| {
                let r = points.row(i);
                (0..width).map(move |c| match order {
                    1 => r[c + 2] - r[c],
                    _ => r[c + 4] - 2.0 * r[c + 2] + r[c],
                })
            })
            .collect();
        let common: Vec<f64> = (0..width)
            .map(|c| median(&mut (0..n).map(|i| diff[i * width + c]).collect::<Vec<_>>()))
            .collect();
        let less: Vec<f64> = (0..n * width)
            .map(|j| diff[j] - common[j % width])
            .collect();
        (less, width)
    };
    let (acceleration, width) = relative(2);
    let rms: Vec<f64> = acceleration
        .chunks_exact(width)
        .map(|a| (a.iter().map(|v| v * v).sum::<f64>() / (frames - 2) as f64).sqrt())
        .collect();
    let (velocity, step) = relative(1);
    let speeds: Vec<f64> = velocity
        .chunks_exact(step)
        .map(|v| v.chunks_exact(2).map(|p| p[0].hypot(p[1])).sum::<f64>() / (frames - 1) as f64)
        .collect();
    let (typical, speed) = (median(&mut rms.clone()), median(&mut speeds.clone()));
    // Not above zero: nothing to judge against.
    if typical.partial_cmp(&0.0) != Some(Ordering::Greater) {
        return Vec::new();
    }
    let bar = (ERRATIC_ACCELERATIONS * typical).max(ERRATIC_SPEEDS * speed);
    (0..n)
        .map(|i| (i, rms[i] / bar.max(ERRATIC_OWN_SPEED * speeds[i])))
        .filter(|&(_, ratio)| ratio > 1.0)
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::data::Kind;

    /// 60 tracks over 5 frames: three motions (constant velocity, steady acceleration, a slow
    /// turn) shaken alike by a camera, with 0.1 px of seeded noise; then `wanderers` random
    /// walks stepping about 5 px a frame.
    pub(crate) fn tracks(wanderers: usize) -> PointSet {
        let shake = [0.0, 1.5, -2.0, 0.7, 0.0];
        let mut state = 7u64;
        let mut noise = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) as f64 / (1u64 << 31) as f64 - 0.5) * 0.2
        };
        let mut rows: Vec<f64> = Vec::new();
        for i in 0..60 {
            let (x0, y0) = (10.0 * (i % 10) as f64, 12.0 * (i / 10) as f64);
            for (t, jolt) in shake.iter().enumerate() {
                let tf = t as f64;
                let (x, y) = match i % 3 {
                    0 => (x0 + 3.0 * tf, y0 + tf),
                    1 => (x0 - 2.0 * tf - 0.5 * tf * tf, y0 + 0.3 * tf * tf),
                    _ => {
                        let a = 0.02 * tf;
                        (x0 * a.cos() - y0 * a.sin(), x0 * a.sin() + y0 * a.cos())
                    }
                };
                rows.extend([x + jolt + noise(), y - jolt + noise()]);
            }
        }
        for w in 0..wanderers {
            let (mut x, mut y) = (50.0 + w as f64, 30.0);
            for t in 0..5 {
                rows.extend([x, y]);
                let turn = (w * 5 + t) as f64;
                x += 5.0 * turn.cos();
                y += 5.0 * (1.7 * turn).sin();
            }
        }
        PointSet::from_flat(Kind::Trajectories, 10, rows).unwrap()
    }

    #[test]
    fn wandering_tracks_are_erratic_and_smooth_ones_are_not() {
        assert_eq!(erratic_tracks(&tracks(0)), Vec::<usize>::new());
        assert_eq!(erratic_tracks(&tracks(2)), vec![60, 61]);
        // At most 5 % of the tracks: of 10 wanderers among 70 tracks, 3.
        assert_eq!(erratic_tracks(&tracks(10)).len(), 3);
        // They are not read, and are named apart from the far rows.
        let with = tracks(2);
        let screened = screen(&with, true, std::slice::from_ref(&with));
        assert_eq!(screened.erratic, vec![60, 61]);
        assert_eq!(screened.far, vec![60, 61]);
        assert!(!screened.read.unwrap().contains(&60));
    }

    #[test]
    fn a_track_erratic_in_any_window_read_is_erratic() {
        // The first window: 60 smooth tracks and two more that follow tracks 0 and 1 a few
        // pixels off; the second: the same 60, and the two wander.
        let smooth = tracks(0);
        let mut values = smooth.values().to_vec();
        for i in [0, 1] {
            values.extend(smooth.row(i).iter().map(|v| v + 3.0));
        }
        let first = PointSet::from_flat(Kind::Trajectories, 10, values).unwrap();
        let second = tracks(2);
        assert!(erratic_tracks(&first).is_empty());
        assert_eq!(
            erratic_in_windows(&[first.clone(), second.clone()]),
            vec![60, 61]
        );
        assert_eq!(erratic_in_windows(&[second, first]), vec![60, 61]);
    }

    /// A drive's view over 5 frames: 80 background tracks flowing out at 1 to 9 px a frame
    /// with 0.05 px a frame² of acceleration, then `near` tracks of points near the camera
    /// moving `speed` px a frame and accelerating `accel` px a frame², smoothly.
    fn drive(near: usize, speed: f64, accel: f64) -> PointSet {
        let rows: Vec<f64> = (0..80 + near)
            .flat_map(|i| {
                let (v, a) = match i >= 80 {
                    true => (speed, accel),
                    false => (1.0 + (i % 9) as f64, 0.05 * ((i % 3) as f64 - 1.0)),
                };
                let (x0, y0) = (7.0 * (i % 11) as f64, 5.0 * (i / 11) as f64);
                (0..5).flat_map(move |t| {
                    let t = t as f64;
                    [x0 + v * t + 0.5 * a * t * t, y0 + 0.3 * v * t]
                })
            })
            .collect();
        PointSet::from_flat(Kind::Trajectories, 10, rows).unwrap()
    }

    #[test]
    fn smooth_tracks_that_accelerate_more_than_most_are_not_erratic() {
        // 8 near points accelerating 20 times as much as the background (1 px a frame²) while
        // moving 12 px a frame: smooth motion, far below its speed.
        assert!(erratic_tracks(&drive(8, 12.0, 1.0)).is_empty());
    }

    #[test]
    fn fast_smooth_tracks_near_a_moving_camera_are_not_erratic() {
        // 6 near points moving 80 px a frame and accelerating 25 px a frame²: ten times the
        // typical speed, but a third of their own (perspective bending a near point's track as
        // the camera drives past).
        assert!(erratic_tracks(&drive(6, 80.0, 25.0)).is_empty());
    }

    #[test]
    fn only_tracks_of_three_frames_or_more_can_be_erratic() {
        // Two frames: no acceleration to measure.
        let short = PointSet::from_flat(
            Kind::Trajectories,
            4,
            (0..40).map(|v| f64::from(v * v % 17)).collect(),
        )
        .unwrap();
        assert!(erratic_tracks(&short).is_empty());
        // Points and correspondences are never tracks.
        let curve = set(&circle());
        assert!(erratic_tracks(&curve).is_empty());
        // Noise-free tracks at constant velocity: the median track does not accelerate, and
        // nothing is judged against it.
        let still = PointSet::from_flat(
            Kind::Trajectories,
            6,
            (0..40)
                .flat_map(|i| (0..3).flat_map(move |t| [f64::from(i + t), f64::from(2 * i)]))
                .collect(),
        )
        .unwrap();
        assert!(erratic_tracks(&still).is_empty());
    }

    /// [`screen`] for a network that reads neighbourhoods.
    fn screen_n(points: &PointSet) -> Screened {
        screen(points, true, std::slice::from_ref(points))
    }

    fn set(rows: &[[f64; 2]]) -> PointSet {
        PointSet::from_flat(Kind::Points2d, 2, rows.concat()).unwrap()
    }

    /// 200 points on a circle of radius 2 around (1, -1).
    fn circle() -> Vec<[f64; 2]> {
        (0..200)
            .map(|i| {
                let t = i as f64 * std::f64::consts::TAU / 200.0;
                [1.0 + 2.0 * t.cos(), -1.0 + 2.0 * t.sin()]
            })
            .collect()
    }

    #[test]
    fn a_set_without_repeats_or_far_rows_is_read_whole() {
        assert_eq!(
            screen_n(&set(&circle())),
            Screened {
                read: None,
                far: Vec::new(),
                erratic: Vec::new()
            }
        );
    }

    #[test]
    fn each_distinct_row_is_read_once_at_its_first_place() {
        let mut rows = circle();
        rows.extend(circle());
        rows.insert(3, rows[7]);
        let screened = screen_n(&set(&rows));
        let read = screened.read.unwrap();
        assert_eq!(read, (0..201).filter(|&i| i != 8).collect::<Vec<_>>());
        // Row 3 is the first of the two copies of circle()[7], now also at row 8.
        assert!(screened.far.is_empty());
        assert_eq!(
            distinct_rows(&set(&[[2.0, 1.0], [0.0, 1.0], [2.0, 1.0], [0.0, 1.0]])),
            [0, 1]
        );
    }

    #[test]
    fn repeats_are_read_by_a_network_that_reads_each_row_alone() {
        let mut rows = circle();
        rows.extend(circle());
        rows.push([1e6, 1e6]);
        let points = set(&rows);
        let screened = screen(&points, false, std::slice::from_ref(&points));
        assert_eq!(screened.far, [400]);
        assert_eq!(screened.read.unwrap(), (0..400).collect::<Vec<_>>());
    }

    #[test]
    fn a_set_of_one_row_repeated_is_read_as_sent() {
        let screened = screen_n(&set(&[[1.0, 2.0]; 9]));
        assert_eq!((screened.read, screened.far.len()), (None, 0));
        let two = screen_n(&set(&[[1.0, 2.0], [1.0, 2.0], [3.0, 2.0]]));
        assert_eq!(two.read, Some(vec![0, 2]));
    }

    #[test]
    fn far_rows_are_set_apart_and_nothing_else() {
        let mut rows = circle();
        rows.push([21.0, 19.0]); // 20 · √2 ≈ 28 from the centre: 14 spreads of the circle
        rows.push([1e6, -1e6]);
        let screened = screen_n(&set(&rows));
        assert_eq!(screened.far, [200, 201]);
        assert_eq!(screened.read.unwrap(), (0..200).collect::<Vec<_>>());
        // A sparse line of 50 rows 2 apart running 50 spreads out beside a dense unit circle
        // of 950: its outer rows pass the spread test, but each runs on from the nearer ones.
        let mut line: Vec<[f64; 2]> = (0..950)
            .map(|i| {
                let t = i as f64 * std::f64::consts::TAU / 950.0;
                [t.cos(), t.sin()]
            })
            .collect();
        line.extend((0..50).map(|i| [-49.0 + 2.0 * i as f64, 0.5]));
        assert!(screen_n(&set(&line)).far.is_empty());
        // 8 spreads away is not far.
        let mut near = circle();
        near.push([
            1.0 + 16.0 * 2f64.sqrt() / 2.0,
            -1.0 + 16.0 * 2f64.sqrt() / 2.0,
        ]);
        assert!(screen_n(&set(&near)).far.is_empty());
    }

    #[test]
    fn at_most_a_twentieth_of_the_rows_is_far() {
        // 10 lost points at one place beside 200 (a twentieth of 210): all set apart, the
        // cluster does not hide itself.
        let mut rows = circle();
        rows.extend((0..10).map(|i| [1e6 + i as f64, 0.0]));
        let far = far_rows(&set(&rows), &(0..210).collect::<Vec<_>>());
        assert_eq!(far, (200..210).collect::<Vec<_>>());
        // 30 of them are part of the data: never more than a twentieth goes.
        let mut more = circle();
        more.extend((0..30).map(|i| [1e6 + i as f64, 0.0]));
        let far = far_rows(&set(&more), &(0..230).collect::<Vec<_>>());
        assert!(far.len() <= 11, "{}", far.len());
        // Too few rows to set any apart, and degenerate sets, give none and no NaN.
        assert!(far_rows(&set(&[[0.0, 0.0], [1e9, 1e9]]), &[0, 1]).is_empty());
        let same = vec![[3.0, 3.0]; 40];
        assert!(far_rows(&set(&same), &(0..40).collect::<Vec<_>>()).is_empty());
    }
}
