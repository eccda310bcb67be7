"""Self-motion labels (semantics §16) in Python: the wheel against the NumPy reference on
hand-computed traverses (a stop, a reverse traverse, a database that is not a sequence),
their errors, a Calibration that keeps their record, and every front end (wheel,
reference, CLI) giving the same labels on the real Corridor and Nordland matrices.

The same scenarios are tested in Rust (crates/qtvpr/src/signals/self_motion.rs,
crates/qtvpr/tests/self_motion.rs, crates/qtvpr-cli/tests/self_motion.rs).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import qtvpr
from qtvpr import reference as ref
from shared_data import DATASETS, TECHNIQUES, nordland_similarity, sequence_average, vprbench
from test_cli import run_cli

IMPLEMENTATIONS = [qtvpr, ref]
SIGNS = {"positive": "+", "negative": "-", "abstain": "?"}


def matrix(n_db: int, best) -> np.ndarray:
    """|DB| x |Q| float64: column j's best match is row best[j] (score 1, else 0)."""
    s = np.zeros((n_db, len(best)))
    s[best, np.arange(len(best))] = 1.0
    return s


def signs(labels) -> str:
    return "".join(SIGNS[str(label)] for label in labels.labels)


def same(a, b) -> None:
    """Two SelfMotionLabels are the same labels, as ground truth and as record."""
    assert signs(a) == signs(b)
    np.testing.assert_array_equal(a.best, b.best)
    np.testing.assert_allclose(a.agreement, b.agreement, rtol=0, atol=0)
    np.testing.assert_array_equal(a.hard, b.hard)
    np.testing.assert_array_equal(a.soft, b.soft)
    assert a.counts == b.counts
    assert a.record == b.record


# The stop: rows 100..=110 (queries 0..=10), row 110 for 19 more queries, then 111..=120.
STOP = list(range(100, 111)) + [110] * 19 + list(range(111, 121))


# ---------------------------------------------------------------------------------------
# By hand
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("impl", IMPLEMENTATIONS, ids=["wheel", "reference"])
def test_a_stop_abstains(impl):
    # Query 12 (row 110): earlier neighbours 107, 108, 109, 110, 110 against predictions
    # 105..109, off by 2, 2, 2, 2, 1 within 2 + 0.2|d| = 3, 2.8, 2.6, 2.4, 2.2: 5 agree; later
    # ones (all 110) off by d, within for d = 1, 2: 7 / 10, positive. Query 13: earlier off
    # by 3, 3, 3, 2, 1: 3 agree, with the 2 later f = 0.5: abstain, up to its mirror, 26.
    labels = impl.ground_truth_from_sequence(matrix(200, STOP))
    assert signs(labels) == "+" * 13 + "?" * 14 + "+" * 13
    assert labels.agreement[12] == 0.7 and labels.agreement[13] == 0.5
    # Deep in the stop (query 20) only d = +-1, +-2 agree: 4 / 10.
    assert labels.agreement[20] == 0.4
    assert labels.counts == {"positive": 26, "negative": 0, "abstain": 14}
    assert len(labels) == 40
    # As ground truth: a positive's best match hard, an abstaining one's soft only.
    assert labels.hard[100, 0] and labels.soft[100, 0]
    assert not labels.hard[110, 20] and labels.soft[110, 20]
    assert labels.hard.sum() == 26 and labels.soft.sum() == 40
    assert labels.record == {
        "labels": "self-motion", "neighbours": 5, "positive_level": 0.7, "negative_level": 0.3,
        "speed": 1.0, "tolerance": 2.0, "drift": 0.2, "queries": 40, "positive": 26, "negative": 0,
        "abstain": 14,
    }
    # Query-major: the same labels, the ground truth transposed.
    t = impl.ground_truth_from_sequence(matrix(200, STOP).T.copy(), query_major=True)
    assert signs(t) == signs(labels)
    np.testing.assert_array_equal(t.hard, labels.hard.T)


@pytest.mark.parametrize("impl", IMPLEMENTATIONS, ids=["wheel", "reference"])
def test_a_reverse_traverse_needs_speed_minus_one(impl):
    # b_q = 139 - q: at speed 1 a neighbour d away is 2|d| rows off, within 2 + 0.2|d| for
    # d = +-1 only: 2 / 10 inside (negative), 2 / 6 at queries 1 and 38 (abstain).
    s = matrix(200, [139 - q for q in range(40)])
    with pytest.raises(ValueError, match=r"no pseudo-positive.*\(40 queries: 38 negative, 2 abstained\)"):
        impl.ground_truth_from_sequence(s)
    back = impl.ground_truth_from_sequence(s, sequence_speed=-1)
    assert signs(back) == "+" * 40
    # The forward traverse's labels, mirrored: the stop driven backwards.
    reverse_stop = impl.ground_truth_from_sequence(matrix(200, STOP[::-1]), sequence_speed=-1)
    assert signs(reverse_stop) == signs(impl.ground_truth_from_sequence(matrix(200, STOP)))[::-1]


