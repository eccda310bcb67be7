//! `thresholds.svg`: each method's per-segment threshold against the oracle's, and the
//! TP, FP and FN of every segment underneath.

use super::*;

pub(super) const THRESHOLD_HEIGHT: u32 = 480;
/// Three rows of legend entries.
pub(super) const LEGEND_HEIGHT: u32 = 72;
pub(super) const STRIP_HEIGHT: u32 = 130;

pub(super) fn thresholds(root: &Area<'_>, ctx: &RunContext, run: &Run) -> Result<()> {
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
    let centres = |inf: &dyn Fn(&qtvpr::SegmentResult) -> bool, m: &MethodResult| -> Vec<f64> {
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
    for m in drawing_order(methods.iter().copied()) {
        for pts in finite_runs(m.segments.iter().map(|g| (g.start as f64, g.end as f64, g.threshold))) {
            draw_line(chart.plotting_area(), line_style(m.method), pts)?;
        }
    }
    let mut entries: Vec<(Swatch, String)> = methods
        .iter()
        .map(|m| (line_style(m.method), m.method.as_str().to_string()))
        .collect();
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
    // Each half has its own scale, so that a few FPs show next to a hundred FNs.
    let (ticks, up, down) = mirrored_counts(up_max, down_max);
    let failed = m.segments.iter().filter(|g| g.counts.positives > 0 && !g.meets).count();
    let caption = format!(
        "{}: %Segs {}, AvgR {}, {} of {} counted segments below precision {}; {} matches accepted",
        m.method,
        m.pct_segs.map_or("n/a".into(), |v| format!("{v:.1}")),
        m.avg_recall.map_or("n/a".into(), |v| format!("{v:.3}")),
        failed,
        m.segments_counted,
        fmt_num(tau),
        m.pooled().accepted()
    );
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FONT, 15).into_font().color(&colour(m.method)))
        .margin_left(10)
        .margin_right(20)
        .x_label_area_size(20)
        .y_label_area_size(75)
        .build_cartesian_2d(0.0..end, ticked(-1.1..1.1, ticks))
        .map_err(err)?;
    chart
        .configure_mesh()
        .y_desc("FN | TP+FP")
        .axis_desc_style((FONT, 12))
        .label_style((FONT, 12))
        .y_label_formatter(&|v| mirrored_label(*v, up, down))
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
