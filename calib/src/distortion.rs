//! The Kinect's fixed depth pattern ("depth distortion", Smisek et al. 2011,
//! Herrera et al. 2012): every pixel of a real unit reads a few tenths of a
//! raw unit more or less than the truth, the same at every pose. A plane
//! fitted per pose absorbs the pattern's constant and linear parts over the
//! ground it saw and leaves the rest in its residuals; both bias the mount.
//!
//! The pattern is found in two parts (docs/method.md, "The depth pattern"):
//!
//! 1. **Its shape** from the fits' residuals. Each pose's residuals are summed
//!    over cells of [`CELL_PX`] pixels ([`crate::residuals`], a few hundred
//!    kilobytes a pose, no frames kept). Over all poses, the cells' pattern
//!    and a correction of each pose's plane are fitted together by least
//!    squares ([`estimate_shape`]); the shape is defined without a plane
//!    part over the cells seen, which no single frame can tell from the
//!    ground's own plane.
//! 2. **Its plane part** from the geometry across poses ([`solve_with_pattern`]):
//!    a constant and two gradients of the raw values, the same at every
//!    pose, move every pose's measured plane by the same amount in inverse
//!    depth, where a change of the mount moves it by amounts that change
//!    with the sensor's height and tilt. Three parameters more in the solve
//!    (by variable projection: the mount is solved again for each), costing
//!    the mount some σ; taken only when the evidence shows them.
//!
//! Units: the fit's inverse depth (1/m) inside, raw units of the depth model
//! outside (one raw unit is about 12 mm of depth at 2 m).

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Vector3};
use rayon::prelude::*;

use crate::cell_noise::{flip_test, CellNoise, Entry, FlipTest};
use crate::depth::Intrinsics;
use crate::disparity::PixelPlane;
use crate::outcome::{DepthPattern, Solution};
use crate::solve::{self, Observation, SolveError, SolveSettings};

pub use crate::depth::DepthCorrection;
pub use crate::residuals::{GroundResiduals, CELL_PX};

/// A cell enters the estimate with at least this many readings over all
/// poses, from at least two poses.
const MIN_CELL_READINGS: f64 = 48.0;

/// Fewest poses with residuals to estimate a pattern from.
pub const MIN_PATTERN_POSES: usize = 10;

/// A shape is taken as real when its size stands this many of noise's σ
/// above the sizes of shapes made of the same poses with random signs
/// ([`crate::cell_noise::flip_test`]) and its RMS reaches
/// [`MIN_SHAPE_RMS_RAW`].
const SHAPE_SIGNIFICANCE: f64 = 8.0;

/// A pattern is not the sensor's fixed one when a test of an alternative
/// finds it by this many of its σ: a pattern that changes with the depth
/// ([`DepthDependence`]), or residuals that stay with the ground as the
/// poses move ([`ShapeEstimate::fixed_in_the_ground`]). The noise these σ
/// are of comes from the poses' own scatter (a real Kinect's is correlated
/// over the image, so no count of pixels can say it).
const ALTERNATIVE_SIGMAS: f64 = 5.0;

/// Turns of relief and shape taken out of each other in
/// [`shape_beside_relief`].
const RELIEF_TURNS: usize = 4;

/// The shape beside the ground's relief stands as the sensor's when it
/// keeps at least this share of its RMS (and stands out of the noise).
const SHAPE_SHARE_BESIDE_RELIEF: f64 = 0.5;

/// A shape stands beside a relief of the ground only when that relief is
/// local, raw units RMS over the ground seen: obstacles' feet in the
/// simulator's clutter make 0.014-0.039 and a real lab floor about 0.16
/// (docs/method.md); bumps all over the ground make 0.53, and a pattern
/// corrected beside them was accepted 0.77° and 8 mm off.
const MAX_RELIEF_BESIDE_RAW: f64 = 0.25;

/// Bins of the ground, metres, in which the residuals are looked for
/// where they stay with the ground: about a cell's footprint at 2 m.
const GROUND_BIN_M: f64 = 0.05;

/// At least this share of the cells seen must keep residuals fixed in the
/// image for the pattern to be the sensor's.
const MIN_KEPT_FRACTION: f64 = 0.5;

/// Below this RMS (raw units) a shape is too small to matter: 0.03 raw
/// units is 0.4 mm at 2 m.
pub const MIN_SHAPE_RMS_RAW: f64 = 0.03;

/// The plane part is taken when it differs from none at this χ² with 3
/// degrees of freedom (a chance of 1 in 1000).
const PLANE_PART_CHI2: f64 = 16.27;

/// The pattern's shape over the cells, and what it changes in each pose's
/// plane, from [`estimate_shape`].
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeEstimate {
    pub columns: usize,
    pub rows: usize,
    /// Per cell, 1/m (0 where not seen): no plane part over the cells seen.
    pub shape: Vec<f64>,
    /// Ground readings per cell over all poses.
    pub readings: Vec<f64>,
    /// Whether each cell entered the estimate.
    pub seen: Vec<bool>,
    /// The noise of a cell's mean at one pose, from the poses' own scatter.
    pub noise: CellNoise,
    /// The variance of each cell's shape from that noise, (1/m)² (0 where
    /// not seen).
    pub cell_variance: Vec<f64>,
    /// The shape against none: Σ shape²/σ² over the cells, and its degrees
    /// of freedom (the cells are correlated: [`ShapeEstimate::flips`] judges).
    pub shape_chi2: f64,
    pub shape_dof: f64,
    /// The shape's size against the sizes the poses make with random signs.
    pub flips: FlipTest,
    /// The residuals left by pattern and planes, cell by cell and pose by
    /// pose, against the readings' noise: about 1 per degree of freedom
    /// when the pattern is fixed in the image and the ground flat.
    pub consistency_chi2: f64,
    pub consistency_dof: f64,
    /// The shape's RMS over every cell seen, before any was left out, raw
    /// units: how warped the ground looked, whatever warped it.
    pub all_cells_rms_raw: f64,
    /// The share of the cells seen that stayed in the estimate (the others'
    /// residuals changed from pose to pose).
    pub kept_fraction: f64,
    /// Whether the pattern changes with the depth, as the cells' residuals
    /// against the shape times their depth say.
    pub depth: DepthDependence,
    /// Whether the residuals left by pattern and planes stay with the
    /// ground as the poses move (uneven ground), as flipping the poses'
    /// signs over bins of the ground says; None without the poses' geometry.
    pub fixed_in_the_ground: Option<FlipTest>,
    /// When residuals stay with the ground: the shape estimated beside
    /// that relief ([`shape_beside_relief`]).
    pub shape_beside_relief: Option<ReliefTest>,
    /// Raw units per 1/m.
    pub raw_per_inverse_depth: f64,
    /// The band within which the poses' ground fits took their readings,
    /// raw units (the median over the poses): a pattern reaching beyond it
    /// had its peaks cut out.
    pub fit_band_raw: f64,
    pub intrinsics: Intrinsics,
    /// Alternations done.
    pub iterations: usize,
}

/// The shape estimated beside the ground's relief ([`shape_beside_relief`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReliefTest {
    /// Its flip test, in noise's σ.
    pub shape_sigmas: f64,
    /// Its RMS against the shape's estimated alone.
    pub shape_share: f64,
    /// The relief's RMS over the ground seen, weighted by readings, 1/m.
    pub relief_rms: f64,
}

impl ShapeEstimate {
    /// The shape's RMS over the cells seen, weighted by their readings, raw units.
    pub fn rms_raw(&self) -> f64 {
        weighted_rms(&self.shape, &self.readings, &self.seen) * self.raw_per_inverse_depth.abs()
    }

    /// Per pose of `poses` (those it was estimated from, in order): the
    /// correction of its plane (1/m, on `c0, cu, cv`) for what the shape bent
    /// it by. The fit's own plane (its rows, its guard, its band) is kept and
    /// only the pattern's share is taken out, so that with no pattern nothing
    /// changes. Every sum the fit took counts, kept or not.
    pub fn plane_corrections(&self, poses: &[&GroundResiduals]) -> Vec<Vector3<f64>> {
        let sigma = self.noise.of_reading().sqrt();
        poses
            .par_iter()
            .map(|pose| -bend(pose, &self.shape, &self.seen, sigma))
            .collect()
    }

    /// Whether the residuals are a pattern fixed in the image: no test of
    /// an alternative finds one (a pattern that changes with depth, ground
    /// that is not flat), and most cells keep their residuals from pose to
    /// pose (obstacles' feet and bumps do not).
    pub fn consistent(&self) -> bool {
        self.why_not_fixed().is_none()
    }

    /// Why the residuals are not the sensor's fixed pattern, when they are not.
    pub fn why_not_fixed(&self) -> Option<crate::outcome::WarpCause> {
        self.why_not_fixed_beside_relief(true)
    }

    /// [`ShapeEstimate::why_not_fixed`] for the residuals left once a first
    /// estimate of the pattern was taken out of the frames: any residuals
    /// that stay with the ground count against it, beside a relief or not.
    /// (What was taken out holds whatever the first fit saw, uneven ground
    /// included; what is left of a relief then looks like a shape standing
    /// beside it, and the simulator's uneven world was accepted 0.13° off.)
    pub fn why_not_fixed_after_a_first_estimate(&self) -> Option<crate::outcome::WarpCause> {
        self.why_not_fixed_beside_relief(false)
    }

    fn why_not_fixed_beside_relief(
        &self,
        relief_may_stand_beside: bool,
    ) -> Option<crate::outcome::WarpCause> {
        use crate::outcome::WarpCause;
        if self.kept_fraction < MIN_KEPT_FRACTION {
            return Some(WarpCause::CellsChange {
                left_out: 1.0 - self.kept_fraction,
            });
        }
        // Both alternatives leave traces of each other (a pattern weaker
        // farther leaves residuals that follow the distance over the ground;
        // bumps seen nearer and farther look like a change with depth): the
        // one whose test stands farther out says why.
        let stays_with_the_ground = self
            .fixed_in_the_ground
            .map(|t| t.sigmas())
            .filter(|s| *s > ALTERNATIVE_SIGMAS);
        // Residuals that stay with the ground count against the pattern
        // only when the shape does not stand beside them (obstacles' feet
        // are fixed in the ground too, beside any pattern of the sensor).
        let ground = stays_with_the_ground
            .filter(|_| !(relief_may_stand_beside && self.stands_beside_the_relief()));
        let depth = self
            .depth
            .significant()
            .then(|| (self.depth.per_m / self.depth.sigma).abs());
        let (largest_raw, band_raw) = (self.largest_raw(), self.fit_band_raw);
        // A shape whose peaks the fit cut is not corrected when any test
        // finds residuals it does not explain, even beside the relief: the
        // correction is then biased (a real Kinect's pattern of 0.8 raw
        // units RMS, corrected beside the relief, put the mount 0.28-0.98
        // mm off on four seeds, and one of 0.56 mm was accepted).
        if (stays_with_the_ground.is_some() || depth.is_some()) && self.peaks_cut_by_the_fit() {
            return Some(WarpCause::BeyondTheFit {
                largest_raw,
                band_raw,
            });
        }
        match (ground, depth) {
            (Some(g), Some(d)) if d > g => Some(WarpCause::ChangesWithDepth {
                per_m: self.depth.per_m,
                sigma: self.depth.sigma,
            }),
            (Some(g), _) => Some(WarpCause::GroundNotFlat { sigmas: g }),
            (None, Some(_)) => Some(WarpCause::ChangesWithDepth {
                per_m: self.depth.per_m,
                sigma: self.depth.sigma,
            }),
            (None, None) => None,
        }
    }

    /// Whether the shape stands beside what stays with the ground: out of
    /// the noise, and most of it left, once the ground's relief is taken
    /// out with it.
    pub fn stands_beside_the_relief(&self) -> bool {
        self.shape_beside_relief.is_some_and(|r| {
            r.shape_sigmas > SHAPE_SIGNIFICANCE
                && r.shape_share >= SHAPE_SHARE_BESIDE_RELIEF
                && r.relief_rms * self.raw_per_inverse_depth.abs() <= MAX_RELIEF_BESIDE_RAW
        })
    }

    /// Whether the shape's peak reaches beyond the fit's band: the fit cut
    /// the readings there, and what the cut leaves behind differs from
    /// pose to pose as uneven ground's residuals would. (A lower bound, the
    /// band less a reading's σ, called the simulator's uneven world a
    /// pattern beyond the fit; the shape beside the ground's relief,
    /// [`ShapeEstimate::stands_beside_the_relief`], is what keeps waves of
    /// ±1.5 raw units in clutter from being called uneven ground.)
    pub fn peaks_cut_by_the_fit(&self) -> bool {
        self.largest_raw() > self.fit_band_raw
    }

