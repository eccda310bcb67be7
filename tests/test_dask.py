"""``qtvpr.dask`` on a two-process local Dask cluster equals the one-machine API exactly.

``qtvpr.dask.transfer`` is held to ``Calibration.transfer`` and ``qtvpr.dask.online``
to ``Online.push_many`` on the whole matrix, every field with ``np.array_equal`` (bit
for bit, not to a tolerance): on real VPR-Bench matrices and Nordland HOG descriptors
(the lazy ``db @ q.T`` path), and on hypothesis cases; for segment sizes that divide
the chunks and that do not, windows longer than a chunk, both matching modes and
query-major input. Errors carry the one-machine messages, with positions in the whole
matrix. One test kills a worker process while its block runs: Dask reruns the block
elsewhere and the result is still exact.

The cluster (``LocalCluster(n_workers=2, threads_per_worker=1, processes=True)``) is
started once for the module. Skipped when Dask is not installed (``pip install
".[dask]"``).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

da = pytest.importorskip("dask.array")
distributed = pytest.importorskip("distributed")
import cloudpickle  # noqa: E402  (a dependency of distributed)

import qtvpr  # noqa: E402
import qtvpr.dask as qd  # noqa: E402
from shared_data import nordland_ground_truth, nordland_hog, unit_rows  # noqa: E402

# The workers cannot import this module (tests/ is not on their path): send its
# functions by value.
cloudpickle.register_pickle_by_value(sys.modules[__name__])

TRANSFER_FIELDS = ("thresholds", "quantiles", "query_quantiles", "query_thresholds", "query_weights", "neighbours")


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, distributed.Client(cluster) as client:
        yield cluster, client


@pytest.fixture(scope="module")
def client(cluster):
    return cluster[1]


def assert_same_transfer(got, want):
    assert type(got) is qtvpr.TransferResult
    assert got.segments == want.segments
    for name in TRANSFER_FIELDS:
        a, b = getattr(got, name), getattr(want, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    for name in ("query_confidences", "query_confidences_lower95"):  # None in multi matching
        a, b = getattr(got, name), getattr(want, name)
        assert (a is None and b is None) or np.array_equal(a, b, equal_nan=True), name


def assert_same_online(got, want):
    """Every column of the core's record (``OnlineDecisions.COLUMNS``), bit for bit: a
    column qtvpr.dask missed fails here."""
    assert type(got) is qtvpr.OnlineDecisions
    assert len(got) == len(want)
    for name in qtvpr.OnlineDecisions.COLUMNS:
        a, b = getattr(got, name), getattr(want, name)
        if b is None:  # a gate's column without the gate
            assert a is None, name
            continue
        # NaN confidences in multi matching.
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name


def spedtest(root: Path, technique: str):
    """(S, GT, calibration queries) of a VPR-Bench SPEDTest matrix: 607 x 607, the
    first 10% (60 queries) calibrate."""
    d = root / "vprbench-spedtest"
    s, gt = np.load(d / f"S_{technique}.npy"), np.load(d / "GT.npy")
    return s, gt, s.shape[1] // 10


# ---------------------------------------------------------------------------------------
# transfer


@pytest.mark.parametrize("matching", ["single", "multi"])
@pytest.mark.parametrize(
    ("segment_size", "chunks"),
    [
        (7, 100),  # ceil(1% of 607): 7 does not divide 100, blocks of 98 = 14 segments
        (50, 100),  # divides: blocks of 100 = 2 segments; the last block 47, one segment
        (120, 100),  # a segment longer than a chunk: blocks of one segment
        (547, 100),  # every query, one segment
        (None, 100),  # no segment size: one segment, one task
        (5, (300, 1, 46, 200)),  # uneven chunks: blocks of 300 (the largest)
    ],
)
def test_transfer_equals_one_machine_on_real_data(client, shared_data, matching, segment_size, chunks):
    s, gt, n_cal = spedtest(shared_data, "NetVLAD")  # float32
    cal = qtvpr.Calibration(s[:, :n_cal], gt[:, :n_cal], matching=matching)
    s_val = s[:, n_cal:]
    # The database axis chunked too: each block gets it whole.
    lazy = da.from_array(s_val, chunks=(250, chunks))
    got = qd.transfer(cal, lazy, k=10, precision=1.0, segment_size=segment_size)
    want = cal.transfer(s_val, k=10, precision=1.0, segment_size=segment_size)
    assert_same_transfer(got, want)
    if segment_size == 7:
        # 547 = 78 * 7 + 1: 79 segments, the last one of the single last query.
        assert len(got.segments) == 79 and got.segments[-1] == (546, 547)


@pytest.mark.parametrize("precision", [1.0, 0.9])
def test_transfer_query_major_float64(client, shared_data, precision):
    # VPR-Bench's own layout: |Q| x |DB|. HOG is float64.
    s, gt, n_cal = spedtest(shared_data, "HOG")
    cal = qtvpr.Calibration(s[:, :n_cal].T, gt[:, :n_cal].T, query_major=True)
    s_val = np.ascontiguousarray(s[:, n_cal:].T)
    got = qd.transfer(cal, da.from_array(s_val, chunks=(64, 607)), precision=precision, segment_size=9,
                      query_major=True)
    want = cal.transfer(s_val, precision=precision, segment_size=9, query_major=True)
    assert_same_transfer(got, want)


def nordland_descriptors(root: Path):
    """L2-normalised Nordland HOG descriptors (winter database, summer queries) and the
    ground truth |i - j| <= 1 of their 3576 x 3576 cosine similarity."""
    db, q = (unit_rows(a) for a in nordland_hog(root))
    return db, q, nordland_ground_truth(len(db), len(q))


# The descriptors are NumPy arrays wrapped by Dask, so they travel in the graph.
@pytest.mark.filterwarnings("ignore:Sending large graph")
def test_lazy_similarity_of_descriptors(client, shared_data):
    # S = db @ q.T is never stored: each block's scores are computed on its worker.
    db, q, gt = nordland_descriptors(shared_data)
    n_cal = len(q) // 10  # 357
    cal = qtvpr.Calibration(db @ q[:n_cal].T, gt[:, :n_cal])
    lazy = da.from_array(db, chunks=(1000, -1)) @ da.from_array(q[n_cal:], chunks=(500, -1)).T
    # The one-machine answer on the same scores (the chunked product, computed whole).
    s_val = lazy.compute()
    assert s_val.shape == (3576, 3219) and s_val.dtype == np.float32
    got = qd.transfer(cal, lazy, segment_size=36)
    assert_same_transfer(got, cal.transfer(s_val, segment_size=36))
    got = qd.online(cal, lazy, window=36, min_window=10)
    assert_same_online(got, qtvpr.Online(cal, window=36, min_window=10).push_many(s_val))


# ---------------------------------------------------------------------------------------
# online


@pytest.mark.parametrize("matching", ["single", "multi"])
@pytest.mark.parametrize(
    ("window", "min_window", "chunks"),
    [
        (1, 1, 100),  # no overlap at all
        (50, 1, 100),  # the previous 49 queries as warm-up
        (50, 50, 100),  # warm-up on the stream's first 49 queries only, not on each block's
        (250, 120, 100),  # a window longer than a chunk: the warm-up spans several chunks
        (20, 5, (3, 10, 1, 150, 383)),  # blocks shorter than the window start near the stream's start
        (600, 1, 200),  # a window longer than the whole stream (547 queries)
    ],
)
def test_online_equals_push_many_on_real_data(client, shared_data, matching, window, min_window, chunks):
    s, gt, n_cal = spedtest(shared_data, "CALC")  # float32
    cal = qtvpr.Calibration(s[:, :n_cal], gt[:, :n_cal], matching=matching)
    s_val = s[:, n_cal:]
    got = qd.online(cal, da.from_array(s_val, chunks=(300, chunks)), window=window, min_window=min_window)
    want = qtvpr.Online(cal, window=window, min_window=min_window).push_many(s_val)
    assert_same_online(got, want)
    # The warm-up: queries 0 .. min_window - 2 are reject-all (quantile 1), no later one.
    assert np.array_equal(np.flatnonzero(got.quantiles == 1.0)[: min_window - 1], np.arange(min_window - 1))
    assert np.array_equal(got.queries, np.arange(547))


def test_online_with_the_margin_gate_has_its_columns(client, shared_data):
    # The gate's columns (the core's record: margins and gates) come through the blocks.
    s, gt, n_cal = spedtest(shared_data, "CALC")
    cal = qtvpr.Calibration(s[:, :n_cal], gt[:, :n_cal])
    s_val = s[:, n_cal:]
    got = qd.online(cal, da.from_array(s_val, chunks=(300, 100)), window=20, gate="margin")
    want = qtvpr.Online(cal, window=20, gate="margin").push_many(s_val)
    assert got.margins is not None and got.gates is not None
    assert_same_online(got, want)


def test_online_query_major_float64_and_defaults_from_the_file(client, shared_data, tmp_path):
    s, gt, n_cal = spedtest(shared_data, "HOG")
    path = tmp_path / "cal.npz"
    qtvpr.Calibration(s[:, :n_cal], gt[:, :n_cal]).save(path, k=5, precision=0.9, window=30)
    cal = qtvpr.Calibration.load(path)  # k, precision and window from the file
    s_val = np.ascontiguousarray(s[:, n_cal:].T)
    got = qd.online(cal, da.from_array(s_val, chunks=(25, -1)), query_major=True)
    assert_same_online(got, qtvpr.Online(cal).push_many(s_val, query_major=True))


# ---------------------------------------------------------------------------------------
# hypothesis: small random cases


@st.composite
def cases(draw):
    n_db = draw(st.integers(2, 12))
    n_cal = draw(st.integers(1, 6))
    n_val = draw(st.integers(1, 30))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    dtype = draw(st.sampled_from([np.float32, np.float64]))
    # Rounded scores make ties, which the thresholds must break the same way.
    s_cal = np.round(rng.normal(size=(n_db, n_cal)), 1).astype(dtype)
    s_val = np.round(rng.normal(size=(n_db, n_val)), 1).astype(dtype)
    gt_cal = rng.random((n_db, n_cal)) < 0.3
    chunk = draw(st.integers(1, n_val))
    return {
        "s_cal": s_cal,
        "gt_cal": gt_cal,
        "s_val": s_val,
        "chunk": chunk,
        "matching": draw(st.sampled_from(["single", "multi"])),
        "k": draw(st.integers(1, 4)),
        "precision": draw(st.sampled_from([1.0, 0.75])),
        "segment_size": draw(st.none() | st.integers(1, n_val)),
        "window": (window := draw(st.integers(1, n_val + 3))),
        "min_window": draw(st.integers(1, window)),
        "query_major": draw(st.booleans()),
    }


FEW = settings(max_examples=12, derandomize=True, deadline=None, database=None,
               suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@FEW
@given(case=cases())
def test_hypothesis_cases_equal_one_machine(client, case):
    c = case
    qm = c["query_major"]
    s_cal, gt_cal, s_val = (m.T if qm else m for m in (c["s_cal"], c["gt_cal"], c["s_val"]))
    cal = qtvpr.Calibration(s_cal, gt_cal, matching=c["matching"], query_major=qm)
    lazy = da.from_array(s_val, chunks=(c["chunk"], -1) if qm else (-1, c["chunk"]))
    p = {"k": c["k"], "precision": c["precision"]}
    got = qd.transfer(cal, lazy, segment_size=c["segment_size"], query_major=qm, **p)
    assert_same_transfer(got, cal.transfer(s_val, segment_size=c["segment_size"], query_major=qm, **p))
    w = {"window": c["window"], "min_window": c["min_window"]}
    got = qd.online(cal, lazy, query_major=qm, **p, **w)
    assert_same_online(got, qtvpr.Online(cal, **p, **w).push_many(s_val, query_major=qm))


# ---------------------------------------------------------------------------------------
# errors: the one-machine exception and message


def small():
    """A calibration over |DB| = 4 and 10 deployment queries."""
    rng = np.random.default_rng(7)
    s_cal, s_val = rng.normal(size=(4, 3)), rng.normal(size=(4, 10))
    return qtvpr.Calibration(s_cal, np.eye(4, 3, dtype=bool)), s_val


def one_machine_error(f):
    with pytest.raises(Exception) as info:
        f()
    return info.type, str(info.value)


@pytest.mark.parametrize("query_major", [False, True])
def test_a_non_finite_score_names_its_column_in_the_whole_matrix(client, query_major):
    cal, s_val = small()
    s_val[2, 7] = np.nan  # query 7, in the block of queries 6..9 (chunks of 3: blocks 0-2, 3-5, 6-8, 9)
    s_val[1, 9] = np.inf  # a later one: not the one reported
    if query_major:
        s_val = np.ascontiguousarray(s_val.T)
    lazy = da.from_array(s_val, chunks=(3, -1) if query_major else (-1, 3))
    kind, message = one_machine_error(lambda: cal.transfer(s_val, segment_size=3, query_major=query_major))
    where = "at row 7, column 2" if query_major else "at row 2, column 7"
    assert kind is ValueError and where in message, message
    with pytest.raises(ValueError) as info:
        qd.transfer(cal, lazy, segment_size=3, query_major=query_major)
    assert str(info.value) == message
    kind, message = one_machine_error(lambda: qtvpr.Online(cal, window=4).push_many(s_val, query_major=query_major))
    assert kind is ValueError and where in message, message
    with pytest.raises(ValueError) as info:
        qd.online(cal, lazy, window=4, query_major=query_major)
    assert str(info.value) == message


@pytest.mark.parametrize(
    ("kwargs", "shape", "dtype"),
    [
        ({}, (5, 10), np.float64),  # another |DB|
        ({"segment_size": 11}, (4, 10), np.float64),  # a segment longer than the deployment set
        ({"segment_size": 0}, (4, 10), np.float64),
        ({"k": 0}, (4, 10), np.float64),
        ({"precision": 1.5}, (4, 10), np.float64),
        ({"k": 0, "segment_size": 11}, (5, 10), np.float64),  # several: the first the one machine checks
        ({}, (4, 10), np.int32),  # an unsupported dtype: TypeError
        ({}, (4, 0), np.float64),  # no query
    ],
)
def test_transfer_errors_are_the_one_machine_errors(client, kwargs, shape, dtype):
    cal, _ = small()
    s_val = np.ones(shape, dtype)
    want = one_machine_error(lambda: cal.transfer(s_val, **kwargs))
    got = one_machine_error(lambda: qd.transfer(cal, da.from_array(s_val, chunks=(-1, 4)), **kwargs))
    assert got == want


@pytest.mark.parametrize(
    ("kwargs", "shape", "dtype"),
    [
        ({"window": 3}, (5, 10), np.float64),  # another |DB|
        ({}, (4, 10), np.float64),  # no window (none in the calibration's defaults)
        ({"window": 3, "min_window": 4}, (4, 10), np.float64),
        ({"window": 3, "k": 0}, (4, 10), np.float64),
        ({"window": 3, "precision": 0.0}, (4, 10), np.float64),
        ({"window": 3}, (4, 10), np.int64),  # an unsupported dtype: TypeError
    ],
)
def test_online_errors_are_the_one_machine_errors(client, kwargs, shape, dtype):
    cal, _ = small()
    s_val = np.ones(shape, dtype)
    want = one_machine_error(lambda: qtvpr.Online(cal, **kwargs).push_many(s_val))
    got = one_machine_error(lambda: qd.online(cal, da.from_array(s_val, chunks=(-1, 4)), **kwargs))
    assert got == want


def test_online_of_no_query_is_empty(client):
    cal, _ = small()
    got = qd.online(cal, da.zeros((4, 0), chunks=(4, 1)), window=3)
    assert len(got) == 0 and got.thresholds.shape == (0,) and got.best.dtype == np.int64


def test_not_a_dask_array(client):
    cal, s_val = small()
    with pytest.raises(TypeError, match=r"s_val: expected a dask.array.Array, got ndarray"):
        qd.transfer(cal, s_val)
    with pytest.raises(TypeError, match=r"calibration: expected a qtvpr.Calibration, got str"):
        qd.transfer("cal.npz", da.from_array(s_val))
    # online builds an Online first: its own error.
    want = one_machine_error(lambda: qtvpr.Online("cal.npz", window=2))
    assert one_machine_error(lambda: qd.online("cal.npz", da.from_array(s_val), window=2)) == want


def test_parts_of_different_lengths_are_refused():
    f, i = np.zeros(2), np.zeros((3, 1), np.int64)
    with pytest.raises(ValueError, match="differ in length"):
        qtvpr.TransferResult._from_parts(f, f, [(0, 1), (1, 3)], np.zeros(3), np.zeros(3), np.zeros(2), i)
    q, b = i[:, 0], np.zeros(3, bool)
    c = np.zeros(3)
    # The others: every column after `queries`, the gates' four included.
    lengths = r"differ in length: queries 3, the others \[3, 3, 3, 3, 3, 2, 3, 3, 3, 3, 3, 3, 3, 3\]"
    with pytest.raises(ValueError, match=lengths):
        qtvpr.OnlineDecisions._from_parts(q, *(np.zeros(3),) * 4, q, np.zeros(2), q, b, c, c)
    with pytest.raises(ValueError, match=r"the others \[3, 3, 3, 3, 3, 3, 3, 3, 3, 2, 3, 3, 3, 3\]"):
        qtvpr.OnlineDecisions._from_parts(q, *(np.zeros(3),) * 4, q, np.zeros(3), q, b, c, np.zeros(2))
    with pytest.raises(TypeError):  # every field in both matching modes
        qtvpr.OnlineDecisions._from_parts(q, *(np.zeros(3),) * 4, q, np.zeros(3), None, b, c, c)
    with pytest.raises(ValueError, match="query_confidences"):
        qtvpr.TransferResult._from_parts(
            f, f, [(0, 1), (1, 3)], np.zeros(3), np.zeros(3), np.zeros(3), i, query_confidences=np.zeros(2)
        )


# ---------------------------------------------------------------------------------------
# a worker dies while its block runs


def block_until_killed(x, marker: str):
    """The identity; but its first call anywhere writes its process id to ``marker``
    and waits to be killed. The rerun (``marker`` exists) returns at once."""
    if x.size == 0:  # Dask's trial call on an empty array, if any: not a block
        return x
    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return x
    os.write(fd, str(os.getpid()).encode())
    os.close(fd)
    threading.Event().wait(120)  # killed long before; a bound, so that a failure cannot hang
    return x


def kill_when_blocked(marker: Path, workers: set[int], killed: list[int]) -> None:
    """Kill the worker process that wrote its id to ``marker``, once it has; only a
    process of ``workers``."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        text = marker.read_text() if marker.exists() else ""
        if text:
            pid = int(text)
            if pid in workers:
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
            return
        time.sleep(0.02)


