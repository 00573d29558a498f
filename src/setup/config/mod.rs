//! The configuration (`config/groundcal.toml` on the robot, `config/sim.toml`
//! for simulated hardware): strict TOML (`deny_unknown_fields`), then semantic
//! checks, so that a typo is an error naming the key rather than a default
//! silently used. `groundcal check-config FILE` runs both.
//!
//! Here: the sections and their checks; the simulator's section in
//! [`simulator`], the choices a word makes (robot, sensor, world) in
//! [`choices`].

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Deserializer};

use crate::calib::quality::Gates;
use crate::calib::sensor::{DepthModel, Intrinsics};
use crate::formats::recording::session::NominalMount;
use crate::platform::input::{parse_toml, read_bounded, InputError};
use crate::setup::schedule::{Limits, Schedule};

/// The whole configuration.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    pub robot: RobotConfig,
    pub sensor: SensorConfig,
    pub calibration: CalibrationConfig,
    #[serde(default)]
    pub sim: Option<SimConfig>,
    #[serde(default)]
    pub serve: Option<ServeConfig>,
    /// `groundcal verify` and the daemon's checks (defaults if absent).
    #[serde(default)]
    pub verify: VerifyConfig,
    /// How this robot's ROS 2 bags name its topics and frames
    /// (`replay BAG.mcap --config`; the flags override it).
    #[serde(default)]
    pub bag: Option<BagConfig>,
}

/// A robot's bags (`[bag]`): what `replay BAG.mcap` reads, so that a
/// quadruped's configuration names its feet once. Each key is optional; a
/// flag given overrides it, and without either the built-in default holds.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct BagConfig {
    pub depth_topic: Option<String>,
    pub camera_info_topic: Option<String>,
    /// The body's frame in the TF tree (REP 103 axes).
    pub body_frame: Option<String>,
    /// The feet's frames, foot 1 first: three or more.
    pub foot_frames: Option<Vec<String>>,
    /// The depth camera's stereo baseline, millimetres, for a disparity
    /// camera other than a Kinect: with its focal length, the constant
    /// that turns its inverse depth into its own pixels of disparity, in
    /// which its pattern is reported and gated.
    pub baseline_mm: Option<f64>,
}

/// How a calibration is checked against the ground and the accelerometer
/// (`groundcal verify`, the daemon at start-up and on "Check").
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VerifyConfig {
    /// A direction has drifted beyond this many of its σ (the calibration's
    /// and the poses' noise together). 4 keeps false alarms near 1 in 1000.
    pub k_sigma: f64,
    /// σ of one accelerometer reading, degrees of gravity's direction (its
    /// noise, its counts of 1/819 g, its alignment with the depth camera).
    pub accelerometer_sigma_deg: f64,
    /// Tilted poses besides the still stance (0: stand still; 4 also see the
    /// yaw). `--poses` overrides it.
    pub poses: usize,
    /// The body's roll and pitch at the tilted poses, degrees (default: 8°,
    /// or the robot's max_tilt_deg if that is less).
    pub tilt_deg: Option<f64>,
    /// Whether `serve` checks the active calibration when it starts.
    pub at_start: bool,
}

impl Default for VerifyConfig {
    fn default() -> Self {
        let d = crate::calib::verify::VerifySettings::default();
        Self {
            k_sigma: d.k_sigma,
            accelerometer_sigma_deg: d.accelerometer_sigma_deg,
            poses: 0,
            tilt_deg: None,
            at_start: true,
        }
    }
}

impl VerifyConfig {
    /// The tilted poses' roll and pitch: the one given, or 8° within the
    /// robot's limits.
    pub fn tilt_deg(&self, limits: &Limits) -> f64 {
        self.tilt_deg.unwrap_or(8f64.min(limits.max_tilt_deg))
    }

    /// The math's settings, with the ground's noise of `[calibration.noise]`.
    pub fn settings(
        &self,
        calibration: &CalibrationConfig,
    ) -> crate::calib::verify::VerifySettings {
        crate::calib::verify::VerifySettings {
            noise: calibration
                .noise
                .unwrap_or_else(crate::calib::plan::NoiseModel::solve_floors),
            accelerometer_sigma_deg: self.accelerometer_sigma_deg,
            k_sigma: self.k_sigma,
        }
    }
}

