//! The result document of `shared/spec/cli.md`, and its readable table.
//!
//! Keys and units are the contract: degrees and millimetres in names ending
//! `_deg` and `_mm`, plane offsets in metres (`d_m`).
//!
//! The document is read back as well as written (`groundcal export`, the
//! store, the daemon's status): [`ResultJson::parse`] names the key of any
//! value that is wrong. `robot_from_sensor`'s numbers must be finite; any
//! other number may be `null`, which is how JSON writes a NaN or an infinite
//! σ, and reads back as NaN.

use serde::{Deserialize, Deserializer, Serialize};

use crate::calib::geometry::{Plane, PoseDegMm, PoseParams};
use crate::calib::observe::NominalMount;
use crate::calib::outcome::{Calibration, GateCheck, PoseOutcome, Verdict};
use crate::calib::sensor::{DepthModel, Intrinsics};

/// `robot_from_sensor` as cli.md prints it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MountJson {
    #[serde(deserialize_with = "finite")]
    pub alpha_deg: f64,
    #[serde(deserialize_with = "finite")]
    pub beta_deg: f64,
    #[serde(deserialize_with = "finite")]
    pub gamma_deg: f64,
    #[serde(deserialize_with = "finite")]
    pub px_mm: f64,
    #[serde(deserialize_with = "finite")]
    pub py_mm: f64,
    #[serde(deserialize_with = "finite")]
    pub pz_mm: f64,
    /// 4×4, translation in millimetres.
    #[serde(deserialize_with = "finite_4x4")]
    pub matrix: [[f64; 4]; 4],
    /// Always written; optional when read (older and other writers).
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "some_finite_4"
    )]
    pub quaternion_xyzw: Option<[f64; 4]>,
}

impl MountJson {
    /// The six parameters in the order α, β, γ, px, py, pz (degrees,
    /// millimetres).
    pub fn values(&self) -> [f64; 6] {
        self.pose().values()
    }

    /// The six parameters as a pose (the matrix and quaternion left out).
    pub fn pose(&self) -> PoseDegMm {
        PoseDegMm {
            alpha_deg: self.alpha_deg,
            beta_deg: self.beta_deg,
            gamma_deg: self.gamma_deg,
            px_mm: self.px_mm,
            py_mm: self.py_mm,
            pz_mm: self.pz_mm,
        }
    }

    pub fn from_params(p: &PoseParams) -> Self {
        let d = PoseDegMm::from_params(p);
        let m = p.to_matrix();
        let matrix = std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                if j == 3 && i < 3 {
                    m[(i, j)] * 1e3
                } else {
                    m[(i, j)]
                }
            })
        });
        let q = p.quaternion();
        // A fixed sign (w ≥ 0) so that equal rotations print equally.
        let sign = if q.w < 0.0 { -1.0 } else { 1.0 };
        Self {
            alpha_deg: d.alpha_deg,
            beta_deg: d.beta_deg,
            gamma_deg: d.gamma_deg,
            px_mm: d.px_mm,
            py_mm: d.py_mm,
            pz_mm: d.pz_mm,
            matrix,
            quaternion_xyzw: Some([q.i * sign, q.j * sign, q.k * sign, q.w * sign]),
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SigmaJson {
    #[serde(deserialize_with = "number_or_nan")]
    pub alpha_deg: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub beta_deg: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub gamma_deg: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub px_mm: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub py_mm: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub pz_mm: f64,
    /// σ of the depth scale, when it was estimated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_scale: Option<f64>,
}

impl SigmaJson {
    /// From σ in radians and metres, in the order α, β, γ, px, py, pz.
    /// σ in radians and metres, in the order α, β, γ, px, py, pz (the
    /// inverse of [`SigmaJson::from_radians_metres`]).
    pub fn radians_metres(&self) -> [f64; 6] {
        [
            self.alpha_deg.to_radians(),
            self.beta_deg.to_radians(),
            self.gamma_deg.to_radians(),
            self.px_mm / 1000.0,
            self.py_mm / 1000.0,
            self.pz_mm / 1000.0,
        ]
    }

    pub fn from_radians_metres(sigma: &[f64; 6]) -> Self {
        Self {
            alpha_deg: sigma[0].to_degrees(),
            beta_deg: sigma[1].to_degrees(),
            gamma_deg: sigma[2].to_degrees(),
            px_mm: sigma[3] * 1000.0,
            py_mm: sigma[4] * 1000.0,
            pz_mm: sigma[5] * 1000.0,
            depth_scale: None,
        }
    }
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct PlaneJson {
    #[serde(deserialize_with = "number_or_nan")]
    pub a: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub b: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub c: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub d_m: f64,
}

impl From<&Plane> for PlaneJson {
    fn from(p: &Plane) -> Self {
        Self {
            a: p.normal.x,
            b: p.normal.y,
            c: p.normal.z,
            d_m: p.d,
        }
    }
}

/// One pose of the input. A pose that gave no plane (no frames, no ground
/// found) has `used: false`, its reason, and no plane or errors.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PoseJson {
    pub index: u32,
    pub used: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub theta_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub e_d_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub inliers: Option<usize>,
    /// The measured ground in the sensor frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plane: Option<PlaneJson>,
    /// The ground the result predicts (paper's "theoretical ground", Table 3).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub predicted_plane: Option<PlaneJson>,
    /// A pose kept with a remark: a slipped foot left out of its body pose.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// The body pose that was asked for (`ground_from_robot`'s parameters:
    /// yaw α′, pitch β′, roll γ′, position; a recording's `commanded`), when
    /// the input has it (`replay`; not a planes file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commanded: Option<PoseDegMm>,
    /// The sensor's turn about the tilt motor's axis at this pose against
    /// the poses' mean, from the accelerometer (degrees; when recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motor_turn_deg: Option<f64>,
}

impl PoseJson {
    /// A pose that gave no plane.
    pub fn failed(index: u32, reason: String) -> Self {
        Self {
            index,
            used: false,
            reason: Some(reason),
            theta_deg: None,
            e_d_mm: None,
            inliers: None,
            plane: None,
            predicted_plane: None,
            note: None,
            commanded: None,
            motor_turn_deg: None,
        }
    }
}

impl From<&PoseOutcome> for PoseJson {
    fn from(p: &PoseOutcome) -> Self {
        Self {
            index: p.index,
            used: p.used,
            reason: p.reason.clone(),
            theta_deg: Some(p.theta.to_degrees()),
            e_d_mm: Some(p.e_d * 1e3),
            inliers: p.inliers,
            plane: Some((&p.measured).into()),
            predicted_plane: Some((&p.predicted).into()),
            note: p.note.clone(),
            commanded: None,
            motor_turn_deg: None,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SummaryJson {
    pub poses_used: usize,
    pub poses_total: usize,
    #[serde(deserialize_with = "number_or_nan")]
    pub theta_deg_mean: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub theta_deg_max: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub e_d_mm_mean: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub e_d_mm_max: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ObservabilityJson {
    #[serde(deserialize_with = "three_or_nan")]
    pub rotation_singular_values: [f64; 3],
    #[serde(deserialize_with = "three_or_nan")]
    pub translation_singular_values: [f64; 3],
    /// The rotation axis (robot frame, unit) the schedule pins down least:
    /// that of the smallest rotation singular value.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "some_three_or_nan"
    )]
    pub rotation_weakest_axis: Option<[f64; 3]>,
    /// The direction of the position (robot frame, unit) it pins down least.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "some_three_or_nan"
    )]
    pub translation_weakest_axis: Option<[f64; 3]>,
}

/// One quality gate as it was checked (`gate_checks[]`): the limit and the
/// value measured are in the unit of the gate's key (`theta_max_deg`:
/// degrees; `min_used_fraction`: a fraction; `observable`: the smallest
/// singular value, about the sine of the tilts' RMS spread).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GateCheckJson {
    pub gate: String,
    #[serde(deserialize_with = "number_or_nan")]
    pub limit: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub measured: f64,
    /// The measured value must be at least the limit (else at most).
    #[serde(default)]
    pub at_least: bool,
    pub passed: bool,
    /// Where the measured value comes from: "pose 7", "β", a direction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<String>,
    /// The same, typed (`{"kind": "pose", "index": 7}`, …), for a page that
    /// words it in its own language.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub place: Option<crate::calib::outcome::GatePlace>,
}

