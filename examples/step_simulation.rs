//! Steps a simulation from your own code, one control step at a time, and prints every event
//! (collision, safe-set violation) as it starts, then whether the run was safe. The book's
//! "Your own code" page shows this file.
//!
//! `cargo run --release --example step_simulation -- worlds/corridor_spoof.toml`
//! (default `worlds/paper_linear.toml`; run from the repository root).

use ftcbf_sim::runner::{RunOptions, Simulation};
use ftcbf_sim::world::World;

fn main() -> anyhow::Result<()> {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "worlds/paper_linear.toml".to_string());
    let world = World::load(std::path::Path::new(&path), &[])?;
    let mut sim = Simulation::new(&world, &RunOptions::default())?;
    while let Some(frame) = sim.step() {
        if !frame.events.is_empty() {
            println!("t = {:.2} s: {:?}", frame.t, frame.events);
        }
    }
    println!("safe: {}", sim.summary().safe);
    Ok(())
}