    /// The shape's largest distance from zero over the cells seen, raw units.
    pub fn largest_raw(&self) -> f64 {
        self.shape
            .iter()
            .zip(&self.seen)
            .filter(|(_, &seen)| seen)
            .map(|(s, _)| (s * self.raw_per_inverse_depth).abs())
            .fold(0.0, f64::max)
    }

    /// Whether the shape stands out of the noise and matters.
    pub fn significant(&self) -> bool {
        self.shape_dof > 0.0
            && self.flips.sigmas() > SHAPE_SIGNIFICANCE
            && self.rms_raw() >= MIN_SHAPE_RMS_RAW
    }

    /// A cell's centre offset from the principal point, pixels.
    fn cell_offset(&self, k: usize) -> (f64, f64) {
        let (column, row) = (k % self.columns, k / self.columns);
        (
            ((column * CELL_PX) as f64 + (CELL_PX as f64 - 1.0) / 2.0) - self.intrinsics.cx,
            ((row * CELL_PX) as f64 + (CELL_PX as f64 - 1.0) / 2.0) - self.intrinsics.cy,
        )
    }
}

/// The pattern's shape and each pose's plane correction, by alternating
/// least squares over the cells (the pattern given the planes, the planes
/// given the pattern) until the pattern moves by less than 10⁻⁴ raw units.
/// `None` with fewer than [`MIN_PATTERN_POSES`] poses or cells of mixed sizes.
pub fn estimate_shape(poses: &[&GroundResiduals]) -> Option<ShapeEstimate> {
    estimate_shape_seen_from(poses, None)
}

/// [`estimate_shape`], with each pose's `ground_from_sensor` when known: the
/// residuals are then also looked for where they stay with the ground.
pub fn estimate_shape_seen_from(
    poses: &[&GroundResiduals],
    ground_from_sensor: Option<&[crate::geometry::Transform]>,
) -> Option<ShapeEstimate> {
    let first = poses.first()?;
    if poses.len() < MIN_PATTERN_POSES
        || poses
            .iter()
            .any(|p| p.cells.len() != first.cells.len() || p.columns != first.columns)
    {
        return None;
    }
    let cells = first.cells.len();
    let within = reading_variance(poses);
    let mut kept = Kept::all(poses);
    let seen_at_first = kept.seen.clone();
    let total: f64 = kept.readings.iter().sum();

    // A cell's sum at one pose whose mean lies far from the pattern and the
    // plane is not the sensor's (an obstacle's foot in that cell at that
    // pose, a bump of the ground): it leaves the estimate, which is made
    // again without it, until the sums kept stay the same. "Far" is in the
    // noise of a cell's mean as the poses' own scatter shows it.
    let mut fitted = alternate(poses, &kept, None);
    let all_cells_rms_raw =
        weighted_rms(&fitted.shape, &kept.readings, &kept.seen) * first.raw_per_inverse_depth.abs();
    let mut noise = estimate_noise(poses, &kept, &fitted, within);
    for _ in 0..5 {
        let next = Kept::within(poses, &fitted, &noise, &seen_at_first);
        if next.out == kept.out {
            break;
        }
        kept = next;
        fitted = alternate(poses, &kept, Some(&fitted.shape));
        noise = estimate_noise(poses, &kept, &fitted, within);
    }
    // A cell far from the cells above and below it is not the sensor's
    // either: a pattern is smooth down the image (a real unit's stripes run
    // down it), where the foot of a wall or a box lies along a row and sits
    // at the same place in the image at every pose.
    for _ in 0..3 {
        let cell_variance = cell_variances(poses, &kept, &noise);
        let lone = lone_cells(
            &fitted.shape,
            &kept,
            first.raw_per_inverse_depth,
            &cell_variance,
        );
        if lone.is_empty() {
            break;
        }
        kept.leave_out(&lone);
        fitted = alternate(poses, &kept, Some(&fitted.shape));
        noise = estimate_noise(poses, &kept, &fitted, within);
    }
    let Fitted {
        shape, iterations, ..
    } = &fitted;
    let seen = kept.seen.clone();
    let observed = seen.iter().filter(|s| **s).count() as f64;
    let cell_variance = cell_variances(poses, &kept, &noise);
    let shape_chi2: f64 = (0..cells)
        .filter(|&k| seen[k] && cell_variance[k] > 0.0)
        .map(|k| shape[k].powi(2) / cell_variance[k])
        .sum();
    let sums = entries(poses, &kept, &fitted);
    let parameters = observed + 3.0 * poses.len() as f64;
    let (consistency_chi2, consistency_dof) = noise.chi2(&sums, parameters);
    let weights: Vec<f64> = (0..cells)
        .map(|k| if seen[k] { kept.readings[k] } else { 0.0 })
        .collect();
    let shape_of = |per_cell: &[f64]| -> Vec<f64> {
        let mut shape: Vec<f64> = per_cell
            .iter()
            .zip(&weights)
            .map(|(s, w)| if *w > 0.0 { s / w } else { 0.0 })
            .collect();
        remove_plane_part(&mut shape, &kept.readings, &seen, first);
        shape
    };
    let mut plain = vec![0.0; cells];
    for e in &sums {
        plain[e.cell as usize] += e.n * e.about_plane;
    }
    let flips = flip_test(&sums, poses.len(), &weights, &shape_of(&plain), shape_of);
    let depth = depth_dependence(poses, &sums, shape, &noise);
    // Residuals that stay with the ground are looked for beyond what a
    // pattern changing with depth would leave: each alternative is asked
    // what the other does not explain.
    let ground_tests = ground_from_sensor
        .filter(|g| g.len() == poses.len())
        .map(|g| {
            let beyond_depth = if depth.significant() {
                without_depth_dependence(poses, &sums, shape)
            } else {
                sums.clone()
            };
            let (test, bin_of) = ground_fixed(poses, &beyond_depth, g);
            // Only asked when the ground's test finds something.
            let beside = (test.sigmas() > ALTERNATIVE_SIGMAS)
                .then(|| shape_beside_relief(&sums, &bin_of, poses.len(), &weights, shape_of));
            (test, beside)
        });
    let fixed_in_the_ground = ground_tests.as_ref().map(|(test, _)| *test);
    let shape_beside_relief = ground_tests.and_then(|(_, beside)| beside);
    let kept_readings: f64 = (0..cells)
        .filter(|&k| seen[k])
        .map(|k| kept.readings[k])
        .sum();
    Some(ShapeEstimate {
        columns: first.columns,
        rows: first.rows,
        shape: shape.clone(),
        readings: kept.readings.clone(),
        seen,
        noise,
        cell_variance,
        shape_chi2,
        shape_dof: observed - 3.0,
        flips,
        consistency_chi2,
        consistency_dof,
        all_cells_rms_raw,
        kept_fraction: if total > 0.0 {
            kept_readings / total
        } else {
            0.0
        },
        depth,
        fixed_in_the_ground,
        shape_beside_relief,
        raw_per_inverse_depth: first.raw_per_inverse_depth,
        fit_band_raw: median_fit_band(poses) * first.raw_per_inverse_depth.abs(),
        intrinsics: first.intrinsics,
        iterations: *iterations,
    })
}

/// The median of the poses' ground-fit bands, 1/m (infinite when no pose
/// says: the residuals of a test, not of a fit).
fn median_fit_band(poses: &[&GroundResiduals]) -> f64 {
    let mut bands: Vec<f64> = poses
        .iter()
        .map(|p| p.fit_band)
        .filter(|b| b.is_finite() && *b > 0.0)
        .collect();
    if bands.is_empty() {
        return f64::INFINITY;
    }
    bands.sort_by(f64::total_cmp);
    bands[bands.len() / 2]
}

/// A cell is left out when it lies this far (raw units) from the median of
/// the two cells above and the two below it, and 6 of its σ: a simulated
/// bowl of ±0.5 raw units changes by 0.03 from a cell to the next down the
/// image, the foot of a box by several tenths.
const LONE_CELL_RAW: f64 = 0.15;

/// The cells seen that lie far from those above and below them.
fn lone_cells(
    shape: &[f64],
    kept: &Kept,
    raw_per_inverse_depth: f64,
    cell_variance: &[f64],
) -> Vec<usize> {
    let cells = shape.len();
    let columns = kept.columns;
    let k_raw = raw_per_inverse_depth.abs();
    let mut lone = Vec::new();
    for k in 0..cells {
        if !kept.seen[k] {
            continue;
        }
        let mut around: Vec<f64> = [-2i64, -1, 1, 2]
            .iter()
            .filter_map(|dr| {
                let j = k as i64 + dr * columns as i64;
                (j >= 0 && (j as usize) < cells && kept.seen[j as usize]).then(|| shape[j as usize])
            })
            .collect();
        if around.len() < 2 {
            continue;
        }
        around.sort_by(f64::total_cmp);
        let median = (around[(around.len() - 1) / 2] + around[around.len() / 2]) / 2.0;
        let off = (shape[k] - median).abs() * k_raw;
        let sigma = cell_variance[k].max(0.0).sqrt() * k_raw;
        if off > LONE_CELL_RAW.max(6.0 * sigma) {
            lone.push(k);
        }
    }
    lone
}

/// A cell's sum at one pose is left out when its mean lies this many of its
/// σ from the pattern and the plane.
const ENTRY_SIGMAS: f64 = 4.5;

/// Which cells' sums, pose by pose, enter the estimate.
#[derive(Debug, Clone, PartialEq)]
struct Kept {
    /// Cells per row of the image.
    columns: usize,
    /// `out[i·cells + k]`: pose i's sum of cell k is left out.
    out: Vec<bool>,
    /// Per cell: readings of the sums kept.
    readings: Vec<f64>,
    /// Per cell: whether it enters the estimate (enough readings kept,
    /// from two poses at least).
    seen: Vec<bool>,
    /// Per pose: the inverse of Σφφᵀ and Σr·φ over its readings less
    /// those of the sums left out.
    inverse_moments: Vec<Matrix3<f64>>,
    rhs: Vec<Vector3<f64>>,
    /// Per pose: the cells whose sums are taken (the loops' work list).
    taken: Vec<Vec<u32>>,
}

impl Kept {
    /// Every sum.
    fn all(poses: &[&GroundResiduals]) -> Self {
        let cells = poses[0].cells.len();
        Self::from_out(poses, vec![false; poses.len() * cells], None)
    }

    /// The sums within [`ENTRY_SIGMAS`] of `fitted`, among the cells first seen.
    fn within(
        poses: &[&GroundResiduals],
        fitted: &Fitted,
        noise: &CellNoise,
        first_seen: &[bool],
    ) -> Self {
        let cells = first_seen.len();
        let mut out = vec![false; poses.len() * cells];
        out.par_chunks_mut(cells)
            .zip(poses)
            .zip(&fitted.planes)
            .for_each(|((out, pose), c)| {
                for (k, cell) in pose.cells.iter().enumerate() {
                    if first_seen[k] && cell.n > 0.0 {
                        let model =
                            fitted.shape[k] * cell.n + c.x * cell.n + c.y * cell.u + c.z * cell.v;
                        let z = (cell.r - model) / cell.n / noise.of_mean(cell.n).sqrt();
                        out[k] = z.abs() > ENTRY_SIGMAS;
                    }
                }
            });
        Self::from_out(poses, out, Some(first_seen))
    }

