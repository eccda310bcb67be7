//! `Calibration` and `TransferResult`: calibrate once, transfer many times.

use std::path::PathBuf;
use std::sync::Arc;

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use qtvpr::{Matching, Params, QuerySplit, ScoreSource, Split, SplitError};

use crate::convert::{self, GroundTruthArgs, Int, Real, count, non_negative, real, sequence_gate};
use crate::descriptors::SourceArg;
use crate::error::Args;

/// The Python `k` default (`10`) is written as a literal so that `help()` shows it.
const _: () = assert!(qtvpr::DEFAULT_K == 10);

/// A calibration traverse with ground truth, ready to transfer thresholds.
///
/// ``s_cal`` is the |DB| x |Qcal| calibration similarity (float32 or float64, higher is
/// more similar), ``gt_cal`` its hard ground truth and ``gt_soft`` its optional soft
/// ground truth (bool or integer 0/1, same shape; entries soft but not hard are
/// ignored). ``matching`` is ``"single"`` (one decision per query, on its best match)
/// or ``"multi"`` (every entry is a candidate). ``query_major=True`` takes every matrix
/// as |Qcal| x |DB| instead.
///
/// ``cal_queries=n`` or ``cal_fraction=f`` calibrates on the first queries of ``s_cal``
/// only (the first ``n``, or ``floor(f * |Q|)``, between 1 and |Q| - 1), as
/// ``qtvpr-cli calibrate --cal-queries`` does: ``gt_cal`` then labels every query of
/// ``s_cal`` and its first columns are used (:func:`quantile_transfer` thresholds the
/// rest). A count below 1, a fraction outside (0, 1), a split that leaves no query on
/// either side and ground truth of another shape raise ``ValueError``.
///
/// Every matrix may also be given as a path (``str`` or ``os.PathLike``) to a ``.npy``
/// file (``gt_cal`` also a VPR_Tutorial ``.npz`` with ``GThard`` and optional
/// ``GTsoft``; an explicit ``gt_soft`` takes precedence over ``GTsoft``), read by the
/// same reader as ``qtvpr-cli``. Similarity files are memory-mapped: a path is the
/// zero-copy way to pass a matrix too large to load.
///
/// Without ground truth, ``gt_cal`` may be the :class:`SelfMotionLabels` of
/// :func:`ground_truth_from_sequence` (with no ``gt_soft``): the calibration keeps their
/// record (:attr:`labels`, and its file's ``meta["labels"]``), and, since they judge one
/// entry per column, ``matching="multi"`` is a ``ValueError``, as with a ground-truth
/// ``.npz`` that holds such a record.
///
/// Everything that depends on the calibration traverse alone (ranked profiles,
/// candidates) is computed here, once; each :meth:`transfer` reuses it. Arrays are read
/// in place and the GIL is released while the work runs.
///
/// ``sequence=L`` (odd, >= 1; semantics §15) calibrates on the causal sequence-matched
/// calibration similarity (:func:`sequence_match` with ``causal=True`` over the
/// calibration queries in order): every :meth:`transfer` and :class:`Online` that uses
/// it matches its deployment columns the same way before deciding, and its file
/// records ``L``. ``None`` (the default) is 1, no matching.
///
/// A calibration can be saved as a calibration file (:meth:`save`), a NumPy ``.npz``
/// that :meth:`load` reads back with bit-identical results, so that calibration is done
/// once, offline; it pickles (as the bytes of that file), so it can be sent to worker
/// processes. :class:`Online` decides deployment queries one at a time from it.
///
/// Raises ``TypeError`` for an unsupported dtype (of an array or a file),
/// ``ValueError`` for bad input (shape mismatch, empty matrix, NaN or infinite score,
/// label other than 0/1, truncated or corrupt file, unknown ``matching``), and for a
/// file that cannot be read ``FileNotFoundError``, ``IsADirectoryError``,
/// ``PermissionError`` or ``OSError``. Messages name the argument, the file and the
/// offending shape or value (positions as the caller stored the matrix).
#[pyclass(frozen, module = "qtvpr", name = "Calibration")]
pub(crate) struct PyCalibration {
    /// Shared with every :class:`Online` built from it.
    inner: Arc<qtvpr::Calibration>,
}

impl PyCalibration {
    /// The core calibration, to share.
    pub(crate) fn inner(&self) -> &Arc<qtvpr::Calibration> {
        &self.inner
    }

    /// `precision`, or the calibration's default when `None`, checked by the core.
    fn precision(&self, precision: Option<Real>) -> PyResult<f64> {
        let precision = real("precision", precision)?;
        let defaults = self
            .inner
            .defaults()
            .resolve(None, precision, None, None, Default::default());
        Ok(defaults.map_err(|e| CAL_ARGS.error(e))?.precision)
    }
}

