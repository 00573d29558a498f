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
//! - [`geometry`], [`depth`]: poses and the Kinect's depth model, shared by the
//!   real and the simulated hardware;
//! - [`sensor`], [`controller`], [`error`]: the traits and their vocabulary.

#![deny(unsafe_code)]

pub mod controller;
pub mod depth;
pub mod error;
pub mod geometry;
pub mod kinect;
pub mod sensor;
pub mod sim;
pub mod udp;

pub use controller::{BodyController, BodyLimits, BodyState, MotionState, Welcome};
pub use error::{Error, ErrorKind};
pub use sensor::{DepthFrame, DepthSensor, Led, SensorInfo, TiltState};
