//! The one error type of the core.
//!
//! Every message is lowercase, names the input it is about (`what`) and says what is
//! wrong with it, so that a front end only has to add the file or argument name
//! (SPEC section 10).

/// Result alias used throughout the core.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can be wrong with the input of the core.
///
/// `what` fields name the matrix the problem is in, e.g. `"calibration similarity"`
/// or `"ground truth"`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A matrix has no rows or no columns.
    #[error("{what} is empty (shape {rows}x{cols})")]
    Empty {
        /// Which matrix.
        what: &'static str,
        /// Its number of rows.
        rows: usize,
        /// Its number of columns.
        cols: usize,
    },
    /// A score is NaN or infinite.
    #[error("{what} contains {value} at row {row}, column {col}; scores must be finite")]
    NotFinite {
        /// Which matrix.
        what: &'static str,
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
        what: &'static str,
        /// Its shape.
        shape: (usize, usize),
        /// The matrix it must match.
        other: &'static str,
        /// That matrix's shape.
        other_shape: (usize, usize),
    },
    /// Calibration and deployment similarity have a different number of database rows.
    #[error(
        "deployment similarity has {deployment} database rows but calibration similarity has {calibration}; \
         both must be scored against the same database"
    )]
    DatabaseMismatch {
        /// |DB| of the calibration matrix.
        calibration: usize,
        /// |DB| of the deployment matrix.
        deployment: usize,
    },
    /// A ground-truth entry is neither 0 nor 1 (nor false/true).
    #[error("{what} has value {value} at row {row}, column {col}; ground truth must be 0/1 or bool")]
    BadLabel {
        /// Which ground-truth matrix.
        what: &'static str,
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
    /// A file's content is not what it must be (not `.npy`, truncated, not 2-D, ...).
    #[error("{path} {message}")]
    File {
        /// The file.
        path: String,
        /// What is wrong, phrased to follow the file name.
        message: String,
    },
    /// A file holds an array of a dtype this input does not take.
    #[error("{path} has dtype {dtype}; expected {expected}")]
    Dtype {
        /// The file.
        path: String,
        /// The dtype as NumPy spells it, e.g. `<c16`.
        dtype: String,
        /// What the input takes.
        expected: &'static str,
    },
    /// A problem with the content of a file that was read (e.g. a bad label).
    #[error("{path}: {source}")]
    InFile {
        /// The file.
        path: String,
        /// The problem.
        source: Box<Error>,
    },
    /// A method name the evaluation protocol does not know.
    #[error(
        "unknown method '{name}'; expected one of quantile-transfer, schubert, schubert-calibrated, \
         calibration-threshold, oracle"
    )]
    UnknownMethod {
        /// The name as given.
        name: String,
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
    // Inputs of the extensions (descriptors, positions), not of the SPEC pipeline.
    /// A descriptor or position matrix holds a NaN or infinite value.
    #[error("{what} contains {value} at row {row}, column {col}; every value must be finite")]
    NotFiniteValue {
        /// Which matrix, e.g. `"database descriptor matrix"`.
        what: &'static str,
        /// Row of the first offending entry.
        row: usize,
        /// Column of the first offending entry.
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// A descriptor is the zero vector, whose cosine similarity is undefined.
    #[error("{what} row {row} is all zeros; the cosine similarity of a zero vector is undefined")]
    ZeroNorm {
        /// Which descriptor matrix.
        what: &'static str,
        /// The first all-zero row.
        row: usize,
    },
    /// Two matrices whose rows must have the same length (descriptor dimension,
    /// coordinates per position) do not.
    #[error("{what} has {cols} columns but {other} has {other_cols}; both must have the same dimension")]
    ColumnMismatch {
        /// The second matrix.
        what: &'static str,
        /// Its number of columns.
        cols: usize,
        /// The matrix it must match.
        other: &'static str,
        /// That matrix's number of columns.
        other_cols: usize,
    },
    /// A position matrix has neither 2 nor 3 columns.
    #[error("{what} has {cols} columns; positions must be x, y (2 columns) or x, y, z (3 columns)")]
    PositionColumns {
        /// Which position matrix.
        what: &'static str,
        /// Its number of columns.
        cols: usize,
    },
}

impl Error {
    pub(crate) fn param(name: &'static str, message: impl Into<String>) -> Self {
        Self::InvalidParameter {
            name,
            message: message.into(),
        }
    }
}
