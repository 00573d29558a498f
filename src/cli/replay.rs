//! `groundcal replay DIR`: solve a recording offline.

use std::path::Path;

use super::args::BagArgs;
use super::{finish, ExitStatus};
use crate::calib::plane::GroundFitMethod;
use crate::formats::recording::Recording;
use crate::formats::report::{write_report, Provenance};
use crate::solving::replay::{replay, ReplayOptions};
use std::path::PathBuf;

/// What a replay writes besides its result.
#[derive(Debug, Clone, Copy, Default)]
pub struct Outputs<'a> {
    /// One JSON document on stdout.
    pub json: bool,
    /// The HTML report's directory.
    pub report: Option<&'a Path>,
    /// The session as an MCAP file.
    pub mcap: Option<&'a Path>,
    /// Takes a recording whose last record is cut off, without that pose.
    pub cut_off: bool,
    /// The input as it was named, when the recording was read out of it
    /// (groundcal's own session MCAP): the report's provenance says it.
    pub read_from: Option<&'a Path>,
}

/// The arguments of `groundcal replay`: a recording or a bag, and what to write.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The recording's directory, or a ROS 2 bag's .mcap file.
    pub dir: PathBuf,
    #[command(flatten)]
    pub bag: BagArgs,
    /// One JSON document on stdout.
    #[arg(long)]
    pub json: bool,
    /// The rough robot_from_sensor (degrees, millimetres) that tells which
    /// plane is the ground; overrides the recording's.
    #[arg(long, value_name = "a,b,g,x,y,z", allow_hyphen_values = true)]
    pub nominal_mount: Option<String>,
    /// Write a self-contained HTML report (index.html) into this directory.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Write the session as an MCAP file (ROS 2 messages) for Foxglove and
    /// ros2 bag: the frames, the body and feet, the mount, the ground found.
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Worker threads (default: every core). The result does not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// The ground fit: disparity (least squares in inverse depth, unbiased)
    /// or paper (the paper's eigenvector fit in metres, to compare).
    #[arg(long, value_name = "disparity|paper", default_value = "disparity")]
    pub ground_fit: GroundFitMethod,
    /// Judge by this configuration's quality gates (default: those the
    /// recording stores from its live run, else the built-in ones).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The Kinect's depth scale: estimate (the default, or --config's
    /// calibration.depth_scale) or a known value such as 1.0032.
    #[arg(long, value_name = "estimate|VALUE", value_parser = crate::setup::config::parse_depth_scale)]
    pub depth_scale: Option<crate::setup::config::DepthScaleSetting>,
    /// Replay a recording whose poses.jsonl ends part-way through a
    /// record (a power cut while recording) without that pose; the result
    /// says so. Without it such a recording is refused, naming the cut.
    #[arg(long)]
    pub cut_off: bool,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: ReplayArgs) -> ExitStatus {
    let (gates, noise, verify, configured_scale, configured_bag) = match args
        .config
        .as_deref()
        .map(crate::setup::config::Config::load)
    {
        None => (None, None, Default::default(), Default::default(), None),
        Some(Ok((config, _))) => (
            Some(config.calibration.gates),
            Some(
                config
                    .calibration
                    .noise
                    .unwrap_or_else(crate::calib::plan::NoiseModel::solve_floors),
            ),
            config.verify.settings(&config.calibration),
            config.calibration.depth_scale,
            config.bag,
        ),
        Some(Err(e)) => return super::usage_error(e.to_string()),
    };
    let nominal_mount = match args
        .nominal_mount
        .map(|m| super::parse_numbers::<6>("--nominal-mount", &m))
    {
        None => None,
        Some(Ok(values)) => Some(crate::calib::observe::NominalMount::from_values(values)),
        Some(Err(e)) => return super::usage_error(e),
    };
    let mut options = ReplayOptions {
        nominal_mount,
        threads: args.threads,
        gates,
        noise,
        verify,
        depth_scale: args.depth_scale.unwrap_or(configured_scale),
        keep: crate::solving::replay::AlsoKeep {
            ground_points: args.mcap.is_some(),
            input_digest: args.report.is_some(),
        },
        ..Default::default()
    };
    options.pose.plane.method = args.ground_fit;
    let outputs = Outputs {
        json: args.json,
        report: args.report.as_deref(),
        mcap: args.mcap.as_deref(),
        cut_off: args.cut_off,
        read_from: None,
    };
    let dir = args.dir;
    if crate::solving::bag::is_mcap_file(&dir) {
        // groundcal's own session carries its recording whole.
        match crate::solving::bag::own::own_recording(&dir) {
            Ok(Some(own)) => {
                let outputs = Outputs {
                    read_from: Some(&dir),
                    ..outputs
                };
                return run(own.dir(), &outputs, &options);
            }
            Ok(None) => {}
            Err(e) => {
                eprintln!("groundcal replay: {e}");
                return ExitStatus::BadInput;
            }
        }
        return match args.bag.options(configured_bag.as_ref()) {
            Ok(bag) => run_bag(&dir, &bag, &outputs, &options),
            Err(e) => super::usage_error(e),
        };
    }
    run(&dir, &outputs, &options)
}