/// The lower computer.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// The robot's name ("octopus"), kept with each calibration and in each
    /// recording: a calibration holds for its own robot only, and `verify`
    /// refuses another's.
    #[serde(default)]
    pub name: Option<String>,
    /// `host:port` of the lower computer (hexapod-udp.md), or `sim` for the
    /// simulated one in process.
    #[serde(deserialize_with = "robot_address")]
    pub address: RobotAddress,
    /// Bind the socket to this network interface (the robot's Wi-Fi).
    #[serde(default)]
    pub interface: Option<String>,
    #[serde(default = "default_retry_interval_ms")]
    pub retry_interval_ms: u64,
    #[serde(default = "default_retries")]
    pub retries: u32,
    /// groundcal's own limits; the stricter of these and the lower
    /// computer's (WELCOME) apply.
    pub limits: Limits,
}

fn default_retry_interval_ms() -> u64 {
    100
}

fn default_retries() -> u32 {
    10
}

/// The depth sensor.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorConfig {
    /// `kinect`, `sim`, or `replay:DIR`.
    #[serde(deserialize_with = "sensor_source")]
    pub source: SensorSource,
    /// The libfreenect library file (e.g. libfreenect's fakenect build).
    #[serde(default)]
    pub freenect_lib: Option<PathBuf>,
    /// The Kinect's motor tilt during calibration; the result holds for it.
    pub tilt_deg: f64,
    /// Overrides the sensor's own model.
    #[serde(default)]
    pub depth_model: Option<DepthModel>,
    /// Overrides the sensor's own intrinsics.
    #[serde(default)]
    pub intrinsics: Option<Intrinsics>,
}

/// How to calibrate.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationConfig {
    /// The pose schedule, relative to the configuration file.
    pub schedule: PathBuf,
    pub frames_per_pose: usize,
    /// Time to move to each pose (SET_POSE duration).
    pub motion_ms: u32,
    /// Wait after the body has settled before capturing.
    pub settle_ms: u64,
    /// The rough mount that tells which plane is the ground.
    #[serde(default)]
    pub nominal_mount: Option<NominalMount>,
    #[serde(default)]
    pub gates: Gates,
    /// A foot farther than this from where it was planted has slipped; once
    /// the feet have shown their own agreement the limit follows it below
    /// this (`calib::observe::SLIP_SCATTERS`).
    #[serde(default = "default_slip_mm")]
    pub slip_threshold_mm: f64,
    /// The fit that refines the ground: `disparity` (in inverse depth, the
    /// default) or `paper` (the paper's eigenvector fit in metres).
    #[serde(default)]
    pub ground_fit: crate::calib::plane::GroundFitMethod,
    /// The noise of one pose's ground, for `plan`'s predictions (default:
    /// the solve's floors, a conservative real robot).
    #[serde(default)]
    pub noise: Option<crate::calib::plan::NoiseModel>,
    /// The Kinect's depth scale: `"estimate"` (the default: with the mount,
    /// when the poses' heights observe it, else 1) or a known value such as
    /// `1.0032` (from an earlier calibration).
    #[serde(default, deserialize_with = "depth_scale_setting")]
    pub depth_scale: DepthScaleSetting,
    /// Calibrate at each of these tilts of the Kinect's motor (two or more,
    /// degrees) and fit the motor's axis, so that the calibration holds at
    /// any tilt between them; empty (the default): at `sensor.tilt_deg` only.
    #[serde(default)]
    pub tilts: Vec<f64>,
}

pub use crate::calib::solve::DepthScaleSetting;

mod choices;
mod simulator;
pub use choices::*;
pub use simulator::*;

/// Tilts to calibrate at: none, or two or more different ones within the
/// Kinect's motor range (±27°).
pub fn check_tilts(tilts: &[f64]) -> Result<(), String> {
    if tilts.len() == 1 {
        return Err("one tilt is no model: give two or more, or none".into());
    }
    for (k, t) in tilts.iter().enumerate() {
        if !(t.is_finite() && (-27.0..=27.0).contains(t)) {
            return Err(format!("{t}° is outside the Kinect's motor range (±27°)"));
        }
        if tilts[..k].iter().any(|u| (u - t).abs() < 1.0) {
            return Err(format!(
                "{t}° is given twice (tilts must differ by 1° or more)"
            ));
        }
    }
    Ok(())
}

/// The tilts of `--tilts` (a type of its own: clap reads a `Vec` as repeated flags).
#[derive(Debug, Clone, PartialEq)]
pub struct Tilts(pub Vec<f64>);

/// `--tilts -20,-10,0`.
pub fn parse_tilts(text: &str) -> Result<Tilts, String> {
    let tilts = text
        .split(',')
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .map_err(|_| format!("\"{}\" is not a tilt in degrees", t.trim()))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    check_tilts(&tilts)?;
    Ok(Tilts(tilts))
}

