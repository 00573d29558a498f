//! Offline replay of a recording (`groundcal replay DIR`): per pose, the body
//! pose from the feet and the ground from the frames, then the solve.
//!
//! Streaming with bounded memory: a pose's frames are read, turned into
//! points and fitted, then dropped; only a few poses are in flight (one per
//! worker thread). Poses are processed in parallel and gathered in order, and
//! every step is deterministic, so the result is bit-identical from run to run
//! and for any number of threads.

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::calib::calibrate::CalibrationSettings;
use crate::calib::geometry::Transform;
use crate::calib::ground_view;
use crate::calib::observe::{BodyEstimate, ObserveSettings, PoseObserver};
use crate::calib::plane::FitBuffers;
use crate::calib::quality::Gates;
use crate::calib::solve::Observation;
use crate::formats::output::{ResultJson, SetupJson};
use crate::formats::recording::session::NominalMount;
use crate::formats::recording::Recording;
use crate::platform::input::InputError;
use crate::solving::verify::{GravityReading, VisitedPose};

/// How to replay.
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    /// Overrides the recording's nominal mount.
    pub nominal_mount: Option<NominalMount>,
    pub pose: ObserveSettings,
    /// The solve's settings; its gates are used only for a recording that
    /// stores none and when `gates` is not given.
    pub calibration: CalibrationSettings,
    /// The gates to judge by (`replay --config`); otherwise the recording's
    /// own (those of its live run), so that both give the same verdict.
    pub gates: Option<Gates>,
    /// The noise the solve assumes at least (`replay --config`'s); otherwise
    /// the recording's own (its live run's).
    pub noise: Option<crate::calib::plan::NoiseModel>,
    /// Worker threads; `None` uses every core.
    pub threads: Option<usize>,
    /// How steady the tilt motor must have stayed (the accelerometer's σ).
    pub verify: crate::calib::verify::VerifySettings,
    /// The depth scale, estimated (the default) or given.
    pub depth_scale: crate::calib::solve::DepthScaleSetting,
    /// What to keep beyond the result.
    pub keep: AlsoKeep,
}

/// What observing a recording keeps beyond its poses: each costs time, and
/// only some outputs need it.
#[derive(Debug, Clone, Copy, Default)]
pub struct AlsoKeep {
    /// Per pose, the readings the fit took for the ground (one per 8 × 8
    /// pixels of the first frame), for `--mcap`.
    pub ground_points: bool,
    /// The input's digest, for a report's provenance: BLAKE3 of every
    /// frame's bytes, about a tenth of a replay's time (docs/performance.md).
    pub input_digest: bool,
}

impl ReplayOptions {
    /// The solve's settings and where the gates came from: these options'
    /// gates and noise, else the input's own (`stored`, a recording's live
    /// run's), else the built-in ones.
    pub fn settings(
        &self,
        stored_gates: Option<Gates>,
        stored_noise: Option<crate::calib::plan::NoiseModel>,
    ) -> (CalibrationSettings, &'static str) {
        let (gates, gates_from) = match (self.gates, stored_gates) {
            (Some(gates), _) => (gates, "config"),
            (None, Some(gates)) => (gates, "recording"),
            (None, None) => (self.calibration.gates, "built-in"),
        };
        let solve = match self.noise.or(stored_noise) {
            Some(noise) => noise.solve_settings(),
            None => self.calibration.solve,
        };
        let solve = crate::calib::solve::SolveSettings {
            depth_scale: self.depth_scale,
            ..solve
        };
        (CalibrationSettings { gates, solve }, gates_from)
    }
}

/// The outcome of a replay.
#[derive(Debug, Clone)]
pub struct Replay {
    pub result: ResultJson,
    /// BLAKE3 of the text files' and every frame's BLAKE3, in order (hex),
    /// when [`AlsoKeep::input_digest`] asked for it. (BLAKE3 rather than
    /// SHA-256: SHA-256 took a quarter of a replay's time, BLAKE3 a third of
    /// that; docs/performance.md.)
    pub input_digest: Option<String>,
    /// Depth frames read.
    pub frames: usize,
    /// Per pose of the recording, in its order: the body pose from the feet.
    pub ground_from_robot: Vec<Option<Transform>>,
    /// Per pose: the readings taken for the ground, in the sensor frame
    /// (when [`ReplayOptions::ground_points`] asked for them).
    pub ground_points: Vec<Option<Vec<Vector3<f64>>>>,
}

/// A worker's memory, reused from pose to pose: a pose's frames take a few
/// megabytes, and fresh memory costs page faults every time.
#[derive(Default)]
struct WorkerBuffers {
    fit: FitBuffers,
    /// Each frame's pixels.
    pixels: Vec<Vec<u16>>,
}

thread_local! {
    static BUFFERS: std::cell::RefCell<WorkerBuffers> = std::cell::RefCell::new(WorkerBuffers::default());
}

/// What one pose gave.
struct PoseOutcome {
    index: u32,
    observation: Result<Observation, String>,
    frame_digests: Vec<[u8; 32]>,
    ground_points: Option<Vec<Vector3<f64>>>,
}

