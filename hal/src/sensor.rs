//! The depth sensor: the Kinect's depth camera, tilt motor, accelerometer and LED.

use crate::error::Error;
use groundcal_calib::depth::{DepthModel, Intrinsics};

/// One raw depth frame as the sensor delivered it.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFrame {
    /// The sensor's own frame timestamp.
    pub timestamp: u32,
    /// Host time of arrival, seconds since the Unix epoch (for recordings).
    pub time_s: f64,
    pub width: usize,
    pub height: usize,
    /// Raw 11-bit values, row-major, top row first; 2047 = no reading.
    pub raw: Vec<u16>,
}

/// The tilt motor and the accelerometer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltState {
    /// The motor's angle, degrees (positive up).
    pub tilt_deg: f64,
    /// Acceleration in g along the sensor's (right, up, forward) axes.
    pub accelerometer_g: [f64; 3],
    /// Whether the motor has stopped.
    pub stopped: bool,
}

/// The Kinect's LED.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Led {
    Off,
    Green,
    Red,
    Yellow,
    BlinkGreen,
    BlinkRedYellow,
}

/// What the calibration needs to know about a sensor's frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorInfo {
    pub depth_model: DepthModel,
    pub intrinsics: Intrinsics,
}

/// A depth sensor. All methods are async: a real device answers on its own
/// thread, a simulated one on the runtime's clock.
#[allow(async_fn_in_trait)]
pub trait DepthSensor {
    type Error: Error;

    /// The model and intrinsics that convert this sensor's frames.
    fn info(&self) -> SensorInfo;

    /// Moves the tilt motor to `degrees` and waits until it has stopped.
    async fn set_tilt(&mut self, degrees: f64) -> Result<(), Self::Error>;

    /// The tilt motor and accelerometer now.
    async fn tilt_state(&mut self) -> Result<TiltState, Self::Error>;

    /// Sets the LED (the operator sees the sensor is in use).
    async fn set_led(&mut self, led: Led) -> Result<(), Self::Error>;

    /// Tells the sensor which pose the next frames belong to: frames queued
    /// before it are discarded (they were taken before the pose began); a
    /// played-back sensor serves that pose's recorded frames.
    fn begin_pose(&mut self, _pose_id: u16) {}

    /// The next depth frame, in the order the sensor delivered them.
    async fn next_frame(&mut self) -> Result<DepthFrame, Self::Error>;
}