/// The arguments of a calibration traverse, converted: the similarity (a matrix, a path
/// or descriptors), its ground truth (built), the matching, and how errors name them.
pub(crate) struct CalibrationArgs<'py> {
    s: SourceArg<'py>,
    gt: qtvpr::GroundTruth,
    matching: Matching,
    args: Args,
}

impl<'py> CalibrationArgs<'py> {
    pub(crate) fn extract(
        py: Python<'py>,
        s_cal: &Bound<'py, PyAny>,
        gt_cal: &Bound<'py, PyAny>,
        gt_soft: Option<&Bound<'py, PyAny>>,
        matching: &str,
        query_major: bool,
    ) -> PyResult<Self> {
        let args = Args {
            gt: "gt_cal",
            query_major,
        };
        let matching: Matching = matching.parse().map_err(|e| args.error(e))?;
        let s = SourceArg::extract("s_cal", s_cal, query_major)?;
        let gt = GroundTruthArgs::extract("gt_cal", gt_cal, gt_soft)?;
        let gt = gt.view(query_major);
        let gt = py.detach(|| gt.build())?;
        Ok(Self { s, gt, matching, args })
    }

    /// The calibration of every query, or of the first queries of `split` (then the
    /// ground truth labels every query), sequence-matched over `length`.
    pub(crate) fn calibrate(self, py: Python<'_>, split: Option<Split>, length: usize) -> PyResult<PyCalibration> {
        let Self { s, gt, matching, args } = self;
        let inner = s
            .with(py, |s| match split {
                None => qtvpr::Calibration::new_sequence(s, &gt, matching, length),
                Some(split) => {
                    let split = QuerySplit::new(split, s.dim())?;
                    let gt = split.calibration_truth(&gt)?;
                    qtvpr::Calibration::new_sequence(s.columns(split.calibration()), &gt, matching, length)
                }
            })?
            .map_err(|e| args.error(e))?;
        Ok(PyCalibration { inner: Arc::new(inner) })
    }

    /// The transfer within the queries split by `split` (the core's
    /// [`QuerySplit::transfer`]): the first calibrate on their columns of the ground
    /// truth, which labels every query, and the rest are thresholded at `params`. Errors
    /// of the transfer name `s_cal`, with positions in the whole matrix.
    pub(crate) fn split_transfer(self, py: Python<'_>, split: Split, params: Params) -> PyResult<TransferResult> {
        let Self { s, gt, matching, args } = self;
        let transfer = |s: ScoreSource<'_, '_>| {
            let split = QuerySplit::new(split, s.dim()).map_err(SplitError::Calibration)?;
            let gt = split.calibration_truth(&gt).map_err(SplitError::Calibration)?;
            split.transfer(s, gt, matching, &params)
        };
        match s.with(py, |s| Ok(transfer(s)))?.map_err(|e| args.error(e))? {
            Ok((_, out)) => Ok(TransferResult::new(py, out)),
            Err(SplitError::Calibration(e)) => Err(args.error(e)),
            Err(SplitError::Deployment(e)) => Err(args.split_error(e)),
        }
    }
}

impl PyCalibration {
    /// The parameters of a transfer: those given, the others this calibration's
    /// defaults.
    fn params(
        &self,
        k: Option<Int>,
        precision: Option<Real>,
        segment_size: Option<Int>,
        gate: Option<&str>,
        sequence: SequenceGateArgs,
        args: Args,
    ) -> PyResult<Params> {
        let (k, segment_size) = (
            k.map(|k| count("k", k)).transpose()?,
            segment_size.map(|m| count("segment_size", m)).transpose()?,
        );
        let precision = real("precision", precision)?;
        let sequence = sequence.overrides()?;
        convert::gate(gate)
            .and_then(|gate| Params::resolve(self.inner.defaults(), k, precision, segment_size, gate, sequence))
            .map_err(|e| args.error(e))
    }
}

/// The sequence gate's keyword arguments of a Python call, as given (semantics §15).
#[derive(Debug, Clone, Default)]
pub(crate) struct SequenceGateArgs {
    pub(crate) window: Option<Int>,
    pub(crate) level: Option<Real>,
    pub(crate) speed: Option<Real>,
    pub(crate) tolerance: Option<Real>,
    pub(crate) drift: Option<Real>,
}

impl SequenceGateArgs {
    /// The core's overrides, the window checked.
    pub(crate) fn overrides(self) -> PyResult<qtvpr::SequenceOverrides> {
        sequence_gate(self.window, self.level, self.speed, self.tolerance, self.drift)
    }
}

