//! Whether the sensor still sits where the active calibration says: a
//! knocked sensor, a bent bracket or a tilt motor that moved, caught while
//! the robot stands still (`groundcal verify`).
//!
//! With the feet planted, the body pose comes from the feet, so the
//! calibration predicts the ground in the sensor frame; the Kinect's
//! accelerometer measures gravity in the same frame. A change of the mount,
//! `robot_from_sensor' = Exp(ω)·robot_from_sensor` turned by the small
//! rotation `ω` (robot axes, about the sensor's optical centre) and moved by
//! `δt`, shows to first order as
//!
//! ```text
//! measured ground normal, in the robot frame through the calibration:  n_p + n_p × ω
//! measured ground distance d:                                          d_p + n_p · δt
//! measured gravity (up), in the robot frame through the calibration:   u + u × ω
//! ```
//!
//! where `n_p` (= `u` on level ground) is the ground's up direction in the
//! robot frame from the feet. This module estimates `(ω, δt)` from the poses
//! by weighted least squares, with a weak prior so that what the poses cannot
//! see stays at zero and is said to be unseen: one still stance sees the two
//! tilts (roll and pitch) and the height; tilted poses add the yaw and, a
//! little, the position along the ground.
//!
//! Each direction is tested against `k` of its σ, which adds the calibration's
//! own σ (the prediction is only as good as it) to the noise of the poses:
//! at `k` = 4 a consistent sensor fails a one-dimensional test with
//! probability 6·10⁻⁵ and a two-dimensional one (the tilt) with at most
//! `exp(−k²/2)` = 3·10⁻⁴, far below the 1 in 50 runs it must stay under.
//!
//! Gravity is a second, independent witness of the tilt. It assumes the robot
//! stands on level ground, as for a calibration: on a slope it says so rather
//! than blame the sensor (the ground's own test, relative to the feet, is
//! not affected by a slope).

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Rotation3, SMatrix, Vector3};

use super::geometry::{Plane, PoseParams, Transform};
use super::plan::NoiseModel;

/// The active calibration as verification needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActiveMount {
    pub robot_from_sensor: PoseParams,
    /// σ of α, β, γ (radians), p_x, p_y, p_z (metres); `None` when the
    /// calibration does not say (then it is taken as exact).
    pub sigma: Option<[f64; 6]>,
    /// Their correlations, when known.
    pub correlations: Option<[[f64; 6]; 6]>,
    /// The depth scale it found (measured distances are divided by it).
    pub depth_scale: f64,
    /// Its σ and its correlations with α, β, γ, p_x, p_y, p_z, when it was
    /// estimated: it correlates strongly with the height, and together they
    /// predict the ground's distance far better than either alone.
    pub depth_scale_sigma: Option<f64>,
    pub depth_scale_correlations: Option<[f64; 6]>,
}

/// What was measured at one pose.
#[derive(Debug, Clone, PartialEq)]
pub struct VerifyPose {
    /// The pose's number (0 for the home stance held still).
    pub index: u32,
    /// The real body pose, from the feet.
    pub ground_from_robot: Transform,
    /// The ground measured in the sensor frame, if a ground was found.
    pub plane: Option<Plane>,
    /// Gravity's reaction (up) measured in the sensor frame (X forward, Y up,
    /// Z right), the mean of `gravity_readings` accelerometer readings.
    pub gravity_up: Option<Vector3<f64>>,
    pub gravity_readings: usize,
}

/// How sure verification must be before it calls a drift.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VerifySettings {
    /// The noise of one pose's ground (as for the solve and `plan`).
    pub noise: NoiseModel,
    /// σ of one accelerometer reading per axis, degrees (of the direction of
    /// gravity): noise, quantisation (1/819 g ≈ 0.07°) and how well the
    /// accelerometer's axes match the depth camera's.
    pub accelerometer_sigma_deg: f64,
    /// A direction drifted when its change exceeds `k` of its σ.
    pub k_sigma: f64,
}

