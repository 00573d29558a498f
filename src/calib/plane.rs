//! Ground plane estimation (paper section 4.1), made robust.
//!
//! The paper fits the eigenvector plane of all points and removes points farther
//! than 2σ until none is. On real scenes that fits the largest plane in view,
//! which may be a wall or a box, and its σ (of absolute distances) shrinks the set
//! without end (conventions.md, errata). Here:
//!
//! 1. **MSAC restricted by a prior** on a fixed subsample: only planes whose upward
//!    normal lies within a cone around the expected one, and whose height lies in
//!    the expected band, are candidates. Among supported candidates that are
//!    parallel, the *lowest* wins: nothing in view lies below the ground the robot
//!    stands on, while box tops and tables lie above it.
//! 2. **The paper's eigenvector fit with iterative rejection**, weighted by the
//!    Kinect's depth noise (`σ(z) ∝ z²`), with σ the RMS of the signed normalised
//!    residuals of the current inliers, a `k·σ` band (k = 2 as in the paper),
//!    bounded iterations and a minimum inlier fraction. Iterations run on a
//!    subsample first and finish on every point.
//! 3. **A covariance** of `(a, b, c, d)` from the scatter of the inliers, for the
//!    solve to weight by.
//!
//! Several frames of one pose are fused by fitting one plane to all their points.
//! Everything is deterministic: the random sampling uses a seeded generator.

use nalgebra::{Matrix3, Matrix4, SymmetricEigen, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use wide::f32x4;

use super::geometry::{angle_between, Plane};
use super::sensor::PointCloud;

/// What is known about the ground before looking: where "up" is and how high
/// the sensor is, both in the sensor frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundPrior {
    /// Expected upward normal of the ground in the sensor frame (unit).
    pub up: Vector3<f64>,
    /// Largest accepted angle between the ground's normal and `up`, radians.
    pub up_tolerance: f64,
    /// Expected height of the sensor above the ground and its tolerance, metres.
    pub height: Option<(f64, f64)>,
}

impl GroundPrior {
    /// A prior on the direction only.
    pub fn up_only(up: Vector3<f64>, up_tolerance: f64) -> Self {
        Self {
            up: up.normalize(),
            up_tolerance,
            height: None,
        }
    }

    fn admits(&self, plane: &Plane) -> bool {
        if angle_between(&plane.normal, &self.up) > self.up_tolerance {
            return false;
        }
        match self.height {
            Some((height, tolerance)) => (plane.d - height).abs() <= tolerance,
            None => true,
        }
    }
}

/// Tuning of the ground fit. The defaults suit a Kinect v1 at 0.5–5 m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFitSettings {
    /// Points drawn (by stride) for the MSAC search.
    pub msac_sample_size: usize,
    /// Random hypotheses per MSAC round.
    pub msac_iterations: usize,
    /// MSAC's truncation, in expected standard deviations of one reading.
    pub msac_threshold_sigmas: f64,
    /// The paper's rejection factor: points beyond `k·σ` are bad points.
    pub rejection_k: f64,
    /// Upper bound on rejection iterations at each resolution.
    pub max_iterations: usize,
    /// The fit fails when fewer than this fraction of valid points are ground.
    pub min_inlier_fraction: f64,
    /// The fit fails with fewer valid points than this.
    pub min_points: usize,
    /// A lower parallel plane replaces the best one when it holds at least this
    /// fraction of the sampled points.
    pub min_lower_support: f64,
    /// Stride of the first refinement stage (1 = every point).
    pub coarse_stride: usize,
    /// Seed of the hypothesis generator.
    pub seed: u64,
}

impl Default for PlaneFitSettings {
    fn default() -> Self {
        Self {
            msac_sample_size: 3000,
            msac_iterations: 300,
            msac_threshold_sigmas: 3.0,
            rejection_k: 2.0,
            max_iterations: 20,
            min_inlier_fraction: 0.1,
            min_points: 500,
            min_lower_support: 0.08,
            coarse_stride: 8,
            seed: 0x6772_6f75_6e64,
        }
    }
}

