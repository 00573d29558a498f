//! The session as an MCAP file, read back by the MCAP project's own Python
//! packages (`mcap`, `mcap-ros2-support`; tests/mcap/check_session.py), not
//! by groundcal's code: every message decodes with its schema, the counts
//! match the recording, the 16UC1 images are the depth model applied to the
//! raw frames, and the TF chain gives the calibrated mount.

mod common;

use std::path::PathBuf;
use std::process::Command;

use common::{groundcal, mcap_python, root, shared, temp_dir};

fn check_with_python(
    python: &PathBuf,
    mcap: &std::path::Path,
    recording: &std::path::Path,
    result: &std::path::Path,
) -> serde_json::Value {
    let out = Command::new(python)
        .arg(root().join("tests/mcap/check_session.py"))
        .args([mcap, recording, result])
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "the independent reader refused the file:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("check_session.py prints one JSON object")
}

#[test]
fn the_samples_replay_as_mcap_reads_back_in_the_mcap_projects_own_reader() {
    let test = "the_samples_replay_as_mcap_reads_back_in_the_mcap_projects_own_reader";
    let Some(python) = mcap_python(test) else {
        return;
    };
    let work = temp_dir("mcap-sample");
    let sample = shared().join("data/sample-12");
    let mcap = work.join("sample-12.mcap");
    let (code, stdout, stderr) = groundcal(&[
        "replay",
        sample.to_str().unwrap(),
        "--json",
        "--mcap",
        mcap.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "replay with --mcap: {stderr}");
    assert!(stderr.contains("MCAP written to"), "{stderr}");
    let result = work.join("result.json");
    std::fs::write(&result, &stdout).unwrap();
    let report = check_with_python(&python, &mcap, &sample, &result);
    let counts = &report["counts"];
    let frames: usize = std::fs::read_to_string(sample.join("poses.jsonl"))
        .unwrap()
        .lines()
        .map(|line| {
            serde_json::from_str::<serde_json::Value>(line).unwrap()["depth_frames"]
                .as_array()
                .unwrap()
                .len()
        })
        .sum();
    assert!(frames > 0);
    assert_eq!(report["frames"], frames, "{report}");
    assert_eq!(report["images_compared"], frames, "{report}");
    assert_eq!(counts["/tf"], 12, "{report}");
    assert_eq!(counts["/groundcal/pose_fit"], 12, "{report}");
    assert_eq!(counts["/groundcal/ground/inliers"], 12, "{report}");
    assert_eq!(report["planes_compared"], 12, "{report}");
    assert!(report["mount_error"].as_f64().unwrap() < 1e-6, "{report}");
    assert!(report["chunks"].as_u64().unwrap() > 1, "{report}");
    // The file is a recording: replayed, it gives the recording's result,
    // byte for byte (issue 44; before, "the feet never stay still … no home
    // stance", exit 2), and leaves nothing behind.
    assert_replays_as_its_recording(&mcap, &stdout);
    // Nothing else was left in the directory: no temporary file.
    let mut names: Vec<String> = std::fs::read_dir(&*work)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["result.json", "sample-12.mcap"]);
}

