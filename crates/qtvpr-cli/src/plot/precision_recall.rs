//! `precision_recall.svg`: the precision-recall curve of the deployment set, with each
//! method's operating point.

use super::*;

pub(super) const PR_HEIGHT: u32 = 670;

pub(super) fn precision_recall(root: &Area<'_>, ctx: &RunContext, run: &Run) -> Result<()> {
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
        .filter_map(|m| m.pooled().measured_precision())
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
        // A method that accepted nothing has no precision, hence no point to draw.
        let label = match p.measured_precision() {
            Some(precision) => {
                draw_marker(chart.plotting_area(), s, (p.recall(), precision), 8, c)?;
                format!(
                    "{}: precision {precision:.3}, recall {:.3} ({} accepted: TP {}, FP {})",
                    m.method,
                    p.recall(),
                    p.accepted(),
                    p.tp,
                    p.fp
                )
            }
            None => format!("{}: no match accepted, so no precision (not drawn)", m.method),
        };
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
