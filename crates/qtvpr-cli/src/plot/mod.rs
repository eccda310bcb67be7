//! `evaluate --plot DIR`: SVG figures drawn with plotters' SVG backend (no system
//! fonts needed: the SVG names a generic sans-serif font and the viewer renders it).
//!
//! - `thresholds.svg` (the paper's Fig. 3): each method's per-segment threshold
//!   against the oracle's along the traverse, and underneath, one strip per method with
//!   the TP (up, green), FP (up, red) and FN (down, grey) of every segment.
//! - `precision_recall.svg` (Fig. 4, right): the precision-recall curve of the
//!   deployment set under one global threshold, with each method's operating point
//!   (its per-segment decisions pooled over the deployment set).
//! - `scores.svg`: the deployment set's best-match scores (every candidate's in multi
//!   matching), right ones up and wrong ones down over the same bins, each method's
//!   threshold (the median of its segments') a vertical line on them.
//! - `reliability.svg` (single matching): the reliability diagram of the confidence
//!   (semantics §14), the hit rate against the mean confidence of each bin of the ECE
//!   that holds a decision, with its count, and the diagonal of perfect calibration.
//! - `ablation_k.svg` / `ablation_cal.svg` (Fig. 5): %Segs and AvgR against k or the
//!   calibration size, when `--k` or the calibration size is given a list.
//!
//! Legends sit outside the plotting areas, so that they cover no data, and every
//! swatch is drawn as its series is (dashed for a dashed line, the marker's shape).
//! Every file is written atomically, like `--output`.

mod ablation;
mod precision_recall;
mod reliability;
mod scores;
mod thresholds;

use std::fmt::Debug;
use std::ops::Range;
use std::path::Path;

use anyhow::{Context as _, Result, anyhow};

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::{CoordTranslate, Shift};
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use qtvpr::Method;
use qtvpr::MethodResult;

use crate::embedded;
use crate::output::emit;
use crate::summary::{Run, RunContext, ablation_setting, fmt_num};
use precision_recall::PR_HEIGHT;
use reliability::{RELIABILITY_BELOW, RELIABILITY_HEIGHT};
use scores::{SCORES_BELOW, SCORES_HEIGHT};
use thresholds::{LEGEND_HEIGHT, STRIP_HEIGHT, THRESHOLD_HEIGHT};

const FONT: &str = "sans-serif";

type Area<'b> = DrawingArea<SVGBackend<'b>, Shift>;
const TP_COLOUR: RGBColor = RGBColor(77, 175, 74);
const FP_COLOUR: RGBColor = RGBColor(228, 26, 28);
const FN_COLOUR: RGBColor = RGBColor(170, 170, 170);
const NOTE_COLOUR: RGBColor = RGBColor(90, 90, 90);
/// Dash and gap of the oracle's threshold line, in pixels (and of its legend swatch).
const ORACLE_DASH: (u32, u32) = (7, 4);
/// Dash and gap of a gated method's threshold line, which lies on quantile transfer's:
/// one for each set of gates, of different periods, so that lines on one another show
/// each colour in turn.
fn gated_dash(m: Method) -> Option<(u32, u32)> {
    let g = m.gate();
    match (g.margin(), g.sequence()) {
        (false, false) => None,
        (true, false) => Some((3, 5)),
        (false, true) => Some((7, 7)),
        (true, true) => Some((2, 10)),
    }
}
/// Width of quantile transfer's threshold line: wider than the lines drawn over it.
const WIDE: u32 = 6;

/// How a method's threshold line is drawn (in `thresholds.svg` and `scores.svg`).
///
/// The three quantile-transfer lines often coincide: quantile-transfer-margin's
/// thresholds are quantile transfer's (its gate acts on the margin), and online's
/// segment threshold is that of the segment's last query, whose window is the segment.
/// So quantile transfer's is wide and drawn first, online's is thin and solid on it,
/// and the gated one is dashed on top: where all three lie together, the wide line shows
/// at both sides of the thin one, and the thin one between the dashes.
fn line_style(m: Method) -> Swatch {
    let c = colour(m);
    if m == Method::QuantileTransfer {
        Swatch::Line(c, WIDE)
    } else if let Some(dash) = gated_dash(m) {
        Swatch::Dashed(c, 2, dash)
    } else {
        Swatch::Line(c, 2)
    }
}

