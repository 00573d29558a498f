//! The depth pattern in the report: the Kinect's own warp of the depth image,
//! drawn as a picture of the image (one pixel per cell, scaled up without
//! smoothing) coloured by the depth error it causes at 2 m, with its scale.
//! A PNG inlined as a data URI: the report loads nothing from anywhere.

use maud::{html, Markup};

use super::html::{num, signed};
use crate::formats::output::DepthPatternJson;

/// The colours of the scale's ends: reads nearer than the truth, farther.
const NEARER: [u8; 3] = [33, 102, 172];
const FARTHER: [u8; 3] = [178, 24, 43];
/// Cells no pose saw the ground in.
const UNSEEN: [u8; 3] = [190, 190, 190];

/// The depth the picture's colours are for, metres: where a legged robot's
/// terrain map reaches.
const AT_M: f64 = 2.0;

/// A cell's depth error at [`AT_M`], millimetres (positive: reads farther).
fn error_mm(raw: f64, pattern: &DepthPatternJson) -> f64 {
    if pattern.raw_per_inverse_depth == 0.0 {
        return 0.0;
    }
    // 1/z reads raw/k more (k = raw_per_inverse_depth), so z reads −z²·raw/k more.
    -AT_M * AT_M * raw / pattern.raw_per_inverse_depth * 1e3
}

/// The scale's half-range: the largest error, rounded up to 1, 2 or 5 × 10ⁿ mm.
fn half_range_mm(largest: f64) -> f64 {
    let largest = largest.max(1.0);
    let decade = 10f64.powf(largest.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * decade)
        .find(|v| *v >= largest)
        .unwrap_or(10.0 * decade)
}

/// The colour of an error on the scale of ± `range` mm: white at 0.
fn colour(error: f64, range: f64) -> [u8; 3] {
    let t = (error / range).clamp(-1.0, 1.0);
    let end = if t < 0.0 { NEARER } else { FARTHER };
    let a = t.abs();
    [0, 1, 2].map(|i| (255.0 + (f64::from(end[i]) - 255.0) * a).round() as u8)
}

/// The picture of `cells` as PNG bytes, one pixel per cell.
fn png(pattern: &DepthPatternJson, cells: &[Option<f64>], range: f64) -> Option<Vec<u8>> {
    let (width, height) = (pattern.columns as u32, pattern.rows as u32);
    let mut pixels = Vec::with_capacity(cells.len() * 3);
    for cell in cells {
        pixels.extend(match cell {
            Some(raw) => colour(error_mm(*raw, pattern), range),
            None => UNSEEN,
        });
    }
    let mut bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut bytes, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().ok()?;
        writer.write_image_data(&pixels).ok()?;
    }
    Some(bytes)
}

