"""Plain NumPy reference implementation of quantile transfer.

This module is the executable form of the project's semantics (``docs/semantics.md``
in the repository, cited as "semantics §N"). It is written to be read, not to be
fast: one function per section, loops where a loop says it more plainly, and no code shared with the Rust
core. Parity tests compare the compiled implementation against it.

Conventions shared by every public function:

- Matrices are |DB| x |Q|, one column per query. ``query_major=True`` means every
  matrix argument (scores and ground truth alike) is given as |Q| x |DB| and is
  transposed first.
- All arithmetic on scores is done in float64; float32 input is converted exactly.
- Ground truth is bool or integer 0/1. ``gt_soft`` marks extra tolerable matches; the
  *ignored* entries are ``gt_soft & ~gt`` and count as neither true nor false.
- Bad input raises ``ValueError`` (or ``TypeError`` for an unsupported dtype) with a
  message that names the argument (semantics §10). Positions in messages are given
  in the caller's own orientation, before any transposition.

One deliberate refinement of semantics §4.3, shared with the Rust core: the top-k
calibration queries are chosen by correlations rounded to a grid of 2**-40, so that
correlations that are equal in exact arithmetic tie whatever the floating-point
summation order. See ``_calibration_neighbours``.
"""

from __future__ import annotations

import functools
import importlib.metadata
import json
import math
import numbers
import operator
import os
from dataclasses import dataclass

import numpy as np

__all__ = [
    "METHODS",
    "Calibration",
    "Online",
    "OnlineDecision",
    "OnlineDecisions",
    "SelfMotionLabels",
    "TransferResult",
    "ablation",
    "best_threshold",
    "confidence_blocks",
    "counts",
    "evaluate",
    "ground_truth_from_sequence",
    "margins",
    "precision_lower95",
    "quantile_transfer",
    "schubert_threshold",
    "sequence_consistency",
    "vprbench_recall_at_100p",
]

#: Tolerance used in every precision comparison (semantics §3, §6 and §8).
EPS = 1e-12

#: Standard normal quantile at 1 - 1e-6 (semantics §7).
SCHUBERT_Z = 4.753424308817087

#: Grid on which correlations are compared when choosing neighbours (refinement of 4.3).
CORRELATION_GRID = 2.0**40

#: The methods that gate decisions on their margin (semantics §13).
MARGIN_GATED = ("quantile-transfer-margin", "margin", "quantile-transfer-margin-sequence")

#: The methods that gate decisions on their consistency (semantics §15).
SEQUENCE_GATED = ("quantile-transfer-sequence", "quantile-transfer-margin-sequence", "sequence")

#: The gated methods: single matching only.
GATED = tuple(dict.fromkeys(MARGIN_GATED + SEQUENCE_GATED))

#: The gates a decision can have (semantics §13, §15), each set as the library writes it.
GATES = ("none", "margin", "sequence", "margin,sequence")

#: The sequence gate's parameters when none is given (semantics §15).
SEQUENCE_DEFAULTS = {"window": 5, "level": 0.8, "speed": 1.0, "tolerance": 2.0, "drift": 0.2}

#: Every method of the evaluation protocol, in report order (semantics §7, §8, §13, §15).
METHODS = (
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
)


# ---------------------------------------------------------------------------------------
# Section 10: bad input
# ---------------------------------------------------------------------------------------


def _shape(a: np.ndarray) -> str:
    return "x".join(str(d) for d in a.shape)


def _check_matrix(name: str, a: np.ndarray) -> None:
    """A matrix argument must be 2-D and non-empty (semantics §10)."""
    if a.ndim != 2:
        raise ValueError(f"{name} must be a 2-D matrix, got a {a.ndim}-D array of shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"{name} is empty (shape {_shape(a)})")


def _scores(name: str, s, query_major: bool) -> np.ndarray:
    """Validate a score matrix and return it as a float64 |DB| x |Q| array.

    Only float32 and float64 are accepted (``TypeError`` otherwise); NaN and infinite
    scores are a ``ValueError`` naming the first offending position.
    """
    a = np.asarray(s)
    if a.dtype.kind != "f" or a.dtype.itemsize not in (4, 8):
        raise TypeError(f"{name} must be float32 or float64, got dtype {a.dtype}")
    _check_matrix(name, a)
    bad = np.argwhere(~np.isfinite(a))
    if len(bad) > 0:
        r, c = (int(v) for v in bad[0])
        what = "NaN" if np.isnan(a[r, c]) else "an infinite value"
        raise ValueError(f"{name} contains {what} at row {r}, column {c}")
    a = a.astype(np.float64)  # exact for float32
    return a.T if query_major else a


def _ground_truth(name: str, g, like_name: str, like: np.ndarray, query_major: bool) -> np.ndarray:
    """Validate a ground-truth matrix against the score matrix ``like`` (caller's
    orientation) and return it as a bool |DB| x |Q| array.

    bool and integer dtypes are accepted (``TypeError`` otherwise); integer values must
    be 0 or 1 (``ValueError`` otherwise).
    """
    a = np.asarray(g)
    if a.dtype.kind not in "biu":
        raise TypeError(f"{name} must be bool or integer 0/1, got dtype {a.dtype}")
    _check_matrix(name, a)
    if a.shape != like.shape:
        raise ValueError(f"{name} shape {_shape(a)} does not match {like_name} shape {_shape(like)}")
    if a.dtype.kind != "b":
        bad = np.argwhere((a != 0) & (a != 1))
        if len(bad) > 0:
            r, c = (int(v) for v in bad[0])
            raise ValueError(
                f"{name} contains {a[r, c]} at row {r}, column {c}; ground truth must be 0 or 1"
            )
    a = a.astype(bool)
    return a.T if query_major else a


def _inputs(s_name, s, gt_name, gt, soft_name, gt_soft, query_major):
    """Validate one score matrix with its hard and optional soft ground truth.

    Returns ``(s, gt, ignored)`` in |DB| x |Q| orientation, where ``ignored`` is
    ``gt_soft & ~gt`` (all False without soft ground truth).
    """
    raw = np.asarray(s)
    s64 = _scores(s_name, raw, query_major)
    hard = _ground_truth(gt_name, gt, s_name, raw, query_major)
    if gt_soft is None:
        ignored = np.zeros_like(hard)
    else:
        soft = _ground_truth(soft_name, gt_soft, s_name, raw, query_major)
        ignored = soft & ~hard
    return s64, hard, ignored


def _check_precision(precision) -> float:
    if not isinstance(precision, numbers.Real):
        raise TypeError(f"precision must be a real number, got {type(precision).__name__}")
    tau = float(precision)
    if not (0.0 < tau <= 1.0):
        raise ValueError(f"precision must be in (0, 1], got {precision}")
    return tau


def _check_matching(matching) -> str:
    if matching not in ("single", "multi"):
        raise ValueError(f"matching must be 'single' or 'multi', got {matching!r}")
    return matching


def _check_positive_int(name: str, value) -> int:
    try:
        v = operator.index(value)
    except TypeError:
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}") from None
    if v < 1:
        raise ValueError(f"{name} must be >= 1, got {v}")
    return v


# ---------------------------------------------------------------------------------------
# Section 2: decisions (matching mode)
# ---------------------------------------------------------------------------------------


def _candidates(s: np.ndarray, gt: np.ndarray, ignored: np.ndarray, matching: str):
    """The candidates of a matrix, as semantics §2 defines them.

    Returns ``(scores, correct, positives)``: the candidate scores (float64), whether
    each candidate is correct (bool), and the number of positives.

    - single: one candidate per query, its best match ``b`` = the first maximum of the
      column; correct iff ``gt[b, j]``; no candidate when ``(b, j)`` is ignored.
      Positives = queries with at least one hard match.
    - multi: every non-ignored entry; correct iff ``gt`` there. Positives = number of
      hard matches.
    """
    if matching == "single":
        scores, correct = [], []
        for j in range(s.shape[1]):
            b = int(np.argmax(s[:, j]))  # first maximum on ties
            if ignored[b, j]:
                continue  # the query makes no decision
            scores.append(s[b, j])
            correct.append(bool(gt[b, j]))
        positives = int(np.count_nonzero(gt.any(axis=0)))
        return np.array(scores, dtype=np.float64), np.array(correct, dtype=bool), positives
    keep = ~ignored
    return s[keep], gt[keep], int(np.count_nonzero(gt))


def _count_at(scores: np.ndarray, correct: np.ndarray, positives: int, threshold: float) -> dict:
    """TP, FP, precision and recall of the candidates at ``threshold`` (s >= t accepts)."""
    accepted = scores >= threshold
    tp = int(np.count_nonzero(accepted & correct))
    fp = int(np.count_nonzero(accepted & ~correct))
    return _counts_of(tp, fp, positives)


def _counts_of(tp: int, fp: int, positives: int) -> dict:
    """The counts dict, with precision None when nothing is accepted (semantics §2: a
    precision that rests on no decision is undefined) and recall 0 without positives."""
    precision = tp / (tp + fp) if tp + fp > 0 else None
    recall = tp / positives if positives > 0 else 0.0
    return {"tp": tp, "fp": fp, "accepted": tp + fp, "positives": positives, "precision": precision,
            "recall": recall}


def _meets(c: dict, tau: float) -> bool:
    """Semantics §8.3: precision >= tau - 1e-12, or nothing accepted (the paper's
    convention, precision taken as 1)."""
    return c["accepted"] == 0 or c["precision"] >= tau - EPS


def _binomial_upper_tail(n: int, a: int, x: float, log_comb: np.ndarray) -> float:
    """P(Binomial(n, x) >= a) = sum over i = a..n of C(n, i) x^i (1 - x)^(n - i), summed
    in log space; ``log_comb[i - a]`` is log C(n, i)."""
    i = np.arange(a, n + 1)
    log_terms = log_comb + i * math.log(x) + (n - i) * math.log1p(-x)
    top = log_terms.max()
    return float(math.exp(top) * np.exp(log_terms - top).sum())


@functools.lru_cache(maxsize=4096)
def precision_lower95(tp: int, fp: int) -> float | None:
    """The one-sided 95% Clopper-Pearson lower bound on a precision of TP / (TP + FP).

    It is the 0.05 quantile of Beta(TP, FP + 1). For integer shapes a and b,
    P(Beta(a, b) <= x) = P(Binomial(a + b - 1, x) >= a), so the quantile is the x at
    which that binomial tail (increasing in x) reaches 0.05, found here by bisection.
    0 when TP = 0; None when nothing is accepted (TP + FP = 0).
    """
    if tp + fp == 0:
        return None
    if tp == 0:
        return 0.0
    a, n = tp, tp + fp  # Beta(a, b) with b = fp + 1: n = a + b - 1
    log_comb = np.array(
        [math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1) for i in range(a, n + 1)]
    )
    lo, hi = 0.0, 1.0
    for _ in range(60):  # 2**-60: below the spacing of doubles near the answer
        mid = (lo + hi) / 2
        if _binomial_upper_tail(n, a, mid, log_comb) < 0.05:
            lo = mid
        else:
            hi = mid
    return (lo + hi) / 2


def counts(s, gt, threshold, *, gt_soft=None, matching="single", query_major=False) -> dict:
    """Counts of one matrix's decisions at ``threshold`` (semantics §2).

    Returns ``dict(tp=, fp=, accepted=, positives=, precision=, recall=,
    precision_lower95=)``, the keys of a segment of ``evaluate``. Precision is None when
    nothing is accepted; recall is 0 when there are no positives. ``threshold`` may be ``inf`` (accepts nothing) but
    not NaN.
    """
    matching = _check_matching(matching)
    if not isinstance(threshold, numbers.Real) or math.isnan(threshold):
        raise ValueError(f"threshold must be a real number other than NaN, got {threshold!r}")
    s, gt, ignored = _inputs("s", s, "gt", gt, "gt_soft", gt_soft, query_major)
    out = _count_at(*_candidates(s, gt, ignored, matching), float(threshold))
    out["precision_lower95"] = precision_lower95(out["tp"], out["fp"])
    return out


# ---------------------------------------------------------------------------------------
# Section 3: best threshold under a precision target
# ---------------------------------------------------------------------------------------


