//! Which observation to set aside: each pose's θ and e_d under a result, its
//! leave-one-out prediction against the spread of the others' (step 2), and
//! the reason in words.

use super::*;

/// θ and e_d of an observation under a result.
pub(super) fn errors(robot_from_sensor: &PoseParams, obs: &Observation) -> (Plane, f64, f64) {
    let predicted = predict(robot_from_sensor, &obs.ground_from_robot);
    let theta = angle_between(&predicted.normal, &obs.plane.normal);
    (predicted, theta, (predicted.d - obs.plane.d).abs())
}

/// The spread of a leave-one-out prediction: the noise of the left-out
/// observation plus what the others leave unknown (its leverage).
pub(super) struct Prediction {
    /// Standard deviation of each tangent component of the normal, radians.
    pub(super) normal_sigma: f64,
    /// Standard deviation of the offset, metres.
    pub(super) offset_sigma: f64,
}

/// How well `others` predict `target`, with the noise level estimated from
/// the others' own residuals under `estimate`.
pub(super) fn prediction_spread(
    others: &[&Observation],
    estimate: &PoseParams,
    target: &Observation,
    settings: &SolveSettings,
) -> Prediction {
    let mut rotation_info = Matrix3::zeros();
    let mut translation_info = Matrix3::zeros();
    let (mut chi2_n, mut chi2_d) = (0.0, 0.0);
    for o in others {
        let w = Weights::of(o, settings);
        let (wn, wd) = (w.normal_weight(), w.offset_whitener.powi(2));
        let up = o.up_in_robot();
        rotation_info += (Matrix3::identity() - up * up.transpose()) * wn;
        translation_info += up * up.transpose() * wd;
        let (_, theta, e_d) = errors(estimate, o);
        chi2_n += wn * theta * theta;
        chi2_d += wd * e_d * e_d;
    }
    let n = others.len() as f64;
    // Two tangent components per normal, one offset; three parameters each.
    let s2_n = chi2_n / (2.0 * n - 3.0).max(1.0);
    let s2_d = chi2_d / (n - 3.0).max(1.0);
    let w = Weights::of(target, settings);
    let up = target.up_in_robot();
    let cross = up.cross_matrix();
    let leverage_n = rotation_info
        .try_inverse()
        .map(|h| (cross * h * cross.transpose()).trace() / 2.0)
        .unwrap_or(f64::INFINITY);
    let leverage_d = translation_info
        .try_inverse()
        .map(|h| (up.transpose() * h * up)[(0, 0)])
        .unwrap_or(f64::INFINITY);
    Prediction {
        normal_sigma: (s2_n * (1.0 / w.normal_weight() + leverage_n)).sqrt(),
        offset_sigma: (s2_d * (1.0 / w.offset_whitener.powi(2) + leverage_d)).sqrt(),
    }
}

/// Finds the observation that disagrees most with all the others, if any is
/// beyond the thresholds, with a reason in words.
///
/// For each candidate, the others are solved without it (closed form) and its
/// prediction error is compared with the prediction's spread: the others' own
/// residual level and the candidate's leverage. A bad observation stands out
/// only once it is left out, so a single outlier among few poses cannot hide
/// by spoiling every fit it is in, and a pose that alone pins a direction down
/// is not blamed for the others' uncertainty there.
pub(super) fn worst_outlier(
    used: &[&Observation],
    settings: &SolveSettings,
) -> Option<(u32, String)> {
    if used.len() < 5 {
        return None;
    }
    struct Candidate {
        position: usize,
        theta: f64,
        e_d: f64,
        theta_limit: f64,
        offset_limit: f64,
    }
    let candidates = (0..used.len()).map(|i| {
        let others: Vec<&Observation> = used
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, o)| *o)
            .collect();
        let estimate = closed_form(&others, settings);
        let spread = prediction_spread(&others, &estimate, used[i], settings);
        let (_, theta, e_d) = errors(&estimate, used[i]);
        Candidate {
            position: i,
            theta,
            e_d,
            // θ of a 2-D error: its RMS is √2 per-component σ.
            theta_limit: (settings.outlier_k * std::f64::consts::SQRT_2 * spread.normal_sigma)
                .max(settings.outlier_angle_floor),
            offset_limit: (settings.outlier_k * spread.offset_sigma)
                .max(settings.outlier_offset_floor),
        }
    });
    let ratio = |c: &Candidate| (c.theta / c.theta_limit).max(c.e_d / c.offset_limit);
    let worst = candidates.max_by(|a, b| ratio(a).total_cmp(&ratio(b)))?;
    if ratio(&worst) <= 1.0 {
        return None;
    }
    let reason = if worst.theta / worst.theta_limit >= worst.e_d / worst.offset_limit {
        format!(
            "inconsistent with the other poses: its ground is tilted {:.2}° from where they put it (limit {:.2}°): a misfit plane, a slipped foot or a wrong pose",
            worst.theta.to_degrees(),
            worst.theta_limit.to_degrees()
        )
    } else {
        format!(
            "inconsistent with the other poses: its ground is {:.1} mm from where they put it (limit {:.1} mm): a misfit plane, a slipped foot or a wrong pose",
            worst.e_d * 1e3,
            worst.offset_limit * 1e3
        )
    };
    Some((used[worst.position].index, reason))
}
