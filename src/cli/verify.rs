//! `groundcal verify`: whether the sensor still sits where the active (or a
//! given) calibration says, from the ground and the accelerometer, live or
//! from a recording. Exit 0 consistent, 4 drift, 1 hardware, 2 bad input.

use std::path::{Path, PathBuf};

use super::calibrate::{show_progress, stop_signal};
use super::{print_json, ExitStatus};
use crate::calib::observe::NominalMount;
use crate::calib::verify::ActiveMount;
use crate::config::Config;
use crate::hardware::{self, Selection};
use crate::output::ResultJson;
use crate::recording::Recording;
use crate::session::{self, Plan, SessionError};
use crate::store::Store;
use crate::verify::{check_schedule, compare, mount_of, VerifyJson};

/// The command's options.
#[derive(Debug, Clone, Default)]
pub struct VerifyOptions {
    pub config: Option<PathBuf>,
    /// A result or active-calibration document; default the store's active one.
    pub calibration: Option<PathBuf>,
    pub selection: Selection,
    /// Verify a recording's poses instead of the robot now.
    pub recording: Option<PathBuf>,
    /// Tilted poses besides the still stance (default `[verify] poses`).
    pub poses: Option<usize>,
    /// Keep what the check saw as a recording.
    pub record: Option<PathBuf>,
    pub json: bool,
}

/// The calibration to check: its mount and σ, and the tilt it holds for.
pub struct Calibration {
    pub mount: ActiveMount,
    pub tilt_deg: Option<f64>,
    /// Where it came from, for messages.
    pub source: String,
}

/// Reads the calibration from a file, or the store's active one.
pub fn load_calibration(
    file: Option<&Path>,
    config: &Config,
    config_path: Option<&Path>,
) -> Result<Calibration, String> {
    let (document, source) = match file {
        Some(path) => {
            let bytes =
                crate::recording::read_bounded(path, 16 << 20).map_err(|e| e.to_string())?;
            let value: serde_json::Value = serde_json::from_slice(&bytes)
                .map_err(|e| format!("{}: not JSON: {e}", path.display()))?;
            (value, path.display().to_string())
        }
        None => {
            let serve = config.serve.as_ref().ok_or(
                "no --calibration FILE, and the configuration has no [serve] state_dir to find the active calibration in",
            )?;
            let dir = match config_path {
                Some(p) => crate::config::resolve_from_config(p, &serve.state_dir),
                None => serve.state_dir.clone(),
            };
            let store = Store::new(&dir);
            match store.active().map_err(|e| e.to_string())? {
                Some(v) => (v, store.active_path().display().to_string()),
                None => {
                    return Err(format!(
                        "no calibration is active in {} yet: calibrate and accept one, or give --calibration FILE",
                        dir.display()
                    ))
                }
            }
        }
    };
    let result = ResultJson::parse(document).map_err(|e| format!("{source}: {e}"))?;
    let mount = mount_of(&result).map_err(|e| format!("{source}: {e}"))?;
    Ok(Calibration {
        mount,
        tilt_deg: result.kinect_tilt_deg,
        source,
    })
}

/// The calibrated mount as the prior that tells the ground from other
/// planes: a knock is far less than 10°.
pub fn ground_prior(mount: &ActiveMount) -> NominalMount {
    let values = crate::calib::geometry::PoseDegMm::from_params(&mount.robot_from_sensor).values();
    NominalMount {
        tolerance_deg: 10.0,
        tolerance_mm: 150.0,
        ..NominalMount::from_values(values)
    }
}

/// Prints the document; the exit status its verdict calls for.
fn finish(document: &VerifyJson, json: bool) -> ExitStatus {
    if json {
        if let Err(e) = print_json(document) {
            eprintln!("groundcal verify: {e}");
            return ExitStatus::RuntimeFailure;
        }
    } else {
        print!("{}", document.to_table());
    }
    if document.drifted() {
        ExitStatus::Drift
    } else {
        ExitStatus::Success
    }
}

