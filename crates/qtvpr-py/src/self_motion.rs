//! `SelfMotionLabels`: the self-motion labels of a calibration traverse (semantics §16),
//! as `ground_truth_from_sequence` returns them and `Calibration` takes them; and their
//! record as a dict. Apart from `ground_truth.rs`, which makes them, so that the
//! conversion of a ground-truth argument (`convert.rs`) can read them without a circle.

use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;

/// The self-motion labels of a calibration traverse (:func:`ground_truth_from_sequence`).
///
/// Per calibration query: ``labels`` (``"positive"``, ``"negative"`` or ``"abstain"``),
/// ``agreement`` (the share of its neighbours that agree with it) and ``best`` (its best
/// match, a database row). As ground truth, in the layout of the similarity they were
/// found on (|DB| x |Qcal|, or |Qcal| x |DB| with ``query_major=True``): ``hard`` and
/// ``soft`` (bool). ``counts`` is ``{"positive", "negative", "abstain"}``, and
/// ``record`` the JSON object that says how they were made (the rule, its parameters,
/// the counts), as a ground-truth ``.npz`` of ``qtvpr-cli ground-truth --from-sequence``
/// holds it in its member ``labels``. ``len()`` is the number of queries.
///
/// Pass it as the ground truth of a :class:`Calibration` (``gt_cal``, with no
/// ``gt_soft``) to keep the record with the calibration.
#[pyclass(frozen, module = "qtvpr", name = "SelfMotionLabels")]
pub(crate) struct SelfMotionLabels {
    /// The hard ground truth (bool).
    #[pyo3(get)]
    hard: Py<PyArray2<bool>>,
    /// The soft ground truth (bool): the hard one and the abstaining queries' best matches.
    #[pyo3(get)]
    soft: Py<PyArray2<bool>>,
    /// Per query, ``"positive"``, ``"negative"`` or ``"abstain"`` (a NumPy string array).
    #[pyo3(get)]
    labels: Py<PyAny>,
    /// Per query, the share of its neighbours that agree with it (float64).
    #[pyo3(get)]
    agreement: Py<PyArray1<f64>>,
    /// Per query, its best match (int64).
    #[pyo3(get)]
    best: Py<PyArray1<i64>>,
    counts: qtvpr::LabelCounts,
    /// The core's ground truth, in the caller's layout, with its record.
    truth: qtvpr::GroundTruth,
}

impl SelfMotionLabels {
    pub(crate) fn new(py: Python<'_>, labels: &qtvpr::SelfMotionLabels, query_major: bool) -> PyResult<Self> {
        let qtvpr::HardSoft { hard, soft } = labels.ground_truth();
        let soft = soft.expect("self-motion labels have a soft ground truth");
        let layout = |m: ndarray::Array2<bool>| if query_major { m.reversed_axes() } else { m };
        let names: Vec<&str> = labels.labels.iter().map(|l| l.as_str()).collect();
        Ok(Self {
            hard: layout(hard).into_pyarray(py).unbind(),
            soft: layout(soft).into_pyarray(py).unbind(),
            labels: py.import("numpy")?.call_method1("array", (names,))?.unbind(),
            agreement: PyArray1::from_slice(py, &labels.agreement).unbind(),
            // Rows of a matrix: they fit an i64.
            best: PyArray1::from_iter(py, labels.best.iter().map(|&b| b as i64)).unbind(),
            counts: labels.counts(),
            truth: labels.truth().oriented(query_major),
        })
    }

    /// The labels as the ground truth of a calibration, with their record, in the
    /// caller's layout (what a ``gt_cal`` array would be).
    pub(crate) fn truth(&self) -> &qtvpr::GroundTruth {
        &self.truth
    }
}

#[pymethods]
impl SelfMotionLabels {
    /// ``{"positive", "negative", "abstain"}``: how many queries have each label.
    #[getter]
    fn counts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(pythonize::pythonize(py, &self.counts)?)
    }

    /// How the labels were made, a dict: ``{"labels": "self-motion", "neighbours": 5,
    /// "positive_level": 0.7, "negative_level": 0.3, "speed": 1.0, "tolerance": 2.0,
    /// "drift": 0.2, "queries": ..., "positive": ..., "negative": ..., "abstain": ...}``.
    #[getter]
    fn record<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        record_dict(py, self.truth.record())
    }

    /// The number of calibration queries.
    fn __len__(&self) -> usize {
        let c = &self.counts;
        c.positive + c.negative + c.abstain
    }

    fn __repr__(&self) -> String {
        let c = &self.counts;
        format!(
            "SelfMotionLabels(queries={}, positive={}, negative={}, abstain={})",
            c.positive + c.negative + c.abstain,
            c.positive,
            c.negative,
            c.abstain
        )
    }
}

/// A record of self-motion labels as a dict (``None`` for none).
pub(crate) fn record_dict<'py>(py: Python<'py>, record: Option<&qtvpr::LabelRecord>) -> PyResult<Bound<'py, PyAny>> {
    match record {
        Some(r) => py.import("json")?.call_method1("loads", (r.json(),)),
        None => Ok(py.None().into_bound(py)),
    }
}
