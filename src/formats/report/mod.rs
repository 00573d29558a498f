//! The offline calibration report (`groundcal replay DIR --report OUTDIR`): one
//! HTML page that a person reads on a phone or a laptop.
//!
//! The page is self-contained so that it can be mailed, archived next to the
//! recording or opened on a robot with no network: inline CSS, no script, no
//! font or image from anywhere (the one picture, the depth pattern, is a data
//! URI), and a Content-Security-Policy that forbids loading anything. Charts are drawn by `plotters` into SVG strings and
//! inlined ([`chart`]); every text that comes from outside (reasons, paths)
//! is escaped ([`html`]).
//!
//! The sections, in the order an operator reads them: the verdict, the
//! quality gates (limit, measured, pass or fail), the mount with its σ, the
//! setup and the change from the nominal mount, the summary, the depth
//! image's own warp (the Kinect's fixed pattern, [`pattern`]), what the
//! schedule could tell (the weakest directions in words), the correlations
//! of the six parameters as a heat map, θ and e_d per pose with the gates as
//! lines, the signed residuals, the measured and predicted ground, the
//! commanded body poses, the poses set aside, every pose, and the
//! provenance. Every table fits a 390 px phone or scrolls in its own box.

mod chart;
mod html;
mod pattern;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use chart::{
    figure, gate_mark, legend, mean_max_marks, tilt_figure, ChartSpec, LegendItem, Line, Tilt,
    YAxis, COMPONENTS, GATE, INK, MAX, MEAN, SET_ASIDE, USED,
};
use html::{escape, num, opt, signed};

use crate::calib::outcome::{position_words, rotation_words};
use crate::calib::sensor::DepthModel;
use crate::formats::output::{GateCheckJson, PoseJson, ResultJson};
use crate::platform::files::{write_atomically, FileError};

/// Where a result came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Provenance {
    pub groundcal_version: String,
    /// What was solved, e.g. the recording directory.
    pub input: String,
    /// Hex BLAKE3 of the input, so that a report can be matched to its data.
    pub input_digest: String,
    /// RFC 3339, UTC.
    pub created: String,
}

impl Provenance {
    /// This groundcal, now.
    pub fn now(input: &str, input_digest: String) -> Self {
        Self {
            groundcal_version: env!("CARGO_PKG_VERSION").to_string(),
            input: input.to_string(),
            input_digest,
            created: humantime::format_rfc3339_seconds(SystemTime::now()).to_string(),
        }
    }
}

/// Writes `dir/index.html` atomically ([`crate::platform::files::write_atomically`]),
/// so that a reader never sees half a report; creates `dir` if needed.
pub fn write_report(
    dir: &Path,
    result: &ResultJson,
    provenance: &Provenance,
) -> Result<PathBuf, FileError> {
    let target = dir.join("index.html");
    write_atomically(&target, render_html(result, provenance).as_bytes())?;
    Ok(target)
}

/// The whole page.
pub fn render_html(result: &ResultJson, provenance: &Provenance) -> String {
    // The words the page and the terminal use for the same verdict.
    let verdict = if result.accepted() {
        "Passed its checks"
    } else {
        "Failed its checks"
    };
    let mut page = String::with_capacity(96 * 1024);
    let _ = write!(
        page,
        r#"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta http-equiv="Content-Security-Policy" content="default-src 'none'; style-src 'unsafe-inline'; img-src data:">
<title>groundcal calibration: {verdict} ({input})</title>
<style>{STYLE}</style>
</head>
<body>
<main>
<header><p class="kicker">groundcal calibration report</p><p class="input">{input}</p></header>
"#,
        input = escape(&provenance.input),
    );
    verdict_section(&mut page, result, verdict);
    gates_section(&mut page, result);
    parameters_section(&mut page, result);
    setup_section(&mut page, result, &provenance.input);
    summary_section(&mut page, result);
    let pattern_too_large = result
        .gate_checks
        .iter()
        .find(|c| c.gate == "pattern_max_mm" && !c.passed)
        .map(|c| c.limit);
    pattern::depth_pattern_section(&mut page, result.depth_pattern.as_ref(), pattern_too_large);
    observability_section(&mut page, result);
    correlations_section(&mut page, result);
    accuracy_section(&mut page, result);
    residuals_section(&mut page, result);
    planes_section(&mut page, result);
    commanded_section(&mut page, result);
    set_aside_section(&mut page, result);
    poses_section(&mut page, result);
    provenance_section(&mut page, provenance);
    page.push_str("</main>\n</body>\n</html>\n");
    page
}

