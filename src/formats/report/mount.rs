//! The mount with its σ, the setup it was found with, the change from the
//! nominal mount, and the summary of the poses.

use super::*;
use crate::formats::output::SigmaJson;

pub(super) fn parameters_section(result: &ResultJson) -> Markup {
    let Some(m) = &result.robot_from_sensor else {
        return html! {
            section #parameters {
                h2 { "Sensor on the body: " code { "robot_from_sensor" } }
                p.none { "No parameters: the calibration could not be solved (see the reasons above)." }
            }
        };
    };
    let sigmas = result.sigma.as_ref().map(SigmaJson::values);
    let scale = result.depth_scale.map(|scale| {
        let estimated = result.depth_scale_estimated.unwrap_or(false);
        let sigma = result
            .sigma
            .as_ref()
            .and_then(|s| s.depth_scale)
            .filter(|_| estimated);
        (scale, sigma)
    });
    let quaternion = m.quaternion_xyzw.map(|q| {
        format!(
            " Quaternion (x, y, z, w): {}, {}, {}, {}",
            num(q[0], 6),
            num(q[1], 6),
            num(q[2], 6),
            num(q[3], 6)
        )
    });
    html! {
        section #parameters {
            h2 { "Sensor on the body: " code { "robot_from_sensor" } }
            div.scroll { table.params {
                thead { tr { th.text { "parameter" } th { "value" } th { "σ" } th.text { "unit" } } }
                tbody {
                    @for (k, (value, unit)) in m.values().into_iter().zip(UNITS).enumerate() {
                        tr {
                            th.text { (param_name(k)) }
                            td { (num(value, 4)) }
                            td { (sigmas.map_or_else(|| "—".to_string(), |s| num(s[k], 4))) }
                            td.text { (unit) }
                        }
                    }
                    @if let Some((scale, sigma)) = scale {
                        tr {
                            th.text { "s" }
                            td { (num(scale, 4)) }
                            td { (opt(sigma, 5)) }
                            td.text { "×" }
                        }
                    }
                }
            } }
            p.note { "X-Y-Z fixed angles (γ about X, then β about Z, then α about Y) and the sensor's position in the body frame; σ is one standard deviation. The depth scale s: the sensor's depth reads s × the truth; estimated with the mount when the body's heights observe it (σ “—”: not estimated, see the notes)." }
            @if let Some(tilt) = result.kinect_tilt_deg {
                p.tilt { "Valid with the Kinect's motor tilted " (num(tilt, 1)) "°." }
            }
            details {
                summary { "Matrix and quaternion" }
                div.scroll { table.matrix { tbody {
                    @for row in &m.matrix { tr { @for v in row { td { (num(*v, 6)) } } } }
                } } }
                p { "Translation in millimetres." (quaternion.unwrap_or_default()) }
            }
        }
    }
}

/// The units of the six parameters, in their order.
const UNITS: [&str; 6] = ["°", "°", "°", "mm", "mm", "mm"];

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

