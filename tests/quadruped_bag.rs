//! A quadruped's session from its ROS 2 bag (issue 44): four feet through hip
//! and knee frames, an 848 × 480 active-stereo camera with its own baseline
//! and the Kinect's real kind of errors scaled to its disparity (correlated
//! noise, a fixed pattern), the body in a schedule `plan --design` made within
//! a quadruped's limits (`config/quadruped.toml`), the bag written by
//! `rosbags`' own Writer (tests/mcap/make_quadruped_bag.py), not by groundcal
//! nor by the MCAP project's writer the other bag tests use.

mod common;

use std::path::Path;
use std::process::Command;

use common::{
    gate_check, groundcal, mcap_python, prerequisite_missing, root, temp_dir, MOUNT_KEYS as KEYS,
};
use serde_json::Value;

/// Writes the bag with `args`; its truth, as the script prints it.
fn make_bag(python: &Path, out: &Path, args: &[&str]) -> Value {
    let made = Command::new(python)
        .arg(root().join("tests/mcap/make_quadruped_bag.py"))
        .arg(root().join("config/schedules/quadruped-designed-52.toml"))
        .arg(out)
        .args(args)
        .output()
        .expect("python runs");
    assert!(
        made.status.success(),
        "make_quadruped_bag.py: {}",
        String::from_utf8_lossy(&made.stderr)
    );
    serde_json::from_slice(&made.stdout).expect("the truth as JSON")
}

/// `groundcal replay` of the bag with `config/quadruped.toml` (its topics
/// and four feet in `[bag]`), and these flags: exit status and result.
fn replay(truth: &Value, flags: &[&str]) -> (i32, Value, String) {
    let bag = truth["bag"].as_str().unwrap();
    let config = root().join("config/quadruped.toml");
    let mut args = vec![
        "replay",
        bag,
        "--config",
        config.to_str().unwrap(),
        "--json",
    ];
    args.extend_from_slice(flags);
    let (code, stdout, stderr) = groundcal(&args);
    let result = serde_json::from_str(&stdout).unwrap_or(Value::Null);
    (code, result, stderr)
}

/// The mount's largest angle and position errors against the truth.
fn errors(result: &Value, truth: &Value) -> (f64, f64) {
    let mount = &result["robot_from_sensor"];
    let error = |k: &str| (mount[k].as_f64().unwrap() - truth["mount"][k].as_f64().unwrap()).abs();
    let angle = KEYS[..3].iter().map(|k| error(k)).fold(0.0, f64::max);
    let position = KEYS[3..].iter().map(|k| error(k)).fold(0.0, f64::max);
    (angle, position)
}

