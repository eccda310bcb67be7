"""File input to the Python API: every matrix argument also takes a path (``str`` or
``os.PathLike``) to a ``.npy`` (ground truth: ``.npy`` or a VPR_Tutorial ``.npz``), read
by the same Rust reader as the CLI. Good files give the same results as arrays; every
bad file of semantics §10 raises the exception a Python user expects, with a message
naming the argument and the file, and never a panic. Wheel only: the reference takes
arrays.
"""

from __future__ import annotations

import os
import re
import struct
from pathlib import Path

import numpy as np
import pytest

import qtvpr
from test_errors import GT_CAL, S_CAL, S_VAL, int_gt, with_value  # the same small case


def npy_raw(path: Path, descr: str, shape: tuple, payload: bytes, fortran: bool = False) -> Path:
    """A ``.npy`` written by hand, so that files no well-behaved writer makes can be made."""
    shape_text = f"({shape[0]},)" if len(shape) == 1 else "(" + ", ".join(map(str, shape)) + ")"
    header = f"{{'descr': '{descr}', 'fortran_order': {fortran}, 'shape': {shape_text}, }}"
    header += " " * ((-(10 + len(header) + 1)) % 64) + "\n"
    path.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + payload)
    return path


def save(path: Path, a) -> Path:
    np.save(path, a, allow_pickle=True)
    return path


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    return {
        "s_cal": save(tmp_path / "s_cal.npy", S_CAL),
        "gt_cal": save(tmp_path / "gt_cal.npy", GT_CAL),
        "s_val": save(tmp_path / "s_val.npy", S_VAL),
    }


# ---------------------------------------------------------------------------------------
# Good files
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("as_type", [str, Path], ids=["str", "PathLike"])
def test_paths_give_the_results_of_arrays(files, as_type):
    f = {n: as_type(p) for n, p in files.items()}
    for kwargs in (dict(k=2), dict(k=1, segment_size=2, precision=0.6, matching="multi")):
        want = qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL, **kwargs)
        got = qtvpr.quantile_transfer(f["s_cal"], f["gt_cal"], f["s_val"], **kwargs)
        np.testing.assert_array_equal(got.thresholds, want.thresholds)
        np.testing.assert_array_equal(got.neighbours, want.neighbours)
    cal = qtvpr.Calibration(f["s_cal"], f["gt_cal"])
    np.testing.assert_array_equal(
        cal.transfer(f["s_val"], k=2).thresholds, qtvpr.Calibration(S_CAL, GT_CAL).transfer(S_VAL, k=2).thresholds
    )
    # Arrays and paths mix freely.
    np.testing.assert_array_equal(cal.transfer(S_VAL, k=2).thresholds, cal.transfer(f["s_val"], k=2).thresholds)
    assert qtvpr.best_threshold(f["s_cal"], f["gt_cal"]) == qtvpr.best_threshold(S_CAL, GT_CAL)
    assert qtvpr.best_threshold(f["s_cal"], GT_CAL, precision=0.5) == qtvpr.best_threshold(S_CAL, GT_CAL, precision=0.5)
    assert qtvpr.counts(f["s_cal"], f["gt_cal"], 0.3) == qtvpr.counts(S_CAL, GT_CAL, 0.3)
    np.testing.assert_array_equal(
        qtvpr.ranked_correlation(f["s_val"], f["s_cal"]), qtvpr.ranked_correlation(S_VAL, S_CAL)
    )


def test_float32_fortran_query_major_and_integer_files(tmp_path):
    s_cal = save(tmp_path / "s_cal_t.npy", np.asfortranarray(S_CAL.T.astype(np.float32)))
    gt_cal = save(tmp_path / "gt_cal_t.npy", GT_CAL.T.astype(np.uint8))
    s_val = save(tmp_path / "s_val_t.npy", S_VAL.T)
    want = qtvpr.quantile_transfer(S_CAL.astype(np.float32), GT_CAL, S_VAL, k=2, segment_size=2)
    got = qtvpr.quantile_transfer(s_cal, gt_cal, s_val, k=2, segment_size=2, query_major=True)
    np.testing.assert_array_equal(got.thresholds, want.thresholds)


