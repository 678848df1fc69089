//! Same world + same seed → the same summary, bit for bit; another seed → different noise.

use std::path::PathBuf;

use ftcbf_sim::runner::{run, RunOptions};
use ftcbf_sim::world::World;

fn world(name: &str) -> World {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("worlds")
        .join(name);
    World::load(&p, &[]).expect("catalogue world loads")
}

fn opts(seed: u64) -> RunOptions {
    RunOptions {
        seed: Some(seed),
        duration: Some(6.0),
        ..RunOptions::default()
    }
}

#[test]
fn rapier_runs_repeat_bit_for_bit() {
    let w = world("field_replay.toml");
    let a = run(&w, &opts(11)).expect("runs");
    let b = run(&w, &opts(11)).expect("runs");
    // RunSummary compares every float exactly.
    assert_eq!(a, b);
    assert_eq!(
        a.final_state.map(f64::to_bits),
        b.final_state.map(f64::to_bits)
    );
    let c = run(&w, &opts(12)).expect("runs");
    assert_ne!(
        a.final_state, c.final_state,
        "a different seed must change the noise"
    );
}

#[test]
fn linear_runs_repeat_bit_for_bit() {
    let w = world("paper_linear.toml");
    let a = run(&w, &opts(5)).expect("runs");
    let b = run(&w, &opts(5)).expect("runs");
    assert_eq!(a, b);
    let c = run(&w, &opts(6)).expect("runs");
    assert_ne!(a.final_state, c.final_state);
}

#[test]
fn parallel_runs_equal_serial_runs() {
    let w = world("corridor_spoof.toml");
    let serial: Vec<_> = (0..4).map(|s| run(&w, &opts(s)).expect("runs")).collect();
    let parallel: Vec<_> = std::thread::scope(|sc| {
        let hs: Vec<_> = (0..4)
            .map(|s| {
                let w = &w;
                sc.spawn(move || run(w, &opts(s)).expect("runs"))
            })
            .collect();
        hs.into_iter().map(|h| h.join().expect("thread")).collect()
    });
    assert_eq!(serial, parallel);
}
