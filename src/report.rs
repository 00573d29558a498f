//! The offline calibration report (`groundcal replay DIR --report OUTDIR`): one
//! HTML page that a person reads on a phone or a laptop.
//!
//! The page is self-contained so that it can be mailed, archived next to the
//! recording or opened on a robot with no network: inline CSS, no script, no
//! font or image from anywhere, and a Content-Security-Policy that forbids
//! loading anything. Charts are drawn by `plotters` into SVG strings and
//! inlined; every text that comes from outside (reasons, paths) is escaped.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use plotters::coord::types::{RangedCoordf64, RangedCoordi32};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::files::{write_atomically, FileError};
use crate::output::{PoseJson, ResultJson};

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

/// Writes `dir/index.html` atomically ([`crate::files::write_atomically`]),
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
    let verdict = if result.accepted() {
        "ACCEPTED"
    } else {
        "REJECTED"
    };
    let mut page = String::with_capacity(64 * 1024);
    let _ = write!(
        page,
        r#"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta http-equiv="Content-Security-Policy" content="default-src 'none'; style-src 'unsafe-inline'">
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
    parameters_section(&mut page, result);
    summary_section(&mut page, result);
    charts_section(&mut page, result);
    set_aside_section(&mut page, result);
    poses_section(&mut page, result);
    provenance_section(&mut page, provenance);
    page.push_str("</main>\n</body>\n</html>\n");
    page
}

/// Escapes text for HTML content and attribute values.
fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A number with fixed decimals, or a dash where there is none (NaN, ∞).
fn num(value: f64, decimals: usize) -> String {
    if value.is_finite() {
        format!("{value:.decimals$}")
    } else {
        "—".to_string()
    }
}

/// [`num`] of a value that may be missing.
fn opt(value: Option<f64>, decimals: usize) -> String {
    value.map_or_else(|| "—".to_string(), |v| num(v, decimals))
}

