//! Identification of `robot_from_sensor` (paper section 4.3).
//!
//! Each observation pairs the real body pose `ground_from_robot` (from the feet)
//! with the ground measured in the sensor frame. The result predicts that plane
//! as row 1 of `ground_from_robot · robot_from_sensor` (paper eq. 28); the paper
//! minimises the squared differences (eq. 31) by Levenberg-Marquardt.
//!
//! The steps here:
//! 1. a closed-form start that needs no guess: the rotation from the normals by
//!    SVD (Wahba's problem), the translation by linear least squares;
//! 2. observations that disagree with all the others (leave-one-out prediction
//!    far beyond the rest) are set aside with their reason, one at a time;
//! 3. Levenberg-Marquardt on the paper's residual, each observation whitened by
//!    its plane covariance plus a noise floor;
//! 4. covariance of the six parameters, with the noise level estimated from
//!    the residuals; observability from the Jacobian's singular values.
//!
//! The normal's residual depends on the rotation only and the offset's on the
//! translation only (eq. 31), so the two blocks have separate variance factors.
//!
//! Here: the steps and the Levenberg-Marquardt problem; step 2 in
//! [`outliers`], the depth scale solved with the translation in [`scale`],
//! step 4's observability in [`observability`].

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{
    storage::Owned, DMatrix, DVector, Dyn, Matrix2, Matrix3, Matrix4, Matrix6, OMatrix,
    SymmetricEigen, Vector3, Vector6, U6,
};

use super::geometry::{
    angle_between, d_rot_x, d_rot_y, d_rot_z, ground_in_sensor, rot_x, rot_y, rot_z, Plane,
    PoseParams, Transform,
};
use crate::outcome::{position_axis_words, DepthScale, Observability, PoseOutcome, Solution};

mod jackknife;
mod observability;
mod outliers;
mod scale;
pub use observability::*;
use outliers::*;
use scale::*;

/// One pose's evidence.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// The pose's number in the schedule (1-based).
    pub index: u32,
    /// The real body pose, from the feet.
    pub ground_from_robot: Transform,
    /// The ground measured in the sensor frame.
    pub plane: Plane,
    /// Covariance of `(a, b, c, d)` from the plane fit, if known.
    pub plane_covariance: Option<Matrix4<f64>>,
    /// Points that supported the plane, if known.
    pub inliers: Option<usize>,
    /// Set aside before solving (feet that do not fix the pose, a failed
    /// fit), with why.
    pub set_aside: Option<String>,
    /// What the operator should know of a pose that is used: a slipped foot
    /// left out of its body pose.
    pub note: Option<String>,
    /// The plane fit's residuals per cell of the image, for the depth
    /// pattern ([`crate::distortion`]), if the frames were at hand.
    pub ground_residuals: Option<std::sync::Arc<crate::residuals::GroundResiduals>>,
}

impl Observation {
    /// An observation with no covariance and nothing set aside.
    pub fn new(index: u32, ground_from_robot: Transform, plane: Plane) -> Self {
        Self {
            index,
            ground_from_robot,
            plane,
            plane_covariance: None,
            inliers: None,
            set_aside: None,
            note: None,
            ground_residuals: None,
        }
    }

    /// The ground's normal in the robot frame: row 1 of `ground_from_robot`'s
    /// rotation. The sensor sees `robot_from_sensorᵀ` of it.
    fn up_in_robot(&self) -> Vector3<f64> {
        let r = self.ground_from_robot.rotation.matrix();
        Vector3::new(r[(1, 0)], r[(1, 1)], r[(1, 2)])
    }

    /// The body's height term `a24` of eq. 28.
    fn body_height(&self) -> f64 {
        self.ground_from_robot.translation.vector.y
    }
}

/// Tuning of the solve. Angles in radians, lengths in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveSettings {
    /// Noise floor of a measured normal, per tangent direction: what a plane fit
    /// cannot see (depth model, body pose from the feet, unevenness).
    pub normal_sigma_floor: f64,
    /// Noise floor of a measured offset `d`.
    pub offset_sigma_floor: f64,
    /// An observation whose leave-one-out error exceeds `k` robust scales of the
    /// others' (and the floors below) is set aside.
    pub outlier_k: f64,
    pub outlier_angle_floor: f64,
    pub outlier_offset_floor: f64,
    /// At most this fraction of the observations is set aside as outliers.
    pub max_outlier_fraction: f64,
    /// A direction whose normalised singular value is below this is unobservable
    /// (about the sine of the RMS spread of the tilts in that direction).
    pub min_spread: f64,
    /// Whether the depth scale is estimated with the mount, or taken as known.
    pub depth_scale: DepthScaleSetting,
    /// Whether the noise level comes from the residuals when there are
    /// enough of them ([`MIN_EVIDENCE_DOF`]), or is the assumed one (the
    /// floors) at least: a prediction before moving has no residuals.
    pub noise_from_residuals: bool,
}

/// The Kinect's depth scale `s` (its depth reads `s` × the truth, so every
/// measured plane's `d` is `s` × the true one and its normal is unchanged):
/// estimated, when the body's heights observe it, or taken as known.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DepthScaleSetting {
    /// Estimated when the poses observe it; else `fallback` (1 if unknown).
    Estimate { fallback: f64 },
    /// Known (from an earlier calibration or the sensor's own data).
    Fixed(f64),
}

