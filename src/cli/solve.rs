//! `groundcal solve FILE`: the identification from plane observations alone.

use std::path::Path;

use super::{print_json, ExitStatus};
use crate::calib::solve::{solve, SolveError, SolveSettings};
use crate::output::ResultJson;
use crate::recording::planes::read_planes;

/// Runs the command; messages go to stderr, the result to stdout.
pub fn run(file: &Path, json: bool, settings: &SolveSettings) -> ExitStatus {
    let observations = match read_planes(file) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("groundcal solve: {e}");
            return ExitStatus::BadInput;
        }
    };
    let result = match solve(&observations, settings) {
        Ok(calibration) => ResultJson::from_calibration(&calibration),
        Err(SolveError::TooFewObservations { usable, outcomes }) => ResultJson::unsolved(
            SolveError::TooFewObservations {
                usable,
                outcomes: Vec::new(),
            }
            .to_string(),
            &outcomes,
        ),
    };
    let printed = if json {
        print_json(&result)
    } else {
        print!("{}", result.to_table());
        Ok(())
    };
    if let Err(e) = printed {
        eprintln!("groundcal solve: {e}");
        return ExitStatus::RuntimeFailure;
    }
    if result.accepted() {
        ExitStatus::Success
    } else {
        ExitStatus::Rejected
    }
}
