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

/// The former model's depth noise in disparity, 1/m, independent from pixel
/// to pixel: `σ(z) = 1.4·10⁻³·z²` m in depth (conventions.md), about half a
/// raw step ([`DepthNoise::White`]).
pub const DISPARITY_SIGMA: f64 = 1.4e-3;

/// The simulated Kinect's depth noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DepthNoise {
    /// As a real Kinect's, measured on real frames: correlated over the
    /// image, held through a pose, growing with depth (the default).
    Kinect(KinectNoise),
    /// Independent per pixel and frame, σ in disparity, 1/m (the former
    /// model, for tests that need noise without structure):
    /// [`DISPARITY_SIGMA`], 0.456 raw units of the inverse-linear model.
    White { disparity_sigma: f64 },
}

impl Default for DepthNoise {
    fn default() -> Self {
        DepthNoise::Kinect(KinectNoise::default())
    }
}

impl DepthNoise {
    /// The former model's white noise ([`DISPARITY_SIGMA`]).
    pub fn white() -> Self {
        DepthNoise::White {
            disparity_sigma: DISPARITY_SIGMA,
        }
    }

    /// The largest σ of a reading at depths up to `max_depth_m`, in
    /// disparity (1/m), for a model of `disparity_per_raw`.
    fn max_disparity_sigma(&self, max_depth_m: f64, disparity_per_raw: f64) -> f64 {
        match self {
            DepthNoise::Kinect(k) => {
                (k.smooth_sigma_raw() + k.white_raw) * k.gain(max_depth_m) * disparity_per_raw.abs()
            }
            DepthNoise::White { disparity_sigma } => *disparity_sigma,
        }
    }

    fn validate(&self) -> Result<(), String> {
        match self {
            DepthNoise::Kinect(k) => k.validate(),
            DepthNoise::White { disparity_sigma } => {
                if disparity_sigma.is_finite() && (0.0..=0.1).contains(disparity_sigma) {
                    Ok(())
                } else {
                    Err(format!(
                        "the white noise's disparity_sigma must lie in [0, 0.1] /m, not {disparity_sigma}"
                    ))
                }
            }
        }
    }
}

/// Accelerometer counts per g (recording.md).
pub const ACCELEROMETER_COUNTS_PER_G: f64 = 819.0;

/// The accelerometer's noise per axis and reading, in g: 1.5·10⁻³ g, about
/// 1.2 counts or 0.09° of gravity's direction (the Kinect's KXSD9-class part
/// reads a count or two of noise at rest).
pub const ACCELEROMETER_NOISE_G: f64 = 1.5e-3;

/// The tilt motor's range, ± degrees from level (the Kinect's is about ±27°).
pub const TILT_LIMIT_DEG: f64 = 27.0;

/// Incidence angles (between the ray and the surface's normal) beyond
/// `acos(GRAZING_COS)` = 75° lose pixels in proportion to how far beyond:
/// the projected speckle smears out and the camera cannot match it.
const GRAZING_COS: f64 = 0.258_819_045_102_520_8;

/// An occluder closer than this to the lit point (metres) casts the
/// emitter's shadow; nearer is the lit surface itself.
const SHADOW_TOLERANCE_M: f64 = 1e-3;