impl Default for DepthScaleSetting {
    fn default() -> Self {
        DepthScaleSetting::Estimate { fallback: 1.0 }
    }
}

/// The depth scale is estimated only when the poses pin it down to this
/// (one σ): looser, its estimate would cost the translation much accuracy
/// (they correlate) and correct the depth by less than its own error. A
/// Kinect's scale is off by up to about 1 %.
pub const MAX_SCALE_SIGMA: f64 = 0.001;

/// A depth scale too loosely pinned to be estimated, which the poses put
/// this many of its σ from the scale taken, rejects the calibration
/// ([`crate::quality`]): the scale taken is what they rule out, and its
/// error moves the position by all of it (10.7 mm of py for 1 % on
/// designed-52) under σ that count it as known. Under the simulator's
/// held Kinect noise, a scale 1 % long put py 10.3-10.6 mm off against σ
/// of 0.35 mm, 3.6-6.1 of the scale's σ from 1 (docs/method.md). Not
/// estimated instead: so loosely pinned, its σ put the position's beyond
/// the 2 mm gate in 3 of those 4 runs anyway, and in the pattern's
/// intermediate solves an uncorrected pattern looks like a scale.
pub const SCALE_CONTRADICTED_SIGMAS: f64 = 3.0;

/// The distances of the poses must vary by at least this much (metres, RMS)
/// beyond what their tilts explain for the depth scale to be estimated: the
/// body's height must change. Tilts alone observe it only through the
/// cosine of their angles, which model errors (feet, an uneven ground) would
/// bias. The paper's schedule gives 34 mm, the same tilts at one height
/// 9 mm, the 16-pose designed schedule 90 mm.
pub const MIN_SCALE_LEVERAGE: f64 = 0.025;

impl Default for SolveSettings {
    fn default() -> Self {
        Self {
            normal_sigma_floor: 0.05f64.to_radians(),
            offset_sigma_floor: 0.0005,
            outlier_k: 6.0,
            outlier_angle_floor: 1.0f64.to_radians(),
            outlier_offset_floor: 0.015,
            max_outlier_fraction: 0.3,
            min_spread: 1.0f64.to_radians().sin(),
            noise_from_residuals: true,
            depth_scale: DepthScaleSetting::default(),
        }
    }
}

/// Why there is no result at all.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("only {usable} usable poses, at least 3 are needed to solve (and many more to trust the result)")]
    TooFewObservations {
        usable: usize,
        outcomes: Vec<PoseOutcome>,
    },
}

/// Whitening of one observation's residuals.
#[derive(Debug, Clone, Copy)]
struct Weights {
    /// Orthonormal basis of the measured normal's tangent plane (columns).
    tangent: nalgebra::Matrix3x2<f64>,
    /// Inverse Cholesky factor of the tangent covariance.
    normal_whitener: Matrix2<f64>,
    /// 1/σ of the offset.
    offset_whitener: f64,
}

/// An orthonormal basis of the plane normal to `n` (a unit vector): the
/// directions in which a measured normal can be wrong.
pub(crate) fn tangent_basis(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = n.cross(&helper).normalize();
    let e2 = n.cross(&e1);
    (e1, e2)
}

impl Weights {
    fn of(obs: &Observation, settings: &SolveSettings) -> Self {
        let (e1, e2) = tangent_basis(&obs.plane.normal);
        let tangent = nalgebra::Matrix3x2::from_columns(&[e1, e2]);
        let floor_n = settings.normal_sigma_floor.powi(2);
        let floor_d = settings.offset_sigma_floor.powi(2);
        let (cov_t, var_d) = match obs.plane_covariance {
            Some(c) => {
                let cn = c.fixed_view::<3, 3>(0, 0).into_owned();
                (
                    tangent.transpose() * cn * tangent + Matrix2::identity() * floor_n,
                    c[(3, 3)] + floor_d,
                )
            }
            None => (Matrix2::identity() * floor_n, floor_d),
        };
        let normal_whitener = cov_t
            .cholesky()
            .and_then(|ch| ch.l().try_inverse())
            .unwrap_or_else(|| Matrix2::identity() / settings.normal_sigma_floor);
        Self {
            tangent,
            normal_whitener,
            offset_whitener: 1.0 / var_d.sqrt(),
        }
    }

    /// A scalar weight for the closed form (mean inverse variance of the normal).
    fn normal_weight(&self) -> f64 {
        self.normal_whitener.norm_squared() / 2.0
    }
}

/// The ground the parameters predict for an observation.
pub fn predict(robot_from_sensor: &PoseParams, ground_from_robot: &Transform) -> Plane {
    ground_in_sensor(&(ground_from_robot * robot_from_sensor.to_transform()))
}

/// The observation a sensor at `robot_from_sensor` makes at a body pose,
/// exactly: the predicted plane, with a (zero) fit covariance, so that a
/// solve of such observations takes its noise from its settings (a
/// prediction's, or a schedule's cost judged apart from the noise met).
pub fn exact_observation(
    index: u32,
    ground_from_robot: Transform,
    robot_from_sensor: &PoseParams,
) -> Observation {
    let plane = predict(robot_from_sensor, &ground_from_robot);
    let mut observation = Observation::new(index, ground_from_robot, plane);
    observation.plane_covariance = Some(Matrix4::zeros());
    observation
}

