//! `cosine_similarity` and `sequence_match`: similarity matrices from descriptors.

use numpy::{IntoPyArray, PyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use qtvpr::npy::FloatMatrix;
use qtvpr::{Sequence, with_scores};

use crate::convert::Int;
use crate::convert::MatrixArg;
use crate::error::named_error;

/// A sequence window from Python arguments: a negative length gets the core's message.
fn sequence(length: Int, causal: bool) -> PyResult<Sequence> {
    let length = length.at_least("sequence length", 0, "odd and >= 1")?;
    let sequence = Sequence { length, causal };
    sequence.validate().map_err(named_error)?;
    Ok(sequence)
}

/// Cosine similarity of database and query descriptors, optionally sequence-matched.
///
/// ``db`` (|DB| x D) and ``queries`` (|Q| x D) hold one descriptor per row, float32 or
/// float64 (e.g. VPR-methods-evaluation's ``database_descriptors.npy`` and
/// ``queries_descriptors.npy``). Returns the |DB| x |Q| float32 matrix ``S[i, j]`` =
/// cosine of ``db[i]`` and ``queries[j]``, i.e. ``normalize(db) @ normalize(queries).T``.
/// The arithmetic is float64 (faer's parallel GEMM) and each entry is rounded once to
/// float32, so the result is within float32 rounding of the exact cosine whatever the
/// descriptor dimension D and the input dtypes.
///
/// ``sequence=L`` (odd, >= 1) applies :func:`sequence_match` with window ``L`` (and
/// ``causal``), an extension beyond the paper: SeqSLAM-style sequence matching.
///
/// Raises ``TypeError`` for a dtype other than float32/float64, ``ValueError`` for a
/// matrix that is not 2-D, empty, of different descriptor dimensions, holds NaN or
/// infinity, or has an all-zero row (its cosine is undefined), and for a bad ``sequence``.
#[pyfunction]
#[pyo3(signature = (db, queries, *, sequence = None, causal = false))]
pub(crate) fn cosine_similarity<'py>(
    py: Python<'py>,
    db: &Bound<'py, PyAny>,
    queries: &Bound<'py, PyAny>,
    sequence: Option<Int>,
    causal: bool,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let window = match sequence {
        Some(length) => Some(self::sequence(length, causal)?),
        None if causal => return Err(PyValueError::new_err("causal=True needs a sequence length")),
        None => None,
    };
    let db = MatrixArg::extract_as("db", db, FloatMatrix::Descriptors)?;
    let queries = MatrixArg::extract_as("queries", queries, FloatMatrix::Descriptors)?;
    let (d, q) = (db.view(false), queries.view(false));
    let s = py
        .detach(|| {
            let s = with_scores!(d, |d| with_scores!(q, |q| qtvpr::cosine_similarity(d, q)))?;
            match window {
                Some(window) => qtvpr::sequence_match(s.view(), window),
                None => Ok(s),
            }
        })
        .map_err(named_error)?;
    Ok(s.into_pyarray(py))
}

/// SeqSLAM-style sequence matching of a similarity matrix (an extension beyond the
/// paper, its stated future work).
///
/// ``S_seq[i, j]`` is the mean of ``s[i + d, j + d]`` over the offsets ``d`` of the
/// window that keep the entry inside the matrix: ``d`` in ``-(length-1)/2 ..
/// (length-1)/2`` (centred, offline), or ``-(length-1) .. 0`` with ``causal=True`` (the
/// current frame and the ones before it, as a robot sees them online). ``length`` must
/// be odd and >= 1; 1 returns ``s`` unchanged. This suits traverses in the same
/// direction at a similar frame rate. ``s`` is |DB| x |Q| (or its transpose: the
/// operation commutes with transposition), float32 or float64; the result has its
/// dtype, with sums in float64, in O(|DB| |Q|) whatever ``length``.
///
/// Raises ``TypeError`` for another dtype, ``ValueError`` for a bad ``length`` or an
/// empty, non-2-D or non-finite ``s``.
#[pyfunction]
#[pyo3(signature = (s, length, *, causal = false))]
pub(crate) fn sequence_match<'py>(
    py: Python<'py>,
    s: &Bound<'py, PyAny>,
    length: Int,
    causal: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let window = sequence(length, causal)?;
    let s = MatrixArg::extract("s", s)?;
    Ok(with_scores!(s.view(false), |v| py
        .detach(|| qtvpr::sequence_match(v, window))
        .map_err(named_error)?
        .into_pyarray(py)
        .into_any()))
}
