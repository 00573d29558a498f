//! `groundcal verify`: whether the sensor still sits where the active (or a
//! given) calibration says, from the ground and the accelerometer, live or
//! from a recording. Exit 0 consistent, 4 drift, 1 hardware, 2 bad input.

use std::path::PathBuf;

use super::args::HardwareArgs;
use super::calibrate::{show_progress, stop_signal};
use super::{print_json, print_stdout, ExitStatus};
use crate::formats::recording::Recording;
use crate::hardware::{self, Selection};
use crate::session::{self, Plan, SessionError};
use crate::solving::verify::{check_schedule, compare, ground_prior, load_calibration, VerifyJson};

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

/// Prints the document; the exit status its verdict calls for.
/// `verify` keeps ignoring SIGPIPE (it moves the robot), so a reader gone
/// is an error here, said if stderr is still there, never a panic.
fn finish(document: &VerifyJson, json: bool) -> ExitStatus {
    let printed = if json {
        print_json(document)
    } else {
        print_stdout(&document.to_table())
    };
    if let Err(e) = printed {
        use std::io::Write;
        let _ = writeln!(std::io::stderr(), "groundcal verify: {e}");
        return ExitStatus::RuntimeFailure;
    }
    if document.drifted() {
        ExitStatus::Drift
    } else {
        ExitStatus::Success
    }
}

/// The arguments of `groundcal verify`: the calibration to check, and on what.
#[derive(Debug, clap::Args)]
pub struct VerifyArgs {
    /// The configuration (default: built-in simulation with --robot sim, else /etc/groundcal/groundcal.toml).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The calibration to check: a result of calibrate/replay/solve --json, or an active.json (default: the store's active calibration, [serve] state_dir).
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    #[command(flatten)]
    pub hardware: HardwareArgs,
    /// Check a recording's poses offline instead of the robot now.
    #[arg(long, value_name = "DIR", conflicts_with = "poses")]
    pub recording: Option<PathBuf>,
    /// Tilted poses besides the still stance (default [verify] poses, 0 = stand still).
    #[arg(long, value_name = "N")]
    pub poses: Option<usize>,
    /// Keep what the check saw as a recording in this new directory.
    #[arg(long, value_name = "DIR", conflicts_with = "recording")]
    pub record: Option<PathBuf>,
    /// One JSON document on stdout (progress stays on stderr).
    #[arg(long)]
    pub json: bool,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: VerifyArgs) -> ExitStatus {
    run(&VerifyOptions {
        config: args.config,
        calibration: args.calibration,
        selection: args.hardware.into(),
        recording: args.recording,
        poses: args.poses,
        record: args.record,
        json: args.json,
    })
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
        let theirs = Some(recording.session.robot.as_str()).filter(|r| !r.is_empty());
        if let Err(e) = calibration.same_robot(theirs, &format!("the recording {}", dir.display()))
        {
            eprintln!("groundcal verify: {e}");
            return ExitStatus::BadInput;
        }
        let mut pose_settings = crate::calib::observe::ObserveSettings::default();
        pose_settings.plane.method = config.calibration.ground_fit;
        pose_settings.slip_threshold_m = config.calibration.slip_threshold_mm / 1000.0;
        // A check takes the calibration's depth pattern; it estimates none.
        pose_settings.ground_residuals = false;
        let observed = match crate::solving::replay::observe_recording(
            &recording,
            Some(ground_prior(&calibration.mount)),
            pose_settings,
            None,
            calibration.depth_correction.as_deref(),
            crate::solving::replay::AlsoKeep::default(),
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

    if let Err(e) = calibration.same_robot(
        config.robot.name.as_deref(),
        "the configuration's [robot] name",
    ) {
        eprintln!("groundcal verify: {e}");
        return ExitStatus::BadInput;
    }
    let tilted = options.poses.unwrap_or(config.verify.poses);
    let check = check_schedule(
        schedule.home,
        tilted,
        config.verify.tilt_deg(&config.robot.limits),
    );
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
        let plan = match Plan::for_check(&config, check, &calibration, options.record.clone()) {
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
