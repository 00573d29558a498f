//! The ground in inverse depth: the Kinect's own noise domain.
//!
//! The Kinect measures disparity; both of its depth models (conventions.md)
//! make the inverse depth `w = 1/z` an affine function of the raw value. Its
//! noise is the same for every pixel in that domain (about half a raw step),
//! where in metres it lies along each ray and grows as `z²`. A plane
//! `n·p + d = 0` seen through the pixel's ray `(1, up, right)` is linear in
//! inverse depth, `w = q·ray` with `q = −n/d`, and the ray is affine in the
//! pixel's column `u` and row `v`, so in the image the ground is
//!
//! ```text
//! w(u, v) = c0 + cu·(u − cx) + cv·(v − cy)
//! ```
//!
//! a [`PixelPlane`]. Fitting it is ordinary linear least squares with one σ for
//! the whole frame: the maximum-likelihood fit, unbiased, with a closed form
//! from moment sums over the pixels ([`DisparityMoments`]), and no conversion
//! of any pixel to metres. The same holds, as an approximation, for metric
//! depth images (PNG/TIFF in millimetres), which are Kinect-class disparity
//! converted to depth.
//!
//! This module holds the image in that domain ([`InverseDepthImage`]), the
//! plane and the moment sums with their solve; the pass over a frame's pixels
//! that gathers the sums is in [`sums`]; the robust search for the ground and
//! the rejection iterations are in [`super::plane`].

use nalgebra::{Matrix3, Matrix4, Vector3};

use super::geometry::Plane;
use crate::depth::{DepthEncoding, DepthRange, Intrinsics, RAW_NO_READING};

mod sums;
pub use sums::*;

/// One frame in inverse depth, 1/m, row-major; `+∞` where the pixel has no
/// trusted reading (no reading, or outside the trusted depth range), so that
/// no band test ever takes it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct InverseDepthImage {
    pub width: usize,
    pub height: usize,
    pub w: Vec<f32>,
    /// Pixels with a trusted reading.
    pub valid: usize,
}

/// How a frame's stored values become inverse depth.
#[derive(Debug, Clone)]
enum Conversion {
    /// Raw Kinect values: `w = a + b·raw` for `lo ≤ raw ≤ hi` (the trusted
    /// range), computed without a table so that the loop vectorises.
    Affine { a: f64, b: f64, lo: u16, hi: u16 },
    /// Any other encoding: one entry per value (`+∞` = not trusted).
    Table(Vec<f32>),
}

impl Conversion {
    /// The trusted readings' lowest and highest inverse depth (1/m).
    fn ends(&self) -> (f32, f32) {
        match self {
            Conversion::Affine { a, b, lo, hi } => {
                let (w_lo, w_hi) = (a + b * f64::from(*lo), a + b * f64::from(*hi));
                (w_lo.min(w_hi) as f32, w_lo.max(w_hi) as f32)
            }
            Conversion::Table(table) => {
                let finite = table.iter().filter(|w| w.is_finite());
                let lo = finite.clone().fold(f32::INFINITY, |m, &w| m.min(w));
                let hi = finite.fold(f32::NEG_INFINITY, |m, &w| m.max(w));
                (lo, hi)
            }
        }
    }
}

/// Converts frames to [`InverseDepthImage`]s: the encoding, the trusted range
/// and the image's size, fixed once per camera.
#[derive(Debug, Clone)]
pub struct InverseDepthConverter {
    conversion: Conversion,
    /// A fixed pattern to take out of every frame, per pixel in inverse
    /// depth (1/m, row-major): the Kinect's depth pattern a calibration
    /// found (`crate::distortion`). The frames are then fitted converted.
    correction: Option<std::sync::Arc<[f32]>>,
    /// The domain the fit reads frames in, worked out once.
    domain: ValueDomain,
    width: usize,
    height: usize,
}

