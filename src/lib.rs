//! groundcal: calibrates where a depth camera sits on a legged robot, using
//! nothing but the ground (Chai et al., "A Novel Identification Methodology for
//! the Coordinate Relationship between a 3D Vision System and a Legged Robot").
//!
//! This crate is the application on top of two others: the math
//! (`groundcal-calib`, re-exported as [`calib`]) and the hardware
//! (`groundcal-hal`). Nothing below may depend on it; `scripts/check-layers`
//! finds import cycles.
//!
//! Inputs and outputs:
//! - [`config`]: the configuration (strict TOML), with the hardware choices as types;
//! - [`schedule`]: pose schedules and their checks before anything moves;
//! - [`depth_image`]: depth images from files (fakenect dumps, PNG, TIFF, PGM);
//! - [`recording`]: the input files of `shared/spec/recording.md`, read and written;
//! - [`files`]: files written whole or not at all, and read with a size bound;
//! - [`output`]: the result document of `shared/spec/cli.md`, written and read back;
//! - [`report`]: the offline calibration report, one self-contained HTML page;
//! - [`export`]: the result in ROS's frames (URDF, `static_transform_publisher`, JSON);
//! - [`mcap_session`]: a session as an MCAP file for Foxglove and ROS 2;
//! - [`bag`]: ROS 2 bags (MCAP) from other robots' stacks as input;
//!
//! Running a calibration:
//! - [`replay`]: a recording solved offline;
//! - [`hardware`]: the sensor and lower computer picked at run time;
//! - [`session`]: the live calibration, one state machine for `calibrate` and `serve`;
//! - [`store`]: the active calibration and its history;
//! - [`terminal`]: the daemon's HTTP API, live events and phone page;
//! - [`systemd`]: sd_notify and the watchdog;
//! - [`cli`]: the `groundcal` command's subcommands.

// No unwrap or expect outside tests: external input and hardware fail with
// an error that says what was wrong (scripts/test runs clippy with this).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

/// The calibration math, its own crate (`calib/`): no I/O.
pub use groundcal_calib as calib;

pub mod bag;
pub mod cli;
pub mod config;
pub mod depth_image;
pub mod design;
pub mod export;
pub mod files;
pub mod hardware;
pub mod input;
pub mod mcap_session;
pub mod output;
pub mod recording;
pub mod replay;
pub mod report;
pub mod schedule;
pub mod session;
pub mod store;
pub mod systemd;
pub mod terminal;
pub mod tilts;
pub mod verify;
