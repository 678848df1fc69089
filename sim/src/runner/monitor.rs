//! What a run measures on the truth: barrier minima, the first safe-set violation, contacts,
//! clearances and the goal. Fed after every plant tick and once per control step.

use std::sync::Arc;

use ftcbf_controller::lyapunov::QuadraticClf;
use ftcbf_controller::{Barrier, State};

use crate::obstacles::ObstacleBarrier;
use crate::state::TruthState;
use crate::summary::{
    disagree, CollisionCounts, CollisionEvent, Disagreement, NamedValue, ViolationEvent,
    STOPPED_SPEED,
};
use crate::world::{GoalMetric, World};
use ftcbf_controller::MoverState;

use crate::model::setup::ControlSetup;
use crate::movers::fleet::MoverSet;
use crate::observe::{Contact, ContactCause};
use crate::plant::Plant;

/// Safety and goal bookkeeping of one run.
pub(super) struct Monitor {
    barriers: Vec<Arc<dyn Barrier>>,
    names: Vec<String>,
    /// The first `safe_sets` barriers are closed-form safe sets (checked every tick).
    safe_sets: usize,
    min_barrier: Vec<f64>,
    in_contact: Vec<bool>,
    clearances: Vec<f64>,
    /// Which of `clearances` are exact (the others are lower bounds above the disagreement
    /// tolerance and above the least clearance: far obstacles are not queried).
    clearance_exact: Vec<bool>,
    pub(super) min_clearance: Option<f64>,
    /// Each obstacle's barrier geometry (distance without margin or lift), to hold the
    /// physics' clearances against.
    geometry: Vec<ObstacleBarrier>,
    /// Each obstacle's bounding box (world frame).
    regions: Vec<parry3d::bounding_volume::Aabb>,
    /// The obstacles' index when the controller has one (issue #52): a barrier whose certified
    /// lower bound on the truth is at or above its least value so far is not evaluated.
    index: Option<crate::active::ObstacleIndex>,
    /// The first instant the barrier geometry and the physics disagreed (see
    /// [`crate::summary::disagree`]).
    pub(super) disagreement: Option<Disagreement>,
    pub(super) first_collision: Option<CollisionEvent>,
    pub(super) first_violation: Option<ViolationEvent>,
    /// The first non-finite quantity seen during the run (a barrier value, the true state, a
    /// clearance) and when: the run fails closed on it.
    pub(super) non_finite: Option<String>,
    pub(super) time_to_goal: Option<f64>,
    /// Time of the last plant tick outside the goal set.
    pub(super) last_outside_goal: Option<f64>,
    /// The CLF, for V(x_true) at the end.
    clf: Option<QuadraticClf>,
    /// Per obstacle: its mover number and whether it is a walker (None: it stands still).
    mover_of: Vec<Option<(usize, bool)>>,
    /// Contacts that began, by who moved.
    pub(super) collisions: CollisionCounts,
}

impl Monitor {
    pub(super) fn new(world: &World, setup: &ControlSetup, movers: &MoverSet) -> Self {
        let barriers = setup.config.barriers.clone();
        let mut mover_of = vec![None; world.obstacles.len()];
        for (k, &i) in movers.obstacles().iter().enumerate() {
            mover_of[i] = Some((k, movers.is_walker(k)));
        }
        Self {
            mover_of,
            collisions: CollisionCounts::default(),
            min_barrier: vec![f64::INFINITY; barriers.len()],
            barriers,
            names: setup.barrier_names.clone(),
            safe_sets: setup.safe_sets,
            in_contact: vec![false; world.obstacles.len()],
            clearances: Vec::new(),
            clearance_exact: Vec::new(),
            min_clearance: None,
            geometry: {
                let bcfg = crate::world::structure::obstacle_barrier_config(world);
                world.obstacles.iter().map(|o| o.barrier(&bcfg)).collect()
            },
            regions: world
                .obstacles
                .iter()
                .map(|o| o.shape().compute_aabb(o.shape_pose()))
                .collect(),
            index: setup.config.barrier_index.as_ref().map(|_| {
                let bcfg = crate::world::structure::obstacle_barrier_config(world);
                let n = setup.config.barriers.len();
                crate::active::ObstacleIndex::new(&world.obstacles, setup.safe_sets, n, &bcfg)
            }),
            disagreement: None,
            first_collision: None,
            first_violation: None,
            non_finite: None,
            time_to_goal: None,
            last_outside_goal: None,
            clf: QuadraticClf::new(
                &setup.config.model.f,
                &setup.config.model.g,
                setup.config.goal,
                world.file.goal.radius,
                &setup.config.clf,
            )
            .ok(),
        }
    }

    /// Settled in the goal at time `t_end` (inside it at every tick of the last
    /// [`crate::summary::SETTLE_WINDOW`] seconds), the distance to the goal in its metric, and
    /// V(x) at `x`.
    pub(super) fn goal_outcome(&self, world: &World, t: &TruthState) -> (bool, f64, Option<f64>) {
        let window_start = t.t - crate::summary::SETTLE_WINDOW;
        let settled = self.time_to_goal.is_some()
            && in_goal(world, t)
            && self.last_outside_goal.is_none_or(|lo| lo < window_start);
        let x = State::new(t.x, t.y, t.vx, t.vy);
        (
            settled,
            goal_distance(world, t),
            self.clf.as_ref().map(|c| c.value(&x)),
        )
    }

