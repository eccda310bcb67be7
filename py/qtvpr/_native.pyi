"""Type stubs of the compiled module; the docstrings are on the compiled objects.

Checked against the compiled module by ``python -m mypy.stubtest qtvpr._native``
(scripts/test.sh): every name, parameter and default here is the runtime's.
"""

import os
from collections.abc import Iterable, Sequence
from typing import Any, ClassVar, Literal, NotRequired, TypedDict, TypeVar, final, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "__version__",
    "quantile_transfer",
    "best_threshold",
    "counts",
    "ranked_correlation",
    "margins",
    "cosine_similarity",
    "sequence_match",
    "ground_truth_tolerance",
    "ground_truth_positions",
    "ground_truth_from_sequence",
    "utm_positions",
    "image_paths",
    "evaluate",
    "schubert_threshold",
    "ablation",
    "set_threads",
    "Calibration",
    "Descriptors",
    "TransferResult",
    "SelfMotionLabels",
    "Online",
    "OnlineDecision",
    "OnlineDecisions",
]

__version__: str

_Matching = Literal["single", "multi"]
# A set of gates; "sequence,margin" is accepted too, and read back as "margin,sequence".
_Gate = Literal["none", "margin", "sequence", "margin,sequence", "sequence,margin"]
# A set of gates as the library writes it.
_GateSet = Literal["none", "margin", "sequence", "margin,sequence"]
_Method = Literal[
    "quantile-transfer",
    "quantile-transfer-online",
    "quantile-transfer-margin",
    "margin",
    "quantile-transfer-sequence",
    "quantile-transfer-margin-sequence",
    "sequence",
    "schubert",
    "schubert-calibrated",
    "calibration-threshold",
    "oracle",
]
# A matrix argument: an array, or the path of a .npy file (ground truth: .npy or a
# VPR_Tutorial .npz with GThard and optional GTsoft), read by the same reader as the CLI.
# Every matrix argument of the module accepts a path.
_Matrix = ArrayLike | str | os.PathLike[str]

class _Counts(TypedDict):
    tp: int
    fp: int
    accepted: int
    positives: int
    precision: float | None
    recall: float
    precision_lower95: float | None

class _Segment(TypedDict):
    start: int
    end: int
    threshold: float
    oracle_threshold: float
    gate: NotRequired[float]
    consistency_level: NotRequired[float]
    tp: int
    fp: int
    accepted: int
    positives: int
    precision: float | None
    recall: float
    precision_lower95: float | None
    meets: bool

class _MethodResult(TypedDict):
    pct_segs: float | None
    avg_recall: float | None
    segments_counted: int
    segments_skipped: int
    threshold_mse: float | None
    pooled_tp: int
    pooled_fp: int
    pooled_accepted: int
    pooled_positives: int
    pooled_precision: float | None
    pooled_recall: float
    pooled_precision_lower95: float | None
    segments: list[_Segment]

# A size as asked for: {"fraction": f} of all |Q| queries, or {"count": n}.
_Split = dict[Literal["fraction", "count"], float]

class _Params(TypedDict):
    calibration: _Split
    deploy_fraction: float | None
    segment: _Split
    k: int
    precision: float
    matching: _Matching
    database_size: int
    queries: int
    calibration_queries: int
    deployment_start: int
    deployment_queries: int
    segment_size: int
    segments: int
    sequence_gate: _SequenceGate

class _SequenceGate(TypedDict):
    window: int
    level: float
    speed: float
    tolerance: float
    drift: float

class _Auroc(TypedDict):
    auroc: float | None

class _ReliabilityBin(TypedDict):
    lower: float
    upper: float
    n: int
    mean_confidence: float
    hit_rate: float

class _Calibrated(TypedDict):
    auroc: float | None
    brier: float | None
    ece: float | None
    # The non-empty bins the ECE is computed from (a reliability diagram).
    bins: list[_ReliabilityBin] | None

