//! Property tests of the identification: ground truths built with a seeded
//! RNG, noise added, and the truth recovered within the predicted uncertainty.

use groundcal::calib::calibrate::{calibrate, CalibrationSettings};
use groundcal::calib::geometry::{Plane, PoseParams};
use groundcal::calib::outcome::{Calibration, Verdict};
use groundcal::calib::solve::{predict, Observation};
use nalgebra::{Matrix4, Vector3};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn gaussian(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.gen_range(f64::EPSILON..1.0);
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

fn random_mount(rng: &mut impl Rng) -> PoseParams {
    PoseParams::new(
        rng.gen_range(-10f64..10.0).to_radians(),
        rng.gen_range(-50f64..-20.0).to_radians(),
        rng.gen_range(-10f64..10.0).to_radians(),
        Vector3::new(
            rng.gen_range(0.3..0.7),
            rng.gen_range(0.2..0.5),
            rng.gen_range(-0.1..0.1),
        ),
    )
}

/// A schedule in the spirit of Table A1: tilts up to ±20°, heights 0.6–0.75 m,
/// with the small real offsets of a robot that does not reach its commands.
fn random_schedule(rng: &mut impl Rng, poses: usize) -> Vec<PoseParams> {
    (0..poses)
        .map(|_| {
            PoseParams::new(
                rng.gen_range(-0.5f64..0.5).to_radians(),
                rng.gen_range(-20f64..20.0).to_radians(),
                rng.gen_range(-20f64..20.0).to_radians(),
                Vector3::new(
                    rng.gen_range(-0.002..0.002),
                    rng.gen_range(0.6..0.75),
                    rng.gen_range(-0.002..0.002),
                ),
            )
        })
        .collect()
}

/// The measured plane: the true one with its normal tilted by a Gaussian of
/// `sigma_n` per tangent direction and its offset moved by one of `sigma_d`.
fn measure(truth: &Plane, sigma_n: f64, sigma_d: f64, rng: &mut impl Rng) -> Plane {
    let helper = if truth.normal.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = truth.normal.cross(&helper).normalize();
    let e2 = truth.normal.cross(&e1);
    let normal =
        (truth.normal + e1 * gaussian(rng) * sigma_n + e2 * gaussian(rng) * sigma_n).normalize();
    Plane {
        normal,
        d: truth.d + gaussian(rng) * sigma_d,
    }
}

/// The plane covariance a fit with this noise would report.
fn covariance(plane: &Plane, sigma_n: f64, sigma_d: f64) -> Matrix4<f64> {
    let mut c = Matrix4::zeros();
    let tangent = nalgebra::Matrix3::identity() - plane.normal * plane.normal.transpose();
    c.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(tangent * sigma_n * sigma_n));
    c[(3, 3)] = sigma_d * sigma_d;
    c
}

/// Observations of `mount` from every pose of `schedule`: the true ground
/// of each pose, passed through `measured` (exact, noisy, ...).
fn observe(
    mount: &PoseParams,
    schedule: &[PoseParams],
    mut measured: impl FnMut(&Plane) -> Plane,
) -> Vec<Observation> {
    schedule
        .iter()
        .enumerate()
        .map(|(i, pose)| {
            let g = pose.to_transform();
            Observation::new(i as u32 + 1, g, measured(&predict(mount, &g)))
        })
        .collect()
}