/// The ground found in one pose's frames.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundFit {
    /// The ground in the sensor frame, `d > 0`.
    pub plane: Plane,
    /// Covariance of `(a, b, c, d)` (unitless normal, metres), from the inliers'
    /// scatter and their residuals. It describes the random error of the fit
    /// only; the solve adds a floor for what pixels cannot show.
    pub covariance: Matrix4<f64>,
    /// Points that support the plane.
    pub inliers: usize,
    /// Points with a valid depth in the trusted range.
    pub valid_points: usize,
    /// RMS distance of the inliers to the plane, metres.
    pub rms_m: f64,
    /// Rejection iterations done.
    pub iterations: usize,
}

/// Why no ground was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlaneFitError {
    #[error("only {found} valid depth points in view, at least {needed} are needed")]
    TooFewPoints { found: usize, needed: usize },
    #[error(
        "no plane in view matches the expected ground (normal within {tolerance_deg:.0}° of the expected up direction{height})"
    )]
    NoGroundInPrior { tolerance_deg: f64, height: String },
    #[error(
        "the ground holds only {percent:.1}% of the valid points, at least {min_percent:.1}% are needed"
    )]
    TooFewInliers { percent: f64, min_percent: f64 },
}

/// Moves of the plane below these (20 µrad, 20 µm: a fortieth of the solve's
/// noise floor per pose) end the rejection iterations.
const SETTLED_TILT: f64 = 2e-5;
const SETTLED_SHIFT: f64 = 2e-5;

/// Fewest MSAC hypotheses drawn, however good the first ones look.
const MIN_HYPOTHESES: usize = 60;

/// A hypothesis of MSAC with its cost and support.
#[derive(Debug, Clone, Copy)]
struct Hypothesis {
    plane: Plane,
    cost: f64,
    support: usize,
}

/// The MSAC sample: points and their expected standard deviations (metres).
struct Sample {
    points: Vec<Vector3<f64>>,
    sigma: Vec<f64>,
}

impl Sample {
    fn draw(clouds: &[&PointCloud], size: usize) -> Self {
        let total: usize = clouds.iter().map(|c| c.len()).sum();
        let cloud = PointCloud::subsample(clouds, (total / size.max(1)).max(1));
        let points = (0..cloud.len()).map(|i| cloud.point(i)).collect();
        let sigma = cloud
            .weight
            .iter()
            .map(|w| 1e-3 / f64::from(*w).sqrt())
            .collect();
        Self { points, sigma }
    }

    /// MSAC among planes admitted by `admit`, on the points not in `excluded`.
    fn msac(
        &self,
        excluded: &[bool],
        rng: &mut ChaCha8Rng,
        settings: &PlaneFitSettings,
        admit: impl Fn(&Plane) -> bool,
    ) -> Option<Hypothesis> {
        let candidates: Vec<usize> = (0..self.points.len()).filter(|&i| !excluded[i]).collect();
        if candidates.len() < 3 {
            return None;
        }
        let t2 = settings.msac_threshold_sigmas * settings.msac_threshold_sigmas;
        let mut best: Option<Hypothesis> = None;
        // Enough draws to pick three inliers of the best plane so far with
        // probability 99.9 % (RANSAC's classic bound), within the limits.
        let mut needed = settings.msac_iterations;
        let mut drawn = 0;
        while drawn < needed.min(settings.msac_iterations) {
            drawn += 1;
            let i = candidates[rng.gen_range(0..candidates.len())];
            let j = candidates[rng.gen_range(0..candidates.len())];
            let k = candidates[rng.gen_range(0..candidates.len())];
            let (p0, p1, p2) = (self.points[i], self.points[j], self.points[k]);
            let normal = (p1 - p0).cross(&(p2 - p0));
            // Nearly collinear triples give meaningless normals.
            if normal.norm() < 1e-4 * (p1 - p0).norm() * (p2 - p0).norm() || normal.norm() == 0.0 {
                continue;
            }
            let Ok(plane) = Plane::through(normal, &p0) else {
                continue;
            };
            if !admit(&plane) {
                continue;
            }
            let mut cost = 0.0;
            let mut support = 0;
            for &c in &candidates {
                let z = plane.signed_distance(&self.points[c]) / self.sigma[c];
                let z2 = z * z;
                if z2 < t2 {
                    cost += z2;
                    support += 1;
                } else {
                    cost += t2;
                }
            }
            if best.is_none_or(|b| cost < b.cost) {
                best = Some(Hypothesis {
                    plane,
                    cost,
                    support,
                });
                let inlier_ratio = support as f64 / candidates.len() as f64;
                let all_three = inlier_ratio.powi(3).min(1.0 - 1e-12);
                let bound = ((1.0 - 0.999f64).ln() / (1.0 - all_three).ln()).ceil();
                needed = (bound as usize).max(MIN_HYPOTHESES);
            }
        }
        best
    }

