"""Hand-computed cases for the NumPy reference (py/qtvpr/reference.py), one group per
section of the semantics (docs/semantics.md), plus input validation and a smoke run on real Corridor data.

Every expected value is worked out by hand in the comment beside it; none is copied
from the output under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from qtvpr import reference as ref
from qtvpr.reference import (
    GATED,
    best_threshold,
    counts,
    evaluate,
    quantile_transfer,
    schubert_threshold,
)

T, F = True, False
Z = 4.753424308817087  # semantics §7


def col(*values):
    """A |DB| x 1 matrix."""
    return np.array(values, dtype=np.float64).reshape(-1, 1)


def gcol(*values):
    return np.array(values, dtype=bool).reshape(-1, 1)


# ---------------------------------------------------------------------------------------
# Sections 2 and 3: decisions and the best threshold
# ---------------------------------------------------------------------------------------


def test_sweep_evaluates_ties_together():
    # multi, one column: 0.9 T | 0.8 T, 0.8 F | 0.7 T
    # group ends: 0.9 -> TP1 FP0; 0.8 -> TP2 FP1 (2/3); 0.7 -> TP3 FP1 (3/4)
    s, gt = col(0.9, 0.8, 0.8, 0.7), gcol(T, T, F, T)
    # tau = 1: only the 0.9 group is valid. Inside the tie, TP2 FP0 would have been
    # wrongly valid at 0.8.
    assert best_threshold(s, gt, matching="multi") == 0.9
    # tau = 0.75: 0.8 -> 2 >= 2.25 no; 0.7 -> 3 >= 3 yes -> TP* = 3 -> 0.7
    assert best_threshold(s, gt, matching="multi", precision=0.75) == 0.7
    # tau = 2/3: 0.8 valid (2 >= 2), 0.7 valid (3 >= 2.67), TP* = 3 first at 0.7
    assert best_threshold(s, gt, matching="multi", precision=2 / 3) == 0.7


def test_sweep_takes_first_group_reaching_max_tp():
    # 0.9 T (1,0) | 0.8 F (1,1) | 0.7 F (1,2) | 0.6 T (2,2); tau = 0.5
    # valid: 0.9 (1 >= 0.5), 0.8 (1 >= 1), 0.7 no (1 < 1.5), 0.6 (2 >= 2) -> TP* = 2 -> 0.6
    s, gt = col(0.9, 0.8, 0.7, 0.6), gcol(T, F, F, T)
    assert best_threshold(s, gt, matching="multi", precision=0.5) == 0.6
    # Without the last T: TP* = 1, reached first at 0.9 (0.8 is valid too but has an FP).
    s, gt = col(0.9, 0.8), gcol(T, F)
    assert best_threshold(s, gt, matching="multi", precision=0.5) == 0.9


def test_reject_all():
    # 0.9 F (0,1) TP = 0 invalid; 0.8 T (1,1) 1 < 2 invalid -> +inf
    assert best_threshold(col(0.9, 0.8), gcol(F, T), matching="multi") == math.inf
    # no positives at all -> +inf, in both modes
    assert best_threshold(col(0.9, 0.8), gcol(F, F)) == math.inf
    assert best_threshold(col(0.9, 0.8), gcol(F, F), matching="multi") == math.inf


def test_single_first_argmax_on_ties():
    # column [0.5, 0.5], GT [F, T]: b = row 0 (first maximum), which is wrong
    s, gt = col(0.5, 0.5), gcol(F, T)
    assert counts(s, gt, 0.5) == {
        "tp": 0, "fp": 1, "accepted": 1, "positives": 1, "precision": 0.0, "recall": 0.0, "precision_lower95": 0.0
    }
    assert best_threshold(s, gt) == math.inf


SINGLE_S = np.array([[0.9, 0.2, 0.7], [0.5, 0.8, 0.1], [0.1, 0.3, 0.6]])
SINGLE_GT = np.array([[F, F, F], [T, T, F], [F, F, T]])
SINGLE_SOFT = np.array([[T, F, F], [T, T, F], [F, F, T]])


def test_single_soft_only_best_match_makes_no_decision():
    # column 0: b = 0 (0.9) is soft-only -> no decision
    # column 1: b = 1 (0.8), GT -> correct;  column 2: b = 0 (0.7), not GT -> wrong
    # positives: every column has a hard match -> 3
    # candidates 0.8 T, 0.7 F -> tau = 1: t = 0.8
    assert best_threshold(SINGLE_S, SINGLE_GT, gt_soft=SINGLE_SOFT) == 0.8
    # at 0.8: TP 1, FP 0, precision 1, recall 1/3
    c = counts(SINGLE_S, SINGLE_GT, 0.8, gt_soft=SINGLE_SOFT)
    # Beta(1, 1) is uniform: its 0.05 quantile is 0.05.
    assert c == {
        "tp": 1, "fp": 0, "accepted": 1, "positives": 3, "precision": 1.0, "recall": 1 / 3,
        "precision_lower95": pytest.approx(0.05, abs=1e-12),
    }
    # at 0.5: 0.8 T and 0.7 F accepted -> precision 1/2
    c = counts(SINGLE_S, SINGLE_GT, 0.5, gt_soft=SINGLE_SOFT)
    assert (c["tp"], c["fp"], c["precision"]) == (1, 1, 0.5)
    # without soft GT, column 0 decides 0.9 wrongly: 0.9 F invalid, 0.8 (1,1) invalid -> inf
    assert best_threshold(SINGLE_S, SINGLE_GT) == math.inf
    # nothing accepted: no precision (semantics §2), recall 0
    c = counts(SINGLE_S, SINGLE_GT, math.inf, gt_soft=SINGLE_SOFT)
    assert c == {"tp": 0, "fp": 0, "accepted": 0, "positives": 3, "precision": None, "recall": 0.0,
                 "precision_lower95": None}


def test_multi_with_ignored_entries():
    s = np.array([[0.9, 0.6], [0.8, 0.7]])
    gt = np.array([[F, T], [T, F]])
    soft = np.array([[T, T], [T, F]])
    # ignored = soft & ~gt = only (0, 0), the 0.9
    # candidates: 0.8 T, 0.7 F, 0.6 T; positives = 2 hard matches
    # sweep: 0.8 (1,0), 0.7 (1,1), 0.6 (2,1)
    assert best_threshold(s, gt, gt_soft=soft, matching="multi") == 0.8
    # tau = 2/3: 0.6 -> 2 >= 2 valid -> TP* = 2 -> 0.6
    assert best_threshold(s, gt, gt_soft=soft, matching="multi", precision=2 / 3) == 0.6
    c = counts(s, gt, 0.6, gt_soft=soft, matching="multi")
    # Beta(2, 2): its CDF is 3x^2 - 2x^3, which is 0.05 at x = 0.13535036...
    assert c == {
        "tp": 2, "fp": 1, "accepted": 3, "positives": 2, "precision": 2 / 3, "recall": 1.0,
        "precision_lower95": pytest.approx(0.1353503621715837, abs=1e-12),
    }
    # without soft GT, 0.9 F heads the sweep: 0.9 (0,1), 0.8 (1,1), ... never valid at tau 1
    assert best_threshold(s, gt, matching="multi") == math.inf
    # integer GT is accepted like bool
    assert best_threshold(s, gt.astype(np.int64), gt_soft=soft.astype(np.uint8), matching="multi") == 0.8


def test_query_major_transposes_every_matrix():
    # the same case as above, given as |Q| x |DB|
    s = SINGLE_S.T.copy()
    assert best_threshold(s, SINGLE_GT.T, gt_soft=SINGLE_SOFT.T, query_major=True) == 0.8
    c = counts(s, SINGLE_GT.T, 0.8, gt_soft=SINGLE_SOFT.T, query_major=True)
    assert (c["tp"], c["positives"]) == (1, 3)


def test_float32_is_widened_exactly():
    # 0.1 in float32 is 0.100000001490116...; the threshold must be that value in f64
    s = np.array([[0.1], [0.05]], dtype=np.float32)
    t = best_threshold(s, gcol(T, F))
    assert t == float(np.float32(0.1)) and t != 0.1


def _brute_force_threshold(scores, correct, positives, tau):
    """Section 3 restated: try every distinct candidate score as a threshold."""
    best = None  # (tp, threshold)
    if positives == 0:
        return math.inf
    for t in sorted(set(scores.tolist()), reverse=True):
        acc = scores >= t
        tp = int((acc & correct).sum())
        fp = int((acc & ~correct).sum())
        if tp > 0 and tp >= tau * (tp + fp) - 1e-12 and (best is None or tp > best[0]):
            best = (tp, t)
    return math.inf if best is None else best[1]


@settings(max_examples=150, deadline=None)
@given(
    data=st.data(),
    rows=st.integers(1, 5),
    cols=st.integers(1, 5),
    tau=st.sampled_from([1.0, 0.9, 0.75, 0.5, 0.1]),
    matching=st.sampled_from(["single", "multi"]),
)
def test_sweep_matches_brute_force(data, rows, cols, tau, matching):
    # scores from a small set, so that ties are common
    s = data.draw(hnp.arrays(np.float64, (rows, cols), elements=st.sampled_from([0.0, 0.25, 0.5, 1.0])))
    gt = data.draw(hnp.arrays(bool, (rows, cols)))
    soft = data.draw(hnp.arrays(bool, (rows, cols)))
    ignored = soft & ~gt
    if matching == "multi":
        scores, correct, positives = s[~ignored], gt[~ignored], int(gt.sum())
    else:
        b = np.argmax(s, axis=0)
        keep = ~ignored[b, np.arange(cols)]
        scores, correct = s[b, np.arange(cols)][keep], gt[b, np.arange(cols)][keep]
        positives = int(gt.any(axis=0).sum())
    expected = _brute_force_threshold(scores, correct, positives, tau)
    assert best_threshold(s, gt, gt_soft=soft, precision=tau, matching=matching) == expected
    assert best_threshold(s.T, gt.T, gt_soft=soft.T, precision=tau, matching=matching, query_major=True) == expected


# ---------------------------------------------------------------------------------------
# Section 4: ranked correlation and neighbours
# ---------------------------------------------------------------------------------------


def test_zero_variance_column_has_correlation_zero():
    # calibration: column 0 = [1, 2, 3] (profile 3, 2, 1), column 1 constant 5
    s_cal = np.array([[1.0, 5.0], [2.0, 5.0], [3.0, 5.0]])
    s_val = np.array([[3.0, 7.0], [1.0, 7.0], [2.0, 7.0]])
    r, nb, w = ref._calibration_neighbours(s_cal, s_val, 2)
    # val 0 has profile 3, 2, 1 -> corr 1 with cal 0, 0 with the constant cal 1
    # val 1 is constant itself -> 0 with everything, exactly
    assert r[0, 1] == 0.0 and r[1, 0] == 0.0 and r[1, 1] == 0.0
    assert r[0, 0] == pytest.approx(1.0, abs=1e-15)
    # val 0: order [0, 1], weight (1 + 0) / 2; val 1: all tied at 0 -> [0, 1], weight 0
    assert nb.tolist() == [[0, 1], [0, 1]]
    assert w[0] == pytest.approx(0.5, abs=1e-15) and w[1] == 0.0


def test_correlation_ties_go_to_lower_index():
    # cal 0 = 7/8 * cal 1 - 2.25, an exact affine image (dyadic values), so both have
    # the same exact correlation with anything. In floating point, R[0, 0] came out one
    # ulp *below* R[0, 1] on the development machine; the 2**-40 grid makes them tie,
    # and the tie goes to index 0.
    base = np.array([45.0, 10.0, 25.0, 13.0, 0.0])
    s_cal = np.stack([base * 7 / 8 - 2.25, base, -base], axis=1)
    s_val = np.array([[14.0], [24.0], [24.0], [5.0], [49.0]])
    r, nb, w = ref._calibration_neighbours(s_cal, s_val, 3)
    assert abs(r[0, 0] - r[0, 1]) < 1e-15
    assert nb.tolist() == [[0, 1, 2]]
    # identical profiles are an exact tie too: cal 1 and a permutation of it
    s_cal = np.stack([base, base[::-1]], axis=1)
    _, nb, _ = ref._calibration_neighbours(s_cal, s_val, 2)
    assert nb.tolist() == [[0, 1]]


def test_correlation_order_and_weight_clipping():
    # val profile (3, 2, 1). cal 0 profile (9, 1, 1): centred (16/3, -8/3, -8/3),
    # dot with (1, 0, -1) = 8, norms sqrt(2) and (8/3) sqrt(6) -> r = 3 / sqrt(12).
    # cal 1 = (1, 2, 3): same profile as val -> r = 1. cal 2 constant -> r = 0.
    s_cal = np.array([[9.0, 1.0, 4.0], [1.0, 2.0, 4.0], [1.0, 3.0, 4.0]])
    s_val = col(2.0, 3.0, 1.0)
    r, nb, w = ref._calibration_neighbours(s_cal, s_val, 2)
    assert r[0] == pytest.approx([3 / math.sqrt(12), 1.0, 0.0], abs=1e-15)
    assert nb.tolist() == [[1, 0]]
    assert w[0] == pytest.approx((1 + 3 / math.sqrt(12)) / 2, abs=1e-15)
    # Two descending profiles are similarly ordered, so by Chebyshev's sum inequality
    # their covariance is >= 0: the clip of w at 0 only ever removes rounding noise.
    assert (w >= 0).all()


def test_k_is_clipped_to_calibration_size():
    s_cal = np.array([[1.0, 2.0], [2.0, 1.0], [0.5, 3.0]])
    gt_cal = np.array([[T, F], [F, F], [F, T]])
    s_val = np.array([[1.0, 2.0, 3.0], [3.0, 2.0, 1.0], [2.0, 2.0, 2.0]])
    res = quantile_transfer(s_cal, gt_cal, s_val, k=10)
    assert res.neighbours.shape == (3, 2)
    assert sorted(res.neighbours[0].tolist()) == [0, 1]


# ---------------------------------------------------------------------------------------
# Section 5: quantile of a subset threshold
# ---------------------------------------------------------------------------------------


def test_subset_quantile_and_round_trip():
    # calibration (both columns are the subset, k = 2):
    #   c0 = (0.9, 0.1, 0.3) GT row 0 -> best 0.9 correct
    #   c1 = (0.2, 0.95, 0.4) GT row 1 -> best 0.95 correct
    # tau = 1: 0.95 (1,0), 0.9 (2,0) -> t = 0.9
    # sample (0.1, 0.2, 0.3, 0.4, 0.9, 0.95), n = 6; c = #{<= 0.9} = 5 -> q = 4/5
    s_cal = np.array([[0.9, 0.2], [0.1, 0.95], [0.3, 0.4]])
    gt_cal = np.array([[T, F], [F, T], [F, F]])
    s_val = col(0.5, 0.7, 0.6)
    res = quantile_transfer(s_cal, gt_cal, s_val, k=2)
    assert res.query_thresholds.tolist() == [0.9]
    assert res.query_quantiles.tolist() == [4 / 5]
    # one query -> batch q = 4/5; batch scores sorted (0.5, 0.6, 0.7), N = 3:
    # h = 2 * 0.8 = 1.6, lo = 1 -> 0.6 + 0.6 * (0.7 - 0.6) = 0.66
    assert res.quantiles.tolist() == [4 / 5]
    assert res.thresholds[0] == pytest.approx(0.66, abs=1e-15)
    assert res.segments == [(0, 1)]
    # round trip on the subset's own sample: h = 5 * 0.8 = 4 -> x[4] = 0.9 exactly
    assert ref._linear_quantile(s_cal, 4 / 5) == 0.9


def test_subset_quantile_n_one_and_reject_all():
    # |DB| = 1: every profile is constant -> all correlations 0 -> neighbour = index 0.
    # subset (0.5) with GT true: t = 0.5, n = 1 -> q = 0
    # batch (0.6), q = 0: h = 0, lo = 0 = N - 1 -> 0.6
    res = quantile_transfer(np.array([[0.5, 0.7]]), np.array([[1, 1]]), np.array([[0.6]]), k=1)
    assert res.neighbours.tolist() == [[0]]
    assert res.query_quantiles.tolist() == [0.0]
    assert res.thresholds.tolist() == [0.6]
    # subset GT false: no positives -> t = inf -> q = 1 (reject-all wins over n = 1)
    # q = 1 -> the next float above the batch maximum 0.6
    res = quantile_transfer(np.array([[0.5, 0.7]]), np.array([[0, 1]]), np.array([[0.6]]), k=1)
    assert res.query_thresholds.tolist() == [math.inf]
    assert res.query_quantiles.tolist() == [1.0]
    assert res.thresholds.tolist() == [np.nextafter(0.6, math.inf)]
    assert res.thresholds[0] > 0.6


def test_subset_quantile_direct():
    sample = np.array([[0.3, 0.1], [0.2, 0.3]])
    # t = 0.2: c = #{0.1, 0.2} = 2 -> (2 - 1) / (4 - 1) = 1/3
    assert ref._subset_quantile(sample, 0.2) == 1 / 3
    # t = 0.3 (tied maximum): c = 4 -> 3/3 = 1
    assert ref._subset_quantile(sample, 0.3) == 1.0
    assert ref._subset_quantile(sample, math.inf) == 1.0
    assert ref._subset_quantile(np.array([[0.4]]), 0.4) == 0.0


# ---------------------------------------------------------------------------------------
# Section 6: weighted median, linear quantile, segments
# ---------------------------------------------------------------------------------------


def test_weighted_median_even_split_takes_lower():
    # sorted q (0.1, 0.2, 0.3, 0.4), equal weights: cumulative (1, 2, 3, 4), half = 2
    # -> first cumulative >= 2 is at 0.2
    assert ref._lower_weighted_median(np.array([0.3, 0.1, 0.2, 0.4]), np.ones(4)) == 0.2
    # weights 0.1, 0.2, 0.3 (sorted order): cumulative 0.1, 0.3, 0.6; half of 0.6 = 0.3
    # -> exactly reached at the second (floating point sums are absorbed by the 1e-12)
    q = np.array([0.9, 0.5, 0.7])
    w = np.array([0.3, 0.1, 0.2])
    assert ref._lower_weighted_median(q, w) == 0.7
    # weights (0.2, 0.2, 0.6): cumulative 0.2, 0.4, 1.0, half 0.5 -> third
    assert ref._lower_weighted_median(np.array([0.1, 0.2, 0.3]), np.array([0.2, 0.2, 0.6])) == 0.3


def test_weighted_median_zero_total_weight_means_equal_weights():
    # all weights 0 -> all 1: sorted (0.1, 0.5, 0.9), cumulative (1, 2, 3), half 1.5 -> 0.5
    assert ref._lower_weighted_median(np.array([0.5, 0.1, 0.9]), np.zeros(3)) == 0.5


def test_linear_quantile():
    x = np.array([[4.0, 1.0], [3.0, 2.0]])  # sorted 1, 2, 3, 4; N = 4
    assert ref._linear_quantile(x, 0.0) == 1.0  # h = 0
    assert ref._linear_quantile(x, 0.5) == 2.5  # h = 1.5 -> 2 + 0.5 * 1
    assert ref._linear_quantile(x, 1 / 3) == 2.0  # h = 3 * (1/3) = 1.0 -> x[1]
    # q = 1 -> reject-all: the next float above 4
    assert ref._linear_quantile(x, 1.0) == np.nextafter(4.0, math.inf)
    # q just below 1: h = 3 - 3 * 2**-53 rounds to 3 - 2**-51 (ulp in [2, 4) is 2**-51),
    # lo = 2 -> 3 + (1 - 2**-51) * (4 - 3) = 4 - 2**-51: still below the maximum, so only
    # q == 1 exactly rejects everything
    assert ref._linear_quantile(x, 1 - 2.0**-53) == 4.0 - 2.0**-51
    # a single score: h = 0, lo = 0 = N - 1 -> x[0]
    assert ref._linear_quantile(np.array([[0.25]]), 0.5) == 0.25


def test_segments_keep_the_shorter_last_one():
    rng = np.random.default_rng(0)
    s_cal = rng.random((6, 4))
    gt_cal = np.eye(6, 4, dtype=bool)
    s_val = rng.random((6, 5))
    res = quantile_transfer(s_cal, gt_cal, s_val, k=2, segment_size=2)
    # 5 deployment queries in runs of 2: (0, 2), (2, 4), (4, 5)
    assert res.segments == [(0, 2), (2, 4), (4, 5)]
    assert res.thresholds.shape == res.quantiles.shape == (3,)
    assert res.query_quantiles.shape == res.query_weights.shape == res.query_thresholds.shape == (5,)
    # segment (4, 5) holds one query: its batch q is that query's q_j
    assert res.quantiles[2] == res.query_quantiles[4]
    whole = quantile_transfer(s_cal, gt_cal, s_val, k=2)
    assert whole.segments == [(0, 5)]


# ---------------------------------------------------------------------------------------
# Section 7: Schubert
# ---------------------------------------------------------------------------------------


def test_schubert_even_count():
    # sorted (1, 2, 3, 10): mu = (2 + 3) / 2 = 2.5
    # |S - mu| = (1.5, 0.5, 0.5, 7.5), sorted (0.5, 0.5, 1.5, 7.5) -> median 1.0
    # sigma = 1 / 0.675, t = 2.5 + Z / 0.675
    assert schubert_threshold(np.array([[1.0, 2.0], [3.0, 10.0]])) == pytest.approx(2.5 + Z / 0.675, rel=1e-15)


def test_schubert_odd_count_and_zero_sigma():
    # (1, 2, 7): mu = 2, |S - mu| = (1, 0, 5) -> median 1 -> t = 2 + Z / 0.675
    assert schubert_threshold(np.array([[1.0, 2.0, 7.0]])) == pytest.approx(2 + Z / 0.675, rel=1e-15)
    # (1, 1, 1, 2): mu = (1 + 1) / 2 = 1, |S - mu| = (0, 0, 0, 1) -> median (0 + 0) / 2 = 0
    # -> sigma 0: a degenerate fit, reject-all
    assert schubert_threshold(np.array([[1.0, 1.0], [1.0, 2.0]])) == math.inf
    # one score: mu = 0.3, MAD 0 -> reject-all; (-1, -1, 2): mu = -1, MAD median(0, 0, 3) = 0
    assert schubert_threshold(np.array([[0.3]], dtype=np.float32)) == math.inf
    assert schubert_threshold(np.array([[-1.0, -1.0, 2.0]])) == math.inf
    # (1, 1, 2, 3): mu = 1.5, |S - mu| = (0.5, 0.5, 0.5, 1.5) -> median 0.5: not degenerate
    assert schubert_threshold(np.array([[1.0, 1.0], [2.0, 3.0]])) == pytest.approx(1.5 + Z * 0.5 / 0.675, rel=1e-15)


def test_schubert_zero_sigma_in_the_protocol():
    # Every score of segment 1 (columns 4, 5: d2, d3) equal: per-segment Schubert is
    # reject-all there, so it accepts nothing and has no MSE; it is inf, not the median.
    s = TINY_S.copy()
    s[:, 4:6] = 0.5
    res = evaluate(s, TINY_GT, precision=0.5, cal_queries=2, segment_size=2, methods=["schubert"])
    seg = res["methods"]["schubert"]["segments"][1]
    assert (seg["threshold"], seg["tp"], seg["fp"], seg["precision_lower95"]) == (math.inf, 0, 0, None)


def test_clopper_pearson_lower_bound():
    # No false positive in n: P(Beta(n, 1) <= x) = x^n, so the bound is 0.05^(1/n);
    # n = 10: exp(ln(0.05) / 10) = exp(-0.2995732) = 0.7411344491
    assert ref.precision_lower95(10, 0) == pytest.approx(0.7411344491, abs=1e-10)
    for n in (1, 2, 28, 1000):
        assert ref.precision_lower95(n, 0) == pytest.approx(0.05 ** (1 / n), abs=1e-12)
    # TP 8, FP 2: the x with P(Binomial(10, x) >= 8) = 0.05, i.e.
    # 45 x^8 (1 - x)^2 + 10 x^9 (1 - x) + x^10 = 0.05 -> x = 0.4930986989
    x = ref.precision_lower95(8, 2)
    assert x == pytest.approx(0.4930986989, abs=1e-10)
    assert 45 * x**8 * (1 - x) ** 2 + 10 * x**9 * (1 - x) + x**10 == pytest.approx(0.05, abs=1e-13)
    # Nothing correct: 0; nothing accepted: None.
    assert ref.precision_lower95(0, 5) == 0.0
    assert ref.precision_lower95(0, 0) is None
    # Many false positives (multi matching pools thousands): 1 correct in 20001 accepted.
    # P(Beta(1, b) <= x) = 1 - (1 - x)^b, so x = 1 - 0.95^(1/b) with b = 20001.
    assert ref.precision_lower95(1, 20000) == pytest.approx(1 - 0.95 ** (1 / 20001), rel=1e-9)


# ---------------------------------------------------------------------------------------
# Section 8: evaluation protocol
# ---------------------------------------------------------------------------------------

# |DB| = 3, |Q| = 7: two calibration columns, then deployment d0..d4.
TINY_S = np.array(
    [
        # c0    c1    d0   d1   d2   d3   d4
        [0.9, 0.2, 0.7, 0.1, 0.5, 0.2, 0.3],
        [0.1, 0.95, 0.3, 0.6, 0.4, 0.9, 0.3],
        [0.3, 0.4, 0.2, 0.5, 0.3, 0.1, 0.3],
    ]
)
TINY_GT = np.array(
    [
        [T, F, T, F, F, F, F],
        [F, F, F, F, F, F, F],
        [F, T, F, T, F, F, F],
    ]
)


def test_evaluate_tiny_matrix_with_skipped_segment():
    # tau = 0.5, 2 calibration queries, segments of 2 over 5 deployment queries:
    # (0, 2) = d0, d1 and (2, 4) = d2, d3; d4 is the dropped remainder.
    #
    # calibration candidates (single): c0 best 0.9 (row 0, GT) correct;
    #   c1 best 0.95 (row 1, not GT) wrong.
    #   sweep: 0.95 (0,1) TP 0 invalid; 0.9 (1,1): 1 >= 0.5 * 2 valid -> t_cal = 0.9
    # segment 0: d0 best 0.7 correct, d1 best 0.6 wrong; positives 2
    #   oracle: 0.7 (1,0) valid, 0.6 (1,1) valid, TP* = 1 first at 0.7
    # segment 1: no GT at all -> positives 0 -> skipped; oracle inf
    #   candidates d2 0.5 wrong, d3 0.9 wrong
    out = evaluate(TINY_S, TINY_GT, precision=0.5, cal_queries=2, segment_size=2)
    assert out["params"] == {
        "calibration": {"count": 2}, "deploy_fraction": None, "segment": {"count": 2}, "k": 10,
        "precision": 0.5, "matching": "single", "database_size": 3, "queries": 7,
        "calibration_queries": 2, "deployment_start": 2, "deployment_queries": 5, "segment_size": 2,
        "segments": 2,
        # Semantics §15: the sequence gate's parameters (its methods' and the consistency
        # signal's), the defaults.
        "sequence_gate": {"window": 5, "level": 0.8, "speed": 1.0, "tolerance": 2.0, "drift": 0.2},
    }
    # full segments d0..d3: d0's best match is a hard match, d1's is not; d2, d3 have no
    # hard match -> R@1 = 1/2
    assert out["recall_at_1"] == 0.5
    res = out["methods"]
    # Every method but the sequence gate's, which cannot tell on |DB| = 3.
    assert list(res) == [m for m in ref.METHODS if m not in ref.SEQUENCE_GATED]
    for m in res.values():
        assert [(r["start"], r["end"]) for r in m["segments"]] == [(0, 2), (2, 4)]
        assert m["segments_counted"] == 1 and m["segments_skipped"] == 1
        assert [r["oracle_threshold"] for r in m["segments"]] == [0.7, math.inf]
        assert [r["positives"] for r in m["segments"]] == [2, 0]

    # oracle at 0.7: TP 1, FP 0, recall 1/2 -> %Segs 100, AvgR 0.5, MSE 0 over segment 0
    o = res["oracle"]
    assert (o["pct_segs"], o["avg_recall"], o["threshold_mse"]) == (100.0, 0.5, 0.0)
    # Pooled over both segments: TP 1, FP 0 (segment 1 accepts nothing at inf), 2
    # positives; one correct decision bounds the precision by 0.05^(1/1) = 0.05.
    assert (o["pooled_tp"], o["pooled_fp"], o["pooled_positives"], o["pooled_recall"]) == (1, 0, 2, 0.5)
    assert o["pooled_precision_lower95"] == pytest.approx(0.05, abs=1e-12)
    assert o["pooled_accepted"] == 1
    # Segment 1 accepts nothing: no precision, no bound, and it meets by convention.
    assert (o["segments"][1]["precision"], o["segments"][1]["precision_lower95"]) == (None, None)
    seg0 = o["segments"][0]
    assert (seg0["threshold"], seg0["tp"], seg0["fp"], seg0["precision"], seg0["recall"], seg0["meets"]) == (
        0.7, 1, 0, 1.0, 0.5, True
    )

    # calibration-threshold 0.9: segment 0 accepts nothing -> precision 1 (meets), recall 0
    # segment 1 accepts d3's 0.9 (inclusive) -> FP 1, precision 0, not met -- but skipped
    # MSE over segment 0 only: (0.9 - 0.7)^2 = 0.04
    c = res["calibration-threshold"]
    assert [r["threshold"] for r in c["segments"]] == [0.9, 0.9]
    assert [(r["tp"], r["fp"], r["meets"]) for r in c["segments"]] == [(0, 0, True), (0, 1, False)]
    assert (c["pct_segs"], c["avg_recall"]) == (100.0, 0.0)
    assert c["threshold_mse"] == pytest.approx(0.04, abs=1e-15)
    # pooled: TP 0, FP 1 -> precision 0, bound 0
    assert (c["pooled_precision"], c["pooled_precision_lower95"]) == (0.0, 0.0)

    # quantile-transfer: k clips to 2, so every deployment query uses subset {c0, c1}:
    #   t = 0.9; sample (0.1, 0.2, 0.3, 0.4, 0.9, 0.95): c = 5 -> q = 4/5 for everyone
    # segment 0 scores sorted (0.1, 0.2, 0.3, 0.5, 0.6, 0.7): h = 5 * 0.8 = 4 -> 0.6
    #   accepts 0.7 (T) and 0.6 (F): precision 1/2 >= 0.5 meets, recall 1/2
    # segment 1 scores sorted (0.1, 0.2, 0.3, 0.4, 0.5, 0.9): h = 4 -> 0.5
    # MSE over segment 0: (0.6 - 0.7)^2 = 0.01
    q = res["quantile-transfer"]
    assert [r["threshold"] for r in q["segments"]] == [0.6, 0.5]
    assert (q["segments"][0]["tp"], q["segments"][0]["fp"]) == (1, 1)
    assert (q["pct_segs"], q["avg_recall"]) == (100.0, 0.5)
    assert q["threshold_mse"] == pytest.approx(0.01, abs=1e-15)

    # schubert-calibrated on (0.1, 0.2, 0.3, 0.4, 0.9, 0.95): mu = (0.3 + 0.4) / 2 = 0.35;
    # |S - mu| sorted (0.05, 0.05, 0.15, 0.25, 0.55, 0.6) -> median 0.2 -> t = 0.35 + Z * 0.2 / 0.675
    sc = res["schubert-calibrated"]
    assert sc["segments"][0]["threshold"] == pytest.approx(0.35 + Z * 0.2 / 0.675, abs=1e-12)
    assert sc["segments"][1]["threshold"] == sc["segments"][0]["threshold"]
    # schubert on segment 0 (0.1, 0.2, 0.3, 0.5, 0.6, 0.7): mu = 0.4; |S - mu| sorted
    # (0.1, 0.1, 0.2, 0.2, 0.3, 0.3) -> median 0.2 -> t = 0.4 + Z * 0.2 / 0.675 (accepts nothing)
    s = res["schubert"]
    assert s["segments"][0]["threshold"] == pytest.approx(0.4 + Z * 0.2 / 0.675, abs=1e-12)
    assert (s["pct_segs"], s["avg_recall"]) == (100.0, 0.0)


def test_evaluate_defaults_and_no_counted_segment():
    # |Q| = 7 with fractions 0.3 and 0.2: calibration floor(2.1) = 2, size ceil(1.4) = 2
    res = evaluate(TINY_S, TINY_GT, precision=0.5, cal_fraction=0.3, segment_fraction=0.2,
                   methods=["oracle"])
    assert list(res["methods"]) == ["oracle"]
    assert len(res["methods"]["oracle"]["segments"]) == 2
    # only segment (2, 4) = d2, d3, which has no positives -> nothing counted -> None
    res = evaluate(TINY_S[:, [0, 1, 4, 5]], TINY_GT[:, [0, 1, 4, 5]], cal_queries=2,
                   segment_size=2, methods=["oracle", "schubert"])
    for m in res["methods"].values():
        assert m["segments_counted"] == 0 and m["segments_skipped"] == 1
        assert m["pct_segs"] is None and m["avg_recall"] is None and m["threshold_mse"] is None


def test_evaluate_deploy_fraction_leaves_a_gap():
    # |Q| = 7, one calibration query (c0), deploy_fraction 0.72: the last floor(5.04) = 5
    # queries deploy (d0..d4, columns 2..6); column 1 (c1) is unused.
    res = evaluate(TINY_S, TINY_GT, precision=0.5, cal_queries=1, segment_size=2,
                   deploy_fraction=0.72)["methods"]
    # Same segments as without the gap: (0, 2) = d0 d1 and (2, 4) = d2 d3.
    assert [(r["start"], r["end"]) for r in res["oracle"]["segments"]] == [(0, 2), (2, 4)]
    assert [r["oracle_threshold"] for r in res["oracle"]["segments"]] == [0.7, math.inf]
    # schubert-calibrated on c0 alone (0.9, 0.1, 0.3): mu = 0.3, |S - mu| = (0.6, 0.2, 0)
    # -> median 0.2 -> t = 0.3 + Z * 0.2 / 0.675
    t = res["schubert-calibrated"]["segments"][0]["threshold"]
    assert t == pytest.approx(0.3 + Z * 0.2 / 0.675, abs=1e-12)
    # calibration-threshold on c0 alone: its best match 0.9 is correct -> 0.9
    assert res["calibration-threshold"]["segments"][0]["threshold"] == 0.9
    # 2 calibration queries + the last floor(0.72 * 7) = 5 fit exactly; 3 + 5 overlap
    with pytest.raises(ValueError, match="overlap"):
        evaluate(TINY_S, TINY_GT, cal_queries=3, segment_size=2, deploy_fraction=0.72)


# ---------------------------------------------------------------------------------------
# Section 10: bad input
# ---------------------------------------------------------------------------------------

S2 = np.array([[0.9, 0.1], [0.2, 0.8]])
G2 = np.eye(2, dtype=bool)


@pytest.mark.parametrize(
    ("call", "exc", "match"),
    [
        (lambda: best_threshold(np.array([[0.1, np.nan], [0.2, 0.3]]), G2),
         ValueError, "s contains NaN at row 0, column 1"),
        (lambda: best_threshold(np.array([[0.1, 0.2], [np.inf, 0.3]]), G2),
         ValueError, "s contains an infinite value at row 1, column 0"),
        (lambda: quantile_transfer(np.array([[0.1, 0.2], [-np.inf, 0.3]]), G2, S2),
         ValueError, "s_cal contains an infinite"),
        (lambda: quantile_transfer(S2, G2, np.array([[0.1], [np.nan]])),
         ValueError, "s_val contains NaN at row 1, column 0"),
        (lambda: best_threshold(S2, np.eye(2, 3, dtype=bool)), ValueError, "gt shape 2x3 does not match s shape 2x2"),
        (lambda: quantile_transfer(S2, np.eye(3, 2, dtype=bool), S2),
         ValueError, "gt_cal shape 3x2 does not match s_cal shape 2x2"),
        (lambda: best_threshold(S2, G2, gt_soft=np.ones((2, 1), bool)), ValueError, "gt_soft shape 2x1"),
        (lambda: quantile_transfer(S2, G2, np.ones((3, 2))), ValueError, "s_val has |DB| = 3 but s_cal has |DB| = 2"),
        (lambda: quantile_transfer(S2, G2, np.ones((2, 3)), query_major=True), ValueError, "s_val has |DB| = 3"),
        (lambda: best_threshold(np.zeros((0, 3)), np.zeros((0, 3), bool)), ValueError, "s is empty"),
        (lambda: best_threshold(np.zeros((3, 0)), np.zeros((3, 0), bool)), ValueError, "s is empty"),
        (lambda: best_threshold(np.ones(3), np.ones(3, bool)), ValueError, "s must be a 2-D matrix"),
        (lambda: best_threshold(np.ones((2, 2, 2)), np.ones((2, 2, 2), bool)), ValueError, "s must be a 2-D matrix"),
        (lambda: best_threshold(S2, np.ones(2, bool)), ValueError, "gt must be a 2-D matrix"),
        (lambda: best_threshold(S2.astype(np.int64), G2), TypeError, "s must be float32 or float64"),
        (lambda: best_threshold(S2.astype(np.float16), G2), TypeError, "s must be float32 or float64"),
        (lambda: best_threshold(S2 > 0.5, G2), TypeError, "s must be float32 or float64"),
        (lambda: best_threshold(S2, G2.astype(np.float64)), TypeError, "gt must be bool or integer"),
        (lambda: best_threshold(S2, G2, gt_soft=S2), TypeError, "gt_soft must be bool or integer"),
        (lambda: best_threshold(S2, np.array([[1, 0], [2, 1]])), ValueError, "gt contains 2 at row 1, column 0"),
        (lambda: best_threshold(S2, np.array([[1, -1], [0, 1]])), ValueError, "gt contains -1"),
        (lambda: quantile_transfer(S2, G2, S2, gt_soft=np.array([[0, 3], [0, 0]])), ValueError, "gt_soft contains 3"),
        (lambda: quantile_transfer(S2, G2, S2, k=0), ValueError, "k must be >= 1, got 0"),
        (lambda: quantile_transfer(S2, G2, S2, k=-3), ValueError, "k must be >= 1, got -3"),
        (lambda: quantile_transfer(S2, G2, S2, k=2.5), TypeError, "k must be an integer"),
        (lambda: evaluate(S2, G2, k=0), ValueError, "k must be >= 1"),
        (lambda: best_threshold(S2, G2, precision=1.5), ValueError, r"precision must be in \(0, 1\], got 1.5"),
        (lambda: best_threshold(S2, G2, precision=0.0), ValueError, "precision must be in"),
        (lambda: best_threshold(S2, G2, precision=-0.5), ValueError, "precision must be in"),
        (lambda: best_threshold(S2, G2, precision=float("nan")), ValueError, "precision must be in"),
        (lambda: quantile_transfer(S2, G2, S2, precision=1.01), ValueError, "precision must be in"),
        (lambda: best_threshold(S2, G2, matching="both"), ValueError, "matching must be"),
        (lambda: counts(S2, G2, float("nan")), ValueError, "threshold"),
        (lambda: quantile_transfer(S2, G2, S2, segment_size=0), ValueError, "segment_size must be >= 1"),
        (lambda: quantile_transfer(S2, G2, S2, segment_size=3),
         ValueError, "segment_size must be <= the number of deployment queries"),
        (lambda: schubert_threshold(np.array([[np.nan]])), ValueError, "s contains NaN"),
        (lambda: schubert_threshold(np.ones((2, 2), np.int32)), TypeError, "s must be float32"),
        (lambda: schubert_threshold(np.ones(4)), ValueError, "2-D"),
        (lambda: evaluate(TINY_S, TINY_GT, methods=["magic"]), ValueError, "unknown method 'magic'"),
        (lambda: evaluate(TINY_S, TINY_GT, cal_queries=7), ValueError, "calibration set"),
        (lambda: evaluate(TINY_S, TINY_GT, cal_queries=0), ValueError, "cal_queries must be >= 1"),
        # floor(0.1 * 7) = 0 calibration queries
        (lambda: evaluate(TINY_S, TINY_GT), ValueError, "calibration set"),
        (lambda: evaluate(TINY_S, TINY_GT, cal_fraction=1.5), ValueError, "cal_fraction must be in"),
        (lambda: evaluate(TINY_S, TINY_GT, cal_queries=2, segment_size=6),
         ValueError, "segment size 6 is larger than the 5 deployment"),
        (lambda: evaluate(TINY_S, TINY_GT, cal_queries=2, segment_size=0), ValueError, "segment_size must be >= 1"),
        (lambda: evaluate(TINY_S, TINY_GT, cal_queries=2, segment_fraction=0.0),
         ValueError, "segment_fraction must be in"),
        (lambda: evaluate(TINY_S, TINY_GT[:, :6], cal_queries=2),
         ValueError, "gt shape 3x6 does not match s shape 3x7"),
    ],
)
def test_bad_input(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def test_query_major_shape_message_uses_callers_orientation():
    with pytest.raises(ValueError, match="gt shape 2x3 does not match s shape 3x2"):
        best_threshold(np.ones((3, 2)), np.ones((2, 3), bool), query_major=True)


# ---------------------------------------------------------------------------------------
# Real data: Corridor (111 x 111)
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def corridor(shared_data):
    d = shared_data / "vprbench-corridor"
    return {
        name: np.load(d / f"S_{name}.npy") for name in ("AMOSNet", "CoHOG")
    }, np.load(d / "GT.npy")


@pytest.mark.parametrize("name", ["AMOSNet", "CoHOG"])
def test_corridor_quantile_transfer_smoke(corridor, name):
    mats, gt = corridor
    s = mats[name]
    s_cal, gt_cal, s_val = s[:, :11], gt[:, :11], s[:, 11:]
    res = quantile_transfer(s_cal, gt_cal, s_val, k=10, segment_size=2)
    assert len(res.segments) == 50 and res.segments[-1] == (98, 100)
    assert np.all((res.query_quantiles >= 0) & (res.query_quantiles <= 1))
    assert np.all((res.quantiles >= 0) & (res.quantiles <= 1))
    assert np.all(np.isfinite(res.thresholds))
    assert np.all(res.query_weights >= 0)
    assert res.neighbours.shape == (100, 10)
    assert all(len(set(row)) == 10 and row.min() >= 0 and row.max() < 11 for row in res.neighbours)
    # every batch quantile is one of its segment's q_j
    for (a, b), q in zip(res.segments, res.quantiles, strict=True):
        assert q in res.query_quantiles[a:b]
    # section 5's round trip: feeding q_j back on its subset's sample returns t_j, except
    # when t_j is reject-all or the subset's maximum (both give q_j = 1)
    s64 = s_cal.astype(np.float64)
    for j in range(100):
        t, q = res.query_thresholds[j], res.query_quantiles[j]
        if q < 1:
            assert ref._linear_quantile(s64[:, res.neighbours[j]], q) == t
    # the same run, query-major
    res_t = quantile_transfer(s_cal.T, gt_cal.T, s_val.T, segment_size=2, query_major=True)
    assert np.array_equal(res_t.thresholds, res.thresholds)


def test_corridor_evaluate_smoke(corridor):
    mats, gt = corridor
    res = evaluate(mats["AMOSNet"], gt)["methods"]  # 11 calibrate; 50 segments of 2
    oracle = res["oracle"]
    assert oracle["pct_segs"] == 100.0  # the oracle always meets its target
    for name, m in res.items():
        # The oracle bounds every score threshold; a gated method is not one (its
        # margin gate can keep a segment clean where no score threshold does).
        bounded = name not in GATED
        assert len(m["segments"]) == 50
        assert m["segments_counted"] + m["segments_skipped"] == 50
        assert m["segments_counted"] > 0
        assert 0.0 <= m["pct_segs"] <= 100.0
        assert 0.0 <= m["avg_recall"] <= (oracle["avg_recall"] if bounded else 1.0)
        assert m["threshold_mse"] is None or m["threshold_mse"] >= 0
        for r, o in zip(m["segments"], oracle["segments"], strict=True):
            assert r["oracle_threshold"] == o["threshold"]
            if r["meets"] and r["positives"] > 0 and bounded:
                assert r["recall"] <= o["recall"]
    assert all(math.isfinite(r["threshold"]) for r in res["quantile-transfer"]["segments"])
