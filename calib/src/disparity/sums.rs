//! The pass over a frame's pixels that gathers the moment sums: the values a
//! frame can hold ([`FitValue`]), its value domain, the pixel grid and its
//! edge guard, and the per-row loops in fixed lanes, so that every build (SSE2,
//! AVX2, NEON) adds the same numbers in the same order, bit for bit.

use super::*;

/// A value of a frame the fit reads: a raw Kinect value, or an inverse depth.
/// Sealed: the fit's vector loops read these two types only.
pub trait FitValue: Copy + Send + Sync + sealed::Sealed {
    /// The step between two values the sensor can give (a whole raw unit),
    /// or 0 where the steps are not even (inverse depth converted from
    /// millimetres): rounding to it is noise of `QUANTUM/√12` at least.
    const QUANTUM: f64;

    fn to_f32(self) -> f32;

    /// How many of `values` lie in `lo..=hi`.
    fn count_between(values: &[Self], lo: f32, hi: f32) -> usize;

    /// The first eight of `values` as f32, in one AVX2 register
    /// ([`lane_sums_avx2`]; element by element, the conversion was most of
    /// its time).
    ///
    /// # Safety
    /// The processor must have AVX2, and `values` hold eight at least.
    #[cfg(target_arch = "x86_64")]
    #[allow(unsafe_code)]
    unsafe fn load8_avx2(values: &[Self]) -> std::arch::x86_64::__m256;
}

/// [`FitValue`]'s seal.
mod sealed {
    pub trait Sealed {}
    impl Sealed for u16 {}
    impl Sealed for f32 {}
}

impl FitValue for u16 {
    const QUANTUM: f64 = 1.0;

    #[inline(always)]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    #[allow(unsafe_code)]
    unsafe fn load8_avx2(values: &[u16]) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        debug_assert!(values.len() >= 8);
        // SAFETY: eight u16 (16 bytes) are in bounds, by the caller's word.
        let raw = unsafe { _mm_loadu_si128(values.as_ptr().cast::<__m128i>()) };
        _mm256_cvtepi32_ps(_mm256_cvtepu16_epi32(raw))
    }

    fn count_between(values: &[u16], lo: f32, hi: f32) -> usize {
        // In integers, one comparison a value: the loop vectorises.
        let lo = lo.ceil().clamp(0.0, 65535.0) as u16;
        let hi = hi.floor().clamp(0.0, 65535.0) as u16;
        if lo > hi {
            return 0;
        }
        let span = hi - lo;
        values
            .chunks(1 << 15)
            .map(|chunk| {
                chunk
                    .iter()
                    .map(|&v| u16::from(v.wrapping_sub(lo) <= span))
                    .sum::<u16>() as usize
            })
            .sum()
    }
}

impl FitValue for f32 {
    const QUANTUM: f64 = 0.0;

    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    #[allow(unsafe_code)]
    unsafe fn load8_avx2(values: &[f32]) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        debug_assert!(values.len() >= 8);
        // SAFETY: eight f32 are in bounds, by the caller's word.
        unsafe { _mm256_loadu_ps(values.as_ptr()) }
    }

    fn count_between(values: &[f32], lo: f32, hi: f32) -> usize {
        values.iter().filter(|&&v| v >= lo && v <= hi).count()
    }
}

/// One frame as the fit reads it: row-major values, in a [`ValueDomain`].
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a, T> {
    pub values: &'a [T],
    pub width: usize,
    pub height: usize,
}

impl<'a, T: FitValue> Frame<'a, T> {
    /// The value at column `u`, row `v`.
    pub fn at(&self, u: usize, v: usize) -> f32 {
        self.values[v * self.width + u].to_f32()
    }

    /// Pixels whose value is trusted.
    pub fn count_trusted(&self, domain: &ValueDomain) -> usize {
        T::count_between(self.values, domain.trusted.0, domain.trusted.1)
    }
}

