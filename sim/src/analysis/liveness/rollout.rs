//! Liveness with movers, decided by the closed loop itself (issue #51).
//!
//! The search past the movers ([`crate::movers::passage`]) explains what a mover does to the
//! robot (waits, a mover that parks across the path), but it plays the robot along a band of its
//! path and the walkers by a model of their social force: over the 442 generated worlds with
//! movers of seeds 51–58 it found no way past a mover in 39 worlds where 19 or 20 of 20 trials
//! got past, and said "live" in 7 where fewer did. What the robot, the walkers and the
//! controller do together is what a run does, so where movers are and the rows leave the path
//! live without them, `ftcbf check` runs the closed loop [`ROLLOUTS`] times and the liveness
//! verdict is theirs: live when every run settles in its goal. This module holds what the runs
//! found and how the verdict reads it; the runs themselves are `ftcbf_lab::trials::roll_out`'s
//! (`analysis` does not run the simulator).
//!
//! The runs are seeded apart from `ftcbf batch`'s trials: run k has `ftcbf batch`'s trial seed
//! `trial_seed(S ⊕` [`ROLLOUT_SALT`]`, k)`, S the world's seed, so `ftcbf batch WORLD
//! --controller KIND --seed (S ⊕ ROLLOUT_SALT) --trials N` (the world's own controller)
//! replays them, and a batch of the world measures trials `check` has not seen.

use super::LivenessReport;
use crate::world::World;

/// How many runs decide a world with movers. At 6, a world where each run settles with
/// probability 0.95 is called live 74 % of the time, one at 0.8 26 %, one at 0.6 5 %.
pub const ROLLOUTS: usize = 6;

/// XORed into the world's seed for the rollouts' base seed (the bytes of "check"), so that
/// they are not `ftcbf batch`'s trials.
pub const ROLLOUT_SALT: u64 = 0x63_68_65_63_6B;

/// What the rollouts found.
#[derive(Debug, Clone, PartialEq)]
pub struct Rollouts {
    /// The world file they ran (for the commands that replay them).
    pub world: String,
    /// The world's controller (`ft-cbf-clf`, `baseline`).
    pub controller: &'static str,
    /// The base seed of the runs (run k: `ftcbf batch`'s trial seed k from it).
    pub base_seed: u64,
    /// How many ran.
    pub runs: usize,
    /// How many settled in the goal over the run's last [`crate::summary::SETTLE_WINDOW`].
    pub settled: usize,
    /// The first run (by k) that did not settle: its seed and its final distance to the goal
    /// \[m\].
    pub first_miss: Option<(u64, f64)>,
    /// Why the runs could not start (the verdict is then the search's).
    pub error: Option<String>,
}

impl Rollouts {
    /// Every run settled (and they ran).
    pub fn all_settled(&self) -> bool {
        self.error.is_none() && self.runs > 0 && self.settled == self.runs
    }

    /// The rollouts in one phrase.
    pub fn text(&self) -> String {
        if let Some(e) = &self.error {
            return format!("the closed loop could not be rolled out ({e})");
        }
        let mut s = format!(
            "{} of {} runs of the closed loop settled in the goal (`ftcbf batch {} --controller {} --seed {} --trials {}` replays them)",
            self.settled, self.runs, self.world, self.controller, self.base_seed, self.runs
        );
        if let Some((seed, d)) = self.first_miss {
            s.push_str(&format!(
                "; the first that did not ended {d:.3} m from the goal's centre (`ftcbf run {} --seed {seed}`)",
                self.world
            ));
        }
        s
    }
}

/// Whether `check` rolls `world` out: it has a moving obstacle, its controller imposes rows,
/// and the rows leave the path live and the goal held in every case without the movers.
pub fn applies(world: &World, report: &LivenessReport) -> bool {
    report.skipped.is_none()
        && report.cases.iter().all(super::LivenessCase::live)
        && world.has_movers()
}