impl From<&GateCheck> for GateCheckJson {
    fn from(c: &GateCheck) -> Self {
        Self {
            gate: c.gate.to_string(),
            limit: c.limit,
            measured: c.measured,
            at_least: c.at_least,
            passed: c.passed,
            at: c.at.clone(),
            place: c.place,
        }
    }
}

/// How the input was made and solved, when it says (`replay` of a
/// recording; a planes file says none of it).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct SetupJson {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<String>,
    /// The schedule's name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedule: Option<String>,
    /// Poses in the input.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub poses: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_per_pose: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_model: Option<DepthModel>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intrinsics: Option<Intrinsics>,
    /// The rough mount the ground search started from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal_mount: Option<NominalMount>,
    /// Where the nominal mount came from: `recording` or `flag`
    /// (`--nominal-mount`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal_mount_from: Option<String>,
    /// Where the gates came from: `config` (`--config`), `recording` (its
    /// live run's) or `built-in`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gates_from: Option<String>,
}

/// The verdict (`"accepted"` or `"rejected"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ResultStatus {
    Accepted,
    Rejected,
}

impl ResultStatus {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Accepted => "accepted",
            Self::Rejected => "rejected",
        }
    }
}

impl<'de> Deserialize<'de> for ResultStatus {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        match serde_json::Value::deserialize(deserializer)? {
            serde_json::Value::String(s) if s == "accepted" => Ok(Self::Accepted),
            serde_json::Value::String(s) if s == "rejected" => Ok(Self::Rejected),
            other => Err(serde::de::Error::custom(format!(
                "is {other}, expected \"accepted\" or \"rejected\""
            ))),
        }
    }
}

/// What the accelerometer says of the tilt motor during a calibration.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct MotorJson {
    /// The tilt the session asked the motor for (relative to gravity).
    pub commanded_deg: f64,
    /// The motor's own reading, averaged over the poses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reported_deg: Option<f64>,
    /// The optical axis's pitch against the body's forward axis (negative
    /// down), from gravity in the sensor frame and the body's attitude from
    /// the feet: the angle the motor actually reached relative to the body.
    pub pitch_to_body_deg: f64,
    /// How far the sensor's turn about the motor's axis (from gravity,
    /// against the solved mount) ranged over the poses.
    pub turn_spread_deg: f64,
    /// The spread beyond which the motor moved.
    pub turn_limit_deg: f64,
    pub moved: bool,
    /// Poses with accelerometer readings.
    pub poses: usize,
}

/// The motor's model as the result carries it (degrees, millimetres).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TiltModelJson {
    /// The tilt of the reference calibration and its mount.
    pub reference_tilt_deg: f64,
    pub reference: MountJson,
    /// The motor's axis in the robot frame (unit).
    pub axis: [f64; 3],
    /// The sensor's turn per commanded degree.
    pub rate: f64,
    /// A point of the axis in the robot frame.
    pub pivot_mm: [f64; 3],
    /// One σ of the axis's direction and of the pivot across it.
    pub axis_sigma_deg: f64,
    pub pivot_sigma_mm: f64,
    /// The largest disagreement of a tilt's calibration with the model.
    pub residual_deg: f64,
    pub residual_mm: f64,
    /// The calibrated range of tilts.
    pub range_deg: [f64; 2],
}

