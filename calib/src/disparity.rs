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
//! plane and the moment sums with their solve; the robust search for the
//! ground and the rejection iterations are in [`super::plane`].

use nalgebra::{Matrix3, Matrix4, Vector3};

use super::geometry::Plane;
use crate::depth::{DepthEncoding, DepthRange, Intrinsics, RAW_NO_READING};

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
            },
            Conversion::Table(table) => {
                let finite = table.iter().filter(|w| w.is_finite());
                let lo = finite.clone().fold(f32::INFINITY, |m, &w| m.min(w));
                let hi = finite.fold(f32::NEG_INFINITY, |m, &w| m.max(w));
                ValueDomain {
                    offset: 0.0,
                    scale: 1.0,
                    trusted: (lo, hi),
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
        if let Conversion::Affine { a, b, lo, hi } = self.conversion {
            let (w_lo, w_hi) = (a + b * f64::from(lo), a + b * f64::from(hi));
            // Wide enough for the corrected values (a pattern is a few raw
            // units at most; the range's ends stay where the depths are).
            let slack = offsets.iter().fold(0f32, |m, o| m.max(o.abs()));
            self.domain = ValueDomain {
                offset: 0.0,
                scale: 1.0,
                trusted: (w_lo.min(w_hi) as f32 - slack, w_lo.max(w_hi) as f32 + slack),
            };
        }
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

/// A value of a frame the fit reads: a raw Kinect value, or an inverse depth.
pub trait FitValue: Copy + Send + Sync {
    /// The step between two values the sensor can give (a whole raw unit),
    /// or 0 where the steps are not even (inverse depth converted from
    /// millimetres): rounding to it is noise of `QUANTUM/√12` at least.
    const QUANTUM: f64;

    fn to_f32(self) -> f32;

    /// How many of `values` lie in `lo..=hi`.
    fn count_between(values: &[Self], lo: f32, hi: f32) -> usize;
}

impl FitValue for u16 {
    const QUANTUM: f64 = 1.0;

    #[inline(always)]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }

    fn count_between(values: &[u16], lo: f32, hi: f32) -> usize {
        // In integers, one comparison a value: the loop vectorises.
        let lo = lo.ceil().clamp(0.0, 65535.0) as u16;
        let hi = hi.floor().clamp(0.0, 65535.0) as u16;
        if lo > hi {
            return 0;
        }
        let span = hi - lo;
        values
            .chunks(1 << 15)
            .map(|chunk| {
                chunk
                    .iter()
                    .map(|&v| u16::from(v.wrapping_sub(lo) <= span))
                    .sum::<u16>() as usize
            })
            .sum()
    }
}

impl FitValue for f32 {
    const QUANTUM: f64 = 0.0;

    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }

    fn count_between(values: &[f32], lo: f32, hi: f32) -> usize {
        values.iter().filter(|&&v| v >= lo && v <= hi).count()
    }
}

/// One frame as the fit reads it: row-major values, in a [`ValueDomain`].
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a, T> {
    pub values: &'a [T],
    pub width: usize,
    pub height: usize,
}

impl<'a, T: FitValue> Frame<'a, T> {
    /// The value at column `u`, row `v`.
    pub fn at(&self, u: usize, v: usize) -> f32 {
        self.values[v * self.width + u].to_f32()
    }

    /// Pixels whose value is trusted.
    pub fn count_trusted(&self, domain: &ValueDomain) -> usize {
        T::count_between(self.values, domain.trusted.0, domain.trusted.1)
    }
}

/// How a frame's values relate to inverse depth, `w = offset + scale·value`
/// (1/m), and which values are trusted. Raw Kinect frames are fitted in raw
/// units, with no conversion of any pixel; other frames are converted to
/// inverse depth first (`offset = 0`, `scale = 1`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValueDomain {
    pub offset: f64,
    pub scale: f64,
    /// Trusted values, lowest and highest (the trusted depth range).
    pub trusted: (f32, f32),
}

impl ValueDomain {
    /// A plane of values as a plane of inverse depth.
    pub fn to_inverse_depth(&self, plane: &PixelPlane) -> PixelPlane {
        PixelPlane {
            c0: self.offset + self.scale * plane.c0,
            cu: self.scale * plane.cu,
            cv: self.scale * plane.cv,
        }
    }

    /// A plane of inverse depth as a plane of values.
    pub fn from_inverse_depth(&self, plane: &PixelPlane) -> PixelPlane {
        PixelPlane {
            c0: (plane.c0 - self.offset) / self.scale,
            cu: plane.cu / self.scale,
            cv: plane.cv / self.scale,
        }
    }
}

