//! What a shape bends each pose's plane by: the ground fit keeps readings
//! within its band, so a pattern lifts some out of it, and the plane the fit
//! finds is the truncated mean's (docs/method.md, "The depth pattern").

use super::*;

/// The plane (1/m on `c0, cu, cv`) by which the pattern `shape` bent the
/// fit of one pose. The fit took only the readings within its band of its
/// own plane, so where the pattern lifts the readings it cut more of their
/// upper tail, and it saw the pattern smaller than it is (a third smaller
/// where the pattern is a σ): its plane `β` solves the expected truncated
/// normal equations `Σ_k n_k·φ_k·g(D_k − φ_k·β) = 0`, with `g(m)` the mean
/// of a reading `m + ε` (ε ~ N(0, σ²)) within the band, times the share
/// kept. Newton's method from the untruncated bend `M⁻¹·Σ D_k·(n, Σu', Σv')_k`.
pub(super) fn bend(
    pose: &GroundResiduals,
    shape: &[f64],
    seen: &[bool],
    sigma: f64,
) -> Vector3<f64> {
    let inverse = pose.moments.try_inverse().unwrap_or_else(Matrix3::zeros);
    let mut untruncated = Vector3::zeros();
    for (k, cell) in pose.cells().enumerate() {
        if seen[k] && cell.n > 0.0 {
            untruncated += Vector3::new(cell.n, cell.u, cell.v) * shape[k];
        }
    }
    let mut plane = inverse * untruncated;
    let band = pose.fit_band;
    if !(band.is_finite() && band > 0.0 && sigma.is_finite() && sigma > 0.0) {
        return plane;
    }
    // The cells with readings, their centres and pattern, once: each Newton
    // step walks them all.
    let cells: Vec<BentCell> = pose
        .cells()
        .enumerate()
        .filter(|(_, cell)| cell.n > 0.0)
        .map(|(k, cell)| BentCell {
            n: cell.n,
            u: cell.u / cell.n,
            v: cell.v / cell.n,
            pattern: if seen[k] { shape[k] } else { 0.0 },
        })
        .collect();
    let beta = band / sigma;
    for _ in 0..6 {
        // Σ φ·n·g·σ, and the slope's six distinct moments Σ φφᵀ·n·g'.
        let (mut value, mut slope) = (Vector3::zeros(), [0.0; 6]);
        for cell in &cells {
            let m = (cell.pattern - (plane.x + cell.u * plane.y + cell.v * plane.z)) / sigma;
            let (g, dg) = truncated_mean(m, beta);
            let (gain, w) = (cell.n * g * sigma, cell.n * dg);
            value += Vector3::new(gain, cell.u * gain, cell.v * gain);
            slope[0] += w;
            slope[1] += cell.u * w;
            slope[2] += cell.v * w;
            slope[3] += cell.u * cell.u * w;
            slope[4] += cell.u * cell.v * w;
            slope[5] += cell.v * cell.v * w;
        }
        let [s0, su, sv, suu, suv, svv] = slope;
        let slope = -Matrix3::new(s0, su, sv, su, suu, suv, sv, suv, svv);
        let Some(step) = slope.try_inverse().map(|h| h * value) else {
            break;
        };
        plane -= step;
        // 10⁻⁹ /m is a millionth of a raw unit.
        if step.amax() < 1e-9 {
            break;
        }
    }
    plane
}

/// A cell as the bend sees it: its readings, their centre (pixels from the
/// principal point) and the pattern there (1/m).
pub(super) struct BentCell {
    pub(super) n: f64,
    pub(super) u: f64,
    pub(super) v: f64,
    pub(super) pattern: f64,
}

/// For ε ~ N(0, 1): `g(m) = E[(m + ε)·1{|m + ε| < β}]` and its derivative.
pub(super) fn truncated_mean(m: f64, beta: f64) -> (f64, f64) {
    let ((pdf_hi, cdf_hi), (pdf_lo, cdf_lo)) = (normal(beta - m), normal(-beta - m));
    let kept = cdf_hi - cdf_lo;
    let g = m * kept - (pdf_hi - pdf_lo);
    // d/dm: the share kept, less what the band's edges take with them.
    let dg = kept - beta * (pdf_hi + pdf_lo);
    (g, dg)
}

/// The standard normal density φ(x) and distribution Φ(x), sharing one
/// exponential (the bend evaluates them for every cell of every pose at
/// each Newton step): Φ by Abramowitz and Stegun 7.1.26, |error| below
/// 1.5·10⁻⁷.
pub(super) fn normal(x: f64) -> (f64, f64) {
    let gauss = (-0.5 * x * x).exp();
    let pdf = gauss / (2.0 * std::f64::consts::PI).sqrt();
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs() / std::f64::consts::SQRT_2);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    // erfc(|x|/√2) = poly·exp(−x²/2).
    let tail = 0.5 * poly * gauss;
    (pdf, if x >= 0.0 { 1.0 - tail } else { tail })
}
