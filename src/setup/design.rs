//! Designing a schedule (`groundcal plan --design N`): the candidate body
//! poses within the robot's limits from which the Kinect still sees the
//! ground, the choice among them that minimises the predicted σ
//! (`calib::plan::design`), the order that keeps each motion short, and the
//! schedule file.

use std::fmt::Write;

use crate::calib::geometry::{PoseDegMm, PoseParams};
use crate::calib::plan::{design, predict_schedule, NoiseModel};
use crate::calib::solve::predict;
use crate::setup::schedule::{Limits, Schedule};

/// Levels of roll and pitch, as fractions of the tilt limit: a margin of a
/// tenth keeps the body off the limit itself.
const TILT_LEVELS: [f64; 5] = [-0.9, -0.45, 0.0, 0.45, 0.9];
/// Heights, as fractions of the height range (a tenth inside each end).
const HEIGHT_LEVELS: [f64; 3] = [0.1, 0.5, 0.9];

/// A designed schedule and what it took.
#[derive(Debug, Clone)]
pub struct Design {
    pub schedule: Schedule,
    /// How many candidate poses were considered (and how many the Kinect
    /// could not see the ground from).
    pub candidates: usize,
    pub unseen: usize,
    /// The largest ratio of a parameter's predicted σ to the reference's
    /// (the choice minimises the mean of their squares).
    pub worst_ratio: f64,
    /// Total motion along the visiting order, from home and back: the sum
    /// of the tilt changes (°) and of the height changes (mm).
    pub motion_deg: f64,
    pub motion_mm: f64,
}

/// How far along its optical axis the sensor sees the ground at a body pose
/// (metres), or None when the axis does not meet the ground. The sensor
/// frame's X is the optical axis; the ground is `n·x + d = 0`.
fn ground_along_axis(nominal: &PoseParams, body: &PoseParams) -> Option<f64> {
    let plane = predict(nominal, &body.to_transform());
    let towards = -plane.normal.x;
    (towards > 1e-6).then(|| plane.d / towards)
}

/// The candidates: a grid of roll, pitch and height within `limits`, level
/// yaw and no shift, kept only where the sensor sees the ground along its
/// axis no farther than it does in `reference` (what that schedule already
/// asks of the Kinect).
fn candidates(
    limits: &Limits,
    reference: &Schedule,
    nominal: &PoseParams,
) -> (Vec<PoseDegMm>, usize) {
    let farthest = reference
        .poses
        .iter()
        .filter_map(|p| ground_along_axis(nominal, &p.to_params()))
        .fold(0.0, f64::max);
    let mut all = Vec::new();
    let mut unseen = 0;
    for &height in &HEIGHT_LEVELS {
        for &pitch in &TILT_LEVELS {
            for &roll in &TILT_LEVELS {
                let pose = PoseDegMm {
                    alpha_deg: 0.0,
                    beta_deg: round1(pitch * limits.max_tilt_deg),
                    gamma_deg: round1(roll * limits.max_tilt_deg),
                    px_mm: 0.0,
                    py_mm: round1(
                        limits.min_height_mm
                            + height * (limits.max_height_mm - limits.min_height_mm),
                    ),
                    pz_mm: 0.0,
                };
                match ground_along_axis(nominal, &pose.to_params()) {
                    Some(t) if t <= farthest => all.push(pose),
                    _ => unseen += 1,
                }
            }
        }
    }
    (all, unseen)
}

fn round1(value: f64) -> f64 {
    (value * 10.0).round() / 10.0
}

/// How far apart two poses are for the robot: degrees of tilt, with 10 mm of
/// height counted as a degree.
fn step(a: &PoseDegMm, b: &PoseDegMm) -> f64 {
    ((a.beta_deg - b.beta_deg).powi(2) + (a.gamma_deg - b.gamma_deg).powi(2)).sqrt()
        + (a.py_mm - b.py_mm).abs() / 10.0
}

