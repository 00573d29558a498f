//! The simulated Kinect's frames through the calibration's own ground fit:
//! raw frames to points as `groundcal plane` and the replay do
//! (`DepthCamera`), fitted by `fit_ground`, give the true ground of
//! conventions.md (row 1 of `ground_from_sensor`) within 0.05° and 1 mm, on
//! flat ground and with boxes and a wall in view, where the ground is chosen
//! by the prior the pipeline makes from a nominal mount; in a corridor full of
//! people where the floor is a tenth of the view; and, over 200 seeded
//! planes per depth model, without bias (where the paper's fit has one).

use groundcal::calib::geometry::{ground_in_sensor, Plane, PoseDegMm, PoseParams, Transform};
use groundcal::calib::observe::{ground_prior, NominalMount};
use groundcal::calib::plane::{
    fit_ground, FitBuffers, GroundFit, GroundFitMethod, GroundPrior, PlaneFitError,
    PlaneFitSettings,
};
use groundcal::calib::sensor::{DepthCamera, DepthEncoding, DepthModel, DepthRange};
use groundcal_hal::sim::kinect::{DepthRenderer, SimKinectConfig};
use groundcal_hal::sim::world::World;

/// The true mount: the shared sample recording's.
const TRUE_MOUNT: [f64; 6] = [4.5, -30.7, -2.0, 491.3, 331.6, 8.7];

/// What the operator knows before calibrating: recording.md's example.
const NOMINAL_MOUNT: [f64; 6] = [0.0, -35.0, 0.0, 520.0, 360.0, 0.0];

fn pose(values: [f64; 6]) -> Transform {
    PoseDegMm::from_values(values).to_params().to_transform()
}

/// Body poses of octopus-52 spanning its range, and the home stance.
fn body_poses() -> Vec<Transform> {
    [
        [0.0, 0.0, 0.0, 0.0, 600.0, 0.0],
        [0.0, 2.0, 20.0, 0.0, 615.0, 0.0],
        [0.0, 20.0, 2.0, 0.0, 651.0, 0.0],
        [0.0, -19.0, -4.0, 0.0, 649.0, 0.0],
        [0.0, -2.0, -20.0, 0.0, 617.0, 0.0],
        [0.0, -11.0, 16.0, 0.0, 623.0, 0.0],
    ]
    .into_iter()
    .map(pose)
    .collect()
}

/// The pipeline's prior for a body pose, from the nominal mount.
fn pipeline_prior(ground_from_robot: &Transform) -> GroundPrior {
    ground_prior(
        Some(&NominalMount::from_values(NOMINAL_MOUNT)),
        ground_from_robot,
    )
}

/// Renders one frame and fits the ground; returns (angle °, height error mm).
fn fit_error(
    world: &World,
    model: DepthModel,
    body: &Transform,
    prior: &GroundPrior,
    seed: u64,
) -> (f64, f64) {
    let ground_from_sensor = body * pose(TRUE_MOUNT);
    let (fit, truth) = fit_frame(
        world,
        model,
        &ground_from_sensor,
        prior,
        seed,
        GroundFitMethod::Disparity,
        DepthRange::default(),
    );
    let fit = fit.unwrap();
    (
        fit.plane.angle_to(&truth).to_degrees(),
        (fit.plane.d - truth.d).abs() * 1e3,
    )
}

/// Renders one frame seen from `ground_from_sensor` and fits its ground;
/// returns the fit and the true ground.
fn fit_frame(
    world: &World,
    model: DepthModel,
    ground_from_sensor: &Transform,
    prior: &GroundPrior,
    seed: u64,
    method: GroundFitMethod,
    range: DepthRange,
) -> (Result<GroundFit, PlaneFitError>, Plane) {
    let config = SimKinectConfig {
        depth_model: model,
        seed,
        ..SimKinectConfig::independent_noise()
    };
    let renderer = DepthRenderer::new(&config).unwrap();
    let raw = renderer.render(world, ground_from_sensor, 0);
    let camera = DepthCamera::new(DepthEncoding::Raw11(model), config.intrinsics, range);
    let settings = PlaneFitSettings {
        method,
        ..Default::default()
    };
    let fit = fit_ground(
        &[&raw],
        &camera,
        prior,
        &settings,
        &mut FitBuffers::default(),
    );
    (fit, ground_in_sensor(ground_from_sensor))
}

