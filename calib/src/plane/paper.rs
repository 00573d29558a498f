//! The paper's ground fit (section 4.1), kept so that anyone can compare it
//! with the fit in inverse depth (`--ground-fit paper`): the eigenvector
//! plane of the points in metres, weighted by the Kinect's depth noise
//! (`σ(z) ∝ z²`), with the paper's iterative rejection (σ the RMS of the
//! signed normalised residuals of the current inliers, a `k·σ` band, bounded
//! iterations), on a subsample first and then on every point.
//!
//! Total least squares assumes the same noise in every direction; the
//! Kinect's lies along each pixel's ray, so these planes come out biased
//! towards the sensor, the more so the farther the ground (docs/method.md
//! gives the figures).

use nalgebra::{Matrix3, Matrix4, SymmetricEigen, Vector3};
use wide::f32x4;

use super::{GroundFit, PlaneFitSettings};
use crate::geometry::{angle_between, Plane};
use crate::sensor::PointCloud;

/// Moves of the plane below these (20 µrad, 20 µm: a fortieth of the solve's
/// noise floor per pose) end the rejection iterations.
const SETTLED_TILT: f64 = 2e-5;
const SETTLED_SHIFT: f64 = 2e-5;

/// A subsample of the points with their expected standard deviations (m),
/// for the robust start of the rejection.
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

    /// A robust scale of the normalised residuals near `plane` (1.4826·MAD).
    fn robust_scale(&self, plane: &Plane, threshold_sigmas: f64) -> f64 {
        let band = 4.0 * threshold_sigmas;
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

    /// A point near the middle of the inliers of `plane`: the fit's moments
    /// are taken about it, which keeps the f32 sums accurate.
    fn centroid(&self, plane: &Plane, threshold_sigmas: f64) -> Vector3<f64> {
        let inliers: Vec<&Vector3<f64>> = self
            .points
            .iter()
            .zip(&self.sigma)
            .filter(|(p, s)| (plane.signed_distance(p) / *s).abs() < threshold_sigmas)
            .map(|(p, _)| p)
            .collect();
        if inliers.is_empty() {
            return Vector3::zeros();
        }
        inliers.iter().copied().sum::<Vector3<f64>>() / inliers.len() as f64
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

/// The paper's fit of the points of one pose's frames, started from the
/// plane the search found. `None` when the points do not fix a plane.
pub fn fit(
    clouds: &[&PointCloud],
    start: &Plane,
    settings: &PlaneFitSettings,
) -> Option<GroundFit> {
    let valid_points: usize = clouds.iter().map(|c| c.len()).sum();
    let sample = Sample::draw(clouds, settings.paper_sample_size);
    // The start band is near the rule's fixed point, about 1.5 robust σ.
    let band = 1.5 * sample.robust_scale(start, settings.paper_threshold_sigmas);
    let reference = sample.centroid(start, settings.paper_threshold_sigmas);
    let coarse = PointCloud::subsample(clouds, settings.paper_coarse_stride);
    let coarse = reject_iteratively(&[&coarse], *start, band, &reference, settings);
    let fine = reject_iteratively(clouds, coarse.plane, coarse.band, &reference, settings);
    let m = &fine.moments;
    let (plane, centroid, eigen) = m.plane(&reference)?;
    tracing::debug!(
        coarse = coarse.iterations,
        fine = fine.iterations,
        inliers = m.count,
        valid_points,
        band = fine.band,
        "paper ground fit"
    );
    Some(GroundFit {
        plane,
        covariance: plane_covariance(m, &centroid, &eigen),
        inliers: m.count,
        valid_points,
        rms_m: (m.distance_sq / m.count.max(1) as f64).sqrt(),
        iterations: coarse.iterations + fine.iterations,
        method: super::GroundFitMethod::Paper,
        band: super::InlierBand::Sigmas(fine.band),
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
