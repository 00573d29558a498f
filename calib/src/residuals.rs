//! One pose's ground residuals per cell of the image: what the depth
//! pattern's estimate ([`crate::distortion`]) needs from a pose, taken
//! while its frames are in memory (sums, not pixels, so that no frame is
//! kept).

use nalgebra::{Matrix3, Matrix4, Vector3};

use crate::depth::Intrinsics;
use crate::disparity::{
    clear_above, lane_sum, EdgeGuard, FitValue, InverseDepthImage, PixelPlane, ValueDomain,
};
use crate::geometry::Plane;
use crate::noise_with_depth::ScatterWithDepth;
use crate::plane::{GroundFit, InlierBand};
use crate::sensor::DepthCamera;

/// Every this many rows are summed: a cell then has 32 readings a frame,
/// its mean a σ of under 0.01 raw units over a calibration's poses, and the
/// pass costs about as much as the fit.
const ROW_STEP: usize = 2;

/// The side of a cell of the pattern, pixels: 80 × 60 cells on a Kinect's
/// 640 × 480 image, fine enough for stripes 48 pixels apart.
pub const CELL_PX: usize = 8;

/// The centre of cell `k` of a grid `columns` cells wide, in pixels from the
/// principal point (`u − cx`, `v − cy`): the one place the pattern's cells
/// meet the image's coordinates.
pub fn cell_centre(k: usize, columns: usize, intrinsics: &Intrinsics) -> (f64, f64) {
    centre_of(k % columns, k / columns, intrinsics)
}

/// [`cell_centre`] from the cell's column and row.
#[inline]
fn centre_of(column: usize, row: usize, intrinsics: &Intrinsics) -> (f64, f64) {
    let half = (CELL_PX as f64 - 1.0) / 2.0;
    (
        (column * CELL_PX) as f64 + half - intrinsics.cx,
        (row * CELL_PX) as f64 + half - intrinsics.cy,
    )
}

/// The residuals are taken within this many times the fit's band (±2σ):
/// where the pattern lifts the readings by a σ, the fit's own band cuts
/// their upper tail and the cells' means would show the pattern smaller
/// than it is; at ±4σ the loss is under 1 %.
const WIDER_BAND: f64 = 2.0;

/// One cell's sums over a pose's ground readings as the pass makes them:
/// residual `r` (1/m), its square, and pixel offsets `u' = u − cx`,
/// `v' = v − cy`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct CellSums {
    pub(crate) n: f64,
    pub(crate) r: f64,
    pub(crate) rr: f64,
    pub(crate) u: f64,
    pub(crate) v: f64,
}

/// One cell's sums at one pose as the pattern's estimate reads them:
/// readings, residuals (1/m) and pixel offsets, as in [`CellSums`]; the
/// squares are read once, when the pose's residuals are made
/// ([`GroundResiduals::reading_scatter`], [`GroundResiduals::scatter_with_depth`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct GroundCell {
    pub(crate) n: f64,
    pub(crate) r: f64,
    pub(crate) u: f64,
    pub(crate) v: f64,
}

/// [`GroundCell`] as a pose keeps it until the calibration's end: 12 bytes
/// where five f64 sums were 40, and a calibration keeps 4,800 a pose (52
/// poses' were 10 MB, half of a replay's heap at its peak). The count and
/// the residuals' sum in f32 (a relative rounding of 6·10⁻⁸, far below a
/// cell mean's noise; counts are whole numbers, exact below 2²⁴); the
/// readings' centre as its offset from the cell's centre, in steps of
/// [`CENTRE_STEP_PX`] (the centre lies within the cell's 8 pixels).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct KeptCell {
    n: f32,
    r: f32,
    du: i16,
    dv: i16,
}

/// The step of a kept cell's centre offset, pixels: 1/8192, so that ±4
/// pixels fit an i16 and the centre is rounded by at most 6·10⁻⁵ pixels
/// (where the f32 sums it replaced rounded it by up to 2·10⁻⁵).
const CENTRE_STEP_PX: f64 = 1.0 / 8192.0;

impl KeptCell {
    /// `sums` of the cell whose centre is `centre` (pixels from the
    /// principal point).
    fn new(sums: &CellSums, centre: (f64, f64)) -> Self {
        if sums.n <= 0.0 {
            return Self::default();
        }
        let per_reading = 1.0 / sums.n;
        // To the nearest step (half away from 0; the cast saturates).
        let offset = |sum: f64, centre: f64| {
            let steps = (sum * per_reading - centre) / CENTRE_STEP_PX;
            (steps + 0.5f64.copysign(steps)) as i16
        };
        Self {
            n: sums.n as f32,
            r: sums.r as f32,
            du: offset(sums.u, centre.0),
            dv: offset(sums.v, centre.1),
        }
    }

    /// The sums again, for the cell whose centre is `centre`.
    #[inline]
    fn sums(&self, centre: (f64, f64)) -> GroundCell {
        let n = f64::from(self.n);
        GroundCell {
            n,
            r: f64::from(self.r),
            u: n * (centre.0 + f64::from(self.du) * CENTRE_STEP_PX),
            v: n * (centre.1 + f64::from(self.dv) * CENTRE_STEP_PX),
        }
    }
}

/// [`GroundResiduals::cells`]: the cell the walk is at and its place, each
/// cell's centre counted along the rows rather than found from its number.
pub(crate) struct EachCell<'a> {
    residuals: &'a GroundResiduals,
    k: usize,
    column: usize,
    row: usize,
}

