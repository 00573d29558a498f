//! Ground plane estimation (paper section 4.1), in the Kinect's own noise
//! domain and made robust.
//!
//! The paper fits the eigenvector plane of all points in metres and removes
//! points farther than 2σ until none is. On real scenes that fits the largest
//! plane in view, which may be a wall or a box; its σ shrinks the set without
//! end (conventions.md, errata); and total least squares in metres is biased,
//! because the Kinect's noise lies along each ray and grows as `z²`. Here:
//!
//! 1. **Search** ([`search`]): a deterministic search of the planes the prior
//!    admits, from small patches of the image in inverse depth, with the
//!    lowest supported plane winning (box tops and tables lie above the
//!    ground, nothing in view below it). It finds a floor that is a tenth of
//!    the view.
//! 2. **Fit in inverse depth** ([`crate::disparity`]): ordinary least
//!    squares of `1/z` over the pixels, where the noise is the same for every
//!    pixel: the maximum-likelihood plane, unbiased, from moment sums. The
//!    paper's 2σ rejection becomes a rejection in inverse depth with one σ
//!    for the whole frame, corrected for the truncation so that `k·σ` means
//!    what it says; iterations on every eighth row of one frame until they
//!    settle, then a pass over every second row and one (rarely more) over
//!    every pixel of every frame.
//! 3. **A covariance** of `(a, b, c, d)` from the fit, for the solve to weight
//!    by.
//!
//! The paper's own fit ([`paper`], `--ground-fit paper`) is kept to compare
//! with. Several frames of one pose are fused by summing their moments.
//! Nothing is random: the result depends on the frames alone.

mod paper;
pub mod search;

use std::fmt;
use std::str::FromStr;

use nalgebra::{Matrix4, Vector3};
use serde::{Deserialize, Serialize};

use super::disparity::{
    truncated_variance_factor, DisparityMoments, EdgeGuard, FitValue, Frame, InverseDepthImage,
    PixelGrid, ValueDomain,
};
use super::geometry::Plane;
use super::sensor::{DepthCamera, PointCloud};

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

    /// Whether a plane is one the prior allows as the ground.
    pub fn admits(&self, plane: &Plane) -> bool {
        // The cone test as a dot product (the search asks a thousand times).
        let cos = plane.normal.dot(&self.up) / (plane.normal.norm() * self.up.norm());
        if cos.is_nan() || cos < self.up_tolerance.min(std::f64::consts::PI).cos() {
            return false;
        }
        match self.height {
            Some((height, tolerance)) => (plane.d - height).abs() <= tolerance,
            None => true,
        }
    }
}

/// Which fit refines the ground once it is found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GroundFitMethod {
    /// Least squares in inverse depth, where the Kinect's noise is constant
    /// (unbiased; the default).
    #[default]
    Disparity,
    /// The paper's eigenvector fit in metres, weighted by `1/σ(z)²`.
    Paper,
}

impl GroundFitMethod {
    pub const NAMES: [&'static str; 2] = ["disparity", "paper"];

    pub fn name(self) -> &'static str {
        match self {
            GroundFitMethod::Disparity => "disparity",
            GroundFitMethod::Paper => "paper",
        }
    }
}

impl fmt::Display for GroundFitMethod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for GroundFitMethod {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "disparity" => Ok(GroundFitMethod::Disparity),
            "paper" => Ok(GroundFitMethod::Paper),
            other => Err(format!(
                "unknown ground fit '{other}' (expected disparity or paper)"
            )),
        }
    }
}

