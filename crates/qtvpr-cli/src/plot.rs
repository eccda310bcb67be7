//! `evaluate --plot DIR`: SVG figures drawn with plotters' SVG backend (no system
//! fonts needed: the SVG names a generic sans-serif font and the viewer renders it).
//!
//! - `thresholds.svg` (the paper's Fig. 3): each method's per-segment threshold
//!   against the oracle's along the traverse, and underneath, one strip per method with
//!   the TP (up, green), FP (up, red) and FN (down, grey) of every segment.
//! - `precision_recall.svg` (Fig. 4, right): the precision-recall curve of the
//!   deployment set under one global threshold, with each method's operating point
//!   (its per-segment decisions pooled over the deployment set).
//! - `ablation_k.svg` / `ablation_cal.svg` (Fig. 5): %Segs and AvgR against k or the
//!   calibration size, when `--k` or the calibration size is given a list.
//!
//! Legends sit outside the plotting areas, so that they cover no data, and every
//! swatch is drawn as its series is (dashed for a dashed line, the marker's shape).
//! Every file is written atomically, like `--output`.

use std::fmt::Debug;
use std::path::Path;

use anyhow::{Context as _, Result, anyhow};
use std::ops::Range;

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::{CoordTranslate, Shift};
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use qtvpr::Method;
use qtvpr::evaluate::MethodResult;

use crate::embedded;
use crate::output::emit;
use crate::summary::{Run, RunContext, ablation_setting, fmt_num};

const FONT: &str = "sans-serif";

type Area<'b> = DrawingArea<SVGBackend<'b>, Shift>;
const TP_COLOUR: RGBColor = RGBColor(77, 175, 74);
const FP_COLOUR: RGBColor = RGBColor(228, 26, 28);
const FN_COLOUR: RGBColor = RGBColor(170, 170, 170);
const NOTE_COLOUR: RGBColor = RGBColor(90, 90, 90);
/// Dash and gap of the oracle's threshold line, in pixels (and of its legend swatch).
const ORACLE_DASH: (u32, u32) = (7, 4);
/// Dash and gap of the target-precision line of the precision-recall figure.
const TARGET_DASH: (u32, u32) = (6, 5);

/// The colour of a method, the same in every figure.
fn colour(m: Method) -> RGBColor {
    match m {
        Method::QuantileTransfer => RGBColor(31, 119, 180),
        Method::QuantileTransferOnline => RGBColor(23, 190, 207),
        Method::QuantileTransferMargin => RGBColor(44, 160, 44),
        Method::Margin => RGBColor(188, 189, 34),
        Method::Schubert => RGBColor(255, 127, 14),
        Method::SchubertCalibrated => RGBColor(148, 103, 189),
        Method::CalibrationThreshold => RGBColor(140, 86, 75),
        Method::Oracle => BLACK,
    }
}

/// A marker shape. Each method has its own (and so does each series of an ablation),
/// so that series drawn at the same place stay distinguishable in print.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Shape {
    Circle,
    Triangle,
    Square,
    Diamond,
    Cross,
    InvertedTriangle,
    Plus,
    Hexagon,
}

/// Shapes in the order series get them.
const SHAPES: [Shape; 8] = [
    Shape::Circle,
    Shape::Triangle,
    Shape::Square,
    Shape::Diamond,
    Shape::Cross,
    Shape::InvertedTriangle,
    Shape::Plus,
    Shape::Hexagon,
];

/// The marker of a method, the same in every figure.
fn shape(m: Method) -> Shape {
    match m {
        Method::QuantileTransfer => Shape::Circle,
        Method::Schubert => Shape::Triangle,
        Method::SchubertCalibrated => Shape::Square,
        Method::CalibrationThreshold => Shape::Diamond,
        Method::Oracle => Shape::Cross,
        Method::QuantileTransferOnline => Shape::InvertedTriangle,
        Method::QuantileTransferMargin => Shape::Hexagon,
        Method::Margin => Shape::Plus,
    }
}

