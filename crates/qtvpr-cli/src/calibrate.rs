//! `qtvpr-cli calibrate`: check a calibration traverse and write it as a calibration
//! file, once, offline, for `stream` and `threshold` (and `qtvpr.Calibration.load`) to
//! use.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use qtvpr::{Calibration, Defaults, Matching, Orientation, QuerySplit, ScoreSource, Split};

use crate::args::{DescriptorFiles, MatchingArg, SequenceGateArgs, SplitArgs, gate_parser};
use crate::gt_source::{CalGtSource, GtSource};
use qtvpr::npy::read_scores;

/// Arguments of `calibrate`.
#[derive(Debug, Args)]
#[command(group(
    clap::ArgGroup::new("cal-input")
        .args(["cal", "similarity", "db_descriptors"])
        .required(true)
        .multiple(false)
))]
pub struct CalibrateArgs {
    /// Calibration similarity matrix (.npy, float32/float64), |DB| x |Qcal|.
    #[arg(long, value_name = "S_cal.npy", conflicts_with = "split")]
    cal: Option<PathBuf>,
    /// One recorded traverse's similarity matrix (.npy), |DB| x |Q|, in place of --cal:
    /// its first queries (--cal-queries or --cal-fraction) calibrate, as `threshold
    /// --similarity` splits it; `stream --val S.npy` with the same split then decides
    /// the rest.
    #[arg(long, value_name = "S.npy", requires = "split")]
    similarity: Option<PathBuf>,
    /// Calibration ground truth: --cal-gt, --cal-gt-tolerance or --cal-gt-db-positions.
    /// With --similarity or descriptors it labels every query (|DB| x |Q|, as
    /// `evaluate`'s --gt); only the calibration queries' columns are used.
    #[command(flatten)]
    cal_gt: CalGtSource,
    /// Database descriptors (.npy, float32/float64), |DB| x D, in place of --cal: the
    /// calibration similarity (cosine of L2-normalised rows, bit for bit as `similarity`
    /// computes it) is computed in memory, never written.
    #[arg(
        long,
        value_name = "DB.npy",
        requires = "query_descriptors",
        conflicts_with = "query_major"
    )]
    db_descriptors: Option<PathBuf>,
    /// Query descriptors (.npy), |Q| x D, with --db-descriptors; every query calibrates
    /// unless --cal-queries or --cal-fraction says how many of the first ones do.
    #[arg(long, value_name = "Q.npy", requires = "db_descriptors")]
    query_descriptors: Option<PathBuf>,
    /// With --similarity (required) or descriptors (default: all): how many of the first
    /// queries calibrate.
    #[command(flatten)]
    split: SplitArgs,
    /// single: one decision per query on its best match; multi: every entry is a candidate.
    #[arg(long, value_enum, default_value_t = MatchingArg::Single)]
    matching: MatchingArg,
    /// Default k stored in the file: calibration queries sampled per deployment query.
    #[arg(long, default_value_t = qtvpr::DEFAULT_K)]
    k: usize,
    /// Default target precision tau stored in the file, in (0, 1].
    #[arg(long, default_value_t = qtvpr::DEFAULT_PRECISION, allow_negative_numbers = true)]
    precision: f64,
    /// Default window stored in the file: the queries each online threshold is taken
    /// over (`stream --window`). Default: none, so `stream` then needs --window.
    #[arg(long, value_name = "M")]
    window: Option<usize>,
    /// Default gate stored in the file: `margin` also requires each best match to stand
    /// out of its column by the margin the calibration calibrates (semantics §13);
    /// `sequence` requires the best matches of the previous queries to agree with it
    /// (semantics §15); `margin,sequence` both. Single matching only [default: none].
    #[arg(long, value_parser = gate_parser())]
    gate: Option<qtvpr::Gate>,
    /// Default sequence gate parameters stored in the file.
    #[command(flatten)]
    sequence_gate: SequenceGateArgs,
    /// Sequence length L (odd, >= 1; semantics §15): the calibration traverse is
    /// sequence-matched causally over L queries (`similarity --sequence L --causal`), and
    /// the file records L, so that `stream`, `threshold` and every front end match
    /// deployment columns the same way before deciding [default: 1, no matching].
    #[arg(long, value_name = "L", allow_negative_numbers = true)]
    sequence: Option<i64>,
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
    let defaults = Defaults::default().resolve(
        Some(args.k),
        Some(args.precision),
        args.window,
        args.gate,
        args.sequence_gate.overrides(),
    )?;
    let split = args.split.split()?;
    let length = crate::args::sequence(args.sequence, true)?.map_or(1, |s| s.length);
    let gt_source = args.cal_gt.source().expect("clap requires one ground-truth source");
    let matching = Matching::from(args.matching);
    let descriptors = args.db_descriptors.as_ref().zip(args.query_descriptors.as_ref());
    let (cal, orientation) = match (&args.cal, &args.similarity, split, descriptors) {
        (Some(path), ..) => {
            let (cal, orientation) = from_matrix(path, gt_source, matching, args.query_major, length)?;
            (cal, Some(orientation))
        }
        (None, Some(path), Some(split), _) => {
            let (cal, orientation) = from_split(path, split, gt_source, matching, args.query_major, length)?;
            (cal, Some(orientation))
        }
        (None, None, split, Some((db, q))) => (from_descriptors(db, q, split, gt_source, matching, length)?, None),
        _ => bail!(
            "give --cal, --similarity with --cal-queries or --cal-fraction, or --db-descriptors and \
             --query-descriptors"
        ),
    };
    // The gate is checked against the calibration (its matching) before the file is
    // touched, so that the error names the option, not the output.
    cal.check_defaults(&defaults).context("--gate")?;
    cal.save(&args.output, &defaults).context("--output")?;
    // Warned once the file is written, so that a failure stays one `error:` line.
    if let Some(o) = &orientation {
        crate::args::warn_orientation(o);
    }
    Ok(())
}

