//! ROS 2 bags (MCAP) as input: `groundcal replay BAG.mcap` calibrates from a
//! bag another robot's stack recorded (docs/export.md, "ROS 2 bags as
//! input").
//!
//! - [`stream`]: the messages of an MCAP file, record by record, chunks
//!   decompressed one at a time;
//! - [`session`]: the bag's intrinsics, home stance and still poses;
//! - [`replay_bag`]: their observations, solved as a recording's are.

pub mod own;
pub mod session;
pub mod stream;

use crate::calib::depth::DepthEncoding;
use crate::calib::geometry::PoseDegMm;
use crate::calib::noise_with_depth;
use crate::calib::observe::{BodyPoseSource, PoseObserver};
use crate::calib::plane::FitBuffers;
use crate::calib::residuals::ScatterMeasured;
use crate::formats::output::{CameraDisparityJson, PatternDisparityJson, ResultJson, SetupJson};
use crate::solving::replay::{Replay, ReplayOptions};
pub use session::{read_bag, BagError, BagOptions, BagSession, CameraDisparity, GivenBaseline};

/// Whether `path` is an MCAP file (its magic), not a recording's directory.
pub fn is_mcap_file(path: &std::path::Path) -> bool {
    use std::io::Read;
    let mut magic = [0u8; 8];
    path.is_file()
        && crate::platform::files::open_regular(path)
            .map_err(std::io::Error::other)
            .and_then(|mut f| f.read_exact(&mut magic))
            .is_ok()
        && &magic == stream::MAGIC
}