@pytest.mark.parametrize("which", ["transfer", "online"])
def test_a_killed_worker_is_replaced_and_the_result_still_exact(cluster, shared_data, tmp_path, which):
    local_cluster, client = cluster
    s, gt, n_cal = spedtest(shared_data, "NetVLAD")
    cal = qtvpr.Calibration(s[:, :n_cal], gt[:, :n_cal])
    s_val = s[:, n_cal:]
    marker = tmp_path / "blocked"
    lazy = da.from_array(s_val, chunks=(-1, 100)).map_blocks(
        block_until_killed, str(marker), meta=np.empty((0, 0), s_val.dtype))
    pids = {w.process.pid for w in local_cluster.workers.values()}
    killed: list[int] = []
    killer = threading.Thread(target=kill_when_blocked, args=(marker, pids, killed))
    killer.start()
    if which == "transfer":
        got = qd.transfer(cal, lazy, segment_size=7)
        want = cal.transfer(s_val, segment_size=7)
        assert_same_transfer(got, want)
    else:
        got = qd.online(cal, lazy, window=40, min_window=5)
        assert_same_online(got, qtvpr.Online(cal, window=40, min_window=5).push_many(s_val))
    killer.join()
    # A worker process was killed mid-block, and the nanny started another one.
    assert len(killed) == 1 and killed[0] in pids
    client.wait_for_workers(2, timeout=60)
    assert len(client.scheduler_info()["workers"]) == 2