/// How the simulated Kinect behaves. The defaults are a typical Kinect v1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimKinectConfig {
    /// How raw values map to depth; frames are rendered in it, and
    /// [`DepthSensor::info`] reports it.
    pub depth_model: DepthModel,
    pub intrinsics: Intrinsics,
    /// The depth noise, drawn in disparity (raw units of the depth model).
    pub noise: DepthNoise,
    /// Multiplies the depth noise; 0 renders exact depths, quantised.
    pub noise_scale: f64,
    /// Fraction of pixels lost at random anywhere (real frames: about 1 %).
    pub dropout_rate: f64,
    /// Fraction lost at the most grazing incidence, falling linearly to none
    /// at 75° from the normal.
    pub grazing_dropout: f64,
    /// Columns at the right border that never have a reading (a real Kinect's
    /// depth image has 8: the correlation window runs off the IR image).
    pub dead_columns: usize,
    /// Readings outside this depth range are "no reading", metres.
    pub min_depth_m: f64,
    pub max_depth_m: f64,
    /// Distance from the camera to the IR emitter along the image's x axis
    /// (the Kinect's 7.5 cm); what a box or a wall hides from the emitter is
    /// "no reading". 0 turns the shadows off.
    pub emitter_baseline_m: f64,
    /// Seed of the noise and dropouts.
    pub seed: u64,
    /// Frames per second of simulated time.
    pub frame_rate_hz: f64,
    /// How much faster than real time the simulation runs (as the simulated
    /// robot's time scale): frame periods and motor moves take
    /// `1/time_scale` of their simulated duration in (tokio) time.
    pub time_scale: f64,
    /// The tilt motor's speed, degrees per second of simulated time.
    pub tilt_speed_deg_s: f64,
    /// The motor angle at which the `robot_from_sensor` given to
    /// [`SimKinect::new`] is the sensor's mount, and the motor's initial angle.
    /// Set it to the session's `tilt_deg`, so that the mount the calibration
    /// finds is the one given.
    pub mount_tilt_deg: f64,
    /// σ of each accelerometer axis per reading, in g (before the reading is
    /// rounded to whole counts of 1/819 g, as a real Kinect's is).
    pub accelerometer_noise_g: f64,
    /// A motor that slips: from this pose id on, the sensor is turned by
    /// this many degrees more about its right axis than the motor says (a
    /// knock, or a motor that moved during a calibration). None: steady.
    pub motor_slip: Option<(u16, f64)>,
    /// The depth the sensor reads, as a multiple of the true depth (a real
    /// Kinect's is often off by a fraction of a percent to about 1 %): 1.01
    /// reads 1 % long. Every point moves along its ray, so a plane keeps its
    /// normal and its distance is multiplied by it.
    pub depth_scale: f64,
    /// A fixed pattern over the image added to every raw value (a real
    /// unit's depth distortion): by default one drawn as a real unit's
    /// ([`DistortionShape::Measured`], 0.8 raw units RMS and its plane part).
    pub distortion: DepthDistortion,
}

/// A real Kinect's fixed disparity pattern (Smisek et al. 2011, Herrera et
/// al. 2012): every pixel reads `amplitude_raw · shape(u, v)` raw units more
/// than the truth (more is farther), times `exp(−decay_per_m·(z − 1 m))` for
/// Herrera's weakening with depth. The shapes lie in [−1, 1] over the image.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DepthDistortion {
    pub shape: DistortionShape,
    pub amplitude_raw: f64,
    /// Herrera's decay with depth, per metre (0: the same at every depth).
    pub decay_per_m: f64,
}

/// The shape of a [`DepthDistortion`], with `x̂ = (u − cx)/cx` and
/// `ŷ = (v − cy)/cy` in [−1, 1].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum DistortionShape {
    #[default]
    None,
    /// A bowl: −1 at the principal point, +1 at the corners (`2ρ² − 1`,
    /// ρ the distance from the centre over the corner's).
    Radial,
    /// A tilted plane, `(x̂ + ŷ)/2`: what a free plane per frame absorbs
    /// entirely, seen only through the geometry across poses.
    Tilted,
    /// A saddle, `x̂·ŷ`.
    Saddle,
    /// Vertical stripes, `sin(2π·u/period_px)`, as on real units.
    Bands { period_px: f64 },
    /// Smooth waves across the image, `sin(π·x̂)·cos(π·ŷ)`.
    Waves,
    /// A real unit's, drawn for the simulator's seed as measured on real
    /// frames ([`measured_pattern`]): a smooth field whose RMS (its plane
    /// part left out) is the amplitude (0.8 measured), sawtooth stripes
    /// 42 pixels apart and a fine texture; with `plane`, the plane part the
    /// smooth field carries, which only the poses' heights can tell from the
    /// mount.
    Measured { plane: bool },
}

