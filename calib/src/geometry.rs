//! Frames, the paper's six-parameter poses, and planes.
//!
//! Everything follows `shared/spec/conventions.md`: a pose `a_from_b` maps
//! coordinates in frame `b` to frame `a`; the six parameters are the paper's
//! X-Y-Z fixed angles (`R = Ry(α)·Rz(β)·Rx(γ)`) and a translation. Code works in
//! radians and metres; files carry degrees and millimetres ([`PoseDegMm`]).

use nalgebra::{
    IsometryMatrix3, Matrix3, Matrix4, Rotation3, Translation3, UnitQuaternion, Vector3,
};
use serde::{Deserialize, Serialize};

/// A rigid transform `a_from_b`: `p_a = rotation · p_b + translation` (metres).
pub type Transform = IsometryMatrix3<f64>;

/// The paper's six parameters of a pose (eq. 1-3 and 17-19), in radians and metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseParams {
    /// Rotation about the parent's Y axis, applied last.
    pub alpha: f64,
    /// Rotation about the parent's Z axis, applied second.
    pub beta: f64,
    /// Rotation about the parent's X axis, applied first.
    pub gamma: f64,
    /// Translation in the parent frame, metres.
    pub translation: Vector3<f64>,
}

/// `Rx(a)` of conventions.md.
pub fn rot_x(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

/// `Ry(a)` of conventions.md.
pub fn rot_y(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

/// `Rz(a)` of conventions.md.
pub fn rot_z(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// Derivative of `Rx(a)` with respect to `a`.
pub fn d_rot_x(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(0.0, 0.0, 0.0, 0.0, -s, -c, 0.0, c, -s)
}

/// Derivative of `Ry(a)` with respect to `a`.
pub fn d_rot_y(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(-s, 0.0, c, 0.0, 0.0, 0.0, -c, 0.0, -s)
}

/// Derivative of `Rz(a)` with respect to `a`.
pub fn d_rot_z(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(-s, -c, 0.0, c, -s, 0.0, 0.0, 0.0, 0.0)
}

impl PoseParams {
    /// A pose from the six parameters.
    pub fn new(alpha: f64, beta: f64, gamma: f64, translation: Vector3<f64>) -> Self {
        Self {
            alpha,
            beta,
            gamma,
            translation,
        }
    }

    /// The identity pose.
    pub fn identity() -> Self {
        Self::new(0.0, 0.0, 0.0, Vector3::zeros())
    }

    /// The rotation `Ry(α)·Rz(β)·Rx(γ)` (paper eq. 2).
    pub fn rotation_matrix(&self) -> Matrix3<f64> {
        rot_y(self.alpha) * rot_z(self.beta) * rot_x(self.gamma)
    }

    /// The pose as a rigid transform.
    pub fn to_transform(&self) -> Transform {
        Transform::from_parts(
            Translation3::from(self.translation),
            Rotation3::from_matrix_unchecked(self.rotation_matrix()),
        )
    }

    /// The homogeneous 4×4 matrix with the translation in metres.
    pub fn to_matrix(&self) -> Matrix4<f64> {
        self.to_transform().to_homogeneous()
    }

    /// The six parameters of a rotation matrix and translation (conventions.md).
    ///
    /// `|β| < 90°` is assumed; at `|β| = 90°` the split between α and γ is
    /// arbitrary (gimbal lock) and γ is set to zero.
    pub fn from_rotation_translation(rotation: &Matrix3<f64>, translation: Vector3<f64>) -> Self {
        let sin_beta = rotation[(1, 0)].clamp(-1.0, 1.0);
        let beta = sin_beta.asin();
        let (alpha, gamma) = if sin_beta.abs() < 1.0 - 1e-12 {
            (
                (-rotation[(2, 0)]).atan2(rotation[(0, 0)]),
                (-rotation[(1, 2)]).atan2(rotation[(1, 1)]),
            )
        } else {
            // Gimbal lock: only α ± γ is defined; put it all in α.
            ((rotation[(0, 2)]).atan2(rotation[(2, 2)]), 0.0)
        };
        Self::new(alpha, beta, gamma, translation)
    }

    /// The six parameters of a rigid transform.
    pub fn from_transform(transform: &Transform) -> Self {
        Self::from_rotation_translation(transform.rotation.matrix(), transform.translation.vector)
    }

    /// The rotation as a unit quaternion.
    pub fn quaternion(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
            self.rotation_matrix(),
        ))
    }

    /// The six parameters from a unit quaternion and a translation.
    pub fn from_quaternion(quaternion: &UnitQuaternion<f64>, translation: Vector3<f64>) -> Self {
        Self::from_rotation_translation(quaternion.to_rotation_matrix().matrix(), translation)
    }

    /// The parameters as a vector `[α, β, γ, px, py, pz]` (radians, metres).
    pub fn to_vector(&self) -> nalgebra::Vector6<f64> {
        nalgebra::Vector6::new(
            self.alpha,
            self.beta,
            self.gamma,
            self.translation.x,
            self.translation.y,
            self.translation.z,
        )
    }

    /// The inverse of [`PoseParams::to_vector`].
    pub fn from_vector(v: &nalgebra::Vector6<f64>) -> Self {
        Self::new(v[0], v[1], v[2], Vector3::new(v[3], v[4], v[5]))
    }
}

/// A pose as files and messages carry it: degrees and millimetres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseDegMm {
    pub alpha_deg: f64,
    pub beta_deg: f64,
    pub gamma_deg: f64,
    pub px_mm: f64,
    pub py_mm: f64,
    pub pz_mm: f64,
}

