//! `qtvpr-cli threshold`: calibrate on one traverse, print thresholds for another.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use qtvpr::{Calibration, Matching, Params, Segment};
use serde::Serialize;

use crate::gt_source::CalGtSource;
use crate::output::{Format, emit};
use crate::{Global, progress};
use qtvpr::npy::read_scores;
use qtvpr::with_scores;

/// Arguments of `threshold`.
#[derive(Debug, Args)]
pub struct ThresholdArgs {
    /// Calibration similarity matrix (.npy, float32/float64), |DB| x |Qcal|.
    #[arg(long, value_name = "S_cal.npy")]
    cal: PathBuf,
    /// Calibration ground truth: --cal-gt, --cal-gt-tolerance or --cal-gt-db-positions.
    #[command(flatten)]
    cal_gt: CalGtSource,
    /// Deployment similarity matrix (.npy), |DB| x |Qval|; needs no ground truth.
    #[arg(long, value_name = "S_val.npy")]
    val: PathBuf,
    /// Calibration queries sampled per deployment query (clipped to |Qcal|). The paper
    /// gives no value; 10 is this project's default.
    #[arg(long, default_value_t = qtvpr::DEFAULT_K)]
    k: usize,
    /// Target precision tau, in (0, 1].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    precision: f64,
    /// single: one decision per query on its best match; multi: every entry is a candidate.
    #[arg(long, value_enum, default_value_t = MatchingArg::Single)]
    matching: MatchingArg,
    /// Deployment queries per segment (one threshold each; the last may be shorter).
    /// Default: all deployment queries form one segment.
    #[arg(long, value_name = "M")]
    segment_size: Option<usize>,
    /// Matrices are stored query-major, |Q| x |DB| (the VPR-Bench convention).
    /// VPR-Bench files are query-major; a square matrix cannot be detected, so pass
    /// this flag for them.
    #[arg(long)]
    query_major: bool,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Json)]
    format: Format,
    /// Write to this file (atomically) instead of stdout.
    #[arg(long, short, value_name = "FILE")]
    output: Option<PathBuf>,
}

/// The `--matching` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MatchingArg {
    /// Single-best-match VPR (one decision per query).
    Single,
    /// Multi-match VPR (every non-ignored entry is a candidate).
    Multi,
}

impl From<MatchingArg> for Matching {
    fn from(m: MatchingArg) -> Self {
        match m {
            MatchingArg::Single => Matching::Single,
            MatchingArg::Multi => Matching::Multi,
        }
    }
}

/// The JSON document of `threshold` (keys: `qtvpr::report`): the core's parameters and
/// segments, with the sizes of the inputs.
#[derive(Serialize)]
struct Report<'a> {
    method: &'static str,
    params: ReportParams,
    segments: &'a [Segment],
    calibration_queries: usize,
    deployment_queries: usize,
    database_size: usize,
}

/// The transfer's [`Params`] (the segment size resolved) and the matching mode.
#[derive(Serialize)]
struct ReportParams {
    #[serde(flatten)]
    params: Params,
    matching: Matching,
}

/// Run `threshold`.
pub fn run(args: &ThresholdArgs, global: &Global) -> Result<()> {
    let matching = Matching::from(args.matching);
    let params = Params {
        k: args.k,
        precision: args.precision,
        segment_size: args.segment_size,
    };
    params.validate()?;
    // Errors about a file's content name the file; the flag says which input it was.
    // The core reports positions and shapes in its |DB| x |Q| views; `oriented` gives
    // them back in the files' orientation.
    let s_val = read_scores(&args.val).context("--val")?;
    let s_val = s_val.view().oriented(args.query_major);
    // The calibration inputs are dropped (and unmapped) once the calibration is built.
    let cal = {
        let s_cal = read_scores(&args.cal).context("--cal")?;
        let s_cal = s_cal.view().oriented(args.query_major);
        let gt_source = args.cal_gt.source().expect("clap requires one ground-truth source");
        let gt = gt_source.load(s_cal.dim(), args.query_major)?;
        with_scores!(s_cal, |v| Calibration::new(v, &gt, matching))
            .map_err(|e| e.oriented(args.query_major))
            .with_context(|| format!("--cal {} / {}", args.cal.display(), gt_source.describe()))?
    };
    let bar = progress::bar(global.quiet, s_val.dim().1, "deployment queries");
    let transfer = with_scores!(s_val, |v| cal
        .transfer_with_progress(v, &params, |done, _| bar.set_position(done as u64)))
    .map_err(|e| query_major_hint(e.oriented(args.query_major), args.query_major))
    .with_context(|| format!("--val {}", args.val.display()))?;
    bar.finish_and_clear();

    let (n_db, n_val) = s_val.dim();
    let report = Report {
        method: "quantile-transfer",
        params: ReportParams {
            params: Params {
                segment_size: Some(params.segment_size.unwrap_or(n_val)),
                ..params
            },
            matching,
        },
        segments: &transfer.segments,
        calibration_queries: cal.len(),
        deployment_queries: n_val,
        database_size: n_db,
    };
    let text = match args.format {
        Format::Json => serde_json::to_string_pretty(&report)? + "\n",
        Format::Csv => {
            let mut t = String::from("start,end,quantile,threshold\n");
            for s in report.segments {
                writeln!(t, "{},{},{},{}", s.start, s.end, s.quantile, s.threshold)?;
            }
            t
        }
    };
    emit(&text, args.output.as_deref())
}

/// A database mismatch of files not declared query-major is often a pair of query-major
/// files (|Q| x |DB|) whose query counts differ: say so.
fn query_major_hint(err: qtvpr::Error, query_major: bool) -> anyhow::Error {
    match err {
        qtvpr::Error::DatabaseMismatch { .. } if !query_major => anyhow::anyhow!(
            "{err}; if the files are query-major (|Q| x |DB|, as VPR-Bench stores them), pass --query-major"
        ),
        err => err.into(),
    }
}