/// `replay FILE.mcap` of groundcal's own session prints `expected` (the
/// JSON of `replay` of the recording it was written from), byte for byte,
/// and leaves nothing of the recording it read out behind (its temporary
/// directory is looked for in a TMPDIR of the test's own).
fn assert_replays_as_its_recording(mcap: &std::path::Path, expected: &str) {
    let tmp = temp_dir("mcap-replay-tmp");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_groundcal"))
        .args(["replay", mcap.to_str().unwrap(), "--json"])
        .env("TMPDIR", &*tmp)
        .output()
        .expect("groundcal runs");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(
        matches!(out.status.code(), Some(0 | 3)),
        "replay of the MCAP: {stderr}"
    );
    assert!(
        stdout == expected,
        "replay of the MCAP differs from the recording's:\n{stdout}\n---\n{expected}"
    );
    let left: Vec<_> = std::fs::read_dir(&*tmp).unwrap().collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn an_mcap_that_cannot_be_written_leaves_nothing_and_says_where() {
    let work = temp_dir("mcap-unwritable");
    let sample = shared().join("data/sample-12");
    // A directory where the file should go.
    let target = work.join("taken.mcap");
    std::fs::create_dir(&target).unwrap();
    let (code, _, stderr) = groundcal(&[
        "replay",
        sample.to_str().unwrap(),
        "--mcap",
        target.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{stderr}");
    assert!(stderr.contains("taken.mcap"), "{stderr}");
    let left: Vec<_> = std::fs::read_dir(&*work).unwrap().collect();
    assert_eq!(
        left.len(),
        1,
        "only the directory that was in the way: {left:?}"
    );
}

#[test]
fn a_live_simulated_calibration_writes_its_session_as_mcap() {
    let test = "a_live_simulated_calibration_writes_its_session_as_mcap";
    let Some(python) = mcap_python(test) else {
        return;
    };
    let work = temp_dir("mcap-live");
    let config = common::sim_config(&work, &[]);
    let (recording, mcap) = (work.join("rec"), work.join("live.mcap"));
    let (code, stdout, stderr) = groundcal(&[
        "calibrate",
        "--config",
        config.to_str().unwrap(),
        "--record",
        recording.to_str().unwrap(),
        "--record-mcap",
        mcap.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(code, 0, "calibrate with --record-mcap: {stderr}");
    assert!(stderr.contains("MCAP written to"), "{stderr}");
    let result = work.join("result.json");
    std::fs::write(&result, &stdout).unwrap();
    let report = check_with_python(&python, &mcap, &recording, &result);
    // The live session's file replays as its recording does.
    let (code, replayed, stderr) = groundcal(&["replay", recording.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{stderr}");
    assert_replays_as_its_recording(&mcap, &replayed);
    let poses = serde_json::from_str::<serde_json::Value>(&stdout).unwrap()["poses"]
        .as_array()
        .unwrap()
        .len();
    assert_eq!(poses, 52);
    let counts = &report["counts"];
    // Two frames a pose (config/sim.toml), each compared with the depth model.
    assert_eq!(report["frames"], 2 * poses, "{report}");
    assert_eq!(report["images_compared"], 2 * poses, "{report}");
    for topic in ["/tf", "/groundcal/pose_fit", "/groundcal/ground/inliers"] {
        assert_eq!(counts[topic], poses, "{topic}: {report}");
    }
    assert_eq!(report["planes_compared"], poses, "{report}");
    assert!(report["mount_error"].as_f64().unwrap() < 1e-6, "{report}");
}

#[test]
fn record_mcap_alone_keeps_no_recording_behind() {
    let work = temp_dir("mcap-live-alone");
    let config = common::sim_config(&work, &[]);
    let mcap = work.join("alone.mcap");
    let (code, _, stderr) = groundcal(&[
        "calibrate",
        "--config",
        config.to_str().unwrap(),
        "--record-mcap",
        mcap.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(!stderr.contains("recording written"), "{stderr}");
    let size = std::fs::metadata(&mcap).expect("the MCAP file").len();
    assert!(size > 1_000_000, "{size} bytes");
    let mut names: Vec<String> = std::fs::read_dir(&*work)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| !name.ends_with(".toml") && !name.starts_with("token"))
        .collect();
    names.sort();
    assert_eq!(names, ["alone.mcap"], "the temporary recording is gone");
}

/// The session as Foxglove's layout shows it (docs/foxglove-layout.json):
/// read by Foxglove's own libraries (@mcap/core's indexed reader through the
/// summary and indexes, @foxglove/rosmsg2-serialization), drawn in headless
/// Chromium by tests/browser/mcap-preview.mjs (not Foxglove itself). The
/// ground the camera saw, through the mount and the body pose, lands where
/// the feet stand. Screenshots in `target/test-screenshots/mcap-preview*.png`.
#[test]
fn the_session_reads_in_foxgloves_own_libraries_and_shows_the_ground_under_the_feet() {
    let test = "the_session_reads_in_foxgloves_own_libraries_and_shows_the_ground_under_the_feet";
    if !common::browser_ready(test) {
        return;
    }
    let work = temp_dir("mcap-preview");
    let mcap = work.join("sample-12.mcap");
    let sample = shared().join("data/sample-12");
    let (code, _, stderr) = groundcal(&[
        "replay",
        sample.to_str().unwrap(),
        "--mcap",
        mcap.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let shots = root().join("target/test-screenshots");
    std::fs::create_dir_all(&shots).unwrap();
    let shot = shots.join("mcap-preview.png");
    let seen = common::run_browser_script(
        "mcap-preview.mjs",
        &[
            mcap.as_os_str(),
            shot.as_os_str(),
            std::ffi::OsStr::new("3"),
        ],
    );
    assert_eq!(seen["problems"], serde_json::json!([]), "{seen}");
    let counts = &seen["counts"];
    assert_eq!(counts["/camera/depth/image_raw"], 24, "{seen}");
    assert_eq!(counts["/groundcal/pose_fit"], 12, "{seen}");
    assert_eq!(seen["pose"], 3);
    assert_eq!(seen["drawn"]["feet"], 6);
    assert!(seen["drawn"]["inliers"].as_u64().unwrap() > 1000, "{seen}");
    for path in [shot.clone(), shots.join("mcap-preview-desktop.png")] {
        assert!(std::fs::metadata(&path).unwrap().len() > 20_000, "{path:?}");
    }
}
