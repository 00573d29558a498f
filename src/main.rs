//! The `groundcal` command: parses arguments, sets up logging, and calls into
//! the library (`groundcal::cli`). See `shared/spec/cli.md` for the contract.

// No unwrap or expect outside tests: external input and hardware fail with
// an error that says what was wrong (scripts/test runs clippy with this).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use groundcal::calib::calibrate::CalibrationSettings;
use groundcal::calib::plane::GroundFitMethod;
use groundcal::cli::{self, plane::PlaneOptions, ExitStatus};
use groundcal::formats::depth_image::DepthUnits;
use groundcal::setup::config::{RobotAddress, SensorSource};
use nalgebra::Vector3;

/// Which hardware a session runs on, overriding the configuration
/// (`calibrate` and `serve`).
#[derive(Debug, clap::Args)]
struct HardwareArgs {
    /// The lower computer: host:port, or sim (simulated, in process).
    #[arg(long)]
    robot: Option<RobotAddress>,
    /// The depth sensor: kinect, sim, or replay:DIR.
    #[arg(long)]
    sensor: Option<SensorSource>,
    /// The libfreenect library file (e.g. libfreenect's fakenect build).
    #[arg(long, value_name = "PATH")]
    freenect_lib: Option<PathBuf>,
}

impl From<HardwareArgs> for groundcal::hardware::Selection {
    fn from(a: HardwareArgs) -> Self {
        Self {
            robot: a.robot,
            sensor: a.sensor,
            freenect_lib: a.freenect_lib,
        }
    }
}

/// What to read from a ROS 2 bag (`replay BAG.mcap`).
#[derive(Debug, clap::Args)]
struct BagArgs {
    /// A bag's depth images (sensor_msgs/msg/Image, 16UC1 or 32FC1).
    #[arg(long, value_name = "TOPIC", default_value = "/camera/depth/image_raw")]
    depth_topic: String,
    /// A bag's intrinsics (sensor_msgs/msg/CameraInfo).
    #[arg(
        long,
        value_name = "TOPIC",
        default_value = "/camera/depth/camera_info"
    )]
    camera_info_topic: String,
    /// A bag's body frame in /tf (REP 103 axes).
    #[arg(long, value_name = "FRAME", default_value = "base_link")]
    body_frame: String,
    /// A bag's six foot frames in /tf, foot 1 first (conventions.md's order).
    #[arg(
        long,
        value_name = "F1,..,F6",
        default_value = "foot_1,foot_2,foot_3,foot_4,foot_5,foot_6"
    )]
    foot_frames: String,
}

