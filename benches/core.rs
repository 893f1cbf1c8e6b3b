//! Core benchmarks: network forward (burn, fused serving path, and the bare matrix multiplies of
//! the same shapes as the floor), k-means with K selection, the whole fit of a shipped model,
//! geometric refinement, the SVG picture of a fit, and training steps.
//! Run: `cargo bench --bench core` (add `-- quick` for fewer repetitions, and section names,
//! e.g. `-- refine`, to run only those; `-- curves` runs one family's refinement rows:
//! curves, homography or subspace). Prints medians.

use std::time::Instant;

use burn::optim::{AdamConfig, GradientsParams};
use burn::prelude::*;
use multifit::cluster::{ClusterParams, Points, Selection, cluster};
use multifit::data::synthetic::{LceConfig, LceGenerator, LceVariant};
use multifit::data::{ImageSize, Kind, PointSet, Sequence};
use multifit::geometry::Family;
use multifit::loss::{Loss, one_hot};
use multifit::model::gemm::matmul;
use multifit::model::{FusedNet, ModelConfig, cpu_device};
use multifit::refine::{RefineParams, refine, refine_on};
use multifit::registry::LoadedModel;
use multifit::render::{Picture, fit_svg};
use multifit::threads::Threads;
use rayon::prelude::*;

fn median_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    f(); // warm-up
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn pseudo(n: usize, salt: usize) -> Vec<f32> {
    (0..n)
        .map(|i| (((i * 7919 + salt * 104729) % 2003) as f32 / 1001.5) - 1.0)
        .collect()
}