/// Tuning of the ground fit. The defaults suit a Kinect v1 at 0.5–5 m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFitSettings {
    pub method: GroundFitMethod,
    /// The paper's rejection factor: pixels beyond `k·σ` are bad points.
    pub rejection_k: f64,
    /// Upper bound on rejection iterations at each resolution.
    pub max_iterations: usize,
    /// The fit fails when fewer than this fraction of valid pixels are ground.
    pub min_inlier_fraction: f64,
    /// The fit fails with fewer valid pixels than this.
    pub min_points: usize,
    /// The search: the ground must hold at least this fraction of the pixels.
    pub min_ground_support: f64,
    /// The search: a lower parallel plane replaces the best one when it holds
    /// at least this fraction of the pixels.
    pub min_lower_support: f64,
    /// The search: a lower plane replaces the best one only when parallel
    /// to it within this many degrees (box tops are level).
    pub lower_parallel_deg: f64,
    /// The search's cells, pixels on a side.
    pub cell_size: usize,
    /// A cell is planar when its RMS is within this many times the frame's noise.
    pub planar_cell_sigmas: f64,
    /// A cell belongs to a plane when they agree within this many times the
    /// frame's noise at every corner of the cell.
    pub agreement_sigmas: f64,
    /// Slack of the prior for one cell's plane (its own noise), degrees and mm.
    pub cell_slack_deg: f64,
    pub cell_slack_mm: f64,
    /// Rows of the first frame used by the first iterations (every n-th).
    pub coarse_row_step: usize,
    /// Where the ground meets what stands on it ([`EdgeGuard`]): a pixel is
    /// fitted only if the pixel this many rows above it is within
    /// `edge_guard_sigmas` of the noise of the plane (or unread). 0: off.
    pub edge_guard_rows: usize,
    pub edge_guard_sigmas: f64,
    /// The paper's fit: points for its robust start, its start band in σ, and
    /// the stride of its first stage.
    pub paper_sample_size: usize,
    pub paper_threshold_sigmas: f64,
    pub paper_coarse_stride: usize,
}

impl Default for PlaneFitSettings {
    fn default() -> Self {
        Self {
            method: GroundFitMethod::Disparity,
            rejection_k: 2.0,
            max_iterations: 20,
            min_inlier_fraction: 0.02,
            min_points: 500,
            min_ground_support: 0.01,
            min_lower_support: 0.015,
            lower_parallel_deg: 5.0,
            cell_size: 24,
            planar_cell_sigmas: 3.0,
            agreement_sigmas: 4.0,
            cell_slack_deg: 5.0,
            cell_slack_mm: 50.0,
            coarse_row_step: 8,
            edge_guard_rows: 6,
            edge_guard_sigmas: 3.0,
            paper_sample_size: 3000,
            paper_threshold_sigmas: 3.0,
            paper_coarse_stride: 8,
        }
    }
}

/// The ground found in one pose's frames.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundFit {
    /// The ground in the sensor frame, `d > 0`.
    pub plane: Plane,
    /// Covariance of `(a, b, c, d)` (unitless normal, metres), from the
    /// inliers' residuals. It describes the random error of the fit only;
    /// the solve adds a floor for what pixels cannot show.
    pub covariance: Matrix4<f64>,
    /// Pixels that support the plane.
    pub inliers: usize,
    /// Pixels with a valid depth in the trusted range.
    pub valid_points: usize,
    /// RMS distance of the inliers to the plane, metres (for the disparity
    /// fit, its RMS in inverse depth seen at the inliers' mean depth).
    pub rms_m: f64,
    /// Rejection iterations done.
    pub iterations: usize,
    pub method: GroundFitMethod,
    /// The final rejection band: which pixels the fit took for the ground.
    pub band: InlierBand,
}

/// The band around the plane within which a fit counted a reading as the
/// ground, in the fit's own measure (the last rejection's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InlierBand {
    /// Within `band` of inverse depth (1/m) of the plane along the pixel's
    /// ray: the disparity fit's band, less the pixels its `edge_guard` left
    /// out (its limit in 1/m too).
    InverseDepth {
        band: f64,
        edge_guard: Option<EdgeGuard>,
    },
    /// Within this many σ(z) of the plane ([`crate::sensor::depth_weight`]):
    /// the paper's fit's band.
    Sigmas(f64),
}