/// ``cal_queries`` / ``cal_fraction``: how many of the first queries calibrate, as a
/// [`Split`] (checked by the core once the number of queries is known); `None` for
/// neither.
pub(crate) fn split_arg(cal_queries: Option<Int>, cal_fraction: Option<Real>) -> PyResult<Option<Split>> {
    match (cal_queries, cal_fraction) {
        (Some(_), Some(_)) => Err(PyValueError::new_err("give cal_queries or cal_fraction, not both")),
        (Some(n), None) => Ok(Some(Split::Count(count("cal_queries", n)?))),
        (None, Some(f)) => Ok(Some(Split::Fraction(f.get("cal_fraction")?))),
        (None, None) => Ok(None),
    }
}

/// How calibration-file calls name their arguments (no matrix is transposed).
const FILE_ARGS: Args = Args {
    gt: "gt",
    query_major: false,
};

/// How a calibration's own methods name their arguments.
const CAL_ARGS: Args = Args {
    gt: "gt_cal",
    query_major: false,
};

#[pymethods]
impl PyCalibration {
    #[new]
    #[pyo3(signature = (
        s_cal, gt_cal, *, gt_soft = None, matching = "single", query_major = false, cal_queries = None,
        cal_fraction = None, sequence = None,
    ))]
    #[allow(clippy::too_many_arguments)] // the Python signature
    pub(crate) fn new(
        py: Python<'_>,
        s_cal: &Bound<'_, PyAny>,
        gt_cal: &Bound<'_, PyAny>,
        gt_soft: Option<&Bound<'_, PyAny>>,
        matching: &str,
        query_major: bool,
        cal_queries: Option<Int>,
        cal_fraction: Option<Real>,
        sequence: Option<Int>,
    ) -> PyResult<Self> {
        let split = split_arg(cal_queries, cal_fraction)?;
        // Checked by the core (odd, >= 1) before the calibration does any work.
        let length = sequence.map(|l| non_negative("sequence", l)).transpose()?.unwrap_or(1);
        qtvpr::Sequence::causal(length)
            .validate()
            .map_err(|e| CAL_ARGS.error(e))?;
        CalibrationArgs::extract(py, s_cal, gt_cal, gt_soft, matching, query_major)?.calibrate(py, split, length)
    }

    /// Write this calibration to ``path`` as a calibration file, atomically.
    ///
    /// The file is a NumPy ``.npz`` (``np.load(path, allow_pickle=False)`` reads it)
    /// holding ``s``, the calibration similarity as given (float32 or float64,
    /// |DB| x |Qcal| whatever the input's orientation), ``gt``, the hard ground truth
    /// (bool), ``gt_soft``, the soft ground truth (bool; only when some entry is soft
    /// but not hard), and ``meta``, a 0-d string array of JSON: ``{"format":
    /// "qtvpr-calibration", "version": 1, "matching": ..., "params": {"k": ...,
    /// "precision": ..., "window": ..., "gate": ...}, "qtvpr": ...}`` (with
    /// ``"sequence_gate"``, the sequence gate's parameters, when it is on or they are not
    /// the defaults, and ``"sequence"``, the calibration's sequence length, when it is
    /// above 1). ``k``, ``precision``, ``window``, ``gate`` and the sequence gate's
    /// ``sequence_window``, ``sequence_level``, ``sequence_speed``,
    /// ``sequence_tolerance`` and ``sequence_drift`` are stored as the defaults of
    /// whoever uses the file (:class:`Online`, :meth:`transfer`, ``qtvpr-cli stream``);
    /// each can be overridden there. Each left as ``None`` is this calibration's own
    /// (:attr:`defaults`: a loaded file's, else 10, 1.0, no window, ``"none"`` and the
    /// sequence gate's defaults), so a loaded file saved again keeps its ``params``.
    /// The name is used as given (no ``.npz`` is appended).
    ///
    /// Raises ``ValueError`` for ``k < 1``, ``precision`` outside (0, 1],
    /// ``window < 1``, a ``gate`` that is not ``"none"`` or a set of ``"margin"`` and
    /// ``"sequence"`` (or a gate on a multi-matching calibration), or a bad sequence
    /// gate parameter, and ``OSError`` (``FileNotFoundError``, ``PermissionError``,
    /// ...) naming the file when it cannot be written; a failed save leaves no file
    /// behind.
    #[pyo3(signature = (
        path, *, k = None, precision = None, window = None, gate = None, sequence_window = None,
        sequence_level = None, sequence_speed = None, sequence_tolerance = None, sequence_drift = None,
    ))]
    #[allow(clippy::too_many_arguments)] // the Python signature
    fn save(
        &self,
        py: Python<'_>,
        path: PathBuf,
        k: Option<Int>,
        precision: Option<Real>,
        window: Option<Int>,
        gate: Option<&str>,
        sequence_window: Option<Int>,
        sequence_level: Option<Real>,
        sequence_speed: Option<Real>,
        sequence_tolerance: Option<Real>,
        sequence_drift: Option<Real>,
    ) -> PyResult<()> {
        let (k, window) = (
            k.map(|k| count("k", k)).transpose()?,
            window.map(|m| count("window", m)).transpose()?,
        );
        let precision = real("precision", precision)?;
        let sequence = sequence_gate(
            sequence_window,
            sequence_level,
            sequence_speed,
            sequence_tolerance,
            sequence_drift,
        )?;
        let defaults = convert::gate(gate)
            .and_then(|gate| self.inner.defaults().resolve(k, precision, window, gate, sequence))
            .map_err(|e| FILE_ARGS.error(e))?;
        py.detach(|| self.inner.save(&path, &defaults))
            .map_err(|e| FILE_ARGS.error(e))
    }

    /// Read a calibration file written by :meth:`save` (or ``qtvpr-cli calibrate``).
    ///
    /// The loaded calibration gives bit-identical results to the one saved; its
    /// :attr:`defaults` are the file's ``params``. Raises ``FileNotFoundError`` (or
    /// another ``OSError``) when the file cannot be read, and ``ValueError`` naming the
    /// file for anything wrong inside it: not an ``.npz``, a missing or corrupt array,
    /// arrays of the wrong shape, a NaN or infinite score, an unknown ``format`` or
    /// ``version``, a bad ``meta``; ``TypeError`` for an array of the wrong dtype
    /// (scores must be float32 or float64, ground truth bool).
    #[staticmethod]
    #[pyo3(signature = (path))]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = py
            .detach(|| qtvpr::Calibration::load(&path))
            .map_err(|e| FILE_ARGS.error(e))?;
        Ok(Self { inner: Arc::new(inner) })
    }

    /// A calibration from the bytes of a calibration file (what pickling uses).
    #[staticmethod]
    #[pyo3(signature = (data))]
    fn _from_bytes(py: Python<'_>, data: &[u8]) -> PyResult<Self> {
        let inner = py
            .detach(|| qtvpr::Calibration::from_bytes(data, "pickled calibration"))
            .map_err(|e| FILE_ARGS.error(e))?;
        Ok(Self { inner: Arc::new(inner) })
    }

    /// Pickled as the bytes of its calibration file, defaults included.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyBytes>,))> {
        let py = slf.py();
        let inner = &slf.get().inner;
        let bytes = py
            .detach(|| inner.to_bytes(inner.defaults()))
            .map_err(|e| FILE_ARGS.error(e))?;
        Ok((slf.get_type().getattr("_from_bytes")?, (PyBytes::new(py, &bytes),)))
    }

    /// The defaults of a calibration file's ``params``: ``{"k", "precision",
    /// "window", "gate", "sequence_gate"}`` (``{"k": 10, "precision": 1.0, "window":
    /// None, "gate": "none", "sequence_gate": {"window": 5, "level": 0.8, "speed": 1.0,
    /// "tolerance": 2.0, "drift": 0.2}}`` for a calibration built from arrays).
    /// :meth:`transfer` and :class:`Online` take each one they are not given from here.
    #[getter]
    fn defaults<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(pythonize::pythonize(py, self.inner.defaults())?)
    }

    /// How the calibration's ground truth was labelled when it came from self-motion
    /// labels (:func:`ground_truth_from_sequence`, or a ground-truth ``.npz`` of
    /// ``qtvpr-cli ground-truth --from-sequence``): their record, a dict (``{"labels":
    /// "self-motion", "neighbours": 5, ...}``), which its calibration file keeps in
    /// ``meta["labels"]``; ``None`` for other ground truth.
    #[getter]
    fn labels<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::self_motion::record_dict(py, self.inner.labels())
    }

    /// |DB|, the number of database images (rows) of the calibration.
    #[getter]
    fn db_size(&self) -> usize {
        self.inner.db_size()
    }

    /// The sequence length ``L`` (semantics §15): 1, or the causal sequence matching
    /// of ``Calibration(..., sequence=L)`` (a file's ``params.sequence``), which every
    /// transfer and :class:`Online` of this calibration applies to its deployment
    /// columns.
    #[getter]
    fn sequence(&self) -> usize {
        self.inner.sequence()
    }

    /// Transfer thresholds to the deployment similarity ``s_val`` (|DB| x |Qval|).
    ///
    /// Each deployment query samples its ``k`` calibration queries of most correlated
    /// ranked similarity profile (``k`` is clipped to the number of calibration
    /// queries); their best threshold at precision target ``precision`` (in (0, 1]) is
    /// turned into a quantile of their scores; each segment of ``segment_size``
    /// consecutive deployment queries (``None``: all of them in one segment; a shorter
    /// last segment is kept) gets the weighted-median quantile of its queries, read off
    /// its own scores. ``query_major=True`` takes ``s_val`` as |Qval| x |DB|. ``s_val``
    /// may be an array or the path of a ``.npy`` file (memory-mapped).
    ///
    /// Returns a :class:`TransferResult`. Raises ``TypeError`` for an unsupported dtype
    /// and ``ValueError`` for bad input (a |DB| other than the calibration's, empty,
    /// NaN or infinite scores, a truncated or corrupt file, ``k < 1``, ``precision``
    /// outside (0, 1], ``segment_size`` outside 1..=|Qval|); ``OSError`` (or its
    /// subclass ``FileNotFoundError``, ...) for a file that cannot be read.
    ///
    /// ``k``, ``precision``, ``gate`` and the sequence gate's parameters left as
    /// ``None`` are the calibration's :attr:`defaults` (its file's ``params``; 10, 1.0,
    /// ``"none"`` and the sequence gate's defaults for a calibration made from arrays).
    /// With ``gate="margin"`` (single matching only) the result also has the margin
    /// gate's ``gate`` (m*) and every query's margin (``query_margins``): a best match
    /// is accepted when its score is at or above its segment's threshold and its margin
    /// at or above m*. With ``gate="sequence"`` (semantics §15; single matching only) it
    /// has the sequence gate's ``consistency_level`` and every query's consistency with
    /// the queries before it (``query_consistencies``, the columns of ``s_val`` a stream
    /// in order, from its first): a best match is accepted when its consistency reaches
    /// the level too. ``gate="margin,sequence"``: both. ``sequence_window`` (W),
    /// ``sequence_level``, ``sequence_speed``, ``sequence_tolerance`` and
    /// ``sequence_drift`` are the sequence gate's parameters. A calibration of sequence
    /// length ``L > 1`` (:attr:`sequence`) matches ``s_val`` causally first.
    #[pyo3(signature = (
        s_val, *, k = None, precision = None, segment_size = None, gate = None, query_major = false,
        sequence_window = None, sequence_level = None, sequence_speed = None, sequence_tolerance = None,
        sequence_drift = None,
    ))]
    #[allow(clippy::too_many_arguments)] // the Python signature
    pub(crate) fn transfer(
        &self,
        py: Python<'_>,
        s_val: &Bound<'_, PyAny>,
        k: Option<Int>,
        precision: Option<Real>,
        segment_size: Option<Int>,
        gate: Option<&str>,
        query_major: bool,
        sequence_window: Option<Int>,
        sequence_level: Option<Real>,
        sequence_speed: Option<Real>,
        sequence_tolerance: Option<Real>,
        sequence_drift: Option<Real>,
    ) -> PyResult<TransferResult> {
        let args = Args {
            gt: "gt_cal",
            query_major,
        };
        let sequence = SequenceGateArgs {
            window: sequence_window,
            level: sequence_level,
            speed: sequence_speed,
            tolerance: sequence_tolerance,
            drift: sequence_drift,
        };
        let params = self.params(k, precision, segment_size, gate, sequence, args)?;
        let s = SourceArg::extract("s_val", s_val, query_major)?;
        let out = s
            .with(py, |s| self.inner.transfer(s, &params))?
            .map_err(|e| args.error(e))?;
        Ok(TransferResult::new(py, out))
    }

    /// Check, from its shape alone, a transfer of a deployment similarity of shape
    /// ``shape`` (as given: |Qval| x |DB| with ``query_major=True``): what
    /// :meth:`transfer` refuses before it reads a score, with its messages. For a
    /// scheduler that transfers blocks of the matrix (``qtvpr.dask``).
    ///
    /// Returns how many queries before a block's first one its decisions look back at
    /// (:meth:`_transfer_at`'s ``before``, at most): ``Calibration::lookback`` of the
    /// core, the sequence gate's window and the ``L - 1`` raw columns of a sequence
    /// length ``L``.
    #[pyo3(signature = (
        shape, *, k = None, precision = None, segment_size = None, gate = None, query_major = false,
        sequence_window = None, sequence_level = None, sequence_speed = None, sequence_tolerance = None,
        sequence_drift = None,
    ))]
    #[allow(clippy::too_many_arguments)] // the Python signature
    fn _check_transfer(
        &self,
        shape: (usize, usize),
        k: Option<Int>,
        precision: Option<Real>,
        segment_size: Option<Int>,
        gate: Option<&str>,
        query_major: bool,
        sequence_window: Option<Int>,
        sequence_level: Option<Real>,
        sequence_speed: Option<Real>,
        sequence_tolerance: Option<Real>,
        sequence_drift: Option<Real>,
    ) -> PyResult<usize> {
        let args = Args {
            gt: "gt_cal",
            query_major,
        };
        let sequence = SequenceGateArgs {
            window: sequence_window,
            level: sequence_level,
            speed: sequence_speed,
            tolerance: sequence_tolerance,
            drift: sequence_drift,
        };
        let params = self.params(k, precision, segment_size, gate, sequence, args)?;
        let shape = if query_major { (shape.1, shape.0) } else { shape };
        self.inner.check_transfer(shape, &params).map_err(|e| args.error(e))?;
        Ok(self.inner.lookback(params.gate, &params.sequence_gate))
    }

    /// :meth:`transfer` of a block of a larger deployment set whose first query is
    /// ``first_query`` (an array or a path), preceded by the ``before`` queries before
    /// it that its decisions look back at (the first ``before`` columns of ``s_val``;
    /// ``Calibration::transfer_block`` of the core): its segments and the positions in
    /// its errors count in the larger set. For a scheduler (``qtvpr.dask``).
    #[pyo3(signature = (
        s_val, first_query, *, before = Int::Small(0), k = None, precision = None, segment_size = None, gate = None,
        query_major = false, sequence_window = None, sequence_level = None, sequence_speed = None,
        sequence_tolerance = None, sequence_drift = None,
    ), text_signature = "(self, s_val, first_query, *, before=0, k=None, precision=None, segment_size=None, \
        gate=None, query_major=False, sequence_window=None, sequence_level=None, sequence_speed=None, \
        sequence_tolerance=None, sequence_drift=None)")]
    #[allow(clippy::too_many_arguments)] // the Python signature
    fn _transfer_at(
        &self,
        py: Python<'_>,
        s_val: &Bound<'_, PyAny>,
        first_query: Int,
        before: Int,
        k: Option<Int>,
        precision: Option<Real>,
        segment_size: Option<Int>,
        gate: Option<&str>,
        query_major: bool,
        sequence_window: Option<Int>,
        sequence_level: Option<Real>,
        sequence_speed: Option<Real>,
        sequence_tolerance: Option<Real>,
        sequence_drift: Option<Real>,
    ) -> PyResult<TransferResult> {
        let args = Args {
            gt: "gt_cal",
            query_major,
        };
        let first_query = non_negative("first_query", first_query)?;
        let before = non_negative("before", before)?;
        let sequence = SequenceGateArgs {
            window: sequence_window,
            level: sequence_level,
            speed: sequence_speed,
            tolerance: sequence_tolerance,
            drift: sequence_drift,
        };
        let params = self.params(k, precision, segment_size, gate, sequence, args)?;
        let s = SourceArg::extract("s_val", s_val, query_major)?;
        let out = s
            .with(py, |s| self.inner.transfer_block(s, &params, first_query, before))?
            .map_err(|e| args.error(e))?;
        Ok(TransferResult::new(py, out))
    }

    /// The best threshold of the whole calibration set at precision target
    /// ``precision`` (in (0, 1]): the threshold of maximum recall whose precision is at
    /// least the target, the highest such. ``math.inf`` means reject all.
    ///
    /// This is the threshold tuned once offline and kept fixed, as practised today.
    /// ``precision=None`` is the calibration's default (:attr:`defaults`).
    #[pyo3(signature = (precision = None))]
    fn threshold(&self, py: Python<'_>, precision: Option<Real>) -> PyResult<f64> {
        let precision = self.precision(precision)?;
        py.detach(|| self.inner.threshold(precision))
            .map_err(|e| CAL_ARGS.error(e))
    }

    /// The margin gate m* at precision target ``precision`` (``None``: the
    /// calibration's default): the best threshold of the calibration's single-match
    /// decisions with their margins (:func:`qtvpr.margins`) in place of their scores.
    /// ``math.inf`` means reject all. Raises ``ValueError`` for a multi-matching
    /// calibration, which has no gate.
    #[pyo3(signature = (precision = None))]
    fn gate(&self, precision: Option<Real>) -> PyResult<f64> {
        let precision = self.precision(precision)?;
        self.inner.gate(precision).map_err(|e| CAL_ARGS.error(e))
    }

    /// The confidence map (semantics §14): the blocks of the fit of the calibration's
    /// single-match decisions (soft-only best matches left out) on their PA-scores, by
    /// ascending confidence, each ``(centre, n, x)``: the map passes through
    /// ``(x + 1) / (n + 2)`` at the block's mean PA-score. Empty for a calibration
    /// without a decision.
    /// Raises ``ValueError`` for a multi-matching calibration, which has no confidence.
    fn confidence_blocks(&self, py: Python<'_>) -> PyResult<Vec<(f64, usize, usize)>> {
        let map = py
            .detach(|| self.inner.confidence_map())
            .map_err(|e| CAL_ARGS.error(e))?;
        Ok(map.blocks().iter().map(|b| (b.pa_score, b.n, b.x)).collect())
    }

    /// The number of calibration queries.
    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// The matching mode, ``"single"`` or ``"multi"``.
    #[getter]
    fn matching(&self) -> &'static str {
        self.inner.matching().as_str()
    }

    fn __repr__(&self) -> String {
        // The sequence length only where it matters, so that plain calibrations print as
        // they did.
        let sequence = match self.inner.sequence() {
            1 => String::new(),
            l => format!(", sequence={l}"),
        };
        format!(
            "Calibration(queries={}, matching='{}'{sequence})",
            self.inner.len(),
            self.inner.matching().as_str()
        )
    }
}

