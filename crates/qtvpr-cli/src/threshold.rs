//! `qtvpr-cli threshold`: calibrate on one traverse, print thresholds for another.
//!
//! `--cal` is either a calibration similarity matrix (`.npy`, with its ground truth
//! from `--cal-gt...`) or a calibration file written by `calibrate` (an `.npz`, which
//! holds its ground truth, matching mode and default `k` and precision). The two are
//! told apart by the file's bytes, not its name ([`qtvpr::npy::is_zip_archive`]): a zip
//! archive is a calibration file, anything else is read as a `.npy` matrix.
//!
//! In place of `--cal` and `--val`, one `--similarity` matrix or descriptor files
//! (`--db-descriptors`, `--query-descriptors`) may be split by `--cal-queries` /
//! `--cal-fraction` (the rule of `evaluate`, [`qtvpr::Split::calibration_size`]): the
//! first queries calibrate, the rest are thresholded. From descriptors the deployment
//! similarity is computed chunk by chunk by the core
//! ([`qtvpr::ScoreSource::Descriptors`]) and never held whole.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use qtvpr::ThresholdReport;
use qtvpr::{Calibration, Defaults, Matching, Options, Params, QuerySplit, ScoreSource};

use crate::args::{DescriptorFiles, MatchingArg, SplitArgs};
use crate::gt_source::OptionalCalGtSource;
use crate::output::{Format, emit};
use crate::{Global, calibrate, progress};
use qtvpr::npy::read_scores;

/// Arguments of `threshold`.
#[derive(Debug, Args)]
pub struct ThresholdArgs {
    /// Calibration similarity matrix (.npy, float32/float64), |DB| x |Qcal|; or a
    /// calibration file written by `calibrate` (.npz, told apart by its content), which
    /// holds its ground truth, matching mode and default k and precision.
    #[arg(long, value_name = "S_cal.npy|cal.npz", conflicts_with_all = ["similarity", "split"])]
    cal: Option<PathBuf>,
    /// Calibration ground truth of a --cal matrix: --cal-gt, --cal-gt-tolerance or
    /// --cal-gt-db-positions (not with a calibration file). With --cal-queries or
    /// --cal-fraction it labels every query (|DB| x |Q|, as `evaluate`'s --gt): only
    /// the calibration queries' columns are used.
    #[command(flatten)]
    cal_gt: OptionalCalGtSource,
    /// Deployment similarity matrix (.npy), |DB| x |Qval|; needs no ground truth.
    #[arg(long, value_name = "S_val.npy", requires = "cal", conflicts_with_all = ["similarity", "db_descriptors"])]
    val: Option<PathBuf>,
    /// One similarity matrix (.npy), |DB| x |Q|, in place of --cal and --val: the first
    /// queries (--cal-queries or --cal-fraction) calibrate, the rest are thresholded.
    #[arg(long, value_name = "S.npy", requires = "split", conflicts_with = "db_descriptors")]
    similarity: Option<PathBuf>,
    /// Database descriptors (.npy, float32/float64), |DB| x D, in place of similarity
    /// matrices: the similarity (cosine of L2-normalised rows, as `similarity` computes
    /// it) is computed chunk by chunk and never written. With --cal-queries or
    /// --cal-fraction the first queries calibrate; with a --cal calibration file every
    /// query is thresholded.
    #[arg(
        long,
        value_name = "DB.npy",
        requires = "query_descriptors",
        conflicts_with = "query_major"
    )]
    db_descriptors: Option<PathBuf>,
    /// Query descriptors (.npy), |Q| x D, with --db-descriptors.
    #[arg(long, value_name = "Q.npy", requires = "db_descriptors")]
    query_descriptors: Option<PathBuf>,
    /// In place of --cal: how many of the first queries calibrate.
    #[command(flatten)]
    split: SplitArgs,
    /// Not available in `threshold`, which never holds a whole similarity matrix:
    /// write the sequence-matched matrix with `similarity --sequence L` and pass it as
    /// --similarity (or --cal and --val), or use `evaluate --sequence L`.
    #[arg(long, value_name = "L", allow_negative_numbers = true, hide = true)]
    sequence: Option<i64>,
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
    /// `margin`: also calibrate the margin gate m* (single matching only; see
    /// docs/semantics.md section 13): a deployed best match is then accepted only if its
    /// score is at or above its segment's threshold and its margin at or above m*
    /// [default: a calibration file's, else none].
    #[arg(long, value_parser = crate::args::gate_parser())]
    gate: Option<qtvpr::Gate>,
    /// Matrices are stored query-major, |Q| x |DB| (the VPR-Bench convention).
    /// VPR-Bench files are query-major; a square matrix cannot be detected, so pass
    /// this flag for them. A calibration file is |DB| x |Qcal| whatever this says.
    #[arg(long)]
    query_major: bool,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Json)]
    format: Format,
    /// Write to this file (atomically) instead of stdout.
    #[arg(long, short, value_name = "FILE")]
    output: Option<PathBuf>,
}