def _sweep(scores: np.ndarray, correct: np.ndarray, positives: int, tau: float) -> float:
    """The exact precision sweep of semantics §3 over a list of candidates.

    Candidates are sorted by decreasing score; the counts are evaluated only at the last
    candidate of each group of equal scores. A group is valid when TP > 0 and
    TP >= tau * (TP + FP) - 1e-12. The threshold is the score of the first group at
    which TP reaches the largest valid TP, or +inf (reject-all) when no group is valid
    or there are no positives.
    """
    if positives == 0 or len(scores) == 0:
        return math.inf
    order = np.argsort(-scores, kind="stable")
    s_sorted = scores[order]
    tp = np.cumsum(correct[order])  # TP and FP after each candidate, down the sweep
    fp = np.arange(1, len(s_sorted) + 1) - tp
    last_of_group = np.append(s_sorted[1:] != s_sorted[:-1], True)
    valid = last_of_group & (tp > 0) & (tp >= tau * (tp + fp) - EPS)
    if not valid.any():
        return math.inf
    best = tp[valid].max()
    # TP never decreases down the sweep, so the first group reaching `best` has the fewest
    # false positives among those with TP == best, and is therefore valid itself.
    first = np.flatnonzero(last_of_group & (tp == best))[0]
    return float(s_sorted[first])


def _best_threshold(s, gt, ignored, tau, matching) -> float:
    return _sweep(*_candidates(s, gt, ignored, matching), tau)


def best_threshold(
    s, gt, *, gt_soft=None, precision=1.0, matching="single", query_major=False
) -> float:
    """Best threshold of one matrix under precision target ``precision`` (semantics §3,
    candidates per section 2). Returns ``math.inf`` for reject-all."""
    tau = _check_precision(precision)
    matching = _check_matching(matching)
    s, gt, ignored = _inputs("s", s, "gt", gt, "gt_soft", gt_soft, query_major)
    return _best_threshold(s, gt, ignored, tau, matching)


# ---------------------------------------------------------------------------------------
# Section 4: calibration sampling (ranked correlation)
# ---------------------------------------------------------------------------------------


def _ranked_unit_profiles(s: np.ndarray) -> np.ndarray:
    """Column-centred, unit-norm ranked similarity profiles (semantics §4.1 and §4.2).

    Each column is sorted in descending order. A sorted column has zero variance exactly
    when its first and last values are equal; its vector is then all zeros, so its
    correlation with everything is exactly 0.
    """
    profiles = -np.sort(-s, axis=0)  # each column in descending order
    z = np.zeros_like(profiles)
    for j in range(profiles.shape[1]):
        p = profiles[:, j]
        if p[0] == p[-1]:
            continue  # zero variance: correlation 0 with everything
        centred = p - p.mean()
        z[:, j] = centred / np.linalg.norm(centred)
    return z


def _calibration_neighbours(s_cal, s_val, k: int):
    """Ranked correlation and top-k calibration queries (semantics §4).

    Takes float64 |DB| x |Qcal| and |DB| x |Qval| matrices. Returns
    ``(R, neighbours, weights)``:

    - ``R[j, i]``: Pearson correlation of the ranked profiles of deployment query j and
      calibration query i, computed as one product of unit profiles ``Zval.T @ Zcal``.
    - ``neighbours[j]``: the ``min(k, |Qcal|)`` calibration indices of highest
      correlation, in decreasing order. Refinement of 4.3: correlations are compared
      after rounding to a grid of 2**-40 (``rint(R * 2**40)``), ties going to the lower
      calibration index, so that correlations equal in exact arithmetic tie whatever
      the summation order.
    - ``weights[j]``: mean of the chosen *raw* correlations, clipped below at 0.
    """
    zcal = _ranked_unit_profiles(s_cal)
    zval = _ranked_unit_profiles(s_val)
    r = zval.T @ zcal
    n_val, n_cal = r.shape
    k = min(k, n_cal)
    index = np.arange(n_cal)
    neighbours = np.empty((n_val, k), dtype=np.int64)
    weights = np.empty(n_val, dtype=np.float64)
    for j in range(n_val):
        key = np.rint(r[j] * CORRELATION_GRID)
        order = np.lexsort((index, -key))  # by decreasing key, then increasing index
        neighbours[j] = order[:k]
        total = 0.0
        for i in neighbours[j]:  # summed one by one, in neighbour order
            total += float(r[j, i])
        weights[j] = max(0.0, total / k)
    return r, neighbours, weights


# ---------------------------------------------------------------------------------------
# Section 5: quantile of a subset threshold
# ---------------------------------------------------------------------------------------


def _subset_quantile(sample: np.ndarray, t: float) -> float:
    """``q = (c - 1) / (n - 1)`` with c = #{sample <= t} (semantics §5).

    Reject-all (t = +inf) gives 1; this takes precedence over n = 1, which gives 0.
    """
    if math.isinf(t):
        return 1.0
    n = sample.size
    if n == 1:
        return 0.0
    c = int(np.count_nonzero(sample <= t))
    return (c - 1) / (n - 1)


# ---------------------------------------------------------------------------------------
# Section 6: deployment threshold for a batch
# ---------------------------------------------------------------------------------------


def _lower_weighted_median(q: np.ndarray, w: np.ndarray) -> float:
    """Lower weighted median (semantics §6.1).

    Stable sort by q; the first q whose cumulative weight is >= 0.5 * total - 1e-12.
    A total weight of 0 makes every weight 1. Weights are summed one by one in sorted
    order, and the total is the last cumulative sum.
    """
    order = np.argsort(q, kind="stable")
    q_sorted = q[order]
    w_sorted = w[order]
    if not np.any(w_sorted > 0):
        w_sorted = np.ones_like(w_sorted)
    cumulative = []
    acc = 0.0
    for weight in w_sorted:
        acc += float(weight)
        cumulative.append(acc)
    half = 0.5 * cumulative[-1] - EPS
    for qi, ci in zip(q_sorted, cumulative, strict=True):
        if ci >= half:
            return float(qi)
    raise AssertionError("unreachable")


def _linear_quantile(scores: np.ndarray, q: float) -> float:
    """Empirical quantile by linear interpolation (semantics §6.2).

    With x sorted ascending, h = (N - 1) q, lo = floor(h), the value is
    ``x[lo] + (h - lo) * (x[lo+1] - x[lo])`` (``x[lo]`` when lo is the last index).
    q = 1 means reject-all: the next float64 above the maximum.
    """
    x = np.sort(scores, axis=None)
    if q == 1.0:
        return float(np.nextafter(x[-1], math.inf))
    n = x.size
    h = (n - 1) * q
    lo = math.floor(h)
    if lo + 1 >= n:
        return float(x[lo])
    x_lo, x_hi, f = float(x[lo]), float(x[lo + 1]), h - lo
    t = x_lo + f * (x_hi - x_lo)
    if not math.isfinite(t):
        # x_hi - x_lo overflowed (scores near +-float max): the same point as a convex
        # combination, clamped against rounding.
        t = min(max((1 - f) * x_lo + f * x_hi, x_lo), x_hi)
    return t


def _segments(n_queries: int, segment_size: int | None) -> list[tuple[int, int]]:
    """Consecutive runs of ``segment_size`` queries from the first one; the shorter last
    run is kept. ``None`` means one batch of everything (semantics §6)."""
    if segment_size is None:
        return [(0, n_queries)]
    return [
        (start, min(start + segment_size, n_queries))
        for start in range(0, n_queries, segment_size)
    ]


def _query_quantiles(s_cal64, gt, ignored, s_val64, k: int, tau: float, matching: str):
    """Per deployment query (sections 4 and 5): ``(q, t, w, neighbours)``, its subset
    quantile q_j, subset threshold t_j, weight w_j and calibration neighbours."""
    _, neighbours, weights = _calibration_neighbours(s_cal64, s_val64, k)
    n_val = s_val64.shape[1]
    q_query = np.empty(n_val, dtype=np.float64)
    t_query = np.empty(n_val, dtype=np.float64)
    for j in range(n_val):
        cols = neighbours[j]
        t = _best_threshold(s_cal64[:, cols], gt[:, cols], ignored[:, cols], tau, matching)
        t_query[j] = t
        q_query[j] = _subset_quantile(s_cal64[:, cols], t)
    return q_query, t_query, weights, neighbours


def _batch_threshold(s_batch: np.ndarray, q_batch: np.ndarray, w_batch: np.ndarray):
    """Section 6 for one batch: ``(q, threshold)``, the lower weighted median of the
    batch's q_j and the linear-interpolation quantile at q of its raw scores."""
    q = _lower_weighted_median(q_batch, w_batch)
    return q, _linear_quantile(s_batch, q)


@dataclass
class TransferResult:
    """Output of :func:`quantile_transfer`.

    Per segment: ``thresholds``, ``quantiles`` and ``segments`` ((start, end) over the
    deployment columns, end exclusive). Per deployment query: ``query_quantiles`` (q_j),
    ``query_thresholds`` (the subset threshold t_j, inf for reject-all),
    ``query_weights`` (w_j) and ``neighbours`` (the chosen calibration columns, by
    decreasing correlation). With the margin gate (semantics §13): ``gate`` (m*) and
    ``query_margins``; None without it. In single matching with |DB| >= 2 (semantics
    §14): ``query_confidences`` and ``query_confidences_lower95``; None otherwise. With
    the sequence gate (semantics §15): ``consistency_level`` and
    ``query_consistencies``; None without it.
    """

    thresholds: np.ndarray
    quantiles: np.ndarray
    segments: list[tuple[int, int]]
    query_quantiles: np.ndarray
    query_thresholds: np.ndarray
    query_weights: np.ndarray
    neighbours: np.ndarray
    gate: float | None = None
    query_margins: np.ndarray | None = None
    query_confidences: np.ndarray | None = None
    query_confidences_lower95: np.ndarray | None = None
    consistency_level: float | None = None
    query_consistencies: np.ndarray | None = None


def quantile_transfer(
    s_cal,
    gt_cal,
    s_val=None,
    *,
    gt_soft=None,
    k=10,
    precision=1.0,
    matching="single",
    segment_size=None,
    gate="none",
    query_major=False,
    cal_queries=None,
    cal_fraction=None,
    sequence_window=None,
    sequence_level=None,
    sequence_speed=None,
    sequence_tolerance=None,
    sequence_drift=None,
) -> TransferResult:
    """Quantile transfer from calibration to deployment queries (semantics §4-§6).

    For every deployment query j: its top-k calibration neighbours and weight w_j
    (section 4), the threshold t_j of that calibration subset and its quantile q_j
    within the subset's raw scores (section 5). For every segment of deployment
    queries: the lower weighted median q of its q_j and the linear-interpolation
    quantile at q of the segment's raw scores (section 6).

    ``gt_soft`` is the calibration soft ground truth. ``segment_size=None`` means one
    batch of all deployment queries. ``gate="margin"`` (section 13) also gives m* and
    every deployment query's margin; ``gate="sequence"`` (section 15) the sequence
    gate's level and every deployment query's consistency, the columns of ``s_val`` a
    stream in order; ``"margin,sequence"`` both. The sequence gate's parameters are
    ``sequence_window`` and the others (None: :data:`SEQUENCE_DEFAULTS`).

    With ``cal_queries`` or ``cal_fraction`` and no ``s_val``, ``s_cal`` and its ground
    truth hold every query: the first ``cal_queries`` (or ``floor(cal_fraction * |Q|)``)
    calibrate and the rest are thresholded (semantics §8.1's calibration rule); they
    are one stream, so the consistency of the first thresholded queries reads the
    calibration queries' best matches.
    """
    before = None  # the columns before the deployment queries in the stream
    if cal_queries is not None or cal_fraction is not None:
        s_cal, gt_cal, gt_soft, s_val = _split(s_cal, gt_cal, gt_soft, s_val, cal_queries, cal_fraction, query_major)
        before = s_cal
    elif s_val is None:
        raise ValueError("no deployment queries: give s_val, or cal_queries or cal_fraction to split s_cal")
    k = _check_positive_int("k", k)
    tau = _check_precision(precision)
    matching = _check_matching(matching)
    gate = _check_gate(gate)
    sequence = _sequence_params(
        SEQUENCE_DEFAULTS,
        sequence_window, sequence_level, sequence_speed, sequence_tolerance, sequence_drift,
    )
    s_cal64, gt, ignored = _inputs("s_cal", s_cal, "gt_cal", gt_cal, "gt_soft", gt_soft, query_major)
    s_val64 = _scores("s_val", s_val, query_major)
    if s_val64.shape[0] != s_cal64.shape[0]:
        raise ValueError(
            f"s_val has |DB| = {s_val64.shape[0]} but s_cal has |DB| = {s_cal64.shape[0]}"
        )
    n_val = s_val64.shape[1]
    if segment_size is not None:
        segment_size = _check_positive_int("segment_size", segment_size)
        if segment_size > n_val:
            raise ValueError(
                f"segment_size must be <= the number of deployment queries ({n_val}), "
                f"got {segment_size}"
            )

    q_query, t_query, weights, neighbours = _query_quantiles(
        s_cal64, gt, ignored, s_val64, k, tau, matching
    )

    segments = _segments(n_val, segment_size)
    quantiles = np.empty(len(segments), dtype=np.float64)
    thresholds = np.empty(len(segments), dtype=np.float64)
    for i, (start, end) in enumerate(segments):
        quantiles[i], thresholds[i] = _batch_threshold(
            s_val64[:, start:end], q_query[start:end], weights[start:end]
        )

    gated = "margin" in gate
    if gated:
        _check_gated(matching, s_cal64.shape[0])
    consistencies = None
    if "sequence" in gate:
        _check_sequence_gate(matching, s_cal64.shape[0], sequence)
        stream = s_val64 if before is None else np.hstack([_scores("s_cal", before, query_major), s_val64])
        consistencies = _consistencies(np.argmax(stream, axis=0), sequence)[stream.shape[1] - n_val :]
    confident = matching == "single" and s_cal64.shape[0] >= 2
    query_confidences = query_lower = None
    if confident:
        blocks = _confidence_blocks(s_cal64, gt, ignored)
        pairs = [_confidence_of(blocks, float(r)) for r in _pa_scores(s_val64)]
        query_confidences = np.array([p[0] for p in pairs], dtype=np.float64)
        query_lower = np.array([p[1] for p in pairs], dtype=np.float64)
    return TransferResult(
        thresholds=thresholds,
        quantiles=quantiles,
        segments=segments,
        query_quantiles=q_query,
        query_thresholds=t_query,
        query_weights=weights,
        neighbours=neighbours,
        gate=_gate(s_cal64, gt, ignored, tau) if gated else None,
        query_margins=_margins(s_val64) if gated else None,
        query_confidences=query_confidences,
        query_confidences_lower95=query_lower,
        consistency_level=sequence["level"] if consistencies is not None else None,
        query_consistencies=consistencies,
    )


