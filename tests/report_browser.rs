//! The calibration report in a real browser: headless Chromium, driven by
//! Playwright (`tests/browser/report.mjs`), opens the page as a phone and as
//! a laptop would, and must see the verdict, the charts and every section an
//! operator reads, with no console error, no script error, no network
//! request and nothing wider than a 390 px phone. Two reports: the paper's
//! Table 2 (ground planes only, rejected) and the shared 12-pose sample
//! recording replayed (accepted, with its setup, nominal mount and commanded
//! poses). What the browser shows is compared with the result it was written
//! from. Screenshots land in `target/test-screenshots/` for a person to look
//! at: `report.png`, `report-desktop.png` (Table 2), `report-sample.png`,
//! `report-sample-desktop.png`.
//!
//! Needs Node.js ≥ 20, `npm ci` in `tests/browser` and Debian's chromium. Under
//! `CI=true` a missing one fails the test; elsewhere the test warns and returns.

mod common;

use std::fs;

use serde_json::Value;

use groundcal::calib::calibrate::{calibrate, CalibrationSettings};
use groundcal::calib::outcome::{position_words, rotation_words};
use groundcal::formats::output::ResultJson;
use groundcal::formats::recording::planes::read_planes;
use groundcal::formats::recording::Recording;
use groundcal::formats::report::{write_report, Provenance};
use groundcal::solving::replay::{replay, AlsoKeep, ReplayOptions};

/// Writes the report, opens it in Chromium and returns the phone's and the
/// laptop's views, after the checks every report must pass.
fn open_in_chromium(tag: &str, result: &ResultJson, provenance: &Provenance) -> Vec<Value> {
    let dir = common::temp_dir(&format!("report-browser-{tag}"));
    let html = write_report(&dir.join("report"), result, provenance).expect("report written");
    let shots = common::root().join("target/test-screenshots");
    fs::create_dir_all(&shots).expect("screenshot directory");
    let name = if tag == "table2" {
        "report".to_string()
    } else {
        format!("report-{tag}")
    };
    let png = shots.join(format!("{name}.png"));
    let desktop = shots.join(format!("{name}-desktop.png"));
    let _ = fs::remove_file(&png);
    let _ = fs::remove_file(&desktop);

    let seen = common::run_browser_script("report.mjs", &[html.as_os_str(), png.as_os_str()]);
    let views = seen["seen"].as_array().expect("views").clone();
    assert_eq!(views.len(), 2, "{seen}");
    let verdict = if result.accepted() {
        "Passed its checks"
    } else {
        "Failed its checks"
    };
    for view in &views {
        assert_eq!(view["verdict"], verdict, "{view}");
        assert!(view["rendered"].as_u64().unwrap() >= 4, "{view}");
        assert_eq!(view["overflow"].as_f64(), Some(0.0), "{view}");
        assert_eq!(view["sticking"], serde_json::json!([]), "{view}");
    }
    for path in [&png, &desktop] {
        let bytes = fs::read(path).expect("screenshot saved");
        assert!(
            bytes.len() > 1000 && bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
            "{} is not a PNG with content",
            path.display()
        );
    }
    fs::remove_dir_all(&dir).unwrap();
    views
}

/// A number as the page prints it (`+0.12`, `-3.5`, `4.50°`).
fn number(text: &str) -> f64 {
    let cleaned: String = text
        .chars()
        .filter(|c| c.is_ascii_digit() || matches!(c, '.' | '-' | '+'))
        .collect();
    cleaned
        .parse()
        .unwrap_or_else(|e| panic!("{text:?} is not a number: {e}"))
}

fn capitalised(words: &str) -> String {
    let mut chars = words.chars();
    chars.next().map_or_else(String::new, |first| {
        first.to_uppercase().collect::<String>() + chars.as_str()
    })
}

