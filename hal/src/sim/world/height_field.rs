//! Uneven ground: a height field of summed waves, and the ray's first hit
//! on it, sphere-traced and refined by Newton's method within the bracket
//! that holds the crossing.

use super::*;

/// One sinusoid of a height field: `amplitude · sin(k·(x, z) + phase)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wave {
    /// Metres.
    pub amplitude_m: f64,
    /// Radians per metre along ground X and Z.
    pub wavevector: Vector2<f64>,
    /// Radians.
    pub phase: f64,
}

/// Ground that is not quite flat: `y = h(x, z) = Σ aᵢ·sin(kᵢ·(x, z) + φᵢ)`.
///
/// Real floors undulate by millimetres to centimetres over metres. A sum of a
/// few sinusoids is smooth (so ray casting converges), has a known bound on
/// its height and slope (so sphere tracing is safe), and averages to the plane
/// `y = 0` over a large area, which stays the ground frame's ground.
#[derive(Debug, Clone, PartialEq)]
pub struct HeightField {
    pub(super) waves: Vec<Wave>,
    /// `Σ |aᵢ|`: no point of the surface is farther than this from `y = 0`.
    pub(super) max_height: f64,
    /// `Σ |aᵢ|·|kᵢ|`: a bound on the gradient's norm.
    pub(super) max_slope: f64,
    /// `Σ |aᵢ|·|kᵢ|²`: a bound on the second derivative in any direction.
    pub(super) max_curvature: f64,
}

impl HeightField {
    /// A height field from its waves.
    pub fn new(waves: Vec<Wave>) -> Self {
        let max_height = waves.iter().map(|w| w.amplitude_m.abs()).sum();
        let max_slope = waves
            .iter()
            .map(|w| w.amplitude_m.abs() * w.wavevector.norm())
            .sum();
        let max_curvature = waves
            .iter()
            .map(|w| w.amplitude_m.abs() * w.wavevector.norm_squared())
            .sum();
        Self {
            waves,
            max_height,
            max_slope,
            max_curvature,
        }
    }

    /// Four waves of random direction, wavelength 0.7–3 m and phase, whose
    /// amplitudes add up to `amplitude_m`: the surface stays within
    /// `±amplitude_m` of `y = 0`.
    pub fn seeded(seed: u64, amplitude_m: f64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let raw: Vec<(f64, f64, f64, f64)> = (0..4)
            .map(|_| {
                (
                    rng.gen_range(0.5..1.0),
                    rng.gen_range(0.0..std::f64::consts::TAU),
                    rng.gen_range(0.7..3.0),
                    rng.gen_range(0.0..std::f64::consts::TAU),
                )
            })
            .collect();
        let total: f64 = raw.iter().map(|r| r.0).sum();
        let waves = raw
            .into_iter()
            .map(|(weight, heading, wavelength, phase)| Wave {
                amplitude_m: amplitude_m.abs() * weight / total,
                wavevector: Vector2::new(heading.cos(), heading.sin())
                    * (std::f64::consts::TAU / wavelength),
                phase,
            })
            .collect();
        Self::new(waves)
    }

    /// The waves.
    pub fn waves(&self) -> &[Wave] {
        &self.waves
    }

    /// The surface's height at ground coordinates `(x, z)`, metres.
    pub fn height(&self, x: f64, z: f64) -> f64 {
        self.waves
            .iter()
            .map(|w| w.amplitude_m * (w.wavevector.x * x + w.wavevector.y * z + w.phase).sin())
            .sum()
    }

    /// The height and its gradient `(∂h/∂x, ∂h/∂z)` at `(x, z)`.
    pub fn height_and_gradient(&self, x: f64, z: f64) -> (f64, Vector2<f64>) {
        let mut h = 0.0;
        let mut g = Vector2::zeros();
        for w in &self.waves {
            let (s, c) = (w.wavevector.x * x + w.wavevector.y * z + w.phase).sin_cos();
            h += w.amplitude_m * s;
            g += w.wavevector * (w.amplitude_m * c);
        }
        (h, g)
    }

    /// The upward unit normal at `(x, z)`.
    pub fn normal(&self, x: f64, z: f64) -> Vector3<f64> {
        let (_, g) = self.height_and_gradient(x, z);
        Vector3::new(-g.x, 1.0, -g.y).normalize()
    }

    /// A bound on `|h|`.
    pub fn max_height(&self) -> f64 {
        self.max_height
    }

