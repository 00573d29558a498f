//! The report's charts: per-pose series drawn by `plotters` into SVG strings
//! that the page inlines, and the HTML keys under them.

use maud::{html, Markup, PreEscaped};
use plotters::coord::types::{RangedCoordf64, RangedCoordi32};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::formats::output::PoseJson;

/// Logical size of every chart. The page scales charts to the column width
/// (about 0.8× on a phone), so the fonts below are large enough to survive it.
const CHART_SIZE: (u32, u32) = (420, 300);
const FONT: &str = "sans-serif";
const TICK_FONT: u32 = 19;
const DESC_FONT: u32 = 20;

pub(super) const INK: RGBColor = RGBColor(0x30, 0x33, 0x36);
pub(super) const USED: RGBColor = RGBColor(0x1a, 0x5f, 0xb4);
pub(super) const SET_ASIDE: RGBColor = RGBColor(0xb3, 0x26, 0x1e);
pub(super) const MEAN: RGBColor = RGBColor(0x1b, 0x7f, 0x3b);
pub(super) const MAX: RGBColor = RGBColor(0x8e, 0x24, 0xaa);
/// A quality gate's limit.
pub(super) const GATE: RGBColor = RGBColor(0xd9, 0x30, 0x25);
/// a, b, c, d.
pub(super) const COMPONENTS: [RGBColor; 4] = [
    RGBColor(0x1a, 0x5f, 0xb4),
    RGBColor(0xe6, 0x61, 0x00),
    RGBColor(0x26, 0xa2, 0x69),
    RGBColor(0x61, 0x35, 0x83),
];

/// A gate further above the data than this many times their extent is left
/// out of the scale (and said so under the chart), so that it does not
/// flatten the poses into one line at the bottom.
const GATE_REACH: f64 = 2.5;

/// One per-pose series.
pub(super) struct Line {
    pub color: RGBColor,
    /// The colour of its marks at set-aside poses.
    pub aside_color: RGBColor,
    /// Predicted: dashed with hollow squares, rather than measured: solid
    /// with filled dots (a dot inside a square where the two agree).
    pub predicted: bool,
    /// None where the pose has no such value (no plane found).
    pub value: fn(&PoseJson) -> Option<f64>,
}

impl Line {
    /// A measured series of used poses, set-aside ones in red.
    pub fn measured(value: fn(&PoseJson) -> Option<f64>) -> Self {
        Self {
            color: USED,
            aside_color: SET_ASIDE,
            predicted: false,
            value,
        }
    }
}

/// A horizontal reference line (mean, max, a gate), labelled in the chart.
pub(super) struct Mark {
    pub label: String,
    pub value: f64,
    pub color: RGBColor,
    /// Where the label goes by preference; it moves when another label is
    /// there, so that two close lines do not overprint.
    pub label_left: bool,
    /// Solid (a gate) rather than dashed (mean, max).
    pub solid: bool,
    /// Left out of the scale when far beyond the data, saying this instead
    /// under the chart (when given).
    pub optional: Option<Option<String>>,
}

/// How the y axis is chosen.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum YAxis {
    /// From zero up (errors that are never negative).
    FromZero,
    /// Around the values.
    Fit,
    /// Symmetric about zero (signed residuals).
    Symmetric,
}

pub(super) struct ChartSpec<'a> {
    /// For screen readers.
    pub description: &'a str,
    pub y_desc: &'a str,
    pub y_axis: YAxis,
    pub lines: Vec<Line>,
    pub marks: Vec<Mark>,
    /// Labels of values beyond the scale.
    pub format: fn(f64) -> String,
}

/// The mean and maximum lines of the used poses.
pub(super) fn mean_max_marks(mean_max: Option<(f64, f64)>, format: fn(f64) -> String) -> Vec<Mark> {
    let Some((mean, max)) = mean_max else {
        return Vec::new();
    };
    vec![
        Mark {
            label: format!("mean {}", format(mean)),
            value: mean,
            color: MEAN,
            label_left: true,
            solid: false,
            optional: None,
        },
        Mark {
            label: format!("max {}", format(max)),
            value: max,
            color: MAX,
            label_left: false,
            solid: false,
            optional: None,
        },
    ]
}

/// The line of a quality gate's limit; `note` is said under the chart when
/// the limit lies too far above the data to be drawn.
pub(super) fn gate_mark(value: f64, label: String, note: Option<String>) -> Mark {
    Mark {
        label,
        value,
        color: GATE,
        label_left: true,
        solid: true,
        optional: Some(note),
    }
}

