//! `groundcal check-config FILE`: what `calibrate` and `serve` would refuse,
//! found before either runs: the configuration (strict TOML, then its
//! checks), the schedule it names and, when it serves, the token.

use std::path::Path;

use super::ExitStatus;
use crate::setup::config::Config;
use crate::terminal::read_token;
use std::path::PathBuf;

/// The arguments of `groundcal check-config`: the file.
#[derive(Debug, clap::Args)]
pub struct CheckConfigArgs {
    /// The configuration file.
    pub file: PathBuf,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: CheckConfigArgs) -> ExitStatus {
    run(&args.file)
}

/// Runs the command: one line on stdout when valid, the reason on stderr
/// (exit 2) when not.
pub fn run(file: &Path) -> ExitStatus {
    match check(file) {
        Ok(summary) => {
            println!("{summary}");
            ExitStatus::Success
        }
        Err(e) => {
            eprintln!("groundcal: {e}");
            ExitStatus::BadInput
        }
    }
}

fn check(file: &Path) -> Result<String, String> {
    let (config, schedule) = Config::load(file).map_err(|e| e.to_string())?;
    // `serve` refuses to start without a token it can read: so does this.
    if let Some(serve) = &config.serve {
        read_token(file, &serve.token_file)
            .map_err(|e| format!("{}: serve.token_file: {e}", file.display()))?;
    }
    Ok(format!(
        "{}: valid; robot {}, sensor {}, schedule \"{}\" with {} poses",
        file.display(),
        config.robot.address,
        config.sensor.source,
        schedule.name,
        schedule.poses.len()
    ))
}
