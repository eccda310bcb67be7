//! `qtvpr._native`: the Python binding of the `qtvpr` core.
//!
//! The binding is thin on purpose: it converts arguments (`convert`), calls the core
//! with the GIL released, and converts results and errors back (`error`). There is no
//! arithmetic here, so the core's tests and the Python parity tests against
//! `qtvpr.reference` cover the numbers, and this crate only has to get the plumbing
//! right: dtypes, orientation, strides, exceptions.
//!
//! Python docstrings live on the `#[pyfunction]`s and `#[pymethods]` below, with
//! `#[pyo3(signature = ...)]` so that `help()` shows the real signature; the types live
//! in `py/qtvpr/_native.pyi`.

// Those docstrings are Python's (reStructuredText, `>>>` examples), not rustdoc's
// Markdown: a `[...]` in them is a Python list, not a link.
#![allow(rustdoc::broken_intra_doc_links)]

mod calibration;
mod convert;
mod descriptors;
mod error;
mod evaluate;
mod ground_truth;
mod image_names;
mod online;
mod self_motion;
mod similarity;

use pyo3::prelude::*;
use qtvpr::Matching;

use crate::calibration::{CalibrationArgs, PyCalibration, SequenceGateArgs, TransferResult};
use crate::convert::{GroundTruthArgs, Int, MatrixArg, Real};
use crate::error::Args;
use qtvpr::with_scores;

/// Quantile transfer from calibration to deployment queries.
///
/// Shorthand for ``Calibration(s_cal, gt_cal, gt_soft=gt_soft, matching=matching,
/// query_major=query_major).transfer(s_val, k=k, precision=precision,
/// segment_size=segment_size, query_major=query_major)``; see :class:`Calibration`.
///
/// ``s_cal`` (|DB| x |Qcal|) and ``s_val`` (|DB| x |Qval|) are float32 or float64
/// similarity matrices, higher is more similar; ``gt_cal`` and ``gt_soft`` are the
/// calibration's hard and soft ground truth (bool or integer 0/1). Each may also be a
/// path (``str`` or ``os.PathLike``) to a ``.npy`` file, or for ``gt_cal`` a
/// VPR_Tutorial ``.npz`` (``GThard``, optional ``GTsoft``), read as ``qtvpr-cli`` reads
/// it. With ``query_major=True`` every matrix is given transposed (|Q| x |DB|, as
/// VPR-Bench stores them). Returns a :class:`TransferResult`; raises as
/// :class:`Calibration` and :meth:`Calibration.transfer` do.
///
/// One matrix of every query may be split instead, as ``qtvpr-cli threshold
/// --similarity S --cal-queries N`` does: with ``cal_queries=n`` (the first ``n``
/// queries) or ``cal_fraction=f`` (the first ``floor(f * |Q|)``) and no ``s_val``, the
/// first queries of ``s_cal`` (a matrix, a path or :class:`Descriptors`) calibrate and
/// the rest are thresholded; ``gt_cal`` then labels every query of ``s_cal``, and
/// segments count from the first thresholded query. Errors name ``s_cal`` and give
/// positions in the whole matrix. The queries split are one traverse: with the sequence
/// gate, the first thresholded queries' consistency reads the calibration queries' best
/// matches (semantics §15).
///
/// ``gate`` (``"none"``, ``"margin"``, ``"sequence"`` or ``"margin,sequence"``) and the
/// sequence gate's ``sequence_window``, ``sequence_level``, ``sequence_speed``,
/// ``sequence_tolerance`` and ``sequence_drift`` (``None``: the defaults) are those of
/// :meth:`Calibration.transfer`.
#[pyfunction]
#[pyo3(signature = (
    s_cal, gt_cal, s_val = None, *, gt_soft = None, k = Int::Small(10), precision = Real::Value(1.0), matching = "single",
    segment_size = None, gate = "none", query_major = false, cal_queries = None, cal_fraction = None,
    sequence_window = None, sequence_level = None, sequence_speed = None, sequence_tolerance = None,
    sequence_drift = None,
), text_signature = "(s_cal, gt_cal, s_val=None, *, gt_soft=None, k=10, precision=1.0, matching='single', \
    segment_size=None, gate='none', query_major=False, cal_queries=None, cal_fraction=None, \
    sequence_window=None, sequence_level=None, sequence_speed=None, sequence_tolerance=None, \
    sequence_drift=None)")]