/// `"estimate"` or a scale near 1 (`--depth-scale`, `calibration.depth_scale`).
pub fn parse_depth_scale(text: &str) -> Result<DepthScaleSetting, String> {
    let text = text.trim();
    if text == "estimate" {
        return Ok(DepthScaleSetting::Estimate { fallback: 1.0 });
    }
    match text.parse::<f64>() {
        Ok(s) if (0.5..=2.0).contains(&s) => Ok(DepthScaleSetting::Fixed(s)),
        Ok(s) => Err(format!(
            "a depth scale of {} is not a Kinect's (it lies near 1, e.g. 1.0032)",
            crate::formats::output::brief_number(s)
        )),
        Err(_) => Err(format!(
            "\"{text}\" is neither \"estimate\" nor a depth scale such as 1.0032"
        )),
    }
}

fn depth_scale_setting<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<DepthScaleSetting, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Raw {
        Word(String),
        Number(f64),
    }
    match Raw::deserialize(deserializer)? {
        Raw::Word(w) => parse_depth_scale(&w),
        Raw::Number(n) => parse_depth_scale(&n.to_string()),
    }
    .map_err(serde::de::Error::custom)
}

/// The daemon's HTTP terminal.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServeConfig {
    pub listen: String,
    /// A file holding the token required for everything that moves the robot.
    pub token_file: PathBuf,
    /// Where the active calibration, its history and recordings live.
    pub state_dir: PathBuf,
    /// Names the page may be opened by besides an address, `localhost` and
    /// the machine's own name (and `NAME.local`), e.g. `["octopus"]`.
    #[serde(default)]
    pub allowed_hosts: Vec<String>,
    /// How often the page's live picture is taken while no session runs,
    /// milliseconds; 0: never (the sensor is opened only by a session).
    #[serde(default = "default_preview_interval_ms")]
    pub preview_interval_ms: u64,
}

fn default_preview_interval_ms() -> u64 {
    1000
}

impl Config {
    /// Parses a configuration's text (no semantic checks).
    pub fn parse(path: &Path, text: &str) -> Result<Self, InputError> {
        parse_toml(path, text)
    }

    /// Reads and checks a configuration file, and the schedule it names.
    pub fn load(path: &Path) -> Result<(Self, Schedule), InputError> {
        let bytes = read_bounded(path, 1 << 20)?;
        let text = std::str::from_utf8(&bytes)
            .map_err(|e| InputError::new(path, None, format!("not UTF-8: {e}")))?;
        let config = Self::parse(path, text)?;
        let schedule = config.validate(path)?;
        Ok((config, schedule))
    }

