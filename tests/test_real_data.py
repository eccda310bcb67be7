"""The wheel equals the NumPy reference on every real VPR-Bench similarity matrix.

Protocol of SPEC section 8: the first 10% of the queries calibrate, the rest deploy,
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

DATASETS = ["vprbench-corridor", "vprbench-spedtest"]
TECHNIQUES = [
    "AMOSNet",
    "AlexNet_VPR",
    "CALC",
    "CoHOG",
    "HOG",
    "HybridNet",
    "NetVLAD",
    "RegionVLAD",
    "ap-gem-r101",
    "denseVLAD",
]


@functools.cache
def load(root: Path, dataset: str, technique: str):
    """(S, GT, number of calibration queries, segment size) of one matrix."""
    d = root / dataset
    s, gt = np.load(d / f"S_{technique}.npy"), np.load(d / "GT.npy")
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
