//! `robustness`: the robustness grid ([`crate::train::robustness`]) run for one model, a line on
//! standard error per finished cell, and the report written as `robustness.md` and
//! `robustness.json` with the command that made it.

use std::fmt;
use std::path::{Path, PathBuf};

use super::CliError;
use super::provenance::command_line;
use crate::train::robustness::{self, CellResult, GridSettings, Report};

/// What [`run`] wrote.
#[derive(Debug, Clone)]
pub struct Written {
    pub report: Report,
    pub out: PathBuf,
}

impl fmt::Display for Written {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "wrote {} and robustness.json ({} cells, {:.0} s)",
            self.out.join("robustness.md").display(),
            self.report.cells.len(),
            self.report.seconds
        )
    }
}

/// The line a finished cell prints: its size, its known-K mean and median error and its
/// chosen-K mean error and share of K right, and its time.
pub fn cell_line(c: &CellResult) -> String {
    format!(
        "{:<16} {:>4} samples  known K {:>6.2} / {:>6.2} %  chosen K {:>6.2} % ({:>5.1} % K right)  {:>5.0} s",
        c.name,
        c.samples,
        100.0 * c.known.mean_error,
        100.0 * c.known.median_error,
        100.0 * c.chosen.mean_error,
        100.0 * c.chosen.k_correct,
        c.seconds
    )
}

/// Runs the grid for the model in `model` (real-data cells scored by the fold models of `folds`
/// when given) and writes the report to `out`.
pub fn run(
    model: &Path,
    folds: Option<&Path>,
    settings: &GridSettings,
    out: &Path,
) -> Result<Written, CliError> {
    let mut on_cell = |c: &CellResult| eprintln!("{}", cell_line(c));
    let mut report = robustness::run(model, folds, settings, &mut on_cell)?;
    report.command = command_line();
    robustness::write(&report, out).map_err(|source| CliError::WriteReport {
        dir: out.to_path_buf(),
        source,
    })?;
    Ok(Written {
        report,
        out: out.to_path_buf(),
    })
}
