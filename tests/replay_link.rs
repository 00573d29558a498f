//! A recorded session run live again: `groundcal calibrate --sensor
//! replay:DIR` against an independent lower computer in its own process
//! (`groundcal sim-robot --replay DIR`) over a lossy loopback link (20% loss
//! each way, duplicates, reordering, delay). The lower computer accepts only
//! the recorded poses, exactly as commanded, and reports the recorded feet,
//! so the live session must send every pose as recorded, once, and find what
//! `groundcal replay DIR` finds: within 0.001° and 0.01 mm, the link carrying
//! f32.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::{groundcal_json, mount_of, shared, temp_dir};
use groundcal::formats::recording::Recording;
use serde_json::Value;

const FAULTS: &str = "loss=0.2,dup=0.05,reorder=0.05,delay_ms=20,seed=3";

/// Runs the live session on `recording` and checks it against the replay.
fn live_session_matches_the_replay(tag: &str, recording: &Path) {
    let work = temp_dir(tag);
    // 30 retries: at 20 % loss each way, a request and its reply both get
    // through with p = 0.64; 31 attempts all failing is ~1e-14.
    let run = common::calibrate_live(recording, &work, FAULTS, "retries = 30");
    let (code, stderr, receipts) = (run.code, run.robot_stderr, run.receipts);
    let live: Value = serde_json::from_str(&run.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout is not one JSON document ({e}): {}\nstderr: {}",
            run.stdout, run.stderr
        )
    });
    let (replay_code, replayed) =
        groundcal_json(&["replay", recording.to_str().unwrap(), "--json"]);
    assert_eq!(code, replay_code, "live {live}\nreplay {replayed}");
    assert_eq!(live["status"], replayed["status"]);

    // The same mount, to what f32 feet allow.
    let (a, b) = (mount_of(&live).values(), mount_of(&replayed).values());
    for k in 0..3 {
        assert!(
            (a[k] - b[k]).abs() < 0.001,
            "angle {k}: {} vs {}",
            a[k],
            b[k]
        );
    }
    for k in 3..6 {
        assert!(
            (a[k] - b[k]).abs() < 0.01,
            "position {k}: {} vs {}",
            a[k],
            b[k]
        );
    }
    assert_eq!(
        live["summary"]["poses_used"], replayed["summary"]["poses_used"],
        "{live}"
    );

    // Every recorded pose was sent exactly as recorded and acted on once, in
    // the recorded order; nothing else was asked.
    let ids: Vec<u64> = Recording::open(recording)
        .unwrap()
        .poses
        .iter()
        .map(|p| u64::from(p.index))
        .collect();
    let stats_line = stderr
        .lines()
        .find_map(|l| l.strip_prefix("sim-robot: stats "))
        .expect("the stats line");
    let stats: Value = serde_json::from_str(stats_line).unwrap();
    let accepted: Vec<u64> = stats["replay"]["accepted"]
        .as_array()
        .expect("a replay tally")
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert_eq!(accepted, ids, "{stats}");
    assert_eq!(
        stats["replay"]["mismatches"],
        Value::Array(vec![]),
        "{stats}"
    );

    // The link was lossy, and the session rode it out.
    let faults = &stats["faults"];
    assert!(faults["lost_in"].as_u64().unwrap() > 0, "{stats}");
    assert!(faults["lost_out"].as_u64().unwrap() > 0, "{stats}");
    let mut new_set_poses: BTreeMap<u64, usize> = BTreeMap::new();
    for line in std::fs::read_to_string(&receipts).unwrap().lines() {
        let v: Value = serde_json::from_str(line).unwrap();
        if v["kind"] == "SET_POSE" && v["outcome"] == "new" {
            *new_set_poses
                .entry(v["pose_id"].as_u64().unwrap())
                .or_default() += 1;
        }
    }
    assert!(new_set_poses.values().all(|&n| n == 1), "{new_set_poses:?}");
    assert_eq!(new_set_poses.keys().copied().collect::<Vec<_>>(), {
        let mut sorted = ids.clone();
        sorted.sort_unstable();
        sorted
    });
    let _ = std::fs::remove_dir_all(&work);
}

#[test]
fn the_sample_recording_runs_live_over_a_lossy_link_to_the_replay_result() {
    live_session_matches_the_replay("replay-link-sample", &shared().join("data/sample-12"));
}

/// A recording whose pose ids have gaps (a pose left out, as after a failed
/// pose) is asked for by its own ids, not renumbered.
#[test]
fn a_recording_with_gaps_in_its_pose_ids_is_asked_for_by_its_own_ids() {
    let dir = sample_with_poses("replay-link-gaps-recording", |lines| {
        lines
            .into_iter()
            .enumerate()
            .filter(|(k, _)| *k != 4)
            .map(|(_, l)| l)
            .collect()
    });
    let ids: Vec<u32> = Recording::open(&dir)
        .unwrap()
        .poses
        .iter()
        .map(|p| p.index)
        .collect();
    assert!(!ids.contains(&5) && ids.contains(&6), "{ids:?}");
    live_session_matches_the_replay("replay-link-gaps", &dir);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A recording whose pose ids do not fit the link's 16 bits is refused
/// before anything moves, with the pose named.
#[test]
fn a_pose_id_beyond_the_link_is_refused_before_moving() {
    let dir = sample_with_poses("replay-link-big-id", |mut lines| {
        let last = lines.pop().unwrap();
        lines.push(last.replacen("\"index\": 12,", "\"index\": 70000,", 1));
        lines
    });
    assert_eq!(
        Recording::open(&dir).unwrap().poses.last().unwrap().index,
        70000
    );
    let sensor = format!("replay:{}", dir.display());
    let (code, stdout, stderr) =
        common::groundcal(&["calibrate", "--robot", "sim", "--sensor", &sensor, "--json"]);
    assert_eq!(code, 2, "{stdout}\n{stderr}");
    assert!(
        stderr.contains("pose 70000") && stderr.contains("65535"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A copy of the shared sample (its frames linked, not copied) with
/// `poses.jsonl`'s lines edited.
fn sample_with_poses(tag: &str, edit: impl FnOnce(Vec<String>) -> Vec<String>) -> common::TempDir {
    let sample = shared().join("data/sample-12");
    let dir = temp_dir(tag);
    std::fs::copy(sample.join("session.json"), dir.join("session.json")).unwrap();
    std::os::unix::fs::symlink(
        sample.join("kinect").canonicalize().unwrap(),
        dir.join("kinect"),
    )
    .unwrap();
    let lines: Vec<String> = std::fs::read_to_string(sample.join("poses.jsonl"))
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(str::to_owned)
        .collect();
    std::fs::write(dir.join("poses.jsonl"), edit(lines).join("\n") + "\n").unwrap();
    dir
}
