//! The alternatives to a pattern fixed in the image, each tested for what it
//! is: a pattern that changes with depth (Herrera et al. 2012), residuals that
//! stay with the ground as the poses move (ground that is not flat), and the
//! shape estimated beside such a relief (obstacles' feet).

use super::*;

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

/// [`DepthDependence`] of the sums kept under the shape.
pub(super) fn depth_dependence(
    poses: &[&GroundResiduals],
    entries: &impl Entries,
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
    // Each cell's centre once (three passes read every entry's).
    let cells = shape.len();
    let centres: Vec<(f64, f64)> = (0..cells)
        .map(|k| cell_centre(k, first.columns, &first.intrinsics))
        .collect();
    let depth = |e: &Entry| {
        let (du, dv) = centres[e.cell as usize];
        let q = poses[e.pose as usize].plane.at(du, dv);
        (q > 0.0).then(|| 1.0 / q)
    };
    // Each cell's mean depth over the poses that saw it.
    let (mut sum, mut weight) = (vec![0.0; cells], vec![0.0; cells]);
    let weights = noise.weights();
    for e in entries.each() {
        if let Some(z) = depth(&e) {
            let w = weights.of(e.n);
            sum[e.cell as usize] += w * z;
            weight[e.cell as usize] += w;
        }
    }
    // residual ≈ −per_m·x with x = shape·(z − z̄), weighted by w. Each
    // pose's score `Σ w·x·(residual + per_m·x)` is `Σ w·x·residual +
    // per_m·Σ w·x²` of its own sums, gathered in the same pass as the fit's
    // (a second pass over every entry was a third of the test's time).
    let rows = entries.each().filter_map(|e| {
        let k = e.cell as usize;
        let (Some(z), true) = (depth(&e), weight[k] > 0.0) else {
            return None;
        };
        let x = shape[k] * (z - sum[k] / weight[k]);
        Some((e.pose, weights.of(e.n), x, e.residual))
    });
    let (mut xx, mut xe, mut ww) = (0.0, 0.0, 0.0);
    let mut by_pose = vec![(0.0, 0.0); poses.len()];
    for (pose, w, x, residual) in rows {
        xx += w * x * x;
        xe += w * x * residual;
        ww += w;
        let (pose_xe, pose_xx) = &mut by_pose[pose as usize];
        *pose_xe += w * x * residual;
        *pose_xx += w * x * x;
    }
    if xx <= 0.0 {
        return none;
    }
    let per_m = -xe / xx;
    let meat: f64 = by_pose
        .iter()
        .map(|(pose_xe, pose_xx)| (pose_xe + per_m * pose_xx).powi(2))
        .sum();
    DepthDependence {
        per_m,
        sigma: meat.sqrt() / xx,
        effect_raw: per_m.abs() * (xx / ww).sqrt() * first.raw_per_inverse_depth.abs(),
    }
}

/// Bins of depth in which the pattern's gain is found when it changes with
/// depth (quantiles of the depths the cells were seen at).
pub(super) const DEPTH_BINS: usize = 8;