impl Default for VerifySettings {
    fn default() -> Self {
        Self {
            noise: NoiseModel::solve_floors(),
            accelerometer_sigma_deg: 0.15,
            k_sigma: 4.0,
        }
    }
}

impl VerifySettings {
    pub fn validate(&self) -> Result<(), String> {
        self.noise.validate()?;
        for (name, value) in [
            ("accelerometer_sigma_deg", self.accelerometer_sigma_deg),
            ("k_sigma", self.k_sigma),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("{name} must be a positive number, not {value}"));
            }
        }
        Ok(())
    }
}

/// The six directions a mount can move in, in the robot frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// About the body's forward axis X: positive leans the sensor's top to the right.
    Roll,
    /// About the body's vertical axis Y: positive turns the sensor to the left.
    Yaw,
    /// About the body's sideways axis Z: positive pitches the sensor up.
    Pitch,
    Forward,
    Height,
    Sideways,
}

impl Direction {
    pub const ALL: [Direction; 6] = [
        Direction::Roll,
        Direction::Yaw,
        Direction::Pitch,
        Direction::Forward,
        Direction::Height,
        Direction::Sideways,
    ];

    /// Its index in `(ω_x, ω_y, ω_z, δt_x, δt_y, δt_z)`.
    fn index(self) -> usize {
        self as usize
    }

    pub fn is_rotation(self) -> bool {
        self.index() < 3
    }

    /// A name for JSON and tables.
    pub fn name(self) -> &'static str {
        match self {
            Direction::Roll => "roll",
            Direction::Yaw => "yaw",
            Direction::Pitch => "pitch",
            Direction::Forward => "forward",
            Direction::Height => "height",
            Direction::Sideways => "sideways",
        }
    }

    /// The change in an operator's words: "tilted 0.40° more to the left".
    /// `change` is in radians or metres.
    pub fn words(self, change: f64) -> String {
        let positive = change >= 0.0;
        let (angle, mm) = (change.abs().to_degrees(), change.abs() * 1000.0);
        let side = |p: &'static str, n: &'static str| if positive { p } else { n };
        match self {
            Direction::Roll => format!("tilted {angle:.2}° more to the {}", side("right", "left")),
            Direction::Yaw => format!("turned {angle:.2}° more to the {}", side("left", "right")),
            Direction::Pitch => format!("pitched {angle:.2}° more {}", side("up", "down")),
            Direction::Forward => format!("{mm:.1} mm farther {}", side("forward", "back")),
            Direction::Height => format!("{mm:.1} mm {}", side("higher", "lower")),
            Direction::Sideways => format!("{mm:.1} mm farther {}", side("right", "left")),
        }
    }
}

/// One direction's estimated change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectionChange {
    pub direction: Direction,
    /// Radians or metres.
    pub change: f64,
    /// Its σ, noise and calibration together.
    pub sigma: f64,
    /// Whether the poses see it (else it was not checked).
    pub seen: bool,
}

impl DirectionChange {
    /// Whether it moved beyond `k` σ (never, when unseen).
    pub fn drifted(&self, k: f64) -> bool {
        self.seen && self.change.abs() > k * self.sigma
    }
}

/// Which measurement says that the sensor moved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Witness {
    /// The ground the depth frames see.
    Ground,
    /// The Kinect's accelerometer.
    Gravity,
}

/// One drift, typed: who says it, and the changes named (radians or metres,
/// signed as [`Direction::words`] reads them).
#[derive(Debug, Clone, PartialEq)]
pub struct Drift {
    pub witness: Witness,
    pub changes: Vec<(Direction, f64)>,
    /// The accelerometer says so but the ground does not (a slope, or an
    /// accelerometer that moved in the Kinect).
    pub ground_disagrees: bool,
}

/// One check with its threshold, as the operator reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// "ground tilt θ", "height e_d", "yaw", "gravity".
    pub name: &'static str,
    /// Radians or metres, never negative.
    pub measured: f64,
    pub threshold: f64,
    pub unit: Unit,
    pub passed: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unit {
    Angle,
    Length,
}

