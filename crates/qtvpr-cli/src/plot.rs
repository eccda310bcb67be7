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
//! Every file is written atomically, like `--output`.

use std::fmt::Debug;
use std::path::Path;

use anyhow::{Context as _, Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;
use qtvpr::Method;
use qtvpr::evaluate::MethodResult;

use crate::evaluate::{Run, RunContext, ablation_setting, fmt_num};
use crate::output::emit;

const FONT: &str = "sans-serif";

type Area<'b> = DrawingArea<SVGBackend<'b>, Shift>;
const TP_COLOUR: RGBColor = RGBColor(77, 175, 74);
const FP_COLOUR: RGBColor = RGBColor(228, 26, 28);
const FN_COLOUR: RGBColor = RGBColor(170, 170, 170);

/// The colour of a method, the same in every figure.
fn colour(m: Method) -> RGBColor {
    match m {
        Method::QuantileTransfer => RGBColor(31, 119, 180),
        Method::QuantileTransferOnline => RGBColor(23, 190, 207),
        Method::Schubert => RGBColor(255, 127, 14),
        Method::SchubertCalibrated => RGBColor(148, 103, 189),
        Method::CalibrationThreshold => RGBColor(140, 86, 75),
        Method::Oracle => BLACK,
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
            (1200, 530 + 130 * run.eval.methods.len() as u32),
            |root| thresholds(root, ctx, run),
        )?;
        svg(dir, "precision_recall.svg", (900, 700), |root| {
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

// ---------------------------------------------------------------------------------------
// Fig. 3: thresholds along the traverse, with TP / FP / FN per segment
// ---------------------------------------------------------------------------------------

fn thresholds(root: &Area<'_>, ctx: &RunContext, run: &Run) -> Result<()> {
    let eval = &run.eval;
    let l = eval.layout;
    let end = (l.segments * l.segment_size) as f64;
    let (top, rest) = root.split_vertically(480);

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
        // Room above the lines for the legend.
        (lo - 0.06 * (hi - lo), hi + 0.45 * (hi - lo))
    };

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
        .build_cartesian_2d(0.0..end, lo..hi)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(format!(
            "deployment query (from query {} of {}: {})",
            l.deployment_start, l.queries, ctx.dataset
        ))
        .y_desc("threshold (accept score >= threshold)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .axis_desc_style((FONT, 16))
        .label_style((FONT, 14))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(err)?;

    // The oracle last, so that it is drawn on top; thicker and dashed.
    let order: Vec<&MethodResult> = eval.methods.iter().filter(|m| m.method != Method::Oracle).collect();
    let oracle_style = ShapeStyle::from(&BLACK).stroke_width(2);
    let mut inf_drawn = false;
    for m in &order {
        let style = ShapeStyle::from(&colour(m.method)).stroke_width(2);
        let mut runs = finite_runs(m.segments.iter().map(|g| (g.start as f64, g.end as f64, g.threshold)));
        if runs.is_empty() {
            runs.push(vec![]); // an empty series, for the legend entry
        }
        for (i, pts) in runs.into_iter().enumerate() {
            let s = chart.draw_series(LineSeries::new(pts, style)).map_err(err)?;
            if i == 0 {
                let c = colour(m.method);
                s.label(m.method.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], c.stroke_width(3)));
            }
        }
        inf_drawn |= reject_all_markers(&mut chart, m, hi, colour(m.method))?;
    }
    // The oracle threshold is in every method's result; draw it from the first one.
    if let Some(first) = eval.methods.first() {
        let runs = finite_runs(
            first
                .segments
                .iter()
                .map(|g| (g.start as f64, g.end as f64, g.oracle_threshold)),
        );
        for (i, pts) in runs.into_iter().enumerate() {
            let s = chart
                .draw_series(DashedLineSeries::new(pts, 7, 4, oracle_style))
                .map_err(err)?;
            if i == 0 {
                s.label("oracle, dashed (the segment's own ground truth)")
                    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], BLACK.stroke_width(2)));
            }
        }
        let oracle_inf = first.segments.iter().filter(|g| g.oracle_threshold.is_infinite());
        let marks: Vec<(f64, f64)> = oracle_inf
            .map(|g| ((g.start + g.end) as f64 / 2.0, hi - 0.015 * (hi - lo)))
            .collect();
        inf_drawn |= !marks.is_empty();
        chart
            .draw_series(marks.into_iter().map(|p| Cross::new(p, 5, BLACK.stroke_width(2))))
            .map_err(err)?;
    }
    if inf_drawn {
        chart
            .draw_series(std::iter::once(Text::new(
                "markers on the top edge: reject-all (+inf); x: oracle has no valid threshold",
                (0.01 * end, hi - 0.06 * (hi - lo)),
                (FONT, 13).into_font().color(&RGBColor(90, 90, 90)),
            )))
            .map_err(err)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(180, 180, 180))
        .label_font((FONT, 14))
        .draw()
        .map_err(err)?;

    // Strips of TP / FP / FN, one per method.
    let n = eval.methods.len();
    let (strips, legend) = rest.split_vertically(130 * n as u32);
    let areas = strips.split_evenly((n.max(1), 1));
    for (area, m) in areas.iter().zip(&eval.methods) {
        counts_strip(area, m, end, l.segment_size as f64, ctx.precision)?;
    }
    counts_legend(&legend)?;
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