/// The least-squares problem of eq. 31, whitened, for the `levenberg-marquardt` crate.
struct IdentificationProblem<'a> {
    observations: Vec<&'a Observation>,
    weights: Vec<Weights>,
    /// Robust (Cauchy) weights of each observation's normal and offset.
    robust: Vec<(f64, f64)>,
    params: Vector6<f64>,
}

impl IdentificationProblem<'_> {
    fn residual_count(&self) -> usize {
        3 * self.observations.len()
    }

    fn residual_vector(&self) -> DVector<f64> {
        let pose = PoseParams::from_vector(&self.params);
        let rotation = pose.rotation_matrix();
        let mut r = DVector::zeros(self.residual_count());
        for (k, (obs, w)) in self.observations.iter().zip(&self.weights).enumerate() {
            let (rn, rd) = self.robust[k];
            let up = obs.up_in_robot();
            let predicted_normal = rotation.transpose() * up;
            let diff =
                w.normal_whitener * (w.tangent.transpose() * (predicted_normal - obs.plane.normal));
            let predicted_d = up.dot(&pose.translation) + obs.body_height();
            r[3 * k] = diff[0] * rn.sqrt();
            r[3 * k + 1] = diff[1] * rn.sqrt();
            r[3 * k + 2] = (predicted_d - obs.plane.d) * w.offset_whitener * rd.sqrt();
        }
        r
    }

    fn jacobian_matrix(&self) -> DMatrix<f64> {
        let p = &self.params;
        let (ry, rz, rx) = (rot_y(p[0]), rot_z(p[1]), rot_x(p[2]));
        let d_rotation = [
            d_rot_y(p[0]) * rz * rx,
            ry * d_rot_z(p[1]) * rx,
            ry * rz * d_rot_x(p[2]),
        ];
        let mut j = DMatrix::zeros(self.residual_count(), 6);
        for (k, (obs, w)) in self.observations.iter().zip(&self.weights).enumerate() {
            let (rn, rd) = self.robust[k];
            let up = obs.up_in_robot();
            for (col, dr) in d_rotation.iter().enumerate() {
                let d_normal = dr.transpose() * up;
                let d = w.normal_whitener * (w.tangent.transpose() * d_normal) * rn.sqrt();
                j[(3 * k, col)] = d[0];
                j[(3 * k + 1, col)] = d[1];
            }
            for axis in 0..3 {
                j[(3 * k + 2, 3 + axis)] = up[axis] * w.offset_whitener * rd.sqrt();
            }
        }
        j
    }
}

impl LeastSquaresProblem<f64, Dyn, U6> for IdentificationProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, U6>;
    type ParameterStorage = Owned<f64, U6>;

    fn set_params(&mut self, x: &Vector6<f64>) {
        self.params = *x;
    }

    fn params(&self) -> Vector6<f64> {
        self.params
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        Some(self.residual_vector())
    }

    fn jacobian(&self) -> Option<OMatrix<f64, Dyn, U6>> {
        let j = self.jacobian_matrix();
        Some(OMatrix::<f64, Dyn, U6>::from_fn(j.nrows(), |r, c| {
            j[(r, c)]
        }))
    }
}

/// The closed-form estimate from the chosen observations: rotation by SVD of
/// the normals' correlation (Wahba), translation by least squares on `d`.
pub fn closed_form(observations: &[&Observation], settings: &SolveSettings) -> PoseParams {
    let mut correlation = Matrix3::zeros();
    let mut normal_eq = Matrix3::zeros();
    let mut rhs = Vector3::zeros();
    for obs in observations {
        let w = Weights::of(obs, settings);
        let up = obs.up_in_robot();
        // up ≈ R · n_sensor for R = robot_from_sensor's rotation.
        correlation += up * obs.plane.normal.transpose() * w.normal_weight();
        let wd = w.offset_whitener.powi(2);
        normal_eq += up * up.transpose() * wd;
        rhs += up * ((obs.plane.d - obs.body_height()) * wd);
    }
    let svd = correlation.svd(true, true);
    let rotation = match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => {
            let sign = (u * v_t).determinant().signum();
            u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, sign)) * v_t
        }
        _ => Matrix3::identity(),
    };
    // A pseudo-inverse keeps an unobservable direction at zero instead of failing.
    let translation = normal_eq
        .svd(true, true)
        .solve(&rhs, 1e-9 * normal_eq.norm().max(1e-300))
        .unwrap_or_default();
    PoseParams::from_rotation_translation(&rotation, translation)
}

