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
    /// A last record cut off part-way (power lost while it was written),
    /// left out of `poses`.
    pub cut_off: Option<CutOff>,
}

/// Where `poses.jsonl` ends part-way through a record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CutOff {
    /// The record's line, 1-based.
    pub line: usize,
    /// The byte of the file where that record starts, 0-based.
    pub byte: usize,
    /// The bytes of it that were written.
    pub written: usize,
}

impl CutOff {
    /// The cut in words, after the file's name and the line.
    pub fn describe(&self) -> String {
        format!(
            "the record that starts at byte {} ends after {} bytes, part-way through: the recording was interrupted while this pose was being written",
            self.byte, self.written
        )
    }
}

/// The most poses a recording may hold: the solve's own bound on
/// observations (a calibration has tens; the paper's schedule 52).
pub const MAX_POSES: usize = crate::formats::recording::planes::MAX_OBSERVATIONS;
/// The most depth frames or accelerometer readings one pose may name (a
/// configuration captures at most 30 frames a pose, and reads 10).
pub const MAX_FILES_PER_POSE: usize = 100;

/// Parses `poses.jsonl`.
///
/// A recorder writes a pose's line after its frames, so a recording cut off
/// part-way holds whole poses up to its last record, which may end part-way
/// through (with or without a newline after it, as a file system may leave
/// it). That record is returned as [`PosesFile::cut_off`], for the caller to
/// refuse or, when asked to, leave out and say so; a record cut off before
/// the last line, and any other defect, is an error.
pub fn parse_poses(path: &Path, text: &str) -> Result<PosesFile, InputError> {
    let mut poses: Vec<PoseRecord> = Vec::new();
    let mut cut_off = None;
    // Where the last line that is not blank starts (lines are not collected:
    // a file of newlines would cost 16 bytes a line).
    let trimmed = text.trim_end();
    let last_record = trimmed.rfind('\n').map_or(0, |i| i + 1);
    let mut byte = 0;
    for (k, raw) in text.split_inclusive('\n').enumerate() {
        let number = k + 1;
        let starts_at = byte;
        byte += raw.len();
        let line = raw.trim_end_matches(['\n', '\r']);
        if line.trim().is_empty() {
            continue;
        }
        let mut record: PoseRecord = match serde_json::from_str(line) {
            Ok(r) => r,
            Err(e) if e.is_eof() && starts_at == last_record && !trimmed.is_empty() => {
                cut_off = Some(CutOff {
                    line: number,
                    byte: starts_at,
                    written: line.len(),
                });
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
        if poses.len() == MAX_POSES {
            return Err(at(format!(
                "more than {MAX_POSES} poses: a recording holds at most {MAX_POSES} (a calibration has tens)"
            )));
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
            if names.len() > MAX_FILES_PER_POSE {
                return Err(at(format!(
                    "{} {what}s: a pose names at most {MAX_FILES_PER_POSE}",
                    names.len()
                )));
            }
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
    Ok(PosesFile { poses, cut_off })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(index: usize, frames: usize) -> String {
        let frames: Vec<String> = (0..frames).map(|k| format!("\"d-{index}-{k}\"")).collect();
        format!(
            "{{\"index\": {index}, \"commanded\": {{\"alpha_deg\": 0, \"beta_deg\": 0, \"gamma_deg\": 0, \"px_mm\": 0, \"py_mm\": 600, \"pz_mm\": 0}}, \"feet_body_mm\": [[300,-600,-200],[0,-600,-300],[-300,-600,-200],[-300,-600,200],[0,-600,300],[300,-600,200]], \"depth_frames\": [{}]}}\n",
            frames.join(", ")
        )
    }

    #[test]
    fn a_recording_with_more_poses_or_files_than_the_bounds_is_refused_with_the_line() {
        let path = Path::new("rec/poses.jsonl");
        let most: String = (1..=MAX_POSES).map(|i| line(i, 1)).collect();
        assert_eq!(parse_poses(path, &most).unwrap().poses.len(), MAX_POSES);
        let over = most + &line(MAX_POSES + 1, 1);
        let e = parse_poses(path, &over).unwrap_err().to_string();
        assert!(
            e.contains(&format!("poses.jsonl:{}:", MAX_POSES + 1))
                && e.contains("more than 2000 poses"),
            "{e}"
        );
        let e = parse_poses(path, &line(1, MAX_FILES_PER_POSE + 1))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("101 depth frames") && e.contains("at most 100"),
            "{e}"
        );
    }
}
