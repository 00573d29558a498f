//! `groundcal solve` on the paper's own numbers (section 5): Tables 2 and 3
//! with Table A1's poses (conventions.md errata: rows 1, 10, 15, 29, 34, 49 are
//! Table A1 poses 1, 15, 8, 25, 37, 45). The expected result is eq. (32).

mod common;

use common::{groundcal_json, test_data};
use serde_json::Value;

const EQ32: [f64; 3] = [-0.4398, -37.4072, -3.0471];

fn angles(result: &Value) -> [f64; 3] {
    let m = &result["robot_from_sensor"];
    ["alpha_deg", "beta_deg", "gamma_deg"].map(|k| m[k].as_f64().expect("angle present"))
}

fn solve(file: &str) -> (i32, Value) {
    let path = test_data(file);
    groundcal_json(&["solve", path.to_str().unwrap(), "--json"])
}

fn assert_angles_within(result: &Value, tolerance_deg: f64) {
    let got = angles(result);
    for (k, (g, e)) in got.iter().zip(EQ32).enumerate() {
        assert!(
            (g - e).abs() <= tolerance_deg,
            "angle {k}: {g}° vs eq. 32's {e}° (tolerance {tolerance_deg}°)"
        );
    }
}

#[test]
fn table3_gives_eq32_within_a_hundredth_of_a_degree() {
    let (_, result) = solve("paper-table3.json");
    assert_angles_within(&result, 0.01);
    assert!(result["poses"]
        .as_array()
        .unwrap()
        .iter()
        .all(|p| p["used"] == true));
}

#[test]
fn table2_measured_planes_with_the_sign_erratum_fixed_give_eq32_within_012_degrees() {
    let (_, result) = solve("paper-table2-fixed.json");
    assert_angles_within(&result, 0.12);
    assert!(result["poses"]
        .as_array()
        .unwrap()
        .iter()
        .all(|p| p["used"] == true));
}

#[test]
fn table2_as_printed_sets_row_10_aside_and_keeps_the_rotation() {
    let (code, result) = solve("paper-table2-printed.json");
    let poses = result["poses"].as_array().unwrap();
    let aside: Vec<&Value> = poses.iter().filter(|p| p["used"] == false).collect();
    assert_eq!(aside.len(), 1, "{poses:#?}");
    assert_eq!(aside[0]["index"], 10);
    let reason = aside[0]["reason"].as_str().unwrap();
    assert!(
        reason.contains("inconsistent with the other poses"),
        "{reason}"
    );
    assert_angles_within(&result, 0.15);
    // Six poses with the tables' inconsistent heights are not a calibration to keep.
    assert_eq!(code, 3);
    assert_eq!(result["status"], "rejected");
}

#[test]
fn the_result_document_follows_cli_md() {
    let (code, result) = solve("paper-table3.json");
    assert!(code == 0 || code == 3);
    for key in [
        "status",
        "reasons",
        "robot_from_sensor",
        "sigma",
        "poses",
        "summary",
    ] {
        assert!(result.get(key).is_some(), "missing {key}");
    }
    let m = &result["robot_from_sensor"];
    let matrix = m["matrix"].as_array().unwrap();
    assert_eq!(matrix.len(), 4);
    assert_eq!(matrix[3], serde_json::json!([0.0, 0.0, 0.0, 1.0]));
    // The matrix's translation is in millimetres, like px_mm.
    assert_eq!(matrix[0][3], m["px_mm"]);
    let q: Vec<f64> = m["quaternion_xyzw"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!((q.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-12);
    let pose = &result["poses"][0];
    for key in ["index", "used", "theta_deg", "e_d_mm", "plane"] {
        assert!(pose.get(key).is_some(), "pose misses {key}");
    }
    for key in [
        "poses_used",
        "theta_deg_mean",
        "theta_deg_max",
        "e_d_mm_mean",
        "e_d_mm_max",
    ] {
        assert!(result["summary"].get(key).is_some(), "summary misses {key}");
    }
}
