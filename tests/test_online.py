"""Online thresholds (semantics §11) and the calibration file (semantics §12).

First the NumPy reference alone: hand-computed windows, warm-up and the online method
of the evaluation protocol, each value worked out in the comment beside it; then the
reference's own definition (theta_j is the batch transfer of the window's columns) on
random and real data; then its calibration file.

Then the wheel: ``qtvpr.Online`` held to the reference to 1e-9 on the 20 real VPR-Bench
matrices and on hypothesis cases (windows of 1 and longer than the traverse, warm-up,
ties, constant columns, soft ground truth, both matching modes, tau < 1, float32,
memory layouts, query-major input, pushes one at a time and in blocks); its calibration
file (bit-identical round trip, read by ``np.load`` and by the reference, every bad
file refused with the file's name) and pickling; and the online method of
``qtvpr.evaluate``.
"""

from __future__ import annotations

import concurrent.futures
import functools
import inspect
import json
import math
import multiprocessing
import pickle
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import qtvpr
from qtvpr import reference as ref
from shared_data import DATASETS, TECHNIQUES, vprbench
from test_cli import run_cli

T, F = True, False

# A calibration of two queries over |DB| = 3 (the one of test_reference's section-5 case):
#   c0 = (0.9, 0.1, 0.3), hard match row 0 -> best 0.9 correct
#   c1 = (0.2, 0.95, 0.4), hard match row 1 -> best 0.95 correct
# k clips to 2, so every deployment query's subset is {c0, c1}, whatever its column.
# single, tau = 1: sweep 0.95 (TP 1, FP 0), 0.9 (2, 0) -> t = 0.9.
# multi, tau = 1: sweep 0.95 T, 0.9 T, then 0.4 F -> t = 0.9 as well.
# sample (0.1, 0.2, 0.3, 0.4, 0.9, 0.95), n = 6, c = #{<= 0.9} = 5 -> q_j = 4/5 for every
# query. All q_j being equal, every window's weighted median is 4/5 whatever the weights.
CAL_S = np.array([[0.9, 0.2], [0.1, 0.95], [0.3, 0.4]])
CAL_GT = np.array([[T, F], [F, T], [F, F]])

# Deployment columns d0..d3 and their hard ground truth.
DEP_S = np.array(
    [
        # d0   d1   d2   d3
        [0.7, 0.1, 0.4, 0.2],
        [0.3, 0.6, 0.4, 0.9],
        [0.2, 0.5, 0.1, 0.1],
    ]
)
DEP_GT = np.array(
    [
        [T, F, T, F],
        [F, F, F, T],
        [F, T, F, F],
    ]
)


def online(matching="single", **kwargs) -> ref.Online:
    return ref.Online(ref.Calibration(CAL_S, CAL_GT, matching=matching), k=10, **kwargs)


# ---------------------------------------------------------------------------------------
# The reference, by hand
# ---------------------------------------------------------------------------------------


def test_window_of_one_query():
    # Window 1: theta_j is the quantile at 4/5 of column j's 3 scores alone:
    # h = (3 - 1) * 0.8 = 1.6, lo = 1 -> x[1] + 0.6 * (x[2] - x[1]).
    # d0 sorted (0.2, 0.3, 0.7): 0.3 + 0.6 * 0.4 = 0.54; best row 0, 0.7 >= 0.54 accepted
    # d1 sorted (0.1, 0.5, 0.6): 0.5 + 0.6 * 0.1 = 0.56; best row 1, 0.6 >= 0.56 accepted
    # d2 sorted (0.1, 0.4, 0.4): 0.4 + 0.6 * 0   = 0.4;  best row 0 (first of the tied
    #    maxima), 0.4 >= 0.4 accepted (inclusive)
    o = online(window=1)
    assert o.threshold is None and o.pushed == 0
    want = [(0.54, 0, 0.7), (0.56, 1, 0.6), (0.4, 0, 0.4)]
    for j, (theta, best, score) in enumerate(want):
        d = o.push(DEP_S[:, j])
        assert d.query == j
        assert d.query_quantile == 4 / 5 and d.quantile == 4 / 5
        assert d.threshold == pytest.approx(theta, abs=1e-15)
        assert (d.best, d.score, d.accepted, d.accept) == (best, score, 1, True)
        assert d.accepted_indices.tolist() == [best]
        assert o.threshold == d.threshold and o.pushed == j + 1
    # Multi matching, same thresholds: d0 accepts 0.7 only; d1 0.6 only (0.5 < 0.56);
    # d2 both 0.4s (rows 0 and 1).
    o = online("multi", window=1)
    for j, indices in enumerate([[0], [1], [0, 1]]):
        d = o.push(DEP_S[:, j])
        assert d.threshold == pytest.approx(want[j][0], abs=1e-15)
        # The record is the same in multi matching: the column's best match too.
        assert (d.best, d.score, d.accept) == (want[j][1], want[j][2], True)
        assert d.accepted == len(indices) and d.accepted_indices.tolist() == indices


def test_window_slides_and_grows_to_its_size():
    # Window 2, 6 scores: h = 5 * 0.8 = 4 -> x[4] exactly.
    # j = 0: d0 alone -> 0.54 (as above)
    # j = 1: d0, d1 sorted (0.1, 0.2, 0.3, 0.5, 0.6, 0.7) -> 0.6; d1's best 0.6 accepted
    # j = 2: d1, d2 sorted (0.1, 0.1, 0.4, 0.4, 0.5, 0.6) -> 0.5; d2's best 0.4 rejected
    # j = 3: d2, d3 sorted (0.1, 0.1, 0.2, 0.4, 0.4, 0.9) -> 0.4; d3's best 0.9 accepted
    o = online(window=2)
    got = [o.push(DEP_S[:, j]) for j in range(4)]
    assert [d.threshold for d in got] == pytest.approx([0.54, 0.6, 0.5, 0.4], abs=1e-15)
    assert [d.accept for d in got] == [True, True, False, True]
    assert got[2].accepted_indices.tolist() == []
    # Window 3 at j = 2: all 9 scores sorted (0.1, 0.1, 0.2, 0.3, 0.4, 0.4, 0.5, 0.6, 0.7),
    # h = 8 * 0.8 = 6.4 -> 0.5 + 0.4 * (0.6 - 0.5) = 0.54. Window 4 (> 3 pushed) is the same.
    for m in (3, 4):
        o = online(window=m)
        for j in range(2):
            o.push(DEP_S[:, j])
        assert o.push(DEP_S[:, 2]).threshold == pytest.approx(0.54, abs=1e-15)


def test_warm_up_rejects_all():
    # min_window 2: query 0 (j + 1 = 1 < 2) is reject-all: quantile 1, threshold the
    # next float above its window's maximum 0.7; its best 0.7 is rejected. Query 1 is
    # thresholded normally on (d0, d1): 0.6, as with no warm-up.
    o = online(window=2, min_window=2)
    d = o.push(DEP_S[:, 0])
    assert d.quantile == 1.0 and d.query_quantile == 4 / 5
    assert d.threshold == np.nextafter(0.7, math.inf)
    assert (d.best, d.score, d.accept) == (0, 0.7, False)
    assert o.push(DEP_S[:, 1]).threshold == pytest.approx(0.6, abs=1e-15)
    # multi, window 3, min_window 3, pushing d0, d1, d3:
    # j = 0, 1: reject-all, the next float above 0.7 (the maximum of d0 and of d0, d1);
    #   d0 would accept its 0.7 at 0.54 without the warm-up.
    # j = 2: 9 scores sorted (0.1, 0.1, 0.2, 0.2, 0.3, 0.5, 0.6, 0.7, 0.9), h = 6.4
    #   -> 0.6 + 0.4 * (0.7 - 0.6) = 0.64; d3 accepts its 0.9 only.
    o = online("multi", window=3, min_window=3)
    got = [o.push(DEP_S[:, j]) for j in (0, 1, 3)]
    assert [d.quantile for d in got[:2]] == [1.0, 1.0]
    assert [d.threshold for d in got[:2]] == [np.nextafter(0.7, math.inf)] * 2
    assert got[2].threshold == pytest.approx(0.64, abs=1e-15)
    assert [d.accepted for d in got] == [0, 0, 1]
    assert got[2].accepted_indices.tolist() == [1]


