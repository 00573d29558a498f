//! The calibration session: one state machine used by `groundcal calibrate`
//! and `groundcal serve`, generic over the hardware traits so that the same
//! logic drives the robot, the simulator and recordings.
//!
//! The order of things, and why:
//! 1. the schedule is checked against groundcal's limits and then the lower
//!    computer's (WELCOME) before anything moves; an invalid one is refused
//!    with the offending pose named;
//! 2. the home stance's feet fix the ground frame; the Kinect is tilted to the
//!    configured angle and waited for (a calibration holds for one tilt);
//! 3. per pose: SET_POSE, poll until settled at that pose, a settle delay, K
//!    frames captured; the ground is fitted on a worker thread while the robot
//!    already moves to the next pose (the fit is never on the critical path);
//! 4. HOME, solve, verdict;
//! 5. on abort (operator, signal, lost link, lost sensor): HALT, then HOME,
//!    then a clear final state.
//!
//! Everything the operator might want to see is sent as an [`Event`].

mod kept_frames;
mod plan;
mod run;

pub use plan::{Plan, RecordedPose, STALL_LIMIT};
pub use run::{run, verify, SessionError, SessionOutcome, VerifyOutcome};

pub use crate::solving::verify::{GravityReading, VisitedPose};

use crate::calib::geometry::PoseDegMm;
use crate::calib::ground_view::GroundView;

/// What happens, for the operator's progress display.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The schedule passed its checks; `poses` will be visited.
    Started { poses: usize, schedule: String },
    /// The lower computer answered.
    Connected { firmware: String },
    /// The robot stands at home; the ground frame is fixed.
    AtHome,
    /// The Kinect is tilted and still.
    SensorReady { tilt_deg: f64 },
    /// Moving to pose `index` of `of`.
    Moving {
        index: u16,
        of: usize,
        commanded: PoseDegMm,
    },
    /// Settled at pose `index`; frames are being captured.
    Capturing { index: u16, of: usize },
    /// The ground of pose `index` was fitted (or not, with why).
    PoseDone {
        index: u16,
        of: usize,
        outcome: Result<PoseFit, String>,
    },
    /// What the camera saw at pose `index` (`None`: at rest, before a run),
    /// with the ground the fit chose.
    GroundSeen {
        index: Option<u16>,
        view: Box<GroundView>,
    },
    /// A provisional solve over the poses fitted so far, for the live chart
    /// of θ and e_d: each pose against the mount those poses give. It moves
    /// as poses arrive; only the final result counts.
    Provisional { poses: Vec<ProvisionalPose> },
    /// All poses visited; back home; solving.
    Solving,
    /// The session ended; see [`SessionOutcome`].
    Finished { accepted: bool },
    /// A check of the active calibration ended (`verify`).
    Verified { consistent: bool },
    /// The session is stopping (an abort or a failure, `why`): the robot
    /// is being halted.
    Halting { why: String },
    /// Halted; the robot is walking back to its home stance.
    WalkingHome,
    /// The session was aborted; the robot was halted and sent home.
    Aborted {
        /// Why, and how the robot was left, in words.
        reason: String,
        /// How the robot was left, for a page that must not guess from words.
        robot_left: RobotLeft,
    },
}

/// How an aborted session left the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RobotLeft {
    /// It was never told to move (the schedule was refused first).
    NotMoved,
    /// Halted, sent home, and it reported the home stance.
    Home,
    /// Halted, but it did not reach (or did not report) the home stance.
    Halted,
    /// It could not be halted: nobody knows where it stands.
    Unknown,
}

/// One pose in a provisional solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProvisionalPose {
    pub index: u16,
    /// The paper's θ, degrees.
    pub theta_deg: f64,
    /// The paper's e_d, mm.
    pub e_d_mm: f64,
    /// Whether the solve used it (false: set aside as an outlier).
    pub used: bool,
}

/// A pose's fitted ground, for the live chart.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseFit {
    pub inliers: usize,
    pub plane: [f64; 4],
}
