//! The pattern's shape from the poses' residual sums: the cells' pattern and
//! each pose's plane correction by alternating least squares, the cells kept,
//! the noise of a cell from the poses' own scatter, and the tests of the
//! shape against none and against its alternatives ([`super::alternatives`]).

use super::cell_set::CellSet;
use super::*;

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
    /// The shape's size against the sizes the poses make with their signs
    /// flipped ([`crate::cell_noise::flip_test`]).
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
        // The ground fit read the cells the estimate does not hold as well:
        // their pattern as their neighbours have it (as a correction is
        // taken out of the frames), not none. Taken as none, a quadruped
        // camera's bowl, largest in the corners few poses see, put the
        // mount 0.021° and 0.38 mm off (8σ).
        let around = extended(&self.shape, &self.seen, self.columns, self.rows);
        let every = vec![true; around.len()];
        poses
            .par_iter()
            .map(|pose| -bend(pose, &around, &every, sigma))
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

    /// Why not, for a first estimate (a relief may stand beside it; its
    /// peaks must lie within the fit's band) or for what a first estimate
    /// left (neither).
    fn why_not_fixed_beside_relief(
        &self,
        first_estimate: bool,
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
        let ground =
            stays_with_the_ground.filter(|_| !(first_estimate && self.stands_beside_the_relief()));
        let depth = self
            .depth
            .significant()
            .then(|| (self.depth.per_m / self.depth.sigma).abs());
        let (largest_raw, band_raw) = (self.largest_raw(), self.fit_band_raw);
        // A shape whose peaks the fit cut is not corrected when any test
        // finds residuals it does not explain, even beside the relief: the
        // correction is then biased (a real Kinect's pattern of 0.8 raw
        // units RMS, corrected beside the relief, put the mount 0.28-0.98
        // mm off on four seeds, and one of 0.56 mm was accepted). A first
        // estimate whose peaks the fit cut is not corrected at all: the
        // ground is fitted again about it instead (`fit_again_about`), and
        // only what that finds is corrected. The cut's own model (the
        // bend) holds for white noise only: the measured pattern under
        // white noise, 8 frames a pose, was corrected through it and
        // accepted 0.078° and 0.87 mm off, 7σ, when the fits about it
        // failed.
        if (first_estimate || stays_with_the_ground.is_some() || depth.is_some())
            && self.peaks_cut_by_the_fit()
        {
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
    pub(super) fn cell_offset(&self, k: usize) -> (f64, f64) {
        cell_centre(k, self.columns, &self.intrinsics)
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
            .any(|p| p.cell_count() != first.cell_count() || p.columns != first.columns)
    {
        return None;
    }
    let cells = first.cell_count();
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
        let Some(next) = kept.within(poses, &fitted, &noise, &seen_at_first) else {
            break;
        };
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
        kept.leave_out(poses, &lone);
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
    let plane_part = PlanePartRemover::new(&kept.readings, &seen, &kept.centres);
    let shape_of = |per_cell: &[f64]| shape_from_sums(per_cell, &weights, &plane_part);
    let shape_of_sums = ShapeOfSums {
        weights: &weights,
        plane: plane_part.plane_removed(),
    };
    // The test that there is a shape beside the tests of its alternatives
    // (the pattern's change with depth, and residuals that stay with the
    // ground): each reads the entries only, and the ground's tests, which
    // wait for the depth's, run while the shape's flips do (after them,
    // they were 11 ms of a 95-ms replay on one core).
    let ground_from_sensor = ground_from_sensor.filter(|g| g.len() == poses.len());
    let (flips, (depth, ground_tests)) = rayon::join(
        || flip_test(&sums, poses.len(), shape_of_sums),
        || {
            let (depth, ground_bins) = rayon::join(
                || depth_dependence(poses, &sums, shape, &noise),
                || ground_from_sensor.map(|g| ground_bins(poses, &sums, g)),
            );
            // Residuals that stay with the ground are looked for beyond
            // what a pattern changing with depth would leave: each
            // alternative is asked what the other does not explain.
            let ground_tests = ground_bins.map(|(bins, bin_of)| {
                // The entries less the change with depth are the same
                // entries, in order, with other residuals: their bins are
                // the same.
                let beyond_depth = depth
                    .significant()
                    .then(|| without_depth_dependence(poses, &sums, shape))
                    .flatten();
                let test = match beyond_depth {
                    Some(residuals) => {
                        let less = WithResiduals {
                            entries: &sums,
                            residuals,
                        };
                        ground_fixed(poses.len(), &less, bins, &bin_of)
                    }
                    None => ground_fixed(poses.len(), &sums, bins, &bin_of),
                };
                // Only asked when the ground's test finds something.
                let beside = (test.sigmas() > ALTERNATIVE_SIGMAS).then(|| {
                    shape_beside_relief(&sums, &bin_of, poses.len(), shape_of_sums, shape_of)
                });
                (test, beside)
            });
            (depth, ground_tests)
        },
    );
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

/// `shape` where `seen`, and elsewhere its neighbours' values ring by ring
/// outwards (`found::extend_to_unseen_cells`); 0 when nothing is seen.
pub(super) fn extended(shape: &[f64], seen: &[bool], columns: usize, rows: usize) -> Vec<f64> {
    let mut cells: Vec<Option<f64>> = shape
        .iter()
        .zip(seen)
        .map(|(v, s)| s.then_some(*v))
        .collect();
    super::found::extend_to_unseen_cells(&mut cells, columns, rows);
    cells.into_iter().map(|c| c.unwrap_or(0.0)).collect()
}

/// The median of the poses' ground-fit bands, 1/m (infinite when no pose
/// says: the residuals of a test, not of a fit).
pub(super) fn median_fit_band(poses: &[&GroundResiduals]) -> f64 {
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
pub(super) const LONE_CELL_RAW: f64 = 0.15;

/// The cells seen that lie far from those above and below them.
pub(super) fn lone_cells(
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
pub(super) const ENTRY_SIGMAS: f64 = 4.5;

/// Which cells' sums, pose by pose, enter the estimate.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Kept {
    /// Cells per row of the image.
    pub(super) columns: usize,
    /// Per pose: the cells whose sums are left out.
    pub(super) out: Vec<CellSet>,
    /// Per cell: readings of the sums kept.
    pub(super) readings: Vec<f64>,
    /// Per cell: whether it enters the estimate (enough readings kept,
    /// from two poses at least).
    pub(super) seen: Vec<bool>,
    /// Per pose: the inverse of Σφφᵀ and Σr·φ over the readings of the
    /// sums it takes.
    pub(super) inverse_moments: Vec<Matrix3<f64>>,
    pub(super) rhs: Vec<Vector3<f64>>,
    /// Per pose: the cells whose sums are taken (the loops' work list).
    pub(super) taken: Vec<CellSet>,
    /// Per cell: its centre (pixels from the principal point), for its
    /// sums at every pose.
    pub(super) centres: Vec<(f64, f64)>,
}

impl Kept {
    /// Every sum.
    pub(super) fn all(poses: &[&GroundResiduals]) -> Self {
        let cells = poses[0].cell_count();
        Self::from_out(poses, vec![CellSet::empty(cells); poses.len()], None)
    }

    /// The sums within [`ENTRY_SIGMAS`] of `fitted`, among the cells first
    /// seen; none when they are the sums these keep (the usual end, which
    /// then costs no pass over the poses' moments).
    fn within(
        &self,
        poses: &[&GroundResiduals],
        fitted: &Fitted,
        noise: &CellNoise,
        first_seen: &[bool],
    ) -> Option<Self> {
        let cells = first_seen.len();
        // |z| > ENTRY_SIGMAS with z = (r − model)/n·√w, squared: no square
        // root or division an entry (they were half of this pass).
        let weights = noise.weights();
        let limit = ENTRY_SIGMAS * ENTRY_SIGMAS;
        let out: Vec<CellSet> = poses
            .par_iter()
            .zip(&fitted.planes)
            .map(|(pose, c)| {
                let mut out = CellSet::empty(cells);
                for (k, cell) in pose.cells().enumerate() {
                    if first_seen[k] && cell.n > 0.0 {
                        let model =
                            fitted.shape[k] * cell.n + c.x * cell.n + c.y * cell.u + c.z * cell.v;
                        let off = cell.r - model;
                        if off * off * weights.of(cell.n) > limit * cell.n * cell.n {
                            out.insert(k);
                        }
                    }
                }
                out
            })
            .collect();
        if out == self.out {
            return None;
        }
        Some(Self::from_out(poses, out, Some(first_seen)))
    }

    fn from_out(poses: &[&GroundResiduals], out: Vec<CellSet>, among: Option<&[bool]>) -> Self {
        let cells = poses[0].cell_count();
        // A block of cells on each core, each cell's poses in their order.
        let mut readings = vec![0.0; cells];
        let mut poses_seen = vec![0usize; cells];
        readings
            .par_chunks_mut(CELL_BLOCK)
            .zip(poses_seen.par_chunks_mut(CELL_BLOCK))
            .enumerate()
            .for_each(|(block, (readings, poses_seen))| {
                let first = block * CELL_BLOCK;
                for (pose, out) in poses.iter().zip(&out) {
                    for (j, (sum, seen_by)) in
                        readings.iter_mut().zip(poses_seen.iter_mut()).enumerate()
                    {
                        let n = pose.readings(first + j);
                        if n > 0.0 && !out.contains(first + j) {
                            *sum += n;
                            *seen_by += 1;
                        }
                    }
                }
            });
        let seen: Vec<bool> = (0..cells)
            .map(|k| {
                among.is_none_or(|a| a[k]) && readings[k] >= MIN_CELL_READINGS && poses_seen[k] >= 2
            })
            .collect();
        let mut kept = Self {
            columns: poses[0].columns,
            out,
            readings,
            seen,
            inverse_moments: Vec::new(),
            rhs: Vec::new(),
            taken: Vec::new(),
            centres: poses[0].centres(),
        };
        kept.take_what_is_seen(poses);
        kept
    }

    /// Each pose's work list, and its moments over exactly those sums: its
    /// readings less those of every sum not taken (left out, or of a cell
    /// not seen), their spread about the cell's centre taken as uniform. A
    /// sum the pattern's estimate does not hold must not pull the pose's
    /// plane either: its share of the pattern, unsubtracted, would tilt
    /// the plane, the same way at every pose that sees it.
    fn take_what_is_seen(&mut self, poses: &[&GroundResiduals]) {
        let cells = self.seen.len();
        let spread = ((CELL_PX * CELL_PX) as f64 - 1.0) / 12.0;
        let (seen, out) = (&self.seen, &self.out);
        let per_pose: Vec<(CellSet, Matrix3<f64>, Vector3<f64>)> = poses
            .par_iter()
            .zip(out)
            .map(|(pose, out)| {
                let (mut moments, mut sums) = (pose.moments, pose.rhs);
                let mut taken = CellSet::empty(cells);
                for (k, _) in pose.each_readings().enumerate().filter(|(_, n)| *n > 0.0) {
                    if seen[k] && !out.contains(k) {
                        taken.insert(k);
                        continue;
                    }
                    let cell = pose.cell(k);
                    let centre = Vector3::new(1.0, cell.u / cell.n, cell.v / cell.n);
                    moments -= (centre * centre.transpose()
                        + Matrix3::from_diagonal(&Vector3::new(0.0, spread, spread)))
                        * cell.n;
                    sums -= centre * cell.r;
                }
                let inverse = moments.try_inverse().unwrap_or_else(Matrix3::zeros);
                (taken, inverse, sums)
            })
            .collect();
        self.taken = Vec::with_capacity(per_pose.len());
        self.inverse_moments = Vec::with_capacity(per_pose.len());
        self.rhs = Vec::with_capacity(per_pose.len());
        for (taken, inverse, rhs) in per_pose {
            self.taken.push(taken);
            self.inverse_moments.push(inverse);
            self.rhs.push(rhs);
        }
    }

    /// Leaves these cells out of the estimate altogether.
    fn leave_out(&mut self, poses: &[&GroundResiduals], cells: &[usize]) {
        for &k in cells {
            self.seen[k] = false;
        }
        self.take_what_is_seen(poses);
    }
}

/// The pattern over the cells seen and each pose's plane given it.
pub(super) struct Fitted {
    /// Per cell, 1/m, without a plane part over the cells seen.
    pub(super) shape: Vec<f64>,
    /// Per pose: the plane (1/m on `c0, cu, cv`) that fits its residuals
    /// less the pattern.
    pub(super) planes: Vec<Vector3<f64>>,
    pub(super) iterations: usize,
}

/// Cells a worker takes at a time in the pattern's step.
pub(super) const CELL_BLOCK: usize = 512;

/// Alternating least squares of the pattern and the planes over the sums
/// kept, until the pattern moves by less than 10⁻⁴ raw units.
pub(super) fn alternate(poses: &[&GroundResiduals], kept: &Kept, start: Option<&[f64]>) -> Fitted {
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
    let plane_part = PlanePartRemover::new(&kept.readings, &kept.seen, &kept.centres);
    let centres = &kept.centres;
    let mut iterations = 0;
    for _ in 0..2000 {
        iterations += 1;
        // Each pose's plane given the pattern.
        planes.par_iter_mut().enumerate().for_each(|(i, plane)| {
            let mut rhs = kept.rhs[i];
            kept.taken[i].for_each_in(0..cells, |k| {
                let cell = poses[i].cell_centred(k, centres[k]);
                rhs -= Vector3::new(cell.n, cell.u, cell.v) * shape[k];
            });
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
                    kept.taken[i].for_each_in(first..end, |k| {
                        let cell = pose.cell_centred(k, centres[k]);
                        next[k - first] += cell.r - (c.x * cell.n + c.y * cell.u + c.z * cell.v);
                    });
                }
            });
        for ((value, seen), readings) in next.iter_mut().zip(&kept.seen).zip(&kept.readings) {
            if *seen {
                *value /= readings;
            }
        }
        // No plane part: that is the planes' (and the geometry's) to say.
        plane_part.remove(&mut next);
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
pub(super) fn reading_variance(poses: &[&GroundResiduals]) -> f64 {
    let (mut within, mut within_dof) = (0.0, 0.0);
    for pose in poses {
        let (scatter, dof) = pose.reading_scatter();
        within += scatter;
        within_dof += dof;
    }
    if within_dof > 0.0 {
        (within / within_dof).max(f64::MIN_POSITIVE)
    } else {
        f64::INFINITY
    }
}

/// The sums kept, each as its cell's mean residual about pattern and plane
/// and about the plane alone.
pub(super) fn entries<'a>(
    poses: &'a [&'a GroundResiduals],
    kept: &'a Kept,
    fitted: &'a Fitted,
) -> KeptEntries<'a> {
    let mut each = Vec::with_capacity(kept.taken.iter().map(CellSet::len).sum());
    each.extend(entries_of(poses, kept, fitted).map(|e| (e.cell, e.about_plane as f32)));
    let mut pose_ends = Vec::with_capacity(poses.len());
    let mut end = 0;
    for taken in &kept.taken {
        end += taken.len();
        pose_ends.push(end);
    }
    KeptEntries {
        poses,
        shape: &fitted.shape,
        pose_ends,
        each,
    }
}

/// The sums kept as the estimate's entries, made as they are read: each
/// entry's cell and its mean about its pose's plane (in f32), in order,
/// pose by pose; its readings from the pose's cell, its residual about the
/// pattern that mean less the pattern's cell. 8 bytes an entry, where
/// whole entries were 32 (6 MB for 52 poses at the estimate's peak); the
/// cells are kept beside the means, not walked from the poses' work lists
/// (bits: 0.76 MB less, but walked a cell at a time by the flip tests and
/// the relief's turns, some thirty times over the entries, they took 9 %
/// more instructions of a 156-frame replay).
pub(super) struct KeptEntries<'a> {
    poses: &'a [&'a GroundResiduals],
    shape: &'a [f64],
    /// Per pose, the end of its entries in `each`.
    pose_ends: Vec<usize>,
    /// Each entry's cell and mean about its pose's plane.
    each: Vec<(u32, f32)>,
}