def test_npz_ground_truth_and_soft_files(tmp_path, files):
    soft = GT_CAL.copy()
    soft[1:, :] |= GT_CAL[:-1, :]
    np.savez(tmp_path / "GT.npz", GThard=GT_CAL, GTsoft=soft)
    npz = tmp_path / "GT.npz"
    soft_npy = save(tmp_path / "soft.npy", soft)
    for matching in ("single", "multi"):
        want = qtvpr.best_threshold(S_CAL, GT_CAL, gt_soft=soft, matching=matching, precision=0.5)
        for gt, gt_soft in [(npz, None), (files["gt_cal"], soft_npy), (files["gt_cal"], soft), (GT_CAL, soft_npy)]:
            got = qtvpr.best_threshold(files["s_cal"], gt, gt_soft=gt_soft, matching=matching, precision=0.5)
            assert got == want, (gt, gt_soft)
        # An explicit gt_soft takes precedence over the archive's GTsoft.
        no_soft = np.zeros_like(GT_CAL)
        assert qtvpr.best_threshold(S_CAL, npz, gt_soft=no_soft, matching=matching, precision=0.5) == (
            qtvpr.best_threshold(S_CAL, GT_CAL, matching=matching, precision=0.5)
        )
    cal = qtvpr.Calibration(files["s_cal"], npz, matching="multi")
    assert cal.threshold(0.5) == qtvpr.best_threshold(S_CAL, GT_CAL, gt_soft=soft, matching="multi", precision=0.5)


# ---------------------------------------------------------------------------------------
# Bad files: every semantics §10 case
# ---------------------------------------------------------------------------------------


def bad_file(tmp_path: Path, kind: str) -> Path:
    """A bad file of each kind; its name says what it is."""
    p = tmp_path / f"{kind}.npy"
    good = save(tmp_path / "good.npy", S_VAL).read_bytes()
    if kind == "nan":
        return save(p, with_value(S_VAL, np.nan))
    if kind == "inf":
        return save(p, with_value(S_VAL.astype(np.float32), np.inf))
    if kind == "neg-inf":
        return save(p, with_value(S_VAL, -np.inf))
    if kind == "no-rows":
        return save(p, np.zeros((0, 5)))
    if kind == "no-cols":
        return save(p, np.zeros((4, 0)))
    if kind == "one-d":
        return save(p, S_VAL[0])
    if kind == "three-d":
        return save(p, S_VAL[None])
    if kind == "complex":
        return save(p, S_VAL.astype(np.complex128))
    if kind == "string":
        return save(p, S_VAL.astype(str))
    if kind == "object":
        return save(p, S_VAL.astype(object))
    if kind == "float16":
        return save(p, S_VAL.astype(np.float16))
    if kind == "truncated":
        p.write_bytes(good[:-5])
        return p
    if kind == "truncated-header":
        p.write_bytes(good[:40])
        return p
    if kind == "corrupt-header":
        corrupt = bytearray(good)
        corrupt[12:20] = b"garbage!"
        p.write_bytes(bytes(corrupt))
        return p
    if kind == "not-npy":
        p.write_text("these are not the scores you are looking for")
        return p
    if kind == "missing":
        return tmp_path / "missing.npy"
    if kind == "directory":
        p.mkdir()
        return p
    raise AssertionError(kind)


# (kind, exception, what the message says after the argument and the file name)
SCORE_FILE_CASES = [
    ("nan", ValueError, "contains NaN at row 1, column 2"),
    ("inf", ValueError, "contains inf at row 1, column 2"),
    ("neg-inf", ValueError, "contains -inf at row 1, column 2"),
    ("no-rows", ValueError, "is empty (shape 0x5)"),
    ("no-cols", ValueError, "is empty (shape 4x0)"),
    ("one-d", ValueError, "holds a 1-D array"),
    ("three-d", ValueError, "holds a 3-D array"),
    ("complex", TypeError, "has dtype <c16; expected float32 or float64"),
    ("string", TypeError, "has dtype <U"),
    ("object", TypeError, "has dtype |O"),
    ("float16", TypeError, "has dtype <f2"),
    ("truncated", ValueError, "is truncated"),
    ("truncated-header", ValueError, "is not a valid .npy file"),
    ("corrupt-header", ValueError, "is not a valid .npy file"),
    ("not-npy", ValueError, "is not a valid .npy file"),
    ("missing", FileNotFoundError, "cannot read"),
    ("directory", IsADirectoryError, "is a directory"),
]


