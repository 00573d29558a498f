//! The simulated Kinect against the geometry it claims: flat ground fitted
//! from its frames is the true ground of conventions.md, boxes and walls are
//! where they stand, the sensor's artefacts are where a Kinect has them, and
//! its clock runs on tokio's (pausable) time.
//!
//! Everything here uses the hardware crate alone: points come from the frames
//! through `DepthModel::depth_m`, the inverse of what the renderer did.

use std::time::Duration;

use groundcal_calib::depth::{DepthModel, Intrinsics, RAW_NO_READING};
use groundcal_calib::geometry::{ground_in_sensor, sensor_from_optical, PoseDegMm, Transform};
use groundcal_hal::sim::kinect::{DepthRenderer, SimKinect, SimKinectConfig};
use groundcal_hal::sim::robot::REFERENCE_HOME;
use groundcal_hal::sim::world::{Ground, Surface, World};
use groundcal_hal::sim::TruePose;
use groundcal_hal::DepthSensor;
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

/// The mount of the shared sample recording's `nominal_mount`: pitched 30.7°
/// down, half a metre ahead of the body's origin.
fn mount() -> Transform {
    PoseDegMm {
        alpha_deg: 4.5,
        beta_deg: -30.7,
        gamma_deg: -2.0,
        px_mm: 491.3,
        py_mm: 331.6,
        pz_mm: 8.7,
    }
    .to_params()
    .to_transform()
}

/// Body poses of octopus-52 (Table A1) spanning its range, and the home stance.
fn body_poses() -> Vec<Transform> {
    [
        (0.0, 0.0, 0.0, 600.0),
        (0.0, 2.0, 20.0, 615.0),
        (0.0, 20.0, 2.0, 651.0),
        (0.0, -19.0, -4.0, 649.0),
        (0.0, -2.0, -20.0, 617.0),
    ]
    .iter()
    .map(|&(a, b, g, py)| {
        PoseDegMm {
            alpha_deg: a,
            beta_deg: b,
            gamma_deg: g,
            px_mm: 0.0,
            py_mm: py,
            pz_mm: 0.0,
        }
        .to_params()
        .to_transform()
    })
    .collect()
}

fn config(model: DepthModel) -> SimKinectConfig {
    SimKinectConfig {
        depth_model: model,
        seed: 42,
        ..SimKinectConfig::independent_noise()
    }
}

/// Back-projects a raw frame into the sensor frame V (X forward, Y up, Z right).
fn points(raw: &[u16], model: &DepthModel, k: &Intrinsics) -> Vec<Vector3<f64>> {
    let mut out = Vec::new();
    for v in 0..k.height {
        for u in 0..k.width {
            if let Some(z) = model.depth_m(raw[v * k.width + u]) {
                let optical = Vector3::new(
                    (u as f64 - k.cx) * z / k.fx,
                    (v as f64 - k.cy) * z / k.fy,
                    z,
                );
                out.push(sensor_from_optical() * optical);
            }
        }
    }
    out
}

/// Total least squares plane `n·p + d = 0`, `d > 0`: the eigenvector of the
/// scatter's smallest eigenvalue through the centroid.
fn fit_plane(points: &[Vector3<f64>]) -> (Vector3<f64>, f64) {
    let centroid = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let mut scatter = Matrix3::zeros();
    for p in points {
        let q = p - centroid;
        scatter += q * q.transpose();
    }
    let eigen = SymmetricEigen::new(scatter);
    let i = eigen.eigenvalues.imin();
    let mut n = eigen.eigenvectors.column(i).into_owned();
    let mut d = -n.dot(&centroid);
    if d < 0.0 {
        n = -n;
        d = -d;
    }
    (n, d)
}

fn angle_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b)).to_degrees()
}

/// The optical ray of pixel (u, v) in G, with optical z = 1 (its ray parameter is the depth).
fn pixel_ray(ground_from_sensor: &Transform, k: &Intrinsics, u: f64, v: f64) -> Vector3<f64> {
    ground_from_sensor.rotation
        * (sensor_from_optical() * Vector3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0))
}

