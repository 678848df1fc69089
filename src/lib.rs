//! # ftcbf
//!
//! The library half of the `ftcbf` command: [`batch`], the Monte Carlo safety certification
//! engine (plans, shards and sweeps, trials on a thread pool, exact Clopper–Pearson intervals,
//! the exact McNemar test, CSV/JSON output, shard merging). It drives any
//! [`batch::TrialRunner`], so a program can certify its own controller or simulator with the
//! same numbers `ftcbf batch` prints (see `examples/custom_controller.rs`). The binary
//! (`src/main.rs`) is a thin shell over it and over `ftcbf-sim`.
//!
//! [`regress`] runs the world catalogue as a regression suite: every world's `[expect]` over its
//! regression seeds, in parallel, with a table (`ftcbf regress`).

pub mod batch;
pub mod regress;
