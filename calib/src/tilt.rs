//! One calibration for every tilt of the Kinect's motor: from calibrations
//! at two or more tilts, the motor's axis and pivot on the body, so that
//! `robot_from_sensor` is known at any tilt in between.
//!
//! The model: `robot_from_sensor(t) = robot_from_motor · R(axis, t) ·
//! motor_from_sensor`. Written against one calibrated tilt `t₀` (the
//! reference), with the axis `a` and a point `c` on it in the robot frame:
//!
//! ```text
//! R(t) = Rot(a, k·(t − t₀)) · R₀        p(t) = c + Rot(a, k·(t − t₀)) · (p₀ − c)
//! ```
//!
//! `k` is the motor's turn per commanded degree (1 for a motor that reaches
//! what it is asked; the fit says what it did). The axis and rate come from
//! the relative rotations `R_i·R₀ᵀ` (their rotation vectors `v_i ≈ a·k·Δt_i`,
//! by least squares); the pivot from `(I − Rot_i)·c = p_i − Rot_i·p₀`, with
//! its component along the axis (which no tilt can see) taken from `p₀`.

use nalgebra::{Matrix3, Rotation3, Unit, Vector3};

use super::geometry::PoseParams;

/// One calibration at one tilt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltCalibration {
    /// The motor's commanded angle, degrees.
    pub tilt_deg: f64,
    pub robot_from_sensor: PoseParams,
    /// σ of α, β, γ (radians) and p (metres).
    pub sigma: [f64; 6],
}

/// The motor on the body, fitted from calibrations at several tilts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltModel {
    /// The reference calibration.
    pub reference_tilt_deg: f64,
    pub reference: PoseParams,
    /// The motor's axis in the robot frame (unit; positive tilts turn the
    /// sensor about it by the right-hand rule).
    pub axis: Vector3<f64>,
    /// The sensor's turn per commanded degree.
    pub rate: f64,
    /// A point of the axis in the robot frame, metres.
    pub pivot: Vector3<f64>,
    /// One σ of the axis's direction (radians) and of the pivot across the
    /// axis (metres), from the calibrations' σ.
    pub axis_sigma: f64,
    pub pivot_sigma: f64,
    /// The largest disagreement of a calibration with the model: angle
    /// (radians) and position (metres).
    pub residual_angle: f64,
    pub residual_position: f64,
    /// The calibrated range of tilts, degrees.
    pub range_deg: (f64, f64),
}

/// Why no model could be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TiltError {
    #[error("a tilt model needs calibrations at two or more different tilts, not {0}")]
    TooFew(usize),
    #[error(
        "the calibrations at different tilts show no turn of the sensor: the motor did not move"
    )]
    NoTurn,
}

impl TiltModel {
    /// The mount at `tilt_deg`.
    pub fn at(&self, tilt_deg: f64) -> PoseParams {
        let turn = Rotation3::from_axis_angle(
            &Unit::new_normalize(self.axis),
            (self.rate * (tilt_deg - self.reference_tilt_deg)).to_radians(),
        );
        let rotation = turn.matrix() * self.reference.rotation_matrix();
        let position = self.pivot + turn * (self.reference.translation - self.pivot);
        PoseParams::from_rotation_translation(&rotation, position)
    }

    /// Whether `tilt_deg` lies within the calibrated range (half a degree of
    /// slack: the motor's own step).
    pub fn covers(&self, tilt_deg: f64) -> bool {
        (self.range_deg.0 - 0.5..=self.range_deg.1 + 0.5).contains(&tilt_deg)
    }
}

