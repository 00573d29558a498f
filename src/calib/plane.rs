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
            coarse_stride: 4,
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

/// Expected variance of one reading at depth `x` (along the optical axis),
/// in square millimetres: 1 mm floor plus `1.4·10⁻³·z²` (conventions.md).
#[inline(always)]
fn variance_mm2(depth_m: f32) -> f32 {
    let q = 1.4 * depth_m * depth_m;
    1.0 + q * q
}

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
        let stride = (total / size.max(1)).max(1);
        let mut points = Vec::with_capacity(size + 1);
        let mut k = 0usize;
        for cloud in clouds {
            for i in 0..cloud.len() {
                if k % stride == 0 {
                    points.push(cloud.point(i));
                }
                k += 1;
            }
        }
        let sigma = points
            .iter()
            .map(|p| f64::from(variance_mm2(p.x as f32)).sqrt() * 1e-3)
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
        for _ in 0..settings.msac_iterations {
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

    /// Accumulates every `stride`-th point of `cloud` whose normalised residual
    /// to `plane` is below `band`. Partial sums in f32 over short runs keep the
    /// loop fast; they are added up in f64.
    fn accumulate(
        &mut self,
        cloud: &PointCloud,
        plane: &Plane,
        reference: &Vector3<f64>,
        band: f64,
        stride: usize,
    ) {
        let (nx, ny, nz) = (
            plane.normal.x as f32,
            plane.normal.y as f32,
            plane.normal.z as f32,
        );
        let offset = plane.signed_distance(reference) as f32;
        let (rx, ry, rz) = (reference.x as f32, reference.y as f32, reference.z as f32);
        let band2 = (band * band) as f32;
        const RUN: usize = 512;
        let n = cloud.len();
        let mut start = 0;
        while start < n {
            let end = (start + RUN * stride).min(n);
            let mut s = [0f32; 13];
            let mut i = start;
            while i < end {
                let x = cloud.x[i] - rx;
                let y = cloud.y[i] - ry;
                let z = cloud.z[i] - rz;
                let r = nx * x + ny * y + nz * z + offset;
                let w = 1.0 / variance_mm2(cloud.x[i]);
                let r_mm2 = r * r * 1.0e6;
                let zn2 = r_mm2 * w;
                let m = if zn2 < band2 { 1.0f32 } else { 0.0 };
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
                i += stride;
            }
            let d: Vec<f64> = s.iter().map(|&v| f64::from(v)).collect();
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
    stride: usize,
) -> Moments {
    let mut total = Moments::default();
    for cloud in clouds {
        let mut m = Moments::default();
        m.accumulate(cloud, plane, reference, band, stride);
        total.add(&m);
    }
    total
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

    // 2. Iterative eigenvector fit: coarse stride until stable, then every point.
    let mut plane = ground.plane;
    let mut band = settings.msac_threshold_sigmas * sample.robust_scale(&plane, settings);
    let reference = {
        let m = moments_over(
            clouds,
            &plane,
            &Vector3::zeros(),
            band,
            settings.coarse_stride.max(8),
        );
        if m.weight > 0.0 {
            m.first / m.weight
        } else {
            Vector3::zeros()
        }
    };
    let mut iterations = 0;
    for stride in [settings.coarse_stride.max(1), 1] {
        let mut previous_count = usize::MAX;
        for _ in 0..settings.max_iterations {
            iterations += 1;
            let m = moments_over(clouds, &plane, &reference, band, stride);
            let Some((next, _, _)) = m.plane(&reference) else {
                break;
            };
            // σ of this iteration: RMS of the signed normalised residuals of the
            // inliers (errata: not of the absolute distances).
            let scale = (m.normalised_sq / m.count.max(1) as f64).sqrt().max(1e-3);
            let moved = angle_between(&next.normal, &plane.normal) + (next.d - plane.d).abs();
            plane = next;
            band = settings.rejection_k * scale;
            if m.count == previous_count && moved < 1e-9 {
                break;
            }
            previous_count = m.count;
            if stride == 1 && moved < 1e-7 {
                break;
            }
        }
        if stride == 1 {
            break;
        }
    }

    // 3. Final pass against the final plane: inliers, RMS and covariance.
    let m = moments_over(clouds, &plane, &reference, band, 1);
    let fraction = m.count as f64 / valid_points as f64;
    if fraction < settings.min_inlier_fraction {
        return Err(PlaneFitError::TooFewInliers {
            percent: 100.0 * fraction,
            min_percent: 100.0 * settings.min_inlier_fraction,
        });
    }
    let (final_plane, centroid, eigen) = m.plane(&reference).ok_or_else(no_ground)?;
    let plane = if prior.admits(&final_plane) {
        final_plane
    } else {
        plane
    };
    let covariance = plane_covariance(&m, &centroid, &eigen);
    Ok(GroundFit {
        plane,
        covariance,
        inliers: m.count,
        valid_points,
        rms_m: (m.distance_sq / m.count.max(1) as f64).sqrt(),
        iterations,
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
