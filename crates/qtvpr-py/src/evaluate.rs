//! `evaluate` and `ablation`: the evaluation protocol (semantics §7 and §8).
//!
//! The results are the core's serde values turned into Python objects by `pythonize`,
//! so the dicts have exactly the keys of `qtvpr-cli evaluate --format json` (listed in
//! `qtvpr::Report`, semantics §9); a reject-all threshold is `math.inf` here, `null` in JSON.

use std::path::PathBuf;

use pyo3::prelude::*;
use qtvpr::Report;
use qtvpr::{GroundTruth, Matching, Method, Protocol, Split};

use crate::calibration::SequenceGateArgs;
use crate::convert::{GroundTruthArgs, Int, Real, count, real};
use crate::descriptors::SourceArg;
use crate::error::Args;

/// One value or a list of them (the settings of an ablation).
#[derive(FromPyObject)]
pub(crate) enum OneOrMany<T> {
    /// A single value.
    One(T),
    /// A list of values.
    Many(Vec<T>),
}

/// The values of argument `name`, at least one.
fn nonempty<T>(name: &str, values: OneOrMany<T>) -> PyResult<Vec<T>> {
    match values {
        OneOrMany::One(v) => Ok(vec![v]),
        OneOrMany::Many(v) if v.is_empty() => Err(pyo3::exceptions::PyValueError::new_err(format!(
            "{name} must have at least one value"
        ))),
        OneOrMany::Many(v) => Ok(v),
    }
}

/// The arguments `evaluate` and `ablation` share, checked.
struct Setup {
    /// `None`: every method that applies ([`methods_for`]).
    methods: Option<Vec<Method>>,
    protocol: Protocol,
    args: Args,
}

/// The methods asked for, or (`None`) every method that applies to the protocol's
/// matching on a database of `n_db` images (the core's [`Method::all_applying`]).
fn methods_for(methods: Option<Vec<Method>>, protocol: &Protocol, n_db: usize) -> Vec<Method> {
    methods.unwrap_or_else(|| Method::all_applying(protocol.matching, n_db, &protocol.sequence_gate))
}

/// The methods, and the protocol of the values given (the core's defaults for those
/// left `None`, [`Protocol::resolve`]).
#[allow(clippy::too_many_arguments)] // the Python signature
fn setup(
    methods: Option<Vec<String>>,
    k: Option<usize>,
    precision: Option<Real>,
    matching: &str,
    calibration: Option<Split>,
    segment_fraction: Option<Real>,
    segment_size: Option<Int>,
    deploy_fraction: Option<Real>,
    sequence: SequenceGateArgs,
    query_major: bool,
) -> PyResult<Setup> {
    let precision = real("precision", precision)?;
    let segment_fraction = real("segment_fraction", segment_fraction)?;
    let deploy_fraction = real("deploy_fraction", deploy_fraction)?;
    let args = Args { gt: "gt", query_major };
    let matching: Matching = matching.parse().map_err(|e| args.error(e))?;
    // None, every method that applies, is resolved on the input ([`methods_for`]).
    let methods: Option<Vec<Method>> = methods
        .map(|names| names.iter().map(|n| n.parse()).collect::<qtvpr::Result<_>>())
        .transpose()
        .map_err(|e| args.error(e))?;
    let segment = match segment_size {
        Some(n) => Some(Split::Count(count("segment_size", n)?)),
        None => segment_fraction.map(Split::Fraction),
    };
    let sequence = sequence.overrides()?;
    let protocol = Protocol::resolve(
        k,
        precision,
        Some(matching),
        calibration,
        segment,
        deploy_fraction,
        sequence,
    )
    .map_err(|e| args.error(e))?;
    Ok(Setup {
        methods,
        protocol,
        args,
    })
}

/// ``cal_queries`` or ``cal_fraction``, `None` for neither.
fn calibration(cal_fraction: Option<Real>, cal_queries: Option<Int>) -> PyResult<Option<Split>> {
    Ok(match cal_queries {
        Some(n) => Some(Split::Count(count("cal_queries", n)?)),
        None => real("cal_fraction", cal_fraction)?.map(Split::Fraction),
    })
}

