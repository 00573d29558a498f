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
    /// The rotation axis (a unit vector in the robot frame, its largest
    /// component positive) of the smallest rotation singular value: the
    /// rotation the schedule pins down least ([`rotation_words`]).
    pub rotation_weakest_axis: [f64; 3],
    /// The same for the translation: the direction of the position the
    /// schedule pins down least ([`position_words`]).
    pub translation_weakest_axis: [f64; 3],
    /// The smallest singular value that counts as observable (the solve's
    /// `min_spread`, about the sine of the tilts' RMS spread).
    pub min_singular_value: f64,
    /// Operator-readable descriptions of unobservable directions.
    pub problems: Vec<String>,
}

/// The axes of the robot frame in an operator's words: the direction's
/// name and the axis's letter.
pub fn axis_words(axis: usize) -> (&'static str, &'static str) {
    match axis {
        0 => ("forward", "X"),
        1 => ("vertical", "Y"),
        _ => ("sideways", "Z"),
    }
}

/// A position along one axis of the robot frame in words, as the reasons
/// name it: `forward (p_x)`.
pub fn position_axis_words(axis: usize) -> String {
    format!(
        "{} (p_{})",
        axis_words(axis).0,
        ["x", "y", "z"][axis.min(2)]
    )
}

/// A rotation about one axis of the robot frame in words, with the
/// parameter it mostly moves: α turns about the body's vertical exactly; β
/// about the sideways axis turned by α (nearly Z, α being small); γ about
/// the forward axis turned by β and α, hence "mostly".
pub fn rotation_axis_words(axis: usize) -> String {
    match axis {
        0 => "rotation about the body's forward axis X (roll of the sensor, mostly γ)".into(),
        1 => "rotation about the body's vertical axis Y (yaw of the sensor, α)".into(),
        _ => "rotation about the body's sideways axis Z (pitch of the sensor, mostly β)".into(),
    }
}

/// The axis a direction lies along (the largest component, when it is
/// within 25° of it), or the two it lies between.
fn nearest_axes(direction: &[f64; 3]) -> Result<usize, (usize, usize)> {
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| direction[b].abs().total_cmp(&direction[a].abs()));
    let norm = direction.iter().map(|v| v * v).sum::<f64>().sqrt();
    if norm > 0.0 && direction[order[0]].abs() / norm >= 25f64.to_radians().cos() {
        Ok(order[0])
    } else {
        let (a, b) = (order[0].min(order[1]), order[0].max(order[1]));
        Err((a, b))
    }
}

/// A rotation axis of the robot frame in an operator's words: "rotation
/// about the body's vertical axis Y (yaw of the sensor, α)", or about an
/// axis between two, with its components.
pub fn rotation_words(axis: &[f64; 3]) -> String {
    match nearest_axes(axis) {
        Ok(a) => rotation_axis_words(a),
        Err((a, b)) => format!(
            "rotation about the axis ({:.2}, {:.2}, {:.2}) of the body, between its {} {} and {} {} axes",
            axis[0],
            axis[1],
            axis[2],
            axis_words(a).0,
            axis_words(a).1,
            axis_words(b).0,
            axis_words(b).1
        ),
    }
}

/// A direction of the sensor's position in the robot frame in an operator's
/// words: "the sensor's forward (p_x) position", or along a direction
/// between two axes, with its components.
pub fn position_words(direction: &[f64; 3]) -> String {
    match nearest_axes(direction) {
        Ok(a) => format!("the sensor's {} position", position_axis_words(a)),
        Err((a, b)) => format!(
            "the sensor's position along ({:.2}, {:.2}, {:.2}), between {} and {}",
            direction[0],
            direction[1],
            direction[2],
            position_axis_words(a),
            position_axis_words(b)
        ),
    }
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
    /// The noise of one pose's ground the solve took ([`Solution`]'s).
    pub noise_per_pose: (f64, f64),
    /// Levenberg-Marquardt's evaluations and termination.
    pub iterations: usize,
    /// Each quality gate with its limit and what was measured, in the
    /// order of [`crate::quality::check_gates`].
    pub checks: Vec<GateCheck>,
    /// The depth scale, estimated or given.
    pub depth_scale: DepthScale,
    /// The depth pattern, when estimated.
    pub depth_pattern: Option<DepthPattern>,
    /// When the gate on `e_d` failed on flat ground with no foot slipped,
    /// and the poses' disagreement grows with the ground's distance so that
    /// its largest is ordinary for its distance: the depth camera's noise,
    /// not the ground or the body.
    pub e_d_from_sensor_noise: Option<GrowthWithDistance>,
}