    fn mark_inliers(&self, plane: &Plane, settings: &PlaneFitSettings, excluded: &mut [bool]) {
        for (i, p) in self.points.iter().enumerate() {
            if (plane.signed_distance(p) / self.sigma[i]).abs() < settings.msac_threshold_sigmas {
                excluded[i] = true;
            }
        }
    }

    /// A robust scale of the normalised residuals near `plane` (1.4826·MAD).
    fn robust_scale(&self, plane: &Plane, settings: &PlaneFitSettings) -> f64 {
        let band = 4.0 * settings.msac_threshold_sigmas;
        let mut residuals: Vec<f64> = self
            .points
            .iter()
            .zip(&self.sigma)
            .map(|(p, s)| (plane.signed_distance(p) / s).abs())
            .filter(|z| *z < band)
            .collect();
        if residuals.is_empty() {
            return 1.0;
        }
        let mid = residuals.len() / 2;
        let (_, median, _) = residuals.select_nth_unstable_by(mid, f64::total_cmp);
        (1.4826 * *median).max(0.25)
    }
}

/// Weighted moments of the points inside a band around a plane.
#[derive(Debug, Clone, Copy, Default)]
struct Moments {
    count: usize,
    weight: f64,
    /// Σ w·q and Σ w·q·qᵀ with `q = p - reference`.
    first: Vector3<f64>,
    second: Matrix3<f64>,
    /// Σ of squared normalised residuals, and of squared distances (m²).
    normalised_sq: f64,
    distance_sq: f64,
}

impl Moments {
    fn add(&mut self, other: &Moments) {
        self.count += other.count;
        self.weight += other.weight;
        self.first += other.first;
        self.second += other.second;
        self.normalised_sq += other.normalised_sq;
        self.distance_sq += other.distance_sq;
    }

    /// Accumulates the points of `cloud` whose normalised residual to `plane`
    /// is below `band`. Four points at a time (SIMD), partial sums in f32 over
    /// short runs, added up in f64 in a fixed order: the result depends on the
    /// input alone.
    fn accumulate(
        &mut self,
        cloud: &PointCloud,
        plane: &Plane,
        reference: &Vector3<f64>,
        band: f64,
    ) {
        const RUN: usize = 1024;
        let splat = |v: f64| f32x4::splat(v as f32);
        let (nx, ny, nz) = (
            splat(plane.normal.x),
            splat(plane.normal.y),
            splat(plane.normal.z),
        );
        let offset = splat(plane.signed_distance(reference));
        let (rx, ry, rz) = (splat(reference.x), splat(reference.y), splat(reference.z));
        let band2 = splat(band * band);
        let million = f32x4::splat(1.0e6);
        let n = cloud.len();
        let (xs, ys, zs, ws) = (
            &cloud.x[..n],
            &cloud.y[..n],
            &cloud.z[..n],
            &cloud.weight[..n],
        );
        // Lanes past the end load weight 0 and are masked, so they add nothing.
        let load = |v: &[f32], i: usize| -> f32x4 {
            match v.get(i..i + 4) {
                Some(four) => f32x4::new([four[0], four[1], four[2], four[3]]),
                None => {
                    let mut lanes = [0f32; 4];
                    for (l, lane) in lanes.iter_mut().enumerate() {
                        *lane = v.get(i + l).copied().unwrap_or(0.0);
                    }
                    f32x4::new(lanes)
                }
            }
        };
        let mut start = 0;
        while start < n {
            let end = (start + RUN).min(n);
            let mut s = [f32x4::ZERO; 13];
            let mut i = start;
            while i < end {
                let valid = if i + 4 <= end {
                    f32x4::ONE
                } else {
                    f32x4::new(std::array::from_fn(|l| if i + l < end { 1.0 } else { 0.0 }))
                };
                let x = load(xs, i) - rx;
                let y = load(ys, i) - ry;
                let z = load(zs, i) - rz;
                let w = load(ws, i);
                let r = nx * x + ny * y + nz * z + offset;
                let r_mm2 = r * r * million;
                let zn2 = r_mm2 * w;
                let m = zn2.simd_lt(band2) & valid;
                let wm = w * m;
                s[0] += m;
                s[1] += wm;
                s[2] += wm * x;
                s[3] += wm * y;
                s[4] += wm * z;
                s[5] += wm * x * x;
                s[6] += wm * x * y;
                s[7] += wm * x * z;
                s[8] += wm * y * y;
                s[9] += wm * y * z;
                s[10] += wm * z * z;
                s[11] += m * zn2;
                s[12] += m * r_mm2;
                i += 4;
            }
            let d: [f64; 13] =
                std::array::from_fn(|k| s[k].to_array().iter().map(|&v| f64::from(v)).sum());
            self.count += d[0].round() as usize;
            self.weight += d[1];
            self.first += Vector3::new(d[2], d[3], d[4]);
            self.second += Matrix3::new(d[5], d[6], d[7], d[6], d[8], d[9], d[7], d[9], d[10]);
            self.normalised_sq += d[11];
            self.distance_sq += d[12] * 1e-6;
            start = end;
        }
    }

