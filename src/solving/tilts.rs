//! Calibrating once for every tilt of the Kinect's motor (`calibrate
//! --tilts`, `replay` of a recording made so, `export --tilt`): the
//! calibrations at each tilt combined into the motor's axis and pivot
//! (`calib::tilt`), and how such a recording is laid out:
//!
//! ```text
//! DIR/tilts.json        {"format": "groundcal-tilts", "version": 1,
//!                        "tilts": [{"tilt_deg": -20, "dir": "tilt-1"}, ...]}
//! DIR/tilt-1/ ...       one recording (recording.md) per tilt, in order
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::calib::geometry::{rot_z, PoseDegMm, PoseParams};
use crate::calib::observe::NominalMount;
use crate::calib::tilt::{fit, TiltCalibration, TiltModel};
use crate::formats::output::{MountJson, ResultJson, ResultStatus, TiltModelJson, TiltResultJson};
use crate::platform::input::InputError;

/// The model as the result carries it.
fn model_json(m: &TiltModel) -> TiltModelJson {
    TiltModelJson {
        reference_tilt_deg: m.reference_tilt_deg,
        reference: MountJson::from_params(&m.reference),
        axis: [m.axis.x, m.axis.y, m.axis.z],
        rate: m.rate,
        pivot_mm: [m.pivot.x * 1e3, m.pivot.y * 1e3, m.pivot.z * 1e3],
        axis_sigma_deg: m.axis_sigma.to_degrees(),
        pivot_sigma_mm: m.pivot_sigma * 1e3,
        residual_deg: m.residual_angle.to_degrees(),
        residual_mm: m.residual_position * 1e3,
        range_deg: [m.range_deg.0, m.range_deg.1],
    }
}

/// The model back from the result (for `export --tilt`).
pub fn model_of(json: &TiltModelJson) -> TiltModel {
    let r = &json.reference;
    TiltModel {
        reference_tilt_deg: json.reference_tilt_deg,
        reference: r.pose().to_params(),
        axis: nalgebra::Vector3::from(json.axis),
        rate: json.rate,
        pivot: nalgebra::Vector3::from(json.pivot_mm) / 1e3,
        axis_sigma: json.axis_sigma_deg.to_radians(),
        pivot_sigma: json.pivot_sigma_mm / 1e3,
        residual_angle: json.residual_deg.to_radians(),
        residual_position: json.residual_mm / 1e3,
        range_deg: (json.range_deg[0], json.range_deg[1]),
    }
}

/// The rough mount at another tilt: the nominal one turned about the
/// sensor's right axis (the motor's, nearly) by the difference, so that the
/// ground is still told from other planes.
pub fn nominal_at(nominal: &NominalMount, nominal_tilt_deg: f64, tilt_deg: f64) -> NominalMount {
    let p = nominal.pose().to_params();
    let turned = p.rotation_matrix() * rot_z((tilt_deg - nominal_tilt_deg).to_radians());
    let v = PoseDegMm::from_params(&PoseParams::from_rotation_translation(
        &turned,
        p.translation,
    ))
    .values();
    NominalMount {
        tolerance_deg: nominal.tolerance_deg,
        tolerance_mm: nominal.tolerance_mm,
        ..NominalMount::from_values(v)
    }
}

/// The calibrations at each tilt combined: the one at (nearest) the
/// reference tilt, with the motor's model and every tilt in brief. Rejected
/// when a tilt's calibration was, or when no model fits.
pub fn combine(results: Vec<(f64, ResultJson)>, reference_tilt_deg: f64) -> ResultJson {
    let tilts: Vec<TiltResultJson> = results
        .iter()
        .map(|(tilt_deg, r)| TiltResultJson {
            tilt_deg: *tilt_deg,
            status: r.status.as_str().into(),
            robot_from_sensor: r.robot_from_sensor.clone(),
            pitch_to_body_deg: r.motor.as_ref().map(|m| m.pitch_to_body_deg),
        })
        .collect();
    let calibrations: Vec<TiltCalibration> = results
        .iter()
        .filter_map(|(tilt_deg, r)| {
            let mount = crate::solving::verify::mount_of(r).ok()?;
            Some(TiltCalibration {
                tilt_deg: *tilt_deg,
                robot_from_sensor: mount.robot_from_sensor,
                sigma: mount.sigma.unwrap_or([0.0; 6]),
            })
        })
        .collect();
    let rejected: Vec<String> = results
        .iter()
        .filter(|(_, r)| !r.accepted())
        .map(|(tilt, r)| {
            format!(
                "the calibration at tilt {tilt}° was rejected: {}",
                r.reasons.join("; ")
            )
        })
        .collect();
    let Some(nearest) = results
        .iter()
        .min_by(|a, b| {
            (a.0 - reference_tilt_deg)
                .abs()
                .total_cmp(&(b.0 - reference_tilt_deg).abs())
        })
        .map(|(tilt, _)| *tilt)
    else {
        return ResultJson::unsolved("no tilt was calibrated".into(), &[]);
    };
    let mut combined = results
        .into_iter()
        .find(|(tilt, _)| *tilt == nearest)
        .map(|(_, r)| r)
        .unwrap_or_else(|| ResultJson::unsolved("no tilt was calibrated".into(), &[]));
    match fit(&calibrations, nearest) {
        Ok(model) => {
            if (nearest - reference_tilt_deg).abs() > 0.25 && model.covers(reference_tilt_deg) {
                // The configured tilt lies between calibrated ones: the
                // model's mount there (σ: the nearest tilt's).
                combined.robot_from_sensor =
                    Some(MountJson::from_params(&model.at(reference_tilt_deg)));
                combined.notes.push(format!(
                    "robot_from_sensor is the tilt model's at the configured tilt {reference_tilt_deg}°, between the calibrated tilts; σ are those of the calibration at {nearest}°"
                ));
                combined.kinect_tilt_deg = Some(reference_tilt_deg);
            }
            combined.tilt_model = Some(model_json(&model));
        }
        Err(e) => {
            combined.status = ResultStatus::Rejected;
            combined.reasons.push(format!("no tilt model: {e}"));
        }
    }
    if !rejected.is_empty() {
        combined.status = ResultStatus::Rejected;
        combined.reasons.extend(rejected);
    }
    combined.tilts = tilts;
    combined
}

