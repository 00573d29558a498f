//! Finding the ground before fitting it: a deterministic search over the
//! planes the prior admits, from small patches of the image.
//!
//! Blind three-point sampling (RANSAC, MSAC) needs about 7,000 draws to find
//! a floor that holds a tenth of the view with 99.9 % confidence, and its
//! answer depends on a seed. Stereo vision finds the road in disparity
//! instead (v-disparity): in the disparity domain a plane is a plane of the
//! image, the same for near and far pixels, so it can be found by grouping.
//!
//! 1. **Cells.** The frame is cut into `cell_size`² cells; each cell's own
//!    least-squares plane in inverse depth (every second pixel) and its RMS.
//!    A cell is planar when its RMS is within a few times the frame's noise,
//!    estimated as a low quantile of all cells' RMS.
//! 2. **Grouping.** Planar cells whose plane the prior admits (with some
//!    slack for a cell's own noise), nearest first, each join the first group
//!    whose pooled plane they agree with at their four corners, or start a
//!    group. A group's plane is the least-squares plane of all its cells'
//!    pixels, so it sharpens as it grows.
//! 3. **Support.** Each group's plane is scored by the pixels of every planar
//!    cell that agrees with it; the prior is then applied strictly.
//! 4. **The lowest supported plane wins.** The best-supported admitted
//!    plane, unless a parallel plane lies lower with enough support: nothing
//!    in view lies below the ground the robot stands on, while box tops and
//!    tables lie above it.
//!
//! Walls and people are not planes facing up and fail the prior at step 2;
//! box tops lose at step 4. Nothing is random, so the result depends on the
//! frame alone.

use super::{GroundPrior, PlaneFitError, PlaneFitSettings};
use crate::calib::disparity::{DisparityMoments, InverseDepthImage, PixelGrid, PixelPlane};
use crate::calib::geometry::{angle_between, Plane};

/// One cell's plane.
#[derive(Debug, Clone, Copy)]
struct Cell {
    /// Sums of `w` itself (residuals to the zero plane), global offsets.
    moments: DisparityMoments,
    plane: PixelPlane,
    rms: f64,
    /// Pixel offsets `(u − cx, v − cy)` of the cell's corners.
    corners: [(f64, f64); 4],
    /// Inverse depth at the cell's centre: larger is nearer.
    centre_w: f64,
}

impl Cell {
    /// Whether the cell's plane lies within `band` of `plane` at every corner.
    fn agrees_with(&self, plane: &PixelPlane, band: f64) -> bool {
        self.corners
            .iter()
            .all(|&(du, dv)| (self.plane.at(du, dv) - plane.at(du, dv)).abs() < band)
    }
}

/// The zero plane: moments taken to it hold `w` itself.
const ZERO: PixelPlane = PixelPlane {
    c0: 0.0,
    cu: 0.0,
    cv: 0.0,
};

/// The ground the search found, to start the fit from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Found {
    pub plane: PixelPlane,
    /// The frame's noise in inverse depth, 1/m, from the cells.
    pub noise: f64,
}

/// Every cell of the frame with enough readings for a plane.
fn cells(image: &InverseDepthImage, grid: &PixelGrid, size: usize) -> (Vec<Cell>, f64) {
    let size = size.max(4);
    let mut out = Vec::new();
    let mut sampled = 0.0;
    let step = 2;
    let min_count = (size / step) * (size / step) / 2;
    let cx = grid.intrinsics.cx;
    for top in (0..image.height.saturating_sub(size - 1)).step_by(size) {
        for left in (0..image.width.saturating_sub(size - 1)).step_by(size) {
            let mut m = DisparityMoments::default();
            for row in (top..top + size).step_by(step) {
                let dv = grid.dv(row);
                let mut row_sums = [0.0f64; 6];
                for u in (left..left + size).step_by(step) {
                    let w = image.w[row * image.width + u];
                    if w.is_finite() {
                        let (du, w) = (u as f64 - cx, f64::from(w));
                        row_sums[0] += 1.0;
                        row_sums[1] += du;
                        row_sums[2] += du * du;
                        row_sums[3] += w;
                        row_sums[4] += du * w;
                        row_sums[5] += w * w;
                    }
                }
                let mut row_moments = DisparityMoments::default();
                let [n, su, suu, sr, sur, srr] = row_sums;
                row_moments.count = n;
                row_moments.su = su;
                row_moments.sv = dv * n;
                row_moments.suu = suu;
                row_moments.suv = dv * su;
                row_moments.svv = dv * dv * n;
                row_moments.sr = sr;
                row_moments.sur = sur;
                row_moments.svr = dv * sr;
                row_moments.srr = srr;
                m.add(&row_moments);
            }
            sampled += m.count;
            if m.count < min_count as f64 {
                continue;
            }
            let Some(fit) = m.solve(&ZERO) else {
                continue;
            };
            let (u0, u1) = (left as f64 - cx, (left + size - 1) as f64 - cx);
            let (v0, v1) = (grid.dv(top), grid.dv(top + size - 1));
            let centre = ((u0 + u1) / 2.0, (v0 + v1) / 2.0);
            out.push(Cell {
                moments: m,
                plane: fit.plane,
                rms: (fit.rss / (m.count - 3.0).max(1.0)).sqrt(),
                corners: [(u0, v0), (u0, v1), (u1, v0), (u1, v1)],
                centre_w: fit.plane.at(centre.0, centre.1),
            });
        }
    }
    (out, sampled)
}

