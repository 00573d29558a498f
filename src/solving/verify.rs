//! Checking a calibration against the sensor now (`groundcal verify`, the
//! daemon's start-up check and its "Check" button), and the tilt motor's
//! steadiness during a calibration. The math is `calib::verify`; this module
//! turns visited poses into its input and its report into the document the
//! operator reads (docs/verify.md).

use std::path::Path;

use nalgebra::Vector3;
use serde::Serialize;

use crate::calib::geometry::{PoseDegMm, PoseParams, Transform};
use crate::calib::observe::NominalMount;
use crate::calib::solve::Observation;
use crate::calib::verify::{
    verify, ActiveMount, Check, DirectionChange, Unit, VerifyError, VerifyPose, VerifyReport,
    VerifySettings,
};
use crate::formats::output::{MotorJson, MountJson, ResultJson, ResultStatus, SigmaJson};
use crate::formats::store::Store;
use crate::setup::config::Config;
use crate::setup::schedule::Schedule;

/// The accelerometer at one pose, its readings averaged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GravityReading {
    /// Gravity's reaction (up) in the sensor frame (X forward, Y up, Z
    /// right), in g: the accelerometer's (right, up, forward) reordered.
    pub up_sensor: Vector3<f64>,
    pub readings: usize,
    /// The angle the tilt motor reported, degrees (its own reading, half
    /// degrees, relative to gravity).
    pub motor_reported_deg: f64,
}

impl GravityReading {
    /// The mean of a pose's readings; none when there are none, or when
    /// they are not about 1 g (a sensor that reports no accelerometer, or
    /// one that moved).
    pub fn from_states(states: &[groundcal_hal::TiltState]) -> Option<Self> {
        if states.is_empty() {
            return None;
        }
        let n = states.len() as f64;
        let mean = |k: usize| states.iter().map(|s| s.accelerometer_g[k]).sum::<f64>() / n;
        let up_sensor = Vector3::new(mean(2), mean(1), mean(0));
        let magnitude = up_sensor.norm();
        if !(0.7..=1.3).contains(&magnitude) {
            return None;
        }
        Some(GravityReading {
            up_sensor,
            readings: states.len(),
            motor_reported_deg: states.iter().map(|s| s.tilt_deg).sum::<f64>() / n,
        })
    }
}

/// One pose a session visited.
#[derive(Debug, Clone)]
pub struct VisitedPose {
    pub index: u32,
    /// The real body pose from the feet, when they fixed it.
    pub ground_from_robot: Option<Transform>,
    /// The pose's observation, or why there is none.
    pub fit: Result<Observation, String>,
    pub gravity: Option<GravityReading>,
}

impl VisitedPose {
    /// The poses' observations, and the poses that gave none with why.
    pub fn fits(poses: &[VisitedPose]) -> (Vec<Observation>, Vec<(u32, String)>) {
        let mut observations = Vec::new();
        let mut failed = Vec::new();
        for pose in poses {
            match &pose.fit {
                Ok(o) => observations.push(o.clone()),
                Err(reason) => failed.push((pose.index, reason.clone())),
            }
        }
        (observations, failed)
    }

    /// Lets go of the poses' ground residuals once the depth pattern has
    /// been estimated from them: a second fit about the pattern makes its
    /// own, and holding both doubled them at the peak (heaptrack: 20.0 MB
    /// for both sets of a 52-pose calibration, of a 57.5 MB heap).
    pub fn forget_ground_residuals(poses: &mut [VisitedPose]) {
        for pose in poses {
            if let Ok(observation) = &mut pose.fit {
                observation.ground_residuals = None;
            }
        }
    }
}

/// The calibration to check: its mount and σ, and the tilt it holds for.
pub struct Calibration {
    pub mount: ActiveMount,
    pub tilt_deg: Option<f64>,
    /// Where it came from, for messages.
    pub source: String,
    /// Its store id (`id`), when it has one.
    pub id: Option<String>,
    /// The robot it was made for, when it says (`robot.name`, or a
    /// replay's `setup.robot`).
    pub robot: Option<String>,
    /// The Kinect's depth pattern it corrected: a check takes it out of its
    /// frames, as the calibration did.
    pub depth_correction: Option<std::sync::Arc<crate::calib::distortion::DepthCorrection>>,
}

