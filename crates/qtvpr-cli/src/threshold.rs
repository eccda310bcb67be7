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
use qtvpr::npy::{MatrixFile, read_scores};
use qtvpr::{
    Calibration, Defaults, Descriptors, Matching, Options, Orientation, Params, ScoreSource, Split, SplitError,
    ThresholdReport, Transfer,
};

use crate::args::{DescriptorFiles, MatchingArg, SequenceGateArgs, SplitArgs};
use crate::gt_source::{GtSource, OptionalCalGtSource};
use crate::output::{Format, emit};
use crate::{Global, calibrate, progress};

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
    /// Not available in `threshold`: a calibration file of `calibrate --sequence L`
    /// matches --val causally itself; otherwise write the sequence-matched matrix with
    /// `similarity --sequence L` and pass it as --similarity (or --cal and --val), or use
    /// `evaluate --sequence L`.
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
    /// `margin`: also calibrate the margin gate m* (semantics §13): a deployed best
    /// match is then accepted only if its score is at or above its segment's threshold
    /// and its margin at or above m*. `sequence`: the sequence gate (semantics §15), each
    /// query's consistency with the previous queries (in column order; with
    /// --cal-queries from the first query of the matrix) and its level are reported; a
    /// best match is accepted only if its consistency reaches the level too.
    /// `margin,sequence`: both. Single matching only [default: a calibration file's,
    /// else none].
    #[arg(long, value_parser = crate::args::gate_parser())]
    gate: Option<qtvpr::Gate>,
    #[command(flatten)]
    sequence_gate: SequenceGateArgs,
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

/// Run `threshold`: resolve the request, then run it.
pub fn run(args: &ThresholdArgs, global: &Global) -> Result<()> {
    Request::new(args)?.run(global)
}

/// What `threshold` was asked, resolved from its arguments once (ripgrep's low-args to
/// high-args): where the calibration and the deployment queries come from, and the
/// parameters given. Every check that needs no file is made here, before any is read;
/// [`Request::run`] then only reads, computes and writes.
struct Request<'a> {
    args: &'a ThresholdArgs,
    calibration: CalibrationInput<'a>,
    deployment: DeploymentInput<'a>,
}

/// Where the calibration comes from.
enum CalibrationInput<'a> {
    /// A calibration file written by `calibrate` (`--cal cal.npz`).
    File(&'a Path),
    /// A similarity matrix and its ground truth (`--cal S_cal.npy --cal-gt...`).
    Matrix(&'a Path, GtSource<'a>),
    /// The first queries of the deployment input (`--cal-queries` / `--cal-fraction`,
    /// the option that asked), with ground truth of every query.
    Split(Split, &'static str, GtSource<'a>),
}

/// Where the deployment queries' scores come from.
#[derive(Clone, Copy)]
enum DeploymentInput<'a> {
    /// A similarity matrix: `--val` or `--similarity` (the option) and its file.
    Matrix(&'static str, &'a Path),
    /// `--db-descriptors` and `--query-descriptors`.
    Descriptors(&'a Path, &'a Path),
}