fn verdict_section(page: &mut String, result: &ResultJson, verdict: &str) {
    let class = verdict.to_lowercase();
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
    let sigma = |f: fn(&crate::output::SigmaJson) -> f64| {
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
    page.push_str("</tbody></table></div>\n");
    page.push_str("<p class=\"note\">X-Y-Z fixed angles (γ about X, then β about Z, then α about Y) and the sensor's position in the body frame; σ is one standard deviation.</p>\n");
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
    if let Some(o) = &result.observability {
        let list = |v: &[f64; 3]| v.map(|x| num(x, 3)).join(", ");
        let _ = writeln!(
            page,
            "<dt>observability, rotation</dt><dd>{}</dd>\n<dt>observability, translation</dt><dd>{}</dd>",
            list(&o.rotation_singular_values),
            list(&o.translation_singular_values)
        );
    }
    page.push_str("</dl>\n<p class=\"note\">θ is the angle between the measured ground and the one the result predicts, e<sub>d</sub> the difference of their distances from the sensor (paper §5.2), over the poses used. Observability: singular values per direction; a value near 0 means the schedule cannot tell that direction.</p>\n</section>\n");
}

fn charts_section(page: &mut String, result: &ResultJson) {
    let solved = result.robot_from_sensor.is_some();
    page.push_str("<section id=\"accuracy\"><h2>Accuracy per pose</h2>\n");
    if !solved {
        page.push_str("<p class=\"none\">No θ or e<sub>d</sub>: without a result there is no predicted ground to compare with.</p>\n");
    } else {
        let mean_max =
            |f: fn(&crate::output::SummaryJson) -> (f64, f64)| result.summary.as_ref().map(f);
        page.push_str("<div class=\"charts\">\n");
        figure(
            page,
            "θ per pose",
            "the angle between the measured and the predicted ground (the paper's Fig. 17)",
            &ChartSpec {
                description: "theta per pose",
                y_desc: "θ (°)",
                from_zero: true,
                lines: vec![Line {
                    color: USED,
                    aside_color: SET_ASIDE,
                    dashed: false,
                    value: |p| p.theta_deg,
                }],
                marks: marks(mean_max(|s| (s.theta_deg_mean, s.theta_deg_max)), |v| {
                    format!("{v:.3}°")
                }),
                format: |v| format!("{v:.2}°"),
            },
            result,
        );
        figure(
            page,
            "e<sub>d</sub> per pose",
            "the difference between the measured and the predicted distance of the ground (the paper's Fig. 18)",
            &ChartSpec {
                description: "e_d per pose",
                y_desc: "e_d (mm)",
                from_zero: true,
                lines: vec![Line {
                    color: USED,
                    aside_color: SET_ASIDE,
                    dashed: false,
                    value: |p| p.e_d_mm,
                }],
                marks: marks(
                    mean_max(|s| (s.e_d_mm_mean, s.e_d_mm_max)),
                    |v| format!("{v:.2} mm"),
                ),
                format: |v| format!("{v:.1} mm"),
            },
            result,
        );
        page.push_str("</div>\n");
        page.push_str(&legend(&[
            LegendItem::Dot(USED, "used pose"),
            LegendItem::Cross(SET_ASIDE, "set aside"),
            LegendItem::Triangle(
                SET_ASIDE,
                "set aside, off the scale (value beside it, or in the table below)",
            ),
            LegendItem::Band,
            LegendItem::Dashed(MEAN, "mean of the used poses"),
            LegendItem::Dashed(MAX, "maximum of the used poses"),
        ]));
    }
    page.push_str("</section>\n");

    if solved {
        page.push_str("<section id=\"planes\"><h2>Measured and predicted ground</h2>\n<p class=\"note\">The ground plane a·x + b·y + c·z + d = 0 in the sensor frame at each pose, as measured and as the result predicts it from the body pose (the paper's Figs. 14 and 15).</p>\n");
    } else {
        page.push_str("<section id=\"planes\"><h2>Measured ground</h2>\n<p class=\"note\">The ground plane a·x + b·y + c·z + d = 0 in the sensor frame at each pose, as measured (the paper's Figs. 14 and 15 without the prediction, for want of a result).</p>\n");
    }
    page.push_str("<div class=\"charts\">\n");
    let component = |color, dashed, value| Line {
        color,
        aside_color: color,
        dashed,
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
            from_zero: false,
            lines: abc,
            marks: Vec::new(),
            format: |v| format!("{v:.3}"),
        },
        result,
    );
    figure(
        page,
        "Distance d",
        &format!("{what}: the sensor's height above the ground (the paper's Fig. 15)"),
        &ChartSpec {
            description: "plane distance d per pose",
            y_desc: "d (m)",
            from_zero: false,
            lines: d,
            marks: Vec::new(),
            format: |v| format!("{v:.3} m"),
        },
        result,
    );
    page.push_str("</div>\n");
    let mut items = vec![
        LegendItem::Dot(COMPONENTS[0], "a"),
        LegendItem::Dot(COMPONENTS[1], "b"),
        LegendItem::Dot(COMPONENTS[2], "c"),
        LegendItem::Dot(COMPONENTS[3], "d"),
        LegendItem::Solid(INK, "measured"),
    ];
    if solved {
        items.push(LegendItem::Dashed(INK, "predicted (open circles)"));
    }
    items.extend([
        LegendItem::Cross(INK, "measured, pose set aside"),
        LegendItem::Band,
    ]);
    page.push_str(&legend(&items));
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

// ---------------------------------------------------------------------------
// Charts

/// Logical size of every chart. The page scales charts to the column width
/// (about 0.8× on a phone), so the fonts below are large enough to survive it.
const CHART_SIZE: (u32, u32) = (420, 300);
const FONT: &str = "sans-serif";
const TICK_FONT: u32 = 19;
const DESC_FONT: u32 = 20;

const INK: RGBColor = RGBColor(0x30, 0x33, 0x36);
const USED: RGBColor = RGBColor(0x1a, 0x5f, 0xb4);
const SET_ASIDE: RGBColor = RGBColor(0xb3, 0x26, 0x1e);
const MEAN: RGBColor = RGBColor(0x1b, 0x7f, 0x3b);
const MAX: RGBColor = RGBColor(0x8e, 0x24, 0xaa);
/// a, b, c, d.
const COMPONENTS: [RGBColor; 4] = [
    RGBColor(0x1a, 0x5f, 0xb4),
    RGBColor(0xe6, 0x61, 0x00),
    RGBColor(0x26, 0xa2, 0x69),
    RGBColor(0x61, 0x35, 0x83),
];

/// One per-pose series.
struct Line {
    color: RGBColor,
    /// The colour of its marks at set-aside poses.
    aside_color: RGBColor,
    /// Dashed with open circles (predicted) rather than solid with dots.
    dashed: bool,
    /// None where the pose has no such value (no plane found).
    value: fn(&PoseJson) -> Option<f64>,
}

/// A horizontal reference line (mean, max), labelled in the chart.
struct Mark {
    label: String,
    value: f64,
    color: RGBColor,
    /// Where the label goes, so that two close lines do not overprint.
    label_left: bool,
}

struct ChartSpec<'a> {
    /// For screen readers.
    description: &'a str,
    y_desc: &'a str,
    from_zero: bool,
    lines: Vec<Line>,
    marks: Vec<Mark>,
    /// Labels of values beyond the scale.
    format: fn(f64) -> String,
}

