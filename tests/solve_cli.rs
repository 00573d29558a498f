//! `groundcal solve` verdicts through the real binary.

mod common;

use common::{groundcal_json, test_data};

#[test]
fn a_schedule_that_never_tilts_exits_3_with_reasons_in_words() {
    let file = test_data("never-tilts.json");
    let (code, result) = groundcal_json(&["solve", file.to_str().unwrap(), "--json"]);
    assert_eq!(code, 3);
    assert_eq!(result["status"], "rejected");
    let reasons: Vec<&str> = result["reasons"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r.as_str().unwrap())
        .collect();
    assert_eq!(
        reasons,
        [
            "rotation of the sensor about the ground normal (α) is not observable: the schedule never tilts the body",
            "the sensor's forward (p_x) and sideways (p_z) positions are not observable: the schedule never tilts the body",
        ]
    );
}

#[test]
fn too_few_poses_is_a_rejection_without_parameters() {
    let text = std::fs::read_to_string(test_data("paper-table3.json")).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    doc["observations"].as_array_mut().unwrap().truncate(2);
    let path =
        std::env::temp_dir().join(format!("groundcal-two-poses-{}.json", std::process::id()));
    std::fs::write(&path, doc.to_string()).unwrap();
    let (code, result) = groundcal_json(&["solve", path.to_str().unwrap(), "--json"]);
    let _ = std::fs::remove_file(&path);
    assert_eq!(code, 3);
    assert!(result.get("robot_from_sensor").is_none());
    assert!(result["reasons"][0]
        .as_str()
        .unwrap()
        .contains("only 2 usable poses"));
    assert_eq!(result["poses"].as_array().unwrap().len(), 2);
}

#[test]
fn the_readable_table_shows_verdict_parameters_and_poses() {
    let file = test_data("paper-table2-printed.json");
    let (code, stdout, _) = common::groundcal(&["solve", file.to_str().unwrap()]);
    assert_eq!(code, 3);
    assert!(stdout.contains("  10  no "), "{stdout}");
    // The verdict and the six values come last: a long schedule's table
    // does not push them off the screen.
    let verdict = stdout
        .find("verdict: failed its checks")
        .expect("the verdict");
    assert!(verdict > stdout.find("  10  no ").unwrap(), "{stdout}");
    let last: Vec<&str> = stdout.lines().rev().take(6).collect();
    for (line, name) in last
        .iter()
        .rev()
        .zip(["alpha", "beta", "gamma", "px", "py", "pz"])
    {
        assert!(line.trim_start().starts_with(name), "{stdout}");
    }
}
