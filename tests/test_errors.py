"""Bad input (semantics §10): the right exception type, with a message naming the
argument, and never a panic.

The table-driven cases run against both the wheel and the reference, so the two agree
on which exception each case raises; the wheel-only tests cover its extra entry points
(``Calibration``, ``ranked_correlation``) and its messages.
"""

from __future__ import annotations

import ast
import functools
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import qtvpr
from qtvpr import reference as ref

IMPLEMENTATIONS = {"wheel": qtvpr, "reference": ref}

S_CAL = np.array([[0.9, 0.2, 0.4], [0.1, 0.8, 0.3], [0.3, 0.4, 0.7], [0.2, 0.1, 0.1]])
GT_CAL = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]], dtype=bool)
S_VAL = np.array(
    [[0.7, 0.1, 0.2, 0.5, 0.3], [0.2, 0.6, 0.3, 0.1, 0.2], [0.1, 0.3, 0.5, 0.4, 0.9], [0.0, 0.2, 0.1, 0.3, 0.4]]
)


def with_value(a: np.ndarray, value) -> np.ndarray:
    b = a.astype(np.result_type(a, type(value))).copy()
    b[1, 2] = value
    return b


def int_gt(value) -> np.ndarray:
    g = GT_CAL.astype(np.int64)
    g[2, 1] = value
    return g


# (id, arguments of quantile_transfer that replace the defaults, exception, argument named)
TRANSFER_CASES = [
    ("gt-shape", dict(gt_cal=GT_CAL[:3]), ValueError, "gt_cal"),
    ("gt-shape-transposed", dict(gt_cal=GT_CAL.T.copy()), ValueError, "gt_cal"),
    ("soft-shape", dict(gt_soft=GT_CAL[:, :2]), ValueError, "gt_soft"),
    ("db-mismatch", dict(s_val=S_VAL[:3]), ValueError, "s_val"),
    ("cal-nan", dict(s_cal=with_value(S_CAL, np.nan)), ValueError, "s_cal"),
    ("cal-inf", dict(s_cal=with_value(S_CAL, np.inf)), ValueError, "s_cal"),
    ("cal-neg-inf", dict(s_cal=with_value(S_CAL, -np.inf)), ValueError, "s_cal"),
    ("val-nan", dict(s_val=with_value(S_VAL, np.nan)), ValueError, "s_val"),
    ("val-inf-f32", dict(s_val=with_value(S_VAL.astype(np.float32), np.inf)), ValueError, "s_val"),
    ("cal-no-rows", dict(s_cal=S_CAL[:0], gt_cal=GT_CAL[:0]), ValueError, "empty"),
    ("cal-no-cols", dict(s_cal=S_CAL[:, :0], gt_cal=GT_CAL[:, :0]), ValueError, "empty"),
    ("val-no-cols", dict(s_val=S_VAL[:, :0]), ValueError, "s_val"),
    ("val-no-rows", dict(s_val=S_VAL[:0]), ValueError, "s_val"),
    ("cal-1d", dict(s_cal=S_CAL[:, 0]), ValueError, "s_cal"),
    ("cal-3d", dict(s_cal=S_CAL[None]), ValueError, "s_cal"),
    ("val-1d", dict(s_val=S_VAL[0]), ValueError, "s_val"),
    ("gt-1d", dict(gt_cal=GT_CAL[:, 0]), ValueError, "gt_cal"),
    ("gt-3d", dict(gt_cal=GT_CAL[None]), ValueError, "gt_cal"),
    ("cal-complex", dict(s_cal=S_CAL.astype(np.complex128)), TypeError, "s_cal"),
    ("cal-str", dict(s_cal=S_CAL.astype(str)), TypeError, "s_cal"),
    ("cal-object", dict(s_cal=S_CAL.astype(object)), TypeError, "s_cal"),
    ("cal-float16", dict(s_cal=S_CAL.astype(np.float16)), TypeError, "s_cal"),
    ("cal-int", dict(s_cal=(S_CAL * 10).astype(np.int64)), TypeError, "s_cal"),
    ("cal-bool", dict(s_cal=S_CAL > 0.5), TypeError, "s_cal"),
    ("val-complex", dict(s_val=S_VAL.astype(np.complex64)), TypeError, "s_val"),
    ("val-longdouble", dict(s_val=S_VAL.astype(np.longdouble)), TypeError, "s_val"),
    ("gt-two", dict(gt_cal=int_gt(2)), ValueError, "gt_cal"),
    ("gt-minus-one", dict(gt_cal=int_gt(-1)), ValueError, "gt_cal"),
    ("soft-two", dict(gt_soft=int_gt(2).astype(np.uint8)), ValueError, "gt_soft"),
    ("gt-float", dict(gt_cal=GT_CAL.astype(np.float64)), TypeError, "gt_cal"),
    ("gt-complex", dict(gt_cal=GT_CAL.astype(np.complex128)), TypeError, "gt_cal"),
    ("gt-str", dict(gt_cal=GT_CAL.astype(str)), TypeError, "gt_cal"),
    ("soft-float", dict(gt_soft=GT_CAL.astype(np.float32)), TypeError, "gt_soft"),
    ("k-zero", dict(k=0), ValueError, "k"),
    ("k-negative", dict(k=-3), ValueError, "k"),
    ("k-float", dict(k=2.0), TypeError, "k"),
    ("precision-zero", dict(precision=0.0), ValueError, "precision"),
    ("precision-negative", dict(precision=-0.5), ValueError, "precision"),
    ("precision-above-one", dict(precision=1.5), ValueError, "precision"),
    ("precision-nan", dict(precision=float("nan")), ValueError, "precision"),
    ("precision-inf", dict(precision=float("inf")), ValueError, "precision"),
    ("segment-zero", dict(segment_size=0), ValueError, "segment_size"),
    ("segment-negative", dict(segment_size=-1), ValueError, "segment_size"),
    ("segment-too-large", dict(segment_size=6), ValueError, "segment_size"),
    ("matching-foo", dict(matching="foo"), ValueError, "matching"),
    ("matching-case", dict(matching="Single"), ValueError, "matching"),
]