/// How a frame's values relate to inverse depth, `w = offset + scale·value`
/// (1/m), and which values are trusted. Raw Kinect frames are fitted in raw
/// units, with no conversion of any pixel; other frames are converted to
/// inverse depth first (`offset = 0`, `scale = 1`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValueDomain {
    pub offset: f64,
    pub scale: f64,
    /// Trusted values, lowest and highest (the trusted depth range).
    pub trusted: (f32, f32),
    /// Where a plane must lie for the fit to read near it: the trusted
    /// values, less the largest correction taken out of the frames. A
    /// reading is cut off by the range on its own value, pattern included,
    /// so a plane nearer the range's end than the pattern's peaks would
    /// keep the readings the pattern pulls inward and lose those it
    /// pushes out: a bias where the range ends, at the same place on the
    /// ground whatever the pose.
    pub plane_within: (f32, f32),
}

impl ValueDomain {
    /// A plane of values as a plane of inverse depth.
    pub fn to_inverse_depth(&self, plane: &PixelPlane) -> PixelPlane {
        PixelPlane {
            c0: self.offset + self.scale * plane.c0,
            cu: self.scale * plane.cu,
            cv: self.scale * plane.cv,
        }
    }

    /// A plane of inverse depth as a plane of values.
    pub fn from_inverse_depth(&self, plane: &PixelPlane) -> PixelPlane {
        PixelPlane {
            c0: (plane.c0 - self.offset) / self.scale,
            cu: plane.cu / self.scale,
            cv: plane.cv / self.scale,
        }
    }
}

/// Column offsets `u − cx` of an image and their squares, built once per
/// camera so that the per-pixel loop only loads them.
#[derive(Debug, Clone)]
pub struct PixelGrid {
    pub intrinsics: Intrinsics,
    pub(super) du: Vec<f32>,
    pub(super) du2: Vec<f32>,
}

/// One pass over a frame: the pixels within `band` of `plane`, on every
/// `rows.1`-th row from `rows.0`, less those the guard leaves out.
pub(super) struct Pass<'a, T> {
    pub(super) frame: &'a Frame<'a, T>,
    pub(super) domain: &'a ValueDomain,
    pub(super) plane: &'a PixelPlane,
    pub(super) band: f64,
    pub(super) rows: (usize, usize),
    pub(super) guard: Option<EdgeGuard>,
}

/// Leaves out the pixels where the ground meets something standing on it.
///
/// The foot of a wall or of a box's side lies on the ground, so the face's
/// lowest rows of pixels are within any band around the ground's plane,
/// always on the side of the sensor: kept, they pull the plane towards the
/// sensor where the obstacles stand (a bias of a few tenths of a millimetre
/// across a cluttered view, issue 22). Going up the image from such a pixel,
/// the face leaves the band within a few rows, while the ground stays in it.
/// So a pixel is kept only when the pixel `rows` rows above it is within
/// `limit` of the plane too, or has no trusted value (a shadow, a dropout).
/// On open ground this leaves out pixels whose neighbour is a noise outlier:
/// a choice independent of their own noise, so it adds no bias.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeGuard {
    /// How far above, in rows.
    pub rows: usize,
    /// How far from the plane the pixel above may be, in the frame's value
    /// units.
    pub limit: f64,
}

/// Lanes of the per-pixel loops: a fixed number, so that every build (SSE2,
/// AVX2, NEON) adds the same numbers in the same order and the results are
/// bit-identical.
pub(super) const LANES: usize = 16;

/// Sums of one row: inliers, `Σu`, `Σu²`, `Σr`, `Σu·r`, `Σr²`.
pub(super) type RowSums = [f64; 6];

/// The sum of `N` lanes (a power of two, at least 4), pairwise in a fixed
/// order: halves folded until four are left, then `(0 + 2) + (1 + 3)`. The
/// same order on every processor, so the sums are bit-identical.
#[inline(always)]
pub(crate) fn lane_sum<const N: usize>(lanes: &[f32; N]) -> f64 {
    let mut values = *lanes;
    let mut n = N;
    while n > 4 {
        n /= 2;
        for i in 0..n {
            values[i] += values[i + n];
        }
    }
    f64::from((values[0] + values[2]) + (values[1] + values[3]))
}