fn python_with_rosbags(test: &str) -> Option<std::path::PathBuf> {
    let python = mcap_python(test)?;
    let ready = Command::new(&python)
        .args(["-c", "import numpy, rosbags"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ready {
        prerequisite_missing(
            test,
            "the MCAP venv has no numpy or rosbags (tests/mcap/requirements.txt; scripts/test installs them)",
        );
        return None;
    }
    Some(python)
}

/// Measured (seed 1): accepted, 0.0057° and 0.069 mm from the truth; the
/// pattern (30 mm at 2 m) fitted about and corrected.
#[test]
fn a_quadrupeds_bag_is_calibrated_from_its_four_feet() {
    let test = "a_quadrupeds_bag_is_calibrated_from_its_four_feet";
    let Some(python) = python_with_rosbags(test) else {
        return;
    };
    let work = temp_dir("quadruped-bag");
    let truth = make_bag(&python, &work.join("bag"), &["--seed", "1"]);
    assert_eq!(truth["counts"]["images"], 104, "{truth}");
    let (code, result, stderr) = replay(&truth, &[]);
    assert_eq!(code, 0, "accepted: {stderr}\n{}", result["reasons"]);
    assert_eq!(result["summary"]["poses_used"], 52, "{stderr}");
    let (angle, position) = errors(&result, &truth);
    assert!(
        angle < 0.012 && position < 0.3,
        "{angle}° and {position} mm off"
    );
    assert_eq!(result["depth_pattern"]["corrected"], true);
    assert_eq!(result["setup"]["intrinsics"]["width"], 848);
    // The baseline from [bag] (its CameraInfo has none, as a RealSense's):
    // the pattern in the camera's own pixels, its gate carried over in them.
    let disparity = &result["setup"]["disparity"];
    assert_eq!(disparity["from"], "config", "{disparity}");
    assert_eq!(disparity["pixels_per_inverse_depth"], 21.25);
    let rms_px = result["depth_pattern"]["disparity"]["shape_rms_px"]
        .as_f64()
        .unwrap();
    let truth_px = truth["pattern_rms_px"].as_f64().unwrap();
    assert!(
        (rms_px / truth_px - 1.0).abs() < 0.2,
        "{rms_px} px against {truth_px}"
    );
    std::fs::remove_dir_all(&work).ok();
}

/// A pattern 2.5 times as large (0.13 px RMS; 0.41 px, 78 mm at 2 m, at its
/// largest cell) is past the 45 mm a Kinect's correction is checked for,
/// but within the 0.48 px that is in the Kinect's own disparity: judged in
/// this camera's pixels (the baseline from its CameraInfo's projection
/// matrix, the configuration naming none), it is corrected and accepted.
/// Measured (seed 4): 0.0122° and 0.189 mm off, the gate's limit 90.6 mm;
/// before the camera's own units it was rejected by the 45 mm gate, with
/// "have a maintainer check the Kinect". (It was 0.0058° and 0.120 mm while
/// each pose's plane in the estimate read the cells the estimate does not
/// hold, their pattern unsubtracted, and the correction of the ground
/// fit's planes took it as none there: two errors that partly cancelled,
/// still 4.9σ off. Both are mended, and this camera's bowl, largest in the
/// corners few poses see, leaves the plane part biased: 6.6σ. Hence
/// 0.015°, not the Kinect's 0.012°; docs/method.md.)
#[test]
fn another_cameras_pattern_is_judged_in_its_own_pixels_of_disparity() {
    let test = "another_cameras_pattern_is_judged_in_its_own_pixels_of_disparity";
    let Some(python) = python_with_rosbags(test) else {
        return;
    };
    let work = temp_dir("quadruped-pattern");
    let truth = make_bag(
        &python,
        &work.join("bag"),
        &["--seed", "4", "--pattern-scale", "2.5", "--info-baseline"],
    );
    // The robot's configuration without its baseline: the bag's own is used.
    let shipped = root().join("config/quadruped.toml");
    let text = std::fs::read_to_string(&shipped).unwrap();
    let schedule = root().join("config/schedules/quadruped-designed-52.toml");
    let config = work.join("no-baseline.toml");
    let without: String = text
        .lines()
        .filter(|line| !line.starts_with("baseline_mm"))
        .map(|line| format!("{line}\n"))
        .collect::<String>()
        .replace(
            "\"schedules/quadruped-designed-52.toml\"",
            &format!("{:?}", schedule.to_str().unwrap()),
        );
    std::fs::write(&config, without).unwrap();
    let bag = truth["bag"].as_str().unwrap();
    let (code, stdout, stderr) = groundcal(&[
        "replay",
        bag,
        "--config",
        config.to_str().unwrap(),
        "--json",
    ]);
    let result: Value = serde_json::from_str(&stdout).unwrap_or(Value::Null);
    assert_eq!(code, 0, "accepted: {stderr}\n{}", result["reasons"]);
    assert_eq!(result["setup"]["disparity"]["from"], "camera_info");
    let (angle, position) = errors(&result, &truth);
    assert!(
        angle < 0.015 && position < 0.3,
        "{angle}° and {position} mm off"
    );
    let pattern = &result["depth_pattern"];
    assert_eq!(pattern["corrected"], true);
    let largest_mm = pattern["largest_mm_at_2m"].as_f64().unwrap();
    assert!(largest_mm > 45.0, "{largest_mm} mm: past a Kinect's gate");
    let gate = gate_check(&result, "pattern_max_mm");
    assert!(
        (gate["limit"].as_f64().unwrap() - 90.6).abs() < 0.1,
        "{gate}"
    );
    let largest_px = pattern["disparity"]["largest_px"].as_f64().unwrap();
    assert!(
        (largest_px - largest_mm * 1e-3 / 4.0 * 21.25).abs() < 1e-9,
        "{largest_px}"
    );

    // A baseline no camera has is named, from the flag.
    let (code, _, stderr) = groundcal(&["replay", bag, "--baseline-mm", "0", "--json"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("--baseline-mm: 0 is not a depth camera's stereo baseline"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&work).ok();
}

/// Foot 2 slips 18 mm (15 forward, 10 down) on the way to pose 20: named
/// there, and the other three carry the body (measured: accepted, 0.0076°
/// and 0.049 mm off). With foot 4's frame left out, three feet cannot find
/// it: the result says so, and the sunk foot tilts every later body pose,
/// which the ground disagrees with (rejected, θ up to 1.3°, e_d 7.5 mm).
#[test]
fn a_quadrupeds_slipped_foot_is_named_and_three_feet_say_they_cannot() {
    let test = "a_quadrupeds_slipped_foot_is_named_and_three_feet_say_they_cannot";
    let Some(python) = python_with_rosbags(test) else {
        return;
    };
    let work = temp_dir("quadruped-slip");
    let truth = make_bag(
        &python,
        &work.join("bag"),
        &["--seed", "2", "--slip", "2@20"],
    );
    let (code, result, stderr) = replay(&truth, &[]);
    assert_eq!(code, 0, "accepted: {stderr}\n{}", result["reasons"]);
    let noted: Vec<(u64, &str)> = result["poses"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|p| Some((p["index"].as_u64()?, p["note"].as_str()?)))
        .collect();
    assert_eq!(noted.len(), 1, "{noted:?}");
    assert_eq!(noted[0].0, 20);
    assert!(
        noted[0].1.starts_with("foot 2 slipped (18.0 mm")
            && noted[0].1.contains("the other three feet's"),
        "{noted:?}"
    );
    let (angle, position) = errors(&result, &truth);
    assert!(
        angle < 0.012 && position < 0.3,
        "{angle}° and {position} mm off"
    );

    let (code, three, stderr) = replay(&truth, &["--foot-frames", "lf_foot,rf_foot,lh_foot"]);
    assert_eq!(code, 3, "rejected, not accepted off: {stderr}");
    let notes = three["notes"].as_array().expect(&stderr);
    assert!(
        notes.iter().any(|n| n
            .as_str()
            .is_some_and(|n| n.starts_with("the body pose comes from 3 planted feet"))),
        "{notes:?}"
    );
    assert!(three["poses"]
        .as_array()
        .unwrap()
        .iter()
        .all(|p| p["note"].is_null()));

    let (code, _, stderr) = replay(&truth, &["--foot-frames", "lf_foot,rf_foot"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("--foot-frames: at least 3 frames"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&work).ok();
}

/// A time-of-flight camera measures distance, not disparity: its noise in
/// inverse depth falls with distance (measured: as (1/z)^1.37, where the
/// stereo camera above gives 0.04, a simulated Kinect 0.01 and the real
/// Kinect sequence -0.23). Refused by name, exit 3, whatever its mount.
#[test]
fn a_time_of_flight_camera_is_refused_by_name() {
    let test = "a_time_of_flight_camera_is_refused_by_name";
    let Some(python) = python_with_rosbags(test) else {
        return;
    };
    let work = temp_dir("quadruped-tof");
    let truth = make_bag(&python, &work.join("bag"), &["--seed", "3", "--tof"]);
    let (code, result, stderr) = replay(&truth, &[]);
    assert_eq!(code, 3, "{stderr}");
    let first = result["reasons"][0].as_str().unwrap_or_default();
    assert!(
        first
            .starts_with("the depth's noise falls with distance as a time-of-flight camera's does")
            && first.contains("not supported"),
        "{first}"
    );
    std::fs::remove_dir_all(&work).ok();
}
