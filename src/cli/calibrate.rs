//! `groundcal calibrate`: one calibration in the foreground, with the same
//! session logic as the daemon; progress on stderr (a bar on a terminal,
//! plain lines otherwise), the result on stdout.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use super::args::HardwareArgs;
use super::{finish, ExitStatus};
use crate::calib::plane::GroundFitMethod;
use crate::hardware::{self, Selection};
use crate::session::{self, Event, Plan, SessionError};
use crate::setup::config::{Config, RobotAddress, SensorSource};
use crate::setup::schedule::Schedule;

/// The command's options.
#[derive(Debug, Clone, Default)]
pub struct CalibrateOptions {
    pub config: Option<PathBuf>,
    pub selection: Selection,
    pub record: Option<PathBuf>,
    /// Also write the session as an MCAP file, once solved.
    pub record_mcap: Option<PathBuf>,
    pub json: bool,
    /// Overrides `calibration.ground_fit`.
    pub ground_fit: Option<GroundFitMethod>,
    /// Overrides `calibration.depth_scale`.
    pub depth_scale: Option<crate::setup::config::DepthScaleSetting>,
    /// Overrides `calibration.tilts`: the motor's tilts to calibrate at.
    pub tilts: Option<Vec<f64>>,
}

/// Where the configuration comes from: the file given; the built-in
/// simulation configuration when both robot and sensor are simulated;
/// otherwise the robot's `/etc/groundcal/groundcal.toml`.
pub fn load_config(options: &CalibrateOptions) -> Result<(Config, Schedule), String> {
    if let Some(path) = &options.config {
        return Config::load(path).map_err(|e| e.to_string());
    }
    let s = &options.selection;
    if s.robot == Some(RobotAddress::Sim)
        && s.sensor
            .as_ref()
            .is_none_or(|v| matches!(v, SensorSource::Sim | SensorSource::Playback(_)))
    {
        return Ok(Config::embedded_sim());
    }
    Config::load(Path::new("/etc/groundcal/groundcal.toml"))
        .map_err(|e| format!("{e} (give --config FILE)"))
}