impl DepthDistortion {
    /// The pattern at pixel `(u, v)` at depth 1 m, raw units.
    pub fn raw_at(&self, u: f64, v: f64, intrinsics: &Intrinsics) -> f64 {
        let (x, y) = (
            (u - intrinsics.cx) / intrinsics.cx,
            (v - intrinsics.cy) / intrinsics.cy,
        );
        let shape = match self.shape {
            DistortionShape::None => 0.0,
            DistortionShape::Radial => {
                let corner = intrinsics.cx.hypot(intrinsics.cy);
                let rho = (u - intrinsics.cx).hypot(v - intrinsics.cy) / corner;
                2.0 * rho * rho - 1.0
            }
            DistortionShape::Tilted => (x + y) / 2.0,
            DistortionShape::Saddle => x * y,
            DistortionShape::Bands { period_px } => (std::f64::consts::TAU * u / period_px).sin(),
            DistortionShape::Waves => {
                (std::f64::consts::PI * x).sin() * (std::f64::consts::PI * y).cos()
            }
            // Drawn over the whole image at once ([`distortion_image`]).
            DistortionShape::Measured { .. } => 0.0,
        };
        self.amplitude_raw * shape
    }

    /// A real unit's pattern as measured (0.8 raw units RMS, its plane part).
    pub fn measured() -> Self {
        Self {
            shape: DistortionShape::Measured { plane: true },
            amplitude_raw: 0.8,
            decay_per_m: 0.0,
        }
    }

    fn validate(&self) -> Result<(), String> {
        if !(self.amplitude_raw.is_finite() && self.amplitude_raw.abs() <= 5.0) {
            return Err(format!(
                "the distortion's amplitude_raw must lie in [−5, 5] raw units, not {}",
                self.amplitude_raw
            ));
        }
        if !(self.decay_per_m.is_finite() && (0.0..=5.0).contains(&self.decay_per_m)) {
            return Err(format!(
                "the distortion's decay_per_m must lie in [0, 5], not {}",
                self.decay_per_m
            ));
        }
        if let DistortionShape::Bands { period_px } = self.shape {
            if !(period_px.is_finite() && period_px >= 8.0) {
                return Err(format!(
                    "the distortion's bands must be at least 8 pixels apart, not {period_px}"
                ));
            }
        }
        Ok(())
    }
}

impl Default for SimKinectConfig {
    fn default() -> Self {
        Self {
            depth_model: DepthModel::default(),
            intrinsics: Intrinsics::default(),
            noise: DepthNoise::default(),
            noise_scale: 1.0,
            dropout_rate: 0.01,
            grazing_dropout: 0.5,
            dead_columns: 8,
            min_depth_m: 0.5,
            max_depth_m: 5.0,
            emitter_baseline_m: 0.075,
            seed: 0,
            frame_rate_hz: 30.0,
            time_scale: 1.0,
            tilt_speed_deg_s: 20.0,
            mount_tilt_deg: 0.0,
            accelerometer_noise_g: ACCELEROMETER_NOISE_G,
            motor_slip: None,
            depth_scale: 1.0,
            distortion: DepthDistortion::measured(),
        }
    }
}

impl SimKinectConfig {
    /// The former model: noise independent per pixel and frame
    /// ([`DepthNoise::White`]) and no pattern; for tests of what a fit does
    /// with noise that has no structure (its bias, its σ against its errors).
    pub fn independent_noise() -> Self {
        Self {
            noise: DepthNoise::white(),
            distortion: DepthDistortion::default(),
            ..Self::default()
        }
    }

