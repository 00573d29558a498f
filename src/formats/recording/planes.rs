//! The planes-only input (`groundcal-planes`, recording.md): observations of the
//! ground in the sensor frame with the real body pose of each, e.g. the paper's
//! tables. Solved by `groundcal solve`.

use std::path::Path;

use serde::Deserialize;

use super::{read_bounded, InputError};
use crate::calib::geometry::{Plane, PoseDegMm};
use crate::calib::solve::Observation;

#[derive(Debug, Deserialize)]
struct PlanesFile {
    format: String,
    version: u32,
    observations: Vec<ObservationRecord>,
}

#[derive(Debug, Deserialize)]
struct ObservationRecord {
    index: u32,
    robot_pose: PoseDegMm,
    plane: PlaneRecord,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlaneRecord {
    a: f64,
    b: f64,
    c: f64,
    d_m: f64,
}

/// Parses a planes file's text into observations (the plane normalised and
/// oriented to `d > 0`).
pub fn parse_planes(path: &Path, text: &str) -> Result<Vec<Observation>, InputError> {
    let not_planes = |e: serde_json::Error| {
        let line = (e.line() > 0).then_some(e.line());
        InputError::new(path, line, format!("not a groundcal-planes document: {e}"))
    };
    // The typed parse skips an unknown key without checking all its escapes
    // (found by fuzzing): text that is not JSON is refused as such first.
    serde_json::from_str::<serde_json::Value>(text).map_err(not_planes)?;
    let file: PlanesFile = serde_json::from_str(text).map_err(not_planes)?;
    if file.format != "groundcal-planes" {
        return Err(InputError::new(
            path,
            None,
            format!(
                "\"format\" is \"{}\", expected \"groundcal-planes\"",
                file.format
            ),
        ));
    }
    if file.version != 1 {
        return Err(InputError::new(
            path,
            None,
            format!(
                "version {} is not supported (this groundcal reads version 1)",
                file.version
            ),
        ));
    }
    if file.observations.is_empty() {
        return Err(InputError::new(path, None, "\"observations\" is empty"));
    }
    if file.observations.len() > MAX_OBSERVATIONS {
        return Err(InputError::new(
            path,
            None,
            format!(
                "{} observations: at most {MAX_OBSERVATIONS} are accepted (a calibration has tens; the solve's time grows faster than their number)",
                file.observations.len()
            ),
        ));
    }
    let mut seen = std::collections::BTreeSet::new();
    file.observations
        .iter()
        .enumerate()
        .map(|(k, record)| {
            let at = |what: &str| {
                InputError::new(
                    path,
                    None,
                    format!("observations[{k}] (index {}): {what}", record.index),
                )
            };
            if !seen.insert(record.index) {
                return Err(at("the index appears twice"));
            }
            if !record.robot_pose.is_finite() {
                return Err(at("robot_pose has a value that is not a finite number"));
            }
            let pose = &record.robot_pose;
            if let Some((name, value)) = [
                ("alpha_deg", pose.alpha_deg),
                ("beta_deg", pose.beta_deg),
                ("gamma_deg", pose.gamma_deg),
            ]
            .into_iter()
            .find(|(_, v)| v.abs() > MAX_ANGLE_DEG)
            {
                return Err(at(&format!(
                    "robot_pose.{name} = {}° is not a body's attitude (at most ±{MAX_ANGLE_DEG}°)",
                    compact(value)
                )));
            }
            if let Some((name, value)) = [
                ("px_mm", pose.px_mm),
                ("py_mm", pose.py_mm),
                ("pz_mm", pose.pz_mm),
            ]
            .into_iter()
            .find(|(_, v)| v.abs() > MAX_DISTANCE_MM)
            {
                return Err(at(&format!(
                    "robot_pose.{name} = {} mm is not where a body stands over its feet (at most ±{MAX_DISTANCE_MM} mm)",
                    compact(value)
                )));
            }
            let p = &record.plane;
            let normal = (p.a * p.a + p.b * p.b + p.c * p.c).sqrt();
            if normal.is_finite() && normal > 0.0 && (p.d_m / normal).abs() > MAX_HEIGHT_M {
                return Err(at(&format!(
                    "plane: d_m = {} m is not a sensor's height above the ground (at most {MAX_HEIGHT_M} m)",
                    compact(p.d_m)
                )));
            }
            let plane = Plane::from_coefficients(p.a, p.b, p.c, p.d_m)
                .map_err(|e| at(&format!("plane: {e}")))?;
            Ok(Observation::new(
                record.index,
                record.robot_pose.to_params().to_transform(),
                plane,
            ))
        })
        .collect()
}

/// Most observations a planes file may hold. A schedule has tens of poses;
/// the solve takes about 0.9 s for 2 000 observations and 3.3 s for 4 000
/// (docs/reliability.md), so more is refused rather than left to run.
pub const MAX_OBSERVATIONS: usize = 2000;

/// Largest body position accepted, mm: a hundred metres, far beyond any
/// legged robot's reach, so that absurd numbers are named as such.
const MAX_DISTANCE_MM: f64 = 100_000.0;

/// Largest body angle accepted, degrees: a turn and more, so that absurd
/// numbers are named as such (as positions are), not set aside as an outlier.
const MAX_ANGLE_DEG: f64 = 360.0;

/// A number as a message quotes it: as written for ordinary magnitudes,
/// in exponent form for huge or tiny ones (1e300 is not 301 digits).
fn compact(value: f64) -> String {
    if value != 0.0 && !(1e-4..1e6).contains(&value.abs()) {
        format!("{value:e}")
    } else {
        format!("{value}")
    }
}

/// Largest sensor height above the ground accepted, metres.
const MAX_HEIGHT_M: f64 = 100.0;

/// Reads a planes file.
pub fn read_planes(path: &Path) -> Result<Vec<Observation>, InputError> {
    let bytes = read_bounded(path, 64 << 20)?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| InputError::new(path, None, format!("not UTF-8 text: {e}")))?;
    parse_planes(path, text)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Vec<Observation>, InputError> {
        parse_planes(Path::new("t.json"), text)
    }

