//! The ground fit in every scene of the simulator, against the paper's fit
//! on the same frames (issue 22): 52 poses of octopus-52 rendered by the
//! simulated Kinect from the true body poses and the true mount, two frames
//! a pose, both fits, then the solve. Per scene, seed and depth model: the
//! mean plane bias (fitted d − true d, and the normal's angle) and the
//! mount's error against the truth.
//!
//! `cargo test --release --test ground_fit_scenes -- --ignored --nocapture
//! table` prints the table of docs/method.md. For the experiments behind it,
//! `run` also reads: `GROUNDCAL_SCENES` (scenes, comma-separated),
//! `GROUNDCAL_SCENES_SEEDS`, `GROUNDCAL_SCENES_POSE` (one pose, no solve),
//! `GROUNDCAL_SCENES_GUARD=ROWS,SIGMAS` and `GROUNDCAL_SCENES_LOWER=DEGREES`
//! (the fit's settings: `0,3` and `15` are the fit before issue 22), and
//! `GROUNDCAL_SCENES_ORACLE` (fit only the pixels that see the ground).

mod common;

use groundcal::calib::geometry::{ground_in_sensor, PoseDegMm, Transform};
use groundcal::calib::observe::{ground_prior, NominalMount};
use groundcal::calib::plane::{fit_ground, FitBuffers, GroundFitMethod, PlaneFitSettings};
use groundcal::calib::sensor::DepthModel;
use groundcal::calib::solve::{solve, DepthScaleSetting, Observation, SolveSettings};
use groundcal_hal::sim::world::World;

/// What the operator knows before calibrating (config/sim.toml).
const NOMINAL_MOUNT: [f64; 6] = [0.0, -35.0, 0.0, 520.0, 360.0, 0.0];

fn pose(values: [f64; 6]) -> Transform {
    PoseDegMm::from_values(values).to_params().to_transform()
}

/// A scene of the simulator, by name and seed.
fn scene(name: &str, seed: u64) -> World {
    match name {
        "flat" => World::flat(),
        "boxes-and-wall" => World::boxes_and_wall(seed),
        "clutter" => World::clutter(seed),
        "low-boxes" => World::low_boxes(seed),
        "wall-meeting-floor" => World::wall_meeting_floor(seed),
        "uneven" => World::uneven(seed, 0.01),
        "corridor" => World::corridor(seed),
        other => panic!("no scene {other}"),
    }
}

/// What one fit method gave over the 52 poses.
#[derive(Debug, Clone, Copy)]
pub struct Outcome {
    /// Mean of fitted d − true d, mm (positive: the ground found farther).
    pub bias_mm: f64,
    /// Mean angle between the fitted and the true normal, degrees.
    pub angle_deg: f64,
    /// The solved mount against the truth: rotation angle, degrees, and
    /// distance, mm.
    pub mount_deg: f64,
    pub mount_mm: f64,
    /// Poses whose ground was found.
    pub fitted: usize,
}

