//! The pattern as the result carries it: raw units per cell (shape and plane
//! part, and what a first estimate took out of the frames), σ, the tests'
//! figures and the words; and the shape to fit the frames about again.

use super::*;

/// What the default fit's residuals, taken beside another fit
/// (`--ground-fit paper`), and the geometry across that fit's planes show.
/// A warp that changes from pose to pose is left uncorrected as with the
/// default fit; a pattern fixed in the image (a shape, or an offset and
/// gradients the geometry finds) is left uncorrected too, with its RMS over
/// the cells seen, for the gate `warp_max_mm` to judge: that fit's planes
/// cannot be corrected by these residuals. The cells keep what was found,
/// but the pattern is not `corrected`, so nothing takes it out of a frame.
pub(super) fn pattern_not_corrected_by_another_fit(
    shape: &ShapeEstimate,
    plane_part: Option<&PlanePartEstimate>,
) -> DepthPattern {
    let shape_fixed = shape.significant() && shape.consistent();
    if !shape_fixed && plane_part.is_none() {
        // Nothing to fit again about: that fit's planes are never corrected.
        return DepthPattern {
            fit_again_about: None,
            ..pattern_of(shape, false, None, None)
        };
    }
    let mut pattern = pattern_of(shape, shape_fixed, plane_part, None);
    // The shape's RMS, as for a warp left uncorrected by the default fit;
    // without one, the offset's and gradients' over the cells seen.
    let rms = if shape_fixed {
        shape.all_cells_rms_raw
    } else {
        let cells: Vec<f64> = pattern.raw.iter().flatten().copied().collect();
        (cells.iter().map(|v| v * v).sum::<f64>() / cells.len().max(1) as f64).sqrt()
    };
    pattern.corrected = false;
    // Nothing to fit again about: that fit's planes are never corrected.
    pattern.fit_again_about = None;
    pattern.uncorrected_shape_rms_raw = Some(rms);
    pattern.uncorrected_fixed = true;
    pattern.note = Some(format!(
        "not corrected: the depth carries a pattern fixed in the image ({rms:.3} raw units RMS, seen by the default fit beside the paper's), which the paper's ground fit (--ground-fit paper) does not correct"
    ));
    pattern
}

/// The shape to fit the frames about again: when its peaks reach beyond the
/// fit's band and it was taken, or left out only for that, and no first
/// estimate was taken out already (the caller adds this one to it).
pub(super) fn fit_again_about(
    shape: &ShapeEstimate,
    shape_taken: bool,
    after_a_first_estimate: bool,
) -> Option<DepthCorrection> {
    let cut = matches!(
        shape.why_not_fixed(),
        Some(crate::outcome::WarpCause::BeyondTheFit { .. })
    );
    if after_a_first_estimate || !shape.peaks_cut_by_the_fit() || !(shape_taken || cut) {
        return None;
    }
    shape_cells(shape)
}

/// The shape as a correction of every cell, raw units, the cells no pose
/// saw given their neighbours' values.
pub(super) fn shape_cells(shape: &ShapeEstimate) -> Option<DepthCorrection> {
    let k_raw = shape.raw_per_inverse_depth;
    let cells: Vec<Option<f64>> = extended(&shape.shape, &shape.seen, shape.columns, shape.rows)
        .into_iter()
        .map(|v| Some(v * k_raw))
        .collect();
    DepthCorrection::from_cells(shape.columns, shape.rows, CELL_PX, &cells)
}

/// Gives each cell no pose saw the mean of its neighbours that have a
/// value, ring by ring outwards: a correction is interpolated between cell
/// centres, and one that fell to 0 past the cells seen would bend the
/// readings at their edge, which some poses see and others do not.
pub(super) fn extend_to_unseen_cells(cells: &mut [Option<f64>], columns: usize, rows: usize) {
    while cells.iter().any(Option::is_none) && cells.iter().any(Option::is_some) {
        let before = cells.to_vec();
        for k in 0..cells.len() {
            if before[k].is_some() {
                continue;
            }
            let (c, r) = ((k % columns) as isize, (k / columns) as isize);
            let (mut sum, mut count) = (0.0, 0);
            for (dc, dr) in [
                (-1, 0),
                (1, 0),
                (0, -1),
                (0, 1),
                (-1, -1),
                (1, 1),
                (-1, 1),
                (1, -1),
            ] {
                let (nc, nr) = (c + dc, r + dr);
                if nc < 0 || nr < 0 || nc >= columns as isize || nr >= rows as isize {
                    continue;
                }
                if let Some(value) = before[nr as usize * columns + nc as usize] {
                    sum += value;
                    count += 1;
                }
            }
            if count > 0 {
                cells[k] = Some(sum / f64::from(count));
            }
        }
    }
}

