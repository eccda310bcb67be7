//! `qtvpr-cli ground-truth`: a ground-truth matrix from a frame tolerance, from
//! positions or from image names carrying positions, written as `.npy` (hard; soft to `--soft-output`) or as a VPR_Tutorial
//! `.npz` (`GThard`, `GTsoft`). The arithmetic is the core's
//! ([`qtvpr::within_tolerance`], [`qtvpr::within_radius`]).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{ArgGroup, Args};
use qtvpr::HardSoft;
use qtvpr::npy::matrix_shape;

use crate::gt_source::{GtSource, Kind};
use crate::output::{write_npy, write_npz};
use qtvpr::DEFAULT_IMAGE_RADIUS;

/// Arguments of `ground-truth`.
#[derive(Debug, Args)]
#[command(group(ArgGroup::new("source").required(true).args(["tolerance", "db_positions", "db_images"])))]
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
    /// Where to write: GT.npy (bool, |DB| x |Q|; a soft ground truth goes to
    /// --soft-output) or GT.npz (VPR_Tutorial: GThard and, if asked for, GTsoft).
    /// Written atomically.
    #[arg(long, short, value_name = "GT.npy|GT.npz")]
    output: PathBuf,
    /// With a .npy --output: where to write the soft ground truth.
    #[arg(long, value_name = "GTsoft.npy")]
    soft_output: Option<PathBuf>,
}

/// Run `ground-truth`.
pub fn run(args: &GroundTruthArgs) -> Result<()> {
    let npz = args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    let has_soft = args.soft_tolerance.is_some() || args.soft_radius.is_some();
    match (npz, has_soft, &args.soft_output) {
        (true, _, Some(_)) => bail!("--soft-output is for a .npy --output; a .npz --output holds GTsoft itself"),
        (false, true, None) => {
            bail!("a soft ground truth needs --soft-output GTsoft.npy, or an --output ending in .npz")
        }
        (false, false, Some(_)) => bail!("--soft-output needs --soft-tolerance or --soft-radius"),
        _ => {}
    }
    let HardSoft { hard, soft } = source(args)?;
    if npz {
        let mut arrays = vec![("GThard", hard.view())];
        if let Some(soft) = &soft {
            arrays.push(("GTsoft", soft.view()));
        }
        write_npz(&args.output, "--output", &arrays)
    } else {
        write_npy(&args.output, "--output", hard.view())?;
        match (&soft, &args.soft_output) {
            (Some(soft), Some(path)) => write_npy(path, "--soft-output", soft.view()),
            _ => Ok(()),
        }
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
