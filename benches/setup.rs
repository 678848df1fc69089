//! Issue #28: what a batch pays to start its trials, before and after compiling the world once,
//! on `paper_turtlebot` (no obstacles) and `doorway_clutter` (obstacles, a path planned around
//! them by A*).
//! `before`: 100 runs each built from the `World` (each computes the controller setup:
//! channels, model, barriers, γ/θ/η by Riccati, κ, CLF, planned path); `after`: the world
//! loaded and compiled once (`CompiledWorld`), then 100 runs built from it (each builds only its
//! sensors, attacks, control law and plant). No step is taken: this is the setup alone. The
//! per-trial pair shows one run's start from either.

use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion};
use ftcbf_sim::runner::{CompiledWorld, RunOptions, Simulation};
use ftcbf_sim::world::World;

const TRIALS: u64 = 100;

fn bench(c: &mut Criterion) {
    for name in ["paper_turtlebot", "doorway_clutter"] {
        bench_world(c, name);
    }
}

fn bench_world(c: &mut Criterion, name: &str) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("worlds/{name}.toml"));
    let world = World::load(&path, &[]).expect("world loads");
    let opts = |k: u64| RunOptions {
        seed: Some(k),
        ..RunOptions::default()
    };
    let mut g = c.benchmark_group(format!("{name}/batch_setup_100_trials"));
    g.sample_size(10);
    g.bench_function("before_per_trial_setup", |b| {
        b.iter(|| {
            for k in 0..TRIALS {
                drop(Simulation::new(&world, &opts(k)).expect("starts"));
            }
        })
    });
    g.bench_function("after_compiled_once", |b| {
        b.iter(|| {
            // The load is counted here (not in `before`): the comparison is conservative.
            let compiled = CompiledWorld::new(World::load(&path, &[]).expect("world loads"))
                .expect("compiles");
            for k in 0..TRIALS {
                drop(Simulation::new(&compiled, &opts(k)).expect("starts"));
            }
        })
    });
    g.finish();

    let compiled =
        CompiledWorld::new(World::load(&path, &[]).expect("world loads")).expect("compiles");
    let mut g = c.benchmark_group(format!("{name}/trial_setup"));
    g.sample_size(20);
    g.bench_function("from_world", |b| {
        b.iter(|| Simulation::new(&world, &opts(1)).map(drop).expect("starts"))
    });
    g.bench_function("from_compiled_world", |b| {
        b.iter(|| {
            Simulation::new(&compiled, &opts(1))
                .map(drop)
                .expect("starts")
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
