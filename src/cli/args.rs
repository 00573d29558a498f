//! The groups of flags that several commands share: the hardware a session
//! runs on, and what to read from a ROS 2 bag.

use std::path::PathBuf;

use crate::setup::config::{RobotAddress, SensorSource};

/// Which hardware a session runs on, overriding the configuration
/// (`calibrate` and `serve`).
#[derive(Debug, clap::Args)]
pub struct HardwareArgs {
    /// The lower computer: host:port, or sim (simulated, in process).
    #[arg(long)]
    pub robot: Option<RobotAddress>,
    /// The depth sensor: kinect, sim, or replay:DIR.
    #[arg(long)]
    pub sensor: Option<SensorSource>,
    /// The libfreenect library file (e.g. libfreenect's fakenect build).
    #[arg(long, value_name = "PATH")]
    pub freenect_lib: Option<PathBuf>,
}

impl From<HardwareArgs> for crate::hardware::Selection {
    fn from(a: HardwareArgs) -> Self {
        Self {
            robot: a.robot,
            sensor: a.sensor,
            freenect_lib: a.freenect_lib,
        }
    }
}

/// What to read from a ROS 2 bag (`replay BAG.mcap`).
#[derive(Debug, clap::Args)]
pub struct BagArgs {
    /// A bag's depth images (sensor_msgs/msg/Image, 16UC1 or 32FC1).
    #[arg(long, value_name = "TOPIC", default_value = "/camera/depth/image_raw")]
    pub depth_topic: String,
    /// A bag's intrinsics (sensor_msgs/msg/CameraInfo).
    #[arg(
        long,
        value_name = "TOPIC",
        default_value = "/camera/depth/camera_info"
    )]
    pub camera_info_topic: String,
    /// A bag's body frame in /tf (REP 103 axes).
    #[arg(long, value_name = "FRAME", default_value = "base_link")]
    pub body_frame: String,
    /// A bag's foot frames in /tf, foot 1 first: three or more (a quadruped's
    /// four, a hexapod's six in conventions.md's order).
    #[arg(
        long,
        value_name = "F1,F2,F3,..",
        default_value = "foot_1,foot_2,foot_3,foot_4,foot_5,foot_6"
    )]
    pub foot_frames: String,
}

impl BagArgs {
    pub fn options(self) -> Result<crate::solving::bag::BagOptions, String> {
        let feet: Vec<String> = self
            .foot_frames
            .split(',')
            .map(|f| f.trim().to_string())
            .collect();
        if feet.len() < crate::calib::body::MIN_FEET {
            return Err(format!(
                "--foot-frames: at least {} frames (a quadruped's four, a hexapod's six), foot 1 first, separated by commas; found {}",
                crate::calib::body::MIN_FEET,
                feet.len()
            ));
        }
        let foot_frames = feet;
        if foot_frames.iter().any(String::is_empty) {
            return Err("--foot-frames: a frame's name is empty".into());
        }
        Ok(crate::solving::bag::BagOptions {
            depth_topic: self.depth_topic,
            camera_info_topic: self.camera_info_topic,
            body_frame: self.body_frame,
            foot_frames,
            ..Default::default()
        })
    }
}
