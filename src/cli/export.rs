//! `groundcal export RESULT.json --format urdf|ros-static|json`: the calibration
//! in other tools' formats (`crate::export`, `docs/export.md`).

use std::io::Write;
use std::path::Path;

use super::ExitStatus;
use crate::export::{read_result_with_scale, ExportFormat, RosMount};

/// Runs the command: the export on stdout, messages on stderr. A rejected
/// calibration, a missing file or an inconsistent result is bad input (exit 2).
pub fn run(file: &Path, format: ExportFormat) -> ExitStatus {
    let (robot_from_sensor, depth_scale) = match read_result_with_scale(file, false) {
        Ok(read) => read,
        Err(e) => {
            eprintln!("groundcal export: {e}");
            return ExitStatus::BadInput;
        }
    };
    let mount = RosMount {
        depth_scale,
        ..RosMount::from_groundcal(&robot_from_sensor)
    };
    // The argument line has no room for a comment: the note goes beside it.
    if let (ExportFormat::RosStatic, Some(note)) = (format, mount.depth_scale_note()) {
        eprintln!("groundcal export: {note}");
    }
    let text = mount.render(format);
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