impl Calibration {
    /// Refuses to compare this calibration with another robot's poses:
    /// `other` is the robot they come from, as `what` names it ("this
    /// recording", "the configuration").
    pub fn same_robot(&self, other: Option<&str>, what: &str) -> Result<(), String> {
        match (self.robot.as_deref(), other) {
            (Some(ours), Some(theirs)) if ours != theirs => Err(format!(
                "{} was made for robot \"{ours}\", but {what} is robot \"{theirs}\": a calibration holds for its own robot only",
                self.source
            )),
            _ => Ok(()),
        }
    }
}

/// Reads the calibration from a file, or the store's active one.
pub fn load_calibration(
    file: Option<&Path>,
    config: &Config,
    config_path: Option<&Path>,
) -> Result<Calibration, String> {
    let (document, source) = match file {
        Some(path) => {
            let bytes =
                crate::platform::input::read_bounded(path, 16 << 20).map_err(|e| e.to_string())?;
            let value: serde_json::Value = serde_json::from_slice(&bytes)
                .map_err(|e| format!("{}: not JSON: {e}", path.display()))?;
            (value, path.display().to_string())
        }
        None => {
            let serve = config.serve.as_ref().ok_or(
                "no --calibration FILE, and the configuration has no [serve] state_dir to find the active calibration in",
            )?;
            let dir = match config_path {
                Some(p) => crate::setup::config::resolve_from_config(p, &serve.state_dir),
                None => serve.state_dir.clone(),
            };
            return calibration_in_store(&Store::new(&dir))?.ok_or_else(|| {
                format!(
                    "no calibration is active in {} yet: calibrate and accept one, or give --calibration FILE",
                    dir.display()
                )
            });
        }
    };
    calibration_of(document, source)
}

/// The store's active calibration, if one is.
pub fn calibration_in_store(store: &Store) -> Result<Option<Calibration>, String> {
    match store.active().map_err(|e| e.to_string())? {
        Some(active) => {
            // The active document carries the result's keys: read as one.
            let document = serde_json::to_value(&active)
                .map_err(|e| format!("cannot read the active calibration: {e}"))?;
            calibration_of(document, store.active_path().display().to_string()).map(Some)
        }
        None => Ok(None),
    }
}

/// A document's store id.
fn document_id(document: &serde_json::Value) -> Option<String> {
    document
        .get("id")
        .and_then(serde_json::Value::as_str)
        .map(String::from)
}

/// A calibration from its document.
fn calibration_of(document: serde_json::Value, source: String) -> Result<Calibration, String> {
    let id = document_id(&document);
    let robot = document
        .pointer("/robot/name")
        .or_else(|| document.pointer("/setup/robot"))
        .and_then(serde_json::Value::as_str)
        .map(String::from);
    let result = ResultJson::parse(document).map_err(|e| format!("{source}: {e}"))?;
    let mount = mount_of(&result).map_err(|e| format!("{source}: {e}"))?;
    let depth_correction = result
        .depth_pattern
        .as_ref()
        .filter(|p| p.corrected)
        .and_then(|p| {
            crate::calib::distortion::DepthCorrection::from_cells(
                p.columns, p.rows, p.cell_px, &p.raw,
            )
        })
        .map(std::sync::Arc::new);
    Ok(Calibration {
        id,
        robot,
        mount,
        tilt_deg: result.kinect_tilt_deg,
        source,
        depth_correction,
    })
}

/// The calibrated mount as the prior that tells the ground from other
/// planes: a knock is far less than 10°.
pub fn ground_prior(mount: &ActiveMount) -> NominalMount {
    let values = crate::calib::geometry::PoseDegMm::from_params(&mount.robot_from_sensor).values();
    NominalMount {
        tolerance_deg: 10.0,
        tolerance_mm: 150.0,
        ..NominalMount::from_values(values)
    }
}