@pytest.mark.parametrize("impl", IMPLEMENTATIONS, ids=["wheel", "reference"])
def test_a_database_that_is_not_a_sequence_labels_nothing_positive(impl):
    # Query q at row 100 + q of a database shuffled by r -> 7r mod 200: neighbours lie 7
    # rows apart (193 back across the wrap), 6|d| or more from q + d: f = 0, all negative.
    s = matrix(200, [7 * (100 + q) % 200 for q in range(40)])
    with pytest.raises(ValueError, match=r"\(40 queries: 40 negative, 0 abstained\); the calibration traverse"):
        impl.ground_truth_from_sequence(s)


def test_the_wheel_equals_the_reference_with_other_parameters():
    rng = np.random.default_rng(0)
    # A forward traverse with a stop, a wrong match every 7th query and noise elsewhere.
    best = np.array(STOP)
    best[::7] = rng.integers(0, 200, size=len(best[::7]))
    s = matrix(200, best) + 0.5 * rng.random((200, len(best)))
    for kw in [{}, {"neighbours": 3}, {"positive_level": 0.5, "negative_level": 0.49},
               {"positive_level": 0.8, "negative_level": 0.2}, {"sequence_tolerance": 1, "sequence_drift": 0}]:
        same(qtvpr.ground_truth_from_sequence(s, **kw), ref.ground_truth_from_sequence(s, **kw))
    same(qtvpr.ground_truth_from_sequence(s.astype(np.float32)), ref.ground_truth_from_sequence(s.astype(np.float32)))


# ---------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("s", "kw", "error", "message"),
    [
        (matrix(200, range(100, 105)), {}, ValueError,
         r"^s_cal: self-motion labels need at least 6 calibration queries in the order they were taken \(each "
         r"best match is judged by its 5 neighbours on each side\), got 5$"),
        (matrix(200, range(100, 103)), {"neighbours": 2}, None, None),
        (matrix(7, range(7)), {}, ValueError,
         r"^s_cal: self-motion labels cannot tell a line from chance with \|DB\| = 7: its widest tolerance, "
         r"\+-3 rows 5 steps away \(sequence tolerance 2 and drift 0.2\), covers 7 rows; it needs \|DB\| >= 8$"),
        (matrix(200, STOP), {"neighbours": 0}, ValueError, r"^neighbours must be >= 1, got 0$"),
        (matrix(200, STOP), {"positive_level": 1.5}, ValueError, r"^positive_level must be in \(0, 1\], got 1.5$"),
        (matrix(200, STOP), {"negative_level": 0.7}, ValueError,
         r"^negative_level must be at least 0 and below the positive level \(0.7\), got 0.7$"),
        (matrix(200, STOP), {"sequence_drift": -1}, ValueError, r"^sequence_drift must be finite and >= 0, got -1"),
        (matrix(200, STOP), {"sequence_speed": float("nan")}, ValueError, r"^sequence_speed must be finite"),
        (matrix(200, STOP).astype(np.int64), {}, TypeError, r"s_cal"),
        (matrix(200, STOP), {"neighbours": 2.5}, TypeError, r"neighbours"),
    ],
)
@pytest.mark.parametrize("impl", IMPLEMENTATIONS, ids=["wheel", "reference"])
def test_bad_input_is_a_clear_error(impl, s, kw, error, message):
    if error is None:  # 3 queries are enough for 2 neighbours a side: all on the line
        assert signs(impl.ground_truth_from_sequence(s, **kw)) == "+++"
        return
    with pytest.raises(error, match=message):
        impl.ground_truth_from_sequence(s, **kw)


# ---------------------------------------------------------------------------------------
# A calibration on the labels
# ---------------------------------------------------------------------------------------