/// One pose against the calibration's prediction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseComparison {
    pub index: u32,
    /// Angle between the measured and the predicted ground (radians).
    pub theta: Option<f64>,
    /// Measured minus predicted ground distance (metres).
    pub e_d: Option<f64>,
    /// Angle between measured and predicted gravity (radians).
    pub gravity_angle: Option<f64>,
    /// The sensor's turn about its own right axis (the Kinect's motor axis)
    /// that gravity shows against the calibration, radians, positive up.
    pub motor_turn: Option<f64>,
}

/// What verification found.
#[derive(Debug, Clone, PartialEq)]
pub struct VerifyReport {
    pub poses: Vec<PoseComparison>,
    /// From the ground: the six directions (unseen ones with `seen` false).
    pub ground: Vec<DirectionChange>,
    /// From gravity alone: the three rotations.
    pub gravity: Vec<DirectionChange>,
    pub checks: Vec<Check>,
    /// The reasons for a drift, in an operator's words (empty: consistent).
    pub reasons: Vec<String>,
    /// The same drifts, typed, one for each reason and in its order: for a
    /// page that says them in words of its own language.
    pub drifts: Vec<Drift>,
    /// Things to know that are not a drift.
    pub notes: Vec<String>,
}

impl VerifyReport {
    pub fn drifted(&self) -> bool {
        !self.reasons.is_empty()
    }

    /// The motor's turn about its axis against the calibration, from gravity,
    /// averaged over the poses (radians).
    pub fn motor_turn(&self) -> Option<f64> {
        mean(self.poses.iter().filter_map(|p| p.motor_turn))
    }
}

/// Why nothing could be verified.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VerifyError {
    #[error("no pose has a ground or an accelerometer reading to compare with the calibration")]
    NothingMeasured,
    #[error("{0}")]
    Settings(String),
}

fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Two unit vectors perpendicular to `n` (unit).
fn tangent_basis(n: &Vector3<f64>) -> [Vector3<f64>; 2] {
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::z()
    };
    let b1 = n.cross(&helper).normalize();
    [b1, n.cross(&b1)]
}

/// The calibration's covariance in `(ω, δt, δs)`: the paper's angles
/// turned into small rotations about the robot's axes, the position, and the
/// depth scale.
fn mount_covariance(mount: &ActiveMount) -> SMatrix<f64, 7, 7> {
    let Some(sigma) = mount.sigma else {
        return SMatrix::zeros();
    };
    let params = mount.robot_from_sensor;
    let base = params.rotation_matrix();
    let mut jacobian = SMatrix::<f64, 7, 7>::zeros();
    let step = 1e-6;
    for j in 0..3 {
        let mut moved = params;
        match j {
            0 => moved.alpha += step,
            1 => moved.beta += step,
            _ => moved.gamma += step,
        }
        let turn = Rotation3::from_matrix_unchecked(moved.rotation_matrix() * base.transpose());
        let omega = turn.scaled_axis() / step;
        for i in 0..3 {
            jacobian[(i, j)] = omega[i];
        }
    }
    for i in 3..7 {
        jacobian[(i, i)] = 1.0;
    }
    let correlations = mount.correlations.unwrap_or_else(|| {
        std::array::from_fn(|i| std::array::from_fn(|j| if i == j { 1.0 } else { 0.0 }))
    });
    let scale_sigma = mount.depth_scale_sigma.unwrap_or(0.0);
    let scale_correlations = mount.depth_scale_correlations.unwrap_or([0.0; 6]);
    let sigma7 = |i: usize| if i < 6 { sigma[i] } else { scale_sigma };
    let covariance = SMatrix::<f64, 7, 7>::from_fn(|i, j| {
        let r = match (i, j) {
            _ if i == j => 1.0,
            (6, k) | (k, 6) => scale_correlations[k],
            _ => correlations[i][j],
        };
        let r = if r.is_finite() { r } else { 0.0 };
        sigma7(i) * sigma7(j) * r
    });
    jacobian * covariance * jacobian.transpose()
}

/// A weak prior on the change (a knock beyond it is a broken mount, which
/// any test catches): what no pose sees stays near zero, and is unseen.
const PRIOR_ANGLE: f64 = 0.1; // rad, 5.7°
const PRIOR_LENGTH: f64 = 0.1; // m

