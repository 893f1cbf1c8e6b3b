//! How long a rayon pool's second thread takes to join work after the pool sat idle, which can
//! leave a fit that follows an idle spell nearly single-threaded (docs/PERFORMANCE.md). Each
//! round sleeps, then runs `rayon::join` of 2 ms of spinning and a closure
//! that records when it starts: if the pool's other thread is awake it steals that closure at
//! once; if not, the first thread runs it after its 2 ms.
//! Run: `cargo bench --bench wake`. Prints medians and 90th percentiles of 30 rounds.

use std::time::{Duration, Instant};

fn spin(d: Duration) {
    let t = Instant::now();
    while t.elapsed() < d {
        std::hint::spin_loop();
    }
}

fn main() {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a pool of 2 threads");
    let half = Duration::from_millis(1);
    println!("rayon pool of 2 threads: join(2 ms of work, a closure), 30 rounds per line");
    for (idle_ms, prewake) in [
        (0u64, false),
        (1, false),
        (5, false),
        (20, false),
        (120, false),
        (120, true),
    ] {
        let mut starts: Vec<f64> = (0..30)
            .map(|_| {
                std::thread::sleep(Duration::from_millis(idle_ms));
                if prewake {
                    // Wake the pool first, then spend 1 ms elsewhere (as a server parsing a body).
                    pool.spawn_broadcast(|_| ());
                    spin(half);
                }
                let t0 = Instant::now();
                pool.install(|| rayon::join(|| spin(2 * half), || t0.elapsed()).1)
                    .as_secs_f64()
                    * 1e3
            })
            .collect();
        starts.sort_by(f64::total_cmp);
        println!(
            "idle {idle_ms:>3} ms before{}: the closure starts after p50 {:.3} ms, p90 {:.3} ms",
            if prewake {
                ", pool woken 1 ms ahead"
            } else {
                ""
            },
            starts[15],
            starts[27]
        );
    }
}