/// Column offsets `u − cx` of an image and their squares, built once per
/// camera so that the per-pixel loop only loads them.
#[derive(Debug, Clone)]
pub struct PixelGrid {
    pub intrinsics: Intrinsics,
    du: Vec<f32>,
    du2: Vec<f32>,
}

/// One pass over a frame: the pixels within `band` of `plane`, on every
/// `rows.1`-th row from `rows.0`, less those the guard leaves out.
struct Pass<'a, T> {
    frame: &'a Frame<'a, T>,
    domain: &'a ValueDomain,
    plane: &'a PixelPlane,
    band: f64,
    rows: (usize, usize),
    guard: Option<EdgeGuard>,
}

/// Leaves out the pixels where the ground meets something standing on it.
///
/// The foot of a wall or of a box's side lies on the ground, so the face's
/// lowest rows of pixels are within any band around the ground's plane,
/// always on the side of the sensor: kept, they pull the plane towards the
/// sensor where the obstacles stand (a bias of a few tenths of a millimetre
/// across a cluttered view, issue 22). Going up the image from such a pixel,
/// the face leaves the band within a few rows, while the ground stays in it.
/// So a pixel is kept only when the pixel `rows` rows above it is within
/// `limit` of the plane too, or has no trusted value (a shadow, a dropout).
/// On open ground this leaves out pixels whose neighbour is a noise outlier:
/// a choice independent of their own noise, so it adds no bias.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeGuard {
    /// How far above, in rows.
    pub rows: usize,
    /// How far from the plane the pixel above may be, in the frame's value
    /// units.
    pub limit: f64,
}

/// Lanes of the per-pixel loops: a fixed number, so that every build (SSE2,
/// AVX2, NEON) adds the same numbers in the same order and the results are
/// bit-identical.
const LANES: usize = 16;

/// Sums of one row: inliers, `Σu`, `Σu²`, `Σr`, `Σu·r`, `Σr²`.
type RowSums = [f64; 6];

/// The sum of `N` lanes (a power of two, at least 4), pairwise in a fixed
/// order: halves folded until four are left, then `(0 + 2) + (1 + 3)`. The
/// same order on every processor, so the sums are bit-identical.
#[inline(always)]
pub(crate) fn lane_sum<const N: usize>(lanes: &[f32; N]) -> f64 {
    let mut values = *lanes;
    let mut n = N;
    while n > 4 {
        n /= 2;
        for i in 0..n {
            values[i] += values[i + n];
        }
    }
    f64::from((values[0] + values[2]) + (values[1] + values[3]))
}

/// The edge guard's test of the pixel above: within `limit` of the plane
/// there (`expected`), or untrusted (outside `lo..=hi`). Branch-free (`|`),
/// so that the lanes stay vectors.
#[inline(always)]
pub(crate) fn clear_above(
    value_above: f32,
    expected: f32,
    (limit, lo, hi): (f32, f32, f32),
) -> bool {
    ((value_above - expected).abs() < limit) | (value_above < lo) | (value_above > hi)
}

/// One row's pixels for the per-pixel loop: the values, the values
/// [`EdgeGuard::rows`] above (the same columns; read only when guarded), and
/// the column offsets `du` and `du²`, all of one length.
#[derive(Clone, Copy)]
struct RowPixels<'a, T> {
    values: &'a [T],
    above: &'a [T],
    du: &'a [f32],
    du2: &'a [f32],
}

/// What the per-pixel loop tests a row's pixels against: the plane's value
/// at `du = 0` on this row (`base`) and on the row above (`base_above`), its
/// slope along the row (`cu`), the band, and the edge guard's
/// `(limit, lo, hi)`.
#[derive(Clone, Copy)]
struct RowTest {
    base: f32,
    base_above: f32,
    cu: f32,
    band: f32,
    guard: (f32, f32, f32),
}

/// Per-lane running sums: inliers, `Σu`, `Σu²`, `Σr`, `Σu·r`, `Σr²`.
type LaneSums = [[f32; LANES]; 6];