impl Entries for KeptEntries<'_> {
    fn count(&self) -> usize {
        self.each.len()
    }

    fn each(&self) -> impl Iterator<Item = Entry> + '_ {
        EachKeptEntry {
            entries: self,
            pose: 0,
            pose_end: self.pose_ends.first().copied().unwrap_or(0),
            index: 0,
        }
    }

    /// Pose by pose, the entries of the cells in `cells` only: a pose's
    /// cells ascend, so each pose's are found by bisection.
    fn each_indexed_among(
        &self,
        cells: std::ops::Range<u32>,
    ) -> impl Iterator<Item = (usize, Entry)> + '_ {
        (0..self.pose_ends.len()).flat_map(move |pose| {
            let start = pose.checked_sub(1).map_or(0, |p| self.pose_ends[p]);
            let of_pose = &self.each[start..self.pose_ends[pose]];
            let from = start + of_pose.partition_point(|(cell, _)| *cell < cells.start);
            let to = start + of_pose.partition_point(|(cell, _)| *cell < cells.end);
            (from..to).map(move |index| (index, self.entry(pose, index)))
        })
    }

    /// The poses walked alongside the indices: an index's pose is the one
    /// whose entries end past it.
    fn each_at<'s>(
        &'s self,
        indices: impl Iterator<Item = usize> + 's,
    ) -> impl Iterator<Item = (usize, Entry)> + 's {
        let mut pose = 0;
        indices
            .take_while(|&index| index < self.each.len())
            .map(move |index| {
                // Ascending: the pose only moves on, and the last pose's
                // end is the count, past every index taken.
                while index >= self.pose_ends[pose] {
                    pose += 1;
                }
                (index, self.entry(pose, index))
            })
    }
}

