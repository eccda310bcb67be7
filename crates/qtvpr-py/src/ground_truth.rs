//! `ground_truth_tolerance` and `ground_truth_positions`: ground truth without a matrix;
//! `ground_truth_from_sequence`: ground truth for calibration queries without any
//! (semantics §16's self-motion labels, a `SelfMotionLabels`).

use numpy::{IntoPyArray, PyArray2};
use pyo3::prelude::*;
use qtvpr::npy::FloatMatrix;
use qtvpr::{LabelParams, with_scores};

use crate::convert::{Int, MatrixArg, Real, count, non_negative, real};
use crate::error::{Args, input_error, named_error};
use crate::self_motion::SelfMotionLabels;

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

/// Self-motion labels (semantics §16): ground truth for calibration queries from their
/// similarity alone, for a robot without GNSS.
///
/// ``s_cal`` is the |DB| x |Qcal| calibration similarity (float32 or float64, or the
/// path of a ``.npy`` file; |Qcal| x |DB| with ``query_major=True``), its columns in the
/// order the queries were taken. Query q's best match (the first maximum of its column)
/// is believed when the best matches of its ``neighbours`` neighbours on each side lie
/// on its line through the database (query ``q + d`` agrees when its best match is
/// within ``sequence_tolerance + sequence_drift * |d|`` rows of ``b_q + sequence_speed *
/// d``): a *pseudo-positive* when at least ``positive_level`` of them agree, a
/// *pseudo-negative* when at most ``negative_level`` do, and it *abstains* in between.
/// Each argument left as ``None`` is the library's default: 5 neighbours, levels 0.7 and
/// 0.3, speed 1 (the same spacing; -1 for the database's route driven backwards),
/// tolerance 2 and drift 0.2 (the sequence gate's). It assumes that both traverses are
/// sequences in the same direction at a similar spacing (or the speed that relates
/// them).
///
/// Returns a :class:`SelfMotionLabels`: its ``hard`` and ``soft`` ground truth (a
/// pseudo-positive's best match is its column's one hard positive, a pseudo-negative's
/// column has none, an abstaining query's best match is soft only, so it makes no
/// decision), in the layout of ``s_cal``, for ``Calibration(s_cal, labels.hard,
/// gt_soft=labels.soft)``; or pass the labels themselves, ``Calibration(s_cal,
/// labels)``, and the calibration keeps their :attr:`~SelfMotionLabels.record`
/// (:attr:`Calibration.labels`, ``meta["labels"]`` of its file). Single matching only.
///
/// Raises ``ValueError`` naming the argument for a parameter out of range (``neighbours
/// < 1``, levels outside ``0 <= negative_level < positive_level <= 1``, a non-finite
/// speed, a negative tolerance or drift), and naming ``s_cal`` for fewer than
/// ``neighbours + 1`` queries, a database too small to tell a line from chance, or no
/// pseudo-positive at all (the traverse is not a sequence, runs backwards, or its
/// matcher is rarely right): a calibration on such labels would reject every query.
/// ``TypeError`` for another dtype.
#[pyfunction]
#[pyo3(signature = (
    s_cal, *, neighbours = None, positive_level = None, negative_level = None, sequence_speed = None,
    sequence_tolerance = None, sequence_drift = None, query_major = false,
))]
#[allow(clippy::too_many_arguments)] // the Python signature
pub(crate) fn ground_truth_from_sequence(
    py: Python<'_>,
    s_cal: &Bound<'_, PyAny>,
    neighbours: Option<Int>,
    positive_level: Option<Real>,
    negative_level: Option<Real>,
    sequence_speed: Option<Real>,
    sequence_tolerance: Option<Real>,
    sequence_drift: Option<Real>,
    query_major: bool,
) -> PyResult<SelfMotionLabels> {
    let args = Args {
        gt: "gt_cal",
        query_major,
    };
    let neighbours = neighbours.map(|n| count("neighbours", n)).transpose()?;
    let params = LabelParams::resolve(
        neighbours,
        real("positive_level", positive_level)?,
        real("negative_level", negative_level)?,
        real("sequence_speed", sequence_speed)?,
        real("sequence_tolerance", sequence_tolerance)?,
        real("sequence_drift", sequence_drift)?,
    )
    .map_err(|e| args.error(e))?;
    let s = MatrixArg::extract("s_cal", s_cal)?;
    let s = s.view(query_major);
    let labels = py
        .detach(|| with_scores!(s, |s| qtvpr::self_motion_labels(s, &params)))
        .map_err(|e| match e {
            // The rule's own errors are about the traverse.
            qtvpr::Error::InvalidParameter { .. } => input_error("s_cal", e),
            e => args.error(e),
        })?;
    SelfMotionLabels::new(py, &labels, query_major)
}