impl Iterator for EachCell<'_> {
    type Item = GroundCell;

    #[inline]
    fn next(&mut self) -> Option<GroundCell> {
        let kept = self.residuals.cells.get(self.k)?;
        let cell = kept.sums(centre_of(self.column, self.row, &self.residuals.intrinsics));
        self.k += 1;
        self.column += 1;
        if self.column == self.residuals.columns {
            (self.column, self.row) = (0, self.row + 1);
        }
        Some(cell)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let left = self.residuals.cells.len() - self.k;
        (left, Some(left))
    }
}

impl ExactSizeIterator for EachCell<'_> {}

/// What a pose's residuals measure of the readings' scatter, beyond the
/// pooled scatter every calibration needs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum ScatterMeasured {
    /// The pooled scatter only.
    #[default]
    Pooled,
    /// And the cells' scatter against the ground's depth
    /// ([`crate::noise_with_depth`], for a camera of unknown kind): two
    /// logarithms a cell, 0.14 ms a pose, which a Kinect's calibration
    /// does not need.
    AlsoWithDepth,
}

/// One pose's ground residuals, summed per cell: what the pattern's
/// estimate needs from a pose, taken while its frames are in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundResiduals {
    pub(crate) columns: usize,
    pub(crate) rows: usize,
    cells: Vec<KeptCell>,
    /// The readings' scatter about their cells' means, `Σ(Σr² − (Σr)²/n)`
    /// over the cells of two readings or more, and its degrees of freedom
    /// `Σ(n − 1)`.
    reading_scatter: (f64, f64),
    /// The cells' scatter against the ground's depth, where measured.
    scatter_with_depth: Option<ScatterWithDepth>,
    /// Σφφᵀ over the pose's ground readings, φ = (1, u', v').
    pub(crate) moments: Matrix3<f64>,
    /// Σ r·φ.
    pub(crate) rhs: Vector3<f64>,
    pub(crate) intrinsics: Intrinsics,
    /// Raw units per 1/m of inverse depth (the depth model's `1/b`).
    pub(crate) raw_per_inverse_depth: f64,
    /// The fit's own rejection band (1/m): the readings it took for the
    /// ground lay within it of its plane.
    pub(crate) fit_band: f64,
    /// The fit's plane in inverse depth (1/m, pixels from the principal
    /// point): the ground's depth at each cell, for a pattern that changes
    /// with depth.
    pub(crate) plane: PixelPlane,
    /// Taken from the default fit made beside another one (the paper's,
    /// `--ground-fit paper`): that default fit's plane and its covariance.
    /// The residuals show a warp of the depth, but the observation's plane
    /// is not the one they bend, so nothing may be corrected by them; and
    /// the geometry across poses is judged on these planes, not the other
    /// fit's, whose own bias (walls, obstacles) would look like a pattern.
    pub(crate) beside_another_fit: Option<DefaultFitBeside>,
}

/// The default fit made beside another fit of the same frames: the plane
/// the residuals were taken from, and its covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct DefaultFitBeside {
    pub(crate) plane: Plane,
    pub(crate) covariance: Matrix4<f64>,
}

/// The sums as one pose's frames are read.
struct Sums {
    cells: Vec<CellSums>,
    moments: Matrix3<f64>,
    rhs: Vector3<f64>,
}

/// One cell's sums over a band of rows, in eight f32 lanes (k is the pixel
/// in the cell, 0–7; `dv` the row's `v − cy`), kept in registers while the
/// band's rows of the cell are read: one AVX2 vector a sum
/// ([`cell_lanes_avx2`]), or independent lanes that the compiler may turn
/// into vectors (the reference, [`CellLanes::of_rows`]). Every lane sums
/// at most a few dozen readings, where f32 loses nothing that matters
/// (residuals of a few hundredths; `dv²` below 2²⁴). What lane k sums times
/// k is k times the lane's sum, so it is not summed pixel by pixel
/// ([`times_k`]): `Σk` and `Σk²` are k and k² times the count, exactly
/// (whole numbers far below 2²⁴); `Σk·r` and `Σk·dv` are k times `Σr` and
/// `Σdv`, within f32's rounding (two sums fewer a pixel, 16 % of the
/// pass).
#[derive(Clone, Copy, Default)]
struct CellLanes {
    n: [f32; CELL_PX],
    r: [f32; CELL_PX],
    rr: [f32; CELL_PX],
    n_dv: [f32; CELL_PX],
    n_dv2: [f32; CELL_PX],
    r_dv: [f32; CELL_PX],
}

/// Each lane of `lane` times `k^power` (k the lane).
fn times_k(lane: &[f32; CELL_PX], power: i32) -> [f32; CELL_PX] {
    std::array::from_fn(|l| (l as f32).powi(power) * lane[l])
}

/// One row of a band as the pass reads it: its pixels, the row
/// [`EdgeGuard::rows`] above it where the fit guarded it, the row's
/// `v − cy` and its square in f32, and the plane's value at `u − cx = 0`
/// on both rows (f64, `c0 + cv·dv`): what every cell of the row shares,
/// worked out once a row.
struct BandRow<'a, T> {
    pixels: &'a [T],
    above: Option<&'a [T]>,
    dv: f32,
    dv2: f32,
    plane_at: f64,
    plane_above_at: f64,
}