/// The result of a quantile transfer.
///
/// Per segment: ``thresholds`` (accept a match when its score is ``>=`` the threshold),
/// ``quantiles`` (the weighted-median quantile the threshold was read at) and
/// ``segments`` (``(start, end)`` deployment-query indices, end exclusive). Per
/// deployment query: ``query_quantiles``, ``query_thresholds`` (the best threshold of
/// its calibration neighbours, ``inf`` for reject-all), ``query_weights`` and
/// ``neighbours`` (|Qval| x min(k, |Qcal|) calibration indices, most correlated first).
/// With the margin gate: ``gate`` (m*, the margin a best match needs) and
/// ``query_margins`` (every query's margin); both ``None`` without it. In single
/// matching: ``query_confidences`` (every query's probability that its best match is
/// right, semantics §14, whatever the gate) and ``query_confidences_lower95`` (their
/// one-sided 95% Clopper-Pearson lower bounds); both ``None`` in multi matching. With
/// the sequence gate (semantics §15): ``consistency_level`` (the consistency a best
/// match needs) and ``query_consistencies`` (every query's); both ``None`` without it.
#[pyclass(frozen, module = "qtvpr", name = "TransferResult")]
pub(crate) struct TransferResult {
    /// One threshold per segment (float64).
    #[pyo3(get)]
    thresholds: Py<PyArray1<f64>>,
    /// One quantile per segment (float64).
    #[pyo3(get)]
    quantiles: Py<PyArray1<f64>>,
    /// ``(start, end)`` of every segment over the deployment queries, end exclusive.
    #[pyo3(get)]
    segments: Vec<(usize, usize)>,
    /// Per deployment query, the quantile of its subset threshold (float64).
    #[pyo3(get)]
    query_quantiles: Py<PyArray1<f64>>,
    /// Per deployment query, its subset threshold, ``inf`` for reject-all (float64).
    #[pyo3(get)]
    query_thresholds: Py<PyArray1<f64>>,
    /// Per deployment query, its weight: the mean of its neighbours' correlations,
    /// clipped below at 0 (float64).
    #[pyo3(get)]
    query_weights: Py<PyArray1<f64>>,
    /// |Qval| x min(k, |Qcal|) calibration indices, most correlated first (int64).
    #[pyo3(get)]
    neighbours: Py<PyArray2<i64>>,
    /// With the margin gate: m* (``None`` without it).
    #[pyo3(get)]
    gate: Option<f64>,
    /// With the margin gate: per deployment query, its margin (float64; ``None``
    /// without it).
    #[pyo3(get)]
    query_margins: Option<Py<PyArray1<f64>>>,
    /// In single matching: per deployment query, its confidence (float64; NaN for a
    /// calibration without a decision; ``None`` in multi matching).
    #[pyo3(get)]
    query_confidences: Option<Py<PyArray1<f64>>>,
    /// In single matching: per deployment query, its confidence's one-sided 95%
    /// Clopper-Pearson lower bound (float64; ``None`` in multi matching).
    #[pyo3(get)]
    query_confidences_lower95: Option<Py<PyArray1<f64>>>,
    /// With the sequence gate: its level (``None`` without it).
    #[pyo3(get)]
    consistency_level: Option<f64>,
    /// With the sequence gate: per deployment query, its consistency with the queries
    /// before it (float64; ``None`` without it).
    #[pyo3(get)]
    query_consistencies: Option<Py<PyArray1<f64>>>,
}

