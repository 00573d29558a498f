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
use groundcal::config::{RobotAddress, SensorSource};
use groundcal::depth_image::DepthUnits;
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

#[derive(Debug, Parser)]
#[command(
    name = "groundcal",
    version,
    about = "Calibrates where a depth camera sits on a legged robot, using the ground"
)]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Solve robot_from_sensor from plane observations (groundcal-planes).
    Solve {
        file: PathBuf,
        /// One JSON document on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Solve a recording (session.json, poses.jsonl, kinect/) offline.
    Replay {
        dir: PathBuf,
        #[arg(long)]
        json: bool,
        /// The rough robot_from_sensor (degrees, millimetres) that tells which
        /// plane is the ground; overrides the recording's.
        #[arg(long, value_name = "a,b,g,x,y,z", allow_hyphen_values = true)]
        nominal_mount: Option<String>,
        /// Write a self-contained HTML report (index.html) into this directory.
        #[arg(long, value_name = "DIR")]
        report: Option<PathBuf>,
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
    },
    /// The calibration in other tools' formats (URDF, ROS 2 static_transform_publisher, JSON).
    Export {
        /// A result document (`groundcal solve|replay|calibrate --json`).
        file: PathBuf,
        #[arg(long, value_enum)]
        format: groundcal::export::ExportFormat,
    },
    /// One calibration in the foreground (the daemon's session logic).
    Calibrate {
        /// The configuration (default: built-in simulation with --robot sim, else /etc/groundcal/groundcal.toml).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        #[command(flatten)]
        hardware: HardwareArgs,
        /// Write everything as a recording into this new directory, as it goes.
        #[arg(long, value_name = "DIR")]
        record: Option<PathBuf>,
        #[arg(long)]
        json: bool,
        /// The ground fit, overriding calibration.ground_fit: disparity or paper.
        #[arg(long, value_name = "disparity|paper")]
        ground_fit: Option<GroundFitMethod>,
    },
    /// The simulated lower computer (hexapod-udp.md) on a UDP socket, until SIGINT or SIGTERM.
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
    Serve {
        #[arg(long)]
        config: PathBuf,
        #[command(flatten)]
        hardware: HardwareArgs,
        /// Overrides serve.listen (HOST:PORT; port 0 picks one).
        #[arg(long)]
        listen: Option<String>,
    },
    /// Validate a configuration (and the schedule it names); non-zero with the reason if invalid.
    CheckConfig { file: PathBuf },
    /// Record N depth frames from the sensor as a recording whose kinect/ is a fakenect dump.
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
    #[command(allow_negative_numbers = true)]
    Plane {
        file: PathBuf,
        #[arg(long)]
        json: bool,
        /// raw11 (fakenect .pgm), mm, or tum (5000 per metre).
        #[arg(long)]
        units: Option<DepthUnits>,
        /// zero-plane or inverse-linear:A,B (raw11 only).
        #[arg(long, default_value = "zero-plane")]
        model: String,
        #[arg(long)]
        fx: Option<f64>,
        #[arg(long)]
        fy: Option<f64>,
        #[arg(long)]
        cx: Option<f64>,
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
    },
}

fn usage_error(message: String) -> ExitStatus {
    eprintln!("groundcal: {message}");
    ExitStatus::BadInput
}

fn run(args: Args) -> ExitStatus {
    match args.command {
        Command::Solve { file, json } => {
            cli::solve::run(&file, json, &CalibrationSettings::default())
        }
        Command::Replay {
            dir,
            json,
            nominal_mount,
            report,
            threads,
            ground_fit,
            config,
        } => {
            let gates = match config.as_deref().map(groundcal::config::Config::load) {
                None => None,
                Some(Ok((config, _))) => Some(config.calibration.gates),
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
            let mut options = groundcal::replay::ReplayOptions {
                nominal_mount,
                threads,
                gates,
                ..Default::default()
            };
            options.pose.plane.method = ground_fit;
            cli::replay::run(&dir, json, report.as_deref(), &options)
        }
        Command::Calibrate {
            config,
            hardware,
            record,
            json,
            ground_fit,
        } => {
            let options = cli::calibrate::CalibrateOptions {
                config,
                selection: hardware.into(),
                record,
                json,
                ground_fit,
            };
            cli::calibrate::run(&options)
        }
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
        Command::Export { file, format } => cli::export::run(&file, format),
        Command::Capture {
            config,
            sensor,
            freenect_lib,
            frames,
            out,
        } => {
            // The configuration's sensor and library, the flags overriding them.
            let sensor_config = match &config {
                Some(path) => match groundcal::config::Config::load(path) {
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
            };
            cli::plane::run(&file, json, &options)
        }
    }
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("GROUNDCAL_LOG")
                .unwrap_or_else(|_| "warn".into()),
        )
        .init();
    let args = Args::parse();
    ExitCode::from(run(args).code() as u8)
}
