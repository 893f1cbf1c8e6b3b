//! `gen-motion` and `gen-twoview`: synthetic multi-body trajectories ([`crate::data::motion`])
//! and two-view correspondences ([`crate::data::twoview`]) written as dataset JSON files, one per
//! sample. Every range flag takes `A-B` or one value; errors name the flag at fault. The same
//! samples are generated in memory by the `motion:` and `twoview:` data specs.

use std::path::{Path, PathBuf};

use clap::Args;

use super::CliError;
use crate::data::SequenceFile;
use crate::data::motion::{MotionParams, MotionSpec};
use crate::data::synthetic::parse_range;
use crate::data::twoview::{TwoViewMode, TwoViewParams, TwoViewSpec};

/// The flags of `gen-motion`; unset ranges keep [`MotionParams::default`].
#[derive(Args, Debug, Clone, Default)]
pub struct GenMotionJob {
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of samples.
    #[arg(long, default_value_t = 200)]
    pub count: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Frames per clip, A-B or one value [default: 2-30].
    #[arg(long)]
    pub frames: Option<String>,
    /// Motions per sample, the static background included [default: 2-5].
    #[arg(long)]
    pub motions: Option<String>,
    /// Tracks per motion [default: 30-200].
    #[arg(long)]
    pub points: Option<String>,
    /// Track noise sigma in pixels [default: 0-1].
    #[arg(long)]
    pub noise: Option<String>,
    /// Share of all tracks that are gross outliers, in [0, 1) [default: 0].
    #[arg(long)]
    pub outliers: Option<String>,
    /// Motion per frame: 0.05 is hand-held at 30 fps, 1 driving at 10 fps [default: 0.05-1].
    #[arg(long)]
    pub motion_scale: Option<String>,
    /// Focal length in pixels [default: 300-1500].
    #[arg(long)]
    pub focal: Option<String>,
    /// Image width in pixels [default: 640-1920].
    #[arg(long)]
    pub width: Option<String>,
    /// Image height in pixels [default: 360-1080].
    #[arg(long)]
    pub height: Option<String>,
    /// Share of the tracks seen in only part of the clip (a run of 2 or more consecutive
    /// frames), written as each file's `visible` mask, in [0, 1) [default: 0].
    #[arg(long)]
    pub dropout: Option<String>,
    /// Probability that an object is flat (points on a square patch, as a checkerboard), drawn
    /// per sample, in [0, 1] [default: 0].
    #[arg(long)]
    pub planar: Option<String>,
}

/// The flags of `gen-twoview`; unset ranges keep [`TwoViewParams::new`]'s for the mode.
#[derive(Args, Debug, Clone)]
pub struct GenTwoViewJob {
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// homography (planes) or fundamental (rigid motions).
    #[arg(long, value_enum)]
    pub mode: TwoViewMode,
    /// Number of samples.
    #[arg(long, default_value_t = 200)]
    pub count: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Planes or objects per sample [default: 2-6 planes, 2-5 objects].
    #[arg(long)]
    pub groups: Option<String>,
    /// Correspondences per group [default: 30-150].
    #[arg(long)]
    pub points: Option<String>,
    /// Noise sigma in pixels [default: 0-1].
    #[arg(long)]
    pub noise: Option<String>,
    /// Share of all rows that are gross outliers, in [0, 1) [default: 0-0.5].
    #[arg(long)]
    pub outliers: Option<String>,
    /// View 1's focal length in pixels [default: 300-1500].
    #[arg(long)]
    pub focal: Option<String>,
    /// Image width in pixels [default: 400-1280].
    #[arg(long)]
    pub width: Option<String>,
    /// Image height in pixels [default: 300-960].
    #[arg(long)]
    pub height: Option<String>,
}

/// `A-B` or `A` of flag `flag` into `[A, B]`; `None` keeps `default`.
fn range<T: std::str::FromStr + Copy>(
    flag: &'static str,
    text: Option<&str>,
    default: [T; 2],
) -> Result<[T; 2], CliError>
where
    T::Err: std::fmt::Display,
{
    let Some(text) = text else {
        return Ok(default);
    };
    let (lo, hi) = parse_range::<T>(text).map_err(|e| CliError::FlagValue {
        flag,
        value: text.to_string(),
        reason: e.to_string(),
    })?;
    Ok([lo, hi.unwrap_or(lo)])
}

fn count(count: usize, max: usize) -> Result<usize, CliError> {
    if count == 0 || count > max {
        return Err(CliError::FlagValue {
            flag: "--count",
            value: count.to_string(),
            reason: format!("count must be 1 to {max}"),
        });
    }
    Ok(count)
}

impl GenMotionJob {
    /// The validated spec the flags describe.
    pub fn spec(&self) -> Result<MotionSpec, CliError> {
        let d = MotionParams::default();
        let params = MotionParams {
            frames: range("--frames", self.frames.as_deref(), d.frames)?,
            motions: range("--motions", self.motions.as_deref(), d.motions)?,
            points: range("--points", self.points.as_deref(), d.points)?,
            noise: range("--noise", self.noise.as_deref(), d.noise)?,
            outliers: range("--outliers", self.outliers.as_deref(), d.outliers)?,
            motion_scale: range(
                "--motion-scale",
                self.motion_scale.as_deref(),
                d.motion_scale,
            )?,
            focal: range("--focal", self.focal.as_deref(), d.focal)?,
            width: range("--width", self.width.as_deref(), d.width)?,
            dropout: range("--dropout", self.dropout.as_deref(), d.dropout)?,
            height: range("--height", self.height.as_deref(), d.height)?,
            planar: range("--planar", self.planar.as_deref(), d.planar)?,
        };
        params.validate()?;
        Ok(MotionSpec {
            count: count(self.count, MotionSpec::MAX_COUNT)?,
            seed: self.seed,
            params,
        })
    }