/// A pattern is not the sensor's fixed one when a test of an alternative
/// finds it by this many of its σ: a pattern that changes with the depth
/// (`distortion::DepthDependence`), or residuals that stay with the ground as the
/// poses move (`distortion::ShapeEstimate::fixed_in_the_ground`). The noise these σ
/// are of comes from the poses' own scatter (a real Kinect's is correlated
/// over the image, so no count of pixels can say it).
pub const ALTERNATIVE_SIGMAS: f64 = 5.0;

/// The poses' height disagreement as it grows with the ground's distance
/// (`crate::disagreement`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GrowthWithDistance {
    /// `e_d`'s σ grows as the distance to this power.
    pub exponent: f64,
    /// The exponent in its own σ: how clearly the growth stands out.
    pub exponent_sigmas: f64,
    /// The nearest used pose's ground distance (m) and `e_d`'s σ there (m).
    pub nearest: [f64; 2],
    /// The farthest used pose's ground distance (m) and `e_d`'s σ there (m).
    pub farthest: [f64; 2],
    /// The pose with the largest `e_d`: its index, and that `e_d` in its
    /// σ at the pose's distance.
    pub worst_pose: u32,
    pub worst_sigmas: f64,
    /// The most, in σ, that the largest of this many poses' `e_d` reaches
    /// by chance once in a hundred calibrations.
    pub worst_bound: f64,
}

/// One quality gate as it was checked: its limit, the value measured and
/// whether it passed.
#[derive(Debug, Clone, PartialEq)]
pub struct GateCheck {
    /// The gate's key in `[calibration.gates]` (`theta_max_deg`), or
    /// `observable` for the solve's observability threshold.
    pub gate: &'static str,
    /// In the unit of the key's suffix (degrees, millimetres, a count, a
    /// fraction; a singular value for `observable`).
    pub limit: f64,
    pub measured: f64,
    /// Whether the measured value must be at least the limit (the fewest
    /// poses, observability) rather than at most.
    pub at_least: bool,
    pub passed: bool,
    /// Where the measured value comes from, in words: the worst pose
    /// ("pose 7"), parameter ("β") or direction.
    pub at: Option<String>,
    /// The same, typed, for a reader that words it in its own language.
    pub place: Option<GatePlace>,
}

/// Where a gate's measured value comes from.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum GatePlace {
    /// The worst pose, by its index.
    Pose { index: u32 },
    /// The worst parameter: 0–2 the angles α, β, γ, 3–5 the positions x, y, z.
    Parameter { index: usize },
    /// The poses used, of all.
    PosesUsed { used: usize, total: usize },
    /// The depth scale.
    DepthScale,
    /// The direction the schedule pins down least, in the robot frame: a
    /// rotation's axis, or a direction of the position.
    Direction { rotation: bool, axis: [f64; 3] },
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
    /// The noise of one pose's ground this solve took, one σ: of the normal
    /// per tangent direction (radians) and of the offset (metres); from the
    /// residuals when they were enough to say (see `solve`).
    pub noise_per_pose: (f64, f64),
    /// Levenberg-Marquardt's evaluations.
    pub iterations: usize,
    /// The depth scale the distances were divided by, estimated or given.
    pub depth_scale: DepthScale,
    /// The depth pattern, when the observations carried ground residuals.
    pub depth_pattern: Option<DepthPattern>,
}

/// Why a warp of the depth was not corrected as the sensor's fixed pattern:
/// the test of the alternative that said so, with its figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WarpCause {
    /// The pattern changes with the distance: it weakens by `per_m` (a
    /// share) a metre farther, ± `sigma`.
    ChangesWithDepth { per_m: f64, sigma: f64 },
    /// The residuals stay with the ground as the poses move: the ground is
    /// not flat (`sigmas` of noise's σ above what the poses make with
    /// their signs flipped).
    GroundNotFlat { sigmas: f64 },
    /// Most cells' residuals change from pose to pose (obstacles' feet,
    /// bumps): `left_out` of the readings were left out.
    CellsChange { left_out: f64 },
    /// A test of an alternative fired, but the pattern reaches `largest_raw`
    /// from the ground's plane, beyond the `band_raw` within which the
    /// ground fit took its readings (raw units): the fit cut its peaks out,
    /// differently at every pose, and what that leaves behind looks like
    /// either alternative. So neither can be told from the sensor's own
    /// pattern (docs/method.md, "A pattern beyond the fit's band").
    BeyondTheFit { largest_raw: f64, band_raw: f64 },
}