impl KeptEntries<'_> {
    /// The entries of pose `pose`, in order.
    pub(super) fn each_of_pose(&self, pose: usize) -> impl Iterator<Item = Entry> + '_ {
        let start = pose.checked_sub(1).map_or(0, |p| self.pose_ends[p]);
        (start..self.pose_ends[pose]).map(move |index| self.entry(pose, index))
    }

    /// Entry `index`, of pose `pose`.
    #[inline]
    fn entry(&self, pose: usize, index: usize) -> Entry {
        let (cell, about_plane) = self.each[index];
        let about_plane = f64::from(about_plane);
        Entry {
            pose: pose as u32,
            cell,
            n: self.poses[pose].readings(cell as usize),
            residual: about_plane - self.shape[cell as usize],
            about_plane,
        }
    }
}

/// [`KeptEntries::each`]: the entry the walk is at, and its pose's end.
struct EachKeptEntry<'a> {
    entries: &'a KeptEntries<'a>,
    pose: usize,
    pose_end: usize,
    index: usize,
}

impl Iterator for EachKeptEntry<'_> {
    type Item = Entry;

    #[inline]
    fn next(&mut self) -> Option<Entry> {
        let entries = self.entries;
        if self.index >= entries.each.len() {
            return None;
        }
        // Past its pose's end (a pose may take no cell): the next pose.
        while self.index == self.pose_end {
            self.pose += 1;
            self.pose_end = entries.pose_ends[self.pose];
        }
        self.index += 1;
        Some(entries.entry(self.pose, self.index - 1))
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let left = self.entries.each.len() - self.index;
        (left, Some(left))
    }
}

