//! One pose's ground residuals per cell of the image: what the depth
//! pattern's estimate ([`crate::distortion`]) needs from a pose, taken
//! while its frames are in memory (sums, not pixels, so that no frame is
//! kept).

use nalgebra::{Matrix3, Vector3};

use crate::depth::Intrinsics;
use crate::disparity::{InverseDepthImage, PixelPlane};
use crate::plane::{GroundFit, InlierBand};
use crate::sensor::DepthCamera;

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
    /// ground lay within it of its plane. `None` for the paper's fit.
    pub(crate) fit_band: Option<f64>,
}

impl GroundResiduals {
    /// The residuals of `frames` from the ground `fit` found in them: the
    /// readings the fit took for the ground, by its own band.
    pub fn of(
        frames: &[&[u16]],
        camera: &DepthCamera,
        fit: &GroundFit,
        image: &mut InverseDepthImage,
    ) -> Self {
        let intrinsics = *camera.intrinsics();
        let (width, height) = (intrinsics.width, intrinsics.height);
        let columns = width.div_ceil(CELL_PX);
        let rows = height.div_ceil(CELL_PX);
        let mut cells = vec![CellSums::default(); columns * rows];
        let mut moments = Matrix3::zeros();
        let mut rhs = Vector3::zeros();
        let plane = PixelPlane::from_plane(&fit.plane, &intrinsics);
        for pixels in frames {
            if pixels.len() != width * height {
                continue;
            }
            camera.inverse_depth_into(pixels, image);
            for v in 0..height {
                let dv = v as f64 - intrinsics.cy;
                let row = &image.w[v * width..(v + 1) * width];
                let cell_row = &mut cells[(v / CELL_PX) * columns..(v / CELL_PX + 1) * columns];
                // Sums per row and cell first, in f64 once per cell.
                for (cell_index, chunk) in row.chunks(CELL_PX).enumerate() {
                    let mut sums = CellSums::default();
                    for (k, &w) in chunk.iter().enumerate() {
                        if !w.is_finite() {
                            continue;
                        }
                        let u = cell_index * CELL_PX + k;
                        let du = u as f64 - intrinsics.cx;
                        let r = f64::from(w) - plane.at(du, dv);
                        let on_ground = match fit.band {
                            InlierBand::InverseDepth(band) => r.abs() <= WIDER_BAND * band,
                            InlierBand::Sigmas(_) => camera
                                .point_at(u, v, pixels[v * width + u])
                                .is_some_and(|p| fit.holds(&p)),
                        };
                        if !on_ground {
                            continue;
                        }
                        sums.n += 1.0;
                        sums.r += r;
                        sums.rr += r * r;
                        sums.u += du;
                        sums.v += dv;
                        let phi = Vector3::new(1.0, du, dv);
                        moments += phi * phi.transpose();
                        rhs += phi * r;
                    }
                    let cell = &mut cell_row[cell_index];
                    cell.n += sums.n;
                    cell.r += sums.r;
                    cell.rr += sums.rr;
                    cell.u += sums.u;
                    cell.v += sums.v;
                }
            }
        }
        Self {
            columns,
            rows,
            cells,
            moments,
            rhs,
            intrinsics,
            raw_per_inverse_depth: camera.raw_per_inverse_depth(),
            fit_band: match fit.band {
                InlierBand::InverseDepth(band) => Some(band),
                InlierBand::Sigmas(_) => None,
            },
        }
    }

    /// Ground readings summed.
    pub fn readings(&self) -> f64 {
        self.cells.iter().map(|c| c.n).sum()
    }
}
