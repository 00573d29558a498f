//! What the API says: the status document and the events of the live
//! stream (docs/api.md), mirrored from the session's events.

use std::collections::VecDeque;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::calib::geometry::PoseDegMm;
use crate::calib::quality::Gates;
use crate::formats::store::{ActiveDocument, HistoryEntry, StoredResult};
use crate::session::{Event, RobotLeft};
use crate::setup::schedule::body_pose_in_words;

/// A serializable mirror of [`Event`] for the API.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum EventJson {
    Started {
        poses: usize,
        schedule: String,
    },
    Connected {
        firmware: String,
    },
    AtHome,
    SensorReady {
        tilt_deg: f64,
    },
    Moving {
        index: u16,
        of: usize,
        /// The commanded body pose in words ("rolled 20° right, …").
        motion: String,
        /// The commanded body pose, for a page that says it in its own words.
        commanded: PoseDegMm,
    },
    Capturing {
        index: u16,
        of: usize,
    },
    PoseDone {
        index: u16,
        of: usize,
        ok: bool,
        inliers: Option<usize>,
        plane: Option<[f64; 4]>,
        error: Option<String>,
    },
    /// A new picture of what the camera sees is at `GET /api/view` (of
    /// pose `index`, or at rest when none).
    GroundSeen {
        index: Option<u16>,
    },
    /// θ and e_d per pose against the mount the poses so far give.
    Provisional {
        poses: Vec<ProvisionalPoseJson>,
    },
    Solving,
    Finished {
        accepted: bool,
    },
    /// A check of the active calibration ended.
    Verified {
        consistent: bool,
    },
    /// The session is stopping: the robot is being halted.
    Halting {
        why: String,
    },
    /// Halted; walking back to the home stance.
    WalkingHome,
    Aborted {
        reason: String,
        robot_left: RobotLeft,
    },
    /// Not a session event: Abort was asked for (by whom); the session is
    /// halting the robot and sending it home.
    Aborting {
        by: String,
    },
    /// Not a session event: a calibration was made active (accepted, or
    /// rolled back to), by whom.
    Activated {
        id: String,
        activated: String,
        by: String,
    },
    /// Not a session event: the result was kept in the store under `id`.
    Stored {
        id: String,
        status: String,
    },
    /// Not a session event: the session ended without a result.
    Failed {
        error: String,
    },
    /// Not a session event: the daemon is alive (every second on each live
    /// stream, never kept in the status).
    Heartbeat,
    /// Not a session event: a check of the active calibration ended,
    /// `consistent`, `drift` or `failed` (with the reasons or the error).
    Checked {
        outcome: String,
        reasons: Vec<String>,
    },
}

/// `GET /api/view`: the latest picture of what the camera sees, and the
/// ground the fit chose in it.
#[derive(Debug, Clone, Serialize)]
pub struct ViewJson {
    /// Counts pictures since the service started: a page redraws a new one.
    pub seq: u64,
    /// How old the picture is, milliseconds (None: there is none yet).
    pub age_ms: Option<u64>,
    /// When it was taken (RFC 3339, UTC).
    pub taken: Option<String>,
    /// The schedule's pose it shows; None: the robot at rest.
    pub pose: Option<u16>,
    pub view: Option<std::sync::Arc<crate::calib::ground_view::GroundView>>,
    /// Why no new picture can be taken now (the sensor is missing, a
    /// recording plays its frames once).
    pub unavailable: Option<String>,
    /// Whether pictures are taken while no session runs (`[serve]
    /// preview_interval_ms` is not 0).
    pub live_at_rest: bool,
}

/// One pose of a provisional solve.
#[derive(Debug, Clone, Serialize)]
pub struct ProvisionalPoseJson {
    pub index: u16,
    pub theta_deg: f64,
    pub e_d_mm: f64,
    pub used: bool,
}

