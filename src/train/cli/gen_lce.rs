//! `gen-lce`: synthetic LCE samples ([`crate::data::synthetic`]) written as dataset JSON files,
//! one per sample, named as the generator names them. Errors name the `gen-lce` flag at fault.

use std::fmt;
use std::path::{Path, PathBuf};

use super::CliError;
use crate::data::synthetic::{LceSpec, parse_range};

/// `--points-per-shape`: `N`, or `MIN-MAX` (the count of each structure drawn in that range).
pub fn points_per_shape(text: &str) -> Result<(usize, Option<usize>), CliError> {
    parse_range::<usize>(text).map_err(|e| CliError::FlagValue {
        flag: "--points-per-shape",
        value: text.to_string(),
        reason: e.to_string(),
    })
}

/// `--arc`: the span of partial arcs in degrees, `MIN-MAX` or one value; `None`: whole shapes.
pub fn arc(text: Option<&str>) -> Result<Option<[f64; 2]>, CliError> {
    let Some(text) = text else { return Ok(None) };
    let (lo, hi) = parse_range::<f64>(text).map_err(|e| CliError::FlagValue {
        flag: "--arc",
        value: text.to_string(),
        reason: e.to_string(),
    })?;
    Ok(Some([lo, hi.unwrap_or(lo)]))
}

/// What [`write`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    pub count: usize,
    pub variant: &'static str,
    pub out: PathBuf,
}

impl fmt::Display for Written {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "wrote {} {} samples to {}",
            self.count,
            self.variant,
            self.out.display()
        )
    }
}

/// Checks `spec` (naming the flag at fault) and writes its samples to `<out>/<name>.json`,
/// creating `out`.
pub fn write(spec: &LceSpec, out: &Path) -> Result<Written, CliError> {
    spec.config.validate().map_err(|e| CliError::FlagValue {
        flag: e.flag(),
        value: e.value,
        reason: e.reason,
    })?;
    if spec.validate().is_err() {
        return Err(CliError::FlagValue {
            flag: "--count",
            value: spec.count.to_string(),
            reason: format!("count must be 1 to {}", LceSpec::MAX_COUNT),
        });
    }
    std::fs::create_dir_all(out).map_err(|source| CliError::Create {
        path: out.to_path_buf(),
        source,
    })?;
    for file in spec.files() {
        let path = out.join(format!("{}.json", file.name));
        let text = serde_json::to_string(&file)?;
        std::fs::write(&path, text).map_err(|source| CliError::Write { path, source })?;
    }
    Ok(Written {
        count: spec.count,
        variant: spec.variant.tag(),
        out: out.to_path_buf(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::load_sequences;
    use crate::data::synthetic::{LceConfig, LceVariant};
    use crate::registry::tests::scratch;

    #[test]
    fn flags_parse_and_errors_name_them() {
        assert_eq!(points_per_shape("50").unwrap(), (50, None));
        assert_eq!(points_per_shape("20-300").unwrap(), (20, Some(300)));
        let e = points_per_shape("x").unwrap_err().to_string();
        assert!(e.starts_with("--points-per-shape x: "), "{e}");
        assert_eq!(arc(None).unwrap(), None);
        assert_eq!(arc(Some("90")).unwrap(), Some([90.0, 90.0]));
        assert_eq!(arc(Some("90-360")).unwrap(), Some([90.0, 360.0]));
        assert!(
            arc(Some("a-b"))
                .unwrap_err()
                .to_string()
                .starts_with("--arc a-b: ")
        );
    }

    #[test]
    fn writes_what_the_spec_generates() {
        let tmp = scratch("gen-lce");
        let spec = LceSpec {
            variant: LceVariant::Unmixed,
            count: 3,
            seed: 2,
            config: LceConfig::default(),
        };
        let out = tmp.path().join("lce");
        let written = write(&spec, &out).unwrap();
        assert_eq!(
            written.to_string(),
            format!("wrote 3 unmixed samples to {}", out.display())
        );
        let loaded = load_sequences(&out, None).unwrap();
        let made = spec.sequences().unwrap();
        assert_eq!(loaded.len(), 3);
        for (a, b) in loaded.iter().zip(&made) {
            assert_eq!(
                (&a.name, &a.labels, a.points.len()),
                (&b.name, &b.labels, b.points.len())
            );
        }
        let bad = LceSpec {
            count: 0,
            ..spec.clone()
        };
        let e = write(&bad, &out).unwrap_err().to_string();
        assert_eq!(
            e,
            format!("--count 0: count must be 1 to {}", LceSpec::MAX_COUNT)
        );
        let bad = LceSpec {
            config: LceConfig {
                noise: -1.0,
                ..spec.config
            },
            ..spec
        };
        assert!(
            write(&bad, &out)
                .unwrap_err()
                .to_string()
                .starts_with("--noise -1: ")
        );
    }
}