    /// Whether every setting is usable.
    pub fn validate(&self) -> Result<(), SimKinectError> {
        let bad = |m: String| Err(SimKinectError::Config(m));
        self.depth_model
            .validate()
            .map_err(SimKinectError::Config)?;
        self.intrinsics.validate().map_err(SimKinectError::Config)?;
        let finite_non_negative = [
            ("noise_scale", self.noise_scale),
            ("emitter_baseline_m", self.emitter_baseline_m),
            ("accelerometer_noise_g", self.accelerometer_noise_g),
        ];
        for (name, value) in finite_non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return bad(format!("{name} must be a finite number ≥ 0, not {value}"));
            }
        }
        for (name, value) in [
            ("dropout_rate", self.dropout_rate),
            ("grazing_dropout", self.grazing_dropout),
        ] {
            if !(0.0..=1.0).contains(&value) {
                return bad(format!("{name} must lie in [0, 1], not {value}"));
            }
        }
        if !(self.min_depth_m > 0.0
            && self.min_depth_m < self.max_depth_m
            && self.max_depth_m.is_finite())
        {
            return bad(format!(
                "the depth range {}–{} m is not a range of positive depths",
                self.min_depth_m, self.max_depth_m
            ));
        }
        for (name, value) in [
            ("frame_rate_hz", self.frame_rate_hz),
            ("time_scale", self.time_scale),
            ("tilt_speed_deg_s", self.tilt_speed_deg_s),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return bad(format!("{name} must be a positive number, not {value}"));
            }
        }
        if let Some((_, degrees)) = self.motor_slip {
            if !(degrees.is_finite() && degrees.abs() <= TILT_LIMIT_DEG) {
                return bad(format!(
                    "motor_slip of {degrees}° is not a slip of the motor (±{TILT_LIMIT_DEG}°)"
                ));
            }
        }
        self.distortion.validate().map_err(SimKinectError::Config)?;
        self.noise.validate().map_err(SimKinectError::Config)?;
        if !(0.5..=2.0).contains(&self.depth_scale) {
            return bad(format!(
                "depth_scale must lie in [0.5, 2], not {}",
                self.depth_scale
            ));
        }
        if !(-TILT_LIMIT_DEG..=TILT_LIMIT_DEG).contains(&self.mount_tilt_deg) {
            return bad(format!(
                "mount_tilt_deg {} is outside the motor's ±{TILT_LIMIT_DEG}°",
                self.mount_tilt_deg
            ));
        }
        if self.dead_columns > self.intrinsics.width {
            return bad(format!(
                "{} dead columns in an image {} wide",
                self.dead_columns, self.intrinsics.width
            ));
        }
        Ok(())
    }
}

/// What went wrong in the simulated Kinect.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimKinectError {
    #[error("simulated Kinect configuration: {0}")]
    Config(String),
    #[error("tilt {0}° is not a number of degrees")]
    InvalidTilt(f64),
    #[error("rendering a simulated frame failed: {0}")]
    Render(String),
}

impl Error for SimKinectError {
    fn kind(&self) -> ErrorKind {
        match self {
            SimKinectError::Config(_) | SimKinectError::InvalidTilt(_) => ErrorKind::Refused,
            SimKinectError::Render(_) => ErrorKind::Other,
        }
    }
}

/// Depth to raw values: every raw value the model maps to a depth, sorted by
/// depth, with the midpoints in disparity (`1/z`, what the Kinect measures
/// and rounds) between neighbours. The nearest raw of a depth is the one
/// between the midpoints around it: the same answer as
/// [`groundcal_calib::depth::raw_for_depth`], found in constant time.
///
/// Both models are linear in disparity (`1/z` is affine in the raw value), so
/// the midpoints are evenly spaced in `1/z`: a table of bins in `1/z`, finer
/// than a raw step, says where to start looking, and a step or two finds the
/// midpoint.
#[derive(Debug, Clone)]
struct Quantiser {
    raws: Vec<u16>,
    depths: Vec<f64>,
    midpoints: Vec<f64>,
    min_depth_m: f64,
    max_depth_m: f64,
    /// The disparity range of the bins, `1/z` in 1/m: from the range's far
    /// end (doubled) to its near end (halved).
    disparity_low: f64,
    disparity_high: f64,
    /// For each bin, from the near end, the index of a midpoint at or below
    /// the nearest depth of the bin.
    bins: Vec<u32>,
}

/// Bins of the quantiser's table: over 0.25–10 m a bin is 0.0005 /m of
/// disparity, a sixth of a raw step in both models (about 0.003 /m). A
/// coarser table would still be exact, only slower.
const QUANTISER_BINS: usize = 8192;