fn marks(mean_max: Option<(f64, f64)>, format: fn(f64) -> String) -> Vec<Mark> {
    let Some((mean, max)) = mean_max else {
        return Vec::new();
    };
    vec![
        Mark {
            label: format!("mean {}", format(mean)),
            value: mean,
            color: MEAN,
            label_left: true,
        },
        Mark {
            label: format!("max {}", format(max)),
            value: max,
            color: MAX,
            label_left: false,
        },
    ]
}

/// One chart with its caption; a chart that cannot be drawn says so instead.
/// `title` and `caption` are this file's own HTML, never outside text.
fn figure(page: &mut String, title: &str, caption: &str, spec: &ChartSpec, result: &ResultJson) {
    let _ = writeln!(
        page,
        "<figure><figcaption><strong>{title}</strong>: {caption}</figcaption>"
    );
    match draw_chart(spec, &result.poses) {
        Ok(svg) => page.push_str(&inline_svg(&svg, spec.description)),
        Err(e) => {
            let _ = writeln!(
                page,
                "<p class=\"none\">The chart could not be drawn: {}</p>",
                escape(&e.to_string())
            );
        }
    }
    page.push_str("</figure>\n");
}

/// A standalone SVG document made fit for inlining in HTML: the namespace is
/// implied there, and the size comes from the page (the viewBox keeps the
/// aspect ratio).
fn inline_svg(svg: &str, description: &str) -> String {
    let (w, h) = CHART_SIZE;
    svg.replacen(" xmlns=\"http://www.w3.org/2000/svg\"", "", 1)
        .replacen(
            &format!("<svg width=\"{w}\" height=\"{h}\""),
            &format!("<svg role=\"img\" aria-label=\"{}\"", escape(description)),
            1,
        )
}

/// Where a value falls on a chart whose y range was chosen from the used poses.
enum Place {
    Inside(f64),
    Above,
    Below,
}

fn place(value: f64, (lo, hi): (f64, f64)) -> Option<Place> {
    if !value.is_finite() {
        None
    } else if value > hi {
        Some(Place::Above)
    } else if value < lo {
        Some(Place::Below)
    } else {
        Some(Place::Inside(value))
    }
}

/// The y range: from the used poses only, so that one wild set-aside pose does
/// not flatten the rest (it is drawn at the edge with its value instead).
fn y_range(spec: &ChartSpec, poses: &[PoseJson]) -> (f64, f64) {
    let any_used = poses.iter().any(|p| p.used);
    let mut values: Vec<f64> = poses
        .iter()
        .filter(|p| p.used || !any_used)
        .flat_map(|p| spec.lines.iter().filter_map(move |l| (l.value)(p)))
        .chain(spec.marks.iter().map(|m| m.value))
        .filter(|v| v.is_finite())
        .collect();
    if spec.from_zero {
        values.push(0.0);
    }
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    if spec.from_zero {
        // Headroom above the max line for its label.
        let top = if hi > 0.0 { hi * 1.3 } else { 1.0 };
        (0.0, top)
    } else {
        let pad = ((hi - lo) * 0.1).max(1e-3);
        (lo - pad, hi + pad)
    }
}