@pytest.fixture(params=sorted(IMPLEMENTATIONS))
def impl(request):
    return IMPLEMENTATIONS[request.param]


@pytest.mark.parametrize(
    "overrides, exc, name", [c[1:] for c in TRANSFER_CASES], ids=[c[0] for c in TRANSFER_CASES]
)
def test_quantile_transfer(impl, overrides, exc, name):
    kwargs = dict(s_cal=S_CAL, gt_cal=GT_CAL, s_val=S_VAL) | overrides
    s_cal, gt_cal, s_val = kwargs.pop("s_cal"), kwargs.pop("gt_cal"), kwargs.pop("s_val")
    with pytest.raises(exc, match=re.escape(name)):
        impl.quantile_transfer(s_cal, gt_cal, s_val, **kwargs)


@pytest.mark.parametrize(
    "overrides, exc, name", [c[1:] for c in TRANSFER_CASES], ids=[c[0] for c in TRANSFER_CASES]
)
def test_quantile_transfer_query_major(overrides, exc, name):
    """The same cases on transposed input: same exception (wheel only)."""
    kwargs = dict(s_cal=S_CAL, gt_cal=GT_CAL, s_val=S_VAL) | overrides
    matrices = [kwargs.pop(n) for n in ("s_cal", "gt_cal", "s_val")]
    matrices = [np.asarray(m).T for m in matrices]
    if kwargs.get("gt_soft") is not None:
        kwargs["gt_soft"] = np.asarray(kwargs["gt_soft"]).T
    with pytest.raises(exc, match=re.escape(name)):
        qtvpr.quantile_transfer(*matrices, query_major=True, **kwargs)


