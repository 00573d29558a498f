//! The calibration in other tools' formats: a URDF joint, the arguments of ROS 2's
//! `static_transform_publisher`, and a plain JSON transform (`groundcal export`,
//! `shared/spec/cli.md`; the frames and formulas are in `docs/export.md`).
//!
//! groundcal's result is `robot_from_sensor` between its own frames
//! (conventions.md): the body frame R (X forward, Y up, Z right) and the sensor
//! frame V (X along the optical axis, Y up in the image, Z right). ROS wants
//! `base_link` (REP-103: x forward, y left, z up) and `camera_depth_optical_frame`
//! (x right, y down, z forward: conventions.md's optical frame O). So
//!
//! ```text
//! base_link_from_camera_optical = base_link_from_robot · robot_from_sensor · sensor_from_optical
//! ```
//!
//! with `base_link` at the origin of R (the body origin of the robot's
//! kinematics). Numbers keep full precision: only values below 1e-15 (rounding
//! noise such as `cos 90°`) are written as 0.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion};
use serde::Serialize;
use serde_json::Value;

use crate::calib::geometry::{self, PoseDegMm, PoseParams, Transform};
use crate::formats::output::{ResultJson, ResultStatus};
use crate::platform::input::{read_bounded, InputError};

/// The ROS parent frame (REP-103 body frame).
pub const PARENT_FRAME: &str = "base_link";
/// The ROS child frame: the depth camera's optical frame.
pub const CHILD_FRAME: &str = "camera_depth_optical_frame";
/// The name of the URDF joint.
pub const JOINT_NAME: &str = "camera_depth_optical_joint";
/// How far the result's `matrix` (and `quaternion_xyzw`) may be from the six
/// parameters, entry by entry, in the file's own units (translation in mm).
pub const CONSISTENCY_TOLERANCE: f64 = 1e-6;
/// Values smaller than this are rounding noise and are written as 0.
const NOISE: f64 = 1e-15;

/// The output formats of `groundcal export --format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    /// A URDF `<joint>` from `base_link` to `camera_depth_optical_frame`.
    Urdf,
    /// The arguments of ROS 2's `static_transform_publisher` (named flags).
    RosStatic,
    /// A JSON document with translation, quaternion, roll-pitch-yaw and matrix.
    Json,
    /// The Kinect's depth pattern the calibration corrected, for a terrain
    /// mapper to take out of its frames (`groundcal-depth-correction`).
    DepthCorrection,
}

impl ExportFormat {
    /// The format's name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ExportFormat::Urdf => "urdf",
            ExportFormat::RosStatic => "ros-static",
            ExportFormat::Json => "json",
            ExportFormat::DepthCorrection => "depth-correction",
        }
    }

    /// The format of a command-line name.
    pub fn parse(name: &str) -> Option<Self> {
        [
            Self::Urdf,
            Self::RosStatic,
            Self::Json,
            Self::DepthCorrection,
        ]
        .into_iter()
        .find(|f| f.name() == name)
    }
}

/// Why a result document cannot be exported.
#[derive(Debug, Clone, PartialEq)]
pub enum ExportError {
    /// The file is missing, unreadable or not a consistent result document;
    /// the message names the file and the key.
    Input(InputError),
    /// The calibration was rejected (`status: "rejected"`).
    Rejected { path: PathBuf, reasons: Vec<String> },
}

impl std::fmt::Display for ExportError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ExportError::Input(e) => e.fmt(f),
            ExportError::Rejected { path, reasons } => {
                write!(
                    f,
                    "{}: the calibration was rejected (\"status\": \"rejected\"); \
                     only an accepted calibration is exported",
                    path.display()
                )?;
                if !reasons.is_empty() {
                    write!(f, ". Reasons: {}", reasons.join("; "))?;
                }
                Ok(())
            }
        }
    }
}

impl std::error::Error for ExportError {}

impl From<InputError> for ExportError {
    fn from(e: InputError) -> Self {
        ExportError::Input(e)
    }
}

// ---------------------------------------------------------------------------
// Frames

/// `base_link_from_robot`: REP-103's `base_link` (x forward, y left, z up) from
/// groundcal's body frame R (X forward, Y up, Z right): `x = X`, `y = -Z`, `z = Y`.
pub fn base_link_from_robot() -> Matrix3<f64> {
    Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0)
}

fn rotation_only(m: Matrix3<f64>) -> Transform {
    Transform::from_parts(
        Translation3::identity(),
        Rotation3::from_matrix_unchecked(m),
    )
}

/// `base_link_from_camera_optical = base_link_from_robot · robot_from_sensor ·
/// sensor_from_optical` (metres).
pub fn base_link_from_camera_optical(robot_from_sensor: &PoseParams) -> Transform {
    rotation_only(base_link_from_robot())
        * robot_from_sensor.to_transform()
        * rotation_only(geometry::sensor_from_optical())
}

/// The inverse of [`base_link_from_camera_optical`]: the six parameters back from
/// a ROS transform (at `|β| = 90°` only α + γ or α − γ is defined; see
/// [`PoseParams::from_rotation_translation`]).
pub fn robot_from_sensor_from_ros(base_link_from_camera_optical: &Transform) -> PoseParams {
    let robot_from_sensor = rotation_only(base_link_from_robot().transpose())
        * base_link_from_camera_optical
        * rotation_only(geometry::sensor_from_optical().transpose());
    PoseParams::from_transform(&robot_from_sensor)
}

// ---------------------------------------------------------------------------
// Rotations in ROS's terms

/// URDF's `rpy`: fixed-axis roll about x, then pitch about y, then yaw about z,
/// `R = Rz(yaw)·Ry(pitch)·Rx(roll)`.
pub fn rotation_from_rpy([roll, pitch, yaw]: [f64; 3]) -> Matrix3<f64> {
    geometry::rot_z(yaw) * geometry::rot_y(pitch) * geometry::rot_x(roll)
}