    fn from_out(poses: &[&GroundResiduals], out: Vec<bool>, among: Option<&[bool]>) -> Self {
        let cells = poses[0].cells.len();
        let mut readings = vec![0.0; cells];
        let mut poses_seen = vec![0usize; cells];
        // A reading's spread about its cell's centre, per axis (pixels²).
        let spread = ((CELL_PX * CELL_PX) as f64 - 1.0) / 12.0;
        // Each pose's moments less those of its sums left out (their
        // readings' spread about the cell's centre taken as uniform).
        let (inverse_moments, rhs): (Vec<Matrix3<f64>>, Vec<Vector3<f64>>) = poses
            .par_iter()
            .zip(out.par_chunks(cells))
            .map(|(pose, out)| {
                let (mut moments, mut sums) = (pose.moments, pose.rhs);
                for (cell, _) in pose.cells.iter().zip(out).filter(|(c, o)| **o && c.n > 0.0) {
                    let centre = Vector3::new(1.0, cell.u / cell.n, cell.v / cell.n);
                    moments -= (centre * centre.transpose()
                        + Matrix3::from_diagonal(&Vector3::new(0.0, spread, spread)))
                        * cell.n;
                    sums -= centre * cell.r;
                }
                (moments.try_inverse().unwrap_or_else(Matrix3::zeros), sums)
            })
            .unzip();
        for (pose, out) in poses.iter().zip(out.chunks(cells)) {
            for (k, (cell, out)) in pose.cells.iter().zip(out).enumerate() {
                if cell.n > 0.0 && !out {
                    readings[k] += cell.n;
                    poses_seen[k] += 1;
                }
            }
        }
        let seen: Vec<bool> = (0..cells)
            .map(|k| {
                among.is_none_or(|a| a[k]) && readings[k] >= MIN_CELL_READINGS && poses_seen[k] >= 2
            })
            .collect();
        let taken = poses
            .par_iter()
            .enumerate()
            .map(|(i, pose)| {
                (0..cells)
                    .filter(|&k| pose.cells[k].n > 0.0 && seen[k] && !out[i * cells + k])
                    .map(|k| k as u32)
                    .collect()
            })
            .collect();
        Self {
            columns: poses[0].columns,
            out,
            readings,
            seen,
            inverse_moments,
            rhs,
            taken,
        }
    }

    /// Leaves these cells out of the estimate altogether.
    fn leave_out(&mut self, cells: &[usize]) {
        for &k in cells {
            self.seen[k] = false;
        }
        let seen = &self.seen;
        for taken in &mut self.taken {
            taken.retain(|&k| seen[k as usize]);
        }
    }

    /// Whether pose i's sum of cell k enters the estimate.
    fn takes(&self, i: usize, k: usize) -> bool {
        self.seen[k] && !self.out[i * self.seen.len() + k]
    }
}

/// The pattern over the cells seen and each pose's plane given it.
struct Fitted {
    /// Per cell, 1/m, without a plane part over the cells seen.
    shape: Vec<f64>,
    /// Per pose: the plane (1/m on `c0, cu, cv`) that fits its residuals
    /// less the pattern.
    planes: Vec<Vector3<f64>>,
    iterations: usize,
}

/// Cells a worker takes at a time in the pattern's step.
const CELL_BLOCK: usize = 512;

/// Alternating least squares of the pattern and the planes over the sums
/// kept, until the pattern moves by less than 10⁻⁴ raw units.
fn alternate(poses: &[&GroundResiduals], kept: &Kept, start: Option<&[f64]>) -> Fitted {
    let cells = kept.seen.len();
    let grid = poses[0];
    let tolerance = 1e-4 / grid.raw_per_inverse_depth.abs();
    // From the last estimate, when there is one: leaving a few cells out
    // moves it little.
    let mut shape = match start {
        Some(start) if start.len() == cells => start
            .iter()
            .zip(&kept.seen)
            .map(|(v, seen)| if *seen { *v } else { 0.0 })
            .collect(),
        _ => vec![0.0; cells],
    };
    let mut planes = vec![Vector3::zeros(); poses.len()];
    let mut iterations = 0;
    for _ in 0..2000 {
        iterations += 1;
        // Each pose's plane given the pattern.
        planes.par_iter_mut().enumerate().for_each(|(i, plane)| {
            let mut rhs = kept.rhs[i];
            for &k in &kept.taken[i] {
                let cell = &poses[i].cells[k as usize];
                rhs -= Vector3::new(cell.n, cell.u, cell.v) * shape[k as usize];
            }
            *plane = kept.inverse_moments[i] * rhs;
        });
        // The pattern given the planes, a block of cells at a time (each
        // cell summed over the poses in their order).
        let mut next = vec![0.0; cells];
        next.par_chunks_mut(CELL_BLOCK)
            .enumerate()
            .for_each(|(block, next)| {
                let (first, end) = (block * CELL_BLOCK, block * CELL_BLOCK + next.len());
                for (i, pose) in poses.iter().enumerate() {
                    let c = planes[i];
                    let taken = &kept.taken[i];
                    let from = taken.partition_point(|&k| (k as usize) < first);
                    for &k in &taken[from..] {
                        let k = k as usize;
                        if k >= end {
                            break;
                        }
                        let cell = &pose.cells[k];
                        next[k - first] += cell.r - (c.x * cell.n + c.y * cell.u + c.z * cell.v);
                    }
                }
            });
        for ((value, seen), readings) in next.iter_mut().zip(&kept.seen).zip(&kept.readings) {
            if *seen {
                *value /= readings;
            }
        }
        // No plane part: that is the planes' (and the geometry's) to say.
        remove_plane_part(&mut next, &kept.readings, &kept.seen, grid);
        let change = next
            .iter()
            .zip(&shape)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        shape = next;
        if change < tolerance {
            break;
        }
    }
    Fitted {
        shape,
        planes,
        iterations,
    }
}

/// The readings' noise about their cell's mean, pooled over cells and
/// poses: a variance, (1/m)².
fn reading_variance(poses: &[&GroundResiduals]) -> f64 {
    let (mut within, mut within_dof) = (0.0, 0.0);
    for pose in poses {
        for cell in &pose.cells {
            if cell.n > 1.0 {
                within += cell.rr - cell.r * cell.r / cell.n;
                within_dof += cell.n - 1.0;
            }
        }
    }
    if within_dof > 0.0 {
        (within / within_dof).max(f64::MIN_POSITIVE)
    } else {
        f64::INFINITY
    }
}

/// A pattern that changes with the depth (Herrera et al. 2012: weaker
/// farther), to first order `D·(1 − per_m·(z − z̄))` about each cell's mean
/// depth over the poses that saw it: found from the cells' residuals after
/// the fixed shape, against the shape times their depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthDependence {
    /// The share by which the pattern weakens a metre farther.
    pub per_m: f64,
    /// Its σ, from the poses' own residuals (a sandwich by pose: the cells
    /// of one pose share its noise).
    pub sigma: f64,
    /// What it changes in the cells over the depths the poses saw: the RMS
    /// of `per_m·shape·(z − z̄)`, raw units.
    pub effect_raw: f64,
}

impl DepthDependence {
    /// Whether it differs from none, and by as much as a shape must to
    /// matter ([`MIN_SHAPE_RMS_RAW`]).
    pub fn significant(&self) -> bool {
        self.sigma > 0.0
            && (self.per_m / self.sigma).abs() > ALTERNATIVE_SIGMAS
            && self.effect_raw >= MIN_SHAPE_RMS_RAW
    }
}

/// A cell's centre, pixels from the principal point.
fn cell_centre(k: usize, columns: usize, intrinsics: &Intrinsics) -> (f64, f64) {
    let (column, row) = (k % columns, k / columns);
    (
        (column * CELL_PX) as f64 + (CELL_PX as f64 - 1.0) / 2.0 - intrinsics.cx,
        (row * CELL_PX) as f64 + (CELL_PX as f64 - 1.0) / 2.0 - intrinsics.cy,
    )
}

/// [`DepthDependence`] of the sums kept under the shape.
fn depth_dependence(
    poses: &[&GroundResiduals],
    entries: &[Entry],
    shape: &[f64],
    noise: &CellNoise,
) -> DepthDependence {
    let none = DepthDependence {
        per_m: 0.0,
        sigma: f64::INFINITY,
        effect_raw: 0.0,
    };
    let Some(first) = poses.first() else {
        return none;
    };
    let depth = |e: &Entry| {
        let (du, dv) = cell_centre(e.cell as usize, first.columns, &first.intrinsics);
        let q = poses[e.pose as usize].plane.at(du, dv);
        (q > 0.0).then(|| 1.0 / q)
    };
    // Each cell's mean depth over the poses that saw it.
    let cells = shape.len();
    let (mut sum, mut weight) = (vec![0.0; cells], vec![0.0; cells]);
    for e in entries {
        if let Some(z) = depth(e) {
            let w = 1.0 / noise.of_mean(e.n);
            sum[e.cell as usize] += w * z;
            weight[e.cell as usize] += w;
        }
    }
    // residual ≈ −per_m·x with x = shape·(z − z̄).
    let mut rows = Vec::with_capacity(entries.len());
    let (mut xx, mut xe, mut ww) = (0.0, 0.0, 0.0);
    for e in entries {
        let k = e.cell as usize;
        let (Some(z), true) = (depth(e), weight[k] > 0.0) else {
            continue;
        };
        let x = shape[k] * (z - sum[k] / weight[k]);
        let w = 1.0 / noise.of_mean(e.n);
        xx += w * x * x;
        xe += w * x * e.residual;
        ww += w;
        rows.push((e.pose, w, x, e.residual));
    }
    if xx <= 0.0 {
        return none;
    }
    let per_m = -xe / xx;
    let mut by_pose = vec![0.0; poses.len()];
    for (pose, w, x, residual) in rows {
        by_pose[pose as usize] += w * x * (residual + per_m * x);
    }
    let meat: f64 = by_pose.iter().map(|s| s * s).sum();
    DepthDependence {
        per_m,
        sigma: meat.sqrt() / xx,
        effect_raw: per_m.abs() * (xx / ww).sqrt() * first.raw_per_inverse_depth.abs(),
    }
}

/// Bins of depth in which the pattern's gain is found when it changes with
/// depth (quantiles of the depths the cells were seen at).
const DEPTH_BINS: usize = 8;

/// The entries less what the pattern's change with depth accounts for: the
/// shape times a gain per bin of depth (any change with depth, not only the
/// linear one [`DepthDependence`] measures), each cell about its own mean
/// gain, by least squares.
fn without_depth_dependence(
    poses: &[&GroundResiduals],
    entries: &[Entry],
    shape: &[f64],
) -> Vec<Entry> {
    use nalgebra::{SMatrix, SVector};
    let first = poses[0];
    let z = |e: &Entry| {
        let (du, dv) = cell_centre(e.cell as usize, first.columns, &first.intrinsics);
        let q = poses[e.pose as usize].plane.at(du, dv);
        (q > 0.0).then(|| 1.0 / q)
    };
    let mut depths: Vec<f64> = entries.iter().filter_map(z).collect();
    if depths.len() < DEPTH_BINS * 10 {
        return entries.to_vec();
    }
    depths.sort_by(f64::total_cmp);
    let edges: Vec<f64> = (1..DEPTH_BINS)
        .map(|j| depths[j * depths.len() / DEPTH_BINS])
        .collect();
    let bin = |z: f64| edges.partition_point(|&edge| edge <= z);
    // Each cell's share of its readings in each bin.
    let cells = shape.len();
    let mut share = vec![[0.0; DEPTH_BINS]; cells];
    let mut total = vec![0.0; cells];
    for e in entries {
        if let Some(z) = z(e) {
            share[e.cell as usize][bin(z)] += e.n;
            total[e.cell as usize] += e.n;
        }
    }
    let design = |e: &Entry, z: f64| -> SVector<f64, DEPTH_BINS> {
        let k = e.cell as usize;
        let mut row = SVector::<f64, DEPTH_BINS>::zeros();
        for j in 0..DEPTH_BINS {
            let own = if bin(z) == j { 1.0 } else { 0.0 };
            row[j] = shape[k] * (own - share[k][j] / total[k]);
        }
        row
    };
    let mut normal = SMatrix::<f64, DEPTH_BINS, DEPTH_BINS>::zeros();
    let mut rhs = SVector::<f64, DEPTH_BINS>::zeros();
    for e in entries {
        if let Some(z) = z(e) {
            if total[e.cell as usize] > 0.0 {
                let row = design(e, z);
                normal += row * row.transpose() * e.n;
                rhs += row * (e.residual * e.n);
            }
        }
    }
    // The gains are known up to a constant (each cell is centred): the
    // smallest change that fits, by a ridge a millionth of the scale.
    let ridge = normal.trace().max(f64::MIN_POSITIVE) * 1e-6;
    let gains = (normal + SMatrix::identity() * ridge)
        .try_inverse()
        .map(|h| h * rhs)
        .unwrap_or_default();
    entries
        .iter()
        .map(|e| match z(e) {
            Some(z) if total[e.cell as usize] > 0.0 => Entry {
                residual: e.residual - design(e, z).dot(&gains),
                ..*e
            },
            _ => *e,
        })
        .collect()
}