# ---------------------------------------------------------------------------------------
# Section 13: the margin gate
# ---------------------------------------------------------------------------------------


def _check_gate(gate) -> str:
    """A set of gates: "none", or gate names joined by commas, each once, in any order;
    returned as the library writes it ("margin,sequence")."""
    if not isinstance(gate, str):
        raise TypeError(f"gate must be a string, got {type(gate).__name__}")
    if gate.strip() == "none":
        return "none"
    names = []
    for name in (n.strip() for n in gate.split(",")):
        if name not in ("margin", "sequence"):
            raise ValueError(
                f"gate must be none, or one or more of margin, sequence joined by commas, got {gate!r}: "
                f"unknown gate {name!r}"
            )
        if name in names:
            raise ValueError(f"gate names {name} twice in {gate!r}")
        names.append(name)
    return ",".join(n for n in ("margin", "sequence") if n in names)


def _check_gated(matching: str, n_db: int) -> None:
    """The gate decides a best match: single matching, and at least 2 database images."""
    if matching != "single":
        raise ValueError(
            "gate margin needs single matching: it gates each query's best match, and multi "
            "matching accepts every database entry at or above the threshold"
        )
    if n_db < 2:
        raise ValueError(
            f"gate margin needs at least 2 database images (a best and a second-best score), got {n_db}"
        )


def _margins(s: np.ndarray) -> np.ndarray:
    """(s1 - s2) / sigma of every column of a validated float64 matrix: its largest
    and second-largest score (equal when the largest occurs twice) over the population
    standard deviation of the column; 0 for a constant column."""
    top2 = np.sort(s, axis=0)[-2:]
    sigma = s.std(axis=0)  # population: the mean of squared deviations
    out = np.zeros(s.shape[1])
    spread = sigma > 0
    out[spread] = (top2[1, spread] - top2[0, spread]) / sigma[spread]
    return out


def margins(s, *, query_major=False) -> np.ndarray:
    """The margin of every query column of ``s`` (semantics §13)."""
    s64 = _scores("s", s, query_major)
    _check_gated("single", s64.shape[0])
    return _margins(s64)


def _gate(s: np.ndarray, gt: np.ndarray, ignored: np.ndarray, tau: float) -> float:
    """m*: section 3 on the calibration's single-match decisions, each with its margin
    in place of its score (soft-only best matches left out; the positives are the
    queries with a hard match)."""
    best = np.argmax(s, axis=0)  # the first maximum
    cols = np.arange(s.shape[1])
    kept = ~ignored[best, cols]
    positives = int(gt.any(axis=0).sum())
    return _sweep(_margins(s)[kept], gt[best, cols][kept], positives, tau)


# ---------------------------------------------------------------------------------------
# Section 15: sequence consistency and the sequence gate
# ---------------------------------------------------------------------------------------


def _sequence_params(base: dict, window=None, level=None, speed=None, tolerance=None, drift=None) -> dict:
    """The sequence gate's parameters: ``base`` with each one given replacing its own,
    checked (window >= 1, level in (0, 1], speed finite, tolerance and drift finite and
    >= 0)."""
    p = dict(base)
    for key, value in zip(("window", "level", "speed", "tolerance", "drift"),
                          (window, level, speed, tolerance, drift), strict=True):
        if value is not None:
            p[key] = value
    if isinstance(p["window"], bool) or not isinstance(p["window"], numbers.Integral):
        raise TypeError(f"sequence_window must be an integer, got {type(p['window']).__name__}")
    if p["window"] < 1:
        raise ValueError(f"sequence_window must be >= 1, got {p['window']}")
    p["window"] = int(p["window"])
    for key in ("level", "speed", "tolerance", "drift"):
        if isinstance(p[key], bool) or not isinstance(p[key], numbers.Real):
            raise TypeError(f"sequence_{key} must be a real number, got {type(p[key]).__name__}")
        p[key] = float(p[key])
    if not (0.0 < p["level"] <= 1.0):
        raise ValueError(f"sequence_level must be in (0, 1], got {p['level']}")
    if not math.isfinite(p["speed"]):
        raise ValueError(f"sequence_speed must be finite, got {p['speed']}")
    for key in ("tolerance", "drift"):
        if not (math.isfinite(p[key]) and p[key] >= 0.0):
            raise ValueError(f"sequence_{key} must be finite and >= 0, got {p[key]}")
    return p


def _check_sequence_gate(matching: str, n_db: int, p: dict) -> None:
    """The gate keeps a best match (single matching), on a database its widest
    tolerance, ``a + b W`` rows either side, does not cover."""
    if matching != "single":
        raise ValueError(
            "gate sequence needs single matching: it gates each query's best match, and multi "
            "matching accepts every database entry at or above the threshold"
        )
    _check_database("gate sequence", n_db, p["tolerance"], p["drift"], p["window"])


def _consistencies(best: np.ndarray, p: dict) -> np.ndarray:
    """c_j = n_j / W for every query of a stream of best matches, in order: n_j counts
    the queries j - 1, ..., j - W that are in the stream and agree with j."""
    w = p["window"]
    out = np.empty(len(best))
    for j in range(len(best)):
        n = sum(
            _agrees(int(best[j]), int(best[j - d]), -d, p["speed"], p["tolerance"], p["drift"])
            for d in range(1, w + 1)
            if j - d >= 0
        )
        out[j] = n / w
    return out


def _passes(consistency: float, p: dict) -> bool:
    """Whether a consistency reaches the level, inclusive (section 3's slack)."""
    return consistency >= p["level"] - EPS


def sequence_consistency(s, *, query_major=False, window=None, level=None, speed=None, tolerance=None,
                         drift=None) -> np.ndarray:
    """The consistency of every column of ``s`` (|DB| x |Q|), its columns a stream in
    order (semantics §15)."""
    p = _sequence_params(SEQUENCE_DEFAULTS, window, level, speed, tolerance, drift)
    s64 = _scores("s", s, query_major)
    _check_sequence_gate("single", s64.shape[0], p)
    return _consistencies(np.argmax(s64, axis=0), p)


def _check_sequence_length(length) -> int:
    """A sequence length L: odd, >= 1."""
    if isinstance(length, bool) or not isinstance(length, numbers.Integral):
        raise TypeError(f"sequence must be an integer, got {type(length).__name__}")
    if length < 1 or length % 2 == 0:
        raise ValueError(f"sequence length must be odd and >= 1, got {length}")
    return int(length)


def _causal_match(s: np.ndarray, length: int) -> np.ndarray:
    """The causal sequence matching of a |DB| x |Q| matrix, in its own dtype: entry
    (i, j) the mean of S[i - d, j - d] for d = 0, ..., L - 1 inside the matrix, its terms
    summed in float64 from 0.0, oldest first (d = L - 1 first), as the core sums them."""
    n, m = s.shape
    s64 = s.astype(np.float64)
    acc = np.zeros((n, m))
    count = np.zeros((n, m))
    for d in reversed(range(length)):
        if d < n and d < m:
            acc[d:, d:] += s64[: n - d, : m - d]
            count[d:, d:] += 1
    return (acc / count).astype(s.dtype)


# ---------------------------------------------------------------------------------------
# Section 14: confidence
# ---------------------------------------------------------------------------------------


def _check_confident(matching: str, n_db: int) -> None:
    """A confidence is that of a best match: single matching, at least 2 database images."""
    if matching != "single":
        raise ValueError(
            "confidence needs single matching: it is the probability that a query's best match is "
            "right, and multi matching accepts every database entry at or above the threshold"
        )
    if n_db < 2:
        raise ValueError(
            f"confidence needs at least 2 database images (a best and a second-best score), got {n_db}"
        )


def _pa_scores(s: np.ndarray) -> np.ndarray:
    """The PA-score of every column of a validated float64 matrix: d1 / d2 with
    d = sqrt(max(0, 2 - 2 s)) for its largest and second-largest score (equal when the
    largest occurs twice); 1 when d2 = 0. Each d is computed halved, as
    sqrt(max(0, (1 - s) / 2)), which no finite score overflows; the halves cancel, to
    the bit, wherever 2 - 2 s is finite."""
    top2 = np.sort(s, axis=0)[-2:]
    d2, d1 = np.sqrt(np.maximum(0.0, (1.0 - top2) / 2.0))
    out = np.ones(s.shape[1])
    apart = d2 > 0
    out[apart] = d1[apart] / d2[apart]
    return out


def _confidence_blocks(s: np.ndarray, gt: np.ndarray, ignored: np.ndarray) -> list[tuple[float, int, int]]:
    """The blocks ``(centre, n, x)`` of section 14's fit of the calibration pairs: each
    calibration query's PA-score and whether its best match is a hard positive
    (soft-only best matches left out, as for m*). See :func:`_pooled_blocks`."""
    best = np.argmax(s, axis=0)  # the first maximum
    cols = np.arange(s.shape[1])
    kept = ~ignored[best, cols]
    return _pooled_blocks(_pa_scores(s)[kept], gt[best, cols][kept])


def _pooled_blocks(r: np.ndarray, c: np.ndarray) -> list[tuple[float, int, int]]:
    """The blocks of pairs (PA-score ``r[i]``, 0/1 ``c[i]``), by descending PA-score.

    Written as the spec says it, pass by pass: equal PA-scores become one point; plain
    pool-adjacent-violators on x/n (pool while the block before is strictly greater),
    then adjacent blocks of equal x/n merged; then the same two passes on the Laplace
    value (x + 1) / (n + 2). Values are compared as fractions, exactly. A block's
    centre is the mean PA-score of its pairs.
    """
    order = np.argsort(-r, kind="stable")
    points: list[list] = []  # [sum of PA-scores, n, x]
    for i in order:
        if points and points[-1][3] == r[i]:
            points[-1][0] += float(r[i])
            points[-1][1] += 1
            points[-1][2] += int(c[i])
        else:
            points.append([float(r[i]), 1, int(c[i]), float(r[i])])

    def pool(blocks: list[list], prior: int) -> list[list]:
        def value(b):  # (x + prior) / (n + 2 prior) as a fraction
            return (b[2] + prior, b[1] + 2 * prior)

        def join(a, b):
            a[0] += b[0]
            a[1] += b[1]
            a[2] += b[2]

        out: list[list] = []
        for block in blocks:
            out.append(list(block))
            while len(out) > 1:
                (xa, na), (xb, nb) = value(out[-2]), value(out[-1])
                if xa * nb <= xb * na:
                    break
                join(out[-2], out.pop())
        merged: list[list] = []
        for block in out:
            if merged:
                (xa, na), (xb, nb) = value(merged[-1]), value(block)
                if xa * nb == xb * na:
                    join(merged[-1], block)
                    continue
            merged.append(block)
        return merged

    blocks = pool(pool(points, 0), 1)
    return [(b[0] / b[1], b[1], b[2]) for b in blocks]


