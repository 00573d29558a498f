//! The depth camera's sensor model: raw values to depth, pixels to points.
//!
//! Two raw-to-depth models for the Kinect v1's 11-bit values are in use
//! (conventions.md): libfreenect's `zero-plane` model and the `inverse-linear`
//! fit. Metric images (millimetres, TUM's 5000 per metre) convert by a scale.
//! Points come out in the sensor frame V (X along the optical axis, Y up, Z right).

use crate::disparity::{InverseDepthConverter, InverseDepthImage, PixelGrid, ValueDomain};

pub use crate::depth::{
    depth_sigma_m, DepthEncoding, DepthModel, DepthRange, Intrinsics, RAW_NO_READING,
};

/// A converter from depth images to points, with its per-value table built once.
#[derive(Debug, Clone)]
pub struct DepthCamera {
    intrinsics: Intrinsics,
    range: DepthRange,
    /// Depth in metres and weight for each possible value; depth 0 = no reading
    /// or out of range.
    table: Vec<(f32, f32)>,
    /// `(u - cx) / fx` per column.
    ray_right: Vec<f32>,
    /// `-(v - cy) / fy` per row (sensor Y is up, image rows go down).
    ray_up: Vec<f32>,
    /// The same frames in inverse depth, for the ground fit.
    inverse_depth: InverseDepthConverter,
    grid: PixelGrid,
    /// Raw units per 1/m of inverse depth: the depth model's `1/b`, or the
    /// default model's for metric frames (raw-equivalent units).
    raw_per_inverse_depth: f64,
    /// The Kinect's depth pattern taken out of every reading, per pixel in
    /// inverse depth (1/m), when a calibration found one.
    correction: Option<std::sync::Arc<[f32]>>,
}

/// Points in the sensor frame V, stored as separate coordinate arrays so that the
/// per-point loops of the plane fit vectorise, each with its weight.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    /// Along the optical axis (the depth), metres.
    pub x: Vec<f32>,
    /// Up in the image, metres.
    pub y: Vec<f32>,
    /// Right in the image, metres.
    pub z: Vec<f32>,
    /// `1/σ²` of the reading in mm⁻² ([`depth_weight`]), computed once here so
    /// that the fit's iterations need no division.
    pub weight: Vec<f32>,
}

/// Weight `1/σ²` (mm⁻²) of a reading at depth `x` metres: a 1 mm floor plus the
/// Kinect's `1.4·10⁻³·z²` (conventions.md), as in [`depth_sigma_m`].
#[inline(always)]
pub fn depth_weight(depth_m: f32) -> f32 {
    let q = 1.4 * depth_m * depth_m;
    1.0 / (1.0 + q * q)
}

impl PointCloud {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Point `i` in double precision.
    pub fn point(&self, i: usize) -> nalgebra::Vector3<f64> {
        nalgebra::Vector3::new(
            f64::from(self.x[i]),
            f64::from(self.y[i]),
            f64::from(self.z[i]),
        )
    }

    /// Appends a point.
    pub fn push(&mut self, p: nalgebra::Vector3<f64>) {
        self.x.push(p.x as f32);
        self.y.push(p.y as f32);
        self.z.push(p.z as f32);
        self.weight.push(depth_weight(p.x as f32));
    }

    fn push_f32(&mut self, x: f32, y: f32, z: f32, weight: f32) {
        self.x.push(x);
        self.y.push(y);
        self.z.push(z);
        self.weight.push(weight);
    }

    /// Every `stride`-th point of the clouds, in order, as one cloud.
    pub fn subsample(clouds: &[&PointCloud], stride: usize) -> PointCloud {
        let stride = stride.max(1);
        let total: usize = clouds.iter().map(|c| c.len()).sum();
        let mut out = PointCloud::with_capacity(total / stride + 1);
        let mut k = 0usize;
        for cloud in clouds {
            // The first index of this cloud that continues the global stride.
            let mut i = (stride - k % stride) % stride;
            while i < cloud.len() {
                out.push_f32(cloud.x[i], cloud.y[i], cloud.z[i], cloud.weight[i]);
                i += stride;
            }
            k += cloud.len();
        }
        out
    }

    /// Removes every point, keeping the memory.
    pub fn clear(&mut self) {
        self.x.clear();
        self.y.clear();
        self.z.clear();
        self.weight.clear();
    }