/// The edge guard's test of the pixel above: within `limit` of the plane
/// there (`expected`), or untrusted (outside `lo..=hi`). Branch-free (`|`),
/// so that the lanes stay vectors.
#[inline(always)]
pub(crate) fn clear_above(
    value_above: f32,
    expected: f32,
    (limit, lo, hi): (f32, f32, f32),
) -> bool {
    ((value_above - expected).abs() < limit) | (value_above < lo) | (value_above > hi)
}

/// [`clear_above`] on eight lanes in AVX2, the same comparisons (ordered:
/// false with NaN): the fit's loop and the residuals' cells test the pixel
/// above alike.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) fn clear_above_avx2(
    value_above: std::arch::x86_64::__m256,
    expected: std::arch::x86_64::__m256,
    (limit, lo, hi): (
        std::arch::x86_64::__m256,
        std::arch::x86_64::__m256,
        std::arch::x86_64::__m256,
    ),
) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    // |x|: the sign bit cleared, as f32::abs does.
    let magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let off = _mm256_sub_ps(value_above, expected);
    _mm256_or_ps(
        _mm256_or_ps(
            _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(off, magnitude), limit),
            _mm256_cmp_ps::<_CMP_LT_OQ>(value_above, lo),
        ),
        _mm256_cmp_ps::<_CMP_GT_OQ>(value_above, hi),
    )
}

/// One row's pixels for the per-pixel loop: the values, the values
/// [`EdgeGuard::rows`] above (the same columns; read only when guarded), and
/// the column offsets `du` and `du²`, all of one length.
#[derive(Clone, Copy)]
pub(super) struct RowPixels<'a, T> {
    pub(super) values: &'a [T],
    pub(super) above: &'a [T],
    pub(super) du: &'a [f32],
    pub(super) du2: &'a [f32],
}

/// What the per-pixel loop tests a row's pixels against: the plane's value
/// at `du = 0` on this row (`base`) and on the row above (`base_above`), its
/// slope along the row (`cu`), the band, and the edge guard's
/// `(limit, lo, hi)`.
#[derive(Clone, Copy)]
pub(super) struct RowTest {
    pub(super) base: f32,
    pub(super) base_above: f32,
    pub(super) cu: f32,
    pub(super) band: f32,
    pub(super) guard: (f32, f32, f32),
}

/// Per-lane running sums: inliers, `Σu`, `Σu²`, `Σr`, `Σu·r`, `Σr²`.
pub(super) type LaneSums = [[f32; LANES]; 6];

/// The per-pixel loop of [`PixelGrid::moments_within`] over one row: the
/// pixels within `band` of `base + cu·du`.
///
/// With `GUARDED`, a pixel counts only if its value in `above` lies within
/// `guard.0` of `base_above + cu·du`, or outside the trusted values
/// `guard.1..=guard.2`.
///
/// The whole chunks of [`LANES`] pixels go through [`lane_sums`] (NEON on
/// arm64, AVX2 where an x86-64 processor has it), the rest one by one in
/// f64.
#[inline(always)]
pub(super) fn row_sums<T: FitValue, const GUARDED: bool>(
    row: RowPixels<'_, T>,
    test: &RowTest,
) -> RowSums {
    let n = row.values.len().min(row.du.len()).min(row.du2.len());
    let n = if GUARDED { n.min(row.above.len()) } else { n };
    let full = n / LANES * LANES;
    let chunks = RowPixels {
        values: &row.values[..full],
        above: if GUARDED { &row.above[..full] } else { &[] },
        du: &row.du[..full],
        du2: &row.du2[..full],
    };
    #[cfg(target_arch = "aarch64")]
    let acc = lane_sums_neon::<T, GUARDED>(chunks, test);
    #[cfg(target_arch = "x86_64")]
    let acc = if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2, checked just above.
        #[allow(unsafe_code)]
        unsafe {
            lane_sums_avx2::<T, GUARDED>(chunks, test)
        }
    } else {
        lane_sums::<T, GUARDED>(chunks, test)
    };
    #[cfg(not(any(target_arch = "aarch64", target_arch = "x86_64")))]
    let acc = lane_sums::<T, GUARDED>(chunks, test);
    let mut sums: RowSums = std::array::from_fn(|k| lane_sum(&acc[k]));
    let RowTest {
        base,
        base_above,
        cu,
        band,
        guard,
    } = *test;
    for k in full..n {
        let (v, d, d2) = (row.values[k], row.du[k], row.du2[k]);
        let r = v.to_f32() - (base + cu * d);
        let clear = !GUARDED || clear_above(row.above[k].to_f32(), base_above + cu * d, guard);
        if r.abs() < band && clear {
            let (d, d2, r) = (f64::from(d), f64::from(d2), f64::from(r));
            sums[0] += 1.0;
            sums[1] += d;
            sums[2] += d2;
            sums[3] += r;
            sums[4] += d * r;
            sums[5] += r * r;
        }
    }
    sums
}