/// `tilts.json` of a recording made at several tilts.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TiltsFile {
    pub format: String,
    pub version: u32,
    /// The tilt the combined result's `robot_from_sensor` is for (the
    /// configured one); default the first.
    #[serde(default)]
    pub reference_tilt_deg: Option<f64>,
    pub tilts: Vec<TiltEntry>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TiltEntry {
    pub tilt_deg: f64,
    /// The tilt's recording, relative to the directory.
    pub dir: String,
}

/// The sub-recording of the `k`-th tilt (from 1).
pub fn tilt_dir(dir: &Path, k: usize) -> PathBuf {
    dir.join(format!("tilt-{k}"))
}

/// Writes `tilts.json` (whole or not at all).
pub fn write_tilts_file(dir: &Path, tilts: &[f64], reference_tilt_deg: f64) -> Result<(), String> {
    let file = TiltsFile {
        format: "groundcal-tilts".into(),
        version: 1,
        reference_tilt_deg: Some(reference_tilt_deg),
        tilts: tilts
            .iter()
            .enumerate()
            .map(|(k, t)| TiltEntry {
                tilt_deg: *t,
                dir: format!("tilt-{}", k + 1),
            })
            .collect(),
    };
    let text = serde_json::to_string_pretty(&file).map_err(|e| e.to_string())?;
    crate::platform::files::write_atomically(&dir.join("tilts.json"), text.as_bytes())
        .map_err(|e| e.to_string())
}

/// The most tilts a recording may have: a motor of ±27° calibrated every
/// 2° is 28, and each tilt is a whole calibration (a replay of one takes
/// seconds, so this bounds a replay to minutes, not hours).
pub const MAX_TILTS: usize = 32;

/// Reads `DIR/tilts.json` if the recording has one. Each tilt's directory
/// must be a real directory inside `DIR`: a symbolic link could lead the
/// replay anywhere on the machine.
pub fn read_tilts_file(dir: &Path) -> Result<Option<TiltsFile>, InputError> {
    let path = dir.join("tilts.json");
    if !path.exists() {
        return Ok(None);
    }
    let bytes = crate::platform::input::read_bounded(&path, 1 << 20)?;
    let text = String::from_utf8(bytes)
        .map_err(|e| InputError::new(&path, None, format!("not UTF-8 text: {e}")))?;
    let file = parse_tilts_file(&path, &text)?;
    for t in &file.tilts {
        let sub = dir.join(&t.dir);
        match std::fs::symlink_metadata(&sub) {
            Ok(m) if m.file_type().is_symlink() => {
                return Err(InputError::new(
                    &path,
                    None,
                    format!(
                        "the tilt {}°'s directory {} is a symbolic link: each tilt's recording must lie inside the recording",
                        t.tilt_deg,
                        sub.display()
                    ),
                ))
            }
            Ok(m) if !m.is_dir() => {
                return Err(InputError::new(
                    &path,
                    None,
                    format!("the tilt {}°'s {} is not a directory", t.tilt_deg, sub.display()),
                ))
            }
            Ok(_) => {}
            Err(e) => {
                return Err(InputError::new(
                    &path,
                    None,
                    format!("the tilt {}°'s directory {}: {e}", t.tilt_deg, sub.display()),
                ))
            }
        }
    }
    Ok(Some(file))
}

