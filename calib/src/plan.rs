//! What a schedule will give, before the robot moves: the six parameters'
//! σ, their correlations and the observability, predicted from the body
//! poses alone.
//!
//! The solve's Jacobian depends only on the body poses, the mount and the
//! planes' noise, not on the measurements. So the prediction runs the solve
//! itself on the planes the nominal mount predicts at each commanded pose
//! (exact, so the solve returns the nominal mount), weighted by a noise model:
//! the covariance it returns is `(JᵀWJ)⁻¹` for that noise. No second copy of
//! the math, so the prediction and the solve cannot drift apart.

use nalgebra::Matrix6;
use serde::{Deserialize, Serialize};

use super::geometry::PoseParams;
use super::outcome::Observability;
use super::solve::{
    exact_observation, solve, DepthScaleSetting, Observation, SolveError, SolveSettings,
};

/// The noise of one observation's ground, as the solve sees it: the
/// measured plane against the one the mount and the body pose from the feet
/// predict. It lumps the plane fit, the body pose from the feet and the
/// ground's unevenness together.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseModel {
    /// σ of the normal's direction, per tangent direction (degrees).
    pub normal_sigma_deg: f64,
    /// σ of the ground's distance `d` (millimetres).
    pub offset_sigma_mm: f64,
}

impl NoiseModel {
    /// The noise the solve assumes at least (its floors): a real Kinect on a
    /// real robot, conservatively.
    pub fn solve_floors() -> Self {
        let floors = SolveSettings::default();
        Self {
            normal_sigma_deg: floors.normal_sigma_floor.to_degrees(),
            offset_sigma_mm: floors.offset_sigma_floor * 1000.0,
        }
    }

    /// The solve's settings with this noise as its floors: what it assumes
    /// at least, so that the σ it reports are the ones predicted here.
    pub fn solve_settings(&self) -> SolveSettings {
        SolveSettings {
            normal_sigma_floor: self.normal_sigma_deg.to_radians(),
            offset_sigma_floor: self.offset_sigma_mm / 1000.0,
            ..SolveSettings::default()
        }
    }

    /// Whether both σ are positive and finite.
    pub fn validate(&self) -> Result<(), String> {
        for (name, value) in [
            ("normal_sigma_deg", self.normal_sigma_deg),
            ("offset_sigma_mm", self.offset_sigma_mm),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("{name} must be a positive number, not {value}"));
            }
        }
        Ok(())
    }
}

/// The prediction for a schedule.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// Covariance of `[α, β, γ, px, py, pz]` (radians, metres).
    pub covariance: Matrix6<f64>,
    /// Whether the depth scale will be estimated, and its σ.
    pub depth_scale: super::outcome::DepthScale,
    pub observability: Observability,
    /// The mean θ and e_d a pose will show, from the noise alone (degrees,
    /// millimetres): a Rayleigh mean for the angle, a half-normal for e_d.
    pub expected_theta_deg: f64,
    pub expected_e_d_mm: f64,
}

impl Prediction {
    /// One σ of each parameter (degrees, millimetres), in the order
    /// α, β, γ, px, py, pz.
    pub fn sigma_deg_mm(&self) -> [f64; 6] {
        let sigma = self.sigma();
        std::array::from_fn(|i| {
            if i < 3 {
                sigma[i].to_degrees()
            } else {
                sigma[i] * 1000.0
            }
        })
    }

    /// One σ of each parameter (radians, metres), in the order α, β, γ,
    /// px, py, pz.
    pub fn sigma(&self) -> [f64; 6] {
        sigma_of_covariance(&self.covariance)
    }

    /// The correlation matrix of the six parameters.
    pub fn correlations(&self) -> [[f64; 6]; 6] {
        let c = &self.covariance;
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let scale = (c[(i, i)] * c[(j, j)]).sqrt();
                if scale > 0.0 && scale.is_finite() {
                    c[(i, j)] / scale
                } else if i == j {
                    1.0
                } else {
                    0.0
                }
            })
        })
    }
}

/// One σ of each parameter of `covariance` (radians, metres), in the order
/// α, β, γ, px, py, pz.
pub fn sigma_of_covariance(covariance: &Matrix6<f64>) -> [f64; 6] {
    super::outcome::sigma_of(covariance).into()
}

/// Predicts what a calibration over `body_poses` (commanded
/// `ground_from_robot`, which the real poses follow closely) will give for
/// a sensor mounted near `nominal`, with `noise` on each observation.
pub fn predict_schedule(
    body_poses: &[PoseParams],
    nominal: &PoseParams,
    noise: &NoiseModel,
) -> Result<Prediction, SolveError> {
    predict_schedule_with(body_poses, nominal, noise, DepthScaleSetting::Fixed(1.0))
}

