//! `scores.svg`: how the deployment set's right and wrong best-match scores are spread,
//! and where each method's threshold cuts them (what a user of a threshold asks first:
//! how many wrong matches sit above it, how many right ones below).
//!
//! The bins and counts are the core's ([`qtvpr::Evaluation::score_histogram`]) and
//! each method's line is the lower median of its segments' thresholds
//! ([`qtvpr::MethodResult::median_threshold`]; semantics §8.7); this module only draws.

use qtvpr::{Matching, ScoreHistogram};

use super::*;

pub(super) const SCORES_HEIGHT: u32 = 560;
/// The legend's two bar rows, and the note under the method rows.
pub(super) const SCORES_BELOW: u32 = 22 + 4 + 50;

/// A method's entry in the legend, and whether its line is drawn: reject-all (`inf`)
/// and no score threshold (`-inf`) are not lines.
fn entry(m: &MethodResult, decimals: usize) -> (String, Option<f64>) {
    let segments = m.segments.len();
    let per = if segments == 1 { "segment" } else { "segments" };
    match m.median_threshold() {
        Some(t) if t == f64::INFINITY => (
            format!("{}: reject-all in most of its {segments} {per} (not drawn)", m.method),
            None,
        ),
        Some(t) if t == f64::NEG_INFINITY => (format!("{}: no score threshold (the gate alone)", m.method), None),
        Some(t) => (
            format!("{}: {t:.decimals$} (median of its {segments} {per})", m.method),
            Some(t),
        ),
        None => (format!("{}: no segment", m.method), None),
    }
}