/// Prints progress as it happens. Returns how an abort left the robot (the
/// `Aborted` event's words), which the command says last.
pub(super) fn show_progress(
    mut events: tokio::sync::mpsc::UnboundedReceiver<Event>,
    command: &'static str,
) -> tokio::task::JoinHandle<Option<String>> {
    tokio::spawn(async move {
        let terminal = std::io::stderr().is_terminal();
        let bar = terminal.then(|| {
            let bar = indicatif::ProgressBar::new(0);
            bar.set_style(
                // One line that fits the terminal: the bar, the step in
                // words ("pose 17/52: capturing", cut to the room left), the
                // time so far and left.
                indicatif::ProgressStyle::with_template(
                    "{spinner} [{bar:20}] {wide_msg} {elapsed:>4} ~{eta} left",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            bar
        });
        let mut aborted = None;
        while let Some(event) = events.recv().await {
            let line = match &event {
                // A picture for the page; the terminal says the fit's outcome.
                Event::GroundSeen { .. } => continue,
                Event::Started { poses, schedule } => {
                    if let Some(bar) = &bar {
                        bar.set_length(*poses as u64);
                    }
                    format!("schedule \"{schedule}\": {poses} poses, checked against the limits")
                }
                Event::Connected { firmware } => format!("lower computer: {firmware}"),
                Event::AtHome => "at the home stance; ground frame fixed".into(),
                Event::SensorReady { tilt_deg } => format!("Kinect tilted to {tilt_deg}°"),
                Event::Moving { index, of, .. } => format!("pose {index}/{of}: moving"),
                Event::Capturing { index, of } => format!("pose {index}/{of}: capturing"),
                Event::PoseDone { index, of, outcome } => {
                    if let Some(bar) = &bar {
                        bar.set_position(u64::from(*index));
                    }
                    match outcome {
                        Ok(fit) => {
                            format!("pose {index}/{of}: ground fitted ({} points)", fit.inliers)
                        }
                        Err(e) => format!("pose {index}/{of}: {e}"),
                    }
                }
                Event::Provisional { poses } => {
                    let used = poses.iter().filter(|p| p.used);
                    let (theta, e_d) = used.fold((0.0f64, 0.0f64), |(t, e), p| {
                        (t.max(p.theta_deg), e.max(p.e_d_mm))
                    });
                    format!(
                        "{} poses so far: θ ≤ {theta:.3}°, e_d ≤ {e_d:.2} mm",
                        poses.len()
                    )
                }
                Event::Solving => "back home; solving".into(),
                Event::Finished { accepted } => format!(
                    "finished: {}",
                    if *accepted {
                        "passed its checks"
                    } else {
                        "failed its checks"
                    }
                ),
                Event::Verified { consistent } => format!(
                    "back home; {}",
                    if *consistent { "consistent" } else { "drift" }
                ),
                // Said on lines of their own, above the bar: the bar redraws
                // at most a few times a second, and these must be seen.
                Event::Halting { .. } | Event::WalkingHome => {
                    let words = if matches!(event, Event::Halting { .. }) {
                        "halting the robot…"
                    } else {
                        "halted; walking home…"
                    };
                    match &bar {
                        Some(bar) => {
                            bar.suspend(|| eprintln!("groundcal {command}: {words}"));
                            bar.set_message(words);
                        }
                        None => eprintln!("groundcal {command}: {words}"),
                    }
                    continue;
                }
                Event::Aborted { reason, .. } => {
                    aborted = Some(reason.clone());
                    continue;
                }
            };
            match &bar {
                Some(bar) => bar.set_message(line),
                None => eprintln!("groundcal {command}: {line}"),
            }
        }
        // The bar gives way to the result; the last step stays on screen.
        // Cut short, the bar stays where the run stopped: a full bar would
        // claim that every pose was done.
        if let Some(bar) = bar {
            if aborted.is_some() {
                bar.abandon();
            } else {
                bar.finish();
            }
            eprintln!();
        }
        aborted
    })
}

/// Completes when the operator presses Ctrl-C or systemd sends SIGTERM.
pub(super) async fn stop_signal() -> String {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => tokio::select! {
                _ = tokio::signal::ctrl_c() => "interrupted (SIGINT)".to_string(),
                _ = term.recv() => "terminated (SIGTERM)".to_string(),
            },
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
                "interrupted (SIGINT)".to_string()
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
        "interrupted".to_string()
    }
}

/// The arguments of `groundcal calibrate`: the configuration, the hardware and what to keep.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// The configuration (default: built-in simulation with --robot sim, else /etc/groundcal/groundcal.toml).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub hardware: HardwareArgs,
    /// Write everything as a recording into this new directory, as it goes.
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
    /// Also write the session as an MCAP file (ROS 2 messages) for
    /// Foxglove and ros2 bag, once the calibration is solved.
    #[arg(long, value_name = "FILE")]
    pub record_mcap: Option<PathBuf>,
    /// One JSON document on stdout (progress stays on stderr).
    #[arg(long)]
    pub json: bool,
    /// The ground fit, overriding calibration.ground_fit: disparity or paper.
    #[arg(long, value_name = "disparity|paper")]
    pub ground_fit: Option<GroundFitMethod>,
    /// The Kinect's depth scale, overriding calibration.depth_scale: estimate
    /// (with the mount, when the body's heights observe it) or a known value such as 1.0032.
    #[arg(long, value_name = "estimate|VALUE", value_parser = crate::setup::config::parse_depth_scale)]
    pub depth_scale: Option<crate::setup::config::DepthScaleSetting>,
    /// Calibrate at each of these tilts of the Kinect's motor (degrees, two or
    /// more, e.g. -20,-10,0) and fit the motor's axis: the result then holds at
    /// any tilt between them (export --tilt). Overrides calibration.tilts.
    #[arg(long, value_name = "T1,T2,...", allow_hyphen_values = true, value_parser = crate::setup::config::parse_tilts)]
    pub tilts: Option<crate::setup::config::Tilts>,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: CalibrateArgs) -> ExitStatus {
    run(&CalibrateOptions {
        config: args.config,
        selection: args.hardware.into(),
        record: args.record,
        record_mcap: args.record_mcap,
        json: args.json,
        ground_fit: args.ground_fit,
        depth_scale: args.depth_scale,
        tilts: args.tilts.map(|t| t.0),
    })
}

