//! `qtvpr-cli ground-truth`: a ground-truth matrix from a frame tolerance, from
//! positions, from image names carrying positions, or from a calibration traverse's own
//! order (self-motion labels, semantics §16), written as `.npy` (hard; soft to
//! `--soft-output`) or as a VPR_Tutorial `.npz` (`GThard`, `GTsoft`; with self-motion
//! labels also their record, `labels`). The arithmetic is the core's
//! ([`qtvpr::within_tolerance`], [`qtvpr::within_radius`], [`qtvpr::self_motion_labels`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{ArgGroup, Args};
use ndarray::{Array2, ArrayView2};
use qtvpr::npy::{matrix_shape, read_scores, write_ground_truth};
use qtvpr::{HardSoft, LabelParams, with_scores};

use crate::gt_source::{GtSource, Kind};
use crate::output::{emit, write_npy};
use qtvpr::DEFAULT_IMAGE_RADIUS;

/// The help heading of the self-motion labels' options.
const SELF_MOTION: &str = "Self-motion labels (--from-sequence; semantics §16)";

/// The sources other than `--from-sequence`, which its options conflict with. (Not
/// `requires = "from_sequence"`: clap does not enforce a requirement of one member of
/// the source group while another is given, and these options have defaults.)
const OTHER_SOURCES: [&str; 3] = ["tolerance", "db_positions", "db_images"];

/// The options of the other sources, which `--from-sequence` conflicts with.
const OTHER_OPTIONS: [&str; 6] = [
    "soft_tolerance",
    "like",
    "db_count",
    "query_count",
    "radius",
    "soft_radius",
];