pub(super) fn scores(root: &Area<'_>, ctx: &RunContext, run: &Run, h: &ScoreHistogram) -> Result<()> {
    let eval = &run.eval;
    let (chart_area, below) = root.split_vertically(SCORES_HEIGHT);
    let (first, last) = (h.edges[0], h.edges[h.edges.len() - 1]);
    // Two more decimals than the axis, so that thresholds close together read apart.
    let (_, decimals) = nice_ticks(first, last, 8);
    let decimals = decimals + 2;
    let methods: Vec<(&MethodResult, String, Option<f64>)> = eval
        .methods
        .iter()
        .map(|m| {
            let (label, t) = entry(m, decimals);
            (m, label, t)
        })
        .collect();
    // The axis spans the bins and every line drawn, a threshold above every score too.
    let (lo, hi) = methods
        .iter()
        .filter_map(|m| m.2)
        .fold((first, last), |(a, b), t| (a.min(t), b.max(t)));
    let margin = 0.02 * (hi - lo);
    let (lo, hi) = (lo - margin, hi + margin);
    let (x_ticks, x_decimals) = nice_ticks(lo, hi, 10);

    // Right above the axis, wrong below it, each on its own count scale (in multi
    // matching the wrong ones outnumber the right ones by about |DB|).
    let max = |v: &[usize]| v.iter().copied().max().unwrap_or(0);
    let (ticks, up, down) = mirrored_counts(max(&h.right), max(&h.wrong));
    // Above the bars, a row per method whose line is drawn, its marker at its threshold:
    // lines that coincide stay apart there.
    let drawn = methods.iter().filter(|m| m.2.is_some()).count();
    let (row, gap) = (0.1, 0.08);
    let lane_y = |i: usize| 1.1 + gap + (i as f64 + 0.5) * row;
    let top = 1.1 + gap + drawn as f64 * row;
    let (what, right, wrong) = match ctx.matching {
        Matching::Single => ("best-match scores", "right best matches", "wrong best matches"),
        Matching::Multi => ("candidate scores", "right candidates", "wrong candidates"),
    };
    let l = eval.layout;
    let mut chart = ChartBuilder::on(&chart_area)
        .caption(
            format!(
                "Deployment {what}, right and wrong, and each method's threshold ({} queries, {} matching)",
                l.segments * l.segment_size,
                ctx.matching.as_str()
            ),
            (FONT, 19),
        )
        .margin(15)
        .x_label_area_size(50)
        .y_label_area_size(75)
        .build_cartesian_2d(ticked(lo..hi, x_ticks), ticked(-1.1..top, ticks))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(format!("score ({} equal bins; {})", h.right.len(), dataset_label(ctx)))
        .y_desc(format!("{wrong} | {right}"))
        .x_label_formatter(&|x| format!("{x:.x_decimals$}"))
        .y_label_formatter(&|v| mirrored_label(*v, up, down))
        .axis_desc_style((FONT, 15))
        .label_style((FONT, 13))
        .bold_line_style(RGBColor(225, 225, 225))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(err)?;
    // A bar per bin that holds a score (an empty bin draws nothing).
    let bars = h
        .edges
        .windows(2)
        .zip(h.right.iter().zip(&h.wrong))
        .flat_map(|(e, (&r, &w))| {
            let right =
                (r > 0).then(|| Rectangle::new([(e[0], 0.0), (e[1], r as f64 / up)], TP_COLOUR.mix(0.85).filled()));
            let wrong = (w > 0)
                .then(|| Rectangle::new([(e[0], -(w as f64) / down), (e[1], 0.0)], FP_COLOUR.mix(0.85).filled()));
            right.into_iter().chain(wrong)
        });
    chart.draw_series(bars).map_err(err)?;
    chart
        .draw_series(std::iter::once(PathElement::new(
            vec![(lo, 0.0), (hi, 0.0)],
            BLACK.stroke_width(1),
        )))
        .map_err(err)?;
    let style = |m: Method| {
        if m == Method::Oracle {
            Swatch::Dashed(BLACK, 2, ORACLE_DASH)
        } else {
            line_style(m)
        }
    };
    let lanes: Vec<(Method, f64)> = methods.iter().filter_map(|m| m.2.map(|t| (m.0.method, t))).collect();
    for m in drawing_order(methods.iter().map(|m| m.0)) {
        if let Some(i) = lanes.iter().position(|l| l.0 == m.method) {
            let t = lanes[i].1;
            draw_line(chart.plotting_area(), style(m.method), vec![(t, -1.1), (t, lane_y(i))])?;
        }
    }
    for (i, &(m, t)) in lanes.iter().enumerate() {
        draw_marker(chart.plotting_area(), shape(m), (t, lane_y(i)), 6, colour(m))?;
    }

    let entries = [
        (Swatch::Block(TP_COLOUR), format!("{right} (up)")),
        (Swatch::Block(FP_COLOUR), format!("{wrong} (down; own scale)")),
    ];
    let (bars_area, rest) = below.split_vertically(26);
    legend(&bars_area, &entries, 80, 1180, Some(2))?;
    let entries: Vec<(Swatch, String)> = methods
        .iter()
        .map(|(m, label, t)| {
            let swatch = if t.is_some() {
                style(m.method).with_marker(shape(m.method))
            } else {
                Swatch::Empty
            };
            (swatch, label.clone())
        })
        .collect();
    let rows = (entries.len() as u32).div_ceil(2);
    let (methods_area, note) = rest.split_vertically(22 * rows + 4);
    legend(&methods_area, &entries, 80, 1180, Some(2))?;
    let text = match ctx.matching {
        Matching::Single => {
            "Right: the best match is a hard match; wrong: it is no match. A best match that is soft but not hard \
             makes no decision (semantics §2) and is in neither."
        }
        Matching::Multi => {
            "Every candidate that is not soft-only: right where the ground truth is hard, wrong where it is no match."
        }
    };
    note.draw(&Text::new(text, (80, 5), (FONT, 13).into_font().color(&NOTE_COLOUR)))
        .map_err(err)?;
    note.draw(&Text::new(
        "A method's line is the median of its per-segment thresholds: it accepts scores at or right of it that \
         its gates (if any) pass; its marker above the bars has a row of its own.",
        (80, 25),
        (FONT, 13).into_font().color(&NOTE_COLOUR),
    ))
    .map_err(err)?;
    Ok(())
}
