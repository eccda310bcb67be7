//! Where a command's ground truth comes from: a file, a frame tolerance, or positions.
//!
//! Ground truth is rarely at hand as a matrix. Every command that needs it takes one of
//! four sources, exactly one of them (a clap `ArgGroup`):
//!
//! | source | options (prefix `P`, e.g. `cal-gt` or `gt`) |
//! |---|---|
//! | a file | `--P GT.npy\|GT.npz [--P-soft GTsoft.npy]` |
//! | frame-aligned traverses, `\|i - j\| <= N` | `--P-tolerance N [--P-soft-tolerance M]` |
//! | positions, distance `<= R` | `--P-db-positions DB.npy --P-query-positions Q.npy --P-radius R [--P-soft-radius R2]` |
//! | UTM positions in image names (`@east@north@...@.jpg`), distance `<= R` (default 25) | `--P-db-images LIST --P-query-images LIST [--P-radius R] [--P-soft-radius R2]` |
//!
//! A LIST is a directory or a text file of paths ([`qtvpr::image_paths`]).
//!
//! The options are one flattenable clap `Args` struct per prefix, made by
//! `gt_source_args!` (a clap-derive struct cannot take its option names at run time),
//! so that `threshold` (`--cal-gt...`) and `evaluate` (`--gt...`) share names, checks
//! and messages. `ground-truth` has the same options without a prefix and no file
//! source, plus the shape options of a tolerance; it builds a [`GtSource`] with the
//! empty prefix. Every source becomes ground truth through the core's one function,
//! [`qtvpr::GtSpec`]; this module only reads files and names options.

use std::path::Path;

use anyhow::{Context, Result, bail};
use qtvpr::Input;
use qtvpr::image_paths;
use qtvpr::npy::{FloatMatrix, read_float_matrix, read_ground_truth};
use qtvpr::{GroundTruth, QuerySplit, ScoresView};
use qtvpr::{GtSpec, HardSoft, check_radius};

use crate::args::blame;

/// Declare a flattenable clap `Args` struct named `$name` with the ground-truth source
/// options under the long-option prefix `$prefix` (see the [module docs](self)).
/// `$matrix` names the option of the similarity matrix the ground truth labels, for
/// help texts; `required` says whether one source must be given; `requires` names
/// the option every source needs; `aliases` gives short visible aliases of the
/// image-list options and the radius (for `evaluate`, whose one ground truth needs no
/// prefix to be unambiguous).
macro_rules! gt_source_args {
    (
        $(#[$doc:meta])* $name:ident, $prefix:literal, $matrix:literal,
        required = $required:literal $(, requires = $requires:literal)?
        $(, aliases = ($db_alias:literal, $q_alias:literal, $radius_alias:literal))?
    ) => {
        $(#[$doc])*
        #[derive(Debug, Clone, clap::Args)]
        #[group(skip)]
        #[command(group(
            clap::ArgGroup::new(concat!($prefix, "-source"))
                .required($required)
                .multiple(false)
                .args(["gt", "gt_tolerance", "gt_db_positions", "gt_db_images"])
                $(.requires($requires))?
        ))]
        #[command(group(
            clap::ArgGroup::new(concat!($prefix, "-places"))
                .multiple(false)
                .args(["gt_db_positions", "gt_db_images"])
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
                $(visible_alias = $radius_alias,)?
                value_name = "R",
                allow_negative_numbers = true,
                requires = concat!($prefix, "-places"),
                help = concat!(
                    "Match radius, in the unit of the positions (distance <= R); with --",
                    $prefix, "-db-images, in metres, default 25"
                )
            )]
            gt_radius: Option<f64>,
            #[arg(
                long = concat!($prefix, "-soft-radius"),
                value_name = "R2",
                allow_negative_numbers = true,
                requires = concat!($prefix, "-places"),
                help = "Soft ground truth by radius R2 >= R"
            )]
            gt_soft_radius: Option<f64>,
            #[arg(
                long = concat!($prefix, "-db-images"),
                $(visible_alias = $db_alias,)?
                value_name = "LIST",
                requires = "gt_query_images",
                help = concat!(
                    "Instead of a file: database images whose names carry UTM positions ",
                    "(@utm_east@utm_north@...@.jpg), one per row of ", $matrix, ": a directory ",
                    "(its .jpg/.jpeg/.png files at any depth, sorted by path, as ",
                    "VPR-methods-evaluation orders its descriptors) or a text file of one path per line"
                )
            )]
            gt_db_images: Option<std::path::PathBuf>,
            #[arg(
                long = concat!($prefix, "-query-images"),
                $(visible_alias = $q_alias,)?
                value_name = "LIST",
                requires = "gt_db_images",
                help = concat!("Query images (a directory or a text file), one per column of ", $matrix)
            )]
            gt_query_images: Option<std::path::PathBuf>,
        }

        impl $name {
            /// The source the options name, if any.
            pub fn source(&self) -> Option<$crate::gt_source::GtSource<'_>> {
                use $crate::gt_source::{GtSource, Kind};
                if self.gt.is_none()
                    && self.gt_tolerance.is_none()
                    && self.gt_db_positions.is_none()
                    && self.gt_db_images.is_none()
                {
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
                } else if let Some(db) = self.gt_db_images.as_deref() {
                    // The lists require each other; the radius has a default.
                    Kind::Images {
                        db,
                        queries: self.gt_query_images.as_deref()?,
                        radius: self.gt_radius.unwrap_or(qtvpr::DEFAULT_IMAGE_RADIUS),
                        soft_radius: self.gt_soft_radius,
                    }
                } else {
                    // The positions require each other and the radius.
                    Kind::Positions {
                        db: self.gt_db_positions.as_deref()?,
                        queries: self.gt_query_positions.as_deref()?,
                        radius: self.gt_radius?,
                        soft_radius: self.gt_soft_radius,
                    }
                };
                Some(GtSource { prefix: $prefix, kind })
            }
        }
    };
}