    /// An empty cloud with room for `n` points.
    pub fn with_capacity(n: usize) -> Self {
        Self {
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            z: Vec::with_capacity(n),
            weight: Vec::with_capacity(n),
        }
    }
}

/// A depth with `offset` (1/m) taken out of its inverse; 0 (no reading) if
/// that leaves none.
fn corrected_depth(z: f32, offset: f32) -> f32 {
    let w = 1.0 / z - offset;
    if w > 0.0 {
        1.0 / w
    } else {
        0.0
    }
}

impl DepthCamera {
    /// A converter for images of the given encoding and intrinsics.
    pub fn new(encoding: DepthEncoding, intrinsics: Intrinsics, range: DepthRange) -> Self {
        let table_len = match encoding {
            DepthEncoding::Raw11(_) => usize::from(RAW_NO_READING) + 1,
            DepthEncoding::Metric { .. } => usize::from(u16::MAX) + 1,
        };
        let table = (0..table_len)
            .map(|value| {
                let z = match encoding {
                    DepthEncoding::Raw11(model) => model.depth_m(value as u16),
                    DepthEncoding::Metric { metres_per_unit } => {
                        (value > 0).then_some(value as f64 * metres_per_unit)
                    }
                };
                match z {
                    Some(z) if z >= range.min_m && z <= range.max_m => {
                        (z as f32, depth_weight(z as f32))
                    }
                    _ => (0.0, 0.0),
                }
            })
            .collect();
        let ray_right = (0..intrinsics.width)
            .map(|u| ((u as f64 - intrinsics.cx) / intrinsics.fx) as f32)
            .collect();
        let ray_up = (0..intrinsics.height)
            .map(|v| (-(v as f64 - intrinsics.cy) / intrinsics.fy) as f32)
            .collect();
        Self {
            intrinsics,
            range,
            table,
            ray_right,
            ray_up,
            inverse_depth: InverseDepthConverter::new(encoding, &intrinsics, range),
            grid: PixelGrid::new(intrinsics),
            raw_per_inverse_depth: 1.0
                / match encoding {
                    DepthEncoding::Raw11(model) => model.inverse_depth_affine().1,
                    DepthEncoding::Metric { .. } => DepthModel::default().inverse_depth_affine().1,
                },
            correction: None,
        }
    }

    /// This camera with the Kinect's depth pattern a calibration found
    /// taken out of every reading: `raw' = raw − correction(u, v)`, that is
    /// `1/z' = 1/z − correction(u, v)/k` (k = [`Self::raw_per_inverse_depth`]).
    pub fn with_depth_correction(&self, correction: &crate::depth::DepthCorrection) -> Self {
        let (width, height) = (self.intrinsics.width, self.intrinsics.height);
        let offsets: std::sync::Arc<[f32]> = (0..height)
            .flat_map(|v| (0..width).map(move |u| (u, v)))
            .map(|(u, v)| {
                (correction.raw_at(u as f64, v as f64) / self.raw_per_inverse_depth) as f32
            })
            .collect();
        let mut camera = self.clone();
        camera.inverse_depth = camera.inverse_depth.with_correction(offsets.clone());
        camera.correction = Some(offsets);
        camera
    }

    /// Converts a frame to inverse depth (`1/z`, the Kinect's noise domain)
    /// into `image`, reusing its memory.
    pub fn inverse_depth_into(&self, pixels: &[u16], image: &mut InverseDepthImage) {
        self.inverse_depth.convert_into(pixels, image);
    }

    /// The domain the ground fit reads frames in (raw values as they are).
    pub fn value_domain(&self) -> ValueDomain {
        self.inverse_depth.domain()
    }

    /// Whether the ground fit reads frames as they are, with no conversion.
    pub fn fits_raw_values(&self) -> bool {
        self.inverse_depth.reads_raw()
    }

    /// The pixel offsets the ground fit works with.
    pub fn grid(&self) -> &PixelGrid {
        &self.grid
    }

    /// The camera's intrinsics.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// Raw units per 1/m of inverse depth (the depth model's `1/b`; for
    /// metric frames the default model's).
    pub fn raw_per_inverse_depth(&self) -> f64 {
        self.raw_per_inverse_depth
    }