/// Monte-Carlo coverage: in ≥ 99 % of (case, parameter) pairs the error is
/// within 4 predicted σ, with and without the fits' covariances.
#[test]
fn recovered_parameters_lie_within_four_predicted_sigma() {
    let mut rng = ChaCha8Rng::seed_from_u64(20261123);
    let settings = CalibrationSettings::default();
    let (mut within, mut total, mut worst) = (0usize, 0usize, 0.0f64);
    for case in 0..400 {
        let mount = random_mount(&mut rng);
        let poses = rng.gen_range(12..=52);
        let schedule = random_schedule(&mut rng, poses);
        let sigma_n = rng.gen_range(0.02f64..0.5).to_radians();
        let sigma_d = rng.gen_range(0.0002..0.003);
        let with_covariance = case % 2 == 0;
        let observations: Vec<Observation> = schedule
            .iter()
            .enumerate()
            .map(|(i, pose)| {
                let g = pose.to_transform();
                let truth = predict(&mount, &g);
                let mut o =
                    Observation::new(i as u32 + 1, g, measure(&truth, sigma_n, sigma_d, &mut rng));
                if with_covariance {
                    o.plane_covariance = Some(covariance(&truth, sigma_n, sigma_d));
                }
                o
            })
            .collect();
        let result = calibrate(&observations, &settings).expect("enough poses");
        let error = result.robot_from_sensor.to_vector() - mount.to_vector();
        let sigma = result.sigma();
        for k in 0..6 {
            let z = error[k].abs() / sigma[k];
            worst = worst.max(z);
            total += 1;
            if z <= 4.0 {
                within += 1;
            }
        }
    }
    let fraction = within as f64 / total as f64;
    eprintln!(
        "coverage: {:.2}% of {total} within 4σ, worst {worst:.2}σ",
        100.0 * fraction
    );
    assert!(
        fraction >= 0.99,
        "only {:.2}% within 4σ (worst {worst:.1}σ)",
        100.0 * fraction
    );
}

/// The predicted σ is not a blanket: it shrinks with less noise.
#[test]
fn predicted_sigma_follows_the_noise() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mount = random_mount(&mut rng);
    let schedule = random_schedule(&mut rng, 52);
    let solve_with = |sigma_n: f64, rng: &mut ChaCha8Rng| {
        let obs: Vec<Observation> = observe(&mount, &schedule, |truth| {
            measure(truth, sigma_n, 0.001, rng)
        });
        calibrate(&obs, &CalibrationSettings::default())
            .unwrap()
            .sigma()
    };
    let noisy = solve_with(0.3f64.to_radians(), &mut rng);
    let quiet = solve_with(0.03f64.to_radians(), &mut rng);
    for k in 0..3 {
        let ratio = noisy[k] / quiet[k];
        assert!(
            (5.0..20.0).contains(&ratio),
            "σ ratio {ratio} for angle {k}"
        );
    }
}

fn schedule_result(schedule: &[PoseParams]) -> Calibration {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mount = random_mount(&mut rng);
    let obs: Vec<Observation> = observe(&mount, schedule, |truth| {
        measure(truth, 0.001, 0.0005, &mut rng)
    });
    calibrate(&obs, &CalibrationSettings::default()).unwrap()
}

#[test]
fn a_schedule_that_never_tilts_is_rejected_with_words() {
    let schedule: Vec<PoseParams> = (0..20)
        .map(|i| {
            PoseParams::new(
                0.0,
                0.0,
                0.0,
                Vector3::new(0.0, 0.6 + 0.007 * i as f64, 0.0),
            )
        })
        .collect();
    let result = schedule_result(&schedule);
    assert_eq!(result.verdict, Verdict::Rejected);
    let text = result.reasons.join("\n");
    assert!(
        text.contains("rotation of the sensor about the ground normal (α) is not observable"),
        "{text}"
    );
    assert!(text.contains("the schedule never tilts the body"), "{text}");
}

#[test]
fn a_schedule_that_only_pitches_cannot_see_the_sideways_position() {
    let schedule: Vec<PoseParams> = (0..20)
        .map(|i| {
            PoseParams::new(
                0.0,
                (-20.0 + 2.0 * i as f64).to_radians(),
                0.0,
                Vector3::new(0.0, 0.65, 0.0),
            )
        })
        .collect();
    let result = schedule_result(&schedule);
    assert_eq!(result.verdict, Verdict::Rejected);
    let text = result.reasons.join("\n");
    assert!(
        text.contains(
            "sideways (p_z) position is not observable: the schedule only pitches the body"
        ),
        "{text}"
    );
    assert!(
        !text.contains("rotation"),
        "the rotation is observable: {text}"
    );
}

#[test]
fn a_schedule_that_only_rolls_cannot_see_the_forward_position() {
    let schedule: Vec<PoseParams> = (0..20)
        .map(|i| {
            PoseParams::new(
                0.0,
                0.0,
                (-20.0 + 2.0 * i as f64).to_radians(),
                Vector3::new(0.0, 0.65, 0.0),
            )
        })
        .collect();
    let result = schedule_result(&schedule);
    assert_eq!(result.verdict, Verdict::Rejected);
    let text = result.reasons.join("\n");
    assert!(
        text.contains("forward (p_x) position is not observable: the schedule only rolls the body"),
        "{text}"
    );
}