/// The per-pixel loop of [`PixelGrid::moments_within`] over one row: the
/// pixels within `band` of `base + cu·du`.
///
/// With `GUARDED`, a pixel counts only if its value in `above` lies within
/// `guard.0` of `base_above + cu·du`, or outside the trusted values
/// `guard.1..=guard.2`.
///
/// The whole chunks of [`LANES`] pixels go through [`lane_sums`] (NEON on
/// arm64), the rest one by one in f64.
#[inline(always)]
fn row_sums<T: FitValue, const GUARDED: bool>(row: RowPixels<'_, T>, test: &RowTest) -> RowSums {
    let n = row.values.len().min(row.du.len()).min(row.du2.len());
    let n = if GUARDED { n.min(row.above.len()) } else { n };
    let full = n / LANES * LANES;
    let chunks = RowPixels {
        values: &row.values[..full],
        above: if GUARDED { &row.above[..full] } else { &[] },
        du: &row.du[..full],
        du2: &row.du2[..full],
    };
    #[cfg(target_arch = "aarch64")]
    let acc = lane_sums_neon::<T, GUARDED>(chunks, test);
    #[cfg(not(target_arch = "aarch64"))]
    let acc = lane_sums::<T, GUARDED>(chunks, test);
    let mut sums: RowSums = std::array::from_fn(|k| lane_sum(&acc[k]));
    let RowTest {
        base,
        base_above,
        cu,
        band,
        guard,
    } = *test;
    for k in full..n {
        let (v, d, d2) = (row.values[k], row.du[k], row.du2[k]);
        let r = v.to_f32() - (base + cu * d);
        let clear = !GUARDED || clear_above(row.above[k].to_f32(), base_above + cu * d, guard);
        if r.abs() < band && clear {
            let (d, d2, r) = (f64::from(d), f64::from(d2), f64::from(r));
            sums[0] += 1.0;
            sums[1] += d;
            sums[2] += d2;
            sums[3] += r;
            sums[4] += d * r;
            sums[5] += r * r;
        }
    }
    sums
}

/// The per-lane sums over whole chunks of [`LANES`] pixels, written as
/// independent lanes, which compilers turn into vector instructions of any
/// width (AVX2 where [`PixelGrid::moments_within`] finds it). This is the
/// reference that [`lane_sums_neon`] matches bit for bit.
#[inline(always)]
#[cfg_attr(target_arch = "aarch64", allow(dead_code))]
fn lane_sums<T: FitValue, const GUARDED: bool>(row: RowPixels<'_, T>, test: &RowTest) -> LaneSums {
    let RowTest {
        base,
        base_above,
        cu,
        band,
        guard,
    } = *test;
    let mut acc: LaneSums = [[0f32; LANES]; 6];
    let mut lanes = |v: &[T], a: &[T], d: &[f32], d2: &[f32]| {
        for l in 0..LANES {
            let r = v[l].to_f32() - (base + cu * d[l]);
            let mut inside = r.abs() < band;
            if GUARDED {
                inside &= clear_above(a[l].to_f32(), base_above + cu * d[l], guard);
            }
            let one = if inside { 1.0 } else { 0.0 };
            let kept = if inside { r } else { 0.0 };
            acc[0][l] += one;
            acc[1][l] += one * d[l];
            acc[2][l] += one * d2[l];
            acc[3][l] += kept;
            acc[4][l] += kept * d[l];
            acc[5][l] += kept * kept;
        }
    };
    let chunks = row
        .values
        .chunks_exact(LANES)
        .zip(row.du.chunks_exact(LANES))
        .zip(row.du2.chunks_exact(LANES));
    if GUARDED {
        for (((v, d), d2), a) in chunks.zip(row.above.chunks_exact(LANES)) {
            lanes(v, a, d, d2);
        }
    } else {
        for ((v, d), d2) in chunks {
            lanes(v, v, d, d2);
        }
    }
    acc
}