/// One tilt's calibration, in brief.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TiltResultJson {
    pub tilt_deg: f64,
    pub status: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot_from_sensor: Option<MountJson>,
    /// The optical axis's pitch against the body, from gravity and the feet.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pitch_to_body_deg: Option<f64>,
}

/// The depth pattern a calibration found: per cell of `cell_px` pixels,
/// row-major from the top left, the raw units a reading there is off by
/// (more is farther; `null` where no pose saw the ground).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DepthPatternJson {
    /// Whether a pattern was found and the calibration corrected for it.
    pub corrected: bool,
    pub note: String,
    pub cell_px: usize,
    pub columns: usize,
    pub rows: usize,
    pub raw: Vec<Option<f64>>,
    pub sigma_raw: Vec<Option<f64>>,
    /// The largest depth error the pattern causes at 2 m, millimetres.
    pub largest_mm_at_2m: f64,
    /// RMS of its shape (less its plane part), raw units.
    pub shape_rms_raw: f64,
    /// The shape against none, χ² per degree of freedom (about 1: none).
    pub shape_chi2_per_dof: f64,
    /// The residuals cell by cell and pose by pose after the pattern, χ² per
    /// degree of freedom against the noise the poses' own scatter shows
    /// (about 1 by that noise's construction: a check, not a test).
    pub consistency_chi2_per_dof: f64,
    /// The shape's size in noise's σ above what the poses make with random
    /// signs: the test that there is a shape.
    #[serde(default)]
    pub shape_sigmas: f64,
    /// The share by which the pattern weakens a metre farther, and its σ.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub changes_with_depth: Option<[f64; 2]>,
    /// How far the residuals stay with the ground as the poses move, in
    /// noise's σ (uneven ground).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed_in_the_ground_sigmas: Option<f64>,
    /// Why a warp was not corrected: `changes_with_depth`,
    /// `ground_not_flat`, `cells_change` or `beyond_the_fit` (the pattern
    /// larger than the ground fit's band, so that neither could be told).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncorrected_because: Option<String>,
    /// Its plane part from the geometry across poses (raw units at the
    /// principal point, per 100 pixels along u and along v), with σ.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane_part_raw: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane_part_sigma_raw: Option<[f64; 3]>,
    pub plane_part_taken: bool,
    /// When the plane part was taken: σ of α, β, γ (degrees) had it been
    /// known exactly, beside the result's σ what correcting it cost (the
    /// gate `pattern_angle_sigma_growth_max` judges it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angle_sigma_known_plane_part_deg: Option<[f64; 3]>,
    /// A warp that stood out of the noise but was not corrected because it
    /// changed from pose to pose: its RMS at 2 m, millimetres (the gate
    /// `warp_max_mm` judges it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncorrected_mm_at_2m: Option<f64>,
    /// That warp is fixed in the image (the sensor's pattern), left
    /// uncorrected because the ground fit in use (the paper's) cannot.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub uncorrected_fixed: bool,
    /// That warp per cell (raw units, as `raw`), when the residuals showed
    /// a shape that was not corrected: what the sensor or the ground
    /// looked like, nothing applied.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncorrected_raw: Option<Vec<Option<f64>>>,
    /// Raw units per 1/m of inverse depth (the depth model's 1/b): the depth
    /// error at z metres is −z²·raw/raw_per_inverse_depth.
    pub raw_per_inverse_depth: f64,
    /// The shape to take out of the frames before fitting their ground
    /// again (the fit's band cut its peaks); not part of the document.
    #[serde(skip)]
    pub fit_again_about: Option<crate::calib::distortion::DepthCorrection>,
}

/// Most ground fits of one calibration: the first, and those about the
/// depth pattern's estimate as it grows (each cuts less of what is left).
pub const MOST_GROUND_FITS: usize = 4;

/// A figure the document can carry: JSON has no infinity (a test whose
/// null had no spread says "beyond any" as 10⁹).
fn finite_or_zero(value: f64) -> f64 {
    if value.is_nan() {
        0.0
    } else {
        value.clamp(-1e9, 1e9)
    }
}

impl DepthPatternJson {
    /// The pattern as the result carries it (cells to 0.001 raw units).
    pub fn from_pattern(p: &crate::calib::outcome::DepthPattern) -> Self {
        let thousandths = |v: &Option<f64>| v.map(|v| (v * 1e3).round() / 1e3);
        DepthPatternJson {
            corrected: p.corrected,
            note: p.note.clone().unwrap_or_default(),
            cell_px: p.cell_px,
            columns: p.columns,
            rows: p.rows,
            raw: p.raw.iter().map(thousandths).collect(),
            sigma_raw: p.sigma_raw.iter().map(thousandths).collect(),
            largest_mm_at_2m: p.largest_depth_error_m(2.0) * 1e3,
            shape_rms_raw: p.shape_rms_raw,
            shape_chi2_per_dof: p.shape_chi2_per_dof,
            consistency_chi2_per_dof: p.consistency_chi2_per_dof,
            shape_sigmas: finite_or_zero(p.shape_sigmas),
            changes_with_depth: p.changes_with_depth,
            fixed_in_the_ground_sigmas: p.fixed_in_the_ground_sigmas.map(finite_or_zero),
            uncorrected_because: p.uncorrected_because.map(|c| {
                use crate::calib::outcome::WarpCause;
                match c {
                    WarpCause::ChangesWithDepth { .. } => "changes_with_depth",
                    WarpCause::GroundNotFlat { .. } => "ground_not_flat",
                    WarpCause::CellsChange { .. } => "cells_change",
                    WarpCause::BeyondTheFit { .. } => "beyond_the_fit",
                }
                .to_string()
            }),
            plane_part_raw: p.plane_part,
            plane_part_sigma_raw: p.plane_part_sigma,
            plane_part_taken: p.plane_part_taken,
            angle_sigma_known_plane_part_deg: p
                .angle_sigma_known_plane_part
                .map(|s| s.map(f64::to_degrees)),
            uncorrected_mm_at_2m: p.uncorrected_shape_rms_raw.map(|raw| {
                crate::calib::outcome::depth_error_m(raw, 2.0, p.raw_per_inverse_depth) * 1e3
            }),
            uncorrected_fixed: p.uncorrected_fixed,
            uncorrected_raw: p
                .uncorrected_raw
                .as_ref()
                .map(|cells| cells.iter().map(thousandths).collect()),
            raw_per_inverse_depth: p.raw_per_inverse_depth,
            fit_again_about: p.fit_again_about.clone(),
        }
    }

