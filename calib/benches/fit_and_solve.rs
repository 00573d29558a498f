//! Criterion benchmarks of the math's two hot paths: the ground fit of one
//! 640×480 raw frame (pixels to plane; in inverse depth and the paper's fit
//! side by side) and the 52-pose solve with its verdict. They run from this
//! crate alone (`cargo bench -p groundcal-calib`); figures are recorded in
//! docs/performance.md.

use std::path::PathBuf;

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use groundcal_calib::calibrate::{calibrate, CalibrationSettings};
use groundcal_calib::disparity::{EdgeGuard, Frame, InverseDepthImage};
use groundcal_calib::geometry::{sensor_from_optical, PoseDegMm, PoseParams};
use groundcal_calib::ground_view::GroundView;
use groundcal_calib::plane::{
    fit_ground, search::find_ground, FitBuffers, GroundFitMethod, GroundPrior, PlaneFitSettings,
};
use groundcal_calib::residuals::GroundResiduals;
use groundcal_calib::sensor::{DepthCamera, DepthEncoding, DepthModel, DepthRange, Intrinsics};
use groundcal_calib::solve::{predict, Observation};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};

/// The poses of a schedule file (config/schedules/*.toml); its other keys
/// are not needed here.
#[derive(serde::Deserialize)]
struct ScheduleFile {
    poses: Vec<PoseDegMm>,
}

/// The pixels of a fakenect dump's depth frame: a binary PGM header, then
/// 640×480 little-endian 16-bit raw values (the reader with every check is
/// the application's; the benchmark needs only the sample's frames).
fn fakenect_pixels(bytes: &[u8]) -> Vec<u16> {
    let header_end = bytes
        .iter()
        .enumerate()
        .filter(|(_, b)| **b == b'\n')
        .map(|(i, _)| i + 1)
        .next()
        .expect("a PGM header line");
    assert!(bytes.starts_with(b"P5 640 480"), "a fakenect depth frame");
    bytes[header_end..]
        .chunks_exact(2)
        .map(|pair| u16::from_le_bytes([pair[0], pair[1]]))
        .collect()
}

/// A depth frame of the shared sample recording, by its file name.
fn sample_pixels(name: &str) -> Vec<u16> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/sample-12/kinect")
        .join(name);
    let bytes = std::fs::read(&path).expect("the shared sample recording is beside the project");
    fakenect_pixels(&bytes)
}

/// The first depth frame of the shared sample recording (inverse-linear model).
fn sample_frame() -> (Vec<u16>, DepthCamera) {
    let pixels = sample_pixels("d-1700000000.001000-2001000.pgm");
    let f = 575.8157389635317;
    let intrinsics = Intrinsics {
        fx: f,
        fy: f,
        ..Intrinsics::default()
    };
    let camera = DepthCamera::new(
        DepthEncoding::Raw11(DepthModel::inverse_linear_default()),
        intrinsics,
        DepthRange::default(),
    );
    (pixels, camera)
}