/// Runs the command.
pub fn run(options: &VerifyOptions) -> ExitStatus {
    let (config, schedule) =
        match super::calibrate::load_config(&super::calibrate::CalibrateOptions {
            config: options.config.clone(),
            selection: options.selection.clone(),
            ..Default::default()
        }) {
            Ok(c) => c,
            Err(e) => {
                eprintln!("groundcal verify: {e}");
                return ExitStatus::BadInput;
            }
        };
    let calibration = match load_calibration(
        options.calibration.as_deref(),
        &config,
        options.config.as_deref(),
    ) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("groundcal verify: {e}");
            return ExitStatus::BadInput;
        }
    };
    let settings = config.verify.settings(&config.calibration);
    eprintln!("groundcal verify: against {}", calibration.source);

    if let Some(dir) = &options.recording {
        let recording = match Recording::open(dir) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("groundcal verify: {e}");
                return ExitStatus::BadInput;
            }
        };
        let mut pose_settings = crate::calib::observe::ObserveSettings::default();
        pose_settings.plane.method = config.calibration.ground_fit;
        pose_settings.slip_threshold_m = config.calibration.slip_threshold_mm / 1000.0;
        let observed = match crate::replay::observe_recording(
            &recording,
            Some(ground_prior(&calibration.mount)),
            pose_settings,
            None,
        ) {
            Ok(o) => o,
            Err(e) => {
                eprintln!("groundcal verify: {e}");
                return ExitStatus::BadInput;
            }
        };
        return match compare(&calibration.mount, &observed.poses, &settings) {
            Ok(report) => finish(
                &VerifyJson::new(
                    &report,
                    &observed.poses,
                    &calibration.mount,
                    calibration.tilt_deg,
                ),
                options.json,
            ),
            Err(e) => {
                eprintln!("groundcal verify: {}: {e}", dir.display());
                ExitStatus::BadInput
            }
        };
    }

    let tilted = options.poses.unwrap_or(config.verify.poses);
    let check = check_schedule(schedule.home, tilted, config.verify.tilt_deg);
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("groundcal verify: cannot start the runtime: {e}");
            return ExitStatus::RuntimeFailure;
        }
    };
    runtime.block_on(async {
        let (mut sensor, mut controller) = match hardware::open(&config, &options.selection).await {
            Ok(h) => h,
            Err(e) => {
                eprintln!("groundcal verify: {e}");
                return ExitStatus::RuntimeFailure;
            }
        };
        let plan = match check_plan(&config, check, &calibration, options.record.clone()) {
            Ok(p) => p,
            Err(e) => {
                eprintln!("groundcal verify: {e}");
                return ExitStatus::BadInput;
            }
        };
        let (events, receiver) = tokio::sync::mpsc::unbounded_channel();
        let progress = show_progress(receiver, "verify");
        let outcome = session::verify(
            &mut sensor,
            &mut controller,
            &plan,
            &events,
            stop_signal(),
            &calibration.mount,
        )
        .await;
        drop(events);
        let aborted = progress.await.ok().flatten();
        match outcome {
            Ok(outcome) => {
                if let Some(dir) = &outcome.recording {
                    eprintln!("groundcal verify: recording written to {}", dir.display());
                }
                finish(
                    &VerifyJson::new(
                        &outcome.report,
                        &outcome.poses,
                        &calibration.mount,
                        calibration.tilt_deg,
                    ),
                    options.json,
                )
            }
            Err(SessionError::Refused(reason)) => {
                eprintln!("groundcal verify: refused before moving: {reason}");
                ExitStatus::BadInput
            }
            Err(e) => {
                match aborted {
                    Some(reason) => eprintln!("groundcal verify: {reason}"),
                    None => eprintln!("groundcal verify: {e}"),
                }
                ExitStatus::RuntimeFailure
            }
        }
    })
}

/// The session plan of a check: the check's schedule, the calibration's
/// tilt, the calibrated mount as the ground's prior, no provisional solves.
pub fn check_plan(
    config: &Config,
    schedule: crate::schedule::Schedule,
    calibration: &Calibration,
    record: Option<PathBuf>,
) -> Result<Plan, String> {
    let mut plan = Plan::from_config(config, schedule, None, record)?;
    plan.calibrating = false;
    plan.nominal_mount = Some(ground_prior(&calibration.mount));
    if let Some(tilt) = calibration.tilt_deg {
        plan.tilt_deg = tilt;
    }
    Ok(plan)
}