impl InverseDepthConverter {
    /// A converter for frames of `intrinsics`' size in `encoding`, trusting
    /// depths in `range`.
    pub fn new(encoding: DepthEncoding, intrinsics: &Intrinsics, range: DepthRange) -> Self {
        let trusted = |z: Option<f64>| z.filter(|z| *z >= range.min_m && *z <= range.max_m);
        let conversion = match encoding {
            DepthEncoding::Raw11(model) => {
                let (a, b) = model.inverse_depth_affine();
                let valid: Vec<u16> = (0..RAW_NO_READING)
                    .filter(|&raw| trusted(model.depth_m(raw)).is_some())
                    .collect();
                match (valid.first(), valid.last()) {
                    // Depth is monotonic in the raw value, so the trusted
                    // values are one run; the table covers any other case.
                    (Some(&lo), Some(&hi)) if usize::from(hi - lo) + 1 == valid.len() => {
                        Conversion::Affine { a, b, lo, hi }
                    }
                    _ => Conversion::Table(
                        (0..=u16::MAX)
                            .map(|raw| match trusted(model.depth_m(raw)) {
                                Some(z) => (1.0 / z) as f32,
                                None => f32::INFINITY,
                            })
                            .collect(),
                    ),
                }
            }
            DepthEncoding::Metric { metres_per_unit } => Conversion::Table(
                (0..=u16::MAX)
                    .map(|value| {
                        let z = (value > 0).then_some(f64::from(value) * metres_per_unit);
                        match trusted(z) {
                            Some(z) => (1.0 / z) as f32,
                            None => f32::INFINITY,
                        }
                    })
                    .collect(),
            ),
        };
        let domain = match &conversion {
            Conversion::Affine { a, b, lo, hi } => ValueDomain {
                offset: *a,
                scale: *b,
                trusted: (f32::from(*lo), f32::from(*hi)),
                plane_within: (f32::from(*lo), f32::from(*hi)),
            },
            Conversion::Table(_) => {
                let (lo, hi) = conversion.ends();
                ValueDomain {
                    offset: 0.0,
                    scale: 1.0,
                    trusted: (lo, hi),
                    plane_within: (lo, hi),
                }
            }
        };
        Self {
            conversion,
            correction: None,
            domain,
            width: intrinsics.width,
            height: intrinsics.height,
        }
    }

    /// This converter taking `offsets` (1/m per pixel, row-major, the
    /// image's size) out of every frame's inverse depth. Frames are then
    /// converted before they are fitted, in inverse depth.
    pub fn with_correction(mut self, offsets: std::sync::Arc<[f32]>) -> Self {
        if offsets.len() != self.width * self.height {
            return self;
        }
        // The depth range's ends in inverse depth, as read (from the
        // conversion, not the domain: a second correction replaces the first).
        let (w_lo, w_hi) = self.conversion.ends();
        // Corrected values lie up to the largest offset beyond the range's
        // ends; a plane must lie as far within them (ValueDomain::plane_within).
        let slack = offsets.iter().fold(0f32, |m, o| m.max(o.abs()));
        self.domain = ValueDomain {
            offset: 0.0,
            scale: 1.0,
            trusted: (w_lo - slack, w_hi + slack),
            plane_within: (w_lo + slack, w_hi - slack),
        };
        self.correction = Some(offsets);
        self
    }

    /// The domain the fit reads frames in: raw values as they are (no
    /// conversion), anything else converted to inverse depth.
    pub fn domain(&self) -> ValueDomain {
        self.domain
    }

    /// Whether frames are fitted as they are (raw values), with no conversion.
    pub fn reads_raw(&self) -> bool {
        matches!(self.conversion, Conversion::Affine { .. }) && self.correction.is_none()
    }

    /// Converts a frame into `image`, reusing its memory. A frame of another
    /// size than the intrinsics' is refused by the caller; here the rows that
    /// both have are used, so nothing panics.
    pub fn convert_into(&self, pixels: &[u16], image: &mut InverseDepthImage) {
        let rows = (pixels.len() / self.width.max(1)).min(self.height);
        let n = rows * self.width;
        image.width = self.width;
        image.height = rows;
        image.w.clear();
        image.w.resize(n, f32::INFINITY);
        let mut valid = 0usize;
        match &self.conversion {
            Conversion::Affine { a, b, lo, hi } => {
                let (a, b) = (*a as f32, *b as f32);
                for (out, &raw) in image.w.iter_mut().zip(&pixels[..n]) {
                    let inside = raw >= *lo && raw <= *hi;
                    *out = if inside {
                        a + b * f32::from(raw)
                    } else {
                        f32::INFINITY
                    };
                    valid += usize::from(inside);
                }
            }
            Conversion::Table(table) => {
                for (out, &value) in image.w.iter_mut().zip(&pixels[..n]) {
                    let w = table[usize::from(value)];
                    *out = w;
                    valid += usize::from(w.is_finite());
                }
            }
        }
        if let Some(offsets) = &self.correction {
            // +∞ (no reading) stays +∞.
            for (w, offset) in image.w.iter_mut().zip(offsets.iter()) {
                *w -= offset;
            }
        }
        image.valid = valid;
    }

