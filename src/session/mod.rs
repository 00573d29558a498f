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

mod run;

pub use run::{run, SessionError, SessionOutcome};

use std::path::PathBuf;
use std::time::Duration;

use crate::calib::calibrate::CalibrationSettings;
use crate::calib::geometry::PoseDegMm;
use crate::calib::observe::ObserveSettings;
use crate::recording::session::NominalMount;
use crate::schedule::{Limits, Schedule};

/// Everything a session needs to know before it starts.
#[derive(Debug, Clone)]
pub struct Plan {
    pub schedule: Schedule,
    /// groundcal's own limits (the lower computer's are added at HELLO).
    pub limits: Limits,
    pub frames_per_pose: usize,
    pub motion: Duration,
    pub settle: Duration,
    /// The Kinect's motor tilt during calibration.
    pub tilt_deg: f64,
    pub nominal_mount: Option<NominalMount>,
    pub pose: ObserveSettings,
    pub calibration: CalibrationSettings,
    /// Write everything as a recording here, as it goes.
    pub record: Option<PathBuf>,
    /// GET_STATE polling while the body moves (at most 200 ms: the lower
    /// computer's watchdog).
    pub poll: Duration,
    /// How long a motion may take beyond its nominal duration.
    pub motion_slack: Duration,
    /// For each pose of the schedule, the pose id sent and the frames
    /// captured, when they are not `1..=N` and `frames_per_pose`: a replayed
    /// recording's own, so that the session asks for what was recorded.
    pub recorded_poses: Option<Vec<RecordedPose>>,
}

/// A pose as a recording has it: its id and how many frames it holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordedPose {
    pub id: u16,
    pub frames: usize,
}

impl Plan {
    /// The pose id sent for the `k`-th pose of the schedule (from 0).
    pub fn pose_id(&self, k: usize) -> u16 {
        self.recorded_poses
            .as_ref()
            .and_then(|r| r.get(k))
            .map_or_else(|| u16::try_from(k + 1).unwrap_or(u16::MAX), |r| r.id)
    }

    /// The frames to capture at the `k`-th pose of the schedule.
    pub fn frames_at(&self, k: usize) -> usize {
        self.recorded_poses
            .as_ref()
            .and_then(|r| r.get(k))
            .map_or(self.frames_per_pose, |r| r.frames)
    }

    /// The longest a motion of `duration` may take before it is a failure.
    pub fn motion_deadline(&self, duration: Duration) -> Duration {
        duration * 3 + self.motion_slack
    }
}

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
    /// A provisional solve over the poses fitted so far, for the live chart
    /// of θ and e_d: each pose against the mount those poses give. It moves
    /// as poses arrive; only the final result counts.
    Provisional { poses: Vec<ProvisionalPose> },
    /// All poses visited; back home; solving.
    Solving,
    /// The session ended; see [`SessionOutcome`].
    Finished { accepted: bool },
    /// The session was aborted; the robot was halted and sent home.
    Aborted { reason: String },
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