/// Whether the residuals left by pattern and planes stay with the ground:
/// each sum's cell seen on the ground from its pose, binned by
/// [`GROUND_BIN_M`], and the bins' means over the poses compared with those
/// the poses make with random signs.
fn ground_fixed(
    poses: &[&GroundResiduals],
    entries: &[Entry],
    ground_from_sensor: &[crate::geometry::Transform],
) -> (FlipTest, Vec<Option<u32>>) {
    let first = poses[0];
    let k = first.intrinsics;
    let sensor_from_optical = crate::geometry::sensor_from_optical();
    let mut bins: std::collections::HashMap<(i64, i64), u32> = std::collections::HashMap::new();
    let mut binned = Vec::with_capacity(entries.len());
    let mut bin_of = Vec::with_capacity(entries.len());
    for e in entries {
        let (du, dv) = cell_centre(e.cell as usize, first.columns, &k);
        let pose = &ground_from_sensor[e.pose as usize];
        let ray = pose.rotation * (sensor_from_optical * Vector3::new(du / k.fx, dv / k.fy, 1.0));
        let origin = pose.translation.vector;
        if ray.y >= -1e-9 {
            bin_of.push(None);
            continue;
        }
        let t = -origin.y / ray.y;
        let (x, z) = (origin.x + t * ray.x, origin.z + t * ray.z);
        let key = (
            (x / GROUND_BIN_M).floor() as i64,
            (z / GROUND_BIN_M).floor() as i64,
        );
        let next = bins.len() as u32;
        let bin = *bins.entry(key).or_insert(next);
        bin_of.push(Some(bin));
        binned.push(Entry {
            cell: bin,
            about_plane: e.residual,
            ..*e
        });
    }
    let mut weights = vec![0.0; bins.len()];
    let mut sums = vec![0.0; bins.len()];
    for e in &binned {
        weights[e.cell as usize] += e.n;
        sums[e.cell as usize] += e.n * e.about_plane;
    }
    let mean = |sums: &[f64]| -> Vec<f64> {
        sums.iter()
            .zip(&weights)
            .map(|(s, w)| if *w > 0.0 { s / w } else { 0.0 })
            .collect()
    };
    let test = flip_test(&binned, poses.len(), &weights, &mean(&sums), mean);
    (test, bin_of)
}

/// The shape estimated beside a relief of the ground: a mean per bin of
/// the ground ([`ground_fixed`]'s, `bin_of` each entry's), taken out in
/// turns with the shape. Its flip test's σ, and its RMS against the
/// shape's alone. What stays with the ground at obstacles' feet is local,
/// and a sensor's pattern stands beside it; bumps all over the ground take
/// the shape with them. A bin seen by fewer than three poses has no relief
/// (it would take in those poses' cells whole).
fn shape_beside_relief(
    entries: &[Entry],
    bin_of: &[Option<u32>],
    poses: usize,
    weights: &[f64],
    shape_of: impl Fn(&[f64]) -> Vec<f64>,
) -> ReliefTest {
    let bins = bin_of.iter().flatten().max().map_or(0, |b| *b as usize + 1);
    let mut seen_by = vec![(0u32, u32::MAX); bins];
    for (e, bin) in entries.iter().zip(bin_of) {
        if let Some(b) = bin {
            let (count, last) = &mut seen_by[*b as usize];
            if *last != e.pose {
                *count += 1;
                *last = e.pose;
            }
        }
    }
    let per_cell = |values: &dyn Fn(&Entry, Option<u32>) -> f64| {
        let mut sums = vec![0.0; weights.len()];
        for (e, bin) in entries.iter().zip(bin_of) {
            sums[e.cell as usize] += e.n * values(e, *bin);
        }
        sums
    };
    let alone = shape_of(&per_cell(&|e, _| e.about_plane));
    let mut shape = alone.clone();
    let mut relief = vec![0.0; bins];
    for _ in 0..RELIEF_TURNS {
        let mut sums = vec![(0.0, 0.0); bins];
        for (e, bin) in entries.iter().zip(bin_of) {
            if let Some(b) = bin.filter(|b| seen_by[*b as usize].0 >= 3) {
                let (s, w) = &mut sums[b as usize];
                *s += e.n * (e.about_plane - shape[e.cell as usize]);
                *w += e.n;
            }
        }
        relief = sums
            .iter()
            .map(|(s, w)| if *w > 0.0 { s / w } else { 0.0 })
            .collect();
        let relief_of = |bin: Option<u32>| bin.map_or(0.0, |b| relief[b as usize]);
        shape = shape_of(&per_cell(&|e, bin| e.about_plane - relief_of(bin)));
    }
    let beside: Vec<Entry> = entries
        .iter()
        .zip(bin_of)
        .map(|(e, bin)| Entry {
            about_plane: e.about_plane - bin.map_or(0.0, |b| relief[b as usize]),
            ..*e
        })
        .collect();
    let size = |s: &[f64]| s.iter().zip(weights).map(|(v, w)| w * v * v).sum::<f64>();
    // The relief's size over the ground seen, weighted by readings.
    let (mut relief_sum, mut readings) = (0.0, 0.0);
    for (e, bin) in entries.iter().zip(bin_of) {
        if let Some(b) = bin {
            relief_sum += e.n * relief[*b as usize].powi(2);
            readings += e.n;
        }
    }
    ReliefTest {
        shape_sigmas: flip_test(&beside, poses, weights, &shape, &shape_of).sigmas(),
        shape_share: (size(&shape) / size(&alone).max(f64::MIN_POSITIVE)).sqrt(),
        relief_rms: (relief_sum / readings.max(f64::MIN_POSITIVE)).sqrt(),
    }
}

/// The sums kept, each as its cell's mean residual about pattern and plane
/// and about the plane alone.
fn entries(poses: &[&GroundResiduals], kept: &Kept, fitted: &Fitted) -> Vec<Entry> {
    let mut entries = Vec::new();
    for (i, pose) in poses.iter().enumerate() {
        let c = fitted.planes[i];
        for (k, cell) in pose.cells.iter().enumerate() {
            if cell.n > 0.0 && kept.takes(i, k) {
                let plane = c.x * cell.n + c.y * cell.u + c.z * cell.v;
                let about_plane = (cell.r - plane) / cell.n;
                entries.push(Entry {
                    pose: i as u32,
                    cell: k as u32,
                    n: cell.n,
                    residual: about_plane - fitted.shape[k],
                    about_plane,
                });
            }
        }
    }
    entries
}

/// The noise of a cell's mean, from the sums kept about pattern and plane.
fn estimate_noise(
    poses: &[&GroundResiduals],
    kept: &Kept,
    fitted: &Fitted,
    within: f64,
) -> CellNoise {
    let entries = entries(poses, kept, fitted);
    let observed = kept.seen.iter().filter(|s| **s).count() as f64;
    CellNoise::estimate(within, &entries, observed + 3.0 * poses.len() as f64)
}

/// Each cell's shape variance under `noise`: one over the sum of its sums'
/// information, pose by pose (0 where not seen).
fn cell_variances(poses: &[&GroundResiduals], kept: &Kept, noise: &CellNoise) -> Vec<f64> {
    let cells = kept.seen.len();
    let mut information = vec![0.0; cells];
    for (i, pose) in poses.iter().enumerate() {
        for &k in &kept.taken[i] {
            let n = pose.cells[k as usize].n;
            information[k as usize] += 1.0 / noise.of_mean(n);
        }
    }
    information
        .iter()
        .map(|&info| if info > 0.0 { 1.0 / info } else { 0.0 })
        .collect()
}

/// The plane (1/m on `c0, cu, cv`) by which the pattern `shape` bent the
/// fit of one pose. The fit took only the readings within its band of its
/// own plane, so where the pattern lifts the readings it cut more of their
/// upper tail, and it saw the pattern smaller than it is (a third smaller
/// where the pattern is a σ): its plane `β` solves the expected truncated
/// normal equations `Σ_k n_k·φ_k·g(D_k − φ_k·β) = 0`, with `g(m)` the mean
/// of a reading `m + ε` (ε ~ N(0, σ²)) within the band, times the share
/// kept. Newton's method from the untruncated bend `M⁻¹·Σ D_k·(n, Σu', Σv')_k`.
fn bend(pose: &GroundResiduals, shape: &[f64], seen: &[bool], sigma: f64) -> Vector3<f64> {
    let inverse = pose.moments.try_inverse().unwrap_or_else(Matrix3::zeros);
    let mut untruncated = Vector3::zeros();
    for (k, cell) in pose.cells.iter().enumerate() {
        if seen[k] && cell.n > 0.0 {
            untruncated += Vector3::new(cell.n, cell.u, cell.v) * shape[k];
        }
    }
    let mut plane = inverse * untruncated;
    let band = pose.fit_band;
    if !(band.is_finite() && band > 0.0 && sigma.is_finite() && sigma > 0.0) {
        return plane;
    }
    // The cells with readings, their centres and pattern, once: each Newton
    // step walks them all.
    let cells: Vec<BentCell> = pose
        .cells
        .iter()
        .enumerate()
        .filter(|(_, cell)| cell.n > 0.0)
        .map(|(k, cell)| BentCell {
            n: cell.n,
            u: cell.u / cell.n,
            v: cell.v / cell.n,
            pattern: if seen[k] { shape[k] } else { 0.0 },
        })
        .collect();
    let beta = band / sigma;
    for _ in 0..6 {
        // Σ φ·n·g·σ, and the slope's six distinct moments Σ φφᵀ·n·g'.
        let (mut value, mut slope) = (Vector3::zeros(), [0.0; 6]);
        for cell in &cells {
            let m = (cell.pattern - (plane.x + cell.u * plane.y + cell.v * plane.z)) / sigma;
            let (g, dg) = truncated_mean(m, beta);
            let (gain, w) = (cell.n * g * sigma, cell.n * dg);
            value += Vector3::new(gain, cell.u * gain, cell.v * gain);
            slope[0] += w;
            slope[1] += cell.u * w;
            slope[2] += cell.v * w;
            slope[3] += cell.u * cell.u * w;
            slope[4] += cell.u * cell.v * w;
            slope[5] += cell.v * cell.v * w;
        }
        let [s0, su, sv, suu, suv, svv] = slope;
        let slope = -Matrix3::new(s0, su, sv, su, suu, suv, sv, suv, svv);
        let Some(step) = slope.try_inverse().map(|h| h * value) else {
            break;
        };
        plane -= step;
        // 10⁻⁹ /m is a millionth of a raw unit.
        if step.amax() < 1e-9 {
            break;
        }
    }
    plane
}

/// A cell as the bend sees it: its readings, their centre (pixels from the
/// principal point) and the pattern there (1/m).
struct BentCell {
    n: f64,
    u: f64,
    v: f64,
    pattern: f64,
}

/// For ε ~ N(0, 1): `g(m) = E[(m + ε)·1{|m + ε| < β}]` and its derivative.
fn truncated_mean(m: f64, beta: f64) -> (f64, f64) {
    let ((pdf_hi, cdf_hi), (pdf_lo, cdf_lo)) = (normal(beta - m), normal(-beta - m));
    let kept = cdf_hi - cdf_lo;
    let g = m * kept - (pdf_hi - pdf_lo);
    // d/dm: the share kept, less what the band's edges take with them.
    let dg = kept - beta * (pdf_hi + pdf_lo);
    (g, dg)
}

/// The standard normal density φ(x) and distribution Φ(x), sharing one
/// exponential (the bend evaluates them for every cell of every pose at
/// each Newton step): Φ by Abramowitz and Stegun 7.1.26, |error| below
/// 1.5·10⁻⁷.
fn normal(x: f64) -> (f64, f64) {
    let gauss = (-0.5 * x * x).exp();
    let pdf = gauss / (2.0 * std::f64::consts::PI).sqrt();
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs() / std::f64::consts::SQRT_2);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    // erfc(|x|/√2) = poly·exp(−x²/2).
    let tail = 0.5 * poly * gauss;
    (pdf, if x >= 0.0 { 1.0 - tail } else { tail })
}

/// RMS of the values of the cells seen, weighted by their readings.
fn weighted_rms(values: &[f64], readings: &[f64], seen: &[bool]) -> f64 {
    let (mut sum, mut weight) = (0.0, 0.0);
    for k in 0..values.len() {
        if seen[k] {
            sum += readings[k] * values[k].powi(2);
            weight += readings[k];
        }
    }
    if weight > 0.0 {
        (sum / weight).sqrt()
    } else {
        0.0
    }
}