/// The calibration of the first queries (`split`, or all of them) of descriptor files
/// `db` and `q`, with ground truth for every query from `gt_source`, sequence-matched
/// over `length`.
fn from_descriptors(
    db: &Path,
    q: &Path,
    split: Option<(Split, &str)>,
    gt_source: GtSource<'_>,
    matching: Matching,
    length: usize,
) -> Result<Calibration> {
    let files = DescriptorFiles::read(db, q)?;
    let d = files.descriptors()?;
    let Some((split, flag)) = split else {
        // Every query calibrates.
        let gt = gt_source.load(d.shape(), false)?;
        return Calibration::new_sequence(&d, &gt, matching, length)
            .with_context(|| format!("{} / {}", files.describe(), gt_source.describe()));
    };
    let split = QuerySplit::new(split, d.shape()).with_context(|| format!("{flag} of {}", files.describe()))?;
    let gt = gt_source.load_split(&split, false, &files.describe())?;
    Calibration::new_sequence(ScoreSource::Descriptors(&d, split.calibration()), &gt, matching, length)
        .with_context(|| format!("{} / {}", files.describe(), gt_source.describe()))
}

/// The calibration of the first queries (`split`) of similarity matrix `--similarity
/// PATH`, with ground truth of every query from `gt_source`, and the matrix's
/// orientation with what ground truth read from a file says of it (as `threshold
/// --similarity` splits it: the core's [`QuerySplit`]).
fn from_split(
    path: &Path,
    split: (Split, &'static str),
    gt_source: GtSource<'_>,
    matching: Matching,
    query_major: bool,
    length: usize,
) -> Result<(Calibration, Orientation)> {
    let file = read_scores(path).context("--similarity")?;
    let s = file.view().oriented(query_major);
    let input = format!("--similarity {}", path.display());
    let split = crate::args::query_split(split, s.dim(), query_major, &input)?;
    let (gt_cal, gt) = gt_source.load_split_read(&split, query_major, &input)?;
    let cal = Calibration::new_sequence(
        ScoreSource::from(s).columns(split.calibration()),
        &gt_cal,
        matching,
        length,
    )
    .map_err(|e| crate::args::oriented(e, query_major))
    .with_context(|| format!("{input} / {}", gt_source.describe()))?;
    Ok((cal, Orientation::of(s.dim(), gt.as_ref(), query_major)))
}

/// The calibration of similarity matrix `--cal PATH` with its ground truth from
/// `gt_source`, and the matrix's orientation with what ground truth read from a file
/// says of it; errors name the files, with positions in their own orientation. The
/// matrix is unmapped once the calibration is built. A `length` above 1 matches it
/// causally first (semantics §15).
pub fn from_matrix(
    path: &Path,
    gt_source: GtSource<'_>,
    matching: Matching,
    query_major: bool,
    length: usize,
) -> Result<(Calibration, Orientation)> {
    let s_cal = read_scores(path).context("--cal")?;
    let s_cal = s_cal.view().oriented(query_major);
    let gt = gt_source.load(s_cal.dim(), query_major)?;
    let cal = Calibration::new_sequence(s_cal, &gt, matching, length)
        .map_err(|e| crate::args::oriented(e, query_major))
        .with_context(|| format!("--cal {} / {}", path.display(), gt_source.describe()))?;
    let orientation = Orientation::of(s_cal.dim(), gt_source.is_file().then_some(&gt), query_major);
    Ok((cal, orientation))
}