/// Standard base64 (RFC 4648) for the data URI.
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for (i, shift) in [18, 12, 6, 0].into_iter().enumerate() {
            if i <= chunk.len() {
                out.push(char::from(ALPHABET[((n >> shift) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// The section: the picture and its scale when a pattern was corrected,
/// else what was found in words. `too_large_for_mm` is the limit of the
/// gate `pattern_max_mm` when the pattern failed it: the correction was
/// made, but the calibration must not lean on it.
pub(super) fn depth_pattern_section(
    pattern: Option<&DepthPatternJson>,
    too_large_for_mm: Option<f64>,
) -> Markup {
    let Some(pattern) = pattern else {
        return html! {};
    };
    let has_cells = pattern.columns > 0 && pattern.rows > 0;
    let drawn = pattern.corrected && has_cells;
    let image = drawn
        .then(|| {
            let range = half_range_mm(pattern.largest_mm_at_2m);
            png(pattern, &pattern.raw, range).map(|bytes| (range, base64(&bytes)))
        })
        .flatten();
    // A warp that stood out but was not corrected is drawn too, for a
    // maintainer to see what the residuals showed.
    let uncorrected = (!drawn && has_cells)
        .then_some(pattern.uncorrected_raw.as_deref())
        .flatten()
        .filter(|cells| cells.len() == pattern.columns * pattern.rows)
        .and_then(|cells| {
            let largest = cells
                .iter()
                .flatten()
                .map(|raw| error_mm(*raw, pattern).abs())
                .fold(0.0, f64::max);
            let range = half_range_mm(largest);
            png(pattern, cells, range).map(|bytes| (largest, range, base64(&bytes)))
        });
    let plane_part = match (
        pattern.plane_part_raw,
        pattern.plane_part_sigma_raw,
        pattern.plane_part_taken,
    ) {
        (Some(part), Some(sigma), true) => Some((part, sigma, "raw units", 3)),
        _ => None,
    };
    // Another camera's in its own pixels of disparity.
    let plane_part = match pattern.disparity {
        Some(own) => plane_part.and_then(|_| {
            Some((
                own.plane_part_px?,
                own.plane_part_sigma_px?,
                "px of disparity",
                4,
            ))
        }),
        None => plane_part,
    };
    // A bag's camera of known baseline is named as what it is, and its
    // pattern given in its own pixels of disparity; else it is a Kinect.
    let camera = if pattern.disparity.is_some() {
        "depth camera"
    } else {
        "Kinect"
    };
    html! {
        section #depth-pattern {
            h2 { "The depth image's own warp" }
            @match image {
                Some((range, data)) => {
                    p.warp-words {
                        "The " (camera) " reads the depth up to " strong { (num(pattern.largest_mm_at_2m, 1)) " mm" }
                        " off at 2 m, in a pattern fixed in its image (red: farther than the truth, blue: nearer)"
                        @match too_large_for_mm {
                            Some(limit) => {
                                ": more than the " (num(limit, 0))
                                "\u{a0}mm its correction is checked for, so the calibration cannot rely on it."
                            },
                            None => ". The calibration was corrected for it.",
                        }
                    }
                    (figure(pattern, &data, range, pattern.largest_mm_at_2m))
                    dl.facts {
                        @if let Some(own) = pattern.disparity {
                            dt { "shape, RMS" } dd { (num(own.shape_rms_px, 3)) " px of disparity" }
                            dt { "largest" } dd { (num(own.largest_px, 3)) " px of disparity" }
                        } @else {
                            dt { "shape, RMS" } dd { (num(pattern.shape_rms_raw, 3)) " raw units" }
                        }
                        @if let Some((part, sigma, unit, digits)) = plane_part {
                            dt { "offset" } dd { (signed(part[0], digits)) " ± " (num(sigma[0], digits)) " " (unit) }
                            dt { "gradient along a row" } dd { (signed(part[1], digits)) " ± " (num(sigma[1], digits)) " per 100 px" }
                            dt { "gradient down a column" } dd { (signed(part[2], digits)) " ± " (num(sigma[2], digits)) " per 100 px" }
                        }
                        dt { "left after it, pose by pose" } dd { (num(pattern.consistency_chi2_per_dof, 2)) " × the noise" }
                    }
                },
                None => {
                    p.none { (pattern.note) }
                    @if let Some((largest, range, data)) = uncorrected {
                        p.warp-words {
                            "What the ground's residuals showed, up to " strong { (num(largest, 1)) " mm" }
                            " at 2 m (red: farther, blue: nearer). Nothing was corrected by it."
                        }
                        (figure(pattern, &data, range, largest))
                    }
                },
            }
            p.note {
                @if drawn {
                    (pattern.note)
                } @else if pattern.disparity.is_some() {
                    "A disparity camera's matching leaves a pattern fixed in its image; groundcal looks for it in the ground's residuals at every calibration."
                } @else {
                    "A real Kinect v1's depth carries a fixed pattern of most of a raw unit RMS (0.84 in a real sequence of a floor; a raw unit is about 12 mm at 2 m); groundcal looks for it in the ground's residuals at every calibration."
                }
            }
        }
    }
}

/// The picture (`data`: PNG in base64) with its scale of ± `range` mm.
fn figure(pattern: &DepthPatternJson, data: &str, range: f64, largest: f64) -> Markup {
    let rgb = |c: [u8; 3]| format!("rgb({},{},{})", c[0], c[1], c[2]);
    html! {
        figure.warp {
            img.warp src={ "data:image/png;base64," (data) } width=(pattern.columns) height=(pattern.rows)
                alt={ "the depth error over the image at 2 m, up to " (num(largest, 1)) " mm" };
            div.warp-scale style={ "background: linear-gradient(to right, " (rgb(NEARER)) ", #fff, " (rgb(FARTHER)) ")" } {}
            div.warp-ticks {
                span { "−" (num(range, 0)) " mm nearer" } span { "0" } span { "+" (num(range, 0)) " mm farther" }
            }
            figcaption {
                "The depth image as the sensor sees it, " (pattern.columns) " × " (pattern.rows)
                " cells of " (pattern.cell_px) " pixels; grey: no ground seen there."
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_of_rfc_4648_vectors() {
        for (text, encoded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(text.as_bytes()), encoded);
        }
    }

    /// A corrected pattern of 2 × 2 cells, 22.6 mm at 2 m at its largest.
    fn corrected_pattern() -> DepthPatternJson {
        DepthPatternJson {
            corrected: true,
            note: String::new(),
            cell_px: 8,
            columns: 2,
            rows: 2,
            raw: vec![Some(-1.5), Some(0.5), None, Some(1.5)],
            sigma_raw: vec![Some(0.02); 4],
            largest_mm_at_2m: 22.6,
            shape_rms_raw: 1.0,
            shape_chi2_per_dof: 40.0,
            consistency_chi2_per_dof: 1.02,
            shape_sigmas: 30.0,
            changes_with_depth: None,
            fixed_in_the_ground_sigmas: None,
            uncorrected_because: None,
            plane_part_raw: None,
            plane_part_sigma_raw: None,
            plane_part_taken: false,
            angle_sigma_known_plane_part_deg: None,
            angle_sigma_growth_by_geometry: None,
            uncorrected_mm_at_2m: None,
            uncorrected_fixed: false,
            uncorrected_raw: None,
            raw_per_inverse_depth: 325.0,
            disparity: None,
        }
    }

    /// Another camera is not called a Kinect, and its pattern is given in
    /// its own pixels of disparity.
    #[test]
    fn another_cameras_pattern_is_given_in_its_own_pixels() {
        let kinect = depth_pattern_section(Some(&corrected_pattern()), None).into_string();
        assert!(
            kinect.contains("The Kinect reads the depth up to"),
            "{kinect}"
        );
        assert!(!kinect.contains("px of disparity"), "{kinect}");
        let mut stereo = corrected_pattern();
        stereo.disparity = crate::formats::output::PatternDisparityJson::of(&stereo, 21.25);
        let words = depth_pattern_section(Some(&stereo), None).into_string();
        assert!(
            words.contains("The depth camera reads the depth up to"),
            "{words}"
        );
        assert!(!words.contains("Kinect"), "{words}");
        // 1.0 raw of a Kinect's 325 per 1/m is 0.065 px on 21.25 px·m;
        // 22.6 mm at 2 m is 0.120 px.
        assert!(words.contains("0.065 px of disparity"), "{words}");
        assert!(words.contains("0.120 px of disparity"), "{words}");
    }

    /// The picture is drawn either way; the words say whether the
    /// calibration may rely on the correction (the gate `pattern_max_mm`).
    #[test]
    fn a_pattern_too_large_for_its_correction_is_not_called_corrected_for() {
        let within = depth_pattern_section(Some(&corrected_pattern()), None).into_string();
        assert!(
            within.contains("The calibration was corrected for it."),
            "{within}"
        );
        assert!(within.contains("<img class=\"warp\""), "{within}");

        let too_large = depth_pattern_section(Some(&corrected_pattern()), Some(15.0)).into_string();
        assert!(
            too_large.contains("22.6 mm</strong> off at 2 m")
                && too_large.contains("more than the 15\u{a0}mm its correction is checked for, so the calibration cannot rely on it."),
            "{too_large}"
        );
        assert!(!too_large.contains("corrected for it"), "{too_large}");
        assert!(too_large.contains("<img class=\"warp\""), "{too_large}");
    }

    #[test]
    fn the_scale_rounds_up_to_one_two_five() {
        assert_eq!(half_range_mm(0.2), 1.0);
        assert_eq!(half_range_mm(1.3), 2.0);
        assert_eq!(half_range_mm(8.8), 10.0);
        assert_eq!(half_range_mm(12.0), 20.0);
    }
}
