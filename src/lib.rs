//! groundcal: calibrates where a depth camera sits on a legged robot, using
//! nothing but the ground (Chai et al., "A Novel Identification Methodology for
//! the Coordinate Relationship between a 3D Vision System and a Legged Robot").
//!
//! This crate is the application on top of two others: the math
//! (`groundcal-calib`, re-exported as [`calib`]) and the hardware
//! (`groundcal-hal`). Nothing below may depend on it; `scripts/check-layers`
//! finds import cycles.
//!
//! Its floors, each using only those before it (`scripts/check-layers`):
//! - [`platform`]: files read with a bound and written whole, bad input
//!   named, systemd;
//! - [`formats`]: depth images, recordings, the result document, the
//!   exports, the HTML report, the calibration store;
//! - [`setup`]: the configuration, the pose schedules and their design;
//! - [`solving`]: the drift check, a recording or a ROS 2 bag replayed, the
//!   motor's tilts, a session as MCAP;
//! - [`hardware`]: the sensor and lower computer picked at run time;
//! - [`session`]: the live calibration, one state machine for `calibrate`
//!   and `serve`;
//! - [`terminal`]: the daemon's HTTP API, live events and phone page;
//! - [`cli`]: the `groundcal` command's subcommands.

// No unwrap or expect outside tests: external input and hardware fail with
// an error that says what was wrong (scripts/test runs clippy with this).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

/// The calibration math, its own crate (`calib/`): no I/O.
pub use groundcal_calib as calib;

pub mod cli;
pub mod formats;
pub mod hardware;
pub mod platform;
pub mod session;
pub mod setup;
pub mod solving;
pub mod terminal;