/// Draw a marker of `size` pixels (its half-width) centred on `at`, in any coordinates.
fn draw_marker<X: CoordTranslate>(
    area: &DrawingArea<SVGBackend<'_>, X>,
    shape: Shape,
    at: X::From,
    size: i32,
    c: RGBColor,
) -> Result<()>
where
    X::From: Clone,
{
    let at = EmptyElement::at(at);
    let (r, h) = (size, size * 3 / 4);
    match shape {
        Shape::Circle => area.draw(&(at + Circle::new((0, 0), r, c.filled()))),
        Shape::Triangle => area.draw(&(at + Polygon::new(vec![(0, -r), (r, h), (-r, h)], c.filled()))),
        Shape::InvertedTriangle => area.draw(&(at + Polygon::new(vec![(0, r), (r, -h), (-r, -h)], c.filled()))),
        Shape::Square => area.draw(&(at + Rectangle::new([(-h, -h), (h, h)], c.filled()))),
        Shape::Diamond => area.draw(&(at + Polygon::new(vec![(0, -r), (r, 0), (0, r), (-r, 0)], c.filled()))),
        Shape::Cross => area.draw(
            &(at + PathElement::new(vec![(-h, -h), (h, h)], c.stroke_width(3))
                + PathElement::new(vec![(-h, h), (h, -h)], c.stroke_width(3))),
        ),
        Shape::Plus => area.draw(
            &(at + PathElement::new(vec![(-r, 0), (r, 0)], c.stroke_width(3))
                + PathElement::new(vec![(0, -r), (0, r)], c.stroke_width(3))),
        ),
        Shape::Hexagon => {
            let q = r / 2;
            area.draw(&(at + Polygon::new(vec![(-r, 0), (-q, -h), (q, -h), (r, 0), (q, h), (-q, h)], c.filled())))
        }
    }
    .map_err(err)
}

/// What a legend entry shows: the series as it is drawn.
#[derive(Clone, Copy)]
enum Swatch {
    /// A solid line of this width.
    Line(RGBColor, u32),
    /// A dashed line: width, (dash, gap).
    Dashed(RGBColor, u32, (u32, u32)),
    /// A marker alone.
    Marker(Shape, RGBColor),
    /// A line of this width with a marker on it.
    LineMarker(RGBColor, u32, Shape),
    /// A filled block (a bar).
    Block(RGBColor),
}

/// Width of a swatch in pixels.
const SWATCH: i32 = 30;

fn draw_swatch(area: &Area<'_>, swatch: Swatch, (x, y): (i32, i32)) -> Result<()> {
    let line = |c: RGBColor, w: u32| area.draw(&PathElement::new(vec![(x, y), (x + SWATCH, y)], c.stroke_width(w)));
    match swatch {
        Swatch::Line(c, w) => line(c, w).map_err(err),
        Swatch::Dashed(c, w, (dash, gap)) => area
            .draw(&DashedPathElement::new(
                vec![(x, y), (x + SWATCH, y)],
                dash,
                gap,
                c.stroke_width(w),
            ))
            .map_err(err),
        Swatch::Marker(s, c) => draw_marker(area, s, (x + SWATCH / 2, y), 6, c),
        Swatch::LineMarker(c, w, s) => {
            line(c, w).map_err(err)?;
            draw_marker(area, s, (x + SWATCH / 2, y), 5, c)
        }
        Swatch::Block(c) => area
            .draw(&Rectangle::new([(x + 6, y - 7), (x + 24, y + 7)], c.filled()))
            .map_err(err),
    }
}

/// Legend entries in rows across `area` from `x0`, wrapping before `right`; `columns`
/// fixes the entries per row (else as many as fit). Returns the rows drawn.
fn legend(area: &Area<'_>, entries: &[(Swatch, String)], x0: i32, right: i32, columns: Option<usize>) -> Result<i32> {
    const ROW: i32 = 22;
    let (mut x, mut y, mut in_row) = (x0, ROW / 2 + 4, 0);
    let column = columns.map(|n| (right - x0) / n as i32);
    for (swatch, label) in entries {
        // About 6.5 pixels a character at 14 px in a sans-serif font (DejaVu Sans, what
        // rsvg and browsers pick on Linux, averages 6 on these labels).
        let width = column.unwrap_or(SWATCH + 8 + (13 * label.chars().count() as i32 + 1) / 2 + 28);
        if in_row > 0 && (x + width > right || columns.is_some_and(|n| in_row == n)) {
            (x, y, in_row) = (x0, y + ROW, 0);
        }
        draw_swatch(area, *swatch, (x, y))?;
        area.draw(&Text::new(
            label.as_str(),
            (x + SWATCH + 8, y),
            TextStyle::from((FONT, 14).into_font()).pos(Pos::new(HPos::Left, VPos::Center)),
        ))
        .map_err(err)?;
        x += width;
        in_row += 1;
    }
    Ok((y + ROW / 2) / ROW)
}

/// An `f64` axis with the ticks given (plotters' `with_key_points` gives an `f64` axis
/// no label formatter, so it cannot be drawn with `configure_mesh`).
struct Ticked {
    range: RangedCoordf64,
    ticks: Vec<f64>,
}

fn ticked(range: Range<f64>, ticks: Vec<f64>) -> Ticked {
    Ticked {
        range: range.into(),
        ticks,
    }
}

impl Ranged for Ticked {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.range.map(value, limit)
    }

    fn key_points<H: KeyPointHint>(&self, hint: H) -> Vec<f64> {
        // Grid lines at the ticks only, none in between.
        if hint.weight().allow_light_points() {
            vec![]
        } else {
            self.ticks.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        self.range.range()
    }
}