    /// Whether the document's pattern is one: its grid's size agrees with
    /// its cells (or it has none, as in the daemon's status), and every
    /// number is one a Kinect's pattern can have.
    pub fn validate(&self) -> Result<(), String> {
        if self.columns > 1024
            || self.rows > 1024
            || (!(1..=64).contains(&self.cell_px) && !self.raw.is_empty())
        {
            return Err(format!(
                "has a grid of {} × {} cells of {} pixels, not a depth image's",
                self.columns, self.rows, self.cell_px
            ));
        }
        let cells = self.columns * self.rows;
        let without_cells = self.raw.is_empty() && self.sigma_raw.is_empty();
        if !without_cells && (self.raw.len() != cells || self.sigma_raw.len() != cells) {
            return Err(format!(
                "has {} values and {} σ for {} × {} = {cells} cells",
                self.raw.len(),
                self.sigma_raw.len(),
                self.columns,
                self.rows
            ));
        }
        if let Some(uncorrected) = &self.uncorrected_raw {
            if without_cells || uncorrected.len() != cells {
                return Err(format!(
                    "has {} uncorrected values for {} × {} = {cells} cells",
                    uncorrected.len(),
                    self.columns,
                    self.rows
                ));
            }
        }
        let uncorrected = self.uncorrected_raw.as_deref().unwrap_or_default();
        for (name, values) in [
            ("raw", &self.raw[..]),
            ("sigma_raw", &self.sigma_raw[..]),
            ("uncorrected_raw", uncorrected),
        ] {
            if let Some((k, v)) = values.iter().enumerate().find_map(|(k, v)| {
                v.filter(|v| !(v.is_finite() && v.abs() <= 50.0))
                    .map(|v| (k, v))
            }) {
                return Err(format!(
                    "\"{name}[{k}]\" is {v}, not a pattern of a Kinect (at most 50 raw units)"
                ));
            }
        }
        if let Some((k, v)) = self.angle_sigma_known_plane_part_deg.and_then(|sigma| {
            (0..3)
                .map(|k| (k, sigma[k]))
                .find(|(_, v)| !(v.is_finite() && *v >= 0.0))
        }) {
            return Err(format!(
                "\"angle_sigma_known_plane_part_deg[{k}]\" is {v}, not a σ"
            ));
        }
        if !self.raw_per_inverse_depth.is_finite()
            || (cells > 0 && self.raw_per_inverse_depth == 0.0)
        {
            return Err(format!(
                "\"raw_per_inverse_depth\" is {}, not a depth model's 1/b",
                self.raw_per_inverse_depth
            ));
        }
        Ok(())
    }
}

/// One pose's noise, in `[calibration.noise]`'s keys.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NoiseJson {
    /// σ of the ground's normal per tangent direction, degrees.
    #[serde(deserialize_with = "number_or_nan")]
    pub normal_sigma_deg: f64,
    /// σ of the ground's offset, millimetres.
    #[serde(deserialize_with = "number_or_nan")]
    pub offset_sigma_mm: f64,
}

/// Which robot a calibration was made for: the name of the configuration's
/// `[robot] name` (or a recording's `robot`), and the lower computer's
/// firmware as its WELCOME said.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RobotJson {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub firmware: Option<String>,
}

/// The whole result document.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ResultJson {
    pub status: ResultStatus,
    #[serde(default)]
    pub reasons: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub robot_from_sensor: Option<MountJson>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma: Option<SigmaJson>,
    /// Correlation coefficients of `[α, β, γ, px, py, pz]`.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "some_6x6_or_nan"
    )]
    pub correlations: Option<[[f64; 6]; 6]>,
    #[serde(default)]
    pub poses: Vec<PoseJson>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub summary: Option<SummaryJson>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub observability: Option<ObservabilityJson>,
    /// The Kinect's motor tilt the calibration holds for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kinect_tilt_deg: Option<f64>,
    /// Things the operator should know that are not reasons to reject.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// Every quality gate with its limit, the value measured and whether it
    /// passed (empty when nothing was solved).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub gate_checks: Vec<GateCheckJson>,
    /// How the input was made and solved, when it says.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub setup: Option<SetupJson>,
    /// The robot it was made for (a calibration holds for one robot only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<RobotJson>,
    /// The σ `groundcal plan` predicted for the schedule before the robot
    /// moved (live calibrations), to compare with `sigma`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub predicted_sigma: Option<SigmaJson>,
    /// The tilt motor during the calibration, from the accelerometer (when
    /// the poses have readings): the angle reached against the body, and
    /// whether it moved.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motor: Option<MotorJson>,
    /// The Kinect's depth scale: its depth reads this × the truth (its σ is
    /// `sigma.depth_scale`). Robots' other programs divide depths by it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_scale: Option<f64>,
    /// Whether the scale was estimated (else given, or 1: the note says why).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_scale_estimated: Option<bool>,
    /// Correlation of the depth scale with α, β, γ, px, py, pz.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_scale_correlations: Option<[f64; 6]>,
    /// The noise of one pose's ground the solve took: from the residuals
    /// when they were enough to say. A measured `[calibration.noise]` for
    /// `plan`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_per_pose: Option<NoiseJson>,
    /// The Kinect's fixed depth pattern, found with the mount (docs/method.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_pattern: Option<DepthPatternJson>,
    /// Calibrated at several tilts of the motor (`--tilts`): the motor's
    /// axis and pivot, which give `robot_from_sensor` at any tilt in the
    /// range (`export --tilt`). `robot_from_sensor` is then the one at the
    /// configured tilt.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tilt_model: Option<TiltModelJson>,
    /// Each tilt's own calibration, in brief.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tilts: Vec<TiltResultJson>,
}

