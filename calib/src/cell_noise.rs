//! How noisy a cell's mean residual is at one pose, and whether a pattern
//! over the cells stands out of that noise: both from the poses' own data,
//! never from a count of pixels.
//!
//! A real Kinect's noise is correlated over the image (an 8 × 8 cell's mean
//! varies 46 times more than independent pixels would make it, docs/method.md)
//! and much of it holds through a pose's frames. So a cell's mean at one
//! pose has a variance `within/n + shared`: `within`, a reading's scatter
//! about its cell's mean (from the sums of squares), averages down with the
//! `n` readings; `shared`, the noise common to the cell's readings at that
//! pose, does not. `shared` is estimated from the scatter of the cells'
//! means about pattern and plane, pose to pose ([`CellNoise::estimate`]);
//! that scatter's expectation is the noise's, less the share the fitted
//! parameters take (their count over the entries), so the estimate is
//! unbiased when the pattern is fixed in the image.
//!
//! Whether a shape stands out of the noise is asked of the poses, not of a
//! distribution that assumes independent cells: a shape fixed in the image
//! is the same at every pose, noise is not, and a pose's residuals may carry
//! their sign or the opposite one equally under noise alone. So the shape's
//! size is compared with the sizes of shapes made from the same poses with
//! their signs flipped, pose by pose, over every choice of the signs
//! ([`flip_test`]): whatever the noise's correlation within a pose, the
//! flipped shapes show what noise alone makes.

use nalgebra::{Matrix3, Vector3};

/// One pose's sum of one cell, as the estimate kept it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Entry {
    /// The pose's position among the poses.
    pub pose: u32,
    /// The cell.
    pub cell: u32,
    /// Readings in the sum.
    pub n: f64,
    /// The mean residual about the pattern and the pose's plane (1/m).
    pub residual: f64,
    /// The mean residual about the pose's plane alone (1/m): the pattern
    /// plus the noise.
    pub about_plane: f64,
}

/// Entries read in order, as often as a test needs them: a slice of them,
/// or an estimate's own made as they are read from its poses' cells
/// (`distortion`'s: 52 poses' entries, stored whole, were 6 MB at the
/// estimate's peak).
pub trait Entries: Sync {
    /// How many there are.
    fn count(&self) -> usize;
    /// Every entry, in order.
    fn each(&self) -> impl Iterator<Item = Entry> + '_;
    /// Every entry whose cell lies in `cells`, with its index in
    /// [`Entries::each`]'s order; it may give the others too (by default it
    /// gives every entry). A source whose cells ascend within each pose
    /// skips to those in `cells`: a flip test reads the cells a block at a
    /// time.
    fn each_indexed_among(
        &self,
        cells: std::ops::Range<u32>,
    ) -> impl Iterator<Item = (usize, Entry)> + '_ {
        let _ = cells;
        self.each().enumerate()
    }

    /// The entries at `indices` (ascending; those past the end are none),
    /// with their indices: a test keyed another way than by cell reads only
    /// the entries of its block of keys, not every entry for every block (a
    /// ground test's walks, block by block, were most of its time).
    fn each_at<'s>(
        &'s self,
        indices: impl Iterator<Item = usize> + 's,
    ) -> impl Iterator<Item = (usize, Entry)> + 's;
}

impl Entries for [Entry] {
    fn count(&self) -> usize {
        self.len()
    }

    fn each(&self) -> impl Iterator<Item = Entry> + '_ {
        self.iter().copied()
    }

    fn each_at<'s>(
        &'s self,
        indices: impl Iterator<Item = usize> + 's,
    ) -> impl Iterator<Item = (usize, Entry)> + 's {
        indices.filter_map(|index| self.get(index).map(|e| (index, *e)))
    }
}

impl Entries for Vec<Entry> {
    fn count(&self) -> usize {
        self.as_slice().count()
    }