/// The per-lane sums over whole chunks of [`LANES`] pixels, written as
/// independent lanes, which compilers turn into vector instructions of any
/// width. This is the reference that [`lane_sums_neon`] and
/// [`lane_sums_avx2`] match bit for bit.
#[inline(always)]
#[cfg_attr(target_arch = "aarch64", allow(dead_code))]
pub(super) fn lane_sums<T: FitValue, const GUARDED: bool>(
    row: RowPixels<'_, T>,
    test: &RowTest,
) -> LaneSums {
    let RowTest {
        base,
        base_above,
        cu,
        band,
        guard,
    } = *test;
    let mut acc: LaneSums = [[0f32; LANES]; 6];
    // Half the lanes at a time, over the whole row, then the other half:
    // each lane adds the same numbers in the same order, and a half's six
    // sums stay in registers (all sixteen lanes' twelve AVX2 registers of
    // sums, beside the test's constants, were stored and loaded on every
    // chunk).
    for half in [0, HALF] {
        let mut lanes = |v: &[T], a: &[T], d: &[f32], d2: &[f32]| {
            for l in half..half + HALF {
                let r = v[l].to_f32() - (base + cu * d[l]);
                let mut inside = r.abs() < band;
                if GUARDED {
                    inside &= clear_above(a[l].to_f32(), base_above + cu * d[l], guard);
                }
                let one = if inside { 1.0 } else { 0.0 };
                let kept = if inside { r } else { 0.0 };
                acc[0][l] += one;
                acc[1][l] += one * d[l];
                acc[2][l] += one * d2[l];
                acc[3][l] += kept;
                acc[4][l] += kept * d[l];
                acc[5][l] += kept * kept;
            }
        };
        let chunks = row
            .values
            .chunks_exact(LANES)
            .zip(row.du.chunks_exact(LANES))
            .zip(row.du2.chunks_exact(LANES));
        if GUARDED {
            for (((v, d), d2), a) in chunks.zip(row.above.chunks_exact(LANES)) {
                lanes(v, a, d, d2);
            }
        } else {
            for ((v, d), d2) in chunks {
                lanes(v, v, d, d2);
            }
        }
    }
    acc
}

/// Half of [`LANES`]: one AVX2 register of f32.
const HALF: usize = LANES / 2;

