//! `session.json`: what was calibrated, and how (recording.md).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::InputError;
use crate::calib::geometry::PoseDegMm;
pub use crate::calib::observe::NominalMount;
use crate::calib::sensor::{DepthModel, Intrinsics};

/// The home stance: the commanded pose and the feet reported there.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Home {
    pub commanded: PoseDegMm,
    pub feet_body_mm: Vec<[f64; 3]>,
}

/// The Kinect's state and model during the session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KinectInfo {
    /// The motor's tilt; a calibration holds for one tilt.
    pub tilt_deg: f64,
    #[serde(default)]
    pub depth_model: DepthModel,
    #[serde(default)]
    pub intrinsics: Intrinsics,
}

/// The whole `session.json`. Unknown keys are ignored (recording.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Session {
    pub format: String,
    pub version: u32,
    #[serde(default)]
    pub robot: String,
    pub home: Home,
    pub kinect: KinectInfo,
    #[serde(default)]
    pub frames_per_pose: Option<u32>,
    #[serde(default)]
    pub schedule: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal_mount: Option<NominalMount>,
    /// The quality gates the live calibration was judged by (a groundcal
    /// extension of recording.md, whose readers ignore keys they do not
    /// know): `replay` judges by the same ones unless told otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gates: Option<crate::calib::quality::Gates>,
    /// The noise the live solve assumed at least (`[calibration.noise]`, a
    /// groundcal extension like `gates`): `replay` assumes the same.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<crate::calib::plan::NoiseModel>,
}

/// Checks that feet are six finite triples.
pub fn check_feet(feet: &[[f64; 3]]) -> Result<(), String> {
    if feet.len() != 6 {
        return Err(format!("expected six feet, found {}", feet.len()));
    }
    if let Some(i) = feet.iter().position(|f| !f.iter().all(|v| v.is_finite())) {
        return Err(format!(
            "foot {} has a value that is not a finite number",
            i + 1
        ));
    }
    Ok(())
}

impl Session {
    /// Parses and checks `session.json`.
    pub fn parse(path: &Path, text: &str) -> Result<Self, InputError> {
        // The version is checked before the rest, so that a future format gets
        // a clear message rather than a complaint about some key.
        let value: serde_json::Value = serde_json::from_str(text).map_err(|e| {
            InputError::new(
                path,
                (e.line() > 0).then_some(e.line()),
                format!("not JSON: {e}"),
            )
        })?;
        match value.get("format").and_then(|f| f.as_str()) {
            Some("groundcal-recording") => {}
            Some(other) => {
                return Err(InputError::new(
                    path,
                    None,
                    format!("\"format\" is \"{other}\", expected \"groundcal-recording\""),
                ))
            }
            None => {
                return Err(InputError::new(
                    path,
                    None,
                    "\"format\" is missing (expected \"groundcal-recording\")",
                ))
            }
        }
        match value.get("version").and_then(|v| v.as_u64()) {
            Some(1) => {}
            Some(v) => {
                return Err(InputError::new(
                    path,
                    None,
                    format!("recording format version {v} is not supported (this groundcal reads version 1)"),
                ))
            }
            None => return Err(InputError::new(path, None, "\"version\" is missing or not a whole number")),
        }
        let session: Session = serde_json::from_str(text).map_err(|e| {
            InputError::new(path, (e.line() > 0).then_some(e.line()), e.to_string())
        })?;
        let bad = |m: String| InputError::new(path, None, m);
        if let Some(gates) = &session.gates {
            gates.validate().map_err(&bad)?;
        }
        if let Some(noise) = &session.noise {
            noise.validate().map_err(|e| bad(format!("noise: {e}")))?;
        }
        check_feet(&session.home.feet_body_mm)
            .map_err(|e| bad(format!("home.feet_body_mm: {e}")))?;
        if !session.home.commanded.is_finite() {
            return Err(bad(
                "home.commanded has a value that is not a finite number".into(),
            ));
        }
        if !session.kinect.tilt_deg.is_finite() {
            return Err(bad("kinect.tilt_deg is not a finite number".into()));
        }
        session
            .kinect
            .depth_model
            .validate()
            .map_err(|e| bad(format!("kinect.depth_model: {e}")))?;
        session
            .kinect
            .intrinsics
            .validate()
            .map_err(|e| bad(format!("kinect.intrinsics: {e}")))?;
        if let Some(m) = &session.nominal_mount {
            m.validate().map_err(bad)?;
        }
        Ok(session)
    }
}
