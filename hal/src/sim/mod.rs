//! Simulated hardware: a hexapod whose real body pose differs from the
//! commanded one, and a Kinect that sees the simulated world from the body's
//! real pose. Tests and demos run the same session logic against them.
//!
//! The two share the body's *true* pose through [`TruePose`]: the simulated
//! lower computer writes it as the body moves, the simulated Kinect reads it
//! to render each frame. Nothing else may read it: the calibration must find
//! the pose from the feet, as on the robot.
//!
//! - [`world`]: ground, boxes, walls, people; what a ray hits;
//! - [`kinect`]: depth frames of the world, with the Kinect's noise;
//! - [`robot`]: the body, its feet and its errors;
//! - [`lower_computer`]: the simulated robot served over UDP
//!   (`groundcal sim-robot`), with fault injection;
//! - [`recorded_robot`]: a lower computer that plays a recording's robot back.

pub mod kinect;
pub mod lower_computer;
pub mod noise;
pub mod recorded_robot;
pub mod robot;
pub mod world;

use std::sync::{Arc, Mutex};

use groundcal_calib::geometry::Transform;

/// The simulated body's true `ground_from_robot`, shared between the
/// simulated lower computer (writer) and the simulated Kinect (reader).
#[derive(Debug, Clone)]
pub struct TruePose(Arc<Mutex<Transform>>);

impl TruePose {
    /// A shared pose starting at `ground_from_robot`.
    pub fn new(ground_from_robot: Transform) -> Self {
        Self(Arc::new(Mutex::new(ground_from_robot)))
    }

    /// The body's true pose now.
    pub fn get(&self) -> Transform {
        // A poisoned lock only means a writer panicked mid-update of a plain
        // value; the value itself is still a valid transform.
        *self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Sets the body's true pose.
    pub fn set(&self, ground_from_robot: Transform) {
        *self.0.lock().unwrap_or_else(|e| e.into_inner()) = ground_from_robot;
    }
}
