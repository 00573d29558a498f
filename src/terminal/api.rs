//! What the API says: the status document and the events of the live
//! stream (docs/api.md), mirrored from the session's events.

use std::collections::VecDeque;

use serde::Serialize;
use serde_json::Value;

use crate::session::Event;

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
    /// θ and e_d per pose against the mount the poses so far give.
    Provisional {
        poses: Vec<ProvisionalPoseJson>,
    },
    Solving,
    Finished {
        accepted: bool,
    },
    Aborted {
        reason: String,
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
            Event::Moving { index, of, .. } => EventJson::Moving {
                index: *index,
                of: *of,
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
            Event::Solving => EventJson::Solving,
            Event::Finished { accepted } => EventJson::Finished {
                accepted: *accepted,
            },
            Event::Aborted { reason } => EventJson::Aborted {
                reason: reason.clone(),
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

/// What `GET /api/status` shows.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Status {
    pub state: RunState,
    /// Who started the current (or last) calibration.
    pub by: Option<String>,
    pub started: Option<String>,
    /// Pose i of N.
    pub pose: Option<u16>,
    pub of: Option<usize>,
    /// The robot's state in words (from the last event).
    pub robot: String,
    pub recent_events: VecDeque<EventJson>,
    /// The current or last result, with its store id.
    pub result: Option<Value>,
    pub result_id: Option<String>,
    /// Why the last session produced no result.
    pub error: Option<String>,
    /// A calibration the service's last stop cut off, in words (until the
    /// next one starts).
    pub interrupted: Option<String>,
    /// Whether the hardware opened when the service started, in words (it
    /// is opened again for each calibration).
    pub hardware: String,
    /// The latest provisional θ and e_d per pose of a running session (kept
    /// here rather than among the recent events: it is replaced, not added).
    pub provisional: Option<Vec<ProvisionalPoseJson>>,
}

impl Status {
    /// What an event changes in the status: the pose, the robot's state in
    /// words, the provisional charts.
    pub fn apply(&mut self, event: &EventJson) {
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
            EventJson::Moving { index, of } => {
                self.pose = Some(*index);
                self.of = Some(*of);
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
            EventJson::Aborted { reason } => self.robot = format!("aborted: {reason}"),
            EventJson::Stored { .. } | EventJson::Failed { .. } => {}
            EventJson::Provisional { poses } => self.provisional = Some(poses.clone()),
        }
    }
}