fn err<E: Debug>(e: E) -> anyhow::Error {
    anyhow!("drawing failed: {e:?}")
}

/// Render `draw` into an SVG of `size` pixels and write it to `dir/name`.
fn svg(dir: &Path, name: &str, size: (u32, u32), draw: impl FnOnce(&Area<'_>) -> Result<()>) -> Result<()> {
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        draw(&root)?;
        root.present().map_err(err)?;
    }
    emit(&text, Some(&dir.join(name)))
}

/// Write every figure that the runs call for into `dir`.
pub fn write_all(dir: &Path, ctx: &RunContext, runs: &[Run], k_varies: bool, cal_varies: bool) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    if !k_varies && !cal_varies {
        let run = &runs[0];
        svg(
            dir,
            "thresholds.svg",
            (
                1200,
                THRESHOLD_HEIGHT + LEGEND_HEIGHT + 50 + STRIP_HEIGHT * run.eval.methods.len() as u32,
            ),
            |root| thresholds(root, ctx, run),
        )?;
        let rows = run.eval.methods.len() as u32 + 2;
        svg(dir, "precision_recall.svg", (900, PR_HEIGHT + 30 + 22 * rows), |root| {
            precision_recall(root, ctx, run)
        })?;
        return Ok(());
    }
    if k_varies {
        svg(dir, "ablation_k.svg", (1200, 600), |root| {
            ablation(root, ctx, runs, Axis::K)
        })?;
    }
    if cal_varies {
        svg(dir, "ablation_cal.svg", (1200, 600), |root| {
            ablation(root, ctx, runs, Axis::Calibration)
        })?;
    }
    Ok(())
}

/// The input's name for an axis label: the file name of a path (the directories would
/// crowd out the label), the embedded data's name as it is.
fn dataset_label(ctx: &RunContext) -> String {
    if ctx.dataset == embedded::NAME {
        return ctx.dataset.clone();
    }
    Path::new(&ctx.dataset)
        .file_name()
        .map_or_else(|| ctx.dataset.clone(), |f| f.to_string_lossy().into_owned())
}

/// Round ticks in `lo..=hi`: the multiples of a step of 1, 2 or 5 times a power of ten,
/// the smallest step that gives at most `max` ticks; and the decimals that tell them apart.
fn nice_ticks(lo: f64, hi: f64, max: usize) -> (Vec<f64>, usize) {
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    let mut e = (span / max as f64).log10().floor() as i32;
    loop {
        for m in [1.0, 2.0, 5.0] {
            let step = m * 10f64.powi(e);
            // A hair of slack, so that a tick at `hi` itself is not lost to rounding.
            let (first, last) = ((lo / step - 1e-9).ceil() as i64, (hi / step + 1e-9).floor() as i64);
            if last - first < max as i64 {
                let ticks = (first..=last).map(|k| k as f64 * step).collect();
                return (ticks, usize::try_from(-e).unwrap_or(0));
            }
        }
        e += 1;
    }
}

/// A count axis whose largest value is `max`: integer ticks every `step` (1, 2 or 5
/// times a power of ten), at most three of them, the last one, `top`, at or above
/// `max`. Returns `(step, top)`; `max` = 0 gets the axis of 1.
fn count_axis(max: usize) -> (usize, usize) {
    let max = max.max(1);
    let mut p = 1;
    loop {
        for step in [p, 2 * p, 5 * p] {
            let n = max.div_ceil(step);
            if n <= 3 {
                return (step, n * step);
            }
        }
        p *= 10;
    }
}

// ---------------------------------------------------------------------------------------
// Fig. 3: thresholds along the traverse, with TP / FP / FN per segment
// ---------------------------------------------------------------------------------------

const THRESHOLD_HEIGHT: u32 = 480;
/// Three rows of legend entries.
const LEGEND_HEIGHT: u32 = 72;
const STRIP_HEIGHT: u32 = 130;

