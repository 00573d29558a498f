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
//!    least-squares plane in inverse depth (every fourth pixel both ways) and
//!    its RMS.
//!    A cell is planar when its RMS is within a few times the frame's noise,
//!    estimated as a low quantile of all cells' RMS.
//! 2. **Grouping.** Planar cells whose plane the prior admits (with some
//!    slack for a cell's own noise), nearest first, each join the largest
//!    group whose pooled plane they agree with at their four corners, or
//!    start a group. A group's plane is the least-squares plane of all its cells'
//!    pixels, so it sharpens as it grows.
//! 3. **Support.** Each group's plane is scored by the pixels of every planar
//!    cell that agrees with it; the prior is then applied strictly.
//! 4. **The lowest supported plane wins.** The best-supported admitted
//!    plane, unless a parallel plane lies lower with enough support: nothing
//!    in view lies below the ground the robot stands on, while box tops and
//!    tables lie above it. Parallel within a few degrees: a box top is as
//!    level as the floor it stands on, while the cells that straddle the
//!    line where a wall meets the floor agree on a phantom plane tilted
//!    between the two, which passes below the floor near the sensor.
//!
//! Walls and people are not planes facing up and fail the prior at step 2;
//! box tops lose at step 4. Nothing is random, so the result depends on the
//! frame alone.

use super::{GroundPrior, PlaneFitError, PlaneFitSettings};
use crate::disparity::{DisparityMoments, FitValue, Frame, PixelGrid, PixelPlane, ValueDomain};
use crate::geometry::{angle_between, Plane};

/// One cell's plane.
#[derive(Debug, Clone, Copy)]
struct Cell {
    /// Sums of the value itself (residuals to the zero plane), global offsets.
    moments: DisparityMoments,
    /// The cell's plane in the frame's value units.
    plane: PixelPlane,
    rms: f64,
    /// Pixel offsets `(u − cx, v − cy)` of the cell's centre, and half its
    /// extent.
    centre: (f64, f64),
    half: (f64, f64),
    /// Inverse depth at the cell's centre: larger is nearer.
    centre_w: f64,
}

impl Cell {
    /// Whether the cell's plane lies within `band` of `plane` at every corner
    /// (the largest difference of two planes over a rectangle is at a corner:
    /// at the centre, plus the slopes' differences times the half extents).
    fn agrees_with(&self, plane: &PixelPlane, band: f64) -> bool {
        let (du, dv) = self.centre;
        let at_centre = (self.plane.at(du, dv) - plane.at(du, dv)).abs();
        at_centre
            + (self.plane.cu - plane.cu).abs() * self.half.0
            + (self.plane.cv - plane.cv).abs() * self.half.1
            < band
    }
}

/// The zero plane: moments taken to it hold the values themselves.
const ZERO: PixelPlane = PixelPlane {
    c0: 0.0,
    cu: 0.0,
    cv: 0.0,
};

/// The ground the search found, to start the fit from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Found {
    /// In the frame's value units.
    pub plane: PixelPlane,
    /// The frame's noise in value units, from the cells.
    pub noise: f64,
}

/// Readings of each cell per side (16 in all, evenly spread): a cell's plane
/// needs only a few, and the search must cost little next to the fit.
const CELL_SAMPLES: usize = 4;