/// [`lane_sums`] in AVX2, two vectors of eight lanes: the same operations
/// in the same order (a multiply then an add, never fused), so the sums are
/// bit-identical to the reference's on every input, NaN and infinities
/// included (the comparisons are ordered: false with NaN, as Rust's are).
/// Written out because the reference's vectors are the compiler's choice:
/// a change elsewhere in the crate once left its guarded loop in scalar
/// instructions, and the replay of the 156-frame recording took 60 %
/// longer (the fit's passes 50 % of the time instead of 21 %).
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
#[allow(unsafe_code)]
pub(super) unsafe fn lane_sums_avx2<T: FitValue, const GUARDED: bool>(
    row: RowPixels<'_, T>,
    test: &RowTest,
) -> LaneSums {
    use std::arch::x86_64::*;
    const VECTORS: usize = LANES / 8;
    let RowTest {
        base,
        base_above,
        cu,
        band,
        guard: (limit, lo, hi),
    } = *test;
    let zero = _mm256_setzero_ps();
    let one = _mm256_set1_ps(1.0);
    // |x|: the sign bit cleared, as f32::abs does.
    let magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let (base, base_above, cu) = (
        _mm256_set1_ps(base),
        _mm256_set1_ps(base_above),
        _mm256_set1_ps(cu),
    );
    let (band, limit, lo, hi) = (
        _mm256_set1_ps(band),
        _mm256_set1_ps(limit),
        _mm256_set1_ps(lo),
        _mm256_set1_ps(hi),
    );
    let n = row.values.len() / LANES * LANES;
    // One vector of eight lanes at a time over the whole row, then the
    // other (as the reference's halves): its six sums stay in registers.
    let mut by_vector = [[zero; 6]; VECTORS];
    for (q, sums) in by_vector.iter_mut().enumerate() {
        for start in (8 * q..n).step_by(LANES) {
            // SAFETY: each load reads the eight values of a slice of eight
            // (the slicing checks the bounds: a row whose `du` or `du2` were
            // shorter than its values would panic, never read past them),
            // on a processor with AVX2 (this function's own condition).
            let (d, d2, v) = unsafe {
                (
                    _mm256_loadu_ps(row.du[start..start + 8].as_ptr()),
                    _mm256_loadu_ps(row.du2[start..start + 8].as_ptr()),
                    T::load8_avx2(&row.values[start..start + 8]),
                )
            };
            let r = _mm256_sub_ps(v, _mm256_add_ps(base, _mm256_mul_ps(cu, d)));
            let mut inside = _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(r, magnitude), band);
            if GUARDED {
                // SAFETY: as above, of `above`.
                let a = unsafe { T::load8_avx2(&row.above[start..start + 8]) };
                let expected = _mm256_add_ps(base_above, _mm256_mul_ps(cu, d));
                inside = _mm256_and_ps(inside, clear_above_avx2(a, expected, (limit, lo, hi)));
            }
            // 1 or +0, r or +0: what the reference's `if` picks.
            let counted = _mm256_and_ps(inside, one);
            let kept = _mm256_and_ps(inside, r);
            sums[0] = _mm256_add_ps(sums[0], counted);
            sums[1] = _mm256_add_ps(sums[1], _mm256_mul_ps(counted, d));
            sums[2] = _mm256_add_ps(sums[2], _mm256_mul_ps(counted, d2));
            sums[3] = _mm256_add_ps(sums[3], kept);
            sums[4] = _mm256_add_ps(sums[4], _mm256_mul_ps(kept, d));
            sums[5] = _mm256_add_ps(sums[5], _mm256_mul_ps(kept, kept));
        }
    }
    let mut out: LaneSums = [[0f32; LANES]; 6];
    for (q, vector_sums) in by_vector.iter().enumerate() {
        for (lanes, sum) in out.iter_mut().zip(vector_sums) {
            // SAFETY: eight f32 into a slice of eight.
            unsafe { _mm256_storeu_ps(lanes[8 * q..8 * q + 8].as_mut_ptr(), *sum) };
        }
    }
    out
}

