//! The position's covariance from the poses themselves: each pose left out
//! in turn and the position solved again (the delete-one jackknife).
//!
//! The covariance of a least-squares fit, `(JᵀWJ)⁻¹` times the residuals'
//! mean square, holds when the weights match each pose's noise. A Kinect's
//! noise does not let them: most of it is correlated over the image and
//! held through a still pose, so a pose's ground is off by an amount its
//! own pixels do not show, and how much differs from pose to pose with
//! what the pose sees (measured on the simulated Kinect, designed-52, 16
//! seeds: 0.25 to 3.2 mm RMS). The poses that pin the position best, the
//! steepest tilts, see the ground farthest and are among the noisiest. So
//! the formula said ±0.62 and ±0.17 mm for px and py where the errors
//! scattered by 1.0 and 0.33 (docs/method.md). The jackknife asks no model
//! of each pose's noise: the poses are independent draws, and how far the
//! estimate moves without each one shows how much each one holds it
//! (asymptotically the sandwich covariance, a little larger in small
//! samples, which errs on the safe side).
//!
//! The offsets' residuals depend on the position alone (eq. 31), so each
//! replicate solves only the three coordinates, with the Cauchy weights of
//! [`super::refine`] found again without the pose: 52 small linear solves.

use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};

use super::{
    median_in_place, Observation, SolveSettings, Weights, CAUCHY, MIN_EVIDENCE_DOF, ROUNDS,
};

/// One pose's offset equation: `up · p + height = d`, whitened by `whitener`.
#[derive(Debug, Clone, Copy)]
struct OffsetRow {
    up: Vector3<f64>,
    height: f64,
    d: f64,
    whitener: f64,
}

impl OffsetRow {
    fn of(observation: &Observation, settings: &SolveSettings) -> Self {
        Self {
            up: observation.up_in_robot(),
            height: observation.body_height(),
            d: observation.plane.d,
            whitener: Weights::of(observation, settings).offset_whitener,
        }
    }

    /// The whitened residual at the position `p`.
    fn residual(&self, p: &Vector3<f64>) -> f64 {
        (self.up.dot(p) + self.height - self.d) * self.whitener
    }
}

/// The position that the rows' offsets give (all but `left_out`), with
/// Cauchy weights found by iterated reweighting at the same scale as the
/// solve's (2.385 robust σ of the whitened residuals, never less than the
/// assumed noise), starting from `robust` and leaving the last ones there.
/// `sizes` is room for the residuals' sizes (no allocation per round).
fn position_from_offsets(
    rows: &[OffsetRow],
    left_out: Option<usize>,
    robust: &mut [f64],
    sizes: &mut Vec<f64>,
) -> Option<Vector3<f64>> {
    let kept = |k: usize| Some(k) != left_out;
    let mut position = None;
    for _ in 0..ROUNDS {
        let (mut normal, mut rhs) = (Matrix3::zeros(), Vector3::zeros());
        for (k, (row, r)) in rows.iter().zip(robust.iter()).enumerate() {
            if kept(k) {
                let w = r * row.whitener * row.whitener;
                normal += row.up * row.up.transpose() * w;
                rhs += row.up * ((row.d - row.height) * w);
            }
        }
        let p = normal.try_inverse()? * rhs;
        position = Some(p);
        sizes.clear();
        sizes.extend(
            rows.iter()
                .enumerate()
                .filter(|(k, _)| kept(*k))
                .map(|(_, row)| row.residual(&p).abs()),
        );
        let c = CAUCHY * (median_in_place(sizes) / 0.6745).max(1.0);
        let mut change: f64 = 0.0;
        for (k, (row, w)) in rows.iter().zip(robust.iter_mut()).enumerate() {
            if kept(k) {
                let next = 1.0 / (1.0 + (row.residual(&p).abs() / c).powi(2));
                change = change.max((next - *w).abs());
                *w = next;
            }
        }
        if change < 1e-9 {
            break;
        }
    }
    position
}

