//! The body controller: the robot's real-time lower computer
//! (`shared/spec/hexapod-udp.md`), which moves the body and reports the feet.

use crate::error::Error;
use groundcal_calib::geometry::PoseDegMm;

/// The lower computer's limits on a commanded pose (WELCOME).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyLimits {
    pub max_tilt_deg: f64,
    pub min_height_mm: f64,
    pub max_height_mm: f64,
    pub max_shift_mm: f64,
}

/// What the lower computer says when a session starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Welcome {
    pub session: u32,
    pub limits: BodyLimits,
    pub firmware: String,
}

/// The body's motion state (STATE `state`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MotionState {
    /// At the home stance, no target.
    Idle,
    Moving,
    /// At the target pose, body still.
    Settled,
    Halted,
    /// A fault, with the lower computer's code (nonzero).
    Fault(u8),
}

/// The body's state and the feet, from forward kinematics of the measured joints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyState {
    pub state: MotionState,
    /// The last accepted target (0 = home).
    pub pose_id: u16,
    /// The lower computer's monotonic clock.
    pub time_us: u64,
    /// The six feet in the body frame, foot 1 first, millimetres.
    pub feet_mm: [[f64; 3]; 6],
}

/// A body controller. One session at a time; every request is answered or
/// fails with an error whose kind says what to do.
#[allow(async_fn_in_trait)]
pub trait BodyController {
    type Error: Error;

    /// Starts a session (HELLO) and returns the limits.
    async fn hello(&mut self) -> Result<Welcome, Self::Error>;

    /// Asks for a body pose (SET_POSE); `Ok` once accepted, not reached.
    async fn set_pose(
        &mut self,
        pose_id: u16,
        pose: &PoseDegMm,
        duration_ms: u32,
    ) -> Result<(), Self::Error>;

    /// The body's state now (GET_STATE).
    async fn state(&mut self) -> Result<BodyState, Self::Error>;

    /// Back to the home stance (HOME).
    async fn home(&mut self, duration_ms: u32) -> Result<(), Self::Error>;

    /// Stops where the body is (HALT).
    async fn halt(&mut self) -> Result<(), Self::Error>;

    /// Ends the session (BYE); the robot holds where it is.
    async fn bye(&mut self) -> Result<(), Self::Error>;
}