fn process_pose(
    recording: &Recording,
    processor: &PoseObserver,
    pose: &crate::formats::recording::poses::PoseRecord,
    body: &Result<BodyEstimate, String>,
    buffers: &mut WorkerBuffers,
    keep: AlsoKeep,
) -> Result<PoseOutcome, InputError> {
    let poses_path = recording.dir.join("poses.jsonl");
    let failed = |reason: String| PoseOutcome {
        index: pose.index,
        observation: Err(reason),
        frame_digests: Vec::new(),
        ground_points: None,
    };
    if pose.depth_frames.is_empty() {
        return Ok(failed(
            "no depth frames were captured at this pose: skipped".into(),
        ));
    }
    let body = body.as_ref().map_err(|e| {
        InputError::new(
            &poses_path,
            Some(pose.line),
            format!("pose {}: feet: {e}", pose.index),
        )
    })?;
    let count = pose.depth_frames.len();
    buffers.pixels.resize_with(count, Vec::new);
    let mut frame_digests = Vec::with_capacity(count);
    for (name, pixels) in pose.depth_frames.iter().zip(&mut buffers.pixels) {
        if keep.input_digest {
            let mut digest = blake3::Hasher::new();
            recording.read_depth_pixels_into(name, pixels, Some(&mut digest))?;
            frame_digests.push(*digest.finalize().as_bytes());
        } else {
            recording.read_depth_pixels_into(name, pixels, None)?;
        }
    }
    let frames: Vec<&[u16]> = buffers.pixels[..count].iter().map(Vec::as_slice).collect();
    let fitted = processor
        .observe_with_fit(pose.index, body, &frames, &mut buffers.fit)
        .map_err(|e| format!("no ground found: {e}"));
    let ground_points = match (&fitted, keep.ground_points) {
        (Ok((_, fit)), true) => Some(ground_view::ground_points(
            frames[0],
            processor.camera(),
            fit,
        )),
        _ => None,
    };
    Ok(PoseOutcome {
        index: pose.index,
        observation: fitted.map(|(observation, _)| observation),
        frame_digests,
        ground_points,
    })
}

/// What a recording's poses gave, in pose order.
pub struct ObservedRecording {
    pub poses: Vec<VisitedPose>,
    /// BLAKE3 of the text files' and every frame's BLAKE3, in order (hex),
    /// when asked for.
    pub input_digest: Option<String>,
    /// Depth frames read.
    pub frames: usize,
    /// A note when no mount tells which plane is the ground.
    pub prior_note: Option<String>,
    /// Per pose, the readings taken for the ground (when asked for).
    pub ground_points: Vec<Option<Vec<Vector3<f64>>>>,
}

/// Per pose of a recording, the body pose from the feet, the ground from the
/// frames (told from other planes by `nominal`) and gravity from the
/// accelerometer readings; shared by `replay` and `verify --recording`.
pub fn observe_recording(
    recording: &Recording,
    nominal: Option<NominalMount>,
    settings: ObserveSettings,
    threads: Option<usize>,
    correction: Option<&crate::calib::distortion::DepthCorrection>,
    keep: AlsoKeep,
) -> Result<ObservedRecording, InputError> {
    let session = &recording.session;
    let session_path = recording.dir.join("session.json");
    let processor = PoseObserver::new(
        session.kinect.depth_model,
        session.kinect.intrinsics,
        &session.home.feet_body_mm,
        nominal,
        settings,
    )
    .map(|observer| match correction {
        Some(correction) => observer.with_depth_correction(correction),
        None => observer,
    })
    .map_err(|e| InputError::new(&session_path, None, e))?;

    // The body poses first, in the order the poses were visited: a foot
    // that slipped counts from where it stays at the following poses.
    let mut feet = processor.feet_tracker();
    let bodies: Vec<Result<BodyEstimate, String>> = recording
        .poses
        .iter()
        .map(|pose| feet.body_pose(&pose.commanded, &pose.feet_body_mm))
        .collect();
    let work = || -> Vec<Result<PoseOutcome, InputError>> {
        recording
            .poses
            .par_iter()
            .zip(&bodies)
            .with_max_len(1)
            .map(|(pose, body)| {
                BUFFERS.with_borrow_mut(|buffers| {
                    process_pose(recording, &processor, pose, body, buffers, keep)
                })
            })
            .collect()
    };
    let gathered = match threads {
        Some(threads) => rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .build()
            .map_err(|e| {
                InputError::new(
                    &recording.dir,
                    None,
                    format!("cannot start worker threads: {e}"),
                )
            })?
            .install(work),
        None => {
            let gathered = work();
            // The workers' buffers (3.7 MB a thread) are not kept past the
            // fits: the pattern's estimate that follows has the peak.
            rayon::broadcast(|_| BUFFERS.take());
            gathered
        }
    };
    // The first error in pose order, whichever thread met it first.
    let outcomes: Vec<PoseOutcome> = gathered.into_iter().collect::<Result<_, _>>()?;

    let frames = recording.poses.iter().map(|p| p.depth_frames.len()).sum();
    let input_digest = keep.input_digest.then(|| {
        let mut hasher = blake3::Hasher::new();
        for text in recording.text_files() {
            hasher.update(blake3::hash(text).as_bytes());
        }
        for digest in outcomes.iter().flat_map(|o| &o.frame_digests) {
            hasher.update(digest);
        }
        hasher.finalize().to_hex().to_string()
    });

    let mut poses = Vec::with_capacity(outcomes.len());
    let mut ground_points = Vec::with_capacity(outcomes.len());
    for ((mut outcome, record), body) in outcomes.into_iter().zip(&recording.poses).zip(&bodies) {
        let states = record
            .accelerometer
            .iter()
            .map(|name| recording.read_tilt_state(name).map(|raw| raw.state()))
            .collect::<Result<Vec<_>, InputError>>()?;
        ground_points.push(outcome.ground_points.take());
        poses.push(VisitedPose {
            index: outcome.index,
            ground_from_robot: body.as_ref().ok().map(|b| b.ground_from_robot),
            fit: outcome.observation,
            gravity: GravityReading::from_states(&states),
        });
    }
    Ok(ObservedRecording {
        poses,
        input_digest,
        frames,
        prior_note: processor.prior_note(),
        ground_points,
    })
}

