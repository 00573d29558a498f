//! The poses: the signed residuals, the measured and predicted ground, the
//! commanded body poses, the poses set aside and every pose.

use super::*;

/// One pose's signed differences between the measured and the predicted
/// ground: d in mm, and the measured normal's tilt from the predicted one
/// about the body's forward and sideways directions along the ground, in
/// degrees (their root sum of squares is θ).
pub(super) struct Residual {
    pub(super) index: u32,
    pub(super) used: bool,
    pub(super) d_mm: f64,
    pub(super) about_forward_deg: f64,
    pub(super) about_sideways_deg: f64,
}

/// Every pose with both planes, in the body frame of the result.
pub(super) fn residuals(result: &ResultJson) -> Vec<Residual> {
    let Some(m) = &result.robot_from_sensor else {
        return Vec::new();
    };
    let body_from_sensor = nalgebra::Matrix3::from_fn(|i, j| m.matrix[i][j]);
    result
        .poses
        .iter()
        .filter_map(|p| {
            let (measured, predicted) = (p.plane?, p.predicted_plane?);
            let n_m = body_from_sensor * Vector3::new(measured.a, measured.b, measured.c);
            let n_p = body_from_sensor * Vector3::new(predicted.a, predicted.b, predicted.c);
            // The small rotation that takes the predicted normal to the
            // measured one: their cross product (its length is sin θ), on
            // the body's forward axis laid along the predicted ground, and
            // on the sideways one (forward × up, as Z = X × Y).
            let omega = n_p.cross(&n_m);
            let forward = (Vector3::x() - n_p * n_p.x).normalize();
            let sideways = forward.cross(&n_p);
            let angle = |s: f64| s.clamp(-1.0, 1.0).asin().to_degrees();
            Some(Residual {
                index: p.index,
                used: p.used,
                d_mm: (measured.d_m - predicted.d_m) * 1e3,
                about_forward_deg: angle(omega.dot(&forward)),
                about_sideways_deg: angle(omega.dot(&sideways)),
            })
        })
        .collect()
}

pub(super) fn residuals_section(result: &ResultJson) -> Markup {
    let rows = residuals(result);
    if rows.is_empty() {
        return html! {
            section #residuals {
                h2 { "Signed residuals per pose" }
                p.none { "No residuals: without a result there is no predicted ground to compare with." }
            }
        };
    }
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
    let chart = figure(
        html! { "Δd per pose" },
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
    html! {
        section #residuals {
            h2 { "Signed residuals per pose" }
            p.note { "Measured minus predicted: a pattern (all of one sign, or growing with the tilt) points at a bias the unsigned θ and " (e_d()) " hide." }
            div.charts {
                (chart)
                div.scroll { table.residuals {
                    thead { tr { th { "pose" } th { "Δd (mm)" } th { "tilt, forward axis (°)" } th { "tilt, sideways axis (°)" } } }
                    tbody {
                        @for r in &rows {
                            tr class=[(!r.used).then_some("unused")] {
                                td { (r.index) }
                                td.dd { (signed(r.d_mm, 2)) }
                                td.tx { (signed(r.about_forward_deg, 3)) }
                                td.tz { (signed(r.about_sideways_deg, 3)) }
                            }
                        }
                    }
                } }
            }
            (legend(&[
                LegendItem::Dot(USED, "used pose"),
                LegendItem::Cross(SET_ASIDE, "set aside"),
                LegendItem::Band,
                LegendItem::Solid(GATE, "e_d's gate, either sign"),
            ]))
            p.note { "Δd > 0: the ground was measured farther from the sensor than predicted. The tilts turn the predicted ground into the measured one, about the body's forward and sideways axes laid along the ground (right-handed: a positive tilt about the forward axis lowers the ground on the right); together they make θ. The shaded rows are poses set aside." }
        }
    }
}

