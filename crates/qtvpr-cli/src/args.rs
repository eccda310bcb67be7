//! The arguments several commands share (`--matching`, `--gate`, `--cal-queries` /
//! `--cal-fraction`, descriptor files, `--sequence`), and core errors named after the
//! command line: which option and file a matrix came from.

use std::path::Path;

use anyhow::{Context, Result};
use clap::Args;
use qtvpr::npy::{FloatMatrix, MatrixFile, read_float_matrix};
use qtvpr::{Descriptors, Input, QuerySplit, Sequence, Split};

/// Attach to a core error the options and files of the matrices it is about:
/// `sources` maps the [`Input`]s a command reads from files to `--option FILE`, looked
/// up by [`qtvpr::Error::inputs`]. Errors about no matrix in `sources` are returned as
/// they are.
pub fn blame(err: qtvpr::Error, sources: &[(Input, String)]) -> anyhow::Error {
    let context: Vec<&str> = err.inputs(|input| {
        sources
            .iter()
            .find(|(i, _)| *i == input)
            .map(|(_, source)| source.as_str())
    });
    if context.is_empty() {
        err.into()
    } else {
        let context = context.join(" / ");
        anyhow::Error::new(err).context(context)
    }
}

/// The option that says matrices are stored query-major, as the core's orientation
/// messages name it.
pub const QUERY_MAJOR: &str = "--query-major";

/// A core error of a computation on views oriented by `query_major`, in the files'
/// orientation ([`qtvpr::Error::oriented`]), with the core's advice when it is the usual
/// sign of a matrix read the wrong way round ([`qtvpr::orientation_hint`]).
pub fn oriented(err: qtvpr::Error, query_major: bool) -> anyhow::Error {
    let hint = qtvpr::orientation_hint(&err, query_major, QUERY_MAJOR);
    let err = err.oriented(query_major);
    match hint {
        Some(hint) => anyhow::anyhow!("{err}; {hint}"),
        None => err.into(),
    }
}

/// Print the core's warning when the ground truth contradicts the orientation assumed.
pub fn warn_orientation(orientation: &qtvpr::Orientation) {
    if let Some(warning) = orientation.warning(QUERY_MAJOR) {
        eprintln!("warning: {warning}");
    }
}

/// The `--matching` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MatchingArg {
    /// Single-best-match VPR (one decision per query).
    Single,
    /// Multi-match VPR (every non-ignored entry is a candidate).
    Multi,
}

impl From<MatchingArg> for qtvpr::Matching {
    fn from(m: MatchingArg) -> Self {
        match m {
            MatchingArg::Single => qtvpr::Matching::Single,
            MatchingArg::Multi => qtvpr::Matching::Multi,
        }
    }
}

/// `--cal-queries` / `--cal-fraction`: the first queries of one recorded traverse (a
/// similarity matrix or the query descriptors) are its calibration queries, by the rule
/// of `evaluate` ([`Split::calibration_size`]), the core's [`QuerySplit`]. `threshold`
/// and `calibrate` calibrate on them; `stream` skips them. One group, so that every
/// command that reads a traverse spells, explains and checks the split alike.
#[derive(Debug, Args)]
#[group(id = "split", multiple = false)]
pub struct SplitArgs {
    /// The first N queries of the traverse (--similarity, --val of `stream`, or the
    /// query descriptors) are its calibration queries: they calibrate, and only the
    /// later ones are thresholded or decided (`stream` skips them).
    #[arg(long, value_name = "N")]
    cal_queries: Option<usize>,
    /// The first floor(F x |Q|) queries are the calibration queries (instead of
    /// --cal-queries), as `evaluate --cal-fraction` counts them.
    #[arg(long, value_name = "F", allow_negative_numbers = true)]
    cal_fraction: Option<f64>,
}

/// The split of a similarity matrix's queries by `asked` (a split and the option that
/// asked for it, [`SplitArgs::split`]): `shape` is the |DB| x |Q| view read (oriented by
/// `query_major`), `input` its `--option FILE`, which an error names with the option.
pub fn query_split(
    (split, flag): (Split, &'static str),
    shape: (usize, usize),
    query_major: bool,
    input: &str,
) -> Result<QuerySplit> {
    QuerySplit::new(split, shape)
        .map_err(|e| oriented(e, query_major))
        .with_context(|| format!("{flag} of {input}"))
}

impl SplitArgs {
    /// The split asked for, with the option that asked; its parameter is checked here,
    /// before any file is read.
    pub fn split(&self) -> Result<Option<(Split, &'static str)>> {
        let split = match (self.cal_queries, self.cal_fraction) {
            (Some(n), _) => Some((Split::Count(n), "--cal-queries")),
            (_, Some(f)) => Some((Split::Fraction(f), "--cal-fraction")),
            _ => None,
        };
        if let Some((split, flag)) = split {
            split.validate().context(flag)?;
        }
        Ok(split)
    }
}

/// The values of `--gate` (semantics §13, §15): a set of gates, named and parsed by
/// the core (`margin,sequence` or `sequence,margin`), its sets listed in `--help`.
pub fn gate_parser() -> GateParser {
    GateParser
}

/// `--gate`'s parser: clap's `PossibleValuesParser` would refuse `sequence,margin`, the
/// same set in another order, so the core parses and clap only lists the sets.
#[derive(Debug, Clone, Copy)]
pub struct GateParser;

impl clap::builder::TypedValueParser for GateParser {
    type Value = qtvpr::Gate;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> std::result::Result<qtvpr::Gate, clap::Error> {
        let text = clap::builder::StringValueParser::new().parse_ref(cmd, arg, value)?;
        text.parse::<qtvpr::Gate>().map_err(|e| {
            let name = arg.map_or_else(|| "--gate".to_owned(), ToString::to_string);
            clap::Error::raw(
                clap::error::ErrorKind::InvalidValue,
                format!("invalid value '{text}' for '{name}': {e}\n"),
            )
            .with_cmd(cmd)
        })
    }

    fn possible_values(&self) -> Option<Box<dyn Iterator<Item = clap::builder::PossibleValue> + '_>> {
        Some(Box::new(
            qtvpr::Gate::ALL
                .into_iter()
                .map(|g| clap::builder::PossibleValue::new(g.as_str())),
        ))
    }
}

