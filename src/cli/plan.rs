//! `groundcal plan [--config FILE] [SCHEDULE] [--json]`: what a schedule will
//! give, before the robot moves (cli.md): each parameter's predicted σ, their
//! correlations, the observability and the θ and e_d to expect, from the
//! commanded poses, the nominal mount and the configuration's noise model
//! (`calib::plan`).

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::ExitStatus;
use crate::calib::outcome::Observability;
use crate::calib::plan::{
    predict_schedule_with, predict_with_depth_pattern, sigma_of_covariance, NoiseModel, Prediction,
};
use crate::formats::output::SigmaJson;
use crate::platform::input::read_bounded;
use crate::setup::config::Config;
use crate::setup::schedule::{Schedule, ScheduleError};

/// What `plan --json` prints.
#[derive(Debug, Serialize)]
pub struct PlanJson {
    /// `observable` or `not_observable`.
    pub status: &'static str,
    /// Why the schedule would not do, in an operator's words.
    pub reasons: Vec<String>,
    pub schedule: String,
    pub poses: usize,
    /// Predicted one-σ of each parameter (degrees, millimetres).
    pub sigma: SigmaJson,
    /// Predicted correlations, in the order α, β, γ, px, py, pz.
    pub correlations: [[f64; 6]; 6],
    pub observability: ObservabilityJson,
    /// The mean θ and e_d a pose should show.
    pub expected: ExpectedJson,
    /// The noise the prediction assumes per pose.
    pub noise: NoiseModel,
    /// Whether the calibration will estimate the depth scale (its σ is
    /// `sigma.depth_scale`), or take it as given, and why.
    pub depth_scale: DepthScaleJson,
    /// Predicted one-σ when the Kinect's depth carries a fixed pattern whose
    /// offset and gradients over the image are estimated with the mount
    /// (docs/method.md, "What pins each part"); absent when the schedule
    /// cannot separate them from the mount at all.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma_with_depth_pattern: Option<SigmaJson>,
    /// When correcting such a pattern would grow an angle's σ beyond the
    /// gate `pattern_angle_sigma_growth_max`, that a calibration of a
    /// Kinect with one will be rejected, in words (every real Kinect's
    /// depth has a pattern; the schedule alone is not refused for it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_pattern_note: Option<String>,
}