def check(exc_info, exc, argument: str, path: Path | None, message: str) -> None:
    """The exception is exactly of the expected class, names the argument and the file."""
    text = str(exc_info.value)
    assert type(exc_info.value) is exc, (type(exc_info.value), text)
    assert text.startswith(f"{argument}: "), text
    if path is not None and "empty" not in message and "contains" not in message:
        assert path.name in text, text
    assert message in text, text
    assert "panicked" not in text and "Traceback" not in text, text


@pytest.mark.parametrize("kind, exc, message", SCORE_FILE_CASES, ids=[c[0] for c in SCORE_FILE_CASES])
@pytest.mark.parametrize("argument", ["s_cal", "s_val"])
def test_bad_score_files_in_quantile_transfer(tmp_path, files, kind, exc, message, argument):
    f = dict(files)
    if kind in ("no-rows", "no-cols", "nan", "inf", "neg-inf") and argument == "s_cal":
        # Same shape as S_CAL so that only the named problem is wrong.
        a = {"no-rows": np.zeros((0, 3)), "no-cols": np.zeros((4, 0))}.get(kind)
        if a is None:
            a = with_value(S_CAL, {"nan": np.nan, "inf": np.inf, "neg-inf": -np.inf}[kind])
            if kind == "inf":
                a = a.astype(np.float32)
        f["s_cal"] = save(tmp_path / f"{kind}.npy", a)
        message = message.replace("0x5", "0x3")
    else:
        f[argument] = bad_file(tmp_path, kind)
    with pytest.raises(exc) as info:
        qtvpr.quantile_transfer(f["s_cal"], f["gt_cal"], f["s_val"], k=2)
    check(info, exc, argument, f[argument], message)
    # Calibration + transfer raise the same.
    with pytest.raises(exc) as info:
        qtvpr.Calibration(f["s_cal"], f["gt_cal"]).transfer(f["s_val"], k=2)
    check(info, exc, argument, f[argument], message)


@pytest.mark.parametrize("kind, exc, message", SCORE_FILE_CASES, ids=[c[0] for c in SCORE_FILE_CASES])
@pytest.mark.parametrize("function", ["best_threshold", "counts", "ranked_correlation"])
def test_bad_score_files_in_matrix_functions(tmp_path, kind, exc, message, function):
    path = bad_file(tmp_path, kind)
    gt = np.zeros(S_VAL.shape, dtype=bool)
    call = {
        "best_threshold": lambda: qtvpr.best_threshold(path, gt),
        "counts": lambda: qtvpr.counts(path, gt, 0.5),
        "ranked_correlation": lambda: qtvpr.ranked_correlation(path, S_VAL),
    }[function]
    argument = "s_val" if function == "ranked_correlation" else "s"
    with pytest.raises(exc) as info:
        call()
    check(info, exc, argument, path, message)


GT_FILE_CASES = [
    ("two", ValueError, "ground truth has value 2 at row 2, column 1"),
    ("minus-one", ValueError, "ground truth has value -1 at row 2, column 1"),
    ("float", TypeError, "has dtype <f8; expected bool or integer 0/1 ground truth"),
    ("complex", TypeError, "has dtype <c16"),
    ("string", TypeError, "has dtype <U"),
    ("object", TypeError, "has dtype |O"),
    ("one-d", ValueError, "holds a 1-D array"),
    ("three-d", ValueError, "holds a 3-D array"),
    ("shape", ValueError, "ground truth shape 3x3 does not match calibration similarity shape 4x3"),
    ("truncated", ValueError, "is truncated: shape 4x3 needs 12 bytes of data, it holds 9"),
    ("corrupt-header", ValueError, "is not a valid .npy file"),
    ("not-npy", ValueError, "is not a valid .npy file"),
    ("missing", FileNotFoundError, "cannot read"),
    ("directory", IsADirectoryError, "is a directory"),
    ("npz-without-gthard", ValueError, "has no array GThard"),
    ("npz-not-zip", ValueError, "is not a valid .npz archive"),
    ("npz-gthard-two", ValueError, "ground truth has value 2 at row 2, column 1"),
]