/// The delete-one jackknife's covariance of estimates made without each
/// item in turn: `(n − 1)/n · Σ (θᵢ − θ̄)(θᵢ − θ̄)ᵀ`.
fn jackknife_covariance<const N: usize>(
    replicates: &[nalgebra::SVector<f64, N>],
) -> nalgebra::SMatrix<f64, N, N> {
    let n = replicates.len() as f64;
    let mean = replicates
        .iter()
        .fold(nalgebra::SVector::<f64, N>::zeros(), |s, r| s + r)
        / n;
    let spread = replicates
        .iter()
        .fold(nalgebra::SMatrix::<f64, N, N>::zeros(), |s, r| {
            s + (r - mean) * (r - mean).transpose()
        });
    spread * ((n - 1.0) / n)
}

/// The covariance of the position (metres²) by leaving each used pose out;
/// `None` when the poses, as their Cauchy weights count them, leave fewer
/// than [`MIN_EVIDENCE_DOF`] residual degrees of freedom (the solve's own
/// test: a short schedule cannot vouch for itself), or a replicate cannot
/// be solved (the poses left do not pin the position).
pub(super) fn position_covariance(
    used: &[&Observation],
    settings: &SolveSettings,
) -> Option<Matrix3<f64>> {
    let rows: Vec<OffsetRow> = used.iter().map(|o| OffsetRow::of(o, settings)).collect();
    let mut sizes = Vec::with_capacity(rows.len());
    // Each replicate starts from the weights of all the poses: a few
    // rounds from there instead of tens from equal weights.
    let mut all = vec![1.0; rows.len()];
    position_from_offsets(&rows, None, &mut all, &mut sizes)?;
    if all.iter().sum::<f64>() - 3.0 < MIN_EVIDENCE_DOF {
        return None;
    }
    let mut robust = all.clone();
    let replicates = (0..rows.len())
        .map(|left_out| {
            robust.copy_from_slice(&all);
            position_from_offsets(&rows, Some(left_out), &mut robust, &mut sizes)
        })
        .collect::<Option<Vec<_>>>()?;
    Some(jackknife_covariance(&replicates))
}

/// `covariance` with each σ raised to `floor`'s where it is smaller, its
/// correlations kept.
pub(super) fn at_least<const N: usize>(
    covariance: &nalgebra::SMatrix<f64, N, N>,
    floor: &nalgebra::SMatrix<f64, N, N>,
) -> nalgebra::SMatrix<f64, N, N> {
    let sigma = |m: &nalgebra::SMatrix<f64, N, N>, i: usize| m[(i, i)].max(0.0).sqrt();
    let raise = |i: usize| {
        let (own, least) = (sigma(covariance, i), sigma(floor, i));
        if own > 0.0 && own < least {
            least / own
        } else {
            1.0
        }
    };
    nalgebra::SMatrix::<f64, N, N>::from_fn(|i, j| {
        let raised = covariance[(i, j)] * raise(i) * raise(j);
        if i == j {
            raised.max(floor[(i, i)])
        } else {
            raised
        }
    })
}

