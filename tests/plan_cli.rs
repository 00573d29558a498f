//! `groundcal plan`: a schedule's σ predicted before the robot moves, checked
//! against what simulated calibrations achieve, and a schedule that cannot
//! calibrate refused by `plan` and, before any motion, by `calibrate`.

mod common;

use common::{groundcal, groundcal_json, root, sim_config, temp_dir};
use serde_json::Value;

use common::MOUNT_KEYS as KEYS;

use common::SIM_MOUNT as TRUTH;

/// The paper's schedule, planned with the simulator's noise model: each
/// predicted σ lies within 0.7–1.5× of the RMS error that simulated
/// calibrations (different seeds: noise and the robot's kinematic error)
/// achieve against the truth. 8 runs here; docs/planning.md gives 20.
#[test]
fn the_predicted_sigma_of_the_paper_schedule_match_simulated_calibrations() {
    let config = root().join("config/sim.toml");
    let (code, plan) = groundcal_json(&["plan", "--config", config.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{plan:#}");
    assert_eq!(plan["status"], "observable", "{plan:#}");
    assert_eq!(plan["poses"], 52);
    assert_eq!(plan["reasons"], serde_json::json!([]));
    assert_eq!(plan["correlations"].as_array().unwrap().len(), 6);

    let dir = temp_dir("plan-honest");
    let runs = 8;
    let mut squares = [0.0f64; 6];
    for seed in 1..=runs {
        let config = sim_config(&dir, &[("seed = 7", &format!("seed = {seed}"))]);
        let (code, result) =
            groundcal_json(&["calibrate", "--config", config.to_str().unwrap(), "--json"]);
        assert_eq!(code, 0, "seed {seed}: {result:#}");
        for (k, key) in KEYS.iter().enumerate() {
            let error = result["robot_from_sensor"][key].as_f64().unwrap() - TRUTH[k];
            squares[k] += error * error / f64::from(runs);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    for (k, key) in KEYS.iter().enumerate() {
        let predicted = plan["sigma"][key].as_f64().unwrap();
        let achieved = squares[k].sqrt();
        let ratio = achieved / predicted;
        println!("{key}: predicted σ {predicted:.5}, achieved RMS {achieved:.5} ({ratio:.2}×)");
        assert!(
            (0.7..=1.5).contains(&ratio),
            "{key}: achieved RMS {achieved} against predicted σ {predicted} ({ratio:.2}×)"
        );
    }
}

/// A schedule that only raises and lowers the body, never tilting it.
fn level_schedule(dir: &std::path::Path) -> std::path::PathBuf {
    let mut text = String::from(
        "name = \"level\"\nhome = { alpha_deg = 0, beta_deg = 0, gamma_deg = 0, px_mm = 0, py_mm = 600, pz_mm = 0 }\nposes = [\n",
    );
    for k in 0..12 {
        text.push_str(&format!(
            "  {{ alpha_deg = 0, beta_deg = 0, gamma_deg = 0, px_mm = 0, py_mm = {}, pz_mm = 0 }},\n",
            560 + 10 * k
        ));
    }
    text.push_str("]\n");
    let path = dir.join("level.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// A depth pattern's offset and gradients over the image are pinned only by
/// the spread of the poses' heights and tilts (docs/method.md, "What pins
/// each part"), and `plan` predicts what finding one costs. With the
/// simulator's noise, on the paper's schedule it costs the angles several
/// times their σ; `config/schedules/designed-52.toml`, whose heights and
/// tilts spread wider, halves that in the same robot time. An independent
/// count (`scripts/count-plane-part`, Fisher information in numpy) gives
/// 0.0031/0.0061/0.0072° for the paper's schedule and 0.0017/0.0033/0.0032°
/// for the designed one. `plan` says beforehand that the paper's schedule's
/// calibration of a Kinect with a pattern will be rejected (the gate
/// `pattern_angle_sigma_growth_max`), and not the designed one's.
#[test]
fn plan_predicts_what_a_depth_pattern_costs_and_a_designed_schedule_halves_it() {
    let config = root().join("config/sim.toml");
    let designed = root().join("config/schedules/designed-52.toml");
    let (code, paper) = groundcal_json(&["plan", "--config", config.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{paper:#}");
    let (code, wide) = groundcal_json(&[
        "plan",
        "--config",
        config.to_str().unwrap(),
        designed.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(code, 0, "{wide:#}");
    let worst_angle = |sigma: &Value| {
        ["alpha_deg", "beta_deg", "gamma_deg"]
            .iter()
            .map(|k| sigma[k].as_f64().unwrap())
            .fold(0.0, f64::max)
    };
    for plan in [&paper, &wide] {
        let with = &plan["sigma_with_depth_pattern"];
        for key in KEYS {
            let (without, with) = (
                plan["sigma"][key].as_f64().unwrap(),
                with[key].as_f64().unwrap(),
            );
            assert!(
                with >= without * (1.0 - 1e-9),
                "{key}: {with} with a pattern, {without} without"
            );
        }
    }
    let (paper_without, paper_with) = (
        worst_angle(&paper["sigma"]),
        worst_angle(&paper["sigma_with_depth_pattern"]),
    );
    let wide_with = worst_angle(&wide["sigma_with_depth_pattern"]);
    println!("largest angle σ: paper's {paper_without:.4}° without a pattern, {paper_with:.4}° with; designed {wide_with:.4}° with");
    assert!(
        paper_with > 3.0 * paper_without,
        "{paper_with} against {paper_without}"
    );
    assert!(
        wide_with < 0.6 * paper_with,
        "{wide_with} against {paper_with}"
    );
    let note = paper["depth_pattern_note"].as_str().unwrap_or_default();
    assert!(
        note.contains("gamma") && note.contains("will be rejected on this schedule"),
        "{paper:#}"
    );
    assert!(wide.get("depth_pattern_note").is_none(), "{wide:#}");
    // Within a quarter of the independent count, angle by angle.
    for (sigma, count) in [
        (&paper["sigma_with_depth_pattern"], [0.0031, 0.0061, 0.0072]),
        (&wide["sigma_with_depth_pattern"], [0.0017, 0.0033, 0.0032]),
    ] {
        for (k, key) in ["alpha_deg", "beta_deg", "gamma_deg"].iter().enumerate() {
            let ratio = sigma[key].as_f64().unwrap() / count[k];
            assert!(
                (0.75..=1.45).contains(&ratio),
                "{key}: {ratio:.2}× the count: {sigma}"
            );
        }
    }
}

#[test]
fn a_schedule_that_never_tilts_is_refused_before_the_robot_moves() {
    let dir = temp_dir("plan-level");
    let level = level_schedule(&dir);
    let config = root().join("config/sim.toml");
    let (code, stdout, stderr) = groundcal(&[
        "plan",
        "--config",
        config.to_str().unwrap(),
        level.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(code, 3, "{stdout}{stderr}");
    let plan: Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(plan["status"], "not_observable", "{plan:#}");
    let reasons = plan["reasons"].to_string();
    assert!(reasons.contains("α"), "{reasons}");

    // `calibrate` with that schedule against a lower computer in its own
    // process: refused (exit 2) before a single SET_POSE is sent.
    let receipts = dir.join("receipts.jsonl");
    let (robot, address) = common::spawn_sim_robot(
        &["--time-scale", "50"],
        &[("GROUNDCAL_SIM_RECEIPTS", receipts.as_os_str())],
    );
    let config = common::config_towards(&address, &dir, "");
    let text = std::fs::read_to_string(&config).unwrap();
    let text = text.replace(
        &format!(
            "schedule = \"{}\"",
            root().join("config/schedules/octopus-52.toml").display()
        ),
        &format!("schedule = \"{}\"", level.display()),
    );
    std::fs::write(&config, text).unwrap();
    let (code, _, said) = groundcal(&[
        "calibrate",
        "--config",
        config.to_str().unwrap(),
        "--sensor",
        "sim",
        "--json",
    ]);
    common::stop_sim_robot(robot);
    assert_eq!(code, 2, "{said}");
    assert!(
        said.contains("cannot calibrate") && said.contains("α"),
        "{said}"
    );
    let received = std::fs::read_to_string(&receipts).unwrap_or_default();
    assert!(
        !received.contains("\"SET_POSE\""),
        "the robot was asked to move: {received}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A pose beyond the robot's limits is bad input (exit 2), named.
#[test]
fn a_pose_beyond_the_limits_is_named() {
    let dir = temp_dir("plan-limits");
    let text = std::fs::read_to_string(root().join("config/schedules/octopus-52.toml"))
        .unwrap()
        .replacen("gamma_deg =  20", "gamma_deg =  40", 1);
    let schedule = dir.join("steep.toml");
    std::fs::write(&schedule, text).unwrap();
    let (code, _, said) = groundcal(&[
        "plan",
        "--config",
        root().join("config/sim.toml").to_str().unwrap(),
        schedule.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{said}");
    assert!(said.contains("pose 1"), "{said}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The shipped designed schedule is what `plan --design 16` makes of the
/// robot's configuration on the paper's schedule, every time; it passes `check-config` and
/// calibrates the simulated robot, accepted.
#[test]
fn the_designed_schedule_is_reproducible_valid_and_calibrates() {
    let dir = temp_dir("plan-design");
    let config = common::robot_config_on_the_papers_schedule(&dir);
    let mut made = Vec::new();
    for run in 0..2 {
        let out = dir.join(format!("designed-{run}.toml"));
        let (code, stdout, said) = groundcal(&[
            "plan",
            "--design",
            "16",
            "--config",
            config.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--json",
        ]);
        assert_eq!(code, 0, "{stdout}{said}");
        let report: Value = serde_json::from_str(&stdout).unwrap();
        assert_eq!(report["designed"]["poses"], 16);
        // A third of the paper's robot time.
        let designed = report["designed"]["wall_time_s"].as_f64().unwrap();
        let configured = report["configured"]["wall_time_s"].as_f64().unwrap();
        assert!(designed * 3.0 <= configured + 1e-9, "{report:#}");
        made.push(std::fs::read_to_string(&out).unwrap());
    }
    assert_eq!(made[0], made[1], "the same input designed two schedules");
    let without_comments = |text: &str| -> String {
        text.lines()
            .filter(|l| !l.starts_with('#'))
            .collect::<Vec<_>>()
            .join("\n")
    };
    let shipped =
        std::fs::read_to_string(root().join("config/schedules/designed-16.toml")).unwrap();
    assert_eq!(
        without_comments(&made[0]),
        without_comments(&shipped),
        "config/schedules/designed-16.toml is not what plan --design 16 makes of config/groundcal.toml on octopus-52"
    );

    let designed = root().join("config/schedules/designed-16.toml");
    let config = sim_config(
        &dir,
        &[(
            &format!(
                "schedule = \"{}\"",
                root().join("config/schedules/octopus-52.toml").display()
            ),
            &format!("schedule = \"{}\"", designed.display()),
        )],
    );
    std::fs::write(dir.join("token.sim"), "a-token\n").unwrap();
    let (code, stdout, said) = groundcal(&["check-config", config.to_str().unwrap()]);
    assert_eq!(code, 0, "{stdout}{said}");
    let (code, result) =
        groundcal_json(&["calibrate", "--config", config.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{result:#}");
    assert_eq!(result["summary"]["poses_used"], 16, "{result:#}");
    let (code, plan) = groundcal_json(&["plan", "--config", config.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{plan:#}");
    // Achieved within four predicted σ of the truth, parameter by parameter.
    for (k, key) in KEYS.iter().enumerate() {
        let error = (result["robot_from_sensor"][key].as_f64().unwrap() - TRUTH[k]).abs();
        let sigma = plan["sigma"][key].as_f64().unwrap();
        assert!(
            error <= 4.0 * sigma,
            "{key}: off by {error}, predicted σ {sigma}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