    /// Converts a frame to a new image.
    pub fn convert(&self, pixels: &[u16]) -> InverseDepthImage {
        let mut image = InverseDepthImage::default();
        self.convert_into(pixels, &mut image);
        image
    }
}

/// A plane in inverse depth over the image:
/// `w(u, v) = c0 + cu·(u − cx) + cv·(v − cy)`, 1/m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelPlane {
    pub c0: f64,
    pub cu: f64,
    pub cv: f64,
}

impl PixelPlane {
    /// The plane in the image of a plane in the sensor frame V.
    pub fn from_plane(plane: &Plane, intrinsics: &Intrinsics) -> Self {
        // w = q·(1, −(v − cy)/fy, (u − cx)/fx) with q = −n/d.
        let q = -plane.normal / plane.d;
        Self {
            c0: q.x,
            cu: q.z / intrinsics.fx,
            cv: -q.y / intrinsics.fy,
        }
    }

    /// `q = −n/d` of the plane in the sensor frame.
    pub fn q(&self, intrinsics: &Intrinsics) -> Vector3<f64> {
        Vector3::new(self.c0, -self.cv * intrinsics.fy, self.cu * intrinsics.fx)
    }

    /// The plane in the sensor frame (`d > 0`), or `None` for a plane through
    /// the optical centre or with numbers that are not finite.
    pub fn to_plane(&self, intrinsics: &Intrinsics) -> Option<Plane> {
        let q = self.q(intrinsics);
        let norm = q.norm();
        if !(norm.is_finite() && norm > 1e-12) {
            return None;
        }
        Some(Plane {
            normal: -q / norm,
            d: 1.0 / norm,
        })
    }

    /// Inverse depth at pixel offsets `(u − cx, v − cy)`.
    pub fn at(&self, du: f64, dv: f64) -> f64 {
        self.c0 + self.cu * du + self.cv * dv
    }

    /// This plane moved by a least-squares correction.
    fn corrected(&self, delta: &Vector3<f64>) -> Self {
        Self {
            c0: self.c0 + delta.x,
            cu: self.cu + delta.y,
            cv: self.cv + delta.z,
        }
    }

    /// The largest difference of inverse depth between two planes over the
    /// image's corners: how far apart they are where it matters.
    pub fn largest_difference(&self, other: &PixelPlane, intrinsics: &Intrinsics) -> f64 {
        let (u0, u1) = (
            -intrinsics.cx,
            intrinsics.width as f64 - 1.0 - intrinsics.cx,
        );
        let (v0, v1) = (
            -intrinsics.cy,
            intrinsics.height as f64 - 1.0 - intrinsics.cy,
        );
        [(u0, v0), (u0, v1), (u1, v0), (u1, v1)]
            .iter()
            .map(|&(u, v)| (self.at(u, v) - other.at(u, v)).abs())
            .fold(0.0, f64::max)
    }

    /// Covariance of `(a, b, c, d)` of the plane in the sensor frame from the
    /// covariance of `(c0, cu, cv)`.
    pub fn plane_covariance(
        &self,
        intrinsics: &Intrinsics,
        covariance: &Matrix3<f64>,
    ) -> Option<Matrix4<f64>> {
        let plane = self.to_plane(intrinsics)?;
        // q = M·(c0, cu, cv).
        let m = Matrix3::new(
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            -intrinsics.fy,
            0.0,
            intrinsics.fx,
            0.0,
        );
        let covariance_q = m * covariance * m.transpose();
        // n = −q/|q|, d = 1/|q|: ∂n/∂q = −d·(I − n·nᵀ), ∂d/∂q = d²·nᵀ.
        let n = plane.normal;
        let d = plane.d;
        let dn = -(Matrix3::identity() - n * n.transpose()) * d;
        let dd = n.transpose() * (d * d);
        let mut jacobian = nalgebra::Matrix4x3::zeros();
        jacobian.fixed_view_mut::<3, 3>(0, 0).copy_from(&dn);
        jacobian.fixed_view_mut::<1, 3>(3, 0).copy_from(&dd);
        Some(jacobian * covariance_q * jacobian.transpose())
    }
}

