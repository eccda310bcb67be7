"""Descriptors in place of a similarity matrix, on real Nordland HOG descriptors.

The same scenarios as the Rust tests (crates/qtvpr/tests/descriptors.rs): calibration,
transfer and evaluation from ``qtvpr.Descriptors`` give exactly the results of
``qtvpr.cosine_similarity`` followed by the matrix path, for float32 and float64
descriptors and a calibration split inside a tile; bad descriptors raise ValueError
naming the argument and the row.
"""

from __future__ import annotations

import numpy as np
import pytest

import qtvpr
from shared_data import nordland_ground_truth, nordland_hog

N_Q = 600
N_CAL = 137  # not a multiple of the kernel's tile of 64 queries


@pytest.fixture(scope="module")
def nordland(shared_data):
    db, q = nordland_hog(shared_data)
    return db, q[:N_Q], nordland_ground_truth(len(db), N_Q)


def _same_transfer(a, b):
    assert a.segments == b.segments
    for name in ("thresholds", "quantiles", "query_quantiles", "query_thresholds", "query_weights", "neighbours"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("matching", ["single", "multi"])
def test_fused_transfer_equals_the_matrix_path(nordland, dtype, matching):
    db, q, gt = nordland
    db, q = db.astype(dtype), q.astype(dtype)
    s = qtvpr.cosine_similarity(db, q)
    d_cal = qtvpr.Descriptors(db, q, stop=N_CAL)
    d_val = qtvpr.Descriptors(db, q, start=N_CAL)
    assert d_cal.shape == (3576, N_CAL) and d_val.shape == (3576, N_Q - N_CAL)
    np.testing.assert_array_equal(d_val.similarity(), s[:, N_CAL:])
    cal = qtvpr.Calibration(s[:, :N_CAL], gt[:, :N_CAL], matching=matching)
    fused = qtvpr.Calibration(d_cal, gt[:, :N_CAL], matching=matching)
    for segment_size in (1, 10, 64, None):
        want = cal.transfer(s[:, N_CAL:], segment_size=segment_size)
        _same_transfer(fused.transfer(d_val, segment_size=segment_size), want)
        # Thresholds are real numbers, not all alike.
        assert np.isfinite(want.thresholds).any()


def test_quantile_transfer_takes_descriptors(nordland):
    db, q, gt = nordland
    s = qtvpr.cosine_similarity(db, q)
    want = qtvpr.quantile_transfer(s[:, :N_CAL], gt[:, :N_CAL], s[:, N_CAL:], segment_size=36)
    got = qtvpr.quantile_transfer(qtvpr.Descriptors(db, q, stop=N_CAL), gt[:, :N_CAL],
                                  qtvpr.Descriptors(db, q, start=N_CAL), segment_size=36)
    _same_transfer(got, want)
    assert len(want.segments) == (N_Q - N_CAL) // 36 + 1  # 12 full segments, 31 left over in the last


def test_evaluate_from_descriptors_equals_the_matrix_path(nordland):
    db, q, gt = nordland
    want = qtvpr.evaluate(qtvpr.cosine_similarity(db, q), gt, cal_queries=N_CAL, segment_size=20)
    got = qtvpr.evaluate(qtvpr.Descriptors(db, q), gt, cal_queries=N_CAL, segment_size=20)
    # Only a matrix has an orientation to report; descriptors have but one. The first
    # N_Q queries of 3576 all have a positive, the database images past them none.
    assert want.pop("orientation")["evidence"]["verdict"] == "consistent"
    assert got == want
    assert want["methods"]["quantile-transfer"]["segments"]


def test_ablation_from_descriptors_equals_the_matrix_path(nordland):
    db, q, gt = nordland
    opts = {"k": [1, 5], "cal_queries": [50, N_CAL], "segment_size": 20, "methods": ["quantile-transfer"]}
    want = qtvpr.ablation(qtvpr.cosine_similarity(db, q), gt, **opts)
    got = qtvpr.ablation(qtvpr.Descriptors(db, q), gt, **opts)
    assert want.pop("orientation")["query_major"] is False
    assert got == want
    runs = want["ablation"]
    assert [(r["params"]["calibration_queries"], r["params"]["k"]) for r in runs] == [
        (50, 1), (50, 5), (N_CAL, 1), (N_CAL, 5)]


def test_bad_descriptors_name_the_row(nordland):
    db, q, _ = nordland
    bad = q.copy()
    bad[42] = 0.0
    with pytest.raises(ValueError, match=r"^queries: query descriptor matrix row 42 is all zeros"):
        qtvpr.Descriptors(db, bad)
    bad = db.copy()
    bad[3, 5] = np.nan
    with pytest.raises(ValueError, match=r"^db: database descriptor matrix contains NaN at row 3, column 5"):
        qtvpr.Descriptors(bad, q)
    with pytest.raises(ValueError, match="755 columns"):
        qtvpr.Descriptors(db, q[:, :755])
    with pytest.raises(ValueError, match=r"select at least one of the 600 queries, got start=600, stop=600"):
        qtvpr.Descriptors(db, q, start=600)
    with pytest.raises(TypeError, match="float32 or float64"):
        qtvpr.Descriptors(db.astype(np.int32), q)
    cal = qtvpr.Calibration(qtvpr.Descriptors(db, q, stop=10), np.eye(3576, 10, dtype=bool))
    with pytest.raises(ValueError, match="database"):
        cal.transfer(qtvpr.Descriptors(db[:100], q))
    with pytest.raises(ValueError, match="query_major"):
        cal.transfer(qtvpr.Descriptors(db, q), query_major=True)
    # The same refusal wherever Descriptors stand for a matrix.
    with pytest.raises(ValueError, match="query_major=True does not apply to Descriptors"):
        qtvpr.Calibration(qtvpr.Descriptors(db, q, stop=10), np.eye(3576, 10, dtype=bool), query_major=True)
    with pytest.raises(ValueError, match="query_major=True does not apply to Descriptors"):
        qtvpr.evaluate(qtvpr.Descriptors(db, q), np.eye(3576, 600, dtype=bool), query_major=True)