/// `[roll, pitch, yaw]` of a rotation, `R = Rz(yaw)·Ry(pitch)·Rx(roll)`, with
/// `pitch` in [-π/2, π/2].
///
/// Accurate near `|pitch| = 90°` too: pitch comes from an `atan2` (not an
/// `asin`), and yaw is taken from what is left once roll and pitch are undone, so
/// that an error in roll (ill-defined there) is absorbed by yaw and the rebuilt
/// rotation stays within rounding of the original. At exactly 90° roll is 0.
pub fn rpy_from_rotation(r: &Matrix3<f64>) -> [f64; 3] {
    let pitch = (-r[(2, 0)]).atan2(r[(0, 0)].hypot(r[(1, 0)]));
    let roll = if r[(2, 1)].hypot(r[(2, 2)]) > 1e-12 {
        r[(2, 1)].atan2(r[(2, 2)])
    } else {
        0.0
    };
    // Rz(yaw) = R · Rx(roll)ᵀ · Ry(pitch)ᵀ
    let z_only = r * geometry::rot_x(roll).transpose() * geometry::rot_y(pitch).transpose();
    let yaw = z_only[(1, 0)].atan2(z_only[(0, 0)]);
    [roll, pitch, yaw]
}

/// The rotation as a unit quaternion `[x, y, z, w]` with `w ≥ 0`.
pub fn quaternion_xyzw(r: &Matrix3<f64>) -> [f64; 4] {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    let sign = if q.w < 0.0 { -1.0 } else { 1.0 };
    [q.i * sign, q.j * sign, q.k * sign, q.w * sign]
}

/// Rounding noise (|x| < 1e-15, and -0) written as 0.
fn clean(x: f64) -> f64 {
    if x.abs() < NOISE {
        0.0
    } else {
        x
    }
}

/// A number as text, shortest form that reads back to the same `f64`.
fn num(x: f64) -> String {
    format!("{}", clean(x))
}

// ---------------------------------------------------------------------------
// The transform in ROS's terms and its three formats

/// A calibration ready for ROS: `base_link_from_camera_optical` and the ways
/// other tools write it.
#[derive(Debug, Clone, PartialEq)]
pub struct RosMount {
    /// The groundcal parameters it came from (degrees, millimetres).
    pub groundcal: PoseDegMm,
    pub base_link_from_camera_optical: Transform,
    /// Metres, in `base_link`.
    pub translation_m: [f64; 3],
    pub quaternion_xyzw: [f64; 4],
    /// URDF `rpy`, radians.
    pub rpy_rad: [f64; 3],
    /// The Kinect's depth scale the calibration found (its depth reads this
    /// × the truth), when it is not 1: the JSON carries it; URDF and the
    /// transform publisher cannot, and say so.
    pub depth_scale: Option<f64>,
}

/// The `json` format.
#[derive(Debug, Clone, Serialize)]
pub struct RosMountJson {
    pub parent: &'static str,
    pub child: &'static str,
    pub translation_m: [f64; 3],
    pub quaternion_xyzw: [f64; 4],
    pub rpy_rad: [f64; 3],
    /// `base_link_from_camera_optical`, 4×4, translation in metres.
    pub matrix: [[f64; 4]; 4],
    /// groundcal's `robot_from_sensor` (degrees, millimetres).
    pub groundcal: PoseDegMm,
    /// The Kinect's depth reads this × the truth: divide depths by it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_scale: Option<f64>,
}

impl RosMount {
    /// The ROS transform of groundcal's `robot_from_sensor`.
    pub fn from_groundcal(robot_from_sensor: &PoseDegMm) -> Self {
        let transform = base_link_from_camera_optical(&robot_from_sensor.to_params());
        let rotation = transform.rotation.matrix();
        let t = transform.translation.vector;
        Self {
            groundcal: *robot_from_sensor,
            base_link_from_camera_optical: transform,
            translation_m: [t.x, t.y, t.z].map(clean),
            quaternion_xyzw: quaternion_xyzw(rotation).map(clean),
            rpy_rad: rpy_from_rotation(rotation).map(clean),
            depth_scale: None,
        }
    }

    /// A note for formats that cannot carry the depth scale, if there is one.
    pub fn depth_scale_note(&self) -> Option<String> {
        self.depth_scale.map(|s| {
            format!(
                "groundcal depth_scale={s:.5}: the Kinect's depth reads {s:.5} × the truth; this format cannot carry it: divide the depths by it before using this transform"
            )
        })
    }

    /// The output in one of the mount's formats, ending with a newline
    /// (`None` for a format that is not the mount's).
    pub fn render(&self, format: ExportFormat) -> Option<String> {
        Some(match format {
            ExportFormat::Urdf => self.to_urdf(),
            ExportFormat::RosStatic => self.to_ros_static_args() + "\n",
            ExportFormat::Json => {
                #[allow(
                    clippy::expect_used,
                    reason = "only finite numbers and plain keys: encoding cannot fail"
                )]
                let mut text =
                    serde_json::to_string_pretty(&self.to_json()).expect("the export JSON encodes");
                text.push('\n');
                text
            }
            ExportFormat::DepthCorrection => return None,
        })
    }

    /// A URDF fixed joint, preceded by a comment with the groundcal parameters.
    pub fn to_urdf(&self) -> String {
        let g = &self.groundcal;
        let [x, y, z] = self.translation_m;
        let [roll, pitch, yaw] = self.rpy_rad;
        let mut out = String::new();
        if let Some(note) = self.depth_scale_note() {
            let _ = writeln!(out, "<!-- {note} -->");
        }
        // XML comments must not contain "--"; numbers and "=" never make one.
        let _ = writeln!(
            out,
            "<!-- groundcal robot_from_sensor: alpha_deg={} beta_deg={} gamma_deg={} \
             px_mm={} py_mm={} pz_mm={} (base_link at the origin of groundcal's body frame) -->",
            g.alpha_deg, g.beta_deg, g.gamma_deg, g.px_mm, g.py_mm, g.pz_mm
        );
        let _ = writeln!(out, "<joint name=\"{JOINT_NAME}\" type=\"fixed\">");
        let _ = writeln!(out, "  <parent link=\"{PARENT_FRAME}\"/>");
        let _ = writeln!(out, "  <child link=\"{CHILD_FRAME}\"/>");
        let _ = writeln!(
            out,
            "  <origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>",
            num(x),
            num(y),
            num(z),
            num(roll),
            num(pitch),
            num(yaw)
        );
        let _ = writeln!(out, "</joint>");
        out
    }

    /// The argument line of ROS 2's `static_transform_publisher`, named-flag form
    /// (`ros2 run tf2_ros static_transform_publisher $(groundcal export … --format
    /// ros-static)`).
    pub fn to_ros_static_args(&self) -> String {
        let [x, y, z] = self.translation_m;
        let [qx, qy, qz, qw] = self.quaternion_xyzw;
        format!(
            "--x {} --y {} --z {} --qx {} --qy {} --qz {} --qw {} \
             --frame-id {PARENT_FRAME} --child-frame-id {CHILD_FRAME}",
            num(x),
            num(y),
            num(z),
            num(qx),
            num(qy),
            num(qz),
            num(qw)
        )
    }

    /// The `json` format's document.
    pub fn to_json(&self) -> RosMountJson {
        let m = self.base_link_from_camera_optical.to_homogeneous();
        RosMountJson {
            parent: PARENT_FRAME,
            child: CHILD_FRAME,
            translation_m: self.translation_m,
            quaternion_xyzw: self.quaternion_xyzw,
            rpy_rad: self.rpy_rad,
            matrix: std::array::from_fn(|i| std::array::from_fn(|j| clean(m[(i, j)]))),
            groundcal: self.groundcal,
            depth_scale: self.depth_scale,
        }
    }
}

