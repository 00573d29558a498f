//! `groundcal export` through the real binary: the three formats read back to
//! the result's six parameters, and rejected or broken results are refused with
//! exit status 2 and a message naming the file and the key.

mod common;

use std::path::PathBuf;

use common::{groundcal, groundcal_json, test_data};
use groundcal::calib::geometry::{PoseDegMm, PoseParams};
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};
use serde_json::Value;

/// A temporary file that removes itself.
struct TempFile(PathBuf);

impl TempFile {
    fn new(name: &str, contents: &str) -> Self {
        let path = std::env::temp_dir().join(format!(
            "groundcal-export-{}-{name}.json",
            std::process::id()
        ));
        std::fs::write(&path, contents).unwrap();
        Self(path)
    }

    fn as_str(&self) -> &str {
        self.0.to_str().unwrap()
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// The result of the paper's Table 3 (rejected: exit 3).
fn table3_result() -> Value {
    let file = test_data("paper-table3.json");
    let (code, result) = groundcal_json(&["solve", file.to_str().unwrap(), "--json"]);
    assert_eq!(code, 3, "the paper's Table 3 result is rejected");
    assert_eq!(result["status"], "rejected");
    assert!(result["robot_from_sensor"].is_object());
    result
}

/// The same result, accepted (as a calibration with better poses would be).
fn accepted_result() -> Value {
    let mut result = table3_result();
    result["status"] = "accepted".into();
    result["reasons"] = serde_json::json!([]);
    result
}

fn params_of(result: &Value) -> PoseDegMm {
    serde_json::from_value(serde_json::json!({
        "alpha_deg": result["robot_from_sensor"]["alpha_deg"],
        "beta_deg": result["robot_from_sensor"]["beta_deg"],
        "gamma_deg": result["robot_from_sensor"]["gamma_deg"],
        "px_mm": result["robot_from_sensor"]["px_mm"],
        "py_mm": result["robot_from_sensor"]["py_mm"],
        "pz_mm": result["robot_from_sensor"]["pz_mm"],
    }))
    .unwrap()
}

/// Undoes the frame changes, written out here independently of the library:
/// base_link (x forward, y left, z up) from groundcal's body frame (X forward,
/// Y up, Z right), and the sensor frame (X optical axis, Y up, Z right) from the
/// optical frame (x right, y down, z forward).
fn groundcal_of(base_link_from_optical: &Matrix3<f64>, translation_m: Vector3<f64>) -> PoseDegMm {
    let base_link_from_robot = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
    let sensor_from_optical = Matrix3::new(0.0, 0.0, 1.0, 0.0, -1.0, 0.0, 1.0, 0.0, 0.0);
    let robot_from_sensor =
        base_link_from_robot.transpose() * base_link_from_optical * sensor_from_optical.transpose();
    let translation = base_link_from_robot.transpose() * translation_m;
    PoseDegMm::from_params(&PoseParams::from_rotation_translation(
        &robot_from_sensor,
        translation,
    ))
}

fn assert_same_params(got: &PoseDegMm, want: &PoseDegMm) {
    for (g, w) in got.values().iter().zip(want.values()) {
        assert!((g - w).abs() <= 1e-9, "got {got:?}, want {want:?}");
    }
}

fn export(file: &TempFile, format: &str) -> String {
    let (code, stdout, stderr) = groundcal(&["export", file.as_str(), "--format", format]);
    assert_eq!(code, 0, "--format {format}: {stderr}");
    assert!(!stdout.is_empty());
    stdout
}

fn numbers(text: &str) -> Vec<f64> {
    text.split_whitespace()
        .map(|s| s.parse().unwrap())
        .collect()
}

fn attribute<'a>(text: &'a str, name: &str) -> &'a str {
    let start = text
        .find(&format!(" {name}=\""))
        .unwrap_or_else(|| panic!("no {name} in {text}"))
        + name.len()
        + 3;
    let len = text[start..].find('"').unwrap();
    &text[start..start + len]
}

#[test]
fn urdf_reads_back_to_the_six_parameters() {
    let result = accepted_result();
    let file = TempFile::new("urdf", &result.to_string());
    let urdf = export(&file, "urdf");
    assert!(urdf.contains("<joint name=\"camera_depth_optical_joint\" type=\"fixed\">"));
    assert!(urdf.contains("<parent link=\"base_link\"/>"));
    assert!(urdf.contains("<child link=\"camera_depth_optical_frame\"/>"));
    assert!(urdf.starts_with("<!-- groundcal robot_from_sensor: alpha_deg="));
    let xyz = numbers(attribute(&urdf, "xyz"));
    let rpy = numbers(attribute(&urdf, "rpy"));
    // URDF: roll about x, then pitch about y, then yaw about z (fixed axes).
    let rotation = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]);
    let back = groundcal_of(rotation.matrix(), Vector3::new(xyz[0], xyz[1], xyz[2]));
    assert_same_params(&back, &params_of(&result));
}