/// Identifies `robot_from_sensor` from the observations: what it found, with
/// its covariance and observability, and the depth scale. Whether that is
/// good enough is for [`crate::quality`] to say.
///
/// The depth scale enters the offsets only: a measured `d` is `s` times
/// `up · p + h`, so with `q = 1/s` the offset block `up · p − q·d + h = 0` is
/// linear in `(p, q)`. The six parameters are solved on the distances
/// divided by the current `s`; then `(p, q)` by weighted least squares with
/// the solve's final weights gives the next `s`, until it settles (a few
/// rounds). The translation's covariance is then the joint one's marginal:
/// estimating `s` costs translation accuracy, as it correlates with it.
pub fn solve(
    observations: &[Observation],
    settings: &SolveSettings,
) -> Result<Solution, SolveError> {
    let mut solution = solve_with_scale(observations, settings)?;
    if !solution.depth_scale.estimated {
        position_by_the_poses(&mut solution, observations, settings);
    }
    Ok(solution)
}

/// [`solve`]'s mount and depth scale, with the position's covariance by
/// the formula only (no pose left out): for a caller that reads the
/// estimate and not its σ. The pattern's plane part differentiates the
/// mount by its three values, four solves a step, and leaving each pose
/// out was a third of each solve's time.
pub fn solve_estimate(
    observations: &[Observation],
    settings: &SolveSettings,
) -> Result<Solution, SolveError> {
    solve_with_scale(observations, settings)
}

/// The position's covariance by leaving each pose out ([`jackknife`]),
/// once the poses are enough to say: the formula's holds only when the
/// weights match each pose's noise, which a Kinect's held noise does not
/// let them. Never below the plane fits' own share, when they have one.
/// Made once, for the solution returned (a scale estimated has the joint
/// fit's own, [`scale::scale_fit`]).
fn position_by_the_poses(
    solution: &mut Solution,
    observations: &[Observation],
    settings: &SolveSettings,
) {
    if !settings.noise_from_residuals {
        return;
    }
    // The poses as the solution was solved: at its depth scale.
    let scaled = at_scale(observations, solution.depth_scale.value);
    let used: Vec<&Observation> = scaled
        .iter()
        .filter(|o| solution.poses.iter().any(|p| p.index == o.index && p.used))
        .collect();
    let Some(by_poses) = jackknife::position_covariance(&used, settings) else {
        return;
    };
    let formula = solution.covariance.fixed_view::<3, 3>(3, 3).into_owned();
    let position = not_below_the_fits(
        &by_poses,
        &formula,
        solution.variance_factors.1,
        &used,
        settings,
    );
    solution
        .covariance
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&position);
}

/// A covariance the poses gave (the jackknife's), never below the plane
/// fits' own share of the formula's (`formula`, made with the offsets'
/// variance factor `factor`), when the planes carry a fit covariance: the
/// poses cannot be less noisy than their pixels.
fn not_below_the_fits<const N: usize>(
    by_poses: &nalgebra::SMatrix<f64, N, N>,
    formula: &nalgebra::SMatrix<f64, N, N>,
    factor: f64,
    used: &[&Observation],
    settings: &SolveSettings,
) -> nalgebra::SMatrix<f64, N, N> {
    if !used.iter().all(|o| o.plane_covariance.is_some()) {
        return *by_poses;
    }
    let fit_share = assumed_noise(used, settings).fit_share.1;
    jackknife::at_least(by_poses, &(formula * (fit_share / factor).min(1.0)))
}

/// Why a scale the poses found is not taken when their joint fit gave no
/// covariance to judge it by.
const SCALE_COVARIANCE_FAILED: &str = "not estimated: the joint fit of the scale with the position gave no covariance (a numerical failure), so how well these poses pin the scale is unknown; giving a known scale avoids it";

