//! The session's steps (see the module documentation for the order and why).

mod capture;
mod fits;
mod motion;

use std::future::Future;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use groundcal_hal::{
    BodyController, BodyState, DepthFrame, DepthSensor, ErrorKind, Led, MotionState, SensorInfo,
    TiltState,
};
use tokio::sync::mpsc::UnboundedSender;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use super::kept_frames::KeptFrames;
use super::{Event, GravityReading, Plan, PoseFit, ProvisionalPose, RobotLeft, VisitedPose};
use crate::calib::geometry::Transform;
use crate::calib::ground_view::GroundView;
use crate::calib::observe::{BodyEstimate, PoseObserver};
use crate::calib::plane::FitBuffers;
use crate::calib::solve::Observation;
use crate::calib::verify::{ActiveMount, VerifyReport};
use crate::formats::depth_image::DepthImage;
use crate::formats::output::ResultJson;
use crate::formats::recording::dump::RawTiltState;
use crate::formats::recording::poses::PoseRecord;
use crate::formats::recording::session::{Home, KinectInfo, Session};
use crate::formats::recording::writer::{RecordingWriter, WriteError};
use crate::setup::schedule::Limits;
use rayon::prelude::*;

use capture::*;
use fits::*;
use motion::*;

/// How a session ended when it produced a result.
#[derive(Debug, Clone)]
pub struct SessionOutcome {
    pub result: ResultJson,
    /// The recording written, if one was asked for.
    pub recording: Option<PathBuf>,
}

/// How a check of a calibration (`verify`) ended.
#[derive(Debug, Clone)]
pub struct VerifyOutcome {
    pub report: VerifyReport,
    /// The poses visited, as measured.
    pub poses: Vec<VisitedPose>,
    pub recording: Option<PathBuf>,
}

/// Why a session produced no result. In every case the robot was halted and
/// sent home before this is returned (as far as the link allowed).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SessionError {
    /// The schedule was refused before anything moved.
    #[error("{0}")]
    Refused(String),
    /// The depth sensor failed.
    #[error("depth sensor: {message}")]
    Sensor { kind: ErrorKind, message: String },
    /// The lower computer failed, refused, or the link was lost.
    #[error("lower computer: {message}")]
    Robot { kind: ErrorKind, message: String },
    /// The recording could not be written.
    #[error("recording: {0}")]
    Recording(String),
    /// The operator or a signal stopped the session.
    #[error("aborted: {0}")]
    Aborted(String),
    /// A session that must not move anything ([`Plan::stand_still`]) would
    /// have had to: nothing was commanded.
    #[error("{0}")]
    WouldMove(String),
}

impl SessionError {
    /// Why the session stopped, for an `Aborted` event (which says "aborted"
    /// itself): an operator's or a signal's reason as given.
    fn cause(&self) -> String {
        match self {
            SessionError::Aborted(reason) => reason.clone(),
            other => other.to_string(),
        }
    }

    fn robot<E: groundcal_hal::Error>(e: E) -> Self {
        SessionError::Robot {
            kind: e.kind(),
            message: e.to_string(),
        }
    }

    fn sensor<E: groundcal_hal::Error>(e: E) -> Self {
        SessionError::Sensor {
            kind: e.kind(),
            message: e.to_string(),
        }
    }
}

impl From<WriteError> for SessionError {
    fn from(e: WriteError) -> Self {
        SessionError::Recording(e.to_string())
    }
}

fn send(events: &UnboundedSender<Event>, event: Event) {
    // Nobody listening is not an error: progress is for the operator.
    let _ = events.send(event);
}

fn millis(d: Duration) -> u32 {
    d.as_millis().min(u128::from(u32::MAX)) as u32
}