/// [`entries`] as they are made, in the same order: pose by pose, the
/// cells it takes (those with readings, seen and not left out) in order.
pub(super) fn entries_of<'a>(
    poses: &'a [&GroundResiduals],
    kept: &'a Kept,
    fitted: &'a Fitted,
) -> impl Iterator<Item = Entry> + 'a {
    (0..poses.len()).flat_map(move |i| entries_of_pose(poses, kept, fitted, i))
}

/// Pose `i`'s share of [`entries_of`].
fn entries_of_pose<'a>(
    poses: &'a [&GroundResiduals],
    kept: &'a Kept,
    fitted: &'a Fitted,
    i: usize,
) -> impl Iterator<Item = Entry> + 'a {
    let (pose, c) = (poses[i], fitted.planes[i]);
    kept.taken[i].iter().map(move |k| {
        let cell = pose.cell_centred(k, kept.centres[k]);
        let plane = c.x * cell.n + c.y * cell.u + c.z * cell.v;
        let about_plane = (cell.r - plane) / cell.n;
        Entry {
            pose: i as u32,
            cell: k as u32,
            n: cell.n,
            residual: about_plane - fitted.shape[k],
            about_plane,
        }
    })
}

/// The noise of a cell's mean, from the sums kept about pattern and plane:
/// each pose's scatter on every core, added in the poses' order (the same
/// number for any count of threads; one pass after the other, it was a
/// tenth of the estimate's time).
pub(super) fn estimate_noise(
    poses: &[&GroundResiduals],
    kept: &Kept,
    fitted: &Fitted,
    within: f64,
) -> CellNoise {
    let observed = kept.seen.iter().filter(|s| **s).count() as f64;
    let by_pose: Vec<Scatter> = (0..poses.len())
        .into_par_iter()
        .map(|i| {
            Scatter::of(
                within,
                entries_of_pose(poses, kept, fitted, i).map(|e| (e.n, e.residual)),
            )
        })
        .collect();
    let scatter = by_pose.into_iter().fold(Scatter::default(), |a, b| a + b);
    CellNoise::from_scatter(within, scatter, observed + 3.0 * poses.len() as f64)
}