/// Sums over pixels for the least-squares plane in inverse depth, with the
/// pixel offsets `(u − cx, v − cy)` and the residuals `r = w − plane(u, v)` to
/// the plane the pixels were chosen by. Sums over several frames (and several
/// cells) add.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DisparityMoments {
    pub count: f64,
    pub su: f64,
    pub sv: f64,
    pub suu: f64,
    pub suv: f64,
    pub svv: f64,
    pub sr: f64,
    pub sur: f64,
    pub svr: f64,
    pub srr: f64,
}

/// The least-squares correction of a plane from its moments.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneCorrection {
    /// The corrected plane.
    pub plane: PixelPlane,
    /// `(XᵀX)⁻¹` of `(c0, cu, cv)`: times σ², the plane's covariance.
    pub inverse_information: Matrix3<f64>,
    /// Residual sum of squares about the corrected plane, (1/m)².
    pub rss: f64,
}

impl DisparityMoments {
    /// Adds another set of sums (another frame, cell or row).
    pub fn add(&mut self, other: &DisparityMoments) {
        self.count += other.count;
        self.su += other.su;
        self.sv += other.sv;
        self.suu += other.suu;
        self.suv += other.suv;
        self.svv += other.svv;
        self.sr += other.sr;
        self.sur += other.sur;
        self.svr += other.svr;
        self.srr += other.srr;
    }

    /// The sums of one row at offset `dv`, from its sums over columns.
    fn add_row(&mut self, dv: f64, row: &[f64; 6]) {
        let [n, su, suu, sr, sur, srr] = *row;
        self.count += n;
        self.su += su;
        self.sv += dv * n;
        self.suu += suu;
        self.suv += dv * su;
        self.svv += dv * dv * n;
        self.sr += sr;
        self.sur += sur;
        self.svr += dv * sr;
        self.srr += srr;
    }

    /// The least-squares plane alone (no covariance), with its residual sum
    /// of squares: the search's many small solves.
    pub fn solve_plane(&self, plane: &PixelPlane) -> Option<(PixelPlane, f64)> {
        if self.count < 3.0 {
            return None;
        }
        // The symmetric 3×3 normal equations by LDLᵀ, written out: the search
        // solves a thousand of them per frame.
        let (a11, a12, a13, a22, a23, a33) =
            (self.count, self.su, self.sv, self.suu, self.suv, self.svv);
        let (b1, b2, b3) = (self.sr, self.sur, self.svr);
        let d1 = a11;
        let l21 = a12 / d1;
        let l31 = a13 / d1;
        let d2 = a22 - l21 * a12;
        if !(d1 > 0.0 && d2 > 1e-12 * a22.abs().max(1.0)) {
            return None;
        }
        let l32 = (a23 - l31 * a12) / d2;
        let d3 = a33 - l31 * a13 - l32 * l32 * d2;
        if d3.is_nan() || d3 <= 1e-12 * a33.abs().max(1.0) {
            return None;
        }
        let y1 = b1;
        let y2 = b2 - l21 * y1;
        let y3 = b3 - l31 * y1 - l32 * y2;
        let x3 = y3 / d3;
        let x2 = y2 / d2 - l32 * x3;
        let x1 = y1 / d1 - l21 * x2 - l31 * x3;
        let delta = Vector3::new(x1, x2, x3);
        if !delta.iter().all(|v| v.is_finite()) {
            return None;
        }
        let rhs = Vector3::new(b1, b2, b3);
        Some((
            plane.corrected(&delta),
            (self.srr - delta.dot(&rhs)).max(0.0),
        ))
    }