/// Methods in the order their threshold lines are drawn: by [`line_style`], the wide
/// line first and the dashed ones last, else in the order given.
fn drawing_order<'m>(methods: impl IntoIterator<Item = &'m MethodResult>) -> Vec<&'m MethodResult> {
    let mut v: Vec<&MethodResult> = methods.into_iter().collect();
    v.sort_by_key(|m| match line_style(m.method) {
        Swatch::Line(_, WIDE) => 0,
        Swatch::Dashed(..) => 2,
        _ => 1,
    });
    v
}

/// Draw a polyline as `style` says (a solid or dashed [`Swatch`]), in any coordinates.
fn draw_line<X: CoordTranslate>(
    area: &DrawingArea<SVGBackend<'_>, X>,
    style: Swatch,
    points: Vec<X::From>,
) -> Result<()>
where
    X::From: Clone,
{
    match style {
        Swatch::Dashed(c, w, (dash, gap)) | Swatch::DashedMarker(c, w, (dash, gap), _) => area
            .draw(&DashedPathElement::new(points, dash, gap, c.stroke_width(w)))
            .map_err(err),
        Swatch::Line(c, w) | Swatch::LineMarker(c, w, _) => {
            area.draw(&PathElement::new(points, c.stroke_width(w))).map_err(err)
        }
        Swatch::Marker(..) | Swatch::Block(_) | Swatch::Empty => Ok(()),
    }
}

/// Dash and gap of the target-precision line of the precision-recall figure.
const TARGET_DASH: (u32, u32) = (6, 5);

/// The colour of a method, the same in every figure.
fn colour(m: Method) -> RGBColor {
    match m {
        Method::QuantileTransfer => RGBColor(31, 119, 180),
        Method::QuantileTransferOnline => RGBColor(23, 190, 207),
        Method::QuantileTransferMargin => RGBColor(44, 160, 44),
        Method::Margin => RGBColor(188, 189, 34),
        Method::QuantileTransferSequence => RGBColor(214, 39, 40),
        Method::QuantileTransferMarginSequence => RGBColor(227, 119, 194),
        Method::Sequence => RGBColor(127, 127, 127),
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
    Ring,
    Pentagon,
    Star,
}

/// Shapes in the order series get them.
const SHAPES: [Shape; 11] = [
    Shape::Circle,
    Shape::Triangle,
    Shape::Square,
    Shape::Diamond,
    Shape::Cross,
    Shape::InvertedTriangle,
    Shape::Plus,
    Shape::Hexagon,
    Shape::Ring,
    Shape::Pentagon,
    Shape::Star,
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
        Method::QuantileTransferSequence => Shape::Pentagon,
        Method::QuantileTransferMarginSequence => Shape::Star,
        Method::Sequence => Shape::Ring,
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
        Shape::Ring => area.draw(&(at + Circle::new((0, 0), r, c.stroke_width(2)))),
        Shape::Pentagon => area.draw(&(at + Polygon::new(polygon(5, r, r), c.filled()))),
        Shape::Star => area.draw(&(at + Polygon::new(polygon(10, r, r / 2), c.filled()))),
    }
    .map_err(err)
}

