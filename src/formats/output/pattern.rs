//! The depth pattern as the result document writes it (cells to 0.001 raw
//! units), and reads it back checked.

use super::*;

/// The depth pattern a calibration found: per cell of `cell_px` pixels,
/// row-major from the top left, the raw units a reading there is off by
/// (more is farther; `null` where no pose saw the ground).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DepthPatternJson {
    /// Whether a pattern was found and the calibration corrected for it.
    pub corrected: bool,
    pub note: String,
    pub cell_px: usize,
    pub columns: usize,
    pub rows: usize,
    pub raw: Vec<Option<f64>>,
    pub sigma_raw: Vec<Option<f64>>,
    /// The largest depth error the pattern causes at 2 m, millimetres.
    pub largest_mm_at_2m: f64,
    /// RMS of its shape (less its plane part), raw units.
    pub shape_rms_raw: f64,
    /// The shape against none, χ² per degree of freedom (about 1: none).
    pub shape_chi2_per_dof: f64,
    /// The residuals cell by cell and pose by pose after the pattern, χ² per
    /// degree of freedom against the noise the poses' own scatter shows
    /// (about 1 by that noise's construction: a check, not a test).
    pub consistency_chi2_per_dof: f64,
    /// The shape's size in noise's σ above what the poses make with random
    /// signs: the test that there is a shape.
    #[serde(default)]
    pub shape_sigmas: f64,
    /// The share by which the pattern weakens a metre farther, and its σ.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub changes_with_depth: Option<[f64; 2]>,
    /// How far the residuals stay with the ground as the poses move, in
    /// noise's σ (uneven ground).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed_in_the_ground_sigmas: Option<f64>,
    /// Why a warp was not corrected: `changes_with_depth`,
    /// `ground_not_flat`, `cells_change` or `beyond_the_fit` (the pattern
    /// larger than the ground fit's band, so that neither could be told).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncorrected_because: Option<String>,
    /// Its plane part from the geometry across poses (raw units at the
    /// principal point, per 100 pixels along u and along v), with σ.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane_part_raw: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane_part_sigma_raw: Option<[f64; 3]>,
    pub plane_part_taken: bool,
    /// When the plane part was taken: σ of α, β, γ (degrees) had it been
    /// known exactly, beside the result's σ what correcting it cost (the
    /// gate `pattern_angle_sigma_growth_max` judges it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angle_sigma_known_plane_part_deg: Option<[f64; 3]>,
    /// When the plane part was taken: how many times it grows each angle's
    /// σ by the poses' geometry alone, the schedule's cost that the gate
    /// `pattern_angle_sigma_growth_max` judges (the measured σ grow by more
    /// or less with the noise met).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angle_sigma_growth_by_geometry: Option<[f64; 3]>,
    /// A warp that stood out of the noise but was not corrected because it
    /// changed from pose to pose: its RMS at 2 m, millimetres (the gate
    /// `warp_max_mm` judges it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncorrected_mm_at_2m: Option<f64>,
    /// That warp is fixed in the image (the sensor's pattern), left
    /// uncorrected because the ground fit in use (the paper's) cannot.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub uncorrected_fixed: bool,
    /// That warp per cell (raw units, as `raw`), when the residuals showed
    /// a shape that was not corrected: what the sensor or the ground
    /// looked like, nothing applied.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncorrected_raw: Option<Vec<Option<f64>>>,
    /// Raw units per 1/m of inverse depth (the depth model's 1/b): the depth
    /// error at z metres is −z²·raw/raw_per_inverse_depth. For a camera
    /// other than a Kinect, the cells are in a Kinect's raw units of the
    /// same inverse depth, and `disparity` gives the camera's own.
    pub raw_per_inverse_depth: f64,
    /// The pattern in the camera's own pixels of disparity, for a bag's
    /// camera of known baseline (`setup.disparity`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub disparity: Option<PatternDisparityJson>,
}

/// A pattern in a camera's own pixels of disparity.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PatternDisparityJson {
    /// RMS of its shape (as `shape_rms_raw`), pixels.
    pub shape_rms_px: f64,
    /// Its largest cell (as `largest_mm_at_2m`), pixels.
    pub largest_px: f64,
    /// Its plane part (as `plane_part_raw`: at the principal point, per 100
    /// pixels along u and along v) and σ, pixels of disparity (more is
    /// nearer, the disparity's own sign).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane_part_px: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane_part_sigma_px: Option<[f64; 3]>,
}

impl PatternDisparityJson {
    /// `pattern`'s figures on a camera of `pixels_per_inverse_depth` (px·m).
    pub fn of(pattern: &DepthPatternJson, pixels_per_inverse_depth: f64) -> Option<Self> {
        (pattern.raw_per_inverse_depth != 0.0).then(|| {
            // In the disparity's own sign: more pixels are nearer, where
            // more of a Kinect's raw units are farther (k < 0).
            let px_per_raw = pixels_per_inverse_depth / pattern.raw_per_inverse_depth;
            let in_px = |raw: [f64; 3]| raw.map(|r| r * px_per_raw);
            PatternDisparityJson {
                shape_rms_px: pattern.shape_rms_raw * px_per_raw.abs(),
                // |δ(1/z)| = δz/z² at 2 m.
                largest_px: pattern.largest_mm_at_2m * 1e-3 / 4.0 * pixels_per_inverse_depth,
                plane_part_px: pattern.plane_part_raw.map(in_px),
                plane_part_sigma_px: pattern.plane_part_sigma_raw.map(|s| in_px(s).map(f64::abs)),
            }
        })
    }
}