    /// The first intersection of the ray with the surface, seen from above,
    /// with `t` in `(T_MIN, t_max]`.
    ///
    /// Along the ray, `f(t) = y(t) - h(x(t), z(t))` has the slope
    /// `f' = d_y - ∇h·d_xz`, at most `L = |d_y| + max_slope·|d_xz|` in size,
    /// and below zero whenever the ray falls more steeply than the surface
    /// can rise (`-d_y > max_slope·|d_xz|`). Every ray a Kinect on a
    /// robot sees the ground with within 5 m does: `f` then has one root, and
    /// Newton's method kept inside the bracket where the ray crosses the slab
    /// `|y| ≤ max_height` finds it in three or four steps. Flatter rays, where a
    /// bump may hide what lies behind it, are sphere traced: a step of `f/L`
    /// never crosses the surface, so the first root is never skipped; Newton
    /// finishes the root once the ray is within 0.1 mm of the surface.
    ///
    /// `height_guess`, the height of the surface near where the ray lands
    /// (a neighbouring pixel's), starts Newton closer to the root.
    pub(super) fn cast(
        &self,
        origin: &Point3<f64>,
        direction: &Vector3<f64>,
        t_max: f64,
        height_guess: Option<f64>,
    ) -> Option<Hit> {
        let a = self.max_height;
        let dy = direction.y;
        // Where the ray enters the slab |y| <= A, and where it leaves it below.
        let t_start = if origin.y > a {
            if dy >= 0.0 {
                return None;
            }
            (origin.y - a) / -dy
        } else {
            0.0
        };
        let t_end = if dy < 0.0 {
            ((origin.y + a) / -dy).min(t_max)
        } else {
            t_max
        };
        if t_start > t_end {
            return None;
        }
        let horizontal = Vector2::new(direction.x, direction.z).norm();
        let f = |t: f64| -> Sample {
            let p = origin + direction * t;
            let (h, gradient) = self.height_and_gradient(p.x, p.z);
            Sample {
                value: p.y - h,
                slope: dy - gradient.x * direction.x - gradient.y * direction.z,
                gradient,
            }
        };
        // Above the slab the ray starts above the surface; within it, check.
        let start = (origin.y <= a).then(|| f(t_start));
        if start.is_some_and(|s| s.value < 0.0) {
            // The origin is under the surface: nothing is seen from there.
            return None;
        }
        let (t, gradient) = if -dy > self.max_slope * horizontal {
            // Beyond t_max the slab's far side is not reached: the root may be.
            let capped = dy >= 0.0 || (origin.y + a) / -dy > t_max;
            let guess = (height_guess.unwrap_or(0.0) - origin.y) / dy;
            // |f''| ≤ max_curvature·|d_xz|² bounds Newton's next error.
            let curvature = self.max_curvature * horizontal * horizontal;
            newton_in_bracket(&f, t_start, t_end, guess, capped, curvature)?
        } else {
            let value = start.unwrap_or_else(|| f(t_start)).value;
            sphere_trace(
                &f,
                t_start,
                t_end,
                value,
                dy.abs() + self.max_slope * horizontal,
            )?
        };
        if t <= T_MIN || t > t_max {
            return None;
        }
        let mut normal = Vector3::new(-gradient.x, 1.0, -gradient.y).normalize();
        if normal.dot(direction) > 0.0 {
            normal = -normal;
        }
        Some(Hit {
            t,
            normal,
            surface: Surface::Ground,
        })
    }
}

/// `f(t) = y(t) - h(x(t), z(t))` along a ray, its slope, and the surface's
/// gradient below the point.
#[derive(Debug, Clone, Copy)]
pub(super) struct Sample {
    pub(super) value: f64,
    pub(super) slope: f64,
    pub(super) gradient: Vector2<f64>,
}

/// Newton's search ends when the error of its next step, bounded by
/// `|f''|·step²/(2·|f'|)`, is below this (metres along a unit ray).
pub(super) const NEWTON_TOLERANCE: f64 = 1e-11;

/// The root of a decreasing `f` in `[lo, hi]` (`f(lo) ≥ 0`), by Newton's
/// method from `guess`, falling back to bisection when a step leaves the
/// bracket; with the surface's gradient there. When `capped` (the bracket
/// ends at `t_max`, not at the slab's far side) and `f(hi) > 0`, the root
/// lies beyond `t_max`: `None`. `curvature` bounds `|f''|`: once a step is
/// so short that the next one would be below [`NEWTON_TOLERANCE`], the step
/// is taken without evaluating `f` again.
pub(super) fn newton_in_bracket(
    f: &impl Fn(f64) -> Sample,
    mut lo: f64,
    mut hi: f64,
    guess: f64,
    capped: bool,
    curvature: f64,
) -> Option<(f64, Vector2<f64>)> {
    if capped && f(hi).value > 0.0 {
        return None;
    }
    let mut t = guess.clamp(lo, hi);
    let mut gradient = Vector2::zeros();
    for _ in 0..100 {
        let s = f(t);
        gradient = s.gradient;
        if s.value > 0.0 {
            lo = t;
        } else {
            hi = t;
        }
        if s.value == 0.0 {
            break;
        }
        let mut next = t - s.value / s.slope;
        let newton = next >= lo && next <= hi;
        if !newton {
            next = 0.5 * (lo + hi);
        }
        let step = next - t;
        t = next;
        if (newton && curvature * step * step < 2.0 * NEWTON_TOLERANCE * s.slope.abs())
            || hi - lo < 1e-13
        {
            break;
        }
    }
    Some((t, gradient))
}

/// The first root of `f` in `[t, t_end]` by sphere tracing with the
/// Lipschitz bound `lipschitz`, finished by Newton's method.
pub(super) fn sphere_trace(
    f: &impl Fn(f64) -> Sample,
    mut t: f64,
    t_end: f64,
    mut value: f64,
    lipschitz: f64,
) -> Option<(f64, Vector2<f64>)> {
    if lipschitz <= 0.0 {
        return None;
    }
    // Where Newton takes over: close enough that the surface is locally a
    // plane to far better than a micrometre.
    const NEAR: f64 = 1e-4;
    let mut steps = 0;
    while value > NEAR {
        t += value / lipschitz;
        if t > t_end || steps > 10_000 {
            return None;
        }
        value = f(t).value;
        steps += 1;
    }
    // Newton from just above the surface. It can only fail near a tangent
    // ray, where the sphere-traced point is already within NEAR.
    let mut s = f(t);
    for _ in 0..8 {
        if s.value.abs() < 1e-12 || s.slope >= -1e-12 {
            break;
        }
        let next = t - s.value / s.slope;
        if !(next.is_finite() && (next - t).abs() < 10.0 * NEAR / s.slope.abs().max(1e-3)) {
            break;
        }
        t = next;
        s = f(t);
    }
    Some((t, s.gradient))
}
