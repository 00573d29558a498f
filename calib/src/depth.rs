//! The Kinect v1 depth camera as hardware: its raw-to-depth models, its
//! intrinsics and its noise (shared/spec/conventions.md). Shared by the
//! calibration (pixels to points) and the simulated Kinect (scenes to pixels).

use serde::{Deserialize, Serialize};

/// The raw value the Kinect reports for "no reading".
pub const RAW_NO_READING: u16 = 2047;

/// The Kinect's raw disparity counts eighths of a pixel of its 640-pixel
/// image: its matcher's subpixel step (libfreenect's zero-plane model shifts
/// by `raw/4` pixels of the 1,280-pixel reference, half the width). With it
/// the Kinect's limits, set in raw units, become pixels of disparity, which
/// another camera's can be compared with ([`kinect_pixels_per_inverse_depth`]).
pub const KINECT_RAW_PER_PIXEL: f64 = 8.0;

/// The baselines groundcal takes for a depth camera's, millimetres: a
/// structured-light or stereo camera's are 15–120 mm (RealSense 50–95,
/// Orbbec 40–75, the Kinect 75); a millimetre to a metre covers any.
pub const BASELINE_MM: std::ops::RangeInclusive<f64> = 1.0..=1000.0;

/// Why `mm` cannot be a depth camera's baseline, if it cannot.
pub fn check_baseline_mm(mm: f64) -> Result<(), String> {
    if mm.is_finite() && BASELINE_MM.contains(&mm) {
        Ok(())
    } else {
        Err(format!(
            "{mm} is not a depth camera's stereo baseline ({} to {} mm)",
            BASELINE_MM.start(),
            BASELINE_MM.end()
        ))
    }
}

/// The default Kinect's pixels of disparity per 1/m of inverse depth (its
/// focal length times its baseline, px·m): 42.8 for the default model,
/// where the sensor's own figures give about 580 px × 75 mm (43.5).
pub fn kinect_pixels_per_inverse_depth() -> f64 {
    let (_, metres_inverse_per_raw) = DepthModel::default().inverse_depth_affine();
    1.0 / (metres_inverse_per_raw.abs() * KINECT_RAW_PER_PIXEL)
}

/// How raw 11-bit Kinect values map to depth (conventions.md).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum DepthModel {
    /// libfreenect's model (`src/registration.c`) from the device's factory constants.
    ZeroPlane {
        reference_distance_mm: f64,
        reference_pixel_size_mm: f64,
        emitter_distance_cm: f64,
        const_shift: f64,
    },
    /// `z_m = 1 / (a + b·raw)`.
    InverseLinear { a: f64, b: f64 },
}

impl Default for DepthModel {
    fn default() -> Self {
        DepthModel::ZeroPlane {
            reference_distance_mm: 120.0,
            reference_pixel_size_mm: 0.1052,
            emitter_distance_cm: 7.5,
            const_shift: 200.0,
        }
    }
}

impl DepthModel {
    /// The usual inverse-linear constants.
    pub fn inverse_linear_default() -> Self {
        DepthModel::InverseLinear {
            a: 3.3309495161,
            b: -0.0030711016,
        }
    }

    /// Depth along the optical axis in metres, or `None` for "no reading" and for
    /// values the model maps to no positive finite depth.
    pub fn depth_m(&self, raw: u16) -> Option<f64> {
        if raw >= RAW_NO_READING {
            return None;
        }
        let raw = f64::from(raw);
        let z = match *self {
            DepthModel::ZeroPlane {
                reference_distance_mm: r,
                reference_pixel_size_mm: p,
                emitter_distance_cm: e,
                const_shift: c,
            } => {
                let s = ((raw - 4.0 * c) / 4.0 - 0.375) * p;
                0.01 * (s * r / (e - s) + r)
            }
            DepthModel::InverseLinear { a, b } => 1.0 / (a + b * raw),
        };
        (z.is_finite() && z > 0.0).then_some(z)
    }

    /// The inverse depth as an affine function of the raw value,
    /// `1/z_m = a + b·raw`, exact for both models: the Kinect measures
    /// disparity, and both models are a disparity-to-depth conversion.
    /// The ground fit works in this domain, where the sensor's noise is the
    /// same for every pixel (`docs/method.md`).
    pub fn inverse_depth_affine(&self) -> (f64, f64) {
        match *self {
            DepthModel::ZeroPlane {
                reference_distance_mm: r,
                reference_pixel_size_mm: p,
                emitter_distance_cm: e,
                const_shift: c,
            } => {
                // z = 0.01·R·E / (E − s), s = P·raw/4 − P·(C + 0.375).
                let scale = 0.01 * r * e;
                ((e + p * (c + 0.375)) / scale, -p / (4.0 * scale))
            }
            DepthModel::InverseLinear { a, b } => (a, b),
        }
    }