impl From<&Event> for EventJson {
    fn from(e: &Event) -> Self {
        match e {
            Event::Started { poses, schedule } => EventJson::Started {
                poses: *poses,
                schedule: schedule.clone(),
            },
            Event::Connected { firmware } => EventJson::Connected {
                firmware: firmware.clone(),
            },
            Event::AtHome => EventJson::AtHome,
            Event::SensorReady { tilt_deg } => EventJson::SensorReady {
                tilt_deg: *tilt_deg,
            },
            Event::Moving {
                index,
                of,
                commanded,
            } => EventJson::Moving {
                index: *index,
                of: *of,
                motion: body_pose_in_words(commanded),
                commanded: *commanded,
            },
            Event::Capturing { index, of } => EventJson::Capturing {
                index: *index,
                of: *of,
            },
            Event::PoseDone { index, of, outcome } => match outcome {
                Ok(fit) => EventJson::PoseDone {
                    index: *index,
                    of: *of,
                    ok: true,
                    inliers: Some(fit.inliers),
                    plane: Some(fit.plane),
                    error: None,
                },
                Err(e) => EventJson::PoseDone {
                    index: *index,
                    of: *of,
                    ok: false,
                    inliers: None,
                    plane: None,
                    error: Some(e.clone()),
                },
            },
            Event::Provisional { poses } => EventJson::Provisional {
                poses: poses
                    .iter()
                    .map(|p| ProvisionalPoseJson {
                        index: p.index,
                        theta_deg: p.theta_deg,
                        e_d_mm: p.e_d_mm,
                        used: p.used,
                    })
                    .collect(),
            },
            Event::GroundSeen { index, .. } => EventJson::GroundSeen { index: *index },
            Event::Solving => EventJson::Solving,
            Event::Finished { accepted } => EventJson::Finished {
                accepted: *accepted,
            },
            Event::Verified { consistent } => EventJson::Verified {
                consistent: *consistent,
            },
            Event::Halting { why } => EventJson::Halting { why: why.clone() },
            Event::WalkingHome => EventJson::WalkingHome,
            Event::Aborted { reason, robot_left } => EventJson::Aborted {
                reason: reason.clone(),
                robot_left: *robot_left,
            },
        }
    }
}

/// Whether a calibration is running (`"idle"` or `"running"` in the JSON).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RunState {
    #[default]
    Idle,
    Running,
}

/// What a running session does: calibrate, or check the active calibration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Task {
    #[default]
    Calibration,
    Check,
}

/// The active calibration, as every page shows it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ActiveRef {
    pub id: String,
    /// When it was made active (RFC 3339).
    pub activated: String,
}

impl ActiveRef {
    /// The id and time of an `active.json` document.
    pub fn of(active: &ActiveDocument) -> ActiveRef {
        ActiveRef {
            id: active.id.clone(),
            activated: active.activated.clone(),
        }
    }
}

/// `GET /api/calibrations`: the history, newest first.
#[derive(Debug, Clone, Serialize)]
pub struct History {
    pub calibrations: Vec<HistoryEntry>,
}

/// An abort, asked for or done.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum AbortState {
    /// Abort reached the daemon; the session is halting the robot.
    Aborting { by: String },
    /// The session ended aborted, leaving the robot so.
    Aborted {
        reason: String,
        robot_left: RobotLeft,
    },
}

/// A run that a stop of the service cut off (a kill, a crash, a power
/// cut): said through any number of restarts, until a person starts the
/// next calibration or check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Interrupted {
    /// Who started it, and when (RFC 3339).
    pub by: String,
    pub started: String,
    /// A calibration or a check.
    pub task: Task,
}

/// What pressing Calibrate or Check will do to the robot, for the page's
/// confirmation ("the robot will move for about 2 min: keep clear").
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MotionPlan {
    /// Body poses visited (the home stance not counted).
    pub poses: usize,
    /// About how long the robot moves, in seconds (the poses' motion, settle
    /// and capture, at the simulator's speed when it is simulated in
    /// process; the real robot's otherwise).
    pub about_s: f64,
    /// `about_s` is the in-process simulator's time (faster than the robot).
    pub simulated: bool,
    /// How long the last such run that went through all its poses took
    /// here, in seconds (None: none yet since the service started). A lower
    /// computer that runs faster than the robot (a simulator) shows here.
    pub last_s: Option<f64>,
}

