//! One pose's ground residuals per cell of the image: what the depth
//! pattern's estimate ([`crate::distortion`]) needs from a pose, taken
//! while its frames are in memory (sums, not pixels, so that no frame is
//! kept).

use nalgebra::{Matrix3, Vector3};
use wide::f32x8;

use crate::depth::Intrinsics;
use crate::disparity::{FitValue, InverseDepthImage, PixelPlane};
use crate::plane::{GroundFit, InlierBand};
use crate::sensor::DepthCamera;

/// Every this many rows are summed: a cell then has 32 readings a frame,
/// its mean a σ of under 0.01 raw units over a calibration's poses, and the
/// pass costs about as much as the fit.
const ROW_STEP: usize = 2;

/// The side of a cell of the pattern, pixels: 80 × 60 cells on a Kinect's
/// 640 × 480 image, fine enough for stripes 48 pixels apart.
pub const CELL_PX: usize = 8;

/// The residuals are taken within this many times the fit's band (±2σ):
/// where the pattern lifts the readings by a σ, the fit's own band cuts
/// their upper tail and the cells' means would show the pattern smaller
/// than it is; at ±4σ the loss is under 1 %.
const WIDER_BAND: f64 = 2.0;

/// One cell's sums over a pose's ground readings: residual `r` (1/m) and
/// pixel offsets `u' = u − cx`, `v' = v − cy`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct CellSums {
    pub(crate) n: f64,
    pub(crate) r: f64,
    pub(crate) rr: f64,
    pub(crate) u: f64,
    pub(crate) v: f64,
}

/// One pose's ground residuals, summed per cell: what the pattern's
/// estimate needs from a pose, taken while its frames are in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundResiduals {
    pub(crate) columns: usize,
    pub(crate) rows: usize,
    pub(crate) cells: Vec<CellSums>,
    /// Σφφᵀ over the pose's ground readings, φ = (1, u', v').
    pub(crate) moments: Matrix3<f64>,
    /// Σ r·φ.
    pub(crate) rhs: Vector3<f64>,
    pub(crate) intrinsics: Intrinsics,
    /// Raw units per 1/m of inverse depth (the depth model's `1/b`).
    pub(crate) raw_per_inverse_depth: f64,
    /// The fit's own rejection band (1/m): the readings it took for the
    /// ground lay within it of its plane.
    pub(crate) fit_band: f64,
}

/// The sums as one pose's frames are read.
struct Sums {
    cells: Vec<CellSums>,
    columns: usize,
    moments: Matrix3<f64>,
    rhs: Vector3<f64>,
}

impl Sums {
    /// One row's readings within `band` of `plane` (both in the row's value
    /// units; trusted values only), the residuals times `to_inverse_depth`.
    /// Each cell's 8 readings are summed in f32 without a branch (a
    /// residual of a few hundredths, squared, loses nothing there), the
    /// cells in f64.
    #[allow(clippy::too_many_arguments)]
    fn add_row<T: FitValue>(
        &mut self,
        row: &[T],
        v: usize,
        intrinsics: &Intrinsics,
        plane: &PixelPlane,
        band: f64,
        trusted: (f32, f32),
        to_inverse_depth: f64,
    ) {
        let dv = v as f64 - intrinsics.cy;
        let cell_row = (v / CELL_PX) * self.columns;
        let (band, scale) = (band as f32, to_inverse_depth);
        let (mut uu, mut ur) = (0.0f64, 0.0f64);
        for (cell_index, chunk) in row.chunks(CELL_PX).enumerate() {
            let first = (cell_index * CELL_PX) as f64 - intrinsics.cx;
            // The plane at the cell's first pixel, and its step per pixel.
            let start = (plane.c0 + plane.cv * dv + plane.cu * first) as f32;
            let step = plane.cu as f32;
            let (n, sr, srr, su, suu, sur) = if chunk.len() == CELL_PX {
                cell_sums(chunk, start, step, band, trusted)
            } else {
                let mut sums = (0f32, 0f32, 0f32, 0f32, 0f32, 0f32);
                for (k, value) in chunk.iter().enumerate() {
                    let x = value.to_f32();
                    let r = x - (start + step * k as f32);
                    if r.abs() <= band && x >= trusted.0 && x <= trusted.1 {
                        let k = k as f32;
                        sums.0 += 1.0;
                        sums.1 += r;
                        sums.2 += r * r;
                        sums.3 += k;
                        sums.4 += k * k;
                        sums.5 += k * r;
                    }
                }
                sums
            };
            if n == 0.0 {
                continue;
            }
            // Offsets within the cell (k) back to u' = first + k.
            let (n, sr, srr) = (
                f64::from(n),
                f64::from(sr) * scale,
                f64::from(srr) * scale * scale,
            );
            let (su, suu, sur) = (f64::from(su), f64::from(suu), f64::from(sur) * scale);
            let sum_u = first * n + su;
            let cell = &mut self.cells[cell_row + cell_index];
            cell.n += n;
            cell.r += sr;
            cell.rr += srr;
            cell.u += sum_u;
            cell.v += n * dv;
            uu += first * first * n + 2.0 * first * su + suu;
            ur += first * sr + sur;
            self.moments[(0, 0)] += n;
            self.moments[(0, 1)] += sum_u;
            self.moments[(0, 2)] += n * dv;
            self.moments[(1, 2)] += sum_u * dv;
            self.moments[(2, 2)] += n * dv * dv;
            self.rhs[0] += sr;
            self.rhs[2] += sr * dv;
        }
        self.moments[(1, 1)] += uu;
        self.rhs[1] += ur;
    }
}