/// [`lane_sums`] in NEON, four vectors of four lanes: the same operations
/// in the same order (a multiply then an add, never fused, as Rust's scalar
/// `a + b * c` is), so the sums are bit-identical to the reference's on
/// every input, NaN and infinities included (a comparison with NaN is false
/// in both). NEON is part of every arm64 processor (and of the target's
/// baseline), so no run-time check is needed.
#[cfg(target_arch = "aarch64")]
#[inline(always)]
pub(super) fn lane_sums_neon<T: FitValue, const GUARDED: bool>(
    row: RowPixels<'_, T>,
    test: &RowTest,
) -> LaneSums {
    use std::arch::aarch64::*;
    const VECTORS: usize = LANES / 4;
    let RowTest {
        base,
        base_above,
        cu,
        band,
        guard: (limit, lo, hi),
    } = *test;
    // SAFETY: NEON is in the aarch64 target's baseline features; the loads
    // and stores read and write `[f32; 4]`s that are in bounds by their type.
    #[allow(unsafe_code)]
    unsafe {
        let zero = vdupq_n_f32(0.0);
        let one = vdupq_n_f32(1.0);
        let (base, base_above, cu) = (vdupq_n_f32(base), vdupq_n_f32(base_above), vdupq_n_f32(cu));
        let (band, limit, lo, hi) = (
            vdupq_n_f32(band),
            vdupq_n_f32(limit),
            vdupq_n_f32(lo),
            vdupq_n_f32(hi),
        );
        let mut acc = [[zero; VECTORS]; 6];
        let n = row.values.len() / LANES * LANES;
        for start in (0..n).step_by(LANES) {
            let mut value = [0f32; LANES];
            let mut value_above = [0f32; LANES];
            for l in 0..LANES {
                value[l] = row.values[start + l].to_f32();
                if GUARDED {
                    value_above[l] = row.above[start + l].to_f32();
                }
            }
            for q in 0..VECTORS {
                let at = start + 4 * q;
                let d = vld1q_f32(row.du[at..at + 4].as_ptr());
                let d2 = vld1q_f32(row.du2[at..at + 4].as_ptr());
                let v = vld1q_f32(value[4 * q..4 * q + 4].as_ptr());
                let r = vsubq_f32(v, vaddq_f32(base, vmulq_f32(cu, d)));
                let mut inside = vcltq_f32(vabsq_f32(r), band);
                if GUARDED {
                    let a = vld1q_f32(value_above[4 * q..4 * q + 4].as_ptr());
                    let off = vsubq_f32(a, vaddq_f32(base_above, vmulq_f32(cu, d)));
                    let clear = vorrq_u32(
                        vorrq_u32(vcltq_f32(vabsq_f32(off), limit), vcltq_f32(a, lo)),
                        vcgtq_f32(a, hi),
                    );
                    inside = vandq_u32(inside, clear);
                }
                let counted = vbslq_f32(inside, one, zero);
                let kept = vbslq_f32(inside, r, zero);
                acc[0][q] = vaddq_f32(acc[0][q], counted);
                acc[1][q] = vaddq_f32(acc[1][q], vmulq_f32(counted, d));
                acc[2][q] = vaddq_f32(acc[2][q], vmulq_f32(counted, d2));
                acc[3][q] = vaddq_f32(acc[3][q], kept);
                acc[4][q] = vaddq_f32(acc[4][q], vmulq_f32(kept, d));
                acc[5][q] = vaddq_f32(acc[5][q], vmulq_f32(kept, kept));
            }
        }
        let mut out: LaneSums = [[0f32; LANES]; 6];
        for (sums, vectors) in out.iter_mut().zip(&acc) {
            for (q, vector) in vectors.iter().enumerate() {
                vst1q_f32(sums[4 * q..4 * q + 4].as_mut_ptr(), *vector);
            }
        }
        out
    }
}

impl PixelGrid {
    pub fn new(intrinsics: Intrinsics) -> Self {
        let du: Vec<f32> = (0..intrinsics.width)
            .map(|u| (u as f64 - intrinsics.cx) as f32)
            .collect();
        let du2 = du.iter().map(|d| d * d).collect();
        Self {
            intrinsics,
            du,
            du2,
        }
    }

    /// Row offset `v − cy`.
    pub fn dv(&self, row: usize) -> f64 {
        row as f64 - self.intrinsics.cy
    }

