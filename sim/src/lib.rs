//! # ftcbf-sim
//!
//! The simulator around [`ftcbf_controller`]: a differential-drive robot loaded from URDF
//! driving in a rapier3d world among parry3d obstacles, redundant noisy sensors, attack
//! injectors, world files, the closed-loop runner and rerun recording.
//!
//! Frames: the world frame is Z-up, REP-103 (x forward, y left at the start pose of
//! identity); SI units, angles in radians.

#![warn(missing_docs)]

pub mod active;
pub mod analysis;
pub mod attacks;
pub mod drivetrain;
pub mod environment;
pub mod model;
pub mod movers;
pub mod observe;
pub mod obstacles;
pub mod physics;
pub mod planner;
pub mod plant;
#[cfg(feature = "record")]
pub mod record;
pub mod robot;
pub mod runner;
pub mod safe_sets;
pub mod sensors;
pub mod spec;
pub mod state;
pub mod summary;
pub mod world;
pub mod worldgen;

pub use ftcbf_controller;
