//! What the poses' disagreement with the result says of its cause.
//!
//! Each used pose's measured ground disagrees with the ground the result
//! predicts by a height `e_d` (the paper's section 5.2). The gate on the
//! largest of them says a ground that is not flat or a body pose that is
//! wrong, and often that is so. But a depth camera's own noise grows with
//! the ground's distance (a disparity camera's as z², and its correlated
//! noise, held through a still pose, does not average away), so a schedule
//! whose farthest poses look at ground 1.2 m off can pass the gate's
//! millimetres on noise alone: under the simulator's Kinect noise,
//! designed-52 on flat ground, `e_d` grew as the distance to the power 2.4–5.2
//! over eight seeds, 0.4 mm RMS below 0.87 m and 2.2 mm beyond 1.1 m, and
//! four of the eight failed the 5 mm gate with words that sent the
//! technician to check the flat ground he stood on (docs/method.md).
//!
//! So the disagreement is asked whether it grows with distance, and whether
//! its largest is ordinary for its pose's distance: `ln e_d` against
//! `ln d` by least squares (a noise `σ·dᵖ` makes `e_d = σ·dᵖ·|z|`, whose
//! log is linear in `ln d` with the same scatter at every distance),
//! `e_d`'s σ at each distance from the fit, and the largest in that σ
//! against the largest that many poses draw by chance. Uneven ground gave
//! no such growth (exponent 0–1.1, under 1σ, four seeds): its poses
//! disagree wherever the ground is bumpy, near or far.

use crate::outcome::{GrowthWithDistance, PoseOutcome};

/// Fewest poses whose disagreement is asked how it grows: two parameters
/// from their scatter.
const MIN_POSES: usize = 12;

/// The growth must stand this far out of its σ to be said.
const MIN_EXPONENT_SIGMAS: f64 = 2.0;

/// The farthest pose's ground at least this many times the nearest's:
/// nearer alike, no growth could show.
const MIN_DISTANCE_RATIO: f64 = 1.2;

/// `E[ln |z|]` of a standard normal `z`: `−(γ + ln 2)/2`.
const MEAN_LN_ABS_NORMAL: f64 = -0.635_181_422_730_739;

impl GrowthWithDistance {
    /// Whether the disagreement is the noise's growth with distance: the
    /// growth stands out, and the largest `e_d` is within what chance
    /// gives that many poses at its distance.
    pub fn explains_the_largest(&self) -> bool {
        self.exponent_sigmas >= MIN_EXPONENT_SIGMAS && self.worst_sigmas <= self.worst_bound
    }

    /// `e_d`'s σ (m) at a ground distance `d` (m).
    fn sigma_at(log_intercept: f64, exponent: f64, d: f64) -> f64 {
        (log_intercept - MEAN_LN_ABS_NORMAL + exponent * d.ln()).exp()
    }
}

/// How the used poses' `e_d` grows with their ground's distance; `None`
/// with fewer than [`MIN_POSES`] poses that disagree at all, or distances
/// too alike to tell.
pub fn growth_with_distance(poses: &[PoseOutcome]) -> Option<GrowthWithDistance> {
    let distance = |p: &PoseOutcome| p.measured.d.abs();
    // Each pose with `ln d` and `ln e_d`.
    let used: Vec<(&PoseOutcome, f64, f64)> = poses
        .iter()
        .filter(|p| p.used && p.e_d > 0.0 && p.e_d.is_finite() && distance(p) > 0.0)
        .map(|p| (p, distance(p).ln(), p.e_d.ln()))
        .collect();
    let n = used.len();
    if n < MIN_POSES {
        return None;
    }
    let distances = used.iter().map(|u| distance(u.0));
    let nearest = distances.clone().fold(f64::INFINITY, f64::min);
    let farthest = distances.fold(0.0, f64::max);
    if farthest < MIN_DISTANCE_RATIO * nearest {
        return None;
    }
    let count = n as f64;
    let mean_x = used.iter().map(|u| u.1).sum::<f64>() / count;
    let mean_y = used.iter().map(|u| u.2).sum::<f64>() / count;
    let sxx: f64 = used.iter().map(|u| (u.1 - mean_x).powi(2)).sum();
    let sxy: f64 = used.iter().map(|u| (u.1 - mean_x) * (u.2 - mean_y)).sum();
    let exponent = sxy / sxx;
    let intercept = mean_y - exponent * mean_x;
    let rss: f64 = used
        .iter()
        .map(|u| (u.2 - intercept - exponent * u.1).powi(2))
        .sum();
    let scatter = (rss / (count - 2.0)).sqrt();
    let exponent_sigmas = exponent / (scatter / sxx.sqrt());
    let sigma = |d: f64| GrowthWithDistance::sigma_at(intercept, exponent, d);
    let (worst, _, _) = used
        .iter()
        .copied()
        .max_by(|a, b| a.0.e_d.total_cmp(&b.0.e_d))?;
    Some(GrowthWithDistance {
        exponent,
        exponent_sigmas,
        nearest: [nearest, sigma(nearest)],
        farthest: [farthest, sigma(farthest)],
        worst_pose: worst.index,
        worst_sigmas: worst.e_d / sigma(distance(worst)),
        worst_bound: normal_upper_quantile(0.005 / count),
    })
}