/// The `n` corners of a polygon about (0, 0), pointing up, at radii `outer` and
/// `inner` in turn (equal for a regular polygon, a star otherwise), in pixels.
fn polygon(n: usize, outer: i32, inner: i32) -> Vec<(i32, i32)> {
    (0..n)
        .map(|i| {
            let radius = f64::from(if i % 2 == 0 { outer } else { inner });
            let angle = std::f64::consts::TAU * i as f64 / n as f64;
            (
                (radius * angle.sin()).round() as i32,
                (-radius * angle.cos()).round() as i32,
            )
        })
        .collect()
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
    /// A dashed line with a marker on it: width, (dash, gap).
    DashedMarker(RGBColor, u32, (u32, u32), Shape),
    /// A filled block (a bar).
    Block(RGBColor),
    /// Nothing: an entry for a series that is not drawn.
    Empty,
}

impl Swatch {
    /// The same line with `shape` on it (a marker or nothing as it is).
    fn with_marker(self, shape: Shape) -> Self {
        match self {
            Swatch::Line(c, w) => Swatch::LineMarker(c, w, shape),
            Swatch::Dashed(c, w, d) => Swatch::DashedMarker(c, w, d, shape),
            other => other,
        }
    }
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
        Swatch::DashedMarker(c, w, d, s) => {
            draw_swatch(area, Swatch::Dashed(c, w, d), (x, y))?;
            draw_marker(area, s, (x + SWATCH / 2, y), 5, c)
        }
        Swatch::Block(c) => area
            .draw(&Rectangle::new([(x + 6, y - 7), (x + 24, y + 7)], c.filled()))
            .map_err(err),
        Swatch::Empty => Ok(()),
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
            |root| thresholds::thresholds(root, ctx, run),
        )?;
        let rows = run.eval.methods.len() as u32 + 2;
        svg(dir, "precision_recall.svg", (900, PR_HEIGHT + 30 + 22 * rows), |root| {
            precision_recall::precision_recall(root, ctx, run)
        })?;
        if let Some(h) = run.eval.score_histogram(qtvpr::SCORE_HISTOGRAM_BINS) {
            let rows = (run.eval.methods.len() as u32).div_ceil(2);
            svg(
                dir,
                "scores.svg",
                (1200, SCORES_HEIGHT + SCORES_BELOW + 22 * rows),
                |root| scores::scores(root, ctx, run, &h),
            )?;
        }
        // Semantics §14's signals exist in single matching only.
        if let Some(signals) = &run.eval.confidence {
            svg(
                dir,
                "reliability.svg",
                (900, RELIABILITY_HEIGHT + RELIABILITY_BELOW),
                |root| reliability::reliability(root, ctx, signals),
            )?;
        }
        return Ok(());
    }
    if k_varies {
        svg(dir, "ablation_k.svg", (1200, 600), |root| {
            ablation::ablation(root, ctx, runs, ablation::Axis::K)
        })?;
    }
    if cal_varies {
        svg(dir, "ablation_cal.svg", (1200, 600), |root| {
            ablation::ablation(root, ctx, runs, ablation::Axis::Calibration)
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

/// A two-sided count axis: counts up to `up_max` above 0 and up to `down_max` below
/// it, each half on its own [`count_axis`] scaled to 1 (so that a few of one show next to
/// a hundred of the other). Returns the ticks (in -1..=1) and the two halves' tops: a
/// count `n` is drawn at `n / up` or `-n / down`.
fn mirrored_counts(up_max: usize, down_max: usize) -> (Vec<f64>, f64, f64) {
    let ((up_step, up), (down_step, down)) = (count_axis(up_max), count_axis(down_max));
    let mut ticks: Vec<f64> = (1..=up / up_step).map(|k| (k * up_step) as f64 / up as f64).collect();
    ticks.extend((0..=down / down_step).map(|k| -((k * down_step) as f64) / down as f64));
    (ticks, up as f64, down as f64)
}

/// The label of tick `v` of [`mirrored_counts`]: the count it stands for. The ticks are
/// k * step / top, so these products are integers up to rounding (`abs` so that the tick
/// at 0 of the lower half is not "-0").
fn mirrored_label(v: f64, up: f64, down: f64) -> String {
    format!("{:.0}", if v >= 0.0 { v * up } else { v * down }.abs())
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
}