/// Tick decimals that tell neighbouring ticks apart without noise.
fn decimals_for(span: f64) -> usize {
    let step = span / 5.0;
    if !(step.is_finite() && step > 0.0) {
        return 2;
    }
    (-step.log10()).ceil().clamp(0.0, 6.0) as usize
}

type DrawError = Box<dyn std::error::Error>;

/// Draws one chart with plotters into a standalone SVG document.
fn draw_chart(spec: &ChartSpec, poses: &[PoseJson]) -> Result<String, DrawError> {
    let x_lo = poses.iter().map(|p| p.index as i32).min().unwrap_or(1) - 1;
    let x_hi = poses.iter().map(|p| p.index as i32).max().unwrap_or(1) + 1;
    let (y_lo, y_hi) = y_range(spec, poses);
    let decimals = decimals_for(y_hi - y_lo);
    let tick = || (FONT, TICK_FONT).into_font().color(&INK);

    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, CHART_SIZE).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(14)
            .margin_right(20)
            .x_label_area_size(58)
            .y_label_area_size(if decimals > 2 { 84 } else { 72 })
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
        let y_formatter = |v: &f64| format!("{v:.decimals$}");
        chart
            .configure_mesh()
            .x_desc("pose")
            .y_desc(spec.y_desc)
            .label_style(tick())
            .axis_desc_style((FONT, DESC_FONT).into_font().color(&INK))
            .axis_style(INK.stroke_width(1))
            .bold_line_style(RGBColor(0xe3, 0xe5, 0xe8).stroke_width(1))
            .light_line_style(TRANSPARENT)
            .x_labels(8)
            .y_labels(6)
            .y_label_formatter(&y_formatter)
            .draw()?;

        let width_px = f64::from(chart.plotting_area().dim_in_pixel().0);
        let unit_px = width_px / f64::from(x_hi - x_lo);
        // Markers and bands scale with the space between neighbouring poses.
        let mut indices: Vec<i32> = poses.iter().map(|p| p.index as i32).collect();
        indices.sort_unstable();
        let gap = indices
            .windows(2)
            .map(|w| w[1] - w[0])
            .filter(|&g| g > 0)
            .min()
            .unwrap_or(1);
        let gap_px = f64::from(gap) * unit_px;
        let frame = Frame {
            x_lo,
            y_range: (y_lo, y_hi),
            width_px,
            unit_px,
            radius: (gap_px * 0.4).clamp(3.0, 6.0) as u32,
        };

        // Set-aside poses: a pale red band across the whole chart.
        let band = (gap_px * 0.6).clamp(4.0, 16.0) as u32;
        chart.draw_series(poses.iter().filter(|p| !p.used).map(|p| {
            let x = p.index as i32;
            PathElement::new(
                vec![(x, y_lo), (x, y_hi)],
                SET_ASIDE.mix(0.13).stroke_width(band),
            )
        }))?;

        for mark in &spec.marks {
            if !(mark.value.is_finite() && mark.value <= y_hi) {
                continue;
            }
            chart.draw_series(DashedLineSeries::new(
                vec![(x_lo, mark.value), (x_hi, mark.value)],
                10,
                6,
                mark.color.stroke_width(2),
            ))?;
            let (x, h, dx) = if mark.label_left {
                (x_lo, HPos::Left, 6)
            } else {
                (x_hi, HPos::Right, -6)
            };
            let style = (FONT, TICK_FONT)
                .into_font()
                .color(&mark.color)
                .pos(Pos::new(h, VPos::Bottom));
            chart.draw_series(std::iter::once(
                EmptyElement::at((x, mark.value)) + Text::new(mark.label.clone(), (dx, -4), style),
            ))?;
        }

        let mut labels = EdgeLabels::default();
        for line in &spec.lines {
            let used: Vec<(i32, f64)> = poses
                .iter()
                .filter(|p| p.used)
                .filter_map(|p| Some((p.index as i32, (line.value)(p)?)))
                .filter(|(_, v)| v.is_finite())
                .collect();
            let r = frame.radius;
            if line.dashed {
                chart.draw_series(DashedLineSeries::new(
                    used.clone(),
                    8,
                    5,
                    line.color.stroke_width(2),
                ))?;
                chart.draw_series(
                    used.iter()
                        .map(|&p| Circle::new(p, r + 1, line.color.stroke_width(2))),
                )?;
            } else {
                chart.draw_series(LineSeries::new(used.clone(), line.color.stroke_width(2)))?;
                chart.draw_series(used.iter().map(|&p| Circle::new(p, r, line.color.filled())))?;
            }
            draw_set_aside(&mut chart, spec, line, poses, &frame, &mut labels)?;
        }
        root.present()?;
    }
    Ok(svg)
}