#[allow(clippy::too_many_arguments)] // the Python signature
fn quantile_transfer(
    py: Python<'_>,
    s_cal: &Bound<'_, PyAny>,
    gt_cal: &Bound<'_, PyAny>,
    s_val: Option<&Bound<'_, PyAny>>,
    gt_soft: Option<&Bound<'_, PyAny>>,
    k: Int,
    precision: Real,
    matching: &str,
    segment_size: Option<Int>,
    gate: &str,
    query_major: bool,
    cal_queries: Option<Int>,
    cal_fraction: Option<Real>,
    sequence_window: Option<Int>,
    sequence_level: Option<Real>,
    sequence_speed: Option<Real>,
    sequence_tolerance: Option<Real>,
    sequence_drift: Option<Real>,
) -> PyResult<TransferResult> {
    let (k, precision) = (Some(convert::count("k", k)?), Some(precision.get("precision")?));
    let sequence = SequenceGateArgs {
        window: sequence_window,
        level: sequence_level,
        speed: sequence_speed,
        tolerance: sequence_tolerance,
        drift: sequence_drift,
    };
    let segment_size = segment_size.map(|m| convert::count("segment_size", m)).transpose()?;
    let args = Args {
        gt: "gt_cal",
        query_major,
    };
    let gate = convert::gate(Some(gate)).map_err(|e| args.error(e))?;
    let split = calibration::split_arg(cal_queries, cal_fraction)?;
    // Check the cheap parameters before the calibration does any work (a calibration
    // from arrays has the library's defaults).
    let overrides = sequence.clone().overrides()?;
    let params = qtvpr::Params::resolve(&qtvpr::Defaults::default(), k, precision, segment_size, gate, overrides)
        .map_err(|e| args.error(e))?;
    let calibration = || CalibrationArgs::extract(py, s_cal, gt_cal, gt_soft, matching, query_major);
    match (s_val, split) {
        (Some(s_val), None) => {
            let cal = calibration()?.calibrate(py, None, 1)?;
            cal.transfer(
                py,
                s_val,
                k.map(Int::from),
                precision.map(Real::Value),
                segment_size.map(Int::from),
                gate.map(qtvpr::Gate::as_str),
                query_major,
                sequence.window,
                sequence.level,
                sequence.speed,
                sequence.tolerance,
                sequence.drift,
            )
        }
        (None, Some(split)) => calibration()?.split_transfer(py, split, params),
        (Some(_), Some(_)) => Err(pyo3::exceptions::PyValueError::new_err(
            "s_val and cal_queries/cal_fraction exclude each other: give s_val, or split s_cal",
        )),
        (None, None) => Err(pyo3::exceptions::PyValueError::new_err(
            "no deployment queries: give s_val, or cal_queries or cal_fraction to split s_cal",
        )),
    }
}

/// The margin of every query of a similarity matrix (semantics §13).
///
/// ``s`` is |DB| x |Q| (|Q| x |DB| with ``query_major=True``), float32 or float64, or
/// the path of a ``.npy`` file. A query's margin is ``(s1 - s2) / sigma``: its largest
/// score less its second largest (equal when the largest occurs twice) over the
/// population standard deviation of its |DB| scores, 0 for a constant column. It does
/// not change when a column's scores are shifted or scaled: it says how far the best
/// match stands out, whatever the score scale. Returns a float64 array of |Q| margins.
/// Raises ``ValueError`` for |DB| < 2, empty, NaN or infinite scores.
#[pyfunction]
#[pyo3(signature = (s, *, query_major = false))]
fn margins<'py>(
    py: Python<'py>,
    s: &Bound<'py, PyAny>,
    query_major: bool,
) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
    let args = Args { gt: "gt", query_major };
    let s = MatrixArg::extract("s", s)?;
    let s = s.view(query_major);
    let m = py
        .detach(|| with_scores!(s, |s| qtvpr::margins(s)))
        .map_err(|e| args.error(e))?;
    Ok(numpy::IntoPyArray::into_pyarray(m, py))
}