/// The matrices, |DB| x |Q|, and the name the report gives them: `s`'s path when it is
/// one.
fn inputs<'py>(
    s: &Bound<'py, PyAny>,
    gt: &Bound<'py, PyAny>,
    gt_soft: Option<&Bound<'py, PyAny>>,
    query_major: bool,
) -> PyResult<(SourceArg<'py>, GroundTruthArgs<'py>, Option<String>)> {
    let scores = SourceArg::extract("s", s, query_major)?;
    let labels = GroundTruthArgs::extract("gt", gt, gt_soft)?;
    let dataset = s.extract::<PathBuf>().ok().map(|p| p.display().to_string());
    Ok((scores, labels, dataset))
}

fn build_ground_truth(py: Python<'_>, gt: &GroundTruthArgs<'_>, query_major: bool) -> PyResult<GroundTruth> {
    let gt = gt.view(query_major);
    py.detach(|| gt.build())
}

/// Run the evaluation protocol of the paper's Table I on one similarity matrix.
///
/// ``s`` (|DB| x |Q|, float32 or float64, an array or a ``.npy`` path; or
/// :class:`Descriptors`, whose similarity is then computed in memory) comes with
/// ground truth ``gt`` (and optional ``gt_soft``) for every query. A parameter left
/// ``None`` is the library's default, as in ``qtvpr-cli evaluate``: ``k=10``,
/// ``precision=1.0``, ``cal_fraction=0.1``, ``segment_fraction=0.01``. The first ``cal_queries`` queries (default
/// ``floor(cal_fraction * |Q|)``) calibrate. The deployment set is every later query,
/// or with ``deploy_fraction`` the last ``floor(deploy_fraction * |Q|)`` queries (the
/// calibration-size ablation: the queries between the two sets are unused). It is cut
/// into full segments of ``segment_size`` queries (default
/// ``ceil(segment_fraction * |Q|)``), the remainder dropped. Each of ``methods``
/// (default all that apply to ``matching``: ``"quantile-transfer"``,
/// ``"quantile-transfer-online"``, ``"quantile-transfer-margin"``, ``"margin"``,
/// ``"quantile-transfer-sequence"``, ``"quantile-transfer-margin-sequence"``,
/// ``"sequence"`` (the gated ones single matching's only), ``"schubert"``,
/// ``"schubert-calibrated"``, ``"calibration-threshold"``, ``"oracle"``) gives every
/// segment a threshold, and the segment's decisions (``matching``) are counted against
/// its own ground truth.
///
/// The sequence methods (semantics §15) keep a best match only when the best matches
/// of the queries before it (the whole matrix is one traverse, in column order) agree
/// with it, by the sequence gate of ``sequence_window``, ``sequence_level``,
/// ``sequence_speed``, ``sequence_tolerance`` and ``sequence_drift`` (``None``: the
/// defaults); each of their segments reports the gate's ``consistency_level``, and the
/// consistency is a signal (``confidence["signals"]["consistency"]``) beside the score,
/// the margin and the PA-score.
///
/// ``"quantile-transfer-online"`` is :class:`Online` inside the protocol: every
/// deployment query is decided at its own threshold, over a window of the segment size
/// that starts at the first deployment query and is not reset at segment boundaries; a
/// segment's counts are the sums of its queries', and its ``threshold`` is its last
/// query's.
///
/// Returns a dict with the keys of ``qtvpr-cli evaluate --format json``:
/// ``dataset`` (``s``'s path if it is one, else ``None``), ``params`` (the parameters
/// and the split: ``calibration_queries``, ``deployment_start``, ``segment_size``,
/// ``segments``, ...), ``recall_at_1`` (R@1 of the deployment set: queries whose best
/// match is a hard match over queries with a hard match) and ``methods``: ``{name:
/// {"pct_segs", "avg_recall", "segments_counted", "segments_skipped", "threshold_mse",
/// "pooled_tp", "pooled_fp", "pooled_accepted", "pooled_positives", "pooled_precision",
/// "pooled_recall", "pooled_precision_lower95", "segments": [...]}}``: ``pooled_accepted``
/// is how many matches the method accepted over every full segment, and
/// ``pooled_precision`` is ``None`` when it accepted none. A segment meets the target when
/// its precision is at least ``precision``, or when it accepts nothing (the paper's
/// convention: a %Segs of 100 may rest on no decision); segments without positives are skipped;
/// ``pct_segs`` is the percentage of counted segments that meet, ``avg_recall`` the
/// mean of their recall (0 for those that miss), both ``None`` when no segment is
/// counted. Each segment has ``start``, ``end`` (indices into the deployment set),
/// ``threshold``, ``oracle_threshold`` (``inf`` is reject-all), ``tp``, ``fp``,
/// ``accepted``, ``positives``, ``precision`` (``None`` when nothing is accepted),
/// ``recall``, ``precision_lower95`` and ``meets``.
/// ``precision_lower95`` is the one-sided 95% Clopper-Pearson lower bound on the
/// precision (the 0.05 quantile of Beta(TP, FP + 1); 0 when TP = 0, ``None`` when
/// nothing is accepted). ``threshold_mse`` is the mean squared difference from the
/// oracle's threshold where both are finite (``None`` if nowhere).
#[pyfunction]
#[pyo3(signature = (
    s, gt, *, gt_soft = None, methods = None, k = None, precision = None, matching = "single",
    cal_fraction = None, cal_queries = None, segment_fraction = None, segment_size = None,
    deploy_fraction = None, query_major = false, sequence_window = None, sequence_level = None,
    sequence_speed = None, sequence_tolerance = None, sequence_drift = None,
))]
#[allow(clippy::too_many_arguments)] // the Python signature
pub(crate) fn evaluate<'py>(
    py: Python<'py>,
    s: &Bound<'py, PyAny>,
    gt: &Bound<'py, PyAny>,
    gt_soft: Option<&Bound<'py, PyAny>>,
    methods: Option<Vec<String>>,
    k: Option<Int>,
    precision: Option<Real>,
    matching: &str,
    cal_fraction: Option<Real>,
    cal_queries: Option<Int>,
    segment_fraction: Option<Real>,
    segment_size: Option<Int>,
    deploy_fraction: Option<Real>,
    query_major: bool,
    sequence_window: Option<Int>,
    sequence_level: Option<Real>,
    sequence_speed: Option<Real>,
    sequence_tolerance: Option<Real>,
    sequence_drift: Option<Real>,
) -> PyResult<Bound<'py, PyAny>> {
    let sequence = SequenceGateArgs {
        window: sequence_window,
        level: sequence_level,
        speed: sequence_speed,
        tolerance: sequence_tolerance,
        drift: sequence_drift,
    };
    let Setup {
        methods,
        protocol,
        args,
    } = setup(
        methods,
        k.map(|k| count("k", k)).transpose()?,
        precision,
        matching,
        calibration(cal_fraction, cal_queries)?,
        segment_fraction,
        segment_size,
        deploy_fraction,
        sequence,
        query_major,
    )?;
    let (s, gt, dataset) = inputs(s, gt, gt_soft, query_major)?;
    let gt = build_ground_truth(py, &gt, query_major)?;
    let orientation = s.orientation(py, &gt)?;
    let out = s
        .with(py, |s| {
            let methods = methods_for(methods, &protocol, s.dim().0);
            qtvpr::evaluate(s, &gt, &protocol, &methods)
        })?
        .map_err(|e| args.error(e))?;
    let report = Report {
        dataset: dataset.as_deref(),
        orientation,
        result: &out,
    };
    Ok(pythonize::pythonize(py, &report)?)
}

