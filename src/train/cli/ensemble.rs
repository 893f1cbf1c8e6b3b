//! `ensemble`: trained models of one architecture combined into one model directory whose fits
//! cluster all their embeddings side by side ([`crate::registry::write_ensemble`]); `sparse`: a
//! model given a second network for the sets sparser than its training sets
//! ([`crate::registry::write_sparse`]).

use std::fmt;
use std::path::{Path, PathBuf};

use super::CliError;
use crate::registry::{write_ensemble, write_sparse};

/// What [`run`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Written {
    pub out: PathBuf,
    pub networks: usize,
}

impl fmt::Display for Written {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "wrote {} ({} networks)",
            self.out.display(),
            self.networks
        )
    }
}

/// The ensemble's name: `name`, else the name of the output directory.
pub fn ensemble_name(out: &Path, name: Option<&str>) -> Result<String, CliError> {
    match name {
        Some(n) => Ok(n.to_string()),
        None => out
            .file_name()
            .and_then(|n| n.to_str())
            .map(str::to_string)
            .ok_or(CliError::NoEnsembleName),
    }
}

/// Combines the models in `models` (the first one's card is the ensemble's) into `out`.
pub fn run(models: &[PathBuf], out: &Path, name: Option<&str>) -> Result<Written, CliError> {
    let name = ensemble_name(out, name)?;
    let card = write_ensemble(models, out, &name)?;
    Ok(Written {
        out: out.to_path_buf(),
        networks: card.members.len() + 1,
    })
}

/// Writes to `out` the model in `model` with the network in `network` for the sets whose
/// spacing exceeds `above` × its training spacing.
pub fn run_sparse(
    model: &Path,
    network: &Path,
    above: f64,
    out: &Path,
) -> Result<Written, CliError> {
    let card = write_sparse(model, network, above, out)?;
    Ok(Written {
        out: out.to_path_buf(),
        networks: card.weight_files().count(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registry::tests::{scratch, two_saved_models};

    #[test]
    fn names_default_to_the_directory() {
        assert_eq!(
            ensemble_name(Path::new("models/pair"), None).unwrap(),
            "pair"
        );
        assert_eq!(
            ensemble_name(Path::new("x"), Some("given")).unwrap(),
            "given"
        );
        assert!(matches!(
            ensemble_name(Path::new("/"), None),
            Err(CliError::NoEnsembleName)
        ));
        let tmp = scratch("cli-ensemble");
        let (_, _, dirs) = two_saved_models(&tmp);
        let out = tmp.path().join("pair");
        let written = run(&dirs, &out, None).unwrap();
        assert_eq!(
            written.to_string(),
            format!("wrote {} (2 networks)", out.display())
        );
        assert_eq!(crate::registry::ModelCard::read(&out).unwrap().name, "pair");
    }
}
