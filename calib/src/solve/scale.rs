//! The depth scale solved with the translation: the joint fit of the
//! position and the scale's correction from the poses' heights, and the
//! solve at a fixed scale.

use super::*;

pub(super) fn solve_fallback(settings: &SolveSettings) -> f64 {
    match settings.depth_scale {
        DepthScaleSetting::Estimate { fallback } => fallback,
        DepthScaleSetting::Fixed(s) => s,
    }
}

/// The joint fit of the translation and the depth scale's correction.
pub(super) struct ScaleFit {
    /// q: the factor by which the current scale's inverse is off (the next
    /// scale is the current one divided by q).
    pub(super) scale_ratio: f64,
    /// Covariance of (p_x, p_y, p_z, q) for unit noise.
    pub(super) covariance: Matrix4<f64>,
    /// RMS (weighted) of the distances beyond what the tilts explain.
    pub(super) leverage: f64,
    /// Covariance of (p_x, p_y, p_z, q) by leaving each pose out
    /// ([`super::jackknife`]), in the noise the poses show.
    pub(super) jackknife: Option<Matrix4<f64>>,
}

/// Weighted least squares of `up · p − q·d' + h = 0` over the used poses
/// (d' the distance at the current scale), with the solve's offset weights.
pub(super) fn scale_fit(
    used: &[&Observation],
    settings: &SolveSettings,
    scale: f64,
) -> Option<ScaleFit> {
    if used.len() < 5 {
        return None;
    }
    let mut normal = Matrix4::zeros();
    let mut rhs = nalgebra::Vector4::zeros();
    let mut up_block = Matrix3::zeros();
    let mut up_d = Vector3::zeros();
    let (mut dd, mut weight_sum) = (0.0, 0.0);
    let mut rows = Vec::with_capacity(used.len());
    for o in used {
        let w = Weights::of(o, settings).offset_whitener.powi(2) * scale * scale;
        let up = o.up_in_robot();
        let d = o.plane.d / scale;
        let row = nalgebra::Vector4::new(up.x, up.y, up.z, -d);
        normal += row * row.transpose() * w;
        rhs += row * (-o.body_height() * w);
        rows.push((row, -o.body_height(), w));
        up_block += up * up.transpose() * w;
        up_d += up * (d * w);
        dd += d * d * w;
        weight_sum += w;
    }
    let covariance = normal.try_inverse()?;
    let x = covariance * rhs;
    // The part of the distances the tilts' up vectors cannot explain.
    let explained = up_block
        .try_inverse()
        .map_or(0.0, |h| (up_d.transpose() * h * up_d)[(0, 0)]);
    let leverage = ((dd - explained).max(0.0) / weight_sum).sqrt();
    Some(ScaleFit {
        scale_ratio: 1.0 / x[3],
        covariance,
        leverage,
        jackknife: super::jackknife::joint_covariance(&rows, &normal, &rhs),
    })
}

/// The six parameters with the measured distances divided by `scale`.
pub(super) fn solve_at_scale(
    observations: &[Observation],
    settings: &SolveSettings,
    scale: f64,
) -> Result<Solution, SolveError> {
    solve_six(&at_scale(observations, scale), settings)
}

/// The observations with their distances, and the distances' covariance,
/// read at the depth scale `scale` (divided by it).
pub(super) fn at_scale(
    observations: &[Observation],
    scale: f64,
) -> std::borrow::Cow<'_, [Observation]> {
    if scale == 1.0 {
        return std::borrow::Cow::Borrowed(observations);
    }
    std::borrow::Cow::Owned(
        observations
            .iter()
            .map(|o| {
                let mut o = o.clone();
                o.plane.d /= scale;
                if let Some(c) = &mut o.plane_covariance {
                    for i in 0..4 {
                        c[(3, i)] /= scale;
                        c[(i, 3)] /= scale;
                    }
                }
                o
            })
            .collect(),
    )
}