/// Run the evaluation protocol once per setting of ``k`` and of the calibration size:
/// the paper's Fig. 5 (%Segs and AvgR@tauP against ``k`` and against the calibration
/// size).
///
/// The arguments are those of :func:`evaluate`, except that ``k``, ``cal_fraction``
/// and ``cal_queries`` may each be a list: the protocol runs for every combination,
/// calibration sizes in the outer loop and ``k`` in the inner one. So that the
/// settings are comparable, every run deploys on the same queries: the last
/// ``floor(deploy_fraction * |Q|)``, by default the last half (``deploy_fraction =
/// 0.5``); the calibration set is always the first queries and may not reach into the
/// deployment set. Every setting is checked before the first one runs.
///
/// Returns a dict with the keys of ``qtvpr-cli evaluate --format json`` given lists:
/// ``dataset`` and ``ablation``, a list with one dict per setting holding the
/// ``params``, ``recall_at_1`` and ``methods`` of that run (as :func:`evaluate`
/// returns them). For example, AvgR@100P of quantile transfer against k::
///
///     runs = qtvpr.ablation(s, gt, k=[1, 3, 5, 10, 20, 40])["ablation"]
///     [(r["params"]["k"], r["methods"]["quantile-transfer"]["avg_recall"]) for r in runs]
#[pyfunction]
#[pyo3(
    signature = (
        s, gt, *, gt_soft = None, methods = None, k = None, precision = None,
        matching = "single", cal_fraction = None, cal_queries = None,
        segment_fraction = None, segment_size = None, deploy_fraction = None, query_major = false,
        sequence_window = None, sequence_level = None, sequence_speed = None, sequence_tolerance = None,
        sequence_drift = None,
    ),
)]
#[allow(clippy::too_many_arguments)] // the Python signature
pub(crate) fn ablation<'py>(
    py: Python<'py>,
    s: &Bound<'py, PyAny>,
    gt: &Bound<'py, PyAny>,
    gt_soft: Option<&Bound<'py, PyAny>>,
    methods: Option<Vec<String>>,
    k: Option<OneOrMany<Int>>,
    precision: Option<Real>,
    matching: &str,
    cal_fraction: Option<OneOrMany<Real>>,
    cal_queries: Option<OneOrMany<Int>>,
    segment_fraction: Option<Real>,
    segment_size: Option<Int>,
    deploy_fraction: Option<Real>,
    query_major: bool,
    sequence_window: Option<Int>,
    sequence_level: Option<Real>,
    sequence_speed: Option<Real>,
    sequence_tolerance: Option<Real>,
    sequence_drift: Option<Real>,
) -> PyResult<Bound<'py, PyAny>> {
    let sequence = SequenceGateArgs {
        window: sequence_window,
        level: sequence_level,
        speed: sequence_speed,
        tolerance: sequence_tolerance,
        drift: sequence_drift,
    };
    // Empty lists: the base protocol's value (the core's default) alone.
    let ks: Vec<usize> = match k {
        Some(k) => nonempty("k", k)?
            .into_iter()
            .map(|k| count("k", k))
            .collect::<PyResult<_>>()?,
        None => vec![],
    };
    let calibrations: Vec<Split> = match (cal_queries, cal_fraction) {
        (Some(n), _) => nonempty("cal_queries", n)?
            .into_iter()
            .map(|n| count("cal_queries", n).map(Split::Count))
            .collect::<PyResult<_>>()?,
        (None, Some(f)) => nonempty("cal_fraction", f)?
            .into_iter()
            .map(|f| f.get("cal_fraction").map(Split::Fraction))
            .collect::<PyResult<_>>()?,
        (None, None) => vec![],
    };
    let Setup {
        methods,
        protocol,
        args,
    } = setup(
        methods,
        ks.first().copied(),
        precision,
        matching,
        calibrations.first().copied(),
        segment_fraction,
        segment_size,
        deploy_fraction,
        sequence,
        query_major,
    )?;
    // Every setting is checked before any input is read (an empty list: the base's).
    protocol.ablation(&ks, &calibrations).map_err(|e| args.error(e))?;
    let (s, gt, dataset) = inputs(s, gt, gt_soft, query_major)?;
    let gt = build_ground_truth(py, &gt, query_major)?;
    let orientation = s.orientation(py, &gt)?;
    let out = s
        .with(py, |s| {
            let methods = methods_for(methods, &protocol, s.dim().0);
            qtvpr::ablation(s, &gt, &protocol, &ks, &calibrations, &methods)
        })?
        .map_err(|e| args.error(e))?;
    let report = Report {
        dataset: dataset.as_deref(),
        orientation,
        result: &out,
    };
    Ok(pythonize::pythonize(py, &report)?)
}