/// Subtracts the plane `A + B·u' + C·v'` that fits the cells seen, weighted
/// by their readings.
fn remove_plane_part(shape: &mut [f64], readings: &[f64], seen: &[bool], grid: &GroundResiduals) {
    let centre = |k: usize| {
        let (column, row) = (k % grid.columns, k / grid.columns);
        Vector3::new(
            1.0,
            (column * CELL_PX) as f64 + (CELL_PX as f64 - 1.0) / 2.0 - grid.intrinsics.cx,
            (row * CELL_PX) as f64 + (CELL_PX as f64 - 1.0) / 2.0 - grid.intrinsics.cy,
        )
    };
    let (mut normal, mut rhs) = (Matrix3::zeros(), Vector3::zeros());
    for k in 0..shape.len() {
        if seen[k] {
            let phi = centre(k);
            normal += phi * phi.transpose() * readings[k];
            rhs += phi * (shape[k] * readings[k]);
        }
    }
    let Some(plane) = normal.try_inverse().map(|h| h * rhs) else {
        return;
    };
    for k in 0..shape.len() {
        if seen[k] {
            shape[k] -= plane.dot(&centre(k));
        }
    }
}

/// The plane part of the pattern in raw units: a constant and its gradients
/// per 100 pixels along the columns and the rows.
type PlanePart = Vector3<f64>;

/// The plane part in inverse depth (1/m) on `c0, cu, cv`.
fn plane_part_inverse_depth(part: &PlanePart, raw_per_inverse_depth: f64) -> Vector3<f64> {
    Vector3::new(part.x, part.y / 100.0, part.z / 100.0) / raw_per_inverse_depth
}

/// The observation with its plane moved by `delta` in inverse depth (1/m on
/// `c0, cu, cv`); unchanged if the plane would not be a plane.
fn moved(observation: &Observation, delta: &Vector3<f64>, intrinsics: &Intrinsics) -> Observation {
    let pixel = PixelPlane::from_plane(&observation.plane, intrinsics);
    let next = PixelPlane {
        c0: pixel.c0 + delta.x,
        cu: pixel.cu + delta.y,
        cv: pixel.cv + delta.z,
    };
    let mut observation = observation.clone();
    if let Some(plane) = next.to_plane(intrinsics) {
        observation.plane = plane;
    }
    observation
}

/// The solve with the depth pattern: the mount, the depth scale and the
/// pattern (shape and plane part) together, each part taken only when the
/// evidence shows it. Without residuals (planes given as numbers) it is the
/// plain solve.
pub fn solve_with_pattern(
    observations: &[Observation],
    settings: &SolveSettings,
) -> Result<Solution, SolveError> {
    solve_with_pattern_taken_out(observations, settings, None)
}

/// [`solve_with_pattern`] for planes fitted to frames from which `taken_out`
/// was taken out first: a first estimate of the pattern, so that the fit's
/// band lies about the pattern and cuts none of its peaks (docs/method.md,
/// "A pattern beyond the fit's band"). When the residuals left are a
/// pattern fixed in the image (no test of an alternative fires), the
/// pattern found is `taken_out` plus what they still show, and its plane
/// part is estimated as for a shape taken; otherwise nothing is corrected
/// and the reason is the residuals'.
pub fn solve_with_pattern_taken_out(
    observations: &[Observation],
    settings: &SolveSettings,
    taken_out: Option<&DepthCorrection>,
) -> Result<Solution, SolveError> {
    let base = solve::solve(observations, settings)?;
    let used = |o: &Observation| base.poses.iter().any(|p| p.index == o.index && p.used);
    let with_residuals: Vec<(usize, &GroundResiduals)> = observations
        .iter()
        .enumerate()
        .filter(|(_, o)| used(o))
        .filter_map(|(k, o)| o.ground_residuals.as_deref().map(|r| (k, r)))
        .collect();
    if with_residuals.is_empty() {
        return Ok(base);
    }
    let residuals: Vec<&GroundResiduals> = with_residuals.iter().map(|(_, r)| *r).collect();
    // Where each pose's sensor stood over the ground, by the plain solve:
    // residuals that stay with the ground are the ground's, not the sensor's.
    let robot_from_sensor = base.robot_from_sensor.to_transform();
    let ground_from_sensor: Vec<crate::geometry::Transform> = with_residuals
        .iter()
        .map(|(k, _)| observations[*k].ground_from_robot * robot_from_sensor)
        .collect();
    let Some(shape) = estimate_shape_seen_from(&residuals, Some(&ground_from_sensor)) else {
        let mut base = base;
        base.depth_pattern = Some(DepthPattern::not_estimated(format!(
            "not estimated: {} poses had ground readings, at least {MIN_PATTERN_POSES} are needed",
            residuals.len()
        )));
        return Ok(base);
    };
    let intrinsics = shape.intrinsics;
    let indices: Vec<usize> = with_residuals.iter().map(|(k, _)| *k).collect();
    if residuals.iter().any(|r| r.beside_another_fit.is_some()) {
        // Another fit's planes: what the residuals and the geometry show is
        // judged, never corrected (the bends are the default fit's). The
        // geometry is that of the default fit's planes too: the other fit's
        // own bias changes with the pose as an offset and gradients would
        // (the paper's, beside a corridor's walls, found a 4σ "pattern"
        // that the default fit's planes do not show).
        let mut own_planes = observations.to_vec();
        for ((k, _), r) in with_residuals.iter().zip(&residuals) {
            if let Some(own) = r.beside_another_fit {
                own_planes[*k].plane = own.plane;
                own_planes[*k].plane_covariance = Some(own.covariance);
            }
        }
        let Ok(own_base) = solve::solve(&own_planes, settings) else {
            let mut base = base;
            base.depth_pattern = Some(pattern_not_corrected_by_another_fit(&shape, None));
            return Ok(base);
        };
        let plane = PlanePartSolve {
            observations: &own_planes,
            indices: &indices,
            settings,
            intrinsics,
            raw_per_inverse_depth: shape.raw_per_inverse_depth,
            noise: own_base.noise_per_pose,
        };
        let part = plane
            .estimate()
            .filter(|found| shape.consistent() && found.chi2 > PLANE_PART_CHI2);
        let mut base = base;
        base.depth_pattern = Some(pattern_not_corrected_by_another_fit(&shape, part.as_ref()));
        return Ok(base);
    }

    // The shape's corrections of each plane, when the shape is real.
    let consistent = match taken_out {
        Some(_) => shape.why_not_fixed_after_a_first_estimate().is_none(),
        None => shape.consistent(),
    };
    let shape_taken = shape.significant() && consistent;
    let taken_out = taken_out.filter(|_| consistent);
    let mut corrected = observations.to_vec();
    if shape_taken {
        let corrections = shape.plane_corrections(&residuals);
        for ((k, _), correction) in with_residuals.iter().zip(&corrections) {
            corrected[*k] = moved(&observations[*k], correction, &intrinsics);
        }
    }
    let shaped = if shape_taken {
        solve::solve(&corrected, settings)?
    } else {
        base.clone()
    };

    // The plane part, by the geometry.
    let plane = PlanePartSolve {
        observations: &corrected,
        indices: &indices,
        settings,
        intrinsics,
        raw_per_inverse_depth: shape.raw_per_inverse_depth,
        noise: shaped.noise_per_pose,
    };
    let estimate = plane.estimate();
    let (solution, plane_part, angle_sigma_known_part) = match estimate {
        Some(found)
            if shape_taken
                || taken_out.is_some()
                || (consistent && found.chi2 > PLANE_PART_CHI2) =>
        {
            let mut solution = found.solution.clone();
            let known = [0, 1, 2].map(|k| solution.covariance[(k, k)].max(0.0).sqrt());
            // The mount's σ with the plane part's own uncertainty.
            solution.covariance +=
                found.sensitivity * found.covariance * found.sensitivity.transpose();
            (solution, Some(found), Some(known))
        }
        other => (
            shaped,
            other.map(|found| PlanePartEstimate {
                taken: false,
                ..found
            }),
            None,
        ),
    };
    let mut solution = solution;
    solution.depth_pattern = Some(DepthPattern {
        angle_sigma_known_plane_part: angle_sigma_known_part,
        ..pattern_of(&shape, shape_taken, plane_part.as_ref(), taken_out)
    });
    Ok(solution)
}

/// The plane part's estimate.
#[derive(Debug, Clone)]
struct PlanePartEstimate {
    value: PlanePart,
    /// Its covariance, raw units.
    covariance: Matrix3<f64>,
    /// Its χ² against none.
    chi2: f64,
    /// How the six parameters move with it (radians and metres per unit).
    sensitivity: nalgebra::Matrix6x3<f64>,
    /// The solve with it.
    solution: Solution,
    taken: bool,
}

/// The plane part by variable projection: Gauss-Newton on the poses'
/// whitened residuals, the mount (and scale) solved again at each value.
struct PlanePartSolve<'a> {
    observations: &'a [Observation],
    /// The observations with ground residuals (the pattern's poses).
    indices: &'a [usize],
    settings: &'a SolveSettings,
    intrinsics: Intrinsics,
    raw_per_inverse_depth: f64,
    /// σ of one pose's normal (radians) and offset (metres) to whiten by.
    noise: (f64, f64),
}

/// Parameters fitted to the plane part's residuals: the mount's six, the
/// depth scale and the plane part's three (the residuals' degrees of
/// freedom are their count less these).
const PARAMETERS_FITTED: f64 = 10.0;

/// Steps of the numerical derivatives, raw units (and per 100 pixels).
const PLANE_PART_STEP: f64 = 0.02;

/// The plane part's problem linearised at one value.
struct Linearised {
    /// The poses' whitened residuals.
    residuals: DVector<f64>,
    /// Their derivatives by the plane part's three parameters.
    jacobian: DMatrix<f64>,
    /// `JᵀJ`: the plane part's information, in units of the whitening noise.
    information: Matrix3<f64>,
    /// How the six parameters move with it (radians and metres per unit).
    sensitivity: nalgebra::Matrix6x3<f64>,
    solution: Solution,
}

/// What estimating a pattern's plane part would add to the mount's
/// covariance (radians and metres), on `observations` that carry noise of
/// `noise` (σ of one pose's normal in radians, of its offset in metres):
/// `S·C·Sᵀ`, with `C` the plane part's covariance and `S` how the mount
/// moves with it. For planning: on exact planes predicted for a schedule it
/// says what a found pattern will cost before the robot moves. The result
/// does not depend on the intrinsics or the depth model, which only
/// re-parametrise the plane part; the defaults are used.
pub fn plane_part_cost(
    observations: &[Observation],
    settings: &SolveSettings,
    noise: (f64, f64),
) -> Option<Matrix6<f64>> {
    let intrinsics = Intrinsics::default();
    let (_, b) = crate::depth::DepthModel::inverse_linear_default().inverse_depth_affine();
    let indices: Vec<usize> = (0..observations.len()).collect();
    let problem = PlanePartSolve {
        observations,
        indices: &indices,
        settings,
        intrinsics,
        raw_per_inverse_depth: 1.0 / b,
        noise,
    };
    let linearised = problem.linearise(&PlanePart::zeros())?;
    let covariance = linearised.information.try_inverse()?;
    let s = linearised.sensitivity;
    Some(s * covariance * s.transpose())
}