def test_push_many_equals_pushes_and_takes_query_major():
    one = online(window=2)
    each = [one.push(DEP_S[:, j]) for j in range(4)]
    many = online(window=2).push_many(DEP_S)
    assert len(many) == 4
    assert many.queries.tolist() == [0, 1, 2, 3]
    assert many.thresholds.tolist() == [d.threshold for d in each]
    assert many.best.tolist() == [0, 1, 0, 1]
    assert many.accept.tolist() == [True, True, False, True]
    assert many.score.tolist() == [0.7, 0.6, 0.4, 0.9]
    assert many.accepted.tolist() == [1, 1, 0, 1]
    qm = online(window=2).push_many(DEP_S.T, query_major=True)
    assert qm.thresholds.tolist() == many.thresholds.tolist()
    # In pieces: the window carries over from one call to the next.
    o = online(window=2)
    o.push_many(DEP_S[:, :1])
    rest = o.push_many(DEP_S[:, 1:])
    assert rest.queries.tolist() == [1, 2, 3]
    assert rest.thresholds.tolist() == many.thresholds[1:].tolist()
    multi = online("multi", window=2).push_many(DEP_S)
    # thresholds 0.54, 0.6, 0.5, 0.4: d0 {0.7}, d1 {0.6}, d2 {}, d3 {0.9}
    assert multi.accepted.tolist() == [1, 1, 0, 1]
    assert multi.best.tolist() == [0, 1, 0, 1] and multi.score.tolist() == [0.7, 0.6, 0.4, 0.9]
    assert multi.accept.tolist() == [True, True, False, True]


def test_evaluate_online_method_by_hand():
    # Columns: c0, c1 (calibration), then d0..d3; segments of 2: (d0, d1), (d2, d3).
    # The online thresholds are those of test_window_slides_and_grows_to_its_size
    # (window = segment size = 2, across the segment boundary): 0.54, 0.6, 0.5, 0.4.
    # d0: best 0.7 (row 0, hard) accepted -> TP
    # d1: best 0.6 (row 1; its hard match is row 2) accepted -> FP
    # d2: best 0.4 (row 0, hard) < 0.5 -> rejected
    # d3: best 0.9 (row 1, hard) accepted -> TP
    # segment 0: TP 1, FP 1, positives 2 -> precision 1/2 misses tau = 1; threshold 0.6
    # segment 1: TP 1, FP 0, positives 2 -> meets, recall 1/2; threshold 0.4 (of d3)
    # %Segs 50, AvgR (0 + 1/2) / 2 = 1/4.
    # oracle: segment 0 candidates 0.7 T, 0.6 F -> 0.7; segment 1 0.9 T, 0.4 T -> 0.4;
    # MSE ((0.6 - 0.7)^2 + 0) / 2 = 0.005.
    s = np.hstack([CAL_S, DEP_S])
    gt = np.hstack([CAL_GT, DEP_GT])
    res = ref.evaluate(s, gt, cal_queries=2, segment_size=2, methods=["quantile-transfer-online", "quantile-transfer"])
    on = res["methods"]["quantile-transfer-online"]
    rows = [(r["start"], r["end"], r["tp"], r["fp"], r["positives"], r["meets"]) for r in on["segments"]]
    assert rows == [(0, 2, 1, 1, 2, False), (2, 4, 1, 0, 2, True)]
    assert [r["threshold"] for r in on["segments"]] == pytest.approx([0.6, 0.4], abs=1e-15)
    assert [r["oracle_threshold"] for r in on["segments"]] == [0.7, 0.4]
    assert (on["pct_segs"], on["avg_recall"]) == (50.0, 0.25)
    assert on["threshold_mse"] == pytest.approx(0.005, abs=1e-15)
    # Offline, segment 1 is one batch (d2, d3) at 0.4, which accepts d2 too: TP 2, recall 1.
    off = res["methods"]["quantile-transfer"]["segments"][1]
    assert (off["threshold"], off["tp"], off["recall"]) == (pytest.approx(0.4, abs=1e-15), 2, 1.0)
    assert "quantile-transfer-online" in ref.METHODS
    # Every method but the sequence gate's, which cannot tell on so small a database.
    every = [m for m in ref.METHODS if m not in ref.SEQUENCE_GATED]
    assert list(ref.evaluate(s, gt, cal_queries=2, segment_size=2)["methods"]) == every


def test_evaluate_online_multi_counts_entries():
    # multi, same thresholds (q_j = 4/5 in multi too): per query, entries >= theta_j
    # d0 >= 0.54: 0.7 (hard)               -> TP 1        positives 1
    # d1 >= 0.6 : 0.6 (not hard)           -> FP 1        positives 1
    # d2 >= 0.5 : none                     ->             positives 1
    # d3 >= 0.4 : 0.9 (hard)               -> TP 1        positives 1
    s = np.hstack([CAL_S, DEP_S])
    gt = np.hstack([CAL_GT, DEP_GT])
    res = ref.evaluate(s, gt, cal_queries=2, segment_size=2, matching="multi", methods=["quantile-transfer-online"])
    rows = [(r["tp"], r["fp"], r["positives"]) for r in res["methods"]["quantile-transfer-online"]["segments"]]
    assert rows == [(1, 1, 2), (1, 0, 2)]


# ---------------------------------------------------------------------------------------
# The reference against its definition: theta_j = the batch transfer of the window
# ---------------------------------------------------------------------------------------

LEVELS = [-1.0, 0.0, 0.25, 0.5, 1.0, 2.0]


@st.composite
def online_cases(draw):
    n_db = draw(st.integers(1, 8))
    n_cal = draw(st.integers(1, 6))
    n_val = draw(st.integers(1, 8))
    values = st.sampled_from(draw(st.lists(st.sampled_from(LEVELS), min_size=1, max_size=4, unique=True)))
    if draw(st.booleans()):
        values = st.one_of(values, st.floats(-2, 2, width=32))

    def matrix(cols):
        return np.array(draw(st.lists(values, min_size=n_db * cols, max_size=n_db * cols))).reshape(n_db, cols)

    s_cal, s_val = matrix(n_cal), matrix(n_val)
    labels = np.array(draw(st.lists(st.integers(0, 3), min_size=n_db * n_cal, max_size=n_db * n_cal)))
    labels = labels.reshape(n_db, n_cal)
    soft = (labels >= 2) if draw(st.booleans()) else None
    window = draw(st.integers(1, n_val + 2))
    return dict(
        s_cal=s_cal, gt=labels == 2, soft=soft, s_val=s_val,
        matching=draw(st.sampled_from(["single", "multi"])),
        k=draw(st.integers(1, 7)), precision=draw(st.sampled_from([1.0, 0.9, 0.5])),
        window=window, min_window=draw(st.integers(1, window)),
    )


