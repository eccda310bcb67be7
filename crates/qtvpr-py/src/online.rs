//! `Online`, `OnlineDecision` and `OnlineDecisions`: deciding deployment queries one at a
//! time, as they arrive, from a calibration (the core's [`qtvpr::Online`]).

use std::sync::Arc;

use numpy::{PyArray1, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use qtvpr::{Decision, Error, OnlineParams};

use crate::calibration::PyCalibration;
use crate::convert::{self, Column, Int, MatrixArg, count, non_negative};
use crate::error::{Args, input_error};
use qtvpr::with_scores;

/// Online thresholds for deployment queries that arrive one at a time.
///
/// ``calibration`` is a :class:`Calibration` (built from arrays, or loaded from a
/// calibration file). Query j is thresholded on its *window*, its last
/// ``min(window, j + 1)`` queries (itself included), exactly as
/// :meth:`Calibration.transfer` thresholds one batch: the lower weighted median of the
/// window's query quantiles, read off all the window's scores. So its threshold is what
/// ``calibration.transfer(window_columns, k=k, precision=precision)`` returns, and it
/// depends on no later query. The query is then decided at that threshold: in
/// ``"single"`` matching its best match (the first maximum) is accepted when its score
/// is ``>=`` the threshold; in ``"multi"`` matching every score ``>=`` it is.
///
/// ``k``, ``precision`` and ``window`` left as ``None`` take the calibration's
/// :attr:`Calibration.defaults` (the ``params`` of its file); a window must come from
/// one or the other. ``min_window`` (in ``1..=window``) is a warm-up: the first
/// ``min_window - 1`` queries are rejected (quantile 1, a threshold just above their
/// window's highest score), so that no decision rests on fewer queries.
///
/// ``gate="margin"`` (single matching only; ``None`` takes the calibration's default,
/// else ``"none"``) also requires a best match's margin (how far it stands out of its
/// column: :func:`qtvpr.margins`) to be at least the calibration's m*
/// (:meth:`Calibration.gate`); each decision then carries its ``margin`` and ``gate``.
///
/// The state keeps only the window (its sorted columns with their quantiles and
/// weights): memory ``8 * window * |DB|`` bytes. The GIL is released while a query is
/// decided. One ``Online`` is one stream: calls on it from several threads at once
/// raise ``RuntimeError`` (already borrowed); give each stream its own.
///
/// Raises ``ValueError`` for ``k < 1``, ``precision`` outside (0, 1], ``window < 1``,
/// no window at all, ``min_window`` outside ``1..=window``, or a ``gate`` other than
/// ``"none"`` or ``"margin"`` (or ``"margin"`` on a multi-matching calibration).
#[pyclass(module = "qtvpr", name = "Online")]
pub(crate) struct PyOnline {
    inner: qtvpr::Online,
    calibration: Py<PyCalibration>,
}

#[pymethods]
impl PyOnline {
    #[new]
    #[pyo3(
        signature = (calibration, *, k = None, precision = None, window = None, min_window = Int::Small(1), gate = None),
        text_signature = "(calibration, *, k=None, precision=None, window=None, min_window=1, gate=None)"
    )]
    fn new(
        calibration: Bound<'_, PyCalibration>,
        k: Option<Int>,
        precision: Option<f64>,
        window: Option<Int>,
        min_window: Int,
        gate: Option<&str>,
    ) -> PyResult<Self> {
        let cal: &Arc<qtvpr::Calibration> = calibration.get().inner();
        let (k, window, min_window) = (
            k.map(|k| count("k", k)).transpose()?,
            window.map(|m| count("window", m)).transpose()?,
            count("min_window", min_window)?,
        );
        let params = convert::gate(gate)
            .and_then(|gate| OnlineParams::resolve(cal.defaults(), k, precision, window, Some(min_window), gate))
            .map_err(|e| ARGS.error(e))?;
        let inner = qtvpr::Online::new(Arc::clone(cal), params).map_err(|e| ARGS.error(e))?;
        Ok(Self {
            inner,
            calibration: calibration.unbind(),
        })
    }

    /// Decide one deployment query from its |DB| scores.
    ///
    /// ``column`` is a 1-D array (or a |DB| x 1 matrix) of float32 or float64 scores,
    /// any strides, read in place. Returns an :class:`OnlineDecision`. Raises
    /// ``TypeError`` for another dtype and ``ValueError`` for a column of another length
    /// than |DB| or with a NaN or infinite score; the state is then unchanged.
    #[pyo3(signature = (column))]
    fn push(&mut self, py: Python<'_>, column: &Bound<'_, PyAny>) -> PyResult<OnlineDecision> {
        let column = Column::extract("column", column)?;
        let view = column.view();
        let online = &mut self.inner;
        let decision = py
            .detach(|| with_scores!(view, |c| online.push(c.column(0))))
            .map_err(column_error)?;
        Ok(OnlineDecision::new(py, &decision, self.inner.accepted()))
    }

    /// Decide several deployment queries, in order: the columns of ``s_val``
    /// (|DB| x n, float32 or float64, any strides; n x |DB| with ``query_major=True``;
    /// or the path of a ``.npy`` file, memory-mapped).
    ///
    /// The same as pushing the columns one by one (the window carries over between
    /// calls), faster. Returns an :class:`OnlineDecisions` of arrays over the n
    /// queries. Raises as :meth:`push`; on a bad column the queries before it are kept
    /// (decided and in the window), the bad one and those after it are not.
    #[pyo3(signature = (s_val, *, query_major = false))]
    fn push_many(&mut self, py: Python<'_>, s_val: &Bound<'_, PyAny>, query_major: bool) -> PyResult<OnlineDecisions> {
        let s = MatrixArg::extract("s_val", s_val)?;
        let view = s.view(query_major);
        let first = self.inner.pushed();
        let online = &mut self.inner;
        let decisions = py
            .detach(|| with_scores!(view, |s| online.push_many(s)))
            .map_err(|e| matrix_error(e, first, query_major))?;
        Ok(OnlineDecisions::new(py, &decisions, self.inner.params().gate))
    }

    /// Continue a stream at query ``first_query`` on a fresh state: ``s_before`` holds
    /// the scores of the ``min(first_query, window - 1)`` queries before it (|DB| x
    /// that many; transposed with ``query_major=True``). The next push is query
    /// ``first_query``, decided as in the whole stream. For a scheduler that decides
    /// blocks of a stream independently (``qtvpr.dask``); errors name the stream's
    /// queries.
    #[pyo3(signature = (first_query, s_before, *, query_major = false))]
    fn _resume(
        &mut self,
        py: Python<'_>,
        first_query: Int,
        s_before: &Bound<'_, PyAny>,
        query_major: bool,
    ) -> PyResult<()> {
        let first = non_negative("first_query", first_query)?;
        let s = MatrixArg::extract("s_val", s_before)?;
        let view = s.view(query_major);
        let online = &mut self.inner;
        py.detach(|| with_scores!(view, |s| online.resume(first, s)))
            .map_err(|e| matrix_error(e, 0, query_major))
    }

    /// :meth:`push_many`, with the positions in its errors counted in the stream (from
    /// query 0) rather than in ``s_val``: for a scheduler (``qtvpr.dask``) that pushes
    /// a block of the stream after :meth:`_resume`.
    #[pyo3(signature = (s_val, *, query_major = false))]
    fn _push_stream(
        &mut self,
        py: Python<'_>,
        s_val: &Bound<'_, PyAny>,
        query_major: bool,
    ) -> PyResult<OnlineDecisions> {
        let s = MatrixArg::extract("s_val", s_val)?;
        let view = s.view(query_major);
        let online = &mut self.inner;
        let decisions = py
            .detach(|| with_scores!(view, |s| online.push_many(s)))
            .map_err(|e| matrix_error(e, 0, query_major))?;
        Ok(OnlineDecisions::new(py, &decisions, self.inner.params().gate))
    }

    /// The threshold of the last decision (``None`` before the first push).
    #[getter]
    fn threshold(&self) -> Option<f64> {
        self.inner.threshold()
    }

    /// The number of queries decided so far.
    #[getter]
    fn pushed(&self) -> usize {
        self.inner.pushed()
    }

    /// Calibration queries sampled per deployment query.
    #[getter]
    fn k(&self) -> usize {
        self.inner.params().k
    }

    /// The precision target.
    #[getter]
    fn precision(&self) -> f64 {
        self.inner.params().precision
    }

    /// The window size.
    #[getter]
    fn window(&self) -> usize {
        self.inner.params().window
    }

    /// The warm-up: queries before the ``min_window``-th are rejected.
    #[getter]
    fn min_window(&self) -> usize {
        self.inner.params().min_window
    }

    /// The gate: ``"none"`` or ``"margin"``.
    #[getter]
    fn gate(&self) -> &'static str {
        self.inner.params().gate.as_str()
    }

    /// The :class:`Calibration` this state decides from.
    #[getter]
    fn calibration(&self, py: Python<'_>) -> Py<PyCalibration> {
        self.calibration.clone_ref(py)
    }

    fn __repr__(&self) -> String {
        let p = self.inner.params();
        format!(
            "Online(k={}, precision={:?}, window={}, min_window={}, gate='{}', matching='{}', pushed={})",
            p.k,
            p.precision,
            p.window,
            p.min_window,
            p.gate.as_str(),
            self.inner.calibration().matching().as_str(),
            self.inner.pushed()
        )
    }
}