    /// After one plant tick: safe sets on the truth, contacts (with an event when one starts),
    /// the goal.
    pub(super) fn after_tick(
        &mut self,
        plant: &Plant,
        world: &World,
        movers: &[MoverState],
        view: &mut super::view::StepView,
    ) {
        let events = &mut view.events;
        let tt = plant.truth();
        let x = tt.planar();
        if self.non_finite.is_none() && !x.iter().all(|v| v.is_finite()) {
            self.non_finite = Some(format!(
                "true state ({}, {}, {}, {}) at t = {:.3} s",
                x[0], x[1], x[2], x[3], tt.t
            ));
        }
        for (j, b) in self.barriers.iter().enumerate().take(self.safe_sets) {
            let h = b.eval(&x).value;
            note_non_finite(&mut self.non_finite, &self.names[j], h, tt.t);
            if h < self.min_barrier[j] {
                self.min_barrier[j] = h;
            }
            if h < 0.0 && self.first_violation.is_none() {
                let set = &self.names[j];
                self.first_violation = Some(ViolationEvent {
                    t: tt.t,
                    set: set.clone(),
                    value: h,
                });
                events.push(format!(
                    "safety violation: left {set} at t = {:.3} s (h = {h:.4})",
                    tt.t
                ));
            }
        }
        for (oi, touching) in self.in_contact.iter_mut().enumerate() {
            let now = plant.in_contact(oi);
            if now && !*touching {
                let c = &mut self.collisions;
                // The robot's speed towards the mover's centre (its own speed when the mover's
                // state is not at hand).
                let speed = match self.mover_of[oi].and_then(|(k, _)| movers.get(k)) {
                    Some(m) => {
                        let p = &world.obstacles[oi].spec.position;
                        let d = [
                            p[0] + m.displacement[0] - tt.x,
                            p[1] + m.displacement[1] - tt.y,
                        ];
                        let n = d[0].hypot(d[1]);
                        if n > 0.0 {
                            (tt.vx * d[0] + tt.vy * d[1]) / n
                        } else {
                            tt.vx.hypot(tt.vy)
                        }
                    }
                    None => tt.vx.hypot(tt.vy),
                };
                let cause = match self.mover_of[oi] {
                    None => ContactCause::Static,
                    Some(_) if speed >= STOPPED_SPEED => ContactCause::RobotMoving,
                    Some((_, walker)) => ContactCause::MoverIntoStopped { walker },
                };
                match cause {
                    ContactCause::Static => c.static_obstacles += 1,
                    ContactCause::RobotMoving => c.mover_robot_moving += 1,
                    ContactCause::MoverIntoStopped { walker } => {
                        c.mover_robot_stopped += 1;
                        c.walker_robot_stopped += u64::from(walker);
                    }
                }
                let name = world.obstacles[oi].name.clone();
                events.push(match cause {
                    ContactCause::Static => format!("collision with {name} at t = {:.3} s", tt.t),
                    ContactCause::RobotMoving => format!(
                        "collision with {name} at t = {:.3} s: the robot moved into the mover ({speed:.3} m/s towards it): the robot's",
                        tt.t
                    ),
                    ContactCause::MoverIntoStopped { .. } => format!(
                        "collision with {name} at t = {:.3} s: the mover walked into the stopped robot (robot {speed:.3} m/s towards it): the mover's, outside the guarantee",
                        tt.t
                    ),
                });
                view.contacts.push(Contact {
                    obstacle: name.clone(),
                    t: tt.t,
                    at: [tt.x, tt.y],
                    cause,
                });
                if self.first_collision.is_none() {
                    self.first_collision = Some(CollisionEvent {
                        t: tt.t,
                        obstacle: name,
                    });
                }
            }
            *touching = now;
        }
        if in_goal(world, &tt) {
            if self.time_to_goal.is_none() {
                self.time_to_goal = Some(tt.t);
            }
        } else {
            self.last_outside_goal = Some(tt.t);
        }
    }