impl PoseDegMm {
    /// Converts to radians and metres.
    pub fn to_params(&self) -> PoseParams {
        PoseParams::new(
            self.alpha_deg.to_radians(),
            self.beta_deg.to_radians(),
            self.gamma_deg.to_radians(),
            Vector3::new(self.px_mm, self.py_mm, self.pz_mm) / 1000.0,
        )
    }

    /// Converts from radians and metres.
    pub fn from_params(p: &PoseParams) -> Self {
        Self {
            alpha_deg: p.alpha.to_degrees(),
            beta_deg: p.beta.to_degrees(),
            gamma_deg: p.gamma.to_degrees(),
            px_mm: p.translation.x * 1000.0,
            py_mm: p.translation.y * 1000.0,
            pz_mm: p.translation.z * 1000.0,
        }
    }

    /// All six values, for validation.
    pub fn values(&self) -> [f64; 6] {
        [
            self.alpha_deg,
            self.beta_deg,
            self.gamma_deg,
            self.px_mm,
            self.py_mm,
            self.pz_mm,
        ]
    }

    /// From `[α, β, γ, x, y, z]` (degrees, mm): the inverse of [`Self::values`].
    pub fn from_values(v: [f64; 6]) -> Self {
        Self {
            alpha_deg: v[0],
            beta_deg: v[1],
            gamma_deg: v[2],
            px_mm: v[3],
            py_mm: v[4],
            pz_mm: v[5],
        }
    }

    /// Whether every value is a finite number.
    pub fn is_finite(&self) -> bool {
        self.values().iter().all(|v| v.is_finite())
    }
}

/// `sensor_from_optical`: `X_V = z_O`, `Y_V = -y_O`, `Z_V = x_O` (conventions.md).
pub fn sensor_from_optical() -> Matrix3<f64> {
    Matrix3::new(0.0, 0.0, 1.0, 0.0, -1.0, 0.0, 1.0, 0.0, 0.0)
}

/// A plane `n·x + d = 0` with `|n| = 1` and `d ≥ 0`: the normal points from the
/// plane towards the origin of its frame, and `d` is the origin's height above it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub normal: Vector3<f64>,
    /// Distance from the frame's origin to the plane, metres.
    pub d: f64,
}

/// Why four numbers are not a plane.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlaneError {
    #[error("the plane's coefficients are not all finite numbers")]
    NotFinite,
    #[error("the plane's normal (a, b, c) is zero")]
    ZeroNormal,
}

impl Plane {
    /// A plane from `a·x + b·y + c·z + d = 0`, normalised and oriented to `d ≥ 0`.
    pub fn from_coefficients(a: f64, b: f64, c: f64, d: f64) -> Result<Self, PlaneError> {
        if ![a, b, c, d].iter().all(|v| v.is_finite()) {
            return Err(PlaneError::NotFinite);
        }
        // Scale first: the norm of huge coefficients (|a| > 1e154) would overflow.
        let largest = [a, b, c, d].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let (a, b, c, d) = if largest > 0.0 {
            (a / largest, b / largest, c / largest, d / largest)
        } else {
            (a, b, c, d)
        };
        let normal = Vector3::new(a, b, c);
        let norm = normal.norm();
        if norm < 1e-12 {
            return Err(PlaneError::ZeroNormal);
        }
        let sign = if d < 0.0 { -1.0 } else { 1.0 };
        Ok(Self {
            normal: normal * (sign / norm),
            d: d * sign / norm,
        })
    }

    /// The plane through `point` with the given (not necessarily oriented) normal.
    pub fn through(normal: Vector3<f64>, point: &Vector3<f64>) -> Result<Self, PlaneError> {
        Self::from_coefficients(normal.x, normal.y, normal.z, -normal.dot(point))
    }

    /// Signed distance of a point: positive on the side of the frame's origin.
    pub fn signed_distance(&self, point: &Vector3<f64>) -> f64 {
        self.normal.dot(point) + self.d
    }

    /// The same plane expressed in frame `a`, given `a_from_b` with `self` in `b`.
    pub fn transformed(&self, a_from_b: &Transform) -> Self {
        let normal = a_from_b.rotation * self.normal;
        let d = self.d - normal.dot(&a_from_b.translation.vector);
        // Re-orient: the origin of `a` may lie on the other side.
        if d < 0.0 {
            Self {
                normal: -normal,
                d: -d,
            }
        } else {
            Self { normal, d }
        }
    }

    /// Angle between the normals of two planes, radians.
    pub fn angle_to(&self, other: &Plane) -> f64 {
        angle_between(&self.normal, &other.normal)
    }
}

/// Angle between two vectors, radians, accurate for small and large angles alike.
pub fn angle_between(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b))
}

