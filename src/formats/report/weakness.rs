//! What the schedule could tell: the weakest directions in words, the
//! correlations of the six parameters as a heat map, and θ and e_d per pose
//! against their gates.

use super::*;

pub(super) fn observability_section(result: &ResultJson) -> Markup {
    let Some(o) = &result.observability else {
        return html! {
            section #observability {
                h2 { "What the schedule could tell" }
                p.none { "Nothing was solved, so nothing was observed." }
            }
        };
    };
    let needed = result
        .gate_checks
        .iter()
        .find(|c| c.gate == "observable")
        .map_or_else(
            || crate::calib::solve::SolveSettings::default().min_spread,
            |c| c.limit,
        );
    let directions = [
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
    ];
    let list = |v: &[f64; 3]| v.map(|x| num(x, 3)).join(", ");
    html! {
        section #observability {
            h2 { "What the schedule could tell" }
            ul.weakest {
                @for (kind, singular, words) in directions {
                    @let told = singular >= needed;
                    @let what = words.map_or_else(
                        || format!("the weakest {kind} direction"),
                        |w| {
                            // Capitalised as the start of a sentence.
                            let mut chars = w.chars();
                            chars.next().map_or_else(String::new, |first| {
                                first.to_uppercase().collect::<String>() + chars.as_str()
                            })
                        },
                    );
                    li class=(if told { "told" } else { "untold" }) data-kind=(kind) {
                        strong { "Weakest " (kind) ":" } " " span.direction { (what) } ". "
                        @if told {
                            "The body's tilts spread it by " (num(spread_deg(singular), 1))
                            "° (RMS); at least " (num(spread_deg(needed), 1)) "° is needed."
                        } @else {
                            "The schedule cannot tell it: the body's tilts spread it by only "
                            (num(spread_deg(singular), 1)) "° (RMS), at least "
                            (num(spread_deg(needed), 1))
                            "° is needed. Add poses that tilt the body about other axes."
                        }
                    }
                }
            }
            p.note { "The ground tells a rotation of the sensor or a shift of its position only as far as the body's tilts turn the ground's direction seen along it: the more the schedule tilts the body, and about more axes, the better every direction is pinned down. The other directions are pinned down better than these two." }
            details {
                summary { "Singular values" }
                dl.facts {
                    dt { "rotation" } dd { (list(&o.rotation_singular_values)) }
                    dt { "translation" } dd { (list(&o.translation_singular_values)) }
                }
                p.note { "Of the solve's Jacobian per observation; each is about the sine of the tilts' RMS spread in its direction, and a value near 0 means the schedule cannot tell that direction." }
            }
        }
    }
}

/// The heat map's colour of a correlation: paler for |r| near 0, darker
/// blue for |r| near 1; the text white on the dark ones.
pub(super) fn heat_colour(r: f64) -> (String, &'static str) {
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

pub(super) fn correlations_section(result: &ResultJson) -> Markup {
    let Some(r) = &result.correlations else {
        return html! {
            section #correlations {
                h2 { "Correlations of the six parameters" }
                p.none { "No correlations: nothing was solved." }
            }
        };
    };
    const PLAIN: [&str; 6] = ["α", "β", "γ", "p_x", "p_y", "p_z"];
    // The strongest pair, in words.
    let strongest = (0..6)
        .flat_map(|i| (i + 1..6).map(move |j| (i, j)))
        .filter(|&(i, j)| r[i][j].is_finite())
        .max_by(|&(a, b), &(c, d)| r[a][b].abs().total_cmp(&r[c][d].abs()));
    let decoupled = (0..3).all(|i| (3..6).all(|j| r[i][j].abs() < 1e-9));
    html! {
        section #correlations {
            h2 { "Correlations of the six parameters" }
            div.scroll { table.heat {
                thead { tr { th {} @for k in 0..6 { th scope="col" { (param_name(k)) } } } }
                tbody {
                    @for (i, row) in r.iter().enumerate() {
                        tr {
                            th scope="row" { (param_name(i)) }
                            @for (j, &value) in row.iter().enumerate() {
                                @let (background, ink) = if i == j {
                                    ("#eceff1".to_string(), "#5f6368")
                                } else {
                                    heat_colour(value)
                                };
                                @let text = if i == j && value.is_finite() { "1".to_string() } else { num(value, 2) };
                                td class=(if i == j { "cell diagonal" } else { "cell" })
                                    style={ "background:" (background) ";color:" (ink) }
                                    title={ (PLAIN[i]) " and " (PLAIN[j]) ": r = " (num(value, 3)) } { (text) }
                            }
                        }
                    }
                }
            } }
            @if let Some((i, j)) = strongest {
                @let v = r[i][j];
                @let words = if v.abs() >= 0.9 {
                    "the schedule hardly tells them apart: an error in one is mostly an error in the other"
                } else if v.abs() >= 0.6 {
                    "their errors move together noticeably"
                } else {
                    "no pair of parameters is strongly tied"
                };
                p.strongest { "Strongest: " (param_name(i)) " and " (param_name(j)) ", r = " (num(v, 2)) ": " (words) "." }
            }
            p.note {
                span.heat-key aria-hidden="true" {}
                " |r| from 0 (pale) to 1 (dark): how much the errors of two parameters move together (the sign says whether in the same or opposite directions)."
                @if decoupled {
                    " The angles come from the ground's direction and the position from its distance, so the two groups do not correlate (the zeros)."
                }
            }
        }
    }
}

pub(super) fn accuracy_section(result: &ResultJson) -> Markup {
    if result.robot_from_sensor.is_none() {
        return html! {
            section #accuracy {
                h2 { "Accuracy per pose" }
                p.none { "No θ or " (e_d()) ": without a result there is no predicted ground to compare with." }
            }
        };
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
    let theta = figure(
        html! { "θ per pose" },
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
    let e_d_chart = figure(
        html! { (e_d()) " per pose" },
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
    html! {
        section #accuracy {
            h2 { "Accuracy per pose" }
            div.charts { (theta) (e_d_chart) }
            (legend(&items))
        }
    }
}
