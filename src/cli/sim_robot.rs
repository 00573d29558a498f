//! `groundcal sim-robot --listen ADDR [--seed N] [--time-scale X] [--replay
//! DIR]`: the simulated lower computer (`shared/spec/hexapod-udp.md`) as its
//! own process, for tests and demos of the UDP link. With `--replay DIR` it
//! plays a recording's robot back instead of simulating one: it accepts only
//! the recorded poses, exactly as commanded, and reports the recorded feet
//! (`groundcal_hal::sim::recorded_robot`).
//!
//! It prints one line `listening on IP:PORT` on stdout once the socket is
//! bound (so that `--listen 127.0.0.1:0` can be used and found), serves until
//! SIGINT or SIGTERM, then prints its counters on stderr as one line
//! `sim-robot: stats {...}` and exits 0. Fault injection and the receipts log
//! come from the environment (`GROUNDCAL_SIM_FAULTS`,
//! `GROUNDCAL_SIM_RECEIPTS`; see `groundcal_hal::sim::lower_computer`): they are
//! for tests, not for operators.

use std::collections::BTreeMap;
use std::io::Write;

use std::path::{Path, PathBuf};

use groundcal_hal::sim::lower_computer::{self, FaultInjection, SimOptions, RECEIPTS_ENV};
use groundcal_hal::sim::recorded_robot::{RecordedScript, RecordedStance};

use crate::formats::recording::Recording;
use groundcal_hal::udp::link::resolve_ipv4_first;

use super::ExitStatus;

/// The arguments of `groundcal sim-robot`: where to listen, and how the robot behaves.
#[derive(Debug, clap::Args)]
pub struct SimRobotArgs {
    /// The address to listen on, e.g. 127.0.0.1:7400 (port 0: any free port; the
    /// bound address is printed on stdout as `listening on IP:PORT`).
    #[arg(long, value_name = "ADDR")]
    pub listen: String,
    /// Picks the robot's kinematic error and noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Motions take duration / X (50: fifty times faster than real time).
    #[arg(long, value_name = "X", default_value_t = 1.0)]
    pub time_scale: f64,
    /// Play this recording's robot back: accept only its poses, exactly as
    /// commanded, and report its feet.
    #[arg(long, value_name = "DIR")]
    pub replay: Option<PathBuf>,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: SimRobotArgs) -> ExitStatus {
    run(
        &args.listen,
        args.seed,
        args.time_scale,
        args.replay.as_deref(),
    )
}

/// Runs the simulated lower computer until a signal.
pub fn run(listen: &str, seed: u64, time_scale: f64, replay: Option<&Path>) -> ExitStatus {
    let usage = |message: String| {
        eprintln!("groundcal: sim-robot: {message}");
        ExitStatus::BadInput
    };
    let address = match resolve_ipv4_first(listen) {
        Ok(a) => a,
        Err(e) => return usage(format!("--listen \"{listen}\": {e}")),
    };
    if !(time_scale.is_finite() && time_scale > 0.0) {
        return usage(format!(
            "--time-scale {time_scale}: must be a positive number (50: motions 50× faster)"
        ));
    }
    let faults = match FaultInjection::from_env() {
        Ok(f) => f,
        Err(e) => return usage(e),
    };
    let replay = match replay.map(|dir| script_of(dir, time_scale)).transpose() {
        Ok(r) => r,
        Err(e) => return usage(format!("--replay: {e}")),
    };
    let options = SimOptions {
        faults,
        receipts: std::env::var_os(RECEIPTS_ENV).map(PathBuf::from),
        replay,
        ..SimOptions::new(seed, time_scale)
    };
    let served = lower_computer::run_until_signal(address, options, |bound| {
        let mut stdout = std::io::stdout().lock();
        // A test waits for this line; a closed stdout must not stop the server.
        let _ = writeln!(stdout, "listening on {bound}");
        let _ = stdout.flush();
    });
    match served {
        Ok(stats) => {
            match serde_json::to_string(&stats) {
                Ok(json) => eprintln!("sim-robot: stats {json}"),
                Err(e) => eprintln!("sim-robot: stats not encoded: {e}"),
            }
            ExitStatus::Success
        }
        Err(e) => {
            eprintln!("groundcal: sim-robot: {listen}: {e}");
            ExitStatus::RuntimeFailure
        }
    }
}

/// A recording's robot as a script for the recorded robot's lower computer.
fn script_of(dir: &Path, time_scale: f64) -> Result<RecordedScript, String> {
    let recording = Recording::open(dir).map_err(|e| e.to_string())?;
    let feet = |feet: &[[f64; 3]], what: &str| -> Result<[[f64; 3]; 6], String> {
        <[[f64; 3]; 6]>::try_from(feet)
            .map_err(|_| format!("{}: {what} has {} feet, not 6", dir.display(), feet.len()))
    };
    let home = RecordedStance {
        commanded: recording.session.home.commanded,
        feet_body_mm: feet(&recording.session.home.feet_body_mm, "the home stance")?,
    };
    let mut poses = BTreeMap::new();
    for pose in &recording.poses {
        let id = u16::try_from(pose.index).map_err(|_| {
            format!(
                "{}: pose {} has an index beyond what the link carries (65535)",
                dir.display(),
                pose.index
            )
        })?;
        let stance = RecordedStance {
            commanded: pose.commanded,
            feet_body_mm: feet(&pose.feet_body_mm, &format!("pose {id}"))?,
        };
        poses.insert(id, stance);
    }
    Ok(RecordedScript {
        home,
        poses,
        time_scale,
        firmware: format!("groundcal-replay 1 ({})", dir.display()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_flags_are_usage_errors() {
        assert_eq!(run("nonsense", 1, 1.0, None), ExitStatus::BadInput);
        assert_eq!(run("127.0.0.1:0", 1, 0.0, None), ExitStatus::BadInput);
        assert_eq!(run("127.0.0.1:0", 1, f64::NAN, None), ExitStatus::BadInput);
        let nowhere = Path::new("/nonexistent/recording");
        assert_eq!(
            run("127.0.0.1:0", 1, 1.0, Some(nowhere)),
            ExitStatus::BadInput
        );
    }

    #[test]
    fn a_recording_becomes_a_script_of_its_poses() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/sample-12");
        let script = script_of(&dir, 50.0).unwrap();
        let recording = Recording::open(&dir).unwrap();
        assert_eq!(script.poses.len(), recording.poses.len());
        let first = &recording.poses[0];
        let stance = &script.poses[&(first.index as u16)];
        assert_eq!(stance.commanded, first.commanded);
        assert_eq!(stance.feet_body_mm.to_vec(), first.feet_body_mm);
    }

    #[test]
    fn listen_addresses_resolve() {
        assert_eq!(
            resolve_ipv4_first("127.0.0.1:7400").unwrap(),
            "127.0.0.1:7400".parse().unwrap()
        );
        assert!(resolve_ipv4_first("localhost:0").is_ok());
        assert!(resolve_ipv4_first("127.0.0.1").is_err());
    }
}