/// The output of `groundcal export` for a result's `robot_from_sensor` in
/// one of the mount's formats.
pub fn render(robot_from_sensor: &PoseDegMm, format: ExportFormat) -> Option<String> {
    RosMount::from_groundcal(robot_from_sensor).render(format)
}

/// `export --format depth-correction`: the depth pattern a calibration
/// corrected, for the robot's other programs (docs/export.md).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DepthCorrectionJson {
    /// `"groundcal-depth-correction"`.
    pub format: &'static str,
    pub version: u32,
    /// Cells of `cell_px` pixels, `columns` × `rows`, row-major from the top left.
    pub cell_px: usize,
    pub columns: usize,
    pub rows: usize,
    /// Per cell, the raw units a reading there is too large (more is
    /// farther); `null` where the calibration saw no ground: apply 0.
    pub raw: Vec<Option<f64>>,
    pub sigma_raw: Vec<Option<f64>>,
    /// The depth model's 1/b (raw units per 1/m): a metric depth z is
    /// corrected as `1/z' = 1/z − raw/raw_per_inverse_depth`.
    pub raw_per_inverse_depth: f64,
    /// The depth scale found with it: divide the corrected depth by it.
    pub depth_scale: f64,
    /// The largest depth error the pattern causes at 2 m, millimetres.
    pub largest_mm_at_2m: f64,
    /// How to apply it, in one line.
    pub apply: &'static str,
}

/// Reads a `groundcal-depth-correction` document (`export --format
/// depth-correction`): its grid must agree with its cells, and every value
/// must be a Kinect's (at most 50 raw units).
pub fn read_depth_correction_file(
    path: &Path,
) -> Result<crate::calib::distortion::DepthCorrection, InputError> {
    let bytes = read_bounded(path, 16 << 20)?;
    let fail = |message: String| InputError::new(path, None, message);
    let document: Value = serde_json::from_slice(&bytes)
        .map_err(|e| fail(format!("not a groundcal depth correction (JSON): {e}")))?;
    if document.get("format").and_then(Value::as_str) != Some("groundcal-depth-correction") {
        return Err(fail(
            "not a groundcal depth correction: \"format\" must be \"groundcal-depth-correction\" (write one with groundcal export RESULT.json --format depth-correction)".into(),
        ));
    }
    if document.get("version").and_then(Value::as_u64) != Some(1) {
        return Err(fail("\"version\" must be 1".into()));
    }
    let count = |key: &str| {
        document
            .get(key)
            .and_then(Value::as_u64)
            .filter(|v| (1..=1024).contains(v))
            .map(|v| v as usize)
            .ok_or_else(|| fail(format!("\"{key}\" must be a whole number from 1 to 1024")))
    };
    let (columns, rows, cell_px) = (count("columns")?, count("rows")?, count("cell_px")?);
    let cells: Vec<Option<f64>> = document
        .get("raw")
        .and_then(Value::as_array)
        .ok_or_else(|| fail("\"raw\" must be an array of numbers or null".into()))?
        .iter()
        .enumerate()
        .map(|(k, v)| match v {
            Value::Null => Ok(None),
            v => v
                .as_f64()
                .filter(|x| x.is_finite() && x.abs() <= 50.0)
                .map(Some)
                .ok_or_else(|| {
                    fail(format!(
                        "\"raw[{k}]\" is {v}, not a pattern of a Kinect (at most 50 raw units)"
                    ))
                }),
        })
        .collect::<Result<_, _>>()?;
    crate::calib::distortion::DepthCorrection::from_cells(columns, rows, cell_px, &cells)
        .ok_or_else(|| {
            fail(format!(
                "\"raw\" has {} cells for a grid of {columns} × {rows}",
                cells.len()
            ))
        })
}

/// The depth correction of an accepted result that corrected a pattern.
pub fn read_depth_correction(path: &Path) -> Result<DepthCorrectionJson, ExportError> {
    let (_, scale) = read_result_with_scale(path, false)?;
    let fail = |message: String| ExportError::Input(InputError::new(path, None, message));
    let bytes = read_bounded(path, 64 << 20)?;
    let document: Value = serde_json::from_slice(&bytes)
        .map_err(|e| fail(format!("not a groundcal result document: {e}")))?;
    let result = ResultJson::parse(document).map_err(fail)?;
    let Some(pattern) = result.depth_pattern.filter(|p| p.corrected) else {
        return Err(fail(
            "the calibration corrected no depth pattern (its \"depth_pattern\" says none was found, or it has none): there is nothing to export; the depth needs no correction beyond its scale".into(),
        ));
    };
    Ok(DepthCorrectionJson {
        format: "groundcal-depth-correction",
        version: 1,
        cell_px: pattern.cell_px,
        columns: pattern.columns,
        rows: pattern.rows,
        raw: pattern.raw,
        sigma_raw: pattern.sigma_raw,
        raw_per_inverse_depth: pattern.raw_per_inverse_depth,
        depth_scale: scale.unwrap_or(1.0),
        largest_mm_at_2m: pattern.largest_mm_at_2m,
        apply: "raw' = raw - bilinear(raw cells at their centres ((c+0.5)*cell_px-0.5, (r+0.5)*cell_px-0.5), held at the border, null = 0); metric: 1/z' = 1/z - correction/raw_per_inverse_depth; then z'' = z' / depth_scale",
    })
}

