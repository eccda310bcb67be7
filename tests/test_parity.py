"""Property tests: the compiled wheel (``qtvpr``) equals the NumPy reference
(``qtvpr.reference``) on random small matrices.

The matrices are built to hit the spec's edge cases: scores drawn from a few levels so
that ties are everywhere (within a column, across columns, whole constant columns),
k larger than |Qcal|, soft ground truth, both matching modes, several precision
targets, segment sizes that do and do not divide |Qval|, float32 and float64, and
every memory layout NumPy can hand over (C, Fortran, strided, negative strides,
query-major).
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import qtvpr
from qtvpr import reference as ref

SETTINGS = settings(max_examples=300, deadline=None, derandomize=True)

PRECISIONS = [1.0, 0.9, 0.5, 0.75]
MATCHING = ["single", "multi"]
LAYOUTS = ["C", "F", "rows-strided", "cols-strided", "rows-reversed", "cols-reversed"]

#: Score levels: few distinct values so ties are frequent; negative scores included.
LEVELS = [-1.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0, 3.0]


def assert_same(actual, expected):
    """Equal to 1e-9, infinities in the same places."""
    np.testing.assert_allclose(np.asarray(actual), np.asarray(expected), rtol=0, atol=1e-9)


def with_layout(a: np.ndarray, layout: str) -> np.ndarray:
    """An array equal to ``a`` with another memory layout (a view into a new buffer)."""
    if layout == "C":
        return np.ascontiguousarray(a)
    if layout == "F":
        return np.asfortranarray(a)
    if layout == "rows-strided":
        big = np.zeros((2 * a.shape[0], a.shape[1]), dtype=a.dtype)
        big[::2] = a
        return big[::2]
    if layout == "cols-strided":
        big = np.zeros((a.shape[0], 3 * a.shape[1]), dtype=a.dtype)
        big[:, ::3] = a
        return big[:, ::3]
    if layout == "rows-reversed":
        return a[::-1].copy()[::-1]
    if layout == "cols-reversed":
        return a[:, ::-1].copy()[:, ::-1]
    raise AssertionError(layout)


@st.composite
def score_matrix(draw, rows: int, cols: int, dtype) -> np.ndarray:
    """Scores from a few levels (sometimes with one-off values), some columns constant."""
    levels = draw(st.lists(st.sampled_from(LEVELS), min_size=1, max_size=4, unique=True))
    values = st.sampled_from(levels)
    if draw(st.booleans()):
        values = st.one_of(values, st.floats(-2.0, 2.0, width=32))
    s = np.array(
        draw(st.lists(values, min_size=rows * cols, max_size=rows * cols)), dtype=dtype
    ).reshape(rows, cols)
    for j in draw(st.sets(st.integers(0, cols - 1), max_size=cols)):
        if draw(st.integers(0, 3)) == 0:  # a constant column now and then
            s[:, j] = s[0, j]
    return s


@st.composite
def bool_matrix(draw, rows: int, cols: int, density: float | None = None) -> np.ndarray:
    p = draw(st.sampled_from([0.0, 0.2, 0.5, 1.0])) if density is None else density
    bits = draw(st.lists(st.floats(0, 1), min_size=rows * cols, max_size=rows * cols))
    return (np.array(bits) < p).reshape(rows, cols) if p < 1.0 else np.ones((rows, cols), bool)


@st.composite
def labels(draw, rows: int, cols: int) -> np.ndarray:
    """Ground truth as bool or as an integer type holding 0/1."""
    g = draw(bool_matrix(rows, cols))
    return g.astype(draw(st.sampled_from([bool, np.int8, np.uint8, np.int32, np.int64])))


@st.composite
def oriented(draw, matrices: list[np.ndarray]):
    """The matrices each in a random layout, all transposed when query-major."""
    query_major = draw(st.booleans())
    out = []
    for a in matrices:
        a = with_layout(a.T if query_major else a, draw(st.sampled_from(LAYOUTS)))
        out.append(a)
    return out, query_major


@st.composite
def transfer_cases(draw):
    n_db = draw(st.integers(1, 12))
    n_cal = draw(st.integers(1, 8))
    n_val = draw(st.integers(1, 10))
    dtype = draw(st.sampled_from([np.float32, np.float64]))
    s_cal = draw(score_matrix(n_db, n_cal, dtype))
    s_val = draw(score_matrix(n_db, n_val, draw(st.sampled_from([np.float32, np.float64]))))
    gt = draw(labels(n_db, n_cal))
    soft = draw(st.none() | labels(n_db, n_cal))
    matrices = [s_cal, gt, s_val] + ([] if soft is None else [soft])
    matrices, query_major = draw(oriented(matrices))
    kwargs = dict(
        gt_soft=matrices[3] if soft is not None else None,
        k=draw(st.integers(1, 12)),
        precision=draw(st.sampled_from(PRECISIONS)),
        matching=draw(st.sampled_from(MATCHING)),
        segment_size=draw(st.none() | st.integers(1, n_val)),
        query_major=query_major,
    )
    return matrices[0], matrices[1], matrices[2], kwargs


def assert_transfer_equal(got, want):
    assert_same(got.thresholds, want.thresholds)
    assert_same(got.quantiles, want.quantiles)
    assert got.segments == want.segments
    assert_same(got.query_quantiles, want.query_quantiles)
    assert_same(got.query_thresholds, want.query_thresholds)
    assert_same(got.query_weights, want.query_weights)
    assert got.neighbours.dtype == np.int64
    np.testing.assert_array_equal(got.neighbours, want.neighbours)


@SETTINGS
@given(transfer_cases())
def test_quantile_transfer(case):
    s_cal, gt, s_val, kwargs = case
    want = ref.quantile_transfer(s_cal, gt, s_val, **kwargs)
    got = qtvpr.quantile_transfer(s_cal, gt, s_val, **kwargs)
    assert_transfer_equal(got, want)


@SETTINGS
@given(transfer_cases())
def test_calibration_reuse(case):
    """One Calibration, several transfers: each equals a fresh reference run."""
    s_cal, gt, s_val, kwargs = case
    qm = kwargs["query_major"]
    cal = qtvpr.Calibration(
        s_cal, gt, gt_soft=kwargs["gt_soft"], matching=kwargs["matching"], query_major=qm
    )
    assert len(cal) == (s_cal.shape[0] if qm else s_cal.shape[1])
    assert cal.matching == kwargs["matching"]
    for precision in PRECISIONS[:2]:
        k = kwargs["k"]
        want = ref.quantile_transfer(s_cal, gt, s_val, **{**kwargs, "precision": precision})
        got = cal.transfer(
            s_val, k=k, precision=precision, segment_size=kwargs["segment_size"], query_major=qm
        )
        assert_transfer_equal(got, want)
        want_t = ref.best_threshold(
            s_cal, gt, gt_soft=kwargs["gt_soft"], precision=precision,
            matching=kwargs["matching"], query_major=qm,
        )
        assert_same(cal.threshold(precision), want_t)


@st.composite
def matrix_cases(draw):
    rows, cols = draw(st.integers(1, 12)), draw(st.integers(1, 10))
    s = draw(score_matrix(rows, cols, draw(st.sampled_from([np.float32, np.float64]))))
    gt = draw(labels(rows, cols))
    soft = draw(st.none() | labels(rows, cols))
    matrices, query_major = draw(oriented([s, gt] + ([] if soft is None else [soft])))
    kwargs = dict(
        gt_soft=matrices[2] if soft is not None else None,
        matching=draw(st.sampled_from(MATCHING)),
        query_major=query_major,
    )
    # A threshold that is one of the scores (ties at the boundary), between them, or inf.
    threshold = draw(
        st.sampled_from([float(v) for v in np.unique(s)] + [np.inf, -np.inf])
        | st.floats(-3.0, 3.0)
    )
    return matrices[0], matrices[1], threshold, kwargs


@SETTINGS
@given(matrix_cases(), st.sampled_from(PRECISIONS))
def test_best_threshold(case, precision):
    s, gt, _, kwargs = case
    want = ref.best_threshold(s, gt, precision=precision, **kwargs)
    got = qtvpr.best_threshold(s, gt, precision=precision, **kwargs)
    assert isinstance(got, float)
    assert_same(got, want)


@SETTINGS
@given(matrix_cases())
def test_counts(case):
    s, gt, threshold, kwargs = case
    want = ref.counts(s, gt, threshold, **kwargs)
    got = qtvpr.counts(s, gt, threshold, **kwargs)
    assert got.keys() == want.keys()
    for key in ("tp", "fp", "accepted", "positives"):
        assert got[key] == want[key], key
    assert_same(got["recall"], want["recall"])
    # A precision (and its bound) is None where nothing is accepted.
    for key in ("precision", "precision_lower95"):
        if want[key] is None:
            assert got[key] is None, key
        else:
            assert_same(got[key], want[key])


@SETTINGS
@given(transfer_cases())
def test_ranked_correlation(case):
    """The correlation matrix equals the product of the reference's unit profiles."""
    s_cal, _, s_val, kwargs = case
    qm = kwargs["query_major"]
    cal, val = (np.asarray(s_cal, np.float64), np.asarray(s_val, np.float64))
    if qm:
        cal, val = cal.T, val.T
    want, _, _ = ref._calibration_neighbours(cal, val, 1)
    got = qtvpr.ranked_correlation(s_val, s_cal, query_major=qm)
    assert got.dtype == np.float64
    assert_same(got, want)