fn thresholds(root: &Area<'_>, ctx: &RunContext, run: &Run) -> Result<()> {
    let eval = &run.eval;
    let l = eval.layout;
    let end = (l.segments * l.segment_size) as f64;
    let (top, rest) = root.split_vertically(THRESHOLD_HEIGHT);
    let (legend_area, rest) = rest.split_vertically(LEGEND_HEIGHT);
    let oracle_of = eval.methods.first();

    // Threshold range over every finite threshold shown.
    let finite: Vec<f64> = eval
        .methods
        .iter()
        .flat_map(|m| m.segments.iter().flat_map(|g| [g.threshold, g.oracle_threshold]))
        .filter(|t| t.is_finite())
        .collect();
    let (lo, hi) = finite
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| (a.min(t), b.max(t)));
    let (lo, hi) = if finite.is_empty() {
        (0.0, 1.0)
    } else if hi - lo < 1e-12 {
        (lo - 0.5, hi + 0.5)
    } else {
        (lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo))
    };
    // Above the thresholds, a band for reject-all (+inf): one lane per method that
    // rejects all somewhere, in its colour, and one for the oracle. Inside the plotting
    // area, so that no marker reaches the title, and one lane each, so that none hides
    // another.
    // A method without a score threshold (the margin gate alone: -inf everywhere) has
    // nothing to draw here.
    let methods: Vec<&MethodResult> = eval
        .methods
        .iter()
        .filter(|m| m.method != Method::Oracle && m.segments.iter().any(|g| g.threshold > f64::NEG_INFINITY))
        .collect();
    let mut lanes: Vec<(Shape, RGBColor, Vec<f64>)> = vec![];
    let centres = |inf: &dyn Fn(&qtvpr::evaluate::SegmentResult) -> bool, m: &MethodResult| -> Vec<f64> {
        m.segments
            .iter()
            .filter(|g| inf(g))
            .map(|g| (g.start + g.end) as f64 / 2.0)
            .collect()
    };
    for m in &methods {
        let xs = centres(&|g| g.threshold == f64::INFINITY, m);
        if !xs.is_empty() {
            lanes.push((Shape::Triangle, colour(m.method), xs));
        }
    }
    let method_lanes = lanes.len();
    // The oracle threshold is in every method's result; take it from the first one.
    if let Some(first) = oracle_of {
        let xs = centres(&|g| g.oracle_threshold.is_infinite(), first);
        if !xs.is_empty() {
            lanes.push((shape(Method::Oracle), BLACK, xs));
        }
    }
    let (row, gap) = (0.045, if lanes.is_empty() { 0.0 } else { 0.03 });
    let span = (hi - lo) / (1.0 - lanes.len() as f64 * row - gap);
    let band = hi + gap * span;
    let lane_y = |i: usize| band + (i as f64 + 0.5) * row * span;
    let (mut ticks, decimals) = nice_ticks(lo, hi, 8);
    if !lanes.is_empty() {
        ticks.push(lane_y(0) + (lanes.len() as f64 - 1.0) * 0.5 * row * span);
    }

    let title = format!(
        "Per-segment thresholds along the traverse ({} segments of {} queries, k = {}, tau = {}, {} matching)",
        l.segments,
        l.segment_size,
        run.k,
        fmt_num(ctx.precision),
        ctx.matching.as_str()
    );
    let mut chart = ChartBuilder::on(&top)
        .caption(title, (FONT, 20))
        .margin_left(10)
        .margin_right(20)
        .margin_top(5)
        .x_label_area_size(45)
        .y_label_area_size(75)
        .build_cartesian_2d(0.0..end, ticked(lo..lo + span, ticks))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(format!(
            "deployment query (from query {} of {}: {})",
            l.deployment_start,
            l.queries,
            dataset_label(ctx)
        ))
        .y_desc("threshold (accept score >= threshold)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| {
            if *y > band {
                "reject-all".to_string()
            } else {
                format!("{y:.decimals$}")
            }
        })
        .axis_desc_style((FONT, 16))
        .label_style((FONT, 14))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(err)?;
    if !lanes.is_empty() {
        chart
            .draw_series(DashedLineSeries::new(
                [(0.0, band), (end, band)],
                3,
                3,
                ShapeStyle::from(&FN_COLOUR).stroke_width(1),
            ))
            .map_err(err)?;
    }

    // The oracle last, so that it is drawn on top; dashed.
    let mut entries: Vec<(Swatch, String)> = vec![];
    for m in &methods {
        let c = colour(m.method);
        for pts in finite_runs(m.segments.iter().map(|g| (g.start as f64, g.end as f64, g.threshold))) {
            chart
                .draw_series(LineSeries::new(pts, c.stroke_width(2)))
                .map_err(err)?;
        }
        entries.push((Swatch::Line(c, 2), m.method.as_str().to_string()));
    }
    if let Some(first) = oracle_of {
        let style = ShapeStyle::from(&BLACK).stroke_width(2);
        let runs = finite_runs(
            first
                .segments
                .iter()
                .map(|g| (g.start as f64, g.end as f64, g.oracle_threshold)),
        );
        for pts in runs {
            chart
                .draw_series(DashedLineSeries::new(pts, ORACLE_DASH.0, ORACLE_DASH.1, style))
                .map_err(err)?;
        }
        entries.push((
            Swatch::Dashed(BLACK, 2, ORACLE_DASH),
            "oracle (the segment's own ground truth)".to_string(),
        ));
    }
    for (i, (s, c, xs)) in lanes.iter().enumerate() {
        for &x in xs {
            draw_marker(chart.plotting_area(), *s, (x, lane_y(i)), 6, *c)?;
        }
    }
    if method_lanes > 0 {
        entries.push((
            Swatch::Marker(Shape::Triangle, NOTE_COLOUR),
            "reject-all (+inf) of the method in that colour: it accepts nothing in the segment".to_string(),
        ));
    }
    if lanes.len() > method_lanes {
        entries.push((
            Swatch::Marker(shape(Method::Oracle), BLACK),
            format!(
                "oracle reject-all: no threshold reaches precision {} in the segment",
                fmt_num(ctx.precision)
            ),
        ));
    }
    legend(&legend_area, &entries, 90, 1180, None)?;

    // Strips of TP / FP / FN, one per method.
    let n = eval.methods.len();
    let (strips, counts_area) = rest.split_vertically(STRIP_HEIGHT * n as u32);
    let areas = strips.split_evenly((n.max(1), 1));
    for (area, m) in areas.iter().zip(&eval.methods) {
        counts_strip(area, m, end, l.segment_size as f64, ctx.precision)?;
    }
    let items = [
        (TP_COLOUR, "TP: accepted and correct (up)"),
        (FP_COLOUR, "FP: accepted and wrong (up, above TP)"),
        (FN_COLOUR, "FN: positives not accepted (down; own scale)"),
    ];
    let items: Vec<(Swatch, String)> = items.iter().map(|&(c, s)| (Swatch::Block(c), s.to_string())).collect();
    legend(&counts_area, &items, 90, 1180, Some(3))?;
    Ok(())
}

