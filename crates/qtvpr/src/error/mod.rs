//! semantics §10: bad input, as the one error type of the core.
//!
//! Every message is lowercase, names the input it is about (`what`) and says what is
//! wrong with it, so that a front end only has to add the file or argument name
//! (semantics §10).

pub(crate) mod names;

/// Result alias used throughout the core.
pub type Result<T, E = Error> = std::result::Result<T, E>;

use std::fmt;

use crate::error::names::Input;

/// Everything that can be wrong with the input of the core.
///
/// `what` and `other` fields name the matrix the problem is in, an
/// [`Input`]; [`Error::about`] lists them.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A matrix has no rows or no columns.
    #[error("{what} is empty (shape {rows}x{cols})")]
    Empty {
        /// Which matrix.
        what: Input,
        /// Its number of rows.
        rows: usize,
        /// Its number of columns.
        cols: usize,
    },
    /// A score (or, in the extensions' descriptor and position matrices, a value) is
    /// NaN or infinite.
    #[error("{what} contains {value} at row {row}, column {col}; {rule}", rule = what.finite_rule())]
    NotFinite {
        /// Which matrix.
        what: Input,
        /// Row of the first offending entry.
        row: usize,
        /// Column of the first offending entry.
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// Two matrices that must have the same shape do not.
    #[error(
        "{what} shape {}x{} does not match {other} shape {}x{}",
        shape.0, shape.1, other_shape.0, other_shape.1
    )]
    ShapeMismatch {
        /// The matrix whose shape is wrong.
        what: Input,
        /// Its shape.
        shape: (usize, usize),
        /// The matrix it must match.
        other: Input,
        /// That matrix's shape.
        other_shape: (usize, usize),
    },
    /// Calibration and deployment similarity are scored against databases of different
    /// sizes (|DB| is the number of rows, or of columns for query-major input; the
    /// message names neither, so it holds in both orientations).
    #[error(
        "deployment similarity has {deployment} database images but calibration similarity has {calibration}; \
         both must be scored against the same database"
    )]
    DatabaseMismatch {
        /// |DB| of the calibration matrix.
        calibration: usize,
        /// |DB| of the deployment matrix.
        deployment: usize,
    },
    /// A deployment column pushed to an online state does not hold one score per
    /// database image.
    #[error(
        "deployment query {query} has {len} scores but the calibration has {db} database images; \
         a query's column holds one score per database image"
    )]
    ColumnLength {
        /// The query's index in arrival order.
        query: usize,
        /// Its number of scores.
        len: usize,
        /// |DB| of the calibration.
        db: usize,
    },
    /// A ground-truth entry is neither 0 nor 1 (nor false/true).
    #[error("{what} has value {value} at row {row}, column {col}; ground truth must be 0/1 or bool")]
    BadLabel {
        /// Which ground-truth matrix.
        what: Input,
        /// Row of the first offending entry.
        row: usize,
        /// Column of the first offending entry.
        col: usize,
        /// The offending value.
        value: i128,
    },
    /// A file cannot be opened or read (missing, a directory, no permission, ...).
    #[error("cannot read {path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// The kind of I/O error, for front ends that map it (e.g. to FileNotFoundError).
        kind: std::io::ErrorKind,
        /// What the operating system said.
        message: String,
    },
    /// A file cannot be written (no such directory, no permission, disk full, ...).
    #[error("cannot write {path}: {message}")]
    Write {
        /// The file.
        path: String,
        /// The kind of I/O error.
        kind: std::io::ErrorKind,
        /// What the operating system said.
        message: String,
    },
    /// A file's content is not what it must be (not `.npy`, truncated, not 2-D, ...).
    #[error("{path} {message}")]
    File {
        /// The file.
        path: String,
        /// What is wrong, phrased to follow the file name.
        message: String,
    },
    /// Memory for a buffer whose size a file or a parameter decides cannot be allocated
    /// (semantics §10: never an abort).
    #[error("cannot allocate {bytes} bytes for {what}")]
    Allocation {
        /// How many bytes were asked for.
        bytes: u128,
        /// What they were for: a file and its member, or a named buffer.
        what: String,
    },
    /// A file holds an array of a dtype this input does not take.
    #[error("{path} has dtype {dtype}; {expected}")]
    Dtype {
        /// The file.
        path: String,
        /// The dtype as NumPy spells it, e.g. `<c16`.
        dtype: String,
        /// What the input takes, e.g. `expected bool or integer 0/1 ground truth` or
        /// `positions must be float32 or float64`.
        expected: &'static str,
    },
    /// A problem with the content of a file that was read (e.g. a bad label).
    ///
    /// The message includes the problem's, so the problem is deliberately not the
    /// error's `source()`: a front end printing the whole chain (anyhow's `{:#}`) would
    /// print it twice.
    #[error("{path}: {error}")]
    InFile {
        /// The file.
        path: String,
        /// The problem.
        error: Box<Error>,
    },
    /// A method name the evaluation protocol does not know.
    #[error("unknown method '{name}'; expected one of {}", .expected.join(", "))]
    UnknownMethod {
        /// The name as given.
        name: String,
        /// Every method's name, in report order (`Method::ALL`).
        expected: Vec<&'static str>,
    },
    /// Ground truth of one set of queries split into calibration and deployment
    /// queries ([`QuerySplit`](crate::QuerySplit)) does not label every query.
    #[error(
        "ground truth shape {}x{} does not match similarity shape {}x{}; the ground truth of a split \
         labels every query, of which the first {calibration} calibrate",
        shape.0, shape.1, similarity_shape.0, similarity_shape.1
    )]
    SplitTruthShape {
        /// The ground truth's shape.
        shape: (usize, usize),
        /// The shape of the similarity split, |DB| x |Q|.
        similarity_shape: (usize, usize),
        /// The number of calibration queries.
        calibration: usize,
    },
    /// A split of the queries that leaves no calibration query or no query after them:
    /// the calibration count must be between 1 and |Q| - 1.
    #[error(
        "the calibration set must have between 1 and {} of the {queries} queries, got {calibration}",
        queries.saturating_sub(1)
    )]
    CalibrationSize {
        /// The calibration queries asked for (a count, or a fraction of |Q| floored).
        calibration: usize,
        /// |Q|.
        queries: usize,
        /// |DB| where it is known: a count beyond |Q| but within |DB| is the usual
        /// sign of a query-major matrix read as |DB| x |Q| ([`crate::input::orientation::hint`]).
        database: Option<usize>,
    },
    /// The evaluation protocol cannot split the queries as asked: no calibration query,
    /// calibration and deployment sets that overlap, or no full segment.
    #[error("{0}")]
    Protocol(String),
    /// A parameter is out of its range.
    #[error("{name} {message}")]
    InvalidParameter {
        /// The parameter, as a user spells it (`k`, `precision`, `segment size`).
        name: &'static str,
        /// What is wrong, e.g. `must be >= 1, got 0`.
        message: String,
    },
    // Inputs of the extensions (descriptors, positions), not of the quantile-transfer pipeline.
    /// A descriptor is the zero vector, whose cosine similarity is undefined.
    #[error("{what} row {row} is all zeros; the cosine similarity of a zero vector is undefined")]
    ZeroNorm {
        /// Which descriptor matrix.
        what: Input,
        /// The first all-zero row.
        row: usize,
    },
    /// Two matrices whose rows must have the same length (descriptor dimension,
    /// coordinates per position) do not.
    #[error("{what} has {cols} columns but {other} has {other_cols}; both must have the same dimension")]
    ColumnMismatch {
        /// The second matrix.
        what: Input,
        /// Its number of columns.
        cols: usize,
        /// The matrix it must match.
        other: Input,
        /// That matrix's number of columns.
        other_cols: usize,
    },
    /// Ground truth from positions does not have the shape of the similarity matrix it
    /// labels.
    #[error(
        "{db} database and {queries} query positions, but the similarity matrix has shape {}x{}",
        shape.0, shape.1
    )]
    PositionCount {
        /// Rows of the database position matrix.
        db: usize,
        /// Rows of the query position matrix.
        queries: usize,
        /// The similarity matrix's shape, |DB| x |Q|.
        shape: (usize, usize),
    },
    /// An image name does not carry UTM coordinates
    /// ([`utm_positions`](crate::utm_positions)).
    #[error("{at}: image name '{name}' {problem}; names must look like @utm_east@utm_north@...@.jpg")]
    ImageName {
        /// Where the name came from: its index, its line in a text file, or its directory.
        at: NameAt,
        /// The name (the path as given).
        name: String,
        /// What is wrong, phrased to follow the name: `has fewer than two '@'`, ...
        problem: String,
    },
    /// A position matrix has neither 2 nor 3 columns.
    #[error("{what} has {cols} columns; positions must be x, y (2 columns) or x, y, z (3 columns)")]
    PositionColumns {
        /// Which position matrix.
        what: Input,
        /// Its number of columns.
        cols: usize,
    },
}

