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
    /// The rows set apart as far from the rest, ascending.
    pub far: Vec<usize>,
}

/// `points` `[n, d]` -> the rows to read: less the far ones ([`far_rows`]), and, for a network
/// that reads `neighbourhoods`, the first of each group of equal rows only; every row where
/// fewer than [`MIN_POINTS`] rows are distinct.
pub fn screen(points: &PointSet, neighbourhoods: bool) -> Screened {
    let distinct = if neighbourhoods {
        distinct_rows(points)
    } else {
        (0..points.len()).collect()
    };
    let far = far_rows(points, &distinct);
    // Fewer distinct rows than a set needs (every row alike): read as sent, as before.
    if (far.is_empty() && distinct.len() == points.len()) || distinct.len() < MIN_POINTS {
        return Screened { read: None, far };
    }
    let read = distinct
        .into_iter()
        .filter(|i| far.binary_search(i).is_err())
        .collect();
    Screened {
        read: Some(read),
        far,
    }
}

/// The rows 0..n that are not among `far` (ascending), ascending.
pub fn not_far(n: usize, far: &[usize]) -> Vec<usize> {
    (0..n).filter(|i| far.binary_search(i).is_err()).collect()
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::Kind;

    /// [`screen`] for a network that reads neighbourhoods.
    fn screen_n(points: &PointSet) -> Screened {
        screen(points, true)
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
                far: Vec::new()
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
        let screened = screen(&set(&rows), false);
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