#[test]
fn the_nominal_mount_is_within_ten_degrees_of_the_truth() {
    let (truth, nominal) = (pose(TRUE_MOUNT), pose(NOMINAL_MOUNT));
    let angle = (truth.rotation.inverse() * nominal.rotation)
        .angle()
        .to_degrees();
    assert!(angle < 10.0, "{angle}°");
}

#[test]
fn flat_ground_is_fitted_to_the_truth() {
    let world = World::flat();
    let mut worst: (f64, f64) = (0.0, 0.0);
    for model in [DepthModel::default(), DepthModel::inverse_linear_default()] {
        for (i, body) in body_poses().iter().enumerate() {
            // The `groundcal plane` prior: up in the image, within 60°.
            let prior = GroundPrior::up_only(nalgebra::Vector3::y(), 60f64.to_radians());
            let (angle, height) = fit_error(&world, model, body, &prior, i as u64);
            assert!(
                angle < 0.05 && height < 1.0,
                "pose {i}: {angle}°, {height} mm"
            );
            worst = (worst.0.max(angle), worst.1.max(height));
        }
    }
    println!("flat: worst {:.4}°, {:.3} mm", worst.0, worst.1);
}

#[test]
fn ground_among_boxes_and_a_wall_is_fitted_to_the_truth_with_the_pipelines_prior() {
    let mut worst: (f64, f64) = (0.0, 0.0);
    for seed in 0..4 {
        let world = World::boxes_and_wall(seed);
        for model in [DepthModel::default(), DepthModel::inverse_linear_default()] {
            for (i, body) in body_poses().iter().enumerate() {
                let prior = pipeline_prior(body);
                let (angle, height) = fit_error(&world, model, body, &prior, seed);
                assert!(
                    angle < 0.05 && height < 1.0,
                    "seed {seed}, pose {i}: {angle}°, {height} mm"
                );
                worst = (worst.0.max(angle), worst.1.max(height));
            }
        }
    }
    println!("boxes and wall: worst {:.4}°, {:.3} mm", worst.0, worst.1);
}

/// Mean and standard error of the mean.
fn mean_and_standard_error(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (variance / n).sqrt())
}

/// The error of d (mm) over `count` seeded sensor poses looking at flat
/// ground 1–4 m away (the fit trusts only that range): heights 0.8–1.5 m,
/// pitched 25–50° down, rolled up to ±8°.
fn d_errors(model: DepthModel, method: GroundFitMethod, count: u64) -> Vec<f64> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let range = DepthRange {
        min_m: 1.0,
        max_m: 4.0,
    };
    (0..count)
        .map(|seed| {
            let ground_from_sensor = PoseParams::new(
                rng.gen_range(-0.5..0.5),
                -rng.gen_range(25f64..50.0).to_radians(),
                rng.gen_range(-8f64..8.0).to_radians(),
                nalgebra::Vector3::new(0.0, rng.gen_range(0.8..1.5), 0.0),
            )
            .to_transform();
            let truth = ground_in_sensor(&ground_from_sensor);
            let prior = GroundPrior {
                up: truth.normal,
                up_tolerance: 15f64.to_radians(),
                height: Some((truth.d, 0.2)),
            };
            let (fit, _) = fit_frame(
                &World::flat(),
                model,
                &ground_from_sensor,
                &prior,
                1000 + seed,
                method,
                range,
            );
            (fit.unwrap().plane.d - truth.d) * 1e3
        })
        .collect()
}