impl ResultJson {
    pub fn from_calibration(c: &Calibration) -> Self {
        let s = c.sigma();
        let r = c.correlations();
        Self {
            status: match c.verdict {
                Verdict::Accepted => ResultStatus::Accepted,
                Verdict::Rejected => ResultStatus::Rejected,
            },
            reasons: c.reasons.clone(),
            robot_from_sensor: Some(MountJson::from_params(&c.robot_from_sensor)),
            sigma: Some(SigmaJson {
                alpha_deg: s[0].to_degrees(),
                beta_deg: s[1].to_degrees(),
                gamma_deg: s[2].to_degrees(),
                px_mm: s[3] * 1e3,
                py_mm: s[4] * 1e3,
                pz_mm: s[5] * 1e3,
                depth_scale: c.depth_scale.sigma,
            }),
            correlations: Some(std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)]))),
            poses: c.poses.iter().map(PoseJson::from).collect(),
            summary: Some(SummaryJson {
                poses_used: c.summary.poses_used,
                poses_total: c.summary.poses_total,
                theta_deg_mean: c.summary.theta_mean.to_degrees(),
                theta_deg_max: c.summary.theta_max.to_degrees(),
                e_d_mm_mean: c.summary.e_d_mean * 1e3,
                e_d_mm_max: c.summary.e_d_max * 1e3,
            }),
            observability: Some(ObservabilityJson {
                rotation_singular_values: c.observability.rotation_singular_values,
                translation_singular_values: c.observability.translation_singular_values,
                rotation_weakest_axis: Some(c.observability.rotation_weakest_axis),
                translation_weakest_axis: Some(c.observability.translation_weakest_axis),
            }),
            kinect_tilt_deg: None,
            notes: match (&c.depth_scale.note, c.depth_scale.estimated) {
                (Some(note), false) => vec![format!(
                    "the depth scale {:.4} was {note}",
                    c.depth_scale.value
                )],
                _ => Vec::new(),
            },
            gate_checks: c.checks.iter().map(GateCheckJson::from).collect(),
            setup: None,
            robot: None,
            predicted_sigma: None,
            motor: None,
            tilt_model: None,
            tilts: Vec::new(),
            depth_scale: Some(c.depth_scale.value),
            depth_scale_estimated: Some(c.depth_scale.estimated),
            depth_scale_correlations: c
                .depth_scale
                .estimated
                .then_some(c.depth_scale.correlations),
            depth_pattern: c.depth_pattern.as_ref().map(DepthPatternJson::from_pattern),
            noise_per_pose: Some(NoiseJson {
                normal_sigma_deg: c.noise_per_pose.0.to_degrees(),
                offset_sigma_mm: c.noise_per_pose.1 * 1e3,
            }),
        }
    }

    /// A rejection with no parameters at all (too few usable poses).
    pub fn unsolved(reason: String, poses: &[PoseOutcome]) -> Self {
        Self {
            status: ResultStatus::Rejected,
            reasons: vec![reason],
            robot_from_sensor: None,
            sigma: None,
            correlations: None,
            poses: poses.iter().map(PoseJson::from).collect(),
            summary: None,
            observability: None,
            kinect_tilt_deg: None,
            notes: Vec::new(),
            gate_checks: Vec::new(),
            setup: None,
            robot: None,
            predicted_sigma: None,
            motor: None,
            tilt_model: None,
            tilts: Vec::new(),
            depth_scale: None,
            depth_scale_estimated: None,
            depth_scale_correlations: None,
            noise_per_pose: None,
            depth_pattern: None,
        }
    }

    /// The result of a calibration from the poses that gave a plane and those
    /// that did not (with why), out of `poses_total`: the solve's verdict, or
    /// an unsolved rejection; the failures listed as poses and as notes.
    pub fn from_poses(
        observations: &[crate::calib::solve::Observation],
        failed: &[(u32, String)],
        poses_total: usize,
        settings: &crate::calib::calibrate::CalibrationSettings,
        kinect_tilt_deg: f64,
    ) -> Self {
        Self::from_poses_taken_out(
            observations,
            failed,
            poses_total,
            settings,
            kinect_tilt_deg,
            None,
        )
    }

    /// [`ResultJson::from_poses`] for planes fitted to frames from which
    /// `taken_out`, a first estimate of the depth pattern, was taken out.
    pub fn from_poses_taken_out(
        observations: &[crate::calib::solve::Observation],
        failed: &[(u32, String)],
        poses_total: usize,
        settings: &crate::calib::calibrate::CalibrationSettings,
        kinect_tilt_deg: f64,
        taken_out: Option<&crate::calib::distortion::DepthCorrection>,
    ) -> Self {
        use crate::calib::calibrate::calibrate_taken_out;
        use crate::calib::solve::SolveError;
        let mut result =
            match calibrate_taken_out(observations, poses_total, settings, taken_out) {
                Ok(calibration) => Self::from_calibration(&calibration),
                Err(SolveError::TooFewObservations { usable, outcomes }) => Self::unsolved(
                    SolveError::TooFewObservations {
                        usable,
                        outcomes: Vec::new(),
                    }
                    .to_string(),
                    &outcomes,
                ),
            }
            .with_failed_poses(failed);
        result.kinect_tilt_deg = Some(kinect_tilt_deg);
        for (index, reason) in failed {
            result.notes.push(format!("pose {index}: {reason}"));
        }
        result
    }

    /// The shape of a depth pattern whose peaks the ground fit's band cut,
    /// to take out of the frames before fitting them again; `None` for any
    /// other result.
    pub fn pattern_to_fit_about(&self) -> Option<&crate::calib::distortion::DepthCorrection> {
        self.depth_pattern.as_ref()?.fit_again_about.as_ref()
    }

    /// When the ground fit's band cut a depth pattern's peaks in this
    /// result, fits the frames again with its estimate taken out
    /// (`fit_again`, for a correction taken out of every frame) until what
    /// is left is a pattern fixed in the image: the result that got there
    /// (with what `fit_again` kept beside it), or `None` to keep this one
    /// (what is left is not such a pattern, or the fits ran out).
    pub fn fit_about_the_pattern<T, E>(
        &self,
        mut fit_again: impl FnMut(
            &crate::calib::distortion::DepthCorrection,
        ) -> Result<(ResultJson, T), E>,
    ) -> Result<Option<(ResultJson, T)>, E> {
        let Some(mut taken_out) = self.pattern_to_fit_about().cloned() else {
            return Ok(None);
        };
        for _ in 1..MOST_GROUND_FITS {
            let (mut result, kept) = fit_again(&taken_out)?;
            if let (Some(pattern), Some(first)) = (&mut result.depth_pattern, &self.depth_pattern) {
                if pattern.corrected {
                    // The evidence that there is a shape is the first fit's:
                    // the later ones see what is left of it.
                    pattern.shape_sigmas = first.shape_sigmas;
                    pattern.shape_chi2_per_dof = first.shape_chi2_per_dof;
                    return Ok(Some((result, kept)));
                }
            }
            let Some(more) = result.pattern_to_fit_about() else {
                break;
            };
            for (all, left) in taken_out.raw.iter_mut().zip(&more.raw) {
                *all += left;
            }
        }
        Ok(None)
    }

    /// Adds poses that gave no plane, keeping the list in index order.
    pub fn with_failed_poses(mut self, failed: &[(u32, String)]) -> Self {
        self.poses.extend(
            failed
                .iter()
                .map(|(index, reason)| PoseJson::failed(*index, reason.clone())),
        );
        self.poses.sort_by_key(|p| p.index);
        if let Some(summary) = &mut self.summary {
            summary.poses_total = self.poses.len();
        }
        self
    }

    /// The result without the depth pattern's cells (`raw` and `sigma_raw`
    /// empty, `uncorrected_raw` left out, the rest kept): for the daemon's
    /// status, which every page polls; the stored document has them.
    pub fn without_pattern_cells(mut self) -> Self {
        if let Some(pattern) = &mut self.depth_pattern {
            pattern.raw = Vec::new();
            pattern.sigma_raw = Vec::new();
            pattern.uncorrected_raw = None;
        }
        self
    }

    /// Whether the calibration was accepted.
    pub fn accepted(&self) -> bool {
        self.status == ResultStatus::Accepted
    }

    /// A table for a person at a terminal.
    pub fn to_table(&self) -> String {
        use std::fmt::Write;
        let mut out = String::new();
        // The poses first and the verdict with the six values last, so that
        // a long schedule does not push the verdict off the screen.
        let _ = writeln!(out, "pose  used   θ (°)   e_d (mm)  note");
        for p in &self.poses {
            let number = |v: Option<f64>, width: usize, decimals: usize| match v {
                Some(v) => format!("{v:>width$.decimals$}"),
                None => format!("{:>width$}", "-"),
            };
            let _ = writeln!(
                out,
                "{:>4}  {:<4} {} {}  {}",
                p.index,
                if p.used { "yes" } else { "no" },
                number(p.theta_deg, 7, 3),
                number(p.e_d_mm, 10, 2),
                p.reason.as_deref().unwrap_or("")
            );
        }
        if let Some(s) = &self.summary {
            let _ = writeln!(
                out,
                "\n{} of {} poses used; θ mean {:.3}° max {:.3}°; e_d mean {:.2} mm max {:.2} mm",
                s.poses_used,
                s.poses_total,
                s.theta_deg_mean,
                s.theta_deg_max,
                s.e_d_mm_mean,
                s.e_d_mm_max
            );
        }
        let _ = writeln!(
            out,
            "\nverdict: {} (status {})",
            if self.accepted() {
                "passed its checks"
            } else {
                "failed its checks"
            },
            self.status.as_str()
        );
        for reason in &self.reasons {
            let _ = writeln!(out, "  - {reason}");
        }
        for note in &self.notes {
            let _ = writeln!(out, "  note: {note}");
        }
        if let Some(tilt) = self.kinect_tilt_deg {
            let _ = writeln!(out, "  for the Kinect tilted {tilt}°");
        }
        if let (Some(m), Some(s)) = (&self.robot_from_sensor, &self.sigma) {
            let predicted = self.predicted_sigma.as_ref();
            let _ = writeln!(
                out,
                "\nrobot_from_sensor            value        σ{}",
                if predicted.is_some() {
                    "   predicted σ"
                } else {
                    ""
                }
            );
            let p = |f: fn(&SigmaJson) -> f64| predicted.map(f);
            for (name, v, sv, pv, unit) in [
                ("alpha", m.alpha_deg, s.alpha_deg, p(|s| s.alpha_deg), "°"),
                ("beta", m.beta_deg, s.beta_deg, p(|s| s.beta_deg), "°"),
                ("gamma", m.gamma_deg, s.gamma_deg, p(|s| s.gamma_deg), "°"),
                ("px", m.px_mm, s.px_mm, p(|s| s.px_mm), " mm"),
                ("py", m.py_mm, s.py_mm, p(|s| s.py_mm), " mm"),
                ("pz", m.pz_mm, s.pz_mm, p(|s| s.pz_mm), " mm"),
            ] {
                let sigma = format!("{sv:>9.4}{unit}");
                let line = match pv {
                    Some(pv) => format!("{sigma:<13}{pv:>11.4}{unit}"),
                    None => sigma,
                };
                let _ = writeln!(out, "  {name:<8} {v:>22.4}{unit:<3} {line}");
            }
        }
        out
    }
}