def check_against_definition(c):
    cal = ref.Calibration(c["s_cal"], c["gt"], gt_soft=c["soft"], matching=c["matching"])
    o = ref.Online(cal, k=c["k"], precision=c["precision"], window=c["window"], min_window=c["min_window"])
    s_val = c["s_val"]
    whole = ref.quantile_transfer(
        c["s_cal"], c["gt"], s_val, gt_soft=c["soft"], k=c["k"], precision=c["precision"], matching=c["matching"],
        segment_size=1,
    )
    for j in range(s_val.shape[1]):
        d = o.push(s_val[:, j])
        lo = max(0, j + 1 - c["window"])
        if j + 1 < c["min_window"]:
            assert d.quantile == 1.0
            assert d.threshold == np.nextafter(float(s_val[:, lo : j + 1].max()), math.inf)
        else:
            want = ref.quantile_transfer(
                c["s_cal"], c["gt"], s_val[:, lo : j + 1], gt_soft=c["soft"], k=c["k"],
                precision=c["precision"], matching=c["matching"],
            )
            assert d.quantile == want.quantiles[0]
            assert d.threshold == want.thresholds[0]
        assert d.query_quantile == whole.query_quantiles[j]
        # One column's correlations come from a matrix-vector product, the batch's from a
        # matrix product: they may differ in the last bits.
        assert d.weight == pytest.approx(whole.query_weights[j], rel=0, abs=1e-12)
        col = s_val[:, j].astype(np.float64)  # compared in f64, as the spec does
        if c["matching"] == "single":
            b = int(np.argmax(col))
            assert (d.best, d.score, d.accept) == (b, col[b], bool(col[b] >= d.threshold))
        else:
            assert d.accepted == int((col >= d.threshold).sum())


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(online_cases())
def test_reference_theta_is_the_batch_transfer_of_its_window(c):
    check_against_definition(c)


@pytest.mark.parametrize("window", [1, 3, 200])
@pytest.mark.parametrize("technique", ["AMOSNet", "CoHOG"])
def test_reference_definition_on_corridor(shared_data, technique, window):
    s, gt = vprbench(shared_data, "vprbench-corridor", technique)
    check_against_definition(dict(
        s_cal=s[:, :11], gt=gt[:, :11], soft=None, s_val=s[:, 11:40], matching="single", k=10,
        precision=0.9, window=window, min_window=min(window, 2),
    ))


def test_reference_online_bad_input():
    cal = ref.Calibration(CAL_S, CAL_GT)
    with pytest.raises(ValueError, match="window is not given and the calibration sets none"):
        ref.Online(cal)
    with pytest.raises(ValueError, match="window must be >= 1"):
        ref.Online(cal, window=0)
    with pytest.raises(ValueError, match=r"min_window must be between 1 and the window \(2\), got 3"):
        ref.Online(cal, window=2, min_window=3)
    with pytest.raises(ValueError, match=r"min_window must be between 1 and the window \(2\), got 0"):
        ref.Online(cal, window=2, min_window=0)
    with pytest.raises(ValueError, match="k must be >= 1"):
        ref.Online(cal, k=0, window=2)
    with pytest.raises(ValueError, match="precision must be in"):
        ref.Online(cal, precision=1.5, window=2)
    o = ref.Online(cal, window=2)
    with pytest.raises(ValueError, match=r"column must hold the \|DB\| = 3 scores"):
        o.push(np.ones(4))
    with pytest.raises(ValueError, match="column contains NaN at row 1"):
        o.push(np.array([0.1, np.nan, 0.2]))
    with pytest.raises(TypeError, match="column must be float32 or float64"):
        o.push(np.ones(3, dtype=np.int64))
    assert o.pushed == 0 and o.threshold is None  # errors leave the state unchanged
    # push_many keeps the queries before a bad column
    bad = DEP_S.copy()
    bad[2, 2] = np.inf
    with pytest.raises(ValueError, match="s_val contains an infinite value at row 2, column 2"):
        o.push_many(bad)
    assert o.pushed == 2
    with pytest.raises(ValueError, match="s_val contains an infinite value at row 2, column 2"):
        ref.Online(cal, window=2).push_many(bad.T, query_major=True)
    with pytest.raises(ValueError, match=r"s_val has \|DB\| = 2"):
        o.push_many(np.ones((2, 2)))
    assert len(o.push_many(np.ones((3, 0)))) == 0 and o.pushed == 2  # no query, no decision


# ---------------------------------------------------------------------------------------
# The reference's calibration file
# ---------------------------------------------------------------------------------------


def test_reference_save_load_round_trip(tmp_path):
    soft = CAL_GT | np.array([[F, T], [F, F], [T, F]])
    for dtype in (np.float32, np.float64):
        cal = ref.Calibration(CAL_S.astype(dtype), CAL_GT, gt_soft=soft, matching="multi")
        path = tmp_path / f"cal-{np.dtype(dtype).name}"  # no .npz suffix: the name is kept
        cal.save(path, k=3, precision=0.9, window=2)
        assert path.exists()
        with np.load(path, allow_pickle=False) as z:
            assert sorted(z.files) == ["gt", "gt_soft", "meta", "s"]
            assert z["s"].dtype == dtype and np.array_equal(z["s"], CAL_S.astype(dtype))
            assert z["gt"].dtype == bool and np.array_equal(z["gt"], CAL_GT)
            assert np.array_equal(z["gt_soft"], soft)
            assert z["meta"].shape == ()
            meta = json.loads(str(z["meta"]))
        assert {k: meta[k] for k in ("format", "version", "matching", "params")} == {
            "format": "qtvpr-calibration", "version": 1, "matching": "multi",
            "params": {"k": 3, "precision": 0.9, "window": 2, "gate": "none"},
        }
        loaded = ref.Calibration.load(path)
        assert loaded.defaults == {"k": 3, "precision": 0.9, "window": 2, "gate": "none",
                                   "sequence_gate": ref.SEQUENCE_DEFAULTS}
        assert loaded.matching == "multi" and len(loaded) == 2
        a = ref.Online(cal, k=3, precision=0.9, window=2).push_many(DEP_S)
        b = ref.Online(loaded).push_many(DEP_S)  # the file's params
        assert a.thresholds.tolist() == b.thresholds.tolist()
        assert a.accepted.tolist() == b.accepted.tolist()
    # No soft ground truth: no gt_soft array; window None is written as null.
    ref.Calibration(CAL_S, CAL_GT).save(tmp_path / "plain.npz")
    with np.load(tmp_path / "plain.npz", allow_pickle=False) as z:
        assert sorted(z.files) == ["gt", "meta", "s"]
        assert json.loads(str(z["meta"]))["params"] == {"k": 10, "precision": 1.0, "window": None, "gate": "none"}
    # The file leaves the sequence gate out when it is off at its defaults; loaded, the
    # defaults have it.
    plain = {"k": 10, "precision": 1.0, "window": None, "gate": "none", "sequence_gate": ref.SEQUENCE_DEFAULTS}
    assert ref.Calibration.load(tmp_path / "plain.npz").defaults == plain


def write_npz(path: Path, meta_json=None, **arrays) -> Path:
    """An .npz of ``arrays``, with ``meta_json`` (a dict or a string) as its ``meta``."""
    if meta_json is not None:
        arrays["meta"] = np.array(meta_json if isinstance(meta_json, str) else json.dumps(meta_json))
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


META = {"format": "qtvpr-calibration", "version": 1, "matching": "single",
        "params": {"k": 10, "precision": 1.0, "window": 28}, "qtvpr": "0.1.0"}
GOOD = dict(s=CAL_S, gt=CAL_GT)

