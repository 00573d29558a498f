//! The `groundcal` command: parses arguments, sets up logging, and calls into
//! the library (`groundcal::cli`). See `shared/spec/cli.md` for the contract.

// No unwrap or expect outside tests: external input and hardware fail with
// an error that says what was wrong (scripts/test runs clippy with this).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use groundcal::cli::{self, ExitStatus};

#[derive(Debug, Parser)]
#[command(
    name = "groundcal",
    version,
    about = "Calibrates where a depth camera sits on a legged robot, using the ground",
    after_help = "\
Exit statuses (every command):
  0  done; for a calibration, accepted by its quality gates
  1  failed at run time: hardware, link, disk
  2  bad input or usage; the message names the file, line, key or flag
  3  solved but rejected: unobservable, residuals or σ beyond the gates (the output says why)
  4  verify only: the sensor no longer agrees with the calibration (drift; the output says which way)

Examples:
  groundcal calibrate --robot sim --sensor sim      a whole simulated calibration
  groundcal replay DIR --report out/                a recording, offline, with its HTML report
  groundcal serve --config /etc/groundcal/groundcal.toml
  groundcal verify --config /etc/groundcal/groundcal.toml   is the sensor still where it was calibrated?

`groundcal help COMMAND` shows each command's flags and an example."
)]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Solve robot_from_sensor from plane observations (groundcal-planes).
    #[command(after_help = "Example:\n  groundcal solve planes.json --json > result.json")]
    Solve(cli::solve::SolveArgs),
    /// Solve a recording (session.json, poses.jsonl, kinect/) offline, or a ROS 2 bag (MCAP).
    #[command(
        after_help = "A ROS 2 bag (an .mcap file) from another robot's stack: depth from sensor_msgs/Image (16UC1 mm or 32FC1 m), intrinsics from CameraInfo, the feet from /tf; still poses are found from the feet (docs/export.md).\n\nExamples:\n  groundcal replay ../shared/data/sample-12 --report /tmp/report --config /etc/groundcal/groundcal.toml\n  groundcal replay session.mcap --depth-topic /kinect/depth/image_raw --foot-frames lf_foot,lm_foot,lh_foot,rh_foot,rm_foot,rf_foot"
    )]
    Replay(cli::replay::ReplayArgs),
    /// The calibration in other tools' formats (URDF, ROS 2 static_transform_publisher, JSON).
    #[command(
        after_help = "Example:\n  groundcal export result.json --format urdf > sensor_mount.urdf"
    )]
    Export(cli::export::ExportArgs),
    /// One calibration in the foreground (the daemon's session logic).
    #[command(
        after_help = "Ctrl-C (or SIGTERM) aborts: the robot is halted and sent home, and the last line says where it stands.\n\nExamples:\n  groundcal calibrate --robot sim --sensor sim\n  groundcal calibrate --config /etc/groundcal/groundcal.toml --record /var/lib/groundcal/rec-1 --json"
    )]
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Whether the sensor still sits where the active (or a given) calibration says: the ground and the accelerometer now, or in a recording; exit 4 on drift.
    #[command(
        after_help = "The robot holds its home stance (with --poses N, also N small tilted poses, which see a turn about the vertical) while the Kinect captures the ground and gravity; both are compared with what the calibration predicts. Exit 0 consistent, 4 drift (the output says which way and by how much), 1 hardware, 2 bad input.\n\nExamples:\n  groundcal verify --config /etc/groundcal/groundcal.toml\n  groundcal verify --config config/sim.toml --calibration result.json --poses 4\n  groundcal verify --config config/sim.toml --calibration result.json --recording rec/ --json"
    )]
    Verify(cli::verify::VerifyArgs),
    /// The simulated lower computer (hexapod-udp.md) on a UDP socket, until SIGINT or SIGTERM.
    #[command(
        after_help = "Example:\n  groundcal sim-robot --listen 127.0.0.1:7400 --time-scale 50"
    )]
    SimRobot(cli::sim_robot::SimRobotArgs),
    /// The daemon for the phone/pad terminal: HTTP API and page, sd_notify.
    #[command(
        after_help = "SIGTERM or SIGINT aborts a running calibration (the robot is halted and sent home), then the service exits.\n\nExample:\n  groundcal serve --config /etc/groundcal/groundcal.toml --listen 0.0.0.0:8080"
    )]
    Serve(cli::serve::ServeArgs),
    /// Predict a schedule's σ, correlations and observability before the robot moves; exit 3 when it would be rejected.
    #[command(
        after_help = "Examples:\n  groundcal plan --config /etc/groundcal/groundcal.toml config/schedules/octopus-52.toml --json\n  groundcal plan --design 16 --config config/sim.toml --out config/schedules/designed-16.toml"
    )]
    Plan(cli::plan::PlanArgs),
    /// Validate a configuration (and the schedule it names); non-zero with the reason if invalid.
    #[command(after_help = "Example:\n  groundcal check-config /etc/groundcal/groundcal.toml")]
    CheckConfig(cli::check_config::CheckConfigArgs),
    /// Record N depth frames from the sensor as a recording whose kinect/ is a fakenect dump.
    #[command(
        after_help = "Example:\n  groundcal capture --sensor kinect --frames 30 --out /tmp/still"
    )]
    Capture(cli::capture::CaptureArgs),
    /// Fit the ground in one depth image.
    #[command(
        allow_negative_numbers = true,
        after_help = "Example:\n  groundcal plane frame.png --units mm --fx 525 --fy 525 --cx 319.5 --cy 239.5 --json"
    )]
    Plane(cli::plane::PlaneArgs),
}

