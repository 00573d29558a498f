//! The hardware a session runs on, chosen at run time from the configuration
//! and the `--robot` / `--sensor` overrides: the real Kinect or lower
//! computer, the simulated ones, or a recording. The session is generic over
//! the traits; these enums let the command line pick at run time.

pub mod playback_sensor;

use std::path::PathBuf;
use std::sync::Arc;

use groundcal_hal::kinect::Kinect;
use groundcal_hal::sim::kinect::{SimKinect, SimKinectConfig};
use groundcal_hal::sim::robot::{SimBodyController, SimRobotConfig, SinkingFoot};
use groundcal_hal::sim::world::World;
use groundcal_hal::sim::TruePose;
use groundcal_hal::udp::{LinkConfig, UdpBodyController};
use groundcal_hal::{
    BodyController, BodyState, DepthFrame, DepthSensor, Error, ErrorKind, Led, SensorInfo,
    TiltState, Welcome,
};

use crate::calib::geometry::PoseDegMm;
use crate::formats::recording::Recording;
use crate::setup::config::{Config, RobotAddress, SensorSource, SimConfig, SimWorld};
use playback_sensor::PlaybackSensor;

/// Any hardware error, keeping its kind and its words.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct HardwareError {
    pub kind: ErrorKind,
    pub message: String,
}

impl Error for HardwareError {
    fn kind(&self) -> ErrorKind {
        self.kind
    }
}

fn wrap<E: Error>(e: E) -> HardwareError {
    HardwareError {
        kind: e.kind(),
        message: e.to_string(),
    }
}

/// The depth sensor chosen at run time.
pub enum Sensor {
    Kinect(Box<Kinect>),
    Sim(Box<SimKinect>),
    Playback(Box<PlaybackSensor>),
}

/// The lower computer chosen at run time.
pub enum Controller {
    Udp(Box<UdpBodyController>),
    Sim(Box<SimBodyController>),
}

macro_rules! each_sensor {
    ($self:ident, $s:ident => $body:expr) => {
        match $self {
            Sensor::Kinect($s) => $body,
            Sensor::Sim($s) => $body,
            Sensor::Playback($s) => $body,
        }
    };
}

macro_rules! each_controller {
    ($self:ident, $c:ident => $body:expr) => {
        match $self {
            Controller::Udp($c) => $body,
            Controller::Sim($c) => $body,
        }
    };
}

impl DepthSensor for Sensor {
    type Error = HardwareError;

    fn info(&self) -> SensorInfo {
        each_sensor!(self, s => s.info())
    }

    async fn set_tilt(&mut self, degrees: f64) -> Result<(), HardwareError> {
        each_sensor!(self, s => s.set_tilt(degrees).await.map_err(wrap))
    }

    async fn tilt_state(&mut self) -> Result<TiltState, HardwareError> {
        each_sensor!(self, s => s.tilt_state().await.map_err(wrap))
    }

    async fn set_led(&mut self, led: Led) -> Result<(), HardwareError> {
        each_sensor!(self, s => s.set_led(led).await.map_err(wrap))
    }

    fn begin_pose(&mut self, pose_id: u16) {
        each_sensor!(self, s => s.begin_pose(pose_id))
    }

    async fn next_frame(&mut self) -> Result<DepthFrame, HardwareError> {
        each_sensor!(self, s => s.next_frame().await.map_err(wrap))
    }
}

impl BodyController for Controller {
    type Error = HardwareError;

    async fn hello(&mut self) -> Result<Welcome, HardwareError> {
        each_controller!(self, c => c.hello().await.map_err(wrap))
    }

    async fn set_pose(
        &mut self,
        pose_id: u16,
        pose: &PoseDegMm,
        duration_ms: u32,
    ) -> Result<(), HardwareError> {
        each_controller!(self, c => c.set_pose(pose_id, pose, duration_ms).await.map_err(wrap))
    }

    async fn state(&mut self) -> Result<BodyState, HardwareError> {
        each_controller!(self, c => c.state().await.map_err(wrap))
    }

    async fn home(&mut self, duration_ms: u32) -> Result<(), HardwareError> {
        each_controller!(self, c => c.home(duration_ms).await.map_err(wrap))
    }

    async fn halt(&mut self) -> Result<(), HardwareError> {
        each_controller!(self, c => c.halt().await.map_err(wrap))
    }

    async fn bye(&mut self) -> Result<(), HardwareError> {
        each_controller!(self, c => c.bye().await.map_err(wrap))
    }
}