    /// After the control step's last tick: obstacle barriers and clearances on the truth, and
    /// h(x_true) of every barrier into `barrier_truth` (NaN for a far obstacle whose certified
    /// lower bound, [`crate::active`], is at or above its least value so far: its minimum
    /// cannot change, so it is not evaluated and not logged); `movers` are the moving
    /// obstacles' states at that instant (their barriers are never covered by the index).
    pub(super) fn after_step(
        &mut self,
        plant: &Plant,
        world: &World,
        movers: &[MoverState],
        barrier_truth: &mut [f64],
    ) {
        use ftcbf_controller::reach::BarrierIndex;
        let truth = plant.truth();
        let x = truth.planar();
        let speed = x[2].hypot(x[3]);
        for (j, b) in self.barriers.iter().enumerate() {
            if let Some(ix) = &self.index {
                let lower = ix
                    .distance(j, [x[0], x[1]])
                    .map(|d| ix.far_bounds(d, speed).h_lower);
                // NaN (a non-finite state) compares false: evaluated.
                if lower.is_some_and(|l| l >= self.min_barrier[j]) {
                    barrier_truth[j] = f64::NAN;
                    continue;
                }
            }
            let h = b.eval_moving(&x, movers).0.value;
            barrier_truth[j] = h;
            note_non_finite(&mut self.non_finite, &self.names[j], h, truth.t);
            if j >= self.safe_sets {
                self.min_barrier[j] = self.min_barrier[j].min(h);
            }
        }
        if !world.obstacles.is_empty() {
            // Exact where the disagreement rule can fire (|c| ≤ its tolerance) and at the
            // minimum; a far obstacle's lower bound decides the rule just as its true value
            // would (both exceed the tolerance).
            plant.clearances_near(
                crate::summary::DISAGREEMENT_TOLERANCE,
                &mut self.clearances,
                &mut self.clearance_exact,
            );
            let m = self
                .clearances
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min);
            if self.non_finite.is_none() {
                if let Some(c) = self.clearances.iter().find(|c| !c.is_finite()) {
                    self.non_finite = Some(format!("clearance {c} at t = {:.3} s", truth.t));
                }
            }
            self.min_clearance = Some(self.min_clearance.map_or(m, |c: f64| c.min(m)));
            self.hold_against_physics(world, plant, [x[0], x[1]], movers, truth.t);
        }
    }

    /// Holds each obstacle's barrier geometry at position `p` against the physics' clearance
    /// just measured; keeps the first disagreement.
    fn hold_against_physics(
        &mut self,
        world: &World,
        plant: &Plant,
        p: [f64; 2],
        movers: &[MoverState],
        t: f64,
    ) {
        if self.disagreement.is_some() {
            return;
        }
        let mover_of = &self.mover_of;
        // A moving obstacle's geometry is that of its start: the robot's position relative to it.
        let at_for = |i: usize| match mover_of[i].and_then(|(k, _)| movers.get(k)) {
            Some(m) => nalgebra::Vector2::new(p[0] - m.displacement[0], p[1] - m.displacement[1]),
            None => nalgebra::Vector2::new(p[0], p[1]),
        };
        self.disagreement = self
            .geometry
            .iter()
            .zip(&self.clearances)
            .zip(&world.obstacles)
            .zip(&self.clearance_exact)
            .enumerate()
            .find_map(|(i, (((g, &c), o), &exact))| {
                let at = at_for(i);
                // A far obstacle (its physics clearance a lower bound above the tolerance) with
                // p outside its box (a mover's box at its start, so p relative to it): sd > 0
                // and c > tol, so neither clause of `disagree` can hold; its geometry is not
                // queried (issue #52).
                if !exact && outside(&self.regions[i], [at.x, at.y]) {
                    return None;
                }
                let d = g.clearance(at);
                let centre = d + g.config().robot_radius;
                disagree(centre, d, c).then(|| Disagreement {
                    t,
                    obstacle: o.name.clone(),
                    centre_distance: centre,
                    barrier_clearance: d,
                    physics_clearance: if exact { c } else { plant.clearance(i) },
                })
            });
    }

    /// Number of barriers (safe sets, then obstacles).
    pub(super) fn barriers(&self) -> usize {
        self.barriers.len()
    }

    /// The smallest h(x_true) so far, per barrier.
    pub(super) fn min_barrier(&self) -> Vec<NamedValue> {
        self.names
            .iter()
            .zip(&self.min_barrier)
            .map(|(name, &value)| NamedValue {
                name: name.clone(),
                value,
            })
            .collect()
    }
}

/// Whether the planar point `p` is outside the xy extent of `b` (by more than f32 rounding).
fn outside(b: &parry3d::bounding_volume::Aabb, p: [f64; 2]) -> bool {
    let pad = crate::active::REGION_PAD;
    p[0] < b.mins.x as f64 - pad
        || p[0] > b.maxs.x as f64 + pad
        || p[1] < b.mins.y as f64 - pad
        || p[1] > b.maxs.y as f64 + pad
}

fn goal_distance(world: &World, t: &TruthState) -> f64 {
    let goal = &world.file.goal;
    let [gx, gy] = goal.center;
    match goal.metric {
        GoalMetric::Position => (t.x - gx).hypot(t.y - gy),
        GoalMetric::State => {
            let d = [t.x - gx, t.y - gy, t.vx, t.vy];
            d.iter().map(|v| v * v).sum::<f64>().sqrt()
        }
    }
}

fn in_goal(world: &World, t: &TruthState) -> bool {
    goal_distance(world, t) <= world.file.goal.radius
}

/// Records the first non-finite barrier value (NaN never lowers a minimum, so it would
/// otherwise pass unseen).
fn note_non_finite(slot: &mut Option<String>, name: &str, h: f64, t: f64) {
    if slot.is_none() && !h.is_finite() {
        *slot = Some(format!("h({name}) = {h} at t = {t:.3} s"));
    }
}