/// The pixel (rounded) a ground point projects to, if in the image.
fn project(
    ground_from_sensor: &Transform,
    k: &Intrinsics,
    p: &Point3<f64>,
) -> Option<(usize, usize)> {
    let sensor = ground_from_sensor.inverse() * p;
    let optical = sensor_from_optical().transpose() * sensor.coords;
    if optical.z <= 0.0 {
        return None;
    }
    let u = (k.fx * optical.x / optical.z + k.cx).round();
    let v = (k.fy * optical.y / optical.z + k.cy).round();
    ((0.0..k.width as f64).contains(&u) && (0.0..k.height as f64).contains(&v))
        .then_some((u as usize, v as usize))
}

#[test]
fn flat_ground_fits_the_true_plane_for_both_models() {
    let world = World::flat();
    let mut worst = (0.0f64, 0.0f64);
    for model in [DepthModel::default(), DepthModel::inverse_linear_default()] {
        let renderer = DepthRenderer::new(&config(model)).unwrap();
        let k = renderer.config().intrinsics;
        for (i, body) in body_poses().iter().enumerate() {
            let ground_from_sensor = body * mount();
            let raw = renderer.render(&world, &ground_from_sensor, i as u64);
            let pts = points(&raw, &model, &k);
            assert!(pts.len() > 100_000, "pose {i}: only {} points", pts.len());
            let (n, d) = fit_plane(&pts);
            let truth = ground_in_sensor(&ground_from_sensor);
            let angle = angle_deg(&n, &truth.normal);
            let offset_mm = (d - truth.d).abs() * 1e3;
            println!(
                "{model:?} pose {i}: {angle:.4}° {offset_mm:.3} mm, {} points",
                pts.len()
            );
            assert!(angle < 0.05, "pose {i}: normal {angle}° off");
            assert!(offset_mm < 1.0, "pose {i}: height {offset_mm} mm off");
            worst = (worst.0.max(angle), worst.1.max(offset_mm));
        }
    }
    println!("worst: {:.4}° {:.3} mm", worst.0, worst.1);
}

#[test]
fn frames_are_deterministic_per_seed_and_frame() {
    let world = World::boxes_and_wall(1);
    let ground_from_sensor = body_poses()[1] * mount();
    let a = DepthRenderer::new(&config(DepthModel::default())).unwrap();
    let b = DepthRenderer::new(&config(DepthModel::default())).unwrap();
    let first = a.render(&world, &ground_from_sensor, 3);
    assert_eq!(first, b.render(&world, &ground_from_sensor, 3));
    // Another frame, or another seed, has other noise.
    assert_ne!(first, a.render(&world, &ground_from_sensor, 4));
    let other = DepthRenderer::new(&SimKinectConfig {
        seed: 43,
        ..config(DepthModel::default())
    })
    .unwrap();
    assert_ne!(first, other.render(&world, &ground_from_sensor, 3));
    // The same on one thread as on many.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    assert_eq!(
        first,
        pool.install(|| a.render(&world, &ground_from_sensor, 3))
    );
}

