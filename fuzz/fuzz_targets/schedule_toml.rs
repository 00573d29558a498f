//! Pose schedules, `config/schedules/*.toml` (`schedule::Schedule::parse`,
//! then `validate` against fixed limits).
#![no_main]

use groundcal::setup::schedule::{Limits, Schedule, ScheduleError};
use groundcal_fuzz::{check_input_error, path, text_of};
use libfuzzer_sys::fuzz_target;

/// The simulator's limits (those of `src/setup/schedule.rs`'s tests).
const SIMULATOR: Limits = Limits {
    max_tilt_deg: 25.0,
    min_height_mm: 500.0,
    max_height_mm: 800.0,
    max_shift_mm: 100.0,
};

/// Limits that let nearly any finite pose through, so that the observability
/// check sees extreme ones.
const WIDE: Limits = Limits {
    max_tilt_deg: 360.0,
    min_height_mm: -1e6,
    max_height_mm: 1e6,
    max_shift_mm: 1e6,
};

fuzz_target!(|data: &[u8]| {
    let text = text_of(data);
    let schedule = match Schedule::parse(path(), &text) {
        Err(e) => return check_input_error(&e, &text),
        Ok(schedule) => schedule,
    };
    for limits in [SIMULATOR, WIDE, SIMULATOR.intersect(&WIDE)] {
        match schedule.validate(&limits) {
            Ok(()) => {
                // A schedule that passes has poses, all within the limits.
                assert!(!schedule.poses.is_empty());
                assert_eq!(limits.violation(&schedule.home), None);
                for (i, pose) in schedule.poses.iter().enumerate() {
                    assert_eq!(limits.violation(pose), None, "pose {}", i + 1);
                }
            }
            Err(ScheduleError::Empty { .. }) => assert!(schedule.poses.is_empty()),
            Err(ScheduleError::OutOfLimits { which, reason, .. }) => {
                // It names a pose that is out of the limits.
                let pose = if which == "the home stance" {
                    schedule.home
                } else {
                    let n: usize = which
                        .strip_prefix("pose ")
                        .and_then(|n| n.parse().ok())
                        .unwrap_or_else(|| panic!("names {which:?}"));
                    schedule.poses[n - 1]
                };
                assert_eq!(limits.violation(&pose), Some(reason));
            }
            Err(ScheduleError::Unobservable { reason, .. }) => assert!(!reason.is_empty()),
        }
    }
});