/// The entries' residuals less what the pattern's change with depth
/// accounts for: the shape times a gain per bin of depth (any change with
/// depth, not only the linear one [`DepthDependence`] measures), each cell
/// about its own mean gain, by least squares. `None` where too few depths
/// were seen to bin them: the residuals as they are.
pub(super) fn without_depth_dependence(
    poses: &[&GroundResiduals],
    entries: &impl Entries,
    shape: &[f64],
) -> Option<Vec<f32>> {
    use nalgebra::{SMatrix, SVector};
    let first = poses[0];
    let z = |e: &Entry| {
        let (du, dv) = cell_centre(e.cell as usize, first.columns, &first.intrinsics);
        let q = poses[e.pose as usize].plane.at(du, dv);
        (q > 0.0).then(|| 1.0 / q)
    };
    let mut depths: Vec<f64> = entries.each().filter_map(|e| z(&e)).collect();
    if depths.len() < DEPTH_BINS * 10 {
        return None;
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
    for e in entries.each() {
        if let Some(z) = z(&e) {
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
    for e in entries.each() {
        if let Some(z) = z(&e) {
            if total[e.cell as usize] > 0.0 {
                let row = design(&e, z);
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
    let residuals = entries
        .each()
        .map(|e| match z(&e) {
            Some(z) if total[e.cell as usize] > 0.0 => e.residual - design(&e, z).dot(&gains),
            _ => e.residual,
        })
        .map(|residual| residual as f32)
        .collect();
    Some(residuals)
}

/// Where each entry's cell meets the ground seen from its pose, in bins of
/// [`GROUND_BIN_M`] numbered in the order first met (`None` where the
/// cell's ray misses the ground), and the count of bins: what
/// [`ground_fixed`] and [`shape_beside_relief`] bin by. It depends on the
/// entries' poses and cells only, so it is made beside the other tests.
pub(super) fn ground_bins(
    poses: &[&GroundResiduals],
    entries: &KeptEntries,
    ground_from_sensor: &[crate::geometry::Transform],
) -> (usize, Vec<Bin>) {
    let first = poses[0];
    let k = first.intrinsics;
    let sensor_from_optical = crate::geometry::sensor_from_optical();
    // Each cell's ray in the sensor's frame, once: the same at every pose.
    let rays: Vec<Vector3<f64>> = (0..first.cell_count())
        .map(|cell| {
            let (du, dv) = cell_centre(cell, first.columns, &k);
            sensor_from_optical * Vector3::new(du / k.fx, dv / k.fy, 1.0)
        })
        .collect();
    let bin_key = |e: &Entry| {
        let pose = &ground_from_sensor[e.pose as usize];
        let ray = pose.rotation * rays[e.cell as usize];
        let origin = pose.translation.vector;
        if ray.y >= -1e-9 {
            return None;
        }
        let t = -origin.y / ray.y;
        let (x, z) = (origin.x + t * ray.x, origin.z + t * ray.z);
        Some((
            (x / GROUND_BIN_M).floor() as i64,
            (z / GROUND_BIN_M).floor() as i64,
        ))
    };
    // The keys a few poses at a time on every core, numbered in order
    // after them (one after the other, the keys were most of the ground's
    // test's time, before the test itself could start).
    let mut numbers = BinNumbers::default();
    let mut numbered = Vec::with_capacity(entries.count());
    // The caller gives each pose's place (the estimate passes them only
    // when there is one for every pose).
    debug_assert_eq!(poses.len(), ground_from_sensor.len());
    let pose_count = poses.len().min(ground_from_sensor.len());
    for chunk_start in (0..pose_count).step_by(POSES_KEYED_AT_ONCE) {
        let chunk_end = (chunk_start + POSES_KEYED_AT_ONCE).min(pose_count);
        let keys: Vec<Vec<Option<(i64, i64)>>> = (chunk_start..chunk_end)
            .into_par_iter()
            .map(|pose| entries.each_of_pose(pose).map(|e| bin_key(&e)).collect())
            .collect();
        numbered.extend(keys.into_iter().flatten().map(|key| numbers.bin(key)));
    }
    (numbers.count as usize, numbered)
}

/// Poses whose entries' bins are found at once (the keys of eight poses of
/// a calibration's: 0.6 MB).
const POSES_KEYED_AT_ONCE: usize = 8;

/// Whether the residuals left by pattern and planes stay with the ground:
/// the entries' means in the bins of the ground ([`ground_bins`]: `bins`
/// of them, `bin_of` each entry's) over the poses, compared with those the
/// poses make with their signs flipped ([`flip_test_over`]). `entries` are
/// those binned, or the same less what a pattern changing with depth
/// accounts for.
pub(super) fn ground_fixed(
    poses: usize,
    entries: &(impl Entries + ?Sized),
    bins: usize,
    bin_of: &[Bin],
) -> FlipTest {
    // Each bin's readings: its shape is the mean residual there.
    let mut weights = vec![0.0; bins];
    for (e, bin) in entries.each().zip(bin_of) {
        if let Some(bin) = bin.number() {
            weights[bin as usize] += e.n;
        }
    }
    let count = entries.count();
    flip_test_over(
        // Keyed by bin: the entries of the block's bins, found in `bin_of`.
        |keys| {
            let in_block = bin_of[..count.min(bin_of.len())]
                .iter()
                .enumerate()
                .filter(move |(_, bin)| bin.number().is_some_and(|b| keys.contains(&b)))
                .map(|(index, _)| index);
            entries.each_at(in_block).map(|(index, e)| {
                bin_of[index]
                    .number()
                    .map(|bin| (bin, e.pose, e.n * e.residual))
            })
        },
        poses,
        ShapeOfSums {
            weights: &weights,
            plane: None,
        },
    )
}

/// An entry's bin of the ground, or none (its cell's ray misses the
/// ground): four bytes, where an `Option<u32>` takes eight (a calibration's
/// entries' bins were 1.5 MB at the estimate's peak).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Bin(Option<std::num::NonZeroU32>);

impl Bin {
    pub(super) const NONE: Bin = Bin(None);

    /// Bin `number` (below `u32::MAX`: there are fewer bins than entries).
    fn numbered(number: u32) -> Bin {
        Bin(std::num::NonZeroU32::new(number.saturating_add(1)))
    }

    /// The bin's number, if the entry has one.
    pub(super) fn number(self) -> Option<u32> {
        self.0.map(|n| n.get() - 1)
    }
}

/// The keys numbered in the order first met, as [`ground_bins`] numbers
/// them: the count of bins and each key's number.
#[cfg(test)]
fn number_in_order_met(keys: impl Iterator<Item = Option<(i64, i64)>>) -> (usize, Vec<Bin>) {
    let mut numbers = BinNumbers::default();
    let numbered = keys.map(|key| numbers.bin(key)).collect();
    (numbers.count as usize, numbered)
}

/// The bins' numbers so far, each key's the next when it is first met (the
/// bins' numbers, and so the order of every sum over them, as a map filled
/// in that order gives them): over a grid that grows to the keys' span
/// while they are read, up to a few million bins (a calibration's ground: a
/// few thousand), then over a map. With std's map the estimate's benchmark
/// took 28.3–31.1 ms, with a grid 26.0–27.5 (three runs of each in turn).
#[derive(Default)]
struct BinNumbers {
    count: u32,
    grid: Option<BinGrid>,
    map: Option<std::collections::HashMap<(i64, i64), u32>>,
}

/// Numbers (`u32::MAX`: none yet) over the keys `x0 ..x0 + width`,
/// `z0 .. z0 + depth`.
struct BinGrid {
    x0: i64,
    z0: i64,
    width: i64,
    depth: i64,
    slots: Vec<u32>,
}

/// The most bins a grid holds (16 MB of numbers).
const MOST_GRID_BINS: i64 = 1 << 22;

impl BinGrid {
    fn at(&self, (x, z): (i64, i64)) -> Option<usize> {
        let (dx, dz) = (x.checked_sub(self.x0)?, z.checked_sub(self.z0)?);
        ((0..self.width).contains(&dx) && (0..self.depth).contains(&dz))
            .then(|| (dz * self.width + dx) as usize)
    }

    /// The grid over its span and `key`'s, with as much again as that span
    /// on each side (so that it grows a few times, not at every key), or
    /// `None` when that is more than [`MOST_GRID_BINS`].
    fn grown_to(&self, (x, z): (i64, i64)) -> Option<BinGrid> {
        let (x_low, x_high) = (self.x0.min(x), (self.x0 + self.width - 1).max(x));
        let (z_low, z_high) = (self.z0.min(z), (self.z0 + self.depth - 1).max(z));
        let span_x = x_high.checked_sub(x_low)?.checked_add(1)?;
        let span_z = z_high.checked_sub(z_low)?.checked_add(1)?;
        let (x0, z0) = (x_low.checked_sub(span_x)?, z_low.checked_sub(span_z)?);
        let (width, depth) = (span_x.checked_mul(3)?, span_z.checked_mul(3)?);
        if width.checked_mul(depth).is_none_or(|n| n > MOST_GRID_BINS) {
            return None;
        }
        let mut grown = BinGrid {
            x0,
            z0,
            width,
            depth,
            slots: vec![u32::MAX; (width * depth) as usize],
        };
        for row in 0..self.depth {
            let from = (row * self.width) as usize;
            let to = grown.at((self.x0, self.z0 + row))?;
            grown.slots[to..to + self.width as usize]
                .copy_from_slice(&self.slots[from..from + self.width as usize]);
        }
        Some(grown)
    }

    /// Every key numbered, with its number.
    fn numbered(&self) -> impl Iterator<Item = ((i64, i64), u32)> + '_ {
        self.slots
            .iter()
            .enumerate()
            .filter(|(_, n)| **n != u32::MAX)
            .map(|(k, n)| {
                let k = k as i64;
                ((self.x0 + k % self.width, self.z0 + k / self.width), *n)
            })
    }
}

impl BinNumbers {
    /// An entry's bin: its key's number, or none without a key.
    fn bin(&mut self, key: Option<(i64, i64)>) -> Bin {
        key.map_or(Bin::NONE, |key| Bin::numbered(self.of(key)))
    }

    /// `key`'s number: its own, or the next when it is met first.
    fn of(&mut self, key: (i64, i64)) -> u32 {
        if let Some(map) = &mut self.map {
            let next = self.count;
            let number = *map.entry(key).or_insert(next);
            self.count += u32::from(number == next);
            return number;
        }
        let grid = self.grid.get_or_insert_with(|| BinGrid {
            x0: key.0,
            z0: key.1,
            width: 1,
            depth: 1,
            slots: vec![u32::MAX],
        });
        let at = match grid.at(key) {
            Some(at) => at,
            None => match grid.grown_to(key) {
                Some(grown) => {
                    *grid = grown;
                    // The grown grid spans the key: `grown_to` made it so.
                    grid.at(key).unwrap_or_default()
                }
                None => {
                    self.map = Some(grid.numbered().collect());
                    self.grid = None;
                    return self.of(key);
                }
            },
        };
        let slot = &mut grid.slots[at];
        if *slot == u32::MAX {
            *slot = self.count;
            self.count += 1;
        }
        *slot
    }
}

/// The shape estimated beside a relief of the ground: a mean per bin of
/// the ground ([`ground_fixed`]'s, `bin_of` each entry's), taken out in
/// turns with the shape. Its flip test's σ, and its RMS against the
/// shape's alone. What stays with the ground at obstacles' feet is local,
/// and a sensor's pattern stands beside it; bumps all over the ground take
/// the shape with them. A bin seen by fewer than three poses has no relief
/// (it would take in those poses' cells whole). `shape_of` makes a shape
/// of per-cell sums as `shape_of_sums` describes it for the flip test.
pub(super) fn shape_beside_relief(
    entries: &impl Entries,
    bin_of: &[Bin],
    poses: usize,
    shape_of_sums: ShapeOfSums,
    shape_of: impl Fn(&[f64]) -> Vec<f64> + Sync,
) -> ReliefTest {
    let weights = shape_of_sums.weights;
    let bins = bin_of
        .iter()
        .filter_map(|b| b.number())
        .max()
        .map_or(0, |b| b as usize + 1);
    let mut seen_by = vec![(0u32, u32::MAX); bins];
    for (e, bin) in entries.each().zip(bin_of) {
        if let Some(b) = bin.number() {
            let (count, last) = &mut seen_by[b as usize];
            if *last != e.pose {
                *count += 1;
                *last = e.pose;
            }
        }
    }
    let alone = shape_of(&per_cell(entries, bin_of, weights.len(), |e, _| {
        e.about_plane
    }));
    let mut shape = alone.clone();
    let mut relief = vec![0.0; bins];
    for _ in 0..RELIEF_TURNS {
        let mut sums = vec![(0.0, 0.0); bins];
        for (e, bin) in entries.each().zip(bin_of) {
            if let Some(b) = bin.number().filter(|b| seen_by[*b as usize].0 >= 3) {
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
        shape = shape_of(&per_cell(entries, bin_of, weights.len(), |e, bin| {
            e.about_plane - relief_of(bin)
        }));
    }
    let beside = |cells| {
        entries.each_indexed_among(cells).map(|(index, e)| {
            let relief = bin_of[index].number().map_or(0.0, |b| relief[b as usize]);
            Some((e.cell, e.pose, e.n * (e.about_plane - relief)))
        })
    };
    let size = |s: &[f64]| s.iter().zip(weights).map(|(v, w)| w * v * v).sum::<f64>();
    // The relief's size over the ground seen, weighted by readings.
    let (mut relief_sum, mut readings) = (0.0, 0.0);
    for (e, bin) in entries.each().zip(bin_of) {
        if let Some(b) = bin.number() {
            relief_sum += e.n * relief[b as usize].powi(2);
            readings += e.n;
        }
    }
    ReliefTest {
        shape_sigmas: flip_test_over(beside, poses, shape_of_sums).sigmas(),
        shape_share: (size(&shape) / size(&alone).max(f64::MIN_POSITIVE)).sqrt(),
        relief_rms: (relief_sum / readings.max(f64::MIN_POSITIVE)).sqrt(),
    }
}

/// Per cell, `Σ n·value` of the entries (with each its bin).
fn per_cell(
    entries: &impl Entries,
    bin_of: &[Bin],
    cells: usize,
    value: impl Fn(&Entry, Option<u32>) -> f64,
) -> Vec<f64> {
    let mut sums = vec![0.0; cells];
    for (e, bin) in entries.each().zip(bin_of) {
        sums[e.cell as usize] += e.n * value(&e, bin.number());
    }
    sums
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ground's test reads each block of bins' entries only, found in
    /// the entries' bins: the same test, bit for bit, as reading every
    /// entry for every block (before), over bins in several blocks and
    /// entries with no bin, of entries as they are and with other residuals.
    #[test]
    fn the_ground_test_reads_each_block_of_bins_only() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (poses, bins) = (52u32, 4_000u32);
        let mut entries = Vec::new();
        let mut bin_of = Vec::new();
        for pose in 0..poses {
            for cell in 0..300u32 {
                entries.push(Entry {
                    pose,
                    cell,
                    n: rng.gen_range(1..=60) as f64,
                    residual: rng.gen_range(-1e-3..1e-3),
                    about_plane: 0.0,
                });
                // One entry in a hundred with no bin.
                let bin = rng.gen_range(0..bins + 40);
                bin_of.push(if bin < bins {
                    Bin::numbered(bin)
                } else {
                    Bin::NONE
                });
            }
        }
        let every_entry = |entries: &dyn Fn() -> Vec<Entry>| {
            let entries = entries();
            let mut weights = vec![0.0; bins as usize];
            for (e, bin) in entries.iter().zip(&bin_of) {
                if let Some(bin) = bin.number() {
                    weights[bin as usize] += e.n;
                }
            }
            flip_test_over(
                |_| {
                    entries
                        .iter()
                        .zip(&bin_of)
                        .map(|(e, bin)| bin.number().map(|bin| (bin, e.pose, e.n * e.residual)))
                },
                poses as usize,
                ShapeOfSums {
                    weights: &weights,
                    plane: None,
                },
            )
        };
        let test = ground_fixed(poses as usize, &entries, bins as usize, &bin_of);
        assert_eq!(test, every_entry(&|| entries.clone()));
        assert!(test.null_sigma > 0.0, "{test:?}");
        let less = WithResiduals {
            entries: &entries,
            residuals: (0..entries.len()).map(|k| (k % 97) as f32 * 1e-5).collect(),
        };
        let replaced = || less.each().collect::<Vec<Entry>>();
        assert_eq!(
            ground_fixed(poses as usize, &less, bins as usize, &bin_of),
            every_entry(&replaced)
        );
    }

    /// The grid that grows numbers the keys as a map filled in order does,
    /// near and far, across its growth and past its size into a map.
    #[test]
    fn bins_are_numbered_in_the_order_first_met() {
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as i64
        };
        let mut keys: Vec<Option<(i64, i64)>> = (0..5000)
            .map(|k| (k % 17 != 0).then(|| (next() % 60 - 30, next() % 40 - 20)))
            .collect();
        // Far keys, and keys at the ends of i64, turn the grid into a map.
        keys.splice(
            2500..2500,
            [
                Some((4000, -3000)),
                Some((i64::MIN, i64::MAX)),
                Some((5, 5)),
            ],
        );
        keys.extend((0..100).map(|k| Some((k % 7, -k % 5))));
        let mut map = std::collections::HashMap::new();
        let expected: Vec<Option<u32>> = keys
            .iter()
            .map(|key| {
                key.map(|key| {
                    let next = map.len() as u32;
                    *map.entry(key).or_insert(next)
                })
            })
            .collect();
        let numbers_of = |keys: &[Option<(i64, i64)>]| {
            let (count, bins) = number_in_order_met(keys.iter().copied());
            (count, bins.into_iter().map(Bin::number).collect::<Vec<_>>())
        };
        let (count, numbers) = numbers_of(&keys);
        assert_eq!((count, &numbers), (map.len(), &expected));
        let (count, numbers) = numbers_of(&keys[..2500]);
        assert_eq!(numbers, expected[..2500]);
        assert_eq!(
            count,
            expected[..2500]
                .iter()
                .flatten()
                .max()
                .map_or(0, |n| *n as usize + 1)
        );
    }
}
