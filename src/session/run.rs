//! The session's steps (see the module documentation for the order and why).

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

/// Watches the session's own thread for a stall: a loop that wakes every
/// [`StallWatch::PERIOD`] and notes when it did. A gap longer than the plan's
/// limit means the process was stopped or starved; the run must not simply go
/// on from where it was (the robot may have been halted by its watchdog, and
/// an Abort pressed meanwhile could not arrive). The session asks
/// [`StallWatch::check`] before every motion it commands, so that a command
/// queued before the stall is not sent after it, whichever of the two runs
/// first when the thread resumes.
struct StallWatch {
    limit: Duration,
    last: std::cell::Cell<std::time::Instant>,
}

impl StallWatch {
    const PERIOD: Duration = Duration::from_millis(100);

    fn new(limit: Duration) -> Self {
        Self {
            limit,
            last: std::cell::Cell::new(std::time::Instant::now()),
        }
    }

    /// Why the run must end, when the thread stalled longer than the limit.
    fn stalled(&self) -> Option<String> {
        let gap = self.last.get().elapsed();
        (gap > self.limit).then(|| {
            format!(
                "the service stalled for {:.1} s (more than {:.1} s): the run does not go on from where it stopped",
                gap.as_secs_f64(),
                self.limit.as_secs_f64()
            )
        })
    }

    /// Before a command that moves the robot.
    fn check(&self) -> Result<(), SessionError> {
        match self.stalled() {
            Some(why) => Err(SessionError::Aborted(why)),
            None => Ok(()),
        }
    }

    /// Completes, with the reason, when the thread has stalled.
    async fn watch(&self) -> String {
        loop {
            tokio::time::sleep(Self::PERIOD).await;
            if let Some(why) = self.stalled() {
                return why;
            }
            self.last.set(std::time::Instant::now());
        }
    }
}

fn send(events: &UnboundedSender<Event>, event: Event) {
    // Nobody listening is not an error: progress is for the operator.
    let _ = events.send(event);
}

fn millis(d: Duration) -> u32 {
    d.as_millis().min(u128::from(u32::MAX)) as u32
}

/// Polls the body's state until `done` holds, failing on a fault, a halt
/// nobody asked for, or the deadline. Polling every `plan.poll` (≤ 200 ms)
/// also feeds the lower computer's watchdog.
async fn wait_for<C: BodyController>(
    controller: &mut C,
    plan: &Plan,
    deadline: Duration,
    what: &str,
    done: impl Fn(&BodyState) -> bool,
) -> Result<BodyState, SessionError> {
    let start = Instant::now();
    loop {
        let state = controller.state().await.map_err(SessionError::robot)?;
        if done(&state) {
            return Ok(state);
        }
        match state.state {
            MotionState::Fault(code) => {
                return Err(SessionError::Robot {
                    kind: ErrorKind::Refused,
                    message: format!("fault {code} while waiting for {what}"),
                })
            }
            MotionState::Halted => {
                return Err(SessionError::Robot {
                    kind: ErrorKind::Refused,
                    message: format!("the body halted while waiting for {what} (the lower computer's watchdog or its operator)"),
                })
            }
            _ => {}
        }
        if start.elapsed() > deadline {
            return Err(SessionError::Robot {
                kind: ErrorKind::Timeout,
                message: format!(
                    "{what} did not happen within {:.1} s",
                    deadline.as_secs_f64()
                ),
            });
        }
        tokio::time::sleep(plan.poll).await;
    }
}