/// Runs the command; the result goes to stdout, messages to stderr, and the
/// HTML report and the MCAP file where `outputs` say.
pub fn run(dir: &Path, outputs: &Outputs, options: &ReplayOptions) -> ExitStatus {
    let (json, report_dir) = (outputs.json, outputs.report);
    match crate::solving::tilts::read_tilts_file(dir) {
        Ok(Some(_)) if outputs.mcap.is_some() => {
            eprintln!("groundcal replay: {}: a recording at several tilts cannot be written as one MCAP file yet; replay each tilt's directory with --mcap", dir.display());
            return ExitStatus::BadInput;
        }
        Ok(Some(tilts)) => return replay_tilts(dir, &tilts, json, options),
        Ok(None) => {}
        Err(e) => {
            eprintln!("groundcal replay: {e}");
            return ExitStatus::BadInput;
        }
    }
    if let Some(path) = outputs.mcap {
        if let Err(e) = crate::solving::mcap_session::writable_place(path) {
            eprintln!("groundcal replay: --mcap: {e}");
            return ExitStatus::RuntimeFailure;
        }
    }
    let opened = if outputs.cut_off {
        Recording::open_cut_off(dir)
    } else {
        Recording::open(dir)
    };
    let recording = match opened {
        Ok(r) => r,
        Err(e) => {
            eprintln!("groundcal replay: {e}");
            return ExitStatus::BadInput;
        }
    };
    if let Some(cut) = recording.cut_off {
        eprintln!(
            "groundcal replay: {}:{}: {}; replayed without that pose (--cut-off)",
            dir.join("poses.jsonl").display(),
            cut.line,
            cut.describe()
        );
    }
    let outcome = match replay(&recording, options) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("groundcal replay: {e}");
            return ExitStatus::BadInput;
        }
    };
    tracing::info!(
        frames = outcome.frames,
        digest = outcome.input_digest.as_deref(),
        "replayed"
    );
    if let Err(status) = report(report_dir, outputs.read_from.unwrap_or(dir), &outcome) {
        return status;
    }
    if let Some(path) = outputs.mcap {
        match crate::solving::mcap_session::write_replay(path, &recording, &outcome) {
            Ok(summary) => eprintln!(
                "groundcal replay: MCAP written to {} ({} messages, {:.1} MB)",
                path.display(),
                summary.messages.values().sum::<u64>(),
                summary.bytes as f64 / 1e6
            ),
            Err(e) => {
                eprintln!("groundcal replay: {e}");
                return match e {
                    crate::solving::mcap_session::McapError::Input(_) => ExitStatus::BadInput,
                    _ => ExitStatus::RuntimeFailure,
                };
            }
        }
    }
    finish("replay", &outcome.result, json)
}

/// The HTML report into `report_dir`, when asked for, with where the input
/// came from; said on stderr.
fn report(
    report_dir: Option<&Path>,
    input: &Path,
    outcome: &crate::solving::replay::Replay,
) -> Result<(), ExitStatus> {
    let Some(report_dir) = report_dir else {
        return Ok(());
    };
    // The caller asks for the digest with the report; a replay without it
    // says so rather than show a digest of nothing.
    let digest = outcome
        .input_digest
        .clone()
        .unwrap_or_else(|| "not computed".into());
    let provenance = Provenance::now(&input.display().to_string(), digest);
    match write_report(report_dir, &outcome.result, &provenance) {
        Ok(path) => {
            eprintln!("groundcal replay: report written to {}", path.display());
            Ok(())
        }
        Err(e) => {
            // The error names the file and what failed on it.
            eprintln!("groundcal replay: cannot write the report: {e}");
            Err(ExitStatus::RuntimeFailure)
        }
    }
}

/// A ROS 2 bag: its still poses found and calibrated, as a recording's.
pub fn run_bag(
    path: &Path,
    bag_options: &crate::solving::bag::BagOptions,
    outputs: &Outputs,
    options: &ReplayOptions,
) -> ExitStatus {
    if outputs.mcap.is_some() {
        eprintln!("groundcal replay: {}: --mcap writes a groundcal recording's session; a bag is MCAP already", path.display());
        return ExitStatus::BadInput;
    }
    let outcome = match crate::solving::bag::read_bag(path, bag_options).and_then(|bag| {
        eprintln!(
            "groundcal replay: {}: {} depth images, {} still poses with frames",
            path.display(),
            bag.images_seen,
            bag.poses.len()
        );
        crate::solving::bag::replay_bag(&bag, options)
    }) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("groundcal replay: {e}");
            return ExitStatus::BadInput;
        }
    };
    if let Err(status) = report(outputs.report, path, &outcome) {
        return status;
    }
    finish("replay", &outcome.result, outputs.json)
}

/// A recording made at several tilts (`tilts.json`): each tilt's recording
/// replayed, then the motor's model, as `calibrate --tilts` made it.
fn replay_tilts(
    dir: &Path,
    tilts: &crate::solving::tilts::TiltsFile,
    json: bool,
    options: &ReplayOptions,
) -> ExitStatus {
    let mut results = Vec::new();
    for entry in &tilts.tilts {
        let sub = dir.join(&entry.dir);
        let outcome = match Recording::open(&sub).and_then(|r| replay(&r, options)) {
            Ok(o) => o,
            Err(e) => {
                eprintln!("groundcal replay: {e}");
                return ExitStatus::BadInput;
            }
        };
        results.push((entry.tilt_deg, outcome.result));
    }
    let reference = tilts.reference_tilt_deg.unwrap_or(tilts.tilts[0].tilt_deg);
    finish(
        "replay",
        &crate::solving::tilts::combine(results, reference),
        json,
    )
}