#[test]
fn dead_border_out_of_range_and_sky_are_no_reading() {
    let world = World::flat();
    let cfg = SimKinectConfig {
        noise_scale: 0.0,
        dropout_rate: 0.0,
        grazing_dropout: 0.0,
        ..config(DepthModel::inverse_linear_default())
    };
    let renderer = DepthRenderer::new(&cfg).unwrap();
    let k = cfg.intrinsics;
    let mut seen_near = false;
    let mut seen_far = false;
    // Pitched up: the top rows see the sky; and low over the ground, pitched
    // down, the bottom rows are nearer than 0.5 m.
    for (body, name) in [(body_poses()[2], "pitched up"), (body_poses()[0], "home")] {
        let ground_from_sensor = body * mount();
        let raw = renderer.render(&world, &ground_from_sensor, 0);
        for v in 0..k.height {
            for u in 0..k.width {
                let value = raw[v * k.width + u];
                if u >= k.width - 8 {
                    assert_eq!(value, RAW_NO_READING, "{name}: dead column {u}");
                    continue;
                }
                let direction = pixel_ray(&ground_from_sensor, &k, u as f64, v as f64);
                let origin = Point3::from(ground_from_sensor.translation.vector);
                match world.hit(&origin, &direction) {
                    Some(z) if (0.5..=5.0).contains(&z) => {
                        // A half raw step off the limits may round either way.
                        if (0.52..=4.9).contains(&z) {
                            assert_ne!(value, RAW_NO_READING, "{name}: ({u}, {v}) at {z} m");
                        }
                    }
                    Some(z) => {
                        seen_near |= z < 0.5;
                        seen_far |= z > 5.0;
                        if !(0.49..=5.1).contains(&z) {
                            assert_eq!(value, RAW_NO_READING, "{name}: ({u}, {v}) at {z} m");
                        }
                    }
                    None => assert_eq!(value, RAW_NO_READING, "{name}: sky at ({u}, {v})"),
                }
            }
        }
    }
    assert!(seen_far, "no pixel beyond 5 m was tested");
    // A sensor low over the ground, looking down steeply, sees it nearer than 0.5 m.
    let low = PoseDegMm {
        alpha_deg: 0.0,
        beta_deg: -60.0,
        gamma_deg: 0.0,
        px_mm: 0.0,
        py_mm: 450.0,
        pz_mm: 0.0,
    }
    .to_params()
    .to_transform();
    let raw = renderer.render(&world, &low, 0);
    let origin = Point3::from(low.translation.vector);
    for v in (0..k.height).step_by(7) {
        for u in (0..k.width - 8).step_by(7) {
            let z = world
                .hit(&origin, &pixel_ray(&low, &k, u as f64, v as f64))
                .unwrap();
            if z < 0.49 {
                seen_near = true;
                assert_eq!(raw[v * k.width + u], RAW_NO_READING);
            }
        }
    }
    assert!(seen_near, "no pixel nearer than 0.5 m was tested");
}

#[test]
fn every_pixel_is_the_quantised_depth_of_its_ray() {
    // Without noise, dropouts and shadows, a frame is the world's depth along
    // each pixel's ray, quantised: what the renderer's shortcuts (obstacle
    // rectangles, Newton started at the neighbour's height) must not change.
    for (world, model) in [
        (World::boxes_and_wall(3), DepthModel::default()),
        (
            World::boxes_and_wall(4),
            DepthModel::inverse_linear_default(),
        ),
        (World::uneven(2, 0.02), DepthModel::default()),
    ] {
        let cfg = SimKinectConfig {
            noise_scale: 0.0,
            dropout_rate: 0.0,
            grazing_dropout: 0.0,
            emitter_baseline_m: 0.0,
            ..config(model)
        };
        let renderer = DepthRenderer::new(&cfg).unwrap();
        let k = cfg.intrinsics;
        for body in body_poses() {
            let ground_from_sensor = body * mount();
            let raw = renderer.render(&world, &ground_from_sensor, 0);
            let origin = Point3::from(ground_from_sensor.translation.vector);
            for v in 0..k.height {
                for u in 0..k.width - 8 {
                    let direction = pixel_ray(&ground_from_sensor, &k, u as f64, v as f64);
                    let expected = world
                        .cast(&origin, &direction, 10.0)
                        .map_or(RAW_NO_READING, |hit| renderer.quantise(hit.t));
                    assert_eq!(raw[v * k.width + u], expected, "({u}, {v})");
                }
            }
        }
    }
}