    /// The weighted eigenvector plane of the accumulated points (paper eq. 12-15),
    /// with the eigen decomposition of their scatter.
    fn plane(
        &self,
        reference: &Vector3<f64>,
    ) -> Option<(Plane, Vector3<f64>, SymmetricEigen<f64, nalgebra::U3>)> {
        if self.count < 3 || self.weight <= 0.0 {
            return None;
        }
        let mean = self.first / self.weight;
        let scatter = self.second - mean * mean.transpose() * self.weight;
        let eigen = SymmetricEigen::new(scatter);
        let smallest = eigen.eigenvalues.imin();
        let normal = eigen.eigenvectors.column(smallest).into_owned();
        let centroid = mean + reference;
        let plane = Plane::through(normal, &centroid).ok()?;
        Some((plane, centroid, eigen))
    }
}

fn moments_over(
    clouds: &[&PointCloud],
    plane: &Plane,
    reference: &Vector3<f64>,
    band: f64,
) -> Moments {
    let mut total = Moments::default();
    for cloud in clouds {
        let mut m = Moments::default();
        m.accumulate(cloud, plane, reference, band);
        total.add(&m);
    }
    total
}

/// The outcome of the rejection iterations: the plane, the final band, the
/// moments of the inliers it was fitted to, and how many iterations it took.
struct Rejection {
    plane: Plane,
    band: f64,
    moments: Moments,
    iterations: usize,
}

/// The paper's iteration: fit the eigenvector plane to the points within
/// `band`, set the band to `k·σ` of the new inliers, repeat until the band and
/// the plane settle (or the bound on iterations).
fn reject_iteratively(
    clouds: &[&PointCloud],
    mut plane: Plane,
    mut band: f64,
    reference: &Vector3<f64>,
    settings: &PlaneFitSettings,
) -> Rejection {
    let mut iterations = 0;
    let mut moments = Moments::default();
    for _ in 0..settings.max_iterations.max(1) {
        iterations += 1;
        let m = moments_over(clouds, &plane, reference, band);
        let Some((next, centroid, eigen)) = m.plane(reference) else {
            break;
        };
        // σ: RMS of the signed normalised residuals of the inliers (errata:
        // not of the absolute distances, which shrinks the set without end).
        let scale = (m.normalised_sq / m.count.max(1) as f64).sqrt().max(1e-3);
        let next_band = settings.rejection_k * scale;
        let tilt = angle_between(&next.normal, &plane.normal);
        let shift = (next.d - plane.d).abs();
        let band_change = (next_band - band).abs() / band;
        // The plane's own uncertainty at this iteration: moves well below it
        // change nothing that matters.
        let covariance = plane_covariance(&m, &centroid, &eigen);
        let sigma_tilt = covariance.fixed_view::<3, 3>(0, 0).trace().sqrt();
        let sigma_d = covariance[(3, 3)].sqrt();
        let settled = band_change < 1e-2
            && tilt <= (0.2 * sigma_tilt).max(SETTLED_TILT)
            && shift <= (0.2 * sigma_d).max(SETTLED_SHIFT);
        tracing::trace!(
            band,
            next_band,
            tilt,
            shift,
            sigma_tilt,
            sigma_d,
            count = m.count,
            "rejection iteration"
        );
        plane = next;
        band = next_band;
        moments = m;
        // Settled: the band within 1 %, the plane within a fifth of its σ or
        // within 20 µrad and 20 µm, whichever is larger.
        if settled {
            break;
        }
    }
    Rejection {
        plane,
        band,
        moments,
        iterations,
    }
}

