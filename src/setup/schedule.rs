//! Pose schedules (`config/schedules/*.toml`): the body poses a calibration
//! visits, checked before anything moves.
//!
//! A schedule is refused, with the offending pose named, when a pose is outside
//! the robot's limits, and when the schedule as a whole cannot observe all six
//! parameters (e.g. it never tilts the body): better to say so before the
//! robot spends minutes moving than after.

use std::path::Path;

use serde::Deserialize;

use crate::calib::geometry::PoseDegMm;
use crate::calib::solve::{observability, Observation, SolveSettings};
use crate::platform::input::{parse_toml, read_bounded, InputError};

/// A schedule as read from its file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    pub name: String,
    /// The home stance (commanded `ground_from_robot`).
    pub home: PoseDegMm,
    /// The poses, visited in order; pose `i` (1-based) is `poses[i - 1]`.
    pub poses: Vec<PoseDegMm>,
    /// The file it was read from, for messages (None: made in the program).
    #[serde(skip)]
    pub file: Option<std::path::PathBuf>,
}

/// A commanded body pose in an operator's words, as the page and the
/// terminal say what the robot is doing: "rolled 20° right, pitched 2°
/// nose up, body at 615 mm". Angles and shifts below 0.05 are left out.
///
/// The body frame is X forward, Y up, Z right (conventions.md): γ about X
/// leans the top to the right (+Z), β about Z lifts the nose (+Y), α about Y
/// turns the nose to the left (−Z).
pub fn body_pose_in_words(pose: &PoseDegMm) -> String {
    let mut parts = Vec::new();
    let mut angle = |value: f64, positive: &str, negative: &str, verb: &str| {
        if value.abs() >= 0.05 {
            let side = if value > 0.0 { positive } else { negative };
            parts.push(format!("{verb} {}° {side}", trim_number(value.abs())));
        }
    };
    angle(pose.gamma_deg, "right", "left", "rolled");
    angle(pose.beta_deg, "nose up", "nose down", "pitched");
    angle(pose.alpha_deg, "left", "right", "turned");
    for (value, positive, negative) in [
        (pose.px_mm, "forward", "back"),
        (pose.pz_mm, "right", "left"),
    ] {
        if value.abs() >= 0.05 {
            let side = if value > 0.0 { positive } else { negative };
            parts.push(format!("shifted {} mm {side}", trim_number(value.abs())));
        }
    }
    parts.push(format!("body at {} mm", trim_number(pose.py_mm)));
    parts.join(", ")
}

/// A number with at most one decimal, and none when it is whole.
fn trim_number(value: f64) -> String {
    let rounded = (value * 10.0).round() / 10.0;
    if rounded.fract() == 0.0 {
        format!("{rounded:.0}")
    } else {
        format!("{rounded:.1}")
    }
}

/// The body's motion limits (hexapod-udp.md: WELCOME, and the configuration).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    pub max_tilt_deg: f64,
    pub min_height_mm: f64,
    pub max_height_mm: f64,
    pub max_shift_mm: f64,
}

impl Limits {
    /// The intersection of two sets of limits (the stricter of each).
    pub fn intersect(&self, other: &Limits) -> Limits {
        Limits {
            max_tilt_deg: self.max_tilt_deg.min(other.max_tilt_deg),
            min_height_mm: self.min_height_mm.max(other.min_height_mm),
            max_height_mm: self.max_height_mm.min(other.max_height_mm),
            max_shift_mm: self.max_shift_mm.min(other.max_shift_mm),
        }
    }

    /// Why `pose` is outside the limits, if it is.
    pub fn violation(&self, pose: &PoseDegMm) -> Option<String> {
        if !pose.is_finite() {
            return Some("has a value that is not a finite number".into());
        }
        for (name, value) in [
            ("alpha", pose.alpha_deg),
            ("beta", pose.beta_deg),
            ("gamma", pose.gamma_deg),
        ] {
            if value.abs() > self.max_tilt_deg {
                return Some(format!(
                    "{name} = {value}° is beyond the ±{}° tilt limit",
                    self.max_tilt_deg
                ));
            }
        }
        if pose.py_mm < self.min_height_mm || pose.py_mm > self.max_height_mm {
            return Some(format!(
                "height py = {} mm is outside {}..{} mm",
                pose.py_mm, self.min_height_mm, self.max_height_mm
            ));
        }
        for (name, value) in [("px", pose.px_mm), ("pz", pose.pz_mm)] {
            if value.abs() > self.max_shift_mm {
                return Some(format!(
                    "{name} = {value} mm is beyond the ±{} mm shift limit",
                    self.max_shift_mm
                ));
            }
        }
        None
    }
}