/// Visits every pose of the schedule: the checks, HELLO, home, then per pose
/// move, settle, capture and hand the frames to a fit; then home and the
/// solve. Any error returns at once: the caller halts the robot and sends it
/// home.
async fn visit_poses<S: DepthSensor, C: BodyController>(
    sensor: &mut S,
    controller: &mut C,
    plan: &Plan,
    events: &UnboundedSender<Event>,
    pending: &mut Vec<PendingFit>,
    stall: &StallWatch,
) -> Result<Visited, SessionError> {
    let schedule = &plan.schedule;
    let of = schedule.poses.len();
    // 1. The schedule, against our limits, then the lower computer's.
    let validate = |limits: &Limits| {
        if plan.calibrating {
            schedule.validate(limits)
        } else {
            schedule.validate_limits(limits)
        }
    };
    validate(&plan.limits).map_err(|e| SessionError::Refused(e.to_string()))?;
    let welcome = controller.hello().await.map_err(SessionError::robot)?;
    let theirs = Limits {
        max_tilt_deg: welcome.limits.max_tilt_deg,
        min_height_mm: welcome.limits.min_height_mm,
        max_height_mm: welcome.limits.max_height_mm,
        max_shift_mm: welcome.limits.max_shift_mm,
    };
    validate(&plan.limits.intersect(&theirs)).map_err(|e| {
        SessionError::Refused(format!(
            "{e} (limits of the lower computer, firmware {})",
            welcome.firmware
        ))
    })?;
    send(
        events,
        Event::Started {
            poses: of,
            schedule: schedule.name.clone(),
        },
    );
    send(
        events,
        Event::Connected {
            firmware: welcome.firmware.clone(),
        },
    );

    // 2. Home stance and its feet; the Kinect tilted and still. A session
    // that must not move takes the stance and the tilt as they are, or none.
    let home = if plan.stand_still {
        standing_at_home(controller).await?
    } else {
        stall.check()?;
        go_home(controller, plan).await?
    };
    send(events, Event::AtHome);
    if plan.stand_still {
        motor_at_tilt(sensor, plan).await?;
    } else {
        bounded(plan, "tilting the Kinect", sensor.set_tilt(plan.tilt_deg)).await?;
    }
    let _ = bounded(plan, "the LED", sensor.set_led(Led::BlinkGreen)).await;
    send(
        events,
        Event::SensorReady {
            tilt_deg: plan.tilt_deg,
        },
    );

    let info = sensor.info();
    let home_feet: Vec<[f64; 3]> = home.feet_mm.to_vec();
    let processor = Arc::new(
        PoseObserver::new(
            info.depth_model,
            info.intrinsics,
            &home_feet,
            plan.nominal_mount,
            plan.pose,
        )
        .map(|observer| match &plan.depth_correction {
            Some(correction) => observer.with_depth_correction(correction),
            None => observer,
        })
        .map_err(|e| SessionError::Robot {
            kind: ErrorKind::Protocol,
            message: format!("home feet: {e}"),
        })?,
    );
    let mut feet = processor.feet_tracker();
    // Created and finished on the blocking pool (directories and fsync: a
    // busy disk must not hold up the session's thread and its stall watch).
    let mut writer = match plan.record.clone() {
        Some(dir) => {
            let session = Session {
                format: "groundcal-recording".into(),
                version: 1,
                // The robot's name when it has one (recording.md's
                // "octopus"), else what its lower computer calls itself.
                robot: plan
                    .robot_name
                    .clone()
                    .unwrap_or_else(|| welcome.firmware.clone()),
                home: Home {
                    commanded: schedule.home,
                    feet_body_mm: home_feet.clone(),
                },
                kinect: KinectInfo {
                    tilt_deg: plan.tilt_deg,
                    depth_model: info.depth_model,
                    intrinsics: info.intrinsics,
                },
                frames_per_pose: Some(plan.frames_per_pose as u32),
                schedule: Some(schedule.name.clone()),
                nominal_mount: plan.nominal_mount,
                gates: Some(plan.calibration.gates),
                noise: Some(plan.noise),
            };
            Some(writing(move || RecordingWriter::create(&dir, &session)).await?)
        }
        None => None,
    };

    // 3. The poses. Their frames are kept for a second fit when
    // calibrating, within a bound on memory.
    let frames_total: usize = (0..schedule.poses.len()).map(|k| plan.frames_at(k)).sum();
    let keeping = plan.calibrating && frames_total <= MOST_KEPT_FRAMES;
    if plan.calibrating && !keeping {
        tracing::warn!(
            frames_total,
            "more frames than are kept for a second fit of the ground: a depth pattern beyond the fit's band will not be fitted about"
        );
    }
    let mut reported = 0;
    for (k, commanded) in schedule.poses.iter().enumerate() {
        let index = plan.pose_id(k);
        let frame_count = plan.frames_at(k);
        send(
            events,
            Event::Moving {
                index,
                of,
                commanded: *commanded,
            },
        );
        // The stance it stands in, for a session that must not move.
        let still = if plan.stand_still {
            Some(standing_at_home(controller).await?)
        } else {
            stall.check()?;
            controller
                .set_pose(index, commanded, millis(plan.motion))
                .await
                .map_err(SessionError::robot)?;
            wait_for(
                controller,
                plan,
                plan.motion_deadline(plan.motion),
                &format!("pose {index}"),
                |s| s.state == MotionState::Settled && s.pose_id == index,
            )
            .await?;
            tokio::time::sleep(plan.settle).await;
            None
        };
        // The feet once the body has been still for the settle delay; never
        // feet reported before it settled (hexapod-udp.md).
        let settled = match still {
            Some(state) => state,
            None => controller.state().await.map_err(SessionError::robot)?,
        };
        if still.is_none() && (settled.state != MotionState::Settled || settled.pose_id != index) {
            return Err(SessionError::Robot {
                kind: ErrorKind::Protocol,
                message: format!(
                    "the body left pose {index} before its frames were captured ({:?})",
                    settled.state
                ),
            });
        }
        send(events, Event::Capturing { index, of });
        sensor.begin_pose(index);
        let frames = capture(sensor, plan, index, frame_count, &info).await?;
        let tilt_states = read_accelerometer(sensor, plan, index).await?;
        let feet_mm: Vec<[f64; 3]> = settled.feet_mm.to_vec();
        if let Some(w) = writer.take() {
            let record = PoseRecord {
                index: u32::from(index),
                commanded: *commanded,
                feet_body_mm: feet_mm.clone(),
                depth_frames: Vec::new(),
                accelerometer: Vec::new(),
                line: 0,
            };
            writer = Some(record_pose(w, &frames, &tilt_states, record).await?);
        }
        let mut ground_from_robot = None;
        let mut kept_body = None;
        let fit = match feet.body_pose(commanded, &feet_mm) {
            Ok(body) => {
                ground_from_robot = Some(body.ground_from_robot);
                kept_body = keeping.then(|| body.clone());
                let processor = Arc::clone(&processor);
                let events = events.clone();
                let keep_frames = keeping;
                tokio::task::spawn_blocking(move || {
                    fit_pose(processor, index, body, frames, events, keep_frames)
                })
            }
            Err(e) => {
                let reason = format!("feet: {e}");
                tokio::task::spawn_blocking(move || (Err(reason), None))
            }
        };
        pending.push(PendingFit {
            index,
            ground_from_robot,
            gravity: GravityReading::from_states(&tilt_states),
            body: kept_body,
            handle: fit,
            done: None,
            frames: None,
        });
        report_finished(pending, &mut reported, of, events, false, plan).await;
    }

    // 4. Home; the fits finish.
    if !plan.stand_still {
        stall.check()?;
        go_home(controller, plan).await?;
    }
    let _ = bounded(plan, "the LED", sensor.set_led(Led::Green)).await;
    if plan.calibrating {
        send(events, Event::Solving);
    }
    report_finished(pending, &mut reported, of, events, true, plan).await;
    let mut poses = Vec::with_capacity(pending.len());
    let mut kept = Vec::new();
    for mut fit in pending.drain(..) {
        let outcome = fit.outcome().await.clone();
        if let (Some(body), Some(frames)) = (fit.body.take(), fit.frames.take()) {
            kept.push((poses.len(), body, frames));
        }
        poses.push(VisitedPose {
            index: u32::from(fit.index),
            ground_from_robot: fit.ground_from_robot,
            fit: outcome,
            gravity: fit.gravity,
        });
    }
    tracing::debug!(
        poses = kept.len(),
        bytes = kept
            .iter()
            .map(|(_, _, frames)| frames.size())
            .sum::<usize>(),
        "frames kept for a second fit"
    );
    let recording = match writer {
        Some(w) => Some(writing(move || w.finish()).await?),
        None => None,
    };
    Ok(Visited {
        poses,
        kept,
        prior_note: processor.prior_note(),
        processor,
        of,
        recording,
        firmware: welcome.firmware.clone(),
    })
}

