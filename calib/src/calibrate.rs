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
    let solution = distortion::solve_with_pattern(observations, &settings.solve)?;
    Ok(quality::assess(solution, poses_total, &settings.gates))
}