impl CellLanes {
    /// The reference loop over a band's `rows` of the cell of `pixels`
    /// (its first pixel's `u − cx` is `first`), which [`cell_lanes_avx2`]
    /// matches bit for bit.
    #[inline(always)]
    fn of_rows<T: FitValue>(
        rows: &[BandRow<'_, T>],
        pixels: std::ops::Range<usize>,
        first: f64,
        pass: &Pass,
    ) -> Self {
        let mut lanes = Self::default();
        for row in rows {
            let x = cell_values(&row.pixels[pixels.clone()]);
            match row.above {
                Some(above) => {
                    let x_above = cell_values(&above[pixels.clone()]);
                    lanes.add_row::<true, T>((x, x_above), row, first, pass);
                }
                None => lanes.add_row::<false, T>((x, x), row, first, pass),
            }
        }
        lanes
    }

    /// Adds one row's readings of the cell whose first pixel is `first`
    /// (`u − cx`) that lie within the pass's band of its plane, where the
    /// plane lies within its region, without a branch. With `GUARDED`, a
    /// reading counts only where the reading above it (`x_above`) clears
    /// the fit's edge guard, as the fit's own loop tests it. A last cell
    /// narrower than [`CELL_PX`] is padded with NaN, which no comparison
    /// takes.
    #[inline(always)]
    fn add_row<const GUARDED: bool, T>(
        &mut self,
        (x, x_above): ([f32; CELL_PX], [f32; CELL_PX]),
        row: &BandRow<'_, T>,
        first: f64,
        pass: &Pass,
    ) {
        let Pass {
            plane,
            band,
            region,
            guard,
            ..
        } = *pass;
        let cu = plane.cu as f32;
        let (dv1, dv2) = (row.dv, row.dv2);
        // The plane at the cell's first pixel, then a step a pixel.
        let start = (row.plane_at + plane.cu * first) as f32;
        let start_above = (row.plane_above_at + plane.cu * first) as f32;
        // Lane l of every sum at once: one vector instruction a sum.
        #[allow(clippy::needless_range_loop)]
        for l in 0..CELL_PX {
            let k = l as f32;
            let on_plane = start + cu * k;
            let r = x[l] - on_plane;
            let clear = !GUARDED || clear_above(x_above[l], start_above + cu * k, guard);
            let keep = r.abs() <= band && on_plane >= region.0 && on_plane <= region.1 && clear;
            let r = if keep { r } else { 0.0 };
            self.n[l] += if keep { 1.0 } else { 0.0 };
            self.r[l] += r;
            self.rr[l] += r * r;
            self.n_dv[l] += if keep { dv1 } else { 0.0 };
            self.n_dv2[l] += if keep { dv2 } else { 0.0 };
            self.r_dv[l] += r * dv1;
        }
    }
}

impl Sums {
    fn new(columns: usize, rows: usize) -> Self {
        Self {
            cells: vec![CellSums::default(); columns * rows],
            moments: Matrix3::zeros(),
            rhs: Vector3::zeros(),
        }
    }

    /// Reduces one cell's lanes over a band (`first`: its first pixel's
    /// `u − cx`) into the cell and the pose's moments, the residuals times
    /// `to_inverse_depth`.
    fn add_cell(&mut self, cell: usize, first: f64, lanes: &CellLanes, to_inverse_depth: f64) {
        let scale = to_inverse_depth;
        let sum = |lane: [f32; CELL_PX]| lane_sum(&lane);
        let n = sum(lanes.n);
        if n == 0.0 {
            return;
        }
        let (sr, srr) = (sum(lanes.r) * scale, sum(lanes.rr) * scale * scale);
        let (sk, skk) = (sum(times_k(&lanes.n, 1)), sum(times_k(&lanes.n, 2)));
        let skr = sum(times_k(&lanes.r, 1)) * scale;
        let (n_dv, k_dv) = (sum(lanes.n_dv), sum(times_k(&lanes.n_dv, 1)));
        let n_dv2 = sum(lanes.n_dv2);
        let r_dv = sum(lanes.r_dv) * scale;
        // Offsets within the cell (k) back to u' = first + k.
        let sum_u = first * n + sk;
        let cell = &mut self.cells[cell];
        cell.n += n;
        cell.r += sr;
        cell.rr += srr;
        cell.u += sum_u;
        cell.v += n_dv;
        self.moments[(0, 0)] += n;
        self.moments[(0, 1)] += sum_u;
        self.moments[(0, 2)] += n_dv;
        self.moments[(1, 1)] += first * first * n + 2.0 * first * sk + skk;
        self.moments[(1, 2)] += first * n_dv + k_dv;
        self.moments[(2, 2)] += n_dv2;
        self.rhs[0] += sr;
        self.rhs[1] += first * sr + skr;
        self.rhs[2] += r_dv;
    }

    /// Every [`ROW_STEP`]th row of each of `frames` (all of the same
    /// size), band by band of [`CELL_PX`] rows, the frames' rows of a band
    /// reduced together. Where the processor has AVX2, each whole cell's
    /// rows go through [`cell_lanes_avx2`] (the same numbers in the same
    /// order: the sums do not depend on the processor).
    fn add_frames<T: FitValue>(&mut self, frames: &[&[T]], pass: &Pass) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            #[allow(unsafe_code)]
            unsafe {
                self.add_frames_avx2(frames, pass)
            };
            return;
        }
        self.add_frames_with(frames, pass, CellLanes::of_rows);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn add_frames_avx2<T: FitValue>(&mut self, frames: &[&[T]], pass: &Pass) {
        self.add_frames_with(frames, pass, |rows, pixels, first, pass| {
            if pixels.len() == CELL_PX {
                // SAFETY: called only on a processor with AVX2 (this
                // function's own condition), for a cell of eight pixels.
                #[allow(unsafe_code)]
                unsafe {
                    cell_lanes_avx2(rows, pixels, first, pass)
                }
            } else {
                CellLanes::of_rows(rows, pixels, first, pass)
            }
        });
    }