/// Each cell's shape variance under `noise`: one over the sum of its sums'
/// information, pose by pose (0 where not seen). A block of cells on each
/// core, each cell's poses in their order.
pub(super) fn cell_variances(
    poses: &[&GroundResiduals],
    kept: &Kept,
    noise: &CellNoise,
) -> Vec<f64> {
    let cells = kept.seen.len();
    let weights = noise.weights();
    let mut information = vec![0.0; cells];
    information
        .par_chunks_mut(CELL_BLOCK)
        .enumerate()
        .for_each(|(block, information)| {
            let first = block * CELL_BLOCK;
            let end = first + information.len();
            for (i, pose) in poses.iter().enumerate() {
                kept.taken[i].for_each_in(first..end, |k| {
                    information[k - first] += weights.of(pose.readings(k));
                });
            }
        });
    information
        .iter()
        .map(|&info| if info > 0.0 { 1.0 / info } else { 0.0 })
        .collect()
}

/// RMS of the values of the cells seen, weighted by their readings.
pub(super) fn weighted_rms(values: &[f64], readings: &[f64], seen: &[bool]) -> f64 {
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

/// The shape of per-cell sums `Σ n·m`: each over its cell's weight (its
/// readings; 0 where it has none), less the plane `plane_part` fits. What a
/// flip test sizes, as [`ShapeOfSums`] describes it.
pub(super) fn shape_from_sums(
    per_cell: &[f64],
    weights: &[f64],
    plane_part: &PlanePartRemover,
) -> Vec<f64> {
    let mut shape: Vec<f64> = per_cell
        .iter()
        .zip(weights)
        .map(|(s, w)| if *w > 0.0 { s / w } else { 0.0 })
        .collect();
    plane_part.remove(&mut shape);
    shape
}

/// Subtracts from a shape the plane `A + B·u' + C·v'` that fits the cells
/// seen, weighted by their readings. Made once for shapes over the same
/// cells and readings: the plane's normal equations are the same for all
/// (the flip tests' draws, when there were forty, and the pattern's steps
/// made them for every shape, a quarter of a millisecond each).
pub(super) struct PlanePartRemover<'a> {
    seen: &'a [bool],
    /// `(1, u', v')` of each cell.
    centres: Vec<Vector3<f64>>,
    readings: &'a [f64],
    /// The normal equations' inverse; none when the cells seen cannot
    /// carry a plane (nothing is removed then).
    inverse: Option<Matrix3<f64>>,
}