/// Fits the motor's axis, rate and pivot; the reference is the calibration
/// nearest `reference_tilt_deg`.
pub fn fit(
    calibrations: &[TiltCalibration],
    reference_tilt_deg: f64,
) -> Result<TiltModel, TiltError> {
    let Some(reference) = calibrations.iter().min_by(|a, b| {
        (a.tilt_deg - reference_tilt_deg)
            .abs()
            .total_cmp(&(b.tilt_deg - reference_tilt_deg).abs())
    }) else {
        return Err(TiltError::TooFew(0));
    };
    let others: Vec<&TiltCalibration> = calibrations
        .iter()
        .filter(|c| (c.tilt_deg - reference.tilt_deg).abs() > 0.25)
        .collect();
    if others.is_empty() {
        return Err(TiltError::TooFew(calibrations.len()));
    }
    let r0 = reference.robot_from_sensor.rotation_matrix();
    // v_i = log(R_i R₀ᵀ) ≈ a·k·Δt_i: least squares for a·k (per radian of command).
    let (mut numerator, mut denominator) = (Vector3::zeros(), 0.0);
    for c in &others {
        let dt = (c.tilt_deg - reference.tilt_deg).to_radians();
        let relative = Rotation3::from_matrix_unchecked(
            c.robot_from_sensor.rotation_matrix() * r0.transpose(),
        );
        numerator += relative.scaled_axis() * dt;
        denominator += dt * dt;
    }
    let axis_rate = numerator / denominator;
    let rate = axis_rate.norm();
    if rate < 1e-3 {
        return Err(TiltError::NoTurn);
    }
    let axis = axis_rate / rate;

    // The pivot: (I − Rot_i)·c = p_i − Rot_i·p₀, plus c·a = p₀·a.
    let p0 = reference.robot_from_sensor.translation;
    let mut normal = axis * axis.transpose();
    let mut rhs = axis * axis.dot(&p0);
    for c in &others {
        let turn = Rotation3::from_axis_angle(
            &Unit::new_normalize(axis),
            rate * (c.tilt_deg - reference.tilt_deg).to_radians(),
        );
        let m: Matrix3<f64> = Matrix3::identity() - turn.matrix();
        normal += m.transpose() * m;
        rhs += m.transpose() * (c.robot_from_sensor.translation - turn * p0);
    }
    let pivot = normal.try_inverse().map_or(p0, |inverse| inverse * rhs);

    let mut model = TiltModel {
        reference_tilt_deg: reference.tilt_deg,
        reference: reference.robot_from_sensor,
        axis,
        rate,
        pivot,
        axis_sigma: 0.0,
        pivot_sigma: 0.0,
        residual_angle: 0.0,
        residual_position: 0.0,
        range_deg: calibrations
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), c| {
                (l.min(c.tilt_deg), h.max(c.tilt_deg))
            }),
    };
    // σ: each relative rotation's axis is uncertain by the two calibrations'
    // angle σ over its turn; the pivot by their position σ over the chord.
    let angle_sigma = |c: &TiltCalibration| c.sigma[..3].iter().fold(0.0f64, |m, s| m.max(*s));
    let position_sigma = |c: &TiltCalibration| c.sigma[3..].iter().fold(0.0f64, |m, s| m.max(*s));
    let (mut axis_information, mut pivot_information) = (0.0, 0.0);
    for c in &others {
        let turn = (rate * (c.tilt_deg - reference.tilt_deg).to_radians()).abs();
        let sa = (angle_sigma(c).powi(2) + angle_sigma(reference).powi(2)).sqrt();
        let sp = (position_sigma(c).powi(2) + position_sigma(reference).powi(2)).sqrt();
        axis_information += (turn / sa.max(1e-12)).powi(2);
        pivot_information += (2.0 * (turn / 2.0).sin() / sp.max(1e-12)).powi(2);
    }
    model.axis_sigma = 1.0 / axis_information.sqrt();
    model.pivot_sigma = 1.0 / pivot_information.sqrt();
    for c in calibrations {
        let predicted = model.at(c.tilt_deg);
        let angle = Rotation3::from_matrix_unchecked(
            predicted.rotation_matrix() * c.robot_from_sensor.rotation_matrix().transpose(),
        )
        .angle();
        let position = (predicted.translation - c.robot_from_sensor.translation).norm();
        model.residual_angle = model.residual_angle.max(angle);
        model.residual_position = model.residual_position.max(position);
    }
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{rot_z, PoseDegMm};

    /// A Kinect whose motor turns it about its own right axis through a
    /// pivot 30 mm below its optical centre, at 0.98° per commanded degree.
    fn truth(tilt_deg: f64) -> PoseParams {
        let mount = PoseDegMm::from_values([0.8, -33.0, 1.5, 510.0, 370.0, 15.0]).to_params();
        let r = mount.rotation_matrix();
        let pivot = mount.translation - r * Vector3::new(0.0, 0.03, 0.0);
        let turn = r * rot_z((0.98 * (tilt_deg + 20.0)).to_radians()) * r.transpose();
        PoseParams::from_rotation_translation(
            &(turn * r),
            pivot + turn * (mount.translation - pivot),
        )
    }

    fn calibrations(tilts: &[f64]) -> Vec<TiltCalibration> {
        tilts
            .iter()
            .map(|&tilt_deg| TiltCalibration {
                tilt_deg,
                robot_from_sensor: truth(tilt_deg),
                sigma: [3e-5, 3e-5, 3e-5, 5e-5, 5e-5, 5e-5],
            })
            .collect()
    }

    #[test]
    fn recovers_the_axis_rate_and_pivot_and_predicts_a_tilt_never_calibrated() {
        let model = fit(&calibrations(&[-25.0, -15.0, -5.0]), -20.0).unwrap();
        let mount = truth(-20.0);
        let true_axis = mount.rotation_matrix() * Vector3::z();
        assert!(model.axis.angle(&true_axis) < 1e-9, "{model:?}");
        assert!((model.rate - 0.98).abs() < 1e-9);
        // The pivot lies on the true axis through the true pivot.
        let true_pivot = mount.translation - mount.rotation_matrix() * Vector3::new(0.0, 0.03, 0.0);
        let off = (model.pivot - true_pivot).cross(&true_axis).norm();
        assert!(off < 1e-9, "{off}");
        for tilt in [-10.0, -22.5, -5.0] {
            let (p, t) = (model.at(tilt), truth(tilt));
            let angle = Rotation3::from_matrix_unchecked(
                p.rotation_matrix() * t.rotation_matrix().transpose(),
            )
            .angle();
            assert!(
                angle < 1e-9 && (p.translation - t.translation).norm() < 1e-9,
                "{tilt}"
            );
        }
        assert!(model.covers(-10.0) && !model.covers(0.0));
        assert!(model.axis_sigma > 0.0 && model.axis_sigma < 1e-3);
    }

    #[test]
    fn one_tilt_or_a_motor_that_never_moved_is_an_error() {
        assert_eq!(
            fit(&calibrations(&[-20.0]), -20.0),
            Err(TiltError::TooFew(1))
        );
        let mut same = calibrations(&[-20.0, -10.0]);
        same[1].robot_from_sensor = same[0].robot_from_sensor;
        assert_eq!(fit(&same, -20.0), Err(TiltError::NoTurn));
    }
}