/// A direction counts as seen when the poses shrink its σ below this
/// fraction of the prior's.
const SEEN_FRACTION: f64 = 0.2;

/// Rows of a linear model `r = A x + noise` with σ per row.
#[derive(Default)]
struct Rows {
    a: Vec<[f64; 6]>,
    r: Vec<f64>,
    sigma: Vec<f64>,
    /// How each row moves with an error of the calibration's depth scale: a
    /// distance `d` (already divided by the scale `s`) by `d/s` per unit.
    scale: Vec<f64>,
}

impl Rows {
    /// The two tangent components of a measured unit vector against its
    /// prediction `p` (both in the robot frame): `m − p = p × ω`.
    fn add_direction(&mut self, predicted: &Vector3<f64>, measured: &Vector3<f64>, sigma: f64) {
        let model = skew(predicted);
        for b in tangent_basis(predicted) {
            let row = b.transpose() * model;
            self.a.push([row[0], row[1], row[2], 0.0, 0.0, 0.0]);
            self.r.push(b.dot(&(measured - predicted)));
            self.sigma.push(sigma);
            self.scale.push(0.0);
        }
    }

    /// The ground's distance: `d_m − d_p = n_p · δt`.
    /// (`per_scale`: how it moves with the calibration's depth scale.)
    fn add_distance(&mut self, normal: &Vector3<f64>, residual: f64, sigma: f64, per_scale: f64) {
        self.a.push([0.0, 0.0, 0.0, normal.x, normal.y, normal.z]);
        self.r.push(residual);
        self.sigma.push(sigma);
        self.scale.push(per_scale);
    }

    /// The weighted least-squares change with the prior, and each
    /// direction's σ against `calibration` (zero rows: None).
    fn estimate(
        &self,
        calibration: &SMatrix<f64, 7, 7>,
        rotations_only: bool,
    ) -> Option<Vec<DirectionChange>> {
        if self.a.is_empty() {
            return None;
        }
        let n = self.a.len();
        let a = DMatrix::from_fn(n, 6, |i, j| self.a[i][j] / self.sigma[i]);
        let r = DVector::from_fn(n, |i, _| self.r[i] / self.sigma[i]);
        let prior = Matrix6::from_diagonal(&nalgebra::Vector6::from_fn(|i, _| {
            let s = if i < 3 { PRIOR_ANGLE } else { PRIOR_LENGTH };
            1.0 / (s * s)
        }));
        let ata = a.transpose() * &a;
        let normal = Matrix6::from_fn(|i, j| ata[(i, j)]) + prior;
        let inverse = normal.try_inverse()?;
        let atr = a.transpose() * r;
        let x = inverse * nalgebra::Vector6::from_fn(|i, _| atr[i]);
        let measurement = inverse * Matrix6::from_fn(|i, j| ata[(i, j)]) * inverse;
        // How an error of the calibration moves the estimate: through each
        // row as a change of the mount would, and through the distances as a
        // change of the depth scale. (Height and scale correlate strongly in
        // a calibration; together they predict the distance far better than
        // either's σ alone says.)
        let to_estimate = DMatrix::from_fn(6, n, |i, k| {
            (0..6).map(|j| inverse[(i, j)] * a[(k, j)]).sum::<f64>() / self.sigma[k]
        });
        let rows_from_calibration =
            DMatrix::from_fn(
                n,
                7,
                |k, j| if j < 6 { self.a[k][j] } else { self.scale[k] },
            );
        let through = &to_estimate * rows_from_calibration;
        let calibration = DMatrix::from_fn(7, 7, |i, j| calibration[(i, j)]);
        let induced = &through * calibration * through.transpose();
        let total = measurement + Matrix6::from_fn(|i, j| induced[(i, j)]);
        let count = if rotations_only { 3 } else { 6 };
        Some(
            Direction::ALL[..count]
                .iter()
                .map(|&direction| {
                    let i = direction.index();
                    let prior_sigma = if i < 3 { PRIOR_ANGLE } else { PRIOR_LENGTH };
                    DirectionChange {
                        direction,
                        change: x[i],
                        sigma: total[(i, i)].max(0.0).sqrt(),
                        seen: inverse[(i, i)].max(0.0).sqrt() < SEEN_FRACTION * prior_sigma,
                    }
                })
                .collect(),
        )
    }
}