    /// Writes the samples to `<out>/<name>.json`; -> what was written.
    pub fn run(&self) -> Result<String, CliError> {
        let spec = self.spec()?;
        write(spec.files()?, &self.out)?;
        Ok(written(spec.count, "motion", &self.out, &spec))
    }
}

impl GenTwoViewJob {
    /// The validated spec the flags describe.
    pub fn spec(&self) -> Result<TwoViewSpec, CliError> {
        let d = TwoViewParams::new(self.mode);
        let params = TwoViewParams {
            mode: self.mode,
            groups: range("--groups", self.groups.as_deref(), d.groups)?,
            points: range("--points", self.points.as_deref(), d.points)?,
            noise: range("--noise", self.noise.as_deref(), d.noise)?,
            outliers: range("--outliers", self.outliers.as_deref(), d.outliers)?,
            focal: range("--focal", self.focal.as_deref(), d.focal)?,
            width: range("--width", self.width.as_deref(), d.width)?,
            height: range("--height", self.height.as_deref(), d.height)?,
        };
        params.validate()?;
        Ok(TwoViewSpec {
            count: count(self.count, TwoViewSpec::MAX_COUNT)?,
            seed: self.seed,
            params,
        })
    }

    /// Writes the samples to `<out>/<name>.json`; -> what was written.
    pub fn run(&self) -> Result<String, CliError> {
        let spec = self.spec()?;
        write(spec.files()?, &self.out)?;
        Ok(written(spec.count, "two-view", &self.out, &spec))
    }
}

/// What a generator command prints.
fn written(count: usize, what: &str, out: &Path, spec: &dyn std::fmt::Display) -> String {
    format!("wrote {count} {what} samples to {} ({spec})", out.display())
}

fn write(files: impl Iterator<Item = SequenceFile>, out: &Path) -> Result<(), CliError> {
    std::fs::create_dir_all(out).map_err(|source| CliError::Create {
        path: out.to_path_buf(),
        source,
    })?;
    for file in files {
        let path = out.join(format!("{}.json", file.name));
        let text = serde_json::to_string(&file)?;
        std::fs::write(&path, text).map_err(|source| CliError::Write { path, source })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::load_sequences;
    use crate::registry::tests::scratch;

    #[test]
    fn gen_motion_writes_what_the_spec_generates_and_names_bad_flags() {
        let tmp = scratch("gen-motion");
        let out = tmp.path().join("motion");
        let job = GenMotionJob {
            out: out.clone(),
            count: 3,
            seed: 4,
            frames: Some("5".into()),
            motions: Some("2-3".into()),
            points: Some("20-40".into()),
            ..GenMotionJob::default()
        };
        let said = job.run().unwrap();
        assert!(said.starts_with("wrote 3 motion samples to "), "{said}");
        let loaded = load_sequences(&out, None).unwrap();
        let made = job.spec().unwrap().sequences().unwrap();
        assert_eq!(loaded.len(), 3);
        for (a, b) in loaded.iter().zip(&made) {
            assert_eq!((&a.name, &a.labels), (&b.name, &b.labels));
            assert_eq!(a.points.dim(), 10);
        }
        for (job, flag) in [
            (
                GenMotionJob {
                    frames: Some("1".into()),
                    ..job.clone()
                },
                "--frames",
            ),
            (
                GenMotionJob {
                    noise: Some("-1".into()),
                    ..job.clone()
                },
                "--noise",
            ),
            (
                GenMotionJob {
                    outliers: Some("1".into()),
                    ..job.clone()
                },
                "--outliers",
            ),
            (
                GenMotionJob {
                    points: Some("x".into()),
                    ..job.clone()
                },
                "--points",
            ),
            (
                GenMotionJob {
                    count: 0,
                    ..job.clone()
                },
                "--count",
            ),
        ] {
            let e = job.run().unwrap_err().to_string();
            assert!(e.contains(flag), "{flag}: {e}");
        }
    }

    #[test]
    fn gen_twoview_writes_its_mode_and_names_bad_flags() {
        let tmp = scratch("gen-twoview");
        let out = tmp.path().join("twoview");
        let job = GenTwoViewJob {
            out: out.clone(),
            mode: TwoViewMode::Fundamental,
            count: 2,
            seed: 1,
            groups: Some("2".into()),
            points: None,
            noise: Some("0.5".into()),
            outliers: Some("0.2".into()),
            focal: None,
            width: None,
            height: None,
        };
        job.run().unwrap();
        let loaded = load_sequences(&out, Some("fundamental")).unwrap();
        assert_eq!(loaded.len(), 2);
        assert!(loaded.iter().all(|s| s.points.dim() == 4));
        let bad = GenTwoViewJob {
            groups: Some("0".into()),
            ..job.clone()
        };
        assert!(bad.run().unwrap_err().to_string().contains("--groups"));
        let bad = GenTwoViewJob {
            width: Some("10".into()),
            ..job
        };
        assert!(bad.run().unwrap_err().to_string().contains("--width"));
    }
}