#[test]
fn random_dropouts_are_about_the_configured_rate() {
    let world = World::flat();
    let renderer = DepthRenderer::new(&SimKinectConfig {
        grazing_dropout: 0.0,
        ..config(DepthModel::default())
    })
    .unwrap();
    let k = renderer.config().intrinsics;
    // Looking steeply down from 0.9 m: every live pixel sees ground in range.
    let down = PoseDegMm {
        alpha_deg: 0.0,
        beta_deg: -70.0,
        gamma_deg: 0.0,
        px_mm: 0.0,
        py_mm: 1200.0,
        pz_mm: 0.0,
    }
    .to_params()
    .to_transform();
    let raw = renderer.render(&world, &down, 0);
    let live = k.height * (k.width - 8);
    let lost = (0..k.height)
        .flat_map(|v| (0..k.width - 8).map(move |u| (u, v)))
        .filter(|&(u, v)| raw[v * k.width + u] == RAW_NO_READING)
        .count();
    let rate = lost as f64 / live as f64;
    assert!((0.008..0.012).contains(&rate), "dropout rate {rate}");
}

#[test]
fn grazing_ground_loses_more_pixels_than_steep_ground() {
    let world = World::flat();
    let renderer = DepthRenderer::new(&config(DepthModel::default())).unwrap();
    let k = renderer.config().intrinsics;
    let ground_from_sensor = body_poses()[0] * mount();
    let raw = renderer.render(&world, &ground_from_sensor, 0);
    let origin = Point3::from(ground_from_sensor.translation.vector);
    let (mut steep, mut steep_lost, mut grazing, mut grazing_lost) = (0, 0, 0, 0);
    for v in 0..k.height {
        for u in 0..k.width - 8 {
            let direction = pixel_ray(&ground_from_sensor, &k, u as f64, v as f64);
            let Some(z) = world.hit(&origin, &direction) else {
                continue;
            };
            if !(0.6..4.8).contains(&z) {
                continue;
            }
            let cos = direction.y.abs() / direction.norm();
            let lost = raw[v * k.width + u] == RAW_NO_READING;
            if cos > 0.3 {
                steep += 1;
                steep_lost += lost as usize;
            } else if cos < 0.22 {
                grazing += 1;
                grazing_lost += lost as usize;
            }
        }
    }
    let (steep_rate, grazing_rate) = (
        steep_lost as f64 / steep as f64,
        grazing_lost as f64 / grazing as f64,
    );
    assert!(grazing > 1000 && steep > 1000);
    assert!(steep_rate < 0.015, "steep {steep_rate}");
    assert!(
        grazing_rate > 2.0 * steep_rate,
        "grazing {grazing_rate}, steep {steep_rate}"
    );
}

#[test]
fn box_tops_and_walls_appear_where_they_stand() {
    let cfg = SimKinectConfig {
        noise_scale: 0.0,
        dropout_rate: 0.0,
        grazing_dropout: 0.0,
        emitter_baseline_m: 0.0,
        ..config(DepthModel::inverse_linear_default())
    };
    let renderer = DepthRenderer::new(&cfg).unwrap();
    let k = cfg.intrinsics;
    let mut checked = 0;
    for seed in 0..10 {
        let world = World::boxes_and_wall(seed);
        for body in body_poses() {
            let ground_from_sensor = body * mount();
            let raw = renderer.render(&world, &ground_from_sensor, 0);
            let origin = Point3::from(ground_from_sensor.translation.vector);
            // The centre of each box's top.
            for b in &world.boxes {
                let top = Point3::new(b.centre_x, b.height, b.centre_z);
                let Some((u, v)) = project(&ground_from_sensor, &k, &top) else {
                    continue;
                };
                if u >= k.width - 8 {
                    continue;
                }
                // The pixel's own ray meets the top's plane at this depth.
                let direction = pixel_ray(&ground_from_sensor, &k, u as f64, v as f64);
                let z = (b.height - origin.y) / direction.y;
                let value = raw[v * k.width + u];
                assert_eq!(
                    value,
                    renderer.quantise(z),
                    "seed {seed}: box top at ({u}, {v})"
                );
                let measured = cfg.depth_model.depth_m(value).unwrap();
                // Within half a raw step (27 mm at 3 m) of the top's depth.
                assert!((measured - z).abs() < 0.5 * 1.4e-2 * z * z);
                checked += 1;
            }
            // The middle of the wall, halfway up.
            let w = world.walls[0];
            let mid = (w.start + w.end) / 2.0;
            let centre = Point3::new(mid.x, w.height / 2.0, mid.y);
            if let Some((u, v)) = project(&ground_from_sensor, &k, &centre) {
                let direction = pixel_ray(&ground_from_sensor, &k, u as f64, v as f64);
                let hit = world.cast(&origin, &direction, 10.0).unwrap();
                if u < k.width - 8 && hit.surface == Surface::Wall(0) && hit.t <= 4.9 {
                    let value = raw[v * k.width + u];
                    assert_eq!(
                        value,
                        renderer.quantise(hit.t),
                        "seed {seed}: wall at ({u}, {v})"
                    );
                    // The depth is the wall plane's along this pixel's ray.
                    let along = (w.end - w.start).normalize();
                    let normal = Vector3::new(-along.y, 0.0, along.x);
                    let start = Vector3::new(w.start.x, 0.0, w.start.y);
                    let z = normal.dot(&(start - origin.coords)) / normal.dot(&direction);
                    assert!((hit.t - z).abs() < 1e-9);
                    checked += 1;
                }
            }
        }
    }
    assert!(
        checked > 50,
        "only {checked} box tops and walls were in view"
    );
}

