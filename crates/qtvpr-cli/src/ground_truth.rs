//! `qtvpr-cli ground-truth`: a ground-truth matrix from a frame tolerance or from
//! positions, written as `.npy` (hard; soft to `--soft-output`) or as a VPR_Tutorial
//! `.npz` (`GThard`, `GTsoft`). The arithmetic is the core's
//! ([`qtvpr::ground_truth`]).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{ArgGroup, Args};
use ndarray::Array2;
use qtvpr::ground_truth::{DB_POSITIONS, QUERY_POSITIONS, check_radius, within_tolerance};

use crate::gt_source::{check_soft, frames, positions_within, read_positions};
use crate::matrix_io::{shape, write_npy, write_npz};

/// Arguments of `ground-truth`.
#[derive(Debug, Args)]
#[command(group(ArgGroup::new("source").required(true).args(["tolerance", "db_positions"])))]
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
    /// Match radius, in the unit of the positions: distance <= R (inclusive).
    #[arg(long, value_name = "R", allow_negative_numbers = true, requires = "db_positions")]
    radius: Option<f64>,
    /// Soft ground truth by radius R2 >= R.
    #[arg(long, value_name = "R2", allow_negative_numbers = true, requires = "radius")]
    soft_radius: Option<f64>,
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
    let (hard, soft) = match args.tolerance {
        Some(tolerance) => from_tolerance(args, tolerance)?,
        None => from_positions(args)?,
    };
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

type HardSoft = (Array2<bool>, Option<Array2<bool>>);

fn from_tolerance(args: &GroundTruthArgs, tolerance: i64) -> Result<HardSoft> {
    let hard = frames("--tolerance", tolerance)?;
    let soft = args
        .soft_tolerance
        .map(|soft| {
            check_soft("--tolerance", tolerance as f64, "--soft-tolerance", soft as f64)?;
            frames("--soft-tolerance", soft)
        })
        .transpose()?;
    let (n_db, n_q) = match (&args.like, args.db_count, args.query_count) {
        (Some(like), _, _) => shape(like).with_context(|| format!("--like {}", like.display()))?,
        (None, Some(n_db), Some(n_q)) => (n_db, n_q),
        _ => bail!("--tolerance needs the shape |DB| x |Q|: --like S.npy, or --db-count N --query-count M"),
    };
    let gt = |t: usize| within_tolerance(n_db, n_q, t).context("--like / --db-count / --query-count");
    Ok((gt(hard)?, soft.map(gt).transpose()?))
}

fn from_positions(args: &GroundTruthArgs) -> Result<HardSoft> {
    let (Some(db), Some(queries), Some(radius)) = (&args.db_positions, &args.query_positions, args.radius) else {
        bail!("--db-positions, --query-positions and --radius go together");
    };
    check_radius("radius", radius).context("--radius")?;
    if let Some(soft) = args.soft_radius {
        check_radius("soft radius", soft).context("--soft-radius")?;
        check_soft("--radius", radius, "--soft-radius", soft)?;
    }
    let db_flag = format!("--db-positions {}", db.display());
    let q_flag = format!("--query-positions {}", queries.display());
    let (db_pos, q_pos) = read_positions(db, queries, &db_flag, &q_flag)?;
    let sources = [(DB_POSITIONS, db_flag), (QUERY_POSITIONS, q_flag)];
    let hard = positions_within(&db_pos, &q_pos, radius, &sources)?;
    let soft = args
        .soft_radius
        .map(|soft| positions_within(&db_pos, &q_pos, soft, &sources))
        .transpose()?;
    Ok((hard, soft))
}