#[derive(Debug, Serialize)]
pub struct DepthScaleJson {
    pub estimated: bool,
    /// The value it is taken as when not estimated.
    pub value: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

#[derive(Debug, Serialize)]
pub struct ObservabilityJson {
    pub rotation_singular_values: [f64; 3],
    pub translation_singular_values: [f64; 3],
    /// The weakest rotation and position, in words.
    pub weakest_rotation: String,
    pub weakest_position: String,
    pub min_singular_value: f64,
}

#[derive(Debug, Serialize)]
pub struct ExpectedJson {
    pub theta_deg: f64,
    pub e_d_mm: f64,
}

/// The arguments of `groundcal plan`: the schedule to judge, or the one to design.
#[derive(Debug, clap::Args)]
pub struct PlanArgs {
    /// The configuration (nominal mount, limits, gates, [calibration.noise]); default /etc/groundcal/groundcal.toml.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The schedule to judge (default: the configuration's).
    pub schedule: Option<PathBuf>,
    /// Design a schedule of N poses within the robot's limits instead (needs --out).
    #[arg(long, value_name = "N", requires = "out")]
    pub design: Option<usize>,
    /// Where --design writes the schedule (a config/schedules/*.toml file).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// One JSON document on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: PlanArgs) -> ExitStatus {
    match (args.design, args.out) {
        (Some(count), Some(out)) => run_design(args.config.as_deref(), count, &out, args.json),
        (None, None) => run(args.config.as_deref(), args.schedule.as_deref(), args.json),
        _ => super::usage_error("plan: --design N and --out FILE go together".into()),
    }
}

/// Runs the command.
pub fn run(config_path: Option<&Path>, schedule_path: Option<&Path>, json: bool) -> ExitStatus {
    let Inputs {
        config,
        schedule,
        nominal,
        noise,
        ..
    } = match load(config_path, schedule_path) {
        Ok(inputs) => inputs,
        Err(e) => {
            eprintln!("groundcal plan: {e}");
            return ExitStatus::BadInput;
        }
    };
    let mut reasons = Vec::new();
    // Limits first: a pose the robot may not take is bad input, named.
    match schedule.validate(&config.robot.limits) {
        Ok(()) => {}
        Err(ScheduleError::Unobservable { reason, .. }) => reasons.push(reason),
        Err(e) => {
            eprintln!("groundcal plan: {e}");
            return ExitStatus::BadInput;
        }
    }
    let poses: Vec<_> = schedule.poses.iter().map(|p| p.to_params()).collect();
    let prediction =
        match predict_schedule_with(&poses, &nominal, &noise, config.calibration.depth_scale) {
            Ok(p) => p,
            Err(e) => {
                eprintln!("groundcal plan: the schedule cannot be solved: {e}");
                return ExitStatus::Rejected;
            }
        };
    for problem in &prediction.observability.problems {
        if !reasons.contains(problem) {
            reasons.push(problem.clone());
        }
    }
    let sigma = prediction.sigma_deg_mm();
    let gates = &config.calibration.gates;
    let worst_angle = sigma[..3].iter().cloned().fold(0.0, f64::max);
    let worst_position = sigma[3..].iter().cloned().fold(0.0, f64::max);
    if worst_angle > gates.sigma_angle_max_deg {
        reasons.push(format!(
            "the predicted σ of an angle is {worst_angle:.3}°, beyond the gate of {}°",
            gates.sigma_angle_max_deg
        ));
    }
    if worst_position > gates.sigma_position_max_mm {
        reasons.push(format!(
            "the predicted σ of a position is {worst_position:.2} mm, beyond the gate of {} mm",
            gates.sigma_position_max_mm
        ));
    }
    if schedule.poses.len() < gates.min_poses_used {
        reasons.push(format!(
            "{} poses, fewer than the {} the gates ask for",
            schedule.poses.len(),
            gates.min_poses_used
        ));
    }
    let mut plan = to_json(&schedule, &prediction, noise, reasons);
    plan.sigma_with_depth_pattern =
        with_depth_pattern(&schedule, &nominal, &noise, config.calibration.depth_scale);
    plan.depth_pattern_note = plan.sigma_with_depth_pattern.as_ref().and_then(|with| {
        depth_pattern_note(&plan.sigma, with, gates.pattern_angle_sigma_growth_max)
    });
    let printed = if json {
        super::print_json(&plan)
    } else {
        print!("{}", to_text(&plan));
        Ok(())
    };
    if let Err(e) = printed {
        eprintln!("groundcal plan: {e}");
        return ExitStatus::RuntimeFailure;
    }
    if plan.reasons.is_empty() {
        ExitStatus::Success
    } else {
        ExitStatus::Rejected
    }
}

/// Whether correcting a depth pattern would grow an angle's predicted σ
/// beyond `growth_max` times `without`, as the calibration's gate judges,
/// in words.
fn depth_pattern_note(without: &SigmaJson, with: &SigmaJson, growth_max: f64) -> Option<String> {
    let (k, growth) = crate::calib::quality::angle_sigma_growth(
        [with.alpha_deg, with.beta_deg, with.gamma_deg],
        [without.alpha_deg, without.beta_deg, without.gamma_deg],
    );
    let name = ["alpha", "beta", "gamma"][k];
    // As the gate judges: within its ratio, or every angle within what costs nothing.
    let negligible = [with.alpha_deg, with.beta_deg, with.gamma_deg]
        .iter()
        .all(|s| *s <= crate::calib::quality::PATTERN_COST_NEGLIGIBLE_DEG);
    (growth > growth_max && !negligible).then(|| {
        format!(
            "a Kinect's depth pattern (a real one always has one) would make {name} {growth:.1} times less certain than without it, more than the {growth_max} times the gate pattern_angle_sigma_growth_max allows: its calibration will be rejected on this schedule; groundcal plan --design spreads the body's heights wider"
        )
    })
}

/// The predicted σ of `schedule` when a depth pattern's plane part is
/// estimated with the mount, or `None` when it cannot be.
fn with_depth_pattern(
    schedule: &Schedule,
    nominal: &crate::calib::geometry::PoseParams,
    noise: &NoiseModel,
    depth_scale: crate::calib::solve::DepthScaleSetting,
) -> Option<SigmaJson> {
    let poses: Vec<_> = schedule.poses.iter().map(|p| p.to_params()).collect();
    let covariance = predict_with_depth_pattern(&poses, nominal, noise, depth_scale)
        .ok()
        .flatten()?;
    Some(SigmaJson::from_radians_metres(&sigma_of_covariance(
        &covariance,
    )))
}

/// What planning starts from: the configuration (every check but the
/// schedule's), the schedule to judge (the one given, else the
/// configuration's), the nominal mount and the noise model.
struct Inputs {
    config: Config,
    config_path: PathBuf,
    schedule: Schedule,
    nominal: crate::calib::geometry::PoseParams,
    noise: NoiseModel,
}

fn load(config_path: Option<&Path>, schedule_path: Option<&Path>) -> Result<Inputs, String> {
    let config_path = config_path
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("/etc/groundcal/groundcal.toml"));
    let bytes = read_bounded(&config_path, 1 << 20).map_err(|e| e.to_string())?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| format!("{}: not UTF-8: {e}", config_path.display()))?;
    let config = Config::parse(&config_path, text).map_err(|e| e.to_string())?;
    config
        .validate_settings(&config_path)
        .map_err(|e| e.to_string())?;
    let schedule_path = schedule_path
        .map(Path::to_path_buf)
        .unwrap_or_else(|| config.schedule_path(&config_path));
    let schedule = Schedule::read(&schedule_path).map_err(|e| e.to_string())?;
    let nominal = config
        .calibration
        .nominal_mount
        .ok_or_else(|| {
            format!(
                "{}: calibration.nominal_mount is needed to plan (the planes depend on the mount)",
                config_path.display()
            )
        })?
        .pose()
        .to_params();
    let noise = config
        .calibration
        .noise
        .unwrap_or_else(NoiseModel::solve_floors);
    Ok(Inputs {
        config,
        config_path,
        schedule,
        nominal,
        noise,
    })
}