/// Run `threshold`.
pub fn run(args: &ThresholdArgs, global: &Global) -> Result<()> {
    if args.sequence.is_some() {
        bail!(
            "--sequence: `threshold` does not sequence-match, as it never holds the whole similarity \
             matrix; write the sequence-matched matrix with `qtvpr-cli similarity --sequence L` and pass it \
             as --similarity (or --cal/--val), or evaluate it with `evaluate --sequence L`"
        );
    }
    let split = args.split.split()?;
    let descriptors_arg = args.db_descriptors.as_ref().zip(args.query_descriptors.as_ref());
    if args.val.is_none() && args.similarity.is_none() && descriptors_arg.is_none() {
        bail!(
            "no deployment similarity: give --cal and --val, one --similarity with --cal-queries or \
             --cal-fraction, or --db-descriptors and --query-descriptors"
        );
    }
    if split.is_none() && args.cal.is_none() {
        bail!(
            "no calibration: give --cal (a similarity matrix or a calibration file), or --cal-queries or \
             --cal-fraction to calibrate on the first queries of the descriptors"
        );
    }
    let from_file = args.cal.as_deref().is_some_and(qtvpr::npy::is_zip_archive);
    if from_file && let Some(source) = args.cal_gt.source() {
        bail!(
            "{}: --cal {} is a calibration file, which holds its own ground truth; \
             --cal-gt... is only for a --cal similarity matrix (.npy)",
            source.describe(),
            args.cal.as_deref().unwrap_or(Path::new("")).display()
        );
    }
    let gt_source = match (from_file, args.cal_gt.source()) {
        (false, None) => match &args.cal {
            Some(cal) => {
                // Not a calibration file may be no file at all: say so, naming it.
                qtvpr::npy::open_input(cal).context("--cal")?;
                bail!(
                    "--cal {} is a similarity matrix, which needs its ground truth: give --cal-gt, \
                     --cal-gt-tolerance or --cal-gt-db-positions (or a calibration file written by `calibrate` as --cal)",
                    cal.display()
                )
            }
            None => bail!(
                "the calibration queries need their ground truth: give --cal-gt, --cal-gt-tolerance or \
                 --cal-gt-db-positions"
            ),
        },
        (_, source) => source,
    };
    // Parameters first, so that a typo fails before any file is read (a calibration
    // file's defaults are checked once it is loaded).
    let params = |defaults: &Defaults| Params::resolve(defaults, args.k, args.precision, args.segment_size, args.gate);
    params(&Defaults::default())?;
    let matching_arg = args.matching.map_or(Matching::Single, Matching::from);
    // Errors about a file's content name the file; the flag says which input it was.
    // The inputs stay where they are read (memory-mapped); `source` views them.
    let matrix_arg =
        (args.val.as_ref().map(|p| ("--val", p))).or(args.similarity.as_ref().map(|p| ("--similarity", p)));
    let (matrix, files, descriptors);
    let (source, input): (ScoreSource<'_, '_>, String) = match (matrix_arg, descriptors_arg) {
        (Some((flag, path)), _) => {
            matrix = read_scores(path).context(flag)?;
            files = None;
            let source = matrix.view().oriented(args.query_major).into();
            (source, format!("{flag} {}", path.display()))
        }
        (None, Some((db, q))) => {
            files = Some(DescriptorFiles::read(db, q)?);
            let read = files.as_ref().expect("just read");
            descriptors = read.descriptors()?;
            (ScoreSource::from(&descriptors), read.describe())
        }
        (None, None) => unreachable!("checked above"),
    };
    // A core error, named in the inputs' terms: a descriptor file by its option, a
    // matrix position in the file's orientation.
    let explain = |e: qtvpr::Error| match &files {
        Some(files) => files.blame(e),
        None => crate::args::oriented(e, args.query_major),
    };
    let (n_db, n_q) = source.dim();

    // The calibration, and the deployment queries: all of them, or those after the split;
    // and what ground truth read from files says of the matrices' orientation.
    let mut evidence = None;
    let (cal, queries, split) = match split {
        Some((split, flag)) => {
            let split = QuerySplit::new(split, (n_db, n_q))
                .map_err(|e| crate::args::oriented(e, args.query_major))
                .with_context(|| format!("{flag} of {input}"))?;
            let gt_source = gt_source.expect("a split needs ground truth, checked above");
            let (gt_cal, gt) = gt_source.load_split_read(&split, args.query_major, &input)?;
            evidence = gt.as_ref().map(qtvpr::Evidence::of);
            // Nothing here saves it: a calibration that keeps neither its scores nor its
            // ground truth, which it drops once it has its candidates.
            let cal = Calibration::for_transfer(source.columns(split.calibration()), gt_cal, matching_arg)
                .map_err(explain)
                .with_context(|| format!("{input} / {}", gt_source.describe()))?;
            (cal, split.deployment(), Some(split))
        }
        None => {
            let cal_path = args.cal.as_deref().expect("checked above");
            let cal = match gt_source {
                None => {
                    let cal = Calibration::load(cal_path).context("--cal")?;
                    if let Some(m) = args.matching.map(Matching::from)
                        && m != cal.matching()
                    {
                        bail!(
                            "--matching {}: --cal {} was calibrated for {} matching",
                            m.as_str(),
                            cal_path.display(),
                            cal.matching().as_str()
                        );
                    }
                    cal
                }
                Some(gt_source) => {
                    let (cal, orientation) =
                        calibrate::from_matrix(cal_path, gt_source, matching_arg, args.query_major)?;
                    evidence = orientation.evidence;
                    cal
                }
            };
            (cal, 0..n_q, None)
        }
    };
    // What was assumed of a matrix's orientation (descriptors have but one).
    let orientation = files.is_none().then(|| qtvpr::Orientation {
        evidence,
        ..qtvpr::Orientation::new((n_db, n_q), args.query_major)
    });
    let params = params(cal.defaults())?;
    cal.check_gate(params.gate).context("--gate")?;
    let bar = progress::bar(global.quiet, queries.len(), "deployment queries");
    let progress = |done: usize, _| bar.set_position(done as u64);
    let transfer = cal
        .transfer(source.columns(queries), Options::new(params).progress(&progress))
        // A split's deployment columns are a view: errors count the matrix's columns.
        .map_err(|e| match &split {
            Some(split) => split.deployment_error(e),
            None => e,
        })
        .map_err(explain)
        .with_context(|| input.clone())?;
    bar.finish_and_clear();

    // Warned once the result stands, so that a failure stays one `error:` line.
    if let Some(o) = &orientation {
        crate::args::warn_orientation(o);
    }
    let report = ThresholdReport {
        orientation,
        ..ThresholdReport::new(&cal, &params, &transfer)
    };
    let text = match args.format {
        Format::Json => serde_json::to_string_pretty(&report)? + "\n",
        Format::Csv => {
            let gate = report.gate.map(|m| format!(",{m}")).unwrap_or_default();
            let mut t = String::from("start,end,quantile,threshold");
            t += if gate.is_empty() { "\n" } else { ",gate\n" };
            for s in report.segments {
                writeln!(t, "{},{},{},{}{gate}", s.start, s.end, s.quantile, s.threshold)?;
            }
            t
        }
    };
    emit(&text, args.output.as_deref())
}