/// One chart with its caption; a chart that cannot be drawn says so instead.
pub(super) fn figure(title: Markup, caption: &str, spec: &ChartSpec, poses: &[PoseJson]) -> Markup {
    html! {
        figure {
            figcaption { strong { (title) } ": " (caption) }
            @match draw_chart(spec, poses) {
                Ok((svg, notes)) => {
                    (inline_svg(&svg, spec.description))
                    @for note in notes { p.note.chart-note { (note) } }
                }
                Err(e) => (cannot_draw(&e)),
            }
        }
    }
}

fn cannot_draw(e: &DrawError) -> Markup {
    html! { p.none { "The chart could not be drawn: " (e.to_string()) } }
}

/// A standalone SVG document made fit for inlining in HTML: the namespace is
/// implied there, and the size comes from the page (the viewBox keeps the
/// aspect ratio). plotters writes the SVG and escapes its texts (all of them
/// the report's own labels and numbers); the description is escaped here.
fn inline_svg(svg: &str, description: &str) -> Markup {
    let (w, h) = CHART_SIZE;
    let label = html! { (description) }.into_string();
    PreEscaped(
        svg.replacen(" xmlns=\"http://www.w3.org/2000/svg\"", "", 1)
            .replacen(
                &format!("<svg width=\"{w}\" height=\"{h}\""),
                &format!("<svg role=\"img\" aria-label=\"{label}\""),
                1,
            ),
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
/// not flatten the rest (it is drawn at the edge with its value instead); a
/// gate only when it is not far beyond them.
fn y_range(spec: &ChartSpec, poses: &[PoseJson]) -> (f64, f64) {
    let any_used = poses.iter().any(|p| p.used);
    let mut values: Vec<f64> = poses
        .iter()
        .filter(|p| p.used || !any_used)
        .flat_map(|p| spec.lines.iter().filter_map(move |l| (l.value)(p)))
        .chain(
            spec.marks
                .iter()
                .filter(|m| m.optional.is_none())
                .map(|m| m.value),
        )
        .filter(|v| v.is_finite())
        .collect();
    let extent = values.iter().fold(0.0, |m: f64, v| m.max(v.abs()));
    values.extend(
        spec.marks
            .iter()
            .filter(|m| m.optional.is_some() && gate_fits(m.value, extent))
            .map(|m| m.value),
    );
    if spec.y_axis == YAxis::FromZero {
        values.push(0.0);
    }
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !lo.is_finite() || !hi.is_finite() {
        return if spec.y_axis == YAxis::Symmetric {
            (-1.0, 1.0)
        } else {
            (0.0, 1.0)
        };
    }
    match spec.y_axis {
        YAxis::FromZero => {
            // Headroom above the highest line for its label.
            let top = if hi > 0.0 { hi * 1.3 } else { 1.0 };
            (0.0, top)
        }
        YAxis::Symmetric => {
            let m = lo.abs().max(hi.abs()) * 1.3;
            if m > 0.0 {
                (-m, m)
            } else {
                (-1.0, 1.0)
            }
        }
        YAxis::Fit => {
            let pad = ((hi - lo) * 0.1).max(1e-3);
            (lo - pad, hi + pad)
        }
    }
}

/// Whether a gate is near enough to the data's extent to be drawn.
fn gate_fits(value: f64, extent: f64) -> bool {
    value.is_finite() && value.abs() <= GATE_REACH * extent
}

/// Tick decimals that tell neighbouring ticks apart without noise.
fn decimals_for(span: f64) -> usize {
    let step = span / 5.0;
    if !(step.is_finite() && step > 0.0) {
        return 2;
    }
    (-step.log10()).ceil().clamp(0.0, 6.0) as usize
}

pub(super) type DrawError = Box<dyn std::error::Error>;

/// Draws one chart with plotters into a standalone SVG document; with it the
/// notes of gates left out of the scale.
fn draw_chart(spec: &ChartSpec, poses: &[PoseJson]) -> Result<(String, Vec<String>), DrawError> {
    let x_lo = poses.iter().map(|p| p.index as i32).min().unwrap_or(1) - 1;
    let x_hi = poses.iter().map(|p| p.index as i32).max().unwrap_or(1) + 1;
    let (y_lo, y_hi) = y_range(spec, poses);
    let decimals = decimals_for(y_hi - y_lo);
    let tick = || (FONT, TICK_FONT).into_font().color(&INK);
    let mut notes = Vec::new();

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

        if spec.y_axis == YAxis::Symmetric && y_lo < 0.0 && y_hi > 0.0 {
            chart.draw_series(LineSeries::new(
                vec![(x_lo, 0.0), (x_hi, 0.0)],
                INK.stroke_width(1),
            ))?;
        }

        // Reference lines, each label clear of the others: on its side above
        // the line, else on the other side, else below the line.
        let top_px = f64::from(chart.backend_coord(&(x_lo, y_hi)).1);
        let mut labels_px: Vec<(bool, f64)> = Vec::new();
        for mark in &spec.marks {
            if !mark.value.is_finite() {
                continue;
            }
            if mark.value > y_hi || mark.value < y_lo {
                if let Some(Some(note)) = &mark.optional {
                    notes.push(note.clone());
                }
                continue;
            }
            let line = vec![(x_lo, mark.value), (x_hi, mark.value)];
            if mark.solid {
                chart.draw_series(LineSeries::new(line, mark.color.stroke_width(2)))?;
            } else {
                chart.draw_series(DashedLineSeries::new(
                    line,
                    10,
                    6,
                    mark.color.stroke_width(2),
                ))?;
            }
            let y_px = f64::from(chart.backend_coord(&(x_lo, mark.value)).1);
            let height = f64::from(TICK_FONT) + 4.0;
            let centre = |below: bool| {
                if below {
                    y_px + height / 2.0
                } else {
                    y_px - height / 2.0
                }
            };
            let free = |left: bool, below: bool| {
                let c = centre(below);
                (below || c - height / 2.0 >= top_px)
                    && labels_px
                        .iter()
                        .all(|&(l, y)| l != left || (y - c).abs() >= height)
            };
            let preferred = mark.label_left;
            let (left, below) = [
                (preferred, false),
                (!preferred, false),
                (preferred, true),
                (!preferred, true),
            ]
            .into_iter()
            .find(|&(l, b)| free(l, b))
            .unwrap_or((preferred, false));
            labels_px.push((left, centre(below)));
            let (x, h, dx) = if left {
                (x_lo, HPos::Left, 6)
            } else {
                (x_hi, HPos::Right, -6)
            };
            let (v, dy) = if below {
                (VPos::Top, 4)
            } else {
                (VPos::Bottom, -4)
            };
            let style = (FONT, TICK_FONT)
                .into_font()
                .color(&mark.color)
                .pos(Pos::new(h, v));
            chart.draw_series(std::iter::once(
                EmptyElement::at((x, mark.value)) + Text::new(mark.label.clone(), (dx, dy), style),
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
            if line.predicted {
                chart.draw_series(DashedLineSeries::new(
                    used.clone(),
                    8,
                    5,
                    line.color.stroke_width(2),
                ))?;
                // A hollow square larger than the measured dot, so that a dot
                // inside a square reads "as predicted".
                let s = r as i32 + 3;
                chart.draw_series(used.iter().map(|&p| {
                    EmptyElement::at(p)
                        + Rectangle::new([(-s, -s), (s, s)], line.color.stroke_width(2))
                }))?;
            } else {
                chart.draw_series(LineSeries::new(used.clone(), line.color.stroke_width(2)))?;
                chart.draw_series(used.iter().map(|&p| Circle::new(p, r, line.color.filled())))?;
            }
            draw_set_aside(&mut chart, spec, line, poses, &frame, &mut labels)?;
        }
        root.present()?;
    }
    Ok((svg, notes))
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

/// Marks at set-aside poses: × (measured) or □ (predicted), or a triangle at
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
            Some(Place::Inside(y)) if line.predicted => {
                let s = r as i32 + 3;
                chart.draw_series(std::iter::once(
                    EmptyElement::at((x, y))
                        + Rectangle::new([(-s, -s), (s, s)], color.stroke_width(2)),
                ))?;
            }
            Some(Place::Inside(y)) => {
                chart.draw_series(std::iter::once(Cross::new(
                    (x, y),
                    r + 1,
                    color.stroke_width(3),
                )))?;
            }
            // Predicted values beyond the scale would only repeat the measured one's warning.
            Some(_) if line.predicted => {}
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

pub(super) enum LegendItem {
    Dot(RGBColor, &'static str),
    Cross(RGBColor, &'static str),
    Triangle(RGBColor, &'static str),
    Solid(RGBColor, &'static str),
    Dashed(RGBColor, &'static str),
    /// A measured series: a solid line through filled dots.
    Measured(RGBColor, &'static str),
    /// A predicted series: a dashed line through hollow squares.
    Predicted(RGBColor, &'static str),
    /// The pale band behind set-aside poses.
    Band,
}

/// The key under a row of charts, in HTML so that it stays readable when the
/// charts are scaled down.
pub(super) fn legend(items: &[LegendItem]) -> Markup {
    let css = |c: &RGBColor| format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2);
    html! {
        ul.legend {
            @for item in items {
                li {
                    @match item {
                        LegendItem::Dot(c, l) => { span.sw.dot style={ "background:" (css(c)) } {} (l) },
                        LegendItem::Cross(c, l) => { span.sw.glyph style={ "color:" (css(c)) } { "×" } (l) },
                        LegendItem::Triangle(c, l) => { span.sw.glyph style={ "color:" (css(c)) } { "▲" } (l) },
                        LegendItem::Solid(c, l) => { span.sw.line style={ "border-color:" (css(c)) } {} (l) },
                        LegendItem::Dashed(c, l) => { span.sw.line.dashed style={ "border-color:" (css(c)) } {} (l) },
                        LegendItem::Measured(c, l) => {
                            span.sw.series style={ "border-color:" (css(c)) } { i.mk.dot style={ "background:" (css(c)) } {} }
                            (l)
                        },
                        LegendItem::Predicted(c, l) => {
                            span.sw.series.dashed style={ "border-color:" (css(c)) } { i.mk.square style={ "border-color:" (css(c)) } {} }
                            (l)
                        },
                        LegendItem::Band => { span.sw.band {} "pose set aside" },
                    }
                }
            }
        }
    }
}

/// A pose's commanded tilt, for the chart of the schedule's tilts.
pub(super) struct Tilt {
    /// γ′, about the body's forward axis.
    pub roll_deg: f64,
    /// β′, about the body's sideways axis.
    pub pitch_deg: f64,
    pub used: bool,
}

/// The commanded roll against pitch of every pose: how the schedule tilts
/// the body (a cloud along one line cannot tell some directions).
pub(super) fn tilt_figure(title: &str, caption: &str, tilts: &[Tilt]) -> Markup {
    html! {
        figure {
            figcaption { strong { (title) } ": " (caption) }
            @match draw_tilts(tilts) {
                Ok(svg) => (inline_svg(&svg, "commanded roll against pitch per pose")),
                Err(e) => (cannot_draw(&e)),
            }
        }
    }
}

fn draw_tilts(tilts: &[Tilt]) -> Result<String, DrawError> {
    let extent = tilts
        .iter()
        .flat_map(|t| [t.roll_deg, t.pitch_deg])
        .filter(|v| v.is_finite())
        .fold(0.0, |m: f64, v| m.max(v.abs()));
    let m = if extent > 0.0 { extent * 1.15 } else { 1.0 };
    let tick = || (FONT, TICK_FONT).into_font().color(&INK);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, CHART_SIZE).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(14)
            .margin_right(20)
            .x_label_area_size(58)
            .y_label_area_size(72)
            .build_cartesian_2d(-m..m, -m..m)?;
        let formatter = |v: &f64| format!("{v:.0}");
        chart
            .configure_mesh()
            .x_desc("roll γ′ (°)")
            .y_desc("pitch β′ (°)")
            .label_style(tick())
            .axis_desc_style((FONT, DESC_FONT).into_font().color(&INK))
            .axis_style(INK.stroke_width(1))
            .bold_line_style(RGBColor(0xe3, 0xe5, 0xe8).stroke_width(1))
            .light_line_style(TRANSPARENT)
            .x_labels(7)
            .y_labels(6)
            .x_label_formatter(&formatter)
            .y_label_formatter(&formatter)
            .draw()?;
        for axis in [vec![(-m, 0.0), (m, 0.0)], vec![(0.0, -m), (0.0, m)]] {
            chart.draw_series(LineSeries::new(axis, INK.mix(0.5).stroke_width(1)))?;
        }
        let finite = |t: &&Tilt| t.roll_deg.is_finite() && t.pitch_deg.is_finite();
        chart.draw_series(
            tilts
                .iter()
                .filter(finite)
                .filter(|t| t.used)
                .map(|t| Circle::new((t.roll_deg, t.pitch_deg), 5, USED.filled())),
        )?;
        chart.draw_series(
            tilts
                .iter()
                .filter(finite)
                .filter(|t| !t.used)
                .map(|t| Cross::new((t.roll_deg, t.pitch_deg), 6, SET_ASIDE.stroke_width(3))),
        )?;
        root.present()?;
    }
    Ok(svg)
}
