"""The wheel equals the NumPy reference on every real VPR-Bench similarity matrix.

Protocol of semantics §8: the first 10% of the queries calibrate, the rest deploy,
in segments of ceil(1%) of |Q| and also as one batch; both matching modes, precision
targets 1.0 and 0.9. The query-major variant feeds the transposed arrays with
``query_major=True`` and must give the same result.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pytest

import qtvpr
from qtvpr import reference as ref
from shared_data import DATASETS, TECHNIQUES, vprbench


@functools.cache
def load(root: Path, dataset: str, technique: str):
    """(S, GT, number of calibration queries, segment size) of one matrix."""
    s, gt = vprbench(root, dataset, technique)
    n_q = s.shape[1]
    return s, gt, math.floor(0.10 * n_q), math.ceil(0.01 * n_q)


@functools.cache
def expected(root: Path, dataset, technique, matching, precision, segmented):
    s, gt, n_cal, size = load(root, dataset, technique)
    return ref.quantile_transfer(
        s[:, :n_cal],
        gt[:, :n_cal],
        s[:, n_cal:],
        matching=matching,
        precision=precision,
        segment_size=size if segmented else None,
    )


def assert_equal(got, want):
    for name in ("thresholds", "quantiles", "query_quantiles", "query_thresholds", "query_weights"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=0, atol=1e-9, err_msg=name)
    assert got.segments == want.segments
    np.testing.assert_array_equal(got.neighbours, want.neighbours)


@pytest.mark.parametrize("segmented", [True, False], ids=["segments", "one-batch"])
@pytest.mark.parametrize("precision", [1.0, 0.9])
@pytest.mark.parametrize("matching", ["single", "multi"])
@pytest.mark.parametrize("query_major", [False, True], ids=["db-major", "query-major"])
@pytest.mark.parametrize("technique", TECHNIQUES)
@pytest.mark.parametrize("dataset", DATASETS)
def test_wheel_equals_reference(shared_data, dataset, technique, query_major, matching, precision, segmented):
    s, gt, n_cal, size = load(shared_data, dataset, technique)
    want = expected(shared_data, dataset, technique, matching, precision, segmented)
    s_cal, gt_cal, s_val = s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:]
    if query_major:
        s_cal, gt_cal, s_val = s_cal.T, gt_cal.T, s_val.T
    got = qtvpr.quantile_transfer(
        s_cal,
        gt_cal,
        s_val,
        matching=matching,
        precision=precision,
        segment_size=size if segmented else None,
        query_major=query_major,
    )
    assert_equal(got, want)


@pytest.mark.parametrize("matching", ["single", "multi"])
@pytest.mark.parametrize("dataset", DATASETS)
def test_calibration_threshold_equals_reference(shared_data, dataset, matching):
    for technique in TECHNIQUES:
        s, gt, n_cal, _ = load(shared_data, dataset, technique)
        cal = qtvpr.Calibration(s[:, :n_cal], gt[:, :n_cal], matching=matching)
        for precision in (1.0, 0.9):
            want = ref.best_threshold(s[:, :n_cal], gt[:, :n_cal], precision=precision, matching=matching)
            assert cal.threshold(precision) == want, (technique, precision)
            got = qtvpr.best_threshold(s, gt, precision=precision, matching=matching)
            assert got == ref.best_threshold(s, gt, precision=precision, matching=matching)


def _ours(s: np.ndarray, gt: np.ndarray) -> tuple[float, float | None]:
    """(our recall at 100% precision, R@1) of every query but the first: the oracle's
    recall over one segment of all of them, from evaluate's keys."""
    out = qtvpr.evaluate(s, gt, cal_queries=1, segment_size=s.shape[1] - 1, methods=["oracle"])
    (segment,) = out["methods"]["oracle"]["segments"]
    return segment["recall"], out["recall_at_1"]


@pytest.mark.parametrize("dataset", DATASETS)
def test_vprbench_recall_at_100p_is_ours_over_recall_at_1(shared_data, dataset):
    """VPR-Bench divides its recall at 100% precision by the correct best matches, we by
    the queries with a match: on every VPR-Bench matrix, theirs is ours / R@1."""
    for technique in TECHNIQUES:
        s, gt, _, _ = load(shared_data, dataset, technique)
        recall, r1 = _ours(s, gt)
        # Every VPR-Bench query has a match, so R@1 is the fraction of correct best matches.
        columns = np.arange(1, s.shape[1])
        assert r1 == np.count_nonzero(gt[np.argmax(s[:, 1:], axis=0), columns]) / (s.shape[1] - 1)
        theirs = ref.vprbench_recall_at_100p(s[:, 1:], gt[:, 1:])
        assert abs(recall / r1 - theirs) <= 1e-12, (technique, recall, r1, theirs)
    # One value by hand: Corridor AMOSNet, queries 1..110: 93 correct best matches of 110
    # (R@1 = 0.8455) and 32 of them accepted before the first wrong one: ours 32 / 110 =
    # 0.2909, VPR-Bench's 32 / 93 = 0.3441.
    if dataset == "vprbench-corridor":
        s, gt, _, _ = load(shared_data, dataset, "AMOSNet")
        recall, r1 = _ours(s, gt)
        assert (recall, r1) == (32 / 110, 93 / 110)
