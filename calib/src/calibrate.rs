//! A whole identification: the solve finds `robot_from_sensor`, then the
//! quality gates judge it. The one entry point for callers that want a
//! verdict (the session, replay, `groundcal solve`).

use crate::distortion;
use crate::outcome::Calibration;
use crate::quality::{self, Gates};
use crate::solve::{Observation, SolveError, SolveSettings};

/// How to solve and what to accept.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CalibrationSettings {
    pub solve: SolveSettings,
    pub gates: Gates,
}

/// Solves the observations and judges the result.
pub fn calibrate(
    observations: &[Observation],
    settings: &CalibrationSettings,
) -> Result<Calibration, SolveError> {
    calibrate_among(observations, observations.len(), settings)
}

/// As [`calibrate`], for observations that are some of `poses_total` poses
/// (the others gave no plane): the gates count the poses that could not be
/// used.
pub fn calibrate_among(
    observations: &[Observation],
    poses_total: usize,
    settings: &CalibrationSettings,
) -> Result<Calibration, SolveError> {
    calibrate_taken_out(observations, poses_total, settings, None)
}

/// As [`calibrate_among`], for planes fitted to frames from which
/// `taken_out`, a first estimate of the depth pattern, was taken out
/// ([`distortion::solve_with_pattern_taken_out`]).
pub fn calibrate_taken_out(
    observations: &[Observation],
    poses_total: usize,
    settings: &CalibrationSettings,
    taken_out: Option<&distortion::DepthCorrection>,
) -> Result<Calibration, SolveError> {
    let solution =
        distortion::solve_with_pattern_taken_out(observations, &settings.solve, taken_out)?;
    Ok(quality::assess(solution, poses_total, &settings.gates))
}
