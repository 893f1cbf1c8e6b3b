//! Which frames of each track were seen: the `visible` mask a trajectory request may carry.
//!
//! Trackers lose features and find new ones, so real tracks start and end at different frames.
//! A request sends every track over all F frames (any finite numbers where a track was not
//! seen) and an N × F mask of 0 and 1. The fit runs on the tracks seen in every frame
//! ([`Visibility::complete`]); each other track seen in at least [`MIN_SEEN_FRAMES`] frames then
//! goes to the motion whose subspace explains its seen frames best, or where the network does
//! better, to the motion it places it with ([`crate::pipeline::fit_seen`]); a track seen in
//! fewer frames is labelled −1.

use super::points::{InputError, PointSet};

/// The fewest frames a partly seen track needs to be placed: 6 coordinates, more than the
/// largest subspace rank (4) fits exactly.
pub const MIN_SEEN_FRAMES: usize = 3;

/// A validated N × F mask: `seen[i][f]` whether track i was seen in frame f.
#[derive(Debug, Clone, PartialEq)]
pub struct Visibility {
    seen: Vec<Vec<bool>>,
}

impl Visibility {
    /// `rows`: one row per track of `frames` flags, each 0 or 1, for `tracks` tracks. At least
    /// 2 tracks must be seen in every frame (what a fit needs).
    pub fn new(rows: &[Vec<bool>], tracks: usize, frames: usize) -> Result<Self, InputError> {
        if rows.len() != tracks {
            return Err(InputError::VisibleRows {
                rows: rows.len(),
                tracks,
            });
        }
        let mut seen = Vec::with_capacity(tracks);
        for (row, flags) in rows.iter().enumerate() {
            if flags.len() != frames {
                return Err(InputError::VisibleWidth {
                    row,
                    found: flags.len(),
                    frames,
                });
            }
            seen.push(flags.clone());
        }
        let visibility = Self { seen };
        let complete = visibility.complete().len();
        if complete < super::MIN_POINTS {
            return Err(InputError::TooFewSeenThroughout { complete });
        }
        Ok(visibility)
    }

    /// The tracks seen in every frame, ascending.
    pub fn complete(&self) -> Vec<usize> {
        (0..self.seen.len())
            .filter(|&i| self.throughout(i))
            .collect()
    }

    /// Whether track `i` was seen in every frame.
    pub fn throughout(&self, i: usize) -> bool {
        self.seen[i].iter().all(|&s| s)
    }

    /// Whether every track was seen in every frame.
    pub fn is_complete(&self) -> bool {
        (0..self.seen.len()).all(|i| self.throughout(i))
    }

    /// The frames track `i` was seen in.
    pub fn seen(&self, i: usize) -> &[bool] {
        &self.seen[i]
    }

    /// `points` (trajectories of this mask's tracks and frames) with each unseen position of a
    /// track replaced by its position in the nearest seen frame (the earlier on a tie), for
    /// drawing: a track then rests where it was last (or first) seen. A track seen in no frame
    /// keeps its values.
    pub fn held(&self, points: &PointSet) -> PointSet {
        let mut values = points.values().to_vec();
        let dim = points.dim();
        for (i, seen) in self.seen.iter().enumerate() {
            let frames = seen.len();
            // The nearest seen frame on each side of every frame, two passes.
            let mut left = vec![None; frames];
            let mut last = None;
            for f in 0..frames {
                if seen[f] {
                    last = Some(f);
                }
                left[f] = last;
            }
            let mut next = None;
            for f in (0..frames).rev() {
                if seen[f] {
                    next = Some(f);
                }
                let source = match (left[f], next) {
                    (Some(l), Some(r)) => {
                        if f - l <= r - f {
                            l
                        } else {
                            r
                        }
                    }
                    (Some(l), None) => l,
                    (None, Some(r)) => r,
                    (None, None) => f,
                };
                let row = &points.values()[i * dim..(i + 1) * dim];
                values[i * dim + 2 * f] = row[2 * source];
                values[i * dim + 2 * f + 1] = row[2 * source + 1];
            }
        }
        PointSet::from_flat(points.kind(), dim, values).unwrap_or_else(|_| points.clone())
    }

    /// Frames in the mask.
    pub fn frames(&self) -> usize {
        self.seen.first().map_or(0, Vec::len)
    }

    /// Tracks in the mask.
    pub fn len(&self) -> usize {
        self.seen.len()
    }

    pub fn is_empty(&self) -> bool {
        self.seen.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 0/1 rows as flags.
    fn flags(rows: &[Vec<u8>]) -> Vec<Vec<bool>> {
        rows.iter()
            .map(|r| r.iter().map(|&v| v == 1).collect())
            .collect()
    }

    #[test]
    fn complete_tracks_are_those_seen_in_every_frame() {
        let v = Visibility::new(
            &flags(&[vec![1, 1, 1], vec![0, 1, 1], vec![1, 1, 1], vec![1, 0, 0]]),
            4,
            3,
        )
        .unwrap();
        assert_eq!(v.complete(), vec![0, 2]);
        assert!(!v.is_complete());
        assert_eq!(v.seen(1), &[false, true, true]);
        let all = Visibility::new(&flags(&[vec![1, 1], vec![1, 1]]), 2, 2).unwrap();
        assert!(all.is_complete());
    }

    #[test]
    fn unseen_positions_are_held_at_the_nearest_seen_frame_for_drawing() {
        let points = PointSet::from_rows(
            super::super::Kind::Trajectories,
            &[
                vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
                vec![0.0, 0.0, 7.0, 8.0, 0.0, 0.0],
                vec![9.0, 9.0, 9.0, 9.0, 9.0, 9.0],
            ],
        )
        .unwrap();
        let v =
            Visibility::new(&flags(&[vec![1, 1, 1], vec![0, 1, 0], vec![1, 1, 1]]), 3, 3).unwrap();
        let held = v.held(&points);
        assert_eq!(held.row(0), points.row(0));
        assert_eq!(held.row(1), &[7.0, 8.0, 7.0, 8.0, 7.0, 8.0]);
    }

    #[test]
    fn masks_of_the_wrong_shape_are_refused_with_the_place() {
        let e =
            |rows: &[Vec<u8>], n, f| Visibility::new(&flags(rows), n, f).unwrap_err().to_string();
        assert_eq!(
            e(&[vec![1, 1]], 2, 2),
            "visible has 1 rows for 2 tracks: one row of 0/1 flags per track"
        );
        assert_eq!(
            e(&[vec![1, 1], vec![1]], 2, 2),
            "visible row 1 has 1 flags for 2 frames"
        );
        assert!(
            e(&[vec![1, 1], vec![0, 1], vec![1, 0]], 3, 2)
                .starts_with("only 1 tracks are seen in every frame")
        );
    }
}
