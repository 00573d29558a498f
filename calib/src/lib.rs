//! The calibration math of groundcal: from depth frames and feet to
//! `robot_from_sensor` with its uncertainty and a verdict (Chai et al., made
//! robust; see docs/method.md).
//!
//! Pure and synchronous: values in, values out, no I/O. It must not depend on
//! an async runtime, sockets, files, FFI or anything of the hardware or the
//! application above it, so that it builds, tests and benchmarks alone and
//! the daemon, replay and tests all compute the same thing.
//!
//! From the bottom up:
//! - [`geometry`]: frames `a_from_b`, the paper's six parameters, planes;
//! - [`depth`]: the Kinect's depth models (zero-plane, inverse-linear) and intrinsics;
//! - [`sensor`]: a depth camera, pixels to points with weights;
//! - [`disparity`]: frames in inverse depth, planes of the image, moment sums;
//! - [`plane`]: the ground in one pose's frames (paper 4.1);
//! - [`ground_view`]: a coarse picture of a frame with the ground the fit chose, for the page;
//! - [`body`]: the ground frame and the body pose from the feet (paper 4.2);
//! - [`residuals`]: a pose's ground residuals per cell, for the depth pattern;
//! - [`observe`]: one pose's evidence (feet and frames) to one observation;
//! - [`outcome`]: what a calibration found, shared by the solve and the verdict;
//! - [`solve`]: `robot_from_sensor` from all observations (paper 4.3);
//! - [`disagreement`]: whether the poses' e_d is the depth camera's noise growing with distance;
//! - [`quality`]: θ and e_d (paper 5.2), gates and the verdict;
//! - [`distortion`]: the Kinect's fixed depth pattern, found with the mount;
//! - [`calibrate`]: the solve then the verdict, in one call;
//! - [`tilt`]: the motor's axis and pivot from calibrations at several tilts;
//! - [`verify`]: whether the sensor still sits where a calibration says.

// One exception, in `disparity`: the AVX2 build of the per-pixel loop, called
// only after the processor was checked for AVX2.
#![deny(unsafe_code)]
// No unwrap or expect outside tests: external input and hardware fail with
// an error that says what was wrong (scripts/test runs clippy with this).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

pub mod body;
pub mod calibrate;
pub mod cell_noise;
pub mod depth;
pub mod disagreement;
pub mod disparity;
pub mod distortion;
pub mod geometry;
pub mod ground_view;
pub mod noise_with_depth;
pub mod observe;
pub mod outcome;
pub mod plan;
pub mod plane;
pub mod quality;
pub mod residuals;
pub mod sensor;
pub mod solve;
pub mod tilt;
pub mod verify;

#[cfg(test)]
mod test_noise;
