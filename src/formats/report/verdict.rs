//! The verdict and the quality gates: what was decided, and each gate's
//! limit, measured value and outcome in words.

use super::*;

pub(super) fn verdict_section(result: &ResultJson, verdict: &str) -> Markup {
    // Coloured by the status (green or red), whatever the words.
    let class = result.status.as_str();
    // Rejected with every gate passed: for a reason that is not a gate
    // (a camera groundcal does not support), not "its quality gates".
    let gates_passed =
        !result.gate_checks.is_empty() && result.gate_checks.iter().all(|c| c.passed);
    let lead = match (result.accepted(), result.reasons.is_empty()) {
        (true, true) => "The calibration passed every quality gate.",
        (true, false) => "The calibration passed its quality gates, with these notes:",
        _ if result.robot_from_sensor.is_none() => "No calibration could be made:",
        (false, false) if gates_passed => {
            "The calibration passed its quality gates, but must not be used:"
        }
        (false, true) => "The calibration did not pass its quality gates.",
        (false, false) => "The calibration did not pass its quality gates:",
    };
    html! {
        section.verdict.(class) #verdict {
            h1 { (verdict) }
            p { (lead) }
            @if !result.reasons.is_empty() {
                ul.reasons { @for reason in &result.reasons { li { (reason) } } }
            }
            @if !result.notes.is_empty() {
                p.notes-lead { "Also note:" }
                ul.reasons { @for note in &result.notes { li { (note) } } }
            }
        }
    }
}

/// The spread of the body's tilts (degrees, RMS) that a singular value of
/// the observability stands for: it is about the sine of that spread.
pub(super) fn spread_deg(singular_value: f64) -> f64 {
    singular_value.clamp(0.0, 1.0).asin().to_degrees()
}

/// A gate's row: what it is, its limit, the value measured, and the words
/// before where the value comes from (none: the place is not shown).
pub(super) fn gate_row(check: &GateCheckJson) -> (Markup, String, String, Option<&'static str>) {
    let (l, m) = (check.limit, check.measured);
    let (name, limit, measured, at): (Markup, String, String, &'static str) = match check
        .gate
        .as_str()
    {
        "theta_max_deg" => (
            html! { "largest θ of a used pose" },
            format!("≤ {}°", num(l, 2)),
            format!("{}°", num(m, 3)),
            "at ",
        ),
        "e_d_max_mm" => (
            html! { "largest " (e_d()) " of a used pose" },
            format!("≤ {} mm", num(l, 1)),
            format!("{} mm", num(m, 2)),
            "at ",
        ),
        "sigma_angle_max_deg" => (
            html! { "largest σ of α, β, γ" },
            format!("≤ {}°", num(l, 3)),
            format!("{}°", num(m, 3)),
            "of ",
        ),
        "sigma_position_max_mm" => (
            html! { "largest σ of " (param_name(3)) ", " (param_name(4)) ", " (param_name(5)) },
            format!("≤ {} mm", num(l, 2)),
            format!("{} mm", num(m, 2)),
            "of ",
        ),
        "depth_scale_max_deviation" => (
            html! { "depth scale's distance from 1" },
            format!("≤ {} %", num(100.0 * l, 1)),
            format!("{} %", num(100.0 * m, 3)),
            "",
        ),
        "depth_scale_taken_sigmas" => (
            html! { "depth scale taken, from where the poses put it" },
            format!("≤ {} σ", num(l, 1)),
            format!("{} σ", num(m, 1)),
            "",
        ),
        "warp_max_mm" => (
            html! { "depth warp at 2\u{a0}m, not corrected (RMS)" },
            format!("≤ {} mm", num(l, 1)),
            format!("{} mm", num(m, 2)),
            "",
        ),
        "pattern_max_mm" => (
            html! { "largest corrected depth pattern at 2\u{a0}m" },
            format!("≤ {} mm", num(l, 0)),
            format!("{} mm", num(m, 1)),
            "",
        ),
        "pattern_angle_sigma_growth_max" => (
            html! { "largest growth of σ of α, β, γ from correcting the depth pattern, by the poses' geometry" },
            format!("≤ {}×", num(l, 1)),
            format!("{}×", num(m, 1)),
            "of ",
        ),
        "min_poses_used" => (
            html! { "poses used" },
            format!("≥ {}", num(l, 0)),
            num(m, 0),
            "",
        ),
        "min_used_fraction" => (
            html! { "share of poses used" },
            format!("≥ {} %", num(100.0 * l, 0)),
            format!("{} %", num(100.0 * m, 0)),
            "",
        ),
        // Where: the weakest direction, in words in the observability
        // section (too long for this column on a phone).
        "observable" => {
            return (
                html! { "tilt spread of the weakest direction (RMS)" span.at { "see “What the schedule could tell”" } },
                format!("≥ {}°", num(spread_deg(l), 1)),
                format!("{}°", num(spread_deg(m), 1)),
                None,
            )
        }
        other => {
            return (
                html! { (other) },
                format!("{} {}", if check.at_least { "≥" } else { "≤" }, num(l, 3)),
                num(m, 3),
                Some(""),
            )
        }
    };
    (name, limit, measured, Some(at))
}

pub(super) fn gates_section(result: &ResultJson) -> Markup {
    if result.gate_checks.is_empty() {
        return html! {
            section #gates {
                h2 { "Quality gates" }
                p.none { "No gates were checked: nothing could be solved (see the reasons above)." }
            }
        };
    }
    let total = result.gate_checks.len();
    let lead = match result.gate_checks.iter().filter(|c| !c.passed).count() {
        0 => format!("All {total} gates passed."),
        1 => format!("1 of {total} gates failed."),
        n => format!("{n} of {total} gates failed."),
    };
    html! {
        section #gates {
            h2 { "Quality gates" }
            p.gates-lead { (lead) }
            div.scroll { table.gates {
                thead { tr { th.text { "gate" } th { "limit" } th { "measured" } th.text { "result" } } }
                tbody {
                    @for check in &result.gate_checks {
                        @let (name, limit, measured, at_words) = gate_row(check);
                        @let (class, verdict) = if check.passed { ("pass", "✓ pass") } else { ("fail", "✗ FAIL") };
                        tr class=(class) data-gate=(check.gate) {
                            td.text.gate {
                                (name)
                                @if let (Some(words), Some(at)) = (at_words, check.at.as_deref()) {
                                    span.at { (words) (at) }
                                }
                            }
                            td { (limit) }
                            td { (measured) }
                            td.text.result { (verdict) }
                        }
                    }
                }
            } }
            p.note {
                "The limits are the " code { "[calibration.gates]" } " the result was judged by (see the setup below); the observability limit and the depth scale taken's (3 σ) are the solve's own. θ's and " (e_d()) "'s limits are drawn as red lines on their charts."
            }
        }
    }
}

/// The gate of a key, if the result was checked against it.
pub(super) fn gate_limit(result: &ResultJson, gate: &str) -> Option<f64> {
    result
        .gate_checks
        .iter()
        .find(|c| c.gate == gate)
        .map(|c| c.limit)
        .filter(|v| v.is_finite())
}