/// A point near the middle of the ground's sample inliers: the fit's moments
/// are taken about it, which keeps the f32 sums accurate.
fn ground_centroid(sample: &Sample, plane: &Plane, settings: &PlaneFitSettings) -> Vector3<f64> {
    let inliers: Vec<&Vector3<f64>> = sample
        .points
        .iter()
        .zip(&sample.sigma)
        .filter(|(p, s)| (plane.signed_distance(p) / *s).abs() < settings.msac_threshold_sigmas)
        .map(|(p, _)| p)
        .collect();
    if inliers.is_empty() {
        return Vector3::zeros();
    }
    inliers.iter().copied().sum::<Vector3<f64>>() / inliers.len() as f64
}

/// Fits the ground to the points of one or more frames of one pose.
pub fn fit_ground(
    clouds: &[&PointCloud],
    prior: &GroundPrior,
    settings: &PlaneFitSettings,
) -> Result<GroundFit, PlaneFitError> {
    let valid_points: usize = clouds.iter().map(|c| c.len()).sum();
    if valid_points < settings.min_points.max(3) {
        return Err(PlaneFitError::TooFewPoints {
            found: valid_points,
            needed: settings.min_points.max(3),
        });
    }

    // 1. MSAC restricted by the prior, then the lowest supported parallel plane.
    let sample = Sample::draw(clouds, settings.msac_sample_size);
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
    let mut excluded = vec![false; sample.points.len()];
    let no_ground = || PlaneFitError::NoGroundInPrior {
        tolerance_deg: prior.up_tolerance.to_degrees(),
        height: match prior.height {
            Some((h, t)) => format!(", sensor height {:.0} ± {:.0} mm", h * 1e3, t * 1e3),
            None => String::new(),
        },
    };
    let mut ground = sample
        .msac(&excluded, &mut rng, settings, |p| prior.admits(p))
        .ok_or_else(no_ground)?;
    let min_support = (settings.min_lower_support * sample.points.len() as f64).ceil() as usize;
    if ground.support < min_support.max(3) {
        return Err(no_ground());
    }
    for _ in 0..3 {
        sample.mark_inliers(&ground.plane, settings, &mut excluded);
        let above = ground.plane;
        let lower = sample.msac(&excluded, &mut rng, settings, |p| {
            prior.admits(p)
                && angle_between(&p.normal, &above.normal) < 15f64.to_radians()
                && p.d > above.d + 0.03
        });
        match lower {
            Some(h) if h.support >= min_support => ground = h,
            _ => break,
        }
    }

    // 2. Iterative eigenvector fit: on a subsample until it settles, then on
    //    every point (which then settles in a few iterations). The start band
    //    is near the rule's fixed point, about 1.5 robust σ.
    let band = 1.5 * sample.robust_scale(&ground.plane, settings);
    let reference = ground_centroid(&sample, &ground.plane, settings);
    let coarse = PointCloud::subsample(clouds, settings.coarse_stride);
    let coarse = reject_iteratively(&[&coarse], ground.plane, band, &reference, settings);
    let fine = reject_iteratively(clouds, coarse.plane, coarse.band, &reference, settings);

    // 3. Inliers, RMS and covariance from the last iteration's moments.
    let m = &fine.moments;
    let fraction = m.count as f64 / valid_points as f64;
    if fraction < settings.min_inlier_fraction {
        return Err(PlaneFitError::TooFewInliers {
            percent: 100.0 * fraction,
            min_percent: 100.0 * settings.min_inlier_fraction,
        });
    }
    let (plane, centroid, eigen) = m.plane(&reference).ok_or_else(no_ground)?;
    if !prior.admits(&plane) {
        // The refinement drifted out of the prior: the MSAC plane was a poor start.
        return Err(no_ground());
    }
    let covariance = plane_covariance(m, &centroid, &eigen);
    tracing::debug!(
        coarse = coarse.iterations,
        fine = fine.iterations,
        inliers = m.count,
        valid_points,
        band = fine.band,
        "ground fit"
    );
    Ok(GroundFit {
        plane,
        covariance,
        inliers: m.count,
        valid_points,
        rms_m: (m.distance_sq / m.count.max(1) as f64).sqrt(),
        iterations: coarse.iterations + fine.iterations,
    })
}