MATRIX_CASES = [
    ("shape", dict(gt=GT_CAL[:, :2]), ValueError, "gt"),
    ("soft-shape", dict(gt_soft=GT_CAL[:2]), ValueError, "gt_soft"),
    ("nan", dict(s=with_value(S_CAL, np.nan)), ValueError, "s"),
    ("inf", dict(s=with_value(S_CAL.astype(np.float32), np.inf)), ValueError, "s"),
    ("neg-inf", dict(s=with_value(S_CAL, -np.inf)), ValueError, "s"),
    ("empty", dict(s=S_CAL[:0], gt=GT_CAL[:0]), ValueError, "empty"),
    ("1d", dict(s=S_CAL[0], gt=GT_CAL[0]), ValueError, "s"),
    ("3d", dict(s=S_CAL[None], gt=GT_CAL[None]), ValueError, "s"),
    ("complex", dict(s=S_CAL.astype(np.complex128)), TypeError, "s"),
    ("object", dict(s=S_CAL.astype(object)), TypeError, "s"),
    ("float16", dict(s=S_CAL.astype(np.float16)), TypeError, "s"),
    ("int", dict(s=np.ones(S_CAL.shape, dtype=np.int32)), TypeError, "s"),
    ("gt-two", dict(gt=int_gt(2)), ValueError, "gt"),
    ("gt-minus-one", dict(gt=int_gt(-1).astype(np.int8)), ValueError, "gt"),
    ("gt-float", dict(gt=GT_CAL.astype(np.float64)), TypeError, "gt"),
    ("matching-foo", dict(matching="foo"), ValueError, "matching"),
]


@pytest.mark.parametrize(
    "overrides, exc, name", [c[1:] for c in MATRIX_CASES], ids=[c[0] for c in MATRIX_CASES]
)
@pytest.mark.parametrize("function", ["best_threshold", "counts"])
def test_matrix_functions(impl, function, overrides, exc, name):
    kwargs = dict(s=S_CAL, gt=GT_CAL) | overrides
    s, gt = kwargs.pop("s"), kwargs.pop("gt")
    args = (s, gt) if function == "best_threshold" else (s, gt, 0.5)
    with pytest.raises(exc, match=re.escape(name)):
        getattr(impl, function)(*args, **kwargs)


@pytest.mark.parametrize("precision", [0.0, 1.5, float("nan"), -1.0])
def test_best_threshold_precision(impl, precision):
    with pytest.raises(ValueError, match="precision"):
        impl.best_threshold(S_CAL, GT_CAL, precision=precision)


def test_counts_nan_threshold(impl):
    with pytest.raises(ValueError, match="threshold"):
        impl.counts(S_CAL, GT_CAL, float("nan"))


# ---------------------------------------------------------------------------------------
# Wheel only
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "overrides, exc, name", [c[1:] for c in TRANSFER_CASES], ids=[c[0] for c in TRANSFER_CASES]
)
def test_calibration(overrides, exc, name):
    """Calibration + transfer raise what quantile_transfer raises."""
    kwargs = dict(s_cal=S_CAL, gt_cal=GT_CAL, s_val=S_VAL) | overrides
    s_cal, gt_cal, s_val = kwargs.pop("s_cal"), kwargs.pop("gt_cal"), kwargs.pop("s_val")
    cal_kwargs = {n: kwargs.pop(n) for n in ("gt_soft", "matching") if n in kwargs}
    with pytest.raises(exc, match=re.escape(name)):
        qtvpr.Calibration(s_cal, gt_cal, **cal_kwargs).transfer(s_val, **kwargs)


@pytest.mark.parametrize("precision", [0.0, 1.5, float("nan")])
def test_calibration_threshold_precision(precision):
    with pytest.raises(ValueError, match="precision"):
        qtvpr.Calibration(S_CAL, GT_CAL).threshold(precision)


@pytest.mark.parametrize(
    "s_val, s_cal, exc",
    [
        (S_VAL[:3], S_CAL, ValueError),
        (with_value(S_VAL, np.nan), S_CAL, ValueError),
        (S_VAL, with_value(S_CAL, -np.inf), ValueError),
        (S_VAL[:, :0], S_CAL, ValueError),
        (S_VAL, S_CAL[0], ValueError),
        (S_VAL.astype(np.complex128), S_CAL, TypeError),
        (S_VAL, S_CAL.astype(np.int16), TypeError),
    ],
)
def test_ranked_correlation(s_val, s_cal, exc):
    with pytest.raises(exc):
        qtvpr.ranked_correlation(s_val, s_cal)