/// The six parameters and the depth scale (the position's covariance by
/// the formula).
fn solve_with_scale(
    observations: &[Observation],
    settings: &SolveSettings,
) -> Result<Solution, SolveError> {
    let (mut scale, estimate) = match settings.depth_scale {
        DepthScaleSetting::Fixed(s) => (s, false),
        DepthScaleSetting::Estimate { fallback } => (fallback, true),
    };
    let mut solution = solve_at_scale(observations, settings, scale)?;
    if !estimate {
        solution.depth_scale = DepthScale::fixed(scale, "given".into());
        return Ok(solution);
    }
    for _ in 0..6 {
        let used: Vec<&Observation> = observations
            .iter()
            .filter(|o| solution.poses.iter().any(|p| p.index == o.index && p.used))
            .collect();
        let Some(joint) = scale_fit(&used, settings, scale) else {
            break;
        };
        let unobserved = (joint.leverage < MIN_SCALE_LEVERAGE).then(|| {
            format!(
                "not estimated: the poses' distances vary by {:.0} mm beyond what their tilts explain, less than the {:.0} mm that observe it (change the body's height more)",
                joint.leverage * 1e3,
                MIN_SCALE_LEVERAGE * 1e3
            )
        });
        if let Some(note) = unobserved {
            // Not observed well enough: solve at the fallback.
            if scale != solve_fallback(settings) {
                scale = solve_fallback(settings);
                solution = solve_at_scale(observations, settings, scale)?;
            }
            solution.depth_scale = DepthScale::fixed(scale, note);
            return Ok(solution);
        }
        if !(joint.scale_ratio.is_finite() && joint.scale_ratio > 0.0) {
            break;
        }
        let next = scale * joint.scale_ratio;
        let settled = (next / scale - 1.0).abs() < 1e-9;
        scale = next;
        if !settled {
            solution = solve_at_scale(observations, settings, scale)?;
        }
        if settled {
            // The translation's marginal covariance, and the scale's σ,
            // from the joint fit: by leaving each pose out when the poses
            // are enough to say (as the position's alone, `jackknife`),
            // else the formula's with the offsets' variance factor.
            let formula = joint.covariance * solution.variance_factors.1;
            let joint_covariance = match &joint.jackknife {
                Some(by_poses) if jackknife_applies(used.len(), 4, settings) => not_below_the_fits(
                    by_poses,
                    &formula,
                    solution.variance_factors.1,
                    &used,
                    settings,
                ),
                _ => formula,
            };
            for i in 0..3 {
                for j in 0..3 {
                    solution.covariance[(3 + i, 3 + j)] = joint_covariance[(i, j)];
                }
            }
            // s = scale/q with q ≈ 1 here: σ_s = scale·σ_q. Judged here, at
            // the settled scale: before, the residuals still hold the scale's
            // own error and overstate the noise.
            let sigma = scale * crate::outcome::sigma_of_variance(joint_covariance[(3, 3)]);
            if sigma.is_nan() {
                // Nothing known of how well the poses pin it: not estimated,
                // and no σ claimed.
                let fallback = solve_fallback(settings);
                let mut fallen = solve_at_scale(observations, settings, fallback)?;
                fallen.depth_scale = DepthScale::fixed(fallback, SCALE_COVARIANCE_FAILED.into());
                return Ok(fallen);
            }
            if sigma > MAX_SCALE_SIGMA {
                let fallback = solve_fallback(settings);
                let mut fallen = solve_at_scale(observations, settings, fallback)?;
                fallen.depth_scale = DepthScale::fixed(
                    fallback,
                    format!(
                        "not estimated: these poses pin it down only to ±{:.2}% (one σ, at the noise the residuals show, or the assumed noise when there are too few of them), too loosely to correct the depth (±{:.2}% would); more poses or larger height changes would, and so would giving a known scale",
                        sigma * 100.0,
                        MAX_SCALE_SIGMA * 100.0
                    ),
                );
                fallen.depth_scale.loose_estimate = Some((scale, sigma));
                return Ok(fallen);
            }
            let translation_sigma: Vec<f64> = (0..3)
                .map(|i| crate::outcome::sigma_of_variance(joint_covariance[(i, i)]))
                .collect();
            let q_sigma = crate::outcome::sigma_of_variance(joint_covariance[(3, 3)]);
            // Correlation of s with each parameter (q and s anticorrelate).
            let mut correlations = [0.0; 6];
            for i in 0..3 {
                let c = joint_covariance[(i, 3)];
                correlations[3 + i] = if translation_sigma[i] > 0.0 && q_sigma > 0.0 {
                    -c / (translation_sigma[i] * q_sigma)
                } else {
                    0.0
                };
            }
            solution.depth_scale = DepthScale {
                value: scale,
                sigma: Some(sigma),
                estimated: true,
                correlations,
                note: None,
                loose_estimate: None,
            };
            return Ok(solution);
        }
    }
    solution.depth_scale = DepthScale::fixed(scale, "the estimate did not settle".into());
    Ok(solution)
}

