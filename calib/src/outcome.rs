//! What a calibration found: the outcome of each pose, the observability of
//! the six parameters, the solver's solution and the verdict on it. Shared by
//! [`crate::solve`] (which finds) and [`crate::quality`] (which judges), so
//! that neither depends on the other.

use nalgebra::{Matrix6, Vector6};

use crate::geometry::{Plane, PoseParams};

/// Verdict of a calibration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Accepted,
    Rejected,
}

/// What happened to one observation.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseOutcome {
    pub index: u32,
    pub used: bool,
    pub reason: Option<String>,
    /// The ground as measured, in the sensor frame.
    pub measured: Plane,
    /// The ground as the result predicts it.
    pub predicted: Plane,
    /// Angle between measured and predicted normals (paper's θ), radians.
    pub theta: f64,
    /// `|d_T - d_M|` (paper's e_d), metres.
    pub e_d: f64,
    pub inliers: Option<usize>,
    /// The observation's note (a slipped foot left out), if any.
    pub note: Option<String>,
}

/// How well the schedule pins down each direction.
#[derive(Debug, Clone, PartialEq)]
pub struct Observability {
    /// Singular values of the rotation block of the Jacobian per observation
    /// (unit noise), largest first: the RMS spread of the ground normals seen
    /// from each rotation axis.
    pub rotation_singular_values: [f64; 3],
    /// The same for the translation block.
    pub translation_singular_values: [f64; 3],
    /// Operator-readable descriptions of unobservable directions.
    pub problems: Vec<String>,
}

/// The result of a calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    pub verdict: Verdict,
    pub reasons: Vec<String>,
    pub robot_from_sensor: PoseParams,
    /// Covariance of `[α, β, γ, px, py, pz]` (radians, metres).
    pub covariance: Matrix6<f64>,
    pub poses: Vec<PoseOutcome>,
    pub summary: Summary,
    pub observability: Observability,
    /// Estimated noise relative to the assumed one: normals, offsets.
    pub variance_factors: (f64, f64),
    /// Levenberg-Marquardt's evaluations and termination.
    pub iterations: usize,
}

impl Calibration {
    /// One standard deviation of each parameter (radians, metres).
    pub fn sigma(&self) -> Vector6<f64> {
        sigma_of(&self.covariance)
    }

    /// Correlation coefficients of the parameters.
    pub fn correlations(&self) -> Matrix6<f64> {
        let s = self.sigma();
        Matrix6::from_fn(|i, j| {
            if s[i] > 0.0 && s[j] > 0.0 {
                self.covariance[(i, j)] / (s[i] * s[j])
            } else if i == j {
                1.0
            } else {
                0.0
            }
        })
    }
}

/// Mean and maximum of θ and e_d over the used poses (the paper's Figs. 17-18).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Summary {
    pub poses_total: usize,
    pub poses_used: usize,
    /// Radians.
    pub theta_mean: f64,
    pub theta_max: f64,
    /// Metres.
    pub e_d_mean: f64,
    pub e_d_max: f64,
}

/// What the solve found, before anyone judges it.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    pub robot_from_sensor: PoseParams,
    /// Covariance of `[α, β, γ, px, py, pz]` (radians, metres).
    pub covariance: Matrix6<f64>,
    pub poses: Vec<PoseOutcome>,
    pub observability: Observability,
    /// Estimated noise relative to the assumed one: normals, offsets.
    pub variance_factors: (f64, f64),
    /// Levenberg-Marquardt's evaluations.
    pub iterations: usize,
}

impl Solution {
    /// One standard deviation of each parameter (radians, metres).
    pub fn sigma(&self) -> Vector6<f64> {
        sigma_of(&self.covariance)
    }
}

fn sigma_of(covariance: &Matrix6<f64>) -> Vector6<f64> {
    Vector6::from_fn(|i, _| covariance[(i, i)].max(0.0).sqrt())
}
