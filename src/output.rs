//! The result document of `shared/spec/cli.md`, and its readable table.
//!
//! Keys and units are the contract: degrees and millimetres in names ending
//! `_deg` and `_mm`, plane offsets in metres (`d_m`).

use serde::Serialize;

use crate::calib::geometry::{Plane, PoseDegMm, PoseParams};
use crate::calib::outcome::{Calibration, PoseOutcome, Verdict};

/// `robot_from_sensor` as cli.md prints it.
#[derive(Debug, Clone, Serialize)]
pub struct MountJson {
    pub alpha_deg: f64,
    pub beta_deg: f64,
    pub gamma_deg: f64,
    pub px_mm: f64,
    pub py_mm: f64,
    pub pz_mm: f64,
    /// 4×4, translation in millimetres.
    pub matrix: [[f64; 4]; 4],
    pub quaternion_xyzw: [f64; 4],
}

impl MountJson {
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
            quaternion_xyzw: [q.i * sign, q.j * sign, q.k * sign, q.w * sign],
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct SigmaJson {
    pub alpha_deg: f64,
    pub beta_deg: f64,
    pub gamma_deg: f64,
    pub px_mm: f64,
    pub py_mm: f64,
    pub pz_mm: f64,
}

#[derive(Debug, Clone, Copy, Serialize)]
pub struct PlaneJson {
    pub a: f64,
    pub b: f64,
    pub c: f64,
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
#[derive(Debug, Clone, Serialize)]
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
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct SummaryJson {
    pub poses_used: usize,
    pub poses_total: usize,
    pub theta_deg_mean: f64,
    pub theta_deg_max: f64,
    pub e_d_mm_mean: f64,
    pub e_d_mm_max: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct ObservabilityJson {
    pub rotation_singular_values: [f64; 3],
    pub translation_singular_values: [f64; 3],
}

/// The whole result document.
#[derive(Debug, Clone, Serialize)]
pub struct ResultJson {
    pub status: &'static str,
    pub reasons: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub robot_from_sensor: Option<MountJson>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma: Option<SigmaJson>,
    /// Correlation coefficients of `[α, β, γ, px, py, pz]`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub correlations: Option<[[f64; 6]; 6]>,
    pub poses: Vec<PoseJson>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub summary: Option<SummaryJson>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub observability: Option<ObservabilityJson>,
    /// The Kinect's motor tilt the calibration holds for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kinect_tilt_deg: Option<f64>,
    /// Things the operator should know that are not reasons to reject.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl ResultJson {
    pub fn from_calibration(c: &Calibration) -> Self {
        let s = c.sigma();
        let r = c.correlations();
        Self {
            status: match c.verdict {
                Verdict::Accepted => "accepted",
                Verdict::Rejected => "rejected",
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
            }),
            kinect_tilt_deg: None,
            notes: Vec::new(),
        }
    }

    /// A rejection with no parameters at all (too few usable poses).
    pub fn unsolved(reason: String, poses: &[PoseOutcome]) -> Self {
        Self {
            status: "rejected",
            reasons: vec![reason],
            robot_from_sensor: None,
            sigma: None,
            correlations: None,
            poses: poses.iter().map(PoseJson::from).collect(),
            summary: None,
            observability: None,
            kinect_tilt_deg: None,
            notes: Vec::new(),
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
        use crate::calib::calibrate::calibrate_among;
        use crate::calib::solve::SolveError;
        let mut result = match calibrate_among(observations, poses_total, settings) {
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

    /// Whether the calibration was accepted.
    pub fn accepted(&self) -> bool {
        self.status == "accepted"
    }

    /// A table for a person at a terminal.
    pub fn to_table(&self) -> String {
        use std::fmt::Write;
        let mut out = String::new();
        let _ = writeln!(out, "status: {}", self.status.to_uppercase());
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
            let _ = writeln!(out, "\nrobot_from_sensor            value        σ");
            for (name, v, sv, unit) in [
                ("alpha", m.alpha_deg, s.alpha_deg, "°"),
                ("beta", m.beta_deg, s.beta_deg, "°"),
                ("gamma", m.gamma_deg, s.gamma_deg, "°"),
                ("px", m.px_mm, s.px_mm, " mm"),
                ("py", m.py_mm, s.py_mm, " mm"),
                ("pz", m.pz_mm, s.pz_mm, " mm"),
            ] {
                let _ = writeln!(out, "  {name:<8} {v:>22.4}{unit:<3} {sv:>9.4}{unit}");
            }
        }
        let _ = writeln!(out, "\npose  used   θ (°)   e_d (mm)  note");
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
        out
    }
}
