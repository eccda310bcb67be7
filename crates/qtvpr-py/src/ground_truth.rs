//! `ground_truth_tolerance` and `ground_truth_positions`: ground truth without a matrix.

use numpy::{IntoPyArray, PyArray2};
use pyo3::prelude::*;
use qtvpr::npy::FloatMatrix;
use qtvpr::with_scores;

use crate::convert::{Int, MatrixArg, Real, non_negative};
use crate::error::{Args, named_error};

/// Ground truth of frame-aligned traverses: ``GT[i, j] = |i - j| <= tolerance``.
///
/// For datasets whose query j shows the place of database image j (Nordland, SFU,
/// Oxford): returns the ``n_db`` x ``n_queries`` bool matrix. A soft ground truth
/// (``gt_soft``) is the same call with a larger tolerance.
///
/// >>> qtvpr.ground_truth_tolerance(3, 3, 1).astype(int)
/// array([[1, 1, 0],
///        [1, 1, 1],
///        [0, 1, 1]])
///
/// Raises ``ValueError`` when a count is 0 or an argument is negative.
#[pyfunction]
#[pyo3(signature = (n_db, n_queries, tolerance))]
pub(crate) fn ground_truth_tolerance<'py>(
    py: Python<'py>,
    n_db: Int,
    n_queries: Int,
    tolerance: Int,
) -> PyResult<Bound<'py, PyArray2<bool>>> {
    let (n_db, n_queries) = (non_negative("n_db", n_db)?, non_negative("n_queries", n_queries)?);
    let tolerance = non_negative("tolerance", tolerance)?;
    let gt = py
        .detach(|| qtvpr::within_tolerance(n_db, n_queries, tolerance))
        .map_err(|e| {
            Args {
                gt: "n_db, n_queries",
                query_major: false,
            }
            .named(e)
        })?;
    Ok(gt.into_pyarray(py))
}

/// Ground truth from positions: ``GT[i, j]`` is true when database position i is within
/// ``radius`` of query position j (distance ``<= radius``, inclusive).
///
/// ``db_positions`` (|DB| x 2 or |DB| x 3) and ``query_positions`` (|Q| x the same) are
/// float32 or float64 coordinates, e.g. UTM east/north in metres (positives within 25
/// m). The squared distances are computed in float64 exactly as the brute force
/// ``((db[:, None] - q[None]) ** 2).sum(-1) <= radius * radius`` computes them on
/// float64 coordinates, so points at the radius agree, but through a k-d tree, without
/// the |DB| x |Q| x K intermediate. A soft ground truth (``gt_soft``) is the same call
/// with a larger radius. Returns the |DB| x |Q| bool matrix.
///
/// Raises ``TypeError`` for another dtype and ``ValueError`` for a negative or
/// non-finite radius, positions that are not 2-D, empty, not of 2 or 3 columns, of
/// different widths, or not finite.
#[pyfunction]
#[pyo3(signature = (db_positions, query_positions, radius))]
pub(crate) fn ground_truth_positions<'py>(
    py: Python<'py>,
    db_positions: &Bound<'py, PyAny>,
    query_positions: &Bound<'py, PyAny>,
    radius: Real,
) -> PyResult<Bound<'py, PyArray2<bool>>> {
    let radius = radius.get("radius")?;
    qtvpr::check_radius("radius", radius).map_err(named_error)?;
    let db = MatrixArg::extract_as("db_positions", db_positions, FloatMatrix::Positions)?;
    let q = MatrixArg::extract_as("query_positions", query_positions, FloatMatrix::Positions)?;
    let (d, q) = (db.view(false), q.view(false));
    let gt = py
        .detach(|| with_scores!(d, |d| with_scores!(q, |q| qtvpr::within_radius(d, q, radius))))
        .map_err(named_error)?;
    Ok(gt.into_pyarray(py))
}