    /// Whether the model's constants are usable numbers.
    pub fn validate(&self) -> Result<(), String> {
        let values: Vec<f64> = match *self {
            DepthModel::ZeroPlane {
                reference_distance_mm,
                reference_pixel_size_mm,
                emitter_distance_cm,
                const_shift,
            } => vec![
                reference_distance_mm,
                reference_pixel_size_mm,
                emitter_distance_cm,
                const_shift,
            ],
            DepthModel::InverseLinear { a, b } => vec![a, b],
        };
        if values.iter().any(|v| !v.is_finite()) {
            return Err("the depth model's constants must be finite numbers".into());
        }
        if let DepthModel::ZeroPlane {
            reference_distance_mm,
            reference_pixel_size_mm,
            ..
        } = *self
        {
            if reference_distance_mm <= 0.0 || reference_pixel_size_mm <= 0.0 {
                return Err(
                    "reference_distance_mm and reference_pixel_size_mm must be positive".into(),
                );
            }
        }
        Ok(())
    }

    /// The focal length libfreenect derives from the model, `R / (2·P)` pixels,
    /// or the Kinect's usual value for models that do not carry it.
    pub fn default_focal_px(&self) -> f64 {
        match *self {
            DepthModel::ZeroPlane {
                reference_distance_mm,
                reference_pixel_size_mm,
                ..
            } => reference_distance_mm / (2.0 * reference_pixel_size_mm),
            DepthModel::InverseLinear { .. } => 120.0 / (2.0 * 0.1052),
        }
    }
}

/// Pinhole intrinsics of the depth image.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    #[serde(default = "default_width")]
    pub width: usize,
    #[serde(default = "default_height")]
    pub height: usize,
}

fn default_width() -> usize {
    640
}

fn default_height() -> usize {
    480
}

impl Default for Intrinsics {
    /// libfreenect's `freenect_camera_to_world` defaults.
    fn default() -> Self {
        let f = DepthModel::default().default_focal_px();
        Self {
            fx: f,
            fy: f,
            cx: 320.0,
            cy: 240.0,
            width: 640,
            height: 480,
        }
    }
}

impl Intrinsics {
    /// Whether the intrinsics describe a usable camera.
    pub fn validate(&self) -> Result<(), String> {
        if ![self.fx, self.fy, self.cx, self.cy]
            .iter()
            .all(|v| v.is_finite())
        {
            return Err("intrinsics must be finite numbers".into());
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(format!(
                "focal lengths must be positive (fx = {}, fy = {})",
                self.fx, self.fy
            ));
        }
        if self.width == 0 || self.height == 0 || self.width > 4096 || self.height > 4096 {
            return Err(format!(
                "image size {}×{} is out of range",
                self.width, self.height
            ));
        }
        Ok(())
    }
}

/// Expected standard deviation of one depth reading at depth `z` metres.
///
/// The Kinect's random error grows as `1.4·10⁻³·z²` (conventions.md); a floor of
/// 1 mm covers quantisation and metric images at short range.
pub fn depth_sigma_m(z: f64) -> f64 {
    let quadratic = 1.4e-3 * z * z;
    (1.0e-6 + quadratic * quadratic).sqrt()
}

/// The raw value whose disparity is nearest that of depth `z` metres, or
/// `None` outside the model's range: the inverse of [`DepthModel::depth_m`],
/// used to render simulated frames. The Kinect measures disparity and rounds
/// it to its raw steps, so the nearest raw value is the nearest in `1/z`
/// (both models are affine there). Depth grows with the raw value, so a
/// bisection finds it.
pub fn raw_for_depth(model: &DepthModel, z: f64) -> Option<u16> {
    let depth = |raw: u16| model.depth_m(raw);
    // The lowest raw value with a depth, and the highest.
    let first = (0..RAW_NO_READING).find(|&r| depth(r).is_some())?;
    let last = (first..RAW_NO_READING)
        .rev()
        .find(|&r| depth(r).is_some())?;
    let (mut lo, mut hi) = (first, last);
    if !(depth(lo)?..=depth(hi)?).contains(&z) {
        return None;
    }
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        match depth(mid) {
            Some(d) if d <= z => lo = mid,
            _ => hi = mid,
        }
    }
    let (zl, zh) = (depth(lo)?, depth(hi)?);
    // Ties go to the raw value below.
    Some(
        if (1.0 / zl - 1.0 / z).abs() <= (1.0 / z - 1.0 / zh).abs() {
            lo
        } else {
            hi
        },
    )
}