    /// The least-squares plane: `plane` (the one the residuals were taken to)
    /// corrected. `None` when the pixels do not fix a plane.
    pub fn solve(&self, plane: &PixelPlane) -> Option<PlaneCorrection> {
        if self.count < 3.0 {
            return None;
        }
        let information = Matrix3::new(
            self.count, self.su, self.sv, self.su, self.suu, self.suv, self.sv, self.suv, self.svv,
        );
        let rhs = Vector3::new(self.sr, self.sur, self.svr);
        let cholesky = information.cholesky()?;
        let delta = cholesky.solve(&rhs);
        if !delta.iter().all(|v| v.is_finite()) {
            return None;
        }
        let rss = (self.srr - delta.dot(&rhs)).max(0.0);
        Some(PlaneCorrection {
            plane: plane.corrected(&delta),
            inverse_information: cholesky.inverse(),
            rss,
        })
    }
}

/// The variance of a standard normal variable kept only within `±b`, relative
/// to the untruncated variance: `1 − 2b·φ(b) / (2Φ(b) − 1)`.
///
/// The rejection keeps the pixels within a band of the plane; the RMS of
/// what it keeps underestimates the noise by this factor, and the paper's
/// rule ("2σ" with σ the RMS of the kept points) settles at ±1.5 true σ.
/// Dividing it out makes `k·σ` mean what it says.
pub fn truncated_variance_factor(b: f64) -> f64 {
    if b > 8.0 {
        return 1.0;
    }
    let phi = (-0.5 * b * b).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let mass = erf(b / std::f64::consts::SQRT_2);
    if mass <= 1e-12 {
        // Vanishing band: the variance of a uniform slice, b²/3.
        return (b * b / 3.0).max(1e-12);
    }
    (1.0 - 2.0 * b * phi / mass).max(1e-12)
}

