//! # ftcbf-lab
//!
//! Experiments without a command line: [`batch`], the Monte Carlo safety certification
//! engine (plans, shards and sweeps, trials on a thread pool, exact Clopper–Pearson intervals,
//! the exact McNemar test, CSV/JSON output, shard merging), given a [`batch::BatchSpec`] (the
//! batch without its command line). It drives any [`batch::TrialRunner`], so a program can certify its own controller or simulator with the
//! same numbers `ftcbf batch` prints (see `examples/custom_controller.rs`); [`falsify`], the
//! search for the worst attack inside a world's threat model (a cross-entropy method on the
//! batch engine's thread pool, compared with random search); [`regress`], the world
//! catalogue as a regression suite: every world's `[expect]` over its regression seeds, in
//! parallel, with a table (`ftcbf regress`); [`report`], the book's results pages rendered
//! from the stored batch and falsify JSON (`ftcbf report`); and [`trials`], the trial runner of a
//! world file that `ftcbf batch`, the examples and the Python package share. Long work tells a
//! [`progress::Progress`] how far it is and draws nothing itself. The `ftcbf` binary (the
//! workspace's root package) is a thin shell over this crate and `ftcbf-sim`: the clap
//! arguments, the commands' printing and the progress bars live there; neither clap nor
//! indicatif is a dependency of this crate, so the Python package links neither.

#![warn(missing_docs)]

pub mod batch;
pub mod falsify;
pub mod progress;
pub mod regress;
pub mod report;
pub mod trials;
