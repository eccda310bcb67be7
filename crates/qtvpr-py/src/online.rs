//! `Online`, `OnlineDecision` and `OnlineDecisions`: deciding deployment queries one at a
//! time, as they arrive, from a calibration (the core's [`qtvpr::Online`]).

use std::sync::Arc;

use numpy::{PyArray1, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyCFunction, PyTuple};
use qtvpr::{Decision, Error, Kind, OnlineParams, Value};

use crate::calibration::PyCalibration;
use crate::convert::{self, Column, Int, MatrixArg, Real, count, non_negative, real, sequence_gate};
use crate::error::{Args, input_error};
use qtvpr::with_scores;

/// The `min_window` default `help()` shows (the core's, which a `None` takes).
const _: () = assert!(qtvpr::DEFAULT_MIN_WINDOW == 1);

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
/// ``gate="sequence"`` (semantics §15; single matching only) requires the best
/// matches of the previous queries of the stream to agree with it: its consistency,
/// the share of the last ``sequence_window`` queries that lie on its line through the
/// database (``sequence_speed`` rows per query, within ``sequence_tolerance`` rows
/// widening by ``sequence_drift`` per step), must reach ``sequence_level``; each
/// decision then carries its ``consistency`` and ``consistency_level``. The stream
/// starts at the first push: its first queries cannot pass. ``gate="margin,sequence"``:
/// both. The sequence gate's parameters left as ``None`` are the calibration's.
///
/// A calibration of sequence length ``L > 1`` (``Calibration(..., sequence=L)``, a file
/// of ``qtvpr-cli calibrate --sequence L``) decides each query on its causal
/// sequence-matched column, formed from the last ``L - 1`` pushed columns, as
/// ``sequence_match(s_val, L, causal=True)`` would match the stream. ``sequence=L``
/// checks that the calibration's is ``L`` (``None``: whatever it is).
///
/// The state keeps only the window (its sorted columns with their quantiles and
/// weights): memory ``8 * window * |DB|`` bytes, and ``8 * (L - 1) * |DB|`` more for
/// the raw columns of a sequence length ``L``. The GIL is released while a query is
/// decided. One ``Online`` is one stream: calls on it from several threads at once
/// raise ``RuntimeError`` (already borrowed); give each stream its own.
///
/// Raises ``ValueError`` for ``k < 1``, ``precision`` outside (0, 1], ``window < 1``,
/// no window at all, ``min_window`` outside ``1..=window``, a ``gate`` that is not
/// ``"none"`` or a set of ``"margin"`` and ``"sequence"`` (or a gate on a
/// multi-matching calibration, or the sequence gate on a database too small for its
/// tolerance), a bad sequence gate parameter, or a ``sequence`` other than the
/// calibration's.
#[pyclass(module = "qtvpr", name = "Online")]
pub(crate) struct PyOnline {
    inner: qtvpr::Online,
    calibration: Py<PyCalibration>,
}