/// Renders the 52 poses of `world` and fits each with both methods; returns
/// (disparity, paper).
fn run(world: &World, model: DepthModel, seed: u64) -> (Outcome, Outcome) {
    let schedule = common::octopus_52();
    let (renderer, camera) = common::sim_renderer(model, seed);
    let nominal = NominalMount::from_values(NOMINAL_MOUNT);
    let mount = pose(common::SIM_MOUNT);
    let mut buffers = FitBuffers::default();
    let methods = [GroundFitMethod::Disparity, GroundFitMethod::Paper];
    let mut observations: [Vec<Observation>; 2] = [Vec::new(), Vec::new()];
    let mut bias = [Vec::new(), Vec::new()];
    let mut angle = [Vec::new(), Vec::new()];
    let only: Option<usize> = std::env::var("GROUNDCAL_SCENES_POSE")
        .ok()
        .and_then(|p| p.parse().ok());
    for (i, commanded) in schedule.poses.iter().enumerate() {
        if only.is_some_and(|p| p != i + 1) {
            continue;
        }
        let ground_from_robot = commanded.to_params().to_transform();
        let ground_from_sensor = ground_from_robot * mount;
        let truth = ground_in_sensor(&ground_from_sensor);
        let oracle = std::env::var("GROUNDCAL_SCENES_ORACLE").is_ok();
        let frames: Vec<Vec<u16>> = (0..2)
            .map(|k| {
                let mut frame = renderer.render(world, &ground_from_sensor, 2 * i as u64 + k);
                if oracle {
                    // Only the pixels that see the ground: those a flat world
                    // renders the same.
                    let flat =
                        renderer.render(&World::flat(), &ground_from_sensor, 2 * i as u64 + k);
                    for (p, f) in frame.iter_mut().zip(&flat) {
                        if p != f {
                            *p = 2047;
                        }
                    }
                }
                frame
            })
            .collect();
        let frames: Vec<&[u16]> = frames.iter().map(Vec::as_slice).collect();
        let prior = ground_prior(Some(&nominal), &ground_from_robot);
        for (m, method) in methods.iter().enumerate() {
            let mut settings = PlaneFitSettings {
                method: *method,
                ..Default::default()
            };
            if let Ok(degrees) = std::env::var("GROUNDCAL_SCENES_LOWER") {
                settings.lower_parallel_deg = degrees.parse().unwrap();
            }
            if let Ok(guard) = std::env::var("GROUNDCAL_SCENES_GUARD") {
                let (rows, sigmas) = guard.split_once(',').expect("ROWS,SIGMAS");
                settings.edge_guard_rows = rows.parse().unwrap();
                settings.edge_guard_sigmas = sigmas.parse().unwrap();
            }
            let Ok(fit) = fit_ground(&frames, &camera, &prior, &settings, &mut buffers) else {
                continue;
            };
            // A pose whose ground is a centimetre off, said (on stderr).
            if (fit.plane.d - truth.d).abs() > 1e-3 {
                eprintln!(
                    "pose {} ({method:?}): d off by {:+.1} mm, normal by {:.3}°, {} inliers of {}",
                    i + 1,
                    (fit.plane.d - truth.d) * 1e3,
                    fit.plane.angle_to(&truth).to_degrees(),
                    fit.inliers,
                    fit.valid_points
                );
            }
            bias[m].push((fit.plane.d - truth.d) * 1e3);
            angle[m].push(fit.plane.angle_to(&truth).to_degrees());
            let mut o = Observation::new(i as u32 + 1, ground_from_robot, fit.plane);
            o.plane_covariance = Some(fit.covariance);
            o.inliers = Some(fit.inliers);
            observations[m].push(o);
        }
    }
    let settings = SolveSettings {
        depth_scale: DepthScaleSetting::Fixed(1.0),
        ..Default::default()
    };
    let truth = mount;
    let outcome = |m: usize| {
        if only.is_some() {
            return Outcome {
                bias_mm: f64::NAN,
                angle_deg: f64::NAN,
                mount_deg: f64::NAN,
                mount_mm: f64::NAN,
                fitted: observations[m].len(),
            };
        }
        let solution = solve(&observations[m], &settings).expect("solved");
        let found = solution.robot_from_sensor.to_transform();
        let rotation = (truth.rotation.inverse() * found.rotation)
            .angle()
            .to_degrees();
        let distance = (truth.translation.vector - found.translation.vector).norm() * 1e3;
        let mean = |v: &Vec<f64>| v.iter().sum::<f64>() / v.len().max(1) as f64;
        Outcome {
            bias_mm: mean(&bias[m]),
            angle_deg: mean(&angle[m]),
            mount_deg: rotation,
            mount_mm: distance,
            fitted: observations[m].len(),
        }
    };
    (outcome(0), outcome(1))
}