    /// The columns of row offset `dv` where `plane` lies within the trusted
    /// values by at least `band`, as `start..end`.
    ///
    /// Pixels are chosen by where the plane says they are, never by their
    /// own reading: a reading near the range's ends is cut off by the noise
    /// on one side only (by the sensor, or by the range check), and choosing
    /// by the reading would bias the fit towards the middle of the range.
    pub(super) fn columns_in_range(
        &self,
        plane: &PixelPlane,
        domain: &ValueDomain,
        dv: f64,
        band: f64,
    ) -> (usize, usize) {
        let (lo, hi) = (
            f64::from(domain.plane_within.0) + band,
            f64::from(domain.plane_within.1) - band,
        );
        let base = plane.c0 + plane.cv * dv;
        let width = self.du.len();
        if lo >= hi {
            return (0, 0);
        }
        if plane.cu.abs() < 1e-15 {
            return if (lo..=hi).contains(&base) {
                (0, width)
            } else {
                (0, 0)
            };
        }
        // base + cu·du ∈ [lo, hi], du = u − cx.
        let (a, b) = ((lo - base) / plane.cu, (hi - base) / plane.cu);
        let (du_min, du_max) = if a <= b { (a, b) } else { (b, a) };
        let cx = self.intrinsics.cx;
        let start = (du_min + cx).ceil().clamp(0.0, width as f64) as usize;
        let end = ((du_max + cx).floor() + 1.0).clamp(0.0, width as f64) as usize;
        (start, end.max(start))
    }

    /// The moments of the pixels of every `row_step`-th row (from `first_row`)
    /// whose value lies within `band` of `plane` (both in the frame's value
    /// units), among the pixels where the plane is within the trusted values
    /// by at least `band`.
    ///
    /// Sums over a row in f32 lanes (residuals are small, so nothing is
    /// lost), rows added in f64 in order: the result depends on the input
    /// alone. Where the processor has AVX2, the same loop runs eight lanes
    /// at a time.
    #[allow(clippy::too_many_arguments)]
    pub fn moments_within<T: FitValue>(
        &self,
        frame: &Frame<T>,
        domain: &ValueDomain,
        plane: &PixelPlane,
        band: f64,
        first_row: usize,
        row_step: usize,
        guard: Option<EdgeGuard>,
    ) -> DisparityMoments {
        let pass = Pass {
            frame,
            domain,
            plane,
            band,
            rows: (first_row, row_step),
            guard,
        };
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            #[allow(unsafe_code)]
            return unsafe { self.moments_avx2(&pass) };
        }
        self.moments(&pass)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) fn moments_avx2<T: FitValue>(&self, pass: &Pass<T>) -> DisparityMoments {
        self.moments(pass)
    }

    #[inline(always)]
    pub(super) fn moments<T: FitValue>(&self, pass: &Pass<T>) -> DisparityMoments {
        let Pass {
            frame,
            domain,
            plane,
            band,
            rows: (first_row, row_step),
            guard,
        } = *pass;
        let width = frame.width.min(self.du.len());
        let mut total = DisparityMoments::default();
        for row in (first_row..frame.height).step_by(row_step.max(1)) {
            let dv = self.dv(row);
            let (start, end) = self.columns_in_range(plane, domain, dv, band);
            let end = end.min(width);
            if start >= end {
                continue;
            }
            let values = &frame.values[row * frame.width + start..row * frame.width + end];
            let base = (plane.c0 + plane.cv * dv) as f32;
            let du = &self.du[start..end];
            let du2 = &self.du2[start..end];
            let sums = match guard.filter(|g| g.rows > 0 && row >= g.rows) {
                Some(g) => {
                    let up = row - g.rows;
                    let pixels = RowPixels {
                        values,
                        above: &frame.values[up * frame.width + start..up * frame.width + end],
                        du,
                        du2,
                    };
                    let test = RowTest {
                        base,
                        base_above: (plane.c0 + plane.cv * self.dv(up)) as f32,
                        cu: plane.cu as f32,
                        band: band as f32,
                        guard: (g.limit as f32, domain.trusted.0, domain.trusted.1),
                    };
                    row_sums::<T, true>(pixels, &test)
                }
                None => {
                    let pixels = RowPixels {
                        values,
                        above: &[],
                        du,
                        du2,
                    };
                    let test = RowTest {
                        base,
                        base_above: base,
                        cu: plane.cu as f32,
                        band: band as f32,
                        guard: (0.0, 0.0, 0.0),
                    };
                    row_sums::<T, false>(pixels, &test)
                }
            };
            total.add_row(dv, &sums);
        }
        total
    }
}
