"""Ground truth from positions or from a frame tolerance (extensions beyond the paper).

- ``qtvpr.ground_truth_positions`` equals the brute-force NumPy
  ``((db[:, None] - q[None]) ** 2).sum(-1) <= r * r`` (float64 coordinates) on random
  positions, with many points exactly at the radius (integer grids, radii taken from
  actual distances, UTM-sized coordinates), bit for bit.
- ``qtvpr.ground_truth_tolerance`` equals ``|i - j| <= tolerance``.
- ``qtvpr-cli ground-truth`` writes what the wheel returns, and ``threshold
  --cal-gt-tolerance`` equals ``--cal-gt`` with the equivalent file on real data.
- Bad input raises TypeError/ValueError naming the argument.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import qtvpr
from test_cli import REPO, run_cli

SETTINGS = settings(max_examples=300, deadline=None, derandomize=True)


def brute_force(db, q, radius) -> np.ndarray:
    db, q = np.asarray(db, np.float64), np.asarray(q, np.float64)
    return ((db[:, None] - q[None]) ** 2).sum(-1) <= radius * radius


@st.composite
def position_cases(draw):
    k = draw(st.sampled_from([2, 3]))
    n_db, n_q = draw(st.integers(1, 40)), draw(st.integers(1, 40))
    mode = draw(st.sampled_from(["grid", "float", "utm"]))
    if mode == "grid":
        # Integer coordinates: distances like 5 = |(3, 4)| sit exactly at integer radii.
        coord = st.integers(-6, 6).map(float)
    elif mode == "float":
        coord = st.floats(-100, 100, allow_nan=False)
    else:
        coord = st.floats(-60, 60, allow_nan=False)
    db = np.array(draw(st.lists(coord, min_size=n_db * k, max_size=n_db * k))).reshape(n_db, k)
    q = np.array(draw(st.lists(coord, min_size=n_q * k, max_size=n_q * k))).reshape(n_q, k)
    if mode == "utm":
        # UTM east/north (and an altitude): large offsets, centimetre detail.
        base = np.array([500_000.0, 5_000_000.0, 100.0][:k])
        db, q = np.round(db + base, 2), np.round(q + base, 2)
    if draw(st.booleans()):
        # Duplicates: a robot standing still.
        q = np.concatenate([q, np.repeat(q[:1], draw(st.integers(1, 40)), axis=0)])
    d2 = ((db[:, None] - q[None]) ** 2).sum(-1)
    choice = draw(st.sampled_from(["pair", "integer", "any"]))
    if choice == "pair":
        # Exactly the distance of one pair: the brute force decides which side it falls on.
        i, j = draw(st.integers(0, n_db - 1)), draw(st.integers(0, q.shape[0] - 1))
        radius = float(np.sqrt(d2[i, j]))
    elif choice == "integer":
        radius = float(draw(st.integers(0, 12)))
    else:
        radius = draw(st.floats(0, 200, allow_nan=False))
    dtype = draw(st.sampled_from([np.float64, np.float32]))
    if dtype == np.float32 and mode != "utm":
        db = db.astype(np.float32)
    layout = draw(st.sampled_from(["C", "F", "strided"]))
    if layout == "F":
        db, q = np.asfortranarray(db), np.asfortranarray(q)
    elif layout == "strided":
        q = np.repeat(q, 2, axis=0)[::2]
    return db, q, radius


@SETTINGS
@given(position_cases())
def test_positions_equal_brute_force(case):
    db, q, radius = case
    got = qtvpr.ground_truth_positions(db, q, radius)
    assert got.dtype == np.bool_ and got.shape == (db.shape[0], q.shape[0])
    np.testing.assert_array_equal(got, brute_force(db, q, radius))


def test_positions_hand_computed():
    # Queries at (0, 0) and (10, 0), radius 5: (3, 4) is exactly 5 from the first
    # (inside); (7, 0) is 3 from the second; (5, 0.001) is just over 5 from both;
    # (10, -5) is exactly 5 from the second.
    q = np.array([[0.0, 0.0], [10.0, 0.0]])
    db = np.array([[3.0, 4.0], [7.0, 0.0], [5.0, 0.001], [10.0, -5.0]], dtype=np.float32)
    np.testing.assert_array_equal(
        qtvpr.ground_truth_positions(db, q, 5.0), [[1, 0], [0, 1], [0, 0], [0, 1]]
    )


def test_positions_on_a_trajectory():
    """A realistic case: two passes along the same 2 km route, 1 m apart on average,
    25 m radius (VPR-methods-evaluation's positives), 3 m soft margin."""
    rng = np.random.default_rng(7)
    t = np.linspace(0, 4 * np.pi, 2000)
    route = np.stack([500_000 + 150 * t + 40 * np.sin(t), 5_000_000 + 80 * np.cos(t / 2)], axis=1)
    db = route + rng.normal(0, 2, route.shape)
    q = route[::2] + rng.normal(0, 2, route[::2].shape)
    for radius in (25.0, 28.0):
        np.testing.assert_array_equal(qtvpr.ground_truth_positions(db, q, radius), brute_force(db, q, radius))


@SETTINGS
@given(st.integers(1, 60), st.integers(1, 60), st.integers(0, 70))
def test_tolerance_equals_definition(n_db, n_q, tolerance):
    got = qtvpr.ground_truth_tolerance(n_db, n_q, tolerance)
    assert got.dtype == np.bool_
    np.testing.assert_array_equal(got, np.abs(np.arange(n_db)[:, None] - np.arange(n_q)[None]) <= tolerance)


def test_tolerance_is_the_corridor_ground_truth():
    gt = np.load(REPO / "data" / "corridor" / "cal_GT.npy")
    np.testing.assert_array_equal(qtvpr.ground_truth_tolerance(*gt.shape, 2), gt)


# ---------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------


def test_cli_ground_truth_equals_wheel(cli, tmp_path):
    rng = np.random.default_rng(3)
    db = np.round(rng.uniform(0, 100, (300, 2)), 1)
    q = np.round(rng.uniform(0, 100, (200, 2)), 1).astype(np.float32)
    np.save(tmp_path / "db.npy", db)
    np.save(tmp_path / "q.npy", q)
    res = run_cli(cli, "ground-truth", "--db-positions", tmp_path / "db.npy", "--query-positions",
                  tmp_path / "q.npy", "--radius", 7.5, "--soft-radius", 10, "--output", tmp_path / "GT.npz")
    assert res.returncode == 0, res.stderr
    with np.load(tmp_path / "GT.npz") as npz:
        assert sorted(npz.files) == ["GThard", "GTsoft"]
        np.testing.assert_array_equal(npz["GThard"], qtvpr.ground_truth_positions(db, q, 7.5))
        np.testing.assert_array_equal(npz["GTsoft"], brute_force(db, q, 10.0))
    res = run_cli(cli, "ground-truth", "--tolerance", 3, "--db-count", 50, "--query-count", 40,
                  "--output", tmp_path / "tol.npy")
    assert res.returncode == 0, res.stderr
    np.testing.assert_array_equal(np.load(tmp_path / "tol.npy"), qtvpr.ground_truth_tolerance(50, 40, 3))


def test_cli_threshold_tolerance_equals_ground_truth_file(cli):
    """On the embedded Corridor data, whose ground truth is |i - j| <= 2."""
    d = REPO / "data" / "corridor"
    common = ["threshold", "--cal", d / "cal_S.npy", "--val", d / "deploy_S.npy", "--segment-size", 10]
    a = run_cli(cli, *common, "--cal-gt", d / "cal_GT.npy")
    b = run_cli(cli, *common, "--cal-gt-tolerance", 2)
    assert a.returncode == 0 and b.returncode == 0, (a.stderr, b.stderr)
    assert json.loads(a.stdout)["segments"] == json.loads(b.stdout)["segments"]


def test_cli_ground_truth_errors(cli, tmp_path):
    np.save(tmp_path / "p.npy", np.zeros((3, 2)))
    np.save(tmp_path / "p4.npy", np.zeros((3, 4)))
    out = tmp_path / "GT.npy"
    for args, message in [
        (["--radius", -1], "error: --radius: radius must be a finite number >= 0, got -1"),
        (["--radius", 1, "--soft-radius", 0.5, "--soft-output", tmp_path / "s.npy"],
         "error: --soft-radius 0.5 is smaller than --radius 1"),
    ]:
        res = run_cli(cli, "ground-truth", "--db-positions", tmp_path / "p.npy", "--query-positions",
                      tmp_path / "p.npy", "--output", out, *args)
        assert res.returncode == 2 and res.stderr.startswith(message), res.stderr
    res = run_cli(cli, "ground-truth", "--db-positions", tmp_path / "p4.npy", "--query-positions",
                  tmp_path / "p.npy", "--radius", 1, "--output", out)
    assert res.returncode == 2
    assert res.stderr.startswith(f"error: --db-positions {tmp_path}/p4.npy: database position matrix has 4 columns")
    assert len(res.stderr.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.npy", "p4.npy"]


# ---------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------

P = np.array([[0.0, 0.0], [1.0, 1.0]])

POSITION_CASES = [
    ("negative-radius", dict(radius=-1.0), ValueError, r"^radius must be a finite number >= 0, got -1"),
    ("nan-radius", dict(radius=float("nan")), ValueError, r"^radius must be a finite number >= 0, got NaN"),
    ("inf-radius", dict(radius=float("inf")), ValueError, r"^radius must be"),
    ("str-radius", dict(radius="5"), TypeError, r"radius"),
    ("four-columns", dict(db_positions=np.zeros((2, 4))), ValueError, r"^db_positions: .*4 columns; positions must be"),
    ("one-column", dict(query_positions=np.zeros((2, 1))), ValueError, r"^query_positions: .*1 columns"),
    ("mismatch", dict(query_positions=np.zeros((2, 3))), ValueError,
     r"^query_positions, db_positions: .*3 columns but .*2"),
    ("nan", dict(db_positions=np.array([[0.0, np.nan]])), ValueError, r"^db_positions: .*NaN at row 0, column 1"),
    ("inf", dict(query_positions=np.array([[np.inf, 0.0]], np.float32)), ValueError, r"^query_positions: .*inf"),
    ("empty", dict(db_positions=P[:0]), ValueError, r"^db_positions: .*empty"),
    ("1d", dict(db_positions=P[0]), ValueError, r"^db_positions must be a 2-D matrix, got a 1-D array"),
    ("3d", dict(query_positions=P[None]), ValueError, r"^query_positions must be a 2-D matrix, got a 3-D"),
    ("int", dict(db_positions=P.astype(np.int64)), TypeError, r"^db_positions must be a float32 or float64 array"),
    ("complex", dict(query_positions=P.astype(complex)), TypeError, r"^query_positions must be a float32"),
]


@pytest.mark.parametrize(
    "overrides, exc, pattern", [c[1:] for c in POSITION_CASES], ids=[c[0] for c in POSITION_CASES]
)
def test_positions_errors(overrides, exc, pattern):
    kwargs = dict(db_positions=P, query_positions=P, radius=1.0) | overrides
    with pytest.raises(exc, match=pattern):
        qtvpr.ground_truth_positions(kwargs.pop("db_positions"), kwargs.pop("query_positions"), kwargs.pop("radius"))


@pytest.mark.parametrize(
    "args, exc, pattern",
    [
        ((3, 3, -1), ValueError, r"^tolerance must be >= 0, got -1$"),
        ((-2, 3, 1), ValueError, r"^n_db must be >= 0, got -2$"),
        ((0, 3, 1), ValueError, r"^n_db, n_queries: ground truth is empty \(shape 0x3\)$"),
        ((3, 0, 1), ValueError, r"empty"),
        ((3, 3, 1.5), TypeError, r"tolerance"),
    ],
)
def test_tolerance_errors(args, exc, pattern):
    with pytest.raises(exc, match=pattern):
        qtvpr.ground_truth_tolerance(*args)
