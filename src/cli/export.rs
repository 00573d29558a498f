//! `groundcal export RESULT.json --format urdf|ros-static|json|depth-correction`:
//! the calibration in other tools' formats (`crate::formats::export`, `docs/export.md`).

use std::io::Write;
use std::path::Path;

use super::ExitStatus;
use crate::formats::export::{read_result_with_scale, ExportFormat, RosMount};
use std::path::PathBuf;

/// The arguments of `groundcal export`: a result and the format.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// A result document (`groundcal solve|replay|calibrate --json`).
    pub file: PathBuf,
    /// The format to write on stdout.
    #[arg(long, value_enum)]
    pub format: crate::formats::export::ExportFormat,
    /// The mount at this tilt of the Kinect's motor (degrees), from a
    /// calibration made at several tilts (calibrate --tilts), within their range.
    #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
    pub tilt: Option<f64>,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: ExportArgs) -> ExitStatus {
    run(&args.file, args.format, args.tilt)
}

/// Runs the command: the export on stdout, messages on stderr. A rejected
/// calibration, a missing file or an inconsistent result is bad input (exit 2).
pub fn run(file: &Path, format: ExportFormat, tilt: Option<f64>) -> ExitStatus {
    if format == ExportFormat::DepthCorrection {
        return depth_correction(file);
    }
    let (mut robot_from_sensor, depth_scale) = match read_result_with_scale(file, false) {
        Ok(read) => read,
        Err(e) => {
            eprintln!("groundcal export: {e}");
            return ExitStatus::BadInput;
        }
    };
    if let Some(tilt) = tilt {
        match at_tilt(file, tilt) {
            Ok(mount) => robot_from_sensor = mount,
            Err(e) => {
                eprintln!("groundcal export: {}: {e}", file.display());
                return ExitStatus::BadInput;
            }
        }
    }
    let mount = RosMount {
        depth_scale,
        ..RosMount::from_groundcal(&robot_from_sensor)
    };
    // The argument line has no room for a comment: the note goes beside it.
    if let (ExportFormat::RosStatic, Some(note)) = (format, mount.depth_scale_note()) {
        eprintln!("groundcal export: {note}");
    }
    let Some(text) = mount.render(format) else {
        return depth_correction(file);
    };
    print(&text)
}

/// `--format depth-correction`: the corrected pattern as a JSON document.
fn depth_correction(file: &Path) -> ExitStatus {
    match crate::formats::export::read_depth_correction(file) {
        Ok(document) => match serde_json::to_string(&document) {
            Ok(text) => print(&(text + "\n")),
            Err(e) => {
                eprintln!("groundcal export: cannot encode the depth correction: {e}");
                ExitStatus::RuntimeFailure
            }
        },
        Err(e) => {
            eprintln!("groundcal export: {e}");
            ExitStatus::BadInput
        }
    }
}

/// Writes the export on stdout.
fn print(text: &str) -> ExitStatus {
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        eprintln!("groundcal export: cannot write the export: {e}");
        return ExitStatus::RuntimeFailure;
    }
    ExitStatus::Success
}

/// The mount at another tilt of the motor, from the result's tilt model.
fn at_tilt(file: &Path, tilt: f64) -> Result<crate::calib::geometry::PoseDegMm, String> {
    let bytes = crate::platform::input::read_bounded(file, 64 << 20).map_err(|e| e.to_string())?;
    let value: serde_json::Value =
        serde_json::from_slice(&bytes).map_err(|e| format!("not JSON: {e}"))?;
    let result = crate::formats::output::ResultJson::parse(value)?;
    let Some(model) = result
        .tilt_model
        .as_ref()
        .map(crate::solving::tilts::model_of)
    else {
        return Err(format!(
            "this calibration holds for one tilt ({}): calibrate with --tilts to export others",
            result
                .kinect_tilt_deg
                .map_or_else(|| "unknown".to_string(), |t| format!("{t}°"))
        ));
    };
    if !tilt.is_finite() || !model.covers(tilt) {
        return Err(format!(
            "tilt {tilt}° lies outside the calibrated range {}° to {}°",
            model.range_deg.0, model.range_deg.1
        ));
    }
    Ok(crate::calib::geometry::PoseDegMm::from_params(
        &model.at(tilt),
    ))
}
