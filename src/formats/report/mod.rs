//! The offline calibration report (`groundcal replay DIR --report OUTDIR`): one
//! HTML page that a person reads on a phone or a laptop.
//!
//! The page is self-contained so that it can be mailed, archived next to the
//! recording or opened on a robot with no network: inline CSS, no script, no
//! font or image from anywhere (the one picture, the depth pattern, is a data
//! URI), and a Content-Security-Policy that forbids loading anything. Charts
//! are drawn by `plotters` into SVG strings and inlined ([`chart`]).
//!
//! The HTML is written with maud's `html!`: the markup is checked when
//! groundcal is compiled, and every value put into it (reasons, paths,
//! numbers) is escaped by construction. Each section is a function that
//! returns its `Markup`, in the module of its group. maud rather than askama:
//! the sections are Rust functions that compose and share helpers
//! ([`html::param_name`]) without a template file or a struct per section.
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
mod mount;
mod pattern;
mod poses;
mod verdict;
mod weakness;

use maud::{html, Markup, PreEscaped, DOCTYPE};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use chart::{
    figure, gate_mark, legend, mean_max_marks, tilt_figure, ChartSpec, LegendItem, Line, Tilt,
    YAxis, COMPONENTS, GATE, INK, MAX, MEAN, SET_ASIDE, USED,
};
use html::{e_d, num, opt, param_name, signed};
use mount::*;
use poses::*;
use verdict::*;
use weakness::*;

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
    let pattern_too_large = result
        .gate_checks
        .iter()
        .find(|c| c.gate == "pattern_max_mm" && !c.passed)
        .map(|c| c.limit);
    let page = html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                meta name="viewport" content="width=device-width, initial-scale=1";
                meta http-equiv="Content-Security-Policy" content="default-src 'none'; style-src 'unsafe-inline'; img-src data:";
                title { "groundcal calibration: " (verdict) " (" (provenance.input) ")" }
                style { (PreEscaped(STYLE)) }
            }
            body {
                main {
                    header {
                        p.kicker { "groundcal calibration report" }
                        p.input { (provenance.input) }
                    }
                    (verdict_section(result, verdict))
                    (gates_section(result))
                    (parameters_section(result))
                    (setup_section(result, &provenance.input))
                    (summary_section(result))
                    (pattern::depth_pattern_section(result.depth_pattern.as_ref(), pattern_too_large))
                    (observability_section(result))
                    (correlations_section(result))
                    (accuracy_section(result))
                    (residuals_section(result))
                    (planes_section(result))
                    (commanded_section(result))
                    (set_aside_section(result))
                    (poses_section(result))
                    (provenance_section(provenance))
                }
            }
        }
    };
    let mut page = page.into_string();
    page.push('\n');
    page
}

fn provenance_section(provenance: &Provenance) -> Markup {
    html! {
        footer #provenance {
            h2 { "Provenance" }
            dl.facts {
                dt { "input" } dd { (provenance.input) }
                dt { "input BLAKE3" } dd { code.digest { (provenance.input_digest) } }
                dt { "groundcal" } dd { (provenance.groundcal_version) }
                dt { "created" } dd { (provenance.created) }
            }
        }
    }
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

    /// Text as the page escapes it.
    fn escape(text: &str) -> String {
        html! { (text) }.into_string()
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

    /// Rejected for a reason that is no gate (a time-of-flight camera):
    /// the page does not say a gate failed when the table shows none did.
    #[test]
    fn a_rejection_without_a_failed_gate_says_so() {
        let mut result = solved();
        for check in &mut result.gate_checks {
            check.passed = true;
        }
        result.reasons = vec!["a time-of-flight camera is not supported".into()];
        let html = render_html(&result, &provenance());
        assert!(html.contains("<h1>Failed its checks</h1>"));
        assert!(html.contains("passed its quality gates, but must not be used:"));
        assert!(!html.contains("did not pass its quality gates"));
        assert!(html.contains("All 7 gates passed."));
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
        assert!(html.contains("&lt;script&gt;alert('x')&lt;/script&gt; &amp; &quot;more&quot;"));
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
            disparity: None,
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
        assert!(html.contains("<strong>Weakest rotation:</strong> <span class=\"direction\">Rotation about the body's vertical axis Y (yaw of the sensor, α)</span>"), "{html}");
        let position = position_words(&o.translation_weakest_axis.unwrap());
        assert_eq!(position, "the sensor's sideways (p_z) position");
        assert!(html.contains("<strong>Weakest position:</strong> <span class=\"direction\">The sensor's sideways (p_z) position</span>"));
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