impl PlanePartSolve<'_> {
    /// The observations with `part` taken out of the pattern's poses.
    fn corrected(&self, part: &PlanePart) -> Vec<Observation> {
        let delta = -plane_part_inverse_depth(part, self.raw_per_inverse_depth);
        let mut corrected = self.observations.to_vec();
        for &k in self.indices {
            corrected[k] = moved(&self.observations[k], &delta, &self.intrinsics);
        }
        corrected
    }

    /// The whitened residuals of the pattern's poses at `part`, with the
    /// solve there. The poses the first solve set aside stay aside, and no
    /// more are looked for: the derivatives must not jump with that choice,
    /// and the search is most of a solve's time.
    fn residuals(&self, part: &PlanePart) -> Option<(DVector<f64>, Solution)> {
        let mut corrected = self.corrected(part);
        for (k, observation) in corrected.iter_mut().enumerate() {
            if !self.indices.contains(&k) && observation.set_aside.is_none() {
                observation.set_aside = Some("set aside by the first solve".into());
            }
        }
        let settings = SolveSettings {
            max_outlier_fraction: 0.0,
            ..*self.settings
        };
        let solution = solve::solve(&corrected, &settings).ok()?;
        let (sigma_normal, sigma_offset) = (self.noise.0.max(1e-9), self.noise.1.max(1e-9));
        let mut values = Vec::with_capacity(3 * self.indices.len());
        let scale = solution.depth_scale.value;
        for &k in self.indices {
            let observed = &corrected[k];
            let predicted =
                solve::predict(&solution.robot_from_sensor, &observed.ground_from_robot);
            // A fixed tangent basis: that of the uncorrected normal.
            let (e1, e2) = solve::tangent_basis(&self.observations[k].plane.normal);
            let dn = predicted.normal - observed.plane.normal;
            values.push(e1.dot(&dn) / sigma_normal);
            values.push(e2.dot(&dn) / sigma_normal);
            values.push((predicted.d - observed.plane.d / scale) / sigma_offset);
        }
        Some((DVector::from_vec(values), solution))
    }

    /// The whitened residuals at `part`, their derivatives by the plane
    /// part, how the mount moves with it, and the solve at `part`.
    fn linearise(&self, part: &PlanePart) -> Option<Linearised> {
        // The residuals at `part` and a step along each of its three
        // parameters: four solves, independent, so side by side.
        let mut solved: Vec<Option<(DVector<f64>, Solution)>> = (0..4)
            .into_par_iter()
            .map(|j| {
                let mut at = *part;
                if j > 0 {
                    at[j - 1] += PLANE_PART_STEP;
                }
                self.residuals(&at)
            })
            .collect();
        let (r0, solution) = solved[0].take()?;
        let mut jacobian = DMatrix::zeros(r0.len(), 3);
        let mut sensitivity = nalgebra::Matrix6x3::zeros();
        let mount = solution.robot_from_sensor.to_vector();
        for j in 0..3 {
            let (r, moved) = solved[j + 1].take()?;
            if r.len() != r0.len() {
                return None;
            }
            jacobian.set_column(j, &((r - &r0) / PLANE_PART_STEP));
            let mut change = moved.robot_from_sensor.to_vector() - mount;
            for angle in 0..3 {
                change[angle] = wrap(change[angle]);
            }
            sensitivity.set_column(j, &(change / PLANE_PART_STEP));
        }
        let information = jacobian.transpose() * &jacobian;
        let information = Matrix3::from_fn(|i, j| information[(i, j)]);
        Some(Linearised {
            residuals: r0,
            jacobian,
            information,
            sensitivity,
            solution,
        })
    }

    fn estimate(&self) -> Option<PlanePartEstimate> {
        let mut part = PlanePart::zeros();
        let mut last = None;
        for _ in 0..6 {
            let Linearised {
                residuals: r0,
                jacobian,
                information,
                sensitivity,
                solution,
            } = self.linearise(&part)?;
            let covariance = information.try_inverse()?;
            let gradient = jacobian.transpose() * &r0;
            let step = -(covariance * Vector3::new(gradient[0], gradient[1], gradient[2]));
            // The noise the residuals show, with the pattern's part taken out.
            let dof = (r0.len() as f64 - PARAMETERS_FITTED).max(1.0);
            let factor = ((r0.norm_squared() - gradient.dot(&-step)) / dof).max(1e-6);
            // Its covariance from the poses' own residuals, never below
            // what their average noise gives: the poses are not equally
            // noisy (far ground fits worse, feet differ), and with every
            // pose taken as the average the plane part's σ came out 20–45 %
            // too small (its errors 1.22–1.45σ RMS, the pitch's 1.3–1.7σ).
            let covariance = at_least(
                &per_pose_sandwich(&covariance, &jacobian, &r0),
                &(covariance * factor),
            );
            last = Some((covariance, sensitivity, solution));
            part += step;
            if step.amax() < 1e-3 {
                break;
            }
        }
        let (covariance, sensitivity, _) = last?;
        // The solve at the plane part found, with the outliers looked for.
        let solution = solve::solve(&self.corrected(&part), self.settings).ok()?;
        let chi2 = covariance
            .try_inverse()
            .map_or(0.0, |h| (part.transpose() * h * part)[(0, 0)]);
        Some(PlanePartEstimate {
            value: part,
            covariance,
            chi2,
            sensitivity,
            solution,
            taken: true,
        })
    }
}

/// The plane part's covariance from the residuals pose by pose (a sandwich
/// clustered by pose, `(JᵀJ)⁻¹·Σ_i J_iᵀ r_i r_iᵀ J_i·(JᵀJ)⁻¹`, times
/// `n/(n − 10)` for the [`PARAMETERS_FITTED`]): right whatever the poses'
/// noise, where `σ²·(JᵀJ)⁻¹` assumes every pose as noisy as the average.
/// `inverse_information` is `(JᵀJ)⁻¹`.
fn per_pose_sandwich(
    inverse_information: &Matrix3<f64>,
    jacobian: &DMatrix<f64>,
    residuals: &DVector<f64>,
) -> Matrix3<f64> {
    let mut meat = Matrix3::zeros();
    for pose in 0..residuals.len() / 3 {
        let mut score = Vector3::zeros();
        for row in 3 * pose..3 * pose + 3 {
            for j in 0..3 {
                score[j] += jacobian[(row, j)] * residuals[row];
            }
        }
        meat += score * score.transpose();
    }
    let n = residuals.len() as f64;
    inverse_information * meat * inverse_information * (n / (n - PARAMETERS_FITTED).max(1.0))
}

/// The smallest covariance (in every direction) at least both `a` and `b`:
/// `b^½·V·max(Λ, 1)·Vᵀ·b^½`, with `VΛVᵀ` the eigen-decomposition of
/// `b^-½·a·b^-½`. `b` when it cannot be formed.
fn at_least(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    let Some(root) = b.cholesky().map(|c| c.l()) else {
        return *b;
    };
    let Some(inverse_root) = root.try_inverse() else {
        return *b;
    };
    let relative = inverse_root * a * inverse_root.transpose();
    let relative = (relative + relative.transpose()) / 2.0;
    let eigen = relative.symmetric_eigen();
    let clamped = eigen.eigenvectors
        * Matrix3::from_diagonal(&eigen.eigenvalues.map(|l| l.max(1.0)))
        * eigen.eigenvectors.transpose();
    root * clamped * root.transpose()
}

/// An angle's difference brought into (−π, π].
fn wrap(angle: f64) -> f64 {
    let turned = angle.rem_euclid(std::f64::consts::TAU);
    if turned > std::f64::consts::PI {
        turned - std::f64::consts::TAU
    } else {
        turned
    }
}

/// What the default fit's residuals, taken beside another fit
/// (`--ground-fit paper`), and the geometry across that fit's planes show.
/// A warp that changes from pose to pose is left uncorrected as with the
/// default fit; a pattern fixed in the image (a shape, or an offset and
/// gradients the geometry finds) is left uncorrected too, with its RMS over
/// the cells seen, for the gate `warp_max_mm` to judge: that fit's planes
/// cannot be corrected by these residuals. The cells keep what was found,
/// but the pattern is not `corrected`, so nothing takes it out of a frame.
fn pattern_not_corrected_by_another_fit(
    shape: &ShapeEstimate,
    plane_part: Option<&PlanePartEstimate>,
) -> DepthPattern {
    let shape_fixed = shape.significant() && shape.consistent();
    if !shape_fixed && plane_part.is_none() {
        return pattern_of(shape, false, None, None);
    }
    let mut pattern = pattern_of(shape, shape_fixed, plane_part, None);
    // The shape's RMS, as for a warp left uncorrected by the default fit;
    // without one, the offset's and gradients' over the cells seen.
    let rms = if shape_fixed {
        shape.all_cells_rms_raw
    } else {
        let cells: Vec<f64> = pattern.raw.iter().flatten().copied().collect();
        (cells.iter().map(|v| v * v).sum::<f64>() / cells.len().max(1) as f64).sqrt()
    };
    pattern.corrected = false;
    pattern.uncorrected_shape_rms_raw = Some(rms);
    pattern.uncorrected_fixed = true;
    pattern.note = Some(format!(
        "not corrected: the depth carries a pattern fixed in the image ({rms:.3} raw units RMS, seen by the default fit beside the paper's), which the paper's ground fit (--ground-fit paper) does not correct"
    ));
    pattern
}

/// The shape to fit the frames about again: when its peaks reach beyond the
/// fit's band and it was taken, or left out only for that, and no first
/// estimate was taken out already (the caller adds this one to it).
fn fit_again_about(
    shape: &ShapeEstimate,
    shape_taken: bool,
    after_a_first_estimate: bool,
) -> Option<DepthCorrection> {
    let cut = matches!(
        shape.why_not_fixed(),
        Some(crate::outcome::WarpCause::BeyondTheFit { .. })
    );
    if after_a_first_estimate || !shape.peaks_cut_by_the_fit() || !(shape_taken || cut) {
        return None;
    }
    let k_raw = shape.raw_per_inverse_depth;
    let mut cells: Vec<Option<f64>> = (0..shape.shape.len())
        .map(|k| shape.seen[k].then(|| shape.shape[k] * k_raw))
        .collect();
    extend_to_unseen_cells(&mut cells, shape.columns, shape.rows);
    DepthCorrection::from_cells(shape.columns, shape.rows, CELL_PX, &cells)
}

/// Gives each cell no pose saw the mean of its neighbours that have a
/// value, ring by ring outwards: a correction is interpolated between cell
/// centres, and one that fell to 0 past the cells seen would bend the
/// readings at their edge, which some poses see and others do not.
fn extend_to_unseen_cells(cells: &mut [Option<f64>], columns: usize, rows: usize) {
    while cells.iter().any(Option::is_none) && cells.iter().any(Option::is_some) {
        let before = cells.to_vec();
        for k in 0..cells.len() {
            if before[k].is_some() {
                continue;
            }
            let (c, r) = ((k % columns) as isize, (k / columns) as isize);
            let (mut sum, mut count) = (0.0, 0);
            for (dc, dr) in [
                (-1, 0),
                (1, 0),
                (0, -1),
                (0, 1),
                (-1, -1),
                (1, 1),
                (-1, 1),
                (1, -1),
            ] {
                let (nc, nr) = (c + dc, r + dr);
                if nc < 0 || nr < 0 || nc >= columns as isize || nr >= rows as isize {
                    continue;
                }
                if let Some(value) = before[nr as usize * columns + nc as usize] {
                    sum += value;
                    count += 1;
                }
            }
            if count > 0 {
                cells[k] = Some(sum / f64::from(count));
            }
        }
    }
}