/// Covariance of `(a, b, c, d)` of a weighted eigenvector plane.
///
/// With weights `w = 1/σ²` (mm⁻²) the information about a tilt of the normal
/// along the scatter's eigenvector `e_k` is `10⁶·λ_k`, and about `d` is
/// `10⁶·Σw`; the variance factor `s²` comes from the normalised residuals.
fn plane_covariance(
    m: &Moments,
    centroid: &Vector3<f64>,
    eigen: &SymmetricEigen<f64, nalgebra::U3>,
) -> Matrix4<f64> {
    let dof = (m.count as f64 - 3.0).max(1.0);
    let s2 = (m.normalised_sq / dof).max(1e-12);
    let smallest = eigen.eigenvalues.imin();
    let mut cov_n = Matrix3::zeros();
    for k in 0..3 {
        if k == smallest {
            continue;
        }
        let lambda = eigen.eigenvalues[k].max(1e-12);
        let e = eigen.eigenvectors.column(k);
        cov_n += e * e.transpose() * (s2 / (1e6 * lambda));
    }
    let var_offset = s2 / (1e6 * m.weight.max(1e-12));
    // d = -n·c: its variance adds the normal's, seen through the centroid.
    let cov_nd = -(cov_n * centroid);
    let var_d = var_offset + (centroid.transpose() * cov_n * centroid)[(0, 0)];
    let mut c = Matrix4::zeros();
    c.fixed_view_mut::<3, 3>(0, 0).copy_from(&cov_n);
    c.fixed_view_mut::<3, 1>(0, 3).copy_from(&cov_nd);
    c.fixed_view_mut::<1, 3>(3, 0)
        .copy_from(&cov_nd.transpose());
    c[(3, 3)] = var_d;
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_distr_free::gaussian;

    /// Box–Muller, so the tests need no extra crate.
    mod rand_distr_free {
        use rand::Rng;
        pub fn gaussian(rng: &mut impl Rng) -> f64 {
            let u1: f64 = rng.gen_range(f64::EPSILON..1.0);
            let u2: f64 = rng.gen();
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        }
    }

    /// Points on `plane` seen by a camera looking along +X, with depth noise of
    /// `noise` times the Kinect's expected σ(z).
    fn noisy_plane_points(
        plane: &Plane,
        n: usize,
        noise: f64,
        rng: &mut ChaCha8Rng,
        cloud: &mut PointCloud,
    ) {
        let mut added = 0;
        while added < n {
            // A ray through a random pixel of a 58°×45° field of view.
            let ray = Vector3::new(1.0, rng.gen_range(-0.4..0.4), rng.gen_range(-0.5..0.5));
            let denom = plane.normal.dot(&ray);
            if denom.abs() < 1e-6 {
                continue;
            }
            let t = -plane.d / denom;
            if t <= 0.0 {
                continue;
            }
            let mut p = ray * t;
            if !(0.5..5.0).contains(&p.x) {
                continue;
            }
            p += ray * (gaussian(rng) * noise * crate::calib::sensor::depth_sigma_m(p.x) / ray.x);
            cloud.push(p);
            added += 1;
        }
    }

    fn level_prior() -> GroundPrior {
        GroundPrior::up_only(Vector3::new(-0.6, 0.8, 0.0), 30f64.to_radians())
    }

    #[test]
    fn recovers_a_noisy_tilted_ground() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let truth = Plane::from_coefficients(-0.55, 0.78, -0.3, 0.99).unwrap();
        let mut cloud = PointCloud::default();
        noisy_plane_points(&truth, 50_000, 1.5, &mut rng, &mut cloud);
        let fit = fit_ground(&[&cloud], &level_prior(), &PlaneFitSettings::default()).unwrap();
        assert!(
            fit.plane.angle_to(&truth).to_degrees() < 0.05,
            "{:?}",
            fit.plane
        );
        assert!((fit.plane.d - truth.d).abs() < 0.0005);
        assert!(
            fit.inliers as f64 > 0.75 * 50_000.0,
            "{} inliers",
            fit.inliers
        );
        // The predicted σ of the normal is of the order of the error made.
        let sigma_n = fit.covariance.fixed_view::<3, 3>(0, 0).trace().sqrt();
        assert!(sigma_n > 0.0 && sigma_n < 1e-3);
    }

    #[test]
    fn a_wall_larger_than_the_ground_does_not_win() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let ground = Plane::from_coefficients(-0.6, 0.8, 0.0, 1.0).unwrap();
        let wall = Plane::from_coefficients(-1.0, 0.0, 0.05, 2.5).unwrap();
        let mut cloud = PointCloud::default();
        noisy_plane_points(&ground, 10_000, 1.5, &mut rng, &mut cloud);
        noisy_plane_points(&wall, 30_000, 1.5, &mut rng, &mut cloud);
        let fit = fit_ground(&[&cloud], &level_prior(), &PlaneFitSettings::default()).unwrap();
        assert!(fit.plane.angle_to(&ground).to_degrees() < 0.2);
        assert!((fit.plane.d - ground.d).abs() < 0.002);
    }

    #[test]
    fn a_large_box_top_above_the_ground_does_not_win() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let ground = Plane::from_coefficients(-0.6, 0.8, 0.0, 1.0).unwrap();
        let box_top = Plane {
            normal: ground.normal,
            d: 0.7,
        };
        let mut ground_cloud = PointCloud::default();
        noisy_plane_points(&ground, 20_000, 1.5, &mut rng, &mut ground_cloud);
        let mut cloud = PointCloud::default();
        // Keep only the near part of the ground (the box hides the rest) ...
        for i in 0..ground_cloud.len() {
            if i % 2 == 0 {
                cloud.push(ground_cloud.point(i));
            }
        }
        // ... and a box top holding more points than the ground.
        noisy_plane_points(&box_top, 25_000, 1.5, &mut rng, &mut cloud);
        let fit = fit_ground(&[&cloud], &level_prior(), &PlaneFitSettings::default()).unwrap();
        assert!(
            (fit.plane.d - ground.d).abs() < 0.003,
            "fitted d = {}",
            fit.plane.d
        );
    }

    #[test]
    fn no_ground_in_the_prior_is_an_error_not_a_wrong_plane() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let wall = Plane::from_coefficients(-1.0, 0.0, 0.0, 2.0).unwrap();
        let mut cloud = PointCloud::default();
        noisy_plane_points(&wall, 5_000, 1.5, &mut rng, &mut cloud);
        let err = fit_ground(&[&cloud], &level_prior(), &PlaneFitSettings::default()).unwrap_err();
        assert!(
            matches!(err, PlaneFitError::NoGroundInPrior { .. }),
            "{err}"
        );
    }

    #[test]
    fn too_few_points_is_an_error() {
        let cloud = PointCloud::default();
        let err = fit_ground(&[&cloud], &level_prior(), &PlaneFitSettings::default()).unwrap_err();
        assert!(matches!(err, PlaneFitError::TooFewPoints { found: 0, .. }));
    }

    #[test]
    fn two_frames_fuse_into_a_better_plane_and_the_fit_is_deterministic() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let truth = Plane::from_coefficients(-0.5, 0.8, 0.2, 1.1).unwrap();
        let mut a = PointCloud::default();
        let mut b = PointCloud::default();
        noisy_plane_points(&truth, 20_000, 1.5, &mut rng, &mut a);
        noisy_plane_points(&truth, 20_000, 1.5, &mut rng, &mut b);
        let settings = PlaneFitSettings::default();
        let one = fit_ground(&[&a], &level_prior(), &settings).unwrap();
        let both = fit_ground(&[&a, &b], &level_prior(), &settings).unwrap();
        assert!(both.inliers > one.inliers);
        assert!(both.covariance[(3, 3)] < one.covariance[(3, 3)]);
        let again = fit_ground(&[&a, &b], &level_prior(), &settings).unwrap();
        assert_eq!(both, again);
    }
}