/// Writes a pose's frames and then its line to the recording on a blocking
/// worker (files and fsync: slow on an SD card, and the session's runtime
/// also drives the UDP link and the watchdog heartbeat); returns the writer.
async fn record_pose(
    mut writer: RecordingWriter,
    frames: &[DepthFrame],
    tilt_states: &[TiltState],
    mut record: PoseRecord,
) -> Result<RecordingWriter, SessionError> {
    // Stamped as fakenect-record stamps them, with the last frame's
    // timestamp; a tenth of a millisecond apart, after that frame.
    let (last_time, last_timestamp) = frames.last().map_or((0.0, 0), |f| (f.time_s, f.timestamp));
    let readings: Vec<(f64, RawTiltState)> = tilt_states
        .iter()
        .enumerate()
        .map(|(k, s)| {
            (
                last_time + (k + 1) as f64 * 1e-4,
                RawTiltState::from_state(s),
            )
        })
        .collect();
    let images: Vec<(f64, u32, DepthImage)> = frames
        .iter()
        .map(|f| {
            let image = DepthImage {
                width: f.width,
                height: f.height,
                pixels: f.raw.clone(),
            };
            (f.time_s, f.timestamp, image)
        })
        .collect();
    let written = tokio::task::spawn_blocking(move || {
        let result = images
            .iter()
            .map(|(time_s, timestamp, image)| writer.write_depth_frame(*time_s, *timestamp, image))
            .collect::<Result<Vec<String>, WriteError>>()
            .and_then(|names| {
                record.depth_frames = names;
                record.accelerometer = readings
                    .iter()
                    .map(|(time_s, state)| writer.write_tilt_state(*time_s, last_timestamp, state))
                    .collect::<Result<Vec<String>, WriteError>>()?;
                writer.write_pose(&record)
            });
        (writer, result)
    })
    .await;
    match written {
        Ok((writer, Ok(()))) => Ok(writer),
        Ok((_, Err(e))) => Err(e.into()),
        Err(e) => Err(SessionError::Recording(format!("the writer failed: {e}"))),
    }
}

/// Most frames a calibration keeps for a second fit of the ground (about
/// 0.2 MB each, compressed: 130 MB; the robot's 52 poses of 3 frames keep
/// 156, about 33 MB).
const MOST_KEPT_FRAMES: usize = 600;

/// A pose whose ground is being fitted on a worker thread.
struct PendingFit {
    index: u16,
    /// The body pose from the feet, when they fixed it.
    ground_from_robot: Option<Transform>,
    gravity: Option<GravityReading>,
    /// The body pose, for a second fit of the frames.
    body: Option<BodyEstimate>,
    handle: JoinHandle<(Result<Observation, String>, Option<KeptFrames>)>,
    /// The fit's outcome once it has been awaited (a handle is awaited once).
    done: Option<Result<Observation, String>>,
    /// The frames, kept for a second fit when calibrating.
    frames: Option<KeptFrames>,
}

impl PendingFit {
    async fn outcome(&mut self) -> &Result<Observation, String> {
        if self.done.is_none() {
            let outcome = match (&mut self.handle).await {
                Ok((outcome, frames)) => {
                    self.frames = frames;
                    outcome
                }
                Err(e) => Err(format!("the fit failed: {e}")),
            };
            self.done = Some(outcome);
        }
        self.done
            .get_or_insert_with(|| Err("the fit was lost".into()))
    }
}

/// Fits the ground of a pose from its frames (on a blocking worker), and
/// shows what the camera saw with the ground it chose.
fn fit_pose(
    processor: Arc<PoseObserver>,
    index: u16,
    body: BodyEstimate,
    frames: Vec<DepthFrame>,
    events: UnboundedSender<Event>,
    keep_frames: bool,
) -> (Result<Observation, String>, Option<KeptFrames>) {
    let raw: Vec<&[u16]> = frames.iter().map(|f| f.raw.as_slice()).collect();
    let fitted = processor
        .observe_with_fit(u32::from(index), &body, &raw, &mut FitBuffers::default())
        .map_err(|e| format!("no ground found: {e}"));
    if let Some(frame) = raw.first() {
        let fit = fitted.as_ref().map(|(_, fit)| fit).map_err(String::as_str);
        let view = GroundView::of(frame, processor.camera(), fit);
        send(
            &events,
            Event::GroundSeen {
                index: Some(index),
                view: Box::new(view),
            },
        );
    }
    let kept = (keep_frames && fitted.is_ok()).then(|| KeptFrames::keep(&frames));
    (fitted.map(|(observation, _)| observation), kept)
}