/// What the two buttons that move the robot will do.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MotionPlans {
    pub calibration: MotionPlan,
    pub check: MotionPlan,
}

/// What became of the check at the service's start. That check moves
/// nothing: it reads the stance the robot already stands in, with the
/// Kinect's motor where it is; otherwise it waits for a person.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StartupCheck {
    /// `[verify] at_start` is off.
    #[default]
    Off,
    /// Nothing to check: no calibration is active, or the hardware did not open.
    NotPossible,
    /// It ran, moving nothing (see `check`).
    Started,
    /// Held: a run was interrupted, so nothing happens until a person asks
    /// for it (Check on the page).
    HeldForAPerson,
    /// Held: the robot did not stand at its home stance, or the Kinect's
    /// motor not at the calibration's tilt, so a check that moves nothing
    /// could not be made; it waits for a person (Check on the page).
    HeldNotStanding,
}

/// A check of the active calibration (`verify`), at the service's start or
/// on "Check". The last one that reached a verdict is kept in the store.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CheckStatus {
    /// The calibration checked (its store id): the outcome holds for it only.
    pub calibration_id: Option<String>,
    /// `running`, `consistent`, `drift` or `failed`.
    pub outcome: String,
    pub by: String,
    /// Started by the service at its start (moving nothing), not by a person.
    #[serde(default)]
    pub started_by_service: bool,
    pub started: String,
    pub finished: Option<String>,
    /// Why it drifted, in an operator's words.
    pub reasons: Vec<String>,
    /// Why it could not check.
    pub error: Option<String>,
    /// The whole report (`groundcal verify --json`).
    pub report: Option<crate::solving::verify::VerifyJson>,
}

/// What a session is doing, as the last event that changed it says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// The schedule passed its checks; connecting to the lower computer.
    Started,
    /// Connected; walking to the home stance.
    Connected,
    /// At the home stance; tilting the Kinect.
    AtHome,
    /// The Kinect is tilted; the first pose comes.
    SensorReady,
    /// Moving the body to pose `pose` (`commanded`).
    Moving,
    /// Holding still at pose `pose`, capturing the ground.
    Capturing,
    /// The ground of pose `pose` was found.
    PoseFound,
    /// Pose `pose` was set aside (the step says why).
    PoseSetAside,
    /// Back at home, solving.
    Solving,
    /// The calibration finished (its result says how).
    Finished,
    /// The check finished (its outcome says how).
    Verified,
    /// Abort reached the daemon: halting the robot and sending it home.
    Aborting,
    /// Stopping after a failure: halting the robot.
    Halting,
    /// Halted; walking home.
    WalkingHome,
    /// Aborted (see `abort`).
    Aborted,
    /// Stopped without a result (see `error`).
    Failed,
    /// The check could not be made (see `check`).
    CheckFailed,
}