/// [`predict_schedule`] with the depth scale estimated or given, as the
/// calibration will treat it: estimating it widens the translation's σ, and
/// the prediction says whether the schedule observes it at all.
pub fn predict_schedule_with(
    body_poses: &[PoseParams],
    nominal: &PoseParams,
    noise: &NoiseModel,
    depth_scale: DepthScaleSetting,
) -> Result<Prediction, SolveError> {
    let observations = exact_observations(body_poses, nominal);
    let settings = prediction_settings(noise, depth_scale);
    let solution = solve(&observations, &settings)?;
    Ok(Prediction {
        covariance: solution.covariance,
        depth_scale: solution.depth_scale,
        observability: solution.observability,
        expected_theta_deg: noise.normal_sigma_deg * (std::f64::consts::PI / 2.0).sqrt(),
        expected_e_d_mm: noise.offset_sigma_mm * (2.0 / std::f64::consts::PI).sqrt(),
    })
}

/// The planes a sensor mounted at `nominal` would see at `body_poses`,
/// exactly.
fn exact_observations(body_poses: &[PoseParams], nominal: &PoseParams) -> Vec<Observation> {
    body_poses
        .iter()
        .enumerate()
        .map(|(i, pose)| exact_observation(i as u32 + 1, pose.to_transform(), nominal))
        .collect()
}

/// The solve's settings for a prediction: the model's noise, not the
/// residuals' (they are zero).
fn prediction_settings(noise: &NoiseModel, depth_scale: DepthScaleSetting) -> SolveSettings {
    SolveSettings {
        depth_scale,
        noise_from_residuals: false,
        ..noise.solve_settings()
    }
}

/// The covariance of `[α, β, γ, px, py, pz]` (radians, metres) a
/// calibration over `body_poses` will have when it finds a depth pattern
/// and estimates its plane part (a constant and two gradients of the raw
/// values) with the mount: the prediction's, plus what the plane part costs.
/// Only the spread of the poses' heights and tilts pins that part
/// (docs/method.md, "What pins each part"), so schedules that predict the
/// same σ without a pattern can differ by two with one. `None` when the
/// plane part is not observable at all.
pub fn predict_with_depth_pattern(
    body_poses: &[PoseParams],
    nominal: &PoseParams,
    noise: &NoiseModel,
    depth_scale: DepthScaleSetting,
) -> Result<Option<Matrix6<f64>>, SolveError> {
    let observations = exact_observations(body_poses, nominal);
    let settings = prediction_settings(noise, depth_scale);
    let per_pose = (
        noise.normal_sigma_deg.to_radians(),
        noise.offset_sigma_mm * 1e-3,
    );
    let (_, with) =
        crate::distortion::covariance_with_plane_part(&observations, &settings, per_pose)?;
    Ok(with)
}