    fn each(&self) -> impl Iterator<Item = Entry> + '_ {
        self.as_slice().each()
    }

    fn each_at<'s>(
        &'s self,
        indices: impl Iterator<Item = usize> + 's,
    ) -> impl Iterator<Item = (usize, Entry)> + 's {
        self.as_slice().each_at(indices)
    }
}

/// Entries with their residuals replaced, in order (the residuals less
/// something a test has accounted for), the rest as they are.
pub struct WithResiduals<'a, E: ?Sized> {
    /// The entries, as they are.
    pub entries: &'a E,
    /// Each entry's residual in their order (1/m; f32, 4 bytes an entry
    /// where a copy of the entries was 32).
    pub residuals: Vec<f32>,
}

impl<E: Entries + ?Sized> Entries for WithResiduals<'_, E> {
    fn count(&self) -> usize {
        self.entries.count()
    }

    fn each(&self) -> impl Iterator<Item = Entry> + '_ {
        self.entries
            .each()
            .zip(&self.residuals)
            .map(|(e, residual)| Entry {
                residual: f64::from(*residual),
                ..e
            })
    }

    fn each_at<'s>(
        &'s self,
        indices: impl Iterator<Item = usize> + 's,
    ) -> impl Iterator<Item = (usize, Entry)> + 's {
        self.entries.each_at(indices).filter_map(|(index, e)| {
            let residual = f64::from(*self.residuals.get(index)?);
            Some((index, Entry { residual, ..e }))
        })
    }
}

/// The noise of a cell's mean at one pose (module documentation), (1/m)².
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellNoise {
    /// A reading's variance about its cell's mean.
    pub within: f64,
    /// The variance of a cell's mean that its count of readings does not
    /// average away.
    pub shared: f64,
}

impl CellNoise {
    /// Only the readings' own scatter, as independent readings would have it.
    pub fn independent(within: f64) -> Self {
        Self {
            within,
            shared: 0.0,
        }
    }

    /// The variance of the mean of `n` readings of a cell at one pose.
    pub fn of_mean(&self, n: f64) -> f64 {
        self.within / n.max(1.0) + self.shared
    }

    /// Each count's weight `1 / of_mean(n)`, made once for the counts a
    /// pose's cell holds (whole numbers, 32 readings a frame): the
    /// estimate weighs every entry several times, and a division was most
    /// of a pass.
    pub fn weights(&self) -> MeanWeights {
        MeanWeights {
            noise: *self,
            table: (0..=TABLED_COUNTS)
                .map(|n| 1.0 / self.of_mean(n as f64))
                .collect(),
        }
    }

    /// A reading's variance about pattern and plane.
    pub fn of_reading(&self) -> f64 {
        self.within + self.shared
    }

    /// `shared` from the entries' scatter about pattern and plane, with
    /// `parameters` fitted to them (the cells' pattern and the poses'
    /// planes): `Σ e² ≈ (1 − p/N)·Σ (within/n + shared)`.
    pub fn estimate(within: f64, entries: &(impl Entries + ?Sized), parameters: f64) -> Self {
        Self::estimate_from(
            within,
            entries.each().map(|e| (e.n, e.residual)),
            parameters,
        )
    }

    /// [`Self::estimate`] of the entries' `(n, residual)` as they are made:
    /// a calibration's entries are a few MB, and the estimate is made again
    /// at every step of the pattern's.
    pub fn estimate_from(
        within: f64,
        entries: impl Iterator<Item = (f64, f64)>,
        parameters: f64,
    ) -> Self {
        Self::from_scatter(within, Scatter::of(within, entries), parameters)
    }

    /// [`Self::estimate`] from the entries' [`Scatter`], summed in parts
    /// (a pose's entries each, on every core) and added in order.
    pub fn from_scatter(within: f64, scatter: Scatter, parameters: f64) -> Self {
        let Scatter {
            count,
            squares,
            averaged,
        } = scatter;
        let count = count as f64;
        if count <= parameters + 1.0 {
            return Self::independent(within);
        }
        let total = squares * count / (count - parameters);
        Self {
            within,
            shared: ((total - averaged) / count).max(0.0),
        }
    }