/// What `GET /api/status` shows.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Status {
    /// A number that names this run of the service (from its start time and
    /// process id): revisions count anew when it starts again.
    pub instance: u64,
    /// Counts the status's changes within `instance`. A page shows an
    /// answer only if it is no older than the one it shows: answers on two
    /// connections can arrive in the other order than the daemon read them.
    pub revision: u64,
    pub state: RunState,
    /// What the running (or last) session does.
    pub task: Task,
    /// The last check of the active calibration (running, or how it ended).
    pub check: Option<CheckStatus>,
    /// The last check that reached a verdict (consistent or drift), kept in
    /// the store across any stop: a check that could not be made does not
    /// replace it, so a knock once found stays said until a new verdict or
    /// a new active calibration (its `calibration_id` is not the active one).
    pub verdict: Option<CheckStatus>,
    /// Who started the current (or last) calibration.
    pub by: Option<String>,
    pub started: Option<String>,
    /// Pose i of N.
    pub pose: Option<u16>,
    pub of: Option<usize>,
    /// The robot's state in words (from the last event).
    pub robot: String,
    /// What the calibration is doing now, in an operator's words ("walking
    /// to pose 7 of 52: rolled 20° right, body at 615 mm").
    pub step: String,
    /// The same, typed: the page words it in its own language.
    pub phase: Option<Phase>,
    /// What the phase's event said in words of its own (English): why a
    /// pose was set aside, why the session stopped or was aborted.
    pub detail: Option<String>,
    /// The body pose the robot is moving to or holds (while running).
    pub commanded: Option<PoseDegMm>,
    /// Seconds since the calibration started (while running).
    pub elapsed_s: Option<f64>,
    /// Seconds left, estimated from the poses' measured durations (once a
    /// pose is done; while running).
    pub remaining_s: Option<f64>,
    /// The gates the result will be judged by (the charts draw θ's and
    /// e_d's as lines).
    pub gates: Option<Gates>,
    pub recent_events: VecDeque<EventJson>,
    /// The current or last result, as the store keeps it (with its id).
    pub result: Option<StoredResult>,
    pub result_id: Option<String>,
    /// Why the last session produced no result.
    pub error: Option<String>,
    /// A calibration the service's last stop cut off (until the next one
    /// starts).
    pub interrupted: Option<Interrupted>,
    /// The check at the service's start.
    pub startup_check: StartupCheck,
    /// The active calibration (None: none yet).
    pub active: Option<ActiveRef>,
    /// The running (or last) session's abort.
    pub abort: Option<AbortState>,
    /// What Calibrate and Check will do to the robot.
    pub motion: Option<MotionPlans>,
    /// Whether the hardware opened when the service started, in words (it
    /// is opened again for each calibration).
    pub hardware: String,
    /// The latest provisional θ and e_d per pose of a running session (kept
    /// here rather than among the recent events: it is replaced, not added).
    pub provisional: Option<Vec<ProvisionalPoseJson>>,
    /// When the running calibration and its poses began.
    #[serde(skip)]
    pub clock: Option<RunClock>,
}

/// The times of a running calibration, for the time so far and left.
#[derive(Debug, Clone, Copy)]
pub struct RunClock {
    pub started: Instant,
    /// When the robot began walking to the first pose.
    pub first_pose: Option<Instant>,
    /// How many poses are done, and when the last one was.
    pub poses_done: usize,
    pub last_done: Option<Instant>,
}

impl RunClock {
    pub fn start(now: Instant) -> Self {
        RunClock {
            started: now,
            first_pose: None,
            poses_done: 0,
            last_done: None,
        }
    }

    /// Seconds left for `of` poses: the poses done so far took this long
    /// each, and so will the rest (walking home and solving take about one).
    pub fn remaining_s(&self, of: usize) -> Option<f64> {
        let per_pose = self
            .last_done?
            .duration_since(self.first_pose?)
            .as_secs_f64()
            / self.poses_done.max(1) as f64;
        Some(per_pose * (of.saturating_sub(self.poses_done) + 1) as f64)
    }
}

impl Status {
    /// A snapshot to show at `now`: the status with its times.
    pub fn at(&self, now: Instant) -> Status {
        let mut shown = self.clone();
        if let (RunState::Running, Some(clock)) = (self.state, self.clock) {
            shown.elapsed_s = Some(now.duration_since(clock.started).as_secs_f64());
            shown.remaining_s = self.of.and_then(|of| clock.remaining_s(of));
        }
        shown
    }

    /// What an event changes in the status: the pose, the robot's state in
    /// words, the step in words, the provisional charts.
    pub fn apply(&mut self, event: &EventJson) {
        self.apply_at(event, Instant::now());
    }

