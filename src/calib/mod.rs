//! The calibration math: pure, synchronous, no I/O.
//!
//! Everything it needs comes in as values, so the same code serves the daemon,
//! replay, tests and benchmarks.
//!
//! - [`geometry`]: frames, the paper's six parameters, planes;
//! - [`sensor`]: the Kinect's depth model and intrinsics, pixels to points;
//! - [`disparity`]: frames in inverse depth, planes of the image, moment sums;
//! - [`plane`]: the ground in one pose's frames (paper 4.1, made robust);
//! - [`body`]: the ground frame and the body pose from the feet (paper 4.2);
//! - [`solve`]: `robot_from_sensor` from all poses (paper 4.3);
//! - [`quality`]: θ and e_d per pose (paper 5.2), gates and verdict.

pub mod body;
pub mod disparity;
/// Frames, the six parameters and planes (in the hardware crate, which
/// carries poses in its messages).
pub use groundcal_hal::geometry;
pub mod plane;
pub mod quality;
pub mod sensor;
pub mod solve;