    /// χ² of the entries about pattern and plane under this noise, and its
    /// degrees of freedom.
    pub fn chi2(&self, entries: &(impl Entries + ?Sized), parameters: f64) -> (f64, f64) {
        let chi2 = entries
            .each()
            .map(|e| e.residual * e.residual / self.of_mean(e.n))
            .sum();
        (chi2, entries.count() as f64 - parameters)
    }
}

/// Entries' scatter about pattern and plane as [`CellNoise::from_scatter`]
/// reads it: their count, `Σ residual²`, and `Σ within/n` (what the
/// readings' own scatter accounts for).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Scatter {
    pub count: usize,
    pub squares: f64,
    pub averaged: f64,
}

impl Scatter {
    /// Of the entries' `(n, residual)`, in order, under a reading's
    /// variance `within`.
    pub fn of(within: f64, entries: impl Iterator<Item = (f64, f64)>) -> Self {
        let mut scatter = Self::default();
        for (n, residual) in entries {
            scatter.count += 1;
            scatter.squares += residual * residual;
            scatter.averaged += within / n.max(1.0);
        }
        scatter
    }
}

/// Both parts' entries.
impl std::ops::Add for Scatter {
    type Output = Self;

    fn add(self, other: Self) -> Self {
        Self {
            count: self.count + other.count,
            squares: self.squares + other.squares,
            averaged: self.averaged + other.averaged,
        }
    }
}

/// The counts [`CellNoise::weights`] tables: a cell's readings over 128
/// frames of a pose.
const TABLED_COUNTS: usize = 4096;

/// `1 / of_mean(n)` of a [`CellNoise`], the same number from a table for
/// whole counts up to the table's size ([`CellNoise::weights`]).
#[derive(Debug, Clone)]
pub struct MeanWeights {
    noise: CellNoise,
    table: Vec<f64>,
}

impl MeanWeights {
    /// `1 / of_mean(n)`, bit for bit.
    pub fn of(&self, n: f64) -> f64 {
        let whole = n as usize;
        match self.table.get(whole) {
            Some(weight) if whole as f64 == n => *weight,
            _ => 1.0 / self.noise.of_mean(n),
        }
    }
}

/// What flipping the poses' signs found: the shape's size against noise's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlipTest {
    /// The shape's weighted sum of squares, `Σ_cells R·shape²`.
    pub observed: f64,
    /// The same for shapes of the poses with their signs flipped, over
    /// every choice of the signs: mean and σ.
    pub null_mean: f64,
    pub null_sigma: f64,
}

impl FlipTest {
    /// How many of noise's σ the shape's size lies above noise's.
    pub fn sigmas(&self) -> f64 {
        if self.null_sigma > 0.0 {
            (self.observed - self.null_mean) / self.null_sigma
        } else if self.observed > self.null_mean {
            f64::INFINITY
        } else {
            0.0
        }
    }

    /// The shape's size over noise's, as a χ² per degree of freedom would
    /// say it (1 for noise alone).
    pub fn ratio(&self) -> f64 {
        if self.null_mean > 0.0 {
            self.observed / self.null_mean
        } else {
            f64::INFINITY
        }
    }
}

/// How a test turns per-key sums `Σ n·m` (a key: a cell, or a bin of the
/// ground) into the shape whose size it takes: each key's sum over its
/// weight (its readings; a weight of 0 leaves the key out), less, where
/// `plane` is given, the plane `A + B·u' + C·v'` that fits the shape over
/// the keys weighted alike, as the pattern's estimate makes a shape. Its
/// size is `Σ weight·shape²`.
#[derive(Debug, Clone, Copy)]
pub struct ShapeOfSums<'a> {
    pub weights: &'a [f64],
    pub plane: Option<PlaneRemoved<'a>>,
}

