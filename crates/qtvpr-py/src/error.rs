//! Core errors as Python exceptions.
//!
//! Every [`qtvpr::Error`] is bad input. Its variant chooses the exception a Python user
//! expects ([`exception`]): a file that cannot be opened or written is the `OSError`
//! subclass of its kind (`FileNotFoundError`, `IsADirectoryError`, `PermissionError`), a
//! wrong dtype is a `TypeError`, anything else a `ValueError`. The message is the
//! core's, prefixed by the Python argument it is about: the core says which matrices
//! an error is about ([`qtvpr::Error::inputs`]), and each call maps those names to its
//! arguments ([`named_error`]).
//!
//! Positions and shapes are given in the caller's orientation: the core computes on
//! |DB| x |Q| views, so for query-major input its errors are transposed back
//! ([`Args::error`]). Errors of reading an argument (a file, or ground truth built in
//! the caller's orientation) are in that orientation already ([`input_error`]).

use pyo3::PyErr;
use pyo3::exceptions::{
    PyFileNotFoundError, PyIsADirectoryError, PyOSError, PyPermissionError, PyTypeError, PyValueError,
};
use qtvpr::Error;
use qtvpr::names::{CAL_SIMILARITY, DEPLOYMENT_SIMILARITY, GROUND_TRUTH, SIMILARITY, SOFT_GROUND_TRUTH};

/// How a call names its arguments, and whether its matrices were transposed.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Args {
    /// The Python name of the hard ground truth (`gt` or `gt_cal`).
    pub(crate) gt: &'static str,
    /// Whether the caller's matrices are query-major.
    pub(crate) query_major: bool,
}

impl Args {
    /// The exception for an error of the core's computation on the oriented views:
    /// positions and shapes in the caller's orientation, prefixed by the argument.
    pub(crate) fn error(self, err: Error) -> PyErr {
        let err = err.oriented(self.query_major);
        match &err {
            // The core names parameters as a user spells them; Python spells them with
            // underscores.
            Error::InvalidParameter { name, message } => {
                PyValueError::new_err(format!("{} {message}", name.replace(' ', "_")))
            }
            Error::DatabaseMismatch { .. } if !self.query_major => PyValueError::new_err(format!(
                "s_val: {err}; if the arrays are query-major (|Q| x |DB|, as VPR-Bench stores them), \
                 pass query_major=True"
            )),
            _ => named_error(
                err,
                &[
                    (CAL_SIMILARITY, "s_cal"),
                    (DEPLOYMENT_SIMILARITY, "s_val"),
                    (SIMILARITY, "s"),
                    (GROUND_TRUTH, self.gt),
                    (SOFT_GROUND_TRUTH, "gt_soft"),
                ],
            ),
        }
    }
}

/// The exception for a core error, prefixed by the arguments it is about: `arguments`
/// maps [`qtvpr::names`] constants to the Python arguments they came from. Errors
/// about no matrix (a parameter, which the core names itself) are not prefixed.
pub(crate) fn named_error(err: Error, arguments: &[(&'static str, &str)]) -> PyErr {
    let names: Vec<&str> = err.inputs(arguments).into_iter().copied().collect();
    match names.as_slice() {
        [] => exception(&err, err.to_string()),
        names => exception(&err, format!("{}: {err}", names.join(", "))),
    }
}

/// The exception for an error about argument `argument` as the caller gave it.
pub(crate) fn input_error(argument: &str, err: Error) -> PyErr {
    exception(&err, format!("{argument}: {err}"))
}

/// The exception class for `err`, carrying `message`.
fn exception(err: &Error, message: String) -> PyErr {
    use std::io::ErrorKind;
    match err {
        Error::Io { kind, .. } | Error::Write { kind, .. } => match kind {
            ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
            ErrorKind::IsADirectory => PyIsADirectoryError::new_err(message),
            ErrorKind::PermissionDenied => PyPermissionError::new_err(message),
            _ => PyOSError::new_err(message),
        },
        Error::Dtype { .. } => PyTypeError::new_err(message),
        Error::InFile { error, .. } => exception(error, message),
        _ => PyValueError::new_err(message),
    }
}