/// Calibrates from a bag's still poses, as `replay` does from a recording:
/// the body pose from the feet, the ground from the frames, the solve and
/// its gates (`options`'s, else the built-in ones).
pub fn replay_bag(bag: &BagSession, options: &ReplayOptions) -> Result<Replay, BagError> {
    let fail = |what: String| BagError {
        path: bag.path.display().to_string(),
        what,
    };
    let nominal = options.nominal_mount.or(bag.nominal_mount);
    // A bag gives the feet, not what was commanded.
    let mut settings = options.pose;
    settings.body_pose_source = BodyPoseSource::Feet;
    // Whose camera it is a bag does not say: its noise against distance is
    // measured, to tell a disparity camera from a time-of-flight one.
    settings.scatter = ScatterMeasured::AlsoWithDepth;
    let observer = PoseObserver::for_encoding(
        DepthEncoding::Metric {
            metres_per_unit: bag.units.metres_per_unit(),
        },
        bag.intrinsics,
        &bag.home_feet_mm,
        nominal,
        settings,
    )
    .map_err(|e| fail(format!("the home stance's feet: {e}")))?;
    let mut feet = observer.feet_tracker();
    let bodies: Vec<_> = bag
        .poses
        .iter()
        .map(|pose| feet.body_pose(&PoseDegMm::from_values([0.0; 6]), &pose.feet_body_mm))
        .collect();
    let threads = options
        .threads
        .unwrap_or_else(rayon::current_num_threads)
        .max(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| fail(format!("cannot start worker threads: {e}")))?;
    let (fits, frames_read) = fit_poses(bag, &observer, &bodies, &pool, threads)?;
    let (observations, failed) = split(bag, fits);
    let exponent = noise_with_depth::noise_exponent(
        observations
            .iter()
            .filter_map(|o| o.ground_residuals.as_deref())
            .filter_map(|r| r.scatter_with_depth()),
    );
    if let Some(p) = exponent {
        tracing::info!("the depth's noise against distance: σ(1/z) ∝ (1/z)^{p:.3}");
    }
    // A bag stores no gates and no noise of a live run. Another camera's
    // pattern is gated in its own pixels of disparity.
    let (mut settings, gates_from) = options.settings(None, None);
    if let Some(camera) = bag.disparity {
        settings.gates = settings
            .gates
            .at_camera_disparity(camera.pixels_per_inverse_depth);
    }
    let first = ResultJson::from_poses(&observations, &failed, bag.poses.len(), &settings, 0.0);
    // Their residuals are not held through a second fit, which makes its own.
    drop(observations);
    // A pattern the fit's band cut: the bag read and fitted again about it.
    let again = first.fit_about_the_pattern(|taken_out| {
        let observer = observer.clone().with_depth_correction(taken_out);
        let (fits, _) = fit_poses(bag, &observer, &bodies, &pool, threads)?;
        let (observations, failed) = split(bag, fits);
        let result = ResultJson::from_poses_taken_out(
            &observations,
            &failed,
            bag.poses.len(),
            &settings,
            0.0,
            Some(taken_out),
        );
        Ok::<_, BagError>((result, ()))
    })?;
    let mut result = match again {
        Some((again, ())) => again,
        None => first.result,
    };
    // A camera that measures distance, not disparity: refused by name.
    if let Some(p) = exponent.filter(|p| *p > noise_with_depth::MAX_DISPARITY_EXPONENT) {
        result.status = crate::formats::output::ResultStatus::Rejected;
        result.reasons.insert(
            0,
            format!(
                "the depth's noise falls with distance as a time-of-flight camera's does (in inverse depth as (1/z)^{p:.2}, where a disparity camera's stays about level: -0.23 to 0.04 measured), and groundcal's fit and checks are made for disparity cameras (structured light, stereo): a time-of-flight camera is not supported, so this result must not be used"
            ),
        );
    }
    if let (Some(camera), Some(pattern)) = (bag.disparity, result.depth_pattern.as_mut()) {
        pattern.disparity = PatternDisparityJson::of(pattern, camera.pixels_per_inverse_depth);
    }
    // The motor's tilt is not in a bag: not claimed.
    result.kinect_tilt_deg = None;
    let mut notes = bag.notes.clone();
    notes.extend(observer.prior_note());
    notes.extend(observer.feet_note());
    if let Some(camera) = bag.disparity {
        notes.extend(raw_units_note(&result, camera));
    }
    result.notes.splice(0..0, notes);
    let frames_per_pose = bag.poses.iter().map(|p| p.stamps.len() as u32).max();
    result.setup = Some(SetupJson {
        robot: None,
        schedule: None,
        poses: Some(bag.poses.len()),
        frames_per_pose,
        depth_model: None,
        intrinsics: Some(bag.intrinsics),
        nominal_mount: nominal,
        nominal_mount_from: match (options.nominal_mount, bag.nominal_mount) {
            (Some(_), _) => Some("flag".into()),
            (None, Some(_)) => Some("bag's TF".into()),
            (None, None) => None,
        },
        gates_from: Some(gates_from.into()),
        disparity: bag.disparity.map(|camera| CameraDisparityJson {
            baseline_mm: camera.baseline_mm,
            pixels_per_inverse_depth: camera.pixels_per_inverse_depth,
            from: camera.from.into(),
        }),
    });
    Ok(Replay {
        result,
        input_digest: Some(bag.digest.clone()),
        frames: frames_read,
        ground_from_robot: bodies
            .iter()
            .map(|b| b.as_ref().ok().map(|b| b.ground_from_robot))
            .collect(),
        ground_points: vec![None; bag.poses.len()],
    })
}

/// What "raw units" in the result's words are, for a camera other than a
/// Kinect: a Kinect's raw units of the same inverse depth, given in this
/// camera's pixels of disparity and in millimetres at 2 m; `None` when the
/// words name none.
fn raw_units_note(result: &ResultJson, camera: session::CameraDisparity) -> Option<String> {
    let named = result
        .reasons
        .iter()
        .chain(result.depth_pattern.as_ref().map(|p| &p.note))
        .any(|words| words.contains("raw unit"));
    // The raw units the words were written in: the pattern's own, else
    // those the camera's frames are read in (the default depth model's).
    let raw_per_inverse_depth = result
        .depth_pattern
        .as_ref()
        .map(|p| p.raw_per_inverse_depth)
        .filter(|k| *k != 0.0)
        .unwrap_or_else(|| {
            1.0 / crate::calib::depth::DepthModel::default()
                .inverse_depth_affine()
                .1
        });
    let per_raw = 1.0 / raw_per_inverse_depth.abs();
    named.then(|| {
        format!(
            "the raw units in these words are a Kinect v1's of the same inverse depth: one is {:.4} px of this camera's disparity, {:.1} mm at 2 m",
            per_raw * camera.pixels_per_inverse_depth,
            per_raw * 4.0 * 1e3
        )
    })
}

