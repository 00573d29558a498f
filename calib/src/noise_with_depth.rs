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

/// At least this many readings in a cell at one pose for its scatter to count.
const MIN_READINGS: f64 = 8.0;

/// Cells enough, over a depth range wide enough (the ratio of the farthest
/// `w` to the nearest), for the exponent to mean something.
const MIN_CELLS: usize = 200;
const MIN_RANGE: f64 = 1.5;

/// Above this exponent the noise falls with distance as no disparity camera's
/// does (a time-of-flight camera's gives 1–2): the fit's weighting is wrong.
pub const MAX_DISPARITY_EXPONENT: f64 = 0.5;

/// One pose's cells' scatter against the ground's depth, as the sums of the
/// weighted least squares of `ln σ² = a + 2p·ln w` (each cell weighted by
/// its readings): what the exponent needs of a pose, taken when its
/// residuals are made, the only time a cell's sum of squares is at hand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScatterWithDepth {
    s: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
    cells: usize,
    /// The nearest and farthest ground's `w` among the cells taken.
    lo: f64,
    hi: f64,
}

impl Default for ScatterWithDepth {
    fn default() -> Self {
        Self {
            s: 0.0,
            sx: 0.0,
            sy: 0.0,
            sxx: 0.0,
            sxy: 0.0,
            cells: 0,
            lo: f64::INFINITY,
            hi: 0.0,
        }
    }
}

impl ScatterWithDepth {
    /// Adds a cell of `n` readings whose residuals sum to `r` and their
    /// squares to `rr`, where the ground's inverse depth is `w` (1/m).
    pub fn add_cell(&mut self, n: f64, r: f64, rr: f64, w: f64) {
        if n < MIN_READINGS {
            return;
        }
        let mean = r / n;
        let variance = (rr / n - mean * mean) * n / (n - 1.0);
        if !(variance > 0.0 && w > 0.0 && variance.is_finite()) {
            return;
        }
        let (x, y, weight) = (w.ln(), variance.ln(), n);
        self.s += weight;
        self.sx += weight * x;
        self.sy += weight * y;
        self.sxx += weight * x * x;
        self.sxy += weight * x * y;
        self.cells += 1;
        self.lo = self.lo.min(w);
        self.hi = self.hi.max(w);
    }

    fn add(&mut self, other: &Self) {
        self.s += other.s;
        self.sx += other.sx;
        self.sy += other.sy;
        self.sxx += other.sxx;
        self.sxy += other.sxy;
        self.cells += other.cells;
        self.lo = self.lo.min(other.lo);
        self.hi = self.hi.max(other.hi);
    }
}

/// The exponent `p` of `σ_w ∝ w^p` over the poses' ground cells, or `None`
/// when too few cells or too narrow a range of depths were seen.
pub fn noise_exponent<'a>(poses: impl IntoIterator<Item = &'a ScatterWithDepth>) -> Option<f64> {
    let mut all = ScatterWithDepth::default();
    for pose in poses {
        all.add(pose);
    }
    let ScatterWithDepth {
        s,
        sx,
        sy,
        sxx,
        sxy,
        cells,
        lo,
        hi,
    } = all;
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

    /// A pose's cells on ground whose inverse depth runs from 0.25 to
    /// `0.25 + span` 1/m down 60 rows of 80 cells, each cell's scatter
    /// `scale · w^p` (unbiased, 32 readings).
    fn pose(p: f64, scale: f64, span: f64) -> ScatterWithDepth {
        let mut sums = ScatterWithDepth::default();
        for row in 0..60 {
            let w = 0.25 + span * row as f64 / 59.0;
            let sigma = scale * w.powf(p);
            for _ in 0..80 {
                sums.add_cell(32.0, 0.0, sigma * sigma * 31.0, w);
            }
        }
        sums
    }

    #[test]
    fn the_exponent_tells_a_disparity_camera_from_a_time_of_flight_one() {
        for p in [-0.2, 0.0, 1.0, 2.0] {
            let poses = [pose(p, 0.003, 0.95), pose(p, 0.003, 0.95)];
            let found = noise_exponent(&poses).unwrap();
            assert!((found - p).abs() < 1e-9, "{found} for {p}");
            assert_eq!(found > MAX_DISPARITY_EXPONENT, p >= 1.0);
        }
        // One depth only: nothing to tell.
        assert_eq!(noise_exponent(&[pose(1.0, 0.003, 0.0)]), None);
        // Too few readings in a cell: not counted.
        let mut few = ScatterWithDepth::default();
        few.add_cell(7.0, 0.0, 1e-6, 0.5);
        assert_eq!(few, ScatterWithDepth::default());
    }
}