fn to_json(
    schedule: &Schedule,
    prediction: &Prediction,
    noise: NoiseModel,
    reasons: Vec<String>,
) -> PlanJson {
    let s = prediction.sigma_deg_mm();
    let o: &Observability = &prediction.observability;
    PlanJson {
        status: if o.problems.is_empty() {
            "observable"
        } else {
            "not_observable"
        },
        reasons,
        schedule: schedule.name.clone(),
        poses: schedule.poses.len(),
        sigma: SigmaJson {
            alpha_deg: s[0],
            beta_deg: s[1],
            gamma_deg: s[2],
            px_mm: s[3],
            py_mm: s[4],
            pz_mm: s[5],
            depth_scale: prediction.depth_scale.sigma,
        },
        depth_scale: DepthScaleJson {
            estimated: prediction.depth_scale.estimated,
            value: prediction.depth_scale.value,
            note: prediction.depth_scale.note.clone(),
        },
        correlations: prediction.correlations(),
        observability: ObservabilityJson {
            rotation_singular_values: o.rotation_singular_values,
            translation_singular_values: o.translation_singular_values,
            weakest_rotation: crate::calib::outcome::rotation_words(&o.rotation_weakest_axis),
            weakest_position: crate::calib::outcome::position_words(&o.translation_weakest_axis),
            min_singular_value: o.min_singular_value,
        },
        expected: ExpectedJson {
            theta_deg: prediction.expected_theta_deg,
            e_d_mm: prediction.expected_e_d_mm,
        },
        noise,
        sigma_with_depth_pattern: None,
        depth_pattern_note: None,
    }
}

fn to_text(plan: &PlanJson) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let s = &plan.sigma;
    let _ = writeln!(
        out,
        "schedule \"{}\": {} poses; noise per pose {}° and {} mm",
        plan.schedule, plan.poses, plan.noise.normal_sigma_deg, plan.noise.offset_sigma_mm
    );
    let _ = writeln!(out, "\npredicted σ");
    for (name, value, unit) in [
        ("alpha", s.alpha_deg, "°"),
        ("beta", s.beta_deg, "°"),
        ("gamma", s.gamma_deg, "°"),
        ("px", s.px_mm, " mm"),
        ("py", s.py_mm, " mm"),
        ("pz", s.pz_mm, " mm"),
    ] {
        let _ = writeln!(out, "  {name:<8} {value:>10.4}{unit}");
    }
    match (plan.depth_scale.estimated, s.depth_scale) {
        (true, Some(sigma)) => {
            let _ = writeln!(
                out,
                "  {:<8} {sigma:>10.5}  (estimated with the mount)",
                "depth scale"
            );
        }
        _ => {
            let _ = writeln!(
                out,
                "  depth scale {:.4}, {}",
                plan.depth_scale.value,
                plan.depth_scale.note.as_deref().unwrap_or("not estimated")
            );
        }
    }
    if let Some(p) = &plan.sigma_with_depth_pattern {
        let _ = writeln!(
            out,
            "\nwith a depth pattern (its offset and gradients estimated with the mount):\n  alpha {:.4}°  beta {:.4}°  gamma {:.4}°\n  px {:.3} mm  py {:.3} mm  pz {:.3} mm",
            p.alpha_deg, p.beta_deg, p.gamma_deg, p.px_mm, p.py_mm, p.pz_mm
        );
    }
    if let Some(note) = &plan.depth_pattern_note {
        let _ = writeln!(out, "  note: {note}");
    }
    let _ = writeln!(
        out,
        "\nweakest rotation: {}\nweakest position: {}",
        plan.observability.weakest_rotation, plan.observability.weakest_position
    );
    let _ = writeln!(
        out,
        "expected per pose: θ {:.3}°, e_d {:.2} mm",
        plan.expected.theta_deg, plan.expected.e_d_mm
    );
    if plan.reasons.is_empty() {
        let _ = writeln!(out, "\nstatus: OBSERVABLE, within the gates");
    } else {
        let _ = writeln!(out, "\nstatus: WOULD BE REJECTED");
        for reason in &plan.reasons {
            let _ = writeln!(out, "  - {reason}");
        }
    }
    out
}