/// Where the hardware comes from: the configuration, with the command line's
/// overrides.
#[derive(Debug, Clone, Default)]
pub struct Selection {
    pub robot: Option<RobotAddress>,
    pub sensor: Option<SensorSource>,
    pub freenect_lib: Option<PathBuf>,
}

impl Selection {
    /// The lower computer after the override.
    pub fn robot(&self, config: &Config) -> RobotAddress {
        self.robot
            .clone()
            .unwrap_or_else(|| config.robot.address.clone())
    }

    /// The sensor source after the override.
    pub fn sensor(&self, config: &Config) -> SensorSource {
        self.sensor
            .clone()
            .unwrap_or_else(|| config.sensor.source.clone())
    }
}

/// The simulated robot and Kinect share the body's true pose.
struct SimParts {
    true_pose: TruePose,
    sim: SimConfig,
}

fn no_sim_table() -> HardwareError {
    HardwareError {
        kind: ErrorKind::DeviceMissing,
        message: "the simulated robot and Kinect need a [sim] table in the configuration".into(),
    }
}

fn sim_parts(config: &Config) -> Result<SimParts, HardwareError> {
    let sim = config.sim.clone().ok_or_else(no_sim_table)?;
    let robot = SimRobotConfig::reference(sim.seed, sim.time_scale);
    let true_pose = TruePose::new(robot.home.to_params().to_transform());
    Ok(SimParts { true_pose, sim })
}

fn world(sim: &SimConfig) -> World {
    match sim.world {
        SimWorld::Flat => World::flat(),
        SimWorld::BoxesAndWall => World::boxes_and_wall(sim.seed),
        SimWorld::Uneven => World::uneven(sim.seed, 0.01),
        SimWorld::Corridor => World::corridor(sim.seed),
        SimWorld::Clutter => World::clutter(sim.seed),
        SimWorld::LowBoxes => World::low_boxes(sim.seed),
        SimWorld::WallMeetingFloor => World::wall_meeting_floor(sim.seed),
    }
}

/// Opens the hardware. The simulated robot and Kinect, when both are chosen,
/// share one simulated body.
pub async fn open(
    config: &Config,
    selection: &Selection,
) -> Result<(Sensor, Controller), HardwareError> {
    let robot = selection.robot(config);
    let source = selection.sensor(config);
    let sim = if robot == RobotAddress::Sim || source == SensorSource::Sim {
        Some(sim_parts(config)?)
    } else {
        None
    };

    let controller = if let RobotAddress::HostPort(address) = &robot {
        let mut link = LinkConfig::resolve(address).map_err(wrap)?;
        link.interface = config.robot.interface.clone();
        link.client.retry_interval =
            std::time::Duration::from_millis(config.robot.retry_interval_ms);
        link.client.retry_limit = config.robot.retries;
        Controller::Udp(Box::new(
            UdpBodyController::connect(&link).await.map_err(wrap)?,
        ))
    } else {
        let parts = sim.as_ref().ok_or_else(no_sim_table)?;
        let mut robot = SimRobotConfig::reference(parts.sim.seed, parts.sim.time_scale);
        robot.sinking_foot = parts.sim.sinking_foot.map(|s| SinkingFoot {
            foot: s.foot,
            from_pose: s.from_pose,
            depth_mm: s.depth_mm,
        });
        Controller::Sim(Box::new(SimBodyController::new(
            robot,
            parts.true_pose.clone(),
        )))
    };

    let sensor = sensor_from(
        config,
        selection,
        source,
        sim.as_ref(),
        robot == RobotAddress::Sim,
    )?;
    Ok((sensor, controller))
}

/// Opens the depth sensor alone, to look without moving: the simulated
/// Kinect sees the simulated body standing at its home stance.
pub fn open_sensor(config: &Config, selection: &Selection) -> Result<Sensor, HardwareError> {
    let source = selection.sensor(config);
    let sim = match source {
        SensorSource::Sim => Some(sim_parts(config)?),
        _ => None,
    };
    let robot_is_sim = selection.robot(config) == RobotAddress::Sim;
    sensor_from(config, selection, source, sim.as_ref(), robot_is_sim)
}