/// The largest σ of roll and pitch together (for the tilt's 2-D test).
fn tilt_of(changes: &[DirectionChange]) -> Option<(f64, f64)> {
    let roll = changes.iter().find(|c| c.direction == Direction::Roll)?;
    let pitch = changes.iter().find(|c| c.direction == Direction::Pitch)?;
    if !(roll.seen && pitch.seen) {
        return None;
    }
    Some((roll.change.hypot(pitch.change), roll.sigma.max(pitch.sigma)))
}

/// Compares the measured poses with the active calibration.
pub fn verify(
    mount: &ActiveMount,
    poses: &[VerifyPose],
    settings: &VerifySettings,
) -> Result<VerifyReport, VerifyError> {
    settings.validate().map_err(VerifyError::Settings)?;
    let robot_from_sensor = mount.robot_from_sensor.to_transform();
    let rotation = robot_from_sensor.rotation;
    let calibration = mount_covariance(mount);
    let normal_sigma = settings.noise.normal_sigma_deg.to_radians();
    let offset_sigma = settings.noise.offset_sigma_mm / 1000.0;
    let reading_sigma = settings.accelerometer_sigma_deg.to_radians();
    let motor_axis = rotation * Vector3::z();

    let mut ground_rows = Rows::default();
    let mut gravity_rows = Rows::default();
    let mut comparisons = Vec::new();
    for pose in poses {
        let ground_from_sensor = pose.ground_from_robot * robot_from_sensor;
        let predicted = super::geometry::ground_in_sensor(&ground_from_sensor);
        // The ground's up direction in the robot frame, from the feet.
        let up = pose.ground_from_robot.rotation.inverse() * Vector3::y();
        let mut comparison = PoseComparison {
            index: pose.index,
            theta: None,
            e_d: None,
            gravity_angle: None,
            motor_turn: None,
        };
        if let Some(plane) = &pose.plane {
            let measured = rotation * plane.normal.normalize();
            ground_rows.add_direction(&up, &measured, normal_sigma);
            let d = plane.d / mount.depth_scale;
            ground_rows.add_distance(&up, d - predicted.d, offset_sigma, d / mount.depth_scale);
            comparison.theta = Some(super::geometry::angle_between(&measured, &up));
            comparison.e_d = Some(d - predicted.d);
        }
        if let Some(g) = pose.gravity_up.filter(|g| g.norm() > 0.0) {
            let measured = rotation * g.normalize();
            let sigma = reading_sigma / (pose.gravity_readings.max(1) as f64).sqrt();
            gravity_rows.add_direction(&up, &measured, sigma);
            comparison.gravity_angle = Some(super::geometry::angle_between(&measured, &up));
            // The turn about the motor's axis that takes the prediction to
            // the measurement: their difference's component about the axis.
            // (A turn δ about the axis a moves u to u − δ·a × u, so
            // (u × m)·a = −δ·(1 − (u·a)²).)
            let across = 1.0 - up.dot(&motor_axis).powi(2);
            if across > 0.1 {
                comparison.motor_turn = Some(-up.cross(&measured).dot(&motor_axis) / across);
            }
        }
        comparisons.push(comparison);
    }
    if ground_rows.a.is_empty() && gravity_rows.a.is_empty() {
        return Err(VerifyError::NothingMeasured);
    }
    let ground = ground_rows
        .estimate(&calibration, false)
        .unwrap_or_default();
    let gravity = gravity_rows
        .estimate(&calibration, true)
        .unwrap_or_default();
    let k = settings.k_sigma;

    let mut checks = Vec::new();
    let mut reasons = Vec::new();
    let mut drifts = Vec::new();
    let mut notes = Vec::new();
    let named = |changes: &[DirectionChange], directions: &[Direction]| -> Vec<(Direction, f64)> {
        let chosen: Vec<&DirectionChange> = changes
            .iter()
            .filter(|c| directions.contains(&c.direction) && c.drifted(k))
            .collect();
        let chosen = if chosen.is_empty() {
            // Together beyond the threshold, neither alone: name the larger.
            changes
                .iter()
                .filter(|c| directions.contains(&c.direction) && c.seen)
                .max_by(|a, b| {
                    (a.change / a.sigma)
                        .abs()
                        .total_cmp(&(b.change / b.sigma).abs())
                })
                .into_iter()
                .collect()
        } else {
            chosen
        };
        chosen.iter().map(|c| (c.direction, c.change)).collect()
    };
    let words = |changes: &[(Direction, f64)]| -> String {
        changes
            .iter()
            .map(|(d, change)| d.words(*change))
            .collect::<Vec<_>>()
            .join(" and ")
    };
    if let Some((tilt, sigma)) = tilt_of(&ground) {
        let passed = tilt <= k * sigma;
        checks.push(Check {
            name: "ground tilt θ",
            measured: tilt,
            threshold: k * sigma,
            unit: Unit::Angle,
            passed,
        });
        if !passed {
            let changes = named(&ground, &[Direction::Roll, Direction::Pitch]);
            reasons.push(format!(
                "the ground says the sensor is {} than the active calibration says",
                words(&changes)
            ));
            drifts.push(Drift {
                witness: Witness::Ground,
                changes,
                ground_disagrees: false,
            });
        }
    }
    for (direction, name, unit) in [
        (Direction::Height, "height e_d", Unit::Length),
        (Direction::Yaw, "yaw", Unit::Angle),
        (Direction::Forward, "forward position", Unit::Length),
        (Direction::Sideways, "sideways position", Unit::Length),
    ] {
        let Some(c) = ground.iter().find(|c| c.direction == direction && c.seen) else {
            continue;
        };
        let passed = !c.drifted(k);
        checks.push(Check {
            name,
            measured: c.change.abs(),
            threshold: k * c.sigma,
            unit,
            passed,
        });
        if !passed {
            reasons.push(format!(
                "the ground says the sensor is {} than the active calibration says",
                direction.words(c.change)
            ));
            drifts.push(Drift {
                witness: Witness::Ground,
                changes: vec![(direction, c.change)],
                ground_disagrees: false,
            });
        }
    }
    if let Some((tilt, sigma)) = tilt_of(&gravity) {
        let passed = tilt <= k * sigma;
        checks.push(Check {
            name: "gravity",
            measured: tilt,
            threshold: k * sigma,
            unit: Unit::Angle,
            passed,
        });
        if !passed {
            let ground_agrees = ground.is_empty()
                || checks
                    .iter()
                    .any(|c| c.name == "ground tilt θ" && !c.passed);
            let changes = named(&gravity, &[Direction::Roll, Direction::Pitch]);
            let said = words(&changes);
            drifts.push(Drift {
                witness: Witness::Gravity,
                changes,
                ground_disagrees: !ground_agrees,
            });
            if ground_agrees {
                reasons.push(format!(
                    "the accelerometer says the sensor is {said} than the active calibration says"
                ));
            } else {
                reasons.push(format!(
                    "the accelerometer says the sensor is {said} than the active calibration says, \
                     but the ground does not: the robot may stand on a slope, or the accelerometer moved in the Kinect"
                ));
            }
        }
    }
    let unseen: Vec<&str> = Direction::ALL
        .iter()
        .filter(|d| !ground.iter().any(|c| c.direction == **d && c.seen))
        .map(|d| d.name())
        .collect();
    if !unseen.is_empty() && !ground.is_empty() {
        notes.push(format!(
            "not checked (these poses cannot see it): {}; tilted poses (--poses N) see the yaw and more",
            unseen.join(", ")
        ));
    }
    Ok(VerifyReport {
        poses: comparisons,
        ground,
        gravity,
        checks,
        reasons,
        drifts,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{ground_in_sensor, PoseDegMm};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn mount() -> PoseParams {
        PoseDegMm::from_values([0.8, -33.0, 1.5, 510.0, 370.0, 15.0]).to_params()
    }

    fn normal(rng: &mut impl Rng) -> f64 {
        let u1: f64 = 1.0 - rng.gen::<f64>();
        let u2: f64 = rng.gen();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    fn noise() -> NoiseModel {
        NoiseModel {
            normal_sigma_deg: 0.0043,
            offset_sigma_mm: 0.058,
        }
    }

    fn settings() -> VerifySettings {
        VerifySettings {
            noise: noise(),
            accelerometer_sigma_deg: 0.1,
            k_sigma: 4.0,
        }
    }

    /// Body poses: home, then rolled and pitched by ±`tilt_deg`.
    fn bodies(tilted: usize, tilt_deg: f64) -> Vec<Transform> {
        let mut out = vec![PoseDegMm::from_values([0.0, 0.0, 0.0, 0.0, 600.0, 0.0])];
        for k in 0..tilted {
            let s = if k % 2 == 0 { tilt_deg } else { -tilt_deg };
            let (beta, gamma) = if (k / 2) % 2 == 0 { (0.0, s) } else { (s, 0.0) };
            out.push(PoseDegMm::from_values([0.0, beta, gamma, 0.0, 600.0, 0.0]));
        }
        out.iter().map(|p| p.to_params().to_transform()).collect()
    }

    /// Poses measured with `truth` as the real mount, with the noise of
    /// `settings` (ground) and `readings` accelerometer readings.
    fn measure(truth: &PoseParams, bodies: &[Transform], rng: &mut impl Rng) -> Vec<VerifyPose> {
        let s = settings();
        bodies
            .iter()
            .enumerate()
            .map(|(k, body)| {
                let ground_from_sensor = body * truth.to_transform();
                let plane = ground_in_sensor(&ground_from_sensor);
                let jitter = |rng: &mut ChaCha8Rng, sigma: f64, v: Vector3<f64>| {
                    let [b1, b2] = tangent_basis(&v);
                    (v + b1 * sigma * normal(rng) + b2 * sigma * normal(rng)).normalize()
                };
                let mut local = ChaCha8Rng::seed_from_u64(rng.gen());
                let normal_sigma = s.noise.normal_sigma_deg.to_radians();
                let plane = Plane {
                    normal: jitter(&mut local, normal_sigma, plane.normal),
                    d: plane.d + s.noise.offset_sigma_mm / 1000.0 * normal(&mut local),
                };
                let up = ground_in_sensor(&ground_from_sensor).normal;
                let readings = 10;
                let gravity = jitter(
                    &mut local,
                    s.accelerometer_sigma_deg.to_radians() / (readings as f64).sqrt(),
                    up,
                );
                VerifyPose {
                    index: k as u32,
                    ground_from_robot: *body,
                    plane: Some(plane),
                    gravity_up: Some(gravity),
                    gravity_readings: readings,
                }
            })
            .collect()
    }

    fn active() -> ActiveMount {
        ActiveMount {
            robot_from_sensor: mount(),
            sigma: Some([
                0.002f64.to_radians(),
                0.002f64.to_radians(),
                0.002f64.to_radians(),
                0.05e-3,
                0.05e-3,
                0.05e-3,
            ]),
            correlations: None,
            depth_scale: 1.0,
            depth_scale_sigma: None,
            depth_scale_correlations: None,
        }
    }

    /// The true mount knocked by `omega` (robot axes, radians) about the
    /// sensor's centre, and moved by `shift` (metres).
    fn knocked(omega: Vector3<f64>, shift: Vector3<f64>) -> PoseParams {
        let t = mount().to_transform();
        let turned = Rotation3::from_scaled_axis(omega) * t.rotation;
        PoseParams::from_rotation_translation(turned.matrix(), t.translation.vector + shift)
    }

    #[test]
    fn a_consistent_sensor_passes_almost_always() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for tilted in [0, 4] {
            let mut false_alarms = 0;
            for _ in 0..500 {
                let poses = measure(&mount(), &bodies(tilted, 8.0), &mut rng);
                if verify(&active(), &poses, &settings()).unwrap().drifted() {
                    false_alarms += 1;
                }
            }
            // Six tests at k = 4: about 1 in 1000 runs; 1 in 50 is the limit.
            assert!(
                false_alarms <= 3,
                "{false_alarms} of 500 with {tilted} tilted poses"
            );
        }
    }

    #[test]
    fn a_still_stance_sees_roll_pitch_and_height_and_names_them() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let cases = [
            (
                Vector3::new(0.1f64.to_radians(), 0.0, 0.0),
                Vector3::zeros(),
                "more to the right",
            ),
            (
                Vector3::new(-0.1f64.to_radians(), 0.0, 0.0),
                Vector3::zeros(),
                "more to the left",
            ),
            (
                Vector3::new(0.0, 0.0, 0.1f64.to_radians()),
                Vector3::zeros(),
                "pitched 0.1",
            ),
            (Vector3::zeros(), Vector3::new(0.0, 0.001, 0.0), "higher"),
            (Vector3::zeros(), Vector3::new(0.0, -0.001, 0.0), "lower"),
        ];
        for (omega, shift, said) in cases {
            for _ in 0..20 {
                let poses = measure(&knocked(omega, shift), &bodies(0, 0.0), &mut rng);
                let report = verify(&active(), &poses, &settings()).unwrap();
                assert!(report.drifted(), "{said}: {report:?}");
                assert!(
                    report.reasons.iter().any(|r| r.contains(said)),
                    "{said}: {:?}",
                    report.reasons
                );
            }
        }
        // The yaw is not seen by one stance, and said so.
        let poses = measure(
            &knocked(Vector3::new(0.0, 0.01, 0.0), Vector3::zeros()),
            &bodies(0, 0.0),
            &mut rng,
        );
        let report = verify(&active(), &poses, &settings()).unwrap();
        assert!(!report.drifted(), "{report:?}");
        assert!(report.notes[0].contains("yaw"), "{:?}", report.notes);
    }

    #[test]
    fn tilted_poses_see_the_yaw() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for sign in [1.0, -1.0] {
            for _ in 0..20 {
                let omega = Vector3::new(0.0, sign * 0.2f64.to_radians(), 0.0);
                let poses = measure(&knocked(omega, Vector3::zeros()), &bodies(4, 8.0), &mut rng);
                let report = verify(&active(), &poses, &settings()).unwrap();
                assert!(
                    report.reasons.iter().any(|r| r.contains("turned 0.")),
                    "{report:?}"
                );
                let side = if sign > 0.0 { "left" } else { "right" };
                assert!(
                    report.reasons.iter().any(|r| r.contains(side)),
                    "{report:?}"
                );
            }
        }
    }

    #[test]
    fn gravity_alone_catches_half_a_degree() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for _ in 0..20 {
            let omega = Vector3::new(0.0, 0.0, -0.5f64.to_radians());
            let mut poses = measure(&knocked(omega, Vector3::zeros()), &bodies(0, 0.0), &mut rng);
            for p in &mut poses {
                p.plane = None;
            }
            let report = verify(&active(), &poses, &settings()).unwrap();
            assert!(
                report.reasons.iter().any(|r| r.contains("accelerometer")
                    && r.contains("pitched 0.")
                    && r.contains("down")),
                "{report:?}"
            );
            // A pitch about the body's sideways axis is nearly the motor's own.
            let turn = report.motor_turn().unwrap().to_degrees();
            assert!((turn + 0.5).abs() < 0.1, "{turn}");
        }
    }

    #[test]
    fn nothing_measured_is_an_error() {
        let poses = vec![VerifyPose {
            index: 0,
            ground_from_robot: Transform::identity(),
            plane: None,
            gravity_up: None,
            gravity_readings: 0,
        }];
        assert_eq!(
            verify(&active(), &poses, &settings()),
            Err(VerifyError::NothingMeasured)
        );
    }
}
