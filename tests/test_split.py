"""One matrix of every query, split by the core: the first queries calibrate, the rest
are thresholded (``cal_queries=`` / ``cal_fraction=``).

The same scenarios as the Rust tests (``crates/qtvpr/src/input/split.rs``, and
``one_matrix_split_by_the_core`` in ``crates/qtvpr-cli/tests/cli.rs``): the split equals
the transfer of the slices, and bad splits (a count of 0 or of |Q|, a fraction outside
(0, 1) or leaving no calibration query, ground truth of the calibration queries alone,
a NaN among the deployment queries) raise ValueError with the core's message.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import qtvpr
from qtvpr import reference as ref

# The hand-computed case of crates/qtvpr/src/operations/transfer.rs as one matrix: columns 0-1
# calibrate, 2-3 are thresholded; the ground truth labels all four.
S = np.array([[3.0, 1.0, 2.0, 2.0], [1.0, 4.0, 6.0, 5.0], [2.0, 1.0, 4.0, 2.0]])
GT = np.array([[1, 1, 0, 1], [0, 1, 1, 0], [1, 0, 0, 0]], dtype=bool)
OPTS = {"k": 1, "matching": "multi", "segment_size": 1}


def _same(a, b):
    assert a.segments == b.segments
    for name in ("thresholds", "quantiles", "query_quantiles", "query_thresholds", "query_weights", "neighbours"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("split", [{"cal_queries": 2}, {"cal_fraction": 0.5}, {"cal_fraction": 0.74}])
def test_split_equals_the_slices(split):
    # floor(0.5 x 4) = floor(0.74 x 4) = 2.
    got = qtvpr.quantile_transfer(S, GT, **split, **OPTS)
    # With k = 1 and segments of one query: quantiles 0.5 and 1, thresholds 4 and the
    # next float64 above 5 (the transfer.rs unit test).
    np.testing.assert_array_equal(got.quantiles, [0.5, 1.0])
    np.testing.assert_array_equal(got.thresholds, [4.0, np.nextafter(5.0, np.inf)])
    assert got.segments == [(0, 1), (1, 2)]
    _same(got, qtvpr.quantile_transfer(S[:, :2], GT[:, :2], S[:, 2:], **OPTS))
    _same(got, qtvpr.quantile_transfer(S.T, GT.T, **split, query_major=True, **OPTS))
    reference = ref.quantile_transfer(S, GT, **split, **OPTS)
    np.testing.assert_array_equal(got.thresholds, reference.thresholds)
    cal = qtvpr.Calibration(S, GT, **split, matching="multi")
    assert len(cal) == 2
    _same(cal.transfer(S[:, 2:], k=1, segment_size=1), got)


def test_split_of_a_file_and_of_descriptors(tmp_path):
    np.save(tmp_path / "S.npy", S)
    np.save(tmp_path / "GT.npy", GT)
    _same(
        qtvpr.quantile_transfer(tmp_path / "S.npy", tmp_path / "GT.npy", cal_queries=2, **OPTS),
        qtvpr.quantile_transfer(S, GT, cal_queries=2, **OPTS),
    )
    rng = np.random.default_rng(5)
    db, q = rng.standard_normal((30, 8)), rng.standard_normal((50, 8))
    gt = np.abs(np.arange(30)[:, None] - np.arange(50)[None, :] * 30 // 50) <= 1
    # floor(0.3 x 50) = 15 calibrate.
    got = qtvpr.quantile_transfer(qtvpr.Descriptors(db, q), gt, cal_fraction=0.3, k=3, segment_size=7)
    want = qtvpr.Calibration(qtvpr.Descriptors(db, q, stop=15), gt[:, :15]).transfer(
        qtvpr.Descriptors(db, q, start=15), k=3, segment_size=7
    )
    _same(got, want)
    s = qtvpr.cosine_similarity(db, q)
    _same(got, qtvpr.quantile_transfer(s, gt, cal_queries=15, k=3, segment_size=7))
    # A Descriptors' own range is split: queries 10..50, floor(0.25 x 40) = 10 calibrate.
    got = qtvpr.quantile_transfer(qtvpr.Descriptors(db, q, start=10), gt[:, 10:], cal_fraction=0.25, k=3)
    _same(got, qtvpr.quantile_transfer(s[:, 10:20], gt[:, 10:20], s[:, 20:], k=3))


BAD = [
    ({"cal_queries": 0}, "cal_queries must be >= 1, got 0"),
    ({"cal_queries": -1}, "cal_queries must be >= 1, got -1"),
    ({"cal_queries": 4}, "the calibration set must have between 1 and 3 of the 4 queries, got 4"),
    ({"cal_fraction": 1.0}, "cal_fraction must be in (0, 1), got 1"),
    ({"cal_fraction": 0.0}, "cal_fraction must be in (0, 1), got 0"),
    ({"cal_fraction": 0.2}, "the calibration set must have between 1 and 3 of the 4 queries, got 0"),
]


@pytest.mark.parametrize(("split", "message"), BAD)
def test_bad_splits(split, message):
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        qtvpr.quantile_transfer(S, GT, **split)
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        qtvpr.Calibration(S, GT, **split)


def test_ground_truth_of_the_calibration_queries_alone():
    message = (
        "gt_cal: ground truth shape 3x2 does not match similarity shape 3x4; the ground truth of a split "
        "labels every query, of which the first 2 calibrate"
    )
    for f in (qtvpr.quantile_transfer, ref.quantile_transfer, qtvpr.Calibration):
        with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
            f(S, GT[:, :2], cal_queries=2)
    # Query-major: shapes as the caller stored them.
    message = message.replace("3x2", "2x3").replace("3x4", "4x3")
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        qtvpr.quantile_transfer(S.T, GT.T[:2], cal_queries=2, query_major=True)


def test_a_non_finite_deployment_score_is_named_in_the_whole_matrix():
    s = S.copy()
    s[1, 3] = np.nan
    # Deployment query 1 is column 2 + 1 = 3 of s.
    message = "s_cal: deployment similarity contains NaN at row 1, column 3; scores must be finite"
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        qtvpr.quantile_transfer(s, GT, cal_queries=2)
    message = "s_cal: deployment similarity contains NaN at row 3, column 1; scores must be finite"
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        qtvpr.quantile_transfer(s.T, GT.T, cal_queries=2, query_major=True)


@pytest.mark.parametrize("f", [qtvpr.quantile_transfer, ref.quantile_transfer])
def test_a_split_or_deployment_queries(f):
    with pytest.raises(ValueError, match="^give cal_queries or cal_fraction, not both$"):
        f(S, GT, cal_queries=2, cal_fraction=0.5)
    with pytest.raises(ValueError, match="^s_val and cal_queries/cal_fraction exclude each other"):
        f(S, GT, S, cal_queries=2)
    with pytest.raises(ValueError, match="^no deployment queries: give s_val, or cal_queries or cal_fraction"):
        f(S, GT)
