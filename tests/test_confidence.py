"""Confidence (semantics §14) in Python: the NumPy reference's PA-score, its two
pooling passes and its centred isotonic map by hand, and their properties; then the
wheel against the reference (its blocks, the batch transfer's ``query_confidences``,
``Online``) and against the CLI's ``stream``, on the embedded Corridor data and, where
present, the real matrices of ``../shared/data``.

The same scenarios are tested in Rust (crates/qtvpr/src/signals/confidence.rs,
crates/qtvpr/tests/confidence.rs, crates/qtvpr-cli/tests/online.rs).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import qtvpr
from qtvpr import reference as ref
from test_cli import run_cli

CORRIDOR = Path(__file__).resolve().parents[1] / "data" / "corridor"
DATASETS = {"corridor": "vprbench-corridor", "spedtest": "vprbench-spedtest"}
TECHNIQUES = ["AlexNet_VPR", "CALC", "HOG", "NetVLAD", "denseVLAD"]
MULTI_WHY = "confidence needs single matching"


def blocks(pairs):
    r = np.array([p[0] for p in pairs], dtype=np.float64)
    c = np.array([p[1] for p in pairs], dtype=bool)
    return [(round(centre, 12), n, x) for centre, n, x in ref._pooled_blocks(r, c)]


def close(a, b, tol=1e-9):
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    assert a.shape == b.shape
    assert np.allclose(a, b, rtol=tol, atol=tol, equal_nan=True), np.nanmax(np.abs(a - b))


# ---------------------------------------------------------------------------------------
# The reference by hand
# ---------------------------------------------------------------------------------------


def test_pa_score_by_hand():
    # The Rust scenario (crates/qtvpr/src/signals/confidence.rs, pa_score_by_hand).
    # Columns: s1 = 0.875, s2 = 0.5 gives sqrt(0.25) / 1; the largest twice gives 1;
    # both at or above 1 (d = 0) give 1; only the best at 1 gives 0; below -1,
    # sqrt(4) / sqrt(8).
    s = np.array([[0.875, 0.3, 1.5, 1.0, -1.0], [0.5, 0.3, 1.2, 0.5, -3.0], [0.1, 0.2, 0.0, 0.0, -5.0]])
    close(ref._pa_scores(s), [0.5, 1.0, 1.0, 0.0, 2 / math.sqrt(8)], 1e-15)


def test_pa_score_at_the_extremes_of_float32_and_float64():
    # The Rust scenario (pa_score_is_finite_at_the_extremes_of_f32_and_f64), d computed
    # as sqrt((1 - s) / 2): -2^1021 gives sqrt(2^1020) = 2^510, -2^1023 gives 2^511, so
    # 0.5 (2 - 2 s overflowed for -2^1023: 0, and inf / inf = NaN for two of them);
    # -f64::MAX twice: 1; the best at f64::MAX (d1 = 0): 0. In float32, -2^125 and
    # -2^127: 2^62 / 2^63 = 0.5; f32::MIN twice: 1.
    big = np.finfo(np.float64).max
    s = np.array([[-(2.0**1021), -(2.0**1023), -big, big], [-(2.0**1023), -(2.0**1023), -big, -big]])
    assert ref._pa_scores(s).tolist() == [0.5, 1.0, 1.0, 0.0]
    low = float(np.finfo(np.float32).min)
    s = np.array([[-(2.0**125), low], [-(2.0**127), low]], dtype=np.float32).astype(np.float64)
    assert ref._pa_scores(s).tolist() == [0.5, 1.0]


def test_a_calibration_query_of_extreme_scores_leaves_every_confidence_finite(cli, tmp_path):
    # Issue 49: the embedded Corridor with its first calibration query's scores all
    # -f64::MAX (finite, accepted). Its PA-score is 1, not NaN, so no NaN centre enters
    # the map: the wheel equals the reference and every confidence is a number, in
    # Online, the batch transfer, evaluate (Brier and ECE) and the CLI's stream.
    s = np.concatenate([np.load(CORRIDOR / "cal_S.npy"), np.load(CORRIDOR / "deploy_S.npy")], axis=1)
    gt = np.concatenate([np.load(CORRIDOR / "cal_GT.npy"), np.load(CORRIDOR / "deploy_GT.npy")], axis=1)
    s[:, 0] = -np.finfo(np.float64).max
    cal, d = check_parity(s[:, :11], gt[:, :11], s[:, 11:])
    assert all(math.isfinite(centre) for centre, _, _ in cal.confidence_blocks())
    assert np.isfinite(d.confidences).all() and np.isfinite(d.confidences_lower95).all()
    got = qtvpr.evaluate(s, gt, methods=["oracle"])["confidence"]
    assert_same_signals(got, ref.evaluate(s, gt, methods=["oracle"])["confidence"])
    assert got["signals"]["confidence"]["brier"] is not None and got["signals"]["confidence"]["ece"] is not None
    cal.save(tmp_path / "cal.npz", window=7)
    np.save(tmp_path / "val.npy", s[:, 11:])
    out = run_cli(cli, "stream", "--calibration", str(tmp_path / "cal.npz"), "--val", str(tmp_path / "val.npy"))
    assert out.returncode == 0, out.stderr
    close([json.loads(line)["confidence"] for line in out.stdout.splitlines()], d.confidences)


def test_pooling_by_hand():
    # The Rust scenario (two_passes_of_pooling). Descending PA-score: 0.9 (0 of 1), 0.5
    # (1 of 10): apart by x/n (0 < 0.1), pooled by (x + 1) / (n + 2) (1/3 >= 2/12).
    assert blocks([(0.9, 0), (0.5, 1)] + [(0.5, 0)] * 9) == [(round(5.9 / 11, 12), 11, 1)]
    # Equal Laplace values merge: 0 of 1 and 1 of 4 are 1/3 and 2/6.
    assert blocks([(0.9, 0), (0.4, 1)] + [(0.4, 0)] * 3) == [(0.5, 5, 1)]
    # A tie is one point, pooled whole: (0.8: 1/1) and (0.2: 0/2) violate, 1 of 3.
    assert blocks([(0.8, 1), (0.2, 0), (0.2, 0)]) == [(0.4, 3, 1)]
    # Increasing values stay apart: 1/4, 2/4, 4/5 by Laplace.
    pairs = [(0.8, 0), (0.8, 0), (0.6, 1), (0.6, 0), (0.1, 1), (0.1, 1), (0.1, 1)]
    assert blocks(pairs) == [(0.8, 2, 0), (0.6, 2, 1), (0.1, 3, 3)]
    # One pair: one block.
    assert blocks([(0.5, 1)]) == [(0.5, 1, 1)]


def test_map_by_hand():
    # The Rust scenarios (one_pair_goes_on_to_its_bounds,
    # linear_between_centres_and_the_lower_bound_of_the_less_confident).
    one = [(0.5, 1, 1)]  # 2/3 at 0.5; on to 0.05 (0.05^(1/1)) at 1 and to 1 at 0
    assert ref._confidence_of(one, 0.5)[0] == 2 / 3
    assert ref._confidence_of(one, 0.75)[0] == pytest.approx((0.05 + 2 / 3) / 2, abs=1e-12)
    assert ref._confidence_of(one, 0.25)[0] == pytest.approx((2 / 3 + 1) / 2, abs=1e-12)
    assert ref._confidence_of(one, 0.0)[0] == 1.0
    assert all(ref._confidence_of(one, r)[1] == pytest.approx(0.05, abs=1e-15) for r in (0.0, 0.3, 0.9, 1.0))
    wrong = [(0.5, 1, 0)]  # 1/3, from 0 to 0.95
    assert ref._confidence_of(wrong, 1.0) == (0.0, 0.0)
    assert ref._confidence_of(wrong, 0.0)[0] == pytest.approx(0.95, abs=1e-15)
    b = [(0.8, 2, 0), (0.6, 2, 1), (0.1, 3, 3)]  # knots (1: 0), (0.8: 1/4), (0.6: 1/2), (0.1: 4/5), (0: 1)
    assert ref._confidence_of(b, 1.0) == (0.0, 0.0)
    assert ref._confidence_of(b, 0.9)[0] == pytest.approx(0.125, abs=1e-12)
    assert ref._confidence_of(b, 0.7) == (pytest.approx(0.375, abs=1e-12), 0.0)
    one_of_two = 1 - math.sqrt(0.95)
    assert ref._confidence_of(b, 0.35) == (pytest.approx(0.65, abs=1e-12), pytest.approx(one_of_two, abs=1e-15))
    assert ref._confidence_of(b, 0.05) == (pytest.approx(0.9, abs=1e-12), pytest.approx(0.05 ** (1 / 3), abs=1e-12))
    assert ref._confidence_of(b, 0.0)[0] == 1.0
    nan = ref._confidence_of([], 0.5)
    assert math.isnan(nan[0]) and math.isnan(nan[1])


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    st.lists(st.tuples(st.integers(0, 10), st.booleans()), min_size=1, max_size=40),
    st.lists(st.integers(0, 1000), min_size=2, max_size=20, unique=True),
)
def test_reference_properties(pairs, probes):
    # The Rust property (strictly_decreasing_bounded_and_lower_below).
    b = ref._pooled_blocks(np.array([r / 10 for r, _ in pairs]), np.array([c for _, c in pairs], dtype=bool))
    assert sum(n for _, n, _ in b) == len(pairs) and sum(x for *_, x in b) == sum(c for _, c in pairs)
    values = [(x + 1) / (n + 2) for _, n, x in b]
    assert all(a < z for a, z in zip(values, values[1:], strict=False))  # maximal, increasing
    assert all(a[0] > z[0] for a, z in zip(b, b[1:], strict=False))  # centres descending
    last = math.inf
    for r in sorted(p / 1000 for p in probes):  # apart by 1e-3, far above rounding
        c, lower = ref._confidence_of(b, r)
        assert 0.0 <= lower <= c <= 1.0
        assert c < last  # a higher PA-score, a strictly lower confidence
        last = c


# ---------------------------------------------------------------------------------------
# The wheel against the reference
# ---------------------------------------------------------------------------------------


def assert_same_blocks(got, want):
    assert [(n, x) for _, n, x in got] == [(n, x) for _, n, x in want]
    close([m for m, *_ in got], [m for m, *_ in want], 1e-12)


def check_parity(s_cal, gt_cal, s_val, window=7, segment_size=10):
    cal, want_cal = qtvpr.Calibration(s_cal, gt_cal), ref.Calibration(s_cal, gt_cal)
    assert_same_blocks(cal.confidence_blocks(), want_cal.confidence_blocks())
    for gate in ("none", "margin"):
        got = cal.transfer(s_val, segment_size=segment_size, gate=gate)
        want = want_cal.transfer(s_val, segment_size=segment_size, gate=gate)
        close(got.query_confidences, want.query_confidences)
        close(got.query_confidences_lower95, want.query_confidences_lower95)
        d = qtvpr.Online(cal, window=window, gate=gate).push_many(s_val)
        w = ref.Online(want_cal, window=window, gate=gate).push_many(s_val)
        close(d.confidences, w.confidences)
        close(d.confidences_lower95, w.confidences_lower95)
        # The batch and the stream give each query the same confidence, whatever the gate.
        assert np.array_equal(d.confidences, got.query_confidences)
        assert np.all(d.confidences_lower95 <= d.confidences)
        one = qtvpr.Online(cal, window=window, gate=gate).push(s_val[:, 0])
        assert (one.confidence, one.confidence_lower95) == (d.confidences[0], d.confidences_lower95[0])
    return cal, d


def test_wheel_equals_reference_on_the_embedded_corridor():
    # The embedded deployment half calibrates (83 of its 100 best matches are right, nine
    # blocks); the embedded calibration half is decided. And the other way round: the
    # calibration's 11 best matches are all right, one block.
    s_val, s_cal = np.load(CORRIDOR / "cal_S.npy"), np.load(CORRIDOR / "deploy_S.npy")
    gt_cal = np.load(CORRIDOR / "deploy_GT.npy")
    cal, d = check_parity(s_cal, gt_cal, s_val, window=4, segment_size=4)
    assert [(n, x) for _, n, x in cal.confidence_blocks()] == [(2, 0), (2, 1), (6, 4), (21, 15), (13, 11), (17, 15),
                                                                (12, 11), (16, 15), (11, 11)]
    # The 11 PA-scores, all distinct, give 11 distinct confidences.
    assert len(set(d.confidences.tolist())) == 11
    cal, _ = check_parity(np.load(CORRIDOR / "cal_S.npy"), np.load(CORRIDOR / "cal_GT.npy"),
                          np.load(CORRIDOR / "deploy_S.npy"))
    assert [(n, x) for _, n, x in cal.confidence_blocks()] == [(11, 11)]


@pytest.mark.parametrize("technique", TECHNIQUES)
@pytest.mark.parametrize("dataset", DATASETS)
def test_wheel_equals_reference_on_real_data(shared_data, dataset, technique):
    d = shared_data / DATASETS[dataset]
    s, gt = np.load(d / f"S_{technique}.npy"), np.load(d / "GT.npy")
    n_cal = s.shape[1] // 10
    check_parity(s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:])


def test_soft_only_best_matches_are_left_out_and_no_pair_is_nan():
    s = np.array([[0.9, 0.5, 0.6, 0.8], [0.1, 0.1, 0.5, 0.1], [0.1, 0.2, 0.4, 0.3]])
    gt = np.array([[1, 0, 1, 0], [0, 1, 0, 1], [0, 0, 0, 0]], dtype=bool)
    soft = gt.copy()
    soft[0, 3] = True  # query 3's best match is soft-only
    for cal in (qtvpr.Calibration(s, gt, gt_soft=soft), ref.Calibration(s, gt, gt_soft=soft)):
        assert sum(n for _, n, _ in cal.confidence_blocks()) == 3
    # Every best match soft-only: no pair, NaN.
    all_soft = np.ones_like(gt)
    for cal in (qtvpr.Calibration(s, np.zeros_like(gt), gt_soft=all_soft),
                ref.Calibration(s, np.zeros_like(gt), gt_soft=all_soft)):
        assert cal.confidence_blocks() == []
        d = (qtvpr.Online if isinstance(cal, qtvpr.Calibration) else ref.Online)(cal, window=2).push(s[:, 0])
        assert math.isnan(d.confidence) and math.isnan(d.confidence_lower95)


def test_multi_matching_has_none():
    s, gt = np.load(CORRIDOR / "cal_S.npy"), np.load(CORRIDOR / "cal_GT.npy")
    s_val = np.load(CORRIDOR / "deploy_S.npy")
    for cal in (qtvpr.Calibration(s, gt, matching="multi"), ref.Calibration(s, gt, matching="multi")):
        with pytest.raises(ValueError, match=MULTI_WHY):
            cal.confidence_blocks()
        assert cal.transfer(s_val, k=3).query_confidences is None
    d = qtvpr.Online(qtvpr.Calibration(s, gt, matching="multi"), window=3).push_many(s_val)
    assert np.isnan(d.confidences).all() and np.isnan(d.confidences_lower95).all()


def test_cli_stream_equals_the_wheel(cli, tmp_path):
    # Calibrate on the embedded deployment half (nine blocks), stream the calibration half.
    cal_path = tmp_path / "cal.npz"
    s_cal, gt_cal = np.load(CORRIDOR / "deploy_S.npy"), np.load(CORRIDOR / "deploy_GT.npy")
    qtvpr.Calibration(s_cal, gt_cal).save(cal_path, window=4)
    # The file stores no map: loading rebuilds it from s and gt, bit for bit (§12).
    assert qtvpr.Calibration.load(cal_path).confidence_blocks() == qtvpr.Calibration(s_cal, gt_cal).confidence_blocks()
    assert ref.Calibration.load(cal_path).confidence_blocks() == ref.Calibration(s_cal, gt_cal).confidence_blocks()
    val = CORRIDOR / "cal_S.npy"
    d = ref.Online(ref.Calibration(s_cal, gt_cal), window=4).push_many(np.load(val))
    out = run_cli(cli, "stream", "--calibration", str(cal_path), "--val", str(val))
    assert out.returncode == 0, out.stderr
    lines = [json.loads(line) for line in out.stdout.splitlines()]
    close([line["confidence"] for line in lines], d.confidences)
    close([line["confidence_lower95"] for line in lines], d.confidences_lower95)
    out = run_cli(cli, "stream", "--calibration", str(cal_path), "--val", str(val), "--format", "csv")
    header, *rows = out.stdout.splitlines()
    cols = header.split(",")
    got = np.array([[float(r.split(",")[cols.index(k)]) for k in ("confidence", "confidence_lower95")] for r in rows])
    close(got[:, 0], d.confidences)
    close(got[:, 1], d.confidences_lower95)
    # Multi matching: null in JSON, NaN in CSV.
    qtvpr.Calibration(s_cal, gt_cal, matching="multi").save(cal_path, window=4)
    out = run_cli(cli, "stream", "--calibration", str(cal_path), "--val", str(val))
    first = json.loads(out.stdout.splitlines()[0])
    assert first["confidence"] is None and first["confidence_lower95"] is None
    out = run_cli(cli, "stream", "--calibration", str(cal_path), "--val", str(val), "--format", "csv")
    assert out.stdout.splitlines()[1].endswith(",NaN,NaN")


# ---------------------------------------------------------------------------------------
# evaluate's signals
# ---------------------------------------------------------------------------------------


def assert_same_bins(got, want):
    """Reliability bins: the same bins and counts, their means to 1e-9."""
    assert (got is None) == (want is None)
    if want is not None:
        assert [(b["lower"], b["upper"], b["n"]) for b in got] == [(b["lower"], b["upper"], b["n"]) for b in want]
        means = [[[b["mean_confidence"], b["hit_rate"]] for b in bins] for bins in (got, want)]
        close(*means)


def assert_same_signals(got, want):
    # The consistency is semantics §15's, beside §14's signals.
    signals = ["score", "margin", "pa_score", "consistency", "confidence"]
    assert list(got) == ["signals"] and list(got["signals"]) == signals
    assert list(got["signals"]["confidence"]) == ["auroc", "brier", "ece", "bins"]
    for signal, figures in want["signals"].items():
        assert list(got["signals"][signal]) == list(figures)
        for key, w in figures.items():
            g = got["signals"][signal][key]
            if key == "bins":
                assert_same_bins(g, w)
            else:
                assert (g is None and w is None) or abs(g - w) <= 1e-9, (signal, key, g, w)


def test_reliability_bins_by_hand():
    # The Rust scenario (crates/qtvpr/src/signals/confidence.rs, reliability_bins_by_hand): p on
    # an edge goes up (0.1: bin 1), except 1.0, which the last bin holds with 0.9.
    p = np.array([0.0, 0.08, 0.1, 0.55, 0.58, 0.59, 0.9, 1.0])
    c = np.array([0, 0, 1, 1, 0, 1, 0, 1], dtype=bool)
    bins = ref._reliability(p, c)
    # Bin 0: mean 0.04, none right; bin 1: 0.1, right; bin 5: 1.72 / 3, 2 of 3 right;
    # bin 9: 0.95, 1 of 2 right. ECE = 2/8 x 0.04 + 1/8 x 0.9 + 3/8 x (2/3 - 1.72/3) +
    # 2/8 x 0.45 = 0.01 + 0.1125 + 0.035 + 0.1125 = 0.27.
    assert [(b["lower"], b["upper"], b["n"]) for b in bins] == [(0.0, 0.1, 2), (0.1, 0.2, 1), (0.5, 0.6, 3),
                                                                 (0.9, 1.0, 2)]
    close([b["mean_confidence"] for b in bins], [0.04, 0.1, 1.72 / 3, 0.95], 1e-12)
    assert [b["hit_rate"] for b in bins] == [0.0, 1.0, 2 / 3, 0.5]
    assert ref._ece(p, c) == pytest.approx(0.27, abs=1e-12)


def test_evaluate_signals_on_the_embedded_corridor(cli):
    # The 11 calibration queries' best matches are all right: one block, 11 of 11. Its
    # map still ranks the 100 deployment decisions (83 right) as their PA-scores do,
    # from 0.05^(1/11) at PA-score 1 through 12/13 at the block's centre.
    s = np.concatenate([np.load(CORRIDOR / "cal_S.npy"), np.load(CORRIDOR / "deploy_S.npy")], axis=1)
    gt = np.concatenate([np.load(CORRIDOR / "cal_GT.npy"), np.load(CORRIDOR / "deploy_GT.npy")], axis=1)
    got, want = qtvpr.evaluate(s, gt)["confidence"], ref.evaluate(s, gt)["confidence"]
    assert_same_signals(got, want)
    sig = want["signals"]
    assert sig["confidence"]["auroc"] == sig["pa_score"]["auroc"] == pytest.approx(0.728561304, abs=1e-9)
    assert sig["score"]["auroc"] == pytest.approx(0.810772502, abs=1e-9)
    assert sig["margin"]["auroc"] == pytest.approx(0.678951099, abs=1e-9)
    c = sig["confidence"]
    # Against 0.17 for the constant 1 the step map gave.
    assert c["brier"] == pytest.approx(0.133097700, abs=1e-9) and c["ece"] == pytest.approx(0.040881813, abs=1e-9)
    assert [(b["lower"], b["n"]) for b in c["bins"]] == [(0.7, 16), (0.8, 43), (0.9, 41)]
    out = run_cli(cli, "evaluate", "--format", "json")  # the embedded demo data
    assert_same_signals(json.loads(out.stdout)["confidence"], want)
    # Multi matching: no signals.
    assert "confidence" not in qtvpr.evaluate(s, gt, matching="multi")
    assert "confidence" not in ref.evaluate(s, gt, matching="multi")


@pytest.mark.parametrize("technique", TECHNIQUES)
@pytest.mark.parametrize("dataset", DATASETS)
def test_evaluate_signals_equal_the_reference(shared_data, dataset, technique):
    d = shared_data / DATASETS[dataset]
    s, gt = np.load(d / f"S_{technique}.npy"), np.load(d / "GT.npy")
    assert_same_signals(qtvpr.evaluate(s, gt, methods=["oracle"])["confidence"],
                        ref.evaluate(s, gt, methods=["oracle"])["confidence"])