/// The plane a shape is taken less of: each key's row `(1, u', v')`, and
/// the inverse of the normal equations `Σ weight·row·rowᵀ` over the keys
/// (as the estimate's plane remover holds them).
#[derive(Debug, Clone, Copy)]
pub struct PlaneRemoved<'a> {
    pub rows: &'a [Vector3<f64>],
    pub inverse_normal: Matrix3<f64>,
}

impl<'a> PlaneRemoved<'a> {
    /// The plane over `rows` weighted by `weights` (keys of no weight left
    /// out); none when the keys cannot carry a plane.
    pub fn weighted(rows: &'a [Vector3<f64>], weights: &[f64]) -> Option<Self> {
        let mut normal = Matrix3::zeros();
        for (row, weight) in rows.iter().zip(weights).filter(|(_, w)| **w > 0.0) {
            normal += row * row.transpose() * *weight;
        }
        let inverse_normal = normal.try_inverse()?;
        Some(Self {
            rows,
            inverse_normal,
        })
    }
}

/// The shape's size against the sizes of shapes made from the same poses
/// with their signs flipped (module documentation): over every choice of
/// signs, exactly. The size of the shape of `Σ_p s_p·X_p` (`X_p`, pose
/// p's per-key sums; `s_p = ±1`) is a quadratic form `sᵀ·G·s` in the signs,
/// so over every choice of signs (each ±1 alike) its mean is `tr G` and its variance
/// `2·Σ_{p≠q} G_pq²`, and the shape found is the one of all signs `+1`,
/// `1ᵀ·G·1` ([`size_gram`]). Forty draws, as the test was first made,
/// knew the null's σ to ±11 % at best (for normal sizes; a quadratic form
/// that a few poses dominate has heavier tails), and read the entries five
/// times.
pub fn flip_test(entries: &(impl Entries + ?Sized), poses: usize, shape: ShapeOfSums) -> FlipTest {
    flip_test_over(
        |cells| {
            entries
                .each_indexed_among(cells)
                .map(|(_, e)| Some((e.cell, e.pose, e.n * e.about_plane)))
        },
        poses,
        shape,
    )
}

/// [`flip_test`] of the entries `entries(keys)` reads in place, each as its
/// key (a cell, or a bin of the ground: below `shape.weights.len()`), its
/// pose and its `n·m`, or `None` to leave it out: a test of the entries
/// binned another way, or less something, where a copy of a calibration's
/// entries was 6 MB at the peak. `entries(keys)` gives every entry whose key
/// lies in `keys`, and may give others (they are skipped).
pub fn flip_test_over<I: Iterator<Item = FlipEntry>>(
    entries: impl Fn(std::ops::Range<u32>) -> I + Sync,
    poses: usize,
    shape: ShapeOfSums,
) -> FlipTest {
    let gram = size_gram(entries, poses, shape);
    let (mut observed, mut null_mean, mut off_diagonal) = (0.0, 0.0, 0.0);
    for p in 0..poses {
        for q in 0..poses {
            let g = gram[p * poses + q];
            observed += g;
            if p == q {
                null_mean += g;
            } else {
                off_diagonal += g * g;
            }
        }
    }
    FlipTest {
        observed,
        null_mean,
        null_sigma: (2.0 * off_diagonal).sqrt(),
    }
}

/// One entry as a flip test reads it: its key, its pose and its `n·m`, or
/// `None` to leave it out.
type FlipEntry = Option<(u32, u32, f64)>;

/// Values of the poses' per-key sums held at once: keys are taken in
/// blocks of `GRAM_BLOCK_VALUES / poses` (1,260 of a 52-pose calibration's
/// 4,800 cells, 0.5 MB), each block's sums made in a read of the entries.
const GRAM_BLOCK_VALUES: usize = 1 << 16;

/// Keys added to the Gram matrix together: one load of its row a group.
const KEY_LANES: usize = 4;