/// Why a schedule cannot be run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScheduleError {
    #[error("schedule {schedule} has no poses")]
    Empty { schedule: String },
    #[error("schedule {schedule}: {which} {reason}")]
    OutOfLimits {
        schedule: String,
        which: String,
        reason: String,
    },
    #[error("schedule {schedule} cannot calibrate: {reason}")]
    Unobservable { schedule: String, reason: String },
}

impl Schedule {
    /// Parses a schedule file's text.
    pub fn parse(path: &Path, text: &str) -> Result<Self, InputError> {
        let mut schedule: Schedule = parse_toml(path, text)?;
        schedule.file = Some(path.to_path_buf());
        Ok(schedule)
    }

    /// The schedule as messages name it: its name, and its file when it
    /// has one (`"octopus-52" in /etc/groundcal/schedules/octopus-52.toml`).
    pub fn label(&self) -> String {
        match &self.file {
            Some(file) => format!("\"{}\" in {}", self.name, file.display()),
            None => format!("\"{}\"", self.name),
        }
    }

    /// Reads a schedule file.
    pub fn read(path: &Path) -> Result<Self, InputError> {
        let bytes = read_bounded(path, 1 << 20)?;
        let text = std::str::from_utf8(&bytes)
            .map_err(|e| InputError::new(path, None, format!("not UTF-8 text: {e}")))?;
        Self::parse(path, text)
    }

    /// Checks every pose and the home stance against `limits`, and the
    /// schedule's ability to observe all six parameters.
    pub fn validate(&self, limits: &Limits) -> Result<(), ScheduleError> {
        self.validate_limits(limits)?;
        self.validate_observability()
    }

    /// Whether it has poses and every one is within `limits` (a check's
    /// schedule needs no more: it solves nothing).
    pub fn validate_limits(&self, limits: &Limits) -> Result<(), ScheduleError> {
        if self.poses.is_empty() {
            return Err(ScheduleError::Empty {
                schedule: self.label(),
            });
        }
        let out = |which: String, reason: String| ScheduleError::OutOfLimits {
            schedule: self.label(),
            which,
            reason,
        };
        if let Some(reason) = limits.violation(&self.home) {
            return Err(out("the home stance".into(), reason));
        }
        for (i, pose) in self.poses.iter().enumerate() {
            if let Some(reason) = limits.violation(pose) {
                return Err(out(format!("pose {}", i + 1), reason));
            }
        }
        Ok(())
    }