/// The ground `y_G = 0` seen from the sensor: row 1 of `ground_from_sensor`
/// (paper eq. 27-28; conventions.md).
pub fn ground_in_sensor(ground_from_sensor: &Transform) -> Plane {
    let r = ground_from_sensor.rotation.matrix();
    let normal = Vector3::new(r[(1, 0)], r[(1, 1)], r[(1, 2)]);
    let d = ground_from_sensor.translation.vector.y;
    // `d` is the sensor's height above the ground; it is positive whenever the
    // sensor is above the ground, which is the only case that is seen.
    Plane { normal, d }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    /// Paper eq. (32) → eq. (33), to the four decimals printed.
    #[test]
    fn paper_eq32_gives_eq33() {
        let pose = PoseDegMm {
            alpha_deg: -0.4398,
            beta_deg: -37.4072,
            gamma_deg: -3.0471,
            px_mm: 527.8885,
            py_mm: 364.8007,
            pz_mm: -33.4003,
        }
        .to_params();
        let m = pose.to_matrix();
        let expected = [
            [0.7943, 0.6070, 0.0246, 0.5278885],
            [-0.6075, 0.7932, 0.0422, 0.3648007],
            [0.0061, -0.0485, 0.9988, -0.0334003],
            [0.0, 0.0, 0.0, 1.0],
        ];
        for (i, row) in expected.iter().enumerate() {
            for (j, value) in row.iter().enumerate() {
                assert!(
                    (m[(i, j)] - value).abs() <= 0.5e-4 + 1e-12,
                    "entry ({i},{j}) is {} but eq. 33 prints {value}",
                    m[(i, j)]
                );
            }
        }
    }

    #[test]
    fn parameters_round_trip_through_matrix_and_quaternion() {
        let pose = PoseParams::new(0.3, -0.6, 1.2, Vector3::new(0.5, 0.36, -0.03));
        let back = PoseParams::from_transform(&pose.to_transform());
        assert_abs_diff_eq!(back.to_vector(), pose.to_vector(), epsilon = 1e-12);
        let back = PoseParams::from_quaternion(&pose.quaternion(), pose.translation);
        assert_abs_diff_eq!(back.to_vector(), pose.to_vector(), epsilon = 1e-12);
    }

    #[test]
    fn derivatives_of_elementary_rotations_match_finite_differences() {
        let h = 1e-7;
        for a in [-2.0, -0.3, 0.0, 0.7, 3.0] {
            for (f, df) in [
                (
                    rot_x as fn(f64) -> Matrix3<f64>,
                    d_rot_x as fn(f64) -> Matrix3<f64>,
                ),
                (rot_y, d_rot_y),
                (rot_z, d_rot_z),
            ] {
                let numeric = (f(a + h) - f(a - h)) / (2.0 * h);
                assert_abs_diff_eq!(numeric, df(a), epsilon = 1e-8);
            }
        }
    }

    #[test]
    fn plane_is_normalised_and_oriented() {
        let p = Plane::from_coefficients(0.0, -2.0, 0.0, -1.0).unwrap();
        assert_abs_diff_eq!(p.normal, Vector3::new(0.0, 1.0, 0.0));
        assert_abs_diff_eq!(p.d, 0.5);
        assert!(Plane::from_coefficients(0.0, 0.0, 0.0, 1.0).is_err());
        assert!(Plane::from_coefficients(f64::NAN, 0.0, 1.0, 1.0).is_err());
        // Found by fuzzing: huge coefficients once overflowed to a zero normal.
        let p = Plane::from_coefficients(1e200, 0.0, 0.0, 1e199).unwrap();
        assert!((p.normal.norm() - 1.0).abs() < 1e-12 && (p.d - 0.1).abs() < 1e-12);
    }

    #[test]
    fn ground_row_matches_transformed_ground_plane() {
        let ground_from_sensor =
            PoseParams::new(0.1, -0.5, 0.2, Vector3::new(0.3, 0.9, -0.1)).to_transform();
        let ground_in_ground = Plane {
            normal: Vector3::y(),
            d: 0.0,
        };
        let transformed = ground_in_ground.transformed(&ground_from_sensor.inverse());
        let row = ground_in_sensor(&ground_from_sensor);
        assert_abs_diff_eq!(row.normal, transformed.normal, epsilon = 1e-12);
        assert_abs_diff_eq!(row.d, transformed.d, epsilon = 1e-12);
        // Every point of the plane, mapped to the ground, has y = 0.
        let on_plane = -row.normal * row.d + row.normal.cross(&Vector3::x()) * 0.7;
        assert_abs_diff_eq!(
            (ground_from_sensor * nalgebra::Point3::from(on_plane)).y,
            0.0,
            epsilon = 1e-12
        );
    }

    #[test]
    fn sensor_from_optical_is_a_proper_rotation() {
        let m = sensor_from_optical();
        assert_abs_diff_eq!(m.determinant(), 1.0);
        // The optical axis (z_O) is the sensor's X axis.
        assert_abs_diff_eq!(m * Vector3::z(), Vector3::x());
    }
}
