//! Core benchmarks: network forward, k-means with K selection, and training steps.
//! Run: `cargo bench --bench core` (add `-- quick` for fewer repetitions). Prints medians.

use std::time::Instant;

use burn::optim::{AdamConfig, GradientsParams};
use burn::prelude::*;
use multifit::cluster::{ClusterParams, Points, Selection, cluster};
use multifit::loss::{Loss, one_hot};
use multifit::model::{ModelConfig, cpu_device};

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
    let quick = std::env::args().any(|a| a == "quick");
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
    };
    let net = cfg.init(&device).expect("config");
    for n in [1000, 5000] {
        let x = pseudo(n * 4, n);
        let ms = median_ms(reps, || {
            std::hint::black_box(net.embed(&x, 4, &device));
        });
        let gflops = 2.0 * cfg.macs_per_point() as f64 * n as f64 / (ms * 1e-3) / 1e9;
        println!(
            "forward  N={n:>5}  width 128, 12 blocks, D=4, E=6: {ms:>8.2} ms  ({gflops:.1} GFLOP/s in matmuls)"
        );
    }

    for n in [1000, 5000] {
        // Embeddings of 4 noisy groups on the unit sphere in 6D.
        let mut z = pseudo(n * 6, 7);
        for (i, row) in z.chunks_mut(6).enumerate() {
            row[i % 4] += 3.0;
            let len = row.iter().map(|v| v * v).sum::<f32>().sqrt();
            row.iter_mut().for_each(|v| *v /= len);
        }
        for sel in [Selection::Sod, Selection::Silhouette] {
            let p = ClusterParams::builder()
                .k_max(8)
                .selection(sel)
                .seed(1)
                .build()
                .unwrap();
            let ms = median_ms(reps, || {
                std::hint::black_box(cluster(Points::new(&z, 6).unwrap(), &p).unwrap());
            });
            println!(
                "cluster  N={n:>5}  K=1..8, 4 restarts, {:<10}: {ms:>8.2} ms",
                sel.name()
            );
        }
    }

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