/// What `plan --design N --json` prints.
#[derive(Debug, Serialize)]
pub struct DesignJson {
    pub out: PathBuf,
    pub designed: ScheduleSummaryJson,
    pub configured: ScheduleSummaryJson,
    /// Candidate poses considered, and those the Kinect could not see the
    /// ground from.
    pub candidates: usize,
    pub candidates_unseen: usize,
}

#[derive(Debug, Serialize)]
pub struct ScheduleSummaryJson {
    pub schedule: String,
    pub poses: usize,
    /// Predicted one-σ (null when the schedule cannot observe all six).
    pub sigma: Option<SigmaJson>,
    /// The same when a depth pattern's offset and gradients are estimated
    /// with the mount (as `plan`'s `sigma_with_depth_pattern`).
    pub sigma_with_depth_pattern: Option<SigmaJson>,
    /// As `plan`'s: when a calibration of a Kinect with a depth pattern
    /// would be rejected on this schedule for the pattern's cost.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_pattern_note: Option<String>,
    /// Estimated robot time: per pose the motion, the settling and the
    /// frames.
    pub wall_time_s: f64,
}

/// `plan --design N --out FILE`: designs a schedule of N poses and writes it.
pub fn run_design(config_path: Option<&Path>, count: usize, out: &Path, json: bool) -> ExitStatus {
    let Inputs {
        config,
        config_path,
        schedule: configured,
        nominal,
        noise,
    } = match load(config_path, None) {
        Ok(inputs) => inputs,
        Err(e) => {
            eprintln!("groundcal plan: {e}");
            return ExitStatus::BadInput;
        }
    };
    let gates = &config.calibration.gates;
    let configured_sigma = crate::setup::design::predicted_sigma(&configured, &nominal, &noise);
    // Against the configured schedule when it observes all six, else the gates.
    let reference = configured_sigma.unwrap_or([
        gates.sigma_angle_max_deg.to_radians(),
        gates.sigma_angle_max_deg.to_radians(),
        gates.sigma_angle_max_deg.to_radians(),
        gates.sigma_position_max_mm / 1000.0,
        gates.sigma_position_max_mm / 1000.0,
        gates.sigma_position_max_mm / 1000.0,
    ]);
    let design = match crate::setup::design::design_schedule(
        count,
        &config.robot.limits,
        &configured,
        &nominal,
        &noise,
        &reference,
    ) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("groundcal plan: {e}");
            return ExitStatus::BadInput;
        }
    };
    let designed_sigma = crate::setup::design::predicted_sigma(&design.schedule, &nominal, &noise);
    let c = &config.calibration;
    let per_pose_s =
        (f64::from(c.motion_ms) + c.settle_ms as f64) / 1000.0 + c.frames_per_pose as f64 / 30.0;
    let how = format!(
        "Designed by `groundcal plan --design {count}` from {config}: of {candidates} candidate\n\
         body poses (roll and pitch at 0, ±45 % and ±90 % of the ±{tilt}° tilt limit, three\n\
         heights within {lo}..{hi} mm; {unseen} left out where the Kinect would see the ground\n\
         farther than in \"{reference}\"), the {count} that minimise the mean squared ratio of\n\
         each parameter's predicted σ to that of \"{reference}\" (backward elimination, then\n\
         exchange), visited nearest first. Largest ratio {ratio:.2}; total motion {deg:.0}° of\n\
         tilt and {mm:.0} mm of height. Noise per pose: {n_deg}° and {n_mm} mm.",
        config = config_path.display(),
        candidates = design.candidates,
        tilt = config.robot.limits.max_tilt_deg,
        lo = config.robot.limits.min_height_mm,
        hi = config.robot.limits.max_height_mm,
        unseen = design.unseen,
        reference = configured.name,
        ratio = design.worst_ratio,
        deg = design.motion_deg,
        mm = design.motion_mm,
        n_deg = noise.normal_sigma_deg,
        n_mm = noise.offset_sigma_mm,
    );
    if let Err(e) = crate::platform::files::write_atomically(
        out,
        crate::setup::design::to_toml(&design, &how).as_bytes(),
    ) {
        eprintln!("groundcal plan: {}: {e}", out.display());
        return ExitStatus::RuntimeFailure;
    }
    let summary = |schedule: &Schedule, sigma: Option<[f64; 6]>| {
        let without = sigma.as_ref().map(SigmaJson::from_radians_metres);
        let with =
            sigma.and_then(|_| with_depth_pattern(schedule, &nominal, &noise, c.depth_scale));
        ScheduleSummaryJson {
            schedule: schedule.name.clone(),
            poses: schedule.poses.len(),
            depth_pattern_note: without
                .as_ref()
                .zip(with.as_ref())
                .and_then(|(without, with)| {
                    depth_pattern_note(without, with, gates.pattern_angle_sigma_growth_max)
                }),
            sigma: without,
            sigma_with_depth_pattern: with,
            wall_time_s: per_pose_s * schedule.poses.len() as f64,
        }
    };
    let report = DesignJson {
        out: out.to_path_buf(),
        designed: summary(&design.schedule, designed_sigma),
        configured: summary(&configured, configured_sigma),
        candidates: design.candidates,
        candidates_unseen: design.unseen,
    };
    let printed = if json {
        super::print_json(&report)
    } else {
        print!("{}", design_text(&report, &how));
        Ok(())
    };
    if let Err(e) = printed {
        eprintln!("groundcal plan: {e}");
        return ExitStatus::RuntimeFailure;
    }
    let passes = report.designed.sigma.as_ref().is_some_and(|s| {
        s.alpha_deg.max(s.beta_deg).max(s.gamma_deg) <= gates.sigma_angle_max_deg
            && s.px_mm.max(s.py_mm).max(s.pz_mm) <= gates.sigma_position_max_mm
    });
    if passes {
        ExitStatus::Success
    } else {
        ExitStatus::Rejected
    }
}