    /// The trusted depth range.
    pub fn range(&self) -> DepthRange {
        self.range
    }

    /// Converts an image (row-major, `width × height` values) to points in the
    /// sensor frame, appending to `cloud`. Returns the number of points added.
    ///
    /// An image of another size than the intrinsics' is refused by the caller;
    /// here the shorter of the two is used, so nothing panics.
    pub fn append_points(&self, pixels: &[u16], cloud: &mut PointCloud) -> usize {
        let before = cloud.len();
        let width = self.intrinsics.width;
        let rows = pixels.len() / width.max(1);
        let room = before + rows.min(self.ray_up.len()) * width;
        // Written without a branch per pixel: every pixel is stored at the
        // cursor, which advances only over valid ones; the excess is cut off.
        cloud.x.resize(room, 0.0);
        cloud.y.resize(room, 0.0);
        cloud.z.resize(room, 0.0);
        cloud.weight.resize(room, 0.0);
        let mut cursor = before;
        for (v, (row, up)) in pixels.chunks_exact(width).zip(&self.ray_up).enumerate() {
            let offsets = self
                .correction
                .as_ref()
                .and_then(|c| c.get(v * width..(v + 1) * width));
            for (u, (&value, &right)) in row.iter().zip(&self.ray_right).enumerate() {
                let (mut z, w) = self
                    .table
                    .get(usize::from(value))
                    .copied()
                    .unwrap_or((0.0, 0.0));
                if let (Some(offsets), true) = (offsets, z > 0.0) {
                    z = corrected_depth(z, offsets[u]);
                }
                cloud.x[cursor] = z;
                cloud.y[cursor] = up * z;
                cloud.z[cursor] = right * z;
                cloud.weight[cursor] = w;
                cursor += usize::from(z > 0.0);
            }
        }
        cloud.x.truncate(cursor);
        cloud.y.truncate(cursor);
        cloud.z.truncate(cursor);
        cloud.weight.truncate(cursor);
        cursor - before
    }

    /// The point one pixel's value reads as, in the sensor frame (metres);
    /// `None` for no reading, one outside the trusted range, or a pixel
    /// outside the image.
    pub fn point_at(&self, u: usize, v: usize, value: u16) -> Option<nalgebra::Vector3<f64>> {
        let (mut z, _) = *self.table.get(usize::from(value))?;
        if let (Some(offsets), true) = (&self.correction, z > 0.0) {
            z = corrected_depth(z, *offsets.get(v * self.intrinsics.width + u)?);
        }
        let right = *self.ray_right.get(u)?;
        let up = *self.ray_up.get(v)?;
        (z > 0.0).then(|| {
            let z = f64::from(z);
            nalgebra::Vector3::new(z, f64::from(up) * z, f64::from(right) * z)
        })
    }

    /// Converts an image into `cloud`, reusing its memory (the streaming path:
    /// no allocation once the buffers have grown to a frame's size).
    pub fn points_into(&self, pixels: &[u16], cloud: &mut PointCloud) -> usize {
        cloud.clear();
        self.append_points(pixels, cloud)
    }

    /// Converts an image to a new point cloud.
    pub fn points(&self, pixels: &[u16]) -> PointCloud {
        let mut cloud = PointCloud::with_capacity(pixels.len());
        self.append_points(pixels, &mut cloud);
        cloud
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_become_sensor_frame_points() {
        let intrinsics = Intrinsics {
            fx: 500.0,
            fy: 500.0,
            cx: 1.0,
            cy: 1.0,
            width: 3,
            height: 2,
        };
        let camera = DepthCamera::new(
            DepthEncoding::Metric {
                metres_per_unit: 0.001,
            },
            intrinsics,
            DepthRange::default(),
        );
        // Row 0: 1000 mm at u = 0, 0 (no reading), 6000 mm (out of range); row 1: 2000 mm at u = 2.
        let cloud = camera.points(&[1000, 0, 6000, 0, 0, 2000]);
        assert_eq!(cloud.len(), 2);
        // u = 0, v = 0: left of and above the centre → Z negative, Y positive.
        assert_eq!((cloud.x[0], cloud.y[0], cloud.z[0]), (1.0, 0.002, -0.002));
        assert_eq!((cloud.x[1], cloud.y[1], cloud.z[1]), (2.0, 0.0, 0.004));
    }
}
