//! Accuracy per pose (paper section 5.2: θ and e_d), its summary, and the
//! quality gates that decide whether a calibration is accepted.

use nalgebra::Vector6;
use serde::{Deserialize, Serialize};

use crate::outcome::{Calibration, Observability, PoseOutcome, Solution, Summary, Verdict};

/// Thresholds a calibration must meet to be accepted. Degrees and millimetres,
/// as an operator would set them in the configuration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Gates {
    /// Largest θ of a used pose. The paper reports 0.52° at most.
    pub theta_max_deg: f64,
    /// Largest e_d of a used pose. The paper reports 3.2 mm at most.
    pub e_d_max_mm: f64,
    /// Largest one-σ of α, β, γ.
    pub sigma_angle_max_deg: f64,
    /// Largest one-σ of px, py, pz.
    pub sigma_position_max_mm: f64,
    /// Fewest poses that must be used.
    pub min_poses_used: usize,
    /// Smallest fraction of the poses that must be used.
    pub min_used_fraction: f64,
}

impl Default for Gates {
    fn default() -> Self {
        Self {
            theta_max_deg: 1.0,
            e_d_max_mm: 5.0,
            sigma_angle_max_deg: 0.1,
            sigma_position_max_mm: 2.0,
            min_poses_used: 6,
            min_used_fraction: 0.7,
        }
    }
}

impl Gates {
    /// Whether the thresholds make sense.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("theta_max_deg", self.theta_max_deg),
            ("e_d_max_mm", self.e_d_max_mm),
            ("sigma_angle_max_deg", self.sigma_angle_max_deg),
            ("sigma_position_max_mm", self.sigma_position_max_mm),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!(
                    "gates.{name} must be a positive number, not {value}"
                ));
            }
        }
        if !(0.0..=1.0).contains(&self.min_used_fraction) {
            return Err(format!(
                "gates.min_used_fraction must lie in 0..1, not {}",
                self.min_used_fraction
            ));
        }
        if self.min_poses_used < 3 {
            return Err("gates.min_poses_used must be at least 3".into());
        }
        Ok(())
    }
}

/// The verdict on what the solve found: the summary of the used poses, the
/// reasons against it and whether it is accepted. `poses_total` counts the
/// poses of the run, including those that gave no observation at all.
pub fn assess(solution: Solution, poses_total: usize, gates: &Gates) -> Calibration {
    let mut summary = summarise(&solution.poses);
    summary.poses_total = summary.poses_total.max(poses_total);
    let reasons = judge(
        gates,
        &summary,
        &solution.poses,
        &solution.sigma(),
        &solution.observability,
    );
    Calibration {
        verdict: if reasons.is_empty() {
            Verdict::Accepted
        } else {
            Verdict::Rejected
        },
        reasons,
        robot_from_sensor: solution.robot_from_sensor,
        covariance: solution.covariance,
        poses: solution.poses,
        summary,
        observability: solution.observability,
        variance_factors: solution.variance_factors,
        iterations: solution.iterations,
    }
}

/// The summary of the used poses.
pub fn summarise(poses: &[PoseOutcome]) -> Summary {
    let used: Vec<&PoseOutcome> = poses.iter().filter(|p| p.used).collect();
    let n = used.len().max(1) as f64;
    Summary {
        poses_total: poses.len(),
        poses_used: used.len(),
        theta_mean: used.iter().map(|p| p.theta).sum::<f64>() / n,
        theta_max: used.iter().map(|p| p.theta).fold(0.0, f64::max),
        e_d_mean: used.iter().map(|p| p.e_d).sum::<f64>() / n,
        e_d_max: used.iter().map(|p| p.e_d).fold(0.0, f64::max),
    }
}

const ANGLE_NAMES: [&str; 3] = ["α", "β", "γ"];
const POSITION_NAMES: [&str; 3] = ["p_x", "p_y", "p_z"];

/// The reasons, in an operator's words, why a result must not be used; empty
/// when it passes every gate. `sigma` is in radians and metres.
pub fn judge(
    gates: &Gates,
    summary: &Summary,
    poses: &[PoseOutcome],
    sigma: &Vector6<f64>,
    observability: &Observability,
) -> Vec<String> {
    let mut reasons: Vec<String> = observability.problems.clone();
    if summary.poses_used < gates.min_poses_used {
        reasons.push(format!(
            "only {} poses could be used, at least {} are needed",
            summary.poses_used, gates.min_poses_used
        ));
    }
    let fraction = summary.poses_used as f64 / summary.poses_total.max(1) as f64;
    if fraction < gates.min_used_fraction {
        reasons.push(format!(
            "only {} of {} poses could be used (at least {:.0}% are needed): see the reasons given for each pose",
            summary.poses_used,
            summary.poses_total,
            100.0 * gates.min_used_fraction
        ));
    }
    let worst = |key: fn(&PoseOutcome) -> f64| {
        poses
            .iter()
            .filter(|p| p.used)
            .max_by(|a, b| key(a).total_cmp(&key(b)))
            .map(|p| p.index)
    };
    if summary.theta_max.to_degrees() > gates.theta_max_deg {
        reasons.push(format!(
            "the measured ground disagrees with the result by up to {:.2}° (pose {}), more than the {:.2}° allowed: the ground may not be flat, or the body pose is wrong",
            summary.theta_max.to_degrees(),
            worst(|p| p.theta).unwrap_or(0),
            gates.theta_max_deg
        ));
    }
    if summary.e_d_max * 1e3 > gates.e_d_max_mm {
        reasons.push(format!(
            "the measured ground height disagrees with the result by up to {:.1} mm (pose {}), more than the {:.1} mm allowed: the ground may not be flat, or the body pose is wrong",
            summary.e_d_max * 1e3,
            worst(|p| p.e_d).unwrap_or(0),
            gates.e_d_max_mm
        ));
    }
    // Unobservable directions are already named; do not repeat them as σ.
    if observability.problems.is_empty() {
        for k in 0..3 {
            let s = sigma[k].to_degrees();
            // NaN (an unobservable direction) fails the gate too.
            if s.is_nan() || s > gates.sigma_angle_max_deg {
                reasons.push(format!(
                    "the angle {} is uncertain (σ = {:.3}°, at most {:.3}° allowed): add poses with larger tilts or more frames per pose",
                    ANGLE_NAMES[k], s, gates.sigma_angle_max_deg
                ));
            }
            let s = sigma[3 + k] * 1e3;
            if s.is_nan() || s > gates.sigma_position_max_mm {
                reasons.push(format!(
                    "the position {} is uncertain (σ = {:.2} mm, at most {:.2} mm allowed): add poses with larger tilts or more frames per pose",
                    POSITION_NAMES[k], s, gates.sigma_position_max_mm
                ));
            }
        }
    }
    reasons
}