    /// Cell by cell of a band, its rows in the frames' order, through
    /// `cell_lanes` (the reference [`CellLanes::of_rows`] or its AVX2
    /// twin): a cell's lanes stay in registers through the band (stored and
    /// loaded a row at a time, they were most of the pass's time), and each
    /// lane adds the same numbers in the same order as row by row across
    /// the band.
    #[inline(always)]
    fn add_frames_with<'a, T: FitValue>(
        &mut self,
        frames: &[&'a [T]],
        pass: &Pass,
        cell_lanes: impl Fn(&[BandRow<'a, T>], std::ops::Range<usize>, f64, &Pass) -> CellLanes,
    ) {
        let (width, cx, cy) = (pass.width, pass.intrinsics.cx, pass.intrinsics.cy);
        let columns = width.div_ceil(CELL_PX);
        let band_px = width * CELL_PX;
        let bands = frames.first().map_or(0, |f| f.len().div_ceil(band_px));
        let guard_rows = pass.guard_rows;
        let mut rows: Vec<BandRow<'a, T>> = Vec::with_capacity(frames.len() * CELL_PX);
        for band_row in 0..bands {
            rows.clear();
            for frame in frames {
                let height = frame.len() / width;
                let first = band_row * CELL_PX;
                for v in (first..height.min(first + CELL_PX)).step_by(ROW_STEP) {
                    // The fit guards the rows with a row that far above them.
                    let up = v.checked_sub(guard_rows).filter(|_| guard_rows > 0);
                    let dv = v as f64 - cy;
                    let dv_above = up.map_or(v as f64, |up| up as f64) - cy;
                    rows.push(BandRow {
                        pixels: &frame[v * width..(v + 1) * width],
                        above: up.map(|up| &frame[up * width..(up + 1) * width]),
                        dv: dv as f32,
                        dv2: (dv * dv) as f32,
                        plane_at: pass.plane.c0 + pass.plane.cv * dv,
                        plane_above_at: pass.plane.c0 + pass.plane.cv * dv_above,
                    });
                }
            }
            for column in 0..columns {
                let pixels = column * CELL_PX..((column + 1) * CELL_PX).min(width);
                let first = (column * CELL_PX) as f64 - cx;
                let lanes = cell_lanes(&rows, pixels, first, pass);
                self.add_cell(
                    band_row * columns + column,
                    first,
                    &lanes,
                    pass.to_inverse_depth,
                );
            }
        }
    }
}

/// [`CellLanes::of_rows`] in AVX2, for a cell of [`CELL_PX`] pixels: the
/// same operations in the same order (a multiply then an add, never fused;
/// ordered comparisons, false with NaN as Rust's are), so the sums are the
/// reference's bit for bit. Written out because the reference's vectors are
/// the compiler's choice, as the fit's loop once showed
/// ([`crate::disparity`]'s `lane_sums_avx2`).
///
/// # Safety
/// The processor must have AVX2, and `pixels` span eight pixels.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
#[allow(unsafe_code)]
unsafe fn cell_lanes_avx2<T: FitValue>(
    rows: &[BandRow<'_, T>],
    pixels: std::ops::Range<usize>,
    first: f64,
    pass: &Pass,
) -> CellLanes {
    use crate::disparity::clear_above_avx2;
    use std::arch::x86_64::*;
    debug_assert_eq!(pixels.len(), CELL_PX);
    let Pass {
        plane,
        band,
        region,
        guard: (limit, lo, hi),
        ..
    } = *pass;
    let one = _mm256_set1_ps(1.0);
    // |x|: the sign bit cleared, as f32::abs does.
    let magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let cu = plane.cu as f32;
    // The plane's change to the cell's first pixel, and its step a pixel
    // from there, `cu·k`, lane by lane as the reference.
    let along = plane.cu * first;
    let step = _mm256_setr_ps(
        cu * 0.0,
        cu * 1.0,
        cu * 2.0,
        cu * 3.0,
        cu * 4.0,
        cu * 5.0,
        cu * 6.0,
        cu * 7.0,
    );
    let (band, below, above_region) = (
        _mm256_set1_ps(band),
        _mm256_set1_ps(region.0),
        _mm256_set1_ps(region.1),
    );
    let (limit, lo, hi) = (
        _mm256_set1_ps(limit),
        _mm256_set1_ps(lo),
        _mm256_set1_ps(hi),
    );
    let [mut n, mut r_sum, mut rr, mut n_dv, mut n_dv2, mut r_dv] = [_mm256_setzero_ps(); 6];
    for row in rows {
        let (dv1, dv2) = (_mm256_set1_ps(row.dv), _mm256_set1_ps(row.dv2));
        let start = (row.plane_at + along) as f32;
        let on_plane = _mm256_add_ps(_mm256_set1_ps(start), step);
        // SAFETY: eight values (the caller's word on `pixels`; the slicing
        // checks the bounds), on a processor with AVX2.
        let x = unsafe { T::load8_avx2(&row.pixels[pixels.clone()]) };
        let r = _mm256_sub_ps(x, on_plane);
        let mut keep = _mm256_and_ps(
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_and_ps(r, magnitude), band),
                _mm256_cmp_ps::<_CMP_GE_OQ>(on_plane, below),
            ),
            _mm256_cmp_ps::<_CMP_LE_OQ>(on_plane, above_region),
        );
        if let Some(above) = row.above {
            let start_above = (row.plane_above_at + along) as f32;
            let expected = _mm256_add_ps(_mm256_set1_ps(start_above), step);
            // SAFETY: as above, of the row above.
            let a = unsafe { T::load8_avx2(&above[pixels.clone()]) };
            keep = _mm256_and_ps(keep, clear_above_avx2(a, expected, (limit, lo, hi)));
        }
        // 1, r, dv, dv² or +0: what the reference's `if` picks.
        let kept = _mm256_and_ps(keep, r);
        n = _mm256_add_ps(n, _mm256_and_ps(keep, one));
        r_sum = _mm256_add_ps(r_sum, kept);
        rr = _mm256_add_ps(rr, _mm256_mul_ps(kept, kept));
        n_dv = _mm256_add_ps(n_dv, _mm256_and_ps(keep, dv1));
        n_dv2 = _mm256_add_ps(n_dv2, _mm256_and_ps(keep, dv2));
        r_dv = _mm256_add_ps(r_dv, _mm256_mul_ps(kept, dv1));
    }
    let mut lanes = CellLanes::default();
    for (out, sum) in [
        (&mut lanes.n, n),
        (&mut lanes.r, r_sum),
        (&mut lanes.rr, rr),
        (&mut lanes.n_dv, n_dv),
        (&mut lanes.n_dv2, n_dv2),
        (&mut lanes.r_dv, r_dv),
    ] {
        // SAFETY: eight f32 into an array of eight.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), sum) };
    }
    lanes
}

/// A cell's values as f32, padded with NaN past the row's end.
#[inline(always)]
fn cell_values<T: FitValue>(chunk: &[T]) -> [f32; CELL_PX] {
    match <&[T; CELL_PX]>::try_from(chunk) {
        Ok(full) => full.map(|value| value.to_f32()),
        Err(_) => {
            let mut x = [f32::NAN; CELL_PX];
            for (out, value) in x.iter_mut().zip(chunk) {
                *out = value.to_f32();
            }
            x
        }
    }
}

/// What one pass over a pose's frames compares and sums.
#[derive(Clone, Copy)]
struct Pass {
    width: usize,
    intrinsics: Intrinsics,
    /// The fit's plane in the frames' value units.
    plane: PixelPlane,
    /// The band about it, in the same units.
    band: f32,
    /// Where the plane's values must lie for a pixel to count: those the
    /// fit took its readings from, the trusted values less its own band at
    /// each end. Chosen by the plane, never by the reading: near the range's
    /// ends the noise is cut off on one side (by the sensor or the range
    /// check), and choosing by the reading kept readings the fit did not
    /// take, biased towards the middle of the range; the bends computed from
    /// them missed the fit's by up to 5 % where the far end of the range
    /// crossed the ground (0.0035° of pitch on a designed schedule).
    region: (f32, f32),
    /// Inverse depth (1/m) per value unit.
    to_inverse_depth: f64,
    /// The fit's edge guard: how many rows up (0: none), and its
    /// `(limit, lo, hi)` in the same units as the plane.
    guard_rows: usize,
    guard: (f32, f32, f32),
}

impl GroundResiduals {
    /// A pose's residuals from its cells' sums (`columns × rows` of them)
    /// and its moments `(Σφφᵀ, Σr·φ)`, with the depth model's raw units per
    /// 1/m and the fit's band (1/m), about the fit's `plane`: the squares
    /// read into the pose's scatter here (`scatter`), the cells kept in f32.
    pub(crate) fn from_sums(
        (columns, rows, cells): (usize, usize, &[CellSums]),
        (moments, rhs): (Matrix3<f64>, Vector3<f64>),
        intrinsics: Intrinsics,
        (raw_per_inverse_depth, fit_band): (f64, f64),
        (plane, scatter): (PixelPlane, ScatterMeasured),
    ) -> Self {
        let mut reading_scatter = (0.0, 0.0);
        for cell in cells.iter().filter(|cell| cell.n > 1.0) {
            reading_scatter.0 += cell.rr - cell.r * cell.r / cell.n;
            reading_scatter.1 += cell.n - 1.0;
        }
        let scatter_with_depth = (scatter == ScatterMeasured::AlsoWithDepth).then(|| {
            let mut with_depth = ScatterWithDepth::default();
            for (k, cell) in cells.iter().enumerate() {
                let (du, dv) = cell_centre(k, columns, &intrinsics);
                with_depth.add_cell(cell.n, cell.r, cell.rr, plane.at(du, dv));
            }
            with_depth
        });
        Self {
            columns,
            rows,
            cells: cells
                .iter()
                .enumerate()
                .map(|(k, sums)| KeptCell::new(sums, cell_centre(k, columns, &intrinsics)))
                .collect(),
            reading_scatter,
            scatter_with_depth,
            moments,
            rhs,
            intrinsics,
            raw_per_inverse_depth,
            fit_band,
            plane,
            beside_another_fit: None,
        }
    }

