"""Online thresholds (SPEC section 11) and the calibration file (SPEC section 12).

First the NumPy reference alone: hand-computed windows, warm-up and the online method
of the evaluation protocol, each value worked out in the comment beside it; then the
reference's own definition (theta_j is the batch transfer of the window's columns) on
random and real data; then its calibration file.
"""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qtvpr import reference as ref

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
        assert (d.best, d.score, d.accept, d.accepted) == (best, score, True, None)
        assert d.accepted_indices.tolist() == [best]
        assert o.threshold == d.threshold and o.pushed == j + 1
    # Multi matching, same thresholds: d0 accepts 0.7 only; d1 0.6 only (0.5 < 0.56);
    # d2 both 0.4s (rows 0 and 1).
    o = online("multi", window=1)
    for j, indices in enumerate([[0], [1], [0, 1]]):
        d = o.push(DEP_S[:, j])
        assert d.threshold == pytest.approx(want[j][0], abs=1e-15)
        assert (d.best, d.score, d.accept) == (None, None, None)
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
    assert many.accepted is None
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
    assert multi.best is None and multi.accept is None and multi.score is None


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
    assert list(ref.evaluate(s, gt, cal_queries=2, segment_size=2)["methods"]) == list(ref.METHODS)


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
    d = shared_data / "vprbench-corridor"
    s, gt = np.load(d / f"S_{technique}.npy"), np.load(d / "GT.npy")
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
            "params": {"k": 3, "precision": 0.9, "window": 2},
        }
        loaded = ref.Calibration.load(path)
        assert loaded.defaults == {"k": 3, "precision": 0.9, "window": 2}
        assert loaded.matching == "multi" and len(loaded) == 2
        a = ref.Online(cal, k=3, precision=0.9, window=2).push_many(DEP_S)
        b = ref.Online(loaded).push_many(DEP_S)  # the file's params
        assert a.thresholds.tolist() == b.thresholds.tolist()
        assert a.accepted.tolist() == b.accepted.tolist()
    # No soft ground truth: no gt_soft array; window None is written as null.
    ref.Calibration(CAL_S, CAL_GT).save(tmp_path / "plain.npz")
    with np.load(tmp_path / "plain.npz", allow_pickle=False) as z:
        assert sorted(z.files) == ["gt", "meta", "s"]
        assert json.loads(str(z["meta"]))["params"] == {"k": 10, "precision": 1.0, "window": None}
    assert ref.Calibration.load(tmp_path / "plain.npz").defaults == {"k": 10, "precision": 1.0, "window": None}


def write_npz(path: Path, meta_json=None, **arrays) -> Path:
    """An .npz of ``arrays``, with ``meta_json`` (a dict or a string) as its ``meta``."""
    if meta_json is not None:
        arrays["meta"] = np.array(meta_json if isinstance(meta_json, str) else json.dumps(meta_json))
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


META = {"format": "qtvpr-calibration", "version": 1, "matching": "single",
        "params": {"k": 10, "precision": 1.0, "window": 28}}
GOOD = dict(s=CAL_S, gt=CAL_GT)

#: Bad calibration files: (what is written, the exception, a part of its message).
BAD_FILES = {
    "missing-s": (dict(gt=CAL_GT, meta=META), ValueError, "missing array 's'"),
    "missing-gt": (dict(s=CAL_S, meta=META), ValueError, "missing array 'gt'"),
    "missing-meta": (dict(GOOD), ValueError, "missing array 'meta'"),
    "gt-shape": (dict(s=CAL_S, gt=CAL_GT[:2], meta=META), ValueError, "gt shape 2x2 does not match s shape 3x2"),
    "soft-shape": (dict(GOOD, gt_soft=CAL_GT[:, :1], meta=META), ValueError, "gt_soft shape 3x1"),
    "s-1d": (dict(s=CAL_S[:, 0], gt=CAL_GT, meta=META), ValueError, "s must be a 2-D matrix"),
    "s-nan": (dict(s=np.where(CAL_S > 0.5, np.nan, CAL_S), gt=CAL_GT, meta=META), ValueError, "s contains NaN at row 0, column 0"),
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
    "params-precision": (dict(GOOD, meta={**META, "params": {"k": 1, "precision": 2.0}}), ValueError, "precision must be in"),
    "params-window": (dict(GOOD, meta={**META, "params": {"k": 1, "precision": 1.0, "window": "28"}}), ValueError, "window must be an integer"),
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
