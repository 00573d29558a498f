//! Hardware abstraction for groundcal.
//!
//! The calibration session talks to hardware only through two small traits, in
//! the manner of embedded-hal: a [`DepthSensor`] (the Kinect) and a
//! [`BodyController`] (the robot's lower computer). Each trait's error exposes
//! an [`ErrorKind`] so that the session can act on a failure (retry, abort and
//! send the robot home, ask the operator) without knowing which implementation
//! produced it. Each trait has a real implementation and a simulated one, and
//! the session is generic over both.
//!
//! - [`sensor`], [`controller`], [`error`]: the traits and their vocabulary;
//! - [`kinect`]: the Kinect over libfreenect (loaded at run time);
//! - [`udp`]: the lower computer's protocol (pure) and its tokio link;
//! - [`sim`]: the simulated world, Kinect and robot, and a simulated lower
//!   computer on UDP.
//!
//! Poses and depth models come from `groundcal-calib` (the math, below this
//! crate). Nothing here may depend on the application (`groundcal`) above it.

#![deny(unsafe_code)]
// No unwrap or expect outside tests: external input and hardware fail with
// an error that says what was wrong (scripts/test runs clippy with this).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

pub mod controller;
pub mod error;
pub mod kinect;
pub mod sensor;
pub mod sim;
pub mod udp;

pub use controller::{BodyController, BodyLimits, BodyState, MotionState, Welcome};
pub use error::{Error, ErrorKind};
pub use sensor::{DepthFrame, DepthSensor, Led, SensorInfo, TiltState};