/// The best threshold of a similarity matrix under a precision target.
///
/// ``s`` is a |DB| x |Q| float32 or float64 similarity matrix, ``gt`` and ``gt_soft``
/// its hard and optional soft ground truth (bool or integer 0/1; entries soft but not
/// hard are ignored). Candidates follow ``matching``: ``"single"`` is each query's best
/// match, ``"multi"`` every entry. Returns the threshold of maximum recall whose
/// precision is at least ``precision`` (in (0, 1]), the highest such: always the score
/// of a correct candidate, or ``math.inf`` (reject all) when there is none.
/// ``query_major=True`` takes both matrices as |Q| x |DB|.
///
/// Each matrix may be an array or a path to a ``.npy`` file (``gt`` also a
/// VPR_Tutorial ``.npz``). Raises ``TypeError`` for an unsupported dtype,
/// ``ValueError`` for bad input or a bad file, ``OSError`` (``FileNotFoundError``,
/// ...) for a file that cannot be read.
#[pyfunction]
#[pyo3(
    signature = (s, gt, *, gt_soft = None, precision = Real::Value(1.0), matching = "single", query_major = false),
    text_signature = "(s, gt, *, gt_soft=None, precision=1.0, matching='single', query_major=False)"
)]
fn best_threshold(
    py: Python<'_>,
    s: &Bound<'_, PyAny>,
    gt: &Bound<'_, PyAny>,
    gt_soft: Option<&Bound<'_, PyAny>>,
    precision: Real,
    matching: &str,
    query_major: bool,
) -> PyResult<f64> {
    let precision = precision.get("precision")?;
    let args = Args { gt: "gt", query_major };
    let matching: Matching = matching.parse().map_err(|e| args.error(e))?;
    let s = MatrixArg::extract("s", s)?;
    let gt = GroundTruthArgs::extract("gt", gt, gt_soft)?;
    let (s, gt) = (s.view(query_major), gt.view(query_major));
    let gt = py.detach(|| gt.build())?;
    py.detach(|| with_scores!(s, |s| qtvpr::best_threshold(s, &gt, matching, precision)))
        .map_err(|e| args.error(e))
}

/// The decisions of a similarity matrix at one threshold.
///
/// A candidate (per ``matching``, as in :func:`best_threshold`) is accepted when its
/// score is ``>= threshold``. Returns ``{"tp", "fp", "accepted", "positives", "precision",
/// "recall", "precision_lower95"}``, the keys of a segment of :func:`evaluate`:
/// ``accepted`` is TP + FP, precision ``None`` when nothing is accepted (it would rest on
/// no decision), recall 0 when there are no positives
/// (queries with a hard match in ``"single"`` mode, hard matches in ``"multi"``), and
/// ``precision_lower95`` the one-sided 95% Clopper-Pearson lower bound on the precision
/// (``None`` when nothing is accepted). ``threshold`` may be ``inf`` (accepts nothing) but not NaN. Matrices
/// may be arrays or paths, and errors are raised, as in :func:`best_threshold`.
#[pyfunction]
#[pyo3(signature = (s, gt, threshold, *, gt_soft = None, matching = "single", query_major = false))]
fn counts<'py>(
    py: Python<'py>,
    s: &Bound<'py, PyAny>,
    gt: &Bound<'py, PyAny>,
    threshold: Real,
    gt_soft: Option<&Bound<'py, PyAny>>,
    matching: &str,
    query_major: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let threshold = threshold.get("threshold")?;
    let args = Args { gt: "gt", query_major };
    let matching: Matching = matching.parse().map_err(|e| args.error(e))?;
    let s = MatrixArg::extract("s", s)?;
    let gt = GroundTruthArgs::extract("gt", gt, gt_soft)?;
    let (s, gt) = (s.view(query_major), gt.view(query_major));
    let gt = py.detach(|| gt.build())?;
    let c = py
        .detach(|| with_scores!(s, |s| qtvpr::counts(s, &gt, matching, threshold)))
        .map_err(|e| args.error(e))?;
    Ok(pythonize::pythonize(py, &c)?)
}

/// The ranked-correlation matrix of deployment and calibration queries.
///
/// Every column of ``s_val`` (|DB| x |Qval|) and ``s_cal`` (|DB| x |Qcal|) is sorted
/// in descending order; entry ``[j, i]`` of the result (|Qval| x |Qcal|, float64) is
/// the Pearson correlation of deployment profile j with calibration profile i, 0 when
/// either is constant. ``query_major=True`` takes both matrices as |Q| x |DB|. Either
/// may be the path of a ``.npy`` file (memory-mapped).
#[pyfunction]
#[pyo3(signature = (s_val, s_cal, *, query_major = false))]
fn ranked_correlation<'py>(
    py: Python<'py>,
    s_val: &Bound<'py, PyAny>,
    s_cal: &Bound<'py, PyAny>,
    query_major: bool,
) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
    let args = Args { gt: "gt", query_major };
    let val = MatrixArg::extract("s_val", s_val)?;
    let cal = MatrixArg::extract("s_cal", s_cal)?;
    let (val, cal) = (val.view(query_major), cal.view(query_major));
    let r = py
        .detach(|| with_scores!(val, |val| with_scores!(cal, |cal| qtvpr::ranked_correlation(val, cal))))
        .map_err(|e| args.error(e))?;
    Ok(numpy::IntoPyArray::into_pyarray(r, py))
}