/// Step-line points of consecutive finite thresholds, one list per unbroken run.
fn finite_runs(segments: impl Iterator<Item = (f64, f64, f64)>) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = vec![];
    let mut current: Vec<(f64, f64)> = vec![];
    for (a, b, t) in segments {
        if t.is_finite() {
            current.push((a, t));
            current.push((b, t));
        } else if !current.is_empty() {
            out.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

fn counts_strip(area: &Area<'_>, m: &MethodResult, end: f64, size: f64, tau: f64) -> Result<()> {
    let up_max = m.segments.iter().map(|g| g.counts.tp + g.counts.fp).max().unwrap_or(0);
    let down_max = m
        .segments
        .iter()
        .map(|g| g.counts.positives - g.counts.tp.min(g.counts.positives))
        .max()
        .unwrap_or(0);
    // Each half has its own scale, so that a few FPs show next to a hundred FNs; both
    // are counts, so their ticks are integers (up to `top` of each, at -1 and 1).
    let ((up_step, up), (down_step, down)) = (count_axis(up_max), count_axis(down_max));
    let mut ticks: Vec<f64> = (1..=up / up_step).map(|k| (k * up_step) as f64 / up as f64).collect();
    ticks.extend((0..=down / down_step).map(|k| -((k * down_step) as f64) / down as f64));
    let failed = m.segments.iter().filter(|g| g.counts.positives > 0 && !g.meets).count();
    let caption = format!(
        "{}: %Segs {}, AvgR {}, {} of {} counted segments below precision {}",
        m.method,
        m.pct_segs.map_or("n/a".into(), |v| format!("{v:.1}")),
        m.avg_recall.map_or("n/a".into(), |v| format!("{v:.3}")),
        failed,
        m.segments_counted,
        fmt_num(tau)
    );
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FONT, 15).into_font().color(&colour(m.method)))
        .margin_left(10)
        .margin_right(20)
        .x_label_area_size(20)
        .y_label_area_size(75)
        .build_cartesian_2d(0.0..end, ticked(-1.1..1.1, ticks))
        .map_err(err)?;
    let (up, down) = (up as f64, down as f64);
    // The ticks are k * step / top, so these products are integers up to rounding.
    // (`abs` so that the tick at 0 of the lower half is not "-0".)
    let tick = |v: &f64| format!("{:.0}", if *v >= 0.0 { v * up } else { v * down }.abs());
    chart
        .configure_mesh()
        .y_desc("FN | TP+FP")
        .axis_desc_style((FONT, 12))
        .label_style((FONT, 12))
        .y_label_formatter(&tick)
        .x_label_formatter(&|x| format!("{x:.0}"))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(err)?;
    let gap = (0.12 * size).min(0.4);
    let bars = m.segments.iter().flat_map(|g| {
        let (a, b) = (g.start as f64 + gap, g.end as f64 - gap);
        let (tp, fp) = (g.counts.tp as f64 / up, g.counts.fp as f64 / up);
        let fn_ = (g.counts.positives - g.counts.tp.min(g.counts.positives)) as f64 / down;
        [
            Rectangle::new([(a, 0.0), (b, tp)], TP_COLOUR.filled()),
            Rectangle::new([(a, tp), (b, tp + fp)], FP_COLOUR.filled()),
            Rectangle::new([(a, -fn_), (b, 0.0)], FN_COLOUR.filled()),
        ]
    });
    chart.draw_series(bars).map_err(err)?;
    chart
        .draw_series(std::iter::once(PathElement::new(
            vec![(0.0, 0.0), (end, 0.0)],
            BLACK.stroke_width(1),
        )))
        .map_err(err)?;
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Fig. 4 (right): precision-recall of the deployment set with operating points
// ---------------------------------------------------------------------------------------

const PR_HEIGHT: u32 = 670;

fn precision_recall(root: &Area<'_>, ctx: &RunContext, run: &Run) -> Result<()> {
    let eval = &run.eval;
    let l = eval.layout;
    let curve = eval.precision_recall_curve(4000);
    // Recall axis: zoomed in when every operating point and the curve's reach at the
    // target precision are far below 1 (hard data), so that they do not sit on the axis.
    let reach = eval
        .methods
        .iter()
        .map(|m| m.pooled().recall())
        .chain(
            curve
                .iter()
                .filter(|p| p.precision >= ctx.precision - 1e-12)
                .map(|p| p.recall),
        )
        .fold(0.0f64, f64::max);
    let x_max = nice_ceiling((1.5 * reach).clamp(0.01, 1.0));
    // Precision axis from a round value below everything shown (tau, the curve, the points).
    let lowest = eval
        .methods
        .iter()
        .map(|m| m.pooled().precision())
        .chain(curve.iter().filter(|p| p.recall <= x_max).map(|p| p.precision))
        .fold(ctx.precision, f64::min);
    let y_min = ((lowest - 0.05) * 10.0).floor().max(0.0) / 10.0;
    let (chart_area, below) = root.split_vertically(PR_HEIGHT);
    let mut chart = ChartBuilder::on(&chart_area)
        .caption(
            format!(
                "Precision-recall on the deployment set ({} queries, {} matching)",
                l.segments * l.segment_size,
                ctx.matching.as_str()
            ),
            (FONT, 20),
        )
        .margin(15)
        .x_label_area_size(50)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..x_max, y_min..1.0 + 0.05 * (1.0 - y_min))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(if x_max < 1.0 {
            format!("recall (axis zoomed to 0..{})", fmt_num(x_max))
        } else {
            "recall".to_string()
        })
        .y_desc("precision")
        .axis_desc_style((FONT, 16))
        .label_style((FONT, 14))
        .bold_line_style(RGBColor(225, 225, 225))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(err)?;
    let curve_colour = RGBColor(110, 110, 110);
    chart
        .draw_series(LineSeries::new(
            curve
                .iter()
                .take_while(|p| p.recall <= x_max)
                .map(|p| (p.recall, p.precision)),
            curve_colour.stroke_width(2),
        ))
        .map_err(err)?;
    let target_colour = RGBColor(200, 0, 0);
    chart
        .draw_series(DashedLineSeries::new(
            [(0.0, ctx.precision), (x_max, ctx.precision)],
            TARGET_DASH.0,
            TARGET_DASH.1,
            ShapeStyle::from(&target_colour).stroke_width(1),
        ))
        .map_err(err)?;
    let mut entries = vec![
        (
            Swatch::Line(curve_colour, 2),
            "one threshold for the whole deployment set".to_string(),
        ),
        (
            Swatch::Dashed(target_colour, 1, TARGET_DASH),
            format!("target precision {}", fmt_num(ctx.precision)),
        ),
    ];
    for m in &eval.methods {
        let p = m.pooled();
        let (c, s) = (colour(m.method), shape(m.method));
        draw_marker(chart.plotting_area(), s, (p.recall(), p.precision()), 8, c)?;
        let label = format!(
            "{}: precision {:.3}, recall {:.3} (TP {}, FP {})",
            m.method,
            p.precision(),
            p.recall(),
            p.tp,
            p.fp
        );
        entries.push((Swatch::Marker(s, c), label));
    }
    // Under the chart, one entry a row: a legend inside would cover points or the curve.
    let (legend_area, note) = below.split_vertically(22 * entries.len() as u32 + 4);
    legend(&legend_area, &entries, 80, 880, Some(1))?;
    note.draw(&Text::new(
        "The curve is one global threshold swept over the deployment set; each point pools a method's \
         per-segment decisions.",
        (80, 5),
        (FONT, 13).into_font().color(&NOTE_COLOUR),
    ))
    .map_err(err)?;
    Ok(())
}