#[test]
fn the_disparity_fit_is_unbiased_where_the_papers_is_not() {
    for model in [DepthModel::default(), DepthModel::inverse_linear_default()] {
        let disparity = d_errors(model, GroundFitMethod::Disparity, 200);
        let (mean, se) = mean_and_standard_error(&disparity);
        println!("{model:?}: disparity fit, mean d error {mean:+.4} mm ± {se:.4} (SE)");
        assert!(
            mean.abs() <= 3.0 * se && mean.abs() <= 0.02,
            "{model:?}: mean d error {mean} mm, SE {se} mm"
        );
        // The paper's fit on the same frames is biased towards the sensor.
        let paper = d_errors(model, GroundFitMethod::Paper, 200);
        let (mean, se) = mean_and_standard_error(&paper);
        println!("{model:?}: paper fit, mean d error {mean:+.4} mm ± {se:.4} (SE)");
        assert!(
            mean < -3.0 * se,
            "{model:?}: the paper's fit shows no bias ({mean} mm, SE {se} mm)"
        );
    }
}

/// Pixels of a frame of `world` that see the ground: those equal to a frame
/// of the flat world with the same noise, among the valid ones.
fn ground_share(world: &World, model: DepthModel, ground_from_sensor: &Transform) -> f64 {
    let config = SimKinectConfig {
        depth_model: model,
        ..SimKinectConfig::independent_noise()
    };
    let renderer = DepthRenderer::new(&config).unwrap();
    let scene = renderer.render(world, ground_from_sensor, 0);
    let flat = renderer.render(&World::flat(), ground_from_sensor, 0);
    let valid = scene.iter().filter(|&&r| r < 2047).count();
    let ground = scene
        .iter()
        .zip(&flat)
        .filter(|(s, f)| **s < 2047 && s == f)
        .count();
    ground as f64 / valid as f64
}

#[test]
fn the_floor_is_found_when_it_is_a_tenth_of_the_view() {
    let mut shares = Vec::new();
    let mut found_at_a_tenth = 0;
    for seed in 0..3 {
        let world = World::corridor(seed);
        for model in [DepthModel::default(), DepthModel::inverse_linear_default()] {
            for (i, body) in body_poses().iter().enumerate() {
                let ground_from_sensor = body * pose(TRUE_MOUNT);
                let share = ground_share(&world, model, &ground_from_sensor);
                shares.push(share);
                let prior = pipeline_prior(body);
                let (fit, truth) = fit_frame(
                    &world,
                    model,
                    &ground_from_sensor,
                    &prior,
                    seed,
                    GroundFitMethod::Disparity,
                    DepthRange::default(),
                );
                let what = format!(
                    "seed {seed}, pose {i}, floor {:.1} % of the view",
                    share * 100.0
                );
                println!("{what}: {:?}", fit.as_ref().map(|f| f.plane.d - truth.d));
                match fit {
                    Ok(fit) => {
                        let (angle, height) = (
                            fit.plane.angle_to(&truth).to_degrees(),
                            (fit.plane.d - truth.d).abs() * 1e3,
                        );
                        // A small patch of floor tells its tilt less well.
                        assert!(angle < 0.1 && height < 1.0, "{what}: {angle}°, {height} mm");
                        if share <= 0.12 {
                            found_at_a_tenth += 1;
                        }
                    }
                    // Only a floor that is hardly in view may be missed, and
                    // then with an error, never a wrong plane.
                    Err(e) => assert!(share < 0.03, "{what}: {e}"),
                }
            }
        }
    }
    let small = shares.iter().filter(|s| (0.03..=0.12).contains(*s)).count();
    println!(
        "corridor: the floor was 3–12 % of the valid pixels in {small} of {} frames, and found wherever it was at most 12 %: {found_at_a_tenth} times",
        shares.len()
    );
    assert!(small >= 10, "only {small} frames show a floor of 3–12 %");
    assert!(
        found_at_a_tenth >= small,
        "found only {found_at_a_tenth} times"
    );
}