def bad_gt_file(tmp_path: Path, kind: str) -> Path:
    p = tmp_path / f"gt-{kind}.npy"
    good = save(tmp_path / "gt-good.npy", GT_CAL).read_bytes()
    if kind == "two":
        return save(p, int_gt(2))
    if kind == "minus-one":
        return save(p, int_gt(-1).astype(np.int8))
    if kind == "float":
        return save(p, GT_CAL.astype(np.float64))
    if kind == "complex":
        return save(p, GT_CAL.astype(np.complex128))
    if kind == "string":
        return save(p, GT_CAL.astype(str))
    if kind == "object":
        return save(p, GT_CAL.astype(object))
    if kind == "one-d":
        return save(p, GT_CAL[:, 0])
    if kind == "three-d":
        return save(p, GT_CAL[None])
    if kind == "shape":
        return save(p, GT_CAL[:3])
    if kind == "truncated":
        p.write_bytes(good[:-3])
        return p
    if kind in ("corrupt-header", "not-npy", "missing", "directory"):
        return bad_file(tmp_path, kind)
    npz = tmp_path / f"gt-{kind}.npz"
    if kind == "npz-without-gthard":
        np.savez(npz, GTsoft=GT_CAL)
    elif kind == "npz-not-zip":
        npz.write_text("not a zip")
    elif kind == "npz-gthard-two":
        np.savez(npz, GThard=int_gt(2))
    return npz


@pytest.mark.parametrize("kind, exc, message", GT_FILE_CASES, ids=[c[0] for c in GT_FILE_CASES])
def test_bad_ground_truth_files(tmp_path, files, kind, exc, message):
    path = bad_gt_file(tmp_path, kind)
    calls = [
        ("gt_cal", lambda: qtvpr.quantile_transfer(files["s_cal"], path, files["s_val"])),
        ("gt_cal", lambda: qtvpr.Calibration(S_CAL, path)),
        ("gt", lambda: qtvpr.best_threshold(files["s_cal"], path)),
        ("gt", lambda: qtvpr.counts(S_CAL, path, 0.5)),
    ]
    if "npz" not in kind:  # soft ground truth is an .npy
        calls.append(("gt_soft", lambda: qtvpr.best_threshold(S_CAL, GT_CAL, gt_soft=path)))
        calls.append(("gt_soft", lambda: qtvpr.Calibration(files["s_cal"], files["gt_cal"], gt_soft=path)))
    for argument, call in calls:
        with pytest.raises(exc) as info:
            call()
        want = message
        if argument == "gt_soft":
            want = message.replace("ground truth has", "soft ground truth has").replace(
                "ground truth shape 3x3 does not match calibration similarity shape 4x3",
                "soft ground truth shape 3x3 does not match ground truth shape 4x3",
            )
        elif argument == "gt":
            want = message.replace("calibration similarity", "similarity")
        check(info, exc, argument, None if kind == "shape" else path, want)


def test_database_mismatch_between_files(tmp_path, files):
    short = save(tmp_path / "short.npy", S_VAL[:3])
    with pytest.raises(ValueError) as info:
        qtvpr.quantile_transfer(files["s_cal"], files["gt_cal"], short)
    check(info, ValueError, "s_val", None,
          "deployment similarity has 3 database images but calibration similarity has 4")
    with pytest.raises(ValueError, match="^s_val: "):
        qtvpr.ranked_correlation(short, files["s_cal"])


PARAMETER_CASES = [
    (dict(k=0), "k must be >= 1, got 0"),
    (dict(precision=0.0), "precision must be in (0, 1], got 0"),
    (dict(precision=1.5), "precision must be in (0, 1], got 1.5"),
    (dict(precision=float("nan")), "precision must be in (0, 1], got NaN"),
    (dict(segment_size=0), "segment_size must be between 1 and the number of deployment queries (5), got 0"),
    (dict(segment_size=6), "segment_size must be between 1 and the number of deployment queries (5), got 6"),
]


@pytest.mark.parametrize("kwargs, message", PARAMETER_CASES)
def test_bad_parameters_with_files(files, kwargs, message):
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        qtvpr.quantile_transfer(files["s_cal"], files["gt_cal"], files["s_val"], **kwargs)
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        qtvpr.Calibration(files["s_cal"], files["gt_cal"]).transfer(files["s_val"], **kwargs)


