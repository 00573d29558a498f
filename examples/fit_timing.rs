use groundcal::calib::geometry::sensor_from_optical;
use groundcal::calib::plane::{fit_ground, GroundPrior, PlaneFitSettings};
use groundcal::calib::sensor::{DepthCamera, DepthEncoding, DepthModel, DepthRange, Intrinsics};
use groundcal::depth_image::{read_depth_image, DepthUnits};
fn main() {
    let path =
        std::path::Path::new("../shared/data/sample-12/kinect/d-1700000000.001000-2001000.pgm");
    let (image, _) = read_depth_image(path, Some(DepthUnits::Raw11)).unwrap();
    let f = 575.8157389635317;
    let camera = DepthCamera::new(
        DepthEncoding::Raw11(DepthModel::inverse_linear_default()),
        Intrinsics {
            fx: f,
            fy: f,
            cx: 320.0,
            cy: 240.0,
            width: 640,
            height: 480,
        },
        DepthRange::default(),
    );
    let prior = GroundPrior::up_only(
        sensor_from_optical() * nalgebra::Vector3::new(0.0, -1.0, 0.0),
        1.0,
    );
    let cloud = camera.points(&image.pixels);
    for _ in 0..200 {
        std::hint::black_box(fit_ground(&[&cloud], &prior, &PlaneFitSettings::default()).unwrap());
    }
}