impl Quantiser {
    fn new(model: &DepthModel, min_depth_m: f64, max_depth_m: f64) -> Result<Self, SimKinectError> {
        let mut pairs: Vec<(f64, u16)> = (0..RAW_NO_READING)
            .filter_map(|raw| model.depth_m(raw).map(|z| (z, raw)))
            .collect();
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        if pairs.is_empty() {
            return Err(SimKinectError::Config(
                "the depth model maps no raw value to a depth".into(),
            ));
        }
        // Halfway in disparity: 1/m = (1/z₀ + 1/z₁)/2.
        let midpoints: Vec<f64> = pairs
            .windows(2)
            .map(|w| 2.0 * w[0].0 * w[1].0 / (w[0].0 + w[1].0))
            .collect();
        let disparity_low = 0.5 / max_depth_m;
        let disparity_high = 2.0 / min_depth_m;
        let width = (disparity_high - disparity_low) / QUANTISER_BINS as f64;
        let bins = (0..QUANTISER_BINS)
            .map(|b| {
                // The nearest depth of bin b; one midpoint lower for rounding.
                let nearest = 1.0 / (disparity_high - b as f64 * width);
                midpoints
                    .partition_point(|&m| m < nearest)
                    .saturating_sub(1) as u32
            })
            .collect();
        Ok(Self {
            raws: pairs.iter().map(|p| p.1).collect(),
            depths: pairs.iter().map(|p| p.0).collect(),
            midpoints,
            min_depth_m,
            max_depth_m,
            disparity_low,
            disparity_high,
            bins,
        })
    }

    /// The largest depth that quantises to a raw value in the range: the
    /// midpoint past the farthest raw in range (half a raw step, 4 cm at 5 m).
    fn farthest_in_range(&self) -> f64 {
        let last = self.depths.partition_point(|&d| d <= self.max_depth_m);
        last.checked_sub(1)
            .and_then(|i| self.midpoints.get(i))
            .map_or(self.max_depth_m, |&m| m.max(self.max_depth_m))
    }

    /// The raw value nearest `z` in disparity, or "no reading" outside the range.
    fn raw(&self, z: f64) -> u16 {
        let disparity = 1.0 / z;
        // Outside the bins (and for NaN) the nearest raw is out of range: a
        // depth half the range's near end or twice its far end lies many raw
        // steps beyond it.
        if !(disparity > self.disparity_low && disparity <= self.disparity_high) {
            return RAW_NO_READING;
        }
        let bin = ((self.disparity_high - disparity) / (self.disparity_high - self.disparity_low)
            * QUANTISER_BINS as f64) as usize;
        let mut i = self.bins[bin.min(QUANTISER_BINS - 1)] as usize;
        // Ties go to the nearer raw below, as raw_for_depth does.
        while i < self.midpoints.len() && self.midpoints[i] < z {
            i += 1;
        }
        let depth = self.depths[i];
        if depth < self.min_depth_m || depth > self.max_depth_m {
            RAW_NO_READING
        } else {
            self.raws[i]
        }
    }
}

/// Renders raw frames of a world from a sensor pose. Pure and synchronous:
/// the same world, pose and frame number give the same frame.
#[derive(Debug, Clone)]
pub struct DepthRenderer {
    config: SimKinectConfig,
    quantiser: Quantiser,
    /// `(u - cx) / fx` per column: the optical ray's x for a depth of 1.
    ray_x: Vec<f64>,
    /// `(v - cy) / fy` per row: the optical ray's y (down) for a depth of 1.
    ray_y: Vec<f64>,
    /// The distortion per pixel at 1 m in disparity (1/m), row-major; empty
    /// without one.
    distortion: Vec<f64>,
    /// Disparity (1/m) per raw unit: the model's `b` (negative: more raw is
    /// farther).
    disparity_per_raw: f64,
}

impl DepthRenderer {
    /// A renderer for the sensor `config` describes.
    pub fn new(config: &SimKinectConfig) -> Result<Self, SimKinectError> {
        config.validate()?;
        let k = &config.intrinsics;
        Ok(Self {
            config: *config,
            quantiser: Quantiser::new(&config.depth_model, config.min_depth_m, config.max_depth_m)?,
            ray_x: (0..k.width).map(|u| (u as f64 - k.cx) / k.fx).collect(),
            ray_y: (0..k.height).map(|v| (v as f64 - k.cy) / k.fy).collect(),
            distortion: distortion_image(config),
            disparity_per_raw: config.depth_model.inverse_depth_affine().1,
        })
    }

    /// The smooth part of the noise drawn for `index` (a pose's, or a
    /// frame's), raw units, to hand to [`DepthRenderer::render_with`]; None
    /// for noise without one.
    pub fn smooth_noise(&self, key: NoiseKey) -> Option<Vec<f32>> {
        match self.config.noise {
            DepthNoise::Kinect(k) if self.config.noise_scale > 0.0 => Some(k.smooth_field(
                self.config.intrinsics.width,
                self.config.intrinsics.height,
                key,
            )),
            _ => None,
        }
    }

