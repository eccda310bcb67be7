//! Core errors as Python exceptions.
//!
//! Every [`qtvpr::Error`] is bad input, so it becomes a `ValueError` carrying the
//! core's message, prefixed by the Python argument it is about. Positions and shapes
//! are given in the caller's orientation: the core sees |DB| x |Q| views, so for
//! query-major input they are swapped back.

use pyo3::PyErr;
use pyo3::exceptions::PyValueError;
use qtvpr::Error;

/// How a call names its arguments, and whether its matrices were transposed.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Args {
    /// The Python name of the hard ground truth (`gt` or `gt_cal`).
    pub(crate) gt: &'static str,
    /// Whether the caller's matrices are query-major.
    pub(crate) query_major: bool,
}

impl Args {
    /// The Python argument the core's matrix name `what` refers to.
    fn argument(self, what: &str) -> &str {
        match what {
            "calibration similarity" => "s_cal",
            "deployment similarity" => "s_val",
            "similarity" => "s",
            "ground truth" => self.gt,
            "soft ground truth" => "gt_soft",
            other => other,
        }
    }

    /// `(a, b)`, swapped for query-major input.
    fn pair(self, (a, b): (usize, usize)) -> (usize, usize) {
        if self.query_major { (b, a) } else { (a, b) }
    }

    /// The `ValueError` for a core error.
    pub(crate) fn error(self, err: Error) -> PyErr {
        let message = match err {
            Error::Empty { what, rows, cols } => {
                let (rows, cols) = self.pair((rows, cols));
                format!("{}: {}", self.argument(what), Error::Empty { what, rows, cols })
            }
            Error::NotFinite { what, row, col, value } => {
                let (row, col) = self.pair((row, col));
                format!(
                    "{}: {}",
                    self.argument(what),
                    Error::NotFinite { what, row, col, value }
                )
            }
            Error::BadLabel { what, row, col, value } => {
                let (row, col) = self.pair((row, col));
                format!("{}: {}", self.argument(what), Error::BadLabel { what, row, col, value })
            }
            Error::ShapeMismatch {
                what,
                shape,
                other,
                other_shape,
            } => {
                let (shape, other_shape) = (self.pair(shape), self.pair(other_shape));
                format!(
                    "{}: {}",
                    self.argument(what),
                    Error::ShapeMismatch {
                        what,
                        shape,
                        other,
                        other_shape
                    }
                )
            }
            err @ Error::DatabaseMismatch { .. } => format!("s_val: {err}"),
            // The core names parameters as a user spells them; Python spells them
            // with underscores.
            Error::InvalidParameter { name, message } => format!("{} {message}", name.replace(' ', "_")),
            err => err.to_string(),
        };
        PyValueError::new_err(message)
    }
}