    /// The shipped simulation configuration (`config/sim.toml`) and its
    /// schedule, built into the binary so that `groundcal calibrate --robot sim
    /// --sensor sim` runs anywhere.
    #[allow(
        clippy::expect_used,
        reason = "files built into the binary, parsed by the unit tests: not input"
    )]
    pub fn embedded_sim() -> (Self, Schedule) {
        const CONFIG: &str = include_str!("../../../config/sim.toml");
        const SCHEDULE: &str = include_str!("../../../config/schedules/octopus-52.toml");
        let config = Self::parse(Path::new("(built-in config/sim.toml)"), CONFIG)
            .expect("the shipped sim.toml parses (tested)");
        let schedule = Schedule::parse(Path::new("(built-in octopus-52.toml)"), SCHEDULE)
            .expect("the shipped schedule parses (tested)");
        (config, schedule)
    }

    /// The schedule's path, relative to the configuration file.
    pub fn schedule_path(&self, config_path: &Path) -> PathBuf {
        resolve_from_config(config_path, &self.calibration.schedule)
    }

    /// The semantic checks; returns the schedule, checked against the limits.
    pub fn validate(&self, path: &Path) -> Result<Schedule, InputError> {
        self.validate_settings(path)?;
        let schedule_path = self.schedule_path(path);
        let schedule = Schedule::read(&schedule_path)?;
        schedule
            .validate(&self.robot.limits)
            .map_err(|e| InputError::new(&schedule_path, None, e.to_string()))?;
        Ok(schedule)
    }

    /// The semantic checks of everything but the schedule (which `plan`
    /// judges itself).
    pub fn validate_settings(&self, path: &Path) -> Result<(), InputError> {
        let bad = |key: &str, m: String| InputError::new(path, None, format!("{key}: {m}"));
        let l = &self.robot.limits;
        if ![
            l.max_tilt_deg,
            l.min_height_mm,
            l.max_height_mm,
            l.max_shift_mm,
        ]
        .iter()
        .all(|v| v.is_finite())
            || l.max_tilt_deg <= 0.0
            || l.min_height_mm >= l.max_height_mm
            || l.max_shift_mm < 0.0
        {
            return Err(bad(
                "robot.limits",
                "must be finite, with min_height_mm < max_height_mm and positive tilt".into(),
            ));
        }
        if let Some(name) = &self.robot.name {
            let plain = !name.trim().is_empty()
                && name.chars().count() <= 64
                && !name.chars().any(char::is_control);
            if !plain {
                return Err(bad(
                    "robot.name",
                    "must be 1 to 64 printable characters, such as \"octopus\"".into(),
                ));
            }
        }
        if let Some(bag) = &self.bag {
            let named =
                |name: &String| !name.trim().is_empty() && !name.chars().any(char::is_control);
            for (key, value) in [
                ("bag.depth_topic", &bag.depth_topic),
                ("bag.camera_info_topic", &bag.camera_info_topic),
                ("bag.body_frame", &bag.body_frame),
            ] {
                if value.as_ref().is_some_and(|v| !named(v)) {
                    return Err(bad(key, "must be a topic or frame name, not empty".into()));
                }
            }
            if let Some(mm) = bag.baseline_mm {
                crate::calib::depth::check_baseline_mm(mm)
                    .map_err(|why| bad("bag.baseline_mm", why))?;
            }
            if let Some(feet) = &bag.foot_frames {
                if feet.len() < crate::calib::body::MIN_FEET || !feet.iter().all(named) {
                    return Err(bad(
                        "bag.foot_frames",
                        format!(
                            "{} frames: at least {} names of the feet's frames, foot 1 first",
                            feet.len(),
                            crate::calib::body::MIN_FEET
                        ),
                    ));
                }
            }
        }
        if let Some(serve) = &self.serve {
            let interval = serve.preview_interval_ms;
            if interval != 0 && !(200..=60_000).contains(&interval) {
                return Err(bad(
                    "serve.preview_interval_ms",
                    format!("{interval} must be 0 (no live picture) or 200 to 60000"),
                ));
            }
        }
        if self.robot.retry_interval_ms == 0 || self.robot.retries == 0 {
            return Err(bad(
                "robot",
                "retry_interval_ms and retries must be positive".into(),
            ));
        }
        if !(self.sensor.tilt_deg.is_finite() && (-31.0..=31.0).contains(&self.sensor.tilt_deg)) {
            return Err(bad(
                "sensor.tilt_deg",
                format!(
                    "{} is outside the Kinect motor's ±31°",
                    self.sensor.tilt_deg
                ),
            ));
        }
        if let Some(m) = &self.sensor.depth_model {
            m.validate().map_err(|e| bad("sensor.depth_model", e))?;
        }
        if let Some(i) = &self.sensor.intrinsics {
            i.validate().map_err(|e| bad("sensor.intrinsics", e))?;
        }
        let c = &self.calibration;
        if c.frames_per_pose == 0 || c.frames_per_pose > 30 {
            return Err(bad(
                "calibration.frames_per_pose",
                format!("{} is not in 1..=30", c.frames_per_pose),
            ));
        }
        if c.motion_ms == 0 || c.motion_ms > 60_000 {
            return Err(bad(
                "calibration.motion_ms",
                format!("{} is not in 1..=60000", c.motion_ms),
            ));
        }
        if c.settle_ms > 60_000 {
            return Err(bad(
                "calibration.settle_ms",
                format!("{} is more than a minute", c.settle_ms),
            ));
        }
        if !(c.slip_threshold_mm.is_finite() && c.slip_threshold_mm > 0.0) {
            return Err(bad(
                "calibration.slip_threshold_mm",
                "must be a positive number".into(),
            ));
        }
        if let Some(m) = &c.nominal_mount {
            m.validate().map_err(|e| bad("calibration", e))?;
        }
        c.gates.validate().map_err(|e| bad("calibration", e))?;
        self.verify
            .settings(c)
            .validate()
            .map_err(|e| bad("verify", e))?;
        let verify_tilt = self.verify.tilt_deg(&self.robot.limits);
        if !(verify_tilt.is_finite()
            && verify_tilt > 0.0
            && verify_tilt <= self.robot.limits.max_tilt_deg)
        {
            return Err(bad(
                "verify.tilt_deg",
                format!(
                    "must be a positive number of degrees within the robot's max_tilt_deg {}, not {}",
                    self.robot.limits.max_tilt_deg, verify_tilt
                ),
            ));
        }
        check_tilts(&c.tilts).map_err(|e| bad("calibration.tilts", e))?;
        if let Some(noise) = &c.noise {
            noise.validate().map_err(|e| bad("calibration.noise", e))?;
        }
        if let Some(sim) = &self.sim {
            if !(sim.time_scale.is_finite() && sim.time_scale > 0.0 && sim.time_scale <= 1000.0) {
                return Err(bad(
                    "sim.time_scale",
                    format!("{} is not in (0, 1000]", sim.time_scale),
                ));
            }
            if !sim.mount.is_finite() {
                return Err(bad(
                    "sim.mount",
                    "has a value that is not a finite number".into(),
                ));
            }
            if let Some(d) = &sim.depth_distortion {
                let needs_amplitude = !matches!(
                    d.shape,
                    SimDistortionShape::None | SimDistortionShape::Measured
                );
                if needs_amplitude && d.amplitude_raw.is_none() {
                    return Err(bad(
                        "sim.depth_distortion.amplitude_raw",
                        "is needed for this shape (raw units, e.g. 0.5)".into(),
                    ));
                }
                if d.plane_part.is_some() && d.shape != SimDistortionShape::Measured {
                    return Err(bad(
                        "sim.depth_distortion.plane_part",
                        "applies to shape = \"measured\" only".into(),
                    ));
                }
            }
            if let Some(sinking) = &sim.sinking_foot {
                if !(1..=6).contains(&sinking.foot) {
                    return Err(bad(
                        "sim.sinking_foot.foot",
                        format!("{} is not a foot (1–6)", sinking.foot),
                    ));
                }
                if !(sinking.depth_mm.is_finite() && sinking.depth_mm.abs() <= 200.0) {
                    return Err(bad(
                        "sim.sinking_foot.depth_mm",
                        format!("{} is not within ±200 mm", sinking.depth_mm),
                    ));
                }
            }
        } else if self.robot.address == RobotAddress::Sim || self.sensor.source == SensorSource::Sim
        {
            return Err(bad(
                "sim",
                "the simulated robot or sensor needs a [sim] table".into(),
            ));
        }
        if let Some(serve) = &self.serve {
            serve
                .listen
                .parse::<std::net::SocketAddr>()
                .map_err(|e| bad("serve.listen", format!("\"{}\": {e}", serve.listen)))?;
        }
        Ok(())
    }
}