#[test]
fn ground_stays_most_of_the_image_with_boxes_and_a_wall() {
    let cfg = SimKinectConfig {
        emitter_baseline_m: 0.0,
        ..config(DepthModel::default())
    };
    let k = cfg.intrinsics;
    for seed in 0..10 {
        let world = World::boxes_and_wall(seed);
        let mut seen = [0usize; 2];
        let mut fractions = Vec::new();
        for body in body_poses() {
            let ground_from_sensor = body * mount();
            let origin = Point3::from(ground_from_sensor.translation.vector);
            let (mut ground, mut other) = (0, 0);
            for v in (0..k.height).step_by(4) {
                for u in (0..k.width - 8).step_by(4) {
                    let direction = pixel_ray(&ground_from_sensor, &k, u as f64, v as f64);
                    match world.cast(&origin, &direction, 5.0).map(|h| h.surface) {
                        Some(Surface::Ground) => ground += 1,
                        Some(Surface::Box(_)) => {
                            other += 1;
                            seen[0] += 1
                        }
                        Some(Surface::Wall(_)) => {
                            other += 1;
                            seen[1] += 1
                        }
                        None => {}
                    }
                }
            }
            let fraction = ground as f64 / (ground + other) as f64;
            // Pitched up (octopus-52's β = 20°) the ground within range
            // shrinks and the wall looms largest; the ground is still most.
            assert!(
                fraction > 0.5,
                "seed {seed}: ground is {fraction:.2} of what is in range"
            );
            fractions.push(fraction);
        }
        assert!(
            seen[0] > 0 && seen[1] > 0,
            "seed {seed}: boxes or wall never in view {seen:?}"
        );
        let mean = fractions.iter().sum::<f64>() / fractions.len() as f64;
        assert!(
            mean > 0.65,
            "seed {seed}: ground is {mean:.2} of what is in range on average"
        );
    }
}