/// The Kinect's fixed depth pattern as a calibration found it
/// ([`crate::distortion`]): per cell of `cell_px` pixels, the raw units every
/// reading there is off by (more is farther), row-major from the top left.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthPattern {
    /// Whether a pattern was found and the planes corrected for it.
    pub corrected: bool,
    pub columns: usize,
    pub rows: usize,
    pub cell_px: usize,
    /// Per cell, raw units; `None` where no pose saw the ground.
    pub raw: Vec<Option<f64>>,
    /// One σ of each cell's value, raw units.
    pub sigma_raw: Vec<Option<f64>>,
    /// RMS of the shape (the pattern less its plane part), raw units.
    pub shape_rms_raw: f64,
    /// The shape against none, χ² per degree of freedom (1: no shape).
    pub shape_chi2_per_dof: f64,
    /// The cells' residuals pose by pose after the pattern, χ² per degree
    /// of freedom against the noise the poses' own scatter shows: near 1 by
    /// that noise's construction (a check of the estimate, not a test).
    pub consistency_chi2_per_dof: f64,
    /// The shape's size in noise's σ above what the poses make with random
    /// signs (the test that a shape is there).
    pub shape_sigmas: f64,
    /// How the pattern changes with depth: the share it weakens a metre
    /// farther, and its σ.
    pub changes_with_depth: Option<[f64; 2]>,
    /// How far the residuals stay with the ground as the poses move, in
    /// noise's σ (uneven ground); None without the poses' geometry.
    pub fixed_in_the_ground_sigmas: Option<f64>,
    /// Why a warp was not corrected, when it was not.
    pub uncorrected_because: Option<WarpCause>,
    /// The plane part, by the geometry across poses: raw units at the
    /// principal point and per 100 pixels along the columns and the rows;
    /// with its σ. `None` when not estimated.
    pub plane_part: Option<[f64; 3]>,
    pub plane_part_sigma: Option<[f64; 3]>,
    /// Whether the plane part was taken (it differed from none).
    pub plane_part_taken: bool,
    /// The RMS of a shape that stood out of the noise but was not corrected
    /// (it changed from pose to pose), raw units.
    pub uncorrected_shape_rms_raw: Option<f64>,
    /// That uncorrected shape per cell (raw units, `None` where no pose saw
    /// the ground): what the residuals showed, for a maintainer to compare
    /// with the sensor's; nothing takes it out of a frame.
    pub uncorrected_raw: Option<Vec<Option<f64>>>,
    /// Whether that uncorrected shape is fixed in the image: the sensor's
    /// own pattern, left uncorrected because the ground fit in use (the
    /// paper's) cannot take it out.
    pub uncorrected_fixed: bool,
    /// Raw units per 1/m of inverse depth (the depth model's `1/b`): a cell's
    /// depth error at depth z is `−z²·value/raw_per_inverse_depth`.
    pub raw_per_inverse_depth: f64,
    /// The σ of α, β, γ (radians) had the plane part been known exactly,
    /// when it was taken: beside the result's σ, what correcting it cost.
    /// The plane part tilts every pose's ground as a turn of the sensor
    /// would, and only the spread of the body's heights tells the two
    /// apart, so this cost is mostly the schedule's.
    pub angle_sigma_known_plane_part: Option<[f64; 3]>,
    /// When the plane part was taken: how many times each angle's σ grows
    /// with it by the poses' geometry alone (their planes exact, the noise
    /// per pose the solve found): the schedule's cost, which the gate
    /// `pattern_angle_sigma_growth_max` judges. The measured σ beside
    /// [`Self::angle_sigma_known_plane_part`] grow by more or less with the
    /// noise met.
    pub angle_sigma_growth_by_geometry: Option<[f64; 3]>,
    /// What was found, in words.
    pub note: Option<String>,
    /// The shape to take out of the frames before fitting their ground
    /// again, when the fit's band cut its peaks (raw units per cell, no
    /// plane part): the first estimate is then biased, and a fit about it
    /// cuts nothing (docs/method.md, "A pattern beyond the fit's band").
    pub fit_again_about: Option<crate::depth::DepthCorrection>,
}

