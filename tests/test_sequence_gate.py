"""The sequence gate and online sequence matching (semantics §15) in Python: the wheel
against the NumPy reference on streams of best matches built by hand (a stop, a jump,
a reverse traverse, the start of a stream, a database that is not a sequence, a split
traverse), ``Online`` equal to the batch path of the causally matched matrix, the
errors, and on the real data (Corridor, Nordland HOG).

The same scenarios are tested in Rust (crates/qtvpr/tests/sequence_gate.rs,
crates/qtvpr-cli/tests/online.rs).
"""

from __future__ import annotations

import numpy as np
import pytest

import qtvpr
from qtvpr import reference as ref
from shared_data import nordland_ground_truth, nordland_hog

N_DB = 40

#: The deployment stream: rows 10..=15 (queries 0..=5), a jump to 30..=34 (6..=10), a
#: stop at 34 (11..=13), then 35 (14).
DEPLOYMENT = [10, 11, 12, 13, 14, 15, 30, 31, 32, 33, 34, 34, 34, 34, 35]

#: Their consistencies with the defaults (W = 5, v = 1, a = 2, b = 0.2), by hand:
#: - 0..=5: the start of the stream, min(j, 5) of 5 agree;
#: - 6 (the jump to 30): rows 15..11 predict 29..25, none is there: 0; 7..=10 as a new
#:   start: 1, 2, 3, 4 of 5;
#: - 11 (34 again): 34, 33, 32, 31, 30 against 33, 32, 31, 30, 29, each 1 away: 1;
#: - 12: 34, 34, 33, 32, 31 against 33, 32, 31, 30, 29: 1, 2, 2, 2, 2 within 2.2, 2.4,
#:   2.6, 2.8, 3: 1;
#: - 13: 34, 34, 34, 33, 32 against 33, 32, 31, 30, 29: 1, 2, 3 (> 2.6), 3 (> 2.8),
#:   3 (<= 3): 3 of 5;
#: - 14 (35): 34, 34, 34, 34, 33 against 34, 33, 32, 31, 30: 0, 1, 2, 3 (> 2.8), 3
#:   (<= 3): 4 of 5.
CONSISTENCY = [0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.0, 0.6, 0.8]


def stream(best, seed: int) -> np.ndarray:
    """A similarity matrix whose column j peaks at row best[j] (0.9 + a little noise),
    every other score below 0.5: its best matches are ``best``."""
    rng = np.random.default_rng(seed)
    s = 0.5 * rng.random((N_DB, len(best)))
    s[best, np.arange(len(best))] = 0.9 + 0.05 * rng.random(len(best))
    return s


def truth(best) -> np.ndarray:
    gt = np.zeros((N_DB, len(best)), dtype=bool)
    gt[best, np.arange(len(best))] = True
    return gt


def calibrations(matching="single"):
    """The wheel's and the reference's calibration on a traverse of 8 queries along
    rows 2..10, all right."""
    best = list(range(2, 10))
    s, gt = stream(best, 1), truth(best)
    return qtvpr.Calibration(s, gt, matching=matching), ref.Calibration(s, gt, matching=matching)


# ---------------------------------------------------------------------------------------
# By hand: what robots do
# ---------------------------------------------------------------------------------------


def test_a_stop_a_jump_and_the_start_of_a_stream_by_hand():
    s_val = stream(DEPLOYMENT, 2)
    for cal in calibrations():
        out = cal.transfer(s_val, k=3, segment_size=5, gate="sequence")
        np.testing.assert_array_equal(out.query_consistencies, CONSISTENCY)
        assert (out.consistency_level, out.gate) == (0.8, None)
        plain = cal.transfer(s_val, k=3, segment_size=5)
        assert (plain.query_consistencies, plain.consistency_level) == (None, None)
        np.testing.assert_array_equal(out.thresholds, plain.thresholds)
    # The first 4 queries of a stream cannot pass; the jump and the 3 after it neither;
    # the stop passes two queries, then 13 (0.6) fails.
    assert [j for j, c in enumerate(CONSISTENCY) if c >= 0.8] == [4, 5, 10, 11, 12, 14]
    for window in (1, 4, 20):
        cal, rcal = calibrations()
        gated = qtvpr.Online(cal, k=3, precision=1.0, window=window, gate="sequence")
        ungated = qtvpr.Online(cal, k=3, precision=1.0, window=window).push_many(s_val)
        expected = ref.Online(rcal, k=3, precision=1.0, window=window, gate="sequence").push_many(s_val)
        decisions = [gated.push(s_val[:, j]) for j in range(len(DEPLOYMENT))]
        for j, d in enumerate(decisions):
            assert (d.consistency, d.consistency_level) == (CONSISTENCY[j], 0.8)
            assert (d.margin, d.gate, d.best) == (None, None, DEPLOYMENT[j])
            assert d.threshold == ungated.thresholds[j]
            assert d.accept == (bool(ungated.accept[j]) and CONSISTENCY[j] >= 0.8), j
        np.testing.assert_array_equal(expected.consistencies, CONSISTENCY)
        np.testing.assert_array_equal(expected.accept, [d.accept for d in decisions])
        many = qtvpr.Online(cal, k=3, precision=1.0, window=window, gate="sequence").push_many(s_val)
        np.testing.assert_array_equal(many.consistencies, CONSISTENCY)
        np.testing.assert_array_equal(many.consistency_levels, [0.8] * len(DEPLOYMENT))


