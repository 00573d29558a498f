//! The documents groundcal reads and writes, each strict and each naming
//! what was wrong: depth images, recordings (`shared/spec/recording.md`),
//! the result document (`shared/spec/cli.md`), the exports to ROS's frames,
//! the HTML report and the calibration store. Above [`crate::platform`]
//! only.

pub mod depth_image;
pub mod export;
pub mod output;
pub mod recording;
pub mod report;
pub mod store;