/// The size's Gram matrix over the poses (row-major, `poses × poses`): with
/// `X_p` pose p's per-key sums, the size of the shape of `Σ_p s_p·X_p` is
/// `sᵀ·G·s` for any signs. The shape is linear in the sums; with `w` the
/// weights, `R` the plane rows and `M = Σ_k w_k·R_k·R_kᵀ`,
/// `G_pq = Σ_k X_pk·X_qk / w_k − b_pᵀ·M⁻¹·b_q`, `b_p = Σ_k R_k·X_pk`
/// (`M⁻¹`: [`PlaneRemoved::inverse_normal`]).
/// The blocks of keys run on every core, and their matrices are added in
/// the blocks' order: the same numbers for any count of threads, and on
/// any processor (each element's products and sums in the same order).
fn size_gram<I: Iterator<Item = FlipEntry>>(
    entries: impl Fn(std::ops::Range<u32>) -> I + Sync,
    poses: usize,
    shape: ShapeOfSums,
) -> Vec<f64> {
    use rayon::prelude::*;
    let keys = shape.weights.len();
    if poses == 0 {
        return Vec::new();
    }
    let block = (GRAM_BLOCK_VALUES / poses.max(1)).max(KEY_LANES) / KEY_LANES * KEY_LANES;
    let blocks: Vec<(Vec<f64>, Vec<Vector3<f64>>)> = (0..keys.div_ceil(block))
        .into_par_iter()
        .map(|b| {
            let first = b * block;
            let end = (first + block).min(keys);
            // Key by key, its sums over the poses.
            let mut sums = vec![0.0; (end - first) * poses];
            for (key, pose, value) in entries(first as u32..end as u32).flatten() {
                let (key, pose) = (key as usize, pose as usize);
                debug_assert!(pose < poses && key < keys, "key {key} of pose {pose}");
                if (first..end).contains(&key) && pose < poses {
                    sums[(key - first) * poses + pose] += value;
                }
            }
            let mut plane_sums = vec![Vector3::zeros(); poses];
            for (key, column) in (first..end).zip(sums.chunks_exact_mut(poses)) {
                let weight = shape.weights[key];
                if weight.is_nan() || weight <= 0.0 {
                    column.fill(0.0);
                    continue;
                }
                if let Some(plane) = shape.plane {
                    for (sum, x) in plane_sums.iter_mut().zip(column.iter()) {
                        *sum += plane.rows[key] * *x;
                    }
                }
                let scale = 1.0 / weight.sqrt();
                for x in column.iter_mut() {
                    *x *= scale;
                }
            }
            let mut gram = vec![0.0; poses * poses];
            add_outer_products(&mut gram, &sums, poses);
            (gram, plane_sums)
        })
        .collect();
    let mut gram = vec![0.0; poses * poses];
    let mut plane_sums = vec![Vector3::zeros(); poses];
    for (block_gram, block_sums) in &blocks {
        for (g, b) in gram.iter_mut().zip(block_gram) {
            *g += b;
        }
        for (s, b) in plane_sums.iter_mut().zip(block_sums) {
            *s += b;
        }
    }
    // Only the upper triangle was summed: the lower is its mirror.
    for p in 0..poses {
        for q in 0..p {
            gram[p * poses + q] = gram[q * poses + p];
        }
    }
    if let Some(plane) = shape.plane {
        let solved: Vec<Vector3<f64>> = plane_sums
            .iter()
            .map(|b| plane.inverse_normal * b)
            .collect();
        for p in 0..poses {
            for q in 0..poses {
                gram[p * poses + q] -= plane_sums[p].dot(&solved[q]);
            }
        }
    }
    gram
}

/// Adds `Σ_k c_k·c_kᵀ` over the columns `c_k` of `columns` (each `poses`
/// long, one after the other) to the upper triangle of `gram`, four
/// columns at a time. Where the processor has AVX2, the same loop four
/// lanes at a time: the same products and sums, bit for bit.
fn add_outer_products(gram: &mut [f64], columns: &[f64], poses: usize) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2, checked just above.
        #[allow(unsafe_code)]
        unsafe {
            add_outer_products_avx2(gram, columns, poses)
        };
        return;
    }
    add_outer_products_lanes(gram, columns, poses);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn add_outer_products_avx2(gram: &mut [f64], columns: &[f64], poses: usize) {
    add_outer_products_lanes(gram, columns, poses);
}