impl Error {
    /// The same error for a caller whose matrices are the transpose of the core's
    /// |DB| x |Q| views (query-major input): rows and columns, shapes and positions
    /// swapped, recursively inside [`Error::InFile`]. Errors without a position are
    /// returned unchanged; `transposed` twice is the identity.
    ///
    /// Front ends call it on errors of the core's computation for query-major input, so
    /// that a message points at the entry as the caller stored it. Errors about a file
    /// as read (its shape, a bad label in it) are already in the file's orientation and
    /// must not be transposed.
    #[must_use]
    pub fn transposed(self) -> Self {
        match self {
            Error::Empty { what, rows, cols } => Error::Empty {
                what,
                rows: cols,
                cols: rows,
            },
            Error::NotFinite { what, row, col, value } => Error::NotFinite {
                what,
                row: col,
                col: row,
                value,
            },
            Error::BadLabel { what, row, col, value } => Error::BadLabel {
                what,
                row: col,
                col: row,
                value,
            },
            Error::ShapeMismatch {
                what,
                shape,
                other,
                other_shape,
            } => Error::ShapeMismatch {
                what,
                shape: (shape.1, shape.0),
                other,
                other_shape: (other_shape.1, other_shape.0),
            },
            Error::InFile { path, error } => Error::InFile {
                path,
                error: Box::new(error.transposed()),
            },
            Error::SplitTruthShape {
                shape,
                similarity_shape,
                calibration,
            } => Error::SplitTruthShape {
                shape: (shape.1, shape.0),
                similarity_shape: (similarity_shape.1, similarity_shape.0),
                calibration,
            },
            Error::PositionCount { db, queries, shape } => Error::PositionCount {
                db,
                queries,
                shape: (shape.1, shape.0),
            },
            other => other,
        }
    }