#[pymethods]
impl PyOnline {
    #[new]
    #[pyo3(
        signature = (
            calibration, *, k = None, precision = None, window = None, min_window = None, gate = None,
            sequence_window = None, sequence_level = None, sequence_speed = None, sequence_tolerance = None,
            sequence_drift = None, sequence = None,
        ),
        text_signature = "(calibration, *, k=None, precision=None, window=None, min_window=1, gate=None, \
            sequence_window=None, sequence_level=None, sequence_speed=None, sequence_tolerance=None, \
            sequence_drift=None, sequence=None)"
    )]
    #[allow(clippy::too_many_arguments)] // the Python signature
    fn new(
        calibration: Bound<'_, PyCalibration>,
        k: Option<Int>,
        precision: Option<Real>,
        window: Option<Int>,
        min_window: Option<Int>,
        gate: Option<&str>,
        sequence_window: Option<Int>,
        sequence_level: Option<Real>,
        sequence_speed: Option<Real>,
        sequence_tolerance: Option<Real>,
        sequence_drift: Option<Real>,
        sequence: Option<Int>,
    ) -> PyResult<Self> {
        let precision = real("precision", precision)?;
        let cal: &Arc<qtvpr::Calibration> = calibration.get().inner();
        let (k, window, min_window) = (
            k.map(|k| count("k", k)).transpose()?,
            window.map(|m| count("window", m)).transpose()?,
            min_window.map(|w| count("min_window", w)).transpose()?,
        );
        let sequence = sequence.map(|l| non_negative("sequence", l)).transpose()?;
        cal.check_sequence(sequence).map_err(|e| ARGS.error(e))?;
        let given = sequence_gate(
            sequence_window,
            sequence_level,
            sequence_speed,
            sequence_tolerance,
            sequence_drift,
        )?;
        let params = convert::gate(gate)
            .and_then(|gate| OnlineParams::resolve(cal.defaults(), k, precision, window, min_window, gate, given))
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
    /// the scores of the :meth:`_lookback` queries before it (|DB| x that many;
    /// transposed with ``query_major=True``). The next push is query ``first_query``,
    /// decided as in the whole stream. For a scheduler that decides blocks of a stream
    /// independently (``qtvpr.dask``); errors name the stream's queries.
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

    /// How many queries before query ``first_query`` a resumed state's decisions look
    /// back at (the core's ``Online::lookback``): its window's, the sequence gate's
    /// (its ``sequence_window``), and the ``L - 1`` raw columns before each of a
    /// calibration of sequence length ``L``; fewer at the start of the stream.
    #[pyo3(signature = (first_query))]
    fn _lookback(&self, first_query: Int) -> PyResult<usize> {
        Ok(self.inner.lookback(non_negative("first_query", first_query)?))
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

    /// The gates: ``"none"``, ``"margin"``, ``"sequence"`` or ``"margin,sequence"``.
    #[getter]
    fn gate(&self) -> &'static str {
        self.inner.params().gate.as_str()
    }

    /// The sequence gate's parameters (semantics §15), read when :attr:`gate` has it:
    /// ``{"window", "level", "speed", "tolerance", "drift"}``.
    #[getter]
    fn sequence_gate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(pythonize::pythonize(py, &self.inner.params().sequence_gate)?)
    }

    /// The calibration's sequence length ``L``: each query is decided on its causal
    /// sequence-matched column over ``L`` queries (1: its own column).
    #[getter]
    fn sequence(&self) -> usize {
        self.inner.calibration().sequence()
    }

    /// The :class:`Calibration` this state decides from.
    #[getter]
    fn calibration(&self, py: Python<'_>) -> Py<PyCalibration> {
        self.calibration.clone_ref(py)
    }

    fn __repr__(&self) -> String {
        let p = self.inner.params();
        // The sequence length only where it matters.
        let sequence = match self.inner.calibration().sequence() {
            1 => String::new(),
            l => format!(", sequence={l}"),
        };
        format!(
            "Online(k={}, precision={:?}, window={}, min_window={}, gate='{}', matching='{}'{sequence}, pushed={})",
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
/// Its attributes are the record's fields, :attr:`FIELDS` (then :attr:`GATE_FIELDS`
/// and :attr:`SEQUENCE_FIELDS`):
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
/// margin) and ``gate`` (m*) are those of the margin gate, ``None`` without it;
/// ``consistency`` (the share of the previous queries whose best matches agree with
/// its own) and ``consistency_level`` are those of the sequence gate (semantics §15),
/// ``None`` without it.
/// ``confidence`` is the probability that the best match is right (the calibration's
/// hit rate at the query's PA-score, semantics §14), whatever the gate, and
/// ``confidence_lower95`` its one-sided 95% Clopper-Pearson lower bound; both NaN in
/// ``"multi"`` matching or for a calibration without a decision.
/// ``accepted_indices`` are the accepted database indices, ascending (int64).
#[pyclass(frozen, module = "qtvpr", name = "OnlineDecision")]
pub(crate) struct OnlineDecision {
    /// The core's record, which the properties of its fields read ([`add_record`]).
    decision: Decision,
    /// The accepted database indices, ascending (int64).
    #[pyo3(get)]
    accepted_indices: Py<PyArray1<i64>>,
}

impl OnlineDecision {
    fn new(py: Python<'_>, d: &Decision, accepted: &[usize]) -> Self {
        Self {
            decision: *d,
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

    /// The fields a record decided with the sequence gate has after :attr:`FIELDS` and
    /// :attr:`GATE_FIELDS` (``consistency`` and ``consistency_level``, semantics §15;
    /// ``None`` on a record without the gate).
    #[classattr]
    #[allow(non_snake_case)]
    fn SEQUENCE_FIELDS(py: Python<'_>) -> PyResult<Py<PyTuple>> {
        Ok(PyTuple::new(py, Decision::SEQUENCE_FIELDS)?.unbind())
    }

    /// Every field of the record, in order, as ``(name, column, kind, gate)``: its
    /// attribute here, its attribute of :class:`OnlineDecisions`, what it holds
    /// (``"count"``, ``"real"`` or ``"flag"``) and the gate that brings it (``"none"``:
    /// every record; ``"margin"`` or ``"sequence"``). The core's list, which this class and :class:`OnlineDecisions`
    /// are laid out from.
    #[classattr]
    #[allow(non_snake_case)]
    fn RECORD(py: Python<'_>) -> PyResult<Py<PyTuple>> {
        let rows = Decision::RECORD.map(|f| (f.name, f.column, f.kind.as_str(), f.gate.as_str()));
        Ok(PyTuple::new(py, rows)?.unbind())
    }

    fn __repr__(&self) -> String {
        let d = &self.decision;
        // With a gate, what the decision also rested on.
        let mut gated = match (d.margin, d.gate) {
            (Some(margin), Some(gate)) => format!(", margin={margin:?}, gate={gate:?}"),
            _ => String::new(),
        };
        if let (Some(c), Some(level)) = (d.consistency, d.consistency_level) {
            gated += &format!(", consistency={c:?}, consistency_level={level:?}");
        }
        format!(
            "OnlineDecision(query={}, quantile={:?}, threshold={:?}, best={}, score={:?}, accepted={}{gated}, accept={})",
            d.query,
            d.quantile,
            d.threshold,
            d.best,
            d.score,
            d.accepted,
            if d.accept() { "True" } else { "False" }
        )
    }
}

/// The decisions of :meth:`Online.push_many`, one entry per pushed query, in order:
/// the fields of :class:`OnlineDecision` as arrays, in both matching modes.
///
/// Its attributes are the record's columns, :attr:`COLUMNS`: ``queries`` (int64, their
/// indices in arrival order), ``query_quantiles``, ``weights``, ``quantiles``,
/// ``thresholds`` and ``score`` (float64), ``best`` and ``accepted`` (int64),
/// ``accept`` (bool), ``confidences`` and ``confidences_lower95`` (float64, NaN in
/// multi matching); with the margin gate ``margins`` and ``gates`` (float64), with the
/// sequence gate ``consistencies`` and ``consistency_levels`` (float64), ``None``
/// without them.
#[pyclass(frozen, module = "qtvpr", name = "OnlineDecisions")]
pub(crate) struct OnlineDecisions {
    /// One array per field of the core's record, in its order; `None` for the field of
    /// a gate the decisions were made without. The properties of the columns read them
    /// ([`add_record`]).
    columns: Vec<Option<Py<PyAny>>>,
    len: usize,
}

impl OnlineDecisions {
    /// The arrays of `decisions`, made by an `Online` with `gate`.
    fn new(py: Python<'_>, decisions: &[Decision], gate: qtvpr::Gate) -> Self {
        let columns = Decision::RECORD.iter().map(|field| {
            // An `Online` gates all its decisions or none.
            field.in_record(gate).then(|| {
                let values = decisions.iter().map(|d| field.value(d));
                match field.kind {
                    // Indices and counts are below |DB| and the number of queries: they
                    // fit in an i64.
                    Kind::Count => PyArray1::from_iter(py, values.map(|v| count_of(v) as i64)).into_any(),
                    Kind::Real => PyArray1::from_iter(py, values.map(real_of)).into_any(),
                    Kind::Flag => PyArray1::from_iter(py, values.map(|v| v == Some(Value::Flag(true)))).into_any(),
                }
                .unbind()
            })
        });
        Self {
            columns: columns.collect(),
            len: decisions.len(),
        }
    }
}

/// A count of the record (a field of every record, so always there).
fn count_of(value: Option<Value>) -> usize {
    match value {
        Some(Value::Count(n)) => n,
        other => unreachable!("a count field holds a count, not {other:?}"),
    }
}

/// A real of the record, NaN where the record has none.
fn real_of(value: Option<Value>) -> f64 {
    match value {
        Some(Value::Real(x)) => x,
        _ => f64::NAN,
    }
}

#[pymethods]
impl OnlineDecisions {
    /// The names of the record's columns, in order (the core's list: ``column`` of
    /// :attr:`OnlineDecision.RECORD`): the attributes of this class, and the arguments
    /// of :meth:`_from_parts`.
    #[classattr]
    #[allow(non_snake_case)]
    fn COLUMNS(py: Python<'_>) -> PyResult<Py<PyTuple>> {
        Ok(PyTuple::new(py, Decision::RECORD.map(|f| f.column))?.unbind())
    }

    /// Decisions from their columns, in the order of :attr:`COLUMNS` (a gate's columns
    /// may be left out or ``None``), as the properties return them (what ``qtvpr.dask``
    /// assembles from the results of its blocks). The arrays are kept, not copied.
    ///
    /// Raises ``TypeError`` for a missing column or an array of another dtype or
    /// dimension, and ``ValueError`` for arrays of different lengths.
    #[staticmethod]
    #[pyo3(signature = (*columns))]
    fn _from_parts(columns: &Bound<'_, PyTuple>) -> PyResult<Self> {
        let given = columns.len();
        if given > Decision::RECORD.len() {
            return Err(PyTypeError::new_err(format!(
                "OnlineDecisions has {} columns, got {given}",
                Decision::RECORD.len()
            )));
        }
        let mut parts = Vec::with_capacity(Decision::RECORD.len());
        for (i, field) in Decision::RECORD.iter().enumerate() {
            let part = if i < given { Some(columns.get_item(i)?) } else { None };
            let part = part.filter(|p| !p.is_none());
            let Some(part) = part else {
                if field.gate == qtvpr::Gate::None {
                    return Err(PyTypeError::new_err(format!(
                        "OnlineDecisions needs column {} in both matching modes",
                        field.column
                    )));
                }
                parts.push(None);
                continue;
            };
            let len = match field.kind {
                Kind::Count => part.cast::<PyArray1<i64>>()?.len(),
                Kind::Real => part.cast::<PyArray1<f64>>()?.len(),
                Kind::Flag => part.cast::<PyArray1<bool>>()?.len(),
            };
            parts.push(Some((part.unbind(), len)));
        }
        let len = parts[0].as_ref().map_or(0, |p| p.1);
        let lengths: Vec<usize> = parts[1..].iter().map(|p| p.as_ref().map_or(len, |p| p.1)).collect();
        if lengths.iter().any(|&n| n != len) {
            return Err(PyValueError::new_err(format!(
                "OnlineDecisions parts differ in length: queries {len}, the others {lengths:?}"
            )));
        }
        Ok(Self {
            columns: parts.into_iter().map(|p| p.map(|p| p.0)).collect(),
            len,
        })
    }

    fn __len__(&self) -> usize {
        self.len
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let thresholds = self.column(py, "thresholds").repr()?;
        Ok(format!(
            "OnlineDecisions(queries={}, thresholds={thresholds})",
            self.len
        ))
    }
}

impl OnlineDecisions {
    /// The column named `name` (`None` without its gate).
    fn column<'py>(&self, py: Python<'py>, name: &str) -> Bound<'py, PyAny> {
        let i = Decision::RECORD
            .iter()
            .position(|f| f.column == name)
            .expect("a column of the record");
        self.columns[i]
            .as_ref()
            .map_or_else(|| py.None().into_bound(py), |c| c.bind(py).clone())
    }
}

/// Lay out [`OnlineDecision`] and [`OnlineDecisions`] from the core's record: one
/// read-only property per field of [`Decision::RECORD`], named by its `name` on a
/// decision and by its `column` on a table of decisions (an int, a float, a bool, or
/// `None` for a gate's field without that gate; int64, float64 or bool arrays). So a
/// field added to the core is an attribute here, with no edit; the stubs
/// (`py/qtvpr/_native.pyi`, checked by `mypy.stubtest`) list them for type checkers.
pub(crate) fn add_record(py: Python<'_>) -> PyResult<()> {
    let property = py.import("builtins")?.getattr("property")?;
    let (decision, decisions) = (py.get_type::<OnlineDecision>(), py.get_type::<OnlineDecisions>());
    for (i, field) in Decision::RECORD.into_iter().enumerate() {
        let one = PyCFunction::new_closure(py, None, None, move |args, _| -> PyResult<Py<PyAny>> {
            let slf = args.get_item(0)?;
            let d = &slf.cast::<OnlineDecision>()?.get().decision;
            let py = slf.py();
            Ok(match field.value(d) {
                None => py.None(),
                Some(Value::Count(n)) => n.into_pyobject(py)?.into_any().unbind(),
                Some(Value::Real(x)) => x.into_pyobject(py)?.into_any().unbind(),
                Some(Value::Flag(b)) => b.into_pyobject(py)?.to_owned().into_any().unbind(),
            })
        })?;
        let doc = format!("The record's ``{}`` (a {}).", field.name, field.kind.as_str());
        decision.setattr(field.name, property.call1((one, py.None(), py.None(), doc))?)?;
        let many = PyCFunction::new_closure(py, None, None, move |args, _| -> PyResult<Py<PyAny>> {
            let slf = args.get_item(0)?;
            let column = &slf.cast::<OnlineDecisions>()?.get().columns[i];
            let py = slf.py();
            Ok(column.as_ref().map_or_else(|| py.None(), |c| c.clone_ref(py)))
        })?;
        let doc = format!("Every decision's ``{}``, one per query.", field.name);
        decisions.setattr(field.column, property.call1((many, py.None(), py.None(), doc))?)?;
    }
    Ok(())
}