#: Bad calibration files: (what is written, the exception, a part of its message).
BAD_FILES = {
    "missing-s": (dict(gt=CAL_GT, meta=META), ValueError, "missing array 's'"),
    "missing-gt": (dict(s=CAL_S, meta=META), ValueError, "missing array 'gt'"),
    "missing-meta": (dict(GOOD), ValueError, "missing array 'meta'"),
    "gt-shape": (dict(s=CAL_S, gt=CAL_GT[:2], meta=META), ValueError, "gt shape 2x2 does not match s shape 3x2"),
    "soft-shape": (dict(GOOD, gt_soft=CAL_GT[:, :1], meta=META), ValueError, "gt_soft shape 3x1"),
    "s-1d": (dict(s=CAL_S[:, 0], gt=CAL_GT, meta=META), ValueError, "s must be a 2-D matrix"),
    "s-nan": (
        dict(s=np.where(CAL_S > 0.5, np.nan, CAL_S), gt=CAL_GT, meta=META),
        ValueError,
        "s contains NaN at row 0, column 0",
    ),
    "s-int": (dict(s=(CAL_S * 10).astype(np.int64), gt=CAL_GT, meta=META), TypeError, "s must be float32 or float64"),
    "gt-int": (dict(s=CAL_S, gt=CAL_GT.astype(np.int8), meta=META), TypeError, "gt must be bool"),
    "soft-int": (dict(GOOD, gt_soft=CAL_GT.astype(np.uint8), meta=META), TypeError, "gt_soft must be bool"),
    "no-params": (dict(GOOD, meta={k: v for k, v in META.items() if k != "params"}), ValueError, "params"),
    "params-no-k": (dict(GOOD, meta={**META, "params": {"precision": 1.0}}), ValueError, "params has no k"),
    "format": (dict(GOOD, meta={**META, "format": "other"}), ValueError, "unknown format 'other'"),
    "version": (dict(GOOD, meta={**META, "version": 2}), ValueError, "unknown version 2"),
    "matching": (dict(GOOD, meta={**META, "matching": "both"}), ValueError, "matching must be"),
    "meta-json": (dict(GOOD, meta="{not json"), ValueError, "meta is not valid JSON"),
    "meta-list": (dict(GOOD, meta="[1, 2]"), ValueError, "meta must be a JSON object"),
    "meta-bytes": (dict(GOOD, meta=None), ValueError, "meta must be a 0-d string array"),
    "params-k": (dict(GOOD, meta={**META, "params": {"k": 0, "precision": 1.0}}), ValueError, "k must be >= 1"),
    "params-precision": (
        dict(GOOD, meta={**META, "params": {"k": 1, "precision": 2.0}}),
        ValueError,
        "precision must be in",
    ),
    "params-window": (
        dict(GOOD, meta={**META, "params": {"k": 1, "precision": 1.0, "window": "28"}}),
        ValueError,
        "window must be an integer",
    ),
}


@pytest.mark.parametrize("kind", list(BAD_FILES))
def test_reference_bad_calibration_files(tmp_path, kind):
    arrays, exc, message = BAD_FILES[kind]
    arrays = dict(arrays)
    meta = arrays.pop("meta", None)
    if kind == "meta-bytes":
        arrays["meta"] = np.array([b"x"])
    path = write_npz(tmp_path / f"{kind}.npz", meta, **arrays)
    with pytest.raises(exc, match=message) as info:
        ref.Calibration.load(path)
    assert str(path) in str(info.value)


def test_reference_unreadable_calibration_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        ref.Calibration.load(tmp_path / "absent.npz")
    good = tmp_path / "good.npz"
    ref.Calibration(CAL_S, CAL_GT).save(good)
    data = good.read_bytes()
    cases = {
        "truncated.npz": data[: len(data) // 2],
        "garbage.npz": b"this is not a zip archive at all",
        "empty.npz": b"",
    }
    # A zip whose member is corrupt: flip bytes in the middle of the first member's data.
    corrupt = bytearray(data)
    for i in range(60, 90):
        corrupt[i] ^= 0xFF
    cases["corrupt.npz"] = bytes(corrupt)
    for name, payload in cases.items():
        p = tmp_path / name
        p.write_bytes(payload)
        with pytest.raises(ValueError, match=str(p)):
            ref.Calibration.load(p)
    npy = tmp_path / "single.npy"
    np.save(npy, CAL_S)
    with pytest.raises(ValueError, match="not an .npz archive"):
        ref.Calibration.load(npy)
    assert zipfile.is_zipfile(good)


# =======================================================================================
# The wheel: qtvpr.Online and the calibration file, held to the reference
# =======================================================================================


def assert_close(got, want, name=""):
    """Equal to 1e-9, infinities in the same places."""
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=0, atol=1e-9, err_msg=name)


def assert_decisions_equal(got, want):
    """One OnlineDecisions (wheel) against the reference's: figures to 1e-9, decisions
    (best, accept, accepted) exactly."""
    assert len(got) == len(want)
    np.testing.assert_array_equal(got.queries, want.queries)
    for name in ("query_quantiles", "weights", "quantiles", "thresholds"):
        assert getattr(got, name).dtype == np.float64, name
        assert_close(getattr(got, name), getattr(want, name), name)
    for name, dtype in (("best", np.int64), ("accept", np.bool_), ("accepted", np.int64)):
        g, w = getattr(got, name), getattr(want, name)
        assert g.dtype == dtype, name
        np.testing.assert_array_equal(g, w, err_msg=name)
    assert_close(got.score, want.score, "score")


def assert_decision_equal(got, want):
    """One OnlineDecision (wheel) against the reference's."""
    assert got.query == want.query
    for name in ("query_quantile", "weight", "quantile", "threshold"):
        assert_close(getattr(got, name), getattr(want, name), name)
    assert (got.best, got.accept, got.accepted) == (want.best, want.accept, want.accepted)
    assert_close(got.score, want.score)
    assert got.accepted_indices.dtype == np.int64
    np.testing.assert_array_equal(got.accepted_indices, want.accepted_indices)


def soft_of(gt: np.ndarray) -> np.ndarray:
    """Every hard match widened by one database image either side."""
    soft = gt.copy()
    soft[1:] |= gt[:-1]
    soft[:-1] |= gt[1:]
    return soft


#: The real matrices, read once per worker.
load_matrix = functools.cache(vprbench)


#: Real-data configurations: window "size" is the protocol's segment size
#: ceil(1% |Q|); "more" is 150 over the first 120 deployment queries, a window longer
#: than the deployment traverse.
REAL_CONFIGS = {
    "single-tau1-segment": dict(matching="single", precision=1.0, window="size", min_window=1, soft=False,
                                query_major=False, one_by_one=False),
    "multi-tau0.9-window1-soft-qm": dict(matching="multi", precision=0.9, window=1, min_window=1, soft=True,
                                         query_major=True, one_by_one=True),
    "single-tau0.9-more-warmup-soft": dict(matching="single", precision=0.9, window="more", min_window=5,
                                           soft=True, query_major=False, one_by_one=False),
    "multi-tau1-segment-warmup-qm": dict(matching="multi", precision=1.0, window="size", min_window="size",
                                         soft=False, query_major=True, one_by_one=False),
}


@pytest.mark.parametrize("config", list(REAL_CONFIGS))
@pytest.mark.parametrize("technique", TECHNIQUES)
@pytest.mark.parametrize("dataset", DATASETS)
def test_wheel_equals_reference_on_real_data(shared_data, dataset, technique, config):
    c = REAL_CONFIGS[config]
    s, gt = load_matrix(shared_data, dataset, technique)
    n_q = s.shape[1]
    n_cal, size = math.floor(0.1 * n_q), math.ceil(0.01 * n_q)
    s_cal, gt_cal, s_val = s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:]
    window = {"size": size, "more": 150}.get(c["window"], c["window"])
    if c["window"] == "more":
        s_val = s_val[:, :120]
    min_window = size if c["min_window"] == "size" else c["min_window"]
    soft = soft_of(gt_cal) if c["soft"] else None
    kwargs = dict(k=10, precision=c["precision"], window=window, min_window=min_window)
    want = ref.Online(ref.Calibration(s_cal, gt_cal, gt_soft=soft, matching=c["matching"]), **kwargs)
    want = want.push_many(s_val)
    qm = c["query_major"]
    orient = (lambda a: None if a is None else a.T) if qm else (lambda a: a)
    cal = qtvpr.Calibration(orient(s_cal), orient(gt_cal), gt_soft=orient(soft), matching=c["matching"],
                            query_major=qm)
    online = qtvpr.Online(cal, **kwargs)
    if c["one_by_one"]:
        # Columns one at a time: rows of the query-major array, strided columns otherwise.
        v = orient(s_val)
        decisions = [online.push(v[j] if qm else v[:, j]) for j in range(s_val.shape[1])]
        got = [d.threshold for d in decisions]
        assert_close(got, want.thresholds)
        assert [d.accepted for d in decisions] == want.accepted.tolist()
        assert_close([d.weight for d in decisions], want.weights)
        assert_close([d.quantile for d in decisions], want.quantiles)
    else:
        assert_decisions_equal(online.push_many(orient(s_val), query_major=qm), want)
    assert online.pushed == s_val.shape[1]
    assert online.threshold == pytest.approx(want.thresholds[-1], abs=1e-9)