/// The mount and σ of a result or an active calibration document.
pub fn mount_of(result: &ResultJson) -> Result<ActiveMount, String> {
    let mount = result.robot_from_sensor.as_ref().ok_or_else(|| {
        "it has no \"robot_from_sensor\": it was not solved, so there is nothing to verify"
            .to_string()
    })?;
    let depth_scale = result.depth_scale.unwrap_or(1.0);
    if !(0.5..=2.0).contains(&depth_scale) {
        return Err(format!(
            "\"depth_scale\" is {depth_scale}, not a Kinect's depth scale (near 1)"
        ));
    }
    let sigma = result
        .sigma
        .as_ref()
        .map(SigmaJson::radians_metres)
        .filter(|v| v.iter().all(|x| x.is_finite()));
    Ok(ActiveMount {
        robot_from_sensor: mount.pose().to_params(),
        sigma,
        correlations: result.correlations,
        depth_scale,
        depth_scale_sigma: result
            .sigma
            .as_ref()
            .and_then(|s| s.depth_scale)
            .filter(|s| s.is_finite()),
        depth_scale_correlations: result.depth_scale_correlations,
    })
}

/// The visited poses against `mount`.
pub fn compare(
    mount: &ActiveMount,
    poses: &[VisitedPose],
    settings: &VerifySettings,
) -> Result<VerifyReport, VerifyError> {
    verify(mount, &verify_poses(poses, true), settings)
}

/// The poses as the math takes them; without their planes when `planes` is
/// false (gravity alone).
fn verify_poses(poses: &[VisitedPose], planes: bool) -> Vec<VerifyPose> {
    poses
        .iter()
        .filter_map(|p| {
            let ground_from_robot: Transform = match &p.fit {
                Ok(o) => o.ground_from_robot,
                Err(_) => p.ground_from_robot?,
            };
            Some(VerifyPose {
                index: p.index,
                ground_from_robot,
                plane: p
                    .fit
                    .as_ref()
                    .ok()
                    .filter(|o| planes && o.set_aside.is_none())
                    .map(|o| o.plane),
                gravity_up: p.gravity.map(|g| g.up_sensor),
                gravity_readings: p.gravity.map_or(0, |g| g.readings),
            })
        })
        .collect()
}

/// The smallest change of the motor's angle during a calibration that is
/// called a move: the Kinect reports its angle in half degrees.
const MOTOR_MOVED_MIN_DEG: f64 = 0.5;

/// Adds the tilt motor's report to a solved result (when the poses carry
/// accelerometer readings) and rejects it when the motor moved during the
/// calibration: the mount then differs from pose to pose.
pub fn judge_motor(
    result: &mut ResultJson,
    poses: &[VisitedPose],
    commanded_deg: f64,
    settings: &VerifySettings,
) {
    let Ok(mount) = mount_of(result) else {
        return;
    };
    let Ok(report) = verify(&mount, &verify_poses(poses, false), settings) else {
        return;
    };
    let turns: Vec<(u32, f64)> = report
        .poses
        .iter()
        .filter_map(|p| Some((p.index, p.motor_turn?.to_degrees())))
        .collect();
    if turns.is_empty() {
        return;
    }
    let readings = poses
        .iter()
        .filter_map(|p| p.gravity.map(|g| g.readings))
        .min()
        .unwrap_or(1)
        .max(1);
    let per_pose = settings.accelerometer_sigma_deg / (readings as f64).sqrt();
    let limit = (2.0 * settings.k_sigma * per_pose).max(MOTOR_MOVED_MIN_DEG);
    let (low, high) = turns
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), t| {
            (l.min(t.1), h.max(t.1))
        });
    let mean_turn = turns.iter().map(|t| t.1).sum::<f64>() / turns.len() as f64;
    let reported: Vec<f64> = poses
        .iter()
        .filter_map(|p| p.gravity.map(|g| g.motor_reported_deg))
        .collect();
    let motor = MotorJson {
        commanded_deg,
        reported_deg: (!reported.is_empty())
            .then(|| reported.iter().sum::<f64>() / reported.len() as f64),
        pitch_to_body_deg: optical_axis_pitch(&mount.robot_from_sensor, mean_turn.to_radians()),
        turn_spread_deg: high - low,
        turn_limit_deg: limit,
        moved: high - low > limit,
        poses: turns.len(),
    };
    for pose in &mut result.poses {
        pose.motor_turn_deg = turns
            .iter()
            .find(|t| t.0 == pose.index)
            .map(|t| t.1 - mean_turn);
    }
    if motor.moved {
        let at = |value: f64| turns.iter().find(|t| t.1 == value).map_or(0, |t| t.0);
        let (first, second) = (at(low).min(at(high)), at(low).max(at(high)));
        result.status = ResultStatus::Rejected;
        result.reasons.push(format!(
            "the Kinect's tilt motor moved during the calibration: the sensor's angle against the body differs by {:.2}° between pose {first} and pose {second} (from the accelerometer; limit {limit:.2}°). Check that nothing touches the Kinect and calibrate again",
            high - low,
        ));
    }
    result.motor = Some(motor);
}