/// A visiting order from home: always the nearest pose not yet visited.
fn visiting_order(home: &PoseDegMm, poses: Vec<PoseDegMm>) -> Vec<PoseDegMm> {
    let mut left = poses;
    let mut ordered = Vec::with_capacity(left.len());
    let mut at = *home;
    while !left.is_empty() {
        let mut nearest = 0;
        for k in 1..left.len() {
            if step(&at, &left[k]) < step(&at, &left[nearest]) {
                nearest = k;
            }
        }
        at = left.remove(nearest);
        ordered.push(at);
    }
    ordered
}

/// Designs a schedule of `count` poses within `limits` whose predicted σ
/// are, parameter by parameter, as small as possible against `reference`
/// (σ in radians and metres, e.g. the configured schedule's prediction).
pub fn design_schedule(
    count: usize,
    limits: &Limits,
    configured: &Schedule,
    nominal: &PoseParams,
    noise: &NoiseModel,
    reference: &[f64; 6],
) -> Result<Design, String> {
    let (candidates, unseen) = candidates(limits, configured, nominal);
    if count < 6 {
        return Err(format!("--design {count}: at least 6 poses are needed"));
    }
    if count > candidates.len() {
        return Err(format!(
            "--design {count}: only {} candidate poses are within the limits and let the Kinect see the ground",
            candidates.len()
        ));
    }
    let params: Vec<PoseParams> = candidates.iter().map(PoseDegMm::to_params).collect();
    let (chosen, worst_ratio) = design(&params, count, nominal, noise, reference)
        .ok_or_else(|| format!("no {count} of the candidate poses observe all six parameters"))?;
    let poses = visiting_order(
        &configured.home,
        chosen.iter().map(|&i| candidates[i]).collect(),
    );
    let mut motion_deg = 0.0;
    let mut motion_mm = 0.0;
    let mut at = configured.home;
    for pose in poses.iter().chain(std::iter::once(&configured.home)) {
        motion_deg += ((pose.beta_deg - at.beta_deg).powi(2)
            + (pose.gamma_deg - at.gamma_deg).powi(2))
        .sqrt();
        motion_mm += (pose.py_mm - at.py_mm).abs();
        at = *pose;
    }
    Ok(Design {
        schedule: Schedule {
            name: format!("designed-{count}"),
            home: configured.home,
            poses,
            file: None,
        },
        candidates: candidates.len() + unseen,
        unseen,
        worst_ratio,
        motion_deg,
        motion_mm,
    })
}

/// The predicted σ of a schedule, in radians and metres (None when it
/// cannot observe all six).
pub fn predicted_sigma(
    schedule: &Schedule,
    nominal: &PoseParams,
    noise: &NoiseModel,
) -> Option<[f64; 6]> {
    let poses: Vec<PoseParams> = schedule.poses.iter().map(PoseDegMm::to_params).collect();
    let prediction = predict_schedule(&poses, nominal, noise).ok()?;
    prediction
        .observability
        .problems
        .is_empty()
        .then(|| prediction.sigma())
}

/// The schedule as a `config/schedules/*.toml` file, with a comment saying
/// how it was made.
pub fn to_toml(design: &Design, how: &str) -> String {
    let mut out = String::new();
    for line in how.lines() {
        let _ = writeln!(out, "# {line}");
    }
    let s = &design.schedule;
    let _ = writeln!(out, "\nname = \"{}\"\n", s.name);
    let pose = |p: &PoseDegMm| {
        format!(
            "{{ alpha_deg = {}, beta_deg = {}, gamma_deg = {}, px_mm = {}, py_mm = {}, pz_mm = {} }}",
            p.alpha_deg, p.beta_deg, p.gamma_deg, p.px_mm, p.py_mm, p.pz_mm
        )
    };
    let _ = writeln!(out, "home = {}\n\nposes = [", pose(&s.home));
    for (i, p) in s.poses.iter().enumerate() {
        let _ = writeln!(out, "  {}, # {}", pose(p), i + 1);
    }
    let _ = writeln!(out, "]");
    out
}