impl TransferResult {
    pub(crate) fn new(py: Python<'_>, out: qtvpr::Transfer) -> Self {
        let per_segment = |f: fn(&qtvpr::Segment) -> f64| PyArray1::from_iter(py, out.segments.iter().map(f)).unbind();
        Self {
            thresholds: per_segment(|s| s.threshold),
            quantiles: per_segment(|s| s.quantile),
            segments: out.segments.iter().map(|s| (s.start, s.end)).collect(),
            query_quantiles: out.query_quantiles.into_pyarray(py).unbind(),
            query_thresholds: out.query_thresholds.into_pyarray(py).unbind(),
            query_weights: out.query_weights.into_pyarray(py).unbind(),
            // Indices are below |Qcal|, so they fit in an i64.
            neighbours: out.neighbours.mapv(|i| i as i64).into_pyarray(py).unbind(),
            gate: out.gate,
            query_margins: out.query_margins.map(|m| m.into_pyarray(py).unbind()),
            query_confidences: out.query_confidences.map(|c| c.into_pyarray(py).unbind()),
            query_confidences_lower95: out.query_confidences_lower95.map(|c| c.into_pyarray(py).unbind()),
            consistency_level: out.consistency_level,
            query_consistencies: out.query_consistencies.map(|c| c.into_pyarray(py).unbind()),
        }
    }
}