fn models() -> [(&'static str, DepthModel); 2] {
    [
        ("zero-plane", DepthModel::default()),
        ("inverse-linear", DepthModel::inverse_linear_default()),
    ]
}

/// The table of docs/method.md: every scene, seeds 1–4, both models.
#[test]
#[ignore = "prints docs/method.md's table (minutes): run with --ignored"]
fn table() {
    use tracing_subscriber::{filter::LevelFilter, filter::Targets, prelude::*};
    // `RUST_LOG` as targets and levels; errors only when unset.
    let filter = std::env::var("RUST_LOG")
        .ok()
        .and_then(|value| value.parse::<Targets>().ok())
        .unwrap_or_else(|| Targets::new().with_default(LevelFilter::ERROR));
    let _ = tracing_subscriber::registry()
        .with(tracing_subscriber::fmt::layer().with_writer(std::io::stderr))
        .with(filter)
        .try_init();
    let scenes: Vec<String> = std::env::var("GROUNDCAL_SCENES")
        .unwrap_or_else(|_| {
            "flat,boxes-and-wall,clutter,low-boxes,wall-meeting-floor,uneven,corridor".into()
        })
        .split(',')
        .map(String::from)
        .collect();
    println!("| scene | seed | depth model | default fit: bias, angle, mount | paper fit: bias, angle, mount |");
    println!("|---|---|---|---|---|");
    for name in &scenes {
        let seeds: Vec<u64> = std::env::var("GROUNDCAL_SCENES_SEEDS")
            .map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect())
            .unwrap_or_else(|_| (1..=4).collect());
        for &seed in &seeds {
            for (model_name, model) in models() {
                let (d, p) = run(&scene(name, seed), model, seed);
                println!(
                    "| {name} | {seed} | {model_name} | {:+.3} mm, {:.4}°, {:.4}° / {:.2} mm ({}) | {:+.3} mm, {:.4}°, {:.4}° / {:.2} mm ({}) |",
                    d.bias_mm, d.angle_deg, d.mount_deg, d.mount_mm, d.fitted,
                    p.bias_mm, p.angle_deg, p.mount_deg, p.mount_mm, p.fitted
                );
            }
        }
    }
}

/// The default fit's outcome in `scene` for `seeds` and both depth models,
/// with the paper's on the same frames.
fn outcomes(name: &str, seeds: &[u64]) -> Vec<(String, Outcome, Outcome)> {
    let mut all = Vec::new();
    for &seed in seeds {
        for (model_name, model) in models() {
            let (disparity, paper) = run(&scene(name, seed), model, seed);
            let label = format!("{name}, seed {seed}, {model_name}");
            eprintln!("{label}: default {disparity:?}; paper {paper:?}");
            all.push((label, disparity, paper));
        }
    }
    all
}

/// Unbiased planes and the mount within `degrees` and `mm` of the truth;
/// planes at least as accurate as the paper's fit gives on the same frames
/// (mean bias and angle), and with all 52 poses the mount too (to within
/// 0.001° and 0.1 mm, the solve's own scatter on these frames; with fewer
/// poses that scatter is larger than either fit's error).
fn assert_unbiased(all: &[(String, Outcome, Outcome)], degrees: f64, mm: f64) {
    for (label, d, p) in all {
        assert!(
            d.bias_mm.abs() <= 0.03,
            "{label}: mean plane bias {:+.3} mm",
            d.bias_mm
        );
        assert!(
            d.mount_deg <= degrees && d.mount_mm <= mm,
            "{label}: the mount is {:.4}° and {:.3} mm off",
            d.mount_deg,
            d.mount_mm
        );
        assert!(
            d.bias_mm.abs() <= p.bias_mm.abs().max(0.01) && d.angle_deg <= p.angle_deg,
            "{label}: planes {:+.3} mm and {:.4}° off, the paper's fit's {:+.3} mm and {:.4}°",
            d.bias_mm,
            d.angle_deg,
            p.bias_mm,
            p.angle_deg
        );
        if d.fitted < 52 {
            continue;
        }
        assert!(
            d.mount_deg <= p.mount_deg.max(0.001) && d.mount_mm <= p.mount_mm.max(0.1),
            "{label}: {:.4}° / {:.3} mm, where the paper's fit gives {:.4}° / {:.3} mm",
            d.mount_deg,
            d.mount_mm,
            p.mount_deg,
            p.mount_mm
        );
    }
}