/// The error function (Abramowitz and Stegun 7.1.26, |error| < 1.5·10⁻⁷).
fn erf(x: f64) -> f64 {
    let sign = x.signum();
    let x = x.abs();
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    sign * (1.0 - poly * (-x * x).exp())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row's readings, the readings above them, `du`, and its test.
    #[cfg(any(target_arch = "aarch64", target_arch = "x86_64"))]
    type RandomRow = (Vec<u16>, Vec<u16>, Vec<f32>, RowTest);

    /// Random rows for the lane loops: raw readings around a plane (some far
    /// off, some untrusted), of a length that leaves a remainder.
    #[cfg(any(target_arch = "aarch64", target_arch = "x86_64"))]
    fn random_rows(seed: u64) -> Vec<RandomRow> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..200)
            .map(|_| {
                let n = rng.gen_range(0..700);
                let base: f32 = rng.gen_range(500.0..1000.0);
                let cu: f32 = rng.gen_range(-0.5..0.5);
                let du: Vec<f32> = (0..n).map(|u| u as f32 - 319.5).collect();
                let reading = |rng: &mut rand_chacha::ChaCha8Rng, d: f32| -> u16 {
                    match rng.gen_range(0..10) {
                        0 => 2047,
                        1 => rng.gen_range(0..2047),
                        _ => (base + cu * d + rng.gen_range(-4.0f32..4.0)).round() as u16,
                    }
                };
                let values = du.iter().map(|&d| reading(&mut rng, d)).collect();
                let above = du.iter().map(|&d| reading(&mut rng, d)).collect();
                let test = RowTest {
                    base,
                    base_above: base - rng.gen_range(0.0..3.0),
                    cu,
                    band: rng.gen_range(0.5..6.0),
                    guard: (rng.gen_range(0.5..6.0), 400.0, 1090.0),
                };
                (values, above, du, test)
            })
            .collect()
    }

    /// The processor's own loop (NEON on arm64, AVX2 on x86-64 where the
    /// processor has it) gives the reference loop's sums bit for bit,
    /// guarded and not, on raw readings and on metric ones with infinities
    /// and NaN.
    #[cfg(any(target_arch = "aarch64", target_arch = "x86_64"))]
    #[test]
    fn the_vector_loop_matches_the_reference_bit_for_bit() {
        #[cfg(target_arch = "aarch64")]
        fn vector_loop<T: FitValue, const GUARDED: bool>(
            pixels: RowPixels<'_, T>,
            test: &RowTest,
        ) -> LaneSums {
            lane_sums_neon::<T, GUARDED>(pixels, test)
        }
        #[cfg(target_arch = "x86_64")]
        fn vector_loop<T: FitValue, const GUARDED: bool>(
            pixels: RowPixels<'_, T>,
            test: &RowTest,
        ) -> LaneSums {
            // SAFETY: only called where the processor has AVX2 (below).
            #[allow(unsafe_code)]
            unsafe {
                lane_sums_avx2::<T, GUARDED>(pixels, test)
            }
        }
        #[cfg(target_arch = "x86_64")]
        if !std::is_x86_feature_detected!("avx2") {
            // Without AVX2 the reference loop is the one that runs.
            eprintln!("this processor has no AVX2: the reference loop is the one that runs");
            return;
        }
        fn same<T: FitValue>(pixels: RowPixels<'_, T>, test: &RowTest) {
            let full = pixels.values.len() / LANES * LANES;
            let pixels = RowPixels {
                values: &pixels.values[..full],
                above: &pixels.above[..full],
                du: &pixels.du[..full],
                du2: &pixels.du2[..full],
            };
            let bits = |sums: LaneSums| sums.map(|lane| lane.map(f32::to_bits));
            assert_eq!(
                bits(lane_sums::<T, true>(pixels, test)),
                bits(vector_loop::<T, true>(pixels, test))
            );
            assert_eq!(
                bits(lane_sums::<T, false>(pixels, test)),
                bits(vector_loop::<T, false>(pixels, test))
            );
        }
        let mut compared = 0;
        for (values, above, du, test) in random_rows(24) {
            let du2: Vec<f32> = du.iter().map(|d| d * d).collect();
            same(
                RowPixels {
                    values: &values,
                    above: &above,
                    du: &du,
                    du2: &du2,
                },
                &test,
            );
            // The same readings as metric values, untrusted ones infinite and
            // one in seven NaN.
            let metric = crate::test_noise::metric_with_nan;
            let scaled = RowTest {
                base: test.base * 1e-3,
                base_above: test.base_above * 1e-3,
                cu: test.cu * 1e-3,
                band: test.band * 1e-3,
                guard: (test.guard.0 * 1e-3, 0.4, 1.09),
            };
            same(
                RowPixels {
                    values: &metric(&values),
                    above: &metric(&above),
                    du: &du,
                    du2: &du2,
                },
                &scaled,
            );
            compared += values.len();
        }
        assert!(compared > 50_000, "{compared} pixels compared");
    }
    use crate::sensor::DepthModel;

    fn intrinsics() -> Intrinsics {
        Intrinsics::default()
    }

    #[test]
    fn pixel_planes_round_trip_to_sensor_planes() {
        let plane = Plane::from_coefficients(-0.55, 0.78, -0.3, 0.99).unwrap();
        let pixel = PixelPlane::from_plane(&plane, &intrinsics());
        let back = pixel.to_plane(&intrinsics()).unwrap();
        assert!((back.normal - plane.normal).norm() < 1e-12);
        assert!((back.d - plane.d).abs() < 1e-12);
        // A point of the plane, seen through its pixel, has the predicted w.
        let (u, v) = (100.0, 400.0);
        let i = intrinsics();
        let ray = Vector3::new(1.0, -(v - i.cy) / i.fy, (u - i.cx) / i.fx);
        let z = -plane.d / plane.normal.dot(&ray);
        assert!((pixel.at(u - i.cx, v - i.cy) - 1.0 / z).abs() < 1e-12);
    }

    #[test]
    fn raw_frames_convert_exactly_and_untrusted_pixels_are_infinite() {
        for model in [DepthModel::default(), DepthModel::inverse_linear_default()] {
            let i = Intrinsics {
                width: 4,
                height: 1,
                ..intrinsics()
            };
            let converter =
                InverseDepthConverter::new(DepthEncoding::Raw11(model), &i, DepthRange::default());
            let image = converter.convert(&[800, RAW_NO_READING, 100, 1000]);
            assert_eq!(image.valid, 2);
            let z = model.depth_m(800).unwrap();
            assert!((f64::from(image.w[0]) - 1.0 / z).abs() < 1e-6);
            assert!(image.w[1].is_infinite() && image.w[2].is_infinite());
        }
    }

    /// With a pattern taken out, the corrected values reach beyond the
    /// range's ends by its largest offset, and a plane must lie as far
    /// within them: readings are cut off by the range on their own value,
    /// pattern included (a plane as near the end as without a correction
    /// lost the readings the pattern pushed out, a bias at the same place
    /// on the ground at every pose: the ground's test fired at 12σ on flat
    /// ground).
    #[test]
    fn a_corrected_plane_keeps_the_patterns_reach_from_the_ranges_ends() {
        for encoding in [
            DepthEncoding::Raw11(DepthModel::inverse_linear_default()),
            DepthEncoding::Metric {
                metres_per_unit: 0.001,
            },
        ] {
            let i = Intrinsics {
                width: 4,
                height: 1,
                ..intrinsics()
            };
            let plain = InverseDepthConverter::new(encoding, &i, DepthRange::default());
            let (lo, hi) = plain.domain().trusted;
            let (lo, hi) = match encoding {
                DepthEncoding::Raw11(model) => {
                    let (a, b) = model.inverse_depth_affine();
                    let ends = (a + b * f64::from(lo), a + b * f64::from(hi));
                    (ends.0.min(ends.1) as f32, ends.0.max(ends.1) as f32)
                }
                DepthEncoding::Metric { .. } => (lo, hi),
            };
            let offsets: std::sync::Arc<[f32]> = vec![0.002, -0.009, 0.0, 0.004].into();
            // A second correction replaces the first, whatever its reach.
            let first: std::sync::Arc<[f32]> = vec![0.05; 4].into();
            let corrected = plain
                .with_correction(first)
                .with_correction(offsets)
                .domain();
            assert!(
                (corrected.plane_within.0 - (lo + 0.009)).abs() < 1e-6,
                "{corrected:?}"
            );
            assert!(
                (corrected.plane_within.1 - (hi - 0.009)).abs() < 1e-6,
                "{corrected:?}"
            );
            assert!(
                (corrected.trusted.0 - (lo - 0.009)).abs() < 1e-6,
                "{corrected:?}"
            );
            assert!(
                (corrected.trusted.1 - (hi + 0.009)).abs() < 1e-6,
                "{corrected:?}"
            );
        }
    }

    #[test]
    fn moments_solve_a_plane_exactly() {
        let i = Intrinsics {
            width: 37,
            height: 11,
            ..intrinsics()
        };
        let truth = PixelPlane {
            c0: 0.8,
            cu: 1e-4,
            cv: -3e-4,
        };
        let mut image = InverseDepthImage {
            width: i.width,
            height: i.height,
            w: Vec::new(),
            valid: 0,
        };
        for v in 0..i.height {
            for u in 0..i.width {
                image
                    .w
                    .push(truth.at(u as f64 - i.cx, v as f64 - i.cy) as f32);
            }
        }
        let grid = PixelGrid::new(i);
        let domain = ValueDomain {
            offset: 0.0,
            scale: 1.0,
            trusted: (0.01, 10.0),
            plane_within: (0.01, 10.0),
        };
        let start = PixelPlane {
            c0: 0.81,
            cu: 0.0,
            cv: 0.0,
        };
        let frame = Frame {
            values: &image.w,
            width: image.width,
            height: image.height,
        };
        let m = grid.moments_within(&frame, &domain, &start, 0.1, 0, 1, None);
        assert_eq!(m.count, (i.width * i.height) as f64);
        let fit = m.solve(&start).unwrap();
        assert!((fit.plane.c0 - truth.c0).abs() < 1e-6, "{:?}", fit.plane);
        assert!((fit.plane.cu - truth.cu).abs() < 1e-8);
        assert!((fit.plane.cv - truth.cv).abs() < 1e-8);
        // What is left is the f32 rounding of the sums (noise would give ~1e-3).
        assert!(fit.rss < 1e-6, "{}", fit.rss);
    }

    #[test]
    fn truncation_factor_matches_known_values() {
        // Var of N(0,1) truncated at ±2: 0.7737; at ±1.5: 0.5516.
        assert!((truncated_variance_factor(2.0) - 0.7737).abs() < 1e-3);
        assert!((truncated_variance_factor(1.5) - 0.5516).abs() < 1e-3);
        assert!((truncated_variance_factor(20.0) - 1.0).abs() < 1e-12);
        assert!((erf(1.0) - 0.842_700_79).abs() < 2e-7);
    }
}