def test_a_calibration_keeps_the_record(tmp_path):
    s = matrix(200, STOP)
    labels = qtvpr.ground_truth_from_sequence(s)
    cal = qtvpr.Calibration(s, labels)
    assert cal.labels == labels.record
    # Its file says so; loaded again, so does the calibration.
    cal.save(tmp_path / "cal.npz")
    meta = json.loads(str(np.load(tmp_path / "cal.npz")["meta"]))
    assert meta["labels"] == labels.record
    assert qtvpr.Calibration.load(tmp_path / "cal.npz").labels == labels.record
    # The same matrices as plain arrays are ordinary ground truth: the same thresholds, no record.
    plain = qtvpr.Calibration(s, labels.hard, gt_soft=labels.soft)
    assert plain.labels is None
    dep = matrix(200, list(range(121, 140)))
    np.testing.assert_array_equal(cal.transfer(dep).thresholds, plain.transfer(dep).thresholds)
    with pytest.raises(ValueError, match="multi does not apply to self-motion labels"):
        qtvpr.Calibration(s, labels, matching="multi")
    with pytest.raises(ValueError, match="gt_soft: .*self-motion labels"):
        qtvpr.Calibration(s, labels, gt_soft=labels.soft)


# ---------------------------------------------------------------------------------------
# Real data: every front end, the same labels
# ---------------------------------------------------------------------------------------


def front_ends(cli, tmp_path, s_cal):
    """The labels of the wheel and the reference, and the CLI's .npz (GThard, GTsoft,
    labels) and stderr line, for one calibration traverse."""
    wheel, reference = qtvpr.ground_truth_from_sequence(s_cal), ref.ground_truth_from_sequence(s_cal)
    same(wheel, reference)
    np.save(tmp_path / "s_cal.npy", s_cal)
    out = run_cli(cli, "ground-truth", "--from-sequence", tmp_path / "s_cal.npy", "--output", tmp_path / "gt.npz")
    assert out.returncode == 0, out.stderr
    c = wheel.counts
    assert out.stderr == (f"self-motion labels of {len(wheel)} calibration queries: {c['positive']} positive, "
                          f"{c['negative']} negative, {c['abstain']} abstained\n")
    with np.load(tmp_path / "gt.npz") as z:
        np.testing.assert_array_equal(z["GThard"], wheel.hard)
        np.testing.assert_array_equal(z["GTsoft"], wheel.soft)
        assert json.loads(str(z["labels"])) == wheel.record
    return wheel


def false_positives(labels, gt_cal) -> int:
    positive = labels.labels == "positive"
    return int((positive & ~gt_cal[labels.best, np.arange(len(labels))]).sum())


def test_corridor_every_front_end_gives_the_same_labels(shared_data, cli, tmp_path):
    # The counts are those of the measurement that chose the rule, with its own
    # implementation (docs/self-motion-labels.md): 55 pseudo-positives, none false; CALC's
    # 11 calibration queries draw no line, an error everywhere.
    positive = false = 0
    for technique in TECHNIQUES:
        s, gt = vprbench(shared_data, DATASETS[0], technique)
        s_cal = s[:, :11]
        if technique == "CALC":
            for impl in IMPLEMENTATIONS:
                with pytest.raises(ValueError, match="no pseudo-positive"):
                    impl.ground_truth_from_sequence(s_cal)
            np.save(tmp_path / "calc.npy", s_cal)
            out = run_cli(cli, "ground-truth", "--from-sequence", tmp_path / "calc.npy", "--output", tmp_path / "x.npz")
            assert (out.returncode, out.stderr.count("\n")) == (2, 1), out.stderr
            assert "no pseudo-positive" in out.stderr and not (tmp_path / "x.npz").exists()
            continue
        labels = front_ends(cli, tmp_path, s_cal)
        positive += labels.counts["positive"]
        false += false_positives(labels, gt[:, :11])
    assert (positive, false) == (55, 0)


def test_nordland_every_front_end_gives_the_same_labels(shared_data, cli, tmp_path):
    # Nordland HOG's 11-frame sequence average, its first 357 queries (the protocol's 10%):
    # 235 pseudo-positives, 3 of them false, as measured (docs/self-motion-labels.md).
    s, gt = nordland_similarity(shared_data, np.float32)
    s_cal = np.ascontiguousarray(sequence_average(s)[:, :357])
    labels = front_ends(cli, tmp_path, s_cal)
    assert labels.counts["positive"] == 235
    assert false_positives(labels, gt[:, :357]) == 3


def test_the_permuted_control_labels_nothing_positive(shared_data):
    # SPEDTest with its database rows permuted (seed 0): no route, no pseudo-positive.
    for technique in TECHNIQUES:
        s, _ = vprbench(shared_data, DATASETS[1], technique)
        s = s[np.random.default_rng(0).permutation(s.shape[0])]
        with pytest.raises(ValueError, match=r"no pseudo-positive.*\(60 queries: "):
            qtvpr.ground_truth_from_sequence(s[:, :60])