class _SignalSet(TypedDict):
    score: _Auroc
    margin: _Auroc
    # The PA-score's AUROC ranks a lower PA-score higher.
    pa_score: _Auroc
    # Semantics §15 (None on a database too small for the sequence gate's parameters).
    consistency: _Auroc
    confidence: _Calibrated

class _Signals(TypedDict):
    signals: _SignalSet

class _Run(TypedDict):
    params: _Params
    recall_at_1: float | None
    methods: dict[_Method, _MethodResult]
    # Semantics §14, in single matching only.
    confidence: NotRequired[_Signals]

class _Evaluation(_Run):
    dataset: str | None

class _Ablation(TypedDict):
    dataset: str | None
    ablation: list[_Run]

@final
class TransferResult:
    @property
    def thresholds(self) -> NDArray[np.float64]: ...
    @property
    def quantiles(self) -> NDArray[np.float64]: ...
    @property
    def segments(self) -> list[tuple[int, int]]: ...
    @property
    def query_quantiles(self) -> NDArray[np.float64]: ...
    @property
    def query_thresholds(self) -> NDArray[np.float64]: ...
    @property
    def query_weights(self) -> NDArray[np.float64]: ...
    @property
    def neighbours(self) -> NDArray[np.int64]: ...
    @property
    def gate(self) -> float | None: ...
    @property
    def query_margins(self) -> NDArray[np.float64] | None: ...
    @property
    def query_confidences(self) -> NDArray[np.float64] | None: ...
    @property
    def query_confidences_lower95(self) -> NDArray[np.float64] | None: ...
    @property
    def consistency_level(self) -> float | None: ...
    @property
    def query_consistencies(self) -> NDArray[np.float64] | None: ...
    @staticmethod
    def _from_parts(
        thresholds: NDArray[np.float64],
        quantiles: NDArray[np.float64],
        segments: Sequence[tuple[int, int]],
        query_quantiles: NDArray[np.float64],
        query_thresholds: NDArray[np.float64],
        query_weights: NDArray[np.float64],
        neighbours: NDArray[np.int64],
        gate: float | None = None,
        query_margins: NDArray[np.float64] | None = None,
        query_confidences: NDArray[np.float64] | None = None,
        query_confidences_lower95: NDArray[np.float64] | None = None,
        consistency_level: float | None = None,
        query_consistencies: NDArray[np.float64] | None = None,
    ) -> TransferResult: ...

class _LabelCounts(TypedDict):
    positive: int
    negative: int
    abstain: int

# How self-motion labels were made (semantics §16): a ground-truth .npz's member
# `labels`, a calibration file's meta["labels"].
class _LabelRecord(TypedDict):
    labels: Literal["self-motion"]
    neighbours: int
    positive_level: float
    negative_level: float
    speed: float
    tolerance: float
    drift: float
    queries: int
    positive: int
    negative: int
    abstain: int

@final
class SelfMotionLabels:
    @property
    def hard(self) -> NDArray[np.bool_]: ...
    @property
    def soft(self) -> NDArray[np.bool_]: ...
    @property
    def labels(self) -> NDArray[np.str_]: ...
    @property
    def agreement(self) -> NDArray[np.float64]: ...
    @property
    def best(self) -> NDArray[np.int64]: ...
    @property
    def counts(self) -> _LabelCounts: ...
    @property
    def record(self) -> _LabelRecord: ...
    def __len__(self) -> int: ...

@final
class Descriptors:
    def __new__(
        cls,
        db: _Matrix,
        queries: _Matrix,
        *,
        start: int = 0,
        stop: int | None = None,
    ) -> Descriptors: ...
    @property
    def shape(self) -> tuple[int, int]: ...
    @property
    def start(self) -> int: ...
    @property
    def stop(self) -> int: ...
    def similarity(self) -> NDArray[np.float32]: ...