impl ResultJson {
    /// Reads a result document; an error names the key that is wrong
    /// (`"robot_from_sensor.pz_mm" is null, …`).
    pub fn parse(document: serde_json::Value) -> Result<Self, String> {
        if !document.is_object() {
            return Err("not a groundcal result document: expected a JSON object with \"status\" and \"robot_from_sensor\"".into());
        }
        let result: Self = serde_path_to_error::deserialize(document).map_err(|e| {
            let path = e.path().to_string();
            let message = e.into_inner().to_string();
            let key = |field: &str| {
                if path == "." {
                    field.to_string()
                } else {
                    format!("{path}.{field}")
                }
            };
            match message
                .strip_prefix("missing field `")
                .and_then(|m| m.strip_suffix('`'))
            {
                Some(field) => format!("\"{}\" is missing", key(field)),
                None if message.starts_with("is ") => format!("\"{path}\" {message}"),
                None => format!("\"{path}\": {message}"),
            }
        })?;
        if let Some(pattern) = &result.depth_pattern {
            pattern
                .validate()
                .map_err(|e| format!("\"depth_pattern\" {e}"))?;
        }
        Ok(result)
    }
}

/// A number that must be finite: `null` (how JSON writes NaN) and anything
/// else are refused in words.
fn finite<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
    match serde_json::Value::deserialize(deserializer)? {
        serde_json::Value::Null => Err(serde::de::Error::custom(
            "is null, not a finite number (JSON writes NaN and infinities as null)",
        )),
        value => value
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| serde::de::Error::custom(format!("is {value}, not a finite number"))),
    }
}