    /// The configuration rendered.
    pub fn config(&self) -> &SimKinectConfig {
        &self.config
    }

    /// The nearest raw value of a depth in metres (2047 outside the range).
    pub fn quantise(&self, z: f64) -> u16 {
        self.quantiser.raw(z)
    }

    /// One raw frame, row-major, top row first, of `world` seen from
    /// `ground_from_sensor`; `frame_index` selects the frame's noise, all of
    /// it drawn for this frame (the smooth part too: [`DepthRenderer::render_with`]
    /// holds it through a pose, as [`SimKinect`] does).
    pub fn render(
        &self,
        world: &World,
        ground_from_sensor: &Transform,
        frame_index: u64,
    ) -> Vec<u16> {
        let smooth = self.smooth_noise(NoiseKey::frame(self.config.seed, frame_index));
        self.render_with(world, ground_from_sensor, frame_index, smooth.as_deref())
    }

    /// [`DepthRenderer::render`] with the smooth part of the noise given
    /// (from [`DepthRenderer::smooth_noise`]); the white part is the frame's.
    ///
    /// Each pixel's ray is the optical `((u-cx)/fx, (v-cy)/fy, 1)`, turned
    /// into G by `ground_from_sensor · sensor_from_optical`: with an optical
    /// z of 1 the ray parameter of the hit is the depth `z` itself.
    pub fn render_with(
        &self,
        world: &World,
        ground_from_sensor: &Transform,
        frame_index: u64,
        smooth: Option<&[f32]>,
    ) -> Vec<u16> {
        let c = &self.config;
        // The noise in disparity (1/m) of a reading at depth z, from its
        // frame's standard normal draw and its pose's smooth part (raw units,
        // more is farther). The former model's white draw enters as
        // `+σ·gaussian` in disparity; the measured one's in raw units.
        let noise = |z: f64, gaussian: f64, smooth_raw: f64| match c.noise {
            DepthNoise::Kinect(k) => {
                self.disparity_per_raw
                    * c.noise_scale
                    * k.gain(z)
                    * (smooth_raw - k.white_raw * gaussian)
            }
            DepthNoise::White { disparity_sigma } => c.noise_scale * disparity_sigma * gaussian,
        };
        let smooth = smooth.filter(|s| s.len() == c.intrinsics.width * c.intrinsics.height);
        let width = c.intrinsics.width;
        let ground_from_optical: Matrix3<f64> =
            ground_from_sensor.rotation.matrix() * sensor_from_optical();
        let (right, down, forward) = (
            ground_from_optical.column(0).into_owned(),
            ground_from_optical.column(1).into_owned(),
            ground_from_optical.column(2).into_owned(),
        );
        let origin = Point3::from(ground_from_sensor.translation.vector);
        // The emitter sits at optical (baseline, 0, 0): sensor Z (right).
        let emitter = ground_from_sensor * Point3::new(0.0, 0.0, c.emitter_baseline_m);
        // Past this depth even 5σ of noise and the whole pattern cannot bring
        // a reading into range.
        let far = self.quantiser.farthest_in_range();
        let pattern_reach = self.distortion.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        let near_enough = 1.0 / far
            - 5.0
                * c.noise_scale
                * c.noise
                    .max_disparity_sigma(c.max_depth_m, self.disparity_per_raw)
            - pattern_reach;
        let t_max = if near_enough > 0.0 {
            1.0 / near_enough
        } else {
            f64::INFINITY
        };
        let live = width - c.dead_columns;
        let shadows = c.emitter_baseline_m > 0.0 && world.has_obstacles();
        // Where each obstacle can be in the image, seen from the camera and
        // from the emitter: rays elsewhere need not ask about it.
        let corners = world.obstacle_corners();
        let in_camera =
            ObstacleBounds::new(&corners, &ground_from_optical, &origin, &c.intrinsics, 0.0);
        let in_emitter = ObstacleBounds::new(
            &corners,
            &ground_from_optical,
            &origin,
            &c.intrinsics,
            c.emitter_baseline_m,
        );
        // A point at depth z seen at column u is at the emitter's column
        // u - fx·baseline/z.
        let emitter_shift = c.intrinsics.fx * c.emitter_baseline_m;

        let mut raw = vec![RAW_NO_READING; width * c.intrinsics.height];
        raw.par_chunks_mut(width).enumerate().for_each(|(v, row)| {
            let mut rng = row_rng(c.seed, frame_index, v);
            let row_direction = forward + down * self.ray_y[v];
            let (camera_row, emitter_row) = (in_camera.row(v as f64), in_emitter.row(v as f64));
            let mut spare = None;
            let mut ground_height = None;
            for (u, value) in row.iter_mut().enumerate().take(live) {
                // A fixed number of draws per pixel: a pixel's noise does
                // not depend on what its neighbours saw.
                let gaussian = spare.take().unwrap_or_else(|| {
                    let (a, b) = normal_pair(&mut rng);
                    spare = Some(b);
                    a
                });
                let chance: f64 = rng.gen();
                let direction = row_direction + right * self.ray_x[u];
                let hints = RayHints {
                    candidates: ObstacleBounds::candidates(&camera_row, u as f64),
                    ground_height,
                };
                let Some(hit) = world.cast_with(&origin, &direction, t_max, &hints) else {
                    continue;
                };
                if hit.surface == Surface::Ground {
                    ground_height = Some(origin.y + direction.y * hit.t);
                }
                let z = hit.t;
                // The noise is in disparity, as the Kinect's correlation
                // measures it (raw units, more is farther): the frame's
                // white part and the pose's smooth part, grown with depth.
                let smooth_raw = smooth.map_or(0.0, |s| f64::from(s[v * width + u]));
                let mut disparity = 1.0 / (z * c.depth_scale) + noise(z, gaussian, smooth_raw);
                if let Some(pattern) = self.distortion.get(v * width + u) {
                    disparity += pattern * (-c.distortion.decay_per_m * (z - 1.0)).exp();
                }
                if disparity <= 0.0 {
                    continue;
                }
                let quantised = self.quantiser.raw(1.0 / disparity);
                if quantised == RAW_NO_READING {
                    continue;
                }
                let cos_incidence = hit.normal.dot(&direction).abs() / direction.norm();
                let grazing = ((GRAZING_COS - cos_incidence) / GRAZING_COS).clamp(0.0, 1.0);
                if chance < c.dropout_rate + c.grazing_dropout * grazing {
                    continue;
                }
                let candidates =
                    ObstacleBounds::candidates(&emitter_row, u as f64 - emitter_shift / z);
                if shadows && candidates != 0 {
                    let lit = origin + direction * z;
                    let towards = lit - emitter;
                    let reach = 1.0 - SHADOW_TOLERANCE_M / towards.norm();
                    if world.blocked_by_obstacle_among(&emitter, &towards, reach, candidates) {
                        continue;
                    }
                }
                *value = quantised;
            }
        });
        raw
    }
}

