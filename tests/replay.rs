//! `groundcal replay` on the shared 12-pose sample recording, and on damaged
//! copies of it.

mod common;

use std::path::{Path, PathBuf};

use common::{distance, groundcal, groundcal_json, mount_of, shared};
use groundcal::calib::geometry::PoseDegMm;
use groundcal::calib::observe::BodyPoseSource;
use groundcal::formats::recording::Recording;
use groundcal::solving::replay::{replay, ReplayOptions};

fn sample() -> PathBuf {
    shared().join("data/sample-12")
}

fn truth() -> PoseDegMm {
    let text = std::fs::read_to_string(shared().join("data/sample-12.truth.json")).unwrap();
    let value: serde_json::Value = serde_json::from_str(&text).unwrap();
    serde_json::from_value(value["extrinsics"].clone()).unwrap()
}

#[test]
fn the_sample_recording_is_accepted_and_matches_its_truth() {
    let (code, result) = groundcal_json(&["replay", sample().to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{result:#}");
    assert_eq!(result["status"], "accepted");
    let (angle, offset) = distance(&mount_of(&result), &truth());
    assert!(angle <= 0.03, "rotation off by {angle}°");
    assert!(offset <= 1.0, "translation off by {offset} mm");
    assert_eq!(result["poses"].as_array().unwrap().len(), 12);
    assert_eq!(result["kinect_tilt_deg"], -20.0);
}

/// The method's point: the real pose from the feet, not the commanded one.
#[test]
fn trusting_the_commanded_poses_fails_the_bound_that_the_feet_meet() {
    let recording = Recording::open(&sample()).unwrap();
    let solve = |source| {
        let mut options = ReplayOptions::default();
        options.pose.body_pose_source = source;
        let result = serde_json::to_value(replay(&recording, &options).unwrap().result).unwrap();
        distance(&mount_of(&result), &truth())
    };
    let (feet_angle, feet_offset) = solve(BodyPoseSource::Feet);
    let (commanded_angle, commanded_offset) = solve(BodyPoseSource::Commanded);
    assert!(feet_angle <= 0.03 && feet_offset <= 1.0);
    assert!(
        commanded_angle > 0.03 || commanded_offset > 1.0,
        "commanded poses gave {commanded_angle}° and {commanded_offset} mm: the test cannot tell feet from commands"
    );
    assert!(commanded_angle > 3.0 * feet_angle || commanded_offset > 3.0 * feet_offset);
}

#[test]
fn the_result_is_bit_identical_for_any_thread_count() {
    let dir = sample();
    let run = |threads: &str| {
        groundcal(&[
            "replay",
            dir.to_str().unwrap(),
            "--json",
            "--threads",
            threads,
        ])
        .1
    };
    let one = run("1");
    assert!(!one.is_empty());
    assert_eq!(one, run("2"));
    assert_eq!(one, run("3"));
    assert_eq!(one, run("2"));
}

/// A copy of the sample recording to damage.
struct Copy(PathBuf);

impl Copy {
    fn new(tag: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("groundcal-replay-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("kinect")).unwrap();
        for name in ["session.json", "poses.jsonl"] {
            std::fs::copy(sample().join(name), dir.join(name)).unwrap();
        }
        for entry in std::fs::read_dir(sample().join("kinect")).unwrap() {
            let entry = entry.unwrap();
            std::fs::copy(entry.path(), dir.join("kinect").join(entry.file_name())).unwrap();
        }
        Self(dir)
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    fn edit(&self, name: &str, f: impl FnOnce(String) -> String) {
        let path = self.path(name);
        std::fs::write(&path, f(std::fs::read_to_string(&path).unwrap())).unwrap();
    }

    fn replay(&self) -> (i32, String, String) {
        groundcal(&["replay", self.0.to_str().unwrap(), "--json"])
    }
}

impl Drop for Copy {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn assert_bad(copy: &Copy, mentions: &[&str]) {
    let (code, stdout, stderr) = copy.replay();
    assert_eq!(code, 2, "stderr: {stderr}");
    assert!(stdout.is_empty());
    assert!(!stderr.contains("panicked"), "{stderr}");
    for m in mentions {
        assert!(
            stderr.contains(m),
            "stderr does not mention {m:?}: {stderr}"
        );
    }
}

#[test]
fn a_truncated_frame_is_named() {
    let copy = Copy::new("truncated");
    let frame = copy.path("kinect/d-1700000000.006999-8007000.pgm");
    let bytes = std::fs::read(&frame).unwrap();
    std::fs::write(&frame, &bytes[..bytes.len() / 2]).unwrap();
    assert_bad(
        &copy,
        &[
            "d-1700000000.006999-8007000.pgm",
            "614417 bytes",
            "truncated",
        ],
    );
}

#[test]
fn a_missing_frame_and_a_name_not_in_the_index_are_named() {
    let copy = Copy::new("missing");
    std::fs::remove_file(copy.path("kinect/d-1700000000.001000-2001000.pgm")).unwrap();
    assert_bad(&copy, &["d-1700000000.001000-2001000.pgm"]);
    let copy = Copy::new("unindexed");
    copy.edit("kinect/INDEX.txt", |t| {
        t.replace("d-1700000000.002000-3002000.pgm\n", "")
    });
    assert_bad(
        &copy,
        &[
            "poses.jsonl:1:",
            "d-1700000000.002000-3002000.pgm",
            "INDEX.txt",
        ],
    );
}

/// The accelerometer readings a pose names (groundcal's key beyond
/// recording.md) must be in the INDEX and be accelerometer files.
#[test]
fn an_accelerometer_reading_not_in_the_index_or_not_one_is_named() {
    let copy = Copy::new("accelerometer");
    copy.edit("poses.jsonl", |t| {
        let mut lines: Vec<String> = t.lines().map(String::from).collect();
        let mut pose: serde_json::Value = serde_json::from_str(&lines[1]).unwrap();
        pose["accelerometer"] = serde_json::json!(["a-1700000000.100000-1.dump"]);
        lines[1] = pose.to_string();
        lines.join("\n") + "\n"
    });
    assert_bad(
        &copy,
        &[
            "poses.jsonl:2:",
            "accelerometer reading \"a-1700000000.100000-1.dump\" is not in kinect/INDEX.txt",
        ],
    );
    let copy = Copy::new("accelerometer-kind");
    copy.edit("poses.jsonl", |t| {
        let mut lines: Vec<String> = t.lines().map(String::from).collect();
        let mut pose: serde_json::Value = serde_json::from_str(&lines[1]).unwrap();
        let frame = pose["depth_frames"][0].clone();
        pose["accelerometer"] = serde_json::json!([frame]);
        lines[1] = pose.to_string();
        lines.join("\n") + "\n"
    });
    assert_bad(
        &copy,
        &["poses.jsonl:2:", "is not an accelerometer reading"],
    );
}

#[test]
fn bad_numbers_feet_and_versions_are_named() {
    let copy = Copy::new("version");
    copy.edit("session.json", |t| {
        t.replace("\"version\": 1", "\"version\": 2")
    });
    assert_bad(&copy, &["session.json", "version 2"]);

    let copy = Copy::new("feet");
    copy.edit("poses.jsonl", |t| {
        let mut lines: Vec<String> = t.lines().map(String::from).collect();
        let mut pose: serde_json::Value = serde_json::from_str(&lines[3]).unwrap();
        pose["feet_body_mm"].as_array_mut().unwrap().pop();
        lines[3] = pose.to_string();
        lines.join("\n") + "\n"
    });
    assert_bad(&copy, &["poses.jsonl:4:", "six feet"]);

    let copy = Copy::new("nan");
    copy.edit("poses.jsonl", |t| {
        t.replacen("\"py_mm\": 615", "\"py_mm\": NaN", 1)
    });
    assert_bad(&copy, &["poses.jsonl:1:"]);

    let copy = Copy::new("pgm");
    let frame = copy.path("kinect/d-1700000000.001000-2001000.pgm");
    let mut bytes = std::fs::read(&frame).unwrap();
    bytes[0] = b'Q';
    std::fs::write(&frame, bytes).unwrap();
    assert_bad(&copy, &["d-1700000000.001000-2001000.pgm"]);
}

#[test]
fn a_pose_without_frames_is_skipped_and_said_so() {
    let copy = Copy::new("noframes");
    copy.edit("poses.jsonl", |t| {
        let mut lines: Vec<String> = t.lines().map(String::from).collect();
        let mut pose: serde_json::Value = serde_json::from_str(&lines[4]).unwrap();
        pose["depth_frames"] = serde_json::json!([]);
        lines[4] = pose.to_string();
        lines.join("\n") + "\n"
    });
    let (code, stdout, _) = copy.replay();
    let result: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let pose = &result["poses"][4];
    assert_eq!(pose["index"], 5);
    assert_eq!(pose["used"], false);
    assert!(pose["reason"].as_str().unwrap().contains("no depth frames"));
    assert!(pose.get("plane").is_none());
    assert_eq!(result["summary"]["poses_used"], 11);
    assert_eq!(result["summary"]["poses_total"], 12);
    assert!(result["notes"]
        .as_array()
        .unwrap()
        .iter()
        .any(|n| n.as_str().unwrap().starts_with("pose 5:")));
    assert_eq!(code, 0, "11 of 12 poses still calibrate");
}

/// A recording cut off part-way through its last record (a power cut
/// while recording) is refused, naming the file, the line and the byte, the
/// same whether a newline followed the cut or not; with `--cut-off` it is
/// replayed without that pose, and the result and stderr say so.
#[test]
fn a_recording_cut_off_mid_record_is_named_and_replayed_only_when_asked() {
    let copy = Copy::new("cut");
    let text = std::fs::read_to_string(copy.path("poses.jsonl")).unwrap();
    let last_line_starts = text.trim_end().rfind('\n').unwrap() + 1;
    let cut = last_line_starts + 40;
    for (what, tail) in [("without a newline", ""), ("with a newline", "\n")] {
        std::fs::write(copy.path("poses.jsonl"), format!("{}{tail}", &text[..cut])).unwrap();
        let (code, stdout, stderr) = copy.replay();
        assert_eq!(code, 2, "{what}: {stderr}");
        assert!(stdout.is_empty(), "{what}: {stdout}");
        let named = format!(
            "poses.jsonl:12: the record that starts at byte {last_line_starts} ends after 40 bytes"
        );
        assert!(stderr.contains(&named), "{what}: {stderr}");
        assert!(stderr.contains("--cut-off"), "{what}: {stderr}");

        let (code, stdout, stderr) =
            groundcal(&["replay", copy.0.to_str().unwrap(), "--json", "--cut-off"]);
        let result: serde_json::Value =
            serde_json::from_str(&stdout).unwrap_or_else(|_| panic!("{what}: {stderr}"));
        assert_eq!(code, 0, "{what}: {stderr}");
        assert!(stderr.contains(&named), "{what}: {stderr}");
        assert_eq!(result["poses"].as_array().unwrap().len(), 11);
        assert!(
            result["notes"].as_array().unwrap().iter().any(|n| {
                let n = n.as_str().unwrap();
                n.contains("line 12") && n.contains("--cut-off")
            }),
            "{what}: {}",
            result["notes"]
        );
    }
    // A record cut off before the last one is no power cut: it is an error
    // that names its line, with or without the flag.
    let mut lines: Vec<&str> = text.lines().collect();
    let whole = lines[6].to_string();
    lines[6] = &whole[..40];
    std::fs::write(copy.path("poses.jsonl"), lines.join("\n") + "\n").unwrap();
    let (code, _, stderr) = groundcal(&["replay", copy.0.to_str().unwrap(), "--json", "--cut-off"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("poses.jsonl:7: not a pose record"),
        "{stderr}"
    );
}

/// Control characters in what a file says (a name in INDEX.txt: a
/// terminal title, a screen clear, a NUL) are escaped in the message, never
/// written raw to the operator's terminal.
#[test]
fn control_characters_from_a_file_are_escaped_in_messages() {
    let copy = Copy::new("escapes");
    copy.edit("kinect/INDEX.txt", |t| {
        format!("{t}\u{1b}]0;owned\u{7}\u{1b}[2Jd-1.0-\u{0}2.pgm\nmore\n")
    });
    let (code, _, stderr) = copy.replay();
    assert_eq!(code, 2, "{stderr}");
    assert!(
        !stderr.chars().any(|c| c.is_control() && c != '\n'),
        "raw control characters on stderr: {stderr:?}"
    );
    assert!(
        stderr.contains("\\u{1b}]0;owned\\u{7}\\u{1b}[2J"),
        "{stderr}"
    );
}

/// An empty `poses.jsonl` is bad input (exit 2, named), not a rejected
/// calibration (exit 3).
#[test]
fn a_recording_without_poses_is_bad_input() {
    let copy = Copy::new("empty");
    std::fs::write(copy.path("poses.jsonl"), "").unwrap();
    assert_bad(&copy, &["poses.jsonl", "no pose record"]);
}

/// A FIFO where a file should be would wait for a writer for ever: it is
/// refused at once, by what it is.
#[test]
fn a_fifo_in_place_of_a_file_is_refused_not_waited_on() {
    let copy = Copy::new("fifo");
    std::fs::remove_file(copy.path("session.json")).unwrap();
    let made = std::process::Command::new("mkfifo")
        .arg(copy.path("session.json"))
        .status()
        .unwrap();
    assert!(made.success());
    let (code, _, stderr) = common::groundcal_within(
        &["replay", copy.0.to_str().unwrap(), "--json"],
        std::time::Duration::from_secs(10),
    );
    assert_eq!(code, 2, "(-1: killed after 10 s) {stderr}");
    assert!(
        stderr.contains("session.json") && stderr.contains("a FIFO"),
        "{stderr}"
    );
}

#[test]
fn not_a_recording_is_named() {
    let (code, _, stderr) = groundcal(&["replay", "/nonexistent/recording", "--json"]);
    assert_eq!(code, 2);
    assert!(
        stderr.contains("/nonexistent/recording") && stderr.contains("not a directory"),
        "{stderr}"
    );
    let path = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (code, _, stderr) = groundcal(&["replay", path.join("tests").to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(stderr.contains("session.json"), "{stderr}");
}

#[test]
fn replay_writes_a_self_contained_report() {
    let out = std::env::temp_dir().join(format!("groundcal-report-{}", std::process::id()));
    let (code, _, stderr) = groundcal(&[
        "replay",
        sample().to_str().unwrap(),
        "--json",
        "--report",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    let _ = std::fs::remove_dir_all(&out);
    assert!(html.contains("Passed its checks"));
    // θ, e_d, Δd, a/b/c, d and the schedule's tilts.
    assert_eq!(html.matches("<svg").count(), 6);
    // What only a recording tells: its setup, nominal mount, commanded poses.
    assert!(html.contains("“sample”, 12 poses, 2 depth frames per pose"));
    assert!(html.contains("<table class=\"nominal\">"));
    assert_eq!(
        html.matches("<td class=\"dd\">").count(),
        12,
        "a Δd per pose"
    );
    let commanded = &html[html.find("<table class=\"commanded\">").unwrap()..];
    let commanded = &commanded[..commanded.find("</table>").unwrap()];
    assert_eq!(
        commanded.matches("<tr><td>").count(),
        12,
        "a commanded pose per pose"
    );
    // Eight gates: seven, and the depth scale taken (1, as its 12 poses pin
    // it only to ±0.4 %) within 3σ of where they put it. The sample was made
    // without a depth pattern, and none is found (before the pattern's
    // statistics came from the poses' own scatter, a 0.7-mm warp was
    // "found" and corrected, with a gate of its own).
    assert_eq!(html.matches("✓ pass").count(), 8, "every gate passed");
    assert!(
        html.contains("none found"),
        "no depth pattern in the sample"
    );
    assert!(!html.contains("http://") && !html.contains("https://"));
    // Provenance: the version and the input's digest.
    assert!(html.contains(env!("CARGO_PKG_VERSION")));
    assert!(html.contains("sample-12"));
}

/// `groundcal replay --json | head`: the reader goes away before the result
/// is printed. The command ends by SIGPIPE as `cat` would, without a panic
/// and its backtrace (before, it panicked: "failed printing to stdout").
#[cfg(unix)]
#[test]
fn a_reader_that_goes_away_ends_the_command_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let sample = sample();
    for json in [true, false] {
        let mut args = vec!["replay", sample.to_str().unwrap()];
        if json {
            args.push("--json");
        }
        // The reading end is closed before the replay (tens of
        // milliseconds) has anything to print.
        let (status, stderr) = common::groundcal_with_reader_gone(&args);
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        assert_eq!(status.signal(), Some(13), "{args:?}: {status:?} {stderr}");
    }
}