/// Schubert et al.'s automatic threshold over every raw score of ``s``.
///
/// ``mu`` is the median, ``sigma`` the median absolute deviation over 0.675, and the
/// threshold ``mu + 4.753424308817087 * sigma`` (the standard normal quantile at
/// 1 - 1e-6), or ``mu`` when ``sigma`` is 0. No ground truth is needed, and the
/// orientation of ``s`` (float32 or float64) does not matter.
#[pyfunction]
#[pyo3(signature = (s))]
fn schubert_threshold(py: Python<'_>, s: &Bound<'_, PyAny>) -> PyResult<f64> {
    let args = Args {
        gt: "gt",
        query_major: false,
    };
    let s = MatrixArg::extract("s", s)?;
    let s = s.view(false);
    py.detach(|| with_scores!(s, |s| qtvpr::schubert_threshold(s)))
        .map_err(|e| args.error(e))
}

/// Set the number of threads of the library's thread pool to ``n``.
///
/// The compiled core runs its parallel work on a pool of its own threads (named
/// ``qtvpr-0``, ``qtvpr-1``, ...). By default it has ``RAYON_NUM_THREADS`` threads (at
/// most 1024) if that environment variable is set when the pool is first used, else one
/// per core.
/// This replaces the pool with one of ``n`` threads; calls already running finish on the
/// old one. A process forked afterwards (``multiprocessing`` on Linux) builds a pool of
/// its own, of the same size. Raises ``ValueError`` for ``n < 1`` or ``n > 1024`` (the
/// work is CPU-bound: more threads than cores only contend).
#[pyfunction]
#[pyo3(signature = (n))]
fn set_threads(py: Python<'_>, n: Int) -> PyResult<()> {
    let args = Args {
        gt: "gt",
        query_major: false,
    };
    let n = convert::count("threads", n)?;
    py.detach(|| qtvpr::set_threads(n)).map_err(|e| args.error(e))
}

/// Quantile transfer for visual place recognition: the compiled core of ``qtvpr``.
#[pymodule(gil_used = false)]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(quantile_transfer, m)?)?;
    m.add_function(wrap_pyfunction!(set_threads, m)?)?;
    m.add_function(wrap_pyfunction!(best_threshold, m)?)?;
    m.add_function(wrap_pyfunction!(counts, m)?)?;
    m.add_function(wrap_pyfunction!(ranked_correlation, m)?)?;
    m.add_function(wrap_pyfunction!(margins, m)?)?;
    // Extensions: similarity from descriptors, sequence matching, ground truth.
    m.add_function(wrap_pyfunction!(similarity::cosine_similarity, m)?)?;
    m.add_function(wrap_pyfunction!(similarity::sequence_match, m)?)?;
    m.add_function(wrap_pyfunction!(ground_truth::ground_truth_tolerance, m)?)?;
    m.add_function(wrap_pyfunction!(ground_truth::ground_truth_positions, m)?)?;
    m.add_function(wrap_pyfunction!(ground_truth::ground_truth_from_sequence, m)?)?;
    m.add_function(wrap_pyfunction!(image_names::utm_positions, m)?)?;
    m.add_function(wrap_pyfunction!(image_names::image_paths, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate::evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate::ablation, m)?)?;
    m.add_function(wrap_pyfunction!(schubert_threshold, m)?)?;
    m.add_class::<descriptors::PyDescriptors>()?;
    m.add_class::<PyCalibration>()?;
    m.add_class::<TransferResult>()?;
    m.add_class::<self_motion::SelfMotionLabels>()?;
    m.add_class::<online::PyOnline>()?;
    m.add_class::<online::OnlineDecision>()?;
    m.add_class::<online::OnlineDecisions>()?;
    // Their attributes, from the core's record.
    online::add_record(m.py())?;
    Ok(())
}
