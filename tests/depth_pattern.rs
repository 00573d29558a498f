//! The Kinect's fixed depth pattern (issue 23): simulated Kinects whose raw
//! depth carries a pattern of ±0.5 raw units are calibrated live with a
//! recording, as a real robot's configuration (no noise table), and the
//! recording is replayed with no configuration at all. A fixed pattern is
//! found within 0.1 raw units RMS and corrected (before: 5.3 mm off for the
//! radial bowl, accepted). On the robot's designed schedule the calibration
//! is accepted; on the paper's, whose heights cannot tell the pattern's
//! slope from a tilt of the sensor (its angles' σ grow 13–17 times), it is
//! rejected in words. No pattern changes nothing; a pattern that weakens
//! with depth, which the model cannot separate, is rejected in words
//! (before: 1.9 mm off, accepted).

mod common;

use std::path::Path;

use common::{gate_check, groundcal, sim_config_with_pattern, temp_dir};
use groundcal::calib::sensor::Intrinsics;
use groundcal_hal::sim::kinect::{DepthDistortion, DistortionShape};
use serde_json::Value;

use common::MOUNT_KEYS as KEYS;
use common::SIM_MOUNT as TRUTH;

/// `calibrate` recording into `dir/rec`, then `replay` of it: both results.
fn calibrate_and_replay(config: &Path, dir: &Path) -> [(i32, Value); 2] {
    let record = dir.join("rec");
    let run = |args: &[&str]| {
        let (code, out, err) = groundcal(args);
        let json = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}\n{err}"));
        (code, json)
    };
    let live = run(&[
        "calibrate",
        "--config",
        config.to_str().unwrap(),
        "--record",
        record.to_str().unwrap(),
        "--json",
    ]);
    let replayed = run(&["replay", record.to_str().unwrap(), "--json"]);
    [live, replayed]
}

/// The outside check's noise: white 0.38 raw units and a field smoothed
/// over about 8 px of 0.25, drawn every frame.
const OUTSIDE_CHECK_NOISE: (&str, &str) = (
    "depth_noise = \"white\"",
    "depth_noise = { white_raw = 0.38, short_raw = 0, medium_raw = 0.25, long_raw = 0, gain_per_m = 0, held = \"frame\" }",
);

/// config/sim.toml, unmeasured, with a real unit's pattern (0.8 raw units
/// RMS) under the outside check's noise, on the robot's schedule, with
/// `frames_per_pose` frames a pose.
fn measured_on_designed_52(dir: &Path, frames_per_pose: u32) -> std::path::PathBuf {
    measured_on_designed_52_under(dir, frames_per_pose, OUTSIDE_CHECK_NOISE)
}

/// [`measured_on_designed_52`] under another `noise` (config/sim.toml's
/// line and its replacement).
fn measured_on_designed_52_under(
    dir: &Path,
    frames_per_pose: u32,
    noise: (&str, &str),
) -> std::path::PathBuf {
    let frames = format!("frames_per_pose = {frames_per_pose}");
    let config = common::sim_config_unmeasured(
        dir,
        &[
            (
                common::SIM_NO_PATTERN_LINE,
                "depth_distortion = { shape = \"measured\" }",
            ),
            noise,
            ("frames_per_pose = 2", &frames),
        ],
    );
    common::on_schedule(&config, "designed-52");
    config
}