#[test]
fn uneven_ground_frames_lie_on_the_surface() {
    let world = World::uneven(5, 0.02);
    let Ground::HeightField(field) = &world.ground else {
        unreachable!()
    };
    let cfg = SimKinectConfig {
        noise_scale: 0.0,
        ..config(DepthModel::default())
    };
    let renderer = DepthRenderer::new(&cfg).unwrap();
    let k = cfg.intrinsics;
    let ground_from_sensor = body_poses()[1] * mount();
    let raw = renderer.render(&world, &ground_from_sensor, 0);
    let origin = Point3::from(ground_from_sensor.translation.vector);
    let mut checked = 0;
    let mut largest_height = 0.0f64;
    for v in (0..k.height).step_by(3) {
        for u in (0..k.width).step_by(3) {
            let Some(measured) = cfg.depth_model.depth_m(raw[v * k.width + u]) else {
                continue;
            };
            let direction = pixel_ray(&ground_from_sensor, &k, u as f64, v as f64);
            let z = world.hit(&origin, &direction).unwrap();
            let p = origin + direction * z;
            assert!((p.y - field.height(p.x, p.z)).abs() < 1e-9);
            largest_height = largest_height.max(p.y.abs());
            // The reading is the surface's depth, quantised.
            assert_eq!(raw[v * k.width + u], renderer.quantise(z));
            assert!((measured - z).abs() < 0.5 * 1.4e-2 * z * z);
            checked += 1;
        }
    }
    assert!(checked > 10_000);
    // The surface is really uneven where it was seen.
    assert!(largest_height > 0.005, "{largest_height}");
}

#[test]
fn box_edges_cast_the_emitters_shadow_on_the_ground() {
    let world = World::boxes_and_wall(2);
    let k = Intrinsics::default();
    let ground_from_sensor = body_poses()[0] * mount();
    let render = |baseline: f64| {
        DepthRenderer::new(&SimKinectConfig {
            emitter_baseline_m: baseline,
            dropout_rate: 0.0,
            grazing_dropout: 0.0,
            ..config(DepthModel::default())
        })
        .unwrap()
        .render(&world, &ground_from_sensor, 0)
    };
    let (lit, shadowed) = (render(0.0), render(0.075));
    let lost: Vec<usize> = (0..lit.len())
        .filter(|&i| lit[i] != RAW_NO_READING && shadowed[i] == RAW_NO_READING)
        .collect();
    assert!(lost.len() > 50, "only {} pixels in shadow", lost.len());
    // Shadows fall only beside obstacles: never where both neighbours ten
    // pixels left and right read the same plain ground depth band.
    assert!(lost.len() < lit.len() / 20);
    // The emitter is to the right of the camera: shadows lie left of edges, so
    // some pixel to the right of each shadow is nearer (an obstacle).
    let with_nearer_right = lost
        .iter()
        .filter(|&&i| {
            let (v, u) = (i / k.width, i % k.width);
            let here = DepthModel::default().depth_m(lit[i]).unwrap();
            (u + 1..(u + 80).min(k.width - 8)).any(|x| {
                DepthModel::default()
                    .depth_m(lit[v * k.width + x])
                    .is_some_and(|d| d < here - 0.05)
            })
        })
        .count();
    assert!(
        with_nearer_right * 10 >= lost.len() * 9,
        "{with_nearer_right} of {}",
        lost.len()
    );
}

fn level_kinect(config: SimKinectConfig) -> (SimKinect, TruePose) {
    let pose = TruePose::new(REFERENCE_HOME.to_params().to_transform());
    let level_mount = PoseDegMm {
        alpha_deg: 0.0,
        beta_deg: 0.0,
        gamma_deg: 0.0,
        px_mm: 500.0,
        py_mm: 300.0,
        pz_mm: 0.0,
    }
    .to_params()
    .to_transform();
    let kinect = SimKinect::new(World::flat(), pose.clone(), level_mount, config).unwrap();
    (kinect, pose)
}