fn design_text(report: &DesignJson, how: &str) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(out, "{how}\n");
    let (d, c) = (&report.designed, &report.configured);
    let _ = writeln!(
        out,
        "predicted σ      {:>14} {:>14}",
        format!("{} ({})", d.schedule, d.poses),
        format!("{} ({})", c.schedule, c.poses)
    );
    let pick = |s: &Option<SigmaJson>, k: usize| {
        s.as_ref().map_or("-".to_string(), |s| {
            let v = s.values()[k];
            if k < 3 {
                format!("{v:.4}°")
            } else {
                format!("{v:.3} mm")
            }
        })
    };
    // Without a depth pattern, then with one (its offset and gradients
    // estimated with the mount).
    for (suffix, designed, configured) in [
        ("", &d.sigma, &c.sigma),
        (
            ", pattern",
            &d.sigma_with_depth_pattern,
            &c.sigma_with_depth_pattern,
        ),
    ] {
        for (k, name) in ["alpha", "beta", "gamma", "px", "py", "pz"]
            .iter()
            .enumerate()
        {
            let _ = writeln!(
                out,
                "  {:<14} {:>14} {:>14}",
                format!("{name}{suffix}"),
                pick(designed, k),
                pick(configured, k)
            );
        }
    }
    let _ = writeln!(
        out,
        "  {:<14} {:>14} {:>14}",
        "robot time",
        format!("{:.0} s", d.wall_time_s),
        format!("{:.0} s", c.wall_time_s)
    );
    for summary in [d, c] {
        if let Some(note) = &summary.depth_pattern_note {
            let _ = writeln!(out, "  note on {}: {note}", summary.schedule);
        }
    }
    let _ = writeln!(out, "\nwritten to {}", report.out.display());
    out
}