@final
class Calibration:
    def __new__(
        cls,
        s_cal: _Matrix | Descriptors,
        gt_cal: _Matrix | SelfMotionLabels,
        *,
        gt_soft: _Matrix | None = None,
        matching: _Matching = "single",
        query_major: bool = False,
        cal_queries: int | None = None,
        cal_fraction: float | None = None,
        sequence: int | None = None,
    ) -> Calibration: ...
    def transfer(
        self,
        s_val: _Matrix | Descriptors,
        *,
        k: int | None = None,
        precision: float | None = None,
        segment_size: int | None = None,
        gate: _Gate | None = None,
        query_major: bool = False,
        sequence_window: int | None = None,
        sequence_level: float | None = None,
        sequence_speed: float | None = None,
        sequence_tolerance: float | None = None,
        sequence_drift: float | None = None,
    ) -> TransferResult: ...
    # Returns how many queries before a block its decisions look back at.
    def _check_transfer(
        self,
        shape: tuple[int, int],
        *,
        k: int | None = None,
        precision: float | None = None,
        segment_size: int | None = None,
        gate: _Gate | None = None,
        query_major: bool = False,
        sequence_window: int | None = None,
        sequence_level: float | None = None,
        sequence_speed: float | None = None,
        sequence_tolerance: float | None = None,
        sequence_drift: float | None = None,
    ) -> int: ...
    def _transfer_at(
        self,
        s_val: _Matrix,
        first_query: int,
        *,
        before: int = 0,
        k: int | None = None,
        precision: float | None = None,
        segment_size: int | None = None,
        gate: _Gate | None = None,
        query_major: bool = False,
        sequence_window: int | None = None,
        sequence_level: float | None = None,
        sequence_speed: float | None = None,
        sequence_tolerance: float | None = None,
        sequence_drift: float | None = None,
    ) -> TransferResult: ...
    def threshold(self, precision: float | None = None) -> float: ...
    def gate(self, precision: float | None = None) -> float: ...
    # (centre PA-score, n, x) per block, by ascending confidence.
    def confidence_blocks(self) -> list[tuple[float, int, int]]: ...
    def save(
        self,
        path: str | os.PathLike[str],
        *,
        k: int | None = None,
        precision: float | None = None,
        window: int | None = None,
        gate: _Gate | None = None,
        sequence_window: int | None = None,
        sequence_level: float | None = None,
        sequence_speed: float | None = None,
        sequence_tolerance: float | None = None,
        sequence_drift: float | None = None,
    ) -> None: ...
    @staticmethod
    def load(path: str | os.PathLike[str]) -> Calibration: ...
    @staticmethod
    def _from_bytes(data: bytes) -> Calibration: ...
    def __reduce__(self) -> tuple[object, tuple[bytes]]: ...
    def __len__(self) -> int: ...
    @property
    def matching(self) -> _Matching: ...
    @property
    def defaults(self) -> _Defaults: ...
    @property
    def db_size(self) -> int: ...
    @property
    def sequence(self) -> int: ...
    @property
    def labels(self) -> _LabelRecord | None: ...

class _Defaults(TypedDict):
    k: int
    precision: float
    window: int | None
    gate: _GateSet
    sequence_gate: _SequenceGate

# A deployment query's scores: a 1-D array of |DB| scores, or a |DB| x 1 matrix.
_Column = ArrayLike

@final
class OnlineDecision:
    FIELDS: ClassVar[tuple[str, ...]]
    GATE_FIELDS: ClassVar[tuple[str, ...]]
    SEQUENCE_FIELDS: ClassVar[tuple[str, ...]]
    # (name, column, kind, gate) of every field: the core's record.
    RECORD: ClassVar[tuple[tuple[str, str, Literal["count", "real", "flag"], _GateSet], ...]]
    @property
    def query(self) -> int: ...
    @property
    def query_quantile(self) -> float: ...
    @property
    def weight(self) -> float: ...
    @property
    def quantile(self) -> float: ...
    @property
    def threshold(self) -> float: ...
    @property
    def best(self) -> int: ...
    @property
    def score(self) -> float: ...
    @property
    def accepted(self) -> int: ...
    @property
    def accept(self) -> bool: ...
    @property
    def margin(self) -> float | None: ...
    @property
    def gate(self) -> float | None: ...
    @property
    def consistency(self) -> float | None: ...
    @property
    def consistency_level(self) -> float | None: ...
    @property
    def confidence(self) -> float: ...
    @property
    def confidence_lower95(self) -> float: ...
    @property
    def accepted_indices(self) -> NDArray[np.int64]: ...

