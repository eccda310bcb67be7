"""Similarity from descriptors and sequence matching (extensions beyond the paper).

- ``qtvpr.cosine_similarity`` equals NumPy's cosine of L2-normalised rows, on random
  descriptors (hypothesis) and on the real Nordland HOG descriptors in ../shared/data.
- ``qtvpr.sequence_match`` equals the plain NumPy definition, entry by entry.
- The sequence-averaged Nordland matrix reproduces the R@1 of the data README.
- ``qtvpr-cli similarity`` writes what the wheel returns.
- Bad input raises TypeError/ValueError naming the argument.
"""

from __future__ import annotations

import inspect
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import qtvpr
from test_cli import run_cli

SETTINGS = settings(max_examples=200, deadline=None, derandomize=True)


def numpy_cosine(db: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``normalize(db) @ normalize(q).T`` in float64."""
    db, q = np.asarray(db, np.float64), np.asarray(q, np.float64)
    return (db / np.linalg.norm(db, axis=1, keepdims=True)) @ (q / np.linalg.norm(q, axis=1, keepdims=True)).T


def numpy_sequence(s: np.ndarray, length: int, causal: bool = False) -> np.ndarray:
    """The definition: the mean of ``s[i+d, j+d]`` over the window's offsets inside."""
    n, m = s.shape
    offsets = range(-(length - 1), 1) if causal else range(-(length - 1) // 2, (length - 1) // 2 + 1)
    total, count = np.zeros((n, m)), np.zeros((n, m))
    for d in offsets:
        # Entries (i, j) with (i + d, j + d) inside.
        i0, i1 = max(0, -d), min(n, n - d)
        j0, j1 = max(0, -d), min(m, m - d)
        if i0 < i1 and j0 < j1:
            total[i0:i1, j0:j1] += s[i0 + d : i1 + d, j0 + d : j1 + d]
            count[i0:i1, j0:j1] += 1
    return total / count


def recall_at_1(s: np.ndarray, tolerance: int = 1) -> float:
    """Fraction of queries whose best match is within ``tolerance`` frames (data README)."""
    best = s.argmax(axis=0)
    return float(np.mean(np.abs(best - np.arange(s.shape[1])) <= tolerance))


# ---------------------------------------------------------------------------------------
# Random cases
# ---------------------------------------------------------------------------------------


@st.composite
def descriptor_pairs(draw):
    n_db, n_q = draw(st.integers(1, 12)), draw(st.integers(1, 12))
    dim = draw(st.integers(1, 40))
    scale = draw(st.sampled_from([1.0, 1e-30, 1e30]))
    dtypes = draw(st.tuples(st.sampled_from([np.float32, np.float64]), st.sampled_from([np.float32, np.float64])))
    values = st.floats(-1.0, 1.0, allow_nan=False, width=32)
    db = np.array(draw(st.lists(values, min_size=n_db * dim, max_size=n_db * dim)), dtype=dtypes[0])
    q = np.array(draw(st.lists(values, min_size=n_q * dim, max_size=n_q * dim)), dtype=dtypes[1])
    db, q = db.reshape(n_db, dim) * dtypes[0](scale), q.reshape(n_q, dim)
    # No zero rows (their cosine is undefined and an error, tested below).
    db[np.all(db == 0, axis=1), 0] = 1
    q[np.all(q == 0, axis=1), -1] = -1
    layout = draw(st.sampled_from(["C", "F", "strided"]))
    if layout == "F":
        db, q = np.asfortranarray(db), np.asfortranarray(q)
    elif layout == "strided":
        db = np.repeat(db, 2, axis=1)[:, ::2]
        q = np.ascontiguousarray(q[::-1])[::-1]
    return db, q


@SETTINGS
@given(descriptor_pairs())
def test_cosine_equals_numpy(pair):
    db, q = pair
    got = qtvpr.cosine_similarity(db, q)
    assert got.dtype == np.float32 and got.shape == (db.shape[0], q.shape[0])
    assert got.flags.c_contiguous
    np.testing.assert_allclose(got, numpy_cosine(db, q), rtol=0, atol=1e-6)


@st.composite
def sequence_cases(draw):
    n, m = draw(st.integers(1, 25)), draw(st.integers(1, 25))
    dtype = draw(st.sampled_from([np.float32, np.float64]))
    values = st.floats(-1e3, 1e3, allow_nan=False, width=32)
    s = np.array(draw(st.lists(values, min_size=n * m, max_size=n * m)), dtype=dtype).reshape(n, m)
    if draw(st.booleans()):
        s = s.T
    length = 2 * draw(st.integers(0, 20)) + 1
    return s, length, draw(st.booleans())


@SETTINGS
@given(sequence_cases())
def test_sequence_match_equals_definition(case):
    s, length, causal = case
    got = qtvpr.sequence_match(s, length, causal=causal)
    assert got.dtype == s.dtype and got.shape == s.shape
    want = numpy_sequence(s.astype(np.float64), length, causal)
    # Sums are float64; a float32 result is rounded once.
    np.testing.assert_allclose(got, want, rtol=1e-12 if s.dtype == np.float64 else 1e-7, atol=1e-9)


def test_sequence_match_hand_computed():
    # L = 3 centred on [[1, 2, 3], [4, 5, 6]]: (0,0) = (1+5)/2, (0,1) = (2+6)/2, (0,2) = 3,
    # (1,0) = 4, (1,1) = (1+5)/2, (1,2) = (2+6)/2.
    s = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    np.testing.assert_array_equal(qtvpr.sequence_match(s, 3), [[3, 4, 3], [4, 3, 4]])
    # Causal, d in -2..0: row 0 unchanged; (1,1) = (1+5)/2; (1,2) = (2+6)/2.
    np.testing.assert_array_equal(qtvpr.sequence_match(s, 3, causal=True), [[1, 2, 3], [4, 3, 4]])
    np.testing.assert_array_equal(qtvpr.sequence_match(s, 1), s)


def test_cosine_with_sequence_is_sequence_of_cosine():
    rng = np.random.default_rng(0)
    db, q = rng.random((30, 8), dtype=np.float32), rng.random((25, 8), dtype=np.float32)
    s = qtvpr.cosine_similarity(db, q)
    for causal in (False, True):
        np.testing.assert_array_equal(
            qtvpr.cosine_similarity(db, q, sequence=5, causal=causal), qtvpr.sequence_match(s, 5, causal=causal)
        )


# ---------------------------------------------------------------------------------------
# Real data: Nordland HOG descriptors
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def nordland(shared_data: Path):
    d = shared_data / "nordland-hog"
    return np.load(d / "db_winter.npy"), np.load(d / "query_summer.npy")


def test_nordland_cosine_equals_numpy(nordland):
    db, q = nordland
    got = qtvpr.cosine_similarity(db, q)
    # NumPy's own float32 computation, as users write it:
    norm = lambda a: a / np.linalg.norm(a, axis=1, keepdims=True)  # noqa: E731
    assert np.abs(got - norm(db) @ norm(q).T).max() < 1e-5
    # And the exact (float64) cosine, to float32 rounding.
    assert np.abs(got - numpy_cosine(db, q)).max() < 1e-7
    np.testing.assert_array_equal(qtvpr.cosine_similarity(db.astype(np.float64), q), got)


def test_nordland_recall_at_1(nordland):
    """The data README: R@1 about 0.23 single-frame, about 0.81 with 11-frame sequences
    (GT: |i - j| <= 1). Measured: 806, 2886 and (causal) 2785 of 3576 queries."""
    db, q = nordland
    single = qtvpr.cosine_similarity(db, q)
    assert 0.22 <= recall_at_1(single) <= 0.23
    sequence = qtvpr.cosine_similarity(db, q, sequence=11)
    assert 0.80 <= recall_at_1(sequence) <= 0.82
    causal = qtvpr.cosine_similarity(db, q, sequence=11, causal=True)
    assert 0.77 <= recall_at_1(causal) <= 0.79
    # The sequence version is the README's definition, d in -5..5, inside the matrix.
    np.testing.assert_allclose(sequence, numpy_sequence(single.astype(np.float64), 11), rtol=0, atol=1e-6)


def test_cli_similarity_equals_wheel(cli, nordland, shared_data, tmp_path):
    db, q = nordland
    d = shared_data / "nordland-hog"
    for extra, kwargs in [([], {}), (["--sequence", "11"], dict(sequence=11)),
                          (["--sequence", "11", "--causal"], dict(sequence=11, causal=True))]:
        out = tmp_path / "S.npy"
        res = run_cli(cli, "similarity", "--db", d / "db_winter.npy", "--queries", d / "query_summer.npy",
                      "--output", out, *extra)
        assert res.returncode == 0, res.stderr
        got = np.load(out)
        assert got.dtype == np.float32 and got.shape == (db.shape[0], q.shape[0])
        np.testing.assert_array_equal(got, qtvpr.cosine_similarity(db, q, **kwargs))


def test_help_shows_signatures_and_docs():
    for f in (qtvpr.cosine_similarity, qtvpr.sequence_match, qtvpr.ground_truth_tolerance,
              qtvpr.ground_truth_positions):
        assert f.__doc__ and f.__text_signature__, f.__name__
    assert str(inspect.signature(qtvpr.cosine_similarity)) == "(db, queries, *, sequence=None, causal=False)"
    assert str(inspect.signature(qtvpr.sequence_match)) == "(s, length, *, causal=False)"
    assert str(inspect.signature(qtvpr.ground_truth_positions)) == "(db_positions, query_positions, radius)"


# ---------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------

DB = np.array([[3.0, 4.0], [1.0, 0.0]], dtype=np.float32)
Q = np.array([[4.0, 3.0], [0.0, 2.0], [-1.0, 0.0]])


def with_value(a: np.ndarray, row: int, col: int, value) -> np.ndarray:
    b = a.astype(np.result_type(a, type(value))).copy()
    b[row, col] = value
    return b


COSINE_CASES = [
    ("dims", dict(queries=np.ones((2, 3))), ValueError, r"^queries, db: .*3 columns but .*2"),
    ("db-nan", dict(db=with_value(DB, 1, 0, np.nan)), ValueError, r"^db: .*NaN at row 1, column 0"),
    ("q-inf", dict(queries=with_value(Q, 2, 1, np.inf)), ValueError, r"^queries: .*inf at row 2, column 1"),
    ("db-zero-row", dict(db=with_value(DB, 1, 0, 0.0)), ValueError, r"^db: .*row 1 is all zeros"),
    ("q-zero-row", dict(queries=np.zeros((1, 2))), ValueError, r"^queries: .*row 0 is all zeros"),
    ("db-no-rows", dict(db=DB[:0]), ValueError, r"^db: .*empty \(shape 0x2\)"),
    ("q-no-dims", dict(queries=Q[:, :0], db=DB[:, :0]), ValueError, r"^db: .*empty"),
    ("db-1d", dict(db=DB[0]), ValueError, r"^db must be a 2-D matrix, got a 1-D array"),
    ("q-3d", dict(queries=Q[None]), ValueError, r"^queries must be a 2-D matrix, got a 3-D array"),
    ("db-int", dict(db=DB.astype(np.int64)), TypeError, r"^db must be a float32 or float64 array, got int64"),
    ("q-complex", dict(queries=Q.astype(np.complex128)), TypeError, r"^queries must be a float32 or float64"),
    ("q-float16", dict(queries=Q.astype(np.float16)), TypeError, r"^queries must be"),
    ("db-bool", dict(db=DB > 1), TypeError, r"^db must be"),
    ("even", dict(sequence=4), ValueError, r"^sequence length must be odd and >= 1, got 4$"),
    ("zero", dict(sequence=0), ValueError, r"sequence length must be odd and >= 1, got 0"),
    ("negative", dict(sequence=-3), ValueError, r"sequence length must be odd and >= 1, got -3"),
    ("float-length", dict(sequence=3.0), TypeError, r"sequence"),
    ("causal-alone", dict(causal=True), ValueError, r"causal=True needs a sequence length"),
]


@pytest.mark.parametrize("overrides, exc, pattern", [c[1:] for c in COSINE_CASES], ids=[c[0] for c in COSINE_CASES])
def test_cosine_errors(overrides, exc, pattern):
    kwargs = dict(db=DB, queries=Q) | overrides
    db, queries = kwargs.pop("db"), kwargs.pop("queries")
    with pytest.raises(exc, match=pattern):
        qtvpr.cosine_similarity(db, queries, **kwargs)


SEQUENCE_CASES = [
    (dict(length=2), ValueError, r"sequence length must be odd and >= 1, got 2"),
    (dict(length=-1), ValueError, r"got -1"),
    (dict(s=with_value(Q, 0, 0, np.nan)), ValueError, r"^s: .*NaN at row 0, column 0"),
    (dict(s=Q[:0]), ValueError, r"^s: .*empty"),
    (dict(s=Q[0]), ValueError, r"^s must be a 2-D matrix"),
    (dict(s=Q.astype(np.int32)), TypeError, r"^s must be a float32 or float64 array"),
]


@pytest.mark.parametrize("overrides, exc, pattern", SEQUENCE_CASES)
def test_sequence_match_errors(overrides, exc, pattern):
    kwargs = dict(s=Q, length=3) | overrides
    with pytest.raises(exc, match=pattern):
        qtvpr.sequence_match(kwargs.pop("s"), kwargs.pop("length"), **kwargs)


def test_cli_similarity_errors(cli, tmp_path):
    """The CLI's bad input (exit 2, one line naming the option and file, no output)."""
    np.save(tmp_path / "db.npy", DB)
    np.save(tmp_path / "q3.npy", np.ones((2, 3)))
    np.save(tmp_path / "zero.npy", with_value(DB, 0, 0, 0.0) * [[0, 0], [1, 1]])
    out = tmp_path / "S.npy"
    for queries, extra, message in [
        ("q3.npy", [], "error: --queries {t}/q3.npy / --db {t}/db.npy: query descriptor matrix has 3 columns"),
        ("zero.npy", [], "error: --queries {t}/zero.npy: query descriptor matrix row 0 is all zeros"),
        ("db.npy", ["--sequence", "4"], "error: --sequence: sequence length must be odd and >= 1, got 4"),
    ]:
        res = run_cli(cli, "similarity", "--db", tmp_path / "db.npy", "--queries", tmp_path / queries,
                      "--output", out, *extra)
        assert res.returncode == 2
        assert res.stderr.startswith(message.format(t=tmp_path)), res.stderr
        assert len(res.stderr.strip().splitlines()) == 1
        assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["db.npy", "q3.npy", "zero.npy"]