/// The pattern as the result carries it: raw units per cell, shape and
/// plane part, with σ and the words.
fn pattern_of(
    shape: &ShapeEstimate,
    shape_taken: bool,
    plane_part: Option<&PlanePartEstimate>,
    taken_out: Option<&DepthCorrection>,
) -> DepthPattern {
    let k_raw = shape.raw_per_inverse_depth;
    let part_taken = plane_part.filter(|p| p.taken);
    let mut raw = Vec::with_capacity(shape.shape.len());
    let mut sigma_raw = Vec::with_capacity(shape.shape.len());
    for k in 0..shape.shape.len() {
        if !shape.seen[k] {
            raw.push(None);
            sigma_raw.push(None);
            continue;
        }
        let (du, dv) = shape.cell_offset(k);
        let basis = Vector3::new(1.0, du / 100.0, dv / 100.0);
        let mut value = 0.0;
        let mut variance = 0.0;
        if shape_taken {
            value += shape.shape[k] * k_raw;
        }
        if shape_taken || taken_out.is_some() {
            // What was taken out first is of the same readings: its
            // cells' noise is theirs.
            variance += shape.cell_variance[k] * k_raw * k_raw;
        }
        if let Some(first) = taken_out {
            let (du, dv) = shape.cell_offset(k);
            value += first.raw_at(du + shape.intrinsics.cx, dv + shape.intrinsics.cy);
        }
        if let Some(part) = part_taken {
            value += part.value.dot(&basis);
            variance += (basis.transpose() * part.covariance * basis)[(0, 0)];
        }
        raw.push(Some(value));
        sigma_raw.push(Some(variance.max(0.0).sqrt()));
    }
    let corrected = shape_taken || part_taken.is_some() || taken_out.is_some();
    let words_rms = match taken_out {
        // The whole shape: what was taken out and what is left.
        Some(first) => {
            let whole: Vec<f64> = (0..shape.shape.len())
                .map(|k| {
                    let (du, dv) = shape.cell_offset(k);
                    let left = if shape_taken {
                        shape.shape[k] * k_raw
                    } else {
                        0.0
                    };
                    first.raw_at(du + shape.intrinsics.cx, dv + shape.intrinsics.cy) + left
                })
                .collect();
            weighted_rms(&whole, &shape.readings, &shape.seen)
        }
        None => shape.rms_raw(),
    };
    let seen_cells = shape.seen.iter().filter(|s| **s).count();
    let left_out = (shape.kept_fraction < 0.995).then(|| {
        format!(
            "; {:.0} % of the cells seen changed from pose to pose (obstacles' feet, bumps) and were left out",
            100.0 * (1.0 - shape.kept_fraction)
        )
    });
    // A warp not corrected: the ground looked warped, but not by a pattern
    // fixed in the image.
    let uncorrected = !shape_taken
        && taken_out.is_none()
        && part_taken.is_none()
        && shape.all_cells_rms_raw >= MIN_SHAPE_RMS_RAW
        && (shape.kept_fraction < 1.0 || !shape.consistent());
    let note = match (shape_taken || taken_out.is_some(), part_taken) {
        (false, None) if uncorrected && !shape.consistent() => {
            let why = match shape.why_not_fixed() {
                Some(crate::outcome::WarpCause::ChangesWithDepth { per_m, sigma }) => format!(
                    "it changes with the distance, {} by {:.0} ± {:.0} % a metre farther: a pattern that changes with depth, which a correction fixed in the image cannot take out",
                    if per_m > 0.0 { "weaker" } else { "stronger" },
                    100.0 * per_m.abs(),
                    100.0 * sigma
                ),
                Some(crate::outcome::WarpCause::GroundNotFlat { sigmas }) => format!(
                    "it stays with the ground as the poses move ({sigmas:.0} of noise's σ): the ground is not flat, not the sensor"
                ),
                Some(crate::outcome::WarpCause::CellsChange { left_out }) => format!(
                    "it changes from pose to pose in {:.0} % of the cells seen: obstacles or bumps in view",
                    100.0 * left_out
                ),
                Some(crate::outcome::WarpCause::BeyondTheFit { largest_raw, band_raw }) => {
                    // Two decimals where one would show them equal.
                    let decimals = if format!("{largest_raw:.1}") == format!("{band_raw:.1}") { 2 } else { 1 };
                    format!(
                        "it reaches {largest_raw:.decimals$} raw units from the ground's plane, beyond the fit's band of {band_raw:.decimals$}: the fit cut its peaks out, and whether it is the sensor's pattern or uneven ground cannot be told"
                    )
                }
                None => "it is not fixed in the image".to_string(),
            };
            let what = if matches!(
                shape.why_not_fixed(),
                Some(crate::outcome::WarpCause::BeyondTheFit { .. })
            ) {
                "cannot be taken for the sensor's fixed pattern"
            } else {
                "are not the sensor's fixed pattern"
            };
            format!(
                "not corrected: the ground's residuals ({:.3} raw units RMS) {what}: {why}",
                shape.all_cells_rms_raw
            )
        }
        (false, None) => format!(
            "none found: the ground's residuals show no fixed pattern beyond the noise (shape {words_rms:.3} raw units RMS over {seen_cells} cells{}), and the geometry across poses no offset or gradient of the depth",
            left_out.unwrap_or_default()
        ),
        (true, None) => "the shape corrected; its offset and gradients are not distinguishable from none by the geometry across poses".to_string(),
        (false, Some(_)) => "an offset or gradient of the depth over the image, found by the geometry across poses, corrected".to_string(),
        (true, Some(_)) => format!("the shape and its offset and gradients corrected{}", left_out.unwrap_or_default()),
    };
    DepthPattern {
        corrected,
        columns: shape.columns,
        rows: shape.rows,
        cell_px: CELL_PX,
        raw,
        sigma_raw,
        shape_rms_raw: words_rms,
        shape_chi2_per_dof: shape.shape_chi2 / shape.shape_dof.max(1.0),
        consistency_chi2_per_dof: shape.consistency_chi2 / shape.consistency_dof.max(1.0),
        shape_sigmas: shape.flips.sigmas(),
        changes_with_depth: shape
            .depth
            .sigma
            .is_finite()
            .then_some([shape.depth.per_m, shape.depth.sigma]),
        fixed_in_the_ground_sigmas: shape.fixed_in_the_ground.map(|t| t.sigmas()),
        uncorrected_because: if uncorrected {
            shape.why_not_fixed()
        } else {
            None
        },
        plane_part: plane_part.map(|p| p.value.into()),
        plane_part_sigma: plane_part
            .map(|p| [0, 1, 2].map(|i| p.covariance[(i, i)].max(0.0).sqrt())),
        plane_part_taken: part_taken.is_some(),
        uncorrected_shape_rms_raw: uncorrected.then_some(shape.all_cells_rms_raw),
        uncorrected_raw: uncorrected.then(|| {
            (0..shape.shape.len())
                .map(|k| shape.seen[k].then(|| shape.shape[k] * k_raw))
                .collect()
        }),
        uncorrected_fixed: false,
        raw_per_inverse_depth: k_raw,
        angle_sigma_known_plane_part: None,
        fit_again_about: fit_again_about(shape, shape_taken, taken_out.is_some()),
        note: Some(match taken_out {
            Some(_) => format!(
                "its first estimate taken out of the frames and the ground fitted again, since the first fit's band cut its peaks; then {note}"
            ),
            None => note,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::residuals::CellSums;

    /// Residuals of synthetic poses: a pattern plus a plane per pose over
    /// a varying ground region, no noise.
    fn synthetic(pattern: impl Fn(f64, f64) -> f64, poses: usize) -> Vec<GroundResiduals> {
        let intrinsics = Intrinsics::default();
        let columns = intrinsics.width.div_ceil(CELL_PX);
        let rows = intrinsics.height.div_ceil(CELL_PX);
        (0..poses)
            .map(|i| {
                let tilt = Vector3::new(
                    1e-3 * i as f64,
                    2e-6 * (i % 3) as f64,
                    -1e-6 * (i % 5) as f64,
                );
                let mut cells = vec![CellSums::default(); columns * rows];
                let (mut moments, mut rhs) = (Matrix3::zeros(), Vector3::zeros());
                // The ground covers rows from a height that changes with the pose.
                let top = 120 + 10 * (i % 7);
                for v in top..intrinsics.height {
                    for u in 0..intrinsics.width {
                        let (du, dv) = (u as f64 - intrinsics.cx, v as f64 - intrinsics.cy);
                        let r = pattern(du, dv) + tilt.dot(&Vector3::new(1.0, du, dv));
                        let cell = &mut cells[(v / CELL_PX) * columns + u / CELL_PX];
                        cell.n += 1.0;
                        cell.r += r;
                        cell.rr += r * r + 1e-12;
                        cell.u += du;
                        cell.v += dv;
                        let phi = Vector3::new(1.0, du, dv);
                        moments += phi * phi.transpose();
                        rhs += phi * r;
                    }
                }
                GroundResiduals {
                    columns,
                    rows,
                    cells,
                    moments,
                    rhs,
                    intrinsics,
                    raw_per_inverse_depth: -1.0 / 0.003,
                    fit_band: f64::INFINITY,
                    plane: PixelPlane {
                        c0: 0.5,
                        cu: 0.0,
                        cv: 0.0,
                    },
                    beside_another_fit: None,
                }
            })
            .collect()
    }

    #[test]
    fn the_truncated_mean_and_its_slope() {
        // Φ against tabulated values.
        for (x, phi) in [
            (0.0, 0.5),
            (1.0, 0.841_344_746),
            (-1.96, 0.024_997_895),
            (3.0, 0.998_650_102),
        ] {
            assert!((normal(x).1 - phi).abs() < 2e-7, "Φ({x}) = {}", normal(x).1);
        }
        // No pattern, no bend; the mean within ±2σ of a reading lifted by
        // a σ is 0.60 of it (times the share kept).
        assert_eq!(truncated_mean(0.0, 2.0).0, 0.0);
        let (g, _) = truncated_mean(1.0, 2.0);
        assert!((g - 0.602_456).abs() < 1e-5, "{g}");
        // The slope by differences (Φ's approximation, within 1.5·10⁻⁷,
        // differs in its slope from φ by up to 2·10⁻⁶: a Newton step a
        // millionth off, which the next step takes out).
        for m in [-1.5, -0.3, 0.0, 0.7, 2.0] {
            let h = 1e-5;
            let numeric = (truncated_mean(m + h, 2.2).0 - truncated_mean(m - h, 2.2).0) / (2.0 * h);
            let slope = truncated_mean(m, 2.2).1;
            assert!(
                (numeric - slope).abs() < 3e-6,
                "{m}: {numeric} against {slope}"
            );
        }
    }

    #[test]
    fn the_correction_is_the_cells_at_their_centres_and_linear_between() {
        let cells: Vec<Option<f64>> = (0..12).map(|k| Some(k as f64)).collect();
        let correction = DepthCorrection::from_cells(4, 3, 8, &cells).expect("a grid");
        // Centres at 3.5, 11.5, 19.5, 27.5 (columns) and 3.5, 11.5, 19.5 (rows).
        assert_eq!(correction.raw_at(3.5, 3.5), 0.0);
        assert_eq!(correction.raw_at(11.5, 11.5), 5.0);
        assert!((correction.raw_at(7.5, 3.5) - 0.5).abs() < 1e-12);
        assert!((correction.raw_at(11.5, 7.5) - 3.0).abs() < 1e-12);
        // Held at the border.
        assert_eq!(correction.raw_at(0.0, 0.0), 0.0);
        assert_eq!(correction.raw_at(31.0, 23.0), 11.0);
        assert!(DepthCorrection::from_cells(4, 3, 8, &cells[..11]).is_none());
        assert_eq!(
            DepthCorrection::from_cells(4, 3, 8, &[None; 12]).map(|c| c.raw_at(9.0, 9.0)),
            Some(0.0)
        );
    }

    #[test]
    fn a_shape_is_recovered_without_its_plane_part() {
        let bowl = |du: f64, dv: f64| 1e-3 * ((du / 320.0).powi(2) + (dv / 240.0).powi(2));
        let poses = synthetic(bowl, 12);
        let refs: Vec<&GroundResiduals> = poses.iter().collect();
        let estimate = estimate_shape(&refs).expect("an estimate");
        // The truth without its plane part over the cells seen.
        let mut truth: Vec<f64> = (0..estimate.shape.len())
            .map(|k| {
                let (du, dv) = estimate.cell_offset(k);
                bowl(du, dv)
            })
            .collect();
        remove_plane_part(&mut truth, &estimate.readings, &estimate.seen, refs[0]);
        let worst = (0..truth.len())
            .filter(|&k| estimate.seen[k])
            .map(|k| (truth[k] - estimate.shape[k]).abs())
            .fold(0.0, f64::max);
        // Within the bowl's own variation inside a cell (about 1 %).
        assert!(
            worst < 2e-5,
            "{worst} after {} iterations",
            estimate.iterations
        );
    }

    /// The mount's σ with a plane part taken holds when the poses' noise
    /// differs: a plane fitted to far ground is noisier than one fitted to
    /// near ground (here σ grows with the square of the depth at the
    /// image's centre, 1–9 times), where the plane part's covariance took
    /// every pose as noisy as the average. A seeded 60-pose grid of
    /// heights, pitches and rolls, exact planes moved by a plane part
    /// (−0.13 raw units and gradients, what a radial bowl leaves), noise
    /// drawn per pose; the errors of the plane part and of the six
    /// parameters against their σ over 100 draws. Before the plane part's
    /// covariance came from the poses' own residuals: 1.24, 1.22 and 1.45σ
    /// RMS for the plane part, 1.28 and 1.30σ for α and β; now 0.97–1.10
    /// and at most 1.14.
    #[test]
    fn the_mounts_sigma_with_a_plane_part_holds_when_the_poses_noise_differs() {
        use crate::geometry::{ground_in_sensor, PoseDegMm};
        use crate::test_noise::gaussian;
        use rand::SeedableRng;
        use std::sync::Arc;

        let mount = PoseDegMm::from_values([0.8, -33.0, 1.5, 510.0, 370.0, 15.0]).to_params();
        let residuals: Vec<Arc<GroundResiduals>> = synthetic(|_, _| 0.0, 12)
            .into_iter()
            .map(Arc::new)
            .collect();
        let intrinsics = residuals[0].intrinsics;
        let truth_part = [-0.13, 0.003, 0.013];
        let part = plane_part_inverse_depth(
            &PlanePart::from(truth_part),
            residuals[0].raw_per_inverse_depth,
        );
        let mut bodies = Vec::new();
        for height in [530.0, 650.0, 770.0] {
            for beta in [-22.5, -11.3, 0.0, 11.3] {
                for gamma in [-22.5, -11.3, 0.0, 11.3, 22.5] {
                    bodies.push(PoseDegMm::from_values([0.0, beta, gamma, 0.0, height, 0.0]));
                }
            }
        }
        let nearest = bodies
            .iter()
            .map(|body| {
                let plane =
                    ground_in_sensor(&(body.to_params().to_transform() * mount.to_transform()));
                -plane.d / plane.normal.x
            })
            .fold(f64::INFINITY, f64::min);
        let mut squares = [0.0; 6];
        let mut part_squares = [0.0; 3];
        let draws = 100;
        for seed in 0..draws {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let observations: Vec<Observation> = bodies
                .iter()
                .enumerate()
                .map(|(i, body)| {
                    let ground_from_robot = body.to_params().to_transform();
                    let exact = ground_in_sensor(&(ground_from_robot * mount.to_transform()));
                    let mut observation = Observation::new(i as u32 + 1, ground_from_robot, exact);
                    observation = moved(&observation, &part, &intrinsics);
                    // The depth at the image's centre, along the optical axis.
                    let depth = -observation.plane.d / observation.plane.normal.x;
                    let noise = (depth / nearest).powi(2);
                    let (e1, e2) = solve::tangent_basis(&observation.plane.normal);
                    let tilt = (e1 * gaussian(&mut rng) + e2 * gaussian(&mut rng))
                        * 0.0005f64.to_radians()
                        * noise;
                    let plane = &mut observation.plane;
                    plane.normal = (plane.normal + tilt).normalize();
                    plane.d += 0.005e-3 * noise * gaussian(&mut rng);
                    observation.ground_residuals = Some(residuals[i % residuals.len()].clone());
                    observation
                })
                .collect();
            let solution =
                solve_with_pattern(&observations, &SolveSettings::default()).expect("a solution");
            let pattern = solution.depth_pattern.as_ref().expect("a pattern");
            assert!(
                pattern.plane_part_taken,
                "draw {seed}: the plane part not taken: {:?} ± {:?}",
                pattern.plane_part, pattern.plane_part_sigma
            );
            let error = solution.robot_from_sensor.to_vector() - mount.to_vector();
            for (k, square) in squares.iter_mut().enumerate() {
                *square += error[k].powi(2) / solution.covariance[(k, k)];
            }
            let (found, sigma) = (
                pattern.plane_part.unwrap(),
                pattern.plane_part_sigma.unwrap(),
            );
            for (k, square) in part_squares.iter_mut().enumerate() {
                *square += ((found[k] - truth_part[k]) / sigma[k]).powi(2);
            }
        }
        let rms = |squares: &[f64]| -> Vec<f64> {
            squares.iter().map(|s| (s / draws as f64).sqrt()).collect()
        };
        let (part, mount) = (rms(&part_squares), rms(&squares));
        eprintln!(
            "errors in their σ, RMS over {draws} draws: plane part {part:.2?}, mount {mount:.2?}"
        );
        let names = ["offset", "gradient along u", "gradient along v"];
        for (name, z) in names.iter().zip(&part) {
            assert!(*z < 1.2, "the plane part's {name}: errors of {z:.2}σ RMS");
        }
        for (name, z) in ["α", "β", "γ", "x", "y", "z"].iter().zip(&mount) {
            assert!(*z < 1.25, "{name}: errors of {z:.2}σ RMS");
        }
    }
}

#[cfg(test)]
mod bend_on_frames {
    use super::*;
    use crate::depth::{DepthEncoding, DepthModel, DepthRange, RAW_NO_READING};
    use crate::disparity::InverseDepthImage;
    use crate::geometry::Plane;
    use crate::plane::{fit_ground, FitBuffers, GroundPrior, PlaneFitSettings};
    use crate::sensor::DepthCamera;
    use crate::test_noise::gaussian;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// How a reading past the range (0.5–5 m) is lost.
    enum Lost {
        /// By the true depth: the range never cuts the noise.
        ByTheTruth,
        /// By the reading, noise and pattern included, as a Kinect loses
        /// what it cannot range.
        ByTheReading,
    }

    /// The real fit of two raw frames of flat ground `truth` carrying
    /// `pattern` (raw units at pixel `(u, v)`), with the simulator's noise
    /// in disparity (0.456 raw units) and whole raw units, and its
    /// residuals.
    fn fitted(
        truth: &Plane,
        prior: &GroundPrior,
        seed: u64,
        pattern: impl Fn(f64, f64) -> f64,
        lost: Lost,
    ) -> (crate::plane::GroundFit, GroundResiduals) {
        let i = Intrinsics::default();
        let model = DepthModel::inverse_linear_default();
        let camera = DepthCamera::new(DepthEncoding::Raw11(model), i, DepthRange::default());
        let (a, b) = model.inverse_depth_affine();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let frames: Vec<Vec<u16>> = (0..2)
            .map(|_| {
                let mut raw = vec![RAW_NO_READING; i.width * i.height];
                for v in 0..i.height {
                    for u in 0..i.width {
                        let ray =
                            Vector3::new(1.0, -(v as f64 - i.cy) / i.fy, (u as f64 - i.cx) / i.fx);
                        let z = -truth.d / truth.normal.dot(&ray);
                        if matches!(lost, Lost::ByTheTruth) && !(0.5..5.0).contains(&z) {
                            continue;
                        }
                        let w = 1.0 / z
                            + 0.456 * b.abs() * gaussian(&mut rng)
                            + b * pattern(u as f64, v as f64);
                        if matches!(lost, Lost::ByTheReading)
                            && (z <= 0.0 || !(0.5..5.0).contains(&(1.0 / w)))
                        {
                            continue;
                        }
                        raw[v * i.width + u] = ((w - a) / b).round().clamp(0.0, 2046.0) as u16;
                    }
                }
                raw
            })
            .collect();
        let frames: Vec<&[u16]> = frames.iter().map(|f| &f[..]).collect();
        let fit = fit_ground(
            &frames,
            &camera,
            prior,
            &PlaneFitSettings::default(),
            &mut FitBuffers::default(),
        )
        .unwrap();
        let residuals =
            GroundResiduals::of(&frames, &camera, &fit, &mut InverseDepthImage::default()).unwrap();
        (fit, residuals)
    }

    /// The residuals are summed over the pixels the fit read, chosen by
    /// the plane, never by the reading. Where the range's far end (5 m)
    /// crosses the ground, a Kinect loses the readings its noise puts past
    /// it; the fit keeps its band clear of that end, and the residuals must
    /// too. Chosen by the reading (before), the rows of cells at the far
    /// end kept readings the fit had not taken, cut on one side, and their
    /// mean residual was biased (here 6.5σ of a row's mean); on a
    /// designed schedule the bends taken from such residuals put the pitch
    /// 0.0035° off.
    #[test]
    fn the_residuals_near_the_ranges_end_are_the_fits_own() {
        // The sensor 1.2 m up, looking 15° down: the far end of the range
        // runs across the middle of the image.
        let truth = Plane::from_coefficients(-0.26, 0.97, 0.03, 1.2).unwrap();
        let prior = GroundPrior {
            up: truth.normal,
            up_tolerance: 15f64.to_radians(),
            height: Some((1.2, 0.3)),
        };
        let (_, residuals) = fitted(&truth, &prior, 3, |_, _| 0.0, Lost::ByTheReading);
        let sigma = reading_variance(&[&residuals]).sqrt();
        // Each row of cells: its mean residual against the σ of that mean.
        let mut worst: (f64, usize) = (0.0, 0);
        let mut rows_seen = 0;
        for row in 0..residuals.rows {
            let cells = &residuals.cells[row * residuals.columns..(row + 1) * residuals.columns];
            let (n, r): (f64, f64) = cells
                .iter()
                .fold((0.0, 0.0), |(n, r), c| (n + c.n, r + c.r));
            if n < 1000.0 {
                continue;
            }
            rows_seen += 1;
            let z = (r / n) / (sigma / n.sqrt());
            if z.abs() > worst.0.abs() {
                worst = (z, row);
            }
        }
        eprintln!("worst row of cells: {worst:?} (σ of its mean, row)");
        assert!(rows_seen > 20, "{rows_seen} rows of cells with readings");
        assert!(
            worst.0.abs() < 5.0,
            "row {} of cells: mean residual {:.1}σ of its mean",
            worst.1,
            worst.0
        );
    }

    /// The bend predicted from the residuals is the one the fit itself
    /// takes: two raw frames of a flat ground 0.9 m away carrying a bowl of
    /// ±1.5 raw units (three times issue 23's), with the Kinect's noise and
    /// rounding, are fitted by the real fit; its plane less the true one
    /// and the bowl's plane part is the bend. Measured: −0.0406 raw units
    /// of offset, predicted −0.0391, where the untruncated bend is 10⁻⁹.
    #[test]
    fn the_bend_predicted_is_the_fits_own() {
        let i = Intrinsics::default();
        let model = DepthModel::inverse_linear_default();
        let (_, b) = model.inverse_depth_affine();
        let bowl = |u: f64, v: f64| {
            let rho = (u - i.cx).hypot(v - i.cy) / i.cx.hypot(i.cy);
            1.5 * (2.0 * rho * rho - 1.0)
        };
        let truth = Plane::from_coefficients(-0.6, 0.8, 0.05, 0.9).unwrap();
        let prior = GroundPrior {
            up: Vector3::new(-0.55, 0.83, 0.0).normalize(),
            up_tolerance: 15f64.to_radians(),
            height: Some((0.9, 0.3)),
        };
        let (fit, residuals) = fitted(&truth, &prior, 1, bowl, Lost::ByTheTruth);

        // The bowl per cell (1/m), less its plane part over the cells seen.
        let cells = residuals.cells.len();
        let centre = |k: usize| {
            let (column, row) = (k % residuals.columns, k / residuals.columns);
            let half = (CELL_PX as f64 - 1.0) / 2.0;
            (
                (column * CELL_PX) as f64 + half,
                (row * CELL_PX) as f64 + half,
            )
        };
        let seen: Vec<bool> = residuals.cells.iter().map(|c| c.n > 0.0).collect();
        let readings: Vec<f64> = residuals.cells.iter().map(|c| c.n).collect();
        let mut shape: Vec<f64> = (0..cells)
            .map(|k| {
                let (u0, v0) = centre(k);
                let mut sum = 0.0;
                for dv in 0..CELL_PX {
                    for du in 0..CELL_PX {
                        let half = (CELL_PX as f64 - 1.0) / 2.0;
                        sum += bowl(u0 - half + du as f64, v0 - half + dv as f64);
                    }
                }
                b * sum / (CELL_PX * CELL_PX) as f64
            })
            .collect();
        let whole = shape.clone();
        remove_plane_part(&mut shape, &readings, &seen, &residuals);
        let (mut moments, mut sums) = (Matrix3::zeros(), Vector3::zeros());
        for k in (0..cells).filter(|&k| seen[k]) {
            let (u, v) = centre(k);
            let phi = Vector3::new(1.0, u - i.cx, v - i.cy);
            moments += phi * phi.transpose() * readings[k];
            sums += phi * ((whole[k] - shape[k]) * readings[k]);
        }
        let plane_part = moments.try_inverse().unwrap() * sums;

        let (fitted, true_plane) = (
            PixelPlane::from_plane(&fit.plane, &i),
            PixelPlane::from_plane(&truth, &i),
        );
        let taken = Vector3::new(
            fitted.c0 - true_plane.c0,
            fitted.cu - true_plane.cu,
            fitted.cv - true_plane.cv,
        ) - plane_part;
        let sigma = reading_variance(&[&residuals]).sqrt();
        let predicted = bend(&residuals, &shape, &seen, sigma);
        let untruncated = bend(
            &GroundResiduals {
                fit_band: f64::INFINITY,
                beside_another_fit: None,
                ..residuals.clone()
            },
            &shape,
            &seen,
            sigma,
        );
        let (taken, predicted, untruncated) = (taken.x / b, predicted.x / b, untruncated.x / b);
        eprintln!("offset bend: taken {taken}, predicted {predicted}, untruncated {untruncated} raw units");
        assert!(taken < -0.03, "the fit's offset bend: {taken} raw units");
        assert!(
            (predicted - taken).abs() < 0.1 * taken.abs(),
            "predicted {predicted}, taken {taken} raw units"
        );
        assert!(untruncated.abs() < 0.1 * taken.abs(), "{untruncated}");
    }
}
