//! Where the CPU-heavy parts of one fit run: on the calling thread, or spread over a rayon pool
//! of the fit's own, so that a fit never uses more threads than it was given (a server running
//! W fits at once on C cores gives each C / W). Results never depend on the thread count: work
//! is split into the same pieces either way and collected in order.

use std::ops::RangeInclusive;
use std::sync::Arc;

use rayon::prelude::*;

/// The threads one fit may use: the calling thread only (the default), or a pool.
#[derive(Debug, Clone, Default)]
pub struct Threads(Option<Arc<rayon::ThreadPool>>);

impl Threads {
    /// `count` threads (0 or 1: the calling thread only).
    pub fn new(count: usize) -> Result<Self, rayon::ThreadPoolBuildError> {
        if count <= 1 {
            return Ok(Self(None));
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(count)
            .thread_name(|i| format!("multifit-fit-{i}"))
            .build()?;
        Ok(Self(Some(Arc::new(pool))))
    }

    pub fn count(&self) -> usize {
        self.0.as_ref().map_or(1, |p| p.current_num_threads())
    }

    /// Runs `f` on the pool (parallel loops inside it then stay on the pool's threads, with no
    /// hand-over to and from the calling thread per loop), or on the caller.
    pub fn install<T: Send>(&self, f: impl FnOnce() -> T + Send) -> T {
        match &self.0 {
            None => f(),
            Some(pool) => pool.install(f),
        }
    }

    /// `a` and `b` side by side on the pool, or one after the other on the calling thread.
    pub fn join<A: Send, B: Send>(
        &self,
        a: impl FnOnce() -> A + Send,
        b: impl FnOnce() -> B + Send,
    ) -> (A, B) {
        match &self.0 {
            None => (a(), b()),
            Some(pool) => pool.install(|| rayon::join(a, b)),
        }
    }

    /// `f` over every item, results in item order. Call inside [`Threads::install`].
    pub fn map<I: Send, T: Send>(
        &self,
        items: &mut [I],
        f: impl Fn(&mut I) -> T + Sync + Send,
    ) -> Vec<T> {
        match &self.0 {
            None => items.iter_mut().map(f).collect(),
            Some(_) => items.par_iter_mut().map(&f).collect(),
        }
    }

    /// `f` over 0..n, results in order. Call inside [`Threads::install`].
    pub fn map_n<T: Send>(&self, n: usize, f: impl Fn(usize) -> T + Sync + Send) -> Vec<T> {
        match &self.0 {
            None => (0..n).map(f).collect(),
            Some(_) => (0..n).into_par_iter().map(&f).collect(),
        }
    }

    /// `f` over a range, results in order. Call inside [`Threads::install`].
    pub fn map_range<T: Send>(
        &self,
        range: RangeInclusive<usize>,
        f: impl Fn(usize) -> T + Sync + Send,
    ) -> Vec<T> {
        match &self.0 {
            None => range.map(f).collect(),
            Some(_) => range.into_par_iter().map(&f).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_in_order_whatever_the_threads() {
        for count in [0, 1, 2, 3] {
            let threads = Threads::new(count).unwrap();
            assert_eq!(threads.count(), count.max(1));
            let squares = threads.install(|| threads.map_range(1..=50, |i| i * i));
            assert_eq!(squares, (1..=50).map(|i| i * i).collect::<Vec<_>>());
            let cubes = threads.install(|| threads.map_n(30, |i| i * i * i));
            assert_eq!(cubes, (0..30).map(|i| i * i * i).collect::<Vec<_>>());
            assert!(threads.install(|| threads.map_n(0, |i| i)).is_empty());
            let mut items: Vec<usize> = (0..40).collect();
            let doubled = threads.install(|| {
                threads.map(&mut items, |v| {
                    *v += 1;
                    *v * 2
                })
            });
            assert_eq!(doubled, (1..=40).map(|i| i * 2).collect::<Vec<_>>());
            assert_eq!(items, (1..=40).collect::<Vec<_>>());
        }
    }

    #[test]
    fn a_join_runs_both_sides_on_the_pool_and_nests() {
        for count in [0, 2] {
            let threads = Threads::new(count).unwrap();
            let on_pool = |name: Option<&str>| name.is_some_and(|n| n.starts_with("multifit-fit-"));
            let ((a, b), c) = threads.join(
                || {
                    threads.join(
                        || threads.install(|| threads.map_n(10, |i| i + 1)),
                        || std::thread::current().name().map(str::to_owned),
                    )
                },
                || (1..=4).product::<usize>(),
            );
            assert_eq!(a, (1..=10).collect::<Vec<_>>());
            assert_eq!(c, 24);
            // With a pool the work runs on the fit's own threads, never the caller's.
            assert_eq!(on_pool(b.as_deref()), count > 1, "{b:?}");
        }
    }
}