/// The distortion of every pixel at 1 m in disparity, 1/m (row-major), or
/// nothing without one: `b` raw units per 1/m (the model's inverse depth is
/// `a + b·raw`).
fn distortion_image(config: &SimKinectConfig) -> Vec<f64> {
    if config.distortion.shape == DistortionShape::None || config.distortion.amplitude_raw == 0.0 {
        return Vec::new();
    }
    let (_, b) = config.depth_model.inverse_depth_affine();
    let k = &config.intrinsics;
    if let DistortionShape::Measured { plane } = config.distortion.shape {
        return measured_pattern(
            k.width,
            k.height,
            config.seed,
            config.distortion.amplitude_raw,
            plane,
        )
        .into_iter()
        .map(|raw| b * f64::from(raw))
        .collect();
    }
    (0..k.height)
        .flat_map(|v| (0..k.width).map(move |u| (u, v)))
        .map(|(u, v)| b * config.distortion.raw_at(u as f64, v as f64, k))
        .collect()
}

/// The pixel rectangles that hold each obstacle's image, as seen by a
/// pinhole at the camera or at the emitter (the camera's intrinsics, shifted
/// along the optical x axis): a ray outside an obstacle's rectangle cannot
/// meet it. An obstacle with a corner behind the pinhole gets no rectangle
/// and is asked by every ray.
struct ObstacleBounds {
    /// `[u_lo, u_hi, v_lo, v_hi]` per obstacle, a pixel wider on every side.
    rectangles: Vec<[f64; 4]>,
}