    /// How many cells the image has (read or not).
    pub(crate) fn cell_count(&self) -> usize {
        self.cells.len()
    }

    /// Cell `k`'s sums.
    #[inline]
    pub(crate) fn cell(&self, k: usize) -> GroundCell {
        self.cells[k].sums(cell_centre(k, self.columns, &self.intrinsics))
    }

    /// Cell `k`'s sums, its centre given (from [`GroundResiduals::centres`]:
    /// the estimate's loops, which read every cell kept at every turn).
    #[inline]
    pub(crate) fn cell_centred(&self, k: usize, centre: (f64, f64)) -> GroundCell {
        self.cells[k].sums(centre)
    }

    /// Every cell's centre, pixels from the principal point, in order.
    pub(crate) fn centres(&self) -> Vec<(f64, f64)> {
        (0..self.cells.len())
            .map(|k| cell_centre(k, self.columns, &self.intrinsics))
            .collect()
    }

    /// Cell `k`'s count of readings alone (its sums need its place too).
    #[inline]
    pub(crate) fn readings(&self, k: usize) -> f64 {
        f64::from(self.cells[k].n)
    }

    /// Every cell's sums, in order.
    pub(crate) fn cells(&self) -> EachCell<'_> {
        EachCell {
            residuals: self,
            k: 0,
            column: 0,
            row: 0,
        }
    }

