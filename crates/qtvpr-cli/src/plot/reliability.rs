//! `reliability.svg`: the reliability diagram of the confidence (semantics §14) over
//! the deployment decisions: per bin of the ECE, the observed hit rate against the mean
//! confidence, with the diagonal of perfect calibration.
//!
//! The bins are the core's ([`qtvpr::Signals::bins`]), the ones its ECE is
//! computed from; this module only draws them.

use qtvpr::Signals;

use super::*;

pub(super) const RELIABILITY_HEIGHT: u32 = 620;
/// Legend rows under the chart, and the note under them.
pub(super) const RELIABILITY_BELOW: u32 = 2 * 22 + 4 + 40;

const POINT_COLOUR: RGBColor = RGBColor(31, 119, 180);
const DIAGONAL_COLOUR: RGBColor = RGBColor(110, 110, 110);
const DIAGONAL_DASH: (u32, u32) = (6, 5);

pub(super) fn reliability(root: &Area<'_>, ctx: &RunContext, signals: &Signals) -> Result<()> {
    let (chart_area, below) = root.split_vertically(RELIABILITY_HEIGHT);
    let figures = match (signals.ece, signals.brier) {
        (Some(ece), Some(brier)) => format!("ECE {ece:.3}, Brier {brier:.3}"),
        _ => "no confidence".to_string(),
    };
    let (ticks, decimals) = nice_ticks(0.0, 1.0, 6);
    // A little room beyond [0, 1], so that a marker at 0 or 1 is drawn whole.
    let range = -0.03..1.03;
    let mut chart = ChartBuilder::on(&chart_area)
        .caption(
            format!("Reliability of the confidence on the deployment set ({figures})"),
            (FONT, 20),
        )
        .margin(15)
        .x_label_area_size(50)
        .y_label_area_size(60)
        .build_cartesian_2d(ticked(range.clone(), ticks.clone()), ticked(range, ticks))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(format!(
            "mean confidence of the bin (10 equal-width bins of [0, 1]; {})",
            dataset_label(ctx)
        ))
        .y_desc("observed hit rate of the bin")
        .x_label_formatter(&|x| format!("{x:.decimals$}"))
        .y_label_formatter(&|y| format!("{y:.decimals$}"))
        .axis_desc_style((FONT, 16))
        .label_style((FONT, 14))
        .bold_line_style(RGBColor(225, 225, 225))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(err)?;
    chart
        .draw_series(DashedLineSeries::new(
            [(0.0, 0.0), (1.0, 1.0)],
            DIAGONAL_DASH.0,
            DIAGONAL_DASH.1,
            ShapeStyle::from(&DIAGONAL_COLOUR).stroke_width(1),
        ))
        .map_err(err)?;
    let bins = signals.bins.as_deref().unwrap_or_default();
    chart
        .draw_series(LineSeries::new(
            bins.iter().map(|b| (b.mean_confidence, b.hit_rate)),
            POINT_COLOUR.stroke_width(2),
        ))
        .map_err(err)?;
    let label_style = TextStyle::from((FONT, 13).into_font()).pos(Pos::new(HPos::Left, VPos::Bottom));
    for b in bins {
        draw_marker(
            chart.plotting_area(),
            Shape::Circle,
            (b.mean_confidence, b.hit_rate),
            6,
            POINT_COLOUR,
        )?;
        // The count up and to the right of its point; left of it near the right edge.
        let (offset, style) = if b.mean_confidence > 0.85 {
            ((-8, -6), label_style.pos(Pos::new(HPos::Right, VPos::Bottom)))
        } else {
            ((8, -6), label_style.clone())
        };
        chart
            .plotting_area()
            .draw(
                &(EmptyElement::at((b.mean_confidence, b.hit_rate)) + Text::new(format!("n = {}", b.n), offset, style)),
            )
            .map_err(err)?;
    }
    let entries = [
        (
            Swatch::Dashed(DIAGONAL_COLOUR, 1, DIAGONAL_DASH),
            "perfect calibration: hit rate = confidence".to_string(),
        ),
        (
            Swatch::LineMarker(POINT_COLOUR, 2, Shape::Circle),
            "a bin that holds decisions (n: how many)".to_string(),
        ),
    ];
    let (legend_area, note) = below.split_vertically(22 * entries.len() as u32 + 4);
    legend(&legend_area, &entries, 80, 880, Some(1))?;
    let text = if bins.is_empty() {
        "No confidence: the calibration has no decision whose best match is not soft-only.".to_string()
    } else {
        "Bins without a decision are left out. The ECE weighs each point's distance from the diagonal by its n."
            .to_string()
    };
    note.draw(&Text::new(text, (80, 5), (FONT, 13).into_font().color(&NOTE_COLOUR)))
        .map_err(err)?;
    Ok(())
}