impl ObstacleBounds {
    fn new(
        corners: &[Vec<Point3<f64>>],
        ground_from_optical: &Matrix3<f64>,
        camera: &Point3<f64>,
        intrinsics: &Intrinsics,
        x_offset: f64,
    ) -> Self {
        let everywhere = [
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
        ];
        let rectangles = corners
            .iter()
            .map(|obstacle| {
                let mut r = [
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                ];
                for corner in obstacle {
                    let p = ground_from_optical.transpose() * (corner - camera);
                    if p.z <= 1e-6 {
                        return everywhere;
                    }
                    let u = intrinsics.fx * (p.x - x_offset) / p.z + intrinsics.cx;
                    let v = intrinsics.fy * p.y / p.z + intrinsics.cy;
                    r = [
                        r[0].min(u - 1.0),
                        r[1].max(u + 1.0),
                        r[2].min(v - 1.0),
                        r[3].max(v + 1.0),
                    ];
                }
                r
            })
            .collect();
        Self { rectangles }
    }

    /// The obstacles (index, u_lo, u_hi) whose rectangles hold row `v`;
    /// those from the 65th on are always there.
    fn row(&self, v: f64) -> Vec<(usize, f64, f64)> {
        self.rectangles
            .iter()
            .enumerate()
            .filter(|(i, r)| *i >= 64 || (r[2]..=r[3]).contains(&v))
            .map(|(i, r)| (i, r[0], r[1]))
            .collect()
    }

    /// The bits of the row's obstacles whose rectangles hold column `u`.
    fn candidates(row: &[(usize, f64, f64)], u: f64) -> u64 {
        row.iter()
            .filter(|&&(i, lo, hi)| i < 64 && (lo..=hi).contains(&u))
            .fold(0, |mask, &(i, _, _)| mask | 1 << i)
    }
}

/// The generator of one row of one frame: keyed by all three so that rows
/// can be drawn in any order on any thread.
fn row_rng(seed: u64, frame_index: u64, row: usize) -> ChaCha8Rng {
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    key[8..16].copy_from_slice(&frame_index.to_le_bytes());
    key[16..24].copy_from_slice(&(row as u64).to_le_bytes());
    key[24..].copy_from_slice(b"simkinct");
    ChaCha8Rng::from_seed(key)
}

/// Two independent standard normal deviates (Box–Muller).
fn normal_pair(rng: &mut impl Rng) -> (f64, f64) {
    let u1: f64 = 1.0 - rng.gen::<f64>();
    let u2: f64 = rng.gen();
    let radius = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
    (radius * c, radius * s)
}

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
    use groundcal_calib::depth::raw_for_depth;
    use groundcal_calib::geometry::PoseParams;
    use nalgebra::Vector3;

    #[test]
    fn quantiser_agrees_with_raw_for_depth() {
        for model in [DepthModel::default(), DepthModel::inverse_linear_default()] {
            let q = Quantiser::new(&model, 0.5, 5.0).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(9);
            for _ in 0..5000 {
                let z = rng.gen_range(0.3..6.0);
                let expected = raw_for_depth(&model, z)
                    .filter(|&r| (0.5..=5.0).contains(&model.depth_m(r).unwrap()))
                    .unwrap_or(RAW_NO_READING);
                assert_eq!(q.raw(z), expected, "z = {z}");
            }
            assert_eq!(q.raw(f64::NAN), RAW_NO_READING);
            assert_eq!(q.raw(-1.0), RAW_NO_READING);
        }
    }

    #[test]
    fn standard_normal_has_unit_variance() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let n = 200_000;
        let samples: Vec<f64> = (0..n / 2)
            .flat_map(|_| {
                let (a, b) = normal_pair(&mut rng);
                [a, b]
            })
            .collect();
        let mean = samples.iter().sum::<f64>() / n as f64;
        let var = samples.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(
            mean.abs() < 0.01 && (var - 1.0).abs() < 0.01,
            "{mean} {var}"
        );
    }

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