def _confidence_of(blocks: list[tuple[float, int, int]], r: float) -> tuple[float, float]:
    """``(confidence, confidence_lower95)`` of a PA-score: the map through each block's
    (x + 1) / (n + 2) at its centre, linear between centres, and on to the first block's
    Clopper-Pearson lower bound at PA-score 1 and the last block's upper bound at 0;
    the lower bound that of the knot at or above r nearest it. NaN without blocks."""
    if not blocks:
        return math.nan, math.nan

    def lower(n, x):
        return precision_lower95(x, n - x)  # x successes of n: Beta(x, n - x + 1); 0 when x = 0

    knots = [(centre, (x + 1) / (n + 2), lower(n, x)) for centre, n, x in blocks]
    if blocks[0][0] < 1.0:
        first = lower(blocks[0][1], blocks[0][2])
        knots.insert(0, (1.0, first, first))
    if blocks[-1][0] > 0.0:
        n, x = blocks[-1][1], blocks[-1][2]
        knots.append((0.0, 1.0 - lower(n, n - x), lower(n, x)))
    if r >= knots[0][0]:
        return knots[0][1], knots[0][2]
    if r <= knots[-1][0]:
        return knots[-1][1], knots[-1][2]
    for (ra, pa, la), (rb, pb, _) in zip(knots, knots[1:], strict=False):
        if ra >= r > rb:
            return pa + (ra - r) / (ra - rb) * (pb - pa), la
    raise AssertionError("a PA-score between the knots")


def confidence_blocks(s_cal, gt_cal, *, gt_soft=None, query_major=False) -> list[tuple[float, int, int]]:
    """The confidence map of a single-matching calibration (semantics §14): its blocks
    ``(centre PA-score, n, x)`` by ascending confidence; empty without a decision."""
    s64, gt, ignored = _inputs("s_cal", s_cal, "gt_cal", gt_cal, "gt_soft", gt_soft, query_major)
    _check_confident("single", s64.shape[0])
    return _confidence_blocks(s64, gt, ignored)


def _auroc(x: np.ndarray, c: np.ndarray) -> float | None:
    """P(x of a right decision > x of a wrong one), ties one half, over every pair;
    None without both kinds."""
    right, wrong = x[c], x[~c]
    if len(right) == 0 or len(wrong) == 0:
        return None
    above = int(np.count_nonzero(right[:, None] > wrong[None, :]))
    ties = int(np.count_nonzero(right[:, None] == wrong[None, :]))
    return (above + ties / 2) / (len(right) * len(wrong))


def _ece(p: np.ndarray, c: np.ndarray) -> float:
    """Expected calibration error over the reliability bins (:func:`_reliability`: 10
    equal-width bins of [0, 1], the last holding 1.0): each bin's |mean p - mean c|
    weighted by its share of the decisions."""
    return float(sum(abs(b["mean_confidence"] - b["hit_rate"]) * b["n"] / len(p) for b in _reliability(p, c)))


def _reliability(p: np.ndarray, c: np.ndarray) -> list[dict]:
    """The reliability bins: of the 10 equal-width bins of [0, 1] (the last holds 1.0),
    those that hold a decision, with their edges, count, mean p and mean c."""
    bins = np.array([min(math.floor(v * 10), 9) for v in p])
    out = []
    for b in range(10):
        here = bins == b
        if here.any():
            out.append({
                "lower": b / 10,
                "upper": (b + 1) / 10,
                "n": int(np.count_nonzero(here)),
                "mean_confidence": float(p[here].mean()),
                "hit_rate": float(c[here].mean()),
            })
    return out


def _confidence_signals(s_cal, gt_cal, ign_cal, s_dep, gt_dep, ign_dep, consistency=None) -> dict:
    """Section 14's evaluation signals over the deployment columns given (soft-only best
    matches left out): AUROC of s1, the margin, the PA-score (lower ranked higher), the
    consistency of section 15 (``consistency``, one per column given; None: no AUROC)
    and the confidence; the confidence's Brier, ECE and reliability bins."""
    blocks = _confidence_blocks(s_cal, gt_cal, ign_cal)
    best = np.argmax(s_dep, axis=0)
    cols = np.arange(s_dep.shape[1])
    kept = ~ign_dep[best, cols]
    c = gt_dep[best, cols][kept]
    s1 = s_dep[best, cols][kept]
    m = _margins(s_dep)[kept]
    r = _pa_scores(s_dep)[kept]
    p = np.array([_confidence_of(blocks, float(v))[0] for v in r], dtype=np.float64)
    calibrated = len(p) > 0 and len(blocks) > 0
    return {
        "signals": {
            "score": {"auroc": _auroc(s1, c)},
            "margin": {"auroc": _auroc(m, c)},
            "pa_score": {"auroc": _auroc(-r, c)},
            "consistency": {"auroc": None if consistency is None else _auroc(consistency[kept], c)},
            "confidence": {
                "auroc": _auroc(p, c) if calibrated else None,
                "brier": float(np.mean((p - c) ** 2)) if calibrated else None,
                "ece": _ece(p, c) if calibrated else None,
                "bins": _reliability(p, c) if calibrated else None,
            },
        }
    }


# ---------------------------------------------------------------------------------------
# Section 16: self-motion labels (with section 15's agreement)
# ---------------------------------------------------------------------------------------

#: The rule a record of self-motion labels names (``{"labels": "self-motion", ...}``).
SELF_MOTION = "self-motion"

#: Section 16's defaults, and section 15's for the agreement.
SELF_MOTION_DEFAULTS = {
    "neighbours": 5,
    "positive_level": 0.7,
    "negative_level": 0.3,
    "sequence_speed": 1.0,
    "sequence_tolerance": 2.0,
    "sequence_drift": 0.2,
}

#: Section 15's slack, which makes the agreement's bound inclusive.
AGREEMENT_SLACK = 1e-9


@dataclass
class SelfMotionLabels:
    """Output of :func:`ground_truth_from_sequence`.

    Per calibration query: ``labels`` (``"positive"``, ``"negative"`` or ``"abstain"``),
    ``agreement`` (f_q) and ``best`` (b_q). ``hard`` and ``soft``: the labels as ground
    truth, in the caller's layout. ``counts``: ``{"positive", "negative", "abstain"}``;
    ``record``: the rule, its parameters and the counts.
    """

    hard: np.ndarray
    soft: np.ndarray
    labels: np.ndarray
    agreement: np.ndarray
    best: np.ndarray
    counts: dict
    record: dict

    def __len__(self) -> int:
        return len(self.labels)


def _agrees(b_q: int, b_other: int, d: int, speed: float, tolerance: float, drift: float) -> bool:
    """Section 15: the best match of the query ``d`` steps from query q lies on q's line."""
    return abs(b_other - (b_q + speed * d)) <= tolerance + drift * abs(d) + AGREEMENT_SLACK


def _check_database(what: str, n_db: int, a: float, b: float, steps: int) -> None:
    """The widest tolerance of a test of agreement over ``steps`` steps, ``a + b steps``
    rows either side, must cover fewer rows than the database has (section 15)."""
    widest = a + b * steps
    covered = 2 * math.floor(widest + AGREEMENT_SLACK) + 1
    if covered >= n_db:
        raise ValueError(
            f"{what} cannot tell a line from chance with |DB| = {n_db}: its widest tolerance, "
            f"+-{_num(widest)} rows {steps} steps away (sequence tolerance {_num(a)} and drift "
            f"{_num(b)}), covers {covered} rows; it needs |DB| >= {covered + 1}"
        )


def _num(x: float) -> str:
    """``x`` as the core prints a float: its shortest form, without a trailing ``.0``."""
    text = repr(float(x))
    return text[:-2] if text.endswith(".0") else text


