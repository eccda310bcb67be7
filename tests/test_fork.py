"""A process that forks after using the library has a working library in the child.

Semantics §10 (Files and processes). On Linux, ``multiprocessing`` forks by default: a
parent that has calibrated, transferred and pushed starts a ``fork`` pool, and its
workers calibrate, load, push and transfer again (on objects inherited from the parent
and on objects sent to them), with the parent's results to the bit. Before the library
owned its thread pool, a worker's first call waited forever for threads that exist only
in the parent; every result here is awaited with a timeout, so that a hang is a failure.

Real data: the embedded VPR-Bench Corridor matrices (``data/corridor``, float64).
"""

from __future__ import annotations

import multiprocessing
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import qtvpr

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="no fork() on Windows")

CORRIDOR = Path(__file__).resolve().parents[1] / "data" / "corridor"
TIMEOUT = 60

# What the workers inherit from the parent at fork time.
_INHERITED: dict[str, Any] = {}


def _results(cal: qtvpr.Calibration, s_val: np.ndarray) -> tuple[list[float], list[bool], list[float]]:
    """Online thresholds and decisions of the first 60 queries (window 20, k 5), and the
    transfer's segment thresholds (segments of 20)."""
    online = qtvpr.Online(cal, k=5, window=20).push_many(s_val[:, :60])
    transfer = cal.transfer(s_val, k=5, segment_size=20)
    return online.thresholds.tolist(), online.accept.tolist(), transfer.thresholds.tolist()


def _worker(task: str, cal: qtvpr.Calibration | None = None) -> Any:
    """One task in a forked worker; see the test."""
    s_val = _INHERITED["s_val"]
    if task == "continue":
        # The parent's Online, 50 queries in: the next 10, one push at a time.
        online = _INHERITED["online"]
        decisions = [online.push(s_val[:, j]) for j in range(50, 60)]
        return [d.threshold for d in decisions], [d.accept for d in decisions]
    if task == "calibrate":
        return _results(qtvpr.Calibration(np.load(CORRIDOR / "cal_S.npy"), np.load(CORRIDOR / "cal_GT.npy")), s_val)
    if task == "load":
        return _results(qtvpr.Calibration.load(_INHERITED["path"]), s_val)
    if task == "sent":
        assert cal is not None
        return _results(cal, s_val)
    if task == "threads":
        # The threads of the library's pool in this process, by name (Linux).
        return sorted((t / "comm").read_text().strip() for t in Path("/proc/self/task").iterdir()
                      if (t / "comm").read_text().startswith("qtvpr-"))
    raise AssertionError(task)


def test_fork_pool_workers_equal_the_parent(tmp_path):
    s_val = np.load(CORRIDOR / "deploy_S.npy")
    cal = qtvpr.Calibration(np.load(CORRIDOR / "cal_S.npy"), np.load(CORRIDOR / "cal_GT.npy"))
    cal.save(tmp_path / "cal.npz")
    # The parent uses the library first: its thread pool exists and has run work.
    want = _results(cal, s_val)
    online = qtvpr.Online(cal, k=5, window=20)
    online.push_many(s_val[:, :50])
    _INHERITED.update(s_val=s_val, online=online, path=tmp_path / "cal.npz")
    assert len(want[0]) == 60 and len(want[2]) == 5

    with multiprocessing.get_context("fork").Pool(2) as pool:
        jobs = {
            "continue": pool.apply_async(_worker, ("continue",)),
            "calibrate": pool.apply_async(_worker, ("calibrate",)),
            "load": pool.apply_async(_worker, ("load",)),
            "sent": pool.apply_async(_worker, ("sent", cal)),
        }
        got = {task: job.get(timeout=TIMEOUT) for task, job in jobs.items()}

    assert got["continue"] == (want[0][50:], want[1][50:])
    for task in ("calibrate", "load", "sent"):
        assert got[task] == want, task
    # The real values: the corridor's segment thresholds are scores of its matrix.
    assert all(np.isfinite(want[2])) and min(want[2]) > 0


def test_pool_size_is_kept_in_a_forked_child():
    """``qtvpr.set_threads`` sizes the pool, in this process and in forked children."""
    with pytest.raises(ValueError, match="threads must be >= 1, got 0"):
        qtvpr.set_threads(0)
    qtvpr.set_threads(2)
    s_val = np.load(CORRIDOR / "deploy_S.npy")
    cal = qtvpr.Calibration(np.load(CORRIDOR / "cal_S.npy"), np.load(CORRIDOR / "cal_GT.npy"))
    want = _results(cal, s_val)
    _INHERITED.update(s_val=s_val)
    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.apply_async(_worker, ("sent", cal)).get(timeout=TIMEOUT) == want
        if Path("/proc/self/task").is_dir():
            assert pool.apply_async(_worker, ("threads",)).get(timeout=TIMEOUT) == ["qtvpr-0", "qtvpr-1"]
