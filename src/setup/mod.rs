//! What the robot is told before anything moves: the configuration (strict
//! TOML, the hardware choices as types), the pose schedules with their
//! checks, and the design of a schedule within the robot's limits.

pub mod config;
pub mod design;
pub mod schedule;