/// How `Online` names its arguments: calibration errors cannot occur here, and a
/// parameter keeps its name.
const ARGS: Args = Args {
    gt: "gt_cal",
    query_major: false,
};

/// The exception for an error of `Online.push(column)`: positions are rows of the
/// column, and the query is its index in arrival order.
fn column_error(err: Error) -> PyErr {
    match err {
        Error::NotFinite { row, col, value, .. } => PyValueError::new_err(format!(
            "column (deployment query {col}) contains {value} at row {row}; scores must be finite"
        )),
        err @ Error::ColumnLength { .. } => input_error("column", err),
        err => ARGS.error(err),
    }
}

/// The exception for an error of `Online.push_many(s_val)` whose first column was
/// deployment query `first`: positions are given within `s_val`, as the caller stored it.
fn matrix_error(err: Error, first: usize, query_major: bool) -> PyErr {
    match err {
        Error::NotFinite { what, row, col, value } => Args {
            gt: "gt_cal",
            query_major,
        }
        .error(Error::NotFinite {
            what,
            row,
            col: col.saturating_sub(first),
            value,
        }),
        err @ Error::ColumnLength { .. } => input_error("s_val", err),
        err => Args {
            gt: "gt_cal",
            query_major,
        }
        .error(err),
    }
}

/// One deployment query decided by :meth:`Online.push`: the decision record, with the
/// values of a ``qtvpr-cli stream`` line and of C's ``qtvpr_decision``.
///
/// ``query`` is its index in arrival order (from 0); ``query_quantile`` and ``weight``
/// its own quantile and weight (from its calibration neighbours, as in
/// :class:`TransferResult`); ``quantile`` and ``threshold`` its window's weighted-median
/// quantile and the threshold read off the window's scores (1 and a threshold above
/// every score during warm-up). ``best`` is its best match (the first maximum: the
/// matcher's own choice) and ``score`` that score, in both matching modes;
/// ``accepted`` is the number of accepted database images (in ``"single"`` matching 1
/// when ``score >= threshold``, else 0; in ``"multi"`` matching every image with a
/// score ``>= threshold``; with the margin gate, single matching also needs
/// ``margin >= gate``) and ``accept`` is ``accepted > 0``. ``margin`` (the query's
/// margin) and ``gate`` (m*) are those of the margin gate, ``None`` without it.
/// ``confidence`` is the probability that the best match is right (the calibration's
/// hit rate at the query's PA-score, semantics §14), whatever the gate, and
/// ``confidence_lower95`` its one-sided 95% Clopper-Pearson lower bound; both NaN in
/// ``"multi"`` matching or for a calibration without a decision.
/// ``accepted_indices`` are the accepted database indices, ascending (int64).
#[pyclass(frozen, module = "qtvpr", name = "OnlineDecision")]
pub(crate) struct OnlineDecision {
    /// The query's index in arrival order, from 0.
    #[pyo3(get)]
    query: usize,
    /// Its own quantile q_j.
    #[pyo3(get)]
    query_quantile: f64,
    /// Its weight w_j.
    #[pyo3(get)]
    weight: f64,
    /// The window's quantile (1 during warm-up).
    #[pyo3(get)]
    quantile: f64,
    /// The window's threshold: accept a score ``>=`` it.
    #[pyo3(get)]
    threshold: f64,
    /// The best match's database index (the first maximum).
    #[pyo3(get)]
    best: usize,
    /// The best match's score.
    #[pyo3(get)]
    score: f64,
    /// The number of accepted database images (0 or 1 in single matching).
    #[pyo3(get)]
    accepted: usize,
    /// Whether anything is accepted (``accepted > 0``).
    #[pyo3(get)]
    accept: bool,
    /// With the margin gate: the query's margin (``None`` without it).
    #[pyo3(get)]
    margin: Option<f64>,
    /// With the margin gate: m*, the margin the best match needs (``None`` without it).
    #[pyo3(get)]
    gate: Option<f64>,
    /// The probability that the best match is right (NaN in multi matching).
    #[pyo3(get)]
    confidence: f64,
    /// Its one-sided 95% Clopper-Pearson lower bound (NaN in multi matching).
    #[pyo3(get)]
    confidence_lower95: f64,
    /// The accepted database indices, ascending (int64).
    #[pyo3(get)]
    accepted_indices: Py<PyArray1<i64>>,
}

