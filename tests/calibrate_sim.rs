//! Full calibrations on the simulated robot and Kinect, through the real
//! binary: the simulator's true mount must be recovered.

mod common;

use std::path::{Path, PathBuf};

use common::{distance, groundcal, groundcal_json, mount_of};
use groundcal::calib::geometry::PoseDegMm;

fn sim_config() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim.toml")
}

fn true_mount() -> PoseDegMm {
    groundcal::config::Config::load(&sim_config())
        .unwrap()
        .0
        .sim
        .unwrap()
        .mount
}

/// A copy of sim.toml with another world, its schedule path made absolute.
fn config_with_world(world: &str) -> PathBuf {
    let text = std::fs::read_to_string(sim_config()).unwrap();
    let schedule = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/schedules/octopus-52.toml");
    let text = text
        .replace("world = \"flat\"", &format!("world = \"{world}\""))
        .replace(
            "schedule = \"schedules/octopus-52.toml\"",
            &format!("schedule = \"{}\"", schedule.display()),
        );
    let path =
        std::env::temp_dir().join(format!("groundcal-sim-{world}-{}.toml", std::process::id()));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn the_readme_command_calibrates_the_simulated_robot() {
    let (code, result) =
        groundcal_json(&["calibrate", "--robot", "sim", "--sensor", "sim", "--json"]);
    assert_eq!(code, 0, "{result:#}");
    assert_eq!(result["status"], "accepted");
    let (angle, offset) = distance(&mount_of(&result), &true_mount());
    assert!(
        angle <= 0.03 && offset <= 1.0,
        "off by {angle}° and {offset} mm"
    );
    assert_eq!(result["summary"]["poses_used"], 52);
}

#[test]
fn boxes_and_a_wall_in_view_do_not_pull_the_result() {
    let config = config_with_world("boxes-and-wall");
    let (code, result) =
        groundcal_json(&["calibrate", "--config", config.to_str().unwrap(), "--json"]);
    let _ = std::fs::remove_file(&config);
    assert_eq!(code, 0, "{result:#}");
    let (angle, offset) = distance(&mount_of(&result), &true_mount());
    assert!(
        angle <= 0.05 && offset <= 1.5,
        "off by {angle}° and {offset} mm"
    );
}

#[test]
fn a_recorded_session_replays_to_the_same_result() {
    let dir = std::env::temp_dir().join(format!("groundcal-recorded-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (code, live) = groundcal_json(&[
        "calibrate",
        "--robot",
        "sim",
        "--sensor",
        "sim",
        "--json",
        "--record",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0);
    let (code, replayed) = groundcal_json(&["replay", dir.to_str().unwrap(), "--json"]);
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(code, 0);
    // The recording holds the very frames and feet the session used.
    let (angle, offset) = distance(&mount_of(&live), &mount_of(&replayed));
    assert!(
        angle < 1e-9 && offset < 1e-6,
        "live and replay differ by {angle}° and {offset} mm"
    );
}

#[test]
fn an_invalid_schedule_is_refused_before_anything_moves() {
    let config = config_with_world("flat");
    let text = std::fs::read_to_string(&config)
        .unwrap()
        .replace("max_tilt_deg = 25.0", "max_tilt_deg = 15.0");
    std::fs::write(&config, text).unwrap();
    let (code, _, stderr) = groundcal(&["calibrate", "--config", config.to_str().unwrap()]);
    let _ = std::fs::remove_file(&config);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("pose 1") && stderr.contains("tilt limit"),
        "{stderr}"
    );
}

/// The comparison itself: zero for one mount, and the right angle for a
/// small turn (acos of the trace would give NaN or lose the small angle).
#[test]
fn mount_distance_is_exact_near_zero() {
    let mount = true_mount();
    assert_eq!(distance(&mount, &mount), (0.0, 0.0));
    let turned = PoseDegMm {
        beta_deg: mount.beta_deg + 1e-7,
        ..mount
    };
    let (angle, offset) = distance(&mount, &turned);
    assert!((angle - 1e-7).abs() < 1e-12, "{angle}");
    assert_eq!(offset, 0.0);
}