/// One finite number as an element of an array (so that the error's path
/// names its index).
struct Finite(f64);

impl<'de> Deserialize<'de> for Finite {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        finite(deserializer).map(Finite)
    }
}

fn finite_4x4<'de, D: Deserializer<'de>>(deserializer: D) -> Result<[[f64; 4]; 4], D::Error> {
    let rows: [[Finite; 4]; 4] = Deserialize::deserialize(deserializer)?;
    Ok(rows.map(|row| row.map(|x| x.0)))
}

fn some_finite_4<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Option<[f64; 4]>, D::Error> {
    let values: [Finite; 4] = Deserialize::deserialize(deserializer)?;
    Ok(Some(values.map(|x| x.0)))
}

/// A number, `null` read as NaN.
fn number_or_nan<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(deserializer)?.unwrap_or(f64::NAN))
}

fn three_or_nan<'de, D: Deserializer<'de>>(deserializer: D) -> Result<[f64; 3], D::Error> {
    let values: [Option<f64>; 3] = Deserialize::deserialize(deserializer)?;
    Ok(values.map(|x| x.unwrap_or(f64::NAN)))
}

fn some_three_or_nan<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<Option<[f64; 3]>, D::Error> {
    three_or_nan(deserializer).map(Some)
}

fn some_6x6_or_nan<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<Option<[[f64; 6]; 6]>, D::Error> {
    let rows: [[Option<f64>; 6]; 6] = Deserialize::deserialize(deserializer)?;
    Ok(Some(rows.map(|row| row.map(|x| x.unwrap_or(f64::NAN)))))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::calibrate::{calibrate, CalibrationSettings};
    use crate::formats::recording::planes::read_planes;

    /// A pattern's σ of the angles had its plane part been known is read
    /// back only as σ: a NaN (written as null, or made up) is named.
    #[test]
    fn a_patterns_angle_sigma_that_is_not_one_is_named() {
        let mut pattern = DepthPatternJson::from_pattern(
            &crate::calib::outcome::DepthPattern::not_estimated(String::new()),
        );
        pattern.angle_sigma_known_plane_part_deg = Some([0.0017, 0.0006, 0.0007]);
        assert_eq!(pattern.validate(), Ok(()));
        pattern.angle_sigma_known_plane_part_deg = Some([0.0017, f64::NAN, 0.0007]);
        let error = pattern.validate().unwrap_err();
        assert!(
            error.contains("\"angle_sigma_known_plane_part_deg[1]\" is NaN"),
            "{error}"
        );
        pattern.angle_sigma_known_plane_part_deg = Some([0.0017, 0.0006, -1.0]);
        assert!(pattern.validate().is_err());
    }

    fn table2() -> ResultJson {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/paper-table2-printed.json");
        let observations = read_planes(&path).expect("Table 2 reads");
        ResultJson::from_calibration(
            &calibrate(&observations, &CalibrationSettings::default()).expect("Table 2 solves"),
        )
    }

    /// The keys added for the report come after cli.md's, which are written
    /// as before; a document without them (an older groundcal's) still reads.
    #[test]
    fn the_added_keys_are_optional_and_last() {
        let result = table2();
        let text = serde_json::to_string(&result).unwrap();
        let at = |key: &str| {
            text.find(&format!("\"{key}\":"))
                .unwrap_or_else(|| panic!("no {key}"))
        };
        let order = [
            "status",
            "reasons",
            "robot_from_sensor",
            "sigma",
            "correlations",
            "poses",
            "summary",
            "observability",
            "rotation_singular_values",
            "translation_singular_values",
            "rotation_weakest_axis",
            "translation_weakest_axis",
            "gate_checks",
        ];
        for pair in order.windows(2) {
            assert!(at(pair[0]) < at(pair[1]), "{pair:?} in {text}");
        }
        assert!(!text.contains("\"setup\"") && !text.contains("\"commanded\""));
        let doc = serde_json::to_value(&result).unwrap();
        assert_eq!(doc["gate_checks"][1]["gate"], "e_d_max_mm");
        assert_eq!(doc["gate_checks"][1]["passed"], false);
        assert_eq!(doc["gate_checks"][1]["at"], "pose 15");
        assert_eq!(
            doc["gate_checks"][1]["place"],
            serde_json::json!({"kind": "pose", "index": 15})
        );

        let mut old = doc.clone();
        let object = old.as_object_mut().unwrap();
        object.remove("gate_checks");
        let o = object["observability"].as_object_mut().unwrap();
        o.remove("rotation_weakest_axis");
        o.remove("translation_weakest_axis");
        let read = ResultJson::parse(old).expect("an older document reads");
        assert!(read.gate_checks.is_empty() && read.setup.is_none());
        let o = read.observability.unwrap();
        assert!(o.rotation_weakest_axis.is_none() && o.translation_weakest_axis.is_none());
        assert!(read.poses.iter().all(|p| p.commanded.is_none()));
    }

    #[test]
    fn the_setup_and_commanded_poses_round_trip() {
        let mut result = table2();
        result.setup = Some(SetupJson {
            robot: Some("octopus".into()),
            schedule: Some("sample".into()),
            poses: Some(6),
            frames_per_pose: Some(2),
            depth_model: Some(DepthModel::InverseLinear { a: 3.3, b: -0.003 }),
            intrinsics: Some(Intrinsics::default()),
            nominal_mount: Some(NominalMount::from_values([
                4.5, -30.7, -2.0, 491.3, 331.6, 8.7,
            ])),
            nominal_mount_from: Some("recording".into()),
            gates_from: Some("built-in".into()),
        });
        result.poses[0].commanded = Some(PoseDegMm {
            alpha_deg: 0.0,
            beta_deg: 2.0,
            gamma_deg: 20.0,
            px_mm: 0.0,
            py_mm: 615.0,
            pz_mm: 0.0,
        });
        let doc = serde_json::to_value(&result).unwrap();
        let read = ResultJson::parse(doc.clone()).expect("reads");
        assert_eq!(serde_json::to_value(&read).unwrap(), doc);
        assert_eq!(read.poses[0].commanded.unwrap().gamma_deg, 20.0);
        assert_eq!(
            read.setup.unwrap().depth_model,
            result.setup.unwrap().depth_model
        );
        // A wrong added key is named like any other.
        let mut doc = doc;
        doc["gate_checks"][0]["passed"] = serde_json::json!("yes");
        let e = ResultJson::parse(doc).unwrap_err();
        assert!(e.contains("gate_checks[0].passed"), "{e}");
    }
}

