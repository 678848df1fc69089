//! `Simulation` stepped by hand: the same numbers as `run`, the frames in order, a user-written
//! `ControlLaw` driven through the same loop, and typed errors when a law cannot be built.

use std::path::PathBuf;

use ftcbf_sim::ftcbf_controller::{ControlLaw, Decision, Input, Readings};
use ftcbf_sim::runner::{run, RunError, RunOptions, Simulation};
use ftcbf_sim::world::World;

fn world(name: &str) -> World {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("worlds")
        .join(name);
    World::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"))
}

/// Holds a constant input and counts what it was given.
struct Hold {
    u: Input,
    steps: u64,
}

impl ControlLaw for Hold {
    fn name(&self) -> &str {
        "hold"
    }
    fn step(&mut self, r: &Readings<'_>) -> Decision<'_> {
        self.steps += 1;
        assert_eq!(r.y.len(), r.fresh.len());
        Decision {
            u: self.u,
            record: None,
        }
    }
}

#[test]
fn stepping_by_hand_gives_the_summary_of_run() {
    for name in ["paper_turtlebot.toml", "corridor_spoof.toml"] {
        let w = world(name);
        let opts = RunOptions::default();
        let mut sim = Simulation::new(&w, &opts).expect("starts");
        let (done, total) = sim.progress();
        assert_eq!(done, 0);
        let mut k = 0;
        while let Some(frame) = sim.step() {
            assert_eq!(frame.step, k, "{name}: frames in order");
            assert!(frame.t >= 0.0 && frame.truth.x.is_finite());
            assert!(!frame.decided_by.is_empty());
            k += 1;
        }
        assert_eq!(k, total, "{name}: one frame per control step");
        assert!(sim.step().is_none(), "{name}: no step after the end");
        assert_eq!(sim.summary(), run(&w, &opts).expect("runs"), "{name}");
    }
}

#[test]
fn a_user_law_is_driven_and_named_in_the_summary() {
    let w = world("paper_linear.toml");
    let u = Input::new(0.05, -0.02);
    let make =
        |_: &_| -> Result<Box<dyn ControlLaw>, String> { Ok(Box::new(Hold { u, steps: 0 })) };
    let mut sim = Simulation::with_law(&w, &RunOptions::default(), make).expect("starts");
    let q = sim.setup().sensor_of_channel.len();
    assert!(q > 0);
    while let Some(frame) = sim.step() {
        assert_eq!(frame.u, [u[0], u[1]], "the frame shows the law's input");
        assert_eq!(frame.decided_by, "hold");
        assert!(frame.estimates.is_empty() && frame.barrier_values.is_empty());
    }
    let s = sim.summary();
    assert_eq!(s.controller, "hold");
    assert_eq!(s.control_steps, sim.progress().1);
    let counted = s.steps.step1 + s.steps.clf_relaxed + s.steps.step2 + s.steps.step3;
    assert_eq!(
        counted + s.steps.infeasible,
        0,
        "no policy record, no stage counts"
    );
    // Same world, seed and law: the same summary, bit for bit.
    let mut again = Simulation::with_law(&w, &RunOptions::default(), make).expect("starts");
    again.run_to_end();
    assert_eq!(again.summary(), s);
    // A constant push moves the plant away from where the FT-CBF-CLF run ends.
    assert_ne!(
        s.final_state,
        run(&w, &RunOptions::default()).unwrap().final_state
    );
}

#[test]
fn a_law_that_cannot_be_built_is_a_typed_error() {
    let w = world("paper_linear.toml");
    let err = Simulation::with_law(&w, &RunOptions::default(), |_| {
        Err("gain matrix is not positive definite".to_string())
    })
    .err()
    .expect("refused");
    match err {
        RunError::Start { what, message, .. } => {
            assert_eq!(what, "controller");
            assert!(message.contains("positive definite"), "{message}");
        }
        other => panic!("unexpected error {other}"),
    }
    let bad = RunOptions {
        duration: Some(f64::NAN),
        ..RunOptions::default()
    };
    assert!(matches!(
        Simulation::new(&w, &bad).err(),
        Some(RunError::Option(_))
    ));
}

/// Issue #30: γ, θ and η are computed for the world's duration (a union bound over its
/// samples); a run past it is refused with the way to extend the horizon, not run past it.
#[test]
fn a_run_past_the_horizon_of_gamma_theta_eta_is_refused() {
    let w = World::load(&PathBuf::from("worlds/corridor_spoof.toml"), &[]).expect("world");
    let longer = RunOptions {
        duration: Some(w.file.duration + 1.0),
        ..RunOptions::default()
    };
    match Simulation::new(&w, &longer).err() {
        Some(RunError::Option(m)) => {
            assert!(m.contains("past the world's duration (25 s)"), "{m}");
            assert!(m.contains("--set duration=26"), "{m}");
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    let shorter = RunOptions {
        duration: Some(w.file.duration - 1.0),
        ..RunOptions::default()
    };
    assert!(Simulation::new(&w, &shorter).is_ok());
}