/// The six parameters from the observations as they are.
fn solve_six(
    observations: &[Observation],
    settings: &SolveSettings,
) -> Result<Solution, SolveError> {
    let mut set_aside: Vec<Option<String>> =
        observations.iter().map(|o| o.set_aside.clone()).collect();
    let candidates = set_aside.iter().filter(|s| s.is_none()).count();
    let max_outliers = (settings.max_outlier_fraction * candidates as f64).floor() as usize;
    let mut outliers = 0;
    while outliers < max_outliers {
        let used: Vec<(usize, &Observation)> = observations
            .iter()
            .enumerate()
            .filter(|(k, _)| set_aside[*k].is_none())
            .collect();
        let used_refs: Vec<&Observation> = used.iter().map(|(_, o)| *o).collect();
        let Some((index, reason)) = worst_outlier(&used_refs, settings) else {
            break;
        };
        let Some((k, _)) = used.iter().find(|(_, o)| o.index == index) else {
            break;
        };
        set_aside[*k] = Some(reason);
        outliers += 1;
    }

    let used: Vec<&Observation> = observations
        .iter()
        .zip(&set_aside)
        .filter(|(_, s)| s.is_none())
        .map(|(o, _)| o)
        .collect();
    if used.len() < 3 {
        let start = PoseParams::identity();
        let outcomes = outcomes(observations, &set_aside, &start);
        return Err(SolveError::TooFewObservations {
            usable: used.len(),
            outcomes,
        });
    }

    let start = closed_form(&used, settings);
    let (robot_from_sensor, problem, evaluations) = refine(&used, start, settings);

    // Variance factors of the two independent blocks, from the residuals
    // (robustly weighted; with unit weights these are χ²/dof).
    let residuals = problem.residual_vector();
    let chi2_normals: f64 = (0..used.len())
        .map(|k| residuals[3 * k].powi(2) + residuals[3 * k + 1].powi(2))
        .sum();
    let chi2_offsets: f64 = (0..used.len()).map(|k| residuals[3 * k + 2].powi(2)).sum();
    let weight_normals: f64 = problem.robust.iter().map(|w| w.0).sum();
    let weight_offsets: f64 = problem.robust.iter().map(|w| w.1).sum();
    let with_fit_covariance = used.iter().all(|o| o.plane_covariance.is_some());
    // The noise is what the residuals show (χ²/dof), once there are enough
    // of them to say: the assumed noise (the floors, or a configured
    // [calibration.noise]) then sets only the relative weights, so a real
    // robot's calibration is as sure as its evidence, not as its guess. The
    // plane fits' own covariance stays a lower bound: the poses cannot be
    // less noisy than their pixels. With fewer residuals than that, the
    // assumed noise is a floor: a short schedule cannot vouch for itself.
    let assumed = assumed_noise(&used, settings);
    let (floor_normals, floor_offsets) = assumed.fit_share;
    let factor = |chi2: f64, dof: f64, fit_share: f64| {
        if dof <= 0.0 {
            1.0
        } else if !with_fit_covariance {
            // Without it the floors only set the relative weights: the level is estimated.
            (chi2 / dof).max(1e-12)
        } else if settings.noise_from_residuals && dof >= MIN_EVIDENCE_DOF {
            (chi2 / dof).max(fit_share)
        } else {
            (chi2 / dof).max(1.0)
        }
    };
    let variance_factors = (
        factor(chi2_normals, 2.0 * weight_normals - 3.0, floor_normals),
        factor(chi2_offsets, weight_offsets - 3.0, floor_offsets),
    );

    let jacobian = problem.jacobian_matrix();
    let information = jacobian.transpose() * &jacobian;
    let mut covariance = Matrix6::zeros();
    for (block, factor) in [(0usize, variance_factors.0), (3, variance_factors.1)] {
        let h = information.view((block, block), (3, 3)).into_owned();
        let h3 = Matrix3::from_fn(|i, j| h[(i, j)]);
        let inverse = h3
            .try_inverse()
            .unwrap_or_else(|| Matrix3::from_diagonal_element(f64::INFINITY));
        covariance
            .fixed_view_mut::<3, 3>(block, block)
            .copy_from(&(inverse * factor));
    }

    let observability = observability(&used, settings);
    let outcomes = outcomes(observations, &set_aside, &robot_from_sensor);
    Ok(Solution {
        robot_from_sensor,
        covariance,
        poses: outcomes,
        observability,
        variance_factors,
        noise_per_pose: (
            (assumed.variance.0 * variance_factors.0).sqrt(),
            (assumed.variance.1 * variance_factors.1).sqrt(),
        ),
        iterations: evaluations,
        depth_scale: DepthScale::fixed(1.0, "given".into()),
        depth_pattern: None,
    })
}

/// Whether a block of `parameters` is judged by the poses themselves (its
/// covariance by the jackknife): when the noise comes from the residuals
/// and they are enough to say ([`MIN_EVIDENCE_DOF`]).
fn jackknife_applies(poses: usize, parameters: usize, settings: &SolveSettings) -> bool {
    settings.noise_from_residuals && poses as f64 - parameters as f64 >= MIN_EVIDENCE_DOF
}

/// Residual degrees of freedom a block needs before its noise is taken from
/// its residuals alone: the variance is then known to about ±30 % (√(2/20)),
/// its σ to ±16 %. 12 poses give the normals 21, 23 poses the offsets 20.
pub const MIN_EVIDENCE_DOF: f64 = 20.0;

/// The noise assumed for one pose, averaged over the poses.
struct AssumedNoise {
    /// The variance of the normal per tangent direction and of the offset:
    /// the fit's covariance plus the floors (what the variance factors scale).
    variance: (f64, f64),
    /// The share of each that the fit's own covariance makes up: the least
    /// a variance factor may be (1 when a pose has no fit covariance).
    fit_share: (f64, f64),
}

fn assumed_noise(used: &[&Observation], settings: &SolveSettings) -> AssumedNoise {
    let floor_n = settings.normal_sigma_floor.powi(2);
    let floor_d = settings.offset_sigma_floor.powi(2);
    let (mut variance, mut share) = ((0.0, 0.0), (0.0, 0.0));
    let mut all_fitted = true;
    for obs in used {
        let (fit_n, fit_d) = match obs.plane_covariance {
            Some(c) => {
                let tangent = Weights::of(obs, settings).tangent;
                let fit_t = tangent.transpose() * c.fixed_view::<3, 3>(0, 0) * tangent;
                (fit_t.trace() / 2.0, c[(3, 3)])
            }
            None => {
                all_fitted = false;
                (0.0, 0.0)
            }
        };
        variance.0 += fit_n + floor_n;
        variance.1 += fit_d + floor_d;
        share.0 += fit_n / (fit_n + floor_n);
        share.1 += fit_d / (fit_d + floor_d);
    }
    let n = used.len().max(1) as f64;
    AssumedNoise {
        variance: (variance.0 / n, variance.1 / n),
        fit_share: if all_fitted {
            (share.0 / n, share.1 / n)
        } else {
            (1.0, 1.0)
        },
    }
}