/// The drawn chart's coordinates in pixels, for marks placed by hand.
struct Frame {
    x_lo: i32,
    y_range: (f64, f64),
    /// Plotting area width.
    width_px: f64,
    /// Pixels per pose.
    unit_px: f64,
    radius: u32,
}

/// Where the last value label beyond the scale ends, at the top and the
/// bottom edge, so that labels of neighbouring poses do not overprint (the
/// table of poses set aside has every value).
#[derive(Default)]
struct EdgeLabels {
    above_end_px: Option<f64>,
    below_end_px: Option<f64>,
}

/// Marks at set-aside poses: × (measured) or ○ (predicted), or a triangle at
/// the edge with the value beside it when beyond the scale.
fn draw_set_aside<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordi32, RangedCoordf64>>,
    spec: &ChartSpec,
    line: &Line,
    poses: &[PoseJson],
    frame: &Frame,
    labels: &mut EdgeLabels,
) -> Result<(), DrawError>
where
    DB::ErrorType: 'static,
{
    let color = line.aside_color;
    let r = frame.radius;
    let px = |x: i32| f64::from(x - frame.x_lo) * frame.unit_px;
    // Triangles on each edge, which a label must not cover either.
    let edge_px = |above: bool| -> Vec<f64> {
        poses
            .iter()
            .filter(|p| !p.used)
            .filter(
                |p| match (line.value)(p).and_then(|v| place(v, frame.y_range)) {
                    Some(Place::Above) => above,
                    Some(Place::Below) => !above,
                    _ => false,
                },
            )
            .map(|p| px(p.index as i32))
            .collect()
    };
    let (above_px, below_px) = (edge_px(true), edge_px(false));
    for p in poses.iter().filter(|p| !p.used) {
        let x = p.index as i32;
        let Some(value) = (line.value)(p) else {
            continue;
        };
        match place(value, frame.y_range) {
            None => {}
            Some(Place::Inside(y)) if line.dashed => {
                chart.draw_series(std::iter::once(Circle::new(
                    (x, y),
                    r + 1,
                    color.stroke_width(2),
                )))?;
            }
            Some(Place::Inside(y)) => {
                chart.draw_series(std::iter::once(Cross::new(
                    (x, y),
                    r + 1,
                    color.stroke_width(3),
                )))?;
            }
            // Predicted values beyond the scale would only repeat the measured one's warning.
            Some(_) if line.dashed => {}
            Some(edge) => {
                let above = matches!(edge, Place::Above);
                let (y, dy, last_end, triangles) = if above {
                    (frame.y_range.1, 12, &mut labels.above_end_px, &above_px)
                } else {
                    (frame.y_range.0, -12, &mut labels.below_end_px, &below_px)
                };
                chart.draw_series(std::iter::once(
                    EmptyElement::at((x, y)) + TriangleMarker::new((0, dy), 8, color.filled()),
                ))?;
                // Beside the triangle, on the side with room, if clear of the last label.
                let text = (spec.format)(value);
                let width = text.chars().count() as f64 * f64::from(TICK_FONT) * 0.6;
                let at = px(x);
                let (start, h, dx) = if at + 12.0 + width <= frame.width_px {
                    (at + 12.0, HPos::Left, 12)
                } else {
                    (at - 12.0 - width, HPos::Right, -12)
                };
                let covers = |t: f64| t != at && t > start - 10.0 && t < start + width + 10.0;
                if last_end.is_some_and(|end| start < end + 6.0)
                    || triangles.iter().any(|&t| covers(t))
                {
                    continue;
                }
                *last_end = Some(start + width);
                let style = (FONT, TICK_FONT)
                    .into_font()
                    .color(&color)
                    .pos(Pos::new(h, VPos::Center));
                chart.draw_series(std::iter::once(
                    EmptyElement::at((x, y)) + Text::new(text, (dx, dy), style),
                ))?;
            }
        }
    }
    Ok(())
}