fn ground_fit(c: &mut Criterion) {
    let (pixels, camera) = sample_frame();
    let prior = GroundPrior::up_only(
        sensor_from_optical() * Vector3::new(0.0, -1.0, 0.0),
        60f64.to_radians(),
    );
    // As in a streaming capture, the buffers are reused from frame to frame.
    let mut buffers = FitBuffers::default();
    // The two fits, and the default one without the edge guard (issue 22),
    // to weigh what the guard costs.
    let cases = [
        (
            "disparity",
            GroundFitMethod::Disparity,
            PlaneFitSettings::default().edge_guard_rows,
        ),
        (
            "paper",
            GroundFitMethod::Paper,
            PlaneFitSettings::default().edge_guard_rows,
        ),
        ("disparity, no edge guard", GroundFitMethod::Disparity, 0),
    ];
    for (name, method, edge_guard_rows) in cases {
        let settings = PlaneFitSettings {
            method,
            edge_guard_rows,
            ..Default::default()
        };
        c.bench_function(
            &format!("ground fit ({name}), one 640x480 raw frame (pixels to plane)"),
            |b| {
                b.iter(|| {
                    fit_ground(
                        &[black_box(&pixels)],
                        &camera,
                        &prior,
                        &settings,
                        &mut buffers,
                    )
                    .unwrap()
                })
            },
        );
    }
    // The page's picture of the same frame: 80 × 60 cells, each tested
    // against the fit's band (what a picture costs beyond its fit).
    let fit = fit_ground(
        &[&pixels],
        &camera,
        &prior,
        &PlaneFitSettings::default(),
        &mut buffers,
    )
    .unwrap();
    c.bench_function(
        "the page's picture (80x60 cells) of one frame, given its fit",
        |b| b.iter(|| GroundView::of(black_box(&pixels), &camera, Ok(&fit))),
    );
    // A pose as recorded: the sample's first pose has two frames, fused.
    let second = sample_pixels("d-1700000000.002000-3002000.pgm");
    let settings = PlaneFitSettings::default();
    c.bench_function(
        "ground fit (disparity), one pose of two 640x480 raw frames",
        |b| {
            b.iter(|| {
                fit_ground(
                    &[black_box(&pixels), black_box(&second)],
                    &camera,
                    &prior,
                    &settings,
                    &mut buffers,
                )
                .unwrap()
            })
        },
    );
    // What the depth pattern's estimate takes from that pose while its
    // frames are in memory: its residuals summed per 8 × 8 cell.
    let fit = fit_ground(
        &[&pixels, &second],
        &camera,
        &prior,
        &settings,
        &mut buffers,
    )
    .unwrap();
    let mut image = InverseDepthImage::default();
    c.bench_function(
        "ground residuals per cell, one pose of two 640x480 raw frames",
        |b| {
            b.iter(|| {
                GroundResiduals::of(
                    &[black_box(&pixels), black_box(&second)],
                    &camera,
                    &fit,
                    &mut image,
                )
            })
        },
    );
    // The fit reads raw frames as they are, in raw units.
    let settings = PlaneFitSettings::default();
    let domain = camera.value_domain();
    let frame = Frame {
        values: &pixels[..],
        width: 640,
        height: 480,
    };
    let no_ground = || panic!("the sample frame has ground");
    let found = find_ground(&frame, &domain, camera.grid(), &prior, &settings, no_ground).unwrap();
    c.bench_function("ground search only (cells, groups, support)", |b| {
        b.iter(|| {
            find_ground(
                black_box(&frame),
                &domain,
                camera.grid(),
                &prior,
                &settings,
                no_ground,
            )
        })
    });
    c.bench_function("one pass of moments over every pixel", |b| {
        b.iter(|| {
            camera.grid().moments_within(
                black_box(&frame),
                &domain,
                &found.plane,
                4.0 * found.noise,
                0,
                1,
                Some(EdgeGuard {
                    rows: 6,
                    limit: 3.0 * found.noise,
                }),
            )
        })
    });
    let mut cloud = camera.points(&pixels);
    c.bench_function("raw frame to points only", |b| {
        b.iter(|| camera.points_into(black_box(&pixels), &mut cloud))
    });
}

/// The paper's Table A1 (config/schedules/octopus-52.toml) with noisy planes.
fn table_a1_observations() -> Vec<Observation> {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/schedules/octopus-52.toml");
    let text = std::fs::read_to_string(&path).expect("the shipped schedule reads");
    let schedule: ScheduleFile = toml::from_str(&text).expect("the shipped schedule parses");
    let mount = PoseParams::new(
        -0.4398f64.to_radians(),
        -37.4072f64.to_radians(),
        -3.0471f64.to_radians(),
        Vector3::new(0.5278885, 0.3648007, -0.0334003),
    );
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(52);
    let mut jitter = || rng.gen_range(-1.0..1.0);
    schedule
        .poses
        .iter()
        .enumerate()
        .map(|(i, pose)| {
            let g = pose.to_params().to_transform();
            let mut plane = predict(&mount, &g);
            plane.normal =
                (plane.normal + Vector3::new(jitter(), jitter(), jitter()) * 0.003).normalize();
            plane.d += jitter() * 0.001;
            Observation::new(i as u32 + 1, g, plane)
        })
        .collect()
}

fn solve_52(c: &mut Criterion) {
    let observations = table_a1_observations();
    let settings = CalibrationSettings::default();
    c.bench_function("solve, 52 poses (Table A1)", |b| {
        b.iter(|| calibrate(black_box(&observations), &settings).unwrap())
    });
}