    /// [`Status::apply`] for an event that came at `now`.
    pub fn apply_at(&mut self, event: &EventJson, now: Instant) {
        // An aborted session's words (why, and where the robot was left)
        // stay: the failure that follows them says only "aborted".
        let said_why = self.step.starts_with("aborted");
        match step_in_words(event) {
            Some(_) if said_why && matches!(event, EventJson::Failed { .. }) => {}
            Some(step) => {
                self.step = step;
                self.phase = phase_of(event);
                self.detail = match event {
                    EventJson::PoseDone { error, .. } => error.clone(),
                    EventJson::Aborted { reason, .. } => Some(reason.clone()),
                    EventJson::Failed { error } => Some(error.clone()),
                    EventJson::Halting { why } => Some(why.clone()),
                    _ => None,
                };
            }
            None => {}
        }
        if let Some(clock) = &mut self.clock {
            match event {
                EventJson::Moving { .. } if clock.first_pose.is_none() => {
                    clock.first_pose = Some(now)
                }
                EventJson::PoseDone { .. } => {
                    clock.poses_done += 1;
                    clock.last_done = Some(now);
                }
                _ => {}
            }
        }
        match event {
            EventJson::Started { poses, .. } => {
                self.of = Some(*poses);
                self.robot = "schedule checked".into();
            }
            EventJson::Connected { firmware } => self.robot = format!("connected ({firmware})"),
            EventJson::AtHome => self.robot = "at the home stance".into(),
            EventJson::SensorReady { tilt_deg } => {
                self.robot = format!("Kinect tilted to {tilt_deg}°")
            }
            EventJson::Moving {
                index,
                of,
                commanded,
                ..
            } => {
                self.pose = Some(*index);
                self.of = Some(*of);
                self.commanded = Some(*commanded);
                self.robot = "moving".into();
            }
            EventJson::Capturing { index, of } => {
                self.pose = Some(*index);
                self.of = Some(*of);
                self.robot = "capturing".into();
            }
            EventJson::PoseDone { index, .. } => self.pose = Some(*index),
            EventJson::Solving => self.robot = "back home; solving".into(),
            EventJson::Finished { accepted } => {
                self.robot = format!(
                    "finished ({})",
                    if *accepted { "accepted" } else { "rejected" }
                )
            }
            EventJson::Verified { consistent } => {
                self.robot = format!(
                    "checked ({})",
                    if *consistent { "consistent" } else { "drift" }
                )
            }
            EventJson::Aborted { reason, robot_left } => {
                self.robot = format!("aborted: {reason}");
                self.abort = Some(AbortState::Aborted {
                    reason: reason.clone(),
                    robot_left: *robot_left,
                });
            }
            EventJson::Halting { .. } => self.robot = "halting".into(),
            EventJson::WalkingHome => self.robot = "walking home".into(),
            EventJson::Aborting { by } => {
                self.abort = Some(AbortState::Aborting { by: by.clone() });
            }
            EventJson::Activated { id, activated, .. } => {
                self.active = Some(ActiveRef {
                    id: id.clone(),
                    activated: activated.clone(),
                });
            }
            EventJson::Stored { .. }
            | EventJson::Failed { .. }
            | EventJson::Checked { .. }
            | EventJson::GroundSeen { .. }
            | EventJson::Heartbeat => {}
            EventJson::Provisional { poses } => self.provisional = Some(poses.clone()),
        }
    }
}

/// The phase an event that changes the step puts the session in.
fn phase_of(event: &EventJson) -> Option<Phase> {
    Some(match event {
        EventJson::Started { .. } => Phase::Started,
        EventJson::Connected { .. } => Phase::Connected,
        EventJson::AtHome => Phase::AtHome,
        EventJson::SensorReady { .. } => Phase::SensorReady,
        EventJson::Moving { .. } => Phase::Moving,
        EventJson::Capturing { .. } => Phase::Capturing,
        EventJson::PoseDone { ok: true, .. } => Phase::PoseFound,
        EventJson::PoseDone { ok: false, .. } => Phase::PoseSetAside,
        EventJson::Solving => Phase::Solving,
        EventJson::Finished { .. } => Phase::Finished,
        EventJson::Verified { .. } => Phase::Verified,
        EventJson::Aborting { .. } => Phase::Aborting,
        EventJson::Halting { .. } => Phase::Halting,
        EventJson::WalkingHome => Phase::WalkingHome,
        EventJson::Aborted { .. } => Phase::Aborted,
        EventJson::Failed { .. } => Phase::Failed,
        EventJson::Checked { .. } => Phase::CheckFailed,
        EventJson::Activated { .. }
        | EventJson::Stored { .. }
        | EventJson::Provisional { .. }
        | EventJson::GroundSeen { .. }
        | EventJson::Heartbeat => return None,
    })
}

