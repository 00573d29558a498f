//! ROS 2 bags as input (issue 25): a bag written by the MCAP project's own
//! ROS 2 writer (`mcap-ros2-support`, tests/mcap/make_bag.py), not
//! groundcal's code, from a simulated 52-pose session, as another robot's
//! stack records one: depth at its own rate (stale images while the body
//! moves), the feet in /tf through hip frames, the robot's rough mount in
//! /tf_static, chunks compressed as rosbag2 compresses them. `replay BAG`
//! finds the still poses from the feet and calibrates within 0.01° and
//! 0.5 mm of the simulator's truth.

mod common;

use std::path::Path;
use std::process::Command;

use common::{groundcal, mcap_python, root, shared, sim_config_unmeasured, temp_dir};
use serde_json::Value;

use common::MOUNT_KEYS as KEYS;
use common::SIM_MOUNT as TRUTH;

/// Starts writing `out` from `recording` with the Python writer.
fn start_bag(python: &Path, recording: &Path, out: &Path, extra: &[&str]) -> std::process::Child {
    Command::new(python)
        .arg(root().join("tests/mcap/make_bag.py"))
        .args([recording, out])
        .args(extra)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("python runs")
}

/// Waits for a bag's writer; its counts.
fn finish_bag(writer: std::process::Child) -> Value {
    let made = writer.wait_with_output().expect("python ends");
    assert!(
        made.status.success(),
        "make_bag.py: {}",
        String::from_utf8_lossy(&made.stderr)
    );
    serde_json::from_slice(&made.stdout).expect("make_bag.py prints its counts")
}

/// Writes `out` from `recording` with the Python writer; its counts.
fn make_bag(python: &Path, recording: &Path, out: &Path, extra: &[&str]) -> Value {
    finish_bag(start_bag(python, recording, out, extra))
}

/// The largest angle (°) and position (mm) errors against the simulator's mount.
fn errors(result: &Value) -> (f64, f64) {
    let mount = &result["robot_from_sensor"];
    let error = |k: usize| (mount[KEYS[k]].as_f64().unwrap() - TRUTH[k]).abs();
    (
        (0..3).map(error).fold(0.0, f64::max),
        (3..6).map(error).fold(0.0, f64::max),
    )
}

#[test]
fn a_bag_from_another_stack_is_calibrated_from_its_still_poses() {
    let test = "a_bag_from_another_stack_is_calibrated_from_its_still_poses";
    let Some(python) = mcap_python(test) else {
        return;
    };
    let work = temp_dir("ros-bag");
    // A real robot's configuration: no noise table.
    let config = sim_config_unmeasured(&work, &[]);
    let recording = work.join("rec");
    let (code, _, stderr) = groundcal(&[
        "calibrate",
        "--config",
        config.to_str().unwrap(),
        "--record",
        recording.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    // Both bags written at once (the writer is single-threaded Python).
    let cases = [("16UC1", "zstd"), ("32FC1", "lz4")].map(|(encoding, compression)| {
        let bag = work.join(format!("{encoding}.mcap"));
        let writer = start_bag(
            &python,
            &recording,
            &bag,
            &["--encoding", encoding, "--compression", compression],
        );
        (encoding, compression, bag, writer)
    });
    for (encoding, compression, bag, writer) in cases {
        let counts = finish_bag(writer);
        assert_eq!(counts["images"], 104, "{counts}");
        assert!(counts["stale_images"].as_u64().unwrap() > 200, "{counts}");
        let (code, out, stderr) = groundcal(&["replay", bag.to_str().unwrap(), "--json"]);
        assert_eq!(code, 0, "{encoding}: {stderr}\n{out}");
        let result: Value = serde_json::from_str(&out).unwrap();
        let setup = &result["setup"];
        // Every still pose found, and no stale image taken for one.
        assert_eq!(setup["poses"], 52, "{encoding}: {setup}");
        assert_eq!(setup["frames_per_pose"], 2, "{encoding}: {setup}");
        assert_eq!(setup["nominal_mount_from"], "bag's TF", "{encoding}");
        assert_eq!(result["summary"]["poses_used"], 52, "{encoding}: {out}");
        let (angle, position) = errors(&result);
        assert!(
            angle < 0.01 && position < 0.5,
            "{encoding}/{compression}: {angle}° and {position} mm off"
        );
        // The motor's tilt is not in a bag, and not claimed.
        assert!(result["kinect_tilt_deg"].is_null(), "{out}");
    }
}

#[test]
fn a_bad_bag_is_refused_with_what_and_where() {
    let test = "a_bad_bag_is_refused_with_what_and_where";
    let Some(python) = mcap_python(test) else {
        return;
    };
    let work = temp_dir("ros-bag-bad");
    let bag = work.join("sample.mcap");
    make_bag(&python, &shared().join("data/sample-12"), &bag, &[]);
    let bag_arg = bag.to_str().unwrap();

    // Feet under other names than the bag's.
    let (code, _, stderr) = groundcal(&["replay", bag_arg, "--foot-frames", "lf,lm,lh,rh,rm,rf"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("sample.mcap") && stderr.contains("no TF path from base_link to lf"),
        "{stderr}"
    );
    // Two feet (any number from three fixes a body).
    let (code, _, stderr) = groundcal(&["replay", bag_arg, "--foot-frames", "a,b"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("at least 3 frames"), "{stderr}");
    // An image topic that is not there.
    let (code, _, stderr) = groundcal(&["replay", bag_arg, "--depth-topic", "/nothing"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("no depth image on /nothing"), "{stderr}");

    // A number no camera has: named, exit 2 (not a calibration rejected
    // for a sensor height of NaN).
    for (poison, said) in [
        ("fx-inf", "/camera/depth/camera_info: K[0] (fx) = inf is not a camera's focal length"),
        ("camera-nan", "the transform of frame \"camera_depth_optical_frame\" from \"base_link\": translation.x = NaN"),
    ] {
        let poisoned = work.join(format!("{poison}.mcap"));
        make_bag(&python, &shared().join("data/sample-12"), &poisoned, &["--poison", poison]);
        let (code, _, stderr) = groundcal(&["replay", poisoned.to_str().unwrap()]);
        assert_eq!(code, 2, "{poison}: {stderr}");
        assert!(stderr.contains(said), "{poison}: {stderr}");
    }

    // Cut in the middle of a chunk: the byte where it ends is named.
    let bytes = std::fs::read(&bag).unwrap();
    let cut = work.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let (code, _, stderr) = groundcal(&["replay", cut.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("cut.mcap") && stderr.contains("byte ") && stderr.contains("ends inside"),
        "{stderr}"
    );
    // One byte of a chunk changed: its CRC says so.
    let mut flipped = bytes.clone();
    let middle = bytes.len() / 3;
    flipped[middle] ^= 0x40;
    let corrupt = work.join("corrupt.mcap");
    std::fs::write(&corrupt, &flipped).unwrap();
    let (code, _, stderr) = groundcal(&["replay", corrupt.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("corrupt.mcap: byte "), "{stderr}");
}
