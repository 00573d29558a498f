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

/// Writes millimetres as a 16-bit grayscale PNG (big-endian samples).
fn write_png_mm(path: &std::path::Path, width: usize, height: usize, mm: &[u16]) {
    let file = std::fs::File::create(path).unwrap();
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width as u32, height as u32);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().unwrap();
    let bytes: Vec<u8> = mm.iter().flat_map(|v| v.to_be_bytes()).collect();
    writer.write_image_data(&bytes).unwrap();
}

/// PCL's real floor frame made into a corridor: all but three bands of the
/// floor, a tenth of the valid pixels, become walls and people (vertical
/// planes 0.9 and 1.4 m away, with the real frame's own noise moved onto
/// them); the laptop and the box stay.
/// The floor, now a tenth of the view, is still found where the whole frame
/// puts it, with the prior of a rough mount (the floor's up within 20°).
#[test]
fn a_real_floor_that_is_a_tenth_of_the_view_is_found() {
    let file = shared().join("data/real/pcl_floor_tilted_frame_20121214T142255.814212_depth.tiff");
    let (image, _) = groundcal::formats::depth_image::read_depth_image(&file, None).unwrap();
    let (w, h) = (image.width, image.height);
    let f = 525.0;
    // The floor of the whole frame (the first test), optical frame.
    let n: [f64; 3] = [0.074, -0.692, -0.718];
    let norm = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let n = n.map(|x| x / norm);
    let d = 0.715;
    let ray = |u: usize, v: usize| [(u as f64 - 320.0) / f, (v as f64 - 240.0) / f, 1.0];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    // Which pixels are floor, and their real noise along the ray (mm).
    let floor_depth = |u: usize, v: usize| -d / dot(n, ray(u, v));
    let valid = image.pixels.iter().filter(|&&z| z > 0).count();
    // Walls and people stand on the floor: their normal is the horizontal
    // direction towards the camera, `-z` made perpendicular to the floor's
    // up (its normal, which points at the camera).
    let up = n;
    let towards = {
        let back = [0.0, 0.0, -1.0];
        let along = dot(back, up);
        let h = [
            back[0] - along * up[0],
            back[1] - along * up[1],
            back[2] - along * up[2],
        ];
        let l = dot(h, h).sqrt();
        h.map(|x| x / l)
    };
    let mut kept_floor = 0;
    let mut masked = image.pixels.clone();
    // Keep the floor in three bands of columns (between the people), about a
    // tenth of the valid pixels; everything else that is floor becomes a
    // wall or a person.
    for v in 0..h {
        for u in 0..w {
            let i = v * w + u;
            let z = f64::from(image.pixels[i]) / 1000.0;
            if z <= 0.0 {
                continue;
            }
            let floor_z = floor_depth(u, v);
            if (z - floor_z).abs() > 0.03 {
                continue; // the laptop, the box
            }
            if (u / 32) % 7 == 0 {
                kept_floor += 1;
                continue;
            }
            // A person every 80 columns, a wall behind them.
            let distance = if (u / 40) % 2 == 0 { 0.9 } else { 1.4 };
            let surface_z = distance / (-dot(towards, ray(u, v))).max(1e-3);
            let noisy = surface_z + (z - floor_z);
            masked[i] = (noisy * 1000.0).round().clamp(1.0, 65535.0) as u16;
        }
    }
    let in_range = masked
        .iter()
        .filter(|&&z| (500..=5000).contains(&z))
        .count();
    println!(
        "valid {valid}, kept floor {kept_floor}, in range after masking {in_range}, towards {towards:?}"
    );
    let dir = std::env::temp_dir().join(format!("groundcal-masked-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("pcl_floor_a_tenth.png");
    write_png_mm(&png, w, h, &masked);
    let up_arg = format!("{},{},{}", up[0], up[1], up[2]);
    let (code, result) = groundcal_json(&[
        "plane",
        png.to_str().unwrap(),
        "--json",
        "--units",
        "mm",
        "--fx",
        "525",
        "--fy",
        "525",
        "--up",
        &up_arg,
        "--up-tolerance",
        "20",
    ]);
    if code == 0 {
        let _ = std::fs::remove_dir_all(&dir);
    }
    assert_eq!(code, 0, "{result} (the frame is kept in {})", dir.display());
    let share = result["inliers"].as_f64().unwrap() / result["valid_pixels"].as_f64().unwrap();
    println!("the floor holds {:.1} % of the valid pixels", share * 100.0);
    assert!(
        share <= 0.12,
        "the floor is {:.1} % of the view",
        share * 100.0
    );
    let p = &result["plane_optical"];
    let normal = ["a", "b", "c"].map(|k| p[k].as_f64().unwrap());
    let found_d = p["d_m"].as_f64().unwrap();
    assert!((found_d - d).abs() <= 0.01, "floor at {found_d} m");
    let angle = angle_deg(normal, n);
    assert!(angle <= 1.0, "normal {normal:?} is {angle}° off");
}