fn run(args: Args) -> ExitStatus {
    match args.command {
        Command::Plan(args) => cli::plan::main(args),
        Command::Solve(args) => cli::solve::main(args),
        Command::Replay(args) => cli::replay::main(args),
        Command::Calibrate(args) => cli::calibrate::main(args),
        Command::Verify(args) => cli::verify::main(args),
        Command::SimRobot(args) => cli::sim_robot::main(args),
        Command::Serve(args) => cli::serve::main(args),
        Command::CheckConfig(args) => cli::check_config::main(args),
        Command::Export(args) => cli::export::main(args),
        Command::Capture(args) => cli::capture::main(args),
        Command::Plane(args) => cli::plane::main(args),
    }
}

/// Looks at standard output before Rust's runtime replaces a closed one
/// with `/dev/null` (`cli::note_whether_stdout_is_closed`): an ELF
/// constructor, run by the C library before `main`.
#[used]
#[link_section = ".init_array"]
static NOTE_WHETHER_STDOUT_IS_CLOSED: extern "C" fn() = {
    extern "C" fn note() {
        cli::note_whether_stdout_is_closed();
    }
    note
};

/// The log's filter from `GROUNDCAL_LOG`: a level (`info`) or targets and
/// levels (`groundcal=debug,tower_http=info`; the targets not named keep
/// their warnings and errors), warnings and errors when unset; a value not
/// understood says so, and the default stands. (Targets, not the
/// `env-filter` feature's spans and fields: that pulled regular expressions
/// into the binary, 0.49 MB of code, and compiled one at every start.)
fn log_filter(value: Option<String>) -> (tracing_subscriber::filter::Targets, Option<String>) {
    use tracing_subscriber::filter::{LevelFilter, Targets};
    let default = || Targets::new().with_default(LevelFilter::WARN);
    match value {
        None => (default(), None),
        Some(value) => match value.parse::<Targets>() {
            Ok(filter) if filter.default_level().is_some() => (filter, None),
            Ok(filter) => (filter.with_default(LevelFilter::WARN), None),
            Err(e) => (
                default(),
                Some(format!(
                    "GROUNDCAL_LOG={value:?} is not a log filter ({e}): expected a level \
                     (error, warn, info, debug, trace) or target=level pairs separated by \
                     commas; logging warnings and errors"
                )),
            ),
        },
    }
}