    /// Found by fuzzing (fuzz/regressions/planes_file/, read as the fuzz
    /// target reads it): text that serde_json's own parse refuses ("unexpected
    /// end of hex escape" in an unknown key) was accepted by the typed parse,
    /// which skips unknown keys without checking all their escapes.
    #[test]
    fn text_that_is_not_json_is_refused_even_in_an_unknown_key() {
        let bytes = include_bytes!(
            "../../../fuzz/regressions/planes_file/invalid-escape-in-unknown-key.json"
        );
        let text = String::from_utf8_lossy(bytes);
        assert!(serde_json::from_str::<serde_json::Value>(&text).is_err());
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.contains("not a groundcal-planes document"), "{e}");
    }

    const ONE: &str = r#"{"format": "groundcal-planes", "version": 1, "observations": [
        {"index": 1, "robot_pose": {"alpha_deg": 0, "beta_deg": 2, "gamma_deg": 20, "px_mm": 0, "py_mm": 615, "pz_mm": 0},
         "plane": {"a": 0.5515, "b": -0.7802, "c": 0.2952, "d_m": -0.9916}}]}"#;

    #[test]
    fn reads_and_orients_planes() {
        let obs = parse(ONE).unwrap();
        assert_eq!(obs.len(), 1);
        assert!(obs[0].plane.d > 0.0 && obs[0].plane.normal.y > 0.0);
        assert!((obs[0].plane.normal.norm() - 1.0).abs() < 1e-12);
        assert!((obs[0].ground_from_robot.translation.vector.y - 0.615).abs() < 1e-12);
    }

    #[test]
    fn defects_are_named() {
        let e = parse("{").unwrap_err();
        assert!(e.to_string().starts_with("t.json:1:"), "{e}");
        let e = parse(&ONE.replace("groundcal-planes", "other")).unwrap_err();
        assert!(e.message.contains("expected \"groundcal-planes\""));
        let e = parse(&ONE.replace("\"version\": 1", "\"version\": 2")).unwrap_err();
        assert!(e.message.contains("version 2"));
        let e = parse(&ONE.replace(
            "\"a\": 0.5515, \"b\": -0.7802, \"c\": 0.2952",
            "\"a\": 0, \"b\": 0, \"c\": 0",
        ))
        .unwrap_err();
        assert!(
            e.message.contains("observations[0] (index 1): plane"),
            "{e}"
        );
        let e = parse(&ONE.replace("\"py_mm\": 615", "\"py_mm\": 1e999")).unwrap_err();
        assert!(e.to_string().contains("t.json"), "{e}");
        let e = parse(&ONE.replace("\"d_m\"", "\"d\"")).unwrap_err();
        assert!(e.message.contains("d_m"), "{e}");
    }

    #[test]
    fn more_observations_than_the_limit_are_refused_with_the_count() {
        let one = ONE
            .split_once("\"observations\": [")
            .and_then(|(_, rest)| rest.rsplit_once("]}"))
            .map(|(record, _)| record.to_string())
            .unwrap();
        let records: Vec<String> = (1..=MAX_OBSERVATIONS + 1)
            .map(|i| one.replace("\"index\": 1", &format!("\"index\": {i}")))
            .collect();
        let text = format!(
            "{{\"format\": \"groundcal-planes\", \"version\": 1, \"observations\": [{}]}}",
            records.join(",")
        );
        let e = parse(&text).unwrap_err();
        assert!(e.message.contains("2001 observations: at most 2000"), "{e}");
        // At the limit, the file is read.
        let text = text.replacen(&format!(",{}", records[MAX_OBSERVATIONS]), "", 1);
        assert_eq!(parse(&text).unwrap().len(), MAX_OBSERVATIONS);
    }

    #[test]
    fn absurd_magnitudes_are_named_for_what_they_are() {
        let e = parse(&ONE.replace("-0.9916", "1e15")).unwrap_err();
        assert!(
            e.message.contains("d_m = 1e15 m is not a sensor's height"),
            "{e}"
        );
        let e = parse(&ONE.replace("\"py_mm\": 615", "\"py_mm\": 1e300")).unwrap_err();
        assert!(
            e.message.contains("robot_pose.py_mm = 1e300 mm is not"),
            "{e}"
        );
        // An angle as absurd is named the same way, not set aside as a pose.
        let e = parse(&ONE.replace("\"beta_deg\": 2", "\"beta_deg\": 1e300")).unwrap_err();
        assert!(
            e.message
                .contains("robot_pose.beta_deg = 1e300° is not a body's attitude"),
            "{e}"
        );
    }
}
