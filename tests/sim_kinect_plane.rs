//! The simulated Kinect's frames through the calibration's own ground fit:
//! raw frames to points as `groundcal plane` and the replay do
//! (`DepthCamera`), fitted by `fit_ground`, give the true ground of
//! conventions.md (row 1 of `ground_from_sensor`) within 0.05° and 1 mm, on
//! flat ground and with boxes and a wall in view, where the ground is chosen
//! by the prior the pipeline makes from a nominal mount.

use groundcal::calib::geometry::{ground_in_sensor, PoseDegMm, Transform};
use groundcal::calib::plane::{fit_ground, GroundPrior, PlaneFitSettings};
use groundcal::calib::sensor::{DepthCamera, DepthEncoding, DepthModel, DepthRange};
use groundcal::pipeline::{nominal_mount_from_values, PoseProcessor, PoseSettings};
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
fn pipeline_prior(model: DepthModel, ground_from_robot: &Transform) -> GroundPrior {
    let home_feet_mm = [
        [692.8, -600.0, 400.0],
        [0.0, -600.0, 800.0],
        [-692.8, -600.0, 400.0],
        [-692.8, -600.0, -400.0],
        [0.0, -600.0, -800.0],
        [692.8, -600.0, -400.0],
    ];
    let processor = PoseProcessor::new(
        model,
        SimKinectConfig::default().intrinsics,
        &home_feet_mm,
        Some(nominal_mount_from_values(NOMINAL_MOUNT)),
        PoseSettings::default(),
    )
    .unwrap();
    processor.prior(ground_from_robot)
}

/// Renders one frame and fits the ground; returns (angle °, height error mm).
fn fit_error(
    world: &World,
    model: DepthModel,
    body: &Transform,
    prior: &GroundPrior,
    seed: u64,
) -> (f64, f64) {
    let config = SimKinectConfig {
        depth_model: model,
        seed,
        ..Default::default()
    };
    let renderer = DepthRenderer::new(&config).unwrap();
    let ground_from_sensor = body * pose(TRUE_MOUNT);
    let raw = renderer.render(world, &ground_from_sensor, 0);
    let camera = DepthCamera::new(
        DepthEncoding::Raw11(model),
        config.intrinsics,
        DepthRange::default(),
    );
    let cloud = camera.points(&raw);
    let fit = fit_ground(&[&cloud], prior, &PlaneFitSettings::default()).unwrap();
    let truth = ground_in_sensor(&ground_from_sensor);
    (
        fit.plane.angle_to(&truth).to_degrees(),
        (fit.plane.d - truth.d).abs() * 1e3,
    )
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
                let prior = pipeline_prior(model, body);
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