enum LegendItem {
    Dot(RGBColor, &'static str),
    Cross(RGBColor, &'static str),
    Triangle(RGBColor, &'static str),
    Solid(RGBColor, &'static str),
    Dashed(RGBColor, &'static str),
    /// The pale band behind set-aside poses.
    Band,
}

/// The key under a row of charts, in HTML so that it stays readable when the
/// charts are scaled down.
fn legend(items: &[LegendItem]) -> String {
    let css = |c: &RGBColor| format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2);
    let mut out = String::from("<ul class=\"legend\">");
    for item in items {
        let (swatch, label) = match item {
            LegendItem::Dot(c, l) => (
                format!(
                    "<span class=\"sw dot\" style=\"background:{}\"></span>",
                    css(c)
                ),
                *l,
            ),
            LegendItem::Cross(c, l) => (
                format!(
                    "<span class=\"sw glyph\" style=\"color:{}\">×</span>",
                    css(c)
                ),
                *l,
            ),
            LegendItem::Triangle(c, l) => (
                format!(
                    "<span class=\"sw glyph\" style=\"color:{}\">▲</span>",
                    css(c)
                ),
                *l,
            ),
            LegendItem::Solid(c, l) => (
                format!(
                    "<span class=\"sw line\" style=\"border-color:{}\"></span>",
                    css(c)
                ),
                *l,
            ),
            LegendItem::Dashed(c, l) => (
                format!(
                    "<span class=\"sw line dashed\" style=\"border-color:{}\"></span>",
                    css(c)
                ),
                *l,
            ),
            LegendItem::Band => (
                "<span class=\"sw band\"></span>".to_string(),
                "pose set aside",
            ),
        };
        let _ = write!(out, "<li>{swatch}{}</li>", escape(label));
    }
    out.push_str("</ul>\n");
    out
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
.verdict h1 { margin: 0 0 6px; font-size: clamp(2.4rem, 12vw, 4rem); letter-spacing: .05em; }
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
@media (max-width: 420px) { section, footer { padding: 12px; } dl.facts { grid-template-columns: 1fr; } dl.facts dd { margin-bottom: 6px; } }
"#;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::calibrate::{calibrate, CalibrationSettings};
    use crate::calib::solve::SolveError;
    use crate::recording::planes::read_planes;

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
    fn shows_the_verdict_reasons_and_four_charts() {
        let result = solved();
        assert!(!result.accepted());
        let html = render_html(&result, &provenance());
        assert!(html.contains("<h1>REJECTED</h1>"));
        for reason in &result.reasons {
            assert!(html.contains(&escape(reason)), "missing reason {reason}");
        }
        assert_eq!(count(&html, "<svg"), 4, "θ, e_d, a/b/c and d");
        assert_eq!(count(&html, "</svg>"), 4);
        // Pose 10 (the sign erratum) is in the table of poses set aside.
        assert!(html.contains("<tr><td>10</td><td class=\"text reason\">inconsistent"));
        assert!(html.contains("mean 0.238°") && html.contains("max 0.463°"));
        assert!(html.contains("-37.4347"));
    }

    #[test]
    fn an_accepted_result_says_so() {
        let mut result = solved();
        result.status = crate::output::ResultStatus::Accepted;
        result.reasons.clear();
        let html = render_html(&result, &provenance());
        assert!(html.contains("<h1>ACCEPTED</h1>"));
        assert!(!html.contains("REJECTED"));
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
        assert!(html.contains("<h1>REJECTED</h1>"));
        assert!(html.contains(&escape(&result.reasons[0])));
        assert!(html.contains("No parameters"));
        assert!(html.contains("No summary"));
        // Only the measured planes: θ, e_d and predictions need a result.
        assert_eq!(count(&html, "<svg"), 2);
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
        assert_eq!(count(&html, "<svg"), 4);
        assert!(html.contains("<tr><td>60</td><td class=\"text reason\">no ground in view</td><td>—</td><td>—</td></tr>"));
        result.poses.clear();
        let html = render_html(&result, &provenance());
        assert_eq!(count(&html, "<svg"), 4);
        assert!(html.contains("All 0 poses"));
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
        assert!(first.contains("REJECTED"));
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
