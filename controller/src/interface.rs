//! The interface between a simulator (or a robot) and a control law: readings in, an input and a
//! decision record out, once per control step.
//!
//! [`ControlLaw`] is what `ftcbf_sim::runner::Simulation` drives. The FT-CBF-CLF controller, the
//! single-filter baseline and the nominal CLF controller are all [`Controller`] (different
//! [`crate::ControllerKind`]s) and implement it below; a user-written law implements it too and
//! runs through the same simulation, summary and Monte Carlo batch (see the workspace's
//! `examples/custom_controller.rs`).

use crate::controller::{ControlOutput, Controller, ControllerKind};
use crate::estimator::EstimatorBank;
use crate::types::Input;

/// The readings of one control step, as the controller receives them (after any attack).
#[derive(Debug, Clone, Copy)]
pub struct Readings<'a> {
    /// Time at the start of the step \[s\].
    pub t: f64,
    /// Control period: time since the previous step \[s\].
    pub dt: f64,
    /// One value per channel of the linear model (the rows of C, in order) [m or m/s]. May be
    /// NaN, ±∞ or absurd under attack: a law must survive that.
    pub y: &'a [f64],
    /// Per channel: a new sample arrived this step (stale values must not be used as new).
    pub fresh: &'a [bool],
    /// The world-frame acceleration [m/s²] the drive actually realised over the period now
    /// ending, when the platform knows it (a differential drive: from the body commands it sent
    /// after its limits, [`crate::drive::realized_acceleration`]); `None` when the input asked for
    /// was realised as asked (the linear plant).
    pub applied: Option<Input>,
    /// The moving obstacles' states at `t` (issue #51), in the order the barriers'
    /// [`crate::Barrier::mover`] index; empty in a world where nothing moves.
    pub movers: &'a [crate::barrier::MoverState],
}

/// What a law decided at one step.
#[derive(Debug, Clone, Copy)]
pub struct Decision<'a> {
    /// The input u = (a_x, a_y) to apply, planar acceleration in the world frame [m/s²].
    pub u: Input,
    /// The full record of the CBF-CLF policy (stage, dropped constraints, rejected readings,
    /// h(x̂), V(x̂)); `None` for a law that has no such record.
    pub record: Option<&'a ControlOutput>,
}

/// A control law stepped once per control period.
pub trait ControlLaw: Send {
    /// Name written to summaries and logs (`ft-cbf-clf`, `baseline`, `nominal`, or the user's).
    fn name(&self) -> &str;

    /// One control step: consume `readings`, return the input to hold until the next step.
    fn step(&mut self, readings: &Readings<'_>) -> Decision<'_>;

    /// The law's estimator bank, if it keeps one. The simulator shows its estimates to observers
    /// and gives a stealthy attacker its all-channel filter's detector view.
    fn estimators(&self) -> Option<&EstimatorBank> {
        None
    }
}

impl ControlLaw for Controller {
    fn name(&self) -> &str {
        match self.kind() {
            ControllerKind::FtCbfClf => "ft-cbf-clf",
            ControllerKind::Baseline => "baseline",
            ControllerKind::Nominal => "nominal",
        }
    }

    fn step(&mut self, readings: &Readings<'_>) -> Decision<'_> {
        if let Some(a) = readings.applied {
            self.set_applied_input(a);
        }
        self.set_movers(readings.movers);
        let out = Controller::step(self, readings.y, readings.fresh, readings.dt);
        Decision {
            u: out.u,
            record: Some(out),
        }
    }

    fn estimators(&self) -> Option<&EstimatorBank> {
        Some(self.bank())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A law that holds a constant input, counting its steps and fresh readings.
    struct Constant {
        u: Input,
        steps: usize,
        fresh_seen: usize,
    }

    impl ControlLaw for Constant {
        fn name(&self) -> &str {
            "constant"
        }
        fn step(&mut self, r: &Readings<'_>) -> Decision<'_> {
            self.steps += 1;
            self.fresh_seen += r.fresh.iter().filter(|f| **f).count();
            Decision {
                u: self.u,
                record: None,
            }
        }
    }

    #[test]
    fn a_user_law_is_driven_through_the_trait() {
        let mut c = Constant {
            u: Input::new(0.5, -0.25),
            steps: 0,
            fresh_seen: 0,
        };
        let law: &mut dyn ControlLaw = &mut c;
        let y = [1.0, f64::NAN];
        let fresh = [true, false];
        for k in 0..3 {
            let r = Readings {
                t: k as f64 * 0.02,
                dt: 0.02,
                y: &y,
                fresh: &fresh,
                applied: None,
                movers: &[],
            };
            let d = law.step(&r);
            assert_eq!(d.u, Input::new(0.5, -0.25));
            assert!(d.record.is_none());
        }
        assert_eq!(law.name(), "constant");
        assert!(law.estimators().is_none());
        assert_eq!((c.steps, c.fresh_seen), (3, 3));
    }
}
