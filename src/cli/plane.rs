//! `groundcal plane FILE`: the ground in one depth image.

use std::path::Path;

use nalgebra::Vector3;
use serde::Serialize;

use super::{print_json, ExitStatus};
use crate::calib::geometry::{sensor_from_optical, Plane};
use crate::calib::plane::{
    fit_ground, FitBuffers, GroundFit, GroundFitMethod, GroundPrior, PlaneFitSettings,
};
use crate::calib::sensor::{DepthCamera, DepthEncoding, DepthModel, DepthRange, Intrinsics};
use crate::formats::depth_image::{read_depth_image, DepthUnits};
use crate::formats::output::PlaneJson;
use std::path::PathBuf;

/// The command's options, already parsed from flags.
#[derive(Debug, Clone)]
pub struct PlaneOptions {
    pub units: Option<DepthUnits>,
    pub model: DepthModel,
    pub fx: Option<f64>,
    pub fy: Option<f64>,
    pub cx: Option<f64>,
    pub cy: Option<f64>,
    /// Expected up direction in the optical frame.
    pub up_optical: Vector3<f64>,
    pub up_tolerance_deg: f64,
    pub ground_fit: GroundFitMethod,
    /// A `groundcal-depth-correction` document to take out of the image.
    pub depth_correction: Option<std::path::PathBuf>,
}

impl Default for PlaneOptions {
    fn default() -> Self {
        Self {
            units: None,
            model: DepthModel::default(),
            fx: None,
            fy: None,
            cx: None,
            cy: None,
            up_optical: Vector3::new(0.0, -1.0, 0.0),
            up_tolerance_deg: 60.0,
            ground_fit: GroundFitMethod::Disparity,
            depth_correction: None,
        }
    }
}

/// Parses `--model zero-plane | inverse-linear[:A,B]`.
pub fn parse_model(text: &str) -> Result<DepthModel, String> {
    match text {
        "zero-plane" => Ok(DepthModel::default()),
        "inverse-linear" => Ok(DepthModel::inverse_linear_default()),
        _ => match text.strip_prefix("inverse-linear:") {
            Some(rest) => {
                let [a, b] = super::parse_numbers::<2>("--model inverse-linear", rest)?;
                Ok(DepthModel::InverseLinear { a, b })
            }
            None => Err(format!(
                "--model: \"{text}\" is neither zero-plane nor inverse-linear:A,B"
            )),
        },
    }
}

#[derive(Debug, Serialize)]
struct PlaneResult {
    plane_sensor: PlaneJson,
    plane_optical: PlaneJson,
    inliers: usize,
    valid_pixels: usize,
    rms_mm: f64,
}

/// The plane in the optical frame (x right, y down, z forward).
pub fn to_optical(plane: &Plane) -> Plane {
    Plane {
        normal: sensor_from_optical().transpose() * plane.normal,
        d: plane.d,
    }
}

/// Reads the image and fits the ground; errors are messages naming the file or flag.
pub fn fit_file(file: &Path, options: &PlaneOptions) -> Result<GroundFit, (ExitStatus, String)> {
    let bad = |m: String| (ExitStatus::BadInput, m);
    let (image, units) = read_depth_image(file, options.units).map_err(|e| bad(e.to_string()))?;
    let defaults = Intrinsics::default();
    let intrinsics = Intrinsics {
        fx: options.fx.unwrap_or(defaults.fx),
        fy: options.fy.unwrap_or(defaults.fy),
        cx: options.cx.unwrap_or(defaults.cx),
        cy: options.cy.unwrap_or(defaults.cy),
        width: image.width,
        height: image.height,
    };
    intrinsics
        .validate()
        .map_err(|e| bad(format!("intrinsics: {e}")))?;
    options
        .model
        .validate()
        .map_err(|e| bad(format!("--model: {e}")))?;
    if !(options.up_tolerance_deg > 0.0 && options.up_tolerance_deg <= 90.0) {
        return Err(bad(format!(
            "--up-tolerance must lie in (0, 90] degrees, not {}",
            options.up_tolerance_deg
        )));
    }
    if options.up_optical.norm() < 1e-9 {
        return Err(bad("--up must not be the zero vector".into()));
    }
    let encoding = match units {
        DepthUnits::Raw11 => DepthEncoding::Raw11(options.model),
        DepthUnits::Millimetres => DepthEncoding::Metric {
            metres_per_unit: 0.001,
        },
        DepthUnits::Tum => DepthEncoding::Metric {
            metres_per_unit: 1.0 / 5000.0,
        },
    };
    let mut camera = DepthCamera::new(encoding, intrinsics, DepthRange::default());
    if let Some(path) = &options.depth_correction {
        let correction = crate::formats::export::read_depth_correction_file(path)
            .map_err(|e| bad(e.to_string()))?;
        camera = camera.with_depth_correction(&correction);
    }
    let up_sensor = sensor_from_optical() * options.up_optical.normalize();
    let prior = GroundPrior::up_only(up_sensor, options.up_tolerance_deg.to_radians());
    let settings = PlaneFitSettings {
        method: options.ground_fit,
        ..Default::default()
    };
    fit_ground(
        &[&image.pixels],
        &camera,
        &prior,
        &settings,
        &mut FitBuffers::default(),
    )
    .map_err(|e| {
        (
            ExitStatus::RuntimeFailure,
            format!("{}: {e}", file.display()),
        )
    })
}

