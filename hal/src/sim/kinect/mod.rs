//! The simulated Kinect: raw 11-bit depth frames of the simulated [`World`]
//! seen from the body's *true* pose, a tilt motor and an accelerometer.
//!
//! The calibration must find `robot_from_sensor` from what a real Kinect would
//! deliver, so the simulator renders what a real Kinect delivers: raw values of
//! the configured [`DepthModel`] (quantised in disparity, so that a raw step is
//! ~3 mm at 1 m and ~27 mm at 3 m), noise in disparity (so growing as `z²` in
//! depth, along each ray) correlated over the image as a real unit's is, and
//! the unit's own fixed pattern ([`crate::sim::noise`], measured on real
//! frames; [`DepthNoise::White`] keeps the former independent noise), scattered
//! dropouts and more of them at grazing angles, the shadows the 7.5 cm
//! emitter–camera baseline makes boxes and walls cast, the dead columns at the
//! right border, and "no reading" (2047) outside 0.5–5 m. Everything random is
//! drawn from a ChaCha generator seeded by (seed, frame number, row): the same
//! seed and the same poses give the same frames, bit for bit, on any number of
//! threads.
//!
//! Frames are rendered from `ground_from_sensor = ground_from_robot ·
//! robot_from_sensor`, with `ground_from_robot` the body's true pose
//! ([`TruePose`], written by the simulated lower computer) and
//! `robot_from_sensor` the simulator's true mount, which the calibration is
//! meant to find. [`SimKinect::true_robot_from_sensor`] is that truth, for tests
//! to compare the result with; nothing in a calibration may call it.
//!
//! What is not modelled: lens distortion, the RGB camera, and the motor's pivot (a tilt turns the sensor about its
//! optical centre; a real Kinect's head pivots a few centimetres below it).
//! The motor's angle is relative to the mount, where a real Kinect levels
//! against gravity with its accelerometer; the calibration identifies the mount
//! at one fixed tilt, and either reading serves that.
//!
//! Here: the sensor itself (its clock, motor, accelerometer and frames);
//! its settings in [`config`], the rendering of one frame in [`render`].