/// Each pose's ground fitted on the worker threads as soon as its frames are
/// read, and its frames freed: at most two poses a thread wait, so a bag of
/// any length takes the memory of a few poses. The results do not depend on
/// the number of threads (each pose is fitted alone). Per pose its
/// observation or why there is none, and the frames read.
fn fit_poses(
    bag: &BagSession,
    observer: &PoseObserver,
    bodies: &[Result<crate::calib::observe::BodyEstimate, String>],
    pool: &rayon::ThreadPool,
    threads: usize,
) -> Result<(Vec<Fit>, usize), BagError> {
    let results: std::sync::Mutex<Vec<Option<Result<crate::calib::solve::Observation, String>>>> =
        std::sync::Mutex::new(vec![None; bag.poses.len()]);
    let in_flight = (std::sync::Mutex::new(0usize), std::sync::Condvar::new());
    let frames_read = pool.in_place_scope(|scope| {
        bag.read_frames(|k, frames| {
            {
                let (count, freed) = &in_flight;
                let mut count = count.lock().unwrap_or_else(|p| p.into_inner());
                while *count >= 2 * threads {
                    count = freed.wait(count).unwrap_or_else(|p| p.into_inner());
                }
                *count += 1;
            }
            let (observer, bodies, results, in_flight) = (&observer, &bodies, &results, &in_flight);
            let pose = &bag.poses[k];
            scope.spawn(move |_| {
                let fit = match &bodies[k] {
                    Err(e) => Err(format!("pose {}: feet: {e}", pose.index)),
                    Ok(body) => {
                        let frames: Vec<&[u16]> = frames.iter().map(Vec::as_slice).collect();
                        observer
                            .observe(pose.index, body, &frames, &mut FitBuffers::default())
                            .map_err(|e| format!("no ground found: {e}"))
                    }
                };
                drop(frames);
                results.lock().unwrap_or_else(|p| p.into_inner())[k] = Some(fit);
                let (count, freed) = in_flight;
                *count.lock().unwrap_or_else(|p| p.into_inner()) -= 1;
                freed.notify_one();
            });
            Ok(())
        })
    })?;
    let fits = results
        .into_inner()
        .unwrap_or_else(|p| p.into_inner())
        .into_iter()
        .map(|fit| fit.unwrap_or_else(|| Err("no frame of this pose was read".into())))
        .collect();
    Ok((fits, frames_read))
}

/// A pose's observation, or why there is none.
type Fit = Result<crate::calib::solve::Observation, String>;

/// The poses' observations, and the poses that gave none with why.
fn split(
    bag: &BagSession,
    fits: Vec<Fit>,
) -> (Vec<crate::calib::solve::Observation>, Vec<(u32, String)>) {
    let mut observations = Vec::new();
    let mut failed = Vec::new();
    for (pose, fit) in bag.poses.iter().zip(fits) {
        match fit {
            Ok(observation) => observations.push(observation),
            Err(reason) => failed.push((pose.index, reason)),
        }
    }
    (observations, failed)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Another camera's words in raw units say what a raw unit is on it: a
    /// Kinect's of the same inverse depth (1/342.2 per metre for the default
    /// model), 0.0621 px on 425 px × 50 mm, 11.7 mm at 2 m; words without
    /// raw units get no such note.
    #[test]
    fn raw_units_are_given_in_the_cameras_own_pixels() {
        let camera = session::CameraDisparity {
            baseline_mm: 50.0,
            pixels_per_inverse_depth: 425.0 * 0.050,
            from: "config",
        };
        let without = ResultJson::unsolved("too few poses".into(), &[]);
        assert_eq!(raw_units_note(&without, camera), None);
        let with = ResultJson::unsolved(
            "it reaches 7.7 raw units from the ground's plane".into(),
            &[],
        );
        let note = raw_units_note(&with, camera).expect("a note");
        assert!(
            note.ends_with("one is 0.0621 px of this camera's disparity, 11.7 mm at 2 m"),
            "{note}"
        );
    }
}