impl OnlineDecision {
    fn new(py: Python<'_>, d: &Decision, accepted: &[usize]) -> Self {
        Self {
            query: d.query,
            query_quantile: d.query_quantile,
            weight: d.weight,
            quantile: d.quantile,
            threshold: d.threshold,
            best: d.best,
            score: d.score,
            accepted: d.accepted,
            accept: d.accept(),
            margin: d.margin,
            gate: d.gate,
            confidence: d.confidence,
            confidence_lower95: d.confidence_lower95,
            // Indices are below |DB|, so they fit in an i64.
            accepted_indices: PyArray1::from_iter(py, accepted.iter().map(|&i| i as i64)).unbind(),
        }
    }
}

#[pymethods]
impl OnlineDecision {
    /// The names of the decision record's fields, in order (the core's, semantics §11):
    /// the keys of a ``qtvpr-cli stream`` line, the columns of its CSV, and attributes
    /// of this class. A front end lays a record out by these names, never its own.
    #[classattr]
    #[allow(non_snake_case)]
    fn FIELDS(py: Python<'_>) -> PyResult<Py<PyTuple>> {
        Ok(PyTuple::new(py, Decision::FIELDS)?.unbind())
    }

    /// The fields a record decided with the margin gate has after :attr:`FIELDS`
    /// (``margin`` and ``gate``, semantics §13; ``None`` on a record without the gate).
    #[classattr]
    #[allow(non_snake_case)]
    fn GATE_FIELDS(py: Python<'_>) -> PyResult<Py<PyTuple>> {
        Ok(PyTuple::new(py, Decision::GATE_FIELDS)?.unbind())
    }

