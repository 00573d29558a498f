//! The plan of a session: everything it needs to know before the robot
//! moves, worked out from the configuration (and, for a played-back sensor, from
//! the recording). Shared by `groundcal calibrate` and the daemon.

use std::path::PathBuf;
use std::time::Duration;

use crate::calib::calibrate::CalibrationSettings;
use crate::calib::observe::ObserveSettings;
use crate::calib::plane::PlaneFitSettings;
use crate::formats::recording::session::NominalMount;
use crate::formats::recording::Recording;
use crate::setup::config::{Config, RobotAddress};
use crate::setup::schedule::{Limits, Schedule};

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
    /// The robot's name (`[robot] name`), kept with the result and the
    /// recording.
    pub robot_name: Option<String>,
    pub nominal_mount: Option<NominalMount>,
    /// The noise of one pose's ground, for the σ predicted before moving.
    pub noise: crate::calib::plan::NoiseModel,
    pub pose: ObserveSettings,
    pub calibration: CalibrationSettings,
    /// Write everything as a recording here, as it goes.
    pub record: Option<PathBuf>,
    /// GET_STATE polling while the body moves (at most 200 ms: the lower
    /// computer's watchdog).
    pub poll: Duration,
    /// How long a motion may take beyond its nominal duration.
    pub motion_slack: Duration,
    /// After a failure, how long to keep trying a lower computer that does
    /// not answer, to halt the body and send it home once the link returns.
    /// Meanwhile its own watchdog (1 s without a word) has halted the body.
    pub link_recovery: Duration,
    /// The longest the depth sensor may take to answer (a frame, the tilt,
    /// the LED) before the session fails: a stalled stream must not hang it.
    pub sensor_timeout: Duration,
    /// A calibration (true: the schedule must observe all six parameters,
    /// provisional solves feed the live charts) or a check (`verify`).
    pub calibrating: bool,
    /// The Kinect's depth pattern to take out of every frame: a check's,
    /// from the calibration it checks. A calibration finds its own.
    pub depth_correction: Option<std::sync::Arc<crate::calib::distortion::DepthCorrection>>,
    /// Accelerometer readings taken at each pose after its frames (their
    /// mean is the pose's gravity).
    pub accelerometer_readings: usize,
    /// How `verify` judges, and how steady the motor must stay.
    pub verify: crate::calib::verify::VerifySettings,
    /// For each pose of the schedule, the pose id sent and the frames
    /// captured, when they are not `1..=N` and `frames_per_pose`: a replayed
    /// recording's own, so that the session asks for what was recorded.
    pub recorded_poses: Option<Vec<RecordedPose>>,
    /// Nothing may move: no SET_POSE, HOME or HALT, and the Kinect's motor
    /// left where it is. The session reads the stance the robot already
    /// stands in, and refuses ([`super::SessionError::WouldMove`]) when the
    /// lower computer does not report it at its home stance or the motor is
    /// not at the plan's tilt. The check at the service's start, which no
    /// person asked for, is such a session.
    pub stand_still: bool,
    /// The longest the session's own thread may be stopped (SIGSTOP, a
    /// suspended machine, a starved scheduler) before the run ends as
    /// aborted when it resumes: beyond it the lower computer's watchdog (1 s)
    /// has halted a moving body, and whoever pressed Abort meanwhile could
    /// not reach the service. Real time, whatever the simulator's speed.
    pub stall_limit: Duration,
}

/// The default [`Plan::stall_limit`]: twice the lower computer's watchdog,
/// and far above any scheduling delay of a busy robot computer (the
/// session's loop wakes at least every 200 ms).
pub const STALL_LIMIT: Duration = Duration::from_secs(2);

/// A pose as a recording has it: its id and how many frames it holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordedPose {
    pub id: u16,
    pub frames: usize,
}