    /// Every cell's count of readings, in order.
    pub(crate) fn each_readings(&self) -> impl ExactSizeIterator<Item = f64> + '_ {
        self.cells.iter().map(|cell| f64::from(cell.n))
    }

    /// The readings' scatter about their cells' means and its degrees of
    /// freedom (the field's documentation).
    pub(crate) fn reading_scatter(&self) -> (f64, f64) {
        self.reading_scatter
    }

    /// The cells' scatter against the ground's depth, for
    /// [`crate::noise_with_depth::noise_exponent`], where measured
    /// ([`ScatterMeasured::AlsoWithDepth`]).
    pub fn scatter_with_depth(&self) -> Option<&ScatterWithDepth> {
        self.scatter_with_depth.as_ref()
    }

    /// These residuals, marked as taken from the default fit made beside
    /// another fit of the same frames, with that default fit's plane and
    /// covariance: they judge a warp, they correct nothing.
    pub fn beside_another_fit(self, plane: Plane, covariance: Matrix4<f64>) -> Self {
        Self {
            beside_another_fit: Some(DefaultFitBeside { plane, covariance }),
            ..self
        }
    }

    /// The residuals of `frames` from the ground `fit` found in them: the
    /// readings within twice the fit's own band, less those its edge guard
    /// left out. The guard leaves out the rows at an obstacle's foot; summed
    /// here, they made the bends predicted from these residuals miss the
    /// fit's by 0.015–0.021 raw units of a ±1 pattern in clutter and where
    /// a wall meets the floor, and put the pitch 3–5σ off. `None` for the
    /// paper's fit (`--ground-fit paper`, kept to compare with): its band
    /// is in metres point by point, and a pattern estimated through it is
    /// not one the default fit would see (in the corridor it found one
    /// where there is none); [`GroundResiduals::beside_another_fit`] marks
    /// the default fit's residuals taken beside it instead.
    pub fn of(
        frames: &[&[u16]],
        camera: &DepthCamera,
        fit: &GroundFit,
        image: &mut InverseDepthImage,
    ) -> Option<Self> {
        Self::of_read(
            Read::Converting(frames, image),
            camera,
            fit,
            ScatterMeasured::Pooled,
        )
    }

    /// [`GroundResiduals::of`] the frames that `fit` was just fitted to
    /// with `buffers`: the frames it converted to inverse depth are read as
    /// they are, not converted again (the same numbers, bit for bit).
    pub fn of_fitted(
        frames: &[&[u16]],
        camera: &DepthCamera,
        fit: &GroundFit,
        buffers: &mut crate::plane::FitBuffers,
    ) -> Option<Self> {
        Self::of_fitted_measuring(frames, camera, fit, buffers, ScatterMeasured::Pooled)
    }

    /// [`GroundResiduals::of_fitted`], measuring `scatter`.
    pub fn of_fitted_measuring(
        frames: &[&[u16]],
        camera: &DepthCamera,
        fit: &GroundFit,
        buffers: &mut crate::plane::FitBuffers,
        scatter: ScatterMeasured,
    ) -> Option<Self> {
        if buffers.converted_images(frames, camera).is_some() {
            let images = buffers.converted_images(frames, camera)?;
            Self::of_read(Read::Converted(frames, images), camera, fit, scatter)
        } else {
            let read = Read::Converting(frames, buffers.residual_image());
            Self::of_read(read, camera, fit, scatter)
        }
    }

    fn of_read(
        read: Read<'_>,
        camera: &DepthCamera,
        fit: &GroundFit,
        scatter: ScatterMeasured,
    ) -> Option<Self> {
        let InlierBand::InverseDepth { band, edge_guard } = fit.band else {
            return None;
        };
        let intrinsics = *camera.intrinsics();
        let (width, height) = (intrinsics.width, intrinsics.height);
        let columns = width.div_ceil(CELL_PX);
        let rows = height.div_ceil(CELL_PX);
        let mut sums = Sums::new(columns, rows);
        let plane = PixelPlane::from_plane(&fit.plane, &intrinsics);
        // The fit's domain: raw values, or inverse depth (metric frames, a
        // corrected camera), in which the converted frames below are read.
        let domain = camera.value_domain();
        let frames = match &read {
            Read::Converting(frames, _) | Read::Converted(frames, _) => *frames,
        };
        let is_whole = |pixels: &&[u16]| pixels.len() == width * height;
        let whole: Vec<&[u16]> = frames.iter().copied().filter(is_whole).collect();
        if camera.fits_raw_values() {
            // Raw frames as the fit read them, in raw values: no pixel
            // converted (the residuals scaled to 1/m by the cell).
            let fit_band = band / domain.scale.abs();
            let pass = Pass {
                width,
                intrinsics,
                plane: domain.from_inverse_depth(&plane),
                band: (WIDER_BAND * fit_band) as f32,
                region: fit_region(&domain, fit_band),
                to_inverse_depth: domain.scale,
                guard_rows: edge_guard.map_or(0, |g| g.rows),
                guard: guard_test(&domain, edge_guard, domain.scale.abs()),
            };
            sums.add_frames(&whole, &pass);
        } else {
            let pass = Pass {
                width,
                intrinsics,
                plane,
                band: (WIDER_BAND * band) as f32,
                region: fit_region(&domain, band),
                to_inverse_depth: 1.0,
                guard_rows: edge_guard.map_or(0, |g| g.rows),
                guard: guard_test(&domain, edge_guard, 1.0),
            };
            match read {
                Read::Converting(_, image) => {
                    for pixels in whole {
                        camera.inverse_depth_into(pixels, image);
                        sums.add_frames(&[&image.w[..]], &pass);
                    }
                }
                Read::Converted(frames, images) => {
                    for (_, image) in frames.iter().zip(images).filter(|(f, _)| is_whole(f)) {
                        sums.add_frames(&[&image.w[..]], &pass);
                    }
                }
            }
        }
        let Sums {
            cells,
            mut moments,
            rhs,
        } = sums;
        moments[(1, 0)] = moments[(0, 1)];
        moments[(2, 0)] = moments[(0, 2)];
        moments[(2, 1)] = moments[(1, 2)];
        Some(Self::from_sums(
            (columns, rows, &cells),
            (moments, rhs),
            intrinsics,
            (camera.raw_per_inverse_depth(), band),
            (plane, scatter),
        ))
    }
}