/// A figure the document can carry: JSON has no infinity (a test whose
/// null had no spread says "beyond any" as 10⁹).
pub(super) fn finite_or_zero(value: f64) -> f64 {
    if value.is_nan() {
        0.0
    } else {
        value.clamp(-1e9, 1e9)
    }
}

impl DepthPatternJson {
    /// The pattern as the result carries it (cells to 0.001 raw units).
    pub fn from_pattern(p: &crate::calib::outcome::DepthPattern) -> Self {
        let thousandths = |v: &Option<f64>| v.map(|v| (v * 1e3).round() / 1e3);
        DepthPatternJson {
            corrected: p.corrected,
            note: p.note.clone().unwrap_or_default(),
            cell_px: p.cell_px,
            columns: p.columns,
            rows: p.rows,
            raw: p.raw.iter().map(thousandths).collect(),
            sigma_raw: p.sigma_raw.iter().map(thousandths).collect(),
            largest_mm_at_2m: p.largest_depth_error_m(2.0) * 1e3,
            shape_rms_raw: p.shape_rms_raw,
            shape_chi2_per_dof: p.shape_chi2_per_dof,
            consistency_chi2_per_dof: p.consistency_chi2_per_dof,
            shape_sigmas: finite_or_zero(p.shape_sigmas),
            changes_with_depth: p.changes_with_depth,
            fixed_in_the_ground_sigmas: p.fixed_in_the_ground_sigmas.map(finite_or_zero),
            uncorrected_because: p.uncorrected_because.map(|c| {
                use crate::calib::outcome::WarpCause;
                match c {
                    WarpCause::ChangesWithDepth { .. } => "changes_with_depth",
                    WarpCause::GroundNotFlat { .. } => "ground_not_flat",
                    WarpCause::CellsChange { .. } => "cells_change",
                    WarpCause::BeyondTheFit { .. } => "beyond_the_fit",
                }
                .to_string()
            }),
            plane_part_raw: p.plane_part,
            plane_part_sigma_raw: p.plane_part_sigma,
            plane_part_taken: p.plane_part_taken,
            angle_sigma_known_plane_part_deg: p
                .angle_sigma_known_plane_part
                .map(|s| s.map(f64::to_degrees)),
            angle_sigma_growth_by_geometry: p.angle_sigma_growth_by_geometry,
            uncorrected_mm_at_2m: p.uncorrected_shape_rms_raw.map(|raw| {
                crate::calib::outcome::depth_error_m(raw, 2.0, p.raw_per_inverse_depth) * 1e3
            }),
            uncorrected_fixed: p.uncorrected_fixed,
            uncorrected_raw: p
                .uncorrected_raw
                .as_ref()
                .map(|cells| cells.iter().map(thousandths).collect()),
            raw_per_inverse_depth: p.raw_per_inverse_depth,
            disparity: None,
        }
    }

    /// Whether the document's pattern is one: its grid's size agrees with
    /// its cells (or it has none, as in the daemon's status), and every
    /// number is one a Kinect's pattern can have.
    pub fn validate(&self) -> Result<(), String> {
        if self.columns > 1024
            || self.rows > 1024
            || (!(1..=64).contains(&self.cell_px) && !self.raw.is_empty())
        {
            return Err(format!(
                "has a grid of {} × {} cells of {} pixels, not a depth image's",
                self.columns, self.rows, self.cell_px
            ));
        }
        let cells = self.columns * self.rows;
        let without_cells = self.raw.is_empty() && self.sigma_raw.is_empty();
        if !without_cells && (self.raw.len() != cells || self.sigma_raw.len() != cells) {
            return Err(format!(
                "has {} values and {} σ for {} × {} = {cells} cells",
                self.raw.len(),
                self.sigma_raw.len(),
                self.columns,
                self.rows
            ));
        }
        if let Some(uncorrected) = &self.uncorrected_raw {
            if without_cells || uncorrected.len() != cells {
                return Err(format!(
                    "has {} uncorrected values for {} × {} = {cells} cells",
                    uncorrected.len(),
                    self.columns,
                    self.rows
                ));
            }
        }
        let uncorrected = self.uncorrected_raw.as_deref().unwrap_or_default();
        for (name, values) in [
            ("raw", &self.raw[..]),
            ("sigma_raw", &self.sigma_raw[..]),
            ("uncorrected_raw", uncorrected),
        ] {
            if let Some((k, v)) = values.iter().enumerate().find_map(|(k, v)| {
                v.filter(|v| !(v.is_finite() && v.abs() <= 50.0))
                    .map(|v| (k, v))
            }) {
                return Err(format!(
                    "\"{name}[{k}]\" is {v}, not a pattern of a Kinect (at most 50 raw units)"
                ));
            }
        }
        for (name, values, what) in [
            (
                "angle_sigma_known_plane_part_deg",
                self.angle_sigma_known_plane_part_deg,
                "a σ",
            ),
            (
                "angle_sigma_growth_by_geometry",
                self.angle_sigma_growth_by_geometry,
                "a ratio of σ",
            ),
        ] {
            if let Some((k, v)) = values.and_then(|values| {
                values
                    .into_iter()
                    .enumerate()
                    .find(|(_, v)| !(v.is_finite() && *v >= 0.0))
            }) {
                return Err(format!("\"{name}[{k}]\" is {v}, not {what}"));
            }
        }
        if !self.raw_per_inverse_depth.is_finite()
            || (cells > 0 && self.raw_per_inverse_depth == 0.0)
        {
            return Err(format!(
                "\"raw_per_inverse_depth\" is {}, not a depth model's 1/b",
                self.raw_per_inverse_depth
            ));
        }
        Ok(())
    }
}
