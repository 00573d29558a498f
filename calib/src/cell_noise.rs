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
//! their signs flipped at random, pose by pose ([`flip_test`]): whatever the
//! noise's correlation within a pose, the flipped shapes show what noise
//! alone makes.

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
}

impl Entries for [Entry] {
    fn count(&self) -> usize {
        self.len()
    }

    fn each(&self) -> impl Iterator<Item = Entry> + '_ {
        self.iter().copied()
    }
}

impl Entries for Vec<Entry> {
    fn count(&self) -> usize {
        self.as_slice().count()
    }

    fn each(&self) -> impl Iterator<Item = Entry> + '_ {
        self.as_slice().each()
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
        let (mut count, mut squares, mut averaged) = (0usize, 0.0, 0.0);
        for (n, residual) in entries {
            count += 1;
            squares += residual * residual;
            averaged += within / n.max(1.0);
        }
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
    /// The same for shapes of the poses with random signs: mean and σ.
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

/// Flips drawn for the test: enough for the null's mean and σ to a few
/// percent, a millisecond each for a calibration's poses.
pub const FLIPS: usize = 40;

/// The shape's size against the sizes of shapes made from the same poses
/// with their signs flipped (module documentation). `weights` are each
/// cell's readings over the poses (0 for cells left out); `shape_of` turns
/// per-cell sums `Σ_p n·m` into a shape as the estimate does (dividing by
/// the readings, removing the plane part). The draws are fixed by a seed:
/// the same poses give the same verdict.
pub fn flip_test(
    entries: &(impl Entries + ?Sized),
    poses: usize,
    weights: &[f64],
    observed: &[f64],
    shape_of: impl Fn(&[f64]) -> Vec<f64> + Sync,
) -> FlipTest {
    flip_test_over(
        || {
            entries
                .each()
                .map(|e| Some((e.cell, e.pose, e.n * e.about_plane)))
        },
        poses,
        weights,
        observed,
        shape_of,
    )
}

/// [`flip_test`] of the entries `entries()` reads in place, in order, each
/// as its key (a cell, or a bin of the ground: below `weights.len()`), its
/// pose and its `n·m`, or `None` to leave it out: a test of the entries
/// binned another way, or less something, where a copy of a calibration's
/// entries was 6 MB at the peak.
///
/// The flips are made [`FLIP_BLOCK`] at a time: each entry, read once a
/// block, adds its value times each of the block's signs of its pose to
/// its key's sums, where a flip at a time read all the entries forty times
/// (docs/performance.md). Each flip's sum of a key adds the same products
/// in the same order as one flip at a time would, so the sizes are the
/// same, bit for bit (a sign is ±1, its product exact). Every flip at
/// once, key by key, was slower (an index of the entries by key, and
/// forty sums a key: 3 MB more at the peak).
pub fn flip_test_over<I: Iterator<Item = FlipEntry>>(
    entries: impl Fn() -> I + Sync,
    poses: usize,
    weights: &[f64],
    observed: &[f64],
    shape_of: impl Fn(&[f64]) -> Vec<f64> + Sync,
) -> FlipTest {
    use rayon::prelude::*;
    let size = |shape: &[f64]| -> f64 { shape.iter().zip(weights).map(|(s, w)| w * s * s).sum() };
    // A block of flips at a time, on every core: each block reads the
    // entries once, in their order, adding each to its key's sums of the
    // block's flips (one cache line).
    let sizes: Vec<f64> = (0..FLIP_BLOCK_COUNT)
        .into_par_iter()
        .flat_map_iter(|block| {
            let signs = block_signs(block, poses);
            let mut sums = vec![[0.0; FLIP_BLOCK]; weights.len()];
            add_flipped(&mut sums, &signs, entries());
            (0..FLIP_BLOCK)
                .map(|j| {
                    let column: Vec<f64> = sums.iter().map(|row| row[j]).collect();
                    size(&shape_of(&column))
                })
                .collect::<Vec<f64>>()
        })
        .collect();
    let n = sizes.len() as f64;
    let mean = sizes.iter().sum::<f64>() / n;
    let sigma = (sizes.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    FlipTest {
        observed: size(observed),
        null_mean: mean,
        null_sigma: sigma,
    }
}

/// Flips made together: one cache line of sums a key.
const FLIP_BLOCK: usize = 8;
const FLIP_BLOCK_COUNT: usize = FLIPS / FLIP_BLOCK;
const _: () = assert!(FLIPS.is_multiple_of(FLIP_BLOCK), "whole blocks of flips");

/// The seed of the flips' signs: the same poses give the same verdict.
const FLIP_SEED: u64 = 0x666c_6970;

/// The signs of block `block`'s flips, pose by pose: flip by flip, each
/// pose's sign in turn, from one sequence drawn from [`FLIP_SEED`]. A
/// block's draws follow the blocks before it in that sequence, and
/// [`splitmix64`]'s state moves by one constant a draw, so each block
/// starts where they end without drawing them.
fn block_signs(block: usize, poses: usize) -> Vec<[f64; FLIP_BLOCK]> {
    let before = (block * FLIP_BLOCK * poses) as u64;
    let mut state = FLIP_SEED.wrapping_add(before.wrapping_mul(SPLITMIX_STEP));
    let mut signs = vec![[0.0; FLIP_BLOCK]; poses];
    for flip in 0..FLIP_BLOCK {
        for pose in signs.iter_mut() {
            pose[flip] = if splitmix64(&mut state) >> 63 == 1 {
                1.0
            } else {
                -1.0
            };
        }
    }
    signs
}

/// One entry as a flip test reads it: its key, its pose and its `n·m`, or
/// `None` to leave it out.
type FlipEntry = Option<(u32, u32, f64)>;

/// Adds each of `entries`, in order, times each flip's sign of its pose to
/// its key's `sums`. Where the processor has AVX2, the same loop
/// four lanes at a time: the same products and sums (a multiply, then an
/// add), bit for bit.
fn add_flipped(
    sums: &mut [[f64; FLIP_BLOCK]],
    signs: &[[f64; FLIP_BLOCK]],
    entries: impl Iterator<Item = FlipEntry>,
) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2, checked just above.
        #[allow(unsafe_code)]
        unsafe {
            add_flipped_avx2(sums, signs, entries)
        };
        return;
    }
    add_flipped_lanes(sums, signs, entries);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn add_flipped_avx2(
    sums: &mut [[f64; FLIP_BLOCK]],
    signs: &[[f64; FLIP_BLOCK]],
    entries: impl Iterator<Item = FlipEntry>,
) {
    add_flipped_lanes(sums, signs, entries);
}

#[inline(always)]
fn add_flipped_lanes(
    sums: &mut [[f64; FLIP_BLOCK]],
    signs: &[[f64; FLIP_BLOCK]],
    entries: impl Iterator<Item = FlipEntry>,
) {
    for (key, pose, value) in entries.flatten() {
        let row = &mut sums[key as usize];
        for (sum, sign) in row.iter_mut().zip(&signs[pose as usize]) {
            *sum += sign * value;
        }
    }
}

/// How far [`splitmix64`]'s state moves a draw.
const SPLITMIX_STEP: u64 = 0x9e37_79b9_7f4a_7c15;

/// SplitMix64: the signs' generator (a fixed sequence; no crate needed).
fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(SPLITMIX_STEP);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
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
            let shape_of = |sums: &[f64]| -> Vec<f64> {
                sums.iter().zip(&weights).map(|(s, w)| s / w).collect()
            };
            let mut sums = vec![0.0; cells];
            for e in &entries {
                sums[e.cell as usize] += e.n * e.about_plane;
            }
            let observed = shape_of(&sums);
            flip_test(&entries, poses, &weights, &observed, shape_of)
        };
        let noise = run(false, &mut rng);
        assert!(noise.sigmas().abs() < 3.0, "{noise:?}");
        let fixed = run(true, &mut rng);
        assert!(fixed.sigmas() > 8.0, "{fixed:?}");
    }

    /// The flips made a block at a time give the sizes one flip at a
    /// time gives, bit for bit: keys met in any order, several entries of
    /// a pose on one key (a bin of the ground), entries left out.
    #[test]
    fn flips_made_in_blocks_are_the_flips_one_at_a_time() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (poses, keys) = (23usize, 301usize);
        let entries: Vec<(u32, u32, f64)> = (0..poses)
            .flat_map(|pose| (0..500).map(move |k| (pose, k)))
            .map(|(pose, _)| (rng.gen_range(0..keys) as u32, pose as u32, normal(&mut rng)))
            .collect();
        let left_out = |k: usize| k.is_multiple_of(11);
        let entry = |k: usize| (!left_out(k)).then_some(entries[k]);
        let weights: Vec<f64> = (0..keys).map(|k| 1.0 + k as f64 % 7.0).collect();
        let shape_of = |sums: &[f64]| -> Vec<f64> {
            let mean = sums.iter().sum::<f64>() / sums.len() as f64;
            sums.iter()
                .zip(&weights)
                .map(|(s, w)| (s - mean) / w)
                .collect()
        };
        let observed = shape_of(&vec![0.5; keys]);
        let found = flip_test_over(
            || (0..entries.len()).map(entry),
            poses,
            &weights,
            &observed,
            shape_of,
        );
        // One flip at a time, over the entries in their order.
        let mut state = FLIP_SEED;
        let sizes: Vec<f64> = (0..FLIPS)
            .map(|_| {
                let signs: Vec<f64> = (0..poses)
                    .map(|_| {
                        if splitmix64(&mut state) >> 63 == 1 {
                            1.0
                        } else {
                            -1.0
                        }
                    })
                    .collect();
                let mut sums = vec![0.0; keys];
                for (key, pose, value) in (0..entries.len()).filter_map(entry) {
                    sums[key as usize] += signs[pose as usize] * value;
                }
                shape_of(&sums)
                    .iter()
                    .zip(&weights)
                    .map(|(s, w)| w * s * s)
                    .sum()
            })
            .collect();
        let mean = sizes.iter().sum::<f64>() / FLIPS as f64;
        let sigma =
            (sizes.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (FLIPS as f64 - 1.0)).sqrt();
        assert_eq!(found.null_mean.to_bits(), mean.to_bits());
        assert_eq!(found.null_sigma.to_bits(), sigma.to_bits());
    }
}