/// The smallest of 1, 2 or 5 times a power of ten that is at least `x` (> 0).
fn nice_ceiling(x: f64) -> f64 {
    let p = 10f64.powf(x.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|&v| v >= x * (1.0 - 1e-12))
        .unwrap_or(10.0 * p)
        .min(1.0)
}

// ---------------------------------------------------------------------------------------
// Fig. 5: ablations
// ---------------------------------------------------------------------------------------

#[derive(Clone, Copy, PartialEq)]
enum Axis {
    K,
    Calibration,
}

fn setting_label(run: &Run, axis: Axis) -> String {
    match axis {
        Axis::K => run.k.to_string(),
        Axis::Calibration => match run.calibration {
            qtvpr::Split::Fraction(f) => format!("{} ({})", fmt_num(f), run.eval.layout.calibration_queries),
            qtvpr::Split::Count(n) => n.to_string(),
        },
    }
}

/// The horizontal offset of series `i` of `n` from its category, in categories.
///
/// Series that reach the same value (several methods at 100 %Segs, say) would hide one
/// another; side by side they all stay visible. The x axis is categorical (one slot per
/// setting), so the offset changes no value that can be read off the figure, as a
/// vertical one would.
/// Offsets are 0.12 apart (10 pixels at 6 settings, two markers' width), or less when
/// there are more than 7 series, so that a slot's series stay within 0.7 of it.
fn dodge(i: usize, n: usize) -> f64 {
    let step = if n > 1 { (0.7 / (n - 1) as f64).min(0.12) } else { 0.0 };
    (i as f64 - (n as f64 - 1.0) / 2.0) * step
}