#[pymethods]
impl TransferResult {
    /// A result from its fields, as the properties return them (what ``qtvpr.dask``
    /// assembles from the results of its blocks). The arrays are kept, not copied.
    ///
    /// Raises ``TypeError`` for an array of another dtype or dimension, and
    /// ``ValueError`` when the per-segment fields (``thresholds``, ``quantiles``,
    /// ``segments``) or the per-query fields (``query_quantiles``,
    /// ``query_thresholds``, ``query_weights``, the rows of ``neighbours``,
    /// ``query_margins``, ``query_confidences``, ``query_confidences_lower95``,
    /// ``query_consistencies``) differ in length.
    #[staticmethod]
    #[pyo3(signature = (
        thresholds, quantiles, segments, query_quantiles, query_thresholds, query_weights, neighbours,
        gate = None, query_margins = None, query_confidences = None, query_confidences_lower95 = None,
        consistency_level = None, query_consistencies = None,
    ))]
    #[allow(clippy::too_many_arguments)] // the fields
    fn _from_parts(
        thresholds: Bound<'_, PyArray1<f64>>,
        quantiles: Bound<'_, PyArray1<f64>>,
        segments: Vec<(usize, usize)>,
        query_quantiles: Bound<'_, PyArray1<f64>>,
        query_thresholds: Bound<'_, PyArray1<f64>>,
        query_weights: Bound<'_, PyArray1<f64>>,
        neighbours: Bound<'_, PyArray2<i64>>,
        gate: Option<Real>,
        query_margins: Option<Bound<'_, PyArray1<f64>>>,
        query_confidences: Option<Bound<'_, PyArray1<f64>>>,
        query_confidences_lower95: Option<Bound<'_, PyArray1<f64>>>,
        consistency_level: Option<Real>,
        query_consistencies: Option<Bound<'_, PyArray1<f64>>>,
    ) -> PyResult<Self> {
        let per_segment = [thresholds.len(), quantiles.len(), segments.len()];
        let per_query = [
            query_quantiles.len(),
            query_thresholds.len(),
            query_weights.len(),
            neighbours.shape()[0],
            query_margins.as_ref().map_or(query_quantiles.len(), |m| m.len()),
            query_confidences.as_ref().map_or(query_quantiles.len(), |m| m.len()),
            query_confidences_lower95
                .as_ref()
                .map_or(query_quantiles.len(), |m| m.len()),
            query_consistencies.as_ref().map_or(query_quantiles.len(), |m| m.len()),
        ];
        if per_segment.iter().any(|&n| n != per_segment[0]) || per_query.iter().any(|&n| n != per_query[0]) {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "TransferResult parts differ in length: thresholds, quantiles, segments {per_segment:?}; \
                 query_quantiles, query_thresholds, query_weights, neighbours rows, query_margins, query_confidences, \
                 query_confidences_lower95, query_consistencies {per_query:?}"
            )));
        }
        Ok(Self {
            thresholds: thresholds.unbind(),
            quantiles: quantiles.unbind(),
            segments,
            query_quantiles: query_quantiles.unbind(),
            query_thresholds: query_thresholds.unbind(),
            query_weights: query_weights.unbind(),
            neighbours: neighbours.unbind(),
            gate: real("gate", gate)?,
            query_margins: query_margins.map(Bound::unbind),
            query_confidences: query_confidences.map(Bound::unbind),
            query_confidences_lower95: query_confidences_lower95.map(Bound::unbind),
            consistency_level: real("consistency_level", consistency_level)?,
            query_consistencies: query_consistencies.map(Bound::unbind),
        })
    }

    /// ``TransferResult(segments=89, queries=3204, k=10, thresholds=[0.881, 0.878, 0.879, ...])``:
    /// the counts and the first thresholds, each to 6 significant digits, so that a
    /// result of thousands of segments prints on one line.
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        const SHOWN: usize = 3;
        let thresholds = self.thresholds.bind(py).readonly();
        let thresholds = thresholds.as_array();
        let n = thresholds.len();
        // All of them when the "..." would stand for just one.
        let shown = if n <= SHOWN + 1 { n } else { SHOWN };
        let spec = pyo3::intern!(py, "{:.6g}");
        let mut parts = thresholds
            .iter()
            .take(shown)
            .map(|&t| spec.call_method1("format", (t,))?.extract::<String>())
            .collect::<PyResult<Vec<String>>>()?;
        if shown < n {
            parts.push("...".to_string());
        }
        let neighbours = self.neighbours.bind(py);
        let (queries, k) = (neighbours.shape()[0], neighbours.shape()[1]);
        Ok(format!(
            "TransferResult(segments={}, queries={queries}, k={k}, thresholds=[{}])",
            self.segments.len(),
            parts.join(", ")
        ))
    }
}