/// Arguments of `ground-truth`.
#[derive(Debug, Args)]
#[command(group(ArgGroup::new("source").required(true).args(["tolerance", "db_positions", "db_images", "from_sequence"])))]
#[command(group(ArgGroup::new("places").args(["db_positions", "db_images"])))]
#[command(group(ArgGroup::new("shape").args(["like", "db_count"])))]
pub struct GroundTruthArgs {
    /// Frame-aligned traverses (Nordland, SFU, Oxford): database image i matches query j
    /// when |i - j| <= N. Needs the shape: --like, or --db-count and --query-count.
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    tolerance: Option<i64>,
    /// Soft ground truth by tolerance M >= N.
    #[arg(long, value_name = "M", allow_negative_numbers = true, requires = "tolerance")]
    soft_tolerance: Option<i64>,
    /// With --tolerance: take |DB| x |Q| from this similarity matrix (.npy; only its
    /// header is read).
    #[arg(long, value_name = "S.npy", requires = "tolerance")]
    like: Option<PathBuf>,
    /// With --tolerance: the number of database images.
    #[arg(long, value_name = "N", requires_all = ["tolerance", "query_count"])]
    db_count: Option<usize>,
    /// With --tolerance: the number of queries.
    #[arg(long, value_name = "M", requires = "db_count")]
    query_count: Option<usize>,
    /// Database positions (.npy, float32/float64, |DB| x 2 or |DB| x 3, e.g. UTM east,
    /// north): a query matches database image i when within --radius of it.
    #[arg(long, value_name = "DB.npy", requires_all = ["query_positions", "radius"])]
    db_positions: Option<PathBuf>,
    /// Query positions (.npy), |Q| x 2 or |Q| x 3.
    #[arg(long, value_name = "Q.npy", requires = "db_positions")]
    query_positions: Option<PathBuf>,
    /// Match radius, in the unit of the positions: distance <= R (inclusive). With
    /// --db-images, in metres, default 25.
    #[arg(long, value_name = "R", allow_negative_numbers = true, requires = "places")]
    radius: Option<f64>,
    /// Soft ground truth by radius R2 >= R.
    #[arg(long, value_name = "R2", allow_negative_numbers = true, requires = "places")]
    soft_radius: Option<f64>,
    /// Database images whose names carry UTM positions (@utm_east@utm_north@...@.jpg):
    /// a directory (its .jpg/.jpeg/.png files at any depth, sorted by path, as
    /// VPR-methods-evaluation orders its descriptors; or the lines of DIR_images_paths.txt
    /// next to it) or a text file of one path per line. One row of the output each.
    #[arg(long, value_name = "LIST", requires = "query_images")]
    db_images: Option<PathBuf>,
    /// Query images (a directory or a text file), one column of the output each.
    #[arg(long, value_name = "LIST", requires = "db_images")]
    query_images: Option<PathBuf>,
    /// Calibrate without ground truth: label calibration queries from their similarity
    /// alone (.npy, float32/float64, |DB| x |Qcal|, its columns in the order the queries
    /// were taken). A query's best match is a positive when its neighbours on the
    /// traverse agree with it (their best matches lie on its line through the database),
    /// wrong when few do, ignored (soft only) in between. Assumes both traverses are
    /// sequences in the same direction at a similar spacing (else --sequence-speed).
    /// Prints the counts on stderr; for `calibrate --cal S_cal.npy --cal-gt GT.npz`.
    #[arg(long, value_name = "S_cal.npy", conflicts_with_all = OTHER_OPTIONS, help_heading = SELF_MOTION)]
    from_sequence: Option<PathBuf>,
    /// The similarity is stored query-major, |Qcal| x |DB| (VPR-Bench); the ground truth
    /// is written in the same layout.
    #[arg(long, conflicts_with_all = OTHER_SOURCES, help_heading = SELF_MOTION)]
    query_major: bool,
    /// The neighbours on each side a best match is judged by.
    #[arg(long, value_name = "N", default_value_t = qtvpr::DEFAULT_NEIGHBOURS, conflicts_with_all = OTHER_SOURCES, help_heading = SELF_MOTION)]
    neighbours: usize,
    /// The share of agreeing neighbours at or above which a best match is a positive.
    #[arg(long, value_name = "P", default_value_t = qtvpr::DEFAULT_POSITIVE_LEVEL, allow_negative_numbers = true, conflicts_with_all = OTHER_SOURCES, help_heading = SELF_MOTION)]
    positive_level: f64,
    /// The share at or below which it is wrong (between the levels: ignored).
    #[arg(long, value_name = "Q", default_value_t = qtvpr::DEFAULT_NEGATIVE_LEVEL, allow_negative_numbers = true, conflicts_with_all = OTHER_SOURCES, help_heading = SELF_MOTION)]
    negative_level: f64,
    /// Database rows per query: 1 for the same spacing, 2 for queries twice as far
    /// apart, -1 for the database's route driven backwards.
    #[arg(long, value_name = "V", default_value_t = qtvpr::DEFAULT_SPEED, allow_negative_numbers = true, conflicts_with_all = OTHER_SOURCES, help_heading = SELF_MOTION)]
    sequence_speed: f64,
    /// How far from its predicted row a neighbour one step away may lie, in rows.
    #[arg(long, value_name = "A", default_value_t = qtvpr::DEFAULT_TOLERANCE, allow_negative_numbers = true, conflicts_with_all = OTHER_SOURCES, help_heading = SELF_MOTION)]
    sequence_tolerance: f64,
    /// How much that tolerance widens per step away, in rows per step.
    #[arg(long, value_name = "B", default_value_t = qtvpr::DEFAULT_DRIFT, allow_negative_numbers = true, conflicts_with_all = OTHER_SOURCES, help_heading = SELF_MOTION)]
    sequence_drift: f64,
    /// What to print of the labels.
    #[arg(long, value_enum, default_value_t = Summary::Text, conflicts_with_all = OTHER_SOURCES, help_heading = SELF_MOTION)]
    format: Summary,
    /// Where to write: GT.npy (bool, |DB| x |Q|; a soft ground truth goes to
    /// --soft-output) or GT.npz (VPR_Tutorial: GThard and, if asked for, GTsoft; with
    /// --from-sequence also `labels`, the record `calibrate` keeps, which .npy files
    /// cannot carry). Written atomically.
    #[arg(long, short, value_name = "GT.npy|GT.npz")]
    output: PathBuf,
    /// With a .npy --output: where to write the soft ground truth.
    #[arg(long, value_name = "GTsoft.npy")]
    soft_output: Option<PathBuf>,
}

/// What `ground-truth --from-sequence` prints of its labels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Summary {
    /// One line on stderr: how many queries are positive, negative and abstained.
    Text,
    /// That line, and on stdout the labels' record: the rule, its parameters and the
    /// counts, one JSON object, as the .npz's member `labels` holds it.
    Json,
}