/// The depth pattern's test that there is a shape (`cell_noise::flip_test`):
/// the null over every choice of the poses' signs, from the poses' Gram
/// matrix of the shape's size. Sized as a 52-pose calibration's: 80 × 60
/// cells, 3,000 of them with ground at each pose, the shape's plane part
/// removed. It runs up to three times in a pattern's estimate, and again
/// when the ground is fitted about the pattern (docs/performance.md). The
/// entries here are a slice, read whole for each block of cells (the
/// estimate's own skip to each block's cells).
fn pattern_flip_test(c: &mut Criterion) {
    use groundcal_calib::cell_noise::{flip_test, Entry, PlaneRemoved, ShapeOfSums};
    let (cells, poses) = (80 * 60, 52);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(41);
    let entries: Vec<Entry> = (0..poses)
        .flat_map(|pose| (1_200..4_200).map(move |cell| (pose, cell)))
        .map(|(pose, cell)| Entry {
            pose,
            cell,
            n: 64.0,
            residual: 0.0,
            about_plane: rng.gen_range(-1.0..1.0) * 1e-3,
        })
        .collect();
    let mut weights = vec![0.0; cells];
    for e in &entries {
        weights[e.cell as usize] += e.n;
    }
    let rows: Vec<Vector3<f64>> = (0..cells)
        .map(|k| {
            Vector3::new(
                1.0,
                (k % 80) as f64 * 8.0 - 316.0,
                (k / 80) as f64 * 8.0 - 236.0,
            )
        })
        .collect();
    let shape = ShapeOfSums {
        weights: &weights,
        plane: Some(PlaneRemoved::weighted(&rows, &weights).expect("the cells carry a plane")),
    };
    c.bench_function(
        "the pattern's flip test, 52 poses x 3000 cells, every choice of signs",
        |b| b.iter(|| flip_test(black_box(&entries), poses as usize, shape)),
    );
}

/// The depth pattern's estimate (`distortion::estimate_shape_seen_from`,
/// issue 41) as `replay` of the 156-frame recording makes it
/// (`scripts/make-perf-recording`): 52 poses, pose i the sample's pose
/// i mod 12 with its two frames, each pose's residuals from its own ground
/// fit, and the sensor over the ground where each pose's plane puts it
/// (the ground's test and the shape beside its relief included). Every
/// pass over the poses' cells, the flip tests and the alternatives; not
/// the fits.
fn pattern_estimate(c: &mut Criterion) {
    use groundcal_calib::distortion::estimate_shape_seen_from;
    use groundcal_calib::geometry::Transform;
    use nalgebra::{Matrix3, Rotation3, Translation3};
    let (_, camera) = sample_frame();
    let prior = GroundPrior::up_only(
        sensor_from_optical() * Vector3::new(0.0, -1.0, 0.0),
        60f64.to_radians(),
    );
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/sample-12/kinect");
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .expect("the shared sample recording is beside the project")
        .map(|entry| entry.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.starts_with("d-") && name.ends_with(".pgm"))
        .collect();
    names.sort();
    let mut buffers = FitBuffers::default();
    let sample_poses: Vec<(GroundResiduals, Transform)> = names
        .chunks(2)
        .map(|pair| {
            let pixels: Vec<Vec<u16>> = pair.iter().map(|name| sample_pixels(name)).collect();
            let frames: Vec<&[u16]> = pixels.iter().map(Vec::as_slice).collect();
            let fit = fit_ground(
                &frames,
                &camera,
                &prior,
                &PlaneFitSettings::default(),
                &mut buffers,
            )
            .unwrap();
            let residuals =
                GroundResiduals::of_fitted(&frames, &camera, &fit, &mut buffers).unwrap();
            // The ground frame's y up along the plane's normal, the sensor
            // at the plane's distance above it.
            let up = fit.plane.normal.normalize();
            let across = up.cross(&Vector3::new(0.0, 0.0, 1.0)).normalize();
            let along = across.cross(&up);
            let rotation = Rotation3::from_matrix_unchecked(Matrix3::from_rows(&[
                across.transpose(),
                up.transpose(),
                along.transpose(),
            ]));
            let ground_from_sensor =
                Transform::from_parts(Translation3::new(0.0, fit.plane.d.abs(), 0.0), rotation);
            (residuals, ground_from_sensor)
        })
        .collect();
    let poses: Vec<&GroundResiduals> = (0..52).map(|i| &sample_poses[i % 12].0).collect();
    let ground_from_sensor: Vec<Transform> = (0..52).map(|i| sample_poses[i % 12].1).collect();
    let estimate = estimate_shape_seen_from(&poses, Some(&ground_from_sensor)).unwrap();
    assert!(
        estimate.fixed_in_the_ground.is_some(),
        "the ground's test ran"
    );
    c.bench_function(
        "the depth pattern's estimate, 52 poses of the sample (156-frame replay's)",
        |b| b.iter(|| estimate_shape_seen_from(black_box(&poses), Some(&ground_from_sensor))),
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(50).measurement_time(std::time::Duration::from_secs(5));
    targets = ground_fit, solve_52, pattern_flip_test, pattern_estimate
}
criterion_main!(benches);
