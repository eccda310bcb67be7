//! What a run of `evaluate` was and how to say it: the runs and their context, and the
//! captions and numbers that the table, the CSV and the figures share.

use std::fmt::Write as _;

use qtvpr::Evaluation;
use qtvpr::{Matching, Split};

/// One run of the protocol.
pub struct Run {
    /// The k of this run.
    pub k: usize,
    /// The calibration size as asked for (a fraction or a count).
    pub calibration: Split,
    /// The result.
    pub eval: Evaluation,
}

impl From<Evaluation> for Run {
    fn from(eval: Evaluation) -> Self {
        let p = eval.layout.protocol;
        Self {
            k: p.k,
            calibration: p.calibration,
            eval,
        }
    }
}

/// What the runs were made on, for captions.
pub struct RunContext {
    /// The dataset's name (a path or the embedded data's name).
    pub dataset: String,
    /// |DB|.
    pub database_size: usize,
    /// The precision target.
    pub precision: f64,
    /// Matching mode.
    pub matching: Matching,
    /// How a similarity file was read (`None` for descriptors and the embedded data).
    pub orientation: Option<qtvpr::Orientation>,
}

impl RunContext {
    /// `AvgR@100P` for tau = 1, `AvgR@90P` for 0.9, ...
    pub fn avg_recall_name(&self) -> String {
        format!("AvgR@{}P", fmt_num(self.precision * 100.0))
    }
}

/// A number without trailing zeros: 100, 90, 0.1.
pub fn fmt_num(x: f64) -> String {
    let s = format!("{:.6}", x);
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// The protocol in one line, for captions.
pub fn describe(ctx: &RunContext, run: &Run) -> String {
    let l = run.eval.layout;
    let used = l.segments * l.segment_size;
    let dropped = l.deployment_queries - used;
    let mut s = format!(
        "{}: {} database images x {} queries; queries 0..{} calibrate; {} segments of {} deployment queries \
         from query {}",
        ctx.dataset,
        ctx.database_size,
        l.queries,
        l.calibration_queries,
        l.segments,
        l.segment_size,
        l.deployment_start
    );
    if dropped > 0 {
        write!(s, " ({dropped} left over, dropped)").unwrap();
    }
    write!(
        s,
        "; k = {}, tau = {}, {} matching.",
        run.k,
        fmt_num(ctx.precision),
        ctx.matching.as_str()
    )
    .unwrap();
    s
}

/// What an ablation holds fixed: "queries a..b (n segments of s); tau = t, m matching"
/// (every run of an ablation shares its deployment set).
pub fn ablation_setting(ctx: &RunContext, run: &Run) -> String {
    let l = run.eval.layout;
    format!(
        "queries {}..{} ({} segments of {}); tau = {}, {} matching",
        l.deployment_start,
        l.queries,
        l.segments,
        l.segment_size,
        fmt_num(ctx.precision),
        ctx.matching.as_str()
    )
}