def test_a_reverse_traverse_passes_only_at_speed_minus_one():
    # Rows 30, 29, ..., 16: at v = 1 a neighbour d back lies 2d from its prediction, so
    # only d = 1 agrees (2 <= 2.2): 0.2 at most. At v = -1: a forward traverse.
    s_val = stream(list(range(30, 15, -1)), 3)
    for cal in calibrations():
        c = cal.transfer(s_val, k=3, gate="sequence").query_consistencies
        np.testing.assert_array_equal(c, [0.0] + [0.2] * 14)
        c = cal.transfer(s_val, k=3, gate="sequence", sequence_speed=-1).query_consistencies
        np.testing.assert_array_equal(c, [0.0, 0.2, 0.4, 0.6, 0.8] + [1.0] * 10)


def test_a_database_that_is_not_a_sequence_fails_safe():
    # Best matches at random rows (a fixed seed): consecutive matches are unrelated.
    best = np.random.default_rng(7).integers(0, N_DB, 30)
    s_val = stream(best, 4)
    # Each query's consistency by the definition: |b_{j-d} - (b_j - d)| <= 2 + 0.2 d.
    want = [sum(abs(best[j - d] - (best[j] - d)) <= 2 + 0.2 * d + 1e-9 for d in range(1, min(j, 5) + 1)) / 5
            for j in range(30)]
    assert max(want) < 0.8
    cal, rcal = calibrations()
    for c in (cal, rcal):
        np.testing.assert_array_equal(c.transfer(s_val, k=3, gate="sequence").query_consistencies, want)
    np.testing.assert_array_equal(ref.sequence_consistency(s_val), want)
    decisions = qtvpr.Online(cal, k=3, window=5, gate="sequence").push_many(s_val)
    assert not decisions.accept.any()


def test_a_split_traverse_looks_back_into_its_calibration_queries():
    # One traverse along rows 2..25, the first 8 calibrate: the deployment queries'
    # windows reach back into the calibration queries, on the same line (1.0 each).
    best = list(range(2, 25))
    s, gt = stream(best, 5), truth(best)
    for transfer in (qtvpr.quantile_transfer, ref.quantile_transfer):
        out = transfer(s, gt, k=3, cal_queries=8, gate="sequence")
        np.testing.assert_array_equal(out.query_consistencies, [1.0] * 15)
        # 3 calibration queries only: the first deployment query sees 3 of 5.
        out = transfer(s, gt, k=3, cal_queries=3, gate="sequence")
        np.testing.assert_array_equal(out.query_consistencies[:3], [0.6, 0.8, 1.0])
    # Alone, the deployment matrix starts a stream of its own.
    alone = qtvpr.Calibration(s[:, :8], gt[:, :8]).transfer(s[:, 8:], k=3, gate="sequence")
    np.testing.assert_array_equal(alone.query_consistencies[:5], [0.0, 0.2, 0.4, 0.6, 0.8])


def test_the_protocols_sequence_methods_match_the_reference():
    # The calibration traverse (8 queries), then the deployment stream (3 segments of
    # 5); every best match right but the stop's last two.
    best = list(range(2, 10)) + DEPLOYMENT
    s = stream(best, 6)
    gt = truth(best)
    gt[best[21], 21] = gt[best[22], 22] = False
    methods = ["quantile-transfer", "sequence", "quantile-transfer-sequence", "quantile-transfer-margin-sequence"]
    kw = dict(methods=methods, k=3, cal_queries=8, segment_size=5)
    got, want = qtvpr.evaluate(s, gt, **kw), ref.evaluate(s, gt, **kw)
    for name in methods:
        for g, w in zip(got["methods"][name]["segments"], want["methods"][name]["segments"], strict=True):
            assert (g["tp"], g["fp"], g.get("consistency_level")) == (w["tp"], w["fp"], w.get("consistency_level"))
    # The gate alone: every passing query is accepted. Its consistencies are those of
    # the whole traverse: 1 for deployment queries 0..=4, then CONSISTENCY.
    consistency = [1.0] * 5 + CONSISTENCY[5:]
    for seg, a in zip(got["methods"]["sequence"]["segments"], range(0, 15, 5), strict=True):
        accepted = [j for j in range(a, a + 5) if consistency[j] >= 0.8]
        fp = sum(j in (13, 14) for j in accepted)
        assert (seg["tp"], seg["fp"], seg["consistency_level"]) == (len(accepted) - fp, fp, 0.8)
    assert got["methods"]["sequence"]["threshold_mse"] is None
    assert got["confidence"]["signals"]["consistency"]["auroc"] == pytest.approx(
        want["confidence"]["signals"]["consistency"]["auroc"], abs=1e-12
    )