impl GroundFit {
    /// Whether a reading (a point in the sensor frame, metres) lies in the
    /// band the fit kept: the ground as the fit saw it, edges included
    /// (the fit's edge guard also leaves out the rows just under an edge).
    pub fn holds(&self, point: &Vector3<f64>) -> bool {
        // The depth along the optical axis (x, conventions.md).
        let z = point.x;
        if z.is_nan() || z <= 0.0 || self.plane.d <= 0.0 {
            return false;
        }
        let distance = self.plane.signed_distance(point);
        match self.band {
            // Along the ray p = z·r, the plane's inverse depth is −(n·r)/d,
            // so the reading's 1/z misses it by (n·p + d)/(z·d).
            InlierBand::InverseDepth { band, .. } => (distance / (z * self.plane.d)).abs() <= band,
            InlierBand::Sigmas(band) => {
                let distance_mm = distance * 1e3;
                distance_mm * distance_mm * f64::from(super::sensor::depth_weight(z as f32))
                    < band * band
            }
        }
    }
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

/// Memory the fit reuses from pose to pose: a frame in inverse depth takes a
/// megabyte, and fresh memory costs page faults every time.
#[derive(Debug, Clone, Default)]
pub struct FitBuffers {
    images: Vec<InverseDepthImage>,
    /// Which frames `images` hold, converted by which camera (addresses:
    /// the frames are borrowed for as long as they are compared).
    converted_from: Option<(usize, Vec<(usize, usize)>)>,
    cloud: PointCloud,
    residuals: InverseDepthImage,
}

impl FitBuffers {
    /// An image for the fit's residuals ([`crate::distortion::GroundResiduals`]).
    pub fn residual_image(&mut self) -> &mut InverseDepthImage {
        &mut self.residuals
    }

    /// The frames the last [`fit_ground`] converted to inverse depth, when
    /// they were these very frames and this very camera: the residuals of a
    /// fit then read them as the fit did, with no second conversion (a
    /// corrected camera's, fitted again about a depth pattern: 13 % of such
    /// a replay's time went to converting every frame twice).
    pub fn converted_images(
        &self,
        frames: &[&[u16]],
        camera: &DepthCamera,
    ) -> Option<&[InverseDepthImage]> {
        let (from_camera, from_frames) = self.converted_from.as_ref()?;
        (*from_camera == std::ptr::from_ref(camera) as usize
            && *from_frames == frame_addresses(frames))
        .then(|| &self.images[..frames.len()])
    }
}

/// Where each frame's pixels are, and how many.
fn frame_addresses(frames: &[&[u16]]) -> Vec<(usize, usize)> {
    frames
        .iter()
        .map(|f| (f.as_ptr() as usize, f.len()))
        .collect()
}

/// Fits the ground to one pose's frames (raw values or metric units, as the
/// camera's encoding says).
pub fn fit_ground(
    frames: &[&[u16]],
    camera: &DepthCamera,
    prior: &GroundPrior,
    settings: &PlaneFitSettings,
    buffers: &mut FitBuffers,
) -> Result<GroundFit, PlaneFitError> {
    let domain = camera.value_domain();
    let width = camera.intrinsics().width;
    let height = camera.intrinsics().height;
    let frame = |values| Frame {
        values,
        width,
        height: (values.len() / width.max(1)).min(height),
    };
    let request = Request {
        pixels: frames,
        camera,
        prior,
        settings,
    };
    buffers.converted_from = None;
    if camera.fits_raw_values() {
        // Raw Kinect frames are fitted as they are: no pixel is converted.
        let raw: Vec<Frame<u16>> = frames.iter().map(|f| frame(f)).collect();
        let valid = raw.iter().map(|f| f.count_trusted(&domain)).collect();
        fit_frames(&raw, valid, &request, &mut buffers.cloud)
    } else {
        buffers
            .images
            .resize_with(frames.len(), InverseDepthImage::default);
        for (pixels, image) in frames.iter().zip(buffers.images.iter_mut()) {
            camera.inverse_depth_into(pixels, image);
        }
        buffers.converted_from =
            Some((std::ptr::from_ref(camera) as usize, frame_addresses(frames)));
        let images = &buffers.images[..frames.len()];
        let converted: Vec<Frame<f32>> = images
            .iter()
            .map(|i| Frame {
                values: &i.w,
                width: i.width,
                height: i.height,
            })
            .collect();
        let valid = images.iter().map(|i| i.valid).collect();
        fit_frames(&converted, valid, &request, &mut buffers.cloud)
    }
}

/// What [`fit_ground`] was asked: the frames as they came, and how to read
/// and judge them.
struct Request<'a> {
    pixels: &'a [&'a [u16]],
    camera: &'a DepthCamera,
    prior: &'a GroundPrior,
    settings: &'a PlaneFitSettings,
}