#[inline(always)]
fn add_outer_products_lanes(gram: &mut [f64], columns: &[f64], poses: usize) {
    if poses == 0 {
        return;
    }
    let none = vec![0.0; poses];
    for group in columns.chunks(KEY_LANES * poses) {
        let mut c: [&[f64]; KEY_LANES] = [&none; KEY_LANES];
        for (lane, column) in group.chunks_exact(poses).enumerate() {
            c[lane] = column;
        }
        for p in 0..poses {
            let a = [c[0][p], c[1][p], c[2][p], c[3][p]];
            let row = &mut gram[p * poses + p..(p + 1) * poses];
            let tails = [&c[0][p..], &c[1][p..], &c[2][p..], &c[3][p..]];
            for (q, g) in row.iter_mut().enumerate() {
                *g += (a[0] * tails[0][q] + a[1] * tails[1][q])
                    + (a[2] * tails[2][q] + a[3] * tails[3][q]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn normal(rng: &mut impl Rng) -> f64 {
        let u1: f64 = 1.0 - rng.gen::<f64>();
        let u2: f64 = rng.gen();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// With noise shared by a cell's readings, the estimate finds it, and
    /// the χ² per degree of freedom is then 1; under independent readings'
    /// noise it is what a count of pixels would claim, many times more.
    #[test]
    fn the_shared_noise_is_found_from_the_scatter() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (within, shared): (f64, f64) = (1.0, 0.2);
        let entries: Vec<Entry> = (0..20_000)
            .map(|k| {
                let n = [16.0, 64.0, 128.0][k % 3];
                let residual =
                    normal(&mut rng) * (within / n).sqrt() + normal(&mut rng) * shared.sqrt();
                Entry {
                    pose: (k / 100) as u32,
                    cell: (k % 100) as u32,
                    n,
                    residual,
                    about_plane: residual,
                }
            })
            .collect();
        let noise = CellNoise::estimate(within, &entries, 0.0);
        assert!((noise.shared - shared).abs() < 0.01, "{noise:?}");
        let (chi2, dof) = noise.chi2(&entries, 0.0);
        assert!((chi2 / dof - 1.0).abs() < 0.03, "{}", chi2 / dof);
        let (chi2, dof) = CellNoise::independent(within).chi2(&entries, 0.0);
        assert!(chi2 / dof > 5.0, "{}", chi2 / dof);
    }

    /// Noise alone, whatever its correlation over the cells of a pose,
    /// stands at about 0 of noise's σ; a fixed pattern far above.
    #[test]
    fn flipping_whole_poses_tells_a_fixed_pattern_from_correlated_noise() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let (poses, cells) = (40usize, 200usize);
        let pattern: Vec<f64> = (0..cells).map(|c| 0.2 * (c as f64 / 10.0).sin()).collect();
        let run = |with_pattern: bool, rng: &mut ChaCha8Rng| {
            let mut entries = Vec::new();
            for p in 0..poses {
                // Noise correlated over all cells of a pose: a common offset
                // and a slow wave, and each cell's own.
                let (offset, phase) = (normal(rng), rng.gen::<f64>() * 6.0);
                for (c, fixed) in pattern.iter().enumerate() {
                    let noise = offset + (c as f64 / 30.0 + phase).sin() + 0.3 * normal(rng);
                    let value = noise + if with_pattern { fixed * 5.0 } else { 0.0 };
                    entries.push(Entry {
                        pose: p as u32,
                        cell: c as u32,
                        n: 10.0,
                        residual: 0.0,
                        about_plane: value,
                    });
                }
            }
            let weights = vec![10.0 * poses as f64; cells];
            let shape = ShapeOfSums {
                weights: &weights,
                plane: None,
            };
            flip_test(&entries, poses, shape)
        };
        let noise = run(false, &mut rng);
        assert!(noise.sigmas().abs() < 3.0, "{noise:?}");
        let fixed = run(true, &mut rng);
        assert!(fixed.sigmas() > 8.0, "{fixed:?}");
    }

    /// The null's mean and σ are those of the sizes over every choice of
    /// the poses' signs, and the shape's size that of all signs `+1`:
    /// counted here sign by sign over 2⁹ choices, the shape made as the
    /// estimate makes it (sums over readings, a plane removed). Keys met
    /// in any order, several entries of a pose on one key (a bin of the
    /// ground), entries left out, keys of no weight, more keys than one
    /// block holds.
    #[test]
    fn the_null_is_the_sizes_over_every_choice_of_signs() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (poses, keys) = (9usize, 9_001usize);
        let entries: Vec<(u32, u32, f64)> = (0..poses)
            .flat_map(|pose| (0..3_000).map(move |k| (pose, k)))
            .map(|(pose, _)| {
                let key = rng.gen_range(0..keys) as u32;
                // A share fixed in the keys, so that the shape stands out.
                let value = normal(&mut rng) + 0.3 * (f64::from(key) / 50.0).sin();
                (key, pose as u32, value)
            })
            .collect();
        let left_out = |k: usize| k.is_multiple_of(11);
        let entry = |k: usize| (!left_out(k)).then_some(entries[k]);
        let weights: Vec<f64> = (0..keys)
            .map(|k| {
                if k % 13 == 0 {
                    0.0
                } else {
                    1.0 + k as f64 % 7.0
                }
            })
            .collect();
        let rows: Vec<Vector3<f64>> = (0..keys)
            .map(|k| Vector3::new(1.0, (k % 97) as f64 - 48.0, (k / 97) as f64 - 46.0))
            .collect();
        // The shape as the estimate makes it: over the weights, less the
        // weighted plane.
        let size_of_sums = |sums: &[f64]| -> f64 {
            let shape: Vec<f64> = sums
                .iter()
                .zip(&weights)
                .map(|(s, w)| if *w > 0.0 { s / w } else { 0.0 })
                .collect();
            let (mut normal, mut rhs) = (Matrix3::zeros(), Vector3::zeros());
            for ((row, w), v) in rows.iter().zip(&weights).zip(&shape) {
                normal += row * row.transpose() * *w;
                rhs += row * (v * w);
            }
            let plane = normal.try_inverse().unwrap() * rhs;
            shape
                .iter()
                .zip(&weights)
                .zip(&rows)
                .map(|((v, w), row)| w * (v - plane.dot(row)).powi(2))
                .sum()
        };
        let sizes: Vec<f64> = (0..1u32 << poses)
            .map(|signs| {
                let mut sums = vec![0.0; keys];
                for (key, pose, value) in (0..entries.len()).filter_map(entry) {
                    let sign = if signs >> pose & 1 == 1 { -1.0 } else { 1.0 };
                    sums[key as usize] += sign * value;
                }
                size_of_sums(&sums)
            })
            .collect();
        let count = sizes.len() as f64;
        let mean = sizes.iter().sum::<f64>() / count;
        let sigma = (sizes.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / count).sqrt();
        let found = flip_test_over(
            |_| (0..entries.len()).map(entry),
            poses,
            ShapeOfSums {
                weights: &weights,
                plane: Some(
                    PlaneRemoved::weighted(&rows, &weights).expect("the keys carry a plane"),
                ),
            },
        );
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs();
        assert!(close(found.null_mean, mean), "{found:?} against {mean}");
        assert!(close(found.null_sigma, sigma), "{found:?} against {sigma}");
        assert!(
            close(found.observed, sizes[0]),
            "{found:?} against {}",
            sizes[0]
        );
        assert!(found.sigmas() > 3.0, "{found:?}");
    }
}