/// A group of cells and its pooled plane.
#[derive(Debug, Clone, Copy)]
struct Group {
    moments: DisparityMoments,
    plane: PixelPlane,
}

/// The most groups kept; later cells that agree with none are ignored.
const MAX_GROUPS: usize = 48;

/// Searches the frame for the ground the prior describes.
pub fn find_ground(
    image: &InverseDepthImage,
    grid: &PixelGrid,
    prior: &GroundPrior,
    settings: &PlaneFitSettings,
    no_ground: impl Fn() -> PlaneFitError,
) -> Result<Found, PlaneFitError> {
    let intrinsics = &grid.intrinsics;
    let (all_cells, sampled) = cells(image, grid, settings.cell_size);
    if all_cells.is_empty() || sampled <= 0.0 {
        return Err(no_ground());
    }
    // The frame's noise: a low quantile of the cells' RMS, so that a view
    // mostly of people and edges does not inflate it.
    let mut rms: Vec<f64> = all_cells.iter().map(|c| c.rms).collect();
    let at = rms.len() * 3 / 10;
    let (_, &mut noise, _) = rms.select_nth_unstable_by(at, f64::total_cmp);
    let noise = noise.max(1e-6);
    let planar_limit = settings.planar_cell_sigmas * noise;
    let agree_band = settings.agreement_sigmas * noise;

    // Cells the prior admits, with slack for a small cell's noisy plane.
    let slack = GroundPrior {
        up: prior.up,
        up_tolerance: prior.up_tolerance + settings.cell_slack_deg.to_radians(),
        height: prior
            .height
            .map(|(h, t)| (h, t + settings.cell_slack_mm * 1e-3)),
    };
    let planar: Vec<&Cell> = all_cells.iter().filter(|c| c.rms <= planar_limit).collect();
    let mut candidates: Vec<&Cell> = planar
        .iter()
        .copied()
        .filter(|c| {
            c.plane
                .to_plane(intrinsics)
                .is_some_and(|p| slack.admits(&p))
        })
        .collect();
    // Nearest first: their planes are the sharpest. Ties keep image order.
    candidates.sort_by(|a, b| b.centre_w.total_cmp(&a.centre_w));

    let mut groups: Vec<Group> = Vec::new();
    for cell in candidates {
        match groups
            .iter()
            .position(|g| cell.agrees_with(&g.plane, agree_band))
        {
            Some(i) => {
                let group = &mut groups[i];
                group.moments.add(&cell.moments);
                if let Some(fit) = group.moments.solve(&ZERO) {
                    group.plane = fit.plane;
                }
            }
            None if groups.len() < MAX_GROUPS => groups.push(Group {
                moments: cell.moments,
                plane: cell.plane,
            }),
            None => {}
        }
    }

    // Support of each group's plane among all planar cells, and the prior.
    struct Scored {
        pixel: PixelPlane,
        plane: Plane,
        support: f64,
    }
    let scored: Vec<Scored> = groups
        .iter()
        .filter_map(|g| {
            let plane = g.plane.to_plane(intrinsics)?;
            if !prior.admits(&plane) {
                return None;
            }
            let support = planar
                .iter()
                .filter(|c| c.agrees_with(&g.plane, agree_band))
                .map(|c| c.moments.count)
                .sum::<f64>()
                / sampled;
            Some(Scored {
                pixel: g.plane,
                plane,
                support,
            })
        })
        .collect();
    let best = scored
        .iter()
        .filter(|s| s.support >= settings.min_ground_support)
        .fold(None::<&Scored>, |best, s| match best {
            Some(b) if b.support >= s.support => Some(b),
            _ => Some(s),
        })
        .ok_or_else(&no_ground)?;
    // The lowest well-supported plane parallel to the best one.
    let lowest = scored
        .iter()
        .filter(|s| {
            s.support >= settings.min_lower_support
                && angle_between(&s.plane.normal, &best.plane.normal) < 15f64.to_radians()
                && s.plane.d > best.plane.d + 0.03
        })
        .fold(best, |low, s| if s.plane.d > low.plane.d { s } else { low });
    tracing::trace!(
        cells = all_cells.len(),
        planar = planar.len(),
        groups = groups.len(),
        support = lowest.support,
        noise,
        "ground search"
    );
    Ok(Found {
        plane: lowest.pixel,
        noise,
    })
}