/// The optical axis's pitch against the body's forward axis, degrees, for
/// the mount turned by `turn` about the sensor's right axis (the motor's).
fn optical_axis_pitch(mount: &PoseParams, turn: f64) -> f64 {
    let turned = mount.rotation_matrix() * crate::calib::geometry::rot_z(turn);
    let optical_axis = turned.column(0);
    optical_axis.y.clamp(-1.0, 1.0).asin().to_degrees()
}

/// The schedule of a check: the home stance held, then `tilted` poses that
/// roll and pitch the body by ±`tilt_deg` in turn (a rotation about the
/// vertical shows only when the body tilts).
pub fn check_schedule(home: PoseDegMm, tilted: usize, tilt_deg: f64) -> Schedule {
    let mut poses = vec![home];
    for k in 0..tilted {
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        // Roll right, left, pitch up, down; then the four diagonals, at 70 %.
        let (roll, pitch) = match k % 8 {
            0 | 1 => (sign, 0.0),
            2 | 3 => (0.0, sign),
            4 | 5 => (sign * 0.7, sign * 0.7),
            _ => (sign * 0.7, -sign * 0.7),
        };
        poses.push(PoseDegMm {
            gamma_deg: home.gamma_deg + roll * tilt_deg,
            beta_deg: home.beta_deg + pitch * tilt_deg,
            ..home
        });
    }
    Schedule {
        name: if tilted == 0 {
            "check: the home stance".into()
        } else {
            format!("check: the home stance and {tilted} tilted poses (±{tilt_deg}°)")
        },
        home,
        poses,
        file: None,
    }
}

/// One check as the document says it.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct CheckJson {
    pub name: String,
    /// Degrees or millimetres, as `unit` says.
    pub measured: f64,
    pub threshold: f64,
    pub unit: String,
    pub passed: bool,
}

/// One direction's change, degrees or millimetres.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct DirectionJson {
    pub direction: String,
    /// `ground` or `gravity`.
    pub from: String,
    pub change: f64,
    pub sigma: f64,
    pub unit: String,
    pub checked: bool,
}

/// One drift, typed ([`crate::calib::verify::Drift`]): for a page that
/// words it in its own language.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct DriftJson {
    /// `ground` or `gravity`: which measurement says it.
    pub from: String,
    pub changes: Vec<DriftChangeJson>,
    /// The accelerometer says so but the ground does not.
    #[serde(default)]
    pub ground_disagrees: bool,
}

/// One direction's change in a drift, degrees or millimetres, signed:
/// positive is right (roll), left (yaw), up (pitch), forward, higher, right
/// (sideways), as the English words read it.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct DriftChangeJson {
    pub direction: String,
    pub change: f64,
    pub unit: String,
}

/// One pose against the calibration.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct VerifyPoseJson {
    pub index: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub theta_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub e_d_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gravity_angle_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motor_turn_deg: Option<f64>,
    /// Why the pose gave no ground.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The tilt motor against the calibration.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct VerifyMotorJson {
    /// The tilt the calibration holds for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibrated_deg: Option<f64>,
    /// The motor's own reading now.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reported_deg: Option<f64>,
    /// The sensor's turn about the motor's axis against the calibration,
    /// from gravity (positive up).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub turn_deg: Option<f64>,
}