impl DepthPattern {
    /// No pattern estimated, with why.
    pub fn not_estimated(note: String) -> Self {
        DepthPattern {
            corrected: false,
            columns: 0,
            rows: 0,
            cell_px: 0,
            raw: Vec::new(),
            sigma_raw: Vec::new(),
            shape_rms_raw: 0.0,
            shape_chi2_per_dof: 0.0,
            consistency_chi2_per_dof: 0.0,
            shape_sigmas: 0.0,
            changes_with_depth: None,
            fixed_in_the_ground_sigmas: None,
            uncorrected_because: None,
            plane_part: None,
            plane_part_sigma: None,
            plane_part_taken: false,
            uncorrected_shape_rms_raw: None,
            uncorrected_raw: None,
            uncorrected_fixed: false,
            raw_per_inverse_depth: 0.0,
            angle_sigma_known_plane_part: None,
            angle_sigma_growth_by_geometry: None,
            note: Some(note),
            fit_again_about: None,
        }
    }

    /// The largest depth error the pattern causes at depth `z_m`, metres,
    /// over the cells seen.
    pub fn largest_depth_error_m(&self, z_m: f64) -> f64 {
        if self.raw_per_inverse_depth == 0.0 {
            return 0.0;
        }
        self.raw
            .iter()
            .flatten()
            .map(|raw| depth_error_m(*raw, z_m, self.raw_per_inverse_depth))
            .fold(0.0, f64::max)
    }
}

/// The depth error `raw` units of disparity cause at depth `z_m`, metres
/// (`1/z = a + b·raw`, so `|δz| = z²·|raw·b|`).
pub fn depth_error_m(raw: f64, z_m: f64, raw_per_inverse_depth: f64) -> f64 {
    if raw_per_inverse_depth == 0.0 {
        return 0.0;
    }
    (z_m * z_m * raw / raw_per_inverse_depth).abs()
}

/// The Kinect's depth scale: its depth reads `value` × the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthScale {
    pub value: f64,
    /// Its σ, when estimated.
    pub sigma: Option<f64>,
    pub estimated: bool,
    /// Its correlation with α, β, γ, px, py, pz (zero for the angles).
    pub correlations: [f64; 6],
    /// Why it was not estimated, in words.
    pub note: Option<String>,
    /// When not estimated because the poses pin it too loosely: where they
    /// put it nonetheless, and its σ (what [`crate::quality`] weighs
    /// against the scale taken).
    pub loose_estimate: Option<(f64, f64)>,
}

impl DepthScale {
    /// A scale taken as known.
    pub fn fixed(value: f64, note: String) -> Self {
        DepthScale {
            value,
            sigma: None,
            estimated: false,
            correlations: [0.0; 6],
            note: Some(note),
            loose_estimate: None,
        }
    }

    /// The value taken, where it was not estimated (given, or the poses
    /// pinned it too loosely).
    pub fn not_estimated(&self) -> Option<f64> {
        (!self.estimated).then_some(self.value)
    }
}

impl Solution {
    /// One standard deviation of each parameter (radians, metres).
    pub fn sigma(&self) -> Vector6<f64> {
        sigma_of(&self.covariance)
    }
}

/// One σ of each parameter from a covariance (its diagonal's roots).
pub(crate) fn sigma_of(covariance: &Matrix6<f64>) -> Vector6<f64> {
    Vector6::from_fn(|i, _| sigma_of_variance(covariance[(i, i)]))
}

/// The σ of a variance: a rounding below zero is 0, and NaN (a covariance
/// that could not be computed) stays NaN, which no gate passes. `max(0.0)`
/// alone made NaN a σ of 0: certainty where nothing is known.
pub(crate) fn sigma_of_variance(variance: f64) -> f64 {
    if variance.is_nan() {
        f64::NAN
    } else {
        variance.max(0.0).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A variance that could not be computed is no σ of 0: NaN stays NaN,
    /// which no σ gate passes; a rounding below zero is 0.
    #[test]
    fn an_unknown_variance_is_no_certainty() {
        let mut covariance = Matrix6::identity() * 4e-6;
        covariance[(4, 4)] = f64::NAN;
        covariance[(5, 5)] = -1e-30;
        let sigma = sigma_of(&covariance);
        assert!(sigma[4].is_nan(), "{sigma}");
        assert_eq!(sigma[5], 0.0);
        assert_eq!(sigma[0], 2e-3);
    }
}
