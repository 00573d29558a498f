//! `poses.jsonl`: one line per pose, in the order the poses were visited.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::session::check_feet;
use super::InputError;
use crate::calib::geometry::PoseDegMm;

/// One pose of a recording. Extra keys written by a recorder are allowed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseRecord {
    /// Counts from 1; the `pose_id` sent to the robot.
    pub index: u32,
    /// The body pose that was asked for.
    pub commanded: PoseDegMm,
    /// The feet the robot reported once settled at this pose, body frame, mm.
    pub feet_body_mm: Vec<[f64; 3]>,
    /// Files in `kinect/` captured at this pose.
    pub depth_frames: Vec<String>,
    /// Accelerometer readings (`a-…` files in `kinect/`) taken at this pose
    /// after its frames: groundcal's key beyond recording.md (docs/recording.md).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub accelerometer: Vec<String>,
    /// The line of `poses.jsonl` it was read from (for messages).
    #[serde(skip)]
    pub line: usize,
}

/// What was read from `poses.jsonl`.
#[derive(Debug, Clone, PartialEq)]
pub struct PosesFile {
    pub poses: Vec<PoseRecord>,
    /// A last line cut off part-way (power loss while writing), left out.
    pub truncated_tail: bool,
}

/// Parses `poses.jsonl`.
///
/// A recorder writes a pose's line after its frames, so a recording cut off
/// part-way is valid up to its last complete line: an unterminated last line
/// that does not parse is left out (and said so); any other defect is an error.
pub fn parse_poses(path: &Path, text: &str) -> Result<PosesFile, InputError> {
    let mut poses: Vec<PoseRecord> = Vec::new();
    let mut truncated_tail = false;
    let ends_with_newline = text.ends_with('\n');
    let lines: Vec<&str> = text.split_inclusive('\n').collect();
    for (k, raw) in lines.iter().enumerate() {
        let number = k + 1;
        let line = raw.trim_end_matches(['\n', '\r']);
        if line.trim().is_empty() {
            continue;
        }
        let is_unterminated_last = k + 1 == lines.len() && !ends_with_newline;
        let mut record: PoseRecord = match serde_json::from_str(line) {
            Ok(r) => r,
            Err(_) if is_unterminated_last => {
                truncated_tail = true;
                break;
            }
            Err(e) => {
                return Err(InputError::new(
                    path,
                    Some(number),
                    format!("not a pose record: {e}"),
                ))
            }
        };
        record.line = number;
        let at = |m: String| InputError::new(path, Some(number), m);
        if record.index == 0 {
            return Err(at("index must count from 1 (0 is the home stance)".into()));
        }
        if let Some(previous) = poses.iter().find(|p| p.index == record.index) {
            return Err(at(format!(
                "pose index {} appears twice (first on line {})",
                record.index, previous.line
            )));
        }
        if !record.commanded.is_finite() {
            return Err(at(
                "commanded has a value that is not a finite number".into()
            ));
        }
        check_feet(&record.feet_body_mm).map_err(|e| at(format!("feet_body_mm: {e}")))?;
        for (what, names) in [
            ("depth frame", &record.depth_frames),
            ("accelerometer reading", &record.accelerometer),
        ] {
            for name in names {
                if name.contains('/') || name.contains('\\') || name == ".." || name.is_empty() {
                    return Err(at(format!(
                        "{what} name \"{name}\" must be a plain file name in kinect/"
                    )));
                }
            }
        }
        poses.push(record);
    }
    Ok(PosesFile {
        poses,
        truncated_tail,
    })
}