    fn __repr__(&self) -> String {
        // With the margin gate, what the decision also rested on.
        let gated = match (self.margin, self.gate) {
            (Some(margin), Some(gate)) => format!(", margin={margin:?}, gate={gate:?}"),
            _ => String::new(),
        };
        format!(
            "OnlineDecision(query={}, quantile={:?}, threshold={:?}, best={}, score={:?}, accepted={}{gated}, accept={})",
            self.query,
            self.quantile,
            self.threshold,
            self.best,
            self.score,
            self.accepted,
            if self.accept { "True" } else { "False" }
        )
    }
}

/// The decisions of :meth:`Online.push_many`, one entry per pushed query, in order:
/// the fields of :class:`OnlineDecision` as arrays, in both matching modes.
///
/// ``queries`` (int64, their indices in arrival order), ``query_quantiles``,
/// ``weights``, ``quantiles``, ``thresholds`` and ``score`` (float64), ``best`` and
/// ``accepted`` (int64), ``accept`` (bool), ``confidences`` and
/// ``confidences_lower95`` (float64, NaN in multi matching); with the margin gate
/// ``margins`` and ``gates`` (float64), ``None`` without it.
#[pyclass(frozen, module = "qtvpr", name = "OnlineDecisions")]
pub(crate) struct OnlineDecisions {
    /// Each query's index in arrival order (int64).
    #[pyo3(get)]
    queries: Py<PyArray1<i64>>,
    /// Each query's own quantile q_j.
    #[pyo3(get)]
    query_quantiles: Py<PyArray1<f64>>,
    /// Each query's weight w_j.
    #[pyo3(get)]
    weights: Py<PyArray1<f64>>,
    /// Each query's window quantile.
    #[pyo3(get)]
    quantiles: Py<PyArray1<f64>>,
    /// Each query's threshold.
    #[pyo3(get)]
    thresholds: Py<PyArray1<f64>>,
    /// Each query's best match (int64).
    #[pyo3(get)]
    best: Py<PyArray1<i64>>,
    /// Each best match's score.
    #[pyo3(get)]
    score: Py<PyArray1<f64>>,
    /// Each query's number of accepted database images (int64).
    #[pyo3(get)]
    accepted: Py<PyArray1<i64>>,
    /// Whether each query accepts anything.
    #[pyo3(get)]
    accept: Py<PyArray1<bool>>,
    /// With the margin gate: each query's margin (``None`` without it).
    #[pyo3(get)]
    margins: Option<Py<PyArray1<f64>>>,
    /// With the margin gate: each query's m* (``None`` without it).
    #[pyo3(get)]
    gates: Option<Py<PyArray1<f64>>>,
    /// Each query's confidence (NaN in multi matching).
    #[pyo3(get)]
    confidences: Py<PyArray1<f64>>,
    /// Each confidence's one-sided 95% Clopper-Pearson lower bound.
    #[pyo3(get)]
    confidences_lower95: Py<PyArray1<f64>>,
    len: usize,
}

