//! Core errors as Python exceptions.
//!
//! Every [`qtvpr::Error`] is bad input. Its variant chooses the exception a Python user
//! expects ([`exception`]): a file that cannot be opened or written is the `OSError`
//! subclass of its kind (`FileNotFoundError`, `IsADirectoryError`, `PermissionError`), a
//! wrong dtype is a `TypeError`, anything else a `ValueError`. The message is the
//! core's, prefixed by the Python argument it is about.
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
    fn argument(self, what: &'static str) -> &'static str {
        match what {
            "calibration similarity" => "s_cal",
            "deployment similarity" => "s_val",
            "similarity" => "s",
            "ground truth" => self.gt,
            "soft ground truth" => "gt_soft",
            other => other,
        }
    }

    /// The exception for an error of the core's computation on the oriented views.
    pub(crate) fn error(self, err: Error) -> PyErr {
        let err = if self.query_major { err.transposed() } else { err };
        match &err {
            Error::Empty { what, .. }
            | Error::NotFinite { what, .. }
            | Error::BadLabel { what, .. }
            | Error::ShapeMismatch { what, .. } => input_error(self.argument(what), err),
            Error::DatabaseMismatch { .. } => input_error("s_val", err),
            // The core names parameters as a user spells them; Python spells them with
            // underscores.
            Error::InvalidParameter { name, message } => {
                PyValueError::new_err(format!("{} {message}", name.replace(' ', "_")))
            }
            _ => exception(&err, err.to_string()),
        }
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
        Error::InFile { source, .. } => exception(source, message),
        _ => PyValueError::new_err(message),
    }
}