impl BagArgs {
    fn options(self) -> Result<groundcal::solving::bag::BagOptions, String> {
        let feet: Vec<String> = self
            .foot_frames
            .split(',')
            .map(|f| f.trim().to_string())
            .collect();
        let foot_frames: [String; 6] = feet.try_into().map_err(|feet: Vec<String>| {
            format!(
                "--foot-frames: six frames, foot 1 first, separated by commas; found {}",
                feet.len()
            )
        })?;
        if foot_frames.iter().any(String::is_empty) {
            return Err("--foot-frames: a frame's name is empty".into());
        }
        Ok(groundcal::solving::bag::BagOptions {
            depth_topic: self.depth_topic,
            camera_info_topic: self.camera_info_topic,
            body_frame: self.body_frame,
            foot_frames,
            ..Default::default()
        })
    }
}

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
    Solve {
        /// The plane observations (shared/spec/recording.md, groundcal-planes).
        file: PathBuf,
        /// One JSON document on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Solve a recording (session.json, poses.jsonl, kinect/) offline, or a ROS 2 bag (MCAP).
    #[command(
        after_help = "A ROS 2 bag (an .mcap file) from another robot's stack: depth from sensor_msgs/Image (16UC1 mm or 32FC1 m), intrinsics from CameraInfo, the feet from /tf; still poses are found from the feet (docs/export.md).\n\nExamples:\n  groundcal replay ../shared/data/sample-12 --report /tmp/report --config /etc/groundcal/groundcal.toml\n  groundcal replay session.mcap --depth-topic /kinect/depth/image_raw --foot-frames lf_foot,lm_foot,lh_foot,rh_foot,rm_foot,rf_foot"
    )]
    Replay {
        /// The recording's directory, or a ROS 2 bag's .mcap file.
        dir: PathBuf,
        #[command(flatten)]
        bag: BagArgs,
        /// One JSON document on stdout.
        #[arg(long)]
        json: bool,
        /// The rough robot_from_sensor (degrees, millimetres) that tells which
        /// plane is the ground; overrides the recording's.
        #[arg(long, value_name = "a,b,g,x,y,z", allow_hyphen_values = true)]
        nominal_mount: Option<String>,
        /// Write a self-contained HTML report (index.html) into this directory.
        #[arg(long, value_name = "DIR")]
        report: Option<PathBuf>,
        /// Write the session as an MCAP file (ROS 2 messages) for Foxglove and
        /// ros2 bag: the frames, the body and feet, the mount, the ground found.
        #[arg(long, value_name = "FILE")]
        mcap: Option<PathBuf>,
        /// Worker threads (default: every core). The result does not depend on it.
        #[arg(long)]
        threads: Option<usize>,
        /// The ground fit: disparity (least squares in inverse depth, unbiased)
        /// or paper (the paper's eigenvector fit in metres, to compare).
        #[arg(long, value_name = "disparity|paper", default_value = "disparity")]
        ground_fit: GroundFitMethod,
        /// Judge by this configuration's quality gates (default: those the
        /// recording stores from its live run, else the built-in ones).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// The Kinect's depth scale: estimate (the default, or --config's
        /// calibration.depth_scale) or a known value such as 1.0032.
        #[arg(long, value_name = "estimate|VALUE", value_parser = groundcal::setup::config::parse_depth_scale)]
        depth_scale: Option<groundcal::setup::config::DepthScaleSetting>,
        /// Replay a recording whose poses.jsonl ends part-way through a
        /// record (a power cut while recording) without that pose; the result
        /// says so. Without it such a recording is refused, naming the cut.
        #[arg(long)]
        cut_off: bool,
    },
    /// The calibration in other tools' formats (URDF, ROS 2 static_transform_publisher, JSON).
    #[command(
        after_help = "Example:\n  groundcal export result.json --format urdf > sensor_mount.urdf"
    )]
    Export {
        /// A result document (`groundcal solve|replay|calibrate --json`).
        file: PathBuf,
        /// The format to write on stdout.
        #[arg(long, value_enum)]
        format: groundcal::formats::export::ExportFormat,
        /// The mount at this tilt of the Kinect's motor (degrees), from a
        /// calibration made at several tilts (calibrate --tilts), within their range.
        #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
        tilt: Option<f64>,
    },
    /// One calibration in the foreground (the daemon's session logic).
    #[command(
        after_help = "Ctrl-C (or SIGTERM) aborts: the robot is halted and sent home, and the last line says where it stands.\n\nExamples:\n  groundcal calibrate --robot sim --sensor sim\n  groundcal calibrate --config /etc/groundcal/groundcal.toml --record /var/lib/groundcal/rec-1 --json"
    )]
    Calibrate {
        /// The configuration (default: built-in simulation with --robot sim, else /etc/groundcal/groundcal.toml).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        #[command(flatten)]
        hardware: HardwareArgs,
        /// Write everything as a recording into this new directory, as it goes.
        #[arg(long, value_name = "DIR")]
        record: Option<PathBuf>,
        /// Also write the session as an MCAP file (ROS 2 messages) for
        /// Foxglove and ros2 bag, once the calibration is solved.
        #[arg(long, value_name = "FILE")]
        record_mcap: Option<PathBuf>,
        /// One JSON document on stdout (progress stays on stderr).
        #[arg(long)]
        json: bool,
        /// The ground fit, overriding calibration.ground_fit: disparity or paper.
        #[arg(long, value_name = "disparity|paper")]
        ground_fit: Option<GroundFitMethod>,
        /// The Kinect's depth scale, overriding calibration.depth_scale: estimate
        /// (with the mount, when the body's heights observe it) or a known value such as 1.0032.
        #[arg(long, value_name = "estimate|VALUE", value_parser = groundcal::setup::config::parse_depth_scale)]
        depth_scale: Option<groundcal::setup::config::DepthScaleSetting>,
        /// Calibrate at each of these tilts of the Kinect's motor (degrees, two or
        /// more, e.g. -20,-10,0) and fit the motor's axis: the result then holds at
        /// any tilt between them (export --tilt). Overrides calibration.tilts.
        #[arg(long, value_name = "T1,T2,...", allow_hyphen_values = true, value_parser = groundcal::setup::config::parse_tilts)]
        tilts: Option<groundcal::setup::config::Tilts>,
    },
    /// Whether the sensor still sits where the active (or a given) calibration says: the ground and the accelerometer now, or in a recording; exit 4 on drift.
    #[command(
        after_help = "The robot holds its home stance (with --poses N, also N small tilted poses, which see a turn about the vertical) while the Kinect captures the ground and gravity; both are compared with what the calibration predicts. Exit 0 consistent, 4 drift (the output says which way and by how much), 1 hardware, 2 bad input.\n\nExamples:\n  groundcal verify --config /etc/groundcal/groundcal.toml\n  groundcal verify --config config/sim.toml --calibration result.json --poses 4\n  groundcal verify --config config/sim.toml --calibration result.json --recording rec/ --json"
    )]
    Verify {
        /// The configuration (default: built-in simulation with --robot sim, else /etc/groundcal/groundcal.toml).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// The calibration to check: a result of calibrate/replay/solve --json, or an active.json (default: the store's active calibration, [serve] state_dir).
        #[arg(long, value_name = "FILE")]
        calibration: Option<PathBuf>,
        #[command(flatten)]
        hardware: HardwareArgs,
        /// Check a recording's poses offline instead of the robot now.
        #[arg(long, value_name = "DIR", conflicts_with = "poses")]
        recording: Option<PathBuf>,
        /// Tilted poses besides the still stance (default [verify] poses, 0 = stand still).
        #[arg(long, value_name = "N")]
        poses: Option<usize>,
        /// Keep what the check saw as a recording in this new directory.
        #[arg(long, value_name = "DIR", conflicts_with = "recording")]
        record: Option<PathBuf>,
        /// One JSON document on stdout (progress stays on stderr).
        #[arg(long)]
        json: bool,
    },
    /// The simulated lower computer (hexapod-udp.md) on a UDP socket, until SIGINT or SIGTERM.
    #[command(
        after_help = "Example:\n  groundcal sim-robot --listen 127.0.0.1:7400 --time-scale 50"
    )]
    SimRobot {
        /// The address to listen on, e.g. 127.0.0.1:7400 (port 0: any free port; the
        /// bound address is printed on stdout as `listening on IP:PORT`).
        #[arg(long, value_name = "ADDR")]
        listen: String,
        /// Picks the robot's kinematic error and noise.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Motions take duration / X (50: fifty times faster than real time).
        #[arg(long, value_name = "X", default_value_t = 1.0)]
        time_scale: f64,
        /// Play this recording's robot back: accept only its poses, exactly as
        /// commanded, and report its feet.
        #[arg(long, value_name = "DIR")]
        replay: Option<PathBuf>,
    },
    /// The daemon for the phone/pad terminal: HTTP API and page, sd_notify.
    #[command(
        after_help = "SIGTERM or SIGINT aborts a running calibration (the robot is halted and sent home), then the service exits.\n\nExample:\n  groundcal serve --config /etc/groundcal/groundcal.toml --listen 0.0.0.0:8080"
    )]
    Serve {
        /// The configuration ([serve]: listen, token_file, state_dir, allowed_hosts).
        #[arg(long)]
        config: PathBuf,
        #[command(flatten)]
        hardware: HardwareArgs,
        /// Overrides serve.listen (HOST:PORT; port 0 picks one).
        #[arg(long)]
        listen: Option<String>,
    },
    /// Predict a schedule's σ, correlations and observability before the robot moves; exit 3 when it would be rejected.
    #[command(
        after_help = "Examples:\n  groundcal plan --config /etc/groundcal/groundcal.toml config/schedules/octopus-52.toml --json\n  groundcal plan --design 16 --config config/sim.toml --out config/schedules/designed-16.toml"
    )]
    Plan {
        /// The configuration (nominal mount, limits, gates, [calibration.noise]); default /etc/groundcal/groundcal.toml.
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// The schedule to judge (default: the configuration's).
        schedule: Option<PathBuf>,
        /// Design a schedule of N poses within the robot's limits instead (needs --out).
        #[arg(long, value_name = "N", requires = "out")]
        design: Option<usize>,
        /// Where --design writes the schedule (a config/schedules/*.toml file).
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
        /// One JSON document on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Validate a configuration (and the schedule it names); non-zero with the reason if invalid.
    #[command(after_help = "Example:\n  groundcal check-config /etc/groundcal/groundcal.toml")]
    CheckConfig {
        /// The configuration file.
        file: PathBuf,
    },
    /// Record N depth frames from the sensor as a recording whose kinect/ is a fakenect dump.
    #[command(
        after_help = "Example:\n  groundcal capture --sensor kinect --frames 30 --out /tmp/still"
    )]
    Capture {
        /// The configuration (sensor, library); the flags override it.
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// The sensor: kinect (libfreenect); default the configuration's, else kinect.
        #[arg(long)]
        sensor: Option<SensorSource>,
        /// The libfreenect library file to load (e.g. libfreenect's fakenect, to play a dump back).
        #[arg(long, value_name = "PATH")]
        freenect_lib: Option<PathBuf>,
        /// How many depth frames to record.
        #[arg(long)]
        frames: usize,
        /// The new recording's directory (must not exist, or be empty).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
    },
    /// Fit the ground in one depth image.
    #[command(
        allow_negative_numbers = true,
        after_help = "Example:\n  groundcal plane frame.png --units mm --fx 525 --fy 525 --cx 319.5 --cy 239.5 --json"
    )]
    Plane {
        /// The depth image: fakenect PGM, 16-bit PGM, PNG or TIFF.
        file: PathBuf,
        /// One JSON document on stdout.
        #[arg(long)]
        json: bool,
        /// raw11 (fakenect .pgm), mm, or tum (5000 per metre).
        #[arg(long)]
        units: Option<DepthUnits>,
        /// zero-plane or inverse-linear:A,B (raw11 only).
        #[arg(long, default_value = "zero-plane")]
        model: String,
        /// Focal length along x, pixels (default: the Kinect's).
        #[arg(long)]
        fx: Option<f64>,
        /// Focal length along y, pixels (default: the Kinect's).
        #[arg(long)]
        fy: Option<f64>,
        /// Principal point x, pixels (default: the Kinect's).
        #[arg(long)]
        cx: Option<f64>,
        /// Principal point y, pixels (default: the Kinect's).
        #[arg(long)]
        cy: Option<f64>,
        /// Expected up direction in the optical frame.
        #[arg(long, default_value = "0,-1,0", allow_hyphen_values = true)]
        up: String,
        /// Largest angle between the ground's normal and --up, degrees.
        #[arg(long, default_value_t = 60.0)]
        up_tolerance: f64,
        /// The ground fit: disparity (least squares in inverse depth, unbiased)
        /// or paper (the paper's eigenvector fit in metres, to compare).
        #[arg(long, value_name = "disparity|paper", default_value = "disparity")]
        ground_fit: GroundFitMethod,
        /// The Kinect's depth pattern to take out of the image first: a
        /// document of `groundcal export RESULT.json --format depth-correction`.
        #[arg(long, value_name = "FILE")]
        depth_correction: Option<PathBuf>,
    },
}