/// groundcal with `args`, logging at INFO: exit status, stdout and the log.
fn logged(args: &[&str]) -> (Option<i32>, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_groundcal"))
        .args(args)
        .env("GROUNDCAL_LOG", "info")
        .output()
        .expect("groundcal runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The largest angle (°) and position (mm) errors, and each in σ.
fn errors(result: &Value) -> ((f64, f64), (f64, f64)) {
    let mount = &result["robot_from_sensor"];
    let sigma = &result["sigma"];
    let error = |k: usize| (mount[KEYS[k]].as_f64().unwrap() - TRUTH[k]).abs();
    let in_sigma = |k: usize| error(k) / sigma[KEYS[k]].as_f64().unwrap();
    let worst =
        |range: std::ops::Range<usize>, f: &dyn Fn(usize) -> f64| range.map(f).fold(0.0, f64::max);
    (
        (worst(0..3, &error), worst(0..3, &in_sigma)),
        (worst(3..6, &error), worst(3..6, &in_sigma)),
    )
}

/// RMS of a found pattern's cells (a result's `depth_pattern`, or an
/// exported correction) against the simulator's, raw units.
fn pattern_error(pattern: &Value, truth: &DepthDistortion) -> f64 {
    let intrinsics = Intrinsics::default();
    let columns = pattern["columns"].as_u64().unwrap() as usize;
    let cell = pattern["cell_px"].as_u64().unwrap() as usize;
    let (mut sum, mut count) = (0.0, 0.0);
    for (k, value) in pattern["raw"].as_array().unwrap().iter().enumerate() {
        let Some(found) = value.as_f64() else {
            continue;
        };
        let (u0, v0) = ((k % columns) * cell, (k / columns) * cell);
        let mut expected = 0.0;
        for dv in 0..cell {
            for du in 0..cell {
                expected += truth.raw_at((u0 + du) as f64, (v0 + dv) as f64, &intrinsics);
            }
        }
        expected /= (cell * cell) as f64;
        sum += (found - expected).powi(2);
        count += 1.0;
    }
    assert!(count > 1000.0, "{count} cells seen");
    (sum / count).sqrt()
}

/// On the paper's schedule each pattern is found and corrected, the mount
/// within 0.3 mm and 3σ of its angles, and the calibration rejected for the
/// pattern's cost alone: the gate `pattern_angle_sigma_growth_max`
/// (before it: accepted, the angles 0.009–0.012° off against issue 23's
/// 0.005°).
#[test]
fn a_fixed_pattern_is_found_and_corrected() {
    let dir = temp_dir("depth-pattern");
    // libfreenect's zero-plane model for two of them (true).
    let cases = [
        ("radial", DistortionShape::Radial, false),
        ("bands", DistortionShape::Bands { period_px: 64.0 }, true),
        ("saddle", DistortionShape::Saddle, true),
    ];
    for (name, shape, zero_plane) in cases {
        let truth = DepthDistortion {
            shape,
            amplitude_raw: 0.5,
            decay_per_m: 0.0,
        };
        let line = format!("depth_distortion = {{ shape = \"{name}\", amplitude_raw = 0.5 }}");
        let case = dir.join(name);
        let runs = calibrate_and_replay(&sim_config_with_pattern(&case, &line, zero_plane), &case);
        for (how, (code, result)) in ["live", "replay"].iter().zip(&runs) {
            assert_eq!(*code, 3, "{name} {how}: {result:#}");
            assert_eq!(result["depth_pattern"]["corrected"], true, "{name} {how}");
            let reasons = result["reasons"].as_array().unwrap();
            assert_eq!(reasons.len(), 1, "{name} {how}: {reasons:#?}");
            assert!(
                reasons[0].as_str().unwrap().contains(
                    "this schedule cannot tell the pattern's slope across the image from a tilt of the sensor"
                ),
                "{name} {how}: {reasons:#?}"
            );
            let growth = gate_check(result, "pattern_angle_sigma_growth_max");
            assert_eq!(growth["passed"], false, "{name} {how}: {growth}");
            assert!(growth["measured"].as_f64().unwrap() > 10.0, "{growth}");
            let ((angle, angle_sigmas), (position, position_sigmas)) = errors(result);
            // The plane part costs the angles σ (docs/method.md): within
            // 3σ of their own, and 0.3 mm.
            assert!(
                position < 0.3 && angle_sigmas < 3.0,
                "{name} {how}: {angle}° ({angle_sigmas}σ), {position} mm ({position_sigmas}σ)"
            );
            let rms = pattern_error(&result["depth_pattern"], &truth);
            assert!(
                rms < 0.1,
                "{name} {how}: pattern off by {rms} raw units RMS"
            );
        }
    }
}

/// The schedule pins the pattern's plane part (docs/method.md, "What pins
/// each part"): `config/schedules/designed-52.toml`, the robot's schedule,
/// what `plan --design 52` makes of config/groundcal.toml on the paper's 52,
/// spreads its heights (530–770 mm) and tilts wider than the paper's 52
/// (615–753 mm) in the same robot time. With a radial bowl of ±0.5 raw units
/// (seed 7), live, the paper's schedule puts the mount 0.24 mm and 0.009°
/// off and is rejected for the pattern's cost; the designed one is accepted,
/// within 0.15 mm, its angles within 0.012° and 4σ, their σ grown by
/// correcting the pattern within the gate (5.5 times), and the pattern
/// within 0.1 raw units RMS.
#[test]
fn a_designed_schedule_pins_the_patterns_plane_part() {
    let dir = temp_dir("depth-pattern-designed");
    let made = dir.join("designed-52.toml");
    let (code, stdout, said) = groundcal(&[
        "plan",
        "--design",
        "52",
        "--config",
        common::robot_config_on_the_papers_schedule(&dir)
            .to_str()
            .unwrap(),
        "--out",
        made.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stdout}{said}");
    // It says which of the two would be rejected with a pattern.
    assert!(
        stdout.contains("note on octopus-52: a Kinect's depth pattern")
            && !stdout.contains("note on designed-52"),
        "{stdout}"
    );
    let shipped = common::root().join("config/schedules/designed-52.toml");
    let poses = |path: &Path| -> String {
        let text = std::fs::read_to_string(path).expect("a schedule");
        text.lines()
            .filter(|l| !l.starts_with('#'))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(
        poses(&made),
        poses(&shipped),
        "config/schedules/designed-52.toml is not what plan --design 52 makes of config/groundcal.toml on octopus-52"
    );

    let line = "depth_distortion = { shape = \"radial\", amplitude_raw = 0.5 }";
    let config = sim_config_with_pattern(&dir, line, false);
    common::on_schedule(&config, "designed-52");
    let (code, out, err) =
        groundcal(&["calibrate", "--config", config.to_str().unwrap(), "--json"]);
    let result: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}\n{err}"));
    assert_eq!(code, 0, "{result:#}");
    assert_eq!(result["summary"]["poses_used"], 52, "{result:#}");
    assert_eq!(result["depth_pattern"]["corrected"], true, "{result:#}");
    let growth = gate_check(&result, "pattern_angle_sigma_growth_max");
    assert_eq!(growth["passed"], true, "{growth}");
    let ((angle, angle_sigmas), (position, position_sigmas)) = errors(&result);
    eprintln!("designed-52, radial ±0.5: {angle:.4}° ({angle_sigmas:.1}σ), {position:.3} mm ({position_sigmas:.1}σ)");
    assert!(
        position < 0.15 && angle < 0.012 && angle_sigmas < 4.0,
        "{angle}° ({angle_sigmas}σ), {position} mm ({position_sigmas}σ)"
    );
    let truth = DepthDistortion {
        shape: DistortionShape::Radial,
        amplitude_raw: 0.5,
        decay_per_m: 0.0,
    };
    let rms = pattern_error(&result["depth_pattern"], &truth);
    eprintln!("designed-52, radial ±0.5: pattern off by {rms:.3} raw units RMS");
    assert!(rms < 0.1, "pattern off by {rms} raw units RMS");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every kind of pattern the simulator makes, on both depth models, at the
/// amplitudes of a real unit (issue 23: 0.25–1.5 raw units), live on the
/// robot's schedule (designed-52; on the paper's every corrected pattern is
/// rejected for its cost, `a_fixed_pattern_is_found_and_corrected`): each is
/// either corrected (the mount within 0.5 mm and 3σ of its angles; at ±0.5
/// raw units or less the pattern within 0.1 raw units RMS) or rejected with
/// a reason, never accepted further off. The cases `a_fixed_pattern_is_found_and_corrected` and
/// `a_pattern_that_changes_with_depth_is_rejected_in_words` already take
/// (with their replays) are not repeated. Waves of 1.5 raw units were
/// accepted 1.0 mm off before the gate `pattern_max_mm` (docs/method.md,
/// "Larger patterns"), which then refused every pattern past ±1 raw unit;
/// since the ground is fitted again about a pattern whose peaks its band
/// cut, they are corrected within the same 0.5 mm, and the gate stands at
/// 45 mm at 2 m (issue 41).
#[test]
fn every_kind_on_both_depth_models_is_corrected_or_rejected_never_accepted_off() {
    let dir = temp_dir("depth-pattern-kinds");
    // (name, shape, amplitude, decay per metre, zero-plane model).
    let cases = [
        ("radial", DistortionShape::Radial, 0.5, 0.0, true),
        ("tilted", DistortionShape::Tilted, 0.5, 0.0, false),
        ("tilted", DistortionShape::Tilted, 0.5, 0.0, true),
        ("saddle", DistortionShape::Saddle, 0.5, 0.0, false),
        (
            "bands",
            DistortionShape::Bands { period_px: 64.0 },
            0.5,
            0.0,
            false,
        ),
        ("waves", DistortionShape::Waves, 0.5, 0.0, false),
        ("waves", DistortionShape::Waves, 0.5, 0.0, true),
        ("radial", DistortionShape::Radial, 0.5, 0.5, true),
        ("radial", DistortionShape::Radial, 0.25, 0.0, false),
        ("radial", DistortionShape::Radial, 1.5, 0.0, true),
        (
            "bands",
            DistortionShape::Bands { period_px: 64.0 },
            1.5,
            0.0,
            true,
        ),
        ("waves", DistortionShape::Waves, 1.5, 0.0, false),
    ];
    // Each case is a calibration in its own process, half of it waiting for
    // the simulated robot to move: two at a time.
    let run = |&(name, shape, amplitude_raw, decay_per_m, zero_plane): &(
        &str,
        DistortionShape,
        f64,
        f64,
        bool,
    )| {
        let bands = match shape {
            DistortionShape::Bands { period_px } => format!(", band_period_px = {period_px:.1}"),
            _ => String::new(),
        };
        let line = format!(
            "depth_distortion = {{ shape = \"{name}\", amplitude_raw = {amplitude_raw}, decay_per_m = {decay_per_m}{bands} }}"
        );
        let model = if zero_plane {
            "zero-plane"
        } else {
            "inverse-linear"
        };
        let case = format!("{name} {amplitude_raw} raw, decay {decay_per_m}/m, {model}");
        let config = sim_config_with_pattern(
            &dir.join(case.replace([' ', ',', '/'], "_")),
            &line,
            zero_plane,
        );
        common::on_schedule(&config, "designed-52");
        let (code, out, err) =
            groundcal(&["calibrate", "--config", config.to_str().unwrap(), "--json"]);
        let result: Value =
            serde_json::from_str(&out).unwrap_or_else(|e| panic!("{case}: {e}: {err}"));
        (case, code, result)
    };
    let outcomes: Vec<(String, i32, Value)> = cases
        .chunks(2)
        .flat_map(|pair| {
            std::thread::scope(|scope| {
                let running: Vec<_> = pair.iter().map(|c| scope.spawn(|| run(c))).collect();
                running
                    .into_iter()
                    .map(|r| r.join().expect("a case's calibration"))
                    .collect::<Vec<_>>()
            })
        })
        .collect();
    for ((case, code, result), (_, shape, amplitude_raw, decay_per_m, _)) in
        outcomes.into_iter().zip(cases)
    {
        let truth = DepthDistortion {
            shape,
            amplitude_raw,
            decay_per_m,
        };
        let ((angle, angle_sigmas), (position, _)) = errors(&result);
        if code == 3 {
            let reasons = result["reasons"].to_string();
            assert!(
                reasons.contains("the depth image is warped"),
                "{case}: {reasons}"
            );
            continue;
        }
        assert_eq!(code, 0, "{case}: {result:#}");
        assert_eq!(result["depth_pattern"]["corrected"], true, "{case}");
        assert!(
            position < 0.5 && angle_sigmas < 3.0,
            "{case}: accepted {angle}° ({angle_sigmas}σ) and {position} mm off"
        );
        // The pattern's own accuracy is asked of the amplitude of issue 23's
        // recordings; at three times it the offset found is off by 0.1–0.2
        // raw units (docs/method.md, "Larger patterns").
        if amplitude_raw <= 0.5 {
            let rms = pattern_error(&result["depth_pattern"], &truth);
            assert!(rms < 0.1, "{case}: pattern off by {rms} raw units RMS");
        }
    }
}

#[test]
fn without_a_pattern_nothing_is_corrected() {
    let dir = temp_dir("depth-pattern-none");
    let runs = calibrate_and_replay(&sim_config_with_pattern(&dir, "", false), &dir);
    for (how, (code, result)) in ["live", "replay"].iter().zip(&runs) {
        assert_eq!(*code, 0, "{how}: {result:#}");
        let pattern = &result["depth_pattern"];
        assert_eq!(pattern["corrected"], false, "{how}: {pattern:#}");
        assert!(
            pattern["note"].as_str().unwrap().starts_with("none found"),
            "{how}: {}",
            pattern["note"]
        );
        let ((angle, _), (position, _)) = errors(result);
        assert!(
            angle < 0.005 && position < 0.3,
            "{how}: {angle}° {position} mm"
        );
    }
}

#[test]
fn a_pattern_that_changes_with_depth_is_rejected_in_words() {
    let dir = temp_dir("depth-pattern-decay");
    let line = "depth_distortion = { shape = \"radial\", amplitude_raw = 0.5, decay_per_m = 0.5 }";
    let runs = calibrate_and_replay(&sim_config_with_pattern(&dir, line, false), &dir);
    for (how, (code, result)) in ["live", "replay"].iter().zip(&runs) {
        assert_eq!(*code, 3, "{how}: {result:#}");
        let reasons = result["reasons"].to_string();
        assert!(
            reasons.contains("the depth image is warped")
                && reasons.contains("it changes with the distance (weaker by")
                && reasons.contains("the ground you calibrated on is not the cause"),
            "{how}: {reasons}"
        );
        assert_eq!(
            result["depth_pattern"]["uncorrected_because"], "changes_with_depth",
            "{how}"
        );
        let check = gate_check(result, "warp_max_mm");
        assert_eq!(check["passed"], false, "{how}: {check}");
    }
}

/// A pattern beyond the fit's band (issue 41): a real Kinect's, 0.8 raw
/// units RMS, reaching 2.5-3.1 raw units from the ground's plane against a
/// fit's band of about 2, under the outside check's correlated noise, on the
/// robot's schedule. The band cut its peaks, so the first estimate is
/// biased and what the cut left looks like uneven ground; the frames are
/// fitted again with that estimate taken out (kept in memory live, read
/// again from the recording in replay), and what is left is a pattern fixed
/// in the image: corrected and accepted, live and in replay alike. Before:
/// rejected as a pattern beyond the fit, 0.027° and 1.23 mm off (seed 1).
/// And a pattern on ground that is not flat stays refused as such: waves of
/// ±1 raw unit on the uneven world (bumps all over the ground, seed 3) were
/// corrected beside the ground's relief and accepted 0.77° and 8 mm off.
#[test]
fn a_pattern_beyond_the_fits_band_is_fitted_about_and_corrected() {
    let dir = temp_dir("depth-pattern-beyond-the-fit");
    let noise = OUTSIDE_CHECK_NOISE;
    for place in ["real", "uneven"] {
        std::fs::create_dir_all(dir.join(place)).expect("a directory for each run");
    }
    let real = measured_on_designed_52(&dir.join("real"), 2);
    let uneven = common::sim_config_unmeasured(
        &dir.join("uneven"),
        &[
            (
                common::SIM_NO_PATTERN_LINE,
                "depth_distortion = { shape = \"waves\", amplitude_raw = 1.0 }",
            ),
            ("world = \"flat\"", "world = \"uneven\""),
            ("seed = 7", "seed = 3"),
            noise,
        ],
    );
    common::on_schedule(&uneven, "designed-52");
    let (runs, (code, out, err)) = std::thread::scope(|scope| {
        let on_uneven = scope
            .spawn(|| groundcal(&["calibrate", "--config", uneven.to_str().unwrap(), "--json"]));
        let runs = calibrate_and_replay(&real, &dir.join("real"));
        (
            runs,
            on_uneven.join().expect("the uneven world's calibration"),
        )
    });
    for (how, (code, result)) in ["live", "replay"].iter().zip(&runs) {
        let pattern = &result["depth_pattern"];
        let note = pattern["note"].as_str().unwrap_or_default();
        assert!(
            pattern["corrected"] == true && note.contains("fitted again"),
            "{how}: {note}: {}",
            result["reasons"]
        );
        assert_eq!(*code, 0, "{how}: {}", result["reasons"]);
        let ((angle, angle_sigmas), (position, _)) = errors(result);
        eprintln!(
            "{how}: the measured pattern, {:.0} mm at 2 m: {angle:.4}° ({angle_sigmas:.1}σ), {position:.3} mm",
            pattern["largest_mm_at_2m"].as_f64().unwrap()
        );
        assert!(
            angle < 0.02 && position < 0.3 && angle_sigmas < 3.0,
            "{how}: {angle}° ({angle_sigmas}σ), {position} mm"
        );
    }
    for key in KEYS {
        let (live, replayed) = (
            &runs[0].1["robot_from_sensor"],
            &runs[1].1["robot_from_sensor"],
        );
        let apart = (live[key].as_f64().unwrap() - replayed[key].as_f64().unwrap()).abs();
        assert!(apart < 1e-6, "{key}: live and replay {apart} apart");
    }
    // The paper's fit (kept to compare with) corrects no pattern, so it
    // never fits the frames again about one: its result says the warp is
    // there and leaves it.
    let recording = dir.join("real").join("rec");
    let (_, paper, stderr) = groundcal(&[
        "replay",
        recording.to_str().unwrap(),
        "--ground-fit",
        "paper",
        "--json",
    ]);
    let paper: Value = serde_json::from_str(&paper).unwrap_or_else(|e| panic!("{e}: {stderr}"));
    let pattern = &paper["depth_pattern"];
    assert_eq!(pattern["corrected"], false, "{pattern}");
    assert!(
        !pattern["note"]
            .as_str()
            .unwrap_or_default()
            .contains("fitted again"),
        "{pattern}"
    );
    let result: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}\n{err}"));
    assert_eq!(code, 3, "uneven ground accepted: {result:#}");
    assert_eq!(
        result["depth_pattern"]["corrected"], false,
        "{}",
        result["depth_pattern"]["note"]
    );
    let reasons = result["reasons"].to_string();
    assert!(reasons.contains("not flat"), "{reasons}");
}

/// A live session keeps its frames for a second fit of the ground only up to
/// 600 (about 130 MB compressed): past that, a pattern beyond the fit's band
/// is not fitted about live, the result says so and points to `replay` of
/// its recording, which reads the frames again and fits about it. The
/// measured pattern under the outside check's noise, 52 poses of 12 frames
/// (624). (Measured: the replay's second fit is then refused, residuals
/// staying with the ground at 14σ: with more frames a pose the fit about the
/// pattern leaves what its own test finds; docs/method.md.)
#[test]
fn a_session_past_the_frames_it_keeps_says_so_and_its_replay_fits_about_the_pattern() {
    let dir = temp_dir("depth-pattern-past-the-kept-frames");
    let config = measured_on_designed_52(&dir, 12);
    let record = dir.join("rec");
    let (_, live, stderr) = groundcal(&[
        "calibrate",
        "--config",
        config.to_str().unwrap(),
        "--record",
        record.to_str().unwrap(),
        "--json",
    ]);
    let live: Value = serde_json::from_str(&live).unwrap_or_else(|e| panic!("{e}: {stderr}"));
    let notes = live["notes"].to_string();
    assert!(
        notes.contains("this session kept no frames to fit again about it (more than 600 frames)"),
        "{notes}"
    );
    assert_ne!(
        live["depth_pattern"]["corrected"], true,
        "{}",
        live["depth_pattern"]["note"]
    );
    let (_, _, log) = logged(&["replay", record.to_str().unwrap(), "--json"]);
    // A log written to a pipe (or the journal) carries no colour codes.
    assert!(!log.contains('\x1b'), "{log}");
    assert!(
        log.contains("the ground fitted again about the depth pattern") && log.contains("fit=2"),
        "{log}"
    );
}

/// With more frames a pose the noise of a cell's mean falls, and the fit
/// about a pattern beyond the fit's band must hold there too. At 4 frames
/// it did not: the second fit's residuals were refused as not fixed in the
/// image, and the first, uncorrected result stood (rejected, 0.238° and
/// 6.66 mm off); then a third fit, adding what the first estimate left,
/// was accepted 0.0123° (3.1σ of β) and 0.134 mm off. Since each pose's
/// plane is fitted to the cells the estimate holds, and the ground is
/// read only where the range leaves the pattern's reach, the second fit is
/// a pattern fixed in the image: measured 0.0065° and 0.223 mm. The
/// measured pattern under the outside check's noise, designed-52.
#[test]
fn with_four_frames_a_pose_the_fit_about_the_pattern_holds() {
    let dir = temp_dir("depth-pattern-four-frames");
    let config = measured_on_designed_52(&dir, 4);
    accepted_within_the_issues_bounds(&config, "fit=2");
}

/// A live calibration on `config` whose log says `fitted`, accepted with
/// the pattern corrected, within issue 41's 0.012° and 0.3 mm.
fn accepted_within_the_issues_bounds(config: &Path, fitted: &str) {
    let (code, out, log) = logged(&["calibrate", "--config", config.to_str().unwrap(), "--json"]);
    let result: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {log}"));
    assert!(log.contains(fitted), "{fitted}: {log}");
    assert_eq!(code, Some(0), "{}", result["reasons"]);
    assert_eq!(result["depth_pattern"]["corrected"], true);
    let ((angle, _), (position, _)) = errors(&result);
    assert!(
        angle < 0.012 && position < 0.3,
        "{angle}° and {position} mm off"
    );
}

/// With many frames a pose, a cell's mean is precise, and the fit about a
/// pattern beyond the band must leave nothing behind that the test of the
/// ground would take for uneven ground. It left two things: each pose's
/// plane was fitted to the readings of cells the estimate did not hold
/// (their pattern unsubtracted), and the fit about the pattern read the
/// ground as near the range's far end as without a correction, where the
/// range cut the readings the pattern pushed out. Both stayed with the
/// ground at 12–17σ; the first fit's uncorrected result stood, rejected
/// 0.239° and 6.67 mm off. Now accepted, measured 0.0047° and 0.148 mm.
/// White noise alone (0.45 raw units), the measured pattern, 8 frames a pose.
#[test]
fn many_frames_a_pose_leave_nothing_with_the_ground_after_the_fit_about_the_pattern() {
    let dir = temp_dir("depth-pattern-eight-frames-white");
    let config = measured_on_designed_52_under(
        &dir,
        8,
        (
            "depth_noise = \"white\"",
            "depth_noise = { white_raw = 0.45, short_raw = 0, medium_raw = 0, long_raw = 0, gain_per_m = 0, held = \"frame\" }",
        ),
    );
    accepted_within_the_issues_bounds(&config, "fitted again about the depth pattern");
}

/// A pattern among obstacles is the sensor's, not uneven ground. Around
/// boxes on the floor, residuals stay with the ground (the obstacles' feet,
/// 9–15 of noise's σ in the simulator's clutter); that alone refused every
/// pattern there as ground that is not flat. The shape is now estimated
/// beside a relief of the ground as well, and stands beside it: waves of
/// ±1 raw unit among the clutter, on the robot's schedule, are corrected
/// and accepted (before, rejected as ground that is not flat). Measured:
/// seeds 1–3 within 0.0116° and 0.20 mm (±0.5 on seeds 1–2 within 0.0031°
/// and 0.06 mm), this test's seed 7 0.0124° (3.2σ) and 0.17 mm; on seed 4
/// the fit's band was 1.4 raw units and the waves reached 1.6, so it was
/// rejected as a pattern beyond the fit.
#[test]
fn a_pattern_among_obstacles_is_corrected_not_called_uneven_ground() {
    let dir = temp_dir("depth-pattern-among-obstacles");
    let config = common::sim_config_unmeasured(
        &dir,
        &[
            (
                common::SIM_NO_PATTERN_LINE,
                "depth_distortion = { shape = \"waves\", amplitude_raw = 1.0 }",
            ),
            ("world = \"flat\"", "world = \"clutter\""),
        ],
    );
    common::on_schedule(&config, "designed-52");
    let (code, out, err) =
        groundcal(&["calibrate", "--config", config.to_str().unwrap(), "--json"]);
    let result: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}\n{err}"));
    let pattern = &result["depth_pattern"];
    assert!(
        pattern["fixed_in_the_ground_sigmas"].as_f64().unwrap() > 5.0,
        "the obstacles' feet stay with the ground: {pattern}"
    );
    assert_eq!(pattern["corrected"], true, "{}", pattern["note"]);
    assert_eq!(code, 0, "{}", result["reasons"]);
    let ((angle, angle_sigmas), (position, _)) = errors(&result);
    eprintln!("clutter, waves ±1: {angle:.4}° ({angle_sigmas:.1}σ), {position:.3} mm");
    assert!(
        angle < 0.015 && position < 0.3 && angle_sigmas < 4.0,
        "{angle}° ({angle_sigmas}σ), {position} mm"
    );
}

/// `--ground-fit paper` (the paper's fit, kept to compare with) corrects no
/// pattern, but no longer hides one: the default fit's residuals, taken
/// beside it, and the geometry across its planes judge the warp. Before,
/// with it the radial bowl was accepted 5.1 mm off, the tilted plane (no
/// shape, only an offset and gradients) 2.0 mm off on the zero-plane model
/// and uneven ground 3.7 mm off; now each is rejected in words, and open
/// flat ground with no pattern is still accepted. In a corridor, where
/// there is no pattern, nothing may claim one: the geometry across the
/// paper's own planes, biased by the walls, once marked a fixed pattern of
/// 0.67 mm there; it is now judged on the default fit's planes.
#[test]
fn the_papers_fit_does_not_hide_a_warped_depth() {
    /// What each case must come to.
    enum Expected {
        Accepted,
        /// Rejected, the depth warped, with these words.
        Warped(&'static str),
        /// Rejected for its poses (a corridor hides the ground in about
        /// half of them), no warp claimed.
        RejectedWithoutWarp,
    }
    let dir = temp_dir("depth-pattern-paper-fit");
    let radial = "depth_distortion = { shape = \"radial\", amplitude_raw = 0.5 }";
    let tilted = "depth_distortion = { shape = \"tilted\", amplitude_raw = 0.5 }";
    let fixed = "in a pattern fixed in the image, which the paper's ground fit (--ground-fit paper) does not correct";
    let cases = [
        (
            "radial",
            sim_config_with_pattern(&dir.join("radial"), radial, false),
            Expected::Warped(fixed),
        ),
        (
            "tilted",
            sim_config_with_pattern(&dir.join("tilted"), tilted, true),
            Expected::Warped(fixed),
        ),
        (
            "uneven",
            {
                let case = dir.join("uneven");
                std::fs::create_dir_all(&case).unwrap();
                common::sim_config_unmeasured(&case, &[("world = \"flat\"", "world = \"uneven\"")])
            },
            Expected::Warped("so the ground is not flat"),
        ),
        (
            "flat",
            sim_config_with_pattern(&dir.join("flat"), "", false),
            Expected::Accepted,
        ),
        (
            "corridor",
            {
                let case = dir.join("corridor");
                std::fs::create_dir_all(&case).unwrap();
                common::sim_config_unmeasured(
                    &case,
                    &[("world = \"flat\"", "world = \"corridor\"")],
                )
            },
            Expected::RejectedWithoutWarp,
        ),
    ];
    for (name, config, expected) in cases {
        let (code, out, err) = groundcal(&[
            "calibrate",
            "--config",
            config.to_str().unwrap(),
            "--ground-fit",
            "paper",
            "--json",
        ]);
        let result: Value =
            serde_json::from_str(&out).unwrap_or_else(|e| panic!("{name}: {e}: {out}\n{err}"));
        let ((angle, _), (position, _)) = errors(&result);
        eprintln!(
            "{name}, the paper's fit: exit {code}, {angle:.4}°, {position:.2} mm off, {}",
            result["reasons"]
        );
        match expected {
            Expected::RejectedWithoutWarp => {
                assert_eq!(code, 3, "{name}: {result:#}");
                let reasons = result["reasons"].to_string();
                assert!(!reasons.contains("warped"), "{name}: {reasons}");
                let pattern = &result["depth_pattern"];
                assert_ne!(pattern["uncorrected_fixed"], true, "{name}: {pattern:#}");
                assert!(
                    pattern["note"].as_str().unwrap().starts_with("none found"),
                    "{name}: {pattern:#}"
                );
            }
            Expected::Warped(words) => {
                assert_eq!(code, 3, "{name}: {result:#}");
                let reasons = result["reasons"].to_string();
                assert!(
                    reasons.contains("the depth image is warped") && reasons.contains(words),
                    "{name}: {reasons}"
                );
                assert_eq!(result["depth_pattern"]["corrected"], false, "{name}");
            }
            Expected::Accepted => {
                assert_eq!(code, 0, "{name}: {result:#}");
                assert!(position < 0.5, "{name}: {position} mm");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The found pattern leaves groundcal for a terrain mapper (`export --format
/// depth-correction`), and a check against the calibration takes it out of
/// its frames as the calibration did: `verify` of the calibration's own
/// recording finds the sensor where it was. Without the correction the
/// pattern's offset and gradients look like a sensor that moved.
#[test]
fn the_correction_is_exported_and_checks_take_it_out() {
    let dir = temp_dir("depth-pattern-export");
    let truth = DepthDistortion {
        shape: DistortionShape::Radial,
        amplitude_raw: 0.5,
        decay_per_m: 0.0,
    };
    let line = "depth_distortion = { shape = \"radial\", amplitude_raw = 0.5 }";
    let config = sim_config_with_pattern(&dir, line, false);
    common::on_schedule(&config, "designed-52");
    let [(code, live), _] = calibrate_and_replay(&config, &dir);
    assert_eq!(code, 0, "{live:#}");
    let result = dir.join("result.json");
    std::fs::write(&result, live.to_string()).unwrap();

    let (code, out, err) = groundcal(&[
        "export",
        result.to_str().unwrap(),
        "--format",
        "depth-correction",
    ]);
    assert_eq!(code, 0, "{err}");
    let exported: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(exported["format"], "groundcal-depth-correction");
    assert_eq!(exported["version"], 1);
    assert_eq!(exported["raw"].as_array().unwrap().len(), 80 * 60);
    assert_eq!(exported["depth_scale"], live["depth_scale"]);
    let rms = pattern_error(&exported, &truth);
    assert!(rms < 0.1, "exported pattern off by {rms} raw units RMS");

    let verify = |calibration: &Path| {
        let (code, out, err) = groundcal(&[
            "verify",
            "--config",
            config.to_str().unwrap(),
            "--calibration",
            calibration.to_str().unwrap(),
            "--recording",
            dir.join("rec").to_str().unwrap(),
            "--json",
        ]);
        (code, out, err)
    };
    let (code, out, err) = verify(&result);
    assert_eq!(code, 0, "with the correction: {out}\n{err}");

    // The same calibration without its pattern, as before issue 23.
    let mut bare = live.clone();
    bare.as_object_mut().unwrap().remove("depth_pattern");
    let without = dir.join("without-pattern.json");
    std::fs::write(&without, bare.to_string()).unwrap();
    let (code, out, _) = verify(&without);
    assert_eq!(
        code, 4,
        "without the correction the pattern looks like drift: {out}"
    );

    // A file that is not a correction is refused in words.
    let frame = std::fs::read_dir(dir.join("rec/kinect"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.file_name().unwrap().to_string_lossy().starts_with("d-"))
        .expect("a depth frame");
    let (code, _, err) = groundcal(&[
        "plane",
        frame.to_str().unwrap(),
        "--depth-correction",
        result.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a groundcal depth correction"), "{err}");
}