/// Issue 22's clutter: four boxes and a wall across the far end of the
/// view. Before the edge guard the planes were 0.14–0.19 mm too far and the
/// mount 0.6–1.1 mm off.
#[test]
fn in_clutter_the_ground_is_fitted_without_bias() {
    assert_unbiased(&outcomes("clutter", &[1, 2, 3, 4]), 0.005, 0.35);
}

/// A wall that meets the floor across the view: before, 0.2–0.27 mm of
/// bias and the mount 1.0–1.5 mm off.
#[test]
fn where_a_wall_meets_the_floor_the_ground_is_fitted_without_bias() {
    assert_unbiased(&outcomes("wall-meeting-floor", &[1, 2]), 0.005, 0.35);
}

/// Boxes 5–10 cm tall: before, on seed 4 one pose's ground was a phantom
/// plane and the mean bias −2.35 mm.
#[test]
fn among_low_boxes_the_ground_is_fitted_without_bias() {
    assert_unbiased(&outcomes("low-boxes", &[4]), 0.005, 0.35);
}

/// A corridor full of people, the floor a tenth of the view in about half
/// the poses: before, 0.16–0.2 mm of bias and the mount 2.5–2.7 mm off on
/// seed 2.
#[test]
fn in_a_corridor_the_ground_is_fitted_without_bias() {
    assert_unbiased(&outcomes("corridor", &[2]), 0.02, 0.6);
}

/// Open ground, and the simulator's boxes and wall, keep their accuracy.
#[test]
fn on_open_ground_the_accuracy_is_kept() {
    let mut all = outcomes("flat", &[1]);
    all.extend(outcomes("boxes-and-wall", &[1]));
    for (label, d, _) in &all {
        assert!(d.bias_mm.abs() <= 0.02, "{label}: {:+.3} mm", d.bias_mm);
    }
    assert_unbiased(&all, 0.002, 0.15);
}