# ---------------------------------------------------------------------------------------
# Hypothesis: small matrices with ties, constant columns, every window
# ---------------------------------------------------------------------------------------

LAYOUTS = ["C", "F", "strided", "reversed"]


def with_layout(a: np.ndarray, layout: str) -> np.ndarray:
    if layout == "C":
        return np.ascontiguousarray(a)
    if layout == "F":
        return np.asfortranarray(a)
    if layout == "strided":
        big = np.zeros((a.shape[0], 2 * a.shape[1]), dtype=a.dtype)
        big[:, ::2] = a
        return big[:, ::2]
    return a[::-1].copy()[::-1]


@st.composite
def wheel_cases(draw):
    c = draw(online_cases())
    for name in ("s_cal", "s_val"):
        c[name] = c[name].astype(draw(st.sampled_from([np.float32, np.float64])))
    for j in draw(st.sets(st.integers(0, c["s_val"].shape[1] - 1))):
        c["s_val"][:, j] = c["s_val"][0, j]  # constant deployment columns
    c["layout"] = draw(st.sampled_from(LAYOUTS))
    c["query_major"] = draw(st.booleans())
    # How the deployment queries are pushed: sizes of push_many calls, 0 meaning push.
    n = c["s_val"].shape[1]
    pieces, left = [], n
    while left > 0:
        p = draw(st.integers(0, left))
        pieces.append(p)
        left -= max(p, 1)
    c["pieces"] = pieces
    return c


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(wheel_cases())
def test_wheel_equals_reference_on_random_cases(c):
    qm = c["query_major"]
    orient = (lambda a: None if a is None else a.T) if qm else (lambda a: a)
    kwargs = dict(k=c["k"], precision=c["precision"], window=c["window"], min_window=c["min_window"])
    want = ref.Online(ref.Calibration(c["s_cal"], c["gt"], gt_soft=c["soft"], matching=c["matching"]), **kwargs)
    cal = qtvpr.Calibration(orient(c["s_cal"]), orient(c["gt"]), gt_soft=orient(c["soft"]),
                            matching=c["matching"], query_major=qm)
    got = qtvpr.Online(cal, **kwargs)
    s_val = c["s_val"]
    start = 0
    for p in c["pieces"]:
        if p == 0:
            col = with_layout(s_val[:, start : start + 1], c["layout"])
            assert_decision_equal(got.push(col if start % 2 else col[:, 0]), want.push(s_val[:, start]))
            start += 1
        else:
            block = with_layout(orient(s_val[:, start : start + p]), c["layout"])
            assert_decisions_equal(got.push_many(block, query_major=qm), want.push_many(s_val[:, start : start + p]))
            start += p
        assert got.pushed == want.pushed == start
        assert got.threshold == pytest.approx(want.threshold, abs=1e-9)


# ---------------------------------------------------------------------------------------
# The wheel's API
# ---------------------------------------------------------------------------------------


def wheel_online(matching="single", **kwargs):
    return qtvpr.Online(qtvpr.Calibration(CAL_S, CAL_GT, matching=matching), k=10, **kwargs)


def test_wheel_hand_computed_windows():
    # The thresholds of test_window_slides_and_grows_to_its_size: 0.54, 0.6, 0.5, 0.4.
    o = wheel_online(window=2)
    assert o.threshold is None and o.pushed == 0
    d = o.push(DEP_S[:, 0])
    assert isinstance(d, qtvpr.OnlineDecision)
    assert (d.query, d.quantile, d.query_quantile) == (0, 4 / 5, 4 / 5)
    assert d.threshold == pytest.approx(0.54, abs=1e-15)
    assert (d.best, d.score, d.accepted, d.accept) == (0, 0.7, 1, True)
    assert d.accepted_indices.tolist() == [0]
    assert repr(d).startswith("OnlineDecision(query=0, quantile=0.8, threshold=0.54")
    assert repr(d).endswith("best=0, score=0.7, accepted=1, accept=True)")
    many = o.push_many(DEP_S[:, 1:])
    assert isinstance(many, qtvpr.OnlineDecisions) and len(many) == 3
    assert many.queries.tolist() == [1, 2, 3]
    assert many.thresholds.tolist() == pytest.approx([0.6, 0.5, 0.4], abs=1e-15)
    assert many.accept.tolist() == [True, False, True]
    assert many.accepted.tolist() == [1, 0, 1]
    assert o.pushed == 4 and o.threshold == pytest.approx(0.4, abs=1e-15)
    # warm-up, multi: j = 0, 1 reject-all above 0.7; j = 2 (d0, d1, d3) at 0.64
    o = wheel_online("multi", window=3, min_window=3)
    got = [o.push(DEP_S[:, j]) for j in (0, 1, 3)]
    assert [d.threshold for d in got[:2]] == [np.nextafter(0.7, math.inf)] * 2
    assert got[2].threshold == pytest.approx(0.64, abs=1e-15)
    assert [d.accepted for d in got] == [0, 0, 1]
    assert got[2].accepted_indices.tolist() == [1]
    assert (got[2].best, got[2].score, got[2].accept) == (1, 0.9, True)
    assert repr(got[2]).endswith("best=1, score=0.9, accepted=1, accept=True)")


def test_wheel_api_shape():
    def parameters(f):  # without self (positional-only in the wheel's methods)
        return [p.replace(kind=p.POSITIONAL_OR_KEYWORD) if p.kind == p.POSITIONAL_ONLY else p
                for p in inspect.signature(f).parameters.values()][1:]

    assert inspect.signature(qtvpr.Online) == inspect.signature(ref.Online)
    for name in ("push", "push_many"):
        assert parameters(getattr(qtvpr.Online, name)) == parameters(getattr(ref.Online, name)), name
        assert getattr(qtvpr.Online, name).__doc__, name
    assert parameters(qtvpr.Calibration.save) == parameters(ref.Calibration.save)
    assert qtvpr.Online.__doc__ and qtvpr.Calibration.save.__doc__ and qtvpr.Calibration.load.__doc__
    cal = qtvpr.Calibration(CAL_S, CAL_GT)
    assert cal.defaults == {"k": 10, "precision": 1.0, "window": None, "gate": "none",
                            "sequence_gate": ref.SEQUENCE_DEFAULTS}
    assert cal.defaults == ref.Calibration(CAL_S, CAL_GT).defaults
    assert cal.db_size == 3
    o = qtvpr.Online(cal, window=2, min_window=2, precision=0.9)
    assert (o.k, o.precision, o.window, o.min_window, o.gate) == (10, 0.9, 2, 2, "none")
    assert o.calibration is cal
    assert repr(o) == "Online(k=10, precision=0.9, window=2, min_window=2, gate='none', matching='single', pushed=0)"
    # A |DB| x 1 matrix is a column; f32 and f64; any stride.
    a = qtvpr.Online(cal, window=2).push(DEP_S[:, :1])
    c = qtvpr.Online(cal, window=2).push(np.asfortranarray(DEP_S)[::-1, 0][::-1])
    assert a.threshold == c.threshold == pytest.approx(0.54, abs=1e-15)
    f32 = DEP_S[:, 0].astype(np.float32)  # its own values, widened exactly
    b = qtvpr.Online(cal, window=2).push(f32)
    assert b.threshold == ref.Online(ref.Calibration(CAL_S, CAL_GT), window=2).push(f32).threshold
    assert b.score == float(np.float32(0.7)) != 0.7
    # Python lists are arrays too.
    assert qtvpr.Online(cal, window=2).push([0.7, 0.3, 0.2]).threshold == a.threshold


