//! `groundcal replay DIR`: solve a recording offline.

use std::path::Path;

use super::{finish, ExitStatus};
use crate::formats::recording::Recording;
use crate::formats::report::{write_report, Provenance};
use crate::solving::replay::{replay, ReplayOptions};

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