/// [`lane_sums`] in NEON, four vectors of four lanes: the same operations
/// in the same order (a multiply then an add, never fused, as Rust's scalar
/// `a + b * c` is), so the sums are bit-identical to the reference's on
/// every input, NaN and infinities included (a comparison with NaN is false
/// in both). NEON is part of every arm64 processor (and of the target's
/// baseline), so no run-time check is needed.
#[cfg(target_arch = "aarch64")]
#[inline(always)]
fn lane_sums_neon<T: FitValue, const GUARDED: bool>(
    row: RowPixels<'_, T>,
    test: &RowTest,
) -> LaneSums {
    use std::arch::aarch64::*;
    const VECTORS: usize = LANES / 4;
    let RowTest {
        base,
        base_above,
        cu,
        band,
        guard: (limit, lo, hi),
    } = *test;
    // SAFETY: NEON is in the aarch64 target's baseline features; the loads
    // and stores read and write `[f32; 4]`s that are in bounds by their type.
    #[allow(unsafe_code)]
    unsafe {
        let zero = vdupq_n_f32(0.0);
        let one = vdupq_n_f32(1.0);
        let (base, base_above, cu) = (vdupq_n_f32(base), vdupq_n_f32(base_above), vdupq_n_f32(cu));
        let (band, limit, lo, hi) = (
            vdupq_n_f32(band),
            vdupq_n_f32(limit),
            vdupq_n_f32(lo),
            vdupq_n_f32(hi),
        );
        let mut acc = [[zero; VECTORS]; 6];
        let n = row.values.len() / LANES * LANES;
        for start in (0..n).step_by(LANES) {
            let mut value = [0f32; LANES];
            let mut value_above = [0f32; LANES];
            for l in 0..LANES {
                value[l] = row.values[start + l].to_f32();
                if GUARDED {
                    value_above[l] = row.above[start + l].to_f32();
                }
            }
            for q in 0..VECTORS {
                let at = start + 4 * q;
                let d = vld1q_f32(row.du[at..at + 4].as_ptr());
                let d2 = vld1q_f32(row.du2[at..at + 4].as_ptr());
                let v = vld1q_f32(value[4 * q..4 * q + 4].as_ptr());
                let r = vsubq_f32(v, vaddq_f32(base, vmulq_f32(cu, d)));
                let mut inside = vcltq_f32(vabsq_f32(r), band);
                if GUARDED {
                    let a = vld1q_f32(value_above[4 * q..4 * q + 4].as_ptr());
                    let off = vsubq_f32(a, vaddq_f32(base_above, vmulq_f32(cu, d)));
                    let clear = vorrq_u32(
                        vorrq_u32(vcltq_f32(vabsq_f32(off), limit), vcltq_f32(a, lo)),
                        vcgtq_f32(a, hi),
                    );
                    inside = vandq_u32(inside, clear);
                }
                let counted = vbslq_f32(inside, one, zero);
                let kept = vbslq_f32(inside, r, zero);
                acc[0][q] = vaddq_f32(acc[0][q], counted);
                acc[1][q] = vaddq_f32(acc[1][q], vmulq_f32(counted, d));
                acc[2][q] = vaddq_f32(acc[2][q], vmulq_f32(counted, d2));
                acc[3][q] = vaddq_f32(acc[3][q], kept);
                acc[4][q] = vaddq_f32(acc[4][q], vmulq_f32(kept, d));
                acc[5][q] = vaddq_f32(acc[5][q], vmulq_f32(kept, kept));
            }
        }
        let mut out: LaneSums = [[0f32; LANES]; 6];
        for (sums, vectors) in out.iter_mut().zip(&acc) {
            for (q, vector) in vectors.iter().enumerate() {
                vst1q_f32(sums[4 * q..4 * q + 4].as_mut_ptr(), *vector);
            }
        }
        out
    }
}

impl PixelGrid {
    pub fn new(intrinsics: Intrinsics) -> Self {
        let du: Vec<f32> = (0..intrinsics.width)
            .map(|u| (u as f64 - intrinsics.cx) as f32)
            .collect();
        let du2 = du.iter().map(|d| d * d).collect();
        Self {
            intrinsics,
            du,
            du2,
        }
    }

    /// Row offset `v − cy`.
    pub fn dv(&self, row: usize) -> f64 {
        row as f64 - self.intrinsics.cy
    }

    /// The columns of row offset `dv` where `plane` lies within the trusted
    /// values by at least `band`, as `start..end`.
    ///
    /// Pixels are chosen by where the plane says they are, never by their
    /// own reading: a reading near the range's ends is cut off by the noise
    /// on one side only (by the sensor, or by the range check), and choosing
    /// by the reading would bias the fit towards the middle of the range.
    fn columns_in_range(
        &self,
        plane: &PixelPlane,
        domain: &ValueDomain,
        dv: f64,
        band: f64,
    ) -> (usize, usize) {
        let (lo, hi) = (
            f64::from(domain.trusted.0) + band,
            f64::from(domain.trusted.1) - band,
        );
        let base = plane.c0 + plane.cv * dv;
        let width = self.du.len();
        if lo >= hi {
            return (0, 0);
        }
        if plane.cu.abs() < 1e-15 {
            return if (lo..=hi).contains(&base) {
                (0, width)
            } else {
                (0, 0)
            };
        }
        // base + cu·du ∈ [lo, hi], du = u − cx.
        let (a, b) = ((lo - base) / plane.cu, (hi - base) / plane.cu);
        let (du_min, du_max) = if a <= b { (a, b) } else { (b, a) };
        let cx = self.intrinsics.cx;
        let start = (du_min + cx).ceil().clamp(0.0, width as f64) as usize;
        let end = ((du_max + cx).floor() + 1.0).clamp(0.0, width as f64) as usize;
        (start, end.max(start))
    }

