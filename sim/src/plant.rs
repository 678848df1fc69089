//! The plant the controller drives: the robot in rapier (through the compensator and the wheel
//! motors), or the paper's linearised model integrated directly.

use ftcbf_controller::model::LinearModel;
use ftcbf_controller::{Input, State, StateMatrix};
use nalgebra::Vector2;
use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;

use crate::drivetrain::{Drive, DriveConfig};
use crate::obstacles::{Obstacle, ObstacleBarrier};
use crate::physics::{PhysicsConfig, PhysicsWorld, Pose2};
use crate::robot::WheelGeometry;
use crate::sensors::stream_rng;
use crate::state::TruthState;
use crate::world::{Dynamics, World};

use crate::world::structure::obstacle_barrier_config;

/// The simulated plant.
#[allow(clippy::large_enum_variant)]
pub enum Plant {
    /// The robot from URDF in rapier3d.
    Rapier {
        /// Physics.
        physics: PhysicsWorld,
        /// Compensator (6.3)-(6.4) and wheel kinematics.
        drive: Drive,
        /// Obstacles in contact after the last tick.
        contact: Vec<bool>,
    },
    /// Eq. 6.2 with Euler–Maruyama.
    Linear {
        /// The model (F, G, σ).
        model: LinearModel,
        /// True state.
        x: State,
        /// Input held over the control period.
        u: Input,
        /// Time \[s\].
        t: f64,
        /// Integration step \[s\].
        dt: f64,
        /// Process-noise stream.
        rng: ChaCha20Rng,
        /// Obstacles, as distance queries for a point robot.
        obstacles: Vec<ObstacleBarrier>,
    },
}

/// The physics settings of `world`'s rapier plant: its `[physics]` step and friction, the
/// rest at their defaults. The drive's identification runs with them and keys its cache on them.
pub fn physics_config(world: &World) -> PhysicsConfig {
    PhysicsConfig {
        dt: world.file.physics.dt,
        friction: world.file.physics.friction,
        ..PhysicsConfig::default()
    }
}

impl Plant {
    /// Builds the plant of `world`.
    pub fn new(world: &World, seed: u64) -> Result<Self, String> {
        match world.file.dynamics {
            Dynamics::Rapier => {
                let start = world
                    .file
                    .robot
                    .as_ref()
                    .map(|r| r.start)
                    .unwrap_or_default();
                let start = Pose2 {
                    x: start.x,
                    y: start.y,
                    theta: start.theta,
                };
                Self::robot(world, start, &world.obstacles)
            }
            Dynamics::Linear => {
                let lin = world
                    .file
                    .linear
                    .as_ref()
                    .ok_or_else(|| "linear dynamics without [linear]".to_string())?;
                let model = LinearModel::new(
                    LinearModel::double_integrator_f(),
                    LinearModel::double_integrator_g(),
                    LinearModel::paper_observation(),
                    StateMatrix::identity() * lin.process_noise,
                    vec![1.0; 6],
                )
                .map_err(|e| e.to_string())?;
                let bcfg = obstacle_barrier_config(world);
                Ok(Plant::Linear {
                    model,
                    x: State::new(lin.x0[0], lin.x0[1], lin.x0[2], lin.x0[3]),
                    u: Input::zeros(),
                    t: 0.0,
                    dt: lin.dt,
                    // Its own stream, independent of every sensor stream.
                    rng: stream_rng(seed, "plant", "process_noise"),
                    obstacles: world.obstacles.iter().map(|o| o.barrier(&bcfg)).collect(),
                })
            }
        }
    }

    /// The world's robot in rapier at `start` among `obstacles`, with its drive (the
    /// identification of the drive runs it alone, with no obstacle).
    pub fn robot(world: &World, start: Pose2, obstacles: &[Obstacle]) -> Result<Self, String> {
        let robot = world
            .robot
            .as_ref()
            .ok_or_else(|| "rapier dynamics without a robot".to_string())?;
        let physics = PhysicsWorld::new(robot, start, obstacles, &physics_config(world))
            .map_err(|e| e.to_string())?;
        let drive = Drive::new(
            &robot.wheels.geometry,
            &robot.limits,
            drive_config(world, &robot.limits),
        )
        .map_err(|e| e.to_string())?;
        Ok(Plant::Rapier {
            physics,
            drive,
            contact: vec![false; obstacles.len()],
        })
    }

    /// The drive's wheel geometry (None for the linear plant, which has no wheels).
    pub fn wheel_geometry(&self) -> Option<WheelGeometry> {
        match self {
            Plant::Rapier { drive, .. } => Some(*drive.geometry()),
            Plant::Linear { .. } => None,
        }
    }

    /// The true state now.
    pub fn truth(&self) -> TruthState {
        match self {
            Plant::Rapier { physics, .. } => physics.truth(),
            Plant::Linear { x, t, .. } => {
                let speed = x[2].hypot(x[3]);
                TruthState {
                    t: *t,
                    x: x[0],
                    y: x[1],
                    theta: if speed > 1e-12 { x[3].atan2(x[2]) } else { 0.0 },
                    vx: x[2],
                    vy: x[3],
                    v_body: speed,
                    omega: 0.0,
                    wheel_left: f64::NAN,
                    wheel_right: f64::NAN,
                    wheel_angle_left: f64::NAN,
                    wheel_angle_right: f64::NAN,
                }
            }
        }
    }