/// Runs a calibration session. `abort` completes (with a reason) when the
/// operator or a signal stops the session; the robot is then halted and sent
/// home, as after any failure.
pub async fn run<S: DepthSensor, C: BodyController>(
    sensor: &mut S,
    controller: &mut C,
    plan: &Plan,
    events: &UnboundedSender<Event>,
    abort: impl Future<Output = String>,
) -> Result<SessionOutcome, SessionError> {
    let visited = guarded(sensor, controller, plan, events, abort).await?;
    // The solve, and a second fit of the frames if it needs one, take a
    // fraction of a second of every core: off the runtime's threads.
    let (plan, events) = (plan.clone(), events.clone());
    tokio::task::spawn_blocking(move || solve_visited(visited, &plan, &events))
        .await
        .map_err(|e| SessionError::Sensor {
            kind: ErrorKind::Other,
            message: format!("the solve failed: {e}"),
        })
}

/// Runs a check of `mount` (`groundcal verify`): the plan's schedule is the
/// still stance and any tilted poses; the poses are then compared with the
/// calibration instead of solved. Aborts and failures as [`run`].
pub async fn verify<S: DepthSensor, C: BodyController>(
    sensor: &mut S,
    controller: &mut C,
    plan: &Plan,
    events: &UnboundedSender<Event>,
    abort: impl Future<Output = String>,
    mount: &ActiveMount,
) -> Result<VerifyOutcome, SessionError> {
    let visited = guarded(sensor, controller, plan, events, abort).await?;
    verify_visited(visited, mount, plan, events)
}