gt_source_args!(
    /// The calibration ground truth of `calibrate` (`--cal-gt...`).
    CalGtSource,
    "cal-gt",
    "--cal",
    required = true
);

gt_source_args!(
    /// The ground truth of `evaluate` (`--gt...`); none for the embedded data.
    EvalGtSource,
    "gt",
    "--similarity",
    required = false,
    requires = "scores",
    aliases = ("db-images", "query-images", "radius")
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

/// The four sources.
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
    /// Positions in image names, within a radius.
    Images {
        /// Database image list (a directory or a text file).
        db: &'a Path,
        /// Query image list.
        queries: &'a Path,
        /// Hard radius.
        radius: f64,
        /// Soft radius.
        soft_radius: Option<f64>,
    },
}

impl GtSource<'_> {
    /// The option `--PREFIX-name` (`--name` for the empty prefix; `--PREFIX` for an
    /// empty `name`).
    pub fn flag(&self, name: &str) -> String {
        match (self.prefix, name) {
            (p, "") => format!("--{p}"),
            ("", n) => format!("--{n}"),
            (p, n) => format!("--{p}-{n}"),
        }
    }

    /// The options as given, for error context: `--cal-gt GT.npy`, `--cal-gt-tolerance 1`, ...
    pub fn describe(&self) -> String {
        match self.kind {
            Kind::File { hard, .. } => format!("{} {}", self.flag(""), hard.display()),
            Kind::Tolerance { hard, .. } => format!("{} {hard}", self.flag("tolerance")),
            Kind::Positions {
                db, queries, radius, ..
            } => format!(
                "{} {} / {} {} / {} {radius}",
                self.flag("db-positions"),
                db.display(),
                self.flag("query-positions"),
                queries.display(),
                self.flag("radius")
            ),
            Kind::Images {
                db, queries, radius, ..
            } => format!(
                "{} {} / {} {} / {} {radius}",
                self.flag("db-images"),
                db.display(),
                self.flag("query-images"),
                queries.display(),
                self.flag("radius")
            ),
        }
    }

    /// Whether the ground truth is read from files, in the similarity's orientation (and
    /// transposed with it): then its positives say something of that orientation
    /// ([`qtvpr::Orientation::of`]); ground truth made for the matrix as read says nothing.
    pub fn is_file(&self) -> bool {
        matches!(self.kind, Kind::File { .. })
    }

    /// The ground truth of a |DB| x |Q| similarity matrix of shape `shape` (as the core
    /// sees it, after orientation). Files are read and, for `query_major`, transposed;
    /// tolerance and positions give |DB| x |Q| directly.
    pub fn load(&self, shape: (usize, usize), query_major: bool) -> Result<GroundTruth> {
        match self.kind {
            Kind::File { hard, soft } => {
                let gt = read_ground_truth(hard, soft).with_context(|| self.flag(""))?;
                Ok(gt.oriented(query_major))
            }
            _ => Ok(self.matrices(Some(shape))?.into_ground_truth()?),
        }
    }

    /// The ground truth of the calibration queries of `split`: the source labels every
    /// query split (a tolerance makes just the calibration columns), and the core
    /// checks its shape and keeps the calibration columns. `input` names the similarity
    /// (its options and files) in errors.
    pub fn load_split(&self, split: &QuerySplit, query_major: bool, input: &str) -> Result<GroundTruth> {
        Ok(self.load_split_read(split, query_major, input)?.0)
    }

    /// [`GtSource::load_split`], and the ground truth of every query when it was read
    /// from files ([`GtSource::is_file`]), for [`qtvpr::Orientation::of`].
    pub fn load_split_read(
        &self,
        split: &QuerySplit,
        query_major: bool,
        input: &str,
    ) -> Result<(GroundTruth, Option<GroundTruth>)> {
        if let Kind::Tolerance { .. } = self.kind {
            return Ok((self.load(split.calibration_shape(), query_major)?, None));
        }
        let gt = self.load(split.shape(), query_major)?;
        let cal = split
            .calibration_truth(&gt)
            .map_err(|e| crate::args::oriented(e, query_major))
            .with_context(|| format!("{input} / {}", self.describe()))?;
        Ok((cal, self.is_file().then_some(gt)))
    }

    /// Hard and soft ground truth of a tolerance or positions source, of shape `shape`
    /// (required for a tolerance, checked for positions), by the core's
    /// [`GtSpec::matrices`]. The parameters are checked first, before any file is read,
    /// so that their messages name the options.
    ///
    /// # Panics
    /// For a file source (which holds its matrices already).
    pub fn matrices(&self, shape: Option<(usize, usize)>) -> Result<HardSoft> {
        match self.kind {
            Kind::File { .. } => unreachable!("a file source is read, not made"),
            Kind::Tolerance { hard, soft } => {
                let (hard_flag, soft_flag) = (self.flag("tolerance"), self.flag("soft-tolerance"));
                let spec = GtSpec::Tolerance {
                    hard: frames(&hard_flag, hard)?,
                    soft: soft.map(|s| frames(&soft_flag, s)).transpose()?,
                };
                if let Some(soft) = soft {
                    check_soft(&hard_flag, hard as f64, &soft_flag, soft as f64)?;
                }
                Ok(spec.matrices(shape).with_context(|| self.describe())?)
            }
            Kind::Positions {
                db,
                queries,
                radius,
                soft_radius,
            } => {
                self.check_radii(radius, soft_radius)?;
                let db_flag = format!("{} {}", self.flag("db-positions"), db.display());
                let q_flag = format!("{} {}", self.flag("query-positions"), queries.display());
                let db = read_float_matrix(db, FloatMatrix::Positions).with_context(|| db_flag.clone())?;
                let queries = read_float_matrix(queries, FloatMatrix::Positions).with_context(|| q_flag.clone())?;
                within(db.view(), queries.view(), radius, soft_radius, shape, [db_flag, q_flag])
            }
            Kind::Images {
                db,
                queries,
                radius,
                soft_radius,
            } => {
                self.check_radii(radius, soft_radius)?;
                let db_flag = format!("{} {}", self.flag("db-images"), db.display());
                let q_flag = format!("{} {}", self.flag("query-images"), queries.display());
                let read = |list: &Path, flag: &String| {
                    image_paths(list)
                        .and_then(|l| l.positions())
                        .with_context(|| flag.clone())
                };
                let (db, queries) = (read(db, &db_flag)?, read(queries, &q_flag)?);
                // Name the list whose length is wrong, with both counts, before the
                // core's message about both.
                if let Some((n_db, n_q)) = shape {
                    let rows = self.labelled();
                    for (flag, n, expected, what) in [
                        (&db_flag, db.nrows(), n_db, "database images"),
                        (&q_flag, queries.nrows(), n_q, "queries"),
                    ] {
                        if n != expected {
                            bail!("{flag}: lists {n} images but {rows} has {expected} {what}");
                        }
                    }
                }
                within(
                    ScoresView::from(db.view()),
                    ScoresView::from(queries.view()),
                    radius,
                    soft_radius,
                    shape,
                    [db_flag, q_flag],
                )
            }
        }
    }

    /// What the ground truth labels, for messages: the similarity matrix (the empty
    /// prefix of `ground-truth` has none).
    fn labelled(&self) -> &'static str {
        match self.prefix {
            // --cal, or with a split every query of --similarity or the descriptors.
            "cal-gt" => "the similarity it labels",
            _ => "the similarity matrix",
        }
    }

    /// The radius and soft radius, checked with messages naming the options.
    fn check_radii(&self, radius: f64, soft_radius: Option<f64>) -> Result<()> {
        let (hard_flag, soft_flag) = (self.flag("radius"), self.flag("soft-radius"));
        check_radius("radius", radius).with_context(|| hard_flag.clone())?;
        if let Some(soft) = soft_radius {
            check_radius("soft radius", soft).with_context(|| soft_flag.clone())?;
            check_soft(&hard_flag, radius, &soft_flag, soft)?;
        }
        Ok(())
    }
}