/// What `groundcal verify --json` prints, and the daemon's status keeps.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct VerifyJson {
    /// `consistent` or `drift`.
    pub status: String,
    #[serde(default)]
    pub reasons: Vec<String>,
    /// The reasons, typed, in their order.
    #[serde(default)]
    pub drifts: Vec<DriftJson>,
    pub checks: Vec<CheckJson>,
    pub directions: Vec<DirectionJson>,
    /// Directions these poses cannot see.
    pub not_checked: Vec<String>,
    pub poses: Vec<VerifyPoseJson>,
    pub motor: VerifyMotorJson,
    /// The calibration checked.
    pub robot_from_sensor: MountJson,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

fn check_json(c: &Check) -> CheckJson {
    let (scale, unit) = match c.unit {
        Unit::Angle => (180.0 / std::f64::consts::PI, "deg"),
        Unit::Length => (1000.0, "mm"),
    };
    CheckJson {
        name: c.name.into(),
        measured: c.measured * scale,
        threshold: c.threshold * scale,
        unit: unit.into(),
        passed: c.passed,
    }
}

fn drift_json(d: &crate::calib::verify::Drift) -> DriftJson {
    use crate::calib::verify::Witness;
    DriftJson {
        from: match d.witness {
            Witness::Ground => "ground",
            Witness::Gravity => "gravity",
        }
        .into(),
        changes: d
            .changes
            .iter()
            .map(|(direction, change)| {
                let (scale, unit) = if direction.is_rotation() {
                    (180.0 / std::f64::consts::PI, "deg")
                } else {
                    (1000.0, "mm")
                };
                DriftChangeJson {
                    direction: direction.name().into(),
                    change: change * scale,
                    unit: unit.into(),
                }
            })
            .collect(),
        ground_disagrees: d.ground_disagrees,
    }
}

fn direction_json(c: &DirectionChange, from: &str) -> DirectionJson {
    let (scale, unit) = if c.direction.is_rotation() {
        (180.0 / std::f64::consts::PI, "deg")
    } else {
        (1000.0, "mm")
    };
    DirectionJson {
        direction: c.direction.name().into(),
        from: from.into(),
        change: c.change * scale,
        sigma: c.sigma * scale,
        unit: unit.into(),
        checked: c.seen,
    }
}

impl VerifyJson {
    /// The document of a report on `poses` against `mount`, whose
    /// calibration holds for the motor at `calibrated_tilt_deg`.
    pub fn new(
        report: &VerifyReport,
        poses: &[VisitedPose],
        mount: &ActiveMount,
        calibrated_tilt_deg: Option<f64>,
    ) -> Self {
        let mut notes = report.notes.clone();
        let reported: Vec<f64> = poses
            .iter()
            .filter_map(|p| p.gravity.map(|g| g.motor_reported_deg))
            .collect();
        let reported_deg =
            (!reported.is_empty()).then(|| reported.iter().sum::<f64>() / reported.len() as f64);
        if reported.is_empty() {
            notes.push("no accelerometer readings: gravity was not checked".into());
        }
        if let (Some(calibrated), Some(now)) = (calibrated_tilt_deg, reported_deg) {
            // The motor reports half degrees, and reaches its angle roughly.
            if (now - calibrated).abs() > 1.0 {
                notes.push(format!(
                    "the tilt motor reports {now:.1}° where the calibration holds for {calibrated:.1}°"
                ));
            }
        }
        let ground_seen: Vec<_> = report.ground.iter().filter(|c| c.seen).collect();
        let not_checked = crate::calib::verify::Direction::ALL
            .iter()
            .filter(|d| !ground_seen.iter().any(|c| c.direction == **d))
            .map(|d| d.name().to_string())
            .collect();
        let poses_json = report
            .poses
            .iter()
            .map(|p| VerifyPoseJson {
                index: p.index,
                theta_deg: p.theta.map(f64::to_degrees),
                e_d_mm: p.e_d.map(|e| e * 1000.0),
                gravity_angle_deg: p.gravity_angle.map(f64::to_degrees),
                motor_turn_deg: p.motor_turn.map(f64::to_degrees),
                error: poses
                    .iter()
                    .find(|v| v.index == p.index)
                    .and_then(|v| v.fit.as_ref().err().cloned()),
            })
            .collect();
        VerifyJson {
            status: if report.drifted() {
                "drift"
            } else {
                "consistent"
            }
            .into(),
            reasons: report.reasons.clone(),
            drifts: report.drifts.iter().map(drift_json).collect(),
            checks: report.checks.iter().map(check_json).collect(),
            directions: report
                .ground
                .iter()
                .map(|c| direction_json(c, "ground"))
                .chain(report.gravity.iter().map(|c| direction_json(c, "gravity")))
                .collect(),
            not_checked,
            poses: poses_json,
            motor: VerifyMotorJson {
                calibrated_deg: calibrated_tilt_deg,
                reported_deg,
                turn_deg: report.motor_turn().map(f64::to_degrees),
            },
            robot_from_sensor: MountJson::from_params(&mount.robot_from_sensor),
            notes,
        }
    }