/// Parses and checks a `tilts.json`: two to [`MAX_TILTS`] tilts, each
/// finite, within the motor's range, 1° or more from the others, and
/// naming a plain directory beside the file that no other tilt names.
pub fn parse_tilts_file(path: &Path, text: &str) -> Result<TiltsFile, InputError> {
    let file: TiltsFile = serde_json::from_str(text).map_err(|e| {
        InputError::new(
            path,
            (e.line() > 0).then_some(e.line()),
            format!("not a groundcal-tilts file: {e}"),
        )
    })?;
    if file.format != "groundcal-tilts" || file.version != 1 {
        return Err(InputError::new(
            path,
            None,
            "expected format \"groundcal-tilts\", version 1",
        ));
    }
    if file.tilts.len() < 2 || file.tilts.len() > MAX_TILTS {
        return Err(InputError::new(
            path,
            None,
            format!(
                "it names {} tilts: a recording at several tilts names 2 to {MAX_TILTS}",
                file.tilts.len()
            ),
        ));
    }
    if let Some(t) = file.reference_tilt_deg.filter(|t| !t.is_finite()) {
        return Err(InputError::new(
            path,
            None,
            format!("reference_tilt_deg {t} is not a finite number of degrees"),
        ));
    }
    for t in &file.tilts {
        let plain = !(t.dir.is_empty()
            || t.dir == "."
            || t.dir == ".."
            || t.dir.contains('/')
            || t.dir.contains('\\'));
        if !plain || !t.tilt_deg.is_finite() {
            return Err(InputError::new(
                path,
                None,
                format!(
                    "tilt entry \"{}\" at {}° must name a plain directory beside tilts.json and a finite tilt",
                    t.dir, t.tilt_deg
                ),
            ));
        }
    }
    let tilts: Vec<f64> = file.tilts.iter().map(|t| t.tilt_deg).collect();
    crate::setup::config::check_tilts(&tilts).map_err(|e| InputError::new(path, None, e))?;
    for (k, t) in file.tilts.iter().enumerate() {
        if file.tilts[..k].iter().any(|u| u.dir == t.dir) {
            return Err(InputError::new(
                path,
                None,
                format!(
                    "the directory \"{}\" is named by two tilts: each tilt has its own",
                    t.dir
                ),
            ));
        }
    }
    Ok(file)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn document(tilts: &[(f64, &str)]) -> String {
        let entries: Vec<String> = tilts
            .iter()
            .map(|(t, d)| format!("{{\"tilt_deg\": {t}, \"dir\": \"{d}\"}}"))
            .collect();
        format!(
            "{{\"format\": \"groundcal-tilts\", \"version\": 1, \"tilts\": [{}]}}",
            entries.join(", ")
        )
    }

    fn parse(tilts: &[(f64, &str)]) -> Result<TiltsFile, String> {
        parse_tilts_file(Path::new("rec/tilts.json"), &document(tilts)).map_err(|e| e.to_string())
    }

    #[test]
    fn too_many_tilts_are_refused_at_once_with_the_count_and_the_bound() {
        let many: Vec<(f64, String)> = (0..10_000)
            .map(|k| (-27.0 + 54.0 * k as f64 / 10_000.0, format!("tilt-{k}")))
            .collect();
        let many: Vec<(f64, &str)> = many.iter().map(|(t, d)| (*t, d.as_str())).collect();
        let e = parse(&many).unwrap_err();
        assert!(e.contains("10000 tilts") && e.contains("2 to 32"), "{e}");
        let most: Vec<(f64, String)> = (0..MAX_TILTS)
            .map(|k| (-26.0 + 1.5 * k as f64, format!("tilt-{}", k + 1)))
            .collect();
        let most: Vec<(f64, &str)> = most.iter().map(|(t, d)| (*t, d.as_str())).collect();
        assert!(parse(&most).is_ok());
    }

    #[test]
    fn a_duplicated_tilt_or_directory_is_named() {
        let e = parse(&[(-20.0, "tilt-1"), (-10.0, "tilt-2"), (-20.0, "tilt-3")]).unwrap_err();
        assert!(
            e.contains("rec/tilts.json") && e.contains("-20° is given twice"),
            "{e}"
        );
        let e = parse(&[(-20.0, "tilt-1"), (-10.0, "tilt-1")]).unwrap_err();
        assert!(e.contains("\"tilt-1\" is named by two tilts"), "{e}");
        let e = parse(&[(-20.0, "tilt-1"), (40.0, "tilt-2")]).unwrap_err();
        assert!(e.contains("40° is outside"), "{e}");
    }

    #[test]
    fn a_tilt_directory_that_is_a_symbolic_link_is_refused() {
        let root =
            std::env::temp_dir().join(format!("groundcal-tilts-link-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let recording = root.join("rec");
        let elsewhere = root.join("elsewhere");
        std::fs::create_dir_all(recording.join("tilt-1")).unwrap();
        std::fs::create_dir_all(&elsewhere).unwrap();
        std::os::unix::fs::symlink(&elsewhere, recording.join("tilt-2")).unwrap();
        std::fs::write(
            recording.join("tilts.json"),
            document(&[(-20.0, "tilt-1"), (-10.0, "tilt-2")]),
        )
        .unwrap();
        let e = read_tilts_file(&recording).unwrap_err().to_string();
        assert!(e.contains("tilt-2") && e.contains("symbolic link"), "{e}");
        std::fs::remove_file(recording.join("tilt-2")).unwrap();
        std::fs::create_dir(recording.join("tilt-2")).unwrap();
        assert!(read_tilts_file(&recording).unwrap().is_some());
        let _ = std::fs::remove_dir_all(&root);
    }
}
