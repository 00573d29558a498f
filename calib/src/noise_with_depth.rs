//! How the depth's noise changes with distance, from the ground's residuals:
//! what tells a disparity camera from a time-of-flight one.
//!
//! The fit weighs every reading alike in inverse depth `w = 1/z`, which is
//! the maximum-likelihood fit where the noise is the same in `w` at every
//! distance: a camera that measures disparity (the Kinect's structured
//! light, active or passive stereo). A time-of-flight camera measures the
//! distance itself; its noise is about the same in `z`, or grows with `z`,
//! so in `w` it falls as `w²` or `w` with distance. Fitted as a disparity
//! camera's, its far readings would weigh as much as its near ones when they
//! are worth far less.
//!
//! Measured here: the exponent `p` of `σ_w ∝ w^p` over the cells of every
//! pose (a cell's scatter about its own mean within the pose, against the
//! ground's `w` at the cell), by least squares on the logarithms, each cell
//! weighted by its readings. A disparity camera gives about 0 (a real
//! Kinect slightly below: its noise grows a little with distance); a
//! time-of-flight camera 1 to 2.

use crate::residuals::{cell_centre, GroundResiduals};

/// At least this many readings in a cell at one pose for its scatter to count.
const MIN_READINGS: f64 = 8.0;

/// Cells enough, over a depth range wide enough (the ratio of the farthest
/// `w` to the nearest), for the exponent to mean something.
const MIN_CELLS: usize = 200;
const MIN_RANGE: f64 = 1.5;

/// Above this exponent the noise falls with distance as no disparity camera's
/// does (a time-of-flight camera's gives 1–2): the fit's weighting is wrong.
pub const MAX_DISPARITY_EXPONENT: f64 = 0.5;

/// The exponent `p` of `σ_w ∝ w^p` over the poses' ground cells, or `None`
/// when too few cells or too narrow a range of depths were seen.
pub fn noise_exponent(poses: &[&GroundResiduals]) -> Option<f64> {
    // Weighted least squares of ln σ² = a + 2p·ln w.
    let (mut s, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut cells, mut lo, mut hi) = (0usize, f64::INFINITY, 0.0f64);
    for residuals in poses {
        for (k, cell) in residuals.cells.iter().enumerate() {
            if cell.n < MIN_READINGS {
                continue;
            }
            let mean = cell.r / cell.n;
            let variance = (cell.rr / cell.n - mean * mean) * cell.n / (cell.n - 1.0);
            let (du, dv) = cell_centre(k, residuals.columns, &residuals.intrinsics);
            let w = residuals.plane.at(du, dv);
            if !(variance > 0.0 && w > 0.0 && variance.is_finite()) {
                continue;
            }
            let (x, y, weight) = (w.ln(), variance.ln(), cell.n);
            s += weight;
            sx += weight * x;
            sy += weight * y;
            sxx += weight * x * x;
            sxy += weight * x * y;
            cells += 1;
            lo = lo.min(w);
            hi = hi.max(w);
        }
    }
    let spread = s * sxx - sx * sx;
    if cells < MIN_CELLS || hi / lo < MIN_RANGE || spread <= 0.0 {
        return None;
    }
    let slope = (s * sxy - sx * sy) / spread;
    Some(slope / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::depth::Intrinsics;
    use crate::disparity::PixelPlane;
    use crate::residuals::{CellSums, CELL_PX};

    /// A pose's cells on ground whose inverse depth runs from 0.25 to 1.2
    /// 1/m down the image, each cell's scatter `scale · w^p` (unbiased, 32
    /// readings).
    fn pose(p: f64, scale: f64) -> GroundResiduals {
        let intrinsics = Intrinsics::default();
        let (columns, rows) = (
            intrinsics.width.div_ceil(CELL_PX),
            intrinsics.height.div_ceil(CELL_PX),
        );
        let plane = PixelPlane {
            c0: 0.7,
            cu: 0.0,
            cv: 0.95 / intrinsics.height as f64,
        };
        let cells = (0..columns * rows)
            .map(|k| {
                let (du, dv) = cell_centre(k, columns, &intrinsics);
                let sigma = scale * plane.at(du, dv).powf(p);
                CellSums {
                    n: 32.0,
                    r: 0.0,
                    rr: sigma * sigma * 31.0,
                    u: 0.0,
                    v: 0.0,
                }
            })
            .collect();
        GroundResiduals::for_test(columns, rows, cells, intrinsics, plane)
    }

    #[test]
    fn the_exponent_tells_a_disparity_camera_from_a_time_of_flight_one() {
        for p in [-0.2, 0.0, 1.0, 2.0] {
            let poses = [pose(p, 0.003), pose(p, 0.003)];
            let found = noise_exponent(&poses.iter().collect::<Vec<_>>()).unwrap();
            assert!((found - p).abs() < 1e-9, "{found} for {p}");
            assert_eq!(found > MAX_DISPARITY_EXPONENT, p >= 1.0);
        }
        // One depth only: nothing to tell.
        let mut flat = pose(1.0, 0.003);
        flat.plane.cv = 0.0;
        assert_eq!(noise_exponent(&[&flat]), None);
    }
}