/// How the residuals read a pose's frames: converting them into an image
/// (or as they are, for a camera that fits raw values), or as the fit
/// converted them.
enum Read<'a> {
    Converting(&'a [&'a [u16]], &'a mut InverseDepthImage),
    Converted(&'a [&'a [u16]], &'a [InverseDepthImage]),
}

/// The edge guard's `(limit, lo, hi)` in the domain's units, from its limit
/// in 1/m (`per_unit`: 1/m per unit): `(0, 0, 0)` without one.
fn guard_test(domain: &ValueDomain, guard: Option<EdgeGuard>, per_unit: f64) -> (f32, f32, f32) {
    guard.map_or((0.0, 0.0, 0.0), |g| {
        (
            (g.limit / per_unit) as f32,
            domain.trusted.0,
            domain.trusted.1,
        )
    })
}

/// The plane values of the pixels the fit read (`PixelGrid::moments_within`):
/// those where the plane lies within the trusted values by at least the
/// fit's `band` (both in the domain's units).
fn fit_region(domain: &ValueDomain, band: f64) -> (f32, f32) {
    let band = band as f32;
    (domain.plane_within.0 + band, domain.plane_within.1 - band)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two frames 76 × 37 pixels (a last cell four pixels wide, a last
    /// band of five rows) of a plane's raw values with noise, outliers and
    /// dropouts, and a pass over them whose region leaves out part of the
    /// plane, guarded (`guard_rows` up) or not.
    fn random_frames(seed: u64, guard_rows: usize) -> (Vec<Vec<u16>>, Pass) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let intrinsics = Intrinsics {
            fx: 580.0,
            fy: 580.0,
            cx: 37.3,
            cy: 18.6,
            width: 76,
            height: 37,
        };
        // One plane in three level and on a whole value: residuals on the
        // band's edge.
        let plane = match seed % 3 {
            0 => PixelPlane {
                c0: 700.0,
                cu: 0.0,
                cv: 0.0,
            },
            _ => PixelPlane {
                c0: rng.gen_range(690.0..710.0),
                cu: rng.gen_range(-0.5..0.5),
                cv: rng.gen_range(-1.5..1.5),
            },
        };
        let frames = (0..2)
            .map(|_| {
                let mut frame = Vec::with_capacity(76 * 37);
                for v in 0..37 {
                    for u in 0..76 {
                        let du = u as f64 - intrinsics.cx;
                        let dv = v as f64 - intrinsics.cy;
                        let value = match rng.gen_range(0..20) {
                            0 => 2047.0,
                            1 => plane.c0 + plane.cu * du + plane.cv * dv - 40.0,
                            _ => {
                                plane.c0 + plane.cu * du + plane.cv * dv + rng.gen_range(-4.0..4.0)
                            }
                        };
                        frame.push(value.round().clamp(0.0, 2047.0) as u16);
                    }
                }
                frame
            })
            .collect();
        let pass = Pass {
            width: 76,
            intrinsics,
            plane,
            band: 3.0,
            region: (690.0, 725.0),
            to_inverse_depth: -0.0028,
            guard_rows,
            guard: (6.0, 400.0, 1000.0),
        };
        (frames, pass)
    }

    /// Every f64 of the sums, as bits.
    fn bits_of(sums: &Sums) -> Vec<u64> {
        let cells = sums.cells.iter().flat_map(|c| [c.n, c.r, c.rr, c.u, c.v]);
        cells
            .chain(sums.moments.iter().copied())
            .chain(sums.rhs.iter().copied())
            .map(f64::to_bits)
            .collect()
    }

    /// The pass's AVX2 loop (where the processor has it) gives the
    /// reference loop's sums bit for bit, guarded and not, on raw frames
    /// and on metric ones with infinities and NaN: a replay's sums do not
    /// depend on the processor.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_cells_vector_loop_matches_the_reference_bit_for_bit() {
        if !std::is_x86_feature_detected!("avx2") {
            eprintln!("this processor has no AVX2: the reference loop is the one that runs");
            return;
        }
        fn same<T: FitValue>(frames: &[&[T]], pass: &Pass) {
            let (columns, rows) = (pass.width.div_ceil(CELL_PX), 37usize.div_ceil(CELL_PX));
            let mut reference = Sums::new(columns, rows);
            reference.add_frames_with(frames, pass, CellLanes::of_rows);
            let mut vector = Sums::new(columns, rows);
            // SAFETY: the processor has AVX2, checked above.
            #[allow(unsafe_code)]
            unsafe {
                vector.add_frames_avx2(frames, pass)
            };
            assert!(reference.moments[(0, 0)] > 300.0, "{}", reference.moments);
            assert_eq!(bits_of(&reference), bits_of(&vector));
        }
        for seed in 0..12 {
            let (frames, pass) = random_frames(seed, [0, 2][seed as usize % 2]);
            let raw: Vec<&[u16]> = frames.iter().map(|f| &f[..]).collect();
            same(&raw, &pass);
            // The same readings as metric values, the dropouts infinite and
            // one in seven NaN.
            let metric: Vec<Vec<f32>> = frames
                .iter()
                .map(|f| crate::test_noise::metric_with_nan(f))
                .collect();
            let metric: Vec<&[f32]> = metric.iter().map(|f| &f[..]).collect();
            let scaled = Pass {
                plane: PixelPlane {
                    c0: pass.plane.c0 * 1e-3,
                    cu: pass.plane.cu * 1e-3,
                    cv: pass.plane.cv * 1e-3,
                },
                band: pass.band * 1e-3,
                region: (pass.region.0 * 1e-3, pass.region.1 * 1e-3),
                guard: (pass.guard.0 * 1e-3, 0.4, 1.0),
                ..pass
            };
            same(&metric, &scaled);
        }
    }

    /// The pass's sums are those of its readings added one by one in f64:
    /// every reading within the band of the plane, on every
    /// [`ROW_STEP`]th row, where the plane is within its region and the
    /// reading above clears the guard; its residual scaled to 1/m. Within
    /// f32's rounding (the lanes), whichever loop runs.
    #[test]
    fn the_pass_sums_its_readings() {
        for seed in 0..6 {
            let (frames, pass) = random_frames(100 + seed, [0, 2][seed as usize % 2]);
            let frames: Vec<&[u16]> = frames.iter().map(|f| &f[..]).collect();
            let (columns, rows) = (76usize.div_ceil(CELL_PX), 37usize.div_ceil(CELL_PX));
            let mut sums = Sums::new(columns, rows);
            sums.add_frames(&frames, &pass);
            let mut cells = vec![[0.0f64; 5]; columns * rows];
            let mut size = vec![[0.0f64; 5]; columns * rows];
            let (mut moments, mut rhs) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
            let (mut moments_size, mut rhs_size) =
                (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
            let (plane, scale) = (pass.plane, pass.to_inverse_depth);
            let kept = |frame: &[u16], u: usize, v: usize| -> Option<f64> {
                let first = (u / CELL_PX * CELL_PX) as f64 - pass.intrinsics.cx;
                let k = (u % CELL_PX) as f32;
                let on = |v: usize| {
                    let dv = v as f64 - pass.intrinsics.cy;
                    ((plane.c0 + plane.cv * dv) + plane.cu * first) as f32 + plane.cu as f32 * k
                };
                let r = f32::from(frame[v * 76 + u]) - on(v);
                let clear = match v
                    .checked_sub(pass.guard_rows)
                    .filter(|_| pass.guard_rows > 0)
                {
                    Some(up) => clear_above(f32::from(frame[up * 76 + u]), on(up), pass.guard),
                    None => true,
                };
                let inside = on(v) >= pass.region.0 && on(v) <= pass.region.1;
                (r.abs() <= pass.band && inside && clear).then_some(f64::from(r) * scale)
            };
            for frame in &frames {
                for v in (0..37).step_by(ROW_STEP) {
                    for u in 0..76 {
                        let Some(r) = kept(frame, u, v) else {
                            continue;
                        };
                        let du = u as f64 - pass.intrinsics.cx;
                        let dv = v as f64 - pass.intrinsics.cy;
                        let cell = v / CELL_PX * columns + u / CELL_PX;
                        let terms = [1.0, r, r * r, du, dv];
                        for (k, t) in terms.iter().enumerate() {
                            cells[cell][k] += t;
                            size[cell][k] += t.abs();
                        }
                        let phi = Vector3::new(1.0, du, dv);
                        moments += phi * phi.transpose();
                        moments_size += (phi * phi.transpose()).abs();
                        rhs += r * phi;
                        rhs_size += (r * phi).abs();
                    }
                }
            }
            let close = |got: f64, want: f64, size: f64| (got - want).abs() <= 1e-5 * size + 1e-12;
            for (k, cell) in sums.cells.iter().enumerate() {
                let got = [cell.n, cell.r, cell.rr, cell.u, cell.v];
                for q in 0..5 {
                    assert!(
                        close(got[q], cells[k][q], size[k][q]),
                        "seed {seed}, cell {k}, sum {q}: {} against {}",
                        got[q],
                        cells[k][q]
                    );
                }
            }
            assert!(moments[(0, 0)] > 300.0);
            for i in 0..3 {
                for j in i..3 {
                    assert!(
                        close(sums.moments[(i, j)], moments[(i, j)], moments_size[(i, j)]),
                        "seed {seed}, moment ({i}, {j}): {} against {}",
                        sums.moments[(i, j)],
                        moments[(i, j)]
                    );
                }
                assert!(
                    close(sums.rhs[i], rhs[i], rhs_size[i]),
                    "seed {seed}, Σr·φ {i}: {} against {}",
                    sums.rhs[i],
                    rhs[i]
                );
            }
        }
    }

    /// A kept cell gives its sums back, the readings' centre within
    /// 6.1·10⁻⁵ pixels anywhere in the cell, and an empty cell as empty.
    #[test]
    fn a_kept_cell_gives_its_sums_back() {
        let centre = (-316.5, 238.5);
        for (n, mean_u, mean_v) in [
            (1.0, -320.0, 235.0),
            (96.0, -316.123_456, 242.0),
            (3072.0, -313.0, 238.5),
        ] {
            let sums = CellSums {
                n,
                r: 0.003 * n,
                rr: 0.0,
                u: mean_u * n,
                v: mean_v * n,
            };
            let back = KeptCell::new(&sums, centre).sums(centre);
            assert_eq!(back.n, n);
            assert!((back.r - sums.r).abs() < 1e-7 * sums.r, "{back:?}");
            assert!(
                (back.u / n - mean_u).abs() <= 6.11e-5,
                "{} against {mean_u}",
                back.u / n
            );
            assert!(
                (back.v / n - mean_v).abs() <= 6.11e-5,
                "{} against {mean_v}",
                back.v / n
            );
        }
        assert_eq!(std::mem::size_of::<KeptCell>(), 12);
        let empty = KeptCell::new(&CellSums::default(), centre).sums(centre);
        assert_eq!(empty, GroundCell::default());
    }
}
