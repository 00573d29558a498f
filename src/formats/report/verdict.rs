//! The verdict and the quality gates: what was decided, and each gate's
//! limit, measured value and outcome in words.

use super::*;

pub(super) fn verdict_section(page: &mut String, result: &ResultJson, verdict: &str) {
    // Coloured by the status (green or red), whatever the words.
    let class = result.status.as_str();
    let _ = writeln!(
        page,
        "<section class=\"verdict {class}\" id=\"verdict\"><h1>{verdict}</h1>"
    );
    let lead = match (result.accepted(), result.reasons.is_empty()) {
        (true, true) => "The calibration passed every quality gate.",
        (true, false) => "The calibration passed its quality gates, with these notes:",
        _ if result.robot_from_sensor.is_none() => "No calibration could be made:",
        (false, true) => "The calibration did not pass its quality gates.",
        (false, false) => "The calibration did not pass its quality gates:",
    };
    let _ = writeln!(page, "<p>{lead}</p>");
    if !result.reasons.is_empty() {
        page.push_str("<ul class=\"reasons\">\n");
        for reason in &result.reasons {
            let _ = writeln!(page, "<li>{}</li>", escape(reason));
        }
        page.push_str("</ul>\n");
    }
    if !result.notes.is_empty() {
        page.push_str("<p class=\"notes-lead\">Also note:</p>\n<ul class=\"reasons\">\n");
        for note in &result.notes {
            let _ = writeln!(page, "<li>{}</li>", escape(note));
        }
        page.push_str("</ul>\n");
    }
    page.push_str("</section>\n");
}

/// The spread of the body's tilts (degrees, RMS) that a singular value of
/// the observability stands for: it is about the sine of that spread.
pub(super) fn spread_deg(singular_value: f64) -> f64 {
    singular_value.clamp(0.0, 1.0).asin().to_degrees()
}

/// A gate's row: what it is (HTML), its limit, the value measured, and the
/// words before where the value comes from.
pub(super) fn gate_row(check: &GateCheckJson) -> (String, String, String, Option<&'static str>) {
    let (l, m) = (check.limit, check.measured);
    let (name, limit, measured, at): (&str, String, String, &'static str) = match check.gate.as_str() {
        "theta_max_deg" => (
            "largest θ of a used pose",
            format!("≤ {}°", num(l, 2)),
            format!("{}°", num(m, 3)),
            "at ",
        ),
        "e_d_max_mm" => (
            "largest e<sub>d</sub> of a used pose",
            format!("≤ {} mm", num(l, 1)),
            format!("{} mm", num(m, 2)),
            "at ",
        ),
        "sigma_angle_max_deg" => (
            "largest σ of α, β, γ",
            format!("≤ {}°", num(l, 3)),
            format!("{}°", num(m, 3)),
            "of ",
        ),
        "sigma_position_max_mm" => (
            "largest σ of p<sub>x</sub>, p<sub>y</sub>, p<sub>z</sub>",
            format!("≤ {} mm", num(l, 2)),
            format!("{} mm", num(m, 2)),
            "of ",
        ),
        "depth_scale_max_deviation" => (
            "depth scale's distance from 1",
            format!("≤ {} %", num(100.0 * l, 1)),
            format!("{} %", num(100.0 * m, 3)),
            "",
        ),
        "warp_max_mm" => (
            "depth warp at 2&nbsp;m, not corrected (RMS)",
            format!("≤ {} mm", num(l, 1)),
            format!("{} mm", num(m, 2)),
            "",
        ),
        "pattern_max_mm" => (
            "largest corrected depth pattern at 2&nbsp;m",
            format!("≤ {} mm", num(l, 0)),
            format!("{} mm", num(m, 1)),
            "",
        ),
        "pattern_angle_sigma_growth_max" => (
            "largest growth of σ of α, β, γ from correcting the depth pattern",
            format!("≤ {}×", num(l, 1)),
            format!("{}×", num(m, 1)),
            "of ",
        ),
        "min_poses_used" => (
            "poses used",
            format!("≥ {}", num(l, 0)),
            num(m, 0),
            "",
        ),
        "min_used_fraction" => (
            "share of poses used",
            format!("≥ {} %", num(100.0 * l, 0)),
            format!("{} %", num(100.0 * m, 0)),
            "",
        ),
        // Where: the weakest direction, in words in the observability
        // section (too long for this column on a phone).
        "observable" => {
            return (
                "tilt spread of the weakest direction (RMS)<span class=\"at\">see “What the schedule could tell”</span>".to_string(),
                format!("≥ {}°", num(spread_deg(l), 1)),
                format!("{}°", num(spread_deg(m), 1)),
                None,
            )
        }
        other => {
            return (
                escape(other),
                format!("{} {}", if check.at_least { "≥" } else { "≤" }, num(l, 3)),
                num(m, 3),
                Some(""),
            )
        }
    };
    (name.to_string(), limit, measured, Some(at))
}

pub(super) fn gates_section(page: &mut String, result: &ResultJson) {
    page.push_str("<section id=\"gates\"><h2>Quality gates</h2>\n");
    if result.gate_checks.is_empty() {
        page.push_str("<p class=\"none\">No gates were checked: nothing could be solved (see the reasons above).</p>\n</section>\n");
        return;
    }
    let failed = result.gate_checks.iter().filter(|c| !c.passed).count();
    let _ = writeln!(
        page,
        "<p class=\"gates-lead\">{}</p>",
        match failed {
            0 => format!("All {} gates passed.", result.gate_checks.len()),
            1 => format!("1 of {} gates failed.", result.gate_checks.len()),
            n => format!("{n} of {} gates failed.", result.gate_checks.len()),
        }
    );
    page.push_str("<div class=\"scroll\"><table class=\"gates\">\n<thead><tr><th class=\"text\">gate</th><th>limit</th><th>measured</th><th class=\"text\">result</th></tr></thead>\n<tbody>\n");
    for check in &result.gate_checks {
        let (name, limit, measured, at_words) = gate_row(check);
        let at = match (at_words, check.at.as_deref()) {
            (Some(words), Some(at)) => format!("<span class=\"at\">{words}{}</span>", escape(at)),
            _ => String::new(),
        };
        let (class, verdict) = if check.passed {
            ("pass", "✓ pass")
        } else {
            ("fail", "✗ FAIL")
        };
        let _ = writeln!(
            page,
            "<tr class=\"{class}\" data-gate=\"{}\"><td class=\"text gate\">{name}{at}</td><td>{limit}</td><td>{measured}</td><td class=\"text result\">{verdict}</td></tr>",
            escape(&check.gate)
        );
    }
    page.push_str("</tbody></table></div>\n<p class=\"note\">The limits are the <code>[calibration.gates]</code> the result was judged by (see the setup below); the observability limit is the solve's own. θ's and e<sub>d</sub>'s limits are drawn as red lines on their charts.</p>\n</section>\n");
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