/// The pattern as the result carries it: raw units per cell, shape and
/// plane part, with σ and the words.
pub(super) fn pattern_of(
    shape: &ShapeEstimate,
    shape_taken: bool,
    plane_part: Option<&PlanePartEstimate>,
    taken_out: Option<&DepthCorrection>,
) -> DepthPattern {
    let k_raw = shape.raw_per_inverse_depth;
    let part_taken = plane_part.filter(|p| p.taken);
    let mut raw = Vec::with_capacity(shape.shape.len());
    let mut sigma_raw = Vec::with_capacity(shape.shape.len());
    for k in 0..shape.shape.len() {
        if !shape.seen[k] {
            raw.push(None);
            sigma_raw.push(None);
            continue;
        }
        let (du, dv) = shape.cell_offset(k);
        let basis = Vector3::new(1.0, du / 100.0, dv / 100.0);
        let mut value = 0.0;
        let mut variance = 0.0;
        if shape_taken {
            value += shape.shape[k] * k_raw;
        }
        if shape_taken || taken_out.is_some() {
            // What was taken out first is of the same readings: its
            // cells' noise is theirs.
            variance += shape.cell_variance[k] * k_raw * k_raw;
        }
        if let Some(first) = taken_out {
            let (du, dv) = shape.cell_offset(k);
            value += first.raw_at(du + shape.intrinsics.cx, dv + shape.intrinsics.cy);
        }
        if let Some(part) = part_taken {
            value += part.value.dot(&basis);
            variance += (basis.transpose() * part.covariance * basis)[(0, 0)];
        }
        raw.push(Some(value));
        sigma_raw.push(Some(variance.max(0.0).sqrt()));
    }
    let corrected = shape_taken || part_taken.is_some() || taken_out.is_some();
    let words_rms = match taken_out {
        // The whole shape: what was taken out and what is left.
        Some(first) => {
            let whole: Vec<f64> = (0..shape.shape.len())
                .map(|k| {
                    let (du, dv) = shape.cell_offset(k);
                    let left = if shape_taken {
                        shape.shape[k] * k_raw
                    } else {
                        0.0
                    };
                    first.raw_at(du + shape.intrinsics.cx, dv + shape.intrinsics.cy) + left
                })
                .collect();
            weighted_rms(&whole, &shape.readings, &shape.seen)
        }
        None => shape.rms_raw(),
    };
    let seen_cells = shape.seen.iter().filter(|s| **s).count();
    let left_out = (shape.kept_fraction < 0.995).then(|| {
        format!(
            "; {:.0} % of the cells seen changed from pose to pose (obstacles' feet, bumps) and were left out",
            100.0 * (1.0 - shape.kept_fraction)
        )
    });
    // A warp not corrected: the ground looked warped, but not by a pattern
    // fixed in the image.
    let uncorrected = !shape_taken
        && taken_out.is_none()
        && part_taken.is_none()
        && shape.all_cells_rms_raw >= MIN_SHAPE_RMS_RAW
        && (shape.kept_fraction < 1.0 || !shape.consistent());
    let note = match (shape_taken || taken_out.is_some(), part_taken) {
        (false, None) if uncorrected && !shape.consistent() => {
            let why = match shape.why_not_fixed() {
                Some(crate::outcome::WarpCause::ChangesWithDepth { per_m, sigma }) => format!(
                    "it changes with the distance, {} by {:.0} ± {:.0} % a metre farther: a pattern that changes with depth, which a correction fixed in the image cannot take out",
                    if per_m > 0.0 { "weaker" } else { "stronger" },
                    100.0 * per_m.abs(),
                    100.0 * sigma
                ),
                Some(crate::outcome::WarpCause::GroundNotFlat { sigmas }) => format!(
                    "it stays with the ground as the poses move ({sigmas:.0} of noise's σ): the ground is not flat, not the sensor"
                ),
                Some(crate::outcome::WarpCause::CellsChange { left_out }) => format!(
                    "it changes from pose to pose in {:.0} % of the cells seen: obstacles or bumps in view",
                    100.0 * left_out
                ),
                Some(crate::outcome::WarpCause::BeyondTheFit { largest_raw, band_raw }) => {
                    // Two decimals where one would show them equal.
                    let decimals = if format!("{largest_raw:.1}") == format!("{band_raw:.1}") { 2 } else { 1 };
                    format!(
                        "it reaches {largest_raw:.decimals$} raw units from the ground's plane, beyond the fit's band of {band_raw:.decimals$}: the fit cut its peaks out, and whether it is the sensor's pattern or uneven ground cannot be told"
                    )
                }
                None => "it is not fixed in the image".to_string(),
            };
            let what = if matches!(
                shape.why_not_fixed(),
                Some(crate::outcome::WarpCause::BeyondTheFit { .. })
            ) {
                "cannot be taken for the sensor's fixed pattern"
            } else {
                "are not the sensor's fixed pattern"
            };
            format!(
                "not corrected: the ground's residuals ({:.3} raw units RMS) {what}: {why}",
                shape.all_cells_rms_raw
            )
        }
        (false, None) => format!(
            "none found: the ground's residuals show no fixed pattern beyond the noise (shape {words_rms:.3} raw units RMS over {seen_cells} cells{}), and the geometry across poses no offset or gradient of the depth",
            left_out.unwrap_or_default()
        ),
        (true, None) => "the shape corrected; its offset and gradients are not distinguishable from none by the geometry across poses".to_string(),
        (false, Some(_)) => "an offset or gradient of the depth over the image, found by the geometry across poses, corrected".to_string(),
        (true, Some(_)) => format!("the shape and its offset and gradients corrected{}", left_out.unwrap_or_default()),
    };
    DepthPattern {
        corrected,
        columns: shape.columns,
        rows: shape.rows,
        cell_px: CELL_PX,
        raw,
        sigma_raw,
        shape_rms_raw: words_rms,
        shape_chi2_per_dof: shape.shape_chi2 / shape.shape_dof.max(1.0),
        consistency_chi2_per_dof: shape.consistency_chi2 / shape.consistency_dof.max(1.0),
        shape_sigmas: shape.flips.sigmas(),
        changes_with_depth: shape
            .depth
            .sigma
            .is_finite()
            .then_some([shape.depth.per_m, shape.depth.sigma]),
        fixed_in_the_ground_sigmas: shape.fixed_in_the_ground.map(|t| t.sigmas()),
        uncorrected_because: if uncorrected {
            shape.why_not_fixed()
        } else {
            None
        },
        plane_part: plane_part.map(|p| p.value.into()),
        plane_part_sigma: plane_part
            .map(|p| [0, 1, 2].map(|i| p.covariance[(i, i)].max(0.0).sqrt())),
        plane_part_taken: part_taken.is_some(),
        uncorrected_shape_rms_raw: uncorrected.then_some(shape.all_cells_rms_raw),
        uncorrected_raw: uncorrected.then(|| {
            (0..shape.shape.len())
                .map(|k| shape.seen[k].then(|| shape.shape[k] * k_raw))
                .collect()
        }),
        uncorrected_fixed: false,
        raw_per_inverse_depth: k_raw,
        angle_sigma_known_plane_part: None,
        angle_sigma_growth_by_geometry: None,
        fit_again_about: fit_again_about(shape, shape_taken, taken_out.is_some()),
        note: Some(match taken_out {
            Some(_) => format!(
                "the pattern's first estimate taken out of the frames and the ground fitted again, because the first fit's band cut its peaks; then {note}"
            ),
            None => note,
        }),
    }
}