/// One cell's 8 readings of a row in one vector: how many lie within
/// `band` of the plane (`start` at the first, `step` a pixel) among the
/// trusted ones, and their Σr, Σr², Σk, Σk², Σk·r (k the pixel in the cell).
#[inline(always)]
fn cell_sums<T: FitValue>(
    chunk: &[T],
    start: f32,
    step: f32,
    band: f32,
    trusted: (f32, f32),
) -> (f32, f32, f32, f32, f32, f32) {
    let mut values = [0f32; CELL_PX];
    for (out, value) in values.iter_mut().zip(chunk) {
        *out = value.to_f32();
    }
    let x = f32x8::from(values);
    let k = f32x8::from([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
    let r = x - (f32x8::splat(start) + f32x8::splat(step) * k);
    let keep = r.abs().simd_le(f32x8::splat(band))
        & x.simd_ge(f32x8::splat(trusted.0))
        & x.simd_le(f32x8::splat(trusted.1));
    let zero = f32x8::splat(0.0);
    let one = f32x8::select(keep, f32x8::splat(1.0), zero);
    let r = f32x8::select(keep, r, zero);
    let k = k * one;
    (
        one.reduce_add(),
        r.reduce_add(),
        (r * r).reduce_add(),
        k.reduce_add(),
        (k * k).reduce_add(),
        (k * r).reduce_add(),
    )
}

impl GroundResiduals {
    /// The residuals of `frames` from the ground `fit` found in them: the
    /// readings within twice the fit's own band. `None` for the paper's fit
    /// (`--ground-fit paper`, kept to compare with): its band is in metres
    /// point by point, and a pattern estimated through it is not one the
    /// default fit would see (in the corridor it found one where there is
    /// none).
    pub fn of(
        frames: &[&[u16]],
        camera: &DepthCamera,
        fit: &GroundFit,
        image: &mut InverseDepthImage,
    ) -> Option<Self> {
        let InlierBand::InverseDepth(band) = fit.band else {
            return None;
        };
        let intrinsics = *camera.intrinsics();
        let (width, height) = (intrinsics.width, intrinsics.height);
        let columns = width.div_ceil(CELL_PX);
        let rows = height.div_ceil(CELL_PX);
        let mut sums = Sums {
            cells: vec![CellSums::default(); columns * rows],
            columns,
            moments: Matrix3::zeros(),
            rhs: Vector3::zeros(),
        };
        let plane = PixelPlane::from_plane(&fit.plane, &intrinsics);
        for pixels in frames {
            if pixels.len() != width * height {
                continue;
            }
            if camera.fits_raw_values() {
                // Raw frames as the fit read them, in raw values: no pixel
                // converted (the residuals scaled to 1/m by the cell).
                let domain = camera.value_domain();
                let values = domain.from_inverse_depth(&plane);
                for (v, row) in pixels.chunks_exact(width).enumerate().step_by(ROW_STEP) {
                    sums.add_row(
                        row,
                        v,
                        &intrinsics,
                        &values,
                        WIDER_BAND * band / domain.scale.abs(),
                        domain.trusted,
                        domain.scale,
                    );
                }
            } else {
                camera.inverse_depth_into(pixels, image);
                for (v, row) in image.w.chunks_exact(width).enumerate().step_by(ROW_STEP) {
                    sums.add_row(
                        row,
                        v,
                        &intrinsics,
                        &plane,
                        WIDER_BAND * band,
                        (f32::MIN, f32::MAX),
                        1.0,
                    );
                }
            }
        }
        let Sums {
            cells,
            mut moments,
            rhs,
            ..
        } = sums;
        moments[(1, 0)] = moments[(0, 1)];
        moments[(2, 0)] = moments[(0, 2)];
        moments[(2, 1)] = moments[(1, 2)];
        Some(Self {
            columns,
            rows,
            cells,
            moments,
            rhs,
            intrinsics,
            raw_per_inverse_depth: camera.raw_per_inverse_depth(),
            fit_band: band,
        })
    }
}
