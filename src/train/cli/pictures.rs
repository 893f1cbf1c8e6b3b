//! `eval --pictures DIR`: the picture of every evaluated sample's fit as served (the card's K
//! selection, refinement as the evaluation ran it), worst first, with an `index.html` that lists
//! them by error.

use std::fmt::Write as _;
use std::path::Path;

use super::CliError;
use crate::cluster::{ClusterParams, Selection};
use crate::data::Sample;
use crate::pipeline::{self, FitOptions};
use crate::registry::LoadedModel;
use crate::render::{Picture, fit_svg};
use crate::train::eval::{EvalRow, EvalSettings};

/// The error of a row under the card's way of choosing K.
fn served_error(row: &EvalRow, selection: Selection) -> f64 {
    match selection {
        Selection::Silhouette => row.silhouette.error,
        Selection::Fixed(_) => row.known.error,
        _ => row.sod.error,
    }
}

/// File-name-safe form of a sample name.
fn file_stem(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Writes `<dir>/<rank>-<sample>.svg` for every sample (rank 1 = the largest error) and
/// `<dir>/index.html`; `settings(sample)` is the evaluation each sample had. -> pictures written.
pub fn write(
    model: &LoadedModel,
    samples: &[Sample],
    rows: &[EvalRow],
    settings: impl Fn(&Sample) -> EvalSettings,
    dir: &Path,
) -> Result<usize, CliError> {
    std::fs::create_dir_all(dir).map_err(|source| CliError::Create {
        path: dir.to_path_buf(),
        source,
    })?;
    let selection = model.card.selection;
    let mut order: Vec<usize> = (0..rows.len().min(samples.len())).collect();
    order.sort_by(|&a, &b| {
        served_error(&rows[b], selection).total_cmp(&served_error(&rows[a], selection))
    });
    let mut index = format!(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{0}: evaluated fits, worst first</title></head>\n<body>\n<h1>{0}: evaluated fits, worst first</h1>\n<ol>\n",
        escape(&model.card.name)
    );
    for (rank, &i) in order.iter().enumerate() {
        let (sample, row) = (&samples[i], &rows[i]);
        let s = settings(sample);
        let params = ClusterParams::builder()
            .selection(selection)
            .k_max(s.k_max.min(sample.points.len()))
            .restarts(s.restarts)
            .seed(s.seed)
            .build()
            .map_err(|e| CliError::Sample {
                name: sample.name.clone(),
                source: e.into(),
            })?;
        let options = FitOptions {
            params: &params,
            symmetries: &model.card.test_symmetries,
            refine: s.refine,
            outlier_group: model.card.outliers,
            erratic_outliers: true,
        };
        let fit = pipeline::fit(model, &sample.points, sample.image_size, &options).map_err(
            |source| CliError::Sample {
                name: sample.name.clone(),
                source,
            },
        )?;
        let error = served_error(row, selection);
        let structures: Vec<_> = fit.structures.iter().map(|s| (s.label, &s.model)).collect();
        let svg = fit_svg(&Picture {
            title: format!(
                "{} · {} · K = {} ({}; true {}) · error {:.1} %",
                model.card.name,
                sample.name,
                fit.k,
                selection.name(),
                row.k_true,
                100.0 * error
            ),
            points: &sample.points,
            image_size: sample.image_size,
            labels: &fit.labels,
            structures: &structures,
            residuals: &fit.clustering.residuals,
            scores: &fit.clustering.scores,
            k: fit.k,
            clustered_k: fit.clustering.k,
            selection: selection.name(),
        });
        let file = format!("{:03}-{}.svg", rank + 1, file_stem(&sample.name));
        let path = dir.join(&file);
        std::fs::write(&path, svg).map_err(|source| CliError::Write { path, source })?;
        let _ = writeln!(
            index,
            "<li><p>{} · error {:.1} % · K {} (true {})</p><img src=\"{file}\" width=\"760\" alt=\"fit of {}\"></li>",
            escape(&sample.name),
            100.0 * error,
            fit.k,
            row.k_true,
            escape(&sample.name)
        );
    }
    index.push_str("</ol>\n</body></html>\n");
    let path = dir.join("index.html");
    std::fs::write(&path, index).map_err(|source| CliError::Write { path, source })?;
    Ok(order.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::motion::MotionSpec;
    use crate::train::eval::evaluate_sample;

    #[test]
    fn one_picture_per_sample_worst_first_with_an_index() {
        let model = crate::registry::tests::tiny(vec![]);
        let spec: MotionSpec = "count=3,seed=5,frames=2,motions=2,points=8-12"
            .parse()
            .unwrap();
        let samples: Vec<Sample> = spec
            .sequences()
            .unwrap()
            .iter()
            .map(|s| s.sample())
            .collect();
        let settings = |_: &Sample| EvalSettings {
            k_max: 5,
            restarts: 2,
            seed: 0,
            refine: None,
            from_truth: false,
        };
        let rows: Vec<EvalRow> = samples
            .iter()
            .map(|s| evaluate_sample(&model, s, &settings(s)).unwrap())
            .collect();
        let tmp = crate::registry::tests::scratch("pictures");
        let dir = tmp.path().join("pictures");
        assert_eq!(write(&model, &samples, &rows, settings, &dir).unwrap(), 3);
        let index = std::fs::read_to_string(dir.join("index.html")).unwrap();
        let mut errors = Vec::new();
        for rank in 1..=3 {
            let file = std::fs::read_dir(&dir)
                .unwrap()
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .find(|f| f.starts_with(&format!("{rank:03}-")) && f.ends_with(".svg"))
                .unwrap();
            assert!(index.contains(&format!("src=\"{file}\"")));
            let svg = std::fs::read_to_string(dir.join(&file)).unwrap();
            // One mark per point.
            let n = samples
                .iter()
                .find(|s| file.contains(&file_stem(&s.name)))
                .unwrap()
                .points
                .len();
            assert_eq!(svg.matches(r#"class="pt""#).count(), n, "{file}");
            let at = svg.find("error ").unwrap();
            let e: f64 = svg[at + 6..].split(' ').next().unwrap().parse().unwrap();
            errors.push(e);
        }
        assert!(errors.windows(2).all(|w| w[0] >= w[1]), "{errors:?}");
    }
}
