//! `qtvpr-cli threshold`: calibrate on one traverse, print thresholds for another.
//!
//! `--cal` is either a calibration similarity matrix (`.npy`, with its ground truth
//! from `--cal-gt...`) or a calibration file written by `calibrate` (an `.npz`, which
//! holds its ground truth, matching mode and default `k` and precision). The two are
//! told apart by the file's first bytes, not its name: a zip archive (`PK\x03\x04`) is a
//! calibration file, anything else is read as a `.npy` matrix.

use std::fmt::Write as _;
use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use qtvpr::{Calibration, Defaults, Matching, Params};
use serde::Serialize;

use crate::gt_source::OptionalCalGtSource;
use crate::output::{Format, emit};
use crate::{Global, progress};
use qtvpr::npy::{ScoresView, read_scores};

/// Arguments of `threshold`.
#[derive(Debug, Args)]
pub struct ThresholdArgs {
    /// Calibration similarity matrix (.npy, float32/float64), |DB| x |Qcal|; or a
    /// calibration file written by `calibrate` (.npz, told apart by its content), which
    /// holds its ground truth, matching mode and default k and precision.
    #[arg(long, value_name = "S_cal.npy|cal.npz")]
    cal: PathBuf,
    /// Calibration ground truth of a --cal matrix: --cal-gt, --cal-gt-tolerance or
    /// --cal-gt-db-positions (not with a calibration file).
    #[command(flatten)]
    cal_gt: OptionalCalGtSource,
    /// Deployment similarity matrix (.npy), |DB| x |Qval|; needs no ground truth.
    #[arg(long, value_name = "S_val.npy")]
    val: PathBuf,
    /// Calibration queries sampled per deployment query (clipped to |Qcal|). The paper
    /// gives no value; 10 is this project's default [default: 10, or the calibration
    /// file's].
    #[arg(long)]
    k: Option<usize>,
    /// Target precision tau, in (0, 1] [default: 1.0, or the calibration file's].
    #[arg(long, allow_negative_numbers = true)]
    precision: Option<f64>,
    /// single: one decision per query on its best match; multi: every entry is a
    /// candidate [default: single, or the calibration file's; another one is an error].
    #[arg(long, value_enum)]
    matching: Option<MatchingArg>,
    /// Deployment queries per segment (one threshold each; the last may be shorter).
    /// Default: all deployment queries form one segment.
    #[arg(long, value_name = "M")]
    segment_size: Option<usize>,
    /// Matrices are stored query-major, |Q| x |DB| (the VPR-Bench convention); a
    /// calibration file is |DB| x |Qcal| whatever this says.
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

#[derive(Serialize)]
struct Report {
    method: &'static str,
    params: ReportParams,
    segments: Vec<ReportSegment>,
    calibration_queries: usize,
    deployment_queries: usize,
    database_size: usize,
}

#[derive(Serialize)]
struct ReportParams {
    k: usize,
    precision: f64,
    matching: &'static str,
    segment_size: usize,
}

#[derive(Serialize)]
struct ReportSegment {
    start: usize,
    end: usize,
    quantile: f64,
    threshold: f64,
}

/// Whether `path` is a zip archive (a calibration file) rather than a `.npy`: by its
/// first bytes, whatever its name. A file that cannot be read is left to the reader
/// that follows, which names the problem.
pub fn is_calibration_file(path: &Path) -> bool {
    let mut magic = [0u8; 4];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut magic))
        .is_ok()
        && &magic == b"PK\x03\x04"
}

/// Run `threshold`.
pub fn run(args: &ThresholdArgs, global: &Global) -> Result<()> {
    let from_file = is_calibration_file(&args.cal);
    if from_file && let Some(source) = args.cal_gt.given() {
        bail!(
            "{}: --cal {} is a calibration file, which holds its own ground truth; \
             --cal-gt... is only for a --cal similarity matrix (.npy)",
            source.describe(),
            args.cal.display()
        );
    }
    let gt_source = match (from_file, args.cal_gt.given()) {
        (false, None) => bail!(
            "--cal {} is a similarity matrix, which needs its ground truth: give --cal-gt, \
             --cal-gt-tolerance or --cal-gt-db-positions (or a calibration file written by `calibrate` as --cal)",
            args.cal.display()
        ),
        (_, source) => source,
    };
    // Parameters first, so that a typo fails before any file is read (a calibration
    // file's defaults are checked once it is loaded).
    let params = |defaults: &Defaults| Params {
        k: args.k.unwrap_or(defaults.k),
        precision: args.precision.unwrap_or(defaults.precision),
        segment_size: args.segment_size,
    };
    params(&Defaults::default()).validate()?;
    // Errors about a file's content name the file; the flag says which input it was.
    // The core reports positions and shapes in its |DB| x |Q| views; give them back in
    // the files' orientation.
    let oriented = |e: qtvpr::Error| if args.query_major { e.transposed() } else { e };
    let s_val = read_scores(&args.val).context("--val")?;
    let s_val = orient(s_val.view(), args.query_major);
    // The calibration inputs are dropped (and unmapped) once the calibration is built.
    let cal = match gt_source {
        None => {
            let cal = Calibration::load(&args.cal).context("--cal")?;
            if let Some(m) = args.matching.map(Matching::from)
                && m != cal.matching()
            {
                bail!(
                    "--matching {}: --cal {} was calibrated for {} matching",
                    m.as_str(),
                    args.cal.display(),
                    cal.matching().as_str()
                );
            }
            cal
        }
        Some(gt_source) => {
            let matching = args.matching.map_or(Matching::Single, Matching::from);
            let s_cal = read_scores(&args.cal).context("--cal")?;
            let s_cal = orient(s_cal.view(), args.query_major);
            let gt = gt_source.load(s_cal.dim(), args.query_major)?;
            with_view!(s_cal, |v| Calibration::new(v, &gt, matching))
                .map_err(oriented)
                .with_context(|| format!("--cal {} / {}", args.cal.display(), gt_source.describe()))?
        }
    };
    let matching = cal.matching();
    let params = params(cal.defaults());
    let bar = progress::bar(global.quiet, s_val.dim().1, "deployment queries");
    let transfer = with_view!(s_val, |v| cal
        .transfer_with_progress(v, &params, |done, _| bar.set_position(done as u64)))
    .map_err(oriented)
    .with_context(|| format!("--val {}", args.val.display()))?;
    bar.finish_and_clear();

    let (n_db, n_val) = s_val.dim();
    let report = Report {
        method: "quantile-transfer",
        params: ReportParams {
            k: params.k,
            precision: params.precision,
            matching: matching.as_str(),
            segment_size: args.segment_size.unwrap_or(n_val),
        },
        segments: transfer
            .segments
            .iter()
            .map(|s| ReportSegment {
                start: s.start,
                end: s.end,
                quantile: s.quantile,
                threshold: s.threshold,
            })
            .collect(),
        calibration_queries: cal.len(),
        deployment_queries: n_val,
        database_size: n_db,
    };
    let text = match args.format {
        Format::Json => serde_json::to_string_pretty(&report)? + "\n",
        Format::Csv => {
            let mut t = String::from("start,end,quantile,threshold\n");
            for s in &report.segments {
                writeln!(t, "{},{},{},{}", s.start, s.end, s.quantile, s.threshold)?;
            }
            t
        }
    };
    emit(&text, args.output.as_deref())
}

/// |DB| x |Q| whatever the stored orientation.
pub fn orient(s: ScoresView<'_>, query_major: bool) -> ScoresView<'_> {
    if query_major { s.t() } else { s }
}