/// Chooses `count` of `candidates` (commanded body poses) whose predicted
/// σ are smallest against `reference` (one σ per parameter, in radians and
/// metres: the configured schedule's, or the gates'): the mean of
/// (σᵢ / referenceᵢ)² is minimised.
///
/// Backward elimination from every candidate (the pose whose loss costs
/// least goes first), then exchange passes (a chosen pose swapped for an
/// unchosen one while that helps). Deterministic: the same input gives the
/// same choice. Returns the chosen indices into `candidates`, in candidate
/// order, and the largest ratio σᵢ / referenceᵢ.
pub fn design(
    candidates: &[PoseParams],
    count: usize,
    nominal: &PoseParams,
    noise: &NoiseModel,
    reference: &[f64; 6],
) -> Option<(Vec<usize>, f64)> {
    if count < 3 || count > candidates.len() {
        return None;
    }
    let objective = |chosen: &[usize]| -> f64 {
        let poses: Vec<PoseParams> = chosen.iter().map(|&i| candidates[i]).collect();
        match predict_schedule(&poses, nominal, noise) {
            // The mean of the squared ratios (A-optimal, each parameter in
            // units of its reference): smooth, so the search does not stall
            // on whichever parameter is worst at the moment.
            Ok(p) if p.observability.problems.is_empty() => {
                (0..6)
                    .map(|i| p.covariance[(i, i)].max(0.0) / reference[i].powi(2))
                    .sum::<f64>()
                    / 6.0
            }
            _ => f64::INFINITY,
        }
    };
    let mut chosen: Vec<usize> = (0..candidates.len()).collect();
    while chosen.len() > count {
        let mut best: Option<(usize, f64)> = None;
        for k in 0..chosen.len() {
            let mut without = chosen.clone();
            without.remove(k);
            let value = objective(&without);
            if best.is_none_or(|(_, b)| value < b) {
                best = Some((k, value));
            }
        }
        let (k, _) = best?;
        chosen.remove(k);
    }
    let mut value = objective(&chosen);
    for _pass in 0..4 {
        let mut improved = false;
        for slot in 0..chosen.len() {
            for candidate in 0..candidates.len() {
                if chosen.contains(&candidate) {
                    continue;
                }
                let mut trial = chosen.clone();
                trial[slot] = candidate;
                let trial_value = objective(&trial);
                if trial_value < value * (1.0 - 1e-9) {
                    chosen = trial;
                    value = trial_value;
                    improved = true;
                }
            }
        }
        if !improved {
            break;
        }
    }
    chosen.sort_unstable();
    if !value.is_finite() {
        return None;
    }
    let poses: Vec<PoseParams> = chosen.iter().map(|&i| candidates[i]).collect();
    let prediction = predict_schedule(&poses, nominal, noise).ok()?;
    let sigma = prediction.sigma();
    let worst = (0..6).map(|i| sigma[i] / reference[i]).fold(0.0, f64::max);
    Some((chosen, worst))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Transform;
    use crate::solve::predict;
    use nalgebra::Vector3;

    fn mount() -> PoseParams {
        PoseParams::new(
            0.8f64.to_radians(),
            (-33.0f64).to_radians(),
            1.5f64.to_radians(),
            Vector3::new(0.510, 0.370, 0.015),
        )
    }

    fn schedule() -> Vec<PoseParams> {
        (0..24)
            .map(|k| {
                let k = k as f64;
                PoseParams::new(
                    (4.0 * (k * 0.9).sin()).to_radians(),
                    (15.0 * (k * 0.7).cos()).to_radians(),
                    (15.0 * (k * 1.3).sin()).to_radians(),
                    Vector3::new(0.0, 0.6 + 0.05 * (k * 0.5).sin(), 0.0),
                )
            })
            .collect()
    }

    /// A seeded noise source (xorshift and Box-Muller): the test is the
    /// same on every machine.
    struct Gauss(u64);
    impl Gauss {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn next(&mut self) -> f64 {
            let (u, v) = (self.uniform(), self.uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
    }

    /// The predicted σ match the spread of 300 solves on planes with that
    /// noise added, parameter by parameter, within 15 %.
    #[test]
    fn predicted_sigma_match_the_spread_of_noisy_solves() {
        let noise = NoiseModel {
            normal_sigma_deg: 0.05,
            offset_sigma_mm: 0.5,
        };
        let truth = mount();
        let prediction = predict_schedule(&schedule(), &truth, &noise).unwrap();
        let mut gauss = Gauss(0x9E37_79B9_7F4A_7C15);
        let runs = 300;
        let mut squares = [0.0f64; 6];
        for _ in 0..runs {
            let observations: Vec<Observation> = schedule()
                .iter()
                .enumerate()
                .map(|(i, pose)| {
                    let ground_from_robot: Transform = pose.to_transform();
                    let mut plane = predict(&truth, &ground_from_robot);
                    let n = plane.normal;
                    let helper = if n.x.abs() < 0.9 {
                        nalgebra::Vector3::x()
                    } else {
                        nalgebra::Vector3::y()
                    };
                    let e1 = n.cross(&helper).normalize();
                    let e2 = n.cross(&e1);
                    let s = noise.normal_sigma_deg.to_radians();
                    plane.normal =
                        (n + e1 * (s * gauss.next()) + e2 * (s * gauss.next())).normalize();
                    plane.d += noise.offset_sigma_mm / 1000.0 * gauss.next();
                    Observation::new(i as u32 + 1, ground_from_robot, plane)
                })
                .collect();
            let settings = SolveSettings {
                normal_sigma_floor: noise.normal_sigma_deg.to_radians(),
                offset_sigma_floor: noise.offset_sigma_mm / 1000.0,
                max_outlier_fraction: 0.0,
                ..SolveSettings::default()
            };
            let solved = solve(&observations, &settings).unwrap().robot_from_sensor;
            let error = [
                solved.alpha - truth.alpha,
                solved.beta - truth.beta,
                solved.gamma - truth.gamma,
                solved.translation.x - truth.translation.x,
                solved.translation.y - truth.translation.y,
                solved.translation.z - truth.translation.z,
            ];
            for (square, e) in squares.iter_mut().zip(error) {
                *square += e * e / runs as f64;
            }
        }
        let predicted = prediction.sigma_deg_mm();
        for i in 0..6 {
            let achieved = if i < 3 {
                squares[i].sqrt().to_degrees()
            } else {
                squares[i].sqrt() * 1000.0
            };
            let ratio = achieved / predicted[i];
            assert!(
                (0.85..=1.15).contains(&ratio),
                "parameter {i}: achieved RMS {achieved} against predicted σ {} ({ratio:.3}×)",
                predicted[i]
            );
        }
    }

    #[test]
    fn a_schedule_that_never_tilts_cannot_observe_alpha() {
        let level: Vec<PoseParams> = schedule()
            .iter()
            .map(|p| PoseParams::new(p.alpha, 0.0, 0.0, p.translation))
            .collect();
        let prediction = predict_schedule(&level, &mount(), &NoiseModel::solve_floors()).unwrap();
        assert!(
            !prediction.observability.problems.is_empty(),
            "{:?}",
            prediction.observability
        );
    }
}
