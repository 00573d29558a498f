//! The configuration, `config/groundcal.toml` and `config/sim.toml`
//! (`config::Config::parse`, then `validate`).
//!
//! `validate` reads the schedule the configuration names, relative to the
//! configuration's directory. The target validates as if the file were in the
//! repository's `config/` (so that `schedules/octopus-52.toml` is the shipped
//! schedule and a valid configuration can pass); a schedule path that is not
//! a plain relative path (absolute, `..`, `.`) is replaced by the shipped one,
//! so that the fuzzer never opens `/dev/stdin` or files outside `config/`.
#![no_main]

use std::path::{Component, Path, PathBuf};
use std::sync::OnceLock;

use groundcal::setup::config::{Config, RobotAddress, SensorSource, SimWorld};
use groundcal_fuzz::{check_input_error, path, text_of};
use libfuzzer_sys::fuzz_target;

/// The shipped schedule, relative to `config/`.
const SHIPPED_SCHEDULE: &str = "schedules/octopus-52.toml";

/// Where `validate` believes the configuration is (the file need not exist:
/// only its directory is used, and the path in messages).
fn config_path() -> &'static Path {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/fuzz-input"))
}

/// The keys `validate` names at the start of its messages (`key: reason`).
const KEYS: &[&str] = &[
    "robot.limits",
    "robot",
    "sensor.tilt_deg",
    "sensor.depth_model",
    "sensor.intrinsics",
    "calibration.frames_per_pose",
    "calibration.motion_ms",
    "calibration.settle_ms",
    "calibration.slip_threshold_mm",
    "calibration",
    "sim.time_scale",
    "sim.mount",
    "sim.sinking_foot.foot",
    "sim.sinking_foot.depth_mm",
    "sim",
    "serve.listen",
    "verify.tilt_deg",
    "verify",
    "calibration.tilts",
    "robot.name",
    "calibration.noise",
    "serve.preview_interval_ms",
    "sim.depth_distortion.amplitude_raw",
    "sim.depth_distortion.plane_part",
    "bag.depth_topic",
    "bag.camera_info_topic",
    "bag.body_frame",
    "bag.foot_frames",
];

fn plain_relative(path: &Path) -> bool {
    !path.as_os_str().is_empty() && path.components().all(|c| matches!(c, Component::Normal(_)))
}

fuzz_target!(|data: &[u8]| {
    let text = text_of(data);
    let mut config = match Config::parse(path(), &text) {
        Err(e) => return check_input_error(&e, &text),
        Ok(config) => config,
    };

    // The values parsed from strings print back to the same string.
    let address = config.robot.address.to_string();
    assert_eq!(address.parse::<RobotAddress>().as_ref(), Ok(&config.robot.address));
    let source = config.sensor.source.to_string();
    assert_eq!(source.parse::<SensorSource>().as_ref(), Ok(&config.sensor.source));
    if let Some(sim) = &config.sim {
        let world = sim.world.to_string();
        assert_eq!(world.parse::<SimWorld>(), Ok(sim.world), "world {world:?}");
    }

    if !plain_relative(&config.calibration.schedule) {
        config.calibration.schedule = PathBuf::from(SHIPPED_SCHEDULE);
    }
    let config_path = config_path();
    let schedule_path = config.schedule_path(config_path);
    match config.validate(config_path) {
        Err(e) if e.path == config_path => {
            // A semantic check: it names the key, and there is no line.
            assert_eq!(e.line, None, "{e}");
            assert!(
                KEYS.iter().any(|key| e
                    .message
                    .strip_prefix(key)
                    .is_some_and(|rest| rest.starts_with(": ") && rest.len() > 2)),
                "error does not name the key: {e}"
            );
        }
        Err(e) => {
            // The schedule: unreadable, not a schedule, or out of the limits.
            assert_eq!(e.path, schedule_path, "error names another file: {e}");
            assert!(!e.message.is_empty(), "error without a message: {e:?}");
        }
        Ok(schedule) => {
            // What validate promises about a configuration it accepts.
            let l = &config.robot.limits;
            assert!(
                [l.max_tilt_deg, l.min_height_mm, l.max_height_mm, l.max_shift_mm]
                    .iter()
                    .all(|v| v.is_finite())
                    && l.max_tilt_deg > 0.0
                    && l.min_height_mm < l.max_height_mm
                    && l.max_shift_mm >= 0.0,
                "limits {l:?} accepted"
            );
            assert!(config.robot.retry_interval_ms > 0 && config.robot.retries > 0);
            assert!((-31.0..=31.0).contains(&config.sensor.tilt_deg));
            let c = &config.calibration;
            assert!((1..=30).contains(&c.frames_per_pose));
            assert!((1..=60_000).contains(&c.motion_ms));
            assert!(c.settle_ms <= 60_000);
            assert!(c.slip_threshold_mm.is_finite() && c.slip_threshold_mm > 0.0);
            match &config.sim {
                Some(sim) => {
                    assert!(sim.time_scale > 0.0 && sim.time_scale <= 1000.0);
                    assert!(sim.mount.is_finite());
                }
                None => assert!(
                    config.robot.address != RobotAddress::Sim
                        && config.sensor.source != SensorSource::Sim,
                    "a simulated robot or sensor without [sim] accepted"
                ),
            }
            if let Some(serve) = &config.serve {
                assert!(serve.listen.parse::<std::net::SocketAddr>().is_ok());
            }
            assert!(!schedule.poses.is_empty());
            assert!(schedule.validate(l).is_ok(), "schedule out of {l:?} accepted");
        }
    }
});
