//! The played-back sensor (`--sensor replay:DIR`): serves a recording's frames
//! for the pose being captured, so that a live session can be run again on
//! what the robot saw. It lives here rather than in `hal/` because it reads
//! the recording format, which is this crate's.

use std::collections::HashMap;
use std::sync::Arc;

use groundcal_hal::{DepthFrame, DepthSensor, Error, ErrorKind, Led, SensorInfo, TiltState};

use crate::formats::recording::Recording;
use crate::platform::input::InputError;

/// Why the recording cannot serve a frame.
#[derive(Debug, thiserror::Error)]
pub enum PlaybackSensorError {
    #[error("{0}")]
    Input(#[from] InputError),
    #[error("the recording has no pose {0}")]
    NoSuchPose(u16),
    #[error("the recording has only {recorded} frames for pose {pose}")]
    OutOfFrames { pose: u16, recorded: usize },
    #[error("no pose is being captured (begin_pose was not called)")]
    NoPose,
    #[error("the recording has {recorded} accelerometer readings for pose {pose}")]
    OutOfReadings { pose: u16, recorded: usize },
    #[error("the recording's reader failed: {0}")]
    Reader(String),
}

impl Error for PlaybackSensorError {
    fn kind(&self) -> ErrorKind {
        match self {
            PlaybackSensorError::Input(_) => ErrorKind::Protocol,
            _ => ErrorKind::Other,
        }
    }
}

/// A recording played back as a sensor. Its files are read on tokio's
/// blocking pool: a read that waits on a busy disk must not hold up the
/// session's thread, whose stall watch would end the run (and which also
/// waits for an Abort), as the simulated Kinect renders off it too.
pub struct PlaybackSensor {
    recording: Arc<Recording>,
    /// Pose id → its line in the recording.
    poses: HashMap<u16, usize>,
    /// Dump file name → (Kinect timestamp, seconds), from the INDEX.
    times: HashMap<String, (u32, f64)>,
    current: Option<(u16, usize)>,
    /// Accelerometer readings of the current pose served so far.
    readings_served: usize,
    tilt_deg: f64,
}

impl PlaybackSensor {
    /// Serves the frames of an opened recording.
    pub fn new(recording: Recording) -> Self {
        let poses = recording
            .poses
            .iter()
            .enumerate()
            .filter_map(|(k, p)| u16::try_from(p.index).ok().map(|id| (id, k)))
            .collect();
        let times = recording
            .index
            .iter()
            .map(|e| (e.name.clone(), (e.timestamp, e.time)))
            .collect();
        let tilt_deg = recording.session.kinect.tilt_deg;
        Self {
            recording: Arc::new(recording),
            poses,
            times,
            current: None,
            readings_served: 0,
            tilt_deg,
        }
    }

    /// The id of the recording's first pose, if it has any.
    pub fn first_pose(&self) -> Option<u16> {
        let first = self.recording.poses.first()?;
        u16::try_from(first.index).ok()
    }

    /// The recording served.
    pub fn recording(&self) -> &Recording {
        &self.recording
    }

    /// `read` of the recording, on tokio's blocking pool.
    async fn read_off_thread<T: Send + 'static>(
        &self,
        read: impl FnOnce(&Recording) -> Result<T, InputError> + Send + 'static,
    ) -> Result<T, PlaybackSensorError> {
        let recording = Arc::clone(&self.recording);
        tokio::task::spawn_blocking(move || read(&recording))
            .await
            .map_err(|e| PlaybackSensorError::Reader(e.to_string()))?
            .map_err(PlaybackSensorError::Input)
    }
}

impl DepthSensor for PlaybackSensor {
    type Error = PlaybackSensorError;

    fn info(&self) -> SensorInfo {
        SensorInfo {
            depth_model: self.recording.session.kinect.depth_model,
            intrinsics: self.recording.session.kinect.intrinsics,
        }
    }

    /// The recording was made at its own tilt; the motor "moves" instantly.
    async fn set_tilt(&mut self, degrees: f64) -> Result<(), Self::Error> {
        if (degrees - self.recording.session.kinect.tilt_deg).abs() > 1e-9 {
            tracing::warn!(
                asked = degrees,
                recorded = self.recording.session.kinect.tilt_deg,
                "the recording was made at another tilt; its frames are served as they are"
            );
        }
        self.tilt_deg = degrees;
        Ok(())
    }

    /// The current pose's recorded accelerometer readings, in order (the
    /// motor at the recording's tilt before any pose).
    async fn tilt_state(&mut self) -> Result<TiltState, Self::Error> {
        let Some((pose_id, _)) = self.current else {
            return Ok(TiltState {
                tilt_deg: self.tilt_deg,
                accelerometer_g: [0.0, 1.0, 0.0],
                stopped: true,
            });
        };
        let line = *self
            .poses
            .get(&pose_id)
            .ok_or(PlaybackSensorError::NoSuchPose(pose_id))?;
        let record = &self.recording.poses[line];
        let name = record.accelerometer.get(self.readings_served).ok_or(
            PlaybackSensorError::OutOfReadings {
                pose: pose_id,
                recorded: record.accelerometer.len(),
            },
        )?;
        let name = name.clone();
        let raw = self
            .read_off_thread(move |recording| recording.read_tilt_state(&name))
            .await?;
        self.readings_served += 1;
        Ok(raw.state())
    }

    async fn set_led(&mut self, _led: Led) -> Result<(), Self::Error> {
        Ok(())
    }

    fn begin_pose(&mut self, pose_id: u16) {
        self.current = Some((pose_id, 0));
        self.readings_served = 0;
    }

    async fn next_frame(&mut self) -> Result<DepthFrame, Self::Error> {
        let (pose_id, served) = self.current.ok_or(PlaybackSensorError::NoPose)?;
        let line = *self
            .poses
            .get(&pose_id)
            .ok_or(PlaybackSensorError::NoSuchPose(pose_id))?;
        let record = &self.recording.poses[line];
        let name = record
            .depth_frames
            .get(served)
            .ok_or(PlaybackSensorError::OutOfFrames {
                pose: pose_id,
                recorded: record.depth_frames.len(),
            })?;
        let (timestamp, time_s) = self.times.get(name).copied().unwrap_or((0, 0.0));
        let name = name.clone();
        let (image, _) = self
            .read_off_thread(move |recording| recording.read_depth_frame(&name))
            .await?;
        self.current = Some((pose_id, served + 1));
        Ok(DepthFrame {
            timestamp,
            time_s,
            width: image.width,
            height: image.height,
            raw: image.pixels,
        })
    }
}