    pub fn drifted(&self) -> bool {
        self.status == "drift"
    }

    /// The report for a terminal: the verdict and its reasons, each check
    /// against its threshold, what was not checked, the motor.
    pub fn to_table(&self) -> String {
        use std::fmt::Write;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{:<20} {:>11} {:>11}",
            "check", "measured", "threshold"
        );
        for c in &self.checks {
            let (m, t) = if c.unit == "deg" {
                (
                    format!("{:.3}°", c.measured),
                    format!("{:.3}°", c.threshold),
                )
            } else {
                (
                    format!("{:.2} mm", c.measured),
                    format!("{:.2} mm", c.threshold),
                )
            };
            let verdict = if c.passed { "passed" } else { "FAILED" };
            let _ = writeln!(out, "{:<20} {m:>11} {t:>11}  {verdict}", c.name);
        }
        if !self.not_checked.is_empty() {
            let _ = writeln!(
                out,
                "not checked (these poses cannot see it): {}",
                self.not_checked.join(", ")
            );
        }
        let m = &self.motor;
        let mut motor = Vec::new();
        if let Some(r) = m.reported_deg {
            motor.push(format!("reports {r:.1}°"));
        }
        if let Some(c) = m.calibrated_deg {
            motor.push(format!("calibrated at {c:.1}°"));
        }
        if let Some(t) = m.turn_deg {
            motor.push(format!(
                "turned {t:+.2}° against the calibration (from gravity)"
            ));
        }
        if !motor.is_empty() {
            let _ = writeln!(out, "tilt motor: {}", motor.join("; "));
        }
        for note in &self.notes {
            if !note.starts_with("not checked") {
                let _ = writeln!(out, "note: {note}");
            }
        }
        let _ = writeln!(out);
        if self.drifted() {
            let _ = writeln!(
                out,
                "DRIFT: the sensor no longer agrees with the calibration"
            );
            for r in &self.reasons {
                let _ = writeln!(out, "  - {r}");
            }
            let _ = writeln!(
                out,
                "  Calibrate again before the robot relies on its terrain map."
            );
        } else {
            let _ = writeln!(out, "consistent: the sensor agrees with the calibration");
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::geometry::ground_in_sensor;
    use crate::calib::solve::Observation;

    const MOUNT: [f64; 6] = [0.8, -33.0, 1.5, 510.0, 370.0, 15.0];

    /// Poses of the paper's kind (rolled and pitched), each with the
    /// gravity the sensor feels when its motor turned by `turn(k)` degrees
    /// about its right axis since the calibration.
    fn poses(turn: impl Fn(usize) -> f64) -> Vec<VisitedPose> {
        let mount = PoseDegMm::from_values(MOUNT).to_params().to_transform();
        (0..12)
            .map(|k| {
                let body = PoseDegMm::from_values([
                    0.0,
                    [0.0, 8.0, -8.0][k % 3],
                    [15.0, -15.0, 0.0, 5.0][k % 4],
                    0.0,
                    600.0,
                    0.0,
                ])
                .to_params()
                .to_transform();
                let motor = Transform::from_parts(
                    nalgebra::Translation3::identity(),
                    nalgebra::Rotation3::from_matrix_unchecked(crate::calib::geometry::rot_z(
                        turn(k).to_radians(),
                    )),
                );
                let up = ground_in_sensor(&(body * mount * motor)).normal;
                let plane = ground_in_sensor(&(body * mount));
                VisitedPose {
                    index: k as u32 + 1,
                    ground_from_robot: Some(body),
                    fit: Ok(Observation::new(k as u32 + 1, body, plane)),
                    gravity: Some(GravityReading {
                        up_sensor: up,
                        readings: 10,
                        motor_reported_deg: -20.0,
                    }),
                }
            })
            .collect()
    }

    fn result() -> ResultJson {
        let mut result = ResultJson::unsolved("x".into(), &[]);
        result.status = ResultStatus::Accepted;
        result.reasons.clear();
        result.robot_from_sensor = Some(MountJson::from_params(
            &PoseDegMm::from_values(MOUNT).to_params(),
        ));
        result.poses = (1..=12)
            .map(|i| crate::formats::output::PoseJson::failed(i, String::new()))
            .collect();
        result
    }

    #[test]
    fn a_steady_motor_passes_and_its_angle_against_the_body_is_the_mounts_pitch() {
        let mut r = result();
        judge_motor(&mut r, &poses(|_| 0.0), -20.0, &VerifySettings::default());
        let motor = r.motor.clone().unwrap();
        assert!(!motor.moved, "{motor:?}");
        assert!(motor.turn_spread_deg < 1e-6, "{motor:?}");
        // β is the optical axis's pitch against the body (α, γ small).
        assert!((motor.pitch_to_body_deg + 33.0).abs() < 0.05, "{motor:?}");
        assert_eq!(motor.poses, 12);
        assert_eq!(motor.reported_deg, Some(-20.0));
        assert_eq!(r.status, ResultStatus::Accepted);
    }

    #[test]
    fn a_motor_that_moved_midway_rejects_the_calibration_naming_the_poses() {
        let mut r = result();
        judge_motor(
            &mut r,
            &poses(|k| if k >= 6 { -1.0 } else { 0.0 }),
            -20.0,
            &VerifySettings::default(),
        );
        let motor = r.motor.clone().unwrap();
        assert!(motor.moved, "{motor:?}");
        assert!((motor.turn_spread_deg - 1.0).abs() < 0.02, "{motor:?}");
        assert_eq!(r.status, ResultStatus::Rejected);
        let reason = r.reasons.join(" ");
        assert!(
            reason.contains("tilt motor moved") && reason.contains("1.00°"),
            "{reason}"
        );
        // One pose before the move (1-6), one after (7-12), in that order.
        let poses: Vec<u32> = reason
            .split("pose ")
            .skip(1)
            .filter_map(|w| w.split_whitespace().next()?.parse().ok())
            .collect();
        assert!(
            poses.len() == 2 && poses[0] <= 6 && poses[1] >= 7,
            "{reason}"
        );
        // Each pose's turn against the mean: half a degree either way.
        let turns: Vec<f64> = r.poses.iter().filter_map(|p| p.motor_turn_deg).collect();
        assert_eq!(turns.len(), 12);
        assert!(
            turns.iter().all(|t| (t.abs() - 0.5).abs() < 0.02),
            "{turns:?}"
        );
    }

    #[test]
    fn the_checks_schedule_holds_home_then_tilts_each_way() {
        let home = PoseDegMm::from_values([0.0, 0.0, 0.0, 0.0, 600.0, 0.0]);
        let still = check_schedule(home, 0, 8.0);
        assert_eq!(still.poses, vec![home]);
        let tilted = check_schedule(home, 4, 8.0);
        let rolls: Vec<f64> = tilted.poses.iter().map(|p| p.gamma_deg).collect();
        let pitches: Vec<f64> = tilted.poses.iter().map(|p| p.beta_deg).collect();
        assert_eq!(rolls, [0.0, 8.0, -8.0, 0.0, 0.0]);
        assert_eq!(pitches, [0.0, 0.0, 0.0, 8.0, -8.0]);
    }
}