/// The fit of frames in one value domain (`valid`: each frame's trusted
/// pixels): search, then refine.
fn fit_frames<T: FitValue>(
    frames: &[Frame<T>],
    valid: Vec<usize>,
    request: &Request,
    cloud: &mut PointCloud,
) -> Result<GroundFit, PlaneFitError> {
    let Request {
        pixels,
        camera,
        prior,
        settings,
    } = *request;
    let domain = camera.value_domain();
    let valid_points: usize = valid.iter().sum();
    let needed = settings.min_points.max(3);
    if valid_points < needed || frames.is_empty() {
        return Err(PlaneFitError::TooFewPoints {
            found: valid_points,
            needed,
        });
    }
    let no_ground = || PlaneFitError::NoGroundInPrior {
        tolerance_deg: prior.up_tolerance.to_degrees(),
        height: match prior.height {
            Some((h, t)) => format!(", sensor height {:.0} ± {:.0} mm", h * 1e3, t * 1e3),
            None => String::new(),
        },
    };
    let grid = camera.grid();
    // The search looks at the frame with the most readings.
    let searched =
        (0..frames.len()).fold(0, |best, i| if valid[i] > valid[best] { i } else { best });
    let found = search::find_ground(&frames[searched], &domain, grid, prior, settings, no_ground)?;

    let fit = match settings.method {
        GroundFitMethod::Disparity => {
            fit_in_inverse_depth(frames, searched, &domain, grid, &found, settings)
                .ok_or_else(no_ground)?
        }
        GroundFitMethod::Paper => {
            let start = domain
                .to_inverse_depth(&found.plane)
                .to_plane(&grid.intrinsics)
                .ok_or_else(no_ground)?;
            cloud.clear();
            for frame in pixels {
                camera.append_points(frame, cloud);
            }
            paper::fit(&[cloud], &start, settings).ok_or_else(no_ground)?
        }
    };
    let fraction = fit.inliers as f64 / valid_points as f64;
    if fraction < settings.min_inlier_fraction {
        return Err(PlaneFitError::TooFewInliers {
            percent: 100.0 * fraction,
            min_percent: 100.0 * settings.min_inlier_fraction,
        });
    }
    if !prior.admits(&fit.plane) {
        // The refinement drifted out of the prior: the start was a poor one.
        return Err(no_ground());
    }
    Ok(GroundFit {
        valid_points,
        ..fit
    })
}

/// Fewest passes over the frames, and most: the first over every second row,
/// the others over every row.
const FINE_PASSES: (usize, usize) = (2, 4);