fn ablation(root: &Area<'_>, ctx: &RunContext, runs: &[Run], axis: Axis) -> Result<()> {
    // The values along the axis, in the order given, and the series: one per method
    // when only this parameter varies, else quantile transfer once per other setting.
    let mut xs: Vec<String> = vec![];
    for r in runs {
        let x = setting_label(r, axis);
        if !xs.contains(&x) {
            xs.push(x);
        }
    }
    let other = |r: &Run| match axis {
        Axis::K => format!("calibration {}", setting_label(r, Axis::Calibration)),
        Axis::Calibration => format!("k = {}", r.k),
    };
    let mut others: Vec<String> = vec![];
    for r in runs {
        if !others.contains(&other(r)) {
            others.push(other(r));
        }
    }
    // (label, colour, marker, points of (x index, %Segs, AvgR))
    type Series = (String, RGBColor, Shape, Vec<(usize, Option<f64>, Option<f64>)>);
    let mut series: Vec<Series> = vec![];
    let x_of = |r: &Run| xs.iter().position(|x| *x == setting_label(r, axis)).unwrap();
    if others.len() == 1 {
        // The oracle first, so that the methods that reach it are drawn over it.
        let mut methods: Vec<Method> = runs[0].eval.methods.iter().map(|m| m.method).collect();
        methods.sort_by_key(|&m| m != Method::Oracle);
        for m in methods {
            let pts = runs
                .iter()
                .filter_map(|r| r.eval.method(m).map(|mr| (x_of(r), mr.pct_segs, mr.avg_recall)))
                .collect();
            series.push((m.as_str().to_string(), colour(m), shape(m), pts));
        }
    } else {
        let palette = [
            RGBColor(31, 119, 180),
            RGBColor(255, 127, 14),
            RGBColor(44, 160, 44),
            RGBColor(214, 39, 40),
            RGBColor(148, 103, 189),
            RGBColor(140, 86, 75),
            RGBColor(227, 119, 194),
            RGBColor(127, 127, 127),
        ];
        for (i, o) in others.iter().enumerate() {
            let pts = runs
                .iter()
                .filter(|r| other(r) == *o)
                .filter_map(|r| {
                    r.eval
                        .method(Method::QuantileTransfer)
                        .map(|mr| (x_of(r), mr.pct_segs, mr.avg_recall))
                })
                .collect();
            series.push((
                format!("QT, {o}"),
                palette[i % palette.len()],
                SHAPES[i % SHAPES.len()],
                pts,
            ));
        }
    }

    let (x_desc, what) = match axis {
        Axis::K => ("k: calibration queries sampled per deployment query", "k"),
        Axis::Calibration => (
            "calibration size: the first fraction of |Q| (queries)",
            "calibration size",
        ),
    };
    let (charts, legend_area) = root.split_vertically(500);
    let (left, right) = charts
        .titled(
            &format!(
                "Sensitivity to {what}: deployment set fixed to {}",
                ablation_setting(ctx, &runs[0])
            ),
            (FONT, 19),
        )
        .map_err(err)?
        .split_horizontally(600);
    let avg = ctx.avg_recall_name();
    let max_recall = series
        .iter()
        .flat_map(|s| s.3.iter().filter_map(|p| p.2))
        .fold(0.0f64, f64::max);
    let min_pct = series
        .iter()
        .flat_map(|s| s.3.iter().filter_map(|p| p.1))
        .fold(100.0f64, f64::min);
    // %Segs from a multiple of 10 below the lowest value shown.
    let pct_min = ((min_pct - 5.0) / 10.0).floor().max(0.0) * 10.0;
    type Panel<'p, 'b> = (&'p Area<'b>, &'p str, f64, f64, bool);
    let panels: [Panel<'_, '_>; 2] = [
        (&left, "%Segs (segments that meet the target)", pct_min, 102.0, true),
        (&right, avg.as_str(), 0.0, (max_recall * 1.1).clamp(0.05, 1.0), false),
    ];
    let n = xs.len();
    for (area, y_desc, y_min, y_max, first) in panels {
        let (ticks, decimals) = nice_ticks(y_min, y_max.min(if first { 100.0 } else { 1.0 }), 8);
        let categories: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let mut chart = ChartBuilder::on(area)
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(60)
            .build_cartesian_2d(ticked(-0.7..n as f64 - 0.3, categories), ticked(y_min..y_max, ticks))
            .map_err(err)?;
        let fmt = |x: &f64| xs.get(x.round() as usize).cloned().unwrap_or_default();
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .x_label_formatter(&fmt)
            .y_label_formatter(&|y| format!("{y:.decimals$}"))
            .axis_desc_style((FONT, 15))
            .label_style((FONT, 13))
            .bold_line_style(RGBColor(225, 225, 225))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(err)?;
        for (i, (label, c, s, pts)) in series.iter().enumerate() {
            let offset = dodge(i, series.len());
            let pts: Vec<(f64, f64)> = pts
                .iter()
                .filter_map(|&(x, p, r)| if first { p } else { r }.map(|y| (x as f64 + offset, y)))
                .collect();
            let width = if label == "oracle" { 3 } else { 2 };
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(width)))
                .map_err(err)?;
            for p in pts {
                draw_marker(chart.plotting_area(), *s, p, 5, *c)?;
            }
        }
    }
    // One legend for both panels, in rows underneath.
    let entries: Vec<(Swatch, String)> = series
        .iter()
        .map(|(label, c, s, _)| {
            let width = if label == "oracle" { 3 } else { 2 };
            (Swatch::LineMarker(*c, width, *s), label.clone())
        })
        .collect();
    let rows = legend(&legend_area, &entries, 80, 1180, None)?;
    legend_area
        .draw(&Text::new(
            "Series are set side by side around each setting, so that equal values stay visible.",
            (80, 22 * rows + 14),
            (FONT, 13).into_font().color(&NOTE_COLOUR),
        ))
        .map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_ticks_are_round_and_told_apart() {
        // 0..0.05 in at most 8 ticks: a step of 0.01 gives 6 (0, 0.01, ..., 0.05);
        // two decimals tell them apart (the old fixed "{:.2}" of a finer grid did not).
        let (t, d) = nice_ticks(0.0, 0.05, 8);
        assert_eq!(d, 2);
        assert_eq!(t.len(), 6);
        assert!((t[5] - 0.05).abs() < 1e-15, "{t:?}");
        // 70..100: a step of 5 gives 7 ticks 70, 75, ..., 100.
        let (t, d) = nice_ticks(70.0, 100.0, 8);
        assert_eq!((t.first(), t.last(), t.len(), d), (Some(&70.0), Some(&100.0), 7, 0));
        // 0.23..0.81 (span 0.58): 0.05 gives 12 > 8, 0.1 gives 0.3 .. 0.8 = 6.
        let (t, d) = nice_ticks(0.23, 0.81, 8);
        assert_eq!((t.len(), d), (6, 1));
        assert!((t[0] - 0.3).abs() < 1e-12 && (t[5] - 0.8).abs() < 1e-12, "{t:?}");
    }

    #[test]
    fn count_axes_have_integer_ticks() {
        // Largest count -> (step, top): at most 3 ticks, each a multiple of the step.
        // 11: steps 1 and 2 need 11 and 6 ticks, 5 needs 3 (5, 10, 15).
        // 36: 10 needs 4, 20 needs 2 (20, 40). 4: 2 needs 2. 0 and 1: one tick at 1.
        let cases = [
            (0, (1, 1)),
            (1, (1, 1)),
            (3, (1, 3)),
            (4, (2, 4)),
            (11, (5, 15)),
            (36, (20, 40)),
            (108, (50, 150)),
        ];
        for (max, want) in cases {
            assert_eq!(count_axis(max), want, "{max}");
        }
    }

    #[test]
    fn dodge_centres_the_series() {
        // 5 series: offsets -0.24, -0.12, 0, 0.12, 0.24 of a category; 1 series: none.
        assert_eq!(dodge(0, 1), 0.0);
        assert!((dodge(0, 5) + 0.24).abs() < 1e-15 && dodge(2, 5) == 0.0);
        assert!((dodge(4, 5) - 0.24).abs() < 1e-15);
        // 11 series: 0.7 / 10 = 0.07 apart, from -0.35 to 0.35: clear of the next slot.
        assert!((dodge(0, 11) + 0.35).abs() < 1e-12 && (dodge(10, 11) - 0.35).abs() < 1e-12);
    }
}
