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

/// What to read from a ROS 2 bag (`replay BAG.mcap`): each flag overrides
/// the configuration's `[bag]`, which overrides the defaults named here.
#[derive(Debug, clap::Args)]
pub struct BagArgs {
    /// A bag's depth images (sensor_msgs/msg/Image, 16UC1 or 32FC1); default
    /// [bag] depth_topic, else /camera/depth/image_raw.
    #[arg(long, value_name = "TOPIC")]
    pub depth_topic: Option<String>,
    /// A bag's intrinsics (sensor_msgs/msg/CameraInfo); default [bag]
    /// camera_info_topic, else /camera/depth/camera_info.
    #[arg(long, value_name = "TOPIC")]
    pub camera_info_topic: Option<String>,
    /// A bag's body frame in /tf (REP 103 axes); default [bag] body_frame,
    /// else base_link.
    #[arg(long, value_name = "FRAME")]
    pub body_frame: Option<String>,
    /// A bag's foot frames in /tf, foot 1 first: three or more (a quadruped's
    /// four, a hexapod's six in conventions.md's order); default [bag]
    /// foot_frames, else foot_1,…,foot_6.
    #[arg(long, value_name = "F1,F2,F3,..")]
    pub foot_frames: Option<String>,
    /// A bag's stereo baseline in millimetres, for a disparity camera other
    /// than a Kinect (its pattern reported and gated in its own pixels of
    /// disparity); default [bag] baseline_mm, else CameraInfo P's baseline
    /// term, else the camera is judged as a Kinect.
    #[arg(long, value_name = "MM")]
    pub baseline_mm: Option<f64>,
}

impl BagArgs {
    /// The options, from these flags over the configuration's `[bag]`.
    pub fn options(
        self,
        configured: Option<&crate::setup::config::BagConfig>,
    ) -> Result<crate::solving::bag::BagOptions, String> {
        let defaults = crate::solving::bag::BagOptions::default();
        let configured = configured.cloned().unwrap_or_default();
        let foot_frames = match self.foot_frames {
            Some(list) => {
                let feet: Vec<String> = list.split(',').map(|f| f.trim().to_string()).collect();
                if feet.len() < crate::calib::body::MIN_FEET {
                    return Err(format!(
                        "--foot-frames: at least {} frames (a quadruped's four, a hexapod's six), foot 1 first, separated by commas; found {}",
                        crate::calib::body::MIN_FEET,
                        feet.len()
                    ));
                }
                if feet.iter().any(String::is_empty) {
                    return Err("--foot-frames: a frame's name is empty".into());
                }
                feet
            }
            None => configured.foot_frames.unwrap_or(defaults.foot_frames),
        };
        let baseline = match (self.baseline_mm, configured.baseline_mm) {
            (Some(mm), _) => {
                crate::calib::depth::check_baseline_mm(mm)
                    .map_err(|why| format!("--baseline-mm: {why}"))?;
                Some(crate::solving::bag::GivenBaseline { mm, from: "flag" })
            }
            (None, Some(mm)) => Some(crate::solving::bag::GivenBaseline { mm, from: "config" }),
            (None, None) => None,
        };
        Ok(crate::solving::bag::BagOptions {
            depth_topic: self
                .depth_topic
                .or(configured.depth_topic)
                .unwrap_or(defaults.depth_topic),
            camera_info_topic: self
                .camera_info_topic
                .or(configured.camera_info_topic)
                .unwrap_or(defaults.camera_info_topic),
            body_frame: self
                .body_frame
                .or(configured.body_frame)
                .unwrap_or(defaults.body_frame),
            foot_frames,
            baseline,
            ..defaults
        })
    }
}