use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use nalgebra::{Matrix3, Point3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use tokio::time::Instant;

use crate::error::{Error, ErrorKind};
use crate::sensor::{DepthFrame, DepthSensor, Led, SensorInfo, TiltState};
use crate::sim::noise::{measured_pattern, KinectNoise, NoiseHeld, NoiseKey};
use crate::sim::world::{RayHints, Surface, World};
use crate::sim::TruePose;
use groundcal_calib::depth::{DepthModel, Intrinsics, RAW_NO_READING};
use groundcal_calib::geometry::{rot_z, sensor_from_optical, Transform};

mod config;
mod render;
pub use config::*;
pub use render::*;

/// Gravity's reaction as the accelerometer feels it, in g along the sensor's
/// (right, up, forward) axes: the ground's up direction in the sensor frame,
/// which is row 1 of `ground_from_sensor` (conventions.md), reordered.
pub fn accelerometer_g(ground_from_sensor: &Transform) -> [f64; 3] {
    let r = ground_from_sensor.rotation.matrix();
    // Sensor axes: X forward, Y up, Z right.
    [r[(1, 2)], r[(1, 1)], r[(1, 0)]]
}

/// The accelerometer's raw counts (819 per g, recording.md), as a
/// `freenect_raw_tilt_state` carries them.
pub fn accelerometer_counts(ground_from_sensor: &Transform) -> [i16; 3] {
    accelerometer_g(ground_from_sensor).map(|g| (g * ACCELEROMETER_COUNTS_PER_G).round() as i16)
}

/// When the frame clock started, in tokio time and in Unix time.
#[derive(Debug, Clone, Copy)]
struct Clock {
    start: Instant,
    unix_start_s: f64,
}

/// The simulated Kinect: a [`DepthSensor`] looking at a [`World`] from the
/// simulated body's true pose.
#[derive(Debug)]
pub struct SimKinect {
    world: Arc<World>,
    true_pose: TruePose,
    /// The true mount at the motor angle `config.mount_tilt_deg`.
    robot_from_sensor: Transform,
    renderer: Arc<DepthRenderer>,
    tilt_deg: f64,
    led: Led,
    /// Frames delivered so far: the next frame's noise is drawn by this
    /// number, so that a run's frames do not depend on the host's timing.
    frames_delivered: u64,
    /// Accelerometer readings so far (their noise is drawn by this number).
    readings: u64,
    /// The slip of the motor now, degrees (see `SimKinectConfig::motor_slip`).
    slipped_deg: f64,
    /// The pose now (0 at rest, before the first pose): the smooth noise is
    /// the pose's ([`NoiseHeld::PerPose`]).
    pose: u64,
    /// The smooth noise of the pose it was drawn for.
    pose_noise: Option<(u64, Arc<Vec<f32>>)>,
    /// Started at the first frame requested (inside the runtime whose clock
    /// counts, paused or not).
    clock: Option<Clock>,
    last_tick: Option<u64>,
}

impl SimKinect {
    /// A simulated Kinect mounted at `robot_from_sensor` (at the motor angle
    /// `config.mount_tilt_deg`) on the body whose true pose `true_pose` holds.
    pub fn new(
        world: impl Into<Arc<World>>,
        true_pose: TruePose,
        robot_from_sensor: Transform,
        config: SimKinectConfig,
    ) -> Result<Self, SimKinectError> {
        let renderer = DepthRenderer::new(&config)?;
        Ok(Self {
            world: world.into(),
            true_pose,
            robot_from_sensor,
            renderer: Arc::new(renderer),
            tilt_deg: config.mount_tilt_deg,
            led: Led::Off,
            frames_delivered: 0,
            readings: 0,
            slipped_deg: 0.0,
            pose: 0,
            pose_noise: None,
            clock: None,
            last_tick: None,
        })
    }

    /// The smooth noise of the next frame: the pose's, drawn once and held
    /// while the sensor holds still (`Ok`, when it is drawn already), or
    /// the key to draw it by, and whether to keep it for the pose.
    fn smooth_noise(&self, frame_index: u64) -> Result<Option<Arc<Vec<f32>>>, (NoiseKey, bool)> {
        let seed = self.config().seed;
        let held = match self.config().noise {
            DepthNoise::Kinect(k) => k.held,
            DepthNoise::White { .. } => return Ok(None),
        };
        match held {
            NoiseHeld::PerFrame => Err((NoiseKey::frame(seed, frame_index), false)),
            NoiseHeld::PerPose => match &self.pose_noise {
                Some((pose, noise)) if *pose == self.pose => Ok(Some(Arc::clone(noise))),
                _ => Err((NoiseKey::pose(seed, self.pose), true)),
            },
        }
    }

    /// The configuration.
    pub fn config(&self) -> &SimKinectConfig {
        self.renderer.config()
    }

    /// The world in view.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The renderer, to render frames synchronously (tests, benchmarks).
    pub fn renderer(&self) -> &DepthRenderer {
        &self.renderer
    }

    /// The LED's colour.
    pub fn led(&self) -> Led {
        self.led
    }

    /// The motor's angle now, degrees.
    pub fn tilt_deg(&self) -> f64 {
        self.tilt_deg
    }

    /// The sensor's true mount at the current motor angle: the given mount
    /// turned about the sensor's right axis (Z) by the tilt since
    /// `mount_tilt_deg`, positive up. The answer a calibration should find;
    /// for tests only.
    pub fn true_robot_from_sensor(&self) -> Transform {
        let turn = (self.tilt_deg + self.slipped_deg - self.config().mount_tilt_deg).to_radians();
        let tilt = Transform::from_parts(
            nalgebra::Translation3::identity(),
            nalgebra::Rotation3::from_matrix_unchecked(rot_z(turn)),
        );
        self.robot_from_sensor * tilt
    }

    /// The sensor's true pose in the ground frame now.
    pub fn true_ground_from_sensor(&self) -> Transform {
        self.true_pose.get() * self.true_robot_from_sensor()
    }

    /// The accelerometer's raw counts now (819 per g).
    pub fn accelerometer_counts(&self) -> [i16; 3] {
        accelerometer_counts(&self.true_ground_from_sensor())
    }

    /// The frame period in tokio time.
    fn frame_period(&self) -> Duration {
        let c = self.config();
        Duration::from_secs_f64(1.0 / (c.frame_rate_hz * c.time_scale))
    }
}

impl DepthSensor for SimKinect {
    type Error = SimKinectError;

    fn info(&self) -> SensorInfo {
        SensorInfo {
            depth_model: self.config().depth_model,
            intrinsics: self.config().intrinsics,
        }
    }

    /// Clamps to the motor's ±27° and waits as long as the motor takes to
    /// get there at `tilt_speed_deg_s` (scaled by the time scale).
    async fn set_tilt(&mut self, degrees: f64) -> Result<(), Self::Error> {
        if !degrees.is_finite() {
            return Err(SimKinectError::InvalidTilt(degrees));
        }
        let target = degrees.clamp(-TILT_LIMIT_DEG, TILT_LIMIT_DEG);
        let c = self.config();
        let travel_s = (target - self.tilt_deg).abs() / c.tilt_speed_deg_s / c.time_scale;
        tokio::time::sleep(Duration::from_secs_f64(travel_s)).await;
        self.tilt_deg = target;
        Ok(())
    }

    /// Gravity from the true pose, with the accelerometer's noise, in whole
    /// counts as a real Kinect reports it.
    async fn tilt_state(&mut self) -> Result<TiltState, Self::Error> {
        let c = *self.config();
        let mut rng = ChaCha8Rng::seed_from_u64(
            c.seed ^ 0xacce_1e50_0000_0000 ^ self.readings.wrapping_mul(0x9e37_79b9_7f4a_7c15),
        );
        self.readings += 1;
        let (n0, n1) = normal_pair(&mut rng);
        let (n2, _) = normal_pair(&mut rng);
        let exact = accelerometer_g(&self.true_ground_from_sensor());
        let noise = [n0, n1, n2];
        let accelerometer_g = std::array::from_fn(|k| {
            let g = exact[k] + c.accelerometer_noise_g * noise[k];
            (g * ACCELEROMETER_COUNTS_PER_G).round() / ACCELEROMETER_COUNTS_PER_G
        });
        Ok(TiltState {
            tilt_deg: self.tilt_deg,
            accelerometer_g,
            stopped: true,
        })
    }

    async fn set_led(&mut self, led: Led) -> Result<(), Self::Error> {
        self.led = led;
        Ok(())
    }

    /// The motor slips at its configured pose (and stays slipped); the
    /// smooth noise is drawn afresh for the new view.
    fn begin_pose(&mut self, pose_id: u16) {
        self.pose = u64::from(pose_id);
        if let Some((from, degrees)) = self.config().motor_slip {
            if pose_id >= from {
                self.slipped_deg = degrees;
            }
        }
    }

    /// Waits for the next tick of the frame clock, then renders the world
    /// from the body's true pose at that moment. Rendering runs on tokio's
    /// blocking pool, so that the runtime's other tasks (the robot's link)
    /// are not held up for the frame's milliseconds.
    async fn next_frame(&mut self) -> Result<DepthFrame, Self::Error> {
        let now = Instant::now();
        let clock = *self.clock.get_or_insert_with(|| Clock {
            start: now,
            unix_start_s: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_secs_f64())
                .unwrap_or(0.0),
        });
        let period = self.frame_period();
        let elapsed = now.saturating_duration_since(clock.start);
        let mut tick = (elapsed.as_secs_f64() / period.as_secs_f64()).floor() as u64 + 1;
        if let Some(last) = self.last_tick {
            tick = tick.max(last + 1);
        }
        let at = clock.start + period.mul_f64(tick as f64);
        tokio::time::sleep_until(at).await;
        self.last_tick = Some(tick);

        let ground_from_sensor = self.true_ground_from_sensor();
        let frame_index = self.frames_delivered;
        let (world, renderer) = (Arc::clone(&self.world), Arc::clone(&self.renderer));
        let smooth = self.smooth_noise(frame_index);
        let (raw, drawn) = tokio::task::spawn_blocking(move || {
            // A new pose's noise is drawn here too, off the session's thread.
            let (smooth, drawn) = match smooth {
                Ok(held) => (held, None),
                Err((key, keep)) => {
                    let noise = renderer.smooth_noise(key).map(Arc::new);
                    let kept = noise.clone().filter(|_| keep);
                    (noise, kept)
                }
            };
            let raw = renderer.render_with(
                &world,
                &ground_from_sensor,
                frame_index,
                smooth.as_deref().map(Vec::as_slice),
            );
            (raw, drawn)
        })
        .await
        .map_err(|e| SimKinectError::Render(e.to_string()))?;
        if let Some(noise) = drawn {
            self.pose_noise = Some((self.pose, noise));
        }
        self.frames_delivered += 1;

        let c = self.config();
        // The sensor's own clock, in microseconds of simulated time.
        let timestamp = ((tick as f64) * 1e6 / c.frame_rate_hz).round() as u64 as u32;
        Ok(DepthFrame {
            timestamp,
            time_s: clock.unix_start_s + (at - clock.start).as_secs_f64(),
            width: c.intrinsics.width,
            height: c.intrinsics.height,
            raw,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use groundcal_calib::geometry::PoseParams;
    use nalgebra::Vector3;

    #[test]
    fn accelerometer_of_a_level_upright_sensor_reads_one_g_up() {
        let level = PoseParams::new(0.0, 0.0, 0.0, Vector3::new(0.5, 0.9, 0.0)).to_transform();
        assert_eq!(accelerometer_counts(&level), [0, 819, 0]);
        // Pitched 90° down (looking at the floor): up is the sensor's back.
        let down = PoseParams::new(0.0, -std::f64::consts::FRAC_PI_2, 0.0, Vector3::zeros())
            .to_transform();
        assert_eq!(accelerometer_counts(&down), [0, 0, -819]);
        // Rolled right by 90° about the optical axis: up is the sensor's left.
        let rolled =
            PoseParams::new(0.0, 0.0, std::f64::consts::FRAC_PI_2, Vector3::zeros()).to_transform();
        assert_eq!(accelerometer_counts(&rolled), [-819, 0, 0]);
    }

    #[test]
    fn bad_configurations_are_refused_with_words() {
        let cases = [
            SimKinectConfig {
                noise_scale: -1.0,
                ..Default::default()
            },
            SimKinectConfig {
                dropout_rate: 1.5,
                ..Default::default()
            },
            SimKinectConfig {
                min_depth_m: 5.0,
                max_depth_m: 0.5,
                ..Default::default()
            },
            SimKinectConfig {
                time_scale: 0.0,
                ..Default::default()
            },
            SimKinectConfig {
                dead_columns: 700,
                ..Default::default()
            },
        ];
        for config in cases {
            let e = DepthRenderer::new(&config).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::Refused);
            assert!(e.to_string().contains("configuration"), "{e}");
        }
    }
}