def test_decisions_are_laid_out_from_the_core_record():
    """Every field of the core's record (``OnlineDecision.RECORD``) is an attribute of a
    decision, of its kind's type (``None`` for a gate's field without the gate), and a
    column of ``OnlineDecisions``, an array of its kind's dtype: a field the binding
    missed fails here."""
    types = {"count": int, "real": float, "flag": bool}
    dtypes = {"count": np.int64, "real": np.float64, "flag": np.bool_}
    record = qtvpr.OnlineDecision.RECORD
    assert tuple(name for name, _, _, gate in record if gate == "none") == qtvpr.OnlineDecision.FIELDS
    assert tuple(name for name, _, _, gate in record if gate == "margin") == qtvpr.OnlineDecision.GATE_FIELDS
    assert tuple(column for _, column, _, _ in record) == qtvpr.OnlineDecisions.COLUMNS
    for gate in ("none", "margin"):
        o = wheel_online(window=2, gate=gate)
        one, many = o.push(DEP_S[:, 0]), o.push_many(DEP_S[:, 1:])
        for name, column, kind, field_gate in record:
            value, values = getattr(one, name), getattr(many, column)
            if field_gate in ("none", gate):
                assert type(value) is types[kind], (gate, name)
                assert values.dtype == dtypes[kind] and values.shape == (3,), (gate, column)
            else:
                assert value is None and values is None, (gate, name)


def test_wheel_online_bad_input():
    cal = qtvpr.Calibration(CAL_S, CAL_GT)
    with pytest.raises(ValueError, match="window is not given and the calibration sets none"):
        qtvpr.Online(cal)
    with pytest.raises(ValueError, match="window must be >= 1"):
        qtvpr.Online(cal, window=0)
    with pytest.raises(ValueError, match=r"min_window must be between 1 and the window \(2\), got 3"):
        qtvpr.Online(cal, window=2, min_window=3)
    with pytest.raises(ValueError, match=r"min_window must be between 1 and the window \(2\), got 0"):
        qtvpr.Online(cal, window=2, min_window=0)
    with pytest.raises(ValueError, match="k must be >= 1"):
        qtvpr.Online(cal, k=0, window=2)
    with pytest.raises(ValueError, match="k must be >= 1"):
        qtvpr.Online(cal, k=-1, window=2)
    with pytest.raises(ValueError, match="precision must be in"):
        qtvpr.Online(cal, precision=1.5, window=2)
    with pytest.raises(TypeError):
        qtvpr.Online(CAL_S, window=2)
    o = qtvpr.Online(cal, window=2)
    with pytest.raises(ValueError, match=r"column: deployment query 0 has 4 scores but the calibration has 3"):
        o.push(np.ones(4))
    with pytest.raises(ValueError, match=r"column must hold one query's scores.*got shape \(3, 2\)"):
        o.push(np.ones((3, 2)))
    with pytest.raises(ValueError, match=r"column must hold one query's scores.*got shape \(\)"):
        o.push(np.float64(1.0))
    with pytest.raises(ValueError, match=r"column \(deployment query 0\) contains NaN at row 1"):
        o.push(np.array([0.1, np.nan, 0.2]))
    with pytest.raises(TypeError, match="column must be a float32 or float64 array, got int64"):
        o.push(np.ones(3, dtype=np.int64))
    assert o.pushed == 0 and o.threshold is None  # errors leave the state unchanged
    bad = DEP_S.copy()
    bad[2, 2] = np.inf
    with pytest.raises(ValueError, match="s_val: deployment similarity contains inf at row 2, column 2"):
        o.push_many(bad)
    assert o.pushed == 2  # the queries before the bad one are kept
    # Positions within the argument, as the caller stored it, on a later call too.
    with pytest.raises(ValueError, match="s_val: deployment similarity contains inf at row 2, column 2"):
        o.push_many(bad.T, query_major=True)
    assert o.pushed == 4
    with pytest.raises(ValueError, match=r"s_val: deployment query 4 has 2 scores but the calibration has 3"):
        o.push_many(np.ones((2, 2)))
    with pytest.raises(TypeError, match="s_val must be a float32 or float64 array"):
        o.push_many(np.ones((3, 2), dtype=np.int32))
    assert len(o.push_many(np.ones((3, 0)))) == 0 and o.pushed == 4  # no query, no decision
    # The reference decides the same 4 queries (d0, d1, then d0, d1 of bad.T) alike.
    r = ref.Online(ref.Calibration(CAL_S, CAL_GT), window=2)
    want = r.push_many(np.hstack([DEP_S[:, :2], DEP_S[:, :2]]))
    assert o.threshold == pytest.approx(want.thresholds[-1], abs=1e-15)


# ---------------------------------------------------------------------------------------
# The calibration file and pickling
# ---------------------------------------------------------------------------------------


def real_calibration(shared_data, technique="CoHOG", dataset="vprbench-spedtest", matching="single"):
    s, gt = load_matrix(shared_data, dataset, technique)
    n_cal = s.shape[1] // 10
    return s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:], matching


@pytest.mark.parametrize("technique", ["CoHOG", "NetVLAD", "AMOSNet"])  # float32, float32, float64
@pytest.mark.parametrize("matching", ["single", "multi"])
def test_save_load_is_bit_identical(shared_data, tmp_path, technique, matching):
    s_cal, gt_cal, s_val, _ = real_calibration(shared_data, technique)
    soft = soft_of(gt_cal)
    cal = qtvpr.Calibration(s_cal.T, gt_cal.T, gt_soft=soft.T, matching=matching, query_major=True)
    path = tmp_path / "cal.npz"
    cal.save(path, k=7, precision=0.9, window=6)
    loaded = qtvpr.Calibration.load(path)
    assert loaded.defaults == {"k": 7, "precision": 0.9, "window": 6, "gate": "none",
                               "sequence_gate": ref.SEQUENCE_DEFAULTS}
    assert (loaded.matching, len(loaded), loaded.db_size) == (matching, len(cal), cal.db_size)
    a = qtvpr.Online(cal, k=7, precision=0.9, window=6).push_many(s_val)
    b = qtvpr.Online(loaded).push_many(s_val)  # the file's params
    for name in ("thresholds", "quantiles", "query_quantiles", "weights", "best", "score", "accept", "accepted"):
        if getattr(a, name) is not None:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    # The batch transfer too, with the file's params as its defaults (semantics §12).
    np.testing.assert_array_equal(cal.transfer(s_val, k=7, precision=0.9, segment_size=6).thresholds,
                                  loaded.transfer(s_val, segment_size=6).thresholds)
    assert cal.threshold(0.9) == loaded.threshold()
    # np.load reads it without pickle: the scores in their own dtype, DB x Q.
    with np.load(path, allow_pickle=False) as z:
        assert sorted(z.files) == ["gt", "gt_soft", "meta", "s"]
        assert z["s"].dtype == s_cal.dtype and np.array_equal(z["s"], s_cal)
        assert z["gt"].dtype == bool and np.array_equal(z["gt"], gt_cal)
        assert np.array_equal(z["gt_soft"], soft)
        meta = json.loads(str(z["meta"][()]))
    assert meta["format"] == "qtvpr-calibration" and meta["version"] == 1
    assert meta["matching"] == matching
    assert meta["params"] == {"k": 7, "precision": 0.9, "window": 6, "gate": "none"}
    assert meta["qtvpr"] == qtvpr.__version__
    # The reference reads the wheel's file, and the wheel the reference's, alike.
    r = ref.Calibration.load(path)
    assert r.defaults == loaded.defaults
    assert_decisions_equal(b, ref.Online(r).push_many(s_val))
    ref.Calibration(s_cal, gt_cal, gt_soft=soft, matching=matching).save(tmp_path / "ref.npz", k=7, precision=0.9,
                                                                          window=6)
    c = qtvpr.Online(qtvpr.Calibration.load(tmp_path / "ref.npz")).push_many(s_val)
    np.testing.assert_array_equal(c.thresholds, b.thresholds)