    /// The moments of the pixels of every `row_step`-th row (from `first_row`)
    /// whose value lies within `band` of `plane` (both in the frame's value
    /// units), among the pixels where the plane is within the trusted values
    /// by at least `band`.
    ///
    /// Sums over a row in f32 lanes (residuals are small, so nothing is
    /// lost), rows added in f64 in order: the result depends on the input
    /// alone. Where the processor has AVX2, the same loop runs eight lanes
    /// at a time.
    #[allow(clippy::too_many_arguments)]
    pub fn moments_within<T: FitValue>(
        &self,
        frame: &Frame<T>,
        domain: &ValueDomain,
        plane: &PixelPlane,
        band: f64,
        first_row: usize,
        row_step: usize,
        guard: Option<EdgeGuard>,
    ) -> DisparityMoments {
        let pass = Pass {
            frame,
            domain,
            plane,
            band,
            rows: (first_row, row_step),
            guard,
        };
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            #[allow(unsafe_code)]
            return unsafe { self.moments_avx2(&pass) };
        }
        self.moments(&pass)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn moments_avx2<T: FitValue>(&self, pass: &Pass<T>) -> DisparityMoments {
        self.moments(pass)
    }

    #[inline(always)]
    fn moments<T: FitValue>(&self, pass: &Pass<T>) -> DisparityMoments {
        let Pass {
            frame,
            domain,
            plane,
            band,
            rows: (first_row, row_step),
            guard,
        } = *pass;
        let width = frame.width.min(self.du.len());
        let mut total = DisparityMoments::default();
        for row in (first_row..frame.height).step_by(row_step.max(1)) {
            let dv = self.dv(row);
            let (start, end) = self.columns_in_range(plane, domain, dv, band);
            let end = end.min(width);
            if start >= end {
                continue;
            }
            let values = &frame.values[row * frame.width + start..row * frame.width + end];
            let base = (plane.c0 + plane.cv * dv) as f32;
            let du = &self.du[start..end];
            let du2 = &self.du2[start..end];
            let sums = match guard.filter(|g| g.rows > 0 && row >= g.rows) {
                Some(g) => {
                    let up = row - g.rows;
                    let pixels = RowPixels {
                        values,
                        above: &frame.values[up * frame.width + start..up * frame.width + end],
                        du,
                        du2,
                    };
                    let test = RowTest {
                        base,
                        base_above: (plane.c0 + plane.cv * self.dv(up)) as f32,
                        cu: plane.cu as f32,
                        band: band as f32,
                        guard: (g.limit as f32, domain.trusted.0, domain.trusted.1),
                    };
                    row_sums::<T, true>(pixels, &test)
                }
                None => {
                    let pixels = RowPixels {
                        values,
                        above: &[],
                        du,
                        du2,
                    };
                    let test = RowTest {
                        base,
                        base_above: base,
                        cu: plane.cu as f32,
                        band: band as f32,
                        guard: (0.0, 0.0, 0.0),
                    };
                    row_sums::<T, false>(pixels, &test)
                }
            };
            total.add_row(dv, &sums);
        }
        total
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

    /// Random rows for the lane loops: raw readings around a plane (some far
    /// off, some untrusted), of a length that leaves a remainder.
    #[cfg(target_arch = "aarch64")]
    fn random_rows(seed: u64) -> Vec<(Vec<u16>, Vec<u16>, Vec<f32>, RowTest)> {
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

    /// The NEON loop gives the reference loop's sums bit for bit, guarded
    /// and not, on raw readings and on metric ones with infinities and NaN.
    #[cfg(target_arch = "aarch64")]
    #[test]
    fn the_neon_loop_matches_the_reference_bit_for_bit() {
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
                bits(lane_sums_neon::<T, true>(pixels, test))
            );
            assert_eq!(
                bits(lane_sums::<T, false>(pixels, test)),
                bits(lane_sums_neon::<T, false>(pixels, test))
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
            let metric = |raw: &[u16]| -> Vec<f32> {
                raw.iter()
                    .enumerate()
                    .map(|(k, &r)| match (r, k % 7) {
                        (2047, _) => f32::INFINITY,
                        (_, 3) => f32::NAN,
                        (r, _) => f32::from(r) * 1e-3,
                    })
                    .collect()
            };
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