/// The simulator's pattern of `[sim] depth_distortion`.
fn sim_distortion(
    config: &crate::setup::config::SimDistortionConfig,
) -> groundcal_hal::sim::kinect::DepthDistortion {
    use crate::setup::config::SimDistortionShape as Shape;
    use groundcal_hal::sim::kinect::{DepthDistortion, DistortionShape};
    let shape = match config.shape {
        Shape::None => DistortionShape::None,
        Shape::Measured => DistortionShape::Measured {
            plane: config.plane_part.unwrap_or(true),
        },
        Shape::Radial => DistortionShape::Radial,
        Shape::Tilted => DistortionShape::Tilted,
        Shape::Saddle => DistortionShape::Saddle,
        Shape::Bands => DistortionShape::Bands {
            period_px: config.band_period_px.unwrap_or(64.0),
        },
        Shape::Waves => DistortionShape::Waves,
    };
    let default_amplitude = match config.shape {
        Shape::Measured => DepthDistortion::measured().amplitude_raw,
        _ => 0.0,
    };
    DepthDistortion {
        shape,
        amplitude_raw: config.amplitude_raw.unwrap_or(default_amplitude),
        decay_per_m: config.decay_per_m,
    }
}

/// Why the simulated Kinect with a lower computer of its own process (or
/// the robot's) cannot calibrate: it renders the simulated body, which that
/// lower computer does not move, so it sees the home stance at every pose.
pub const SIM_SENSOR_BLIND: &str = "the simulated Kinect sees only the in-process simulated body, which this lower computer does not move: every pose looks like the home stance, so a calibration finds no ground where it expects it and judges the tilt motor moved (use --robot sim, or a recording's frames with sim-robot --replay)";

/// A warning for the operator about the hardware chosen, when its parts do
/// not belong together ([`SIM_SENSOR_BLIND`]).
pub fn mismatch(config: &Config, selection: &Selection) -> Option<&'static str> {
    let sensor_is_sim = matches!(selection.sensor(config), SensorSource::Sim);
    let robot_is_sim = selection.robot(config) == RobotAddress::Sim;
    (sensor_is_sim && !robot_is_sim).then_some(SIM_SENSOR_BLIND)
}

/// The sensor of `source`; the simulated one sees the body of `sim`.
fn sensor_from(
    config: &Config,
    selection: &Selection,
    source: SensorSource,
    sim: Option<&SimParts>,
    robot_is_sim: bool,
) -> Result<Sensor, HardwareError> {
    Ok(match source {
        SensorSource::Sim => {
            let parts = sim.ok_or_else(no_sim_table)?;
            if !robot_is_sim {
                tracing::warn!("{}", SIM_SENSOR_BLIND);
            }
            let mut kinect = SimKinectConfig {
                seed: parts.sim.seed,
                time_scale: parts.sim.time_scale,
                mount_tilt_deg: config.sensor.tilt_deg,
                depth_scale: parts.sim.depth_scale.unwrap_or(1.0),
                distortion: parts
                    .sim
                    .depth_distortion
                    .map(|d| sim_distortion(&d))
                    .unwrap_or_else(groundcal_hal::sim::kinect::DepthDistortion::measured),
                motor_slip: parts.sim.motor_slip.map(|m| (m.from_pose, m.degrees)),
                ..SimKinectConfig::default()
            };
            if let Some(model) = config.sensor.depth_model {
                kinect.depth_model = model;
            }
            match parts.sim.depth_noise {
                crate::setup::config::SimNoise::Kinect => {}
                crate::setup::config::SimNoise::White => {
                    kinect.noise = groundcal_hal::sim::kinect::DepthNoise::white();
                }
                crate::setup::config::SimNoise::Parts(parts) => {
                    kinect.noise = groundcal_hal::sim::kinect::DepthNoise::Kinect(parts);
                }
            }
            if let Some(intrinsics) = config.sensor.intrinsics {
                kinect.intrinsics = intrinsics;
            }
            let mount = parts.sim.mount.to_params().to_transform();
            Sensor::Sim(Box::new(
                SimKinect::new(
                    Arc::new(world(&parts.sim)),
                    parts.true_pose.clone(),
                    mount,
                    kinect,
                )
                .map_err(wrap)?,
            ))
        }
        SensorSource::Kinect => {
            let library = selection
                .freenect_lib
                .clone()
                .or_else(|| config.sensor.freenect_lib.clone());
            Sensor::Kinect(Box::new(Kinect::open(library.as_deref(), 0).map_err(wrap)?))
        }
        SensorSource::Playback(dir) => {
            let recording = Recording::open(&dir).map_err(|e| HardwareError {
                kind: ErrorKind::DeviceMissing,
                message: e.to_string(),
            })?;
            Sensor::Playback(Box::new(PlaybackSensor::new(recording)))
        }
    })
}