/// The sequence gate's parameters (semantics §15), each left out taking the
/// calibration file's value, else the core's default.
#[derive(Debug, Args)]
pub struct SequenceGateArgs {
    /// Sequence gate: how many previous queries each query's best match is compared
    /// with (semantics §15) [default: the calibration file's, else 5].
    #[arg(long, value_name = "W")]
    sequence_window: Option<usize>,
    /// Sequence gate: the share of those previous queries whose best matches must agree,
    /// in (0, 1] [default: the calibration file's, else 0.8].
    #[arg(long, value_name = "LEVEL", allow_negative_numbers = true)]
    sequence_level: Option<f64>,
    /// Sequence gate: database rows per query, the speed ratio of the two traverses (-1:
    /// the route driven backwards) [default: the calibration file's, else 1].
    #[arg(long, value_name = "V", allow_negative_numbers = true)]
    sequence_speed: Option<f64>,
    /// Sequence gate: how far, in database rows, a neighbour one step away may lie from
    /// where the line predicts [default: the calibration file's, else 2].
    #[arg(long, value_name = "A", allow_negative_numbers = true)]
    sequence_tolerance: Option<f64>,
    /// Sequence gate: how much that tolerance widens per step away, in rows per step
    /// [default: the calibration file's, else 0.2].
    #[arg(long, value_name = "B", allow_negative_numbers = true)]
    sequence_drift: Option<f64>,
}

// The defaults the help texts above state are the core's.
const _: () = assert!(qtvpr::DEFAULT_SEQUENCE_WINDOW == 5);
const _: () = assert!(qtvpr::DEFAULT_SEQUENCE_LEVEL == 0.8);
const _: () = assert!(qtvpr::DEFAULT_SPEED == 1.0);
const _: () = assert!(qtvpr::DEFAULT_TOLERANCE == 2.0);
const _: () = assert!(qtvpr::DEFAULT_DRIFT == 0.2);

impl SequenceGateArgs {
    /// The parameters given, for the core to resolve.
    pub fn overrides(&self) -> qtvpr::SequenceOverrides {
        qtvpr::SequenceOverrides {
            window: self.sequence_window,
            level: self.sequence_level,
            speed: self.sequence_speed,
            tolerance: self.sequence_tolerance,
            drift: self.sequence_drift,
        }
    }
}

/// `--db-descriptors` and `--query-descriptors`, read (memory-mapped where possible) and
/// held for the [`Descriptors`] that view them.
pub struct DescriptorFiles {
    db: MatrixFile,
    queries: MatrixFile,
    /// `--option FILE` of each, for [`blame`].
    sources: [(Input, String); 2],
}

impl DescriptorFiles {
    /// Read the two files; an error names the option and the file.
    pub fn read(db: &Path, queries: &Path) -> Result<Self> {
        Ok(Self {
            db: read_float_matrix(db, FloatMatrix::Descriptors).context("--db-descriptors")?,
            queries: read_float_matrix(queries, FloatMatrix::Descriptors).context("--query-descriptors")?,
            sources: [
                (Input::DbDescriptors, format!("--db-descriptors {}", db.display())),
                (
                    Input::QueryDescriptors,
                    format!("--query-descriptors {}", queries.display()),
                ),
            ],
        })
    }

    /// The descriptors, checked by the core (a bad row is named with its file).
    pub fn descriptors(&self) -> Result<Descriptors<'_>> {
        Descriptors::new(self.db.view(), self.queries.view()).map_err(|e| self.blame(e))
    }

    /// A core error, with the option and file of the descriptors it is about.
    pub fn blame(&self, err: qtvpr::Error) -> anyhow::Error {
        blame(err, &self.sources)
    }

    /// `--db-descriptors DB / --query-descriptors Q`, to say what an error is about.
    pub fn describe(&self) -> String {
        format!("{} / {}", self.sources[0].1, self.sources[1].1)
    }
}

/// `--sequence L` (with `causal`), checked before anything is read; `None` without it.
pub fn sequence(length: Option<i64>, causal: bool) -> Result<Option<Sequence>> {
    length
        .map(|length| {
            let Ok(length) = usize::try_from(length) else {
                anyhow::bail!("sequence length must be odd and >= 1, got {length}");
            };
            let sequence = Sequence { length, causal };
            sequence.validate()?;
            Ok(sequence)
        })
        .transpose()
        .context("--sequence")
}
