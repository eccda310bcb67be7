"""The shape of the Python API: names, signatures (the same as the reference's),
result types, and inputs the binding reads in place."""

from __future__ import annotations

import inspect
import subprocess
import sys

import numpy as np
import pytest

import qtvpr
from qtvpr import reference as ref

S_CAL = np.array([[0.9, 0.2, 0.4], [0.1, 0.8, 0.3], [0.3, 0.4, 0.7], [0.2, 0.1, 0.1]])
GT_CAL = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]], dtype=bool)
S_VAL = np.array(
    [[0.7, 0.1, 0.2, 0.5, 0.3], [0.2, 0.6, 0.3, 0.1, 0.2], [0.1, 0.3, 0.5, 0.4, 0.9], [0.0, 0.2, 0.1, 0.3, 0.4]]
)


def test_public_names():
    assert sorted(qtvpr.__all__) == sorted(
        ["Calibration", "Online", "OnlineDecision", "OnlineDecisions", "TransferResult", "__version__", "ablation",
         "best_threshold", "counts", "evaluate", "margins", "quantile_transfer", "ranked_correlation",
         "schubert_threshold"]
        # extensions
        + ["Descriptors", "cosine_similarity", "ground_truth_positions", "ground_truth_tolerance", "image_paths",
           "sequence_match", "utm_positions"]
        # self-motion labels (semantics §16)
        + ["SelfMotionLabels", "ground_truth_from_sequence"]
        # the thread pool (no reference counterpart)
        + ["set_threads"]
    )
    for name in qtvpr.__all__:
        assert hasattr(qtvpr, name), name
    assert isinstance(qtvpr.__version__, str) and qtvpr.__version__


@pytest.mark.parametrize(
    "name", ["quantile_transfer", "best_threshold", "counts", "evaluate", "ablation", "ground_truth_from_sequence"]
)
def test_signatures_match_reference(name):
    assert inspect.signature(getattr(qtvpr, name)) == inspect.signature(getattr(ref, name)).replace(
        return_annotation=inspect.Signature.empty
    )


def test_docstrings_and_signatures_for_help():
    for f in (qtvpr.quantile_transfer, qtvpr.best_threshold, qtvpr.counts, qtvpr.ranked_correlation):
        assert f.__doc__ and f.__text_signature__, f.__name__
    assert "k=None, precision=None" in qtvpr.Calibration.transfer.__text_signature__  # the file's, else 10 and 1.0
    assert qtvpr.Calibration.__doc__
    params = inspect.signature(qtvpr.Calibration).parameters
    assert list(params) == [
        "s_cal", "gt_cal", "gt_soft", "matching", "query_major", "cal_queries", "cal_fraction", "sequence",
    ]


def test_transfer_result():
    r = qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL, k=5, segment_size=2)
    assert r.segments == [(0, 2), (2, 4), (4, 5)]
    for name in ("thresholds", "quantiles"):
        a = getattr(r, name)
        assert a.dtype == np.float64 and a.shape == (3,), name
    for name in ("query_quantiles", "query_thresholds", "query_weights"):
        a = getattr(r, name)
        assert a.dtype == np.float64 and a.shape == (5,), name
    # k = 5 is clipped to the 3 calibration queries.
    assert r.neighbours.dtype == np.int64 and r.neighbours.shape == (5, 3)
    # Three segments: every threshold shown, to 6 significant digits.
    t = r.thresholds
    assert repr(r) == f"TransferResult(segments=3, queries=5, k=3, thresholds=[{t[0]:.6g}, {t[1]:.6g}, {t[2]:.6g}])"
    with pytest.raises(AttributeError):
        r.thresholds = np.zeros(3)
    assert isinstance(r, qtvpr.TransferResult)


def test_transfer_result_repr_is_short():
    # Five segments of one query: the first three thresholds, then "...".
    r = qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL, k=5, segment_size=1)
    t = r.thresholds
    assert len(t) == 5
    first = f"{t[0]:.6g}, {t[1]:.6g}, {t[2]:.6g}"
    assert repr(r) == f"TransferResult(segments=5, queries=5, k=3, thresholds=[{first}, ...])"
    # Four segments: the "..." would hide one threshold, so all four are shown.
    r4 = qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL[:, :4], k=5, segment_size=1)
    assert repr(r4).endswith(", ".join(f"{x:.6g}" for x in r4.thresholds) + "])")
    # 10000 segments still print on one short line (the old repr printed an array of them).
    big = qtvpr.quantile_transfer(S_CAL, GT_CAL, np.tile(S_VAL, (1, 2000)), k=5, segment_size=1)
    assert repr(big) == repr(r).replace("segments=5, queries=5", "segments=10000, queries=10000")
    assert len(repr(big)) < 120