/// The sections every report shows from its result: each gate with its
/// verdict, the heat map's 36 values, the weakest directions named in
/// words, a signed residual per pose with a plane (used rows = poses used).
fn check_common_sections(sections: &Value, result: &ResultJson) {
    let gates = sections["gates"]["rows"].as_array().unwrap();
    assert_eq!(gates.len(), result.gate_checks.len(), "{sections}");
    // Every gate; the warp's when the ground looked warped, the pattern's
    // when one was corrected, the depth scale taken's when the poses pinned
    // it too loosely to estimate.
    let optional = result
        .gate_checks
        .iter()
        .filter(|c| {
            ["warp_max_mm", "pattern_max_mm", "depth_scale_taken_sigmas"].contains(&c.gate.as_str())
        })
        .count();
    assert_eq!(gates.len(), 7 + optional, "every gate: {sections}");
    for (row, check) in gates.iter().zip(&result.gate_checks) {
        assert_eq!(row["gate"], check.gate.as_str(), "{row}");
        assert_eq!(row["passed"], check.passed, "{row}");
        let verdict = row["cells"][3].as_str().unwrap();
        assert_eq!(
            verdict,
            if check.passed { "✓ pass" } else { "✗ FAIL" },
            "{row}"
        );
    }

    let heat = &sections["correlations"];
    let cells = heat["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 36, "{heat}");
    let r = result.correlations.expect("correlations");
    for (k, cell) in cells.iter().enumerate() {
        let (i, j) = (k / 6, k % 6);
        let text = cell["text"].as_str().unwrap();
        if i == j {
            assert_eq!(text, "1", "{cell}");
        } else {
            assert!(
                (number(text) - r[i][j]).abs() <= 0.005 + 1e-9,
                "cell {i},{j}: {text} against {}",
                r[i][j]
            );
        }
    }

    let o = result.observability.as_ref().expect("observability");
    let weakest = sections["observability"]["weakest"].as_array().unwrap();
    assert_eq!(weakest.len(), 2, "{weakest:?}");
    assert_eq!(weakest[0]["kind"], "rotation");
    assert_eq!(
        weakest[0]["direction"],
        capitalised(&rotation_words(&o.rotation_weakest_axis.unwrap())).as_str()
    );
    assert_eq!(weakest[1]["kind"], "position");
    assert_eq!(
        weakest[1]["direction"],
        capitalised(&position_words(&o.translation_weakest_axis.unwrap())).as_str()
    );

    let rows = sections["residuals"]["rows"].as_array().unwrap();
    let with_planes: Vec<_> = result
        .poses
        .iter()
        .filter(|p| p.plane.is_some() && p.predicted_plane.is_some())
        .collect();
    assert_eq!(rows.len(), with_planes.len(), "{rows:?}");
    let used = rows.iter().filter(|r| r["used"] == true).count();
    assert_eq!(used, result.summary.as_ref().unwrap().poses_used);
    for (row, pose) in rows.iter().zip(&with_planes) {
        assert_eq!(
            number(row["cells"][0].as_str().unwrap()),
            f64::from(pose.index)
        );
        let d = number(row["cells"][1].as_str().unwrap());
        let expected = (pose.plane.unwrap().d_m - pose.predicted_plane.unwrap().d_m) * 1e3;
        assert!((d - expected).abs() <= 0.005 + 1e-9, "{row}: {expected}");
        // Signed, and as large as e_d.
        assert!((d.abs() - pose.e_d_mm.unwrap()).abs() <= 0.006, "{row}");
    }
}

/// The paper's Table 2 (ground planes, no recording): rejected, with failing
/// gates drawn as lines, and no setup, nominal mount or commanded poses.
#[test]
fn report_of_ground_planes_opens_cleanly_on_a_phone_and_a_laptop() {
    if !common::browser_ready("report_browser") {
        return;
    }
    let input = common::test_data("paper-table2-printed.json");
    let observations = read_planes(&input).expect("Table 2 reads");
    let calibration =
        calibrate(&observations, &CalibrationSettings::default()).expect("Table 2 solves");
    let result = ResultJson::from_calibration(&calibration);
    // The report labels the digest BLAKE3, as `replay` computes it.
    let digest = blake3::hash(&fs::read(&input).unwrap())
        .to_hex()
        .to_string();
    let provenance = Provenance::now("tests/data/paper-table2-printed.json", digest);

    for view in open_in_chromium("table2", &result, &provenance) {
        let sections = &view["sections"];
        check_common_sections(sections, &result);
        let failed: Vec<&str> = sections["gates"]["rows"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["passed"] == false)
            .map(|r| r["gate"].as_str().unwrap())
            .collect();
        assert_eq!(
            failed,
            [
                "e_d_max_mm",
                "sigma_angle_max_deg",
                "sigma_position_max_mm",
                "min_poses_used"
            ],
            "{view}"
        );
        // Both gates are near the data: drawn as lines on θ's and e_d's charts.
        assert_eq!(
            sections["accuracy"]["gateLabels"],
            serde_json::json!(["gate 1.00°", "gate 5.0 mm"]),
            "{view}"
        );
        // Pose 10 is set aside: its residual row is shaded.
        let rows = sections["residuals"]["rows"].as_array().unwrap();
        assert!(rows
            .iter()
            .any(|r| r["used"] == false && r["cells"][0] == "10"));
        // A planes file says nothing of the setup, and says so.
        let setup = &sections["setup"];
        assert_eq!(
            setup["facts"]["input"],
            "tests/data/paper-table2-printed.json"
        );
        assert_eq!(setup["facts"]["nominal mount"], "not known");
        assert_eq!(setup["nominal"], serde_json::json!([]));
        assert!(
            setup["notes"]
                .as_array()
                .unwrap()
                .iter()
                .any(|n| n.as_str().unwrap().contains("No nominal mount is known")),
            "{setup}"
        );
        assert_eq!(sections["commanded"]["rows"], serde_json::json!([]));
        assert!(
            sections["commanded"]["none"]
                .as_str()
                .unwrap()
                .contains("no commanded poses"),
            "{view}"
        );
        // Measured and predicted are told apart: hollow squares, in the key.
        assert!(sections["planes"]["squares"].as_u64().unwrap() >= 5 * 4);
        let legend = sections["planes"]["legend"].to_string();
        assert!(legend.contains("measured") && legend.contains("predicted"));
    }
}

/// The shared sample recording replayed: accepted, with the setup it was
/// recorded with, the change from its nominal mount and the commanded pose of
/// each of its 12 poses.
#[test]
fn report_of_a_recording_shows_its_setup_and_commanded_poses() {
    if !common::browser_ready("report_browser") {
        return;
    }
    let dir = common::shared().join("data/sample-12");
    let recording = Recording::open(&dir).expect("the sample opens");
    let options = ReplayOptions {
        keep: AlsoKeep {
            input_digest: true,
            ..Default::default()
        },
        ..Default::default()
    };
    let replayed = replay(&recording, &options).expect("the sample replays");
    let result = replayed.result;
    assert!(result.accepted(), "{:?}", result.reasons);
    let digest = replayed.input_digest.expect("asked for");
    let provenance = Provenance::now("../shared/data/sample-12", digest);

    for view in open_in_chromium("sample", &result, &provenance) {
        let sections = &view["sections"];
        check_common_sections(sections, &result);
        assert!(result.gate_checks.iter().all(|c| c.passed));
        // The poses lie far below the gates: said under the charts.
        let notes = sections["accuracy"]["notes"].as_array().unwrap();
        assert_eq!(notes.len(), 2, "{view}");
        assert!(notes[0].as_str().unwrap().contains("The gate (1.00°)"));

        let facts = &sections["setup"]["facts"];
        assert_eq!(facts["input"], "../shared/data/sample-12");
        assert_eq!(facts["robot"], "octopus");
        assert_eq!(
            facts["schedule"],
            "“sample”, 12 poses, 2 depth frames per pose"
        );
        assert!(facts["depth model"]
            .as_str()
            .unwrap()
            .starts_with("inverse-linear"));
        assert!(facts["sensor tilt"].as_str().unwrap().starts_with("-20.0°"));
        assert!(facts["nominal mount"]
            .as_str()
            .unwrap()
            .starts_with("α 4.5°, β -30.7°, γ -2.0°; p 491.3, 331.6, 8.7 mm"));
        assert!(facts["quality gates"]
            .as_str()
            .unwrap()
            .contains("built-in"));

        // Change = result − nominal, for each of the six parameters.
        let nominal = [4.5, -30.7, -2.0, 491.3, 331.6, 8.7];
        let m = result.robot_from_sensor.as_ref().unwrap();
        let values = m.values();
        let rows = sections["setup"]["nominal"].as_array().unwrap();
        assert_eq!(rows.len(), 6, "{view}");
        for ((row, value), nominal) in rows.iter().zip(values).zip(nominal) {
            let change = number(row[3].as_str().unwrap());
            assert!(
                (change - (value - nominal)).abs() <= 0.051,
                "{row}: {value} - {nominal}"
            );
        }

        // Every pose's commanded attitude, as recorded.
        let rows = sections["commanded"]["rows"].as_array().unwrap();
        assert_eq!(rows.len(), 12, "{view}");
        for (row, pose) in rows.iter().zip(&recording.poses) {
            let cell = |k: usize| number(row[k].as_str().unwrap());
            assert_eq!(cell(0), f64::from(pose.index));
            assert_eq!(cell(1), pose.commanded.gamma_deg, "roll: {row}");
            assert_eq!(cell(2), pose.commanded.beta_deg, "pitch: {row}");
            assert_eq!(cell(3), pose.commanded.alpha_deg, "yaw: {row}");
            assert_eq!(cell(4), pose.commanded.py_mm, "height: {row}");
        }
        assert_eq!(sections["commanded"]["svgs"], 1, "the chart of tilts");
    }
}

/// A calibration whose Kinect warps its depth (a radial bowl of ±0.5 raw
/// units, simulated): the report draws the warp as a picture of the image,
/// coloured by the depth error at 2 m as the result says cell by cell, with
/// its scale in millimetres, at phone and laptop size. Screenshots:
/// `report-pattern.png`, `report-pattern-desktop.png`.
#[test]
fn report_draws_the_depth_images_own_warp() {
    if !common::browser_ready("report_browser") {
        return;
    }
    let dir = common::temp_dir("report-pattern");
    let line = "depth_distortion = { shape = \"radial\", amplitude_raw = 0.5 }";
    let config = common::sim_config_with_pattern(&dir, line, false);
    common::on_schedule(&config, "designed-52");
    let (code, out, err) =
        common::groundcal(&["calibrate", "--config", config.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{err}");
    let result = ResultJson::parse(serde_json::from_str(&out).unwrap()).expect("a result");
    let pattern = result.depth_pattern.clone().expect("a depth pattern");
    assert!(pattern.corrected, "{}", pattern.note);
    let provenance = Provenance::now("a simulated Kinect with a radial pattern", String::new());

    for view in open_in_chromium("pattern", &result, &provenance) {
        let seen = &view["pattern"];
        assert_eq!(seen["heading"], "The depth image's own warp", "{seen}");
        let words = seen["words"].as_str().unwrap();
        assert!(
            words.contains(&format!("{:.1} mm", pattern.largest_mm_at_2m))
                && words.contains("corrected"),
            "{words}"
        );
        let picture = &seen["picture"];
        assert_eq!(picture["naturalWidth"], pattern.columns, "{picture}");
        assert_eq!(picture["naturalHeight"], pattern.rows);
        // Wide enough to read on a phone, and 4:3 as the image.
        let (width, height) = (
            picture["width"].as_f64().unwrap(),
            picture["height"].as_f64().unwrap(),
        );
        assert!(
            width >= 300.0 && (width / height - 4.0 / 3.0).abs() < 0.02,
            "{width} × {height}"
        );
        // Each cell coloured as its value says: red farther, blue nearer,
        // grey unseen; the darkest where the error is largest.
        let hex = picture["rgb"].as_str().unwrap();
        assert_eq!(hex.len(), 6 * pattern.raw.len());
        let rgb: Vec<[i64; 3]> = hex
            .as_bytes()
            .chunks(6)
            .map(|c| {
                let part = |k: usize| {
                    i64::from_str_radix(std::str::from_utf8(&c[k..k + 2]).unwrap(), 16).unwrap()
                };
                [part(0), part(2), part(4)]
            })
            .collect();
        let (mut farther, mut nearer, mut unseen) = (0, 0, 0);
        for (cell, colour) in pattern.raw.iter().zip(rgb) {
            let c = colour;
            match cell {
                None => {
                    assert_eq!(c, [190, 190, 190]);
                    unseen += 1;
                }
                Some(raw) => {
                    let error_mm = -4.0 * raw / pattern.raw_per_inverse_depth * 1e3;
                    if error_mm > 0.5 {
                        assert!(
                            c[0] > c[2],
                            "{raw} raw reads {error_mm} mm farther, drawn {c:?}"
                        );
                        farther += 1;
                    } else if error_mm < -0.5 {
                        assert!(
                            c[2] > c[0],
                            "{raw} raw reads {error_mm} mm nearer, drawn {c:?}"
                        );
                        nearer += 1;
                    }
                }
            }
        }
        // The bowl: nearer in the middle, farther at the corners.
        assert!(
            farther > 500 && nearer > 500,
            "{farther} farther, {nearer} nearer, {unseen} unseen"
        );
        let ticks: Vec<&str> = seen["ticks"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| t.as_str().unwrap())
            .collect();
        assert_eq!(ticks.len(), 3, "{ticks:?}");
        assert!(
            ticks[0].ends_with("mm nearer") && ticks[2].ends_with("mm farther"),
            "{ticks:?}"
        );
    }
}
