//! Where a command's ground truth comes from: a file, a frame tolerance, or positions.
//!
//! Ground truth is rarely at hand as a matrix. Every command that needs it takes one of
//! three sources, exactly one of them (a clap `ArgGroup`):
//!
//! | source | options (prefix `P`, e.g. `cal-gt` or `gt`) |
//! |---|---|
//! | a file | `--P GT.npy\|GT.npz [--P-soft GTsoft.npy]` |
//! | frame-aligned traverses, `\|i - j\| <= N` | `--P-tolerance N [--P-soft-tolerance M]` |
//! | positions, distance `<= R` | `--P-db-positions DB.npy --P-query-positions Q.npy --P-radius R [--P-soft-radius R2]` |
//!
//! The options are one flattenable clap `Args` struct per prefix, made by
//! [`gt_source_args!`], so that `threshold` (`--cal-gt...`) and any other command
//! (e.g. `evaluate`, `--gt...`) share names, checks and messages:
//!
//! ```ignore
//! gt_source_args!(
//!     /// Ground truth of the evaluated queries.
//!     EvalGtSource, "gt", "--s"
//! );
//! #[derive(clap::Args)]
//! struct EvaluateArgs {
//!     #[command(flatten)]
//!     gt: EvalGtSource,
//!     // ...
//! }
//! // Then, with the similarity matrix read and oriented |DB| x |Q|:
//! let gt = args.gt.source().load(s.dim(), args.query_major)?;
//! ```

use std::path::Path;

use anyhow::{Context, Result, bail};
use qtvpr::GroundTruth;
use qtvpr::ground_truth::{DB_POSITIONS, QUERY_POSITIONS, check_radius, within_radius, within_tolerance};

use crate::matrix_io::{blame, read_rows};
use qtvpr::npy::{Scores, read_ground_truth};

/// Declare a flattenable clap `Args` struct named `$name` with the ground-truth source
/// options under the long-option prefix `$prefix` (see the [module docs](self)).
/// `$matrix` names the option of the similarity matrix the ground truth labels, for
/// help texts.
///
/// With `, required = false` at the end, the source may be left out: use
/// [`given`](CalGtSource::given) then, not `source`.
macro_rules! gt_source_args {
    ($(#[$doc:meta])* $name:ident, $prefix:literal, $matrix:literal) => {
        gt_source_args!($(#[$doc])* $name, $prefix, $matrix, required = true);
    };
    ($(#[$doc:meta])* $name:ident, $prefix:literal, $matrix:literal, required = $required:literal) => {
        $(#[$doc])*
        #[derive(Debug, Clone, clap::Args)]
        #[group(skip)]
        #[command(group(
            clap::ArgGroup::new(concat!($prefix, "-source"))
                .required($required)
                .multiple(false)
                .args(["gt", "gt_tolerance", "gt_db_positions"])
        ))]
        pub struct $name {
            #[arg(
                long = $prefix,
                value_name = "GT.npy|GT.npz",
                help = concat!(
                    "Ground truth of ", $matrix, ": .npy (bool or 0/1 integers, same shape), or a ",
                    "VPR_Tutorial .npz with GThard and optional GTsoft"
                )
            )]
            gt: Option<std::path::PathBuf>,
            #[arg(
                long = concat!($prefix, "-soft"),
                value_name = "GTsoft.npy",
                requires = "gt",
                help = "Soft ground truth (.npy): entries soft but not hard are ignored"
            )]
            gt_soft: Option<std::path::PathBuf>,
            #[arg(
                long = concat!($prefix, "-tolerance"),
                value_name = "N",
                allow_negative_numbers = true,
                help = concat!(
                    "Instead of a file: frame-aligned traverses, database image i matches query j ",
                    "(column j of ", $matrix, ") when |i - j| <= N"
                )
            )]
            gt_tolerance: Option<i64>,
            #[arg(
                long = concat!($prefix, "-soft-tolerance"),
                value_name = "M",
                allow_negative_numbers = true,
                requires = "gt_tolerance",
                help = "Soft ground truth by frame tolerance M >= N"
            )]
            gt_soft_tolerance: Option<i64>,
            #[arg(
                long = concat!($prefix, "-db-positions"),
                value_name = "DB.npy",
                requires_all = ["gt_query_positions", "gt_radius"],
                help = concat!(
                    "Instead of a file: database positions (.npy, float, |DB| x 2 or x 3, e.g. UTM ",
                    "east, north); a match is within the radius"
                )
            )]
            gt_db_positions: Option<std::path::PathBuf>,
            #[arg(
                long = concat!($prefix, "-query-positions"),
                value_name = "Q.npy",
                requires = "gt_db_positions",
                help = concat!("Query positions (.npy, one row per column of ", $matrix, ")")
            )]
            gt_query_positions: Option<std::path::PathBuf>,
            #[arg(
                long = concat!($prefix, "-radius"),
                value_name = "R",
                allow_negative_numbers = true,
                requires = "gt_db_positions",
                help = "Match radius, in the unit of the positions (distance <= R)"
            )]
            gt_radius: Option<f64>,
            #[arg(
                long = concat!($prefix, "-soft-radius"),
                value_name = "R2",
                allow_negative_numbers = true,
                requires = "gt_radius",
                help = "Soft ground truth by radius R2 >= R"
            )]
            gt_soft_radius: Option<f64>,
        }

        impl $name {
            /// The source the options name (one is required, unless declared
            /// `required = false`).
            #[allow(dead_code)] // a command with an optional source uses `given`
            pub fn source(&self) -> $crate::gt_source::GtSource<'_> {
                self.given().expect("clap requires one source")
            }

            /// The source the options name, if any.
            pub fn given(&self) -> Option<$crate::gt_source::GtSource<'_>> {
                use $crate::gt_source::{GtSource, Kind};
                if self.gt.is_none() && self.gt_tolerance.is_none() && self.gt_db_positions.is_none() {
                    return None;
                }
                let kind = if let Some(hard) = &self.gt {
                    Kind::File {
                        hard,
                        soft: self.gt_soft.as_deref(),
                    }
                } else if let Some(hard) = self.gt_tolerance {
                    Kind::Tolerance {
                        hard,
                        soft: self.gt_soft_tolerance,
                    }
                } else {
                    // clap's ArgGroup requires one of the three, and the positions
                    // require each other.
                    Kind::Positions {
                        db: self.gt_db_positions.as_deref().expect("one source is required"),
                        queries: self.gt_query_positions.as_deref().expect("required by db positions"),
                        radius: self.gt_radius.expect("required by db positions"),
                        soft_radius: self.gt_soft_radius,
                    }
                };
                Some(GtSource { prefix: $prefix, kind })
            }
        }
    };
}
#[allow(unused_imports)] // for the next command that takes ground truth (`evaluate`)
pub(crate) use gt_source_args;

