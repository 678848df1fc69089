//! Progress of long work, reported to whoever runs it.
//!
//! The library draws nothing: a batch, a falsification search or a regression run tells a
//! [`Progress`] how far it is, and the caller decides what to show — the `ftcbf` binary draws an
//! indicatif bar on a terminal, the Python package and tests pass [`Silent`]. (rapier takes an
//! `EventHandler` the same way.) Every method takes `&self`: the trials that advance it run on
//! a thread pool.

/// Where a long piece of work reports how far it is.
pub trait Progress: Sync {
    /// Work of `len` units (runs, trials) begins, labelled `label`; counting restarts at 0.
    fn start(&self, len: u64, label: &str);
    /// `n` more units are done.
    fn advance(&self, n: u64);
    /// The work enters a new phase (e.g. "cem generation 3/8"); the count goes on.
    fn phase(&self, label: &str);
    /// The work is over: whatever was shown can go.
    fn finish(&self);
}

/// Reports nothing: for callers without a display (tests, the Python package, nested runs).
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {
    fn start(&self, _len: u64, _label: &str) {}
    fn advance(&self, _n: u64) {}
    fn phase(&self, _label: &str) {}
    fn finish(&self) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU64, Ordering};

    /// Counts what it is told, to check that a caller's progress hears every unit.
    struct Count(AtomicU64);
    impl Progress for Count {
        fn start(&self, _len: u64, _label: &str) {
            self.0.store(0, Ordering::Relaxed);
        }
        fn advance(&self, n: u64) {
            self.0.fetch_add(n, Ordering::Relaxed);
        }
        fn phase(&self, _label: &str) {}
        fn finish(&self) {}
    }

    #[test]
    fn a_trait_object_counts_from_many_threads() {
        let count = Count(AtomicU64::new(7));
        let p: &dyn Progress = &count;
        p.start(100, "trials");
        std::thread::scope(|s| {
            for _ in 0..4 {
                s.spawn(|| (0..25).for_each(|_| p.advance(1)));
            }
        });
        p.finish();
        assert_eq!(count.0.load(Ordering::Relaxed), 100);
    }
}