pub(super) fn setup_section(result: &ResultJson, input: &str) -> Markup {
    let setup = result.setup.clone().unwrap_or_default();
    let mut schedule = Vec::new();
    if let Some(name) = &setup.schedule {
        schedule.push(format!("“{name}”"));
    }
    let poses = setup.poses.unwrap_or(result.poses.len());
    schedule.push(format!("{poses} pose{}", if poses == 1 { "" } else { "s" }));
    if let Some(frames) = setup.frames_per_pose {
        schedule.push(format!("{frames} depth frames per pose"));
    }
    let tilt = result.kinect_tilt_deg.map_or_else(
        || "not known".to_string(),
        |t| {
            format!(
                "{}° (the Kinect's motor; the calibration holds for this tilt)",
                num(t, 1)
            )
        },
    );
    let nominal = setup.nominal_mount;
    let nominal_words = nominal.as_ref().map_or_else(
        || "not known".to_string(),
        |n| {
            format!(
                "α {}°, β {}°, γ {}°; p {}, {}, {} mm ({}; within ±{}°, ±{} mm)",
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
            )
        },
    );
    let gates_from = setup.gates_from.as_deref().map(|from| match from {
        "config" => "those of the configuration given (--config)",
        "recording" => "those of the recording's live run",
        "built-in" => "the built-in ones (the recording stores none)",
        other => other,
    });
    html! {
        section #setup {
            h2 { "Setup" }
            dl.facts.setup {
                dt { "input" } dd { (input) }
                @if let Some(robot) = &setup.robot { dt { "robot" } dd { (robot) } }
                dt { (if result.setup.is_some() { "schedule" } else { "poses" }) }
                dd { (schedule.join(", ")) }
                @if let Some(model) = &setup.depth_model {
                    dt { "depth model" } dd { (depth_model_words(model)) }
                }
                @if let Some(k) = &setup.intrinsics {
                    dt { "intrinsics" }
                    dd {
                        "f" sub { "x" } " " (num(k.fx, 1)) ", f" sub { "y" } " " (num(k.fy, 1))
                        ", c" sub { "x" } " " (num(k.cx, 1)) ", c" sub { "y" } " " (num(k.cy, 1))
                        " px; " (k.width) "×" (k.height)
                    }
                }
                dt { "sensor tilt" } dd { (tilt) }
                dt { "nominal mount" } dd { (nominal_words) }
                @if let Some(words) = gates_from { dt { "quality gates" } dd { (words) } }
            }
            @if result.setup.is_none() {
                p.none { "This input (ground planes only) does not say how it was recorded: no schedule, depth model, commanded poses or nominal mount." }
            }
            h3 #nominal-change { "Change from the nominal mount" }
            @match (&nominal, &result.robot_from_sensor) {
                (None, _) if result.setup.is_some() => p.none {
                    "No nominal mount is known for this recording, so there is nothing to compare with ("
                    code { "groundcal replay --nominal-mount a,b,g,x,y,z" } " gives one)."
                },
                (None, _) => p.none { "No nominal mount is known for this input, so there is nothing to compare with." },
                (Some(_), None) => p.none { "No result to compare with the nominal mount." },
                (Some(n), Some(m)) => {
                    @let nominal = [n.alpha_deg, n.beta_deg, n.gamma_deg, n.px_mm, n.py_mm, n.pz_mm];
                    div.scroll { table.nominal {
                        thead { tr { th.text { "parameter" } th { "nominal" } th { "result" } th { "change" } } }
                        tbody {
                            @for (k, ((result_value, unit), nominal_value)) in m.values().into_iter().zip(UNITS).zip(nominal).enumerate() {
                                @let decimals = if unit == "°" { 2 } else { 1 };
                                tr {
                                    th.text { (param_name(k)) " " span.unit { "(" (unit) ")" } }
                                    td { (num(nominal_value, decimals)) }
                                    td { (num(result_value, decimals)) }
                                    td.delta { (signed(result_value - nominal_value, decimals)) }
                                }
                            }
                        }
                    } }
                    p.note {
                        "Change = result − nominal. The nominal mount only told the ground search where to look (within ±"
                        (num(n.tolerance_deg, 0)) "° and ±" (num(n.tolerance_mm, 0))
                        " mm); a large change means the sensor is not mounted as drawn, or the nominal is out of date."
                    }
                }
            }
        }
    }
}

pub(super) fn summary_section(result: &ResultJson) -> Markup {
    let Some(s) = &result.summary else {
        let aside = result.poses.iter().filter(|p| !p.used).count();
        return html! {
            section #summary {
                h2 { "Summary" }
                p.none {
                    "No summary: the calibration could not be solved. " (result.poses.len())
                    " poses in the input, " (aside) " set aside."
                }
            }
        };
    };
    html! {
        section #summary {
            h2 { "Summary" }
            dl.facts {
                dt { "poses used" } dd { (s.poses_used) " of " (s.poses_total) }
                dt { "θ, mean / max" } dd { (num(s.theta_deg_mean, 3)) "° / " (num(s.theta_deg_max, 3)) "°" }
                dt { (e_d()) ", mean / max" } dd { (num(s.e_d_mm_mean, 2)) " mm / " (num(s.e_d_mm_max, 2)) " mm" }
            }
            p.note { "θ is the angle between the measured ground and the one the result predicts, " (e_d()) " the difference of their distances from the sensor (paper §5.2), over the poses used." }
        }
    }
}
