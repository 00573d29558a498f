//! `groundcal plane` on real depth frames from public datasets
//! (`shared/data/real/`, provenance beside each file).

mod common;

use common::{groundcal_json, shared};

fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    let dot: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
    let na = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    let nb = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    (dot / (na * nb)).clamp(-1.0, 1.0).acos().to_degrees()
}

/// PCL's tilted floor frame: a carpeted floor with a laptop and a box on it.
/// The floor is 0.715 m below the camera with optical normal (0.074, -0.692, -0.718).
#[test]
fn pcl_tilted_floor_is_found_under_the_laptop_and_the_box() {
    let file = shared().join("data/real/pcl_floor_tilted_frame_20121214T142255.814212_depth.tiff");
    let (code, result) = groundcal_json(&[
        "plane",
        file.to_str().unwrap(),
        "--json",
        "--fx",
        "525",
        "--fy",
        "525",
        "--cx",
        "320",
        "--cy",
        "240",
    ]);
    assert_eq!(code, 0);
    let p = &result["plane_optical"];
    let normal = ["a", "b", "c"].map(|k| p[k].as_f64().unwrap());
    let d = p["d_m"].as_f64().unwrap();
    assert!((d - 0.715).abs() <= 0.01, "floor at {d} m");
    let angle = angle_deg(normal, [0.074, -0.692, -0.718]);
    assert!(angle <= 1.0, "normal {normal:?} is {angle}° off");
    // The sensor-frame plane is the same plane with the axes renamed.
    let s = &result["plane_sensor"];
    assert_eq!(s["a"], p["c"]);
    assert_eq!(s["c"], p["a"]);
    assert_eq!(s["b"].as_f64().unwrap(), -p["b"].as_f64().unwrap());
    assert!(result["inliers"].as_u64().unwrap() > 100_000);
    assert!(result["rms_mm"].as_f64().unwrap() < 5.0);
}

/// A sample recording's raw 11-bit fakenect frame, through its inverse-linear
/// model, against the recording's ground truth plane.
#[test]
fn fakenect_frame_of_the_sample_recording_matches_its_truth() {
    let file = shared().join("data/sample-12/kinect/d-1700000000.001000-2001000.pgm");
    let (code, result) = groundcal_json(&[
        "plane",
        file.to_str().unwrap(),
        "--json",
        "--model",
        "inverse-linear:3.3309495161,-0.0030711016",
        "--fx",
        "575.8157389635317",
        "--fy",
        "575.8157389635317",
    ]);
    assert_eq!(code, 0);
    let truth: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(shared().join("data/sample-12.truth.json")).unwrap(),
    )
    .unwrap();
    let t: Vec<f64> = truth["planes"][0]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let p = &result["plane_sensor"];
    let normal = ["a", "b", "c"].map(|k| p[k].as_f64().unwrap());
    assert!(angle_deg(normal, [t[0], t[1], t[2]]) < 0.05);
    assert!((p["d_m"].as_f64().unwrap() - t[3]).abs() < 0.001);
}

/// With the expected up direction along the camera's x axis instead, 70° from
/// the floor's normal, the floor must not be reported: the prior excludes it,
/// no other plane in this frame qualifies, and the command says so (exit 1)
/// in words that name the prior.
#[test]
fn a_prior_that_excludes_the_floor_finds_no_ground() {
    let file = shared().join("data/real/pcl_floor_tilted_frame_20121214T142255.814212_depth.tiff");
    let (code, stdout, stderr) = common::groundcal(&[
        "plane",
        file.to_str().unwrap(),
        "--json",
        "--fx",
        "525",
        "--fy",
        "525",
        "--up",
        "1,0,0",
        "--up-tolerance",
        "20",
    ]);
    assert_eq!(code, 1, "stdout: {stdout}\nstderr: {stderr}");
    assert!(stdout.is_empty(), "no plane is printed: {stdout}");
    assert!(
        stderr.contains("no plane in view matches the expected ground")
            && stderr.contains("within 20°"),
        "{stderr}"
    );
    // The same frame with the floor's side of the prior finds the floor.
    let (code, _, stderr) = common::groundcal(&[
        "plane",
        file.to_str().unwrap(),
        "--fx",
        "525",
        "--fy",
        "525",
        "--up",
        "0,-1,-1",
        "--up-tolerance",
        "20",
    ]);
    assert_eq!(code, 0, "{stderr}");
}