/// Run `ground-truth`.
pub fn run(args: &GroundTruthArgs) -> Result<()> {
    let npz = args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    let has_soft = args.soft_tolerance.is_some() || args.soft_radius.is_some() || args.from_sequence.is_some();
    match (npz, has_soft, &args.soft_output) {
        (true, _, Some(_)) => bail!("--soft-output is for a .npy --output; a .npz --output holds GTsoft itself"),
        (false, true, None) if args.from_sequence.is_some() => bail!(
            "self-motion labels have a soft ground truth (the best matches of the queries that abstain): give \
             --soft-output GTsoft.npy, or an --output ending in .npz"
        ),
        (false, true, None) => {
            bail!("a soft ground truth needs --soft-output GTsoft.npy, or an --output ending in .npz")
        }
        (false, false, Some(_)) => bail!("--soft-output needs --soft-tolerance or --soft-radius"),
        _ => {}
    }
    if let Some(path) = &args.from_sequence {
        return from_sequence(args, path, npz);
    }
    write(args, npz, &source(args)?, None)
}

/// Write ground truth (in the layout of its similarity: transposed for
/// `--query-major`) to `--output`, and its soft ground truth to the `.npz` or to
/// `--soft-output`; `record`, of self-motion labels, goes into the `.npz` only.
fn write(args: &GroundTruthArgs, npz: bool, gt: &HardSoft, record: Option<&qtvpr::LabelRecord>) -> Result<()> {
    fn layout(m: &Array2<bool>, query_major: bool) -> ArrayView2<'_, bool> {
        if query_major { m.t() } else { m.view() }
    }
    let hard = layout(&gt.hard, args.query_major);
    let soft = gt.soft.as_ref().map(|s| layout(s, args.query_major));
    if npz {
        return write_ground_truth(&args.output, hard, soft, record).context("--output");
    }
    write_npy(&args.output, "--output", hard)?;
    match (soft, &args.soft_output) {
        (Some(soft), Some(path)) => write_npy(path, "--soft-output", soft),
        _ => Ok(()),
    }
}

/// `--from-sequence`: the core's self-motion labels of the calibration similarity at
/// `path`, written, and their counts printed (and their record, for `--format json`).
fn from_sequence(args: &GroundTruthArgs, path: &Path, npz: bool) -> Result<()> {
    let params = LabelParams::resolve(
        Some(args.neighbours),
        Some(args.positive_level),
        Some(args.negative_level),
        Some(args.sequence_speed),
        Some(args.sequence_tolerance),
        Some(args.sequence_drift),
    )?;
    let input = || format!("--from-sequence {}", path.display());
    let s = read_scores(path).with_context(input)?;
    let s = s.view().oriented(args.query_major);
    let labels = with_scores!(s, |s| qtvpr::self_motion_labels(s, &params))
        .map_err(|e| crate::args::oriented(e, args.query_major))
        .with_context(input)?;
    let record = labels.record();
    write(args, npz, &labels.ground_truth(), Some(&record))?;
    eprintln!("{labels}");
    match args.format {
        Summary::Text => Ok(()),
        Summary::Json => emit(&format!("{}\n", record.json()), None),
    }
}

/// The tolerance or positions as a [`GtSource`] without a prefix, made into ground
/// truth as `threshold` and `evaluate` make theirs.
fn source(args: &GroundTruthArgs) -> Result<HardSoft> {
    if let Some(hard) = args.tolerance {
        let source = GtSource {
            prefix: "",
            kind: Kind::Tolerance {
                hard,
                soft: args.soft_tolerance,
            },
        };
        let shape = match (&args.like, args.db_count, args.query_count) {
            (Some(like), _, _) => matrix_shape(like).with_context(|| format!("--like {}", like.display()))?,
            (None, Some(n_db), Some(n_q)) => (n_db, n_q),
            _ => bail!("--tolerance needs the shape |DB| x |Q|: --like S.npy, or --db-count N --query-count M"),
        };
        return source.matrices(Some(shape));
    }
    if let (Some(db), Some(queries)) = (&args.db_images, &args.query_images) {
        let source = GtSource {
            prefix: "",
            kind: Kind::Images {
                db,
                queries,
                radius: args.radius.unwrap_or(DEFAULT_IMAGE_RADIUS),
                soft_radius: args.soft_radius,
            },
        };
        return source.matrices(None);
    }
    let (Some(db), Some(queries), Some(radius)) = (&args.db_positions, &args.query_positions, args.radius) else {
        bail!("--db-positions, --query-positions and --radius go together");
    };
    let source = GtSource {
        prefix: "",
        kind: Kind::Positions {
            db,
            queries,
            radius,
            soft_radius: args.soft_radius,
        },
    };
    source.matrices(None)
}