def test_messages_name_argument_and_position():
    with pytest.raises(ValueError, match=r"^s_cal: .*NaN at row 1, column 2"):
        qtvpr.quantile_transfer(with_value(S_CAL, np.nan), GT_CAL, S_VAL)
    with pytest.raises(ValueError, match=r"^gt_cal: .*value 2 at row 2, column 1"):
        qtvpr.quantile_transfer(S_CAL, int_gt(2), S_VAL)
    with pytest.raises(ValueError, match=r"^gt_cal: .*shape 3x3 does not match .*shape 4x3"):
        qtvpr.quantile_transfer(S_CAL, GT_CAL[:3], S_VAL)
    with pytest.raises(TypeError, match=r"^s_val must be a float32 or float64 array, got complex128$"):
        qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL.astype(np.complex128))


def test_query_major_messages_use_callers_orientation():
    # The caller's matrices are |Q| x |DB|; positions and shapes are given as passed.
    s = with_value(S_CAL, np.nan).T.copy()  # NaN at caller's row 2, column 1
    with pytest.raises(ValueError, match=r"NaN at row 2, column 1"):
        qtvpr.quantile_transfer(s, GT_CAL.T, S_VAL.T, query_major=True)
    g = int_gt(2).T.copy()  # 2 at caller's row 1, column 2
    with pytest.raises(ValueError, match=r"value 2 at row 1, column 2"):
        qtvpr.quantile_transfer(S_CAL.T, g, S_VAL.T, query_major=True)
    with pytest.raises(ValueError, match=r"^gt: .*shape 2x4 does not match .*shape 3x4"):
        qtvpr.best_threshold(S_CAL.T, GT_CAL.T[:2], query_major=True)


def test_lists_are_accepted_and_checked():
    got = qtvpr.quantile_transfer(S_CAL.tolist(), GT_CAL.tolist(), S_VAL.tolist(), k=2)
    want = qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL, k=2)
    np.testing.assert_array_equal(got.thresholds, want.thresholds)
    with pytest.raises(TypeError, match="s_cal"):
        qtvpr.quantile_transfer([[1, 2], [3, 4]], [[1, 0], [0, 1]], [[1.0], [2.0]])
    with pytest.raises(ValueError, match="s_cal"):
        qtvpr.quantile_transfer([0.5, 0.25], [1, 0], [[1.0], [2.0]])


@pytest.mark.parametrize(
    ("name", "value", "call"),
    [
        ("k", True, lambda cal: qtvpr.Online(cal, k=True, window=2)),
        ("window", True, lambda cal: qtvpr.Online(cal, window=True)),
        ("min_window", False, lambda cal: qtvpr.Online(cal, window=2, min_window=False)),
        ("segment_size", True, lambda cal: cal.transfer(S_VAL, segment_size=True)),
        ("k", True, lambda cal: qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL, k=True)),
        ("threads", True, lambda cal: qtvpr.set_threads(True)),
    ],
)
def test_a_bool_is_not_an_integer_argument(name, value, call):
    """Issue 49: ``Online(k=True)`` ran with k = 1, since Python counts True as 1. An
    integer argument refuses a bool with a ``TypeError`` naming it."""
    with pytest.raises(TypeError) as info:
        call(qtvpr.Calibration(S_CAL, GT_CAL))
    assert str(info.value) == f"{name} must be an int, got a bool ({value})"


def _float_arguments() -> set[tuple[str, str]]:
    """Every (callable, argument) of the stubs typed as a float (``float``, ``float |
    None``, a sequence of floats), so that a float argument added to the binding is
    checked below, or this test fails until it is."""
    tree = ast.parse((Path(qtvpr.__file__).parent / "_native.pyi").read_text())
    found = set()

    def walk(nodes, prefix=""):
        for node in nodes:
            if isinstance(node, ast.ClassDef):
                walk(node.body, f"{prefix}{node.name}.")
            elif isinstance(node, ast.FunctionDef):
                a = node.args
                for arg in a.posonlyargs + a.args + a.kwonlyargs:
                    kind = ast.unparse(arg.annotation) if arg.annotation is not None else ""
                    if "float" in kind and "NDArray" not in kind:
                        found.add((prefix + node.name, arg.arg))

    walk(tree.body)
    return found