/// The arguments of `groundcal plane`: one depth image and how to read it.
#[derive(Debug, clap::Args)]
pub struct PlaneArgs {
    /// The depth image: fakenect PGM, 16-bit PGM, PNG or TIFF.
    pub file: PathBuf,
    /// One JSON document on stdout.
    #[arg(long)]
    pub json: bool,
    /// raw11 (fakenect .pgm), mm, or tum (5000 per metre).
    #[arg(long)]
    pub units: Option<DepthUnits>,
    /// zero-plane or inverse-linear:A,B (raw11 only).
    #[arg(long, default_value = "zero-plane")]
    pub model: String,
    /// Focal length along x, pixels (default: the Kinect's).
    #[arg(long)]
    pub fx: Option<f64>,
    /// Focal length along y, pixels (default: the Kinect's).
    #[arg(long)]
    pub fy: Option<f64>,
    /// Principal point x, pixels (default: the Kinect's).
    #[arg(long)]
    pub cx: Option<f64>,
    /// Principal point y, pixels (default: the Kinect's).
    #[arg(long)]
    pub cy: Option<f64>,
    /// Expected up direction in the optical frame.
    #[arg(long, default_value = "0,-1,0", allow_hyphen_values = true)]
    pub up: String,
    /// Largest angle between the ground's normal and --up, degrees.
    #[arg(long, default_value_t = 60.0)]
    pub up_tolerance: f64,
    /// The ground fit: disparity (least squares in inverse depth, unbiased)
    /// or paper (the paper's eigenvector fit in metres, to compare).
    #[arg(long, value_name = "disparity|paper", default_value = "disparity")]
    pub ground_fit: GroundFitMethod,
    /// The Kinect's depth pattern to take out of the image first: a
    /// document of `groundcal export RESULT.json --format depth-correction`.
    #[arg(long, value_name = "FILE")]
    pub depth_correction: Option<PathBuf>,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: PlaneArgs) -> ExitStatus {
    let model = match parse_model(&args.model) {
        Ok(m) => m,
        Err(e) => return super::usage_error(e),
    };
    let up = match super::parse_numbers::<3>("--up", &args.up) {
        Ok([x, y, z]) => nalgebra::Vector3::new(x, y, z),
        Err(e) => return super::usage_error(e),
    };
    let options = PlaneOptions {
        units: args.units,
        model,
        fx: args.fx,
        fy: args.fy,
        cx: args.cx,
        cy: args.cy,
        up_optical: up,
        up_tolerance_deg: args.up_tolerance,
        ground_fit: args.ground_fit,
        depth_correction: args.depth_correction,
    };
    run(&args.file, args.json, &options)
}

/// Runs the command.
pub fn run(file: &Path, json: bool, options: &PlaneOptions) -> ExitStatus {
    let fit = match fit_file(file, options) {
        Ok(fit) => fit,
        Err((status, message)) => {
            eprintln!("groundcal plane: {message}");
            return status;
        }
    };
    let result = PlaneResult {
        plane_sensor: (&fit.plane).into(),
        plane_optical: (&to_optical(&fit.plane)).into(),
        inliers: fit.inliers,
        valid_pixels: fit.valid_points,
        rms_mm: fit.rms_m * 1e3,
    };
    if json {
        if let Err(e) = print_json(&result) {
            eprintln!("groundcal plane: {e}");
            return ExitStatus::RuntimeFailure;
        }
    } else {
        let s = &result.plane_sensor;
        let o = &result.plane_optical;
        println!(
            "ground (sensor frame):  {:+.4} x {:+.4} y {:+.4} z {:+.4} = 0",
            s.a, s.b, s.c, s.d_m
        );
        println!(
            "ground (optical frame): {:+.4} x {:+.4} y {:+.4} z {:+.4} = 0",
            o.a, o.b, o.c, o.d_m
        );
        println!(
            "sensor height {:.1} mm; {} of {} valid pixels on the ground; RMS {:.2} mm",
            s.d_m * 1e3,
            result.inliers,
            result.valid_pixels,
            result.rms_mm
        );
    }
    ExitStatus::Success
}
