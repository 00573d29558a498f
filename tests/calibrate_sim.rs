//! Full calibrations on the simulated robot and Kinect, through the real
//! binary: the simulator's true mount must be recovered.

mod common;

use std::path::{Path, PathBuf};

use common::{distance, gate_check, groundcal, groundcal_json, mount_of};
use groundcal::calib::geometry::PoseDegMm;

fn sim_config() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim.toml")
}

fn true_mount() -> PoseDegMm {
    groundcal::setup::config::Config::load(&sim_config())
        .unwrap()
        .0
        .sim
        .unwrap()
        .mount
}

/// A copy of sim.toml with another world, its schedule path made absolute.
fn config_with_world(world: &str) -> PathBuf {
    config_with(
        world,
        &[(r#"world = "flat""#, &format!(r#"world = "{world}""#))],
    )
}

/// A copy of sim.toml (named by `name`) with text replaced, its schedule path
/// made absolute. Every replacement must take.
fn config_with(name: &str, replacements: &[(&str, &str)]) -> PathBuf {
    let mut text = std::fs::read_to_string(sim_config()).unwrap();
    let schedule = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/schedules/octopus-52.toml");
    let absolute = format!("schedule = \"{}\"", schedule.display());
    for (from, to) in [(
        "schedule = \"schedules/octopus-52.toml\"",
        absolute.as_str(),
    )]
    .iter()
    .chain(replacements)
    {
        assert!(text.contains(from), "sim.toml has no {from}");
        text = text.replace(from, to);
    }
    let path =
        std::env::temp_dir().join(format!("groundcal-sim-{name}-{}.toml", std::process::id()));
    std::fs::write(&path, text).unwrap();
    path
}

const INVERSE_LINEAR: &str =
    r#"depth_model = { kind = "inverse-linear", a = 3.3309495161, b = -0.0030711016 }"#;
const ZERO_PLANE: &str = r#"depth_model = { kind = "zero-plane", reference_distance_mm = 120.0, reference_pixel_size_mm = 0.1052, emitter_distance_cm = 7.5, const_shift = 200.0 }"#;
const PAPER_LIKE_MOUNT: &str = "mount = { alpha_deg = 0.8, beta_deg = -33.0, gamma_deg = 1.5, px_mm = 510.0, py_mm = 370.0, pz_mm = 15.0 }";
/// Tilted only 24° down: it sees ground twice as far away.
const FAR_SEEING_MOUNT: &str = "mount = { alpha_deg = 0.8, beta_deg = -24.0, gamma_deg = 1.5, px_mm = 510.0, py_mm = 370.0, pz_mm = 15.0 }";

/// Calibrates with `config` and returns the result and the simulator's mount.
fn calibrate(config: &Path) -> (i32, serde_json::Value, PoseDegMm) {
    let truth = groundcal::setup::config::Config::load(config)
        .unwrap()
        .0
        .sim
        .unwrap()
        .mount;
    let (code, result) =
        groundcal_json(&["calibrate", "--config", config.to_str().unwrap(), "--json"]);
    (code, result, truth)
}

#[test]
fn both_depth_models_and_a_far_seeing_mount_recover_the_mount_to_the_noise_floor() {
    for (model_name, model) in [
        ("inverse-linear", INVERSE_LINEAR),
        ("zero-plane", ZERO_PLANE),
    ] {
        for (mount_name, mount) in [
            ("paper-like", PAPER_LIKE_MOUNT),
            ("24° down", FAR_SEEING_MOUNT),
        ] {
            let config = config_with(
                "models",
                &[(INVERSE_LINEAR, model), (PAPER_LIKE_MOUNT, mount)],
            );
            let (code, result, truth) = calibrate(&config);
            let _ = std::fs::remove_file(&config);
            assert_eq!(code, 0, "{model_name}, {mount_name}: {result:#}");
            let (angle, offset) = distance(&mount_of(&result), &truth);
            println!("{model_name}, {mount_name}: off by {angle:.5}° and {offset:.3} mm");
            assert!(
                angle <= 0.005 && offset <= 0.3,
                "{model_name}, {mount_name}: off by {angle}° and {offset} mm"
            );
        }
    }
}

#[test]
fn a_foot_that_sinks_is_left_out_and_named_and_the_result_holds() {
    let dir = std::env::temp_dir().join(format!("groundcal-sinking-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let config = config_with(
        "sinking",
        &[(
            r#"world = "flat""#,
            "world = \"flat\"\nsinking_foot = { foot = 3, from_pose = 30, depth_mm = 15.0 }",
        )],
    );
    let truth = groundcal::setup::config::Config::load(&config)
        .unwrap()
        .0
        .sim
        .unwrap()
        .mount;
    let (code, live) = groundcal_json(&[
        "calibrate",
        "--config",
        config.to_str().unwrap(),
        "--json",
        "--record",
        dir.to_str().unwrap(),
    ]);
    let _ = std::fs::remove_file(&config);
    assert_eq!(code, 0, "{live:#}");
    assert_eq!(live["summary"]["poses_used"], 52, "{live:#}");
    let (angle, offset) = distance(&mount_of(&live), &truth);
    println!("a foot sunk 15 mm from pose 30: off by {angle:.5}° and {offset:.3} mm");
    assert!(
        angle <= 0.03 && offset <= 1.0,
        "off by {angle}° and {offset} mm"
    );
    // Pose 30 names the foot; from then on the foot counts where it sank.
    let note = |index: usize| live["poses"][index - 1]["note"].as_str().map(str::to_owned);
    assert!(note(29).is_none(), "{:?}", note(29));
    let at_30 = note(30).expect("pose 30 names the foot");
    // It names the foot and how far it sank (15 mm, give or take the feet's
    // noise).
    let miss_mm: f64 = at_30
        .split_once("slipped (")
        .and_then(|(_, rest)| rest.split_once(" mm"))
        .and_then(|(number, _)| number.parse().ok())
        .unwrap_or_else(|| panic!("no distance in {at_30}"));
    assert!(
        at_30.contains("foot 3") && (14.0..16.0).contains(&miss_mm),
        "{at_30}"
    );
    assert!(note(31).is_none(), "{:?}", note(31));

    // The recording replays to the same, and its report names the foot.
    let report = dir.join("report");
    let (code, replayed) = groundcal_json(&[
        "replay",
        dir.to_str().unwrap(),
        "--json",
        "--report",
        report.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{replayed:#}");
    assert_eq!(replayed["poses"][29]["note"], live["poses"][29]["note"]);
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(html.contains("Poses kept with a note") && html.contains("foot 3 slipped"));
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
    // The recording holds the very frames and feet the session used, and
    // the noise its solve assumed: the same mount to within the solve's
    // stopping tolerance (1.3e-9° measured with the simulator's noise).
    let (angle, offset) = distance(&mount_of(&live), &mount_of(&replayed));
    assert!(
        angle < 1e-8 && offset < 1e-6,
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

/// A live calibration judged by stricter gates than the built-in ones: its
/// recording keeps them, so `replay` gives the live verdict; `replay --config`
/// judges by the configuration's gates, which give the same verdict too.
#[test]
fn replay_judges_by_the_gates_of_the_live_run() {
    let strict = config_with(
        "strict-gates",
        &[("theta_max_deg = 1.0", "theta_max_deg = 0.001")],
    );
    let dir = std::env::temp_dir().join(format!("groundcal-gates-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (code, live) = groundcal_json(&[
        "calibrate",
        "--config",
        strict.to_str().unwrap(),
        "--json",
        "--record",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 3, "{live}");
    assert_eq!(live["status"], "rejected");
    let (code, replayed) = groundcal_json(&["replay", dir.to_str().unwrap(), "--json"]);
    assert_eq!(code, 3, "the recording's gates: {replayed}");
    assert_eq!(replayed["reasons"], live["reasons"]);
    let (code, judged) = groundcal_json(&[
        "replay",
        dir.to_str().unwrap(),
        "--config",
        strict.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(code, 3, "--config's gates: {judged}");
    assert_eq!(judged["reasons"], live["reasons"]);
    // The built-in gates accept the same run.
    let lenient = config_with("lenient-gates", &[]);
    let (code, judged) = groundcal_json(&[
        "replay",
        dir.to_str().unwrap(),
        "--config",
        lenient.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(code, 0, "{judged}");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_file(strict);
    let _ = std::fs::remove_file(lenient);
}

/// Under the simulator's own Kinect noise (held through a pose, no noise
/// table), on flat ground with the feet held, designed-52's farthest poses
/// disagree with the result by more than the 5 mm gate (four seeds of
/// eight, docs/method.md): the depth camera's noise, which grows with the
/// ground's distance. The rejection says so in figures, and the result
/// carries it typed for the page, where it used to send the technician to
/// check the flat ground he stood on ("the ground may not be flat, or the
/// body pose is wrong").
#[test]
fn a_disagreement_that_grows_with_distance_is_named_the_sensors_noise() {
    let config = config_with(
        "far-noise",
        &[
            ("octopus-52.toml\"", "designed-52.toml\""),
            ("frames_per_pose = 2", "frames_per_pose = 3"),
            ("seed = 7", "seed = 8"),
            (r#"depth_noise = "white""#, r#"depth_noise = "kinect""#),
            (
                "[calibration.noise]\nnormal_sigma_deg = 0.0043\noffset_sigma_mm = 0.058\n",
                "",
            ),
        ],
    );
    let (code, result) =
        groundcal_json(&["calibrate", "--config", config.to_str().unwrap(), "--json"]);
    let _ = std::fs::remove_file(&config);
    assert_eq!(code, 3, "{result:#}");
    let gate = gate_check(&result, "e_d_max_mm");
    assert_eq!(gate["passed"], false, "{gate:#}");
    let noise = &result["e_d_from_sensor_noise"];
    assert_eq!(
        noise["worst_pose"], gate["place"]["index"],
        "{noise:#} {gate:#}"
    );
    assert!(noise["exponent"].as_f64().unwrap() > 2.0, "{noise:#}");
    let words = result["reasons"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|r| r.as_str())
        .find(|r| r.contains("ground height disagrees"))
        .expect("the reason");
    assert!(
        words.contains("grows with the ground's distance")
            && words.contains("ordinary for its distance")
            && !words.contains("may not be flat"),
        "{words}"
    );
    println!("{words}");
}