/// Replays a recording.
pub fn replay(recording: &Recording, options: &ReplayOptions) -> Result<Replay, InputError> {
    let session = &recording.session;
    if recording.poses.is_empty() {
        // Nothing to solve is a defect of the input, not a rejected calibration.
        return Err(InputError::new(
            &recording.dir.join("poses.jsonl"),
            None,
            "holds no pose record: a recording to replay has at least one pose (a calibration has tens)",
        ));
    }
    let nominal = options.nominal_mount.or(session.nominal_mount);
    // A replay finds the depth pattern afresh, as the calibration did.
    let observed = observe_recording(
        recording,
        nominal,
        options.pose,
        options.threads,
        None,
        options.keep,
    )?;
    let (observations, failed) = VisitedPose::fits(&observed.poses);
    let (settings, gates_from) = options.settings(session.gates, session.noise);
    let first = ResultJson::from_poses(
        &observations,
        &failed,
        recording.poses.len(),
        &settings,
        session.kinect.tilt_deg,
    );
    drop(observations);
    let mut observed = observed;
    VisitedPose::forget_ground_residuals(&mut observed.poses);
    // A pattern the fit's band cut: the frames fitted again about it.
    let again = first.fit_about_the_pattern(|taken_out| {
        let again = observe_recording(
            recording,
            nominal,
            options.pose,
            options.threads,
            Some(taken_out),
            options.keep,
        )?;
        let (observations, failed) = VisitedPose::fits(&again.poses);
        let result = ResultJson::from_poses_taken_out(
            &observations,
            &failed,
            recording.poses.len(),
            &settings,
            session.kinect.tilt_deg,
            Some(taken_out),
        );
        let mut again = again;
        VisitedPose::forget_ground_residuals(&mut again.poses);
        Ok((result, again))
    })?;
    let mut result = first.result;
    if let Some(again) = again {
        (result, observed) = (
            again.0,
            ObservedRecording {
                input_digest: observed.input_digest,
                frames: observed.frames,
                ..again.1
            },
        );
    }
    if let Some(note) = observed.prior_note {
        result.notes.insert(0, note);
    }
    crate::solving::verify::judge_motor(
        &mut result,
        &observed.poses,
        session.kinect.tilt_deg,
        &options.verify,
    );
    for pose in &mut result.poses {
        pose.commanded = recording
            .poses
            .iter()
            .find(|r| r.index == pose.index)
            .map(|r| r.commanded);
    }
    result.robot = Some(session.robot.clone())
        .filter(|r| !r.is_empty())
        .map(|name| crate::formats::output::RobotJson {
            name: Some(name),
            firmware: None,
        });
    result.setup = Some(SetupJson {
        robot: Some(session.robot.clone()).filter(|r| !r.is_empty()),
        schedule: session.schedule.clone(),
        poses: Some(recording.poses.len()),
        frames_per_pose: session.frames_per_pose,
        depth_model: Some(session.kinect.depth_model),
        intrinsics: Some(session.kinect.intrinsics),
        nominal_mount: nominal,
        nominal_mount_from: match (options.nominal_mount, session.nominal_mount) {
            (Some(_), _) => Some("flag".into()),
            (None, Some(_)) => Some("recording".into()),
            (None, None) => None,
        },
        gates_from: Some(gates_from.into()),
        disparity: None,
    });
    if let Some(cut) = recording.cut_off {
        result.notes.push(format!(
            "poses.jsonl line {}: {}; replayed with --cut-off, without that pose",
            cut.line,
            cut.describe()
        ));
    }
    Ok(Replay {
        result,
        input_digest: observed.input_digest,
        frames: observed.frames,
        ground_from_robot: observed.poses.iter().map(|p| p.ground_from_robot).collect(),
        ground_points: observed.ground_points,
    })
}