# ---------------------------------------------------------------------------------------
# Online sequence matching
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("length", [3, 5, 11])
@pytest.mark.parametrize("gate", ["none", "sequence", "margin,sequence"])
def test_online_sequence_matching_is_the_matched_matrix_then_the_batch_path(length, gate):
    rng = np.random.default_rng(9)
    s_cal = rng.random((N_DB, 12)) + (np.arange(N_DB)[:, None] == 3 + np.arange(12)[None, :])
    gt = np.arange(N_DB)[:, None] == 3 + np.arange(12)[None, :]
    s_val = rng.random((N_DB, 30)) + 0.8 * (np.arange(N_DB)[:, None] == 5 + np.arange(30)[None, :] // 2)
    cal = qtvpr.Calibration(s_cal, gt, sequence=length)
    plain = qtvpr.Calibration(qtvpr.sequence_match(s_cal, length, causal=True), gt)
    assert (cal.sequence, plain.sequence) == (length, 1)
    matched = qtvpr.sequence_match(s_val, length, causal=True)
    want = qtvpr.Online(plain, k=3, window=6, gate=gate).push_many(matched)
    online = qtvpr.Online(cal, k=3, window=6, gate=gate, sequence=length)
    assert online.sequence == length
    got = [online.push(s_val[:, j]) for j in range(30)]
    np.testing.assert_array_equal([d.threshold for d in got], want.thresholds)
    np.testing.assert_array_equal([d.accept for d in got], want.accept)
    if gate != "none":
        np.testing.assert_array_equal([d.consistency for d in got], want.consistencies)
    # The reference, from the raw scores too.
    r = ref.Online(ref.Calibration(s_cal, gt, sequence=length), k=3, window=6, gate=gate).push_many(s_val)
    np.testing.assert_allclose(r.thresholds, want.thresholds, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(r.accept, want.accept)
    # And the batch.
    a = cal.transfer(s_val, k=3, segment_size=5, gate=gate)
    b = plain.transfer(matched, k=3, segment_size=5, gate=gate)
    np.testing.assert_array_equal(a.thresholds, b.thresholds)
    if gate != "none":
        np.testing.assert_array_equal(a.query_consistencies, b.query_consistencies)


def test_errors_name_what_is_wrong():
    cal, _ = calibrations()
    multi, _ = calibrations("multi")
    with pytest.raises(ValueError, match="gate sequence needs single matching"):
        qtvpr.Online(multi, window=4, gate="sequence")
    with pytest.raises(ValueError, match="gate names sequence twice"):
        qtvpr.Online(cal, window=4, gate="sequence,sequence")
    with pytest.raises(ValueError, match="unknown gate 'ratio'|unknown gate \"ratio\""):
        qtvpr.Online(cal, window=4, gate="ratio")
    with pytest.raises(ValueError, match="sequence_window must be >= 1, got 0"):
        qtvpr.Online(cal, window=4, gate="sequence", sequence_window=0)
    with pytest.raises(ValueError, match="sequence_level must be in"):
        cal.transfer(stream(DEPLOYMENT, 2), gate="sequence", sequence_level=1.5)
    with pytest.raises(ValueError, match="3 is not the calibration's sequence length 1"):
        qtvpr.Online(cal, window=4, sequence=3)
    with pytest.raises(ValueError, match="odd"):
        qtvpr.Calibration(stream(DEPLOYMENT, 2), truth(DEPLOYMENT), sequence=4)
    # |DB| = 7: +-3 rows cover 7 rows.
    small = qtvpr.Calibration(np.eye(7)[:, :3], np.eye(7, dtype=bool)[:, :3])
    with pytest.raises(ValueError, match=r"it needs \|DB\| >= 8"):
        small.transfer(np.eye(7), gate="sequence")


def test_the_file_keeps_the_gate_and_the_length(tmp_path):
    rng = np.random.default_rng(11)
    best = list(range(2, 14))
    s_cal, gt = stream(best, 8), truth(best)
    cal = qtvpr.Calibration(s_cal, gt, sequence=3)
    cal.save(tmp_path / "cal.npz", window=5, gate="sequence", sequence_level=0.6)
    loaded = qtvpr.Calibration.load(tmp_path / "cal.npz")
    assert loaded.sequence == 3
    assert loaded.defaults["gate"] == "sequence"
    assert loaded.defaults["sequence_gate"] == {"window": 5, "level": 0.6, "speed": 1.0, "tolerance": 2.0,
                                                "drift": 0.2}
    s_val = stream(list(range(14, 34)), 12) + 0.01 * rng.random((N_DB, 20))
    a = qtvpr.Online(loaded).push_many(s_val)
    b = qtvpr.Online(cal, window=5, gate="sequence", sequence_level=0.6).push_many(s_val)
    np.testing.assert_array_equal(a.thresholds, b.thresholds)
    np.testing.assert_array_equal(a.consistencies, b.consistencies)
    np.testing.assert_array_equal(a.consistency_levels, [0.6] * 20)


@pytest.mark.parametrize("length", [1, 3])
def test_dask_blocks_look_back_as_the_whole_stream(length):
    # Blocks of 7 queries: each preceded by what its decisions look back at (the gate's
    # window, the L - 1 raw columns), so that the stream cut into blocks is the whole.
    da = pytest.importorskip("dask.array")
    import qtvpr.dask as qd

    best = list(range(2, 14))
    cal = qtvpr.Calibration(stream(best, 8), truth(best), sequence=length)
    s_val = stream(DEPLOYMENT + DEPLOYMENT[::-1] + DEPLOYMENT, 13)
    lazy = da.from_array(s_val, chunks=(N_DB, 7))
    kw = dict(k=3, segment_size=7, gate="margin,sequence")
    got, want = qd.transfer(cal, lazy, **kw), cal.transfer(s_val, **kw)
    np.testing.assert_array_equal(got.thresholds, want.thresholds)
    np.testing.assert_array_equal(got.query_consistencies, want.query_consistencies)
    assert got.consistency_level == want.consistency_level == 0.8
    got = qd.online(cal, lazy, k=3, window=4, gate="sequence")
    want = qtvpr.Online(cal, k=3, window=4, gate="sequence").push_many(s_val)
    for name in ("thresholds", "best", "accept", "consistencies"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


# ---------------------------------------------------------------------------------------
# Real data
# ---------------------------------------------------------------------------------------


def online_equals_the_batch(s, gt, n_cal, length):
    """``Online`` with the gate (on a calibration of sequence length L) equals the
    batch path and the reference, query by query."""
    s_cal, s_val = s[:, :n_cal], s[:, n_cal:]
    cal = qtvpr.Calibration(s_cal, gt[:, :n_cal], sequence=length)
    decisions = qtvpr.Online(cal, k=10, window=28, gate="sequence").push_many(s_val)
    batch = cal.transfer(s_val, k=10, gate="sequence")
    np.testing.assert_array_equal(decisions.consistencies, batch.query_consistencies)
    assert (decisions.consistencies >= 0.8).any(), "some query passes on a traverse"
    matched = qtvpr.sequence_match(s_val, length, causal=True)
    best = np.argmax(matched, axis=0)
    np.testing.assert_array_equal(decisions.best, best)
    np.testing.assert_array_equal(batch.query_consistencies, ref.sequence_consistency(matched))
    accept = (decisions.score >= decisions.thresholds) & (decisions.consistencies >= 0.8 - 1e-12)
    np.testing.assert_array_equal(decisions.accept, accept)
    # The reference's online state, on its own calibration, the first 60 queries.
    r = ref.Online(ref.Calibration(s_cal, gt[:, :n_cal], sequence=length), k=10, window=28, gate="sequence")
    expected = r.push_many(s_val[:, :60])
    np.testing.assert_allclose(expected.thresholds, decisions.thresholds[:60], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(expected.consistencies, decisions.consistencies[:60])


@pytest.mark.parametrize("length", [1, 11])
def test_online_with_the_gate_equals_the_batch_on_corridor(shared_data, length):
    d = shared_data / "vprbench-corridor"
    s, gt = np.load(d / "S_AMOSNet.npy"), np.load(d / "GT.npy")
    online_equals_the_batch(s, gt.astype(bool), 11, length)


@pytest.mark.parametrize("length", [1, 11])
def test_online_with_the_gate_equals_the_batch_on_nordland(shared_data, length):
    db, q = nordland_hog(shared_data)
    s = qtvpr.cosine_similarity(db, q[:400])
    online_equals_the_batch(s, nordland_ground_truth(len(db), 400), 40, length)
