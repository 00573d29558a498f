//! SIGTERM in the middle of a calibration: the lower computer receives HALT
//! then HOME, the process exits cleanly with the reason, and the recording is
//! valid up to the last pose completed.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use groundcal::formats::recording::Recording;

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("groundcal-sigterm-{name}-{}", std::process::id()))
}

fn signal(pid: u32, name: &str) {
    let status = Command::new("kill")
        .args([&format!("-{name}"), &pid.to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

fn lines(path: &Path) -> usize {
    std::fs::read_to_string(path)
        .map(|t| t.lines().count())
        .unwrap_or(0)
}

#[test]
fn sigterm_at_pose_20_halts_then_homes_and_keeps_a_valid_recording() {
    let receipts = temp("receipts.jsonl");
    let record = temp("recording");
    let _ = std::fs::remove_dir_all(&record);
    let (robot, address) = common::spawn_sim_robot(
        &["--seed", "5", "--time-scale", "50"],
        &[("GROUNDCAL_SIM_RECEIPTS", receipts.as_os_str())],
    );

    // The simulation configuration, talking to the separate lower computer.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = temp("config.toml");
    let text = std::fs::read_to_string(root.join("config/sim.toml"))
        .unwrap()
        .replace("address = \"sim\"", &format!("address = \"{address}\""))
        .replace(
            "schedule = \"schedules/octopus-52.toml\"",
            &format!(
                "schedule = \"{}\"",
                root.join("config/schedules/octopus-52.toml").display()
            ),
        );
    std::fs::write(&config, text).unwrap();
    let calibrate = Command::new(env!("CARGO_BIN_EXE_groundcal"))
        .args([
            "calibrate",
            "--config",
            config.to_str().unwrap(),
            "--json",
            "--record",
            record.to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();

    // Pose 19's line is written once its frames are on disk: pose 20 is next.
    let start = Instant::now();
    while lines(&record.join("poses.jsonl")) < 19 {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "the calibration never reached pose 20"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    signal(calibrate.id(), "TERM");
    let out = calibrate.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        out.stdout.is_empty(),
        "no result is printed for an aborted calibration"
    );
    assert!(
        stderr.contains("SIGTERM") && stderr.contains("sent home"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");

    common::stop_sim_robot(robot);
    let log = std::fs::read_to_string(&receipts).unwrap();
    let kinds: Vec<(String, String)> = log
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["event"] == "datagram" && v["outcome"] == "new")
        .map(|v| {
            (
                v["kind"].as_str().unwrap_or("").to_string(),
                v["pose_id"].to_string(),
            )
        })
        .collect();
    let last_set_pose = kinds
        .iter()
        .rposition(|(k, _)| k == "SET_POSE")
        .expect("poses were sent");
    let after: Vec<&str> = kinds[last_set_pose + 1..]
        .iter()
        .map(|(k, _)| k.as_str())
        .filter(|k| *k != "GET_STATE")
        .collect();
    assert_eq!(
        after.first().copied(),
        Some("HALT"),
        "after the last SET_POSE: {after:?}"
    );
    assert_eq!(
        after.get(1).copied(),
        Some("HOME"),
        "after the last SET_POSE: {after:?}"
    );
    assert!(
        kinds[last_set_pose].1 == "20" || kinds[last_set_pose].1 == "21",
        "{:?}",
        kinds[last_set_pose]
    );

    let recording = Recording::open(&record).expect("the recording is valid");
    assert!(
        (19..=20).contains(&recording.poses.len()),
        "{} poses",
        recording.poses.len()
    );
    for (k, pose) in recording.poses.iter().enumerate() {
        assert_eq!(pose.index as usize, k + 1);
    }
    let _ = std::fs::remove_dir_all(&record);
    let _ = std::fs::remove_file(&config);
    let _ = std::fs::remove_file(&receipts);
}