/// Levenberg-Marquardt from the closed form, inside iteratively reweighted
/// least squares with Cauchy weights: observations far from the rest lose
/// influence smoothly, so a few noisy poses cannot drag the result. The scale
/// is 2.385 robust standard deviations of the whitened residuals (95 %
/// efficiency on Gaussian noise), never less than the assumed noise.
fn refine<'a>(
    used: &[&'a Observation],
    start: PoseParams,
    settings: &SolveSettings,
) -> (PoseParams, IdentificationProblem<'a>, usize) {
    let weights: Vec<Weights> = used.iter().map(|o| Weights::of(o, settings)).collect();
    let mut problem = IdentificationProblem {
        observations: used.to_vec(),
        weights,
        robust: vec![(1.0, 1.0); used.len()],
        params: start.to_vector(),
    };
    let mut evaluations = 0;
    for _ in 0..ROUNDS {
        let before = problem.params;
        let (solved, report) = LevenbergMarquardt::new().with_tol(1e-12).minimize(problem);
        problem = solved;
        evaluations += report.number_of_evaluations;
        if !(report.termination.was_successful() && problem.params.iter().all(|v| v.is_finite())) {
            tracing::warn!(termination = ?report.termination, "Levenberg-Marquardt did not converge; keeping the previous estimate");
            problem.params = before;
            break;
        }
        // Unweighted whitened residual sizes per observation.
        let saved = std::mem::replace(&mut problem.robust, vec![(1.0, 1.0); used.len()]);
        let r = problem.residual_vector();
        problem.robust = saved;
        let normal_sizes: Vec<f64> = (0..used.len())
            .map(|k| r[3 * k].hypot(r[3 * k + 1]))
            .collect();
        let offset_sizes: Vec<f64> = (0..used.len()).map(|k| r[3 * k + 2].abs()).collect();
        // Median of a 2-D Gaussian's length is 1.1774 σ; of a 1-D's magnitude 0.6745 σ.
        let c_n = CAUCHY * (median(&normal_sizes) / 1.1774).max(1.0);
        let c_d = CAUCHY * (median(&offset_sizes) / 0.6745).max(1.0);
        let robust: Vec<(f64, f64)> = normal_sizes
            .iter()
            .zip(&offset_sizes)
            .map(|(n, d)| {
                (
                    1.0 / (1.0 + (n / c_n).powi(2)),
                    1.0 / (1.0 + (d / c_d).powi(2)),
                )
            })
            .collect();
        let change = robust
            .iter()
            .zip(&problem.robust)
            .map(|(a, b)| (a.0 - b.0).abs().max((a.1 - b.1).abs()))
            .fold(0.0, f64::max);
        tracing::debug!(?robust, c_n, c_d, params = ?problem.params, termination = ?report.termination, "robust round");
        problem.robust = robust;
        if change < 1e-9 {
            break;
        }
    }
    // Wrap the angles into (-π, π] through the matrix round trip.
    let robot_from_sensor =
        PoseParams::from_transform(&PoseParams::from_vector(&problem.params).to_transform());
    problem.params = robot_from_sensor.to_vector();
    (robot_from_sensor, problem, evaluations)
}

/// The Cauchy weights' scale, in robust standard deviations of the
/// whitened residuals (95 % efficiency on Gaussian noise).
const CAUCHY: f64 = 2.385;

/// Rounds of reweighting at most.
const ROUNDS: usize = 50;

/// The median of `values` (0 when empty).
pub(crate) fn median(values: &[f64]) -> f64 {
    median_in_place(&mut values.to_vec())
}

/// The median of `values`, which it reorders (0 when empty).
fn median_in_place(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_unstable_by(f64::total_cmp);
    let mid = values.len() / 2;
    if values.len().is_multiple_of(2) {
        0.5 * (values[mid - 1] + values[mid])
    } else {
        values[mid]
    }
}

