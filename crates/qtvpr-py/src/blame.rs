//! Core errors of the extension functions (descriptors, sequences, positions) as
//! `ValueError`s naming the Python argument.

use pyo3::PyErr;
use pyo3::exceptions::PyValueError;
use qtvpr::Error;

/// The `ValueError` for a core error: `names` maps the core's matrix names (e.g.
/// [`qtvpr::similarity::DB_DESCRIPTORS`]) to the Python arguments they came from, and
/// the message is prefixed by them. Parameters are named by the core already.
pub(crate) fn value_error(err: Error, names: &[(&str, &str)]) -> PyErr {
    let about: Vec<&str> = match &err {
        Error::Empty { what, .. }
        | Error::NotFinite { what, .. }
        | Error::NotFiniteValue { what, .. }
        | Error::ZeroNorm { what, .. }
        | Error::PositionColumns { what, .. } => vec![what],
        Error::ColumnMismatch { what, other, .. } => vec![what, other],
        _ => vec![],
    };
    let arguments: Vec<&str> = about
        .iter()
        .filter_map(|w| names.iter().find(|(name, _)| name == w))
        .map(|(_, argument)| *argument)
        .collect();
    match arguments.as_slice() {
        [] => PyValueError::new_err(err.to_string()),
        args => PyValueError::new_err(format!("{}: {err}", args.join(", "))),
    }
}