def test_reference_is_imported_on_first_use():
    # In a fresh interpreter: a bare `import qtvpr` does not load the reference (it
    # imports NumPy, ten times the cost of `import qtvpr`), and attribute access does.
    code = """
import sys, qtvpr
assert "qtvpr.reference" not in sys.modules
assert "reference" in dir(qtvpr) and "reference" not in qtvpr.__all__
f = qtvpr.reference.evaluate
assert "qtvpr.reference" in sys.modules and qtvpr.reference is sys.modules["qtvpr.reference"]
try:
    qtvpr.no_such_name
except AttributeError as e:
    assert str(e) == "module 'qtvpr' has no attribute 'no_such_name'", e
else:
    raise AssertionError("no AttributeError")
print(f.__module__)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout == "qtvpr.reference\n"


def test_calibration_object():
    cal = qtvpr.Calibration(S_CAL, GT_CAL, matching="multi")
    assert len(cal) == 3
    assert cal.matching == "multi"
    assert repr(cal) == "Calibration(queries=3, matching='multi')"
    assert cal.threshold() == ref.best_threshold(S_CAL, GT_CAL, matching="multi")
    a = cal.transfer(S_VAL, k=2)
    b = qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL, k=2, matching="multi")
    np.testing.assert_array_equal(a.thresholds, b.thresholds)
    np.testing.assert_array_equal(a.neighbours, b.neighbours)


def test_counts_types():
    c = qtvpr.counts(S_CAL, GT_CAL, 0.5)
    want = ref.counts(S_CAL, GT_CAL, 0.5)
    # The keys of an evaluate segment, in its order (qtvpr::report).
    assert list(c) == list(want) == ["tp", "fp", "accepted", "positives", "precision", "recall", "precision_lower95"]
    # The best matches 0.9, 0.8, 0.7 are all correct and >= 0.5: TP 3 of 3 positives, and
    # the lower bound of 3 correct of 3 is 0.05 ** (1 / 3).
    assert [c[k] for k in ("tp", "fp", "positives", "precision", "recall")] == [3, 0, 3, 1.0, 1.0]
    assert [type(c[k]) for k in ("tp", "fp", "positives", "precision", "recall")] == [int, int, int, float, float]
    assert c["precision_lower95"] == pytest.approx(0.05 ** (1 / 3), abs=1e-12)
    assert want["precision_lower95"] == pytest.approx(0.05 ** (1 / 3), abs=1e-12)
    # Nothing accepted: the precision rests on no decision, so it is undefined (None).
    nothing = qtvpr.counts(S_CAL, GT_CAL, np.inf)
    assert (nothing["tp"], nothing["accepted"], nothing["precision"], nothing["precision_lower95"]) == (
        0, 0, None, None)


def test_read_only_shared_and_byte_swapped_inputs():
    s = S_CAL.copy()
    s.flags.writeable = False
    want = qtvpr.quantile_transfer(S_CAL, GT_CAL, S_CAL, k=2)
    got = qtvpr.quantile_transfer(s, GT_CAL, s, k=2)  # the same read-only array twice
    np.testing.assert_array_equal(got.thresholds, want.thresholds)
    swapped = S_CAL.astype(S_CAL.dtype.newbyteorder())
    got = qtvpr.quantile_transfer(swapped, GT_CAL.astype(">i4"), S_CAL, k=2)
    np.testing.assert_array_equal(got.thresholds, want.thresholds)
    assert np.array_equal(S_CAL, swapped)  # the input is untouched


def test_empty_views_of_misaligned_arrays_are_errors_not_panics():
    # A float64 matrix at an odd address, and its empty slice: NumPy calls the slice
    # aligned, but it keeps the odd pointer (this panicked in the dev build).
    raw = np.frombuffer(bytearray(8 * S_CAL.size + 1), np.uint8)[1:].view(np.float64).reshape(S_CAL.shape)
    raw[...] = S_CAL
    empty = raw[:, :0]
    assert empty.ctypes.data % 8 != 0
    cal = qtvpr.Calibration(raw, GT_CAL)  # misaligned and not empty: converted
    with pytest.raises(ValueError, match=r"^s_val: deployment similarity is empty \(shape 4x0\)$"):
        cal.transfer(empty)
    assert len(qtvpr.Online(cal, window=2).push_many(empty)) == 0


def test_ranked_correlation_shape():
    r = qtvpr.ranked_correlation(S_VAL, S_CAL)
    assert r.shape == (5, 3) and r.dtype == np.float64
    np.testing.assert_array_equal(qtvpr.ranked_correlation(S_VAL.T, S_CAL.T, query_major=True), r)


def test_module_docstring_examples_run():
    """The examples of ``help(qtvpr)``, the online one included, run as written."""
    import doctest

    result = doctest.testmod(qtvpr)
    assert result.failed == 0 and result.attempted >= 10, result