/// A number for a message, short whatever its size: `1.0032`, `1e308`,
/// `-2.5e-9` (an input echoed back in full could run to 309 digits).
pub fn brief_number(value: f64) -> String {
    let plain = format!("{value}");
    if plain.len() <= 12 {
        plain
    } else {
        let scientific = format!("{value:.6e}");
        match scientific.split_once('e') {
            Some((mantissa, exponent)) if mantissa.contains('.') => format!(
                "{}e{exponent}",
                mantissa.trim_end_matches('0').trim_end_matches('.')
            ),
            _ => scientific,
        }
    }
}

#[cfg(test)]
mod brief_number_tests {
    use super::brief_number;

    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(brief_number(1.0032), "1.0032");
        assert_eq!(brief_number(1e308), "1e308");
        assert_eq!(brief_number(1e300), "1e300");
        assert_eq!(brief_number(-2.5e-9), "-2.5e-9");
        assert_eq!(brief_number(f64::MAX).len(), "1.797693e308".len());
        assert_eq!(brief_number(12345.678), "12345.678");
    }
}

/// Text for a terminal `width` columns wide: a longer line is broken at the
/// last space that fits (never inside a word), and its continuation is
/// indented under the line's text (past a leading "- " or "note: ").
pub fn wrap_words(text: &str, width: usize) -> String {
    let mut out = String::with_capacity(text.len() + 64);
    for line in text.split_inclusive('\n') {
        let (body, newline) = match line.strip_suffix('\n') {
            Some(b) => (b, "\n"),
            None => (line, ""),
        };
        if body.chars().count() <= width || width < 20 {
            out.push_str(line);
            continue;
        }
        let lead = body.len() - body.trim_start().len();
        let rest = &body[lead..];
        let bullet = ["- ", "note: "]
            .iter()
            .find(|b| rest.starts_with(**b))
            .map_or(0, |b| b.chars().count());
        let indent = " ".repeat((lead + bullet).min(width / 2));
        // Words as split at single spaces, so that runs of spaces (aligned
        // columns) are kept where the line is not broken.
        let mut current = " ".repeat(lead);
        let mut started = false;
        for word in rest.split(' ') {
            let length = current.chars().count() + usize::from(started) + word.chars().count();
            if started && length > width && !word.is_empty() {
                out.push_str(current.trim_end());
                out.push('\n');
                current = indent.clone();
                started = false;
            }
            if started {
                current.push(' ');
            }
            current.push_str(word);
            started = true;
        }
        out.push_str(current.trim_end());
        out.push_str(newline);
    }
    out
}

#[cfg(test)]
mod wrap_tests {
    use super::wrap_words;

    #[test]
    fn long_lines_break_between_words_under_their_text() {
        let text = "  - the angle β (pitch) is uncertain (σ = 0.120°, at most 0.100° allowed): calibrate again with the robot on open, flat ground\nshort\n";
        let wrapped = wrap_words(text, 40);
        for line in wrapped.lines() {
            assert!(line.chars().count() <= 40, "{line:?}");
        }
        let lines: Vec<&str> = wrapped.lines().collect();
        assert!(lines[0].starts_with("  - the angle"), "{wrapped}");
        assert!(
            lines[1].starts_with("    ") && !lines[1].starts_with("     "),
            "{wrapped}"
        );
        assert_eq!(*lines.last().unwrap(), "short");
        // No word is cut: the words are the same, in order.
        let words = |s: &str| s.split_whitespace().map(String::from).collect::<Vec<_>>();
        assert_eq!(words(&wrapped), words(text));
    }
}