def test_query_major_file_errors_use_the_files_orientation(tmp_path, files):
    # The file is |Q| x |DB|; NaN at its row 2, column 1.
    s = save(tmp_path / "s_t.npy", with_value(S_CAL, np.nan).T)
    with pytest.raises(ValueError, match=r"^s_cal: calibration similarity contains NaN at row 2, column 1"):
        qtvpr.quantile_transfer(s, GT_CAL.T, S_VAL.T, query_major=True)
    g = save(tmp_path / "g_t.npy", int_gt(2).T)  # 2 at the file's row 1, column 2
    with pytest.raises(ValueError, match=r"^gt_cal: .*g_t\.npy: ground truth has value 2 at row 1, column 2"):
        qtvpr.quantile_transfer(S_CAL.T, g, S_VAL.T, query_major=True)
    g = save(tmp_path / "g_short_t.npy", GT_CAL.T[:2])
    s_t = save(tmp_path / "s_cal_t.npy", S_CAL.T)
    with pytest.raises(ValueError, match=r"^gt: ground truth shape 2x4 does not match similarity shape 3x4"):
        qtvpr.best_threshold(s_t, g, query_major=True)


def test_errors_leave_the_module_usable(tmp_path, files):
    """A robot pipeline keeps calling after an error: nothing is left in a bad state."""
    want = qtvpr.quantile_transfer(files["s_cal"], files["gt_cal"], files["s_val"], k=2).thresholds
    for kind, exc, _ in SCORE_FILE_CASES:
        d = tmp_path / kind
        d.mkdir()
        with pytest.raises(exc):
            qtvpr.quantile_transfer(files["s_cal"], files["gt_cal"], bad_file(d, kind))
        got = qtvpr.quantile_transfer(files["s_cal"], files["gt_cal"], files["s_val"], k=2).thresholds
        np.testing.assert_array_equal(got, want)


def test_oserror_subclasses_carry_the_file(tmp_path):
    missing = tmp_path / "nope.npy"
    with pytest.raises(OSError) as info:
        qtvpr.best_threshold(missing, GT_CAL)
    assert isinstance(info.value, FileNotFoundError)
    assert str(missing) in str(info.value)
    d = tmp_path / "d.npy"
    d.mkdir()
    with pytest.raises(OSError) as info:
        qtvpr.Calibration(S_CAL, d)
    assert isinstance(info.value, IsADirectoryError)
    assert os.fspath(d) in str(info.value)


def test_headers_claiming_impossible_shapes(tmp_path):
    """Regression: an element count that overflows 64 bits used to wrap and panic."""
    for descr, argument in [("|b1", "gt"), ("<f8", "s"), (">f8", "s")]:
        path = npy_raw(tmp_path / "huge.npy", descr, (1 << 32, 1 << 32), bytes(16))
        args = (S_CAL, path) if argument == "gt" else (path, GT_CAL)
        with pytest.raises(ValueError) as info:
            qtvpr.best_threshold(*args)
        check(info, ValueError, argument, path, "is corrupt: its shape 4294967296x4294967296 is larger than any file")


def test_deeply_nested_headers_fail_fast(tmp_path):
    """Regression (found by fuzz/npy_read, a hang): npyz's header parser backtracks
    exponentially in bracket nesting, so such headers are refused before it runs."""
    import zipfile

    header = "{'descr': '|b1', 'shape': " + "[" * 100 + "('fortran'" * 3
    header += " " * ((-(10 + len(header) + 1)) % 64) + "\n"
    raw = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode()
    npy = tmp_path / "nested.npy"
    npy.write_bytes(raw)
    with pytest.raises(ValueError) as info:
        qtvpr.best_threshold(npy, GT_CAL)
    check(info, ValueError, "s", npy, "is not a valid .npy file: its header nests brackets 104 deep")
    npz = tmp_path / "nested.npz"
    with zipfile.ZipFile(npz, "w") as z:
        z.writestr("GThard.npy", raw)
    with pytest.raises(ValueError) as info:
        qtvpr.best_threshold(S_CAL, npz)
    check(info, ValueError, "gt", npz, "is not a valid .npy file: its header nests brackets 104 deep")


