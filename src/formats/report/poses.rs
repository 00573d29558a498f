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

pub(super) fn residuals_section(page: &mut String, result: &ResultJson) {
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

pub(super) fn planes_section(page: &mut String, result: &ResultJson) {
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

pub(super) fn commanded_section(page: &mut String, result: &ResultJson) {
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

pub(super) fn set_aside_section(page: &mut String, result: &ResultJson) {
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

pub(super) fn poses_section(page: &mut String, result: &ResultJson) {
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
