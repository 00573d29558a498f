//! groundcal: calibrates where a depth camera sits on a legged robot, using
//! nothing but the ground (Chai et al., "A Novel Identification Methodology for
//! the Coordinate Relationship between a 3D Vision System and a Legged Robot").
//!
//! Layout:
//! - [`calib`]: the math (ground plane fit, body pose from the feet, the solve,
//!   accuracy and verdict), pure and synchronous;
//! - [`depth_image`]: depth images from files (fakenect dumps, PNG, TIFF, PGM);
//! - [`recording`]: the input files of `shared/spec/recording.md`;
//! - [`output`]: the result JSON of `shared/spec/cli.md`;
//! - [`report`]: the offline calibration report, one self-contained HTML page;
//! - [`export`]: the result in ROS's frames (URDF, `static_transform_publisher`, JSON);
//! - [`schedule`]: pose schedules and their checks before anything moves;
//! - [`cli`]: the `groundcal` command's subcommands.

/// The calibration math, its own crate (`calib/`): no I/O.
pub use groundcal_calib as calib;
pub mod cli;
pub mod config;
pub mod depth_image;
pub mod export;
pub mod files;
pub mod hardware;
pub mod output;
pub mod recording;
pub mod replay;
pub mod report;
pub mod schedule;
pub mod session;
pub mod store;
pub mod systemd;
pub mod terminal;