/// The covariance of the joint fit's `(p_x, p_y, p_z, q)` by leaving each
/// pose out ([`super::scale::scale_fit`]'s weighted least squares, each
/// pose's terms taken out of the sums), or `None` when one cannot be solved.
pub(super) fn joint_covariance(
    rows: &[(Vector4<f64>, f64, f64)],
    normal: &Matrix4<f64>,
    rhs: &Vector4<f64>,
) -> Option<Matrix4<f64>> {
    let replicates = rows
        .iter()
        .map(|(row, target, w)| {
            let without = normal - row * row.transpose() * *w;
            let rhs = rhs - row * (target * w);
            Some(without.try_inverse()? * rhs)
        })
        .collect::<Option<Vec<_>>>()?;
    Some(jackknife_covariance(&replicates))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::PoseParams;
    use crate::solve::exact_observation;
    use crate::test_noise::gaussian;
    use rand::{Rng, SeedableRng};

    /// Body poses of a schedule's kind (`ground_from_robot`): tilts up to
    /// 20° about both horizontal axes, heights 0.60–0.75 m.
    fn schedule(count: usize) -> Vec<PoseParams> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        (0..count)
            .map(|_| {
                PoseParams::new(
                    rng.gen_range(-0.1..0.1),
                    rng.gen_range(-0.35..0.35),
                    rng.gen_range(-0.35..0.35),
                    Vector3::new(0.0, rng.gen_range(0.60..0.75), 0.0),
                )
            })
            .collect()
    }

    /// Under independent noise whose size differs from pose to pose, and is
    /// largest where the poses tilt most (the case of the Kinect's held
    /// noise), the jackknife's σ match the scatter of the estimates over
    /// many draws, where the residuals' mean square under-states it.
    #[test]
    fn the_jackknife_matches_the_scatter_of_unequal_noise() {
        let truth = PoseParams::new(
            0.8f64.to_radians(),
            (-33.0f64).to_radians(),
            1.5f64.to_radians(),
            Vector3::new(0.510, 0.370, 0.015),
        );
        let settings = SolveSettings::default();
        let poses = schedule(52);
        // Each pose's σ grows with its tilt: 0.2 mm level, 3 mm at 20°.
        let sigmas: Vec<f64> = poses
            .iter()
            .map(|p| 2e-4 + 2.8e-3 * (p.beta.abs().max(p.gamma.abs()) / 0.35).powi(3))
            .collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (mut errors, mut jackknife, mut formula) = (vec![], vec![], vec![]);
        for _ in 0..400 {
            let observations: Vec<Observation> = poses
                .iter()
                .zip(&sigmas)
                .enumerate()
                .map(|(k, (pose, sigma))| {
                    let mut o = exact_observation(k as u32 + 1, pose.to_transform(), &truth);
                    o.plane.d += sigma * gaussian(&mut rng);
                    o.plane_covariance = None;
                    o
                })
                .collect();
            let used: Vec<&Observation> = observations.iter().collect();
            let rows: Vec<OffsetRow> = used.iter().map(|o| OffsetRow::of(o, &settings)).collect();
            let mut robust = vec![1.0; rows.len()];
            let p = position_from_offsets(&rows, None, &mut robust, &mut vec![]).unwrap();
            errors.push(p - truth.translation);
            jackknife.push(position_covariance(&used, &settings).unwrap());
            // The formula: (UᵀWU)⁻¹ × the weighted mean square.
            let (mut information, mut chi2, mut weight) = (Matrix3::zeros(), 0.0, 0.0);
            let sizes: Vec<f64> = rows.iter().map(|r| r.residual(&p).abs()).collect();
            let c = CAUCHY * (median_in_place(&mut sizes.clone()) / 0.6745).max(1.0);
            for (row, size) in rows.iter().zip(&sizes) {
                let w = 1.0 / (1.0 + (size / c).powi(2));
                information += row.up * row.up.transpose() * (w * row.whitener * row.whitener);
                chi2 += w * size * size;
                weight += w;
            }
            formula.push(information.try_inverse().unwrap() * (chi2 / (weight - 3.0)));
        }
        for axis in 0..3 {
            let scatter =
                (errors.iter().map(|e| e[axis].powi(2)).sum::<f64>() / errors.len() as f64).sqrt();
            let rms_sigma = |c: &[Matrix3<f64>]| {
                (c.iter().map(|m| m[(axis, axis)]).sum::<f64>() / c.len() as f64).sqrt()
            };
            let (by_jackknife, by_formula) = (rms_sigma(&jackknife), rms_sigma(&formula));
            // Measured: the scatter 1.408, 0.162, 1.134 mm; the jackknife
            // 1.490, 0.185, 1.239; the formula 0.952, 0.180, 0.884.
            assert!(
                (by_jackknife / scatter - 1.0).abs() < 0.15,
                "axis {axis}: the jackknife's σ {by_jackknife:.2e} m, the scatter {scatter:.2e}"
            );
            if axis != 1 {
                assert!(
                    by_formula < 0.8 * scatter,
                    "axis {axis}: the formula's σ {by_formula:.2e} m, the scatter {scatter:.2e}"
                );
            }
        }
    }
}