/// Among obstacles, what a depth pattern bends each pose's plane by is
/// predicted from that pose's residuals (issue 23): the residuals are summed
/// over the very pixels the fit read, its edge guard included. Every
/// fourth pose of octopus-52, in three scenes, is rendered twice with the
/// same noise: with a bowl of ±1 raw unit and without. The fit's own bend
/// is the difference of the two planes; the prediction is the bend of the
/// true bowl over the patterned fit's residuals. Before the residuals left
/// out what the fit's edge guard leaves out, the rows at every obstacle's
/// foot were in the prediction and not in the fit. The bends then missed
/// by 0.021, 0.015 and 0.002 raw units RMS in offset (clutter, the wall,
/// low boxes), 0.017, 0.007 and 0.003 in the gradient down the image, and
/// a bowl among clutter put the pitch 3–5σ off on every seed; now they
/// miss by 0.001–0.003.
#[test]
fn among_obstacles_a_patterns_bend_is_predicted_from_the_residuals() {
    use groundcal::calib::disparity::PixelPlane;
    use groundcal::calib::distortion::{estimate_shape, GroundResiduals, CELL_PX};
    use groundcal_hal::sim::kinect::{
        DepthDistortion, DepthRenderer, DistortionShape, SimKinectConfig,
    };
    use nalgebra::Vector3;

    let model = DepthModel::inverse_linear_default();
    let schedule = common::octopus_52();
    let nominal = NominalMount::from_values(NOMINAL_MOUNT);
    let mount = pose(common::SIM_MOUNT);
    let bowl = DepthDistortion {
        shape: DistortionShape::Radial,
        amplitude_raw: 1.0,
        decay_per_m: 0.0,
    };
    for (name, seed) in [("clutter", 7), ("wall-meeting-floor", 1), ("low-boxes", 4)] {
        let world = scene(name, seed);
        let (_, camera) = common::sim_renderer(model, seed);
        let renderer = |distortion| {
            DepthRenderer::new(&SimKinectConfig {
                depth_model: model,
                seed,
                distortion,
                ..SimKinectConfig::independent_noise()
            })
            .expect("a valid simulated Kinect")
        };
        let (warped, straight) = (renderer(bowl), renderer(DepthDistortion::default()));
        let intrinsics = *camera.intrinsics();
        let mut buffers = FitBuffers::default();
        let (mut residuals, mut taken) = (Vec::new(), Vec::new());
        for (i, commanded) in schedule.poses.iter().enumerate().step_by(4) {
            let ground_from_robot = commanded.to_params().to_transform();
            let ground_from_sensor = ground_from_robot * mount;
            let prior = ground_prior(Some(&nominal), &ground_from_robot);
            let mut fit = |renderer: &DepthRenderer| {
                let frames: Vec<Vec<u16>> = (0..2)
                    .map(|k| renderer.render(&world, &ground_from_sensor, 2 * i as u64 + k))
                    .collect();
                let frames: Vec<&[u16]> = frames.iter().map(Vec::as_slice).collect();
                let settings = PlaneFitSettings::default();
                let fit = fit_ground(&frames, &camera, &prior, &settings, &mut buffers)
                    .expect("the ground found");
                let of = GroundResiduals::of(&frames, &camera, &fit, buffers.residual_image());
                (PixelPlane::from_plane(&fit.plane, &intrinsics), of)
            };
            let ((bent, of), (plain, _)) = (fit(&warped), fit(&straight));
            residuals.push(of.expect("the default fit's residuals"));
            taken.push(Vector3::new(
                bent.c0 - plain.c0,
                bent.cu - plain.cu,
                bent.cv - plain.cv,
            ));
        }
        let refs: Vec<&GroundResiduals> = residuals.iter().collect();
        // The estimate's cells and scales, with the true bowl for its shape
        // (the bend of its plane part is that plane part, at every pose).
        let mut truth = estimate_shape(&refs).expect("enough poses");
        for (k, value) in truth.shape.iter_mut().enumerate() {
            let (column, row) = (k % truth.columns, k / truth.columns);
            let mut sum = 0.0;
            for dv in 0..CELL_PX {
                for du in 0..CELL_PX {
                    let (u, v) = (column * CELL_PX + du, row * CELL_PX + dv);
                    sum += bowl.raw_at(u as f64, v as f64, &intrinsics);
                }
            }
            *value = sum / (CELL_PX * CELL_PX) as f64 / truth.raw_per_inverse_depth;
            truth.seen[k] = true;
        }
        let predicted = truth.plane_corrections(&refs);
        // What the prediction missed, raw units (gradients per 100 pixels).
        let raw = truth.raw_per_inverse_depth;
        let missed: Vec<Vector3<f64>> = taken
            .iter()
            .zip(&predicted)
            .map(|(taken, correction)| {
                let m = taken + correction;
                Vector3::new(m.x * raw, m.y * raw * 100.0, m.z * raw * 100.0)
            })
            .collect();
        let rms = missed
            .iter()
            .map(|m| m.component_mul(m))
            .sum::<Vector3<f64>>()
            .map(|s| (s / missed.len() as f64).sqrt());
        eprintln!(
            "{name} (seed {seed}): the bend missed by {:.4} {:.4} {:.4} raw units RMS (offset, along u, along v) over {} poses",
            rms.x, rms.y, rms.z, missed.len()
        );
        assert!(
            rms.x < 0.006 && rms.z < 0.005,
            "{name}: the bends predicted missed the fit's by {rms:?} raw units RMS"
        );
    }
}