/// Ground truth within a radius of positions read from the options `flags`
/// (database, queries), by the core's [`GtSpec::Positions`].
fn within<'a>(
    db: ScoresView<'a>,
    queries: ScoresView<'a>,
    radius: f64,
    soft_radius: Option<f64>,
    shape: Option<(usize, usize)>,
    flags: [String; 2],
) -> Result<HardSoft> {
    let spec = GtSpec::Positions {
        db,
        queries,
        radius,
        soft_radius,
    };
    let [db_flag, q_flag] = flags;
    let sources = [(Input::DbPositions, db_flag), (Input::QueryPositions, q_flag)];
    spec.matrices(shape).map_err(|e| blame(e, &sources))
}

/// A frame count from the command line: negative values are refused here, with the
/// name of the option.
fn frames(flag: &str, n: i64) -> Result<usize> {
    usize::try_from(n).map_err(|_| anyhow::anyhow!("{flag} must be >= 0, got {n}"))
}

/// A soft tolerance or radius must include the hard one; the flags name them. (The
/// core checks the same, naming its parameters; this names the options.)
fn check_soft(hard_flag: &str, hard: f64, soft_flag: &str, soft: f64) -> Result<()> {
    if soft < hard {
        bail!("{soft_flag} {soft} is smaller than {hard_flag} {hard}; soft ground truth must include the hard");
    }
    Ok(())
}
