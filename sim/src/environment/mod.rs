//! Obstacles loaded from the files robots already live in (`[environment]`, issue #47):
//! ROS occupancy maps ([`map`]).

pub mod map;

pub use map::{MapError, MapField, OccupancyGrid, UnknownCells};