#[tokio::test(start_paused = true)]
async fn accelerometer_and_tilt_follow_the_true_pose() {
    let (mut kinect, pose) = level_kinect(SimKinectConfig {
        accelerometer_noise_g: 0.0,
        ..SimKinectConfig::default()
    });
    let state = kinect.tilt_state().await.unwrap();
    assert_eq!(state.accelerometer_g, [0.0, 1.0, 0.0]);
    assert_eq!(kinect.accelerometer_counts(), [0, 819, 0]);
    assert!(state.stopped);

    // 20° down at 20°/s takes a second, and the sensor then looks 20° down.
    let start = tokio::time::Instant::now();
    kinect.set_tilt(-20.0).await.unwrap();
    assert_eq!(start.elapsed(), Duration::from_secs(1));
    let state = kinect.tilt_state().await.unwrap();
    assert_eq!(state.tilt_deg, -20.0);
    let (s, c) = 20f64.to_radians().sin_cos();
    let expected = [0.0, c, -s];
    // Whole counts, as a real Kinect reports them.
    for (got, want) in state.accelerometer_g.iter().zip(expected) {
        assert!(
            (got - want).abs() <= 0.5 / 819.0,
            "{:?}",
            state.accelerometer_g
        );
        assert_eq!((got * 819.0).fract(), 0.0);
    }
    assert_eq!(kinect.accelerometer_counts(), [0, 770, -280]);

    // The body rolls right by 10°: the accelerometer sees it.
    pose.set(
        PoseDegMm {
            gamma_deg: 10.0,
            ..REFERENCE_HOME
        }
        .to_params()
        .to_transform(),
    );
    let g = kinect.tilt_state().await.unwrap().accelerometer_g;
    assert!(g[0] < -0.17 && g[0] > -0.18, "{g:?}");

    // Beyond the motor's range is clamped; not a number is refused.
    kinect.set_tilt(40.0).await.unwrap();
    assert_eq!(kinect.tilt_deg(), 27.0);
    let e = kinect.set_tilt(f64::NAN).await.unwrap_err();
    assert_eq!(
        groundcal_hal::Error::kind(&e),
        groundcal_hal::ErrorKind::Refused
    );
}

#[tokio::test(start_paused = true)]
async fn accelerometer_readings_are_noisy_whole_counts_around_gravity() {
    let (mut kinect, _pose) = level_kinect(SimKinectConfig::default());
    kinect.set_tilt(-20.0).await.unwrap();
    let (s, c) = 20f64.to_radians().sin_cos();
    let expected = [0.0, c, -s];
    let n = 2000;
    let mut sum = [0.0; 3];
    let mut squares = [0.0; 3];
    for _ in 0..n {
        let g = kinect.tilt_state().await.unwrap().accelerometer_g;
        for k in 0..3 {
            assert_eq!((g[k] * 819.0).fract(), 0.0, "{g:?}");
            sum[k] += g[k] - expected[k];
            squares[k] += (g[k] - expected[k]).powi(2);
        }
    }
    for k in 0..3 {
        let mean = sum[k] / n as f64;
        let rms = (squares[k] / n as f64).sqrt();
        // Noise 1.5·10⁻³ g with rounding to 1/819 g (σ 3.5·10⁻⁴ g): 1.54·10⁻³ g.
        assert!(mean.abs() < 1e-4, "axis {k}: mean {mean}");
        assert!((rms - 1.54e-3).abs() < 1e-4, "axis {k}: rms {rms}");
    }
}

#[tokio::test(start_paused = true)]
async fn frames_come_at_the_frame_rate_scaled_by_the_time_scale() {
    for (time_scale, expected) in [
        (1.0, Duration::from_secs(1)),
        (10.0, Duration::from_millis(100)),
    ] {
        let (mut kinect, _) = level_kinect(SimKinectConfig {
            time_scale,
            ..SimKinectConfig::default()
        });
        let start = tokio::time::Instant::now();
        let mut timestamps = Vec::new();
        for _ in 0..30 {
            let frame = kinect.next_frame().await.unwrap();
            assert_eq!(
                (frame.width, frame.height, frame.raw.len()),
                (640, 480, 640 * 480)
            );
            timestamps.push(frame.timestamp);
        }
        let elapsed = start.elapsed();
        assert!(
            elapsed.abs_diff(expected) < Duration::from_millis(2),
            "time scale {time_scale}: 30 frames took {elapsed:?}"
        );
        // The sensor's clock counts simulated microseconds, whatever the scale.
        let steps: Vec<u32> = timestamps.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(
            steps.iter().all(|&s| (33_333..=33_334).contains(&s)),
            "{steps:?}"
        );
        // Tilting at a time scale of 10 is ten times quicker.
        let start = tokio::time::Instant::now();
        kinect.set_tilt(20.0).await.unwrap();
        assert!(
            start
                .elapsed()
                .abs_diff(Duration::from_secs_f64(1.0 / time_scale))
                < Duration::from_millis(1)
        );
    }
}

