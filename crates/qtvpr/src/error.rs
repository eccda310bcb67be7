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
}

impl Error {
    pub(crate) fn param(name: &'static str, message: impl Into<String>) -> Self {
        Self::InvalidParameter {
            name,
            message: message.into(),
        }
    }
}
