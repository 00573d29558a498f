//! The mount with its σ, the setup it was found with, the change from the
//! nominal mount, and the summary of the poses.

use super::*;

pub(super) fn parameters_section(page: &mut String, result: &ResultJson) {
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
pub(super) fn depth_model_words(model: &DepthModel) -> String {
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
pub(super) fn six(values: [f64; 6]) -> [(&'static str, f64, &'static str); 6] {
    [
        ("α", values[0], "°"),
        ("β", values[1], "°"),
        ("γ", values[2], "°"),
        ("p<sub>x</sub>", values[3], "mm"),
        ("p<sub>y</sub>", values[4], "mm"),
        ("p<sub>z</sub>", values[5], "mm"),
    ]
}

pub(super) fn setup_section(page: &mut String, result: &ResultJson, input: &str) {
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

pub(super) fn summary_section(page: &mut String, result: &ResultJson) {
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
