//! One calibration for every tilt of the Kinect's motor: the simulated robot
//! calibrated at three tilts gives the simulator's motor axis, and the mount
//! at a fourth tilt that was never calibrated; its recording replays to the
//! same; exports refuse tilts outside the calibrated range.

mod common;

use common::{groundcal, root, temp_dir};
use groundcal::calib::geometry::{rot_z, PoseDegMm, Transform};
use nalgebra::{Rotation3, Translation3, Vector3};
use serde_json::Value;

use common::SIM_MOUNT as TRUTH;

fn true_mount_at(tilt_deg: f64) -> Transform {
    let turn = Transform::from_parts(
        Translation3::identity(),
        Rotation3::from_matrix_unchecked(rot_z((tilt_deg + 20.0).to_radians())),
    );
    PoseDegMm::from_values(TRUTH).to_params().to_transform() * turn
}

fn json(args: &[&str]) -> (i32, Value, String) {
    let (code, out, err) = groundcal(args);
    let value = serde_json::from_str(&out).unwrap_or(Value::Null);
    (code, value, err)
}

fn axis_of(result: &Value) -> Vector3<f64> {
    let a = &result["tilt_model"]["axis"];
    Vector3::new(
        a[0].as_f64().unwrap(),
        a[1].as_f64().unwrap(),
        a[2].as_f64().unwrap(),
    )
}

#[test]
fn three_tilts_give_the_motor_axis_and_a_fourth_tilt() {
    let dir = temp_dir("tilts");
    let config = root().join("config/sim.toml");
    let record = dir.join("rec");
    let (code, result, err) = json(&[
        "calibrate",
        "--config",
        config.to_str().unwrap(),
        "--tilts=-25,-15,-5",
        "--record",
        record.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(code, 0, "{err}\n{result:#}");
    assert_eq!(result["tilts"].as_array().unwrap().len(), 3);
    // The simulator's axis: the sensor's right axis on the body.
    let true_axis = true_mount_at(-20.0).rotation * Vector3::z();
    let angle = axis_of(&result).angle(&true_axis).to_degrees();
    assert!(angle < 0.05, "axis off by {angle}°");
    let rate = result["tilt_model"]["rate"].as_f64().unwrap();
    assert!((rate - 1.0).abs() < 0.005, "{rate}");
    assert!(result["tilt_model"]["axis_sigma_deg"].as_f64().unwrap() < 0.05);

    // A tilt never calibrated: -10°.
    let file = dir.join("result.json");
    std::fs::write(&file, result.to_string()).unwrap();
    let (code, exported, err) = json(&[
        "export",
        file.to_str().unwrap(),
        "--format",
        "json",
        "--tilt=-10",
    ]);
    assert_eq!(code, 0, "{err}");
    let g = &exported["groundcal"];
    let keys = [
        "alpha_deg",
        "beta_deg",
        "gamma_deg",
        "px_mm",
        "py_mm",
        "pz_mm",
    ];
    let values: [f64; 6] = std::array::from_fn(|k| g[keys[k]].as_f64().unwrap());
    let predicted = PoseDegMm::from_values(values).to_params().to_transform();
    let truth = true_mount_at(-10.0);
    let angle = (predicted.rotation * truth.rotation.inverse())
        .angle()
        .to_degrees();
    let distance = (predicted.translation.vector - truth.translation.vector).norm() * 1000.0;
    assert!(angle < 0.05 && distance < 1.0, "{angle}° {distance} mm");

    // Outside the calibrated range, and a calibration of one tilt: refused.
    let (code, _, err) = json(&[
        "export",
        file.to_str().unwrap(),
        "--format",
        "json",
        "--tilt=5",
    ]);
    assert_eq!(code, 2);
    assert!(
        err.contains("outside the calibrated range -25° to -5°"),
        "{err}"
    );

    // The recording at several tilts replays to the same model.
    let (code, replayed, err) = json(&["replay", record.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{err}");
    let angle = axis_of(&replayed).angle(&axis_of(&result)).to_degrees();
    assert!(angle < 0.001, "{angle}°");
    assert!(std::fs::read_to_string(record.join("tilts.json"))
        .unwrap()
        .contains("groundcal-tilts"));
}

#[test]
fn a_single_tilt_is_not_a_model() {
    let config = root().join("config/sim.toml");
    let (code, _, err) = groundcal(&[
        "calibrate",
        "--config",
        config.to_str().unwrap(),
        "--tilts=-20",
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("one tilt is no model"), "{err}");
    let result = root().join("tests/data/paper-table2-printed.json");
    let dir = temp_dir("tilts-one");
    let (_, out, _) = groundcal(&["solve", result.to_str().unwrap(), "--json"]);
    let mut doc: Value = serde_json::from_str(&out).unwrap();
    doc["status"] = "accepted".into();
    doc["reasons"] = serde_json::json!([]);
    let file = dir.join("one.json");
    std::fs::write(&file, doc.to_string()).unwrap();
    let (code, _, err) = groundcal(&[
        "export",
        file.to_str().unwrap(),
        "--format",
        "urdf",
        "--tilt=-10",
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("holds for one tilt"), "{err}");
}