fn usage_error(message: String) -> ExitStatus {
    eprintln!("groundcal: {message}");
    ExitStatus::BadInput
}

fn run(args: Args) -> ExitStatus {
    match args.command {
        Command::Plan {
            config,
            schedule,
            design,
            out,
            json,
        } => match (design, out) {
            (Some(count), Some(out)) => cli::plan::run_design(config.as_deref(), count, &out, json),
            (None, None) => cli::plan::run(config.as_deref(), schedule.as_deref(), json),
            _ => usage_error("plan: --design N and --out FILE go together".into()),
        },
        Command::Solve { file, json } => {
            cli::solve::run(&file, json, &CalibrationSettings::default())
        }
        Command::Replay {
            dir,
            bag,
            json,
            nominal_mount,
            report,
            mcap,
            threads,
            ground_fit,
            config,
            depth_scale,
            cut_off,
        } => {
            let (gates, noise, verify, configured_scale) = match config
                .as_deref()
                .map(groundcal::setup::config::Config::load)
            {
                None => (None, None, Default::default(), Default::default()),
                Some(Ok((config, _))) => (
                    Some(config.calibration.gates),
                    Some(
                        config
                            .calibration
                            .noise
                            .unwrap_or_else(groundcal::calib::plan::NoiseModel::solve_floors),
                    ),
                    config.verify.settings(&config.calibration),
                    config.calibration.depth_scale,
                ),
                Some(Err(e)) => return usage_error(e.to_string()),
            };
            let nominal_mount =
                match nominal_mount.map(|m| cli::parse_numbers::<6>("--nominal-mount", &m)) {
                    None => None,
                    Some(Ok(values)) => {
                        Some(groundcal::calib::observe::NominalMount::from_values(values))
                    }
                    Some(Err(e)) => return usage_error(e),
                };
            let mut options = groundcal::solving::replay::ReplayOptions {
                nominal_mount,
                threads,
                gates,
                noise,
                verify,
                depth_scale: depth_scale.unwrap_or(configured_scale),
                keep: groundcal::solving::replay::AlsoKeep {
                    ground_points: mcap.is_some(),
                    input_digest: report.is_some(),
                },
                ..Default::default()
            };
            options.pose.plane.method = ground_fit;
            let outputs = cli::replay::Outputs {
                json,
                report: report.as_deref(),
                mcap: mcap.as_deref(),
                cut_off,
                read_from: None,
            };
            if groundcal::solving::bag::is_mcap_file(&dir) {
                // groundcal's own session carries its recording whole.
                match groundcal::solving::bag::own::own_recording(&dir) {
                    Ok(Some(own)) => {
                        let outputs = cli::replay::Outputs {
                            read_from: Some(&dir),
                            ..outputs
                        };
                        return cli::replay::run(own.dir(), &outputs, &options);
                    }
                    Ok(None) => {}
                    Err(e) => {
                        eprintln!("groundcal replay: {e}");
                        return ExitStatus::BadInput;
                    }
                }
                return match bag.options() {
                    Ok(bag) => cli::replay::run_bag(&dir, &bag, &outputs, &options),
                    Err(e) => usage_error(e),
                };
            }
            cli::replay::run(&dir, &outputs, &options)
        }
        Command::Calibrate {
            config,
            hardware,
            record,
            record_mcap,
            json,
            ground_fit,
            depth_scale,
            tilts,
        } => {
            let options = cli::calibrate::CalibrateOptions {
                config,
                selection: hardware.into(),
                record,
                record_mcap,
                json,
                ground_fit,
                depth_scale,
                tilts: tilts.map(|t| t.0),
            };
            cli::calibrate::run(&options)
        }
        Command::Verify {
            config,
            calibration,
            hardware,
            recording,
            poses,
            record,
            json,
        } => cli::verify::run(&cli::verify::VerifyOptions {
            config,
            calibration,
            selection: hardware.into(),
            recording,
            poses,
            record,
            json,
        }),
        Command::SimRobot {
            listen,
            seed,
            time_scale,
            replay,
        } => cli::sim_robot::run(&listen, seed, time_scale, replay.as_deref()),
        Command::Serve {
            config,
            hardware,
            listen,
        } => cli::serve::run(&cli::serve::ServeOptions {
            config,
            selection: hardware.into(),
            listen,
        }),
        Command::CheckConfig { file } => cli::check_config::run(&file),
        Command::Export { file, format, tilt } => cli::export::run(&file, format, tilt),
        Command::Capture {
            config,
            sensor,
            freenect_lib,
            frames,
            out,
        } => {
            // The configuration's sensor and library, the flags overriding them.
            let sensor_config = match &config {
                Some(path) => match groundcal::setup::config::Config::load(path) {
                    Ok((config, _)) => Some(config.sensor),
                    Err(e) => return usage_error(e.to_string()),
                },
                None => None,
            };
            let source = sensor
                .or_else(|| sensor_config.as_ref().map(|s| s.source.clone()))
                .unwrap_or(SensorSource::Kinect);
            let library = freenect_lib.or_else(|| sensor_config.and_then(|s| s.freenect_lib));
            match source {
                SensorSource::Kinect => cli::capture::run(library.as_deref(), frames, &out),
                other => usage_error(format!(
                    "--sensor: \"{other}\" cannot capture (yet); use kinect"
                )),
            }
        }
        Command::Plane {
            file,
            json,
            units,
            model,
            fx,
            fy,
            cx,
            cy,
            up,
            up_tolerance,
            ground_fit,
            depth_correction,
        } => {
            let model = match cli::plane::parse_model(&model) {
                Ok(m) => m,
                Err(e) => return usage_error(e),
            };
            let up = match cli::parse_numbers::<3>("--up", &up) {
                Ok([x, y, z]) => Vector3::new(x, y, z),
                Err(e) => return usage_error(e),
            };
            let options = PlaneOptions {
                units,
                model,
                fx,
                fy,
                cx,
                cy,
                up_optical: up,
                up_tolerance_deg: up_tolerance,
                ground_fit,
                depth_correction,
            };
            cli::plane::run(&file, json, &options)
        }
    }
}

fn main() -> ExitCode {
    cli::guard_standard_descriptors();
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("GROUNDCAL_LOG")
                .unwrap_or_else(|_| "warn".into()),
        )
        .init();
    let args = Args::parse();
    if matches!(
        args.command,
        Command::Plan { .. }
            | Command::Solve { .. }
            | Command::Replay { .. }
            | Command::CheckConfig { .. }
            | Command::Export { .. }
            | Command::Plane { .. }
    ) {
        cli::ends_quietly_on_a_closed_pipe();
    }
    ExitCode::from(run(args).code() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

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
