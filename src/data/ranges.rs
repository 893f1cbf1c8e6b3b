//! The settings of the motion and two-view generators are inclusive ranges `[min, max]` a sample
//! draws from, written `A-B` (or `A` for `[A, A]`) on the command line and in specs. This module
//! holds their checks and the error that names the flag (or spec key) at fault.

/// A generator setting that cannot be drawn from: the flag that sets it, its value and why.
/// Its spec key (`motion:frames=...`, `twoview:homography,groups=...`) is the flag without the
/// dashes ([`Self::key`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RangeError {
    /// A value outside what the generator accepts.
    #[error("{flag} {value}: {reason}")]
    OutOfRange {
        flag: &'static str,
        value: String,
        reason: String,
    },
    /// A range whose smallest value exceeds its largest.
    #[error("{flag} {value}: the smallest value ({min}) exceeds the largest ({max})")]
    Inverted {
        flag: &'static str,
        value: String,
        min: String,
        max: String,
    },
}

impl RangeError {
    /// The command-line flag of the setting (`--frames`).
    pub fn flag(&self) -> &'static str {
        match self {
            Self::OutOfRange { flag, .. } | Self::Inverted { flag, .. } => flag,
        }
    }

    /// Its key in a spec (`frames`).
    pub fn key(&self) -> &'static str {
        &self.flag()[2..]
    }

    /// The message naming the spec key instead of the flag (`frames=1: ...`).
    pub fn for_spec(&self) -> String {
        let text = self.to_string();
        format!("{}={}", self.key(), &text[self.flag().len() + 1..])
    }
}

/// `A` for a range of one value, else `A-B`.
pub(super) fn range_text<T: PartialEq + std::fmt::Display>([lo, hi]: [T; 2]) -> String {
    if lo == hi {
        lo.to_string()
    } else {
        format!("{lo}-{hi}")
    }
}

/// Checks that `[lo, hi]` is ordered and inside `[min, max]` (an open upper end when
/// `open_max`).
pub(super) fn check_range<T: PartialOrd + Copy + std::fmt::Display>(
    flag: &'static str,
    range: [T; 2],
    allowed: (T, T, bool),
    what: &str,
) -> Result<(), RangeError> {
    let (min, max, open_max) = allowed;
    let inside = |v: T| v >= min && if open_max { v < max } else { v <= max };
    if !(inside(range[0]) && inside(range[1])) {
        let close = if open_max { ")" } else { "]" };
        return Err(RangeError::OutOfRange {
            flag,
            value: range_text(range),
            reason: format!("{what} must lie in [{min}, {max}{close}"),
        });
    }
    if range[0] > range[1] {
        return Err(RangeError::Inverted {
            flag,
            value: range_text(range),
            min: range[0].to_string(),
            max: range[1].to_string(),
        });
    }
    Ok(())
}
