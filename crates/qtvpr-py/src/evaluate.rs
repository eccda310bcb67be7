//! `evaluate`: the evaluation protocol (SPEC sections 7 and 8), as a dict like the
//! reference's.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use qtvpr::{Matching, Method, Protocol, Split};

use crate::convert::{GroundTruthArgs, Scores, count, with_scores};
use crate::error::Args;

/// Run the evaluation protocol of the paper's Table I on one similarity matrix.
///
/// ``s`` (|DB| x |Q|, float32 or float64) comes with ground truth ``gt`` (and optional
/// ``gt_soft``) for every query. The first ``cal_queries`` queries (default
/// ``floor(cal_fraction * |Q|)``) calibrate. The deployment set is every later query,
/// or with ``deploy_fraction`` the last ``floor(deploy_fraction * |Q|)`` queries (the
/// calibration-size ablation: the queries between the two sets are unused). It is cut
/// into full segments of ``segment_size`` queries (default
/// ``ceil(segment_fraction * |Q|)``), the remainder dropped. Each of ``methods``
/// (default all: ``"quantile-transfer"``, ``"quantile-transfer-online"``,
/// ``"schubert"``, ``"schubert-calibrated"``, ``"calibration-threshold"``,
/// ``"oracle"``) gives every segment a threshold, and the segment's decisions
/// (``matching``) are counted against its own ground truth.
///
/// ``"quantile-transfer-online"`` is :class:`Online` inside the protocol: every
/// deployment query is decided at its own threshold, over a window of the segment size
/// that starts at the first deployment query and is not reset at segment boundaries; a
/// segment's counts are the sums of its queries', and its ``threshold`` is its last
/// query's.
///
/// Returns ``{"methods": {name: {"pct_segs", "avg_recall", "segments_counted",
/// "segments_skipped", "threshold_mse", "segments": [...]}}}``. A segment meets the
/// target when its precision is at least ``precision``; segments without positives
/// are skipped; ``pct_segs`` is the percentage of counted segments that meet,
/// ``avg_recall`` the mean of their recall (0 for those that miss), both ``None`` when
/// no segment is counted. Each segment has ``start``, ``end`` (indices into the
/// deployment set), ``threshold``, ``oracle_threshold`` (``inf`` is reject-all),
/// ``tp``, ``fp``, ``positives``, ``precision``, ``recall`` and ``meets``.
/// ``threshold_mse`` is the mean squared difference from the oracle's threshold where
/// both are finite (``None`` if nowhere).
#[pyfunction]
#[pyo3(signature = (
    s, gt, *, gt_soft = None, methods = None, k = 10, precision = 1.0, matching = "single",
    cal_fraction = 0.1, cal_queries = None, segment_fraction = 0.01, segment_size = None,
    deploy_fraction = None, query_major = false,
))]
#[allow(clippy::too_many_arguments)] // the Python signature
pub(crate) fn evaluate<'py>(
    py: Python<'py>,
    s: &Bound<'py, PyAny>,
    gt: &Bound<'py, PyAny>,
    gt_soft: Option<&Bound<'py, PyAny>>,
    methods: Option<Vec<String>>,
    k: i64,
    precision: f64,
    matching: &str,
    cal_fraction: f64,
    cal_queries: Option<i64>,
    segment_fraction: f64,
    segment_size: Option<i64>,
    deploy_fraction: Option<f64>,
    query_major: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let args = Args { gt: "gt", query_major };
    let methods: Vec<Method> = match methods {
        None => Method::ALL.to_vec(),
        Some(names) => names
            .iter()
            .map(|n| n.parse())
            .collect::<qtvpr::Result<_>>()
            .map_err(|e| args.error(e))?,
    };
    let matching: Matching = matching.parse().map_err(|e| args.error(e))?;
    let protocol = Protocol {
        calibration: match cal_queries {
            Some(n) => Split::Count(count("cal_queries", n)?),
            None => Split::Fraction(cal_fraction),
        },
        deploy_fraction,
        segment: match segment_size {
            Some(n) => Split::Count(count("segment_size", n)?),
            None => Split::Fraction(segment_fraction),
        },
        k: count("k", k)?,
        precision,
        matching,
    };
    protocol.validate().map_err(|e| args.error(e))?;
    let s = Scores::extract("s", s)?;
    let gt = GroundTruthArgs::extract("gt", gt, gt_soft)?;
    let (s, gt) = (s.view(query_major), gt.view(query_major));
    let gt = py.detach(|| gt.build())?;
    let out = py
        .detach(|| with_scores!(s, s => qtvpr::evaluate(s, &gt, &protocol, &methods)))
        .map_err(|e| args.error(e))?;

    let report = PyDict::new(py);
    for m in &out.methods {
        let segments = PyList::empty(py);
        for g in &m.segments {
            let d = PyDict::new(py);
            d.set_item("start", g.start)?;
            d.set_item("end", g.end)?;
            d.set_item("threshold", g.threshold)?;
            d.set_item("oracle_threshold", g.oracle_threshold)?;
            d.set_item("tp", g.counts.tp)?;
            d.set_item("fp", g.counts.fp)?;
            d.set_item("positives", g.counts.positives)?;
            d.set_item("precision", g.counts.precision())?;
            d.set_item("recall", g.counts.recall())?;
            d.set_item("meets", g.meets)?;
            segments.append(d)?;
        }
        let d = PyDict::new(py);
        d.set_item("pct_segs", m.pct_segs)?;
        d.set_item("avg_recall", m.avg_recall)?;
        d.set_item("segments_counted", m.segments_counted)?;
        d.set_item("segments_skipped", m.segments_skipped)?;
        d.set_item("threshold_mse", m.threshold_mse)?;
        d.set_item("segments", segments)?;
        report.set_item(m.method.as_str(), d)?;
    }
    let result = PyDict::new(py);
    result.set_item("methods", report)?;
    Ok(result)
}