/// The fewest fitted poses a provisional solve is tried on: below that the
/// six parameters are not all observable by any schedule.
const PROVISIONAL_MIN_POSES: usize = 6;

/// Solves over the poses fitted so far and reports θ and e_d per pose (about
/// a millisecond for 52 poses; a schedule that does not pin every parameter
/// down yet gives nothing).
fn report_provisional(pending: &[PendingFit], plan: &Plan, events: &UnboundedSender<Event>) {
    let observations: Vec<Observation> = pending
        .iter()
        .filter_map(|fit| fit.done.as_ref()?.as_ref().ok().cloned())
        .collect();
    if observations.len() < PROVISIONAL_MIN_POSES {
        return;
    }
    let Ok(calibration) = crate::calib::solve::solve(&observations, &plan.calibration.solve) else {
        return;
    };
    let poses = calibration
        .poses
        .iter()
        .map(|p| ProvisionalPose {
            index: u16::try_from(p.index).unwrap_or(u16::MAX),
            theta_deg: p.theta.to_degrees(),
            e_d_mm: p.e_d * 1000.0,
            used: p.used,
        })
        .collect();
    send(events, Event::Provisional { poses });
}

/// Reports the fits that have finished, in pose order; after new ones
/// (while poses are still being visited), a provisional solve.
async fn report_finished(
    pending: &mut [PendingFit],
    reported: &mut usize,
    of: usize,
    events: &UnboundedSender<Event>,
    all: bool,
    plan: &Plan,
) {
    let before = *reported;
    while let Some(fit) = pending.get_mut(*reported) {
        if !all && !fit.handle.is_finished() {
            break;
        }
        let outcome = match fit.outcome().await {
            Ok(o) => Ok(PoseFit {
                inliers: o.inliers.unwrap_or(0),
                plane: [
                    o.plane.normal.x,
                    o.plane.normal.y,
                    o.plane.normal.z,
                    o.plane.d,
                ],
            }),
            Err(e) => Err(e.clone()),
        };
        send(
            events,
            Event::PoseDone {
                index: fit.index,
                of,
                outcome,
            },
        );
        *reported += 1;
    }
    if !all && *reported > before && plan.calibrating {
        report_provisional(pending, plan, events);
    }
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
    let mut writer = match &plan.record {
        Some(dir) => Some(RecordingWriter::create(
            dir,
            &Session {
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
            },
        )?),
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
        Some(w) => Some(w.finish()?),
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

/// What visiting the poses gave.
struct Visited {
    /// The lower computer's firmware, as its WELCOME said.
    firmware: String,
    poses: Vec<VisitedPose>,
    /// Per pose that gave a plane when calibrating: its place in `poses`,
    /// its body pose and its frames, for a second fit.
    kept: Vec<(usize, BodyEstimate, KeptFrames)>,
    /// What fitted the poses.
    processor: Arc<PoseObserver>,
    /// Poses in the schedule.
    of: usize,
    prior_note: Option<String>,
    recording: Option<PathBuf>,
}

/// The calibration's end: the solve, the verdict, the motor's steadiness.
fn solve_visited(
    mut visited: Visited,
    plan: &Plan,
    events: &UnboundedSender<Event>,
) -> SessionOutcome {
    let (observations, failed) = VisitedPose::fits(&visited.poses);
    let mut result = ResultJson::from_poses(
        &observations,
        &failed,
        visited.of,
        &plan.calibration,
        plan.tilt_deg,
    );
    // A pattern the fit's band cut: the kept frames fitted again about it,
    // as `replay` fits a recording's.
    let again = result.fit_about_the_pattern(|taken_out| {
        let observer = (*visited.processor)
            .clone()
            .with_depth_correction(taken_out);
        let mut poses = visited.poses.clone();
        let refits: Vec<(usize, Result<Observation, String>)> = visited
            .kept
            .par_iter()
            .map(|(at, body, kept)| {
                let fit = match kept.frames() {
                    Some(frames) => {
                        let frames: Vec<&[u16]> = frames.iter().map(Vec::as_slice).collect();
                        observer
                            .observe(poses[*at].index, body, &frames, &mut FitBuffers::default())
                            .map_err(|e| format!("no ground found: {e}"))
                    }
                    None => Err("its frames could not be restored for the second fit".into()),
                };
                (*at, fit)
            })
            .collect();
        for (at, fit) in refits {
            poses[at].fit = fit;
        }
        let (observations, failed) = VisitedPose::fits(&poses);
        let result = ResultJson::from_poses_taken_out(
            &observations,
            &failed,
            visited.of,
            &plan.calibration,
            plan.tilt_deg,
            Some(taken_out),
        );
        Ok::<_, std::convert::Infallible>((result, poses))
    });
    if let Ok(Some((second, poses))) = again {
        (result, visited.poses) = (second, poses);
    } else if visited.kept.is_empty() && result.pattern_to_fit_about().is_some() {
        result.notes.push(format!(
            "the depth pattern reaches beyond the ground fit's band, but this session kept no frames to fit again about it (more than {MOST_KEPT_FRAMES} frames): `groundcal replay` of its recording fits them again"
        ));
    }
    if let Some(note) = visited.prior_note {
        result.notes.insert(0, note);
    }
    result.predicted_sigma = predicted_sigma(plan);
    result.robot = Some(crate::formats::output::RobotJson {
        name: plan.robot_name.clone(),
        firmware: Some(visited.firmware.clone()),
    });
    crate::solving::verify::judge_motor(&mut result, &visited.poses, plan.tilt_deg, &plan.verify);
    send(
        events,
        Event::Finished {
            accepted: result.accepted(),
        },
    );
    SessionOutcome {
        result,
        recording: visited.recording,
    }
}

/// A check's end: the poses against the calibration.
fn verify_visited(
    visited: Visited,
    mount: &ActiveMount,
    plan: &Plan,
    events: &UnboundedSender<Event>,
) -> Result<VerifyOutcome, SessionError> {
    let report =
        crate::solving::verify::compare(mount, &visited.poses, &plan.verify).map_err(|e| {
            SessionError::Sensor {
                kind: ErrorKind::Other,
                message: e.to_string(),
            }
        })?;
    send(
        events,
        Event::Verified {
            consistent: !report.drifted(),
        },
    );
    Ok(VerifyOutcome {
        report,
        poses: visited.poses,
        recording: visited.recording,
    })
}

/// Sends the body home and waits until it stands there; its state then
/// (the home feet).
async fn go_home<C: BodyController>(
    controller: &mut C,
    plan: &Plan,
) -> Result<BodyState, SessionError> {
    controller
        .home(millis(plan.motion))
        .await
        .map_err(SessionError::robot)?;
    wait_until_home(controller, plan).await
}

/// The body's state, when the lower computer reports it standing at its
/// home stance with no target (idle); otherwise the refusal of a session that
/// must not move it.
async fn standing_at_home<C: BodyController>(
    controller: &mut C,
) -> Result<BodyState, SessionError> {
    let state = controller.state().await.map_err(SessionError::robot)?;
    if state.state == MotionState::Idle {
        return Ok(state);
    }
    Err(SessionError::WouldMove(format!(
        "the lower computer does not report the robot standing at its home stance ({}): a check that moves nothing cannot be made now; it waits for a person to press Check",
        motion_in_words(state.state)
    )))
}

/// A motion state in an operator's words.
fn motion_in_words(state: MotionState) -> String {
    match state {
        MotionState::Idle => "at home".into(),
        MotionState::Moving => "moving".into(),
        MotionState::Settled => "holding a pose away from home".into(),
        MotionState::Halted => "halted where it stood".into(),
        MotionState::Fault(code) => format!("fault {code}"),
    }
}

/// Whether the Kinect's motor already stands at the plan's tilt (within a
/// degree), for a session that must not turn it.
async fn motor_at_tilt<S: DepthSensor>(sensor: &mut S, plan: &Plan) -> Result<(), SessionError> {
    let reading = tokio::time::timeout(plan.sensor_timeout, sensor.tilt_state()).await;
    let tilt_deg = match reading {
        Ok(Ok(state)) => state.tilt_deg,
        Ok(Err(e)) => {
            return Err(SessionError::WouldMove(format!(
                "the Kinect's motor angle cannot be read ({e}): a check that turns nothing cannot tell whether it stands at the calibration's {:.1}°; it waits for a person to press Check",
                plan.tilt_deg
            )))
        }
        Err(_) => {
            return Err(SessionError::Sensor {
                kind: ErrorKind::Timeout,
                message: format!(
                    "the tilt motor: no answer from the depth sensor in {} s",
                    plan.sensor_timeout.as_secs_f64()
                ),
            })
        }
    };
    if (tilt_deg - plan.tilt_deg).abs() > 1.0 {
        return Err(SessionError::WouldMove(format!(
            "the Kinect's motor stands at {tilt_deg:.1}°, the calibration's tilt is {:.1}°: turning it waits for a person to press Check",
            plan.tilt_deg
        )));
    }
    Ok(())
}

/// Waits until the body reports the home stance (idle).
async fn wait_until_home<C: BodyController>(
    controller: &mut C,
    plan: &Plan,
) -> Result<BodyState, SessionError> {
    wait_for(
        controller,
        plan,
        plan.motion_deadline(plan.motion),
        "the home stance",
        |s| s.state == MotionState::Idle,
    )
    .await
}

/// A call to the depth sensor, bounded by `plan.sensor_timeout`: a device
/// that stops answering fails the session (which halts the robot and sends
/// it home) instead of hanging it.
async fn bounded<T, E: groundcal_hal::Error>(
    plan: &Plan,
    what: &str,
    call: impl Future<Output = Result<T, E>>,
) -> Result<T, SessionError> {
    match tokio::time::timeout(plan.sensor_timeout, call).await {
        Ok(answer) => answer.map_err(SessionError::sensor),
        Err(_) => Err(SessionError::Sensor {
            kind: ErrorKind::Timeout,
            message: format!(
                "{what}: no answer from the depth sensor in {} s",
                plan.sensor_timeout.as_secs_f64()
            ),
        }),
    }
}

/// A pose's frames. A frame whose size is not the sensor's is corrupt and
/// skipped; more than [`MAX_CORRUPT_FRAMES`] of them at one pose fail the
/// session, as a stalled stream does.
async fn capture<S: DepthSensor>(
    sensor: &mut S,
    plan: &Plan,
    index: u16,
    frame_count: usize,
    info: &SensorInfo,
) -> Result<Vec<DepthFrame>, SessionError> {
    let (width, height) = (info.intrinsics.width, info.intrinsics.height);
    let mut frames = Vec::with_capacity(frame_count);
    let mut corrupt = 0;
    while frames.len() < frame_count {
        let frame = bounded(
            plan,
            &format!("pose {index}: waiting for a depth frame"),
            sensor.next_frame(),
        )
        .await?;
        if frame.width == width && frame.height == height && frame.raw.len() == width * height {
            frames.push(frame);
            continue;
        }
        corrupt += 1;
        let what = format!(
            "a corrupt depth frame at pose {index}: {}×{} with {} values, where the sensor gives {width}×{height}",
            frame.width,
            frame.height,
            frame.raw.len()
        );
        if corrupt > MAX_CORRUPT_FRAMES {
            return Err(SessionError::Sensor {
                kind: ErrorKind::Protocol,
                message: format!("{corrupt} corrupt frames at pose {index}; the last was {what}"),
            });
        }
        tracing::warn!("{what}; skipped");
    }
    Ok(frames)
}

/// A pose's accelerometer readings, after its frames. A sensor that has
/// none (a recording made without) gives none; one that stops answering
/// fails the session, as a stalled stream does.
async fn read_accelerometer<S: DepthSensor>(
    sensor: &mut S,
    plan: &Plan,
    index: u16,
) -> Result<Vec<TiltState>, SessionError> {
    let mut states = Vec::with_capacity(plan.accelerometer_readings);
    for _ in 0..plan.accelerometer_readings {
        match tokio::time::timeout(plan.sensor_timeout, sensor.tilt_state()).await {
            Ok(Ok(state)) => states.push(state),
            Ok(Err(e)) => {
                tracing::debug!("pose {index}: no accelerometer reading: {e}");
                break;
            }
            Err(_) => {
                return Err(SessionError::Sensor {
                    kind: ErrorKind::Timeout,
                    message: format!(
                        "pose {index}: the accelerometer: no answer from the depth sensor in {} s",
                        plan.sensor_timeout.as_secs_f64()
                    ),
                })
            }
        }
    }
    Ok(states)
}

/// Corrupt frames skipped at one pose before the session fails.
const MAX_CORRUPT_FRAMES: usize = 3;

/// Halts the body, then sends it home and waits until it is there. A lower
/// computer that does not answer (the link is down) is tried again, every
/// half second for `plan.link_recovery`: its own watchdog has halted the body
/// meanwhile, and once the link returns the body is sent home. Returns a
/// description of how the robot was left.
async fn stop_safely<C: BodyController>(
    controller: &mut C,
    plan: &Plan,
    events: &UnboundedSender<Event>,
) -> (RobotLeft, String) {
    let deadline = tokio::time::Instant::now() + plan.link_recovery;
    let mut retries = 0u32;
    let halted = loop {
        match controller.halt().await {
            Ok(()) => break Ok(()),
            Err(e) if link_down(&e) && tokio::time::Instant::now() < deadline => {
                retries += 1;
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
            Err(e) => break Err(e),
        }
    };
    if let Err(e) = halted {
        return (
            RobotLeft::Unknown,
            format!("could not halt the robot ({e}); check it"),
        );
    }
    let after = if retries > 0 {
        format!(" (the link came back after {retries} more tries)")
    } else {
        String::new()
    };
    send(events, Event::WalkingHome);
    if let Err(e) = controller.home(millis(plan.motion)).await {
        return (
            RobotLeft::Halted,
            format!("halted{after}, but could not send it home ({e})"),
        );
    }
    match wait_until_home(controller, plan).await {
        Ok(_) => (
            RobotLeft::Home,
            format!("halted and sent home{after}; it stands at the home stance"),
        ),
        Err(e) => (
            RobotLeft::Halted,
            format!("halted and sent home{after}, but it did not report the home stance: {e}"),
        ),
    }
}

/// Whether an error says the lower computer did not answer (and may again).
fn link_down<E: groundcal_hal::Error>(e: &E) -> bool {
    matches!(e.kind(), ErrorKind::Timeout | ErrorKind::LinkLost)
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

/// The σ `groundcal plan` predicts for the plan's schedule, with the depth
/// scale's when it will be estimated (None without a nominal mount, or for a
/// schedule the prediction cannot solve).
fn predicted_sigma(plan: &Plan) -> Option<crate::formats::output::SigmaJson> {
    let nominal = plan.nominal_mount?.pose().to_params();
    let poses: Vec<_> = plan.schedule.poses.iter().map(|p| p.to_params()).collect();
    let prediction = crate::calib::plan::predict_schedule_with(
        &poses,
        &nominal,
        &plan.noise,
        plan.calibration.solve.depth_scale,
    )
    .ok()?;
    if !prediction.observability.problems.is_empty() {
        return None;
    }
    let mut sigma = crate::formats::output::SigmaJson::from_radians_metres(&prediction.sigma());
    sigma.depth_scale = prediction.depth_scale.sigma;
    Some(sigma)
}