// ---------------------------------------------------------------------------
// Reading the result document

/// Reads a result document (cli.md) and returns its `robot_from_sensor`.
///
/// A `status` other than `"accepted"` is refused ([`ExportError::Rejected`] for
/// `"rejected"`) unless `allow_rejected`; so are missing or non-finite values and
/// a `matrix` (or `quaternion_xyzw`) that disagrees with the six parameters by
/// more than [`CONSISTENCY_TOLERANCE`].
pub fn read_result(path: &Path, allow_rejected: bool) -> Result<PoseDegMm, ExportError> {
    let bytes = read_bounded(path, 64 << 20)?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| InputError::new(path, None, format!("not UTF-8 text: {e}")))?;
    parse_result(path, text, allow_rejected)
}

/// [`read_result`] with the depth scale the result found, when it is not 1.
pub fn read_result_with_scale(
    path: &Path,
    allow_rejected: bool,
) -> Result<(PoseDegMm, Option<f64>), ExportError> {
    let bytes = read_bounded(path, 64 << 20)?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| InputError::new(path, None, format!("not UTF-8 text: {e}")))?;
    parse_result_with_scale(path, text, allow_rejected)
}

/// [`read_result`] on a document's text; `path` is only for messages.
pub fn parse_result(
    path: &Path,
    text: &str,
    allow_rejected: bool,
) -> Result<PoseDegMm, ExportError> {
    parse_result_with_scale(path, text, allow_rejected).map(|(pose, _)| pose)
}

/// [`parse_result`] with the depth scale, when it is not 1.
pub fn parse_result_with_scale(
    path: &Path,
    text: &str,
    allow_rejected: bool,
) -> Result<(PoseDegMm, Option<f64>), ExportError> {
    let fail = |message: String| ExportError::Input(InputError::new(path, None, message));
    let doc: Value = serde_json::from_str(text).map_err(|e| {
        let line = (e.line() > 0).then_some(e.line());
        let near = key_near(text, e.line(), e.column())
            .map(|k| format!(" at \"{k}\""))
            .unwrap_or_default();
        InputError::new(
            path,
            line,
            format!("not a groundcal result document{near} (a value must be a finite number): {e}"),
        )
    })?;
    let result = ResultJson::parse(doc).map_err(fail)?;
    if result.status == ResultStatus::Rejected && !allow_rejected {
        return Err(ExportError::Rejected {
            path: path.to_path_buf(),
            reasons: result.reasons,
        });
    }
    let Some(mount) = result.robot_from_sensor else {
        return Err(fail(if result.status == ResultStatus::Rejected {
            "\"robot_from_sensor\" is missing: the solve found no parameters to export".into()
        } else {
            "\"robot_from_sensor\" is missing".into()
        }));
    };
    let pose = PoseDegMm {
        alpha_deg: mount.alpha_deg,
        beta_deg: mount.beta_deg,
        gamma_deg: mount.gamma_deg,
        px_mm: mount.px_mm,
        py_mm: mount.py_mm,
        pz_mm: mount.pz_mm,
    };
    check_matrix(&mount.matrix, &pose).map_err(fail)?;
    if let Some(q) = mount.quaternion_xyzw {
        check_quaternion(q, &pose).map_err(fail)?;
    }
    let scale = match result.depth_scale {
        Some(s) if !(0.5..=2.0).contains(&s) => {
            return Err(fail(format!(
                "\"depth_scale\" is {s}, not a Kinect's depth scale (near 1)"
            )))
        }
        Some(s) if s != 1.0 => Some(s),
        _ => None,
    };
    Ok((pose, scale))
}

/// The 4×4 `matrix` (translation in mm) must be the six parameters' matrix.
fn check_matrix(matrix: &[[f64; 4]; 4], pose: &PoseDegMm) -> Result<(), String> {
    let key = "robot_from_sensor.matrix";
    let expected = pose.to_params().to_matrix();
    for (i, row) in matrix.iter().enumerate() {
        for (j, &value) in row.iter().enumerate() {
            let want = if j == 3 && i < 3 {
                expected[(i, j)] * 1e3
            } else {
                expected[(i, j)]
            };
            if (value - want).abs() > CONSISTENCY_TOLERANCE {
                return Err(format!(
                    "\"{key}[{i}][{j}]\" is {value} but the six parameters (alpha_deg … pz_mm) \
                     give {want}: the matrix and the parameters disagree by more than \
                     {CONSISTENCY_TOLERANCE}, so the file is not a consistent result"
                ));
            }
        }
    }
    Ok(())
}

/// `quaternion_xyzw`, where present, must be the parameters' rotation (either sign).
fn check_quaternion(q: [f64; 4], pose: &PoseDegMm) -> Result<(), String> {
    let key = "robot_from_sensor.quaternion_xyzw";
    let want = quaternion_xyzw(&pose.to_params().rotation_matrix());
    let distance = |sign: f64| {
        q.iter()
            .zip(&want)
            .map(|(a, b)| (a - sign * b).abs())
            .fold(0.0, f64::max)
    };
    if distance(1.0).min(distance(-1.0)) > CONSISTENCY_TOLERANCE {
        return Err(format!(
            "\"{key}\" is {q:?} but the six parameters (alpha_deg … gamma_deg) give {want:?}: \
             they disagree by more than {CONSISTENCY_TOLERANCE}, so the file is not a consistent result"
        ));
    }
    Ok(())
}

