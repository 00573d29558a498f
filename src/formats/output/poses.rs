//! The poses, the summary, the gates, the setup, the verdict's status and
//! the motor's steadiness and tilts, as the result document writes them.

use super::*;

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
    /// A bag's disparity camera other than a Kinect, when its baseline is
    /// known: the units its pattern is reported and gated in.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub disparity: Option<CameraDisparityJson>,
}

/// A disparity camera's own units (a bag's camera of known baseline).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraDisparityJson {
    pub baseline_mm: f64,
    /// Pixels of disparity per 1/m of inverse depth (`fx · baseline`, px·m).
    pub pixels_per_inverse_depth: f64,
    /// Where the baseline came from: `flag` (`--baseline-mm`), `config`
    /// (`[bag] baseline_mm`) or `camera_info` (its projection matrix).
    pub from: String,
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