gt_source_args!(
    /// The calibration ground truth of `calibrate` (`--cal-gt...`).
    CalGtSource,
    "cal-gt",
    "--cal"
);

gt_source_args!(
    /// The calibration ground truth of `threshold` (`--cal-gt...`): not needed when
    /// `--cal` is a calibration file, which holds its own.
    OptionalCalGtSource,
    "cal-gt",
    "--cal",
    required = false
);

/// One ground-truth source, as given on the command line.
#[derive(Debug, Clone, Copy)]
pub struct GtSource<'a> {
    /// The long-option prefix, e.g. `cal-gt`.
    pub prefix: &'static str,
    /// The source.
    pub kind: Kind<'a>,
}

/// The three sources.
#[derive(Debug, Clone, Copy)]
pub enum Kind<'a> {
    /// `.npy`/`.npz` files.
    File {
        /// Hard ground truth (or a VPR_Tutorial `.npz`).
        hard: &'a Path,
        /// Soft ground truth.
        soft: Option<&'a Path>,
    },
    /// `|i - j| <= hard` (and `<= soft`).
    Tolerance {
        /// Hard tolerance, in frames.
        hard: i64,
        /// Soft tolerance.
        soft: Option<i64>,
    },
    /// Positions within a radius.
    Positions {
        /// Database positions file.
        db: &'a Path,
        /// Query positions file.
        queries: &'a Path,
        /// Hard radius.
        radius: f64,
        /// Soft radius.
        soft_radius: Option<f64>,
    },
}