impl OnlineDecisions {
    /// The arrays of `decisions`, made by an `Online` with `gate`.
    fn new(py: Python<'_>, decisions: &[Decision], gate: qtvpr::Gate) -> Self {
        // An `Online` gates all its decisions or none.
        let gated = |f: fn(&Decision) -> Option<f64>| {
            gate.is_on()
                .then(|| PyArray1::from_iter(py, decisions.iter().map(|d| f(d).unwrap_or(f64::NAN))).unbind())
        };
        let f64s = |f: fn(&Decision) -> f64| PyArray1::from_iter(py, decisions.iter().map(f)).unbind();
        // Indices and counts are below |DB| and the number of queries: they fit in an i64.
        let i64s = |f: fn(&Decision) -> usize| PyArray1::from_iter(py, decisions.iter().map(|d| f(d) as i64)).unbind();
        Self {
            queries: i64s(|d| d.query),
            query_quantiles: f64s(|d| d.query_quantile),
            weights: f64s(|d| d.weight),
            quantiles: f64s(|d| d.quantile),
            thresholds: f64s(|d| d.threshold),
            best: i64s(|d| d.best),
            score: f64s(|d| d.score),
            accepted: i64s(|d| d.accepted),
            accept: PyArray1::from_iter(py, decisions.iter().map(Decision::accept)).unbind(),
            margins: gated(|d| d.margin),
            gates: gated(|d| d.gate),
            confidences: f64s(|d| d.confidence),
            confidences_lower95: f64s(|d| d.confidence_lower95),
            len: decisions.len(),
        }
    }
}

#[pymethods]
impl OnlineDecisions {
    /// Decisions from their fields, as the properties return them (what ``qtvpr.dask``
    /// assembles from the results of its blocks). The arrays are kept, not copied.
    ///
    /// Raises ``TypeError`` for an array of another dtype or dimension, and
    /// ``ValueError`` for arrays of different lengths.
    #[staticmethod]
    #[pyo3(signature = (
        queries, query_quantiles, weights, quantiles, thresholds, best, score, accepted, accept, confidences,
        confidences_lower95, margins = None, gates = None,
    ))]
    #[allow(clippy::too_many_arguments)]
    fn _from_parts(
        queries: Bound<'_, PyArray1<i64>>,
        query_quantiles: Bound<'_, PyArray1<f64>>,
        weights: Bound<'_, PyArray1<f64>>,
        quantiles: Bound<'_, PyArray1<f64>>,
        thresholds: Bound<'_, PyArray1<f64>>,
        best: Bound<'_, PyArray1<i64>>,
        score: Bound<'_, PyArray1<f64>>,
        accepted: Bound<'_, PyArray1<i64>>,
        accept: Bound<'_, PyArray1<bool>>,
        confidences: Bound<'_, PyArray1<f64>>,
        confidences_lower95: Bound<'_, PyArray1<f64>>,
        margins: Option<Bound<'_, PyArray1<f64>>>,
        gates: Option<Bound<'_, PyArray1<f64>>>,
    ) -> PyResult<Self> {
        let len = queries.len();
        let lengths = [
            query_quantiles.len(),
            weights.len(),
            quantiles.len(),
            thresholds.len(),
            best.len(),
            score.len(),
            accepted.len(),
            accept.len(),
            confidences.len(),
            confidences_lower95.len(),
            margins.as_ref().map_or(len, |m| m.len()),
            gates.as_ref().map_or(len, |g| g.len()),
        ];
        if lengths.iter().any(|&n| n != len) {
            return Err(PyValueError::new_err(format!(
                "OnlineDecisions parts differ in length: queries {len}, the others {lengths:?}"
            )));
        }
        Ok(Self {
            queries: queries.unbind(),
            query_quantiles: query_quantiles.unbind(),
            weights: weights.unbind(),
            quantiles: quantiles.unbind(),
            thresholds: thresholds.unbind(),
            best: best.unbind(),
            score: score.unbind(),
            accepted: accepted.unbind(),
            accept: accept.unbind(),
            margins: margins.map(Bound::unbind),
            gates: gates.map(Bound::unbind),
            confidences: confidences.unbind(),
            confidences_lower95: confidences_lower95.unbind(),
            len,
        })
    }

    fn __len__(&self) -> usize {
        self.len
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let thresholds = self.thresholds.bind(py).repr()?;
        Ok(format!(
            "OnlineDecisions(queries={}, thresholds={thresholds})",
            self.len
        ))
    }
}