def test_nested_headers_fail_fast_on_every_path_argument(tmp_path):
    """Regression (the CLI hung on it): a 128-byte header nesting 20 brackets is refused
    at once by every function that takes a path, through the core's checked reader."""
    import time

    header = "{'descr': '<f8', 'fortran_order': False, 'shape': " + "[" * 20 + "]" * 20 + "}"
    header += " " * ((-(10 + len(header) + 1)) % 64) + "\n"
    npy = tmp_path / "nested.npy"
    npy.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode())
    assert npy.stat().st_size == 128
    p = np.zeros((2, 2))
    calls = [
        ("db", lambda: qtvpr.cosine_similarity(npy, p)),
        ("queries", lambda: qtvpr.cosine_similarity(p, npy)),
        ("db_positions", lambda: qtvpr.ground_truth_positions(npy, p, 1.0)),
        ("query_positions", lambda: qtvpr.ground_truth_positions(p, npy, 1.0)),
        ("s", lambda: qtvpr.sequence_match(npy, 3)),
        ("s", lambda: qtvpr.evaluate(npy, GT_CAL)),
        ("s_val", lambda: qtvpr.quantile_transfer(S_CAL, GT_CAL, npy)),
        ("gt_soft", lambda: qtvpr.best_threshold(S_CAL, GT_CAL, gt_soft=npy)),
    ]
    for argument, call in calls:
        start = time.perf_counter()
        with pytest.raises(ValueError) as info:
            call()
        assert time.perf_counter() - start < 1.0, argument
        assert str(info.value) == f"{argument}: {npy} is not a valid .npy file: its header nests brackets 21 deep"


def test_descriptor_and_position_files_say_what_they_must_hold(tmp_path):
    ints = save(tmp_path / "ints.npy", np.zeros((2, 2), dtype=np.int64))
    one_d = save(tmp_path / "one_d.npy", np.zeros(2))
    with pytest.raises(TypeError) as info:
        qtvpr.cosine_similarity(ints, np.ones((2, 2)))
    assert str(info.value) == f"db: {ints} has dtype <i8; descriptors must be float32 or float64"
    with pytest.raises(TypeError) as info:
        qtvpr.ground_truth_positions(np.zeros((2, 2)), ints, 1.0)
    assert str(info.value) == f"query_positions: {ints} has dtype <i8; positions must be float32 or float64"
    with pytest.raises(ValueError) as info:
        qtvpr.ground_truth_positions(one_d, np.zeros((2, 2)), 1.0)
    assert str(info.value) == (
        f"db_positions: {one_d} holds a 1-D array of shape [2], expected an N x 2 (x, y) or N x 3 (x, y, z) "
        "position matrix"
    )


def test_a_bad_label_file_is_reported_once(tmp_path):
    path = save(tmp_path / "gt2.npy", int_gt(2))
    with pytest.raises(ValueError) as info:
        qtvpr.best_threshold(S_CAL, path)
    assert str(info.value) == (
        f"gt: {path}: ground truth has value 2 at row 2, column 1; ground truth must be 0/1 or bool"
    )


def test_a_database_mismatch_hints_at_query_major(files, tmp_path):
    short = save(tmp_path / "short.npy", S_VAL[:3])
    with pytest.raises(ValueError) as info:
        qtvpr.quantile_transfer(files["s_cal"], files["gt_cal"], short)
    assert str(info.value) == (
        "s_val: deployment similarity has 3 database images but calibration similarity has 4; both must be "
        "scored against the same database; if the matrices are query-major (|Q| x |DB|, as VPR-Bench stores "
        "them), pass query_major=True"
    )
    # Query-major: |DB| is 3 (cal) against 4 (val); the hint would be wrong.
    with pytest.raises(ValueError) as info:
        qtvpr.quantile_transfer(S_CAL, GT_CAL, S_VAL.T, query_major=True)
    assert str(info.value) == (
        "s_val: deployment similarity has 4 database images but calibration similarity has 3; both must be "
        "scored against the same database"
    )


def test_evaluate_query_major_errors_use_the_files_orientation(tmp_path):
    # |Q| x |DB| = 7 x 3 with NaN at the file's row 5, column 1.
    s = np.full((7, 3), 0.5)
    s[5, 1] = np.nan
    path = save(tmp_path / "s_t.npy", s)
    with pytest.raises(ValueError) as info:
        qtvpr.evaluate(path, np.zeros((7, 3), dtype=bool), query_major=True, cal_queries=2, segment_size=2)
    assert str(info.value) == "s: similarity contains NaN at row 5, column 1; scores must be finite"
