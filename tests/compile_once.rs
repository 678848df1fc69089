//! Issue #28: a batch compiles its world once. `ftcbf batch`'s runner (`prepare_batch`, through
//! the library, without spawning the binary) computes the controller setup (channels, model,
//! barriers, γ/θ/η by Riccati, κ, CLF, planned path) once for a 100-trial batch of two
//! controllers, where a runner that starts each trial from the `World` computes it once per
//! trial; both give the same trial records, bit for bit.
//!
//! One test in this file: [`setups_computed`] is a process-wide counter, and tests of one file
//! run in parallel.

use std::path::PathBuf;

use ftcbf_lab::batch::{run_batch, BatchPlan, BatchResult, Execution, TrialRunner};
use ftcbf_lab::trials::{plan_for, prepare_batch, trial_options};
use ftcbf_sim::runner::{run, setups_computed};
use ftcbf_sim::summary::RunSummary;
use ftcbf_sim::world::World;

const TRIALS: u64 = 100;
const CONTROLLERS: [&str; 2] = ["ft-cbf-clf", "baseline"];

/// The runner before issue #28: every trial builds its run from the `World`.
struct PerTrial(World);

impl TrialRunner for PerTrial {
    fn run_trial(&self, controller: &str, seed: u64) -> anyhow::Result<RunSummary> {
        Ok(run(&self.0, &trial_options(controller, seed)?)?)
    }
}

fn batch(runner: &dyn TrialRunner, plan: &BatchPlan) -> BatchResult {
    let exec = Execution {
        jobs: None,
        progress: &ftcbf_lab::progress::Silent,
    };
    run_batch(runner, plan, exec).expect("the batch runs")
}

#[test]
fn a_batch_computes_its_worlds_setup_once() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("worlds/paper_linear.toml");
    let world = World::load(&path, &[]).expect("world loads");
    let controllers = CONTROLLERS.iter().map(|c| c.to_string()).collect();
    let plan = plan_for(&world, &path, TRIALS, controllers);

    let before = setups_computed();
    let prepared = prepare_batch(&path)(&[]).expect("prepared");
    let compiled = batch(prepared.runner.as_ref(), &plan);
    assert_eq!(
        setups_computed() - before,
        1,
        "one setup for {TRIALS} trials × {} controllers (and the check line)",
        CONTROLLERS.len()
    );

    let before = setups_computed();
    let per_trial = batch(&PerTrial(world), &plan);
    assert_eq!(
        setups_computed() - before,
        TRIALS * CONTROLLERS.len() as u64,
        "the per-trial runner computes one setup per trial"
    );

    // As JSON: a record's NaN fields are written as text, so equal text is equal bits.
    let json = |r: &BatchResult| serde_json::to_string(r).expect("serialises");
    assert_eq!(compiled.records.len(), per_trial.records.len());
    for (a, b) in compiled.records.iter().zip(&per_trial.records) {
        assert_eq!(
            serde_json::to_string(a).expect("serialises"),
            serde_json::to_string(b).expect("serialises"),
            "trial {} with {}",
            a.trial,
            a.controller
        );
    }
    assert_eq!(json(&compiled), json(&per_trial));
}