fn verdict_section(page: &mut String, result: &ResultJson, verdict: &str) {
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
fn spread_deg(singular_value: f64) -> f64 {
    singular_value.clamp(0.0, 1.0).asin().to_degrees()
}

/// A gate's row: what it is (HTML), its limit, the value measured, and the
/// words before where the value comes from.
fn gate_row(check: &GateCheckJson) -> (String, String, String, Option<&'static str>) {
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

fn gates_section(page: &mut String, result: &ResultJson) {
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

fn parameters_section(page: &mut String, result: &ResultJson) {
    page.push_str(
        "<section id=\"parameters\"><h2>Sensor on the body: <code>robot_from_sensor</code></h2>\n",
    );
    let Some(m) = &result.robot_from_sensor else {
        page.push_str(
            "<p class=\"none\">No parameters: the calibration could not be solved (see the reasons above).</p>\n</section>\n",
        );
        return;
    };
    let sigma = |f: fn(&crate::formats::output::SigmaJson) -> f64| {
        result
            .sigma
            .as_ref()
            .map_or_else(|| "—".to_string(), |s| num(f(s), 4))
    };
    page.push_str(
        "<div class=\"scroll\"><table class=\"params\">\n<thead><tr><th class=\"text\">parameter</th><th>value</th><th>σ</th><th class=\"text\">unit</th></tr></thead>\n<tbody>\n",
    );
    for (name, value, s, unit) in [
        ("α", m.alpha_deg, sigma(|s| s.alpha_deg), "°"),
        ("β", m.beta_deg, sigma(|s| s.beta_deg), "°"),
        ("γ", m.gamma_deg, sigma(|s| s.gamma_deg), "°"),
        ("p<sub>x</sub>", m.px_mm, sigma(|s| s.px_mm), "mm"),
        ("p<sub>y</sub>", m.py_mm, sigma(|s| s.py_mm), "mm"),
        ("p<sub>z</sub>", m.pz_mm, sigma(|s| s.pz_mm), "mm"),
    ] {
        let _ = writeln!(
            page,
            "<tr><th class=\"text\">{name}</th><td>{}</td><td>{s}</td><td class=\"text\">{unit}</td></tr>",
            num(value, 4)
        );
    }
    if let Some(scale) = result.depth_scale {
        let estimated = result.depth_scale_estimated.unwrap_or(false);
        let s = result
            .sigma
            .as_ref()
            .and_then(|s| s.depth_scale)
            .filter(|_| estimated)
            .map_or_else(|| "—".to_string(), |s| num(s, 5));
        let _ = writeln!(
            page,
            "<tr><th class=\"text\">s</th><td>{}</td><td>{s}</td><td class=\"text\">×</td></tr>",
            num(scale, 4)
        );
    }
    page.push_str("</tbody></table></div>\n");
    page.push_str("<p class=\"note\">X-Y-Z fixed angles (γ about X, then β about Z, then α about Y) and the sensor's position in the body frame; σ is one standard deviation. The depth scale s: the Kinect's depth reads s × the truth; estimated with the mount when the body's heights observe it (σ “—”: not estimated, see the notes).</p>\n");
    if let Some(tilt) = result.kinect_tilt_deg {
        let _ = writeln!(
            page,
            "<p class=\"tilt\">Valid with the Kinect's motor tilted {}°.</p>",
            num(tilt, 1)
        );
    }
    page.push_str("<details><summary>Matrix and quaternion</summary>\n<div class=\"scroll\"><table class=\"matrix\"><tbody>\n");
    for row in &m.matrix {
        page.push_str("<tr>");
        for v in row {
            let _ = write!(page, "<td>{}</td>", num(*v, 6));
        }
        page.push_str("</tr>\n");
    }
    let quaternion = m
        .quaternion_xyzw
        .map(|q| {
            format!(
                " Quaternion (x, y, z, w): {}, {}, {}, {}",
                num(q[0], 6),
                num(q[1], 6),
                num(q[2], 6),
                num(q[3], 6)
            )
        })
        .unwrap_or_default();
    let _ = writeln!(
        page,
        "</tbody></table></div>\n<p>Translation in millimetres.{quaternion}</p>\n</details>"
    );
    page.push_str("</section>\n");
}

/// The depth model in words.
fn depth_model_words(model: &DepthModel) -> String {
    match model {
        DepthModel::InverseLinear { a, b } => {
            format!("inverse-linear: z = 1 / (a + b·raw), a = {a}, b = {b}")
        }
        DepthModel::ZeroPlane {
            reference_distance_mm,
            reference_pixel_size_mm,
            emitter_distance_cm,
            const_shift,
        } => format!(
            "zero-plane (libfreenect's): reference distance {reference_distance_mm} mm, pixel size {reference_pixel_size_mm} mm, emitter distance {emitter_distance_cm} cm, shift {const_shift}"
        ),
    }
}

/// The six parameters of a mount, its unit and decimals: (name, value, unit).
fn six(values: [f64; 6]) -> [(&'static str, f64, &'static str); 6] {
    [
        ("α", values[0], "°"),
        ("β", values[1], "°"),
        ("γ", values[2], "°"),
        ("p<sub>x</sub>", values[3], "mm"),
        ("p<sub>y</sub>", values[4], "mm"),
        ("p<sub>z</sub>", values[5], "mm"),
    ]
}

fn setup_section(page: &mut String, result: &ResultJson, input: &str) {
    page.push_str("<section id=\"setup\"><h2>Setup</h2>\n<dl class=\"facts setup\">\n");
    let _ = writeln!(page, "<dt>input</dt><dd>{}</dd>", escape(input));
    let setup = result.setup.clone().unwrap_or_default();
    if let Some(robot) = &setup.robot {
        let _ = writeln!(page, "<dt>robot</dt><dd>{}</dd>", escape(robot));
    }
    let mut schedule = Vec::new();
    if let Some(name) = &setup.schedule {
        schedule.push(format!("“{}”", escape(name)));
    }
    let poses = setup.poses.unwrap_or(result.poses.len());
    schedule.push(format!("{poses} pose{}", if poses == 1 { "" } else { "s" }));
    if let Some(frames) = setup.frames_per_pose {
        schedule.push(format!("{frames} depth frames per pose"));
    }
    let _ = writeln!(
        page,
        "<dt>{}</dt><dd>{}</dd>",
        if result.setup.is_some() {
            "schedule"
        } else {
            "poses"
        },
        schedule.join(", ")
    );
    if let Some(model) = &setup.depth_model {
        let _ = writeln!(
            page,
            "<dt>depth model</dt><dd>{}</dd>",
            escape(&depth_model_words(model))
        );
    }
    if let Some(k) = &setup.intrinsics {
        let _ = writeln!(
            page,
            "<dt>intrinsics</dt><dd>f<sub>x</sub> {}, f<sub>y</sub> {}, c<sub>x</sub> {}, c<sub>y</sub> {} px; {}×{}</dd>",
            num(k.fx, 1),
            num(k.fy, 1),
            num(k.cx, 1),
            num(k.cy, 1),
            k.width,
            k.height
        );
    }
    let _ = writeln!(
        page,
        "<dt>sensor tilt</dt><dd>{}</dd>",
        result.kinect_tilt_deg.map_or_else(
            || "not known".to_string(),
            |t| format!(
                "{}° (the Kinect's motor; the calibration holds for this tilt)",
                num(t, 1)
            )
        )
    );
    let nominal = setup.nominal_mount;
    match &nominal {
        Some(n) => {
            let _ = writeln!(
                page,
                "<dt>nominal mount</dt><dd>α {}°, β {}°, γ {}°; p {}, {}, {} mm ({}; within ±{}°, ±{} mm)</dd>",
                num(n.alpha_deg, 1),
                num(n.beta_deg, 1),
                num(n.gamma_deg, 1),
                num(n.px_mm, 1),
                num(n.py_mm, 1),
                num(n.pz_mm, 1),
                match setup.nominal_mount_from.as_deref() {
                    Some("flag") => "from --nominal-mount",
                    _ => "from the recording",
                },
                num(n.tolerance_deg, 0),
                num(n.tolerance_mm, 0)
            );
        }
        None => page.push_str("<dt>nominal mount</dt><dd>not known</dd>\n"),
    }
    if let Some(from) = &setup.gates_from {
        let words = match from.as_str() {
            "config" => "those of the configuration given (--config)".to_string(),
            "recording" => "those of the recording's live run".to_string(),
            "built-in" => "the built-in ones (the recording stores none)".to_string(),
            other => escape(other),
        };
        let _ = writeln!(page, "<dt>quality gates</dt><dd>{words}</dd>");
    }
    page.push_str("</dl>\n");
    if result.setup.is_none() {
        page.push_str("<p class=\"none\">This input (ground planes only) does not say how it was recorded: no schedule, depth model, commanded poses or nominal mount.</p>\n");
    }

    page.push_str("<h3 id=\"nominal-change\">Change from the nominal mount</h3>\n");
    match (&nominal, &result.robot_from_sensor) {
        (None, _) if result.setup.is_some() => page.push_str("<p class=\"none\">No nominal mount is known for this recording, so there is nothing to compare with (<code>groundcal replay --nominal-mount a,b,g,x,y,z</code> gives one).</p>\n"),
        (None, _) => page.push_str("<p class=\"none\">No nominal mount is known for this input, so there is nothing to compare with.</p>\n"),
        (Some(_), None) => page.push_str("<p class=\"none\">No result to compare with the nominal mount.</p>\n"),
        (Some(n), Some(m)) => {
            let nominal = [n.alpha_deg, n.beta_deg, n.gamma_deg, n.px_mm, n.py_mm, n.pz_mm];
            page.push_str("<div class=\"scroll\"><table class=\"nominal\">\n<thead><tr><th class=\"text\">parameter</th><th>nominal</th><th>result</th><th>change</th></tr></thead>\n<tbody>\n");
            for ((name, result_value, unit), nominal_value) in six(m.values()).into_iter().zip(nominal) {
                let decimals = if unit == "°" { 2 } else { 1 };
                let _ = writeln!(
                    page,
                    "<tr><th class=\"text\">{name} <span class=\"unit\">({unit})</span></th><td>{}</td><td>{}</td><td class=\"delta\">{}</td></tr>",
                    num(nominal_value, decimals),
                    num(result_value, decimals),
                    signed(result_value - nominal_value, decimals)
                );
            }
            let _ = writeln!(
                page,
                "</tbody></table></div>\n<p class=\"note\">Change = result − nominal. The nominal mount only told the ground search where to look (within ±{}° and ±{} mm); a large change means the sensor is not mounted as drawn, or the nominal is out of date.</p>",
                num(n.tolerance_deg, 0),
                num(n.tolerance_mm, 0)
            );
        }
    }
    page.push_str("</section>\n");
}

fn summary_section(page: &mut String, result: &ResultJson) {
    page.push_str("<section id=\"summary\"><h2>Summary</h2>\n");
    let Some(s) = &result.summary else {
        let aside = result.poses.iter().filter(|p| !p.used).count();
        let _ = writeln!(
            page,
            "<p class=\"none\">No summary: the calibration could not be solved. {} poses in the input, {aside} set aside.</p>\n</section>",
            result.poses.len()
        );
        return;
    };
    let _ = writeln!(
        page,
        "<dl class=\"facts\">\n<dt>poses used</dt><dd>{} of {}</dd>\n<dt>θ, mean / max</dt><dd>{}° / {}°</dd>\n<dt>e<sub>d</sub>, mean / max</dt><dd>{} mm / {} mm</dd>",
        s.poses_used,
        s.poses_total,
        num(s.theta_deg_mean, 3),
        num(s.theta_deg_max, 3),
        num(s.e_d_mm_mean, 2),
        num(s.e_d_mm_max, 2)
    );
    page.push_str("</dl>\n<p class=\"note\">θ is the angle between the measured ground and the one the result predicts, e<sub>d</sub> the difference of their distances from the sensor (paper §5.2), over the poses used.</p>\n</section>\n");
}

fn observability_section(page: &mut String, result: &ResultJson) {
    page.push_str("<section id=\"observability\"><h2>What the schedule could tell</h2>\n");
    let Some(o) = &result.observability else {
        page.push_str(
            "<p class=\"none\">Nothing was solved, so nothing was observed.</p>\n</section>\n",
        );
        return;
    };
    let needed = result
        .gate_checks
        .iter()
        .find(|c| c.gate == "observable")
        .map_or_else(
            || crate::calib::solve::SolveSettings::default().min_spread,
            |c| c.limit,
        );
    page.push_str("<ul class=\"weakest\">\n");
    for (kind, singular, words) in [
        (
            "rotation",
            o.rotation_singular_values[2],
            o.rotation_weakest_axis.map(|a| rotation_words(&a)),
        ),
        (
            "position",
            o.translation_singular_values[2],
            o.translation_weakest_axis.map(|a| position_words(&a)),
        ),
    ] {
        let told = singular >= needed;
        let what = words.map_or_else(
            || format!("the weakest {kind} direction"),
            |w| {
                // Capitalised as the start of a sentence.
                let mut chars = w.chars();
                let w = chars.next().map_or_else(String::new, |first| {
                    first.to_uppercase().collect::<String>() + chars.as_str()
                });
                escape(&w)
            },
        );
        let _ = writeln!(
            page,
            "<li class=\"{}\" data-kind=\"{kind}\"><strong>Weakest {kind}:</strong> <span class=\"direction\">{what}</span>. {}</li>",
            if told { "told" } else { "untold" },
            if told {
                format!(
                    "The body's tilts spread it by {}° (RMS); at least {}° is needed.",
                    num(spread_deg(singular), 1),
                    num(spread_deg(needed), 1)
                )
            } else {
                format!(
                    "The schedule cannot tell it: the body's tilts spread it by only {}° (RMS), at least {}° is needed. Add poses that tilt the body about other axes.",
                    num(spread_deg(singular), 1),
                    num(spread_deg(needed), 1)
                )
            }
        );
    }
    page.push_str("</ul>\n<p class=\"note\">The ground tells a rotation of the sensor or a shift of its position only as far as the body's tilts turn the ground's direction seen along it: the more the schedule tilts the body, and about more axes, the better every direction is pinned down. The other directions are pinned down better than these two.</p>\n");
    let list = |v: &[f64; 3]| v.map(|x| num(x, 3)).join(", ");
    let _ = writeln!(
        page,
        "<details><summary>Singular values</summary>\n<dl class=\"facts\">\n<dt>rotation</dt><dd>{}</dd>\n<dt>translation</dt><dd>{}</dd>\n</dl>\n<p class=\"note\">Of the solve's Jacobian per observation; each is about the sine of the tilts' RMS spread in its direction, and a value near 0 means the schedule cannot tell that direction.</p>\n</details>",
        list(&o.rotation_singular_values),
        list(&o.translation_singular_values)
    );
    page.push_str("</section>\n");
}

/// The heat map's colour of a correlation: paler for |r| near 0, darker
/// blue for |r| near 1; the text white on the dark ones.
fn heat_colour(r: f64) -> (String, &'static str) {
    if !r.is_finite() {
        return ("#eceff1".into(), "#5f6368");
    }
    let a = r.abs().min(1.0);
    let lightness = 97.0 - 60.0 * a;
    (
        format!("hsl(212,72%,{lightness:.0}%)"),
        if a >= 0.55 { "#fff" } else { "#1d1f21" },
    )
}

fn correlations_section(page: &mut String, result: &ResultJson) {
    page.push_str("<section id=\"correlations\"><h2>Correlations of the six parameters</h2>\n");
    let Some(r) = &result.correlations else {
        page.push_str("<p class=\"none\">No correlations: nothing was solved.</p>\n</section>\n");
        return;
    };
    const NAMES: [&str; 6] = [
        "α",
        "β",
        "γ",
        "p<sub>x</sub>",
        "p<sub>y</sub>",
        "p<sub>z</sub>",
    ];
    const PLAIN: [&str; 6] = ["α", "β", "γ", "p_x", "p_y", "p_z"];
    page.push_str("<div class=\"scroll\"><table class=\"heat\">\n<thead><tr><th></th>");
    for name in NAMES {
        let _ = write!(page, "<th scope=\"col\">{name}</th>");
    }
    page.push_str("</tr></thead>\n<tbody>\n");
    for (i, row) in r.iter().enumerate() {
        let _ = write!(page, "<tr><th scope=\"row\">{}</th>", NAMES[i]);
        for (j, &value) in row.iter().enumerate() {
            let (background, ink) = if i == j {
                ("#eceff1".to_string(), "#5f6368")
            } else {
                heat_colour(value)
            };
            let text = if i == j && value.is_finite() {
                "1".to_string()
            } else {
                num(value, 2)
            };
            let _ = write!(
                page,
                "<td class=\"cell{}\" style=\"background:{background};color:{ink}\" title=\"{} and {}: r = {}\">{text}</td>",
                if i == j { " diagonal" } else { "" },
                PLAIN[i],
                PLAIN[j],
                num(value, 3)
            );
        }
        page.push_str("</tr>\n");
    }
    page.push_str("</tbody></table></div>\n");
    // The strongest pair, in words.
    let strongest = (0..6)
        .flat_map(|i| (i + 1..6).map(move |j| (i, j)))
        .filter(|&(i, j)| r[i][j].is_finite())
        .max_by(|&(a, b), &(c, d)| r[a][b].abs().total_cmp(&r[c][d].abs()));
    if let Some((i, j)) = strongest {
        let v = r[i][j];
        let words = if v.abs() >= 0.9 {
            "the schedule hardly tells them apart: an error in one is mostly an error in the other"
        } else if v.abs() >= 0.6 {
            "their errors move together noticeably"
        } else {
            "no pair of parameters is strongly tied"
        };
        let _ = writeln!(
            page,
            "<p class=\"strongest\">Strongest: {} and {}, r = {}: {words}.</p>",
            NAMES[i],
            NAMES[j],
            num(v, 2)
        );
    }
    let decoupled = (0..3).all(|i| (3..6).all(|j| r[i][j].abs() < 1e-9));
    let _ = writeln!(
        page,
        "<p class=\"note\"><span class=\"heat-key\" aria-hidden=\"true\"></span> |r| from 0 (pale) to 1 (dark): how much the errors of two parameters move together (the sign says whether in the same or opposite directions).{}</p>",
        if decoupled {
            " The angles come from the ground's direction and the position from its distance, so the two groups do not correlate (the zeros)."
        } else {
            ""
        }
    );
    page.push_str("</section>\n");
}

/// The gate of a key, if the result was checked against it.
fn gate_limit(result: &ResultJson, gate: &str) -> Option<f64> {
    result
        .gate_checks
        .iter()
        .find(|c| c.gate == gate)
        .map(|c| c.limit)
        .filter(|v| v.is_finite())
}

fn accuracy_section(page: &mut String, result: &ResultJson) {
    page.push_str("<section id=\"accuracy\"><h2>Accuracy per pose</h2>\n");
    if result.robot_from_sensor.is_none() {
        page.push_str("<p class=\"none\">No θ or e<sub>d</sub>: without a result there is no predicted ground to compare with.</p>\n</section>\n");
        return;
    }
    let mean_max =
        |f: fn(&crate::formats::output::SummaryJson) -> (f64, f64)| result.summary.as_ref().map(f);
    // The gate's line, or under the chart how far below it the poses are.
    let with_gate = |mut marks: Vec<chart::Mark>,
                     gate: Option<f64>,
                     worst: Option<f64>,
                     format: fn(f64) -> String| {
        if let Some(limit) = gate {
            let share = worst
                .filter(|w| w.is_finite() && limit > 0.0)
                .map(|w| {
                    format!(
                        " (the worst used pose is at {} % of it)",
                        num(100.0 * w / limit, 0)
                    )
                })
                .unwrap_or_default();
            marks.push(gate_mark(
                limit,
                format!("gate {}", format(limit)),
                Some(format!(
                    "The gate ({}) lies far above every pose{share}: it is left off the scale.",
                    format(limit)
                )),
            ));
        }
        marks
    };
    page.push_str("<div class=\"charts\">\n");
    figure(
        page,
        "θ per pose",
        "the angle between the measured and the predicted ground (the paper's Fig. 17)",
        &ChartSpec {
            description: "theta per pose",
            y_desc: "θ (°)",
            y_axis: YAxis::FromZero,
            lines: vec![Line::measured(|p| p.theta_deg)],
            marks: with_gate(
                mean_max_marks(mean_max(|s| (s.theta_deg_mean, s.theta_deg_max)), |v| {
                    format!("{v:.3}°")
                }),
                gate_limit(result, "theta_max_deg"),
                result.summary.as_ref().map(|s| s.theta_deg_max),
                |v| format!("{v:.2}°"),
            ),
            format: |v| format!("{v:.2}°"),
        },
        &result.poses,
    );
    figure(
        page,
        "e<sub>d</sub> per pose",
        "the difference between the measured and the predicted distance of the ground (the paper's Fig. 18)",
        &ChartSpec {
            description: "e_d per pose",
            y_desc: "e_d (mm)",
            y_axis: YAxis::FromZero,
            lines: vec![Line::measured(|p| p.e_d_mm)],
            marks: with_gate(
                mean_max_marks(mean_max(|s| (s.e_d_mm_mean, s.e_d_mm_max)), |v| {
                    format!("{v:.2} mm")
                }),
                gate_limit(result, "e_d_max_mm"),
                result.summary.as_ref().map(|s| s.e_d_mm_max),
                |v| format!("{v:.1} mm"),
            ),
            format: |v| format!("{v:.1} mm"),
        },
        &result.poses,
    );
    page.push_str("</div>\n");
    let mut items = vec![
        LegendItem::Dot(USED, "used pose"),
        LegendItem::Cross(SET_ASIDE, "set aside"),
        LegendItem::Triangle(
            SET_ASIDE,
            "set aside, off the scale (value beside it, or in the table below)",
        ),
        LegendItem::Band,
        LegendItem::Dashed(MEAN, "mean of the used poses"),
        LegendItem::Dashed(MAX, "maximum of the used poses"),
    ];
    if !result.gate_checks.is_empty() {
        items.push(LegendItem::Solid(GATE, "quality gate (the limit)"));
    }
    page.push_str(&legend(&items));
    page.push_str("</section>\n");
}

/// One pose's signed differences between the measured and the predicted
/// ground: d in mm, and the measured normal's tilt from the predicted one
/// about the body's forward and sideways directions along the ground, in
/// degrees (their root sum of squares is θ).
struct Residual {
    index: u32,
    used: bool,
    d_mm: f64,
    about_forward_deg: f64,
    about_sideways_deg: f64,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Every pose with both planes, in the body frame of the result.
fn residuals(result: &ResultJson) -> Vec<Residual> {
    let Some(m) = &result.robot_from_sensor else {
        return Vec::new();
    };
    let rotate = |v: [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|i| (0..3).map(|j| m.matrix[i][j] * v[j]).sum())
    };
    result
        .poses
        .iter()
        .filter_map(|p| {
            let (measured, predicted) = (p.plane?, p.predicted_plane?);
            let n_m = rotate([measured.a, measured.b, measured.c]);
            let n_p = rotate([predicted.a, predicted.b, predicted.c]);
            // The small rotation that takes the predicted normal to the
            // measured one: their cross product (its length is sin θ), on
            // the body's forward axis laid along the predicted ground, and
            // on the sideways one (forward × up, as Z = X × Y).
            let omega = cross(n_p, n_m);
            let along = dot([1.0, 0.0, 0.0], n_p);
            let forward = [1.0 - along * n_p[0], -along * n_p[1], -along * n_p[2]];
            let norm = dot(forward, forward).sqrt();
            let forward = forward.map(|v| v / norm);
            let sideways = cross(forward, n_p);
            let angle = |s: f64| s.clamp(-1.0, 1.0).asin().to_degrees();
            Some(Residual {
                index: p.index,
                used: p.used,
                d_mm: (measured.d_m - predicted.d_m) * 1e3,
                about_forward_deg: angle(dot(omega, forward)),
                about_sideways_deg: angle(dot(omega, sideways)),
            })
        })
        .collect()
}

fn residuals_section(page: &mut String, result: &ResultJson) {
    page.push_str("<section id=\"residuals\"><h2>Signed residuals per pose</h2>\n");
    let rows = residuals(result);
    if rows.is_empty() {
        page.push_str("<p class=\"none\">No residuals: without a result there is no predicted ground to compare with.</p>\n</section>\n");
        return;
    }
    page.push_str("<p class=\"note\">Measured minus predicted: a pattern (all of one sign, or growing with the tilt) points at a bias the unsigned θ and e<sub>d</sub> hide.</p>\n");
    let mut marks = Vec::new();
    if let Some(limit) = gate_limit(result, "e_d_max_mm") {
        marks.push(gate_mark(
            limit,
            format!("gate +{limit:.1} mm"),
            Some(format!(
                "The gate (±{limit:.1} mm) lies far beyond every pose: it is left off the scale."
            )),
        ));
        marks.push(gate_mark(-limit, format!("gate -{limit:.1} mm"), None));
    }
    page.push_str("<div class=\"charts\">\n");
    figure(
        page,
        "Δd per pose",
        "the measured minus the predicted distance of the ground, signed",
        &ChartSpec {
            description: "signed d residual per pose",
            y_desc: "Δd (mm)",
            y_axis: YAxis::Symmetric,
            lines: vec![Line::measured(|p| {
                Some((p.plane?.d_m - p.predicted_plane?.d_m) * 1e3)
            })],
            marks,
            format: |v| format!("{v:+.1} mm"),
        },
        &result.poses,
    );
    page.push_str("<div class=\"scroll\"><table class=\"residuals\">\n<thead><tr><th>pose</th><th>Δd (mm)</th><th>tilt, forward axis (°)</th><th>tilt, sideways axis (°)</th></tr></thead>\n<tbody>\n");
    for r in &rows {
        let _ = writeln!(
            page,
            "<tr{}><td>{}</td><td class=\"dd\">{}</td><td class=\"tx\">{}</td><td class=\"tz\">{}</td></tr>",
            if r.used { "" } else { " class=\"unused\"" },
            r.index,
            signed(r.d_mm, 2),
            signed(r.about_forward_deg, 3),
            signed(r.about_sideways_deg, 3)
        );
    }
    page.push_str("</tbody></table></div>\n</div>\n");
    page.push_str(&legend(&[
        LegendItem::Dot(USED, "used pose"),
        LegendItem::Cross(SET_ASIDE, "set aside"),
        LegendItem::Band,
        LegendItem::Solid(GATE, "e_d's gate, either sign"),
    ]));
    page.push_str("<p class=\"note\">Δd &gt; 0: the ground was measured farther from the sensor than predicted. The tilts turn the predicted ground into the measured one, about the body's forward and sideways axes laid along the ground (right-handed: a positive tilt about the forward axis lowers the ground on the right); together they make θ. The shaded rows are poses set aside.</p>\n</section>\n");
}

fn planes_section(page: &mut String, result: &ResultJson) {
    let solved = result.robot_from_sensor.is_some();
    if solved {
        page.push_str("<section id=\"planes\"><h2>Measured and predicted ground</h2>\n<p class=\"note\">The ground plane a·x + b·y + c·z + d = 0 in the sensor frame at each pose, as measured (filled dots, solid lines) and as the result predicts it from the body pose (hollow squares, dashed lines; a dot inside its square is a pose where the two agree) (the paper's Figs. 14 and 15).</p>\n");
    } else {
        page.push_str("<section id=\"planes\"><h2>Measured ground</h2>\n<p class=\"note\">The ground plane a·x + b·y + c·z + d = 0 in the sensor frame at each pose, as measured (the paper's Figs. 14 and 15 without the prediction, for want of a result).</p>\n");
    }
    page.push_str("<div class=\"charts\">\n");
    let component = |color, predicted, value| Line {
        color,
        aside_color: color,
        predicted,
        value,
    };
    let mut abc = vec![
        component(COMPONENTS[0], false, |p: &PoseJson| p.plane.map(|q| q.a)),
        component(COMPONENTS[1], false, |p: &PoseJson| p.plane.map(|q| q.b)),
        component(COMPONENTS[2], false, |p: &PoseJson| p.plane.map(|q| q.c)),
    ];
    let mut d = vec![component(COMPONENTS[3], false, |p: &PoseJson| {
        p.plane.map(|q| q.d_m)
    })];
    if solved {
        abc.extend([
            component(COMPONENTS[0], true, |p: &PoseJson| {
                p.predicted_plane.map(|q| q.a)
            }),
            component(COMPONENTS[1], true, |p: &PoseJson| {
                p.predicted_plane.map(|q| q.b)
            }),
            component(COMPONENTS[2], true, |p: &PoseJson| {
                p.predicted_plane.map(|q| q.c)
            }),
        ]);
        d.push(component(COMPONENTS[3], true, |p: &PoseJson| {
            p.predicted_plane.map(|q| q.d_m)
        }));
    }
    let what = if solved {
        "measured and predicted"
    } else {
        "measured"
    };
    figure(
        page,
        "Normal a, b, c",
        &format!("{what} (the paper's Fig. 14)"),
        &ChartSpec {
            description: "plane normal a, b, c per pose",
            y_desc: "a, b, c",
            y_axis: YAxis::Fit,
            lines: abc,
            marks: Vec::new(),
            format: |v| format!("{v:.3}"),
        },
        &result.poses,
    );
    figure(
        page,
        "Distance d",
        &format!("{what}: the sensor's height above the ground (the paper's Fig. 15)"),
        &ChartSpec {
            description: "plane distance d per pose",
            y_desc: "d (m)",
            y_axis: YAxis::Fit,
            lines: d,
            marks: Vec::new(),
            format: |v| format!("{v:.3} m"),
        },
        &result.poses,
    );
    page.push_str("</div>\n");
    let mut items = vec![
        LegendItem::Dot(COMPONENTS[0], "a"),
        LegendItem::Dot(COMPONENTS[1], "b"),
        LegendItem::Dot(COMPONENTS[2], "c"),
        LegendItem::Dot(COMPONENTS[3], "d"),
        LegendItem::Measured(INK, "measured"),
    ];
    if solved {
        items.push(LegendItem::Predicted(INK, "predicted"));
    }
    items.extend([
        LegendItem::Cross(INK, "measured, pose set aside"),
        LegendItem::Band,
    ]);
    page.push_str(&legend(&items));
    page.push_str("</section>\n");
}

fn commanded_section(page: &mut String, result: &ResultJson) {
    page.push_str("<section id=\"commanded\"><h2>Commanded body poses</h2>\n");
    let poses: Vec<(&PoseJson, crate::calib::geometry::PoseDegMm)> = result
        .poses
        .iter()
        .filter_map(|p| Some((p, p.commanded?)))
        .collect();
    if poses.is_empty() {
        page.push_str("<p class=\"none\">This input has no commanded poses (ground planes only): the body's attitudes are not known here.</p>\n</section>\n");
        return;
    }
    page.push_str("<p class=\"note\">What the body was asked for at each pose (the solve uses the real pose from the feet, not these): roll γ′ about its forward axis, pitch β′ about its sideways axis, yaw α′ about the vertical, and its height.</p>\n<div class=\"charts\">\n");
    let tilts: Vec<Tilt> = poses
        .iter()
        .map(|(p, c)| Tilt {
            roll_deg: c.gamma_deg,
            pitch_deg: c.beta_deg,
            used: p.used,
        })
        .collect();
    tilt_figure(
        page,
        "Tilts of the schedule",
        "the commanded roll against pitch of every pose; a cloud along one line cannot tell every direction",
        &tilts,
    );
    // Shifts of the body only when some pose has one.
    let shifted = poses
        .iter()
        .any(|(_, c)| c.px_mm.abs() > 1e-9 || c.pz_mm.abs() > 1e-9);
    page.push_str("<div class=\"scroll\"><table class=\"commanded\">\n<thead><tr><th>pose</th><th>roll γ′ (°)</th><th>pitch β′ (°)</th><th>yaw α′ (°)</th><th>height (mm)</th>");
    if shifted {
        page.push_str("<th>x′ (mm)</th><th>z′ (mm)</th>");
    }
    page.push_str("</tr></thead>\n<tbody>\n");
    for (p, c) in &poses {
        let _ = write!(
            page,
            "<tr{}><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>",
            if p.used { "" } else { " class=\"unused\"" },
            p.index,
            num(c.gamma_deg, 1),
            num(c.beta_deg, 1),
            num(c.alpha_deg, 1),
            num(c.py_mm, 0)
        );
        if shifted {
            let _ = write!(
                page,
                "<td>{}</td><td>{}</td>",
                num(c.px_mm, 0),
                num(c.pz_mm, 0)
            );
        }
        page.push_str("</tr>\n");
    }
    page.push_str("</tbody></table></div>\n</div>\n");
    page.push_str(&legend(&[
        LegendItem::Dot(USED, "used pose"),
        LegendItem::Cross(SET_ASIDE, "set aside (shaded rows)"),
    ]));
    page.push_str("</section>\n");
}

fn set_aside_section(page: &mut String, result: &ResultJson) {
    page.push_str("<section id=\"set-aside\"><h2>Poses set aside</h2>\n");
    let aside: Vec<&PoseJson> = result.poses.iter().filter(|p| !p.used).collect();
    if aside.is_empty() {
        page.push_str("<p>None: every pose was used.</p>\n");
    } else {
        page.push_str("<div class=\"scroll\"><table class=\"aside\">\n<thead><tr><th>pose</th><th class=\"text\">why</th><th>θ (°)</th><th>e<sub>d</sub> (mm)</th></tr></thead>\n<tbody>\n");
        for p in aside {
            let _ = writeln!(
                page,
                "<tr><td>{}</td><td class=\"text reason\">{}</td><td>{}</td><td>{}</td></tr>",
                p.index,
                escape(p.reason.as_deref().unwrap_or("no reason given")),
                opt(p.theta_deg, 3),
                opt(p.e_d_mm, 2)
            );
        }
        page.push_str("</tbody></table></div>\n");
    }
    // Poses kept with a remark: a slipped foot left out of the body pose.
    let noted: Vec<&PoseJson> = result.poses.iter().filter(|p| p.note.is_some()).collect();
    if !noted.is_empty() {
        page.push_str("<h3 id=\"noted\">Poses kept with a note</h3>\n<div class=\"scroll\"><table class=\"aside\">\n<thead><tr><th>pose</th><th class=\"text\">note</th></tr></thead>\n<tbody>\n");
        for p in noted {
            let _ = writeln!(
                page,
                "<tr><td>{}</td><td class=\"text reason\">{}</td></tr>",
                p.index,
                escape(p.note.as_deref().unwrap_or_default())
            );
        }
        page.push_str("</tbody></table></div>\n");
    }
    page.push_str("</section>\n");
}

fn poses_section(page: &mut String, result: &ResultJson) {
    let _ = writeln!(
        page,
        "<section id=\"poses\"><details><summary>All {} poses</summary>",
        result.poses.len()
    );
    page.push_str("<div class=\"scroll\"><table class=\"poses\">\n<thead><tr><th>pose</th><th>used</th><th>θ (°)</th><th>e<sub>d</sub> (mm)</th><th>inliers</th><th>a</th><th>b</th><th>c</th><th>d (m)</th><th>predicted a</th><th>b</th><th>c</th><th>d (m)</th></tr></thead>\n<tbody>\n");
    for p in &result.poses {
        let _ = write!(
            page,
            "<tr{}><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>",
            if p.used { "" } else { " class=\"unused\"" },
            p.index,
            if p.used { "yes" } else { "no" },
            opt(p.theta_deg, 3),
            opt(p.e_d_mm, 2),
            p.inliers.map_or_else(|| "—".to_string(), |n| n.to_string()),
        );
        for plane in [p.plane, p.predicted_plane] {
            let values = plane.map(|q| [q.a, q.b, q.c, q.d_m]);
            for k in 0..4 {
                let _ = write!(page, "<td>{}</td>", opt(values.map(|v| v[k]), 4));
            }
        }
        page.push_str("</tr>\n");
    }
    page.push_str("</tbody></table></div>\n</details></section>\n");
}

fn provenance_section(page: &mut String, provenance: &Provenance) {
    let _ = writeln!(
        page,
        "<footer id=\"provenance\"><h2>Provenance</h2>\n<dl class=\"facts\">\n<dt>input</dt><dd>{}</dd>\n<dt>input BLAKE3</dt><dd><code class=\"digest\">{}</code></dd>\n<dt>groundcal</dt><dd>{}</dd>\n<dt>created</dt><dd>{}</dd>\n</dl>\n</footer>",
        escape(&provenance.input),
        escape(&provenance.input_digest),
        escape(&provenance.groundcal_version),
        escape(&provenance.created)
    );
}

/// Inline, because the page must open with no network; large type and one
/// column on a phone, two chart columns from a laptop's width.
const STYLE: &str = r#"
:root { --ink: #1d1f21; --muted: #5f6368; --line: #dadce0; --ok: #1b7f3b; --bad: #b3261e; --bg: #f4f5f7; }
* { box-sizing: border-box; }
html { -webkit-text-size-adjust: 100%; text-size-adjust: 100%; }
body { margin: 0; background: var(--bg); color: var(--ink);
  font: 16px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, "Noto Sans", "DejaVu Sans", sans-serif; }
main { max-width: 1060px; margin: 0 auto; padding: 12px; }
header { padding: 4px 4px 10px; }
.kicker { margin: 0; font-size: .85rem; letter-spacing: .06em; text-transform: uppercase; color: var(--muted); }
.input { margin: 0; font-weight: 600; overflow-wrap: anywhere; }
section, footer { background: #fff; border-radius: 12px; padding: 14px 16px; margin: 0 0 14px;
  box-shadow: 0 1px 2px rgba(0,0,0,.08); }
h1, h2 { line-height: 1.2; }
h2 { font-size: 1.2rem; margin: 0 0 10px; }
.verdict { color: #fff; }
.verdict.accepted { background: var(--ok); }
.verdict.rejected { background: var(--bad); }
.verdict h1 { margin: 0 0 6px; font-size: clamp(1.9rem, 9vw, 3.4rem); letter-spacing: .02em; }
.verdict p { margin: 0 0 6px; font-size: 1.05rem; }
.reasons { margin: 0; padding-left: 1.2em; }
.reasons li { margin: 6px 0; overflow-wrap: anywhere; }
.none { color: var(--muted); font-style: italic; }
.note { color: var(--muted); font-size: .9rem; margin: 8px 0; }
.scroll { overflow-x: auto; -webkit-overflow-scrolling: touch; }
table { border-collapse: collapse; width: 100%; font-variant-numeric: tabular-nums; }
th, td { padding: 6px 8px; border-bottom: 1px solid var(--line); text-align: right; white-space: nowrap; }
thead th { font-size: .85rem; color: var(--muted); font-weight: 600; }
.text { text-align: left; }
td.reason { white-space: normal; min-width: 8em; }
table.aside th, table.aside td { padding: 6px 5px; vertical-align: top; }
table.params { font-size: 1.1rem; max-width: 36rem; }
table.params td:nth-child(3) { color: var(--muted); }
table.poses { font-size: .85rem; }
tr.unused td { background: #fbeceb; }
details { margin-top: 10px; }
summary { cursor: pointer; font-weight: 600; }
figure.warp { margin: 8px 0; max-width: 480px; }
img.warp { display: block; width: 100%; height: auto; image-rendering: pixelated; border: 1px solid #ccc; }
.warp-scale { height: 12px; margin-top: 6px; border: 1px solid #ccc; }
.warp-ticks { display: flex; justify-content: space-between; font-size: 0.85em; }
figure.warp figcaption { font-size: 0.85em; color: #5f6368; margin-top: 4px; }
dl.facts { display: grid; grid-template-columns: max-content 1fr; gap: 4px 14px; margin: 0; }
dl.facts dt { color: var(--muted); }
dl.facts dd { margin: 0; overflow-wrap: anywhere; }
code.digest { font-size: .85rem; word-break: break-all; }
.charts { display: grid; grid-template-columns: 1fr; gap: 14px; }
@media (min-width: 820px) { .charts { grid-template-columns: 1fr 1fr; } main { padding: 20px; } }
figure { margin: 0; min-width: 0; }
figcaption { font-size: .95rem; margin-bottom: 6px; }
figure svg { display: block; width: 100%; height: auto; }
.legend { list-style: none; padding: 0; margin: 10px 0 0; display: flex; flex-wrap: wrap; gap: 6px 16px; font-size: .9rem; }
.legend li { display: flex; align-items: center; gap: 6px; }
.sw { display: inline-block; flex: none; }
.sw.dot { width: 11px; height: 11px; border-radius: 50%; }
.sw.glyph { width: 14px; text-align: center; font-weight: 700; line-height: 1; }
.sw.line { width: 26px; border-top: 3px solid; }
.sw.line.dashed { border-top-style: dashed; }
.sw.band { width: 14px; height: 18px; background: rgba(179,38,30,.18); }
h3 { font-size: 1.05rem; margin: 16px 0 8px; }
thead th { white-space: normal; vertical-align: bottom; }
.charts > * { min-width: 0; }
.gates-lead { margin: 0 0 8px; font-weight: 600; }
table.gates th, table.gates td { padding: 6px 5px; vertical-align: top; }
table.gates td.gate { white-space: normal; min-width: 6.5em; }
table.gates .at { display: block; font-size: .8rem; color: var(--muted); overflow-wrap: anywhere; }
table.gates td.result { font-weight: 700; }
tr.pass td.result { color: var(--ok); }
tr.fail td { background: #fbeceb; }
tr.fail td.result { color: var(--bad); }
table.nominal { max-width: 30rem; }
table.nominal td.delta { font-weight: 600; }
table.nominal .unit { color: var(--muted); font-weight: 400; font-size: .85rem; }
table.gates { font-size: .9rem; }
.weakest { margin: 0; padding-left: 1.2em; }
.weakest li { margin: 6px 0; }
.weakest li.untold { color: var(--bad); }
table.heat { width: auto; margin: 0 auto; border-collapse: separate; border-spacing: 2px; font-size: .85rem; }
table.heat th, table.heat td { padding: 0; border: 0; text-align: center; white-space: nowrap; }
table.heat td { width: 2.85rem; min-width: 2.85rem; height: 2.3rem; border-radius: 4px; }
table.heat th { color: var(--muted); font-weight: 600; font-size: .9rem; }
table.heat tbody th { padding-right: 4px; }
.heat-key { display: inline-block; width: 60px; height: 10px; vertical-align: middle; border: 1px solid var(--line);
  background: linear-gradient(to right, hsl(212,72%,97%), hsl(212,72%,37%)); }
table.residuals, table.commanded { font-size: .9rem; }
.chart-note { margin-top: 4px; }
.sw.series { position: relative; width: 36px; height: 0; border-top: 3px solid; }
.sw.series.dashed { border-top-style: dashed; }
.mk { position: absolute; left: 50%; top: -1.5px; transform: translate(-50%, -50%); }
.mk.dot { width: 10px; height: 10px; border-radius: 50%; }
.mk.square { width: 13px; height: 13px; border: 2px solid; background: #fff; }
@media (max-width: 420px) { section, footer { padding: 12px; } dl.facts { grid-template-columns: 1fr; } dl.facts dd { margin-bottom: 6px; } }
"#;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::calibrate::{calibrate, CalibrationSettings};
    use crate::calib::solve::SolveError;
    use crate::formats::recording::planes::read_planes;

    fn table2() -> Vec<crate::calib::solve::Observation> {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/paper-table2-printed.json");
        read_planes(&path).expect("the Table 2 data reads")
    }

    fn solved() -> ResultJson {
        let calibration =
            calibrate(&table2(), &CalibrationSettings::default()).expect("Table 2 solves");
        ResultJson::from_calibration(&calibration)
    }

    /// Two poses are too few: the solve gives up, as `groundcal solve` reports it.
    fn unsolved() -> ResultJson {
        let observations: Vec<_> = table2().into_iter().take(2).collect();
        match calibrate(&observations, &CalibrationSettings::default()) {
            Err(e @ SolveError::TooFewObservations { .. }) => {
                let SolveError::TooFewObservations { outcomes, .. } = &e;
                ResultJson::unsolved(e.to_string(), outcomes)
            }
            Ok(_) => panic!("two poses must not solve"),
        }
    }

    fn provenance() -> Provenance {
        Provenance::now("recordings/2024-05-01 <table 2>", "ab".repeat(32))
    }

    fn count(haystack: &str, needle: &str) -> usize {
        haystack.matches(needle).count()
    }

    #[test]
    fn shows_the_verdict_reasons_and_five_charts() {
        let result = solved();
        assert!(!result.accepted());
        let html = render_html(&result, &provenance());
        assert!(html.contains("<h1>Failed its checks</h1>"));
        // White words on the verdict's own colour, never on white.
        assert!(html.contains("<section class=\"verdict rejected\" id=\"verdict\">"));
        for reason in &result.reasons {
            assert!(html.contains(&escape(reason)), "missing reason {reason}");
        }
        assert_eq!(count(&html, "<svg"), 5, "θ, e_d, Δd, a/b/c and d");
        assert_eq!(count(&html, "</svg>"), 5);
        // Pose 10 (the sign erratum) is in the table of poses set aside.
        assert!(html.contains("<tr><td>10</td><td class=\"text reason\">inconsistent"));
        assert!(html.contains("mean 0.238°") && html.contains("max 0.463°"));
        assert!(html.contains("-37.4347"));
    }

    #[test]
    fn an_accepted_result_says_so() {
        let mut result = solved();
        result.status = crate::formats::output::ResultStatus::Accepted;
        result.reasons.clear();
        let html = render_html(&result, &provenance());
        assert!(html.contains("<h1>Passed its checks</h1>"));
        assert!(html.contains("<section class=\"verdict accepted\" id=\"verdict\">"));
        assert!(!html.contains("Failed its checks"));
        assert!(html.contains("passed every quality gate"));
        result.notes.push("the <floor> was wet".into());
        result.kinect_tilt_deg = Some(-5.0);
        let html = render_html(&result, &provenance());
        assert!(html.contains("<li>the &lt;floor&gt; was wet</li>"));
        assert!(html.contains("tilted -5.0°"));
    }

    #[test]
    fn escapes_every_text_from_outside() {
        let mut result = solved();
        result
            .reasons
            .push("<script>alert('x')</script> & \"more\"".into());
        result.poses[1].reason = Some("<img src=x onerror=alert(1)>".into());
        let html = render_html(&result, &provenance());
        assert!(!html.contains("<script"));
        assert!(!html.contains("<img"));
        assert!(
            html.contains("&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; &amp; &quot;more&quot;")
        );
        assert!(html.contains("&lt;img src=x onerror=alert(1)&gt;"));
        assert!(html.contains("recordings/2024-05-01 &lt;table 2&gt;"));
        assert!(!html.contains("<table 2>"));
    }

    #[test]
    fn needs_no_network() {
        let html = render_html(&solved(), &provenance());
        let lower = html.to_lowercase();
        for needle in [
            "http://", "https://", "<script", "<link", "<img", "@import", "url(",
        ] {
            assert!(!lower.contains(needle), "the page contains {needle}");
        }
        assert!(html.contains("name=\"viewport\""));
        assert!(html.contains("default-src 'none'"));
    }

    #[test]
    fn renders_an_unsolved_result() {
        let result = unsolved();
        assert!(result.robot_from_sensor.is_none() && result.summary.is_none());
        let html = render_html(&result, &provenance());
        assert!(html.contains("<h1>Failed its checks</h1>"));
        assert!(html.contains(&escape(&result.reasons[0])));
        assert!(html.contains("No parameters"));
        assert!(html.contains("No summary"));
        // Only the measured planes: θ, e_d, Δd and predictions need a result.
        assert_eq!(count(&html, "<svg"), 2);
        assert!(html.contains("No gates were checked"));
        assert!(html.contains("No correlations"));
        assert!(html.contains("Nothing was solved, so nothing was observed"));
        assert!(html.contains("No residuals"));
        assert!(!html.contains("http://") && !html.contains("https://"));
        assert!(html.ends_with("</html>\n"));
    }

    #[test]
    fn survives_odd_values() {
        let mut result = solved();
        result.poses[0].theta_deg = Some(f64::NAN);
        result.poses[2].plane.as_mut().unwrap().d_m = f64::INFINITY;
        result.poses.truncate(3);
        // A pose that gave no plane at all.
        result
            .poses
            .push(PoseJson::failed(60, "no ground in view".into()));
        let html = render_html(&result, &provenance());
        assert_eq!(count(&html, "<svg"), 5);
        assert!(html.contains("<tr><td>60</td><td class=\"text reason\">no ground in view</td><td>—</td><td>—</td></tr>"));
        result.poses.clear();
        let html = render_html(&result, &provenance());
        // No pose, no residual: no Δd chart.
        assert_eq!(count(&html, "<svg"), 4);
        assert!(html.contains("All 0 poses"));
    }

    /// A text of a chart, as plotters writes it.
    fn svg_text(text: &str) -> String {
        format!(">\n{text}\n</text>")
    }

    /// The rows of `table.{class}`'s body.
    fn rows<'a>(html: &'a str, class: &str) -> Vec<&'a str> {
        let start = html
            .find(&format!("<table class=\"{class}\">"))
            .unwrap_or_else(|| panic!("no table.{class}"));
        let body = &html[start..];
        let body = &body[body.find("<tbody>").unwrap()..body.find("</tbody>").unwrap()];
        body.split("<tr").skip(1).collect()
    }

    /// A result as `replay` writes it: the setup, the nominal mount and the
    /// commanded pose of each pose.
    fn recorded() -> ResultJson {
        use crate::calib::geometry::PoseDegMm;
        use crate::calib::observe::NominalMount;
        use crate::calib::sensor::{DepthModel, Intrinsics};
        let mut result = solved();
        result.kinect_tilt_deg = Some(-20.0);
        result.setup = Some(crate::formats::output::SetupJson {
            robot: Some("octopus".into()),
            schedule: Some("table <2>".into()),
            poses: Some(6),
            frames_per_pose: Some(4),
            depth_model: Some(DepthModel::InverseLinear {
                a: 3.33,
                b: -0.00307,
            }),
            intrinsics: Some(Intrinsics::default()),
            nominal_mount: Some(NominalMount::from_values([
                0.0, -37.0, -3.0, 500.0, 350.0, -100.0,
            ])),
            nominal_mount_from: Some("flag".into()),
            gates_from: Some("recording".into()),
        });
        for (k, pose) in result.poses.iter_mut().enumerate() {
            pose.commanded = Some(PoseDegMm {
                alpha_deg: 0.0,
                beta_deg: k as f64 * 2.0,
                gamma_deg: -(k as f64),
                px_mm: 0.0,
                py_mm: 600.0 + k as f64,
                pz_mm: 0.0,
            });
        }
        result
    }

    #[test]
    fn gates_table_has_every_gate_with_its_limit_value_and_verdict() {
        let result = solved();
        let html = render_html(&result, &provenance());
        let gates = rows(&html, "gates");
        assert_eq!(gates.len(), 7);
        assert_eq!(gates.len(), result.gate_checks.len());
        let failed = result.gate_checks.iter().filter(|c| !c.passed).count();
        assert_eq!(failed, 4);
        assert_eq!(count(&html, "✗ FAIL"), failed);
        assert_eq!(count(&html, "✓ pass"), 7 - failed);
        assert!(html.contains("4 of 7 gates failed."));
        let e_d = gates
            .iter()
            .find(|r| r.contains("data-gate=\"e_d_max_mm\""))
            .unwrap();
        assert!(e_d.starts_with(" class=\"fail\""), "{e_d}");
        assert!(
            e_d.contains("≤ 5.0 mm") && e_d.contains("26.78 mm") && e_d.contains("at pose 15"),
            "{e_d}"
        );
        let theta = gates
            .iter()
            .find(|r| r.contains("data-gate=\"theta_max_deg\""))
            .unwrap();
        assert!(
            theta.starts_with(" class=\"pass\"")
                && theta.contains("≤ 1.00°")
                && theta.contains("0.463°"),
            "{theta}"
        );
        let fraction = gates
            .iter()
            .find(|r| r.contains("data-gate=\"min_used_fraction\""))
            .unwrap();
        assert!(
            fraction.contains("≥ 70 %") && fraction.contains("83 %"),
            "{fraction}"
        );
    }

    #[test]
    fn theta_and_e_d_charts_draw_their_gate_as_a_line_or_say_where_it_is() {
        let mut result = solved();
        let html = render_html(&result, &provenance());
        // θ's gate (1°) and e_d's (5 mm) are near the data: lines with labels.
        assert!(html.contains(&svg_text("gate 1.00°")), "θ's gate line");
        assert!(html.contains(&svg_text("gate 5.0 mm")), "e_d's gate line");
        assert!(
            html.contains(&svg_text("gate +5.0 mm")) && html.contains(&svg_text("gate -5.0 mm"))
        );
        assert!(!html.contains("left off the scale"));
        // A gate far above every pose is said under the chart instead.
        for check in &mut result.gate_checks {
            if check.gate == "theta_max_deg" {
                check.limit = 20.0;
            }
        }
        let html = render_html(&result, &provenance());
        assert!(!html.contains(&svg_text("gate 20.00°")));
        assert!(html.contains("The gate (20.00°) lies far above every pose (the worst used pose is at 2 % of it): it is left off the scale."));
        // Old documents have no checks: no gate lines, no legend for them.
        result.gate_checks.clear();
        let html = render_html(&result, &provenance());
        assert!(!html.contains(">\ngate ") && !html.contains("quality gate (the limit)"));
    }

    #[test]
    fn correlations_are_a_labelled_heat_map_of_36_values() {
        let result = solved();
        let r = result.correlations.unwrap();
        let html = render_html(&result, &provenance());
        let heat = rows(&html, "heat");
        assert_eq!(heat.len(), 6);
        assert_eq!(count(&html, "<td class=\"cell"), 36);
        assert_eq!(count(&html, "<td class=\"cell diagonal\""), 6);
        for name in [
            "α",
            "β",
            "γ",
            "p<sub>x</sub>",
            "p<sub>y</sub>",
            "p<sub>z</sub>",
        ] {
            assert!(
                html.contains(&format!("<th scope=\"col\">{name}</th>")),
                "{name}"
            );
            assert!(
                html.contains(&format!("<th scope=\"row\">{name}</th>")),
                "{name}"
            );
        }
        // Each value in its cell, coloured by |r|.
        let ag = format!(
            "title=\"α and γ: r = {}\">{}</td>",
            num(r[0][2], 3),
            num(r[0][2], 2)
        );
        assert!(html.contains(&ag), "{ag}");
        let (pale, _) = heat_colour(0.0);
        let (dark, ink) = heat_colour(-0.95);
        assert_eq!(heat_colour(0.95), heat_colour(-0.95), "by |r|");
        assert_ne!(pale, dark);
        assert_eq!(ink, "#fff");
        assert!(
            html.contains("Strongest: α and γ, r = 0.55"),
            "the strongest pair named"
        );
    }

    #[test]
    fn names_the_weakest_directions_in_words() {
        let result = solved();
        let o = result.observability.as_ref().unwrap();
        let html = render_html(&result, &provenance());
        assert!(html.contains("<strong>Weakest rotation:</strong> <span class=\"direction\">Rotation about the body&#39;s vertical axis Y (yaw of the sensor, α)</span>"), "{html}");
        let position = position_words(&o.translation_weakest_axis.unwrap());
        assert_eq!(position, "the sensor's sideways (p_z) position");
        assert!(html.contains("<strong>Weakest position:</strong> <span class=\"direction\">The sensor&#39;s sideways (p_z) position</span>"));
        // As the spread of the tilts it stands for, against the threshold.
        let spread = num(spread_deg(o.translation_singular_values[2]), 1);
        assert!(html.contains(&format!(
            "spread it by {spread}° (RMS); at least 1.0° is needed"
        )));
        // A direction below the threshold is said to be untold.
        let mut result = result;
        if let Some(o) = &mut result.observability {
            o.translation_singular_values[2] = 0.001;
        }
        let html = render_html(&result, &provenance());
        assert!(html.contains("<li class=\"untold\" data-kind=\"position\">"));
        assert!(html.contains("The schedule cannot tell it"));
        // An old document without the axes still reads.
        if let Some(o) = &mut result.observability {
            o.rotation_weakest_axis = None;
            o.translation_weakest_axis = None;
        }
        let html = render_html(&result, &provenance());
        assert!(html.contains("<span class=\"direction\">the weakest rotation direction</span>"));
    }

    #[test]
    fn shows_the_setup_and_the_change_from_the_nominal_mount() {
        let result = recorded();
        let html = render_html(&result, &provenance());
        for fact in [
            "<dt>robot</dt><dd>octopus</dd>",
            "<dt>schedule</dt><dd>“table &lt;2&gt;”, 6 poses, 4 depth frames per pose</dd>",
            "<dt>depth model</dt><dd>inverse-linear: z = 1 / (a + b·raw), a = 3.33, b = -0.00307</dd>",
            "<dt>sensor tilt</dt><dd>-20.0°",
            "<dt>nominal mount</dt><dd>α 0.0°, β -37.0°, γ -3.0°; p 500.0, 350.0, -100.0 mm (from --nominal-mount;",
            "<dt>quality gates</dt><dd>those of the recording's live run</dd>",
        ] {
            assert!(html.contains(fact), "missing {fact}");
        }
        let nominal = rows(&html, "nominal");
        assert_eq!(nominal.len(), 6);
        // β: -37.4347 - (-37) and p_z: -119.9 - (-100).
        assert!(
            nominal[1].contains("<td>-37.00</td><td>-37.43</td><td class=\"delta\">-0.43</td>"),
            "{}",
            nominal[1]
        );
        assert!(
            nominal[5].contains("<td>-100.0</td><td>-119.9</td><td class=\"delta\">-19.9</td>"),
            "{}",
            nominal[5]
        );

        // A planes file: no setup, said so; nothing to compare with.
        let html = render_html(&solved(), &provenance());
        assert!(html.contains("<dt>poses</dt><dd>6 poses</dd>"));
        assert!(html.contains("<dt>nominal mount</dt><dd>not known</dd>"));
        assert!(html.contains("does not say how it was recorded"));
        assert!(html.contains("No nominal mount is known for this input"));
        assert!(!html.contains("<table class=\"nominal\">"));
    }

    #[test]
    fn signed_residuals_one_per_pose_with_a_plane() {
        let result = solved();
        let html = render_html(&result, &provenance());
        let table = rows(&html, "residuals");
        assert_eq!(table.len(), 6);
        let used: Vec<&&str> = table.iter().filter(|r| !r.contains("unused")).collect();
        assert_eq!(used.len(), result.summary.as_ref().unwrap().poses_used);
        for (row, pose) in table.iter().zip(&result.poses) {
            let d = (pose.plane.unwrap().d_m - pose.predicted_plane.unwrap().d_m) * 1e3;
            assert!(
                row.contains(&format!("<td class=\"dd\">{}</td>", signed(d, 2))),
                "{row}"
            );
            assert!((d.abs() - pose.e_d_mm.unwrap()).abs() < 1e-9, "|Δd| is e_d");
        }
        // The measured normal's tilts from the predicted one make θ.
        for (r, pose) in residuals(&result).iter().zip(&result.poses) {
            let tilt = r.about_forward_deg.hypot(r.about_sideways_deg);
            let theta = pose.theta_deg.unwrap();
            assert!(
                (tilt - theta).abs() < 1e-3 * theta.max(1.0),
                "{tilt} {theta}"
            );
        }
        assert!(html.contains("<tr class=\"unused\"><td>10</td><td class=\"dd\">+45.39</td>"));
    }

    #[test]
    fn lists_the_commanded_attitude_of_each_pose() {
        let result = recorded();
        let html = render_html(&result, &provenance());
        let commanded = rows(&html, "commanded");
        assert_eq!(commanded.len(), result.poses.len());
        assert!(
            commanded[2].contains("<td>15</td><td>-2.0</td><td>4.0</td><td>0.0</td><td>602</td>"),
            "{}",
            commanded[2]
        );
        assert!(
            commanded[1].starts_with(" class=\"unused\""),
            "pose 10 is set aside"
        );
        assert!(
            !html.contains("<th>x′ (mm)</th>"),
            "no shifts, no columns for them"
        );
        assert_eq!(count(&html, "<svg"), 6, "the chart of tilts too");
        assert!(html.contains("aria-label=\"commanded roll against pitch per pose\""));
        // A planes file has none, and says so.
        let html = render_html(&solved(), &provenance());
        assert!(html.contains("This input has no commanded poses"));
        assert!(!html.contains("<table class=\"commanded\">"));
    }

    #[test]
    fn predicted_planes_are_hollow_squares_told_apart_from_measured_dots() {
        let html = render_html(&solved(), &provenance());
        let planes = &html[html.find("<section id=\"planes\">").unwrap()..];
        let planes = &planes[..planes.find("</section>").unwrap()];
        // Past the two charts' backgrounds: 5 used poses × (a, b, c, d)
        // predicted, and pose 10's predicted a, b, c (its d is off the scale).
        assert_eq!(count(planes, "<rect") - 2, 5 * 4 + 3, "{planes}");
        assert!(
            planes.contains("<i class=\"mk dot\"") && planes.contains("<i class=\"mk square\"")
        );
        assert!(planes.contains("measured</li>") && planes.contains("predicted</li>"));
    }

    #[test]
    fn writes_index_html_atomically() {
        use std::fs;
        let dir = std::env::temp_dir().join(format!(
            "groundcal-report-test-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        let _ = fs::remove_dir_all(&dir);
        let nested = dir.join("a/b");
        let result = solved();
        let path = write_report(&nested, &result, &provenance()).expect("writes");
        assert_eq!(path, nested.join("index.html"));
        let first = fs::read_to_string(&path).unwrap();
        assert!(first.contains("Failed its checks"));
        // Again over the old one; no temporary file is left behind.
        write_report(&nested, &result, &provenance()).expect("rewrites");
        let names: Vec<_> = fs::read_dir(&nested)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("index.html")]);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn provenance_is_this_groundcal_now() {
        let p = provenance();
        assert_eq!(p.groundcal_version, env!("CARGO_PKG_VERSION"));
        let created = humantime::parse_rfc3339(&p.created).expect("RFC 3339");
        let age = SystemTime::now().duration_since(created).unwrap();
        assert!(age.as_secs() < 60);
        assert!(p.created.ends_with('Z'));
        let html = render_html(&solved(), &p);
        assert!(html.contains(&p.created) && html.contains(&p.input_digest));
    }
}