/// What the 16-bit values of an image mean, with the model that converts them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DepthEncoding {
    /// Raw 11-bit Kinect values through a depth model.
    Raw11(DepthModel),
    /// Metric depth: `value × metres_per_unit`, 0 = no reading.
    Metric { metres_per_unit: f64 },
}

/// The range of depths that are trusted (conventions.md: 0.5–5 m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DepthRange {
    pub min_m: f64,
    pub max_m: f64,
}

impl Default for DepthRange {
    fn default() -> Self {
        Self {
            min_m: 0.5,
            max_m: 5.0,
        }
    }
}

/// A found pattern as a correction of raw values at any pixel: the cells'
/// values interpolated bilinearly between their centres, held at the
/// border's; cells no pose saw count as 0 (nothing known, nothing changed).
/// `raw' = raw − raw_at(u, v)` (docs/export.md, "depth-correction"); found by `crate::distortion`.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthCorrection {
    pub columns: usize,
    pub rows: usize,
    pub cell_px: usize,
    /// Per cell, raw units, row-major.
    pub raw: Vec<f64>,
}

impl DepthCorrection {
    /// The correction of a grid of cells (`None`: not seen, taken as 0);
    /// `None` if the grid's size disagrees with its values.
    pub fn from_cells(
        columns: usize,
        rows: usize,
        cell_px: usize,
        cells: &[Option<f64>],
    ) -> Option<Self> {
        (columns > 0 && rows > 0 && cell_px > 0 && cells.len() == columns * rows).then(|| Self {
            columns,
            rows,
            cell_px,
            raw: cells.iter().map(|c| c.unwrap_or(0.0)).collect(),
        })
    }

    /// The raw units a reading at pixel `(u, v)` reads too much.
    pub fn raw_at(&self, u: f64, v: f64) -> f64 {
        let size = self.cell_px as f64;
        // Cell (c, r)'s centre is pixel ((c + ½)·size − ½, (r + ½)·size − ½).
        let x = ((u + 0.5) / size - 0.5).clamp(0.0, (self.columns - 1) as f64);
        let y = ((v + 0.5) / size - 0.5).clamp(0.0, (self.rows - 1) as f64);
        let (c0, r0) = (x.floor() as usize, y.floor() as usize);
        let (c1, r1) = ((c0 + 1).min(self.columns - 1), (r0 + 1).min(self.rows - 1));
        let (fx, fy) = (x - c0 as f64, y - r0 as f64);
        let at = |c: usize, r: usize| self.raw[r * self.columns + c];
        let top = at(c0, r0) * (1.0 - fx) + at(c1, r0) * fx;
        let bottom = at(c0, r1) * (1.0 - fx) + at(c1, r1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_plane_check_values_of_conventions() {
        let model = DepthModel::default();
        for (raw, mm) in [(400u16, 498.4), (700, 885.0), (800, 1193.7), (1000, 3948.3)] {
            let z = model.depth_m(raw).unwrap() * 1000.0;
            assert!((z - mm).abs() < 0.05, "raw {raw}: {z} mm, expected {mm}");
        }
        assert_eq!(model.depth_m(RAW_NO_READING), None);
    }

    #[test]
    fn inverse_linear_matches_formula() {
        let model = DepthModel::inverse_linear_default();
        let z = model.depth_m(800).unwrap();
        assert!((z - 1.0 / (3.3309495161 - 0.0030711016 * 800.0)).abs() < 1e-12);
        // Values past the model's pole give no depth rather than a negative one.
        assert_eq!(model.depth_m(1100), None);
    }

    #[test]
    fn inverse_depth_is_affine_in_the_raw_value_for_both_models() {
        for model in [DepthModel::default(), DepthModel::inverse_linear_default()] {
            let (a, b) = model.inverse_depth_affine();
            for raw in (350u16..1090).step_by(7) {
                if let Some(z) = model.depth_m(raw) {
                    let w = a + b * f64::from(raw);
                    assert!((1.0 / z - w).abs() < 1e-12, "{model:?} raw {raw}");
                }
            }
        }
    }

    #[test]
    fn default_focal_length_is_libfreenects() {
        assert!((Intrinsics::default().fx - 570.34).abs() < 0.01);
    }

    #[test]
    fn raw_for_depth_inverts_both_models() {
        for model in [DepthModel::default(), DepthModel::inverse_linear_default()] {
            for raw in [500u16, 600, 700, 800, 900, 1000] {
                let Some(z) = model.depth_m(raw) else {
                    continue;
                };
                assert_eq!(raw_for_depth(&model, z), Some(raw));
            }
            assert_eq!(raw_for_depth(&model, 0.01), None);
            assert_eq!(raw_for_depth(&model, -1.0), None);
        }
    }
}