    /// Whether a calibration on it could observe all six parameters.
    fn validate_observability(&self) -> Result<(), ScheduleError> {
        // The commanded poses stand in for the real ones: observability depends
        // on the tilts, which the real poses follow closely.
        let stand_ins: Vec<Observation> = self
            .poses
            .iter()
            .enumerate()
            .map(|(i, pose)| {
                let ground_from_robot = pose.to_params().to_transform();
                let plane = crate::calib::geometry::Plane {
                    normal: nalgebra::Vector3::y(),
                    d: 1.0,
                };
                Observation::new(i as u32 + 1, ground_from_robot, plane)
            })
            .collect();
        let refs: Vec<&Observation> = stand_ins.iter().collect();
        let report = observability(&refs, &SolveSettings::default());
        if let Some(reason) = report.problems.first() {
            return Err(ScheduleError::Unobservable {
                schedule: self.label(),
                reason: reason.clone(),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIMULATOR: Limits = Limits {
        max_tilt_deg: 25.0,
        min_height_mm: 500.0,
        max_height_mm: 800.0,
        max_shift_mm: 100.0,
    };

    fn octopus() -> Schedule {
        let path = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/config/schedules/octopus-52.toml"
        ));
        Schedule::read(path).unwrap()
    }

    #[test]
    fn the_shipped_octopus_schedule_is_table_a1() {
        let s = octopus();
        assert_eq!(s.poses.len(), 52);
        let p = |i: usize| s.poses[i - 1];
        assert_eq!(
            (p(1).beta_deg, p(1).gamma_deg, p(1).py_mm),
            (2.0, 20.0, 615.0)
        );
        assert_eq!(
            (p(25).beta_deg, p(25).gamma_deg, p(25).py_mm),
            (17.0, 11.0, 694.0)
        );
        assert_eq!(
            (p(52).beta_deg, p(52).gamma_deg, p(52).py_mm),
            (-12.0, -3.0, 750.0)
        );
        assert!(s
            .poses
            .iter()
            .all(|p| p.alpha_deg == 0.0 && p.px_mm == 0.0 && p.pz_mm == 0.0));
        s.validate(&SIMULATOR).unwrap();
    }

    #[test]
    fn a_pose_beyond_the_limits_is_named() {
        let strict = Limits {
            max_tilt_deg: 18.0,
            ..SIMULATOR
        };
        let err = octopus().validate(&strict).unwrap_err().to_string();
        // The schedule is named by its file, where an operator can fix it.
        assert_eq!(
            err,
            format!(
                "schedule \"octopus-52\" in {}/config/schedules/octopus-52.toml: pose 1 gamma = 20° is beyond the ±18° tilt limit",
                env!("CARGO_MANIFEST_DIR")
            )
        );
        let low = Limits {
            max_height_mm: 700.0,
            ..SIMULATOR
        };
        let err = octopus()
            .validate(&low.intersect(&SIMULATOR))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("pose 41 height py = 730 mm is outside 500..700 mm"),
            "{err}"
        );
    }

    #[test]
    fn a_schedule_that_never_tilts_is_refused_before_moving() {
        let mut s = octopus();
        for p in &mut s.poses {
            p.beta_deg = 0.0;
            p.gamma_deg = 0.0;
        }
        let err = s.validate(&SIMULATOR).unwrap_err().to_string();
        assert!(
            err.contains("cannot calibrate: rotation of the sensor about the ground normal"),
            "{err}"
        );
    }

    #[test]
    fn a_pose_in_words_names_each_motion_by_its_side() {
        let pose = |alpha_deg, beta_deg, gamma_deg, px_mm, pz_mm| PoseDegMm {
            alpha_deg,
            beta_deg,
            gamma_deg,
            px_mm,
            py_mm: 615.0,
            pz_mm,
        };
        assert_eq!(
            body_pose_in_words(&pose(0.0, 2.0, 20.0, 0.0, 0.0)),
            "rolled 20° right, pitched 2° nose up, body at 615 mm"
        );
        assert_eq!(
            body_pose_in_words(&pose(-3.5, -8.0, -19.0, 20.0, -10.0)),
            "rolled 19° left, pitched 8° nose down, turned 3.5° right, shifted 20 mm forward, shifted 10 mm left, body at 615 mm"
        );
        assert_eq!(
            body_pose_in_words(&pose(0.0, 0.0, 0.0, 0.0, 0.0)),
            "body at 615 mm"
        );
    }

    #[test]
    fn bad_files_name_the_line() {
        let text = "name = \"x\"\nhome = { alpha_deg = 0, beta_deg = 0, gamma_deg = 0, px_mm = 0, py_mm = 600, pz_mm = 0 }\nposes = [ { alpha_deg = 0 } ]\n";
        let err = Schedule::parse(Path::new("s.toml"), text).unwrap_err();
        assert_eq!(err.line, Some(3), "{err}");
        assert!(err.to_string().starts_with("s.toml:3:"), "{err}");
        // Found by fuzzing: some syntax errors once gave an empty message.
        for text in ["#\u{0}\n", "name = ", "poses = [ #"] {
            let err = Schedule::parse(Path::new("s.toml"), text).unwrap_err();
            assert!(!err.message.trim().is_empty(), "{text:?}");
        }
        let err = Schedule::parse(Path::new("s.toml"), "name = \"x\"\nspeed = 3\n").unwrap_err();
        assert!(
            err.message.contains("speed") || err.message.contains("unknown"),
            "{err}"
        );
    }
}