@final
class OnlineDecisions:
    COLUMNS: ClassVar[tuple[str, ...]]
    @property
    def queries(self) -> NDArray[np.int64]: ...
    @property
    def query_quantiles(self) -> NDArray[np.float64]: ...
    @property
    def weights(self) -> NDArray[np.float64]: ...
    @property
    def quantiles(self) -> NDArray[np.float64]: ...
    @property
    def thresholds(self) -> NDArray[np.float64]: ...
    @property
    def best(self) -> NDArray[np.int64]: ...
    @property
    def score(self) -> NDArray[np.float64]: ...
    @property
    def accepted(self) -> NDArray[np.int64]: ...
    @property
    def accept(self) -> NDArray[np.bool_]: ...
    @property
    def margins(self) -> NDArray[np.float64] | None: ...
    @property
    def gates(self) -> NDArray[np.float64] | None: ...
    @property
    def consistencies(self) -> NDArray[np.float64] | None: ...
    @property
    def consistency_levels(self) -> NDArray[np.float64] | None: ...
    @property
    def confidences(self) -> NDArray[np.float64]: ...
    @property
    def confidences_lower95(self) -> NDArray[np.float64]: ...
    @staticmethod
    def _from_parts(*columns: NDArray[Any] | None) -> OnlineDecisions: ...
    def __len__(self) -> int: ...

@final
class Online:
    def __new__(
        cls,
        calibration: Calibration,
        *,
        k: int | None = None,
        precision: float | None = None,
        window: int | None = None,
        min_window: int = 1,
        gate: _Gate | None = None,
        sequence_window: int | None = None,
        sequence_level: float | None = None,
        sequence_speed: float | None = None,
        sequence_tolerance: float | None = None,
        sequence_drift: float | None = None,
        sequence: int | None = None,
    ) -> Online: ...
    def push(self, column: _Column) -> OnlineDecision: ...
    def push_many(self, s_val: _Matrix, *, query_major: bool = False) -> OnlineDecisions: ...
    def _resume(self, first_query: int, s_before: _Matrix, *, query_major: bool = False) -> None: ...
    def _lookback(self, first_query: int) -> int: ...
    def _push_stream(self, s_val: _Matrix, *, query_major: bool = False) -> OnlineDecisions: ...
    @property
    def threshold(self) -> float | None: ...
    @property
    def pushed(self) -> int: ...
    @property
    def k(self) -> int: ...
    @property
    def precision(self) -> float: ...
    @property
    def window(self) -> int: ...
    @property
    def min_window(self) -> int: ...
    @property
    def gate(self) -> _GateSet: ...
    @property
    def sequence_gate(self) -> _SequenceGate: ...
    @property
    def sequence(self) -> int: ...
    @property
    def calibration(self) -> Calibration: ...