#[tokio::test(start_paused = true)]
async fn a_session_of_frames_is_deterministic_and_changes_with_the_pose() {
    // Independent noise and no pattern: the fitted plane is the true one.
    let (mut a, pose_a) = level_kinect(SimKinectConfig::independent_noise());
    let (mut b, pose_b) = level_kinect(SimKinectConfig::independent_noise());
    for kinect in [&mut a, &mut b] {
        kinect.set_tilt(-25.0).await.unwrap();
    }
    let fa = a.next_frame().await.unwrap();
    let fb = b.next_frame().await.unwrap();
    assert_eq!(fa.raw, fb.raw);
    // Waiting longer between frames does not change their noise.
    tokio::time::sleep(Duration::from_millis(500)).await;
    let fa2 = a.next_frame().await.unwrap();
    let fb2 = b.next_frame().await.unwrap();
    assert_eq!(fa2.raw, fb2.raw);
    assert_ne!(fa.raw, fa2.raw);
    // The frames follow the true pose.
    let tilted = PoseDegMm {
        beta_deg: 10.0,
        ..REFERENCE_HOME
    }
    .to_params()
    .to_transform();
    pose_a.set(tilted);
    pose_b.set(tilted);
    let fa3 = a.next_frame().await.unwrap();
    let fb3 = b.next_frame().await.unwrap();
    assert_eq!(fa3.raw, fb3.raw);
    let valid = |raw: &[u16]| raw.iter().filter(|&&r| r != RAW_NO_READING).count();
    // Pitched up by 10°, less of the ground is within 5 m.
    assert!(valid(&fa3.raw) < valid(&fa2.raw));
    // And the ground fitted from it is the true ground at that pose.
    let model = a.info().depth_model;
    let (n, d) = fit_plane(&points(&fa3.raw, &model, &a.info().intrinsics));
    let truth = ground_in_sensor(&a.true_ground_from_sensor());
    assert!(angle_deg(&n, &truth.normal) < 0.05);
    assert!((d - truth.d).abs() < 1e-3);
}

/// The measured noise holds its smooth part through a pose (the speckle's
/// error belongs to the scene as seen): two frames of one pose differ by
/// the white part only, a frame of the next pose by much more; and the same
/// pose of another run draws the same.
#[tokio::test(start_paused = true)]
async fn a_poses_frames_share_their_smooth_noise() {
    let (mut a, _) = level_kinect(SimKinectConfig::default());
    let (mut b, _) = level_kinect(SimKinectConfig::default());
    for kinect in [&mut a, &mut b] {
        kinect.set_tilt(-25.0).await.unwrap();
        kinect.begin_pose(1);
    }
    let first = a.next_frame().await.unwrap().raw;
    let second = a.next_frame().await.unwrap().raw;
    a.begin_pose(2);
    let next_pose = a.next_frame().await.unwrap().raw;
    b.begin_pose(1);
    assert_eq!(b.next_frame().await.unwrap().raw, first);
    let rms = |x: &[u16], y: &[u16]| {
        let (mut s, mut n) = (0.0, 0.0);
        for (&p, &q) in x.iter().zip(y) {
            if p != RAW_NO_READING && q != RAW_NO_READING {
                s += (f64::from(p) - f64::from(q)).powi(2);
                n += 1.0;
            }
        }
        (s / n).sqrt()
    };
    let within = rms(&first, &second);
    let across = rms(&first, &next_pose);
    assert!(
        within < 0.6 && across > 2.0 * within,
        "raw RMS difference within a pose {within:.3}, across poses {across:.3}"
    );
}