/// The key whose value a JSON syntax error is in, if it can be told: the last
/// `"key":` before the error with nothing but a (broken) value in between.
fn key_near(text: &str, line: usize, column: usize) -> Option<String> {
    if line == 0 {
        return None;
    }
    let line_start: usize = text
        .split_inclusive('\n')
        .take(line - 1)
        .map(str::len)
        .sum();
    let mut end = (line_start + column).min(text.len());
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    let before = &text[..end];
    let colon = before.rfind(':')?;
    if before[colon + 1..].contains([',', '{', '[', '}', ']', '"']) {
        return None;
    }
    let quoted = before[..colon].trim_end().strip_suffix('"')?;
    let open = quoted.rfind('"')?;
    Some(quoted[open + 1..].to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::output::MountJson;
    use approx::assert_abs_diff_eq;
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::FRAC_PI_2;

    // Independent of the module: the frame changes written out, and URDF's rpy
    // through nalgebra's own Euler angles (roll, then pitch, then yaw).
    fn base_link_from_r() -> Matrix3<f64> {
        // columns: R's X (forward) = x, R's Y (up) = z, R's Z (right) = -y
        Matrix3::from_columns(&[Vector3::x(), Vector3::z(), -Vector3::y()])
    }
    fn v_from_o() -> Matrix3<f64> {
        // columns: O's x (right) = Z_V, O's y (down) = -Y_V, O's z (forward) = X_V
        Matrix3::from_columns(&[Vector3::z(), -Vector3::y(), Vector3::x()])
    }

    /// Undoes the frame changes of a ROS rotation and translation: the six
    /// parameters in degrees and millimetres.
    fn groundcal_of(rotation: &Matrix3<f64>, translation_m: Vector3<f64>) -> PoseDegMm {
        let r_from_v = base_link_from_r().transpose() * rotation * v_from_o().transpose();
        let t_r = base_link_from_r().transpose() * translation_m;
        PoseDegMm::from_params(&PoseParams::from_rotation_translation(&r_from_v, t_r))
    }

    fn assert_params_close(got: &PoseDegMm, want: &PoseDegMm, tol: f64) {
        for (g, w) in got.values().iter().zip(want.values()) {
            assert!((g - w).abs() <= tol, "got {got:?}, want {want:?}");
        }
    }

    fn attribute<'a>(text: &'a str, name: &str) -> &'a str {
        let start = text.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        let len = text[start..].find('"').unwrap();
        &text[start..start + len]
    }

    fn numbers(text: &str) -> Vec<f64> {
        text.split_whitespace()
            .map(|s| s.parse().unwrap())
            .collect()
    }

    /// (rotation, translation) read back from the URDF text.
    fn from_urdf(urdf: &str) -> (Matrix3<f64>, Vector3<f64>) {
        let xyz = numbers(attribute(urdf, "xyz"));
        let rpy = numbers(attribute(urdf, "rpy"));
        let r = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]);
        (*r.matrix(), Vector3::new(xyz[0], xyz[1], xyz[2]))
    }

    fn from_ros_static(args: &str) -> (Matrix3<f64>, Vector3<f64>) {
        let words: Vec<&str> = args.split_whitespace().collect();
        assert_eq!(words.len(), 18, "{args}");
        let flag = |name: &str| -> f64 {
            let k = words.iter().position(|w| *w == name).unwrap();
            words[k + 1].parse().unwrap()
        };
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            flag("--qw"),
            flag("--qx"),
            flag("--qy"),
            flag("--qz"),
        ));
        (
            *q.to_rotation_matrix().matrix(),
            Vector3::new(flag("--x"), flag("--y"), flag("--z")),
        )
    }

    fn from_json(text: &str) -> (Matrix3<f64>, Vector3<f64>, Value) {
        let v: Value = serde_json::from_str(text).unwrap();
        let m = |i: usize, j: usize| v["matrix"][i][j].as_f64().unwrap();
        let r = Matrix3::from_fn(m);
        assert_eq!(
            [m(3, 0), m(3, 1), m(3, 2), m(3, 3)],
            [0.0, 0.0, 0.0, 1.0],
            "last row"
        );
        (r, Vector3::new(m(0, 3), m(1, 3), m(2, 3)), v)
    }

    fn random_mounts(n: usize) -> Vec<PoseDegMm> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(20240613);
        (0..n)
            .map(|_| PoseDegMm {
                alpha_deg: rng.gen_range(-179.0..179.0),
                beta_deg: rng.gen_range(-85.0..85.0),
                gamma_deg: rng.gen_range(-179.0..179.0),
                px_mm: rng.gen_range(-800.0..800.0),
                py_mm: rng.gen_range(-800.0..800.0),
                pz_mm: rng.gen_range(-800.0..800.0),
            })
            .chain([
                // Paper eq. (32).
                PoseDegMm {
                    alpha_deg: -0.4398,
                    beta_deg: -37.4072,
                    gamma_deg: -3.0471,
                    px_mm: 527.8885,
                    py_mm: 364.8007,
                    pz_mm: -33.4003,
                },
                PoseDegMm::from_params(&PoseParams::identity()),
            ])
            .collect()
    }

    fn pose(a: f64, b: f64, g: f64, x: f64, y: f64, z: f64) -> PoseDegMm {
        PoseDegMm {
            alpha_deg: a,
            beta_deg: b,
            gamma_deg: g,
            px_mm: x,
            py_mm: y,
            pz_mm: z,
        }
    }

    #[test]
    fn identity_mount_is_the_usual_optical_frame() {
        let ros = RosMount::from_groundcal(&pose(0.0, 0.0, 0.0, 0.0, 0.0, 0.0));
        let r = ros.base_link_from_camera_optical.rotation.matrix();
        // Optical z (forward) is base_link x, x (right) is -y, y (down) is -z.
        assert_abs_diff_eq!(r * Vector3::z(), Vector3::x(), epsilon = 1e-15);
        assert_abs_diff_eq!(r * Vector3::x(), -Vector3::y(), epsilon = 1e-15);
        assert_abs_diff_eq!(r * Vector3::y(), -Vector3::z(), epsilon = 1e-15);
        // The well-known rpy and quaternion of ROS optical frames.
        assert_abs_diff_eq!(
            Vector3::from(ros.rpy_rad),
            Vector3::new(-FRAC_PI_2, 0.0, -FRAC_PI_2),
            epsilon = 1e-15
        );
        assert_abs_diff_eq!(
            nalgebra::Vector4::from(ros.quaternion_xyzw),
            nalgebra::Vector4::new(-0.5, 0.5, -0.5, 0.5),
            epsilon = 1e-15
        );
        assert_eq!(ros.translation_m, [0.0, 0.0, 0.0]);
        // The independent frame changes agree with the module's.
        assert_abs_diff_eq!(base_link_from_r(), base_link_from_robot());
        assert_abs_diff_eq!(v_from_o(), geometry::sensor_from_optical());
    }

    #[test]
    fn a_sensor_forward_and_up_is_forward_and_up_in_base_link() {
        let ros = RosMount::from_groundcal(&pose(0.0, 0.0, 0.0, 500.0, 360.0, 0.0));
        assert_eq!(ros.translation_m, [0.5, 0.0, 0.36]);
        let urdf = ros.to_urdf();
        assert!(urdf.contains("xyz=\"0.5 0 0.36\""), "{urdf}");
        assert!(ros
            .to_ros_static_args()
            .starts_with("--x 0.5 --y 0 --z 0.36 --qx "));
        // A sensor to the right (groundcal +Z) is on base_link's -y.
        let ros = RosMount::from_groundcal(&pose(0.0, 0.0, 0.0, 0.0, 0.0, 100.0));
        assert_eq!(ros.translation_m, [0.0, -0.1, 0.0]);
    }

    #[test]
    fn urdf_round_trips_to_the_six_parameters() {
        for mount in random_mounts(200) {
            let urdf = render(&mount, ExportFormat::Urdf).expect("a mount format");
            let (r, t) = from_urdf(&urdf);
            assert_params_close(&groundcal_of(&r, t), &mount, 1e-9);
        }
    }

    #[test]
    fn ros_static_round_trips_to_the_six_parameters() {
        for mount in random_mounts(200) {
            let args = render(&mount, ExportFormat::RosStatic).expect("a mount format");
            assert!(args
                .ends_with("--frame-id base_link --child-frame-id camera_depth_optical_frame\n"));
            assert_eq!(args.lines().count(), 1);
            let (r, t) = from_ros_static(&args);
            assert_params_close(&groundcal_of(&r, t), &mount, 1e-9);
        }
    }

    #[test]
    fn json_round_trips_and_its_parts_agree() {
        for mount in random_mounts(200) {
            let text = render(&mount, ExportFormat::Json).expect("a mount format");
            let (r, t, v) = from_json(&text);
            assert_params_close(&groundcal_of(&r, t), &mount, 1e-9);
            assert_eq!(v["parent"], "base_link");
            assert_eq!(v["child"], "camera_depth_optical_frame");
            let g = |k: &str| v["groundcal"][k].as_f64().unwrap();
            let back = pose(
                g("alpha_deg"),
                g("beta_deg"),
                g("gamma_deg"),
                g("px_mm"),
                g("py_mm"),
                g("pz_mm"),
            );
            assert_params_close(&back, &mount, 1e-12);
            let arr = |k: &str| -> Vec<f64> {
                v[k].as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect()
            };
            let tr = arr("translation_m");
            assert_abs_diff_eq!(Vector3::new(tr[0], tr[1], tr[2]), t, epsilon = 1e-15);
            let rpy = arr("rpy_rad");
            assert_abs_diff_eq!(
                rotation_from_rpy([rpy[0], rpy[1], rpy[2]]),
                r,
                epsilon = 1e-12
            );
            let q = arr("quaternion_xyzw");
            let q =
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[3], q[0], q[1], q[2]));
            assert_abs_diff_eq!(*q.to_rotation_matrix().matrix(), r, epsilon = 1e-12);
        }
    }

    #[test]
    fn rpy_agrees_with_nalgebra_away_from_gimbal_lock() {
        for mount in random_mounts(100) {
            let ros = RosMount::from_groundcal(&mount);
            let (roll, pitch, yaw) = ros.base_link_from_camera_optical.rotation.euler_angles();
            if pitch.abs() > 1.4 {
                continue;
            }
            assert_abs_diff_eq!(
                Vector3::from(ros.rpy_rad),
                Vector3::new(roll, pitch, yaw),
                epsilon = 1e-12
            );
        }
    }

    #[test]
    fn pitch_near_and_at_90_degrees_gives_numbers_that_rebuild_the_rotation() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for sign in [1.0, -1.0] {
            for offset in [0.0, 1e-15, 1e-12, 1e-9, 1e-7, 1e-5, 1e-3] {
                let pitch = sign * (FRAC_PI_2 - offset);
                let roll = rng.gen_range(-3.0..3.0);
                let yaw = rng.gen_range(-3.0..3.0);
                let rotation = rotation_from_rpy([roll, pitch, yaw]);
                let rpy = rpy_from_rotation(&rotation);
                assert!(rpy.iter().all(|v| v.is_finite()), "{rpy:?}");
                assert_abs_diff_eq!(rotation_from_rpy(rpy), rotation, epsilon = 1e-14);
                // Through the whole export: a mount whose ROS pitch is ±90°.
                let transform = Transform::from_parts(
                    Translation3::new(0.1, -0.2, 0.3),
                    Rotation3::from_matrix_unchecked(rotation),
                );
                let mount = PoseDegMm::from_params(&robot_from_sensor_from_ros(&transform));
                for format in [
                    ExportFormat::Urdf,
                    ExportFormat::RosStatic,
                    ExportFormat::Json,
                ] {
                    let text = render(&mount, format).expect("a mount format");
                    assert!(!text.contains("NaN") && !text.contains("inf"), "{text}");
                    let (r, t) = match format {
                        ExportFormat::Urdf => from_urdf(&text),
                        ExportFormat::RosStatic => from_ros_static(&text),
                        ExportFormat::Json | ExportFormat::DepthCorrection => {
                            let (r, t, _) = from_json(&text);
                            (r, t)
                        }
                    };
                    assert_abs_diff_eq!(r, rotation, epsilon = 1e-12);
                    assert_abs_diff_eq!(t, transform.translation.vector, epsilon = 1e-15);
                }
            }
        }
    }

    #[test]
    fn camera_looking_straight_down_or_up_exports_cleanly() {
        // groundcal β = ∓90°: the optical axis along -Y_R / +Y_R (its own gimbal lock).
        for beta in [-90.0, 90.0] {
            let mount = pose(12.0, beta, -30.0, 100.0, 400.0, -20.0);
            let ros = RosMount::from_groundcal(&mount);
            let r = ros.base_link_from_camera_optical.rotation.matrix();
            assert_abs_diff_eq!(
                r * Vector3::z(),
                Vector3::new(0.0, 0.0, beta.signum()),
                epsilon = 1e-15
            );
            for format in [
                ExportFormat::Urdf,
                ExportFormat::RosStatic,
                ExportFormat::Json,
            ] {
                let text = render(&mount, format).expect("a mount format");
                assert!(!text.contains("NaN"), "{text}");
            }
            let (back_r, back_t) = from_urdf(&ros.to_urdf());
            assert_abs_diff_eq!(back_r, *r, epsilon = 1e-12);
            // The parameters come back as the same pose (α and γ only up to their
            // sum, which is all that is defined at β = ±90°).
            let back = groundcal_of(&back_r, back_t).to_params();
            assert_abs_diff_eq!(
                back.to_matrix(),
                mount.to_params().to_matrix(),
                epsilon = 1e-12
            );
        }
    }

    #[test]
    fn frame_change_inverts() {
        for mount in random_mounts(50) {
            let p = mount.to_params();
            let back = robot_from_sensor_from_ros(&base_link_from_camera_optical(&p));
            assert_abs_diff_eq!(back.to_vector(), p.to_vector(), epsilon = 1e-12);
        }
    }

    #[test]
    fn urdf_names_the_joint_frames_and_groundcal_parameters() {
        let mount = pose(-0.4398, -37.4072, -3.0471, 527.8885, 364.8007, -33.4003);
        let urdf = render(&mount, ExportFormat::Urdf).expect("a mount format");
        assert!(urdf.contains(
            "alpha_deg=-0.4398 beta_deg=-37.4072 gamma_deg=-3.0471 \
             px_mm=527.8885 py_mm=364.8007 pz_mm=-33.4003"
        ));
        assert!(urdf.contains("<joint name=\"camera_depth_optical_joint\" type=\"fixed\">"));
        assert!(urdf.contains("<parent link=\"base_link\"/>"));
        assert!(urdf.contains("<child link=\"camera_depth_optical_frame\"/>"));
        assert!(urdf.trim_end().ends_with("</joint>"));
        // An XML comment may not contain "--".
        let comment = urdf.lines().next().unwrap();
        let body = &comment["<!--".len()..comment.len() - "-->".len()];
        assert!(!body.contains("--") && !body.ends_with('-'), "{comment}");
    }

    #[test]
    fn format_names() {
        for f in [
            ExportFormat::Urdf,
            ExportFormat::RosStatic,
            ExportFormat::Json,
        ] {
            assert_eq!(ExportFormat::parse(f.name()), Some(f));
            let clap_name = clap::ValueEnum::to_possible_value(&f).unwrap();
            assert_eq!(clap_name.get_name(), f.name());
        }
        assert_eq!(ExportFormat::parse("yaml"), None);
    }

    // ---- reading result documents

    fn result_doc(status: &str, mount: &PoseDegMm) -> Value {
        serde_json::json!({
            "status": status,
            "reasons": if status == "accepted" { vec![] } else { vec!["the schedule never tilts the body"] },
            "robot_from_sensor": serde_json::to_value(MountJson::from_params(&mount.to_params())).unwrap(),
            "poses": [],
        })
    }

    fn parse(doc: &Value, allow_rejected: bool) -> Result<PoseDegMm, ExportError> {
        parse_result(Path::new("r.json"), &doc.to_string(), allow_rejected)
    }

    fn input_error(doc: &Value) -> String {
        match parse(doc, false) {
            Err(e @ ExportError::Input(_)) => {
                let text = e.to_string();
                assert!(text.starts_with("r.json"), "{text}");
                text
            }
            other => panic!("expected an input error, got {other:?}"),
        }
    }

    #[test]
    fn reads_what_groundcal_writes_exactly() {
        for mount in random_mounts(20) {
            let doc = result_doc("accepted", &mount);
            let got = parse(&doc, false).unwrap();
            // serde_json (without its float_roundtrip feature) may read a
            // number 1 ulp off what it wrote.
            assert_params_close(&got, &PoseDegMm::from_params(&mount.to_params()), 1e-12);
            assert_params_close(&got, &mount, 1e-9);
        }
    }

    #[test]
    fn rejected_results_are_refused_unless_allowed() {
        let mount = pose(1.0, -30.0, 2.0, 500.0, 360.0, -20.0);
        let doc = result_doc("rejected", &mount);
        let err = parse(&doc, false).unwrap_err();
        assert!(matches!(err, ExportError::Rejected { .. }));
        let text = err.to_string();
        assert!(
            text.starts_with("r.json: the calibration was rejected"),
            "{text}"
        );
        assert!(text.contains("the schedule never tilts the body"), "{text}");
        assert_params_close(&parse(&doc, true).unwrap(), &mount, 1e-9);
        // A rejection without parameters, even when allowed.
        let mut doc = doc;
        doc.as_object_mut().unwrap().remove("robot_from_sensor");
        assert!(matches!(
            parse(&doc, false).unwrap_err(),
            ExportError::Rejected { .. }
        ));
        let text = parse(&doc, true).unwrap_err().to_string();
        assert!(text.contains("\"robot_from_sensor\" is missing"), "{text}");
        // Other statuses are not results.
        let mut doc = result_doc("accepted", &mount);
        doc["status"] = "maybe".into();
        assert!(input_error(&doc).contains("\"status\" is \"maybe\""));
        doc.as_object_mut().unwrap().remove("status");
        assert!(input_error(&doc).contains("\"status\" is missing"));
    }

    #[test]
    fn missing_and_non_finite_values_are_named() {
        let mount = pose(1.0, -30.0, 2.0, 500.0, 360.0, -20.0);
        let good = result_doc("accepted", &mount);

        let mut doc = good.clone();
        doc.as_object_mut().unwrap().remove("robot_from_sensor");
        let e = input_error(&doc);
        assert!(e.contains("\"robot_from_sensor\" is missing"), "{e}");

        let mut doc = good.clone();
        doc["robot_from_sensor"]
            .as_object_mut()
            .unwrap()
            .remove("py_mm");
        let e = input_error(&doc);
        assert!(e.contains("\"robot_from_sensor.py_mm\" is missing"), "{e}");

        // serde_json writes NaN as null.
        let mut doc = good.clone();
        doc["robot_from_sensor"]["beta_deg"] = Value::Null;
        let e = input_error(&doc);
        assert!(e.contains("\"robot_from_sensor.beta_deg\" is null"), "{e}");

        let mut doc = good.clone();
        doc["robot_from_sensor"]["gamma_deg"] = "NaN".into();
        let e = input_error(&doc);
        assert!(
            e.contains("\"robot_from_sensor.gamma_deg\" is \"NaN\""),
            "{e}"
        );

        let mut doc = good.clone();
        doc["robot_from_sensor"]["matrix"][2][3] = Value::Null;
        let e = input_error(&doc);
        assert!(
            e.contains("\"robot_from_sensor.matrix[2][3]\" is null"),
            "{e}"
        );

        let mut doc = good.clone();
        doc["robot_from_sensor"]
            .as_object_mut()
            .unwrap()
            .remove("matrix");
        let e = input_error(&doc);
        assert!(e.contains("\"robot_from_sensor.matrix\" is missing"), "{e}");

        // Numbers beyond f64, and Python's NaN / Infinity, are syntax errors
        // for JSON; the key is still named.
        let text = good.to_string();
        for (key, bad) in [
            ("alpha_deg", "1e999"),
            ("px_mm", "NaN"),
            ("pz_mm", "-Infinity"),
        ] {
            let at = text.find(&format!("\"{key}\":")).unwrap() + key.len() + 3;
            let len = text[at..].find([',', '}']).unwrap();
            let broken = format!("{}{bad}{}", &text[..at], &text[at + len..]);
            let e = parse_result(Path::new("r.json"), &broken, false)
                .unwrap_err()
                .to_string();
            assert!(e.starts_with("r.json:1:"), "{e}");
            assert!(e.contains(&format!("at \"{key}\"")), "{e}");
        }
        let e = parse_result(Path::new("r.json"), "[1, 2]", false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("expected a JSON object"), "{e}");
    }

    #[test]
    fn a_matrix_that_disagrees_with_the_parameters_is_refused() {
        let mount = pose(1.0, -30.0, 2.0, 500.0, 360.0, -20.0);
        let mut doc = result_doc("accepted", &mount);
        let m01 = doc["robot_from_sensor"]["matrix"][0][1].as_f64().unwrap();
        // Within the tolerance: accepted.
        doc["robot_from_sensor"]["matrix"][0][1] = (m01 + 5e-7).into();
        assert!(parse(&doc, false).is_ok());
        doc["robot_from_sensor"]["matrix"][0][1] = (m01 + 1e-4).into();
        let e = input_error(&doc);
        assert!(e.contains("\"robot_from_sensor.matrix[0][1]\""), "{e}");
        assert!(e.contains("disagree"), "{e}");
        // Translation in mm.
        let mut doc = result_doc("accepted", &mount);
        doc["robot_from_sensor"]["matrix"][1][3] = 361.0.into();
        assert!(input_error(&doc).contains("matrix[1][3]"));
        // An edited parameter with the old matrix.
        let mut doc = result_doc("accepted", &mount);
        doc["robot_from_sensor"]["alpha_deg"] = 1.5.into();
        assert!(input_error(&doc).contains("disagree"));
        let mut doc = result_doc("accepted", &mount);
        doc["robot_from_sensor"]["matrix"][3] = serde_json::json!([0, 0, 0]);
        assert!(input_error(&doc).contains("\"robot_from_sensor.matrix[3]\""));
        // The quaternion is checked too when present, either sign.
        let mut doc = result_doc("accepted", &mount);
        let q = doc["robot_from_sensor"]["quaternion_xyzw"].clone();
        let negated: Vec<f64> = q
            .as_array()
            .unwrap()
            .iter()
            .map(|v| -v.as_f64().unwrap())
            .collect();
        doc["robot_from_sensor"]["quaternion_xyzw"] = serde_json::json!(negated);
        assert!(parse(&doc, false).is_ok());
        doc["robot_from_sensor"]["quaternion_xyzw"] = serde_json::json!([0, 0, 0, 1]);
        assert!(input_error(&doc).contains("\"robot_from_sensor.quaternion_xyzw\""));
    }

    #[test]
    fn a_missing_file_is_named() {
        let e = read_result(Path::new("/nonexistent/r.json"), false)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("/nonexistent/r.json: cannot open"), "{e}");
    }

    /// docs/export.md's examples are what this module writes for the parameters
    /// in their URDF comment (checked through the independent read-back).
    #[test]
    fn the_documented_examples_are_consistent() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/export.md");
        let Ok(doc) = std::fs::read_to_string(&path) else {
            panic!("{} is missing", path.display());
        };
        let urdf = doc
            .split("```xml\n")
            .nth(1)
            .and_then(|s| s.split("```").next())
            .expect("an xml example");
        let comment = urdf.lines().next().unwrap();
        let value = |key: &str| -> f64 {
            let start = comment.find(&format!(" {key}=")).unwrap() + key.len() + 2;
            comment[start..]
                .split_whitespace()
                .next()
                .unwrap()
                .parse()
                .unwrap()
        };
        let mount = pose(
            value("alpha_deg"),
            value("beta_deg"),
            value("gamma_deg"),
            value("px_mm"),
            value("py_mm"),
            value("pz_mm"),
        );
        assert_eq!(
            urdf,
            render(&mount, ExportFormat::Urdf).expect("a mount format")
        );
        let args = render(&mount, ExportFormat::RosStatic).expect("a mount format");
        assert!(doc.contains(args.trim_end()), "docs lack {args}");
        let json = doc
            .split("```json\n")
            .nth(1)
            .and_then(|s| s.split("```").next())
            .expect("a json example");
        assert_eq!(
            json,
            render(&mount, ExportFormat::Json).expect("a mount format")
        );
    }
}