fn outcomes(
    observations: &[Observation],
    set_aside: &[Option<String>],
    result: &PoseParams,
) -> Vec<PoseOutcome> {
    observations
        .iter()
        .zip(set_aside)
        .map(|(obs, aside)| {
            let (predicted, theta, e_d) = errors(result, obs);
            PoseOutcome {
                index: obs.index,
                used: aside.is_none(),
                reason: aside.clone(),
                measured: obs.plane,
                predicted,
                theta,
                e_d,
                inliers: obs.inliers,
                note: obs.note.clone(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use levenberg_marquardt::differentiate_numerically;

    fn schedule() -> Vec<PoseParams> {
        let mut poses = Vec::new();
        for (beta, gamma, py) in [
            (2.0, 20.0, 615.0),
            (15.0, 12.0, 631.0),
            (19.0, 4.0, 647.0),
            (-11.0, -16.0, 625.0),
            (-19.0, -8.0, 641.0),
            (3.0, 19.0, 690.0),
            (17.0, 7.0, 686.0),
            (-12.0, -15.0, 700.0),
            (-18.0, -3.0, 676.0),
            (9.0, 9.0, 738.0),
            (-9.0, -9.0, 740.0),
            (-12.0, -3.0, 750.0),
        ] {
            poses.push(PoseParams::new(
                0.0,
                f64::to_radians(beta),
                f64::to_radians(gamma),
                Vector3::new(0.0, py / 1e3, 0.0),
            ));
        }
        poses
    }

    fn exact_observations(truth: &PoseParams) -> Vec<Observation> {
        schedule()
            .iter()
            .enumerate()
            .map(|(i, pose)| {
                let g = pose.to_transform();
                Observation::new(i as u32 + 1, g, predict(truth, &g))
            })
            .collect()
    }

    #[test]
    fn analytic_jacobian_matches_numerical() {
        let truth = PoseParams::new(0.1, -0.6, 0.05, Vector3::new(0.5, 0.36, -0.03));
        let obs = exact_observations(&truth);
        let settings = SolveSettings::default();
        let mut problem = IdentificationProblem {
            observations: obs.iter().collect(),
            weights: obs.iter().map(|o| Weights::of(o, &settings)).collect(),
            robust: vec![(1.0, 0.5); obs.len()],
            params: Vector6::new(0.2, -0.5, -0.1, 0.4, 0.3, 0.01),
        };
        let numerical = differentiate_numerically(&mut problem).unwrap();
        let analytic = problem.jacobian().unwrap();
        let scale = analytic.amax();
        assert!(
            (numerical - analytic).amax() < 1e-6 * scale,
            "Jacobian mismatch"
        );
    }

    #[test]
    fn exact_planes_give_the_exact_mount_from_no_guess() {
        let truth = PoseParams::new(
            -0.0077,
            -0.6529,
            -0.0532,
            Vector3::new(0.5279, 0.3648, -0.0334),
        );
        let result = solve(&exact_observations(&truth), &SolveSettings::default()).unwrap();
        assert!((result.robot_from_sensor.to_vector() - truth.to_vector()).amax() < 1e-9);
        assert!(result
            .poses
            .iter()
            .all(|p| p.used && p.theta < 1e-9 && p.e_d < 1e-9));
    }

    #[test]
    fn a_schedule_that_never_tilts_is_rejected_in_words() {
        let truth = PoseParams::new(0.0, -0.6, 0.0, Vector3::new(0.5, 0.36, 0.0));
        let obs: Vec<Observation> = (0..10)
            .map(|i| {
                let g =
                    PoseParams::new(0.0, 0.0, 0.0, Vector3::new(0.0, 0.6 + 0.01 * i as f64, 0.0))
                        .to_transform();
                Observation::new(i + 1, g, predict(&truth, &g))
            })
            .collect();
        // The words come from the observability; the verdict from the gates.
        let result = crate::calibrate::calibrate(&obs, &Default::default()).unwrap();
        assert_eq!(result.verdict, crate::outcome::Verdict::Rejected);
        let text = result.reasons.join("\n");
        assert!(text.contains("rotation of the sensor about the ground normal (α) is not observable: the schedule never tilts the body"), "{text}");
        assert!(
            text.contains("forward (p_x)") && text.contains("sideways (p_z)"),
            "{text}"
        );
    }

    /// The weakest directions in words: a schedule that rolls and pitches
    /// pins the yaw down least, and one that only pitches cannot tell the
    /// sideways position.
    #[test]
    fn names_the_weakest_directions() {
        use crate::outcome::{position_words, rotation_words};
        let truth = PoseParams::new(0.01, -0.6, 0.02, Vector3::new(0.5, 0.36, 0.01));
        let settings = SolveSettings::default();
        let obs = exact_observations(&truth);
        let used: Vec<&Observation> = obs.iter().collect();
        let o = observability(&used, &settings);
        assert!(o.problems.is_empty(), "{:?}", o.problems);
        assert_eq!(o.min_singular_value, settings.min_spread);
        assert!(
            o.rotation_weakest_axis[1] > 0.95,
            "{:?}",
            o.rotation_weakest_axis
        );
        assert_eq!(
            rotation_words(&o.rotation_weakest_axis),
            "rotation about the body's vertical axis Y (yaw of the sensor, α)"
        );
        assert!(position_words(&o.translation_weakest_axis).starts_with("the sensor's "));

        let pitched: Vec<Observation> = [-15.0f64, -8.0, 0.0, 7.0, 16.0]
            .iter()
            .enumerate()
            .map(|(i, beta)| {
                let g = PoseParams::new(0.0, beta.to_radians(), 0.0, Vector3::new(0.0, 0.62, 0.0))
                    .to_transform();
                Observation::new(i as u32 + 1, g, predict(&truth, &g))
            })
            .collect();
        let used: Vec<&Observation> = pitched.iter().collect();
        let o = observability(&used, &settings);
        assert_eq!(
            position_words(&o.translation_weakest_axis),
            "the sensor's sideways (p_z) position"
        );
        assert!(o.translation_singular_values[2] < o.min_singular_value);
        // Between two axes, the components are given.
        assert_eq!(
            position_words(&[0.62, 0.03, 0.78]),
            "the sensor's position along (0.62, 0.03, 0.78), between forward (p_x) and sideways (p_z)"
        );
        assert_eq!(
            rotation_words(&[0.71, 0.0, 0.71]),
            "rotation about the axis (0.71, 0.00, 0.71) of the body, between its forward X and sideways Z axes"
        );
    }
}