fn main() -> ExitCode {
    // Colours only on a terminal: the journal, a file or a pipe would keep
    // the escape codes as bytes.
    let on_a_terminal = std::io::IsTerminal::is_terminal(&std::io::stderr());
    use tracing_subscriber::prelude::*;
    let (filter, not_understood) = log_filter(std::env::var("GROUNDCAL_LOG").ok());
    tracing_subscriber::registry()
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(std::io::stderr)
                .with_ansi(on_a_terminal),
        )
        .with(filter)
        .init();
    if let Some(why) = not_understood {
        tracing::warn!("{why}");
    }
    let args = Args::parse();
    if matches!(
        args.command,
        Command::Plan(_)
            | Command::Solve(_)
            | Command::Replay(_)
            | Command::CheckConfig(_)
            | Command::Export(_)
            | Command::Plane(_)
    ) {
        cli::ends_quietly_on_a_closed_pipe();
    }
    ExitCode::from(run(args).code() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// `GROUNDCAL_LOG` takes a level or targets' levels; anything else is
    /// named in a warning and warnings and errors are logged.
    #[test]
    fn the_log_filter_is_read_or_named_as_not_understood() {
        use tracing_subscriber::filter::LevelFilter;
        let (unset, why) = log_filter(None);
        assert_eq!(
            (unset.default_level(), why),
            (Some(LevelFilter::WARN), None)
        );
        let (info, why) = log_filter(Some("info".into()));
        assert_eq!((info.default_level(), why), (Some(LevelFilter::INFO), None));
        let (targets, why) = log_filter(Some("groundcal=debug,tower_http=info".into()));
        assert!(why.is_none());
        assert!(targets.would_enable("groundcal::session", &tracing::Level::DEBUG));
        assert!(!targets.would_enable("tower_http", &tracing::Level::DEBUG));
        assert!(targets.would_enable("hyper", &tracing::Level::WARN));
        assert!(!targets.would_enable("hyper", &tracing::Level::INFO));
        for bad in ["groundcal=loud", "a=b=c"] {
            let (filter, why) = log_filter(Some(bad.into()));
            assert_eq!(filter.default_level(), Some(LevelFilter::WARN), "{bad}");
            let why = why.unwrap_or_default();
            assert!(why.contains("GROUNDCAL_LOG") && why.contains(bad), "{why}");
        }
    }

    /// `--help` documents every flag and argument of every command, gives
    /// each command an example, and the top level lists the exit statuses.
    #[test]
    fn help_documents_every_flag_with_an_example_per_command() {
        let top = Args::command();
        let statuses = top
            .get_after_help()
            .map(|h| h.to_string())
            .unwrap_or_default();
        for status in ["0 ", "1 ", "2 ", "3 "] {
            assert!(statuses.contains(&format!("\n  {status}")), "{statuses}");
        }
        let mut undocumented = Vec::new();
        for command in top.get_subcommands() {
            let name = command.get_name();
            let after = command
                .get_after_help()
                .map(|h| h.to_string())
                .unwrap_or_default();
            if command.get_about().is_none() {
                undocumented.push(format!("{name}: no about"));
            }
            if !after.contains("Example") {
                undocumented.push(format!("{name}: no example"));
            }
            if !after.contains(&format!("groundcal {name}")) {
                undocumented.push(format!("{name}: the example does not run it"));
            }
            for arg in command.get_arguments() {
                let id = arg.get_id().as_str();
                if id != "help" && arg.get_help().is_none() {
                    undocumented.push(format!("{name} {id}"));
                }
            }
        }
        assert!(undocumented.is_empty(), "undocumented: {undocumented:?}");
    }

    /// `docs/cli.md` is what the commands' definitions say
    /// (`GROUNDCAL_BLESS=1` writes it).
    #[test]
    fn cli_reference_is_the_codes() {
        let made = groundcal::cli::reference::markdown(&Args::command());
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/cli.md");
        if std::env::var_os("GROUNDCAL_BLESS").is_some() {
            std::fs::write(&path, &made).unwrap();
        }
        let file = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            file == made,
            "docs/cli.md differs from the commands' definitions: \
             GROUNDCAL_BLESS=1 cargo test --bin groundcal cli_reference writes it"
        );
    }
}