pub(super) fn planes_section(result: &ResultJson) -> Markup {
    let solved = result.robot_from_sensor.is_some();
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
    let normal = figure(
        html! { "Normal a, b, c" },
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
    let distance = figure(
        html! { "Distance d" },
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
    html! {
        section #planes {
            @if solved {
                h2 { "Measured and predicted ground" }
                p.note { "The ground plane a·x + b·y + c·z + d = 0 in the sensor frame at each pose, as measured (filled dots, solid lines) and as the result predicts it from the body pose (hollow squares, dashed lines; a dot inside its square is a pose where the two agree) (the paper's Figs. 14 and 15)." }
            } @else {
                h2 { "Measured ground" }
                p.note { "The ground plane a·x + b·y + c·z + d = 0 in the sensor frame at each pose, as measured (the paper's Figs. 14 and 15 without the prediction, for want of a result)." }
            }
            div.charts { (normal) (distance) }
            (legend(&items))
        }
    }
}

pub(super) fn commanded_section(result: &ResultJson) -> Markup {
    let poses: Vec<(&PoseJson, crate::calib::geometry::PoseDegMm)> = result
        .poses
        .iter()
        .filter_map(|p| Some((p, p.commanded?)))
        .collect();
    if poses.is_empty() {
        return html! {
            section #commanded {
                h2 { "Commanded body poses" }
                p.none { "This input has no commanded poses (ground planes only): the body's attitudes are not known here." }
            }
        };
    }
    let tilts: Vec<Tilt> = poses
        .iter()
        .map(|(p, c)| Tilt {
            roll_deg: c.gamma_deg,
            pitch_deg: c.beta_deg,
            used: p.used,
        })
        .collect();
    // Shifts of the body only when some pose has one.
    let shifted = poses
        .iter()
        .any(|(_, c)| c.px_mm.abs() > 1e-9 || c.pz_mm.abs() > 1e-9);
    html! {
        section #commanded {
            h2 { "Commanded body poses" }
            p.note { "What the body was asked for at each pose (the solve uses the real pose from the feet, not these): roll γ′ about its forward axis, pitch β′ about its sideways axis, yaw α′ about the vertical, and its height." }
            div.charts {
                (tilt_figure(
                    "Tilts of the schedule",
                    "the commanded roll against pitch of every pose; a cloud along one line cannot tell every direction",
                    &tilts,
                ))
                div.scroll { table.commanded {
                    thead { tr {
                        th { "pose" } th { "roll γ′ (°)" } th { "pitch β′ (°)" } th { "yaw α′ (°)" } th { "height (mm)" }
                        @if shifted { th { "x′ (mm)" } th { "z′ (mm)" } }
                    } }
                    tbody {
                        @for (p, c) in &poses {
                            tr class=[(!p.used).then_some("unused")] {
                                td { (p.index) }
                                td { (num(c.gamma_deg, 1)) }
                                td { (num(c.beta_deg, 1)) }
                                td { (num(c.alpha_deg, 1)) }
                                td { (num(c.py_mm, 0)) }
                                @if shifted { td { (num(c.px_mm, 0)) } td { (num(c.pz_mm, 0)) } }
                            }
                        }
                    }
                } }
            }
            (legend(&[
                LegendItem::Dot(USED, "used pose"),
                LegendItem::Cross(SET_ASIDE, "set aside (shaded rows)"),
            ]))
        }
    }
}

pub(super) fn set_aside_section(result: &ResultJson) -> Markup {
    let aside: Vec<&PoseJson> = result.poses.iter().filter(|p| !p.used).collect();
    // Poses kept with a remark: a slipped foot left out of the body pose.
    let noted: Vec<&PoseJson> = result.poses.iter().filter(|p| p.note.is_some()).collect();
    html! {
        section #set-aside {
            h2 { "Poses set aside" }
            @if aside.is_empty() {
                p { "None: every pose was used." }
            } @else {
                div.scroll { table.aside {
                    thead { tr { th { "pose" } th.text { "why" } th { "θ (°)" } th { (e_d()) " (mm)" } } }
                    tbody {
                        @for p in aside {
                            tr {
                                td { (p.index) }
                                td.text.reason { (p.reason.as_deref().unwrap_or("no reason given")) }
                                td { (opt(p.theta_deg, 3)) }
                                td { (opt(p.e_d_mm, 2)) }
                            }
                        }
                    }
                } }
            }
            @if !noted.is_empty() {
                h3 #noted { "Poses kept with a note" }
                div.scroll { table.aside {
                    thead { tr { th { "pose" } th.text { "note" } } }
                    tbody {
                        @for p in noted {
                            tr { td { (p.index) } td.text.reason { (p.note.as_deref().unwrap_or_default()) } }
                        }
                    }
                } }
            }
        }
    }
}

pub(super) fn poses_section(result: &ResultJson) -> Markup {
    html! {
        section #poses { details {
            summary { "All " (result.poses.len()) " poses" }
            div.scroll { table.poses {
                thead { tr {
                    th { "pose" } th { "used" } th { "θ (°)" } th { (e_d()) " (mm)" } th { "inliers" }
                    th { "a" } th { "b" } th { "c" } th { "d (m)" }
                    th { "predicted a" } th { "b" } th { "c" } th { "d (m)" }
                } }
                tbody {
                    @for p in &result.poses {
                        tr class=[(!p.used).then_some("unused")] {
                            td { (p.index) }
                            td { (if p.used { "yes" } else { "no" }) }
                            td { (opt(p.theta_deg, 3)) }
                            td { (opt(p.e_d_mm, 2)) }
                            td { (p.inliers.map_or_else(|| "—".to_string(), |n| n.to_string())) }
                            @for plane in [p.plane, p.predicted_plane] {
                                @let values = plane.map(|q| [q.a, q.b, q.c, q.d_m]);
                                @for k in 0..4 { td { (opt(values.map(|v| v[k]), 4)) } }
                            }
                        }
                    }
                }
            } }
        } }
    }
}
