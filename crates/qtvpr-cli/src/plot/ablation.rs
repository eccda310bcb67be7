//! `ablation_k.svg` / `ablation_cal.svg`: %Segs and AvgR against k or the calibration
//! size.

use super::*;

#[derive(Clone, Copy, PartialEq)]
pub(super) enum Axis {
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

/// Where a run sits on the x axis: the value of its setting (k, or the calibration
/// fraction or count as given), on a log scale (the settings run from 1 to 40 or from
/// 0.01 to 0.5). Every point is drawn at its own setting.
fn position(run: &Run, axis: Axis) -> f64 {
    match axis {
        Axis::K => run.k as f64,
        Axis::Calibration => match run.calibration {
            qtvpr::Split::Fraction(f) => f,
            qtvpr::Split::Count(n) => n as f64,
        },
    }
    .ln()
}

/// Marker half-width of series `i` of `n`: the first drawn the largest, 2 pixels more
/// than the next, so that series at the same point show as nested markers (at most 11
/// pixels, at least 4).
fn marker_size(i: usize, n: usize) -> i32 {
    let step = if n > 1 { (7 / (n as i32 - 1)).min(2) } else { 0 };
    4 + step * (n - 1 - i) as i32
}

pub(super) fn ablation(root: &Area<'_>, ctx: &RunContext, runs: &[Run], axis: Axis) -> Result<()> {
    // The values along the axis, in the order given, and the series: one per method
    // when only this parameter varies, else quantile transfer once per other setting.
    let mut xs: Vec<(String, f64)> = vec![];
    for r in runs {
        let x = (setting_label(r, axis), position(r, axis));
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
    // (label, colour, marker, points of (x, %Segs, AvgR))
    type Series = (String, RGBColor, Shape, Vec<(f64, Option<f64>, Option<f64>)>);
    let mut series: Vec<Series> = vec![];
    let x_of = |r: &Run| position(r, axis);
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
    let (lo, hi) = xs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x.1), b.max(x.1)));
    let pad = if hi > lo { 0.07 * (hi - lo) } else { 0.5 };
    for (area, y_desc, y_min, y_max, first) in panels {
        let (ticks, decimals) = nice_ticks(y_min, y_max.min(if first { 100.0 } else { 1.0 }), 8);
        let at: Vec<f64> = xs.iter().map(|x| x.1).collect();
        let mut chart = ChartBuilder::on(area)
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(60)
            .build_cartesian_2d(ticked(lo - pad..hi + pad, at), ticked(y_min..y_max, ticks))
            .map_err(err)?;
        let fmt = |x: &f64| {
            let nearest = xs.iter().min_by(|a, b| (a.1 - x).abs().total_cmp(&(b.1 - x).abs()));
            nearest.map(|n| n.0.clone()).unwrap_or_default()
        };
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
            let pts: Vec<(f64, f64)> = pts
                .iter()
                .filter_map(|&(x, p, r)| if first { p } else { r }.map(|y| (x, y)))
                .collect();
            let width = if label == "oracle" { 3 } else { 2 };
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(width)))
                .map_err(err)?;
            for p in pts {
                draw_marker(chart.plotting_area(), *s, p, marker_size(i, series.len()), *c)?;
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
            "Each point is at its own setting (a log scale). Equal values share a point: each series' marker is \
             smaller than the one drawn before it.",
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
    fn markers_nest() {
        // 8 series: 7 / 7 = 1 -> min(1, 2) = 1 pixel apart, 11 down to 4; 3 series: 2
        // apart, 8, 6, 4; one series: 4.
        assert_eq!((marker_size(0, 8), marker_size(7, 8)), (11, 4));
        assert_eq!((0..3).map(|i| marker_size(i, 3)).collect::<Vec<_>>(), [8, 6, 4]);
        assert_eq!(marker_size(0, 1), 4);
    }
}
