//! `qtvpr-cli calibrate`: check a calibration traverse and write it as a calibration
//! file, once, offline, for `stream` and `threshold` (and `qtvpr.Calibration.load`) to
//! use.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use qtvpr::{Calibration, Defaults, Matching};

use crate::gt_source::CalGtSource;
use crate::threshold::{MatchingArg, orient};
use qtvpr::npy::read_scores;

/// Arguments of `calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Calibration similarity matrix (.npy, float32/float64), |DB| x |Qcal|.
    #[arg(long, value_name = "S_cal.npy")]
    cal: PathBuf,
    /// Calibration ground truth: --cal-gt, --cal-gt-tolerance or --cal-gt-db-positions.
    #[command(flatten)]
    cal_gt: CalGtSource,
    /// single: one decision per query on its best match; multi: every entry is a candidate.
    #[arg(long, value_enum, default_value_t = MatchingArg::Single)]
    matching: MatchingArg,
    /// Default k stored in the file: calibration queries sampled per deployment query.
    #[arg(long, default_value_t = qtvpr::DEFAULT_K)]
    k: usize,
    /// Default target precision tau stored in the file, in (0, 1].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    precision: f64,
    /// Default window stored in the file: the queries each online threshold is taken
    /// over (`stream --window`). Default: none, so `stream` then needs --window.
    #[arg(long, value_name = "M")]
    window: Option<usize>,
    /// Matrices are stored query-major, |Q| x |DB| (the VPR-Bench convention); the file
    /// holds |DB| x |Qcal| whatever the input's orientation.
    #[arg(long)]
    query_major: bool,
    /// The calibration file to write (.npz), atomically.
    #[arg(long, short, value_name = "cal.npz")]
    output: PathBuf,
}

/// Run `calibrate`.
pub fn run(args: &CalibrateArgs) -> Result<()> {
    let defaults = Defaults {
        k: args.k,
        precision: args.precision,
        window: args.window,
    };
    defaults.validate()?;
    let matching = Matching::from(args.matching);
    let s_cal = read_scores(&args.cal).context("--cal")?;
    let s_cal = orient(s_cal.view(), args.query_major);
    let gt_source = args.cal_gt.source();
    let gt = gt_source.load(s_cal.dim(), args.query_major)?;
    let cal = with_view!(s_cal, |v| Calibration::new(v, &gt, matching))
        .map_err(|e| if args.query_major { e.transposed() } else { e })
        .with_context(|| format!("--cal {} / {}", args.cal.display(), gt_source.describe()))?;
    cal.save(&args.output, &defaults).context("--output")
}