impl Plan {
    /// The session plan from the configuration; a played-back sensor brings its
    /// recording's schedule, pose ids, frames per pose, tilt and nominal mount
    /// (refused when a pose id does not fit the link's 16 bits).
    pub fn from_config(
        config: &Config,
        schedule: Schedule,
        replay: Option<&Recording>,
        record: Option<PathBuf>,
    ) -> Result<Plan, String> {
        let c = &config.calibration;
        // Simulated hardware runs faster than real time: so do the waits.
        let scale = match (&config.sim, &config.robot.address) {
            (Some(sim), RobotAddress::Sim) => sim.time_scale,
            _ => 1.0,
        };
        let mut plan = Plan {
            schedule,
            robot_name: config.robot.name.clone(),
            limits: config.robot.limits,
            frames_per_pose: c.frames_per_pose,
            motion: Duration::from_millis(u64::from(c.motion_ms)),
            settle: Duration::from_millis(c.settle_ms).div_f64(scale),
            tilt_deg: config.sensor.tilt_deg,
            nominal_mount: c.nominal_mount,
            noise: c
                .noise
                .unwrap_or_else(crate::calib::plan::NoiseModel::solve_floors),
            pose: ObserveSettings {
                slip_threshold_m: c.slip_threshold_mm / 1000.0,
                plane: PlaneFitSettings {
                    method: c.ground_fit,
                    ..Default::default()
                },
                ..ObserveSettings::default()
            },
            calibration: crate::calib::calibrate::CalibrationSettings {
                gates: c.gates,
                // The configured noise is what the solve assumes at least:
                // the σ it reports are then the ones `plan` predicts.
                solve: crate::calib::solve::SolveSettings {
                    depth_scale: c.depth_scale,
                    ..c.noise
                        .map_or_else(Default::default, |n| n.solve_settings())
                },
            },
            record,
            poll: Duration::from_millis(100)
                .div_f64(scale.max(1.0))
                .max(Duration::from_millis(5)),
            motion_slack: Duration::from_secs(5),
            link_recovery: Duration::from_secs(30),
            sensor_timeout: Duration::from_secs(10),
            calibrating: true,
            depth_correction: None,
            accelerometer_readings: 10,
            verify: config.verify.settings(c),
            recorded_poses: None,
            stand_still: false,
            stall_limit: STALL_LIMIT,
        };
        if let Some(recording) = replay {
            plan.schedule = Schedule {
                name: format!("replay of {}", recording.dir.display()),
                home: recording.session.home.commanded,
                poses: recording.poses.iter().map(|p| p.commanded).collect(),
                file: None,
            };
            plan.accelerometer_readings = recording
                .poses
                .iter()
                .map(|p| p.accelerometer.len())
                .max()
                .unwrap_or(0);
            plan.frames_per_pose = recording
                .poses
                .iter()
                .map(|p| p.depth_frames.len())
                .max()
                .unwrap_or(1)
                .max(1);
            let recorded = recording
                .poses
                .iter()
                .map(|p| {
                    let id = u16::try_from(p.index).map_err(|_| {
                        format!(
                            "{}: pose {} (poses.jsonl line {}): the link's pose ids stop at 65535",
                            recording.dir.display(),
                            p.index,
                            p.line
                        )
                    })?;
                    Ok(RecordedPose {
                        id,
                        frames: p.depth_frames.len(),
                    })
                })
                .collect::<Result<Vec<_>, String>>()?;
            plan.recorded_poses = Some(recorded);
            plan.tilt_deg = recording.session.kinect.tilt_deg;
            plan.nominal_mount = recording.session.nominal_mount.or(plan.nominal_mount);
        }
        Ok(plan)
    }

    /// The plan of a check (`verify`): the check's schedule, the motor at
    /// the calibration's tilt, the calibrated mount as the ground's prior,
    /// no provisional solves.
    pub fn for_check(
        config: &Config,
        schedule: Schedule,
        calibration: &crate::solving::verify::Calibration,
        record: Option<PathBuf>,
    ) -> Result<Plan, String> {
        let mut plan = Plan::from_config(config, schedule, None, record)?;
        plan.calibrating = false;
        plan.nominal_mount = Some(crate::solving::verify::ground_prior(&calibration.mount));
        plan.depth_correction = calibration.depth_correction.clone();
        plan.pose.ground_residuals = false;
        if let Some(tilt) = calibration.tilt_deg {
            plan.tilt_deg = tilt;
        }
        Ok(plan)
    }

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
