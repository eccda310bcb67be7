"""Spec invariants of the wheel on random small matrices (hypothesis, derandomized).

The Rust property tests (crates/qtvpr/tests/properties.rs) say exactly which outputs
are invariant under which transform and test more of them; these check the same
invariants through the Python API, so that the binding's conversions (orientation,
dtypes, arguments) are covered too.
"""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import qtvpr

SETTINGS = settings(derandomize=True, max_examples=150, deadline=None, database=None)
TAUS = [1.0, 0.9, 0.75, 0.6, 0.5]


@st.composite
def problems(draw, unique_max: bool = False):
    """Integer scores in -4..=4 (many ties), hard and soft ground truth, parameters."""
    n_db = draw(st.integers(1, 7))
    n_cal = draw(st.integers(1, 5))
    n_val = draw(st.integers(1, 7))
    matching = draw(st.sampled_from(["single", "multi"]))
    ints = st.integers(-4, 4)
    s_cal = np.array(draw(st.lists(ints, min_size=n_db * n_cal, max_size=n_db * n_cal)), float).reshape(n_db, n_cal)
    s_val = np.array(draw(st.lists(ints, min_size=n_db * n_val, max_size=n_db * n_val)), float).reshape(n_db, n_val)
    if unique_max and matching == "single":
        # The best match is the first maximum: make every column's maximum unique so
        # that a row permutation cannot reorder tied maxima.
        first = s_cal.argmax(axis=0)
        s_cal[first, np.arange(n_cal)] += 0.5
    labels = np.array(draw(st.lists(st.integers(0, 3), min_size=n_db * n_cal, max_size=n_db * n_cal)))
    labels = labels.reshape(n_db, n_cal)
    gt, soft = labels == 2, labels >= 2
    return dict(
        s_cal=s_cal, gt=gt, soft=soft, s_val=s_val, matching=matching,
        tau=draw(st.sampled_from(TAUS)), k=draw(st.integers(1, 7)),
        segment_size=draw(st.none() | st.integers(1, n_val)),
    )


def transfer(p, **overrides):
    p = p | overrides
    return qtvpr.quantile_transfer(
        p["s_cal"], p["gt"], p["s_val"], gt_soft=p["soft"], k=p["k"], precision=p["tau"],
        matching=p["matching"], segment_size=p["segment_size"],
    )


@SETTINGS
@given(problems(unique_max=True), st.randoms(use_true_random=False))
def test_permuting_database_rows_changes_nothing(p, rnd):
    perm = list(range(p["s_cal"].shape[0]))
    rnd.shuffle(perm)
    a = transfer(p)
    b = transfer(p, s_cal=p["s_cal"][perm], gt=p["gt"][perm], soft=p["soft"][perm], s_val=p["s_val"][perm])
    for name in ("thresholds", "quantiles", "query_thresholds", "query_quantiles", "query_weights", "neighbours"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@SETTINGS
@given(problems(), st.lists(st.integers(1, 1000), min_size=9, max_size=9), st.floats(-50, 50))
def test_strictly_increasing_transform_maps_best_threshold(p, steps, base):
    table = base + np.concatenate([[0.0], np.cumsum(steps) / 64.0])
    f = lambda x: table[(np.asarray(x) + 4).astype(int)]  # noqa: E731 - scores are integers
    t = qtvpr.best_threshold(p["s_cal"], p["gt"], gt_soft=p["soft"], precision=p["tau"], matching=p["matching"])
    ft = qtvpr.best_threshold(f(p["s_cal"]), p["gt"], gt_soft=p["soft"], precision=p["tau"], matching=p["matching"])
    assert ft == (f(t) if np.isfinite(t) else t)
    for x in (-4, 0, 3):
        assert qtvpr.counts(p["s_cal"], p["gt"], x, gt_soft=p["soft"], matching=p["matching"]) == qtvpr.counts(
            f(p["s_cal"]), p["gt"], float(f(x)), gt_soft=p["soft"], matching=p["matching"]
        )


@SETTINGS
@given(problems())
def test_raising_tau_never_raises_recall(p):
    recalls = []
    for tau in sorted(TAUS + [0.01, 0.3, 0.999]):
        t = qtvpr.best_threshold(p["s_cal"], p["gt"], gt_soft=p["soft"], precision=tau, matching=p["matching"])
        recalls.append(qtvpr.counts(p["s_cal"], p["gt"], t, gt_soft=p["soft"], matching=p["matching"])["recall"])
    assert all(b <= a for a, b in itertools.pairwise(recalls)), recalls


@SETTINGS
@given(problems())
def test_the_oracle_meets_tau_on_its_own_segment(p):
    # The calibration matrix plays a deployment traverse with its own ground truth.
    s, gt, soft = p["s_cal"], p["gt"], p["soft"]
    m = p["segment_size"] or s.shape[1]
    for start in range(0, s.shape[1], m):
        cols = slice(start, start + m)
        t = qtvpr.best_threshold(s[:, cols], gt[:, cols], gt_soft=soft[:, cols], precision=p["tau"],
                                 matching=p["matching"])
        c = qtvpr.counts(s[:, cols], gt[:, cols], t, gt_soft=soft[:, cols], matching=p["matching"])
        # It meets tau (semantics §8.3), by convention when it accepts nothing.
        assert c["accepted"] == 0 or c["precision"] >= p["tau"] - 1e-12, (c, t)
        assert (c["tp"] > 0) if np.isfinite(t) else (c["tp"] + c["fp"] == 0), (c, t)


@SETTINGS
@given(problems())
def test_query_major_and_float32_change_nothing(p):
    a = transfer(p)
    b = qtvpr.quantile_transfer(
        p["s_cal"].T.astype(np.float32), p["gt"].T, p["s_val"].T.astype(np.float32), gt_soft=p["soft"].T,
        k=p["k"], precision=p["tau"], matching=p["matching"], segment_size=p["segment_size"], query_major=True,
    )
    # Integer scores are exact in float32.
    np.testing.assert_array_equal(a.thresholds, b.thresholds)
    np.testing.assert_array_equal(a.neighbours, b.neighbours)
