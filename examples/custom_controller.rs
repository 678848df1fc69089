//! A user-written control law driven through the simulator and certified by a Monte Carlo
//! batch, next to the paper's FT-CBF-CLF controller, on the same seeds.
//!
//! The law ("median-pd") reads the world's channels through the same interface the built-in
//! controllers use ([`ControlLaw`]): per state component (p_x, p_y, v_x, v_y) it takes the median
//! of the fresh, finite readings of the channels that measure that component directly, holds
//! the last value between samples, and applies a saturated PD law toward the goal. It has no
//! barrier: the batch shows what that costs.
//!
//! Run: `cargo run --release --example custom_controller [WORLD.toml] [TRIALS]`
//! (default `worlds/paper_linear.toml`, 40 trials).

use std::path::PathBuf;

use anyhow::Context;
use ftcbf_lab::batch::{self, Execution, TrialRunner};
use ftcbf_lab::trials::{plan_for, WorldRunner};
use ftcbf_sim::ftcbf_controller::{ControlLaw, ControllerConfig, Decision, Input, Readings, State};
use ftcbf_sim::runner::{RunOptions, Simulation};
use ftcbf_sim::summary::RunSummary;
use ftcbf_sim::world::World;

/// Proportional gain [1/s²] and damping gain [1/s] of the PD law.
const KP: f64 = 0.6;
const KD: f64 = 1.2;
/// Input bound when the world gives none [m/s²].
const DEFAULT_LIMIT: f64 = 1.0;

struct MedianPd {
    /// For each channel, the state component it measures directly (a unit row of C), if any.
    component: Vec<Option<usize>>,
    goal: State,
    limit: Input,
    /// Last estimate per component (NaN until a first reading).
    x: [f64; 4],
    buf: Vec<f64>,
}

impl MedianPd {
    fn new(cfg: &ControllerConfig) -> Self {
        let component = cfg
            .model
            .c
            .iter()
            .map(|row| {
                let ones: Vec<usize> = (0..4).filter(|&i| row[i] == 1.0).collect();
                let zeros = (0..4).filter(|&i| row[i] == 0.0).count();
                (ones.len() == 1 && zeros == 3).then(|| ones[0])
            })
            .collect();
        Self {
            component,
            goal: cfg.goal,
            limit: cfg
                .input_limit
                .unwrap_or(Input::new(DEFAULT_LIMIT, DEFAULT_LIMIT)),
            x: [f64::NAN; 4],
            buf: Vec::new(),
        }
    }
}

impl ControlLaw for MedianPd {
    fn name(&self) -> &str {
        "median-pd"
    }

    fn step(&mut self, r: &Readings<'_>) -> Decision<'_> {
        for i in 0..4 {
            self.buf.clear();
            for (k, c) in self.component.iter().enumerate() {
                let (y, fresh) = (r.y.get(k), r.fresh.get(k));
                if let (Some(&y), Some(true), Some(ci)) = (y, fresh.copied(), *c) {
                    if ci == i && y.is_finite() {
                        self.buf.push(y);
                    }
                }
            }
            if !self.buf.is_empty() {
                self.buf.sort_by(f64::total_cmp);
                let n = self.buf.len();
                self.x[i] = 0.5 * (self.buf[(n - 1) / 2] + self.buf[n / 2]);
            }
        }
        let u = Input::from_fn(|a, _| {
            let (p, v) = (self.x[a], self.x[a + 2]);
            let v = if v.is_finite() { v } else { 0.0 };
            let raw = if p.is_finite() {
                KP * (self.goal[a] - p) - KD * (v - self.goal[a + 2])
            } else {
                0.0
            };
            raw.clamp(-self.limit[a], self.limit[a])
        });
        Decision { u, record: None }
    }
}

/// Runs trials of one world: "median-pd" is the law above, anything else a built-in controller
/// (run as `ftcbf batch` runs it).
struct Runner(WorldRunner);

impl TrialRunner for Runner {
    fn run_trial(&self, controller: &str, seed: u64) -> anyhow::Result<RunSummary> {
        if controller != "median-pd" {
            return self.0.run_trial(controller, seed);
        }
        let opts = RunOptions {
            seed: Some(seed),
            ..RunOptions::default()
        };
        let mut sim = Simulation::with_law(&self.0 .0, &opts, |cfg| {
            Ok(Box::new(MedianPd::new(cfg)) as Box<dyn ControlLaw>)
        })?;
        sim.run_to_end();
        Ok(sim.summary())
    }
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().unwrap_or("worlds/paper_linear.toml".into()));
    let trials: u64 = match args.next() {
        Some(s) => s
            .parse()
            .with_context(|| format!("TRIALS: expected a count, found `{s}`"))?,
        None => 40,
    };
    // Compiled once (γ, θ, η, barriers, CLF, path): the stepped run and every trial below
    // borrow it.
    let runner = Runner(WorldRunner::new(World::load(&path, &[])?)?);
    let world = runner.0.world();

    // One run, stepped by hand: count the steps whose frame reports an event.
    let mut sim = Simulation::with_law(&runner.0 .0, &RunOptions::default(), |cfg| {
        Ok(Box::new(MedianPd::new(cfg)) as Box<dyn ControlLaw>)
    })?;
    let mut eventful = 0;
    while let Some(frame) = sim.step() {
        eventful += usize::from(!frame.events.is_empty());
    }
    let s = sim.summary();
    println!(
        "{}: {} seed {}: safe {}, goal reached {}, {} steps with events",
        s.world, s.controller, s.seed, s.safe, s.goal_reached, eventful
    );

    // A paired batch: both laws on the same trial seeds, exact 95 % intervals.
    let controllers = vec!["ft-cbf-clf".into(), "median-pd".into()];
    let plan = plan_for(world, &path, trials, controllers);
    let exec = Execution {
        jobs: None,
        progress: &ftcbf_lab::progress::Silent,
    };
    let result = batch::run_batch(&runner, &plan, exec)?;
    for c in &result.summaries {
        println!(
            "{:>11}: safe {}/{} = {:.3}, 95 % CI [{:.3}, {:.3}], goal rate {:.3}",
            c.controller,
            c.safe,
            c.trials,
            c.safe_rate,
            c.safe_ci.lower,
            c.safe_ci.upper,
            c.goal_rate
        );
    }
    for p in &result.paired {
        println!(
            "McNemar {} vs {}: only first safe {}, only second safe {}, p = {:.3e}",
            p.first, p.second, p.only_first_safe, p.only_second_safe, p.p_value
        );
    }
    Ok(())
}