/// Runs the command.
pub fn run(options: &CalibrateOptions) -> ExitStatus {
    let (mut config, schedule) = match load_config(options) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("groundcal calibrate: {e}");
            return ExitStatus::BadInput;
        }
    };
    if let Some(method) = options.ground_fit {
        config.calibration.ground_fit = method;
    }
    if let Some(scale) = options.depth_scale {
        config.calibration.depth_scale = scale;
    }
    // An MCAP file that could not be written at the end is refused before
    // the robot moves.
    if let Some(path) = &options.record_mcap {
        if let Err(e) = crate::solving::mcap_session::writable_place(path) {
            eprintln!("groundcal calibrate: --record-mcap: {e}");
            return ExitStatus::RuntimeFailure;
        }
    }
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("groundcal calibrate: cannot start the runtime: {e}");
            return ExitStatus::RuntimeFailure;
        }
    };
    let tilts = options
        .tilts
        .clone()
        .unwrap_or_else(|| config.calibration.tilts.clone());
    if tilts.len() == 1 {
        config.sensor.tilt_deg = tilts[0];
    }
    runtime.block_on(async {
        let (mut sensor, mut controller) = match hardware::open(&config, &options.selection).await {
            Ok(h) => h,
            Err(e) => {
                eprintln!("groundcal calibrate: {e}");
                return ExitStatus::RuntimeFailure;
            }
        };
        let replay = match &sensor {
            hardware::Sensor::Playback(r) => Some(r.recording().clone()),
            _ => None,
        };
        if tilts.len() < 2 {
            // The MCAP file is written from the session's recording: the
            // one asked for, or a temporary one beside the file.
            let recording = match (&options.record, &options.record_mcap) {
                (Some(dir), _) => Some(RecordingDir::Kept(dir.clone())),
                (None, Some(mcap)) => Some(RecordingDir::temporary_beside(mcap)),
                (None, None) => None,
            };
            let plan = match Plan::from_config(
                &config,
                schedule,
                replay.as_ref(),
                recording.as_ref().map(|r| r.path().to_path_buf()),
            ) {
                Ok(p) => p,
                Err(e) => {
                    eprintln!("groundcal calibrate: {e}");
                    return ExitStatus::BadInput;
                }
            };
            let temporary = matches!(recording, Some(RecordingDir::Temporary(_)));
            let result = match calibrate_once(&mut sensor, &mut controller, &plan, !temporary).await {
                Ok(result) => result,
                Err(status) => return status,
            };
            let written = match (&options.record_mcap, &recording) {
                (Some(mcap), Some(recording)) => {
                    write_mcap(mcap, recording.path(), &result, &config)
                }
                _ => Ok(()),
            };
            let status = finish("calibrate", &result, options.json);
            return match written {
                Ok(()) => status,
                Err(e) => {
                    eprintln!("groundcal calibrate: {e}");
                    ExitStatus::RuntimeFailure
                }
            };
        }
        // Once per tilt, the same schedule; then the motor's model.
        if options.record_mcap.is_some() {
            eprintln!("groundcal calibrate: --record-mcap: a calibration at several tilts cannot be written as one MCAP file yet; --record DIR, then replay each tilt's directory with --mcap");
            return ExitStatus::BadInput;
        }
        if replay.is_some() {
            eprintln!("groundcal calibrate: --tilts needs a live or simulated sensor, not a played-back one (replay a recording made at several tilts instead)");
            return ExitStatus::BadInput;
        }
        if let Some(dir) = &options.record {
            if let Err(e) = std::fs::create_dir_all(dir) {
                eprintln!("groundcal calibrate: {}: {e}", dir.display());
                return ExitStatus::RuntimeFailure;
            }
        }
        let mut results = Vec::new();
        for (k, tilt) in tilts.iter().enumerate() {
            let record = options
                .record
                .as_deref()
                .map(|dir| crate::solving::tilts::tilt_dir(dir, k + 1));
            let mut plan = match Plan::from_config(&config, schedule.clone(), None, record) {
                Ok(p) => p,
                Err(e) => {
                    eprintln!("groundcal calibrate: {e}");
                    return ExitStatus::BadInput;
                }
            };
            plan.tilt_deg = *tilt;
            plan.nominal_mount = plan
                .nominal_mount
                .map(|n| crate::solving::tilts::nominal_at(&n, config.sensor.tilt_deg, *tilt));
            eprintln!(
                "groundcal calibrate: tilt {} of {}: the Kinect at {tilt}°",
                k + 1,
                tilts.len()
            );
            match calibrate_once(&mut sensor, &mut controller, &plan, true).await {
                Ok(result) => results.push((*tilt, result)),
                Err(status) => return status,
            }
        }
        if let Some(dir) = &options.record {
            if let Err(e) = crate::solving::tilts::write_tilts_file(dir, &tilts, config.sensor.tilt_deg) {
                eprintln!("groundcal calibrate: {}: {e}", dir.display());
                return ExitStatus::RuntimeFailure;
            }
        }
        let combined = crate::solving::tilts::combine(results, config.sensor.tilt_deg);
        finish("calibrate", &combined, options.json)
    })
}