    /// Holds the controller's input `u` for the coming control period. For the robot, the
    /// compensator, corrected to the wheel encoders' speed, turns it into (v, ω) about the
    /// measured `heading`, then into wheel speeds. Returns the body command (v, ω) the wheels
    /// follow after saturation (zero for the linear plant).
    pub fn apply_input(&mut self, u: &Input, heading: f64, control_dt: f64) -> [f64; 2] {
        match self {
            Plant::Rapier { physics, drive, .. } => {
                // The wheel encoders' forward speed closes the loop of (6.3) (see crate::drivetrain).
                let (wl, wr) = physics.wheel_speeds();
                let measured = drive.body_from_wheels(wl, wr).v;
                let (sent, (l, r)) = drive.step(*u, heading, control_dt, Some(measured), false);
                physics.set_wheel_speeds(l, r);
                [sent.v, sent.omega]
            }
            Plant::Linear { u: held, .. } => {
                *held = *u;
                [0.0, 0.0]
            }
        }
    }

    /// The forward speed the wheel encoders measure [m/s] (None for the linear plant).
    pub fn encoder_speed(&self) -> Option<f64> {
        match self {
            Plant::Rapier { physics, drive, .. } => {
                let (wl, wr) = physics.wheel_speeds();
                Some(drive.body_from_wheels(wl, wr).v)
            }
            Plant::Linear { .. } => None,
        }
    }

    /// One plant step.
    pub fn tick(&mut self) {
        match self {
            Plant::Rapier {
                physics, contact, ..
            } => {
                physics.step();
                contact.iter_mut().for_each(|c| *c = false);
                for i in physics.contacts() {
                    if let Some(c) = contact.get_mut(i) {
                        *c = true;
                    }
                }
            }
            Plant::Linear {
                model,
                x,
                u,
                t,
                dt,
                rng,
                ..
            } => {
                let w = State::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal));
                *x = model.euler_maruyama_step(x, u, *dt, &w);
                *t += *dt;
            }
        }
    }

    /// Whether the robot touches obstacle `i` after the last step.
    pub fn in_contact(&self, i: usize) -> bool {
        match self {
            Plant::Rapier { contact, .. } => contact.get(i).copied().unwrap_or(false),
            Plant::Linear { x, obstacles, .. } => obstacles
                .get(i)
                .is_some_and(|o| o.clearance(Vector2::new(x[0], x[1])) < 0.0),
        }
    }

    /// True clearance to each obstacle \[m\].
    pub fn clearances(&self, out: &mut Vec<f64>) {
        match self {
            Plant::Rapier { physics, .. } => physics.clearances(out),
            Plant::Linear { x, obstacles, .. } => {
                out.clear();
                out.extend(
                    obstacles
                        .iter()
                        .map(|o| o.clearance(Vector2::new(x[0], x[1]))),
                );
            }
        }
    }

    /// The clearances where they can matter (see [`crate::physics::PhysicsWorld::clearances_near`]):
    /// exact at or below `within` and at the minimum, a lower bound elsewhere (`exact[i]`
    /// false). The linear plant's are all exact.
    pub fn clearances_near(&self, within: f64, out: &mut Vec<f64>, exact: &mut Vec<bool>) {
        match self {
            Plant::Rapier { physics, .. } => physics.clearances_near(within, out, exact),
            Plant::Linear { .. } => {
                self.clearances(out);
                exact.clear();
                exact.resize(out.len(), true);
            }
        }
    }

    /// The exact clearance to obstacle `i` \[m\] (+∞ for an index out of range).
    pub fn clearance(&self, i: usize) -> f64 {
        match self {
            Plant::Rapier { physics, .. } => physics.clearance(i),
            Plant::Linear { x, obstacles, .. } => obstacles
                .get(i)
                .map_or(f64::INFINITY, |o| o.clearance(Vector2::new(x[0], x[1]))),
        }
    }

    /// World poses of the robot's bodies (empty for the linear plant, which is drawn as a point).
    pub fn link_poses(&self, out: &mut Vec<(String, [f32; 3], [f32; 4])>) {
        out.clear();
        if let Plant::Rapier { physics, .. } = self {
            out.extend(physics.link_poses().map(|(n, p, q)| (n.to_string(), p, q)));
        }
    }
}

/// The compensator settings of `[control.drive]`, with the defaults of the world's form: the
/// paper form keeps the thesis' (6.3)–(6.4) (floor law, no rate limits); the safety-filter form
/// gets the regularised law, v's rate limited to the input box and ω's to ω_max per second —
/// the settings every catalogue robot world was measured with, taken from the robot's limits.
pub(crate) fn drive_config(world: &World, limits: &crate::robot::DriveLimits) -> DriveConfig {
    use crate::world::{FormSpec, LowSpeedSpec};
    let c = &world.file.control;
    let d = &c.drive;
    let base = DriveConfig::default();
    let smooth = c.form == FormSpec::SafetyFilter;
    let scale = d.low_speed_scale.unwrap_or(base.v_floor);
    let law = d.low_speed.unwrap_or(if smooth {
        LowSpeedSpec::Regularised
    } else {
        LowSpeedSpec::Floor
    });
    DriveConfig {
        v_floor: scale,
        v_soft: (law == LowSpeedSpec::Regularised).then_some(scale),
        dv_max: d.dv_max.or(smooth.then(|| c.input_limit.unwrap_or(1.0))),
        domega_max: d.domega_max.or(smooth.then_some(limits.omega_max)),
        wheel_speed_resolution: d.wheel_speed_resolution.unwrap_or(0.0),
        ..base
    }
}