/// Every cell of the frame with enough trusted readings for a plane, and the
/// number of trusted readings looked at.
fn cells<T: FitValue>(
    frame: &Frame<T>,
    domain: &ValueDomain,
    grid: &PixelGrid,
    size: usize,
) -> (Vec<Cell>, f64) {
    let step = (size / CELL_SAMPLES).max(1);
    let size = step * CELL_SAMPLES;
    let mut out = Vec::new();
    let mut sampled = 0.0;
    let per_side = CELL_SAMPLES;
    let min_count = (per_side * per_side / 2).max(4) as f64;
    let (lo, hi) = domain.trusted;
    let cx = grid.intrinsics.cx;
    for top in (0..frame.height.saturating_sub(size - 1)).step_by(size) {
        for left in (0..frame.width.saturating_sub(size - 1)).step_by(size) {
            // Sums about the cell's first reading and centre, in f64.
            let (cu, cv) = ((left + size / 2) as f64 - cx, grid.dv(top + size / 2));
            let mut reference = None;
            let mut local = [0.0f64; 10];
            for row in (top + step / 2..top + size).step_by(step) {
                let b = grid.dv(row) - cv;
                for u in (left + step / 2..left + size).step_by(step) {
                    let value = frame.at(u, row);
                    if !(value >= lo && value <= hi) {
                        continue;
                    }
                    let value = f64::from(value);
                    let r = *reference.get_or_insert(value);
                    let (a, y) = (u as f64 - cx - cu, value - r);
                    for (sum, term) in local.iter_mut().zip([
                        1.0,
                        a,
                        b,
                        a * a,
                        a * b,
                        b * b,
                        y,
                        a * y,
                        b * y,
                        y * y,
                    ]) {
                        *sum += term;
                    }
                }
            }
            let [n, sa, sb, saa, sab, sbb, sy, say, sby, syy] = local;
            sampled += n;
            let Some(r) = reference.filter(|_| n >= min_count) else {
                continue;
            };
            // The same sums about the principal point and zero.
            let m = DisparityMoments {
                count: n,
                su: sa + n * cu,
                sv: sb + n * cv,
                suu: saa + 2.0 * cu * sa + n * cu * cu,
                suv: sab + cu * sb + cv * sa + n * cu * cv,
                svv: sbb + 2.0 * cv * sb + n * cv * cv,
                sr: sy + n * r,
                sur: say + r * sa + cu * sy + n * cu * r,
                svr: sby + r * sb + cv * sy + n * cv * r,
                srr: syy + 2.0 * r * sy + n * r * r,
            };
            // The cell's own plane, solved about its centre for accuracy.
            let centred = DisparityMoments {
                count: n,
                su: sa,
                sv: sb,
                suu: saa,
                suv: sab,
                svv: sbb,
                sr: sy,
                sur: say,
                svr: sby,
                srr: syy,
            };
            let Some((local_plane, rss)) = centred.solve_plane(&ZERO) else {
                continue;
            };
            let plane = PixelPlane {
                c0: local_plane.c0 + r - local_plane.cu * cu - local_plane.cv * cv,
                cu: local_plane.cu,
                cv: local_plane.cv,
            };
            let half = (size - 1) as f64 / 2.0;
            out.push(Cell {
                moments: m,
                plane,
                rms: (rss / (n - 3.0).max(1.0)).sqrt(),
                centre: (left as f64 + half - cx, grid.dv(top) + half),
                half: (half, half),
                centre_w: domain.offset + domain.scale * (local_plane.c0 + r),
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
    /// Pixels when the plane was last solved: it is solved again once the
    /// group has grown by a quarter.
    solved_at: f64,
}

/// The most groups kept; later cells that agree with none are ignored.
const MAX_GROUPS: usize = 48;

/// Searches the frame for the ground the prior describes.
pub fn find_ground<T: FitValue>(
    frame: &Frame<T>,
    domain: &ValueDomain,
    grid: &PixelGrid,
    prior: &GroundPrior,
    settings: &PlaneFitSettings,
    no_ground: impl Fn() -> PlaneFitError,
) -> Result<Found, PlaneFitError> {
    let intrinsics = &grid.intrinsics;
    // A plane of values in the sensor frame.
    let to_plane = |p: &PixelPlane| domain.to_inverse_depth(p).to_plane(intrinsics);
    let (all_cells, sampled) = cells(frame, domain, grid, settings.cell_size);
    if all_cells.is_empty() || sampled <= 0.0 {
        return Err(no_ground());
    }
    // The frame's noise: a low quantile of the cells' RMS, so that a view
    // mostly of people and edges does not inflate it; but not below the
    // values' rounding. A quiet sensor's cells where the ground is level
    // along the rows read one value throughout and fit exactly: a noise
    // of zero from them let no two cells agree.
    let mut rms: Vec<f64> = all_cells.iter().map(|c| c.rms).collect();
    let at = rms.len() * 3 / 10;
    let (_, &mut noise, _) = rms.select_nth_unstable_by(at, f64::total_cmp);
    let noise = noise.max(T::QUANTUM / 12f64.sqrt()).max(1e-6);
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
        .filter(|c| to_plane(&c.plane).is_some_and(|p| slack.admits(&p)))
        .collect();
    // Nearest first: their planes are the sharpest. Ties keep image order.
    candidates.sort_by(|a, b| b.centre_w.total_cmp(&a.centre_w));

    // Groups are kept largest first, and a cell joins the largest it agrees
    // with (most cells join the ground's at the first try).
    let mut groups: Vec<Group> = Vec::new();
    for cell in candidates {
        match groups
            .iter()
            .position(|g| cell.agrees_with(&g.plane, agree_band))
        {
            Some(mut i) => {
                let group = &mut groups[i];
                group.moments.add(&cell.moments);
                if group.moments.count >= 1.25 * group.solved_at {
                    if let Some((plane, _)) = group.moments.solve_plane(&ZERO) {
                        group.plane = plane;
                    }
                    group.solved_at = group.moments.count;
                }
                while i > 0 && groups[i - 1].moments.count < groups[i].moments.count {
                    groups.swap(i - 1, i);
                    i -= 1;
                }
            }
            None if groups.len() < MAX_GROUPS => groups.push(Group {
                moments: cell.moments,
                plane: cell.plane,
                solved_at: cell.moments.count,
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
    // Groups of fewer than half the pixels that can win are not scored: a
    // plane that many more cells agree with has a larger group of its own.
    let smallest = 0.5 * settings.min_ground_support.min(settings.min_lower_support) * sampled;
    let scored: Vec<Scored> = groups
        .iter_mut()
        .filter(|g| g.moments.count >= smallest)
        .filter_map(|g| {
            if let Some((plane, _)) = g.moments.solve_plane(&ZERO) {
                g.plane = plane;
            }
            let plane = to_plane(&g.plane)?;
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
    for s in &scored {
        tracing::debug!(
            normal = ?s.plane.normal.as_slice(),
            d = s.plane.d,
            support = s.support,
            "ground search: a candidate plane"
        );
    }
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
                && angle_between(&s.plane.normal, &best.plane.normal)
                    < settings.lower_parallel_deg.to_radians()
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