/// Where a calibration is recorded: the directory asked for, or a temporary
/// one (for `--record-mcap` alone) removed when dropped.
enum RecordingDir {
    Kept(PathBuf),
    Temporary(PathBuf),
}

impl RecordingDir {
    /// A new directory's name beside `file`, on its file system.
    fn temporary_beside(file: &Path) -> Self {
        let name = file
            .file_name()
            .map_or_else(|| "session".into(), |n| n.to_string_lossy().into_owned());
        let dir = file.with_file_name(format!(".{name}.recording-{}", std::process::id()));
        RecordingDir::Temporary(dir)
    }

    fn path(&self) -> &Path {
        match self {
            RecordingDir::Kept(dir) | RecordingDir::Temporary(dir) => dir,
        }
    }
}

impl Drop for RecordingDir {
    fn drop(&mut self) {
        if let RecordingDir::Temporary(dir) = self {
            // Best effort: it may never have been created.
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

/// The calibrated session as an MCAP file: the recording's frames and body
/// poses, the live result, and the ground each pose's fit took (fitted again
/// from the recording with the live run's settings).
fn write_mcap(
    path: &Path,
    recording_dir: &Path,
    result: &crate::formats::output::ResultJson,
    config: &Config,
) -> Result<(), String> {
    let recording =
        crate::formats::recording::Recording::open(recording_dir).map_err(|e| e.to_string())?;
    let mut options = crate::solving::replay::ReplayOptions {
        depth_scale: config.calibration.depth_scale,
        keep: crate::solving::replay::AlsoKeep {
            ground_points: true,
            input_digest: false,
        },
        ..Default::default()
    };
    options.pose.plane.method = config.calibration.ground_fit;
    let mut replayed =
        crate::solving::replay::replay(&recording, &options).map_err(|e| e.to_string())?;
    replayed.result = result.clone();
    let summary = crate::solving::mcap_session::write_replay(path, &recording, &replayed)
        .map_err(|e| e.to_string())?;
    eprintln!(
        "groundcal calibrate: MCAP written to {} ({} messages, {:.1} MB)",
        path.display(),
        summary.messages.values().sum::<u64>(),
        summary.bytes as f64 / 1e6
    );
    Ok(())
}

/// One calibration session with its progress; the result, or the exit
/// status of why there is none (said on stderr). `announce_recording` says
/// where the recording went (not for a temporary one).
async fn calibrate_once(
    sensor: &mut hardware::Sensor,
    controller: &mut hardware::Controller,
    plan: &Plan,
    announce_recording: bool,
) -> Result<crate::formats::output::ResultJson, ExitStatus> {
    let (events, receiver) = tokio::sync::mpsc::unbounded_channel();
    let progress = show_progress(receiver, "calibrate");
    let outcome = session::run(sensor, controller, plan, &events, stop_signal()).await;
    drop(events);
    let aborted = progress.await.ok().flatten();
    match outcome {
        Ok(outcome) => {
            if let Some(dir) = outcome.recording.as_ref().filter(|_| announce_recording) {
                eprintln!(
                    "groundcal calibrate: recording written to {}",
                    dir.display()
                );
            }
            Ok(outcome.result)
        }
        Err(SessionError::Refused(reason)) => {
            eprintln!("groundcal calibrate: refused before moving: {reason}");
            Err(ExitStatus::BadInput)
        }
        // Said last, with where the robot was left: "aborted:
        // interrupted (SIGINT); halted and sent home; it stands at …"
        // (the event's words are the error's cause and the robot's state).
        Err(e) => {
            match aborted {
                Some(reason) => {
                    let prefix = if matches!(e, SessionError::Aborted(_)) {
                        "aborted: "
                    } else {
                        ""
                    };
                    eprint!(
                        "{}",
                        super::for_terminal(
                            &format!("groundcal calibrate: {prefix}{reason}\n"),
                            true
                        )
                    );
                }
                None => eprintln!("groundcal calibrate: {e}"),
            }
            Err(ExitStatus::RuntimeFailure)
        }
    }
}