# ---------------------------------------------------------------------------------------
# the optional dependency


def test_import_qtvpr_does_not_import_dask_and_the_extra_is_named_when_missing():
    code = (
        "import sys; import qtvpr; assert 'dask' not in sys.modules, 'import qtvpr imported dask'\n"
        "sys.modules['dask'] = None  # as if Dask were not installed\n"
        "try:\n    import qtvpr.dask\nexcept ImportError as e:\n    print(e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == 'qtvpr.dask needs Dask: pip install "dask[array]" distributed (the dask extra of qtvpr)'


CORRIDOR = Path(__file__).resolve().parent.parent / "data" / "corridor"


@pytest.mark.parametrize("matching", ["single", "multi"])
def test_the_files_params_are_every_front_ends_defaults(client, cli, tmp_path, matching):
    # Regression: with a file of k = 3 and tau = 0.9, `qtvpr-cli threshold --cal`
    # used them while `Calibration.load(...).transfer` and `qtvpr.dask.transfer` silently
    # used k = 10, tau = 1 (semantics §12: the file's params are every front end's
    # defaults). On the embedded VPR-Bench Corridor data.
    cal_file = tmp_path / "k3.npz"
    subprocess.run([str(cli), "calibrate", "--cal", str(CORRIDOR / "cal_S.npy"), "--cal-gt",
                    str(CORRIDOR / "cal_GT.npy"), "--matching", matching, "--k", "3", "--precision", "0.9",
                    "--window", "10", "--output", str(cal_file)], check=True)
    s_val = np.load(CORRIDOR / "deploy_S.npy")
    out = subprocess.run([str(cli), "--quiet", "threshold", "--cal", str(cal_file), "--val",
                          str(CORRIDOR / "deploy_S.npy"), "--segment-size", "10"],
                         check=True, capture_output=True, text=True)
    report = json.loads(out.stdout)
    assert (report["params"]["k"], report["params"]["precision"]) == (3, 0.9)
    from_cli = np.array([np.inf if g["threshold"] is None else g["threshold"] for g in report["segments"]])

    cal = qtvpr.Calibration.load(cal_file)
    assert cal.defaults == {"k": 3, "precision": 0.9, "window": 10, "gate": "none",
                            "sequence_gate": {"window": 5, "level": 0.8, "speed": 1.0, "tolerance": 2.0, "drift": 0.2}}
    explicit = cal.transfer(s_val, k=3, precision=0.9, segment_size=10)
    library = cal.transfer(s_val, k=10, precision=1.0, segment_size=10)
    assert not np.array_equal(explicit.thresholds, library.thresholds)  # the case tells them apart
    np.testing.assert_array_equal(explicit.thresholds, from_cli)
    assert_same_transfer(cal.transfer(s_val, segment_size=10), explicit)
    assert_same_transfer(qd.transfer(cal, da.from_array(s_val, chunks=(-1, 25)), segment_size=10), explicit)
    assert cal.threshold() == cal.threshold(0.9)
    # Saved again without arguments, a loaded file keeps its params.
    cal.save(tmp_path / "again.npz")
    assert qtvpr.Calibration.load(tmp_path / "again.npz").defaults == cal.defaults