def quantile_transfer(
    s_cal: _Matrix | Descriptors,
    gt_cal: _Matrix,
    s_val: _Matrix | Descriptors | None = None,
    *,
    gt_soft: _Matrix | None = None,
    k: int = 10,
    precision: float = 1.0,
    matching: _Matching = "single",
    segment_size: int | None = None,
    gate: _Gate = "none",
    query_major: bool = False,
    cal_queries: int | None = None,
    cal_fraction: float | None = None,
    sequence_window: int | None = None,
    sequence_level: float | None = None,
    sequence_speed: float | None = None,
    sequence_tolerance: float | None = None,
    sequence_drift: float | None = None,
) -> TransferResult: ...
def margins(s: _Matrix, *, query_major: bool = False) -> NDArray[np.float64]: ...
def best_threshold(
    s: _Matrix,
    gt: _Matrix,
    *,
    gt_soft: _Matrix | None = None,
    precision: float = 1.0,
    matching: _Matching = "single",
    query_major: bool = False,
) -> float: ...
def counts(
    s: _Matrix,
    gt: _Matrix,
    threshold: float,
    *,
    gt_soft: _Matrix | None = None,
    matching: _Matching = "single",
    query_major: bool = False,
) -> _Counts: ...
def ranked_correlation(
    s_val: _Matrix,
    s_cal: _Matrix,
    *,
    query_major: bool = False,
) -> NDArray[np.float64]: ...

# Extensions: similarity from descriptors, sequence matching, ground truth.
_F = TypeVar("_F", np.float32, np.float64)

def cosine_similarity(
    db: _Matrix,
    queries: _Matrix,
    *,
    sequence: int | None = None,
    causal: bool = False,
) -> NDArray[np.float32]: ...

# The result has the dtype of `s`: known for an array, not for a path.
@overload
def sequence_match(s: NDArray[_F], length: int, *, causal: bool = False) -> NDArray[_F]: ...
@overload
def sequence_match(
    s: _Matrix, length: int, *, causal: bool = False
) -> NDArray[np.float32] | NDArray[np.float64]: ...
def ground_truth_tolerance(n_db: int, n_queries: int, tolerance: int) -> NDArray[np.bool_]: ...
def ground_truth_from_sequence(
    s_cal: _Matrix,
    *,
    neighbours: int | None = None,
    positive_level: float | None = None,
    negative_level: float | None = None,
    sequence_speed: float | None = None,
    sequence_tolerance: float | None = None,
    sequence_drift: float | None = None,
    query_major: bool = False,
) -> SelfMotionLabels: ...
def ground_truth_positions(
    db_positions: _Matrix,
    query_positions: _Matrix,
    radius: float,
) -> NDArray[np.bool_]: ...
def utm_positions(paths: Sequence[str | os.PathLike[str]]) -> NDArray[np.float64]: ...
def image_paths(source: str | os.PathLike[str]) -> list[str]: ...
def schubert_threshold(s: _Matrix) -> float: ...
def set_threads(n: int) -> None: ...
def evaluate(
    s: _Matrix | Descriptors,
    gt: _Matrix,
    *,
    gt_soft: _Matrix | None = None,
    methods: Iterable[_Method] | None = None,
    k: int | None = None,
    precision: float | None = None,
    matching: _Matching = "single",
    cal_fraction: float | None = None,
    cal_queries: int | None = None,
    segment_fraction: float | None = None,
    segment_size: int | None = None,
    deploy_fraction: float | None = None,
    query_major: bool = False,
    sequence_window: int | None = None,
    sequence_level: float | None = None,
    sequence_speed: float | None = None,
    sequence_tolerance: float | None = None,
    sequence_drift: float | None = None,
) -> _Evaluation: ...
def ablation(
    s: _Matrix | Descriptors,
    gt: _Matrix,
    *,
    gt_soft: _Matrix | None = None,
    methods: Iterable[_Method] | None = None,
    k: int | Sequence[int] | None = None,
    precision: float | None = None,
    matching: _Matching = "single",
    cal_fraction: float | Sequence[float] | None = None,
    cal_queries: int | Sequence[int] | None = None,
    segment_fraction: float | None = None,
    segment_size: int | None = None,
    deploy_fraction: float | None = None,
    query_major: bool = False,
    sequence_window: int | None = None,
    sequence_level: float | None = None,
    sequence_speed: float | None = None,
    sequence_tolerance: float | None = None,
    sequence_drift: float | None = None,
) -> _Ablation: ...
