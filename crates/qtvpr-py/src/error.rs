//! Core errors as Python exceptions.
//!
//! Every [`qtvpr::Error`] is bad input. Its variant chooses the exception a Python user
//! expects ([`exception`]): a file that cannot be opened or written is the `OSError`
//! subclass of its kind (`FileNotFoundError`, `IsADirectoryError`, `PermissionError`), a
//! wrong dtype is a `TypeError`, anything else a `ValueError`. The message is the
//! core's, prefixed by the Python argument it is about: the core says which matrices
//! an error is about ([`qtvpr::Error::inputs`]), and [`Args::argument`] names each
//! [`Input`] by its argument, in one exhaustive `match` (an input added to the core
//! does not compile here until it has a Python name).
//!
//! Positions and shapes are given in the caller's orientation: the core computes on
//! |DB| x |Q| views, so for query-major input its errors are transposed back
//! ([`Args::error`]). Errors of reading an argument (a file, or ground truth built in
//! the caller's orientation) are in that orientation already ([`input_error`]).

use pyo3::PyErr;
use pyo3::exceptions::{
    PyFileNotFoundError, PyIsADirectoryError, PyMemoryError, PyOSError, PyPermissionError, PyTypeError, PyValueError,
};
use qtvpr::Error;
use qtvpr::Input;

/// How a call names its arguments, and whether its matrices were transposed.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Args {
    /// The Python name of the hard ground truth (`gt` or `gt_cal`; `n_db, n_queries` for
    /// the ground truth those make).
    pub(crate) gt: &'static str,
    /// Whether the caller's matrices are query-major.
    pub(crate) query_major: bool,
}

/// How the functions without a `gt_cal` name their arguments.
pub(crate) const NAMED: Args = Args {
    gt: "gt",
    query_major: false,
};

impl Args {
    /// The Python argument `input` comes from.
    pub(crate) fn argument(self, input: Input) -> &'static str {
        match input {
            Input::Similarity => "s",
            Input::CalSimilarity => "s_cal",
            Input::DeploymentSimilarity => "s_val",
            Input::GroundTruth => self.gt,
            Input::SoftGroundTruth => "gt_soft",
            Input::DbDescriptors => "db",
            Input::QueryDescriptors => "queries",
            Input::DbPositions => "db_positions",
            Input::QueryPositions => "query_positions",
        }
    }

    /// The exception for an error of the core's computation on the oriented views:
    /// positions and shapes in the caller's orientation, prefixed by the argument.
    pub(crate) fn error(self, err: Error) -> PyErr {
        self.error_naming(err, |input| self.argument(input))
    }

    /// [`Args::error`] for the transfer of the queries after a split of `s_cal`
    /// (`cal_queries=`, `cal_fraction=`): the deployment similarity is `s_cal` too.
    pub(crate) fn split_error(self, err: Error) -> PyErr {
        self.error_naming(err, |input| match input {
            Input::DeploymentSimilarity => self.argument(Input::CalSimilarity),
            input => self.argument(input),
        })
    }

    /// [`Args::error`], naming inputs by `argument`, with the core's advice when the
    /// error is the usual sign of a matrix read the wrong way round
    /// ([`qtvpr::orientation_hint`]).
    fn error_naming(self, err: Error, argument: impl Fn(Input) -> &'static str) -> PyErr {
        let hint = qtvpr::orientation_hint(&err, self.query_major, "query_major=True");
        let err = err.oriented(self.query_major);
        let message = match &err {
            // The core names parameters as a user spells them; Python spells them with
            // underscores.
            Error::InvalidParameter { name, message } => format!("{} {message}", name.replace(' ', "_")),
            _ => message(&err, argument),
        };
        match hint {
            Some(hint) => exception(&err, format!("{message}; {hint}")),
            None => exception(&err, message),
        }
    }

    /// The exception for a core error as it is, prefixed by the arguments it is about
    /// ([`Args::argument`]). Errors about no matrix (a parameter, which the core names
    /// itself) are not prefixed.
    pub(crate) fn named(self, err: Error) -> PyErr {
        named(err, |input| self.argument(input))
    }
}

/// The exception for a core error as it is, prefixed by the arguments it is about, as
/// `argument` names them.
fn named(err: Error, argument: impl Fn(Input) -> &'static str) -> PyErr {
    let message = message(&err, argument);
    exception(&err, message)
}

/// The message of a core error, prefixed by the arguments it is about, as `argument`
/// names them.
fn message(err: &Error, argument: impl Fn(Input) -> &'static str) -> String {
    let names = err.inputs(|input| Some(argument(input)));
    match names.as_slice() {
        [] => err.to_string(),
        names => format!("{}: {err}", names.join(", ")),
    }
}

/// [`Args::named`] for the functions without a `gt_cal` ([`NAMED`]).
pub(crate) fn named_error(err: Error) -> PyErr {
    NAMED.named(err)
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
        Error::Allocation { .. } => PyMemoryError::new_err(message),
        Error::InFile { error, .. } => exception(error, message),
        _ => PyValueError::new_err(message),
    }
}