/// A path named in the configuration: relative paths are relative to the
/// configuration file's directory, not to wherever the service was started.
pub fn resolve_from_config(config_path: &Path, path: &Path) -> PathBuf {
    match config_path.parent() {
        Some(dir) if path.is_relative() => dir.join(path),
        _ => path.to_path_buf(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("config")
            .join(name)
    }

    #[test]
    fn every_shipped_configuration_is_valid() {
        for name in ["groundcal.toml", "sim.toml", "quadruped.toml"] {
            let (config, schedule) = Config::load(&shipped(name)).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(schedule.poses.len(), 52, "{name}");
            assert!(config.calibration.frames_per_pose >= 1);
        }
    }

    #[test]
    fn a_robots_bag_names_three_feet_or_more() {
        let path = shipped("quadruped.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let (config, _) = Config::load(&path).unwrap();
        let bag = config.bag.unwrap();
        assert_eq!(bag.foot_frames.unwrap().len(), 4);
        assert_eq!(
            bag.depth_topic.as_deref(),
            Some("/camera/depth/image_rect_raw")
        );
        let two = Config::parse(
            &path,
            &text.replace(
                r#"foot_frames = ["lf_foot", "rf_foot", "lh_foot", "rh_foot"]"#,
                r#"foot_frames = ["lf_foot", "rf_foot"]"#,
            ),
        )
        .unwrap();
        let err = two.validate_settings(&path).unwrap_err().to_string();
        assert!(
            err.contains("bag.foot_frames: 2 frames: at least 3"),
            "{err}"
        );
        assert_eq!(bag.baseline_mm, Some(50.0));
        let no_baseline = Config::parse(
            &path,
            &text.replace("baseline_mm = 50.0", "baseline_mm = 0.0"),
        )
        .unwrap();
        let err = no_baseline
            .validate_settings(&path)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(
                "bag.baseline_mm: 0 is not a depth camera's stereo baseline (1 to 1000 mm)"
            ),
            "{err}"
        );
        let typo = Config::parse(&path, &text.replace("body_frame =", "body_fram =")).unwrap_err();
        assert!(typo.to_string().contains("body_fram"), "{typo}");
    }

    #[test]
    fn the_built_in_simulation_configuration_is_the_shipped_one() {
        let (embedded, schedule) = Config::embedded_sim();
        let (shipped, shipped_schedule) = Config::load(&shipped("sim.toml")).unwrap();
        assert_eq!(embedded, shipped);
        // The same poses; only the file named in messages differs.
        assert_eq!(
            Schedule {
                file: None,
                ..schedule
            },
            Schedule {
                file: None,
                ..shipped_schedule
            }
        );
    }

    #[test]
    fn typos_and_bad_values_are_named() {
        let text = std::fs::read_to_string(shipped("sim.toml")).unwrap();
        let path = shipped("sim.toml");
        let err = Config::parse(
            &path,
            &text.replace("frames_per_pose", "frames_per_posture"),
        )
        .unwrap_err();
        assert!(err.to_string().contains("frames_per_posture"), "{err}");
        assert!(err.line.is_some());
        let config =
            Config::parse(&path, &text.replace("tilt_deg = -20.0", "tilt_deg = 45.0")).unwrap();
        let err = config.validate(&path).unwrap_err();
        assert!(err.to_string().contains("sensor.tilt_deg"), "{err}");
        let err = Config::parse(&path, &text.replace("world = \"flat\"", "world = \"moon\""))
            .unwrap_err();
        assert!(err.to_string().contains("sim.world"), "{err}");
    }

    /// `[sim] depth_noise` by name or as a table of the measured model's
    /// parts, and what is wrong in either named.
    #[test]
    fn the_simulated_noise_by_name_or_by_parts() {
        use groundcal_hal::sim::noise::{KinectNoise, NoiseHeld};
        let text = std::fs::read_to_string(shipped("sim.toml")).unwrap();
        let path = shipped("sim.toml");
        let with = |noise: &str| {
            Config::parse(
                &path,
                &text.replace("depth_noise = \"white\"", &format!("depth_noise = {noise}")),
            )
        };
        assert_eq!(
            with("\"kinect\"").unwrap().sim.unwrap().depth_noise,
            SimNoise::Kinect
        );
        let parts = with("{ white_raw = 0.38, medium_raw = 0.25, long_raw = 0, held = \"frame\" }")
            .unwrap()
            .sim
            .unwrap()
            .depth_noise;
        assert_eq!(
            parts,
            SimNoise::Parts(KinectNoise {
                white_raw: 0.38,
                medium_raw: 0.25,
                long_raw: 0.0,
                held: NoiseHeld::PerFrame,
                ..KinectNoise::default()
            })
        );
        for (noise, words) in [
            ("\"pink\"", "\"pink\" is not a noise"),
            ("{ white = 0.3 }", "unknown field `white`"),
            ("{ held = \"ever\" }", "held = \"ever\""),
            ("{ long_raw = -1.0 }", "long_raw must lie in [0, 10]"),
            ("3", "a TOML integer is not a noise"),
        ] {
            let err = with(noise).unwrap_err().to_string();
            assert!(
                err.contains("sim.depth_noise") && err.contains(words),
                "{noise}: {err}"
            );
        }
    }

    /// A robot that tilts less than the check's default 8° still has a valid
    /// configuration without a [verify] table (found by the config_toml
    /// fuzz target); a tilt given beyond the robot's limit is named.
    #[test]
    fn the_checks_tilt_follows_the_robots_limit() {
        let text = std::fs::read_to_string(shipped("groundcal.toml")).unwrap();
        let path = shipped("groundcal.toml");
        let start = text.find("[verify]").unwrap();
        let end = start + text[start..].find("[serve]").unwrap();
        let without = format!("{}{}", &text[..start], &text[end..])
            .replace("max_tilt_deg = 25.0", "max_tilt_deg = 2.0");
        let config = Config::parse(&path, &without).unwrap();
        config.validate_settings(&path).unwrap();
        assert_eq!(config.verify.tilt_deg(&config.robot.limits), 2.0);
        let given = without.replace("[serve]", "[verify]\ntilt_deg = 5.0\n\n[serve]");
        let config = Config::parse(&path, &given).unwrap();
        let err = config.validate_settings(&path).unwrap_err();
        assert!(err.to_string().contains("verify.tilt_deg"), "{err}");
    }
}
