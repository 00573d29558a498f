//! Criterion benchmark of the simulated Kinect: demos and tests run whole
//! calibrations on its frames. Figures in docs/performance.md.

use criterion::{black_box, criterion_group, criterion_main, Criterion};

/// The simulated Kinect's frame (demos and tests run a full calibration on
/// it): one 640×480 frame from a tilted body pose of Table A1, per world.
fn sim_render(c: &mut Criterion) {
    use groundcal_calib::geometry::PoseDegMm;
    use groundcal_hal::sim::kinect::{DepthRenderer, SimKinectConfig};
    use groundcal_hal::sim::world::World;
    let renderer = DepthRenderer::new(&SimKinectConfig::default()).unwrap();
    let body = PoseDegMm::from_values([0.0, 20.0, 2.0, 0.0, 651.0, 0.0]);
    let mount = PoseDegMm::from_values([4.5, -30.7, -2.0, 491.3, 331.6, 8.7]);
    let ground_from_sensor = body.to_params().to_transform() * mount.to_params().to_transform();
    for (name, world) in [
        ("flat", World::flat()),
        ("boxes and wall", World::boxes_and_wall(1)),
        ("uneven 2 cm", World::uneven(1, 0.02)),
    ] {
        let mut frame = 0;
        c.bench_function(&format!("simulated Kinect frame, {name}"), |b| {
            b.iter(|| {
                frame += 1;
                renderer.render(black_box(&world), &ground_from_sensor, frame)
            })
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(50).measurement_time(std::time::Duration::from_secs(5));
    targets = sim_render
}
criterion_main!(benches);