#[test]
fn ros_static_reads_back_to_the_six_parameters() {
    let result = accepted_result();
    let file = TempFile::new("ros-static", &result.to_string());
    let line = export(&file, "ros-static");
    assert_eq!(line.lines().count(), 1);
    let words: Vec<&str> = line.split_whitespace().collect();
    let flag = |name: &str| -> &str {
        let k = words
            .iter()
            .position(|w| *w == name)
            .unwrap_or_else(|| panic!("no {name} in {line}"));
        words[k + 1]
    };
    assert_eq!(flag("--frame-id"), "base_link");
    assert_eq!(flag("--child-frame-id"), "camera_depth_optical_frame");
    let value = |name: &str| -> f64 { flag(name).parse().unwrap() };
    let q = UnitQuaternion::from_quaternion(Quaternion::new(
        value("--qw"),
        value("--qx"),
        value("--qy"),
        value("--qz"),
    ));
    let back = groundcal_of(
        q.to_rotation_matrix().matrix(),
        Vector3::new(value("--x"), value("--y"), value("--z")),
    );
    assert_same_params(&back, &params_of(&result));
}

#[test]
fn json_reads_back_to_the_six_parameters() {
    let result = accepted_result();
    let file = TempFile::new("json", &result.to_string());
    let text = export(&file, "json");
    let doc: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(doc["parent"], "base_link");
    assert_eq!(doc["child"], "camera_depth_optical_frame");
    let m = |i: usize, j: usize| doc["matrix"][i][j].as_f64().unwrap();
    let rotation = Matrix3::from_fn(m);
    let translation = Vector3::new(m(0, 3), m(1, 3), m(2, 3));
    assert_same_params(&groundcal_of(&rotation, translation), &params_of(&result));
    for (k, t) in translation.iter().enumerate() {
        assert_eq!(doc["translation_m"][k].as_f64().unwrap(), *t);
    }
    let groundcal: PoseDegMm = serde_json::from_value(doc["groundcal"].clone()).unwrap();
    assert_same_params(&groundcal, &params_of(&result));
}

#[test]
fn a_rejected_calibration_is_refused() {
    let file = TempFile::new("rejected", &table3_result().to_string());
    let (code, stdout, stderr) = groundcal(&["export", file.as_str(), "--format", "urdf"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stdout.is_empty(), "{stdout}");
    assert!(stderr.contains(file.as_str()), "{stderr}");
    assert!(stderr.contains("the calibration was rejected"), "{stderr}");
}

fn assert_refused(name: &str, result: &Value, must_mention: &[&str]) {
    let file = TempFile::new(name, &result.to_string());
    for format in ["urdf", "ros-static", "json"] {
        let (code, stdout, stderr) = groundcal(&["export", file.as_str(), "--format", format]);
        assert_eq!(code, 2, "{name}: {stderr}");
        assert!(stdout.is_empty(), "{name}: {stdout}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(stderr.contains(file.as_str()), "{name}: {stderr}");
        for word in must_mention {
            assert!(stderr.contains(word), "{name}: no {word:?} in {stderr}");
        }
    }
}

#[test]
fn broken_results_are_refused_with_the_key_named() {
    let good = accepted_result();

    let mut doc = good.clone();
    doc.as_object_mut().unwrap().remove("robot_from_sensor");
    assert_refused("no-mount", &doc, &["\"robot_from_sensor\" is missing"]);

    let mut doc = good.clone();
    doc["robot_from_sensor"]["pz_mm"] = Value::Null;
    assert_refused("null", &doc, &["\"robot_from_sensor.pz_mm\" is null"]);

    let mut doc = good.clone();
    doc["robot_from_sensor"]["matrix"][0][3] = 600.0.into();
    assert_refused(
        "inconsistent",
        &doc,
        &["\"robot_from_sensor.matrix[0][3]\"", "disagree"],
    );

    let text = good.to_string();
    let at = text.find("\"alpha_deg\":").unwrap() + "\"alpha_deg\":".len();
    let len = text[at..].find(',').unwrap();
    let broken = format!("{}1e999{}", &text[..at], &text[at + len..]);
    let file = TempFile::new("overflow", &broken);
    let (code, _, stderr) = groundcal(&["export", file.as_str(), "--format", "json"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("\"alpha_deg\""), "{stderr}");
}

#[test]
fn a_missing_file_and_an_unknown_format_are_usage_errors() {
    let (code, stdout, stderr) =
        groundcal(&["export", "/nonexistent/result.json", "--format", "urdf"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stdout.is_empty());
    assert!(stderr.contains("/nonexistent/result.json"), "{stderr}");

    let file = TempFile::new("format", &accepted_result().to_string());
    let (code, stdout, stderr) = groundcal(&["export", file.as_str(), "--format", "yaml"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stdout.is_empty());
    assert!(stderr.contains("--format"), "{stderr}");
}
