//! What the schedule can tell: the singular values of the solve's Jacobian
//! per observation, the weakest rotation and position directions, and the
//! problems named when one of them is below the threshold.

use super::*;

/// An eigenvector with a fixed sign (its largest component positive), so
/// that equal directions print equally.
pub(super) fn signed_axis(v: &Vector3<f64>) -> [f64; 3] {
    let largest = v
        .iter()
        .copied()
        .fold(0.0, |m: f64, x| if x.abs() > m.abs() { x } else { m });
    let sign = if largest < 0.0 { -1.0 } else { 1.0 };
    [v.x * sign, v.y * sign, v.z * sign]
}

/// Singular values of the per-observation Jacobian blocks and the words for
/// every direction the schedule cannot observe.
///
/// With unit noise, the rotation block of observation i is `[up_i]×` (how the
/// normal moves as the sensor turns), and the translation block is `up_iᵀ`.
/// Their Gram matrices, divided by the number of observations, are
/// `mean(I - up·upᵀ)` and `mean(up·upᵀ)`.
pub fn observability(used: &[&Observation], settings: &SolveSettings) -> Observability {
    let n = used.len().max(1) as f64;
    let ups: Vec<Vector3<f64>> = used.iter().map(|o| o.up_in_robot()).collect();
    let rotation_gram: Matrix3<f64> = ups
        .iter()
        .map(|u| Matrix3::identity() - u * u.transpose())
        .sum::<Matrix3<f64>>()
        / n;
    let translation_gram: Matrix3<f64> =
        ups.iter().map(|u| u * u.transpose()).sum::<Matrix3<f64>>() / n;
    let spectrum = |gram: Matrix3<f64>| {
        let eigen = SymmetricEigen::new(gram);
        let mut pairs: Vec<(f64, Vector3<f64>)> = (0..3)
            .map(|k| {
                (
                    eigen.eigenvalues[k].max(0.0).sqrt(),
                    eigen.eigenvectors.column(k).into_owned(),
                )
            })
            .collect();
        pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
        pairs
    };
    let rotation = spectrum(rotation_gram);
    let translation = spectrum(translation_gram);

    let mean_up = ups.iter().sum::<Vector3<f64>>().normalize();
    let max_tilt_spread = ups
        .iter()
        .map(|u| angle_between(u, &mean_up))
        .fold(0.0, f64::max);
    let never_tilts = max_tilt_spread < 1f64.to_radians();

    let mut problems = Vec::new();
    let weak_rotations: Vec<&Vector3<f64>> = rotation
        .iter()
        .filter(|(s, _)| *s < settings.min_spread)
        .map(|(_, v)| v)
        .collect();
    if !weak_rotations.is_empty() {
        problems.push(if never_tilts {
            "rotation of the sensor about the ground normal (α) is not observable: the schedule never tilts the body".to_string()
        } else {
            let v = weak_rotations[0];
            format!(
                "rotation of the sensor about the axis ({:.2}, {:.2}, {:.2}) of the body is not observable: the body's tilts barely change the ground's direction; use larger tilts",
                v.x, v.y, v.z
            )
        });
    }
    let weak_translations: Vec<&Vector3<f64>> = translation
        .iter()
        .filter(|(s, _)| *s < settings.min_spread)
        .map(|(_, v)| v)
        .collect();
    if !weak_translations.is_empty() {
        // Which body axes lie in the unobservable subspace.
        let mut axes: Vec<(usize, f64)> = (0..3)
            .map(|a| {
                (
                    a,
                    weak_translations
                        .iter()
                        .map(|v| v[a].powi(2))
                        .sum::<f64>()
                        .sqrt(),
                )
            })
            .collect();
        axes.sort_by(|a, b| b.1.total_cmp(&a.1));
        let named: Vec<usize> = axes
            .iter()
            .take(weak_translations.len())
            .map(|(a, _)| *a)
            .collect();
        let position_words: Vec<String> = named.iter().map(|&a| position_axis_words(a)).collect();
        let what = format!(
            "the sensor's {} position{}",
            position_words.join(" and "),
            if named.len() > 1 { "s" } else { "" }
        );
        let why = if never_tilts {
            "the schedule never tilts the body".to_string()
        } else if named == [2] {
            "the schedule only pitches the body (turns it about its sideways Z axis, β′); add poses that roll it (γ′)".to_string()
        } else if named == [0] {
            "the schedule only rolls the body (turns it about its forward X axis, γ′); add poses that pitch it (β′)".to_string()
        } else {
            "the body's tilts all share one axis; add poses that tilt it about another".to_string()
        };
        problems.push(format!(
            "{what} {} not observable: {why}",
            if named.len() > 1 { "are" } else { "is" }
        ));
    }
    Observability {
        rotation_singular_values: [rotation[0].0, rotation[1].0, rotation[2].0],
        translation_singular_values: [translation[0].0, translation[1].0, translation[2].0],
        rotation_weakest_axis: signed_axis(&rotation[2].1),
        translation_weakest_axis: signed_axis(&translation[2].1),
        min_singular_value: settings.min_spread,
        problems,
    }
}