/// Visits the poses; on an abort or a failure halts the robot and sends it
/// home before returning the error.
async fn guarded<S: DepthSensor, C: BodyController>(
    sensor: &mut S,
    controller: &mut C,
    plan: &Plan,
    events: &UnboundedSender<Event>,
    abort: impl Future<Output = String>,
) -> Result<Visited, SessionError> {
    let mut pending = Vec::new();
    let stall = StallWatch::new(plan.stall_limit);
    let outcome = {
        let work = visit_poses(sensor, controller, plan, events, &mut pending, &stall);
        tokio::pin!(work);
        // A stall is looked at first: after one, the run ends as aborted
        // before anything else it was waiting for goes on.
        tokio::select! {
            biased;
            reason = stall.watch() => Err(SessionError::Aborted(reason)),
            reason = abort => Err(SessionError::Aborted(reason)),
            outcome = &mut work => outcome,
        }
    };
    match outcome {
        Ok(o) => Ok(o),
        Err(e @ (SessionError::Refused(_) | SessionError::WouldMove(_))) => {
            // Nothing moved: nothing to stop.
            send(
                events,
                Event::Aborted {
                    reason: e.cause(),
                    robot_left: RobotLeft::NotMoved,
                },
            );
            Err(e)
        }
        Err(e) if plan.stand_still => {
            // Nothing was commanded to move: nothing to halt or send home.
            for fit in pending {
                fit.handle.abort();
            }
            send(
                events,
                Event::Aborted {
                    reason: format!("{}; nothing was moved", e.cause()),
                    robot_left: RobotLeft::NotMoved,
                },
            );
            Err(e)
        }
        Err(e) => {
            send(events, Event::Halting { why: e.cause() });
            let (robot_left, left) = stop_safely(controller, plan, events).await;
            let _ = bounded(plan, "the LED", sensor.set_led(Led::Red)).await;
            for fit in pending {
                fit.handle.abort();
            }
            send(
                events,
                Event::Aborted {
                    reason: format!("{}; {left}", e.cause()),
                    robot_left,
                },
            );
            Err(e)
        }
    }
}