def _cal():
    return qtvpr.Calibration(S_CAL, GT_CAL)


def _evaluate_with(function, name, value):
    return getattr(qtvpr, function)(S_CAL, GT_CAL, **{name: value})


def _labels_with(name, value):
    return qtvpr.ground_truth_from_sequence(np.eye(20), **{name: value})


#: Each call that takes the sequence gate's parameters, with one of them (and the gate).
SEQUENCE_GATE_CALLS = {
    "Calibration.transfer": lambda **kw: _cal().transfer(S_VAL, **kw),
    "Calibration._check_transfer": lambda **kw: _cal()._check_transfer(S_VAL.shape, **kw),
    "Calibration._transfer_at": lambda **kw: _cal()._transfer_at(S_VAL, 0, **kw),
    "Calibration.save": lambda **kw: _cal().save("never-written.npz", **kw),
    "Online.__new__": lambda **kw: qtvpr.Online(_cal(), window=2, **kw),
    "quantile_transfer": lambda **kw: qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL, **kw),
    "evaluate": lambda **kw: qtvpr.evaluate(S_CAL, GT_CAL, **kw),
    "ablation": lambda **kw: qtvpr.ablation(S_CAL, GT_CAL, **kw),
}


def _sequence_with(function, name, value):
    return SEQUENCE_GATE_CALLS[function](**{name: value})


#: A call of each float argument with ``value``, the others valid.
FLOAT_CALLS = {
    ("TransferResult._from_parts", "gate"): lambda v: qtvpr.TransferResult._from_parts(
        *(np.zeros(0),) * 2, [], *(np.zeros(0),) * 3, np.zeros((0, 1), dtype=np.int64), gate=v),
    ("Calibration.__new__", "cal_fraction"): lambda v: qtvpr.Calibration(
        np.hstack([S_CAL, S_CAL]), np.hstack([GT_CAL, GT_CAL]), cal_fraction=v),
    ("Calibration.transfer", "precision"): lambda v: _cal().transfer(S_VAL, precision=v),
    ("Calibration._check_transfer", "precision"): lambda v: _cal()._check_transfer(S_VAL.shape, precision=v),
    ("Calibration._transfer_at", "precision"): lambda v: _cal()._transfer_at(S_VAL, 0, precision=v),
    ("Calibration.threshold", "precision"): lambda v: _cal().threshold(precision=v),
    ("Calibration.gate", "precision"): lambda v: _cal().gate(precision=v),
    ("Calibration.save", "precision"): lambda v: _cal().save("never-written.npz", precision=v),
    ("Online.__new__", "precision"): lambda v: qtvpr.Online(_cal(), window=2, precision=v),
    ("quantile_transfer", "precision"): lambda v: qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL, precision=v),
    ("quantile_transfer", "cal_fraction"): lambda v: qtvpr.quantile_transfer(
        np.hstack([S_CAL, S_CAL]), np.hstack([GT_CAL, GT_CAL]), cal_fraction=v),
    ("best_threshold", "precision"): lambda v: qtvpr.best_threshold(S_CAL, GT_CAL, precision=v),
    ("counts", "threshold"): lambda v: qtvpr.counts(S_CAL, GT_CAL, v),
    ("ground_truth_positions", "radius"): lambda v: qtvpr.ground_truth_positions(
        np.zeros((2, 2)), np.zeros((3, 2)), v),
    **{(f, name): functools.partial(_evaluate_with, f, name)
       for f in ("evaluate", "ablation")
       for name in ("precision", "cal_fraction", "segment_fraction", "deploy_fraction")},
    **{("ground_truth_from_sequence", name): functools.partial(_labels_with, name)
       for name in ("positive_level", "negative_level", "sequence_speed", "sequence_tolerance", "sequence_drift")},
    ("TransferResult._from_parts", "consistency_level"): lambda v: qtvpr.TransferResult._from_parts(
        *(np.zeros(0),) * 2, [], *(np.zeros(0),) * 3, np.zeros((0, 1), dtype=np.int64), consistency_level=v),
    # The sequence gate's float parameters (semantics §15), wherever they are taken.
    **{(f, name): functools.partial(_sequence_with, f, name) for f in SEQUENCE_GATE_CALLS for name in
       ("sequence_level", "sequence_speed", "sequence_tolerance", "sequence_drift")},
}