type ThresholdChart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// Triangles on the top edge where a method rejects everything; true if any.
fn reject_all_markers(chart: &mut ThresholdChart<'_, '_>, m: &MethodResult, hi: f64, c: RGBColor) -> Result<bool> {
    let pts: Vec<(f64, f64)> = m
        .segments
        .iter()
        .filter(|g| g.threshold.is_infinite())
        .map(|g| ((g.start + g.end) as f64 / 2.0, hi))
        .collect();
    let any = !pts.is_empty();
    chart
        .draw_series(pts.into_iter().map(|p| TriangleMarker::new(p, 6, c.filled())))
        .map_err(err)?;
    Ok(any)
}

fn counts_strip(area: &Area<'_>, m: &MethodResult, end: f64, size: f64, tau: f64) -> Result<()> {
    let up = m
        .segments
        .iter()
        .map(|g| g.counts.tp + g.counts.fp)
        .max()
        .unwrap_or(0)
        .max(1) as f64;
    let down = m
        .segments
        .iter()
        .map(|g| g.counts.positives - g.counts.tp.min(g.counts.positives))
        .max()
        .unwrap_or(0)
        .max(1) as f64;
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
        .build_cartesian_2d(0.0..end, -1.1..1.1)
        .map_err(err)?;
    // Each half has its own scale, so that a few FPs show next to a hundred FNs.
    let tick = |v: &f64| {
        let n = if *v >= 0.0 { v * up } else { -v * down };
        if (n - n.round()).abs() < 1e-9 {
            format!("{n:.0}")
        } else {
            format!("{n:.1}")
        }
    };
    chart
        .configure_mesh()
        .y_desc("FN | TP+FP")
        .axis_desc_style((FONT, 12))
        .label_style((FONT, 12))
        .y_labels(5)
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

fn counts_legend(area: &Area<'_>) -> Result<()> {
    let items = [
        (TP_COLOUR, "TP: accepted and correct (up)"),
        (FP_COLOUR, "FP: accepted and wrong (up, above TP)"),
        (FN_COLOUR, "FN: positives not accepted (down; own scale)"),
    ];
    let mut x = 90;
    for (c, label) in items {
        area.draw(&Rectangle::new([(x, 14), (x + 18, 28)], c.filled()))
            .map_err(err)?;
        area.draw(&Text::new(label, (x + 26, 14), (FONT, 15))).map_err(err)?;
        x += 360;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Fig. 4 (right): precision-recall of the deployment set with operating points
// ---------------------------------------------------------------------------------------

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
    let (chart_area, note) = root.split_vertically(670);
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
    chart
        .draw_series(LineSeries::new(
            curve
                .iter()
                .take_while(|p| p.recall <= x_max)
                .map(|p| (p.recall, p.precision)),
            RGBColor(110, 110, 110).stroke_width(2),
        ))
        .map_err(err)?
        .label("one threshold for the whole deployment set")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], RGBColor(110, 110, 110).stroke_width(2)));
    chart
        .draw_series(DashedLineSeries::new(
            [(0.0, ctx.precision), (x_max, ctx.precision)],
            6,
            5,
            ShapeStyle::from(&RGBColor(200, 0, 0)).stroke_width(1),
        ))
        .map_err(err)?
        .label(format!("target precision {}", fmt_num(ctx.precision)))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], RGBColor(200, 0, 0)));
    for m in &eval.methods {
        let p = m.pooled();
        let c = colour(m.method);
        let point = (p.recall(), p.precision());
        let s = if m.method == Method::Oracle {
            chart
                .draw_series(std::iter::once(Cross::new(point, 8, c.stroke_width(3))))
                .map_err(err)?
        } else {
            chart
                .draw_series(std::iter::once(Circle::new(point, 8, c.filled())))
                .map_err(err)?
        };
        let label = format!(
            "{}: precision {:.3}, recall {:.3} (TP {}, FP {})",
            m.method,
            p.precision(),
            p.recall(),
            p.tp,
            p.fp
        );
        if m.method == Method::Oracle {
            s.label(label)
                .legend(move |(x, y)| Cross::new((x + 12, y), 6, c.stroke_width(3)));
        } else {
            s.label(label)
                .legend(move |(x, y)| Circle::new((x + 12, y), 6, c.filled()));
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.9))
        .border_style(RGBColor(180, 180, 180))
        .label_font((FONT, 14))
        .draw()
        .map_err(err)?;
    note.draw(&Text::new(
        "The curve is one global threshold swept over the deployment set; each point pools a method's \
         per-segment decisions.",
        (80, 5),
        (FONT, 13).into_font().color(&RGBColor(90, 90, 90)),
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
    // (label, colour, points of (x index, %Segs, AvgR))
    type Series = (String, RGBColor, Vec<(i32, Option<f64>, Option<f64>)>);
    let mut series: Vec<Series> = vec![];
    let x_of = |r: &Run| xs.iter().position(|x| *x == setting_label(r, axis)).unwrap() as i32;
    if others.len() == 1 {
        // The oracle first, so that the methods that reach it stay visible on top.
        let mut methods: Vec<Method> = runs[0].eval.methods.iter().map(|m| m.method).collect();
        methods.sort_by_key(|&m| m != Method::Oracle);
        for m in methods.iter().map(|&m| runs[0].eval.method(m).expect("asked for")) {
            let pts = runs
                .iter()
                .filter_map(|r| r.eval.method(m.method).map(|mr| (x_of(r), mr.pct_segs, mr.avg_recall)))
                .collect();
            series.push((m.method.as_str().to_string(), colour(m.method), pts));
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
            series.push((format!("QT, {o}"), palette[i % palette.len()], pts));
        }
    }

    let (x_desc, what) = match axis {
        Axis::K => ("k: calibration queries sampled per deployment query", "k"),
        Axis::Calibration => (
            "calibration size: the first fraction of |Q| (queries)",
            "calibration size",
        ),
    };
    let (charts, legend) = root.split_vertically(500);
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
        .flat_map(|s| s.2.iter().filter_map(|p| p.2))
        .fold(0.0f64, f64::max);
    let min_pct = series
        .iter()
        .flat_map(|s| s.2.iter().filter_map(|p| p.1))
        .fold(100.0f64, f64::min);
    // %Segs from a multiple of 10 below the lowest value shown.
    let pct_min = ((min_pct - 5.0) / 10.0).floor().max(0.0) * 10.0;
    type Panel<'p, 'b> = (&'p Area<'b>, &'p str, f64, f64, bool);
    let panels: [Panel<'_, '_>; 2] = [
        (&left, "%Segs (segments that meet the target)", pct_min, 102.0, true),
        (&right, avg.as_str(), 0.0, (max_recall * 1.1).clamp(0.05, 1.0), false),
    ];
    let n = xs.len() as i32;
    for (area, y_desc, y_min, y_max, first) in panels {
        let mut chart = ChartBuilder::on(area)
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(60)
            .build_cartesian_2d(-1..n, y_min..y_max)
            .map_err(err)?;
        let fmt = |i: &i32| {
            usize::try_from(*i)
                .ok()
                .and_then(|i| xs.get(i).cloned())
                .unwrap_or_default()
        };
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .x_labels(xs.len() + 2)
            .x_label_formatter(&fmt)
            .y_label_formatter(&|y| if first { format!("{y:.0}") } else { format!("{y:.2}") })
            .axis_desc_style((FONT, 15))
            .label_style((FONT, 13))
            .bold_line_style(RGBColor(225, 225, 225))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(err)?;
        for (label, c, pts) in &series {
            let pts: Vec<(i32, f64)> = pts
                .iter()
                .filter_map(|&(x, p, r)| if first { p } else { r }.map(|y| (x, y)))
                .collect();
            let c = *c;
            let width = if label == "oracle" { 4 } else { 2 };
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(width)))
                .map_err(err)?;
            chart
                .draw_series(pts.into_iter().map(|p| Circle::new(p, 4, c.filled())))
                .map_err(err)?;
        }
    }
    // One legend for both panels, in rows underneath.
    let (mut x, mut y) = (80, 20);
    for (label, c, _) in &series {
        let width = 48 + (8 * label.len() as i32).max(60);
        if x + width > 1180 {
            (x, y) = (80, y + 24);
        }
        legend
            .draw(&PathElement::new(vec![(x, y), (x + 26, y)], c.stroke_width(3)))
            .map_err(err)?;
        legend.draw(&Circle::new((x + 13, y), 4, c.filled())).map_err(err)?;
        legend
            .draw(&Text::new(label.as_str(), (x + 34, y - 8), (FONT, 14)))
            .map_err(err)?;
        x += width;
    }
    Ok(())
}