impl<'a> Request<'a> {
    /// The request of `args`, checked as far as it can be without reading a file (a
    /// calibration file is told apart by its first bytes).
    fn new(args: &'a ThresholdArgs) -> Result<Self> {
        if args.sequence.is_some() {
            bail!(
                "--sequence: `threshold` takes the sequence length of its calibration file (`calibrate --sequence \
                 L`), which matches --val causally; otherwise write the sequence-matched matrix with `qtvpr-cli \
                 similarity --sequence L` and pass it as --similarity (or --cal/--val), or evaluate it with \
                 `evaluate --sequence L`"
            );
        }
        let split = args.split.split()?;
        let matrix =
            (args.val.as_ref().map(|p| ("--val", p))).or(args.similarity.as_ref().map(|p| ("--similarity", p)));
        let descriptors = args.db_descriptors.as_ref().zip(args.query_descriptors.as_ref());
        let deployment = match (matrix, descriptors) {
            (Some((flag, path)), _) => DeploymentInput::Matrix(flag, path),
            (None, Some((db, q))) => DeploymentInput::Descriptors(db, q),
            (None, None) => bail!(
                "no deployment similarity: give --cal and --val, one --similarity with --cal-queries or \
                 --cal-fraction, or --db-descriptors and --query-descriptors"
            ),
        };
        if split.is_none() && args.cal.is_none() {
            bail!(
                "no calibration: give --cal (a similarity matrix or a calibration file), or --cal-queries or \
                 --cal-fraction to calibrate on the first queries of the descriptors"
            );
        }
        let from_file = args.cal.as_deref().is_some_and(qtvpr::npy::is_zip_archive);
        let calibration = match (split, args.cal.as_deref(), from_file, args.cal_gt.source()) {
            (_, Some(cal), true, Some(source)) => bail!(
                "{}: --cal {} is a calibration file, which holds its own ground truth; \
                 --cal-gt... is only for a --cal similarity matrix (.npy)",
                source.describe(),
                cal.display()
            ),
            (_, Some(cal), true, None) => CalibrationInput::File(cal),
            (_, Some(cal), false, None) => {
                // Not a calibration file may be no file at all: say so, naming it.
                qtvpr::npy::open_input(cal).context("--cal")?;
                bail!(
                    "--cal {} is a similarity matrix, which needs its ground truth: give --cal-gt, \
                     --cal-gt-tolerance or --cal-gt-db-positions (or a calibration file written by `calibrate` as --cal)",
                    cal.display()
                )
            }
            (_, Some(cal), false, Some(source)) => CalibrationInput::Matrix(cal, source),
            (Some(_), None, _, None) => bail!(
                "the calibration queries need their ground truth: give --cal-gt, --cal-gt-tolerance or \
                 --cal-gt-db-positions"
            ),
            (Some((split, flag)), None, _, Some(source)) => CalibrationInput::Split(split, flag, source),
            (None, None, ..) => unreachable!("checked above"),
        };
        let request = Self {
            args,
            calibration,
            deployment,
        };
        // Parameters first, so that a typo fails before any file is read (a calibration
        // file's defaults are checked once it is loaded).
        request.params(&Defaults::default())?;
        Ok(request)
    }

    /// The parameters given, each left out taking `defaults`' value (a calibration's).
    fn params(&self, defaults: &Defaults) -> Result<Params> {
        let a = self.args;
        Ok(Params::resolve(
            defaults,
            a.k,
            a.precision,
            a.segment_size,
            a.gate,
            a.sequence_gate.overrides(),
        )?)
    }

    /// The matching asked for (single when none is).
    fn matching(&self) -> Matching {
        self.args.matching.map_or(Matching::Single, Matching::from)
    }

    /// Read the inputs, calibrate, transfer, and write the report.
    fn run(&self, global: &Global) -> Result<()> {
        let args = self.args;
        // The inputs stay where they are read (memory-mapped); `source` views them.
        let read = Read::new(self.deployment)?;
        let descriptors = read.descriptors()?;
        let (source, input) = match (&read, &descriptors) {
            (Read::Matrix(flag, path, file), _) => (
                ScoreSource::from(file.view().oriented(args.query_major)),
                format!("{flag} {}", path.display()),
            ),
            (Read::Descriptors(files), Some(d)) => (ScoreSource::from(d), files.describe()),
            (Read::Descriptors(_), None) => unreachable!("read with the files"),
        };
        // A core error, named in the inputs' terms: a descriptor file by its option, a
        // matrix position in the file's orientation.
        let explain = |e: qtvpr::Error| match &read {
            Read::Descriptors(files) => files.blame(e),
            Read::Matrix(..) => crate::args::oriented(e, args.query_major),
        };
        let (n_db, n_q) = source.dim();

        // What ground truth read from files says of the matrices' orientation.
        let mut evidence = None;
        let (cal, params, transfer) = match &self.calibration {
            CalibrationInput::Split(split, flag, gt_source) => {
                let split = crate::args::query_split((*split, *flag), (n_db, n_q), args.query_major, &input)?;
                let (gt_cal, gt) = gt_source.load_split_read(&split, args.query_major, &input)?;
                evidence = gt.as_ref().map(qtvpr::Evidence::of);
                // Nothing here saves it: a calibration of the split's own defaults.
                let params = self.params(&Defaults::default())?;
                qtvpr::check_gate(params.gate, &params.sequence_gate, self.matching(), n_db).context("--gate")?;
                let bar = progress::bar(global.quiet, split.deployment().len(), "deployment queries");
                let progress = |done: usize, _| bar.set_position(done as u64);
                let options = Options::new(params).progress(&progress);
                let (cal, transfer) =
                    split
                        .transfer(source, gt_cal, self.matching(), options)
                        .map_err(|e| match e {
                            SplitError::Calibration(e) => {
                                explain(e).context(format!("{input} / {}", gt_source.describe()))
                            }
                            SplitError::Deployment(e) => explain(e).context(input.clone()),
                        })?;
                bar.finish_and_clear();
                (cal, params, transfer)
            }
            CalibrationInput::File(path) => {
                let cal = Calibration::load(path).context("--cal")?;
                if let Some(m) = args.matching.map(Matching::from)
                    && m != cal.matching()
                {
                    bail!(
                        "--matching {}: --cal {} was calibrated for {} matching",
                        m.as_str(),
                        path.display(),
                        cal.matching().as_str()
                    );
                }
                self.transfer(cal, source, global, &input, explain)?
            }
            CalibrationInput::Matrix(path, gt_source) => {
                let (cal, orientation) =
                    calibrate::from_matrix(path, *gt_source, self.matching(), args.query_major, 1)?;
                evidence = orientation.evidence;
                self.transfer(cal, source, global, &input, explain)?
            }
        };

        // What was assumed of a matrix's orientation (descriptors have but one); warned
        // once the result stands, so that a failure stays one `error:` line.
        let orientation = matches!(read, Read::Matrix(..)).then(|| Orientation {
            evidence,
            ..Orientation::new((n_db, n_q), args.query_major)
        });
        if let Some(o) = &orientation {
            crate::args::warn_orientation(o);
        }
        let report = ThresholdReport {
            orientation,
            ..ThresholdReport::new(&cal, &params, &transfer)
        };
        emit(&text(&report, args.format)?, args.output.as_deref())
    }