fn main() {
    // Sections to run: those named on the command line (forward, cluster, fit, refine, render,
    // train), or all.
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "quick");
    let named: Vec<&str> = args
        .iter()
        .map(String::as_str)
        .filter(|a| !a.starts_with('-') && *a != "quick")
        .collect();
    // A family name (curves, homography, subspace) picks refinement rows, and the refine section.
    let families = ["curves", "homography", "subspace"];
    let (picked, sections): (Vec<&str>, Vec<&str>) =
        named.iter().partition(|a| families.contains(a));
    let family_named = |name: &str| picked.is_empty() || picked.iter().any(|a| name.ends_with(a));
    let wanted = |section: &str| {
        named.is_empty()
            || sections.contains(&section)
            || (section == "refine" && !picked.is_empty())
    };
    let reps = if quick { 3 } else { 15 };
    let device = cpu_device();
    device.seed(0);
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "all".into());
    println!("multifit core benchmarks (median of {reps}; rayon threads: {threads})");

    let cfg = ModelConfig {
        input_dim: 4,
        width: 128,
        depth: 12,
        embed_dim: 6,
        batch_norm: false,
        cn_epsilon: 1e-3,
        neighbors: 0,
        graph_neighbors: 0,
    };
    let net = cfg.init(&device).expect("config");
    let fused = FusedNet::from_net(&net).expect("fused weights");
    let (d, w, e) = (cfg.input_dim, cfg.width, cfg.embed_dim);
    let gflops =
        |n: usize, ms: f64| 2.0 * cfg.macs_per_point() as f64 * n as f64 / (ms * 1e-3) / 1e9;
    println!("forward: width 128, 12 blocks, D=4, E=6; GFLOP/s counts the matrix multiplies only");
    if wanted("forward") {
        for n in [1000, 5000] {
            let x = pseudo(n * d, n);
            let burn_ms = median_ms(reps, || {
                std::hint::black_box(net.embed(&x, d, &device));
            });
            println!(
                "forward  N={n:>5}  burn (all threads)    : {burn_ms:>8.2} ms  ({:.1} GFLOP/s)",
                gflops(n, burn_ms)
            );
            for threads in [1, 2] {
                let pool = Threads::new(threads).expect("threads");
                let fused_ms = median_ms(reps, || {
                    std::hint::black_box(fused.forward(&x, &pool));
                });
                // The floor: the same matrix multiplies with nothing between them, the rows split in
                // `threads` equal parts, one single-threaded sgemm call per part and layer.
                let (wd, ww, we) = (pseudo(d * w, 1), pseudo(w * w, 2), pseudo(w * e, 3));
                let rows = n.div_ceil(threads);
                // One part: its input rows, two hidden-layer buffers (ping-pong), its embeddings.
                type Part<'a> = (&'a [f32], Vec<f32>, Vec<f32>, Vec<f32>);
                let mut parts: Vec<Part> = x
                    .chunks(rows * d)
                    .map(|p| {
                        let r = p.len() / d;
                        (p, vec![0f32; r * w], vec![0f32; r * w], vec![0f32; r * e])
                    })
                    .collect();
                let floor = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let floor_ms = median_ms(reps, || {
                    floor.install(|| {
                        parts.par_iter_mut().for_each(|(p, h, h2, z)| {
                            matmul(p, d, &wd, w, h);
                            for _ in 0..cfg.depth {
                                matmul(h, w, &ww, w, h2);
                                matmul(h2, w, &ww, w, h);
                            }
                            matmul(h, w, &we, e, z);
                        })
                    });
                    std::hint::black_box(&parts);
                });
                println!(
                    "forward  N={n:>5}  fused, {threads} thread(s)   : {fused_ms:>8.2} ms  ({:.1} GFLOP/s); \
                 bare sgemm {floor_ms:.2} ms ({:.1} GFLOP/s); fused at {:.0} % of sgemm throughput; \
                 {:.1}x faster than burn",
                    gflops(n, fused_ms),
                    gflops(n, floor_ms),
                    100.0 * floor_ms / fused_ms,
                    burn_ms / fused_ms
                );
            }
        }
    }
    let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    if wanted("cluster") {
        // Real embeddings: the shipped adelaide-homography model on the AdelaideRMF pair bonhall
        // (1068 correspondences, 6 planes and outliers), E = 8.
        let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets");
        let model = LoadedModel::load(&models.join("adelaide-homography")).expect("shipped model");
        let pair = Sequence::load(&data.join("adelaidermf/bonhall.json")).expect("dataset");
        let z = model.embed(
            &multifit::pipeline::prepare(&model, &pair.points, pair.image_size).expect("input"),
        );
        // K = 1..8 with 4 restarts, the median time of `sel` on `[n, dim]` embeddings.
        let cluster_ms = |z: &[f32], dim: usize, sel: Selection| {
            let p = ClusterParams::builder()
                .k_max(8)
                .selection(sel)
                .seed(1)
                .build()
                .unwrap();
            median_ms(reps, || {
                std::hint::black_box(cluster(Points::new(z, dim).unwrap(), &p).unwrap());
            })
        };
        for sel in [Selection::Sod, Selection::Silhouette] {
            let ms = cluster_ms(&z, 8, sel);
            println!(
                "cluster  N={:>5}  K=1..8, 4 restarts, {:<10}: {ms:>8.2} ms  (real embeddings: bonhall)",
                pair.points.len(),
                sel.name()
            );
        }

        for n in [1000, 5000, 20000] {
            // Embeddings of 4 noisy groups on the unit sphere in 6D.
            let mut z = pseudo(n * 6, 7);
            for (i, row) in z.chunks_mut(6).enumerate() {
                row[i % 4] += 3.0;
                let len = row.iter().map(|v| v * v).sum::<f32>().sqrt();
                row.iter_mut().for_each(|v| *v /= len);
            }
            for sel in [Selection::Sod, Selection::Silhouette] {
                let ms = cluster_ms(&z, 6, sel);
                println!(
                    "cluster  N={n:>5}  K=1..8, 4 restarts, {:<10}: {ms:>8.2} ms",
                    sel.name()
                );
            }
        }
    }
    if wanted("fit") {
        // The whole fit (normalise, embed, cluster) of a shipped model on 4 planes of pseudo-random
        // correspondences: what one request costs the server beyond HTTP and JSON.
        for n in [1000, 5000, 20000] {
            let rows: Vec<Vec<f64>> = pseudo(n * 4, 11)
                .chunks(4)
                .enumerate()
                .map(|(i, r)| {
                    let (x, y, g) = (
                        f64::from(r[0]) * 400.0 + 500.0,
                        f64::from(r[1]) * 300.0 + 400.0,
                        (i % 4) as f64,
                    );
                    vec![
                        x,
                        y,
                        x * (1.0 + 0.05 * g) + 20.0 * g,
                        y + 10.0 * g * g + f64::from(r[2]),
                    ]
                })
                .collect();
            let points = PointSet::from_rows(Kind::Correspondences, &rows).expect("points");
            let image = Some(ImageSize::new(1024.0, 768.0).expect("image size"));
            for threads in [1, 2] {
                let model = LoadedModel::load(&models.join("adelaide-homography"))
                    .expect("shipped model")
                    .with_threads(threads)
                    .expect("threads");
                let p = ClusterParams::builder()
                    .k_max(8)
                    .selection(Selection::Silhouette)
                    .seed(1)
                    .build()
                    .unwrap();
                let ms = median_ms(reps.min(5), || {
                    std::hint::black_box(model.fit(&points, image, &p).unwrap());
                });
                println!(
                    "fit      N={n:>5}  adelaide-homography, silhouette K=1..8, {threads} thread(s): {ms:>8.2} ms"
                );
            }
        }
    }
    if wanted("refine") {
        // Refinement at N = 1000, started from the true groups (the reassignment rounds and every
        // refit run as in a fit): 4 LCE shapes of 250 points; 4 planes of correspondences; 4 motions
        // of 20-frame tracks; and 3 motions of 100 tracks of 100 frames (N = 300).
        let mut lce = LceGenerator::new(
            5,
            LceConfig {
                points_per_shape: 250,
                scale: 2.0,
                ..LceConfig::default()
            },
        );
        let curves = lce.sample(LceVariant::Mixed, "bench").sample;
        let planes: Vec<Vec<f64>> = (0..1000)
            .map(|i| {
                let g = (i % 4) as f64;
                let r = pseudo(3, i);
                let (x, y) = (
                    f64::from(r[0]) * 400.0 + 500.0,
                    f64::from(r[1]) * 300.0 + 400.0,
                );
                let w = 1.0 + 1e-4 * g * x;
                vec![
                    x,
                    y,
                    (x * (1.0 + 0.05 * g) + 20.0 * g) / w,
                    (y + 10.0 * g * g) / w + 0.5 * f64::from(r[2]),
                ]
            })
            .collect();
        // `n` tracks of `frames` frames, `motions` rigid motions seen by a perspective camera,
        // track i following motion i % motions.
        let tracks = |n: usize, frames: usize, motions: usize| -> Vec<Vec<f64>> {
            (0..n)
                .map(|i| {
                    let g = (i % motions) as f64;
                    let r = pseudo(3, i + 5000);
                    let (x, y, z) = (
                        f64::from(r[0]) * 5.0,
                        f64::from(r[1]) * 5.0,
                        f64::from(r[2]) + 10.0,
                    );
                    (0..frames)
                        .flat_map(|f| {
                            let (a, t) = (0.01 * f as f64 * (g + 1.0), 0.2 * f as f64 * g);
                            let (xr, zr) =
                                (x * a.cos() + z * a.sin() + t, -x * a.sin() + z * a.cos());
                            [500.0 * xr / zr + 600.0, 500.0 * y / zr + 200.0]
                        })
                        .collect()
                })
                .collect()
        };
        let sets = [
            (
                "lce shapes, curves",
                curves.points.clone(),
                curves.labels.clone(),
                Family::Curves,
            ),
            (
                "planes, homography",
                PointSet::from_rows(Kind::Correspondences, &planes).expect("points"),
                (0..1000).map(|i| i % 4).collect(),
                Family::Homography,
            ),
            (
                "20-frame tracks, subspace",
                PointSet::from_rows(Kind::Trajectories, &tracks(1000, 20, 4)).expect("points"),
                (0..1000).map(|i| i % 4).collect(),
                Family::Subspace,
            ),
            // Long tracks, fewer per motion than coordinates (2F = 200): Gram matrices.
            (
                "100-frame tracks, subspace",
                PointSet::from_rows(Kind::Trajectories, &tracks(300, 100, 3)).expect("points"),
                (0..300).map(|i| i % 3).collect(),
                Family::Subspace,
            ),
        ];
        for (name, points, labels, family) in sets.iter().filter(|s| family_named(s.0)) {
            let k = labels.iter().max().map_or(0, |m| m + 1);
            // K chosen automatically (structures may merge), a caller's K, and a caller's K without
            // the hypotheses stage (what it costs). Curves keep a point within 1 σ of its
            // structure, as `lce` refines.
            let shipped = RefineParams {
                stay: if *family == Family::Curves { 1.0 } else { 0.0 },
                ..RefineParams::default()
            };
            let plain = RefineParams {
                hypotheses: false,
                ..shipped
            };
            for (auto_k, how, params) in [
                (true, "K chosen", shipped),
                (false, "K given", shipped),
                (false, "K given, no hypotheses", plain),
            ] {
                for count in [1, 2] {
                    let pool = Threads::new(count).expect("threads");
                    let ms = median_ms(reps, || {
                        let k_chosen = auto_k.then_some(8);
                        std::hint::black_box(refine_on(
                            points, labels, k, *family, &params, k_chosen, &pool,
                        ));
                    });
                    println!(
                        "refine   N={:>5}  {name:<26}, {how}, {count} thread(s): {ms:>8.2} ms",
                        points.len()
                    );
                }
            }
        }
    }
    if wanted("render") {
        // The SVG picture of a 20000-point fit with four circle structures and a residual curve.
        let mut big = LceGenerator::new(
            6,
            LceConfig {
                points_per_shape: 5000,
                ..LceConfig::default()
            },
        );
        let sample = big.sample(LceVariant::Mixed, "bench").sample;
        let labels: Vec<i64> = sample.labels.iter().map(|&l| l as i64).collect();
        let fitted = refine(
            &sample.points,
            &sample.labels,
            4,
            Family::Curves,
            &RefineParams::default(),
            None,
        );
        let structures: Vec<(usize, &multifit::geometry::Model)> = fitted
            .structures
            .iter()
            .map(|s| (s.label, &s.model))
            .collect();
        let residuals: Vec<(usize, f64)> = (1..=6).map(|k| (k, 1.0 / k as f64)).collect();
        let ms = median_ms(reps, || {
            std::hint::black_box(fit_svg(&Picture {
                title: "lce · K = 4 (sod)".into(),
                points: &sample.points,
                image_size: None,
                labels: &labels,
                structures: &structures,
                residuals: &residuals,
                scores: &residuals,
                k: 4,
                clustered_k: 4,
                selection: "sod",
            }));
        });
        println!(
            "render   N={:>5}  SVG picture of a fit       : {ms:>8.2} ms",
            sample.points.len()
        );
    }
    if wanted("train") {
        let ad = device.clone().autodiff();
        ad.seed(0);
        let tcfg = ModelConfig {
            input_dim: 10,
            embed_dim: 5,
            ..cfg
        };
        let mut model = tcfg.init(&ad).expect("config");
        let mut optim = AdamConfig::new().init();
        for n in [500, 1000] {
            let x = pseudo(n * 10, n);
            let labels: Vec<usize> = (0..n).map(|i| i % 3).collect();
            let ms = median_ms(reps, || {
                let xt = Tensor::<3>::from_data(TensorData::new(x.clone(), [1, n, 10]), &ad);
                let z = model.forward(xt).reshape([n, 5]);
                let loss = Loss::Mimi { alpha: 0.6 }.compute(z, one_hot(&labels, 3, &ad));
                let grads = GradientsParams::from_grads(loss.backward(), &model);
                model = optim.step(1e-4, model.clone(), grads);
            });
            println!(
                "train    N={n:>5}  fwd+bwd+Adam, MIMI, width 128, 12 blocks: {ms:>8.2} ms/step  ({:.1} steps/s)",
                1e3 / ms
            );
        }
    }
}