def _check_real(name: str, value, low: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    if not math.isfinite(v) or (low is not None and v < low):
        rule = "finite" if low is None else f"finite and >= {low:g}"
        raise ValueError(f"{name} must be {rule}, got {value}")
    return v


def ground_truth_from_sequence(
    s_cal,
    *,
    neighbours=None,
    positive_level=None,
    negative_level=None,
    sequence_speed=None,
    sequence_tolerance=None,
    sequence_drift=None,
    query_major=False,
) -> SelfMotionLabels:
    """Section 16: each calibration query's best match labelled from its neighbours on
    the traverse. Each argument ``None`` is its default (``SELF_MOTION_DEFAULTS``)."""
    given = {
        "neighbours": neighbours,
        "positive_level": positive_level,
        "negative_level": negative_level,
        "sequence_speed": sequence_speed,
        "sequence_tolerance": sequence_tolerance,
        "sequence_drift": sequence_drift,
    }
    p = {key: SELF_MOTION_DEFAULTS[key] if value is None else value for key, value in given.items()}
    n = _check_positive_int("neighbours", p["neighbours"])
    positive = _check_real("positive_level", p["positive_level"])
    if not 0.0 < positive <= 1.0:
        raise ValueError(f"positive_level must be in (0, 1], got {p['positive_level']}")
    negative = _check_real("negative_level", p["negative_level"])
    if not 0.0 <= negative < positive:
        raise ValueError(
            f"negative_level must be at least 0 and below the positive level ({positive}), got {negative}"
        )
    v = _check_real("sequence_speed", p["sequence_speed"])
    a = _check_real("sequence_tolerance", p["sequence_tolerance"], 0.0)
    b = _check_real("sequence_drift", p["sequence_drift"], 0.0)
    s = _scores("s_cal", s_cal, query_major)
    n_db, n_cal = s.shape
    if n_cal < n + 1:
        raise ValueError(
            f"s_cal: self-motion labels need at least {n + 1} calibration queries in the order they were "
            f"taken (each best match is judged by its {n} neighbours on each side), got {n_cal}"
        )
    _check_database("s_cal: self-motion labels", n_db, a, b, n)
    best = [int(np.argmax(s[:, q])) for q in range(n_cal)]  # the first maximum
    labels, agreement = [], []
    for q in range(n_cal):
        around = [d for d in range(-n, n + 1) if d != 0 and 0 <= q + d < n_cal]
        agreeing = sum(_agrees(best[q], best[q + d], d, v, a, b) for d in around)
        f = agreeing / len(around)
        agreement.append(f)
        if f >= positive - EPS:
            labels.append("positive")
        elif f <= negative + EPS:
            labels.append("negative")
        else:
            labels.append("abstain")
    counts = {label: labels.count(label) for label in ("positive", "negative", "abstain")}
    if counts["positive"] == 0:
        raise ValueError(
            f"s_cal: self-motion labels found no pseudo-positive: no calibration query's best match agrees "
            f"with {_num(positive * 100)}% of its neighbours ({n_cal} queries: {counts['negative']} negative, "
            f"{counts['abstain']} abstained); the calibration traverse does not follow the database's route "
            "(it is not a sequence, runs backwards: sequence speed -1, or at another spacing: sequence "
            "speed), or its matcher is rarely right"
        )
    hard = np.zeros((n_db, n_cal), dtype=bool)
    soft = np.zeros((n_db, n_cal), dtype=bool)
    for q, label in enumerate(labels):
        hard[best[q], q] = label == "positive"
        soft[best[q], q] = label != "negative"
    record = {
        "labels": SELF_MOTION,
        "neighbours": n,
        "positive_level": positive,
        "negative_level": negative,
        "speed": v,
        "tolerance": a,
        "drift": b,
        "queries": n_cal,
        **counts,
    }
    return SelfMotionLabels(
        hard=hard.T if query_major else hard,
        soft=soft.T if query_major else soft,
        labels=np.array(labels),
        agreement=np.array(agreement, dtype=np.float64),
        best=np.array(best, dtype=np.int64),
        counts=counts,
        record=record,
    )


# ---------------------------------------------------------------------------------------
# Section 7: baselines
# ---------------------------------------------------------------------------------------


def _median(values: np.ndarray) -> float:
    """Median; the mean of the two middle values, (a + b) / 2, when the count is even."""
    x = np.sort(values, axis=None)
    n = x.size
    if n % 2 == 1:
        return float(x[n // 2])
    return float((x[n // 2 - 1] + x[n // 2]) / 2.0)


def _schubert(s: np.ndarray) -> float:
    mu = _median(s)
    sigma = _median(np.abs(s - mu)) / 0.675
    if sigma == 0.0:
        return math.inf  # a degenerate fit: VPR_Tutorial's NaN threshold accepts nothing
    return mu + sigma * SCHUBERT_Z


def schubert_threshold(s) -> float:
    """Schubert et al.'s automatic threshold over all raw scores of ``s`` (semantics §7).

    mu = median, sigma = median(|S - mu|) / 0.675, t = mu + sigma * 4.753424308817087;
    when sigma = 0 (half or more of the scores equal) the threshold is reject-all,
    ``math.inf``. The orientation of ``s`` does not matter.
    """
    return _schubert(_scores("s", s, False))


# ---------------------------------------------------------------------------------------
# Section 8: evaluation protocol
# ---------------------------------------------------------------------------------------


def _calibration_size(n_q, cal_fraction, cal_queries) -> int:
    """The first queries that calibrate (semantics §8.1): ``floor(cal_fraction * n_q)``
    or ``cal_queries``, between 1 and ``n_q - 1``."""
    if cal_queries is None:
        n_cal = math.floor(_check_fraction("cal_fraction", cal_fraction) * n_q)
    else:
        n_cal = _check_positive_int("cal_queries", cal_queries)
    if not (1 <= n_cal < n_q):
        raise ValueError(
            f"the calibration set must have between 1 and {n_q - 1} of the {n_q} queries, "
            f"got {n_cal}"
        )
    return n_cal


def _split(s, gt, gt_soft, s_val, cal_queries, cal_fraction, query_major):
    """One matrix of every query split: ``(s_cal, gt_cal, gt_soft_cal, s_val)`` in the
    caller's orientation."""
    if cal_queries is not None and cal_fraction is not None:
        raise ValueError("give cal_queries or cal_fraction, not both")
    if s_val is not None:
        raise ValueError("s_val and cal_queries/cal_fraction exclude each other: give s_val, or split s_cal")
    s = np.asarray(s)
    axis = 0 if query_major else 1
    n_cal = _calibration_size(s.shape[axis], cal_fraction, cal_queries)
    labels = [np.asarray(gt), None if gt_soft is None else np.asarray(gt_soft)]
    for name, g in zip(("gt_cal", "gt_soft"), labels, strict=True):
        if g is not None and g.shape != s.shape:
            raise ValueError(
                f"{name}: ground truth shape {g.shape[0]}x{g.shape[1]} does not match similarity shape "
                f"{s.shape[0]}x{s.shape[1]}; the ground truth of a split labels every query, of which "
                f"the first {n_cal} calibrate"
            )
    first = (lambda a: a[:n_cal]) if query_major else (lambda a: a[:, :n_cal])
    rest = s[n_cal:] if query_major else s[:, n_cal:]
    return first(s), first(labels[0]), None if labels[1] is None else first(labels[1]), rest


def _check_fraction(name: str, value) -> float:
    if not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    if not (0.0 < v < 1.0):
        raise ValueError(f"{name} must be in (0, 1), got {value}")
    return v


def _layout(n_db, n_q, cal_fraction, cal_queries, deploy_fraction, segment_fraction, segment_size) -> dict:
    """Where the protocol puts the queries, with the parameters as asked for: the
    ``params`` of the result but ``k``, ``precision`` and ``matching``."""
    if cal_queries is None:
        calibration = {"fraction": _check_fraction("cal_fraction", cal_fraction)}
        n_cal = math.floor(calibration["fraction"] * n_q)
    else:
        calibration = {"count": _check_positive_int("cal_queries", cal_queries)}
        n_cal = calibration["count"]
    if not (1 <= n_cal < n_q):
        raise ValueError(
            f"the calibration set must have between 1 and {n_q - 1} of the {n_q} queries, "
            f"got {n_cal}"
        )
    if deploy_fraction is None:
        n_dep = n_q - n_cal
    else:
        deploy_fraction = _check_fraction("deploy_fraction", deploy_fraction)
        n_dep = math.floor(deploy_fraction * n_q)
        if n_dep < 1:
            raise ValueError(f"the deployment set has no query: floor({deploy_fraction} * {n_q}) = 0")
        if n_cal + n_dep > n_q:
            raise ValueError(
                f"the calibration set ({n_cal} queries) and the deployment set ({n_dep} queries) "
                f"overlap: together they exceed the {n_q} queries"
            )
    if segment_size is None:
        segment = {"fraction": _check_fraction("segment_fraction", segment_fraction)}
        size = math.ceil(segment["fraction"] * n_q)
    else:
        segment = {"count": _check_positive_int("segment_size", segment_size)}
        size = segment["count"]
    if size > n_dep:
        raise ValueError(
            f"segment size {size} is larger than the {n_dep} deployment queries"
        )
    return {
        "calibration": calibration,
        "deploy_fraction": deploy_fraction,
        "segment": segment,
        "database_size": n_db,
        "queries": n_q,
        "calibration_queries": n_cal,
        "deployment_start": n_q - n_dep,
        "deployment_queries": n_dep,
        "segment_size": size,
        "segments": n_dep // size,
    }


def _recall_at_1(s: np.ndarray, gt: np.ndarray) -> float | None:
    """R@1: the queries whose best match (first maximum) is a hard match, over the
    queries with at least one hard match; None when no query has one."""
    with_match = gt.any(axis=0)
    if not with_match.any():
        return None
    hits = gt[np.argmax(s, axis=0), np.arange(s.shape[1])]
    return int(np.count_nonzero(hits)) / int(np.count_nonzero(with_match))


def _counts_with_bound(c: dict, prefix: str = "") -> dict:
    """Counts and their figures with the precision's lower bound, keys prefixed."""
    c = {**c, "precision_lower95": precision_lower95(c["tp"], c["fp"])}
    return {prefix + key: value for key, value in c.items()}


def _run(s, gt, ignored, methods, k, tau, matching, layout, sequence=None) -> dict:
    """One run of the protocol on validated |DB| x |Q| input: params, R@1, methods.
    ``sequence``: the sequence gate's parameters (None: the defaults)."""
    sequence = dict(SEQUENCE_DEFAULTS) if sequence is None else sequence
    n_cal, dep_start, size = layout["calibration_queries"], layout["deployment_start"], layout["segment_size"]
    segments = _segments(layout["segments"] * size, size)  # full segments only

    s_cal, gt_cal, ign_cal = s[:, :n_cal], gt[:, :n_cal], ignored[:, :n_cal]
    s_dep, gt_dep, ign_dep = s[:, dep_start:], gt[:, dep_start:], ignored[:, dep_start:]

    # Each segment's candidates, counted against its own ground truth, and its oracle.
    candidates = [
        _candidates(s_dep[:, a:b], gt_dep[:, a:b], ign_dep[:, a:b], matching)
        for a, b in segments
    ]
    oracle = [_sweep(*c, tau) for c in candidates]

    thresholds = {}
    per_query = {}  # methods that decide each query at its own threshold: theta_j
    n_full = layout["segments"] * size
    margin_gated = [name for name in methods if name in MARGIN_GATED]
    sequence_gated = [name for name in methods if name in SEQUENCE_GATED]
    if margin_gated:
        _check_gated(matching, s.shape[0])
    if sequence_gated:
        _check_sequence_gate(matching, s.shape[0], sequence)
    m_star = None
    if margin_gated:
        m_star = _gate(s_cal, gt_cal, ign_cal, tau)
        margin_passes = _margins(s_dep) >= m_star  # per deployment query: the gate's verdict
    # Section 15: the whole traverse is one stream, in column order.
    consistency = None
    try:
        if matching == "single":
            _check_sequence_gate("single", s.shape[0], sequence)
            consistency = _consistencies(np.argmax(s, axis=0), sequence)[dep_start : dep_start + n_full]
    except ValueError:
        pass  # a database too small for the gate: no consistency (nor sequence method)
    for name in methods:
        if name == "quantile-transfer-online":
            # Section 11: the window (m = segment size) runs over the deployment queries
            # from the first one, not reset at segment boundaries.
            online = Online(
                Calibration(s_cal, gt_cal, gt_soft=gt_cal | ign_cal, matching=matching),
                k=k,
                precision=tau,
                window=size,
            )
            theta = online.push_many(s_dep[:, : segments[-1][1]]).thresholds
            per_query[name] = theta
            thresholds[name] = [float(theta[b - 1]) for _, b in segments]  # its last query's
        elif name in ("quantile-transfer", "quantile-transfer-margin", "quantile-transfer-sequence",
                      "quantile-transfer-margin-sequence"):
            transfer = quantile_transfer(
                s_cal,
                gt_cal,
                s_dep[:, : segments[-1][1]],
                gt_soft=gt_cal | ign_cal,
                k=k,
                precision=tau,
                matching=matching,
                segment_size=size,
            )
            thresholds[name] = [float(t) for t in transfer.thresholds]
        elif name in ("margin", "sequence"):  # a gate alone
            thresholds[name] = [-math.inf] * len(segments)
        elif name == "schubert":
            thresholds[name] = [_schubert(s_dep[:, a:b]) for a, b in segments]
        elif name == "schubert-calibrated":
            thresholds[name] = [_schubert(s_cal)] * len(segments)
        elif name == "calibration-threshold":
            t = _best_threshold(s_cal, gt_cal, ign_cal, tau, matching)
            thresholds[name] = [t] * len(segments)
        else:  # oracle
            thresholds[name] = list(oracle)

    report = {}
    for name in methods:
        rows = []
        for (a, b), cand, t, t_oracle in zip(segments, candidates, thresholds[name], oracle, strict=True):
            if name in per_query or name in GATED:
                # The segment's counts are the sums of its queries' counts: each at its
                # own threshold, or at the segment's when it passes every gate of the
                # method (a query that fails a gate accepts nothing).
                tp = fp = positives = 0
                for j in range(a, b):
                    if name in GATED:
                        passes = (name not in MARGIN_GATED or margin_passes[j]) and (
                            name not in SEQUENCE_GATED or _passes(consistency[j], sequence)
                        )
                        t_j = t if passes else math.inf
                    else:
                        t_j = float(per_query[name][j])
                    cj = _count_at(
                        *_candidates(s_dep[:, j : j + 1], gt_dep[:, j : j + 1], ign_dep[:, j : j + 1], matching),
                        t_j,
                    )
                    tp, fp, positives = tp + cj["tp"], fp + cj["fp"], positives + cj["positives"]
                c = _counts_of(tp, fp, positives)
            else:
                c = _count_at(*cand, t)
            row = {"start": a, "end": b, "threshold": t, "oracle_threshold": t_oracle}
            if name in MARGIN_GATED:
                row["gate"] = m_star
            if name in SEQUENCE_GATED:
                row["consistency_level"] = sequence["level"]
            rows.append({**row, **_counts_with_bound(c), "meets": _meets(c, tau)})
        counted = [r for r in rows if r["positives"] > 0]
        if counted:
            pct_segs = 100.0 * sum(r["meets"] for r in counted) / len(counted)
            avg_recall = sum(r["recall"] if r["meets"] else 0.0 for r in counted) / len(counted)
        else:
            pct_segs = avg_recall = None
        finite = [
            (r["threshold"] - r["oracle_threshold"]) ** 2
            for r in counted
            if math.isfinite(r["threshold"]) and math.isfinite(r["oracle_threshold"])
        ]
        # Pooled over every full segment, skipped ones included.
        pooled = _counts_of(*(sum(r[key] for r in rows) for key in ("tp", "fp", "positives")))
        report[name] = {
            "pct_segs": pct_segs,
            "avg_recall": avg_recall,
            "segments_counted": len(counted),
            "segments_skipped": len(rows) - len(counted),
            "threshold_mse": sum(finite) / len(finite) if finite else None,
            **_counts_with_bound(pooled, "pooled_"),
            "segments": rows,
        }
    end = dep_start + layout["segments"] * size
    params = {
        **{key: layout[key] for key in ("calibration", "deploy_fraction", "segment")},
        "k": k,
        "precision": tau,
        "matching": matching,
        "sequence_gate": sequence,
        **{key: value for key, value in layout.items() if key not in ("calibration", "deploy_fraction", "segment")},
    }
    out = {
        "params": params,
        "recall_at_1": _recall_at_1(s[:, dep_start:end], gt[:, dep_start:end]),
        "methods": report,
    }
    if matching == "single" and s.shape[0] >= 2:  # section 14's signals
        out["confidence"] = _confidence_signals(
            s_cal, gt_cal, ign_cal, s[:, dep_start:end], gt[:, dep_start:end], ignored[:, dep_start:end],
            consistency,
        )
    return out


def _check_methods(methods, matching: str) -> list:
    """The methods asked for, once each; None is every method that applies to
    ``matching`` (the gated ones need single matching)."""
    if methods is None:
        methods = [m for m in METHODS if matching == "single" or m not in GATED]
    methods = list(methods)
    for name in methods:
        if name not in METHODS:
            raise ValueError(f"unknown method {name!r}; expected one of {', '.join(METHODS)}")
    return list(dict.fromkeys(methods))  # a repeated method once


def _applying(methods: list, given, n_db: int, sequence: dict) -> list:
    """``methods`` as :func:`_check_methods` gave them; when none was ``given`` (every
    method that applies), less the sequence gate's on a database its widest tolerance
    covers."""
    if given is not None:
        return methods
    try:
        _check_sequence_gate("single", n_db, sequence)
    except ValueError:
        return [m for m in methods if m not in SEQUENCE_GATED]
    return methods


#: The protocol's defaults (the paper's): k, precision, calibration and segment fractions.
PROTOCOL_DEFAULTS = (10, 1.0, 0.1, 0.01)


def _protocol_defaults(*given):
    """Each of ``k``, ``precision``, ``cal_fraction``, ``segment_fraction``, or its
    default when None."""
    return tuple(d if v is None else v for v, d in zip(given, PROTOCOL_DEFAULTS, strict=True))


#: Semantics §1: the share of queries without a positive from which, every database
#: image having one, ground truth contradicts the layout read (and the reverse).
CONTRADICTION_SHARE = 0.05


def orientation(shape: tuple[int, int], gt: np.ndarray | None, query_major: bool) -> dict:
    """What was assumed of a similarity matrix's orientation (``shape`` is its |DB| x |Q|
    view) and, with hard ground truth ``gt`` given in the matrix's orientation, what its
    positives say: ``"contradicts"`` when every database image has a positive and at
    least 5% of the queries (and one) have none, ``"consistent"`` the other way round,
    else ``"cannot-tell"``; and ``layout``, whether the layout read was confirmed by the
    ground truth, assumed or contradicted, in words."""
    out = {"db": shape[0], "queries": shape[1], "query_major": bool(query_major)}
    if gt is None or gt.shape[0] != shape[0]:
        out["layout"] = "assumed (no ground truth was read in the matrix's layout to tell)"
        return out
    n_db, n_q = gt.shape
    q_without = int((~gt.any(axis=0)).sum())
    db_without = int((~gt.any(axis=1)).sum())

    def many(without: int, of: int) -> bool:
        return without >= 1 and without >= CONTRADICTION_SHARE * of

    if db_without == 0 and many(q_without, n_q):
        verdict = "contradicts"
    elif q_without == 0 and many(db_without, n_db):
        verdict = "consistent"
    else:
        verdict = "cannot-tell"
    if verdict == "consistent":
        out["layout"] = (f"confirmed by the ground truth (every query has a positive; database images without "
                         f"one: {db_without} of {n_db})")
    elif verdict == "contradicts":
        out["layout"] = (f"contradicted by the ground truth (queries without a positive: {q_without} of {n_q}, "
                         "while every database image has one)")
    elif q_without == db_without == 0:
        out["layout"] = "assumed (the ground truth cannot tell: every query and every database image has a positive)"
    else:
        out["layout"] = (f"assumed (the ground truth cannot tell: queries without a positive: {q_without} of {n_q}; "
                         f"database images without one: {db_without} of {n_db})")
    out["evidence"] = {"labelled_queries": n_q, "queries_without_positive": q_without,
                       "db_without_positive": db_without, "verdict": verdict}
    return out


def evaluate(
    s,
    gt,
    *,
    gt_soft=None,
    methods=None,
    k=None,
    precision=None,
    matching="single",
    cal_fraction=None,
    cal_queries=None,
    segment_fraction=None,
    segment_size=None,
    deploy_fraction=None,
    query_major=False,
    sequence_window=None,
    sequence_level=None,
    sequence_speed=None,
    sequence_tolerance=None,
    sequence_drift=None,
) -> dict:
    """The evaluation protocol of the paper's Table I (semantics §7 and §8).

    The first ``cal_queries`` (default ``floor(cal_fraction * |Q|)``) columns calibrate;
    the deployment set is every later column, or with ``deploy_fraction`` the last
    ``floor(deploy_fraction * |Q|)`` columns (the paper's Fig. 5 protocol: the
    deployment set stays fixed while the calibration size varies; columns between the
    two sets are unused, and the two may not overlap). The deployment set is cut into
    ``floor(|Qdeploy| / size)`` full segments of ``segment_size`` (default
    ``ceil(segment_fraction * |Q|)``) queries, the remainder dropped. Every method gives
    each segment a threshold, and the segment's decisions are counted against its own
    ground truth. For quantile-transfer each segment is its own batch.

    Returns the keys of ``qtvpr-cli evaluate --format json``: ``dataset`` (None here),
    ``orientation`` (:func:`orientation`), ``params`` (the parameters as asked for and the split: ``database_size``,
    ``queries``, ``calibration_queries``, ``deployment_start``, ``deployment_queries``,
    ``segment_size``, ``segments``), ``recall_at_1`` of the full segments' queries, and
    ``methods``: ``{name: {"pct_segs", "avg_recall", "segments_counted",
    "segments_skipped", "threshold_mse", "pooled_tp", "pooled_fp", "pooled_accepted",
    "pooled_positives", "pooled_precision", "pooled_recall", "pooled_precision_lower95", "segments":
    [...]}}``; each segment reports ``start``, ``end`` (indices into the deployment set,
    end exclusive: deployment query i is column ``|Q| - |Qdeploy| + i`` of ``s``),
    ``threshold``, ``oracle_threshold``, ``tp``, ``fp``, ``accepted``, ``positives``, ``precision``,
    ``recall``, ``precision_lower95`` (:func:`precision_lower95`) and ``meets``.
    Segments without positives are skipped in the summary figures, which are None when
    no segment is counted; ``threshold_mse`` is None when no counted segment has both
    thresholds finite. The pooled counts are summed over every full segment; a precision
    (a segment's or the pooled one) is None when nothing was accepted.

    The sequence methods (section 15) gate on each deployment query's consistency over
    the whole matrix, one traverse in column order, with the sequence gate of
    ``sequence_window`` and the others (None: :data:`SEQUENCE_DEFAULTS`); their segments
    report its ``consistency_level``, and the consistency is a signal of section 14's.
    """
    k, precision, cal_fraction, segment_fraction = _protocol_defaults(k, precision, cal_fraction, segment_fraction)
    k = _check_positive_int("k", k)
    tau = _check_precision(precision)
    matching = _check_matching(matching)
    sequence = _sequence_params(SEQUENCE_DEFAULTS, sequence_window, sequence_level, sequence_speed,
                                sequence_tolerance, sequence_drift)
    given, methods = methods, _check_methods(methods, matching)
    s, gt, ignored = _inputs("s", s, "gt", gt, "gt_soft", gt_soft, query_major)
    methods = _applying(methods, given, s.shape[0], sequence)
    layout = _layout(*s.shape, cal_fraction, cal_queries, deploy_fraction, segment_fraction, segment_size)
    return {"dataset": None, "orientation": orientation(s.shape, gt, query_major),
            **_run(s, gt, ignored, methods, k, tau, matching, layout, sequence)}


#: The deployment set of an ablation without ``deploy_fraction``: the last half.
ABLATION_DEPLOY_FRACTION = 0.5


def _values(value) -> list:
    """A list of settings: ``value`` itself if it is a list or tuple, else ``[value]``."""
    return list(value) if isinstance(value, (list, tuple)) else [value]


def ablation(
    s,
    gt,
    *,
    gt_soft=None,
    methods=None,
    k=None,
    precision=None,
    matching="single",
    cal_fraction=None,
    cal_queries=None,
    segment_fraction=None,
    segment_size=None,
    deploy_fraction=None,
    query_major=False,
    sequence_window=None,
    sequence_level=None,
    sequence_speed=None,
    sequence_tolerance=None,
    sequence_drift=None,
) -> dict:
    """The protocol once per setting of ``k`` and of the calibration size (Fig. 5).

    ``k``, ``cal_fraction`` and ``cal_queries`` may be lists; every combination runs,
    calibration sizes in the outer loop and ``k`` in the inner one, each as
    :func:`evaluate` would with that setting, except that every run deploys on the
    last ``floor(deploy_fraction * |Q|)`` queries, ``deploy_fraction`` defaulting to
    0.5. Every setting is checked before the first runs. Returns ``{"dataset": None,
    "orientation": ..., "ablation": [run, ...]}``, each run with the ``params``, ``recall_at_1`` and
    ``methods`` of :func:`evaluate`.
    """
    k, precision, cal_fraction, segment_fraction = _protocol_defaults(k, precision, cal_fraction, segment_fraction)
    given, methods = methods, _check_methods(methods, _check_matching(matching))
    ks = [_check_positive_int("k", v) for v in _values(k)]
    if cal_queries is None:
        settings = [(f, None) for f in _values(cal_fraction)]
        name = "cal_fraction"
    else:
        settings = [(None, _check_positive_int("cal_queries", n)) for n in _values(cal_queries)]
        name = "cal_queries"
    if not ks or not settings:
        raise ValueError(f"{'k' if not ks else name} must have at least one value")
    tau = _check_precision(precision)
    matching = _check_matching(matching)
    sequence = _sequence_params(SEQUENCE_DEFAULTS, sequence_window, sequence_level, sequence_speed,
                                sequence_tolerance, sequence_drift)
    s, gt, ignored = _inputs("s", s, "gt", gt, "gt_soft", gt_soft, query_major)
    methods = _applying(methods, given, s.shape[0], sequence)
    if deploy_fraction is None:
        deploy_fraction = ABLATION_DEPLOY_FRACTION
    layouts = [
        _layout(*s.shape, f, n, deploy_fraction, segment_fraction, segment_size) for f, n in settings
    ]
    runs = [_run(s, gt, ignored, methods, kk, tau, matching, layout, sequence) for layout in layouts for kk in ks]
    return {"dataset": None, "orientation": orientation(s.shape, gt, query_major), "ablation": runs}


# ---------------------------------------------------------------------------------------
# For comparison: VPR-Bench's recall at 100% precision (not a section of the semantics)
# ---------------------------------------------------------------------------------------


def vprbench_recall_at_100p(s: np.ndarray, gt: np.ndarray) -> float:
    """VPR-Bench's recall at 100% precision of ``s`` (|DB| x |Q|) under ``gt``.

    ``matches[j]`` is whether query j's best match (``argmax``, the first on ties) is
    correct, ``scores[j]`` its score. Over the distinct thresholds (accept
    ``score >= t``), precision = correct accepted / accepted and recall = correct
    accepted / all correct matches; the result is the largest recall at precision 1,
    or 0 if no threshold has precision 1.
    """
    columns = np.arange(s.shape[1])
    best = np.argmax(s, axis=0)
    scores, matches = s[best, columns].astype(np.float64), gt[best, columns].astype(bool)
    if not matches.any():
        return float("nan")  # VPR-Bench divides by zero
    order = np.argsort(-scores, kind="stable")
    scores, matches = scores[order], matches[order]
    tp, fp = np.cumsum(matches), np.cumsum(~matches)
    last = np.append(scores[1:] != scores[:-1], True)  # equal scores are accepted together
    exact = last & (fp == 0)
    return float(tp[exact].max() / matches.sum()) if exact.any() else 0.0


# ---------------------------------------------------------------------------------------
# Section 11: online thresholds, a causal window
# ---------------------------------------------------------------------------------------


@dataclass
class OnlineDecision:
    """One deployment query decided by :class:`Online` (semantics §11).

    ``query`` is its index in arrival order (from 0); ``query_quantile`` and ``weight``
    its own q_j and w_j (sections 4 and 5); ``quantile`` and ``threshold`` its window's
    weighted-median quantile and threshold theta_j (section 6 on the window; 1 and the
    next float above the window's maximum during warm-up). In both matching modes
    (the decision record of §11) ``best`` is the first maximum of the column and
    ``score`` its score; ``accepted`` is the number of accepted entries (single: 1 when
    ``score >= threshold``, else 0; multi: the scores ``>= threshold``) and ``accept``
    is ``accepted > 0``. ``accepted_indices`` are the accepted database indices,
    ascending. With the margin gate (section 13) ``margin`` is the column's margin and
    ``gate`` m*, and single matching accepts only when ``margin >= gate`` too; both are
    None without it. With the sequence gate (section 15) ``consistency`` is the query's
    consistency with the previous queries of the stream and ``consistency_level`` the
    gate's level, and single matching accepts only when the consistency reaches it too;
    both None without it. ``confidence`` and ``confidence_lower95`` (section 14) are the
    calibration's hit rate at the column's PA-score and its lower bound, whatever the
    gate; NaN in multi matching.
    """

    query: int
    query_quantile: float
    weight: float
    quantile: float
    threshold: float
    best: int
    score: float
    accepted: int
    accept: bool
    accepted_indices: np.ndarray
    margin: float | None = None
    gate: float | None = None
    consistency: float | None = None
    consistency_level: float | None = None
    confidence: float = math.nan
    confidence_lower95: float = math.nan


@dataclass
class OnlineDecisions:
    """The decisions of :meth:`Online.push_many`, one entry per pushed query: the
    fields of :class:`OnlineDecision` as arrays (``queries``, ``query_quantiles``,
    ``weights``, ``quantiles``, ``thresholds``, ``best``, ``score``, ``accepted``,
    ``accept``, ``confidences``, ``confidences_lower95``, with the margin gate
    ``margins`` and ``gates``, with the sequence gate ``consistencies`` and
    ``consistency_levels``), in both matching modes."""

    queries: np.ndarray
    query_quantiles: np.ndarray
    weights: np.ndarray
    quantiles: np.ndarray
    thresholds: np.ndarray
    best: np.ndarray
    score: np.ndarray
    accepted: np.ndarray
    accept: np.ndarray
    confidences: np.ndarray
    confidences_lower95: np.ndarray
    margins: np.ndarray | None = None
    gates: np.ndarray | None = None
    consistencies: np.ndarray | None = None
    consistency_levels: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.queries)


def _non_finite(name: str, a: np.ndarray, where) -> None:
    """Raise the section-10 error for the first non-finite entry of the 1-D ``a``;
    ``where(i)`` says where entry i is."""
    bad = np.flatnonzero(~np.isfinite(a))
    if len(bad) > 0:
        i = int(bad[0])
        what = "NaN" if np.isnan(a[i]) else "an infinite value"
        raise ValueError(f"{name} contains {what} at {where(i)}")


def _check_float_dtype(name: str, a: np.ndarray) -> None:
    if a.dtype.kind != "f" or a.dtype.itemsize not in (4, 8):
        raise TypeError(f"{name} must be float32 or float64, got dtype {a.dtype}")


class Online:
    """Online thresholds for queries that arrive one at a time (semantics §11).

    ``Online(calibration, *, k=None, precision=None, window=None, min_window=1)``: each
    of ``k``, ``precision`` and ``window`` left as None takes the calibration's default
    (:attr:`Calibration.defaults`, from its file); a window is required from one or the
    other. Query j is thresholded on the batch of its last ``min(window, j + 1)``
    queries (itself included) exactly as section 6 thresholds a batch, and decided at
    that threshold (section 2). Queries with ``j + 1 < min_window`` are reject-all
    (warm-up).

    ``gate`` is "none", "margin", "sequence" or "margin,sequence" (None: the
    calibration's), with the sequence gate's ``sequence_window`` and others (None: the
    calibration's). A calibration of sequence length L (``Calibration(...,
    sequence=L)``) decides each query on its causal sequence-matched column: the mean of
    the raw columns' diagonals over the last L pushed queries (section 15). ``sequence``
    checks that length (None: whatever it is).

    Written the plain way: each query's q_j and w_j are computed from its own column and
    the calibration; the window keeps its raw columns and their q, w; the stream keeps
    its best matches and, for L > 1, its raw columns.
    """

    def __init__(self, calibration, *, k=None, precision=None, window=None, min_window=1, gate=None,
                 sequence_window=None, sequence_level=None, sequence_speed=None, sequence_tolerance=None,
                 sequence_drift=None, sequence=None):
        if not isinstance(calibration, Calibration):
            raise TypeError(
                f"calibration must be a qtvpr.reference.Calibration, got {type(calibration).__name__}"
            )
        defaults = calibration.defaults
        self.calibration = calibration
        self.k = _check_positive_int("k", defaults["k"] if k is None else k)
        self.precision = _check_precision(defaults["precision"] if precision is None else precision)
        if window is None:
            window = defaults["window"]
            if window is None:
                raise ValueError("window is not given and the calibration sets none")
        self.window = _check_positive_int("window", window)
        self.min_window = operator.index(min_window)
        if not (1 <= self.min_window <= self.window):
            raise ValueError(
                f"min_window must be between 1 and the window ({self.window}), got {self.min_window}"
            )
        if sequence is not None and _check_sequence_length(sequence) != calibration.sequence:
            raise ValueError(
                f"sequence {sequence} is not the calibration's sequence length {calibration.sequence}: the "
                "length belongs to the calibration, whose scores were matched over it (calibrate with that "
                "length instead)"
            )
        self.gate = _check_gate(defaults["gate"] if gate is None else gate)
        self.sequence_gate = _sequence_params(defaults["sequence_gate"], sequence_window, sequence_level,
                                              sequence_speed, sequence_tolerance, sequence_drift)
        self._m_star = None
        if "margin" in self.gate:
            _check_gated(calibration.matching, calibration.db_size)
        if "sequence" in self.gate:
            _check_sequence_gate(calibration.matching, calibration.db_size, self.sequence_gate)
        if "margin" in self.gate:
            self._m_star = _gate(calibration._s64, calibration._gt, calibration._ignored, self.precision)
        self._level = self.sequence_gate["level"] if "sequence" in self.gate else None
        self._best: list[int] = []  # the stream's best matches, in order
        self._raw: list[np.ndarray] = []  # the stream's last L - 1 raw columns, in their dtype
        self._blocks = None  # the confidence map, in single matching with |DB| >= 2
        if calibration.matching == "single" and calibration.db_size >= 2:
            self._blocks = _confidence_blocks(calibration._s64, calibration._gt, calibration._ignored)
        self._columns: list[np.ndarray] = []  # the window's raw columns (float64)
        self._q: list[float] = []
        self._w: list[float] = []
        self.pushed = 0  # queries decided so far
        self.threshold: float | None = None  # theta of the last decision

    def _decide(self, raw: np.ndarray) -> OnlineDecision:
        """Decide one validated column of |DB| scores (its own dtype): on its causal
        sequence-matched column with a sequence length L > 1."""
        cal = self.calibration
        column = raw.astype(np.float64)
        if cal.sequence > 1:
            # Its last min(L, j + 1) raw columns, matched in float64, the result in the
            # pushed column's own type (as a matrix of that type is).
            stream = np.stack([*self._raw, raw], axis=1).astype(np.float64)
            column = _causal_match(stream, cal.sequence)[:, -1].astype(raw.dtype).astype(np.float64)
            self._raw = [*self._raw, raw][-(cal.sequence - 1) :]
        q_j, _, w_j, _ = _query_quantiles(
            cal._s64, cal._gt, cal._ignored, column[:, None], self.k, self.precision, cal.matching
        )
        self._columns.append(column)
        self._q.append(float(q_j[0]))
        self._w.append(float(w_j[0]))
        if len(self._columns) > self.window:  # keep the last min(m, j + 1) queries
            del self._columns[0], self._q[0], self._w[0]
        j = self.pushed
        batch = np.stack(self._columns, axis=1)
        if j + 1 < self.min_window:  # warm-up: reject-all, as section 6 writes it
            quantile = 1.0
            threshold = _linear_quantile(batch, quantile)
        else:
            quantile, threshold = _batch_threshold(batch, np.array(self._q), np.array(self._w))
        self.pushed += 1
        self.threshold = threshold
        b = int(np.argmax(column))  # first maximum on ties: the matcher's choice, both modes
        margin = None if self._m_star is None else float(_margins(column[:, None])[0])
        consistency = None
        if self._level is not None:
            consistency = float(_consistencies(np.array([*self._best, b]), self.sequence_gate)[-1])
        self._best.append(b)
        confidence = lower = math.nan
        if self._blocks is not None:
            confidence, lower = _confidence_of(self._blocks, float(_pa_scores(column[:, None])[0]))
        if cal.matching == "single":
            passes = (margin is None or margin >= self._m_star) and (
                consistency is None or _passes(consistency, self.sequence_gate)
            )
            indices = np.array([b] if column[b] >= threshold and passes else [], dtype=np.int64)
        else:
            indices = np.flatnonzero(column >= threshold).astype(np.int64)
        return OnlineDecision(
            query=j, query_quantile=self._q[-1], weight=self._w[-1], quantile=quantile,
            threshold=threshold, best=b, score=float(column[b]), accepted=len(indices),
            accept=len(indices) > 0, accepted_indices=indices, margin=margin, gate=self._m_star,
            consistency=consistency, consistency_level=self._level,
            confidence=confidence, confidence_lower95=lower,
        )

    def push(self, column) -> OnlineDecision:
        """Decide one deployment query from its |DB| scores: a 1-D array, or a |DB| x 1
        matrix; float32 or float64. Bad input raises and leaves the state unchanged."""
        a = np.asarray(column)
        _check_float_dtype("column", a)
        n_db = self.calibration.db_size
        if a.ndim == 2 and a.shape[1] == 1:
            a = a[:, 0]
        if a.ndim != 1 or a.shape[0] != n_db:
            raise ValueError(
                f"column must hold the |DB| = {n_db} scores of one query (a 1-D array or a "
                f"{n_db} x 1 matrix), got shape {a.shape}"
            )
        _non_finite("column", a, lambda i: f"row {i}")
        return self._decide(a)

    def push_many(self, s_val, *, query_major=False) -> OnlineDecisions:
        """Decide every query of ``s_val`` (|DB| x n, columns in arrival order; n x |DB|
        with ``query_major=True``), as :meth:`push` one by one. On a bad column the
        queries before it stay pushed. No query (n = 0) is no decision."""
        a = np.asarray(s_val)
        _check_float_dtype("s_val", a)
        if a.ndim != 2:
            raise ValueError(f"s_val must be a 2-D matrix, got a {a.ndim}-D array of shape {a.shape}")
        s = a.T if query_major else a
        n_db = self.calibration.db_size
        if s.shape[1] > 0 and s.shape[0] != n_db:
            raise ValueError(f"s_val has |DB| = {s.shape[0]} but the calibration has |DB| = {n_db}")
        decisions = []
        for j in range(s.shape[1]):
            col = s[:, j]
            where = (lambda i, j=j: f"row {j}, column {i}") if query_major else (lambda i, j=j: f"row {i}, column {j}")
            _non_finite("s_val", col, where)
            decisions.append(self._decide(np.array(col)))

        def field(name, dtype):
            return np.array([getattr(d, name) for d in decisions], dtype=dtype)

        return OnlineDecisions(
            queries=field("query", np.int64),
            query_quantiles=field("query_quantile", np.float64),
            weights=field("weight", np.float64),
            quantiles=field("quantile", np.float64),
            thresholds=field("threshold", np.float64),
            best=field("best", np.int64),
            score=field("score", np.float64),
            accepted=field("accepted", np.int64),
            accept=field("accept", bool),
            confidences=field("confidence", np.float64),
            confidences_lower95=field("confidence_lower95", np.float64),
            margins=field("margin", np.float64) if self._m_star is not None else None,
            gates=field("gate", np.float64) if self._m_star is not None else None,
            consistencies=field("consistency", np.float64) if self._level is not None else None,
            consistency_levels=field("consistency_level", np.float64) if self._level is not None else None,
        )


# ---------------------------------------------------------------------------------------
# Section 12: the calibration file
# ---------------------------------------------------------------------------------------

#: ``meta["format"]`` of a calibration file, and the one version this module knows.
CALIBRATION_FORMAT = "qtvpr-calibration"
CALIBRATION_VERSION = 1


def _package_version() -> str:
    try:
        return importlib.metadata.version("qtvpr")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


class Calibration:
    """A calibration traverse with ground truth: what :class:`Online` and a calibration
    file (semantics §12) hold.

    ``Calibration(s_cal, gt_cal, *, gt_soft=None, matching="single", query_major=False,
    sequence=None)`` validates its input as :func:`quantile_transfer` does and keeps the
    raw scores in their own dtype, |DB| x |Qcal|, with the hard and the optional soft
    ground truth. ``defaults`` are the parameters a calibration file stores for its
    users (``{"k": 10, "precision": 1.0, "window": None, "gate": "none",
    "sequence_gate": SEQUENCE_DEFAULTS}`` for one built here). With ``sequence=L``
    (section 15) the scores kept are the causal sequence matching of ``s_cal`` over L
    queries, and every transfer and :class:`Online` matches its deployment columns so.
    """

    def __init__(self, s_cal, gt_cal, *, gt_soft=None, matching="single", query_major=False, sequence=None):
        length = 1 if sequence is None else _check_sequence_length(sequence)
        if length > 1:
            raw = _scores("s_cal", s_cal, query_major)  # checked first, as the core does
            s_cal = _causal_match(np.asarray(s_cal).T if query_major else np.asarray(s_cal), length)
            s_cal = s_cal.T if query_major else s_cal
            del raw
        self._init("s_cal", s_cal, "gt_cal", gt_cal, "gt_soft", gt_soft, matching, query_major)
        self.sequence = length
        self.defaults = {"k": 10, "precision": 1.0, "window": None, "gate": "none",
                         "sequence_gate": dict(SEQUENCE_DEFAULTS)}

    def _init(self, s_name, s, gt_name, gt, soft_name, gt_soft, matching, query_major):
        self.matching = _check_matching(matching)
        self._s64, self._gt, self._ignored = _inputs(
            s_name, s, gt_name, gt, soft_name, gt_soft, query_major
        )
        raw = np.asarray(s)
        self._s = np.array(raw.T if query_major else raw)  # own dtype, a copy
        # Soft ground truth as a superset of the hard one, kept only when some entry is
        # soft but not hard: only those ignored entries matter.
        self._soft = self._gt | self._ignored if self._ignored.any() else None

    def __len__(self) -> int:
        return self._s.shape[1]

    @property
    def db_size(self) -> int:
        """|DB| of the calibration."""
        return self._s.shape[0]

    def transfer(self, s_val, *, k=None, precision=None, segment_size=None, gate=None, query_major=False,
                 sequence_window=None, sequence_level=None, sequence_speed=None, sequence_tolerance=None,
                 sequence_drift=None):
        """:func:`quantile_transfer` from this calibration; ``k``, ``precision``, ``gate``
        and the sequence gate's parameters left as ``None`` are the calibration's
        :attr:`defaults` (semantics §12). With a sequence length L > 1, ``s_val`` is
        matched causally first (section 15)."""
        k = self.defaults["k"] if k is None else k
        precision = self.defaults["precision"] if precision is None else precision
        gate = self.defaults["gate"] if gate is None else gate

        def oriented(a):
            return None if a is None else (a.T if query_major else a)

        if self.sequence > 1:
            _scores("s_val", s_val, query_major)  # checked first, as the core does
            s_val = oriented(_causal_match(oriented(np.asarray(s_val)), self.sequence))
        # Each parameter given, else the file's: passed whole.
        p = _sequence_params(self.defaults["sequence_gate"], sequence_window, sequence_level, sequence_speed,
                             sequence_tolerance, sequence_drift)
        return quantile_transfer(
            oriented(self._s), oriented(self._gt), s_val, gt_soft=oriented(self._soft), k=k,
            precision=precision, matching=self.matching, segment_size=segment_size, gate=gate,
            query_major=query_major, sequence_window=p["window"], sequence_level=p["level"],
            sequence_speed=p["speed"], sequence_tolerance=p["tolerance"], sequence_drift=p["drift"],
        )

    def threshold(self, precision=None) -> float:
        """The best threshold of the whole calibration (section 3); ``precision=None`` is
        the calibration's."""
        precision = self.defaults["precision"] if precision is None else precision
        return _best_threshold(self._s64, self._gt, self._ignored, _check_precision(precision), self.matching)

    def gate(self, precision=None) -> float:
        """m*, the margin gate of section 13 (``precision=None``: the calibration's)."""
        precision = self.defaults["precision"] if precision is None else precision
        _check_gated(self.matching, self.db_size)
        return _gate(self._s64, self._gt, self._ignored, _check_precision(precision))

    def confidence_blocks(self) -> list[tuple[float, int, int]]:
        """The confidence map of section 14: its blocks ``(centre PA-score, n, x)``."""
        _check_confident(self.matching, self.db_size)
        return _confidence_blocks(self._s64, self._gt, self._ignored)

    def save(self, path, *, k=None, precision=None, window=None, gate=None, sequence_window=None,
             sequence_level=None, sequence_speed=None, sequence_tolerance=None, sequence_drift=None) -> None:
        """Write the semantics §12 ``.npz`` to ``path`` (the name is used as given):
        ``s``, ``gt``, ``gt_soft`` when there is one, and ``meta``, a 0-d string array of
        JSON whose ``params`` are ``k``, ``precision``, ``window`` and ``gate``, with
        ``sequence_gate`` when the sequence gate is on or its parameters are not the
        defaults, and ``sequence`` when the sequence length is above 1 (each ``None``:
        the calibration's own :attr:`defaults`)."""
        k = self.defaults["k"] if k is None else k
        precision = self.defaults["precision"] if precision is None else precision
        window = self.defaults["window"] if window is None else window
        params = {
            "k": _check_positive_int("k", k),
            "precision": _check_precision(precision),
            "window": None if window is None else _check_positive_int("window", window),
            "gate": _check_gate(self.defaults["gate"] if gate is None else gate),
        }
        sequence_gate = _sequence_params(self.defaults["sequence_gate"], sequence_window, sequence_level,
                                         sequence_speed, sequence_tolerance, sequence_drift)
        if "margin" in params["gate"]:
            _check_gated(self.matching, self.db_size)
        if "sequence" in params["gate"]:
            _check_sequence_gate(self.matching, self.db_size, sequence_gate)
        if "sequence" in params["gate"] or sequence_gate != SEQUENCE_DEFAULTS:
            params["sequence_gate"] = sequence_gate
        if self.sequence > 1:
            params["sequence"] = self.sequence
        meta = {
            "format": CALIBRATION_FORMAT,
            "version": CALIBRATION_VERSION,
            "matching": self.matching,
            "params": params,
            "qtvpr": _package_version(),
        }
        arrays = {"s": self._s, "gt": self._gt}
        if self._soft is not None:
            arrays["gt_soft"] = self._soft
        with open(path, "wb") as f:  # a file object: np.savez would append ".npz" to a name
            np.savez(f, **arrays, meta=np.array(json.dumps(meta)))

    @staticmethod
    def load(path) -> Calibration:
        """Read a calibration file written by :meth:`save` (or by ``qtvpr``).

        Raises ``FileNotFoundError`` (or another ``OSError``) when the file cannot be
        opened, and ``ValueError`` naming the file for anything wrong inside it: not an
        ``.npz``, a missing or unreadable array, ``meta`` that is not a 0-d string of
        JSON, an unknown ``format`` or ``version``, bad ``matching`` or ``params`` (``k``
        and ``precision`` required, ``window`` optional), and every section-10 error of
        the arrays themselves (``TypeError`` for a dtype: scores float32 or float64,
        ground truth bool).
        """
        name = os.fspath(path)

        def bad(what: str) -> ValueError:
            return ValueError(f"{name}: {what}")

        try:
            npz = np.load(path, allow_pickle=False)
        except (FileNotFoundError, IsADirectoryError, PermissionError):
            raise
        except Exception as e:  # not an archive, a corrupt zip, pickled data, ...
            raise bad(f"not a readable .npz archive ({e})") from None
        if not isinstance(npz, np.lib.npyio.NpzFile):
            raise bad("not an .npz archive (it holds a single array)")
        arrays = {}
        with npz:
            for key in ("s", "gt", "gt_soft", "meta"):
                if key in npz.files:
                    try:
                        arrays[key] = npz[key]
                    except Exception as e:  # a corrupt member
                        raise bad(f"array {key!r} cannot be read ({e})") from None
        for key in ("s", "gt", "meta"):
            if key not in arrays:
                raise bad(f"missing array {key!r}")
        meta = arrays["meta"]
        if meta.shape != () or meta.dtype.kind != "U":
            raise bad(f"meta must be a 0-d string array, got dtype {meta.dtype} and shape {meta.shape}")
        try:
            meta = json.loads(str(meta))
        except json.JSONDecodeError as e:
            raise bad(f"meta is not valid JSON ({e})") from None
        if not isinstance(meta, dict):
            raise bad("meta must be a JSON object")
        if meta.get("format") != CALIBRATION_FORMAT:
            raise bad(f"unknown format {meta.get('format')!r}, expected {CALIBRATION_FORMAT!r}")
        version = meta.get("version")
        if type(version) is not int or version != CALIBRATION_VERSION:
            raise bad(f"unknown version {version!r}, expected {CALIBRATION_VERSION}")
        params = meta.get("params")
        if not isinstance(params, dict):
            raise bad("meta params must be a JSON object")
        for key in ("k", "precision"):
            if key not in params:
                raise bad(f"meta params has no {key}")
        defaults = {"window": None, "gate": "none", "sequence": 1, **params}
        try:
            for key in ("k", "window"):
                v = defaults[key]
                if isinstance(v, bool) or not (v is None and key == "window" or isinstance(v, int)):
                    raise TypeError(f"{key} must be an integer, got {v!r}")
            defaults["k"] = _check_positive_int("k", defaults["k"])
            if isinstance(defaults["precision"], bool):
                raise TypeError("precision must be a real number, got bool")
            defaults["precision"] = _check_precision(defaults["precision"])
            if defaults["window"] is not None:
                defaults["window"] = _check_positive_int("window", defaults["window"])
            defaults["gate"] = _check_gate(defaults["gate"])
            given = defaults.get("sequence_gate") or {}
            if not isinstance(given, dict):
                raise TypeError(f"sequence_gate must be a JSON object, got {given!r}")
            defaults["sequence_gate"] = _sequence_params(
                SEQUENCE_DEFAULTS, *(given.get(key) for key in ("window", "level", "speed", "tolerance", "drift"))
            )
            length = _check_sequence_length(defaults["sequence"])
        except (TypeError, ValueError) as e:
            raise bad(f"meta params: {e}") from None
        for key in ("gt", "gt_soft"):
            if key in arrays and arrays[key].dtype != bool:
                raise TypeError(f"{name}: {key} must be bool, got dtype {arrays[key].dtype}")
        cal = Calibration.__new__(Calibration)
        try:
            cal._init("s", arrays["s"], "gt", arrays["gt"], "gt_soft", arrays.get("gt_soft"),
                      meta.get("matching"), False)
        except (TypeError, ValueError) as e:  # a dtype stays a TypeError
            raise type(e)(f"{name}: {e}") from None
        cal.defaults = {key: defaults[key] for key in ("k", "precision", "window", "gate", "sequence_gate")}
        cal.sequence = length  # s is already matched over it
        try:
            if "margin" in cal.defaults["gate"]:
                _check_gated(cal.matching, cal.db_size)
            if "sequence" in cal.defaults["gate"]:
                _check_sequence_gate(cal.matching, cal.db_size, cal.defaults["sequence_gate"])
        except ValueError as e:
            raise bad(f"meta params: {e}") from None
        return cal