    /// The error of a computation on views made by
    /// [`ScoresView::oriented`](crate::ScoresView::oriented) with the same
    /// `query_major`, in the caller's orientation: [`Error::transposed`] when
    /// `query_major`, else unchanged.
    #[must_use]
    pub fn oriented(self, query_major: bool) -> Self {
        if query_major { self.transposed() } else { self }
    }

    /// The same error for a view whose columns are columns `first..` of a larger
    /// matrix (a block of deployment queries): the column of a non-finite score moves
    /// by `first`. Other errors, which name no column, are returned unchanged.
    #[must_use]
    pub fn shifted(self, first: usize) -> Self {
        match self {
            Error::NotFinite { what, row, col, value } => Error::NotFinite {
                what,
                row,
                col: col + first,
                value,
            },
            other => other,
        }
    }

    /// The matrices the error is about. A shape
    /// mismatch is about the matrix whose shape is wrong (ground truth must take the
    /// shape of the similarity it labels); a column mismatch about both matrices,
    /// neither of which is the reference. Empty for errors about a parameter or about
    /// a file (which name the file themselves).
    pub fn about(&self) -> Vec<Input> {
        match self {
            Error::Empty { what, .. }
            | Error::NotFinite { what, .. }
            | Error::BadLabel { what, .. }
            | Error::ShapeMismatch { what, .. }
            | Error::ZeroNorm { what, .. }
            | Error::PositionColumns { what, .. } => vec![*what],
            Error::ColumnMismatch { what, other, .. } => vec![*what, *other],
            Error::DatabaseMismatch { .. } => vec![Input::DeploymentSimilarity],
            Error::SplitTruthShape { .. } => vec![Input::GroundTruth],
            Error::PositionCount { .. } => vec![Input::DbPositions, Input::QueryPositions],
            _ => vec![],
        }
    }

    /// The inputs the error is about, as a front end calls them: `name` maps each
    /// [`Input`] of [`Error::about`] to whatever the front end calls it (an option and
    /// its file, a Python argument), `None` for an input it does not name; in the order
    /// of [`Error::about`]. This is the one way a front end attaches its names to a core
    /// error; a front end that names every input writes `name` as one exhaustive
    /// `match`, which stops compiling when an input is added.
    pub fn inputs<T>(&self, name: impl FnMut(Input) -> Option<T>) -> Vec<T> {
        self.about().into_iter().filter_map(name).collect()
    }

    pub(crate) fn param(name: &'static str, message: impl Into<String>) -> Self {
        Self::InvalidParameter {
            name,
            message: message.into(),
        }
    }
}

/// Where an image name came from, for the message of an [`Error::ImageName`] ([`utm_positions`](crate::utm_positions)).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NameAt {
    /// Index `i` (0-based) of a list of paths given in memory: shown as `paths[i]`.
    Index(usize),
    /// Line `line` (1-based) of the text file `file`: shown as `FILE line N`.
    Line {
        /// The text file, as given.
        file: String,
        /// The line, 1-based.
        line: usize,
    },
    /// A file found in the directory `dir`: shown as the directory.
    Directory(String),
}