def test_every_float_argument_is_checked_here():
    assert _float_arguments() == set(FLOAT_CALLS)


@pytest.mark.parametrize("value", [True, False])
@pytest.mark.parametrize(("function", "name"), sorted(FLOAT_CALLS))
def test_a_bool_is_not_a_float_argument(function, name, value):
    """Issue 49: pyo3 converts a bool to a float, so ``precision=True`` ran at 1.0. Every
    float argument refuses a bool with a ``TypeError`` naming it, as an integer one does,
    before anything is computed or written."""
    with pytest.raises(TypeError) as info:
        FLOAT_CALLS[(function, name)](value)
    assert str(info.value) == f"{name} must be a float, got a bool ({value})"
    assert not Path("never-written.npz").exists()


def test_a_bool_in_a_list_of_floats_is_refused_too():
    with pytest.raises(TypeError, match=r"^cal_fraction must be a float, got a bool \(True\)$"):
        qtvpr.ablation(S_CAL, GT_CAL, cal_fraction=[0.5, True])
    # A float argument still takes an int or a NumPy scalar.
    assert qtvpr.best_threshold(S_CAL, GT_CAL, precision=1) == qtvpr.best_threshold(
        S_CAL, GT_CAL, precision=np.float32(1.0))


def test_more_threads_than_the_cap_are_refused():
    """Issue 49: ``set_threads(10**6)`` started up to 65,535 threads, one by one, for
    minutes. The cap is 1024; a count above it is refused before a thread starts."""
    for n in (1025, 10**6):
        with pytest.raises(ValueError, match=rf"^threads must be at most 1024, got {n}$"):
            qtvpr.set_threads(n)


# The child: a transfer on the Corridor (which starts the pool), then its thresholds and
# the pool's threads, counted by name once there are at least argv[2] of them (a thread
# names itself when it first runs) or after 30 s.
_POOL_CHILD = """
import json, sys, time
from pathlib import Path
import numpy as np, qtvpr
data, want = Path(sys.argv[1]), int(sys.argv[2])
cal = qtvpr.Calibration(np.load(data / "cal_S.npy"), np.load(data / "cal_GT.npy"))
r = cal.transfer(np.load(data / "deploy_S.npy"), segment_size=20)
def named():
    return sum((t / "comm").read_text().startswith("qtvpr-") for t in Path("/proc/self/task").iterdir())
deadline = time.monotonic() + 30
while named() < want and time.monotonic() < deadline:
    time.sleep(0.01)
print(json.dumps([named(), r.thresholds.tolist()]))
"""


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts the pool's threads in /proc (Linux)")
def test_rayon_num_threads_above_the_cap_starts_the_cap():
    """``RAYON_NUM_THREADS=1000000`` started up to 65,535 threads, one by one, for
    minutes, on the first computation. An environment variable cannot be refused with an
    error there: the pool starts 1024 threads, and the answer is the same."""
    data = Path(__file__).resolve().parents[1] / "data" / "corridor"
    cal = qtvpr.Calibration(np.load(data / "cal_S.npy"), np.load(data / "cal_GT.npy"))
    want = cal.transfer(np.load(data / "deploy_S.npy"), segment_size=20).thresholds.tolist()
    for value, threads in (("1000000", 1024), ("3", 3)):
        env = dict(os.environ, RAYON_NUM_THREADS=value)
        proc = subprocess.run([sys.executable, "-c", _POOL_CHILD, str(data), str(threads)], env=env,
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        assert json.loads(proc.stdout) == [threads, want], value
