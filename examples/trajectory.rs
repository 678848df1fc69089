//! Prints a run's true trajectory, one line per control step: `t x y theta` (world frame, m and
//! rad). Used to measure how far a change that alters the numerics (physics or solver settings)
//! moves the robot's path: run it before and after and compare the columns.
//!
//! `cargo run --release --example trajectory -- worlds/paper_turtlebot.toml [CONTROLLER] [SEED]`
//! (CONTROLLER: ft-cbf-clf, baseline or nominal; default the world's; SEED default the world's).

use ftcbf_sim::runner::{RunOptions, Simulation};
use ftcbf_sim::world::{ControllerKindSpec, World};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .unwrap_or_else(|| "worlds/paper_turtlebot.toml".to_string());
    let controller = match args.next() {
        Some(c) => Some(
            c.parse::<ControllerKindSpec>()
                .map_err(|e| anyhow::anyhow!("{e}"))?,
        ),
        None => None,
    };
    let seed = args.next().map(|s| s.parse::<u64>()).transpose()?;
    let world = World::load(std::path::Path::new(&path), &[])?;
    let opts = RunOptions {
        seed,
        controller,
        duration: None,
    };
    let mut sim = Simulation::new(&world, &opts)?;
    while let Some(frame) = sim.step() {
        let s = frame.truth;
        println!("{:.3} {:.9} {:.9} {:.9}", frame.t, s.x, s.y, s.theta);
    }
    let summary = sim.summary();
    eprintln!("safe {} goal {}", summary.safe, summary.goal_reached);
    Ok(())
}
