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

mod mount;
mod numbers;
mod pattern;
mod poses;
mod words;

use serde::{Deserialize, Deserializer, Serialize};

use crate::calib::geometry::{Plane, PoseDegMm, PoseParams};
use crate::calib::observe::NominalMount;
use crate::calib::outcome::{Calibration, GateCheck, PoseOutcome, Verdict};
use crate::calib::sensor::{DepthModel, Intrinsics};

pub use mount::*;
use numbers::*;
pub use pattern::*;
pub use poses::*;
pub use words::*;

/// Most ground fits of one calibration: the first, and those about the
/// depth pattern's estimate as it grows (each cuts less of what is left).
pub const MOST_GROUND_FITS: usize = 4;

/// A failed gate on `e_d` that is the depth camera's noise: the poses'
/// disagreement grows with the ground's distance and its largest is
/// ordinary there (`calib::disagreement`); the page words its advice from
/// this, not from the reason's English. A figure that is not a number (an
/// exact fit's infinite exponent σ) is written as null and read back as NaN,
/// as the other figures are, so that the stored result still reads.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorNoiseJson {
    /// `e_d`'s σ grows as the ground's distance to this power.
    #[serde(deserialize_with = "number_or_nan")]
    pub exponent: f64,
    /// The exponent in its own σ.
    #[serde(deserialize_with = "number_or_nan")]
    pub exponent_sigmas: f64,
    /// The nearest used pose's ground distance (m) and `e_d`'s σ there (mm).
    #[serde(deserialize_with = "number_or_nan")]
    pub nearest_m: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub nearest_sigma_mm: f64,
    /// The farthest used pose's ground distance (m) and `e_d`'s σ there (mm).
    #[serde(deserialize_with = "number_or_nan")]
    pub farthest_m: f64,
    #[serde(deserialize_with = "number_or_nan")]
    pub farthest_sigma_mm: f64,
    /// The pose with the largest `e_d`, and that `e_d` in its σ there.
    pub worst_pose: u32,
    #[serde(deserialize_with = "number_or_nan")]
    pub worst_sigmas: f64,
    /// The most, in σ, the largest of this many poses reaches by chance
    /// once in a hundred calibrations.
    #[serde(deserialize_with = "number_or_nan")]
    pub worst_bound: f64,
}

impl SensorNoiseJson {
    fn from_growth(g: &crate::calib::outcome::GrowthWithDistance) -> Self {
        Self {
            exponent: g.exponent,
            exponent_sigmas: g.exponent_sigmas,
            nearest_m: g.nearest[0],
            nearest_sigma_mm: g.nearest[1] * 1e3,
            farthest_m: g.farthest[0],
            farthest_sigma_mm: g.farthest[1] * 1e3,
            worst_pose: g.worst_pose,
            worst_sigmas: g.worst_sigmas,
            worst_bound: g.worst_bound,
        }
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
    /// When the gate on `e_d` failed because of the depth camera's noise at
    /// the farthest poses, not the ground or the feet.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub e_d_from_sensor_noise: Option<SensorNoiseJson>,
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
            e_d_from_sensor_noise: c
                .e_d_from_sensor_noise
                .as_ref()
                .map(SensorNoiseJson::from_growth),
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
            e_d_from_sensor_noise: None,
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
    ) -> Solved {
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
    ) -> Solved {
        use crate::calib::calibrate::calibrate_taken_out;
        use crate::calib::solve::SolveError;
        let mut fit_again_about = None;
        let mut result =
            match calibrate_taken_out(observations, poses_total, settings, taken_out) {
                Ok(calibration) => {
                    fit_again_about = calibration
                        .depth_pattern
                        .as_ref()
                        .and_then(|p| p.fit_again_about.clone());
                    Self::from_calibration(&calibration)
                }
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
        Solved {
            result,
            fit_again_about,
        }
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

/// A result, and what a second fit of the ground would start from: the
/// depth pattern's shape, when the ground fit's band cut its peaks (kept
/// beside the result document, never in it).
#[derive(Debug, Clone)]
pub struct Solved {
    pub result: ResultJson,
    /// The shape to take out of the frames before fitting their ground
    /// again (docs/method.md, "A pattern beyond the fit's band").
    pub fit_again_about: Option<crate::calib::distortion::DepthCorrection>,
}

impl Solved {
    /// When the ground fit's band cut a depth pattern's peaks in this
    /// result, fits the frames again with its estimate taken out
    /// (`fit_again`, for a correction taken out of every frame) until what
    /// is left is a pattern fixed in the image: the result that got there
    /// (with what `fit_again` kept beside it), or `None` to keep this one
    /// (what is left is not such a pattern, or the fits ran out).
    pub fn fit_about_the_pattern<T, E>(
        &self,
        mut fit_again: impl FnMut(&crate::calib::distortion::DepthCorrection) -> Result<(Solved, T), E>,
    ) -> Result<Option<(ResultJson, T)>, E> {
        let Some(mut taken_out) = self.fit_again_about.clone() else {
            return Ok(None);
        };
        for fit in 2..=MOST_GROUND_FITS {
            let (again, kept) = fit_again(&taken_out)?;
            let mut result = again.result;
            tracing::info!(
                fit,
                pattern = result.depth_pattern.as_ref().map(|p| p.note.as_str()),
                "the ground fitted again about the depth pattern"
            );
            if let (Some(pattern), Some(first)) =
                (&mut result.depth_pattern, &self.result.depth_pattern)
            {
                if pattern.corrected {
                    // The evidence that there is a shape is the first fit's:
                    // the later ones see what is left of it.
                    pattern.shape_sigmas = first.shape_sigmas;
                    pattern.shape_chi2_per_dof = first.shape_chi2_per_dof;
                    return Ok(Some((result, kept)));
                }
            }
            let Some(more) = again.fit_again_about else {
                break;
            };
            for (all, left) in taken_out.raw.iter_mut().zip(&more.raw) {
                *all += left;
            }
        }
        Ok(None)
    }
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
        pattern.angle_sigma_known_plane_part_deg = Some([0.0017, 0.0006, 0.0007]);
        pattern.angle_sigma_growth_by_geometry = Some([1.4, f64::INFINITY, 5.1]);
        let error = pattern.validate().unwrap_err();
        assert!(
            error.contains("\"angle_sigma_growth_by_geometry[1]\" is inf, not a ratio of σ"),
            "{error}"
        );
    }

    /// A figure of the sensor-noise finding that is not a finite number is
    /// written as null (JSON has no infinity) and the stored result still
    /// reads: the daemon reads its results back.
    #[test]
    fn a_sensor_noise_finding_with_an_infinite_figure_reads_back() {
        let mut result = table2();
        result.e_d_from_sensor_noise = Some(SensorNoiseJson {
            exponent: 4.0,
            exponent_sigmas: f64::INFINITY,
            nearest_m: 0.64,
            nearest_sigma_mm: 0.1,
            farthest_m: 1.23,
            farthest_sigma_mm: 3.0,
            worst_pose: 35,
            worst_sigmas: 2.0,
            worst_bound: 3.73,
        });
        let text = serde_json::to_string(&result).unwrap();
        assert!(text.contains("\"exponent_sigmas\":null"), "{text}");
        let back: ResultJson = serde_json::from_str(&text).expect("reads back");
        let noise = back.e_d_from_sensor_noise.expect("kept");
        assert!(noise.exponent_sigmas.is_nan() && noise.worst_pose == 35);
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
            disparity: None,
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