/// What an event says the calibration is doing, in an operator's words; None
/// for an event that does not change the step.
fn step_in_words(event: &EventJson) -> Option<String> {
    Some(match event {
        EventJson::Started { poses, schedule } => {
            format!("schedule \"{schedule}\" checked: {poses} poses; connecting to the robot")
        }
        EventJson::Connected { .. } => "connected; walking to the home stance".into(),
        EventJson::AtHome => "at the home stance; tilting the Kinect".into(),
        EventJson::SensorReady { tilt_deg } => {
            format!("Kinect at {tilt_deg}°; starting the first pose")
        }
        EventJson::Moving {
            index, of, motion, ..
        } => {
            format!("pose {index} of {of}: moving the body ({motion})")
        }
        EventJson::Capturing { index, of } => {
            format!("pose {index} of {of}: holding still, capturing the ground")
        }
        EventJson::PoseDone {
            index,
            of,
            ok,
            error,
            ..
        } => match (ok, error) {
            (true, _) => format!("pose {index} of {of}: ground found"),
            (false, Some(e)) => format!("pose {index} of {of}: set aside ({e})"),
            (false, None) => format!("pose {index} of {of}: set aside"),
        },
        EventJson::Solving => "back at the home stance; solving".into(),
        EventJson::Finished { accepted } => format!(
            "finished: {}",
            if *accepted {
                "passed its checks"
            } else {
                "failed its checks"
            }
        ),
        EventJson::Verified { consistent } => format!(
            "checked: {}",
            if *consistent {
                "the sensor agrees with the active calibration"
            } else {
                "the sensor has moved since it was calibrated"
            }
        ),
        EventJson::Aborted { reason, .. } => format!("aborted: {reason}"),
        EventJson::Aborting { .. } => "aborting: halting the robot and sending it home".into(),
        EventJson::Halting { why } => format!("stopping ({why}): halting the robot…"),
        EventJson::WalkingHome => "halted; walking home…".into(),
        EventJson::Activated { .. } => return None,
        EventJson::Failed { error } => format!("stopped without a result: {error}"),
        EventJson::Checked { outcome, .. } if outcome == "failed" => {
            "the check could not be made (see below)".into()
        }
        EventJson::Checked { .. } => return None,
        EventJson::Stored { .. }
        | EventJson::Provisional { .. }
        | EventJson::GroundSeen { .. }
        | EventJson::Heartbeat => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    /// The time left comes from the poses' measured durations.
    #[test]
    fn time_left_follows_the_poses_measured_durations() {
        let t0 = Instant::now();
        let mut status = Status {
            state: RunState::Running,
            clock: Some(RunClock::start(t0)),
            ..Status::default()
        };
        let at = |s| t0 + Duration::from_secs(s);
        let moving = |index| EventJson::Moving {
            index,
            of: 10,
            motion: "body at 600 mm".into(),
            commanded: PoseDegMm::from_values([0.0, 0.0, 0.0, 0.0, 600.0, 0.0]),
        };
        status.apply_at(&moving(1), at(5));
        assert_eq!(status.at(at(6)).remaining_s, None, "no pose done yet");
        assert!(status.step.starts_with("pose 1 of 10: moving the body"));
        assert_eq!(status.phase, Some(Phase::Moving));
        assert_eq!(status.commanded.map(|c| c.py_mm), Some(600.0));
        for index in 1..=4u16 {
            let done = EventJson::PoseDone {
                index,
                of: 10,
                ok: true,
                inliers: Some(100),
                plane: None,
                error: None,
            };
            status.apply_at(&done, at(5 + 3 * u64::from(index)));
        }
        let shown = status.at(at(20));
        assert_eq!(shown.elapsed_s, Some(20.0));
        // 4 poses in 12 s: 3 s each, 6 left and one for home and the solve.
        assert_eq!(shown.remaining_s, Some(21.0));
        assert_eq!(shown.step, "pose 4 of 10: ground found");
    }
}
