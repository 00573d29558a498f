//! `groundcal solve FILE`: the identification from plane observations alone.

use std::path::Path;

use super::{finish, ExitStatus};
use crate::calib::calibrate::{calibrate, CalibrationSettings};
use crate::calib::solve::SolveError;
use crate::formats::output::ResultJson;
use crate::formats::recording::planes::read_planes;
use std::path::PathBuf;

/// The arguments of `groundcal solve`: a planes file.
#[derive(Debug, clap::Args)]
pub struct SolveArgs {
    /// The plane observations (shared/spec/recording.md, groundcal-planes).
    pub file: PathBuf,
    /// One JSON document on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: SolveArgs) -> ExitStatus {
    run(&args.file, args.json, &CalibrationSettings::default())
}

/// Runs the command; messages go to stderr, the result to stdout.
pub fn run(file: &Path, json: bool, settings: &CalibrationSettings) -> ExitStatus {
    let observations = match read_planes(file) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("groundcal solve: {e}");
            return ExitStatus::BadInput;
        }
    };
    let result = match calibrate(&observations, settings) {
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
    finish("solve", &result, json)
}