    /// The transfer of every deployment query of `source` on `cal`, at the parameters
    /// given and `cal`'s defaults.
    fn transfer(
        &self,
        cal: Calibration,
        source: ScoreSource<'_, '_>,
        global: &Global,
        input: &str,
        explain: impl Fn(qtvpr::Error) -> anyhow::Error,
    ) -> Result<(Calibration, Params, Transfer)> {
        let params = self.params(cal.defaults())?;
        cal.check_gate(params.gate, &params.sequence_gate).context("--gate")?;
        let bar = progress::bar(global.quiet, source.dim().1, "deployment queries");
        let progress = |done: usize, _| bar.set_position(done as u64);
        let transfer = cal
            .transfer(source, Options::new(params).progress(&progress))
            .map_err(explain)
            .with_context(|| input.to_string())?;
        bar.finish_and_clear();
        Ok((cal, params, transfer))
    }
}

/// The deployment input, read: a matrix (mapped where possible) or descriptor files.
enum Read<'a> {
    Matrix(&'static str, &'a Path, MatrixFile),
    Descriptors(DescriptorFiles),
}

impl<'a> Read<'a> {
    fn new(input: DeploymentInput<'a>) -> Result<Self> {
        Ok(match input {
            DeploymentInput::Matrix(flag, path) => Read::Matrix(flag, path, read_scores(path).context(flag)?),
            DeploymentInput::Descriptors(db, q) => Read::Descriptors(DescriptorFiles::read(db, q)?),
        })
    }

    /// The descriptors of descriptor files, checked by the core.
    fn descriptors(&self) -> Result<Option<Descriptors<'_>>> {
        match self {
            Read::Matrix(..) => Ok(None),
            Read::Descriptors(files) => files.descriptors().map(Some),
        }
    }
}

/// The report as `format` writes it.
fn text(report: &ThresholdReport<'_>, format: Format) -> Result<String> {
    Ok(match format {
        Format::Json => serde_json::to_string_pretty(report)? + "\n",
        Format::Csv => {
            // A gate's level, the same on every segment's row.
            let levels = [("gate", report.gate), ("consistency_level", report.consistency_level)];
            let (mut header, mut cells) = (String::from("start,end,quantile,threshold"), String::new());
            for (name, level) in levels {
                if let Some(level) = level {
                    write!(header, ",{name}")?;
                    write!(cells, ",{level}")?;
                }
            }
            let mut t = header + "\n";
            for s in report.segments {
                writeln!(t, "{},{},{},{}{cells}", s.start, s.end, s.quantile, s.threshold)?;
            }
            t
        }
    })
}
