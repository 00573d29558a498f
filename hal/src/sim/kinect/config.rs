//! The simulated Kinect's settings: its noise (the measured model or the former
//! white one), its fixed depth pattern, the depth model and intrinsics it
//! renders with, and the errors a wrong setting gives.

use super::*;

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
    pub(super) fn max_disparity_sigma(&self, max_depth_m: f64, disparity_per_raw: f64) -> f64 {
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
pub(super) const GRAZING_COS: f64 = 0.258_819_045_102_520_8;

/// An occluder closer than this to the lit point (metres) casts the
/// emitter's shadow; nearer is the lit surface itself.
pub(super) const SHADOW_TOLERANCE_M: f64 = 1e-3;

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