/// The `x` a standard normal exceeds with probability `tail` (at most
/// 0.024): Acklam's rational approximation of the normal quantile in its
/// tail region, within 10⁻⁸ of the exact one relative.
pub fn normal_upper_quantile(tail: f64) -> f64 {
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    let q = (-2.0 * tail.clamp(1e-300, 0.024_25).ln()).sqrt();
    let numerator = C.iter().fold(0.0, |acc, c| acc * q + c);
    let denominator = D.iter().fold(0.0, |acc, d| acc * q + d) * q + 1.0;
    -numerator / denominator
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Plane;
    use crate::test_noise::gaussian;
    use nalgebra::Vector3;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn pose(index: u32, distance: f64, e_d: f64) -> PoseOutcome {
        let plane = Plane {
            normal: Vector3::y(),
            d: distance,
        };
        PoseOutcome {
            index,
            used: true,
            reason: None,
            measured: plane,
            predicted: plane,
            theta: 0.0,
            e_d,
            inliers: None,
            note: None,
        }
    }

    /// Poses whose ground lies 0.65–1.25 m off, `e_d` drawn as
    /// `σ(d)·|z|`.
    fn drawn(seed: u64, sigma: impl Fn(f64) -> f64) -> Vec<PoseOutcome> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..52)
            .map(|i| {
                let d = 0.65 + 0.6 * (i as f64 * 0.618_034).fract();
                pose(i + 1, d, sigma(d) * gaussian(&mut rng).abs())
            })
            .collect()
    }

    #[test]
    fn the_quantile_is_the_normals() {
        // Python's statistics.NormalDist().inv_cdf(1 − tail).
        for (tail, x) in [
            (0.01, 2.326_347_874),
            (0.001, 3.090_232_306),
            (1e-4, 3.719_016_485),
            (0.005 / 52.0, 3.728_912_783),
            (1e-8, 5.612_001_244),
        ] {
            let found = normal_upper_quantile(tail);
            assert!((found - x).abs() < 1e-6 * x, "{tail}: {found} against {x}");
        }
    }

    /// A noise that grows as d⁴ (the simulator's Kinect, held through a
    /// pose) explains its largest pose, seed after seed; the exponent is
    /// found within its σ.
    #[test]
    fn noise_that_grows_with_distance_explains_the_largest_disagreement() {
        let mut explained = 0;
        for seed in 0..40 {
            let poses = drawn(seed, |d| 1e-3 * d.powi(4));
            let growth = growth_with_distance(&poses).expect("enough poses");
            assert!(
                (growth.exponent - 4.0).abs() < 4.0 * growth.exponent / growth.exponent_sigmas,
                "{growth:?}"
            );
            explained += usize::from(growth.explains_the_largest());
        }
        // The bound is the 1 % point of the largest: about one in a hundred
        // fall past it, and a trend this strong always stands out.
        assert!(explained >= 37, "{explained} of 40");
    }

    /// The same poses with one wrong by 8 mm at a near pose (a foot that
    /// slipped there), or a noise the same at every distance (bumps of the
    /// ground): not the growth with distance.
    #[test]
    fn a_wrong_pose_or_noise_alike_at_every_distance_is_not_explained() {
        for seed in 0..20 {
            let mut poses = drawn(seed, |d| 1e-3 * d.powi(4));
            let nearest = (0..poses.len())
                .min_by(|&a, &b| poses[a].measured.d.total_cmp(&poses[b].measured.d))
                .unwrap();
            poses[nearest].e_d = 8e-3;
            let growth = growth_with_distance(&poses).unwrap();
            assert!(!growth.explains_the_largest(), "{seed}: {growth:?}");
            assert_eq!(growth.worst_pose, poses[nearest].index);

            let bumps = drawn(seed, |_| 1.5e-3);
            let growth = growth_with_distance(&bumps).unwrap();
            assert!(
                !growth.explains_the_largest() || growth.exponent_sigmas < 3.0,
                "{seed}: {growth:?}"
            );
        }
        // Over many seeds, alike at every distance passes the trend's
        // threshold about as often as a one-sided 2σ does (2.3 %).
        let passed = (100..300)
            .filter(|&seed| {
                growth_with_distance(&drawn(seed, |_| 1.5e-3))
                    .is_some_and(|g| g.explains_the_largest())
            })
            .count();
        assert!(passed <= 12, "{passed} of 200");
    }

    #[test]
    fn too_few_poses_or_distances_too_alike_say_nothing() {
        let poses = drawn(1, |d| 1e-3 * d.powi(4));
        assert!(growth_with_distance(&poses[..MIN_POSES - 1]).is_none());
        let alike: Vec<PoseOutcome> = (0..30)
            .map(|i| pose(i + 1, 1.0 + 0.001 * i as f64, 1e-3 * (1.0 + (i % 3) as f64)))
            .collect();
        assert!(growth_with_distance(&alike).is_none());
        let mut unused = poses.clone();
        for p in unused.iter_mut().skip(5) {
            p.used = false;
        }
        assert!(growth_with_distance(&unused).is_none());
    }
}