/// Least squares in inverse depth (in the frames' value units, which are
/// affine in it) with the rejection of the paper, from the plane the search
/// found.
fn fit_in_inverse_depth<T: FitValue>(
    frames: &[Frame<T>],
    first: usize,
    domain: &ValueDomain,
    grid: &PixelGrid,
    found: &search::Found,
    settings: &PlaneFitSettings,
) -> Option<GroundFit> {
    let intrinsics = &grid.intrinsics;
    let k = settings.rejection_k;
    let mut plane = found.plane;
    let mut sigma = found.noise;
    // Start wide (the search's plane is a few cells' worth), never wider than
    // this: past it, the band would take in what lies on the ground.
    let mut band = 2.0 * k * sigma;
    let widest = 4.0 * band;
    let mut iterations = 0;
    let guard = |sigma: f64| {
        (settings.edge_guard_rows > 0).then_some(EdgeGuard {
            rows: settings.edge_guard_rows,
            limit: settings.edge_guard_sigmas * sigma,
        })
    };

    // 1. One frame, every few rows, until the plane and the band settle.
    for _ in 0..settings.max_iterations.max(1) {
        iterations += 1;
        let m = grid.moments_within(
            &frames[first],
            domain,
            &plane,
            band,
            0,
            settings.coarse_row_step,
            guard(sigma),
        );
        let (next_plane, rss) = m.solve_plane(&plane)?;
        // σ of the kept residuals, corrected for the truncation at ±band.
        let kept = (rss / (m.count - 3.0).max(1.0)).max(1e-18);
        let next_sigma = (kept / truncated_variance_factor(band / sigma)).sqrt();
        let next_band = (k * next_sigma).min(widest);
        let moved = next_plane.largest_difference(&plane, intrinsics);
        let settled = moved < 0.05 * next_sigma && (next_band - band).abs() < 0.01 * band;
        plane = next_plane;
        sigma = next_sigma;
        band = next_band;
        if settled {
            break;
        }
    }

    // 2. Every frame: every second row, then every row, until the plane
    //    moves by less than a fifth of a pixel's noise anywhere in the
    //    image. The pass on every row is the one kept; the one before it
    //    centres its band, so that the result hardly depends on where the
    //    subsample put it.
    let mut last = None;
    for pass in 0..FINE_PASSES.1 {
        iterations += 1;
        let row_step = if pass == 0 { 2 } else { 1 };
        let mut m = DisparityMoments::default();
        for frame in frames {
            m.add(&grid.moments_within(frame, domain, &plane, band, 0, row_step, guard(sigma)));
        }
        let correction = m.solve(&plane)?;
        let moved = correction.plane.largest_difference(&plane, intrinsics);
        last = Some((m, plane, correction));
        plane = correction.plane;
        if pass + 1 >= FINE_PASSES.0 && moved < 0.2 * sigma {
            break;
        }
    }
    let (m, taken_to, correction) = last?;

    // 3. The plane, its covariance and its residuals, in inverse depth.
    let dof = (m.count - 3.0).max(1.0);
    let variance = correction.rss / dof;
    let in_inverse_depth = domain.to_inverse_depth(&correction.plane);
    let covariance = in_inverse_depth.plane_covariance(
        intrinsics,
        &(correction.inverse_information * (variance * domain.scale * domain.scale)),
    )?;
    let result = in_inverse_depth.to_plane(intrinsics)?;
    // Mean inverse depth of the inliers, to express the RMS in metres.
    let mean_value =
        (m.count * taken_to.c0 + taken_to.cu * m.su + taken_to.cv * m.sv + m.sr) / m.count.max(1.0);
    let mean_w = domain.offset + domain.scale * mean_value;
    tracing::debug!(
        iterations,
        inliers = m.count,
        band,
        sigma,
        "ground fit in inverse depth"
    );
    Some(GroundFit {
        plane: result,
        covariance,
        inliers: m.count as usize,
        valid_points: 0,
        rms_m: variance.sqrt() * domain.scale.abs() / (mean_w * mean_w).max(1e-12),
        iterations,
        method: GroundFitMethod::Disparity,
        band: InlierBand::InverseDepth {
            band: band * domain.scale.abs(),
            edge_guard: guard(sigma).map(|g| EdgeGuard {
                limit: g.limit * domain.scale.abs(),
                ..g
            }),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::{DepthEncoding, DepthModel, DepthRange, Intrinsics, RAW_NO_READING};
    use crate::test_noise::gaussian;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn camera() -> DepthCamera {
        DepthCamera::new(
            DepthEncoding::Raw11(DepthModel::inverse_linear_default()),
            Intrinsics::default(),
            DepthRange::default(),
        )
    }

    /// A raw frame of a scene: for each pixel, the nearest of the planes that
    /// `owner(u, v)` allows, with the Kinect's noise in disparity (half a raw
    /// step) and quantised as the Kinect does.
    fn render(
        planes: &[Plane],
        owner: impl Fn(usize, usize) -> Vec<usize>,
        rng: &mut ChaCha8Rng,
    ) -> Vec<u16> {
        render_with_noise(planes, owner, rng, 0.46)
    }

    /// [`render`] with `noise_raw` raw units of noise in disparity.
    fn render_with_noise(
        planes: &[Plane],
        owner: impl Fn(usize, usize) -> Vec<usize>,
        rng: &mut ChaCha8Rng,
        noise_raw: f64,
    ) -> Vec<u16> {
        let i = Intrinsics::default();
        let (a, b) = DepthModel::inverse_linear_default().inverse_depth_affine();
        let mut raw = vec![RAW_NO_READING; i.width * i.height];
        for v in 0..i.height {
            for u in 0..i.width {
                let ray = Vector3::new(1.0, -(v as f64 - i.cy) / i.fy, (u as f64 - i.cx) / i.fx);
                let z = owner(u, v)
                    .into_iter()
                    .filter_map(|k| {
                        let p = &planes[k];
                        let z = -p.d / p.normal.dot(&ray);
                        (z > 0.0).then_some(z)
                    })
                    .fold(f64::INFINITY, f64::min);
                if !(0.5..5.0).contains(&z) {
                    continue;
                }
                let w = 1.0 / z + noise_raw * b.abs() * gaussian(rng);
                raw[v * i.width + u] = ((w - a) / b).round().clamp(0.0, 2046.0) as u16;
            }
        }
        raw
    }

    fn ground() -> Plane {
        Plane::from_coefficients(-0.6, 0.8, 0.05, 1.0).unwrap()
    }

    fn prior() -> GroundPrior {
        GroundPrior {
            up: Vector3::new(-0.55, 0.83, 0.0).normalize(),
            up_tolerance: 15f64.to_radians(),
            height: Some((1.05, 0.2)),
        }
    }

    fn fit(frames: &[&[u16]], method: GroundFitMethod) -> Result<GroundFit, PlaneFitError> {
        let settings = PlaneFitSettings {
            method,
            ..Default::default()
        };
        fit_ground(
            frames,
            &camera(),
            &prior(),
            &settings,
            &mut FitBuffers::default(),
        )
    }

    #[test]
    fn recovers_a_noisy_tilted_ground_with_both_fits() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let truth = ground();
        let raw = render(&[truth], |_, _| vec![0], &mut rng);
        for method in [GroundFitMethod::Disparity, GroundFitMethod::Paper] {
            let fit = fit(&[&raw], method).unwrap();
            assert_eq!(fit.method, method);
            assert!(
                fit.plane.angle_to(&truth).to_degrees() < 0.02,
                "{method}: {:?}",
                fit.plane
            );
            assert!(
                (fit.plane.d - truth.d).abs() < 0.0005,
                "{method}: {:?}",
                fit.plane
            );
            assert!(
                fit.inliers as f64 > 0.75 * fit.valid_points as f64,
                "{method}"
            );
            // The predicted σ of the normal is small but not zero.
            let sigma_n = fit.covariance.fixed_view::<3, 3>(0, 0).trace().sqrt();
            assert!(sigma_n > 0.0 && sigma_n < 1e-3, "{method}: {sigma_n}");
        }
    }

    /// A quiet sensor must not lose the ground. With little noise and the
    /// ground level along the image's rows, many of the search's cells
    /// read one raw value throughout: their planes fit exactly, and a
    /// noise taken from the cells alone came out near zero, so no two
    /// cells agreed and no ground was found (seen on the simulator at a
    /// fifth of the Kinect's noise, the body pitched 11.3°). The raw
    /// values' rounding is noise of 1/√12 of a step at least.
    #[test]
    fn a_quiet_sensor_and_a_ground_level_along_the_rows_are_found() {
        // Seen 21° below the optical axis, 1.12 m away, as in the simulator.
        let level = Plane::from_coefficients(-0.355, 0.935, 0.0, 1.12).unwrap();
        for noise_raw in [0.0, 0.05, 0.1] {
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            let raw = render_with_noise(&[level], |_, _| vec![0], &mut rng, noise_raw);
            // The paper's fit, in metres, takes the undithered rounding's
            // steps (several millimetres at 3 m) as they come: found, but
            // not as close.
            for (method, degrees, metres) in [
                (GroundFitMethod::Disparity, 0.02, 0.0005),
                (GroundFitMethod::Paper, 0.05, 0.002),
            ] {
                let fit = fit(&[&raw], method)
                    .unwrap_or_else(|e| panic!("noise {noise_raw} raw, {method}: {e}"));
                assert!(
                    fit.plane.angle_to(&level).to_degrees() < degrees
                        && (fit.plane.d - level.d).abs() < metres,
                    "noise {noise_raw} raw, {method}: {:?}",
                    fit.plane
                );
            }
        }
    }

    #[test]
    fn the_disparity_fit_predicts_its_own_error() {
        // Over seeds, the error of d has the spread the covariance says.
        let truth = ground();
        let mut z2 = 0.0;
        let runs = 12;
        for seed in 0..runs {
            let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
            let raw = render(&[truth], |_, _| vec![0], &mut rng);
            let fit = fit(&[&raw], GroundFitMethod::Disparity).unwrap();
            z2 += (fit.plane.d - truth.d).powi(2) / fit.covariance[(3, 3)];
        }
        let ratio = (z2 / runs as f64).sqrt();
        assert!((0.4..2.0).contains(&ratio), "error / predicted σ = {ratio}");
    }

    #[test]
    fn a_wall_larger_than_the_ground_does_not_win() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let wall = Plane::from_coefficients(-1.0, 0.0, 0.05, 2.5).unwrap();
        // The wall fills everything above row 330.
        let raw = render(
            &[ground(), wall],
            |_, v| if v < 330 { vec![1] } else { vec![0] },
            &mut rng,
        );
        let fit = fit(&[&raw], GroundFitMethod::Disparity).unwrap();
        assert!(fit.plane.angle_to(&ground()).to_degrees() < 0.1);
        assert!((fit.plane.d - ground().d).abs() < 0.002);
    }

    #[test]
    fn a_large_box_top_above_the_ground_does_not_win() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let box_top = Plane {
            normal: ground().normal,
            d: 0.8,
        };
        // The box top holds the middle 60 % of the columns.
        let raw = render(
            &[ground(), box_top],
            |u, _| {
                if (128..512).contains(&u) {
                    vec![1]
                } else {
                    vec![0]
                }
            },
            &mut rng,
        );
        let fit = fit(&[&raw], GroundFitMethod::Disparity).unwrap();
        assert!(
            (fit.plane.d - ground().d).abs() < 0.002,
            "fitted d = {}",
            fit.plane.d
        );
    }

    #[test]
    fn a_floor_that_is_a_tenth_of_the_view_is_found() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        // Walls left and right, and people (vertical planes facing the
        // sensor) in between: the floor shows in a strip at the bottom and
        // in the gaps between people.
        let left = Plane::from_coefficients(-0.2, 0.0, 1.0, 0.6).unwrap();
        let right = Plane::from_coefficients(-0.2, 0.0, -1.0, 0.6).unwrap();
        let people = Plane::from_coefficients(-1.0, 0.0, 0.1, 1.6).unwrap();
        let raw = render(
            &[ground(), left, right, people],
            |u, v| {
                if u < 150 {
                    vec![1]
                } else if u >= 490 {
                    vec![2]
                } else if v < 400 && (u / 40) % 4 != 0 {
                    vec![3]
                } else if v < 400 {
                    vec![0, 3]
                } else {
                    vec![0]
                }
            },
            &mut rng,
        );
        let fit = fit(&[&raw], GroundFitMethod::Disparity).unwrap();
        let share = fit.inliers as f64 / fit.valid_points as f64;
        assert!(
            share < 0.15,
            "the floor is {:.0} % of the view",
            share * 100.0
        );
        assert!(fit.plane.angle_to(&ground()).to_degrees() < 0.1);
        assert!((fit.plane.d - ground().d).abs() < 0.002);
    }

    #[test]
    fn no_ground_in_the_prior_is_an_error_not_a_wrong_plane() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let wall = Plane::from_coefficients(-1.0, 0.0, 0.0, 2.0).unwrap();
        let raw = render(&[wall], |_, _| vec![0], &mut rng);
        let err = fit(&[&raw], GroundFitMethod::Disparity).unwrap_err();
        assert!(
            matches!(err, PlaneFitError::NoGroundInPrior { .. }),
            "{err}"
        );
    }

    #[test]
    fn too_few_points_is_an_error() {
        let raw = vec![RAW_NO_READING; 640 * 480];
        let err = fit(&[&raw], GroundFitMethod::Disparity).unwrap_err();
        assert!(matches!(err, PlaneFitError::TooFewPoints { found: 0, .. }));
    }

    #[test]
    fn two_frames_fuse_into_a_better_plane_and_the_fit_is_deterministic() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let a = render(&[ground()], |_, _| vec![0], &mut rng);
        let b = render(&[ground()], |_, _| vec![0], &mut rng);
        let one = fit(&[&a], GroundFitMethod::Disparity).unwrap();
        let both = fit(&[&a, &b], GroundFitMethod::Disparity).unwrap();
        assert!(both.inliers > one.inliers);
        assert!(both.covariance[(3, 3)] < one.covariance[(3, 3)]);
        let again = fit(&[&a, &b], GroundFitMethod::Disparity).unwrap();
        assert_eq!(both, again);
    }

    #[test]
    fn method_names_parse_and_print() {
        for name in GroundFitMethod::NAMES {
            assert_eq!(name.parse::<GroundFitMethod>().unwrap().to_string(), name);
        }
        assert!("ransac"
            .parse::<GroundFitMethod>()
            .unwrap_err()
            .contains("ransac"));
    }
}