impl GtSource<'_> {
    /// The options as given, for error context: `--cal-gt GT.npy`, `--cal-gt-tolerance 1`, ...
    pub fn describe(&self) -> String {
        let p = self.prefix;
        match self.kind {
            Kind::File { hard, .. } => format!("--{p} {}", hard.display()),
            Kind::Tolerance { hard, .. } => format!("--{p}-tolerance {hard}"),
            Kind::Positions {
                db, queries, radius, ..
            } => format!(
                "--{p}-db-positions {} / --{p}-query-positions {} / --{p}-radius {radius}",
                db.display(),
                queries.display()
            ),
        }
    }

    /// The ground truth of a |DB| x |Q| similarity matrix of shape `shape` (as the core
    /// sees it, after orientation). Files are read and, for `query_major`, transposed;
    /// tolerance and positions give |DB| x |Q| directly.
    pub fn load(&self, shape: (usize, usize), query_major: bool) -> Result<GroundTruth> {
        let p = self.prefix;
        match self.kind {
            Kind::File { hard, soft } => {
                let gt = read_ground_truth(hard, soft).with_context(|| format!("--{p}"))?;
                Ok(if query_major { gt.reversed_axes() } else { gt })
            }
            Kind::Tolerance { hard, soft } => {
                let hard_n = frames(&format!("--{p}-tolerance"), hard)?;
                let gt = within_tolerance(shape.0, shape.1, hard_n).with_context(|| self.describe())?;
                let gt = GroundTruth::new(gt.view())?;
                match soft {
                    None => Ok(gt),
                    Some(soft) => {
                        let soft_n = frames(&format!("--{p}-soft-tolerance"), soft)?;
                        check_soft(
                            &format!("--{p}-tolerance"),
                            hard as f64,
                            &format!("--{p}-soft-tolerance"),
                            soft as f64,
                        )?;
                        Ok(gt.with_soft(within_tolerance(shape.0, shape.1, soft_n)?.view())?)
                    }
                }
            }
            Kind::Positions {
                db,
                queries,
                radius,
                soft_radius,
            } => {
                check_radius("radius", radius).with_context(|| format!("--{p}-radius"))?;
                if let Some(soft) = soft_radius {
                    check_radius("soft radius", soft).with_context(|| format!("--{p}-soft-radius"))?;
                    check_soft(&format!("--{p}-radius"), radius, &format!("--{p}-soft-radius"), soft)?;
                }
                let db_flag = format!("--{p}-db-positions {}", db.display());
                let q_flag = format!("--{p}-query-positions {}", queries.display());
                let (db_pos, q_pos) = read_positions(db, queries, &db_flag, &q_flag)?;
                let (n_db, n_q) = (db_pos.view().dim().0, q_pos.view().dim().0);
                if (n_db, n_q) != shape {
                    bail!(
                        "{db_flag} / {q_flag}: {n_db} database and {n_q} query positions, \
                         but the similarity matrix has shape {}x{}",
                        shape.0,
                        shape.1
                    );
                }
                let sources = [(DB_POSITIONS, db_flag), (QUERY_POSITIONS, q_flag)];
                let hard = positions_within(&db_pos, &q_pos, radius, &sources)?;
                let gt = GroundTruth::new(hard.view())?;
                match soft_radius {
                    None => Ok(gt),
                    Some(soft) => {
                        let soft = positions_within(&db_pos, &q_pos, soft, &sources)?;
                        Ok(gt.with_soft(soft.view())?)
                    }
                }
            }
        }
    }
}

/// A frame count from the command line: negative values are refused here, with the
/// name of the option.
pub fn frames(flag: &str, n: i64) -> Result<usize> {
    usize::try_from(n).map_err(|_| anyhow::anyhow!("{flag} must be >= 0, got {n}"))
}

/// A soft tolerance or radius must include the hard one; the flags name them.
pub fn check_soft(hard_flag: &str, hard: f64, soft_flag: &str, soft: f64) -> Result<()> {
    if soft < hard {
        bail!("{soft_flag} {soft} is smaller than {hard_flag} {hard}; soft ground truth must include the hard");
    }
    Ok(())
}

/// Read database and query position files (N x 2 or N x 3, float32/float64); the flags
/// name them in errors.
pub fn read_positions(db: &Path, queries: &Path, db_flag: &str, q_flag: &str) -> Result<(Scores, Scores)> {
    const LAYOUT: &str = "an N x 2 (x, y) or N x 3 (x, y, z) position matrix";
    let db = read_rows(db, "positions", LAYOUT).with_context(|| db_flag.to_string())?;
    let q = read_rows(queries, "positions", LAYOUT).with_context(|| q_flag.to_string())?;
    Ok((db, q))
}

/// [`within_radius`] on positions as read; `sources` name the files for [`blame`].
/// Check the radius first ([`check_radius`]), to name its option.
pub fn positions_within(
    db: &Scores,
    queries: &Scores,
    radius: f64,
    sources: &[(&str, String)],
) -> Result<ndarray::Array2<bool>> {
    with_view!(db.view(), |d| with_view!(queries.view(), |q| within_radius(
        d, q, radius
    )))
    .map_err(|e| blame(e, sources))
}
