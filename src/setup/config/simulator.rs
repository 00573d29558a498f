//! The simulator's section (`[sim]`): its world, its Kinect's noise (a name or
//! a table of parts) and depth pattern, and the faults it can stage (a motor
//! that slips, a foot that sinks).

use super::*;

pub(super) fn default_slip_mm() -> f64 {
    10.0
}

/// The simulated robot and world (`--robot sim`, `--sensor sim`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    pub seed: u64,
    /// Motions and frames this many times faster than real time.
    pub time_scale: f64,
    /// The simulated robot's true `robot_from_sensor`: what a calibration
    /// should find.
    pub mount: crate::calib::geometry::PoseDegMm,
    /// `flat`, `boxes-and-wall`, `uneven` or `corridor`.
    #[serde(deserialize_with = "sim_world")]
    pub world: SimWorld,
    /// A foot that sinks into soft ground from a pose on (tests of slipped
    /// feet): `{ foot = 3, from_pose = 30, depth_mm = 15.0 }`.
    #[serde(default)]
    pub sinking_foot: Option<SinkingFootConfig>,
    /// The simulated Kinect's depth as a multiple of the truth (1.01: reads
    /// 1 % long); default 1.
    #[serde(default)]
    pub depth_scale: Option<f64>,
    /// A tilt motor that slips during a calibration (tests of the motor's
    /// check): `{ from_pose = 26, degrees = 1.0 }`.
    #[serde(default)]
    pub motor_slip: Option<MotorSlipConfig>,
    /// The fixed pattern the simulated Kinect adds to its raw depth:
    /// by default one drawn as a real unit's (`shape = "measured"`, 0.8 raw
    /// units RMS with its plane part); `{ shape = "radial", amplitude_raw =
    /// 0.5 }` and the other shapes for tests; `{ shape = "none" }` for none.
    #[serde(default)]
    pub depth_distortion: Option<SimDistortionConfig>,
    /// The simulated Kinect's depth noise: `kinect` (the default: measured
    /// on real frames, correlated over the image and held through a pose),
    /// `white` (independent per pixel and frame, the former model), or a
    /// table of the measured model's parts for another sensor or a test:
    /// `{ white_raw = 0.38, short_raw = 0, medium_raw = 0.25, long_raw = 0,
    /// gain_per_m = 0, held = "frame" }` (what is left out is as measured).
    #[serde(default, deserialize_with = "sim_noise")]
    pub depth_noise: SimNoise,
}

/// `[sim] depth_noise`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum SimNoise {
    #[default]
    Kinect,
    White,
    /// The measured model with parts of its own.
    Parts(groundcal_hal::sim::noise::KinectNoise),
}

/// `[sim] depth_noise` as a table: the measured model's parts, each
/// optional.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SimNoiseParts {
    pub(super) white_raw: Option<f64>,
    pub(super) short_raw: Option<f64>,
    pub(super) medium_raw: Option<f64>,
    pub(super) long_raw: Option<f64>,
    pub(super) gain_from_m: Option<f64>,
    pub(super) gain_per_m: Option<f64>,
    pub(super) held: Option<String>,
}

pub(super) fn sim_noise<'de, D: serde::Deserializer<'de>>(d: D) -> Result<SimNoise, D::Error> {
    let value = toml::Value::deserialize(d)?;
    sim_noise_of(value).map_err(|e| serde::de::Error::custom(format!("sim.depth_noise: {e}")))
}

pub(super) fn sim_noise_of(value: toml::Value) -> Result<SimNoise, String> {
    use groundcal_hal::sim::noise::{KinectNoise, NoiseHeld};
    let parts = match value {
        toml::Value::String(name) => {
            return match name.as_str() {
                "kinect" => Ok(SimNoise::Kinect),
                "white" => Ok(SimNoise::White),
                other => Err(format!(
                    "\"{other}\" is not a noise of the simulated Kinect (kinect, white, or a table of parts)"
                )),
            }
        }
        table @ toml::Value::Table(_) => {
            SimNoiseParts::deserialize(table).map_err(|e| e.to_string())?
        }
        other => {
            return Err(format!(
                "a TOML {} is not a noise of the simulated Kinect (kinect, white, or a table of parts)",
                other.type_str()
            ))
        }
    };
    let measured = KinectNoise::default();
    let held = match parts.held.as_deref() {
        None | Some("pose") => NoiseHeld::PerPose,
        Some("frame") => NoiseHeld::PerFrame,
        Some(other) => {
            return Err(format!(
                "held = \"{other}\": the smooth noise is held a \"pose\" or a \"frame\""
            ))
        }
    };
    let noise = KinectNoise {
        white_raw: parts.white_raw.unwrap_or(measured.white_raw),
        short_raw: parts.short_raw.unwrap_or(measured.short_raw),
        medium_raw: parts.medium_raw.unwrap_or(measured.medium_raw),
        long_raw: parts.long_raw.unwrap_or(measured.long_raw),
        gain_from_m: parts.gain_from_m.unwrap_or(measured.gain_from_m),
        gain_per_m: parts.gain_per_m.unwrap_or(measured.gain_per_m),
        held,
    };
    noise.validate()?;
    Ok(SimNoise::Parts(noise))
}

/// `[sim] depth_distortion`: the simulated Kinect's fixed pattern.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimDistortionConfig {
    pub shape: SimDistortionShape,
    /// Raw units: the shapes' peak, or the measured pattern's RMS (0.8 by
    /// default); not needed for `none`.
    #[serde(default)]
    pub amplitude_raw: Option<f64>,
    /// For `measured`: whether the pattern keeps the plane part a real
    /// unit's carries (default true), which only the poses' heights tell
    /// from the mount.
    #[serde(default)]
    pub plane_part: Option<bool>,
    /// Herrera's weakening with depth, per metre; default 0.
    #[serde(default)]
    pub decay_per_m: f64,
    /// The stripes' period for `shape = "bands"`, pixels; default 64.
    #[serde(default)]
    pub band_period_px: Option<f64>,
}

/// The shapes of `[sim] depth_distortion`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SimDistortionShape {
    None,
    Measured,
    Radial,
    Tilted,
    Saddle,
    Bands,
    Waves,
}

/// `[sim] motor_slip`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotorSlipConfig {
    pub from_pose: u16,
    pub degrees: f64,
}

/// `[sim] sinking_foot`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SinkingFootConfig {
    pub foot: usize,
    pub from_pose: u16,
    pub depth_mm: f64,
}