impl<'a> PlanePartRemover<'a> {
    pub(super) fn new(readings: &'a [f64], seen: &'a [bool], centres: &[(f64, f64)]) -> Self {
        let centres: Vec<Vector3<f64>> = centres
            .iter()
            .map(|&(du, dv)| Vector3::new(1.0, du, dv))
            .collect();
        let mut normal = Matrix3::zeros();
        for k in 0..seen.len() {
            if seen[k] {
                let phi = centres[k];
                normal += phi * phi.transpose() * readings[k];
            }
        }
        Self {
            seen,
            centres,
            readings,
            inverse: normal.try_inverse(),
        }
    }

    /// The plane it removes, as a flip test sizes shapes ([`ShapeOfSums`]):
    /// each cell's row `(1, u', v')` and the normal equations' inverse;
    /// none when it removes nothing.
    pub(super) fn plane_removed(&self) -> Option<PlaneRemoved<'_>> {
        self.inverse.map(|inverse_normal| PlaneRemoved {
            rows: &self.centres,
            inverse_normal,
        })
    }

    pub(super) fn remove(&self, shape: &mut [f64]) {
        let Some(inverse) = self.inverse else {
            return;
        };
        let cells = || self.seen.iter().zip(&self.centres);
        let mut rhs = Vector3::zeros();
        for ((seen, centre), (value, readings)) in cells().zip(shape.iter().zip(self.readings)) {
            if *seen {
                rhs += centre * (value * readings);
            }
        }
        let plane = inverse * rhs;
        for ((seen, centre), value) in cells().zip(shape.iter_mut()) {
            if *seen {
                *value -= plane.dot(centre);
            }
        }
    }
}