def test_save_details(tmp_path):
    cal = qtvpr.Calibration(CAL_S, CAL_GT)
    # The name is kept as given, str or PathLike; no soft ground truth, no gt_soft.
    cal.save(str(tmp_path / "plain"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain"]
    with np.load(tmp_path / "plain", allow_pickle=False) as z:
        assert sorted(z.files) == ["gt", "meta", "s"]
        assert json.loads(str(z["meta"][()]))["params"] == {"k": 10, "precision": 1.0, "window": None, "gate": "none"}
    loaded = qtvpr.Calibration.load(str(tmp_path / "plain"))
    assert loaded.defaults["window"] is None
    with pytest.raises(ValueError, match="window is not given and the calibration sets none"):
        qtvpr.Online(loaded)
    for kwargs, message in ((dict(k=0), "k must be >= 1"), (dict(precision=0.0), "precision must be in"),
                            (dict(window=0), "window must be >= 1")):
        with pytest.raises(ValueError, match=message):
            cal.save(tmp_path / "bad.npz", **kwargs)
    with pytest.raises(FileNotFoundError, match="no-such-dir"):
        cal.save(tmp_path / "no-such-dir" / "cal.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain"]  # nothing half-written


def test_pickle_round_trip(shared_data):
    s_cal, gt_cal, s_val, _ = real_calibration(shared_data, "NetVLAD", matching="multi")
    cal = qtvpr.Calibration(s_cal, gt_cal, gt_soft=soft_of(gt_cal), matching="multi")
    back = pickle.loads(pickle.dumps(cal))
    assert isinstance(back, qtvpr.Calibration) and back is not cal
    assert (back.matching, len(back), back.db_size, back.defaults) == ("multi", len(cal), cal.db_size, cal.defaults)
    a = qtvpr.Online(cal, window=6).push_many(s_val)
    b = qtvpr.Online(back, window=6).push_many(s_val)
    np.testing.assert_array_equal(a.thresholds, b.thresholds)
    np.testing.assert_array_equal(a.accepted, b.accepted)
    # A restored calibration pickles again, to the same results.
    again = pickle.loads(pickle.dumps(back))
    np.testing.assert_array_equal(qtvpr.Online(again, window=6).push_many(s_val).thresholds, a.thresholds)


def thresholds_in_worker(cal, s_val):
    """Run in a worker process: the online thresholds of ``s_val`` (window 6)."""
    return qtvpr.Online(cal, window=6).push_many(s_val).thresholds


def test_calibration_goes_to_a_worker_process(shared_data):
    s_cal, gt_cal, s_val, _ = real_calibration(shared_data, "HOG")
    cal = qtvpr.Calibration(s_cal, gt_cal)
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        got = pool.submit(thresholds_in_worker, cal, s_val[:, :40]).result(timeout=120)
    np.testing.assert_array_equal(got, thresholds_in_worker(cal, s_val[:, :40]))


def test_pickle_keeps_loaded_defaults(tmp_path):
    qtvpr.Calibration(CAL_S, CAL_GT, matching="multi").save(tmp_path / "c.npz", k=3, precision=0.75, window=4)
    back = pickle.loads(pickle.dumps(qtvpr.Calibration.load(tmp_path / "c.npz")))
    assert back.defaults == {"k": 3, "precision": 0.75, "window": 4, "gate": "none",
                             "sequence_gate": ref.SEQUENCE_DEFAULTS}
    assert qtvpr.Online(back).window == 4


#: Wheel messages for BAD_FILES (the exception class is the reference's).
WHEEL_MESSAGES = {
    "missing-s": "has no array s; a calibration file holds s, gt and meta",
    "missing-gt": "has no array gt",
    "missing-meta": "has no array meta",
    "gt-shape": "ground truth shape 2x2 does not match calibration similarity shape 3x2",
    "soft-shape": "soft ground truth shape 3x1 does not match ground truth shape 3x2",
    "s-1d": r"\(array s\) holds a 1-D array",
    "s-nan": "calibration similarity contains NaN at row 0, column 0",
    "s-int": r"\(array s\) has dtype <i8; expected float32 or float64",
    "gt-int": r"\(array gt\) has dtype \|i1; expected bool",
    "soft-int": r"\(array gt_soft\) has dtype \|u1; expected bool",
    "no-params": "malformed meta: missing field `params`",
    "params-no-k": "malformed meta: missing field `k`",
    "format": "its meta format is 'other', expected 'qtvpr-calibration'",
    "version": "has calibration file version 2",
    "matching": "has meta matching 'both'",
    "meta-json": "has a meta that is not JSON",
    "meta-list": "has a meta without a format string",
    "meta-bytes": r"\(array meta\) holds an array of dtype \|S1",
    "params-k": "bad meta params: k must be >= 1, got 0",
    "params-precision": r"bad meta params: precision must be in \(0, 1\]",
    "params-window": "malformed meta: invalid type",
}


@pytest.mark.parametrize("kind", list(BAD_FILES))
def test_wheel_bad_calibration_files(tmp_path, kind):
    arrays, exc, _ = BAD_FILES[kind]
    arrays = dict(arrays)
    meta = arrays.pop("meta", None)
    if kind == "meta-bytes":
        arrays["meta"] = np.array([b"x"])
    path = write_npz(tmp_path / f"{kind}.npz", meta, **arrays)
    with pytest.raises(exc, match=WHEEL_MESSAGES[kind]) as info:
        qtvpr.Calibration.load(path)
    assert str(path) in str(info.value)


def test_wheel_unreadable_calibration_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="absent.npz"):
        qtvpr.Calibration.load(tmp_path / "absent.npz")
    with pytest.raises(IsADirectoryError):
        qtvpr.Calibration.load(tmp_path)
    good = tmp_path / "good.npz"
    qtvpr.Calibration(CAL_S, CAL_GT).save(good)
    data = good.read_bytes()
    corrupt = bytearray(data)
    for i in range(60, 90):
        corrupt[i] ^= 0xFF
    cases = {
        "truncated.npz": data[: len(data) // 2],
        "garbage.npz": b"this is not a zip archive at all",
        "empty.npz": b"",
        "corrupt.npz": bytes(corrupt),
    }
    for name, payload in cases.items():
        p = tmp_path / name
        p.write_bytes(payload)
        with pytest.raises(ValueError, match=str(p)):
            qtvpr.Calibration.load(p)
    npy = tmp_path / "single.npy"
    np.save(npy, CAL_S)
    with pytest.raises(ValueError, match=str(npy)):
        qtvpr.Calibration.load(npy)
    with pytest.raises(ValueError, match="pickled calibration"):
        qtvpr.Calibration._from_bytes(data[:100])
    # Every prefix of a good file is refused cleanly, never a crash.
    for n in range(0, len(data), max(1, len(data) // 40)):
        p = tmp_path / "prefix.npz"
        p.write_bytes(data[:n])
        with pytest.raises(ValueError):
            qtvpr.Calibration.load(p)


@pytest.mark.parametrize("matching", ["single", "multi"])
@pytest.mark.parametrize("technique", ["CoHOG", "HOG"])
def test_evaluate_online_method_equals_reference(shared_data, technique, matching):
    """The online method inside the protocol, with a segment size other than the
    default and soft ground truth (test_evaluate.py covers the defaults)."""
    s, gt = load_matrix(shared_data, "vprbench-spedtest", technique)
    kwargs = dict(methods=["quantile-transfer-online", "oracle"], matching=matching, precision=0.9,
                  segment_size=11, gt_soft=soft_of(gt))
    want = ref.evaluate(s, gt, **kwargs)["methods"]
    got = qtvpr.evaluate(s.T, gt.T, **{**kwargs, "gt_soft": soft_of(gt).T}, query_major=True)["methods"]
    assert list(got) == list(want)
    for name in want:
        g, w = got[name], want[name]
        for key in ("segments_counted", "segments_skipped"):
            assert g[key] == w[key]
        for key in ("pct_segs", "avg_recall", "threshold_mse"):
            assert g[key] == pytest.approx(w[key], abs=1e-9)
        for gs, ws in zip(g["segments"], w["segments"], strict=True):
            assert (gs["tp"], gs["fp"], gs["positives"], gs["meets"]) == (ws["tp"], ws["fp"], ws["positives"],
                                                                          ws["meets"])
            assert gs["threshold"] == pytest.approx(ws["threshold"], abs=1e-9)


# ---------------------------------------------------------------------------------------
# qtvpr-cli calibrate + stream, held to the reference
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def stream_cli(cli):
    """The CLI, if it has the online commands (they come with the core's online branch)."""
    if run_cli(cli, "stream", "--help").returncode != 0:
        pytest.skip("this qtvpr-cli has no stream command")
    return cli


@pytest.mark.parametrize(
    ("dataset", "technique", "matching", "precision", "window", "min_window", "soft", "query_major"),
    [
        ("vprbench-corridor", "AMOSNet", "single", 1.0, 2, 1, False, False),
        ("vprbench-corridor", "CoHOG", "multi", 0.9, 150, 3, True, True),  # window > |Qval|
        ("vprbench-spedtest", "NetVLAD", "single", 0.9, 1, 1, True, True),
        ("vprbench-spedtest", "HOG", "multi", 1.0, 7, 7, False, False),
    ],
)
def test_cli_stream_equals_reference(stream_cli, shared_data, tmp_path, dataset, technique, matching,
                                     precision, window, min_window, soft, query_major):
    s, gt = load_matrix(shared_data, dataset, technique)
    n_cal = s.shape[1] // 10
    s_cal, gt_cal, s_val = s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:]
    gt_soft = soft_of(gt_cal) if soft else None
    orient = (lambda a: a.T) if query_major else (lambda a: a)
    files = {}
    for name, a in (("cal", s_cal), ("val", s_val)):
        files[name] = tmp_path / f"{name}.npy"
        np.save(files[name], orient(a))
    gt_file = tmp_path / "gt.npz"
    np.savez(gt_file, **{"GThard": orient(gt_cal), **({"GTsoft": orient(gt_soft)} if soft else {})})
    cal_file = tmp_path / "cal.npz"
    qm = ["--query-major"] if query_major else []
    res = run_cli(stream_cli, "calibrate", "--cal", files["cal"], "--cal-gt", gt_file, "--matching", matching,
                  "--k", 10, "--precision", precision, "--window", window, *qm, "--output", cal_file)
    assert res.returncode == 0, res.stderr
    # Options left out take the file's params (here: all but min_window).
    res = run_cli(stream_cli, "stream", "--calibration", cal_file, "--val", files["val"], "--min-window", min_window,
                  *qm, "--quiet")
    assert res.returncode == 0, res.stderr
    lines = [json.loads(line) for line in res.stdout.splitlines()]
    want = ref.Online(ref.Calibration(s_cal, gt_cal, gt_soft=gt_soft, matching=matching), k=10, precision=precision,
                      window=window, min_window=min_window).push_many(s_val)
    assert len(lines) == len(want) == s_val.shape[1]
    assert [line["query"] for line in lines] == want.queries.tolist()
    for key, name in (("threshold", "thresholds"), ("quantile", "quantiles"),
                      ("query_quantile", "query_quantiles"), ("weight", "weights")):
        assert_close([line[key] for line in lines], getattr(want, name), key)
    # The eleven fields of the decision record, in both matching modes (the confidence
    # null in multi matching).
    assert all(list(line) == ["query", "query_quantile", "weight", "quantile", "threshold", "best", "score",
                              "accepted", "accept", "confidence", "confidence_lower95"] for line in lines)
    confidences = [math.nan if line["confidence"] is None else line["confidence"] for line in lines]
    np.testing.assert_allclose(confidences, want.confidences, rtol=0, atol=1e-9)
    assert all((line["confidence"] is None) == (matching == "multi") for line in lines)
    assert [line["best"] for line in lines] == want.best.tolist()
    assert_close([line["score"] for line in lines], want.score, "score")
    assert [line["accepted"] for line in lines] == want.accepted.tolist()
    assert [line["accept"] for line in lines] == want.accept.tolist() == (want.accepted > 0).tolist()
    # The CLI's file is the wheel's and the reference's too.
    assert ref.Calibration.load(cal_file).defaults == {"k": 10, "precision": precision, "window": window,
                                                       "gate": "none", "sequence_gate": ref.SEQUENCE_DEFAULTS}
    got = qtvpr.Online(qtvpr.Calibration.load(cal_file), min_window=min_window).push_many(s_val)
    np.testing.assert_array_equal(got.thresholds, [line["threshold"] for line in lines])


def test_a_window_no_allocation_could_hold_is_refused(tmp_path, cli):
    """The window's state is window x |DB| float64 scores: one that no allocation could
    hold (above (2**63 - 1) // 8 // |DB|) is a ValueError (exit 2 in the CLI) naming the
    window, never a state that grows until memory runs out. |DB| = 3 here:
    (2**63 - 1) // 8 = 1152921504606846975, // 3 = 384307168202282325."""
    cal = qtvpr.Calibration(CAL_S, CAL_GT)
    largest = 384307168202282325
    with pytest.raises(ValueError, match=f"window {largest + 1} is too large.*at most {largest}"):
        qtvpr.Online(cal, window=largest + 1)
    with pytest.raises(ValueError, match="window 9223372036854775807 is too large"):
        qtvpr.Online(cal, window=2**63 - 1)
    # The largest is accepted and decides as any window longer than the stream.
    got = qtvpr.Online(cal, window=largest).push_many(DEP_S)
    np.testing.assert_array_equal(got.thresholds, qtvpr.Online(cal, window=4).push_many(DEP_S).thresholds)
    cal.save(tmp_path / "cal.npz")
    np.save(tmp_path / "dep.npy", DEP_S)
    r = run_cli(cli, "stream", "--calibration", tmp_path / "cal.npz", "--val", tmp_path / "dep.npy",
                "--window", str(2**64 - 1))
    assert r.returncode == 2 and r.stdout == ""
    assert "window 18446744073709551615 is too large" in r.stderr, r.stderr


def test_a_resumed_state_decides_as_the_whole_stream():
    """The Rust scenario of crates/qtvpr/tests/blocks.rs: a fresh state resumed at
    query j from the min(j, window - 1) queries before it decides queries j.. as the
    whole stream does, warm-up and numbering included; errors name the stream's
    queries (what qtvpr.dask schedules blocks with)."""
    rng = np.random.default_rng(3)
    s_cal, s_val = rng.random((6, 8)), rng.random((6, 12))
    gt = np.arange(6)[:, None] == np.arange(8)[None, :] % 6
    for matching in ("single", "multi"):
        cal = qtvpr.Calibration(s_cal, gt, matching=matching)
        params = {"k": 3, "precision": 0.75, "window": 4, "min_window": 3}
        whole = qtvpr.Online(cal, **params).push_many(s_val)
        assert whole.quantiles[1] == 1.0 and whole.accepted[1] == 0  # the warm-up
        for first, before in ((1, slice(0, 1)), (5, slice(2, 5)), (0, slice(0, 0))):
            state = qtvpr.Online(cal, **params)
            state._resume(first, s_val[:, before])
            assert state.pushed == first
            got = state._push_stream(s_val[:, first:])
            for name in ("queries", "query_quantiles", "weights", "quantiles", "thresholds", "best", "score",
                         "accepted", "accept"):
                np.testing.assert_array_equal(getattr(got, name), getattr(whole, name)[first:], err_msg=name)
    state = qtvpr.Online(cal, window=4)
    message = "resume at query 5 with a window of 4 takes the 3 queries before it, got 2"
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        state._resume(5, s_val[:, 0:2])
    bad = s_val.copy()
    bad[4, 3] = np.inf
    message = "s_val: deployment similarity contains inf at row 4, column 3; scores must be finite"
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        state._resume(5, bad[:, 2:5])
    assert state.pushed == 0