impl fmt::Display for NameAt {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NameAt::Index(i) => write!(f, "paths[{i}]"),
            NameAt::Line { file, line } => write!(f, "{file} line {line}"),
            NameAt::Directory(dir) => write!(f, "{dir}"),
        }
    }
}

/// Room for `more` further elements in `v`, reserved fallibly (semantics §10: a buffer
/// a file or a parameter sizes is an error when memory runs out, never an abort);
/// `what` names the buffer for [`Error::Allocation`].
///
/// # Errors
/// [`Error::Allocation`].
pub(crate) fn try_reserve<T>(v: &mut Vec<T>, more: usize, what: impl FnOnce() -> String) -> Result<()> {
    v.try_reserve_exact(more).map_err(|_| Error::Allocation {
        bytes: (v.len() as u128 + more as u128) * size_of::<T>() as u128,
        what: what(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transposed_swaps_positions_and_shapes() {
        let e = Error::NotFinite {
            what: Input::Similarity,
            row: 1,
            col: 2,
            value: f64::NAN,
        };
        assert_eq!(
            e.transposed().to_string(),
            "similarity contains NaN at row 2, column 1; scores must be finite"
        );
        let e = Error::ShapeMismatch {
            what: Input::GroundTruth,
            shape: (3, 4),
            other: Input::Similarity,
            other_shape: (3, 5),
        };
        assert_eq!(
            e.clone().transposed().to_string(),
            "ground truth shape 4x3 does not match similarity shape 5x3"
        );
        assert_eq!(e.clone().transposed().transposed(), e);
        let e = Error::Empty {
            what: Input::Similarity,
            rows: 0,
            cols: 7,
        };
        assert_eq!(e.transposed().to_string(), "similarity is empty (shape 7x0)");
        let e = Error::InFile {
            path: "gt.npy".into(),
            error: Box::new(Error::BadLabel {
                what: Input::GroundTruth,
                row: 5,
                col: 0,
                value: -1,
            }),
        };
        assert_eq!(
            e.transposed().to_string(),
            "gt.npy: ground truth has value -1 at row 0, column 5; ground truth must be 0/1 or bool"
        );
        // Errors without a position are unchanged.
        let e = Error::DatabaseMismatch {
            calibration: 3,
            deployment: 2,
        };
        assert_eq!(e.clone().transposed(), e);
        assert_eq!(
            e.to_string(),
            "deployment similarity has 2 database images but calibration similarity has 3; \
             both must be scored against the same database"
        );
    }

    #[test]
    fn not_finite_says_what_every_value_must_be() {
        let error = |what| Error::NotFinite {
            what,
            row: 2,
            col: 0,
            value: f64::INFINITY,
        };
        assert_eq!(
            error(Input::CalSimilarity).to_string(),
            "calibration similarity contains inf at row 2, column 0; scores must be finite"
        );
        assert_eq!(
            error(Input::QueryDescriptors).to_string(),
            "query descriptor matrix contains inf at row 2, column 0; every value must be finite"
        );
        assert_eq!(
            error(Input::DbPositions).to_string(),
            "database position matrix contains inf at row 2, column 0; every value must be finite"
        );
    }

    #[test]
    fn unknown_method_lists_the_methods_it_is_given() {
        // `Method`'s parser gives every method (evaluate/protocol.rs tests that list).
        let e = Error::UnknownMethod {
            name: "best".into(),
            expected: vec!["oracle", "schubert"],
        };
        assert_eq!(e.to_string(), "unknown method 'best'; expected one of oracle, schubert");
    }

    #[test]
    fn inputs_are_named_by_the_front_end_in_order() {
        let e = Error::ColumnMismatch {
            what: Input::QueryDescriptors,
            cols: 3,
            other: Input::DbDescriptors,
            other_cols: 4,
        };
        assert_eq!(e.about(), [Input::QueryDescriptors, Input::DbDescriptors]);
        let name = |input| match input {
            Input::DbDescriptors => Some("db"),
            Input::QueryDescriptors => Some("queries"),
            _ => None,
        };
        assert_eq!(e.inputs(name), ["queries", "db"]);
        let e = Error::DatabaseMismatch {
            calibration: 3,
            deployment: 2,
        };
        assert_eq!(e.inputs(name), Vec::<&str>::new());
        assert_eq!(e.inputs(|i| Some(i.as_str())), ["deployment similarity"]);
        assert!(Error::param("k", "must be >= 1, got 0").about().is_empty());
    }
}