#[test]
fn a_good_schedule_with_little_noise_is_accepted() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let schedule = random_schedule(&mut rng, 52);
    let result = schedule_result(&schedule);
    assert_eq!(result.verdict, Verdict::Accepted, "{:?}", result.reasons);
    assert!(result.reasons.is_empty());
}

#[test]
fn a_pose_set_aside_beforehand_keeps_its_reason_and_is_not_used() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let mount = random_mount(&mut rng);
    let schedule = random_schedule(&mut rng, 20);
    let mut obs: Vec<Observation> = observe(&mount, &schedule, |truth| *truth);
    // A slipped foot: the body pose is wrong by 3° and 2 cm.
    obs[4].ground_from_robot = PoseParams::new(0.0, 0.05, 0.0, Vector3::new(0.0, 0.02, 0.0))
        .to_transform()
        * obs[4].ground_from_robot;
    obs[4].set_aside = Some("foot 3 slipped (31 mm)".into());
    let result = calibrate(&obs, &CalibrationSettings::default()).unwrap();
    let pose = &result.poses[4];
    assert!(!pose.used);
    assert_eq!(pose.reason.as_deref(), Some("foot 3 slipped (31 mm)"));
    assert!((result.robot_from_sensor.to_vector() - mount.to_vector()).amax() < 1e-8);
}

#[test]
fn gross_errors_in_a_few_poses_are_set_aside_and_do_not_move_the_result() {
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let mount = random_mount(&mut rng);
    let schedule = random_schedule(&mut rng, 52);
    let mut obs: Vec<Observation> = observe(&mount, &schedule, |truth| {
        measure(truth, 0.1f64.to_radians(), 0.0005, &mut rng)
    });
    // A typo in a table (sign of c), a box top fitted instead of the ground,
    // and a pose whose body height is wrong.
    obs[7].plane.normal.z = -obs[7].plane.normal.z;
    obs[20].plane.d -= 0.12;
    obs[33].ground_from_robot.translation.vector.y += 0.05;
    let result = calibrate(&obs, &CalibrationSettings::default()).unwrap();
    let aside: Vec<u32> = result
        .poses
        .iter()
        .filter(|p| !p.used)
        .map(|p| p.index)
        .collect();
    assert_eq!(aside, vec![8, 21, 34]);
    let error = result.robot_from_sensor.to_vector() - mount.to_vector();
    let sigma = result.sigma();
    for k in 0..6 {
        assert!(
            error[k].abs() < 4.0 * sigma[k],
            "parameter {k}: error {} vs σ {}",
            error[k],
            sigma[k]
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    /// Exact planes from any mount and any tilting schedule give that mount
    /// back, with no initial guess.
    #[test]
    fn exact_planes_recover_any_mount(
        alpha in -30f64..30.0, beta in -60f64..0.0, gamma in -30f64..30.0,
        px in 0.0f64..0.8, py in 0.1f64..0.6, pz in -0.3f64..0.3, seed in any::<u64>(),
    ) {
        let mount = PoseParams::new(alpha.to_radians(), beta.to_radians(), gamma.to_radians(), Vector3::new(px, py, pz));
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let obs: Vec<Observation> = observe(&mount, &random_schedule(&mut rng, 12), |truth| *truth);
        let result = calibrate(&obs, &CalibrationSettings::default()).unwrap();
        prop_assert!((result.robot_from_sensor.to_vector() - mount.to_vector()).amax() < 1e-7);
        prop_assert!(result.poses.iter().all(|p| p.used));
    }

    /// The six parameters survive the matrix and the quaternion.
    #[test]
    fn parameters_round_trip(alpha in -3.1f64..3.1, beta in -1.5f64..1.5, gamma in -3.1f64..3.1,
                             x in -2.0f64..2.0, y in -2.0f64..2.0, z in -2.0f64..2.0) {
        let p = PoseParams::new(alpha, beta, gamma, Vector3::new(x, y, z));
        let back = PoseParams::from_transform(&p.to_transform());
        prop_assert!((back.to_vector() - p.to_vector()).amax() < 1e-9);
        let back = PoseParams::from_quaternion(&p.quaternion(), p.translation);
        prop_assert!((back.to_vector() - p.to_vector()).amax() < 1e-9);
    }
}
