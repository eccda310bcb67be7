"""``qtvpr.dask.transfer`` at MSLS-val scale against the one-process CLI.

The matrix: benches/synthetic.py at 18,871 DB x 11,084 queries, float32; the first 10%
(1,108 queries) calibrate and the other 9,976 deploy, in segments of ceil(1%) = 111
queries, k = 10, tau = 1. The deployment part is written twice, as the ``.npy`` that
``qtvpr-cli threshold`` memory-maps and as a zarr store (chunks of |DB| x 222, two
segments, zarr's default compression), and thresholded:

1. by ``qtvpr-cli threshold`` (one process, all cores; and with one thread);
2. by ``qtvpr.dask.transfer`` reading the zarr store, on a ``LocalCluster`` of 1 and of
   2 worker processes with one thread each (``RAYON_NUM_THREADS=1`` in the workers, so
   that a worker is one core);
3. lazily: the same 9,976 x 18,871 scores as ``db_desc @ q_desc.T`` of two Dask arrays of
   256-d unit descriptors (random), never stored, on 2 workers.

Reported: wall time (cluster start excluded, reading included), the peak RSS of each
worker process (or of the CLI), and the cost of one block per worker-second, from which
the paragraph of docs/dask.md on a city-scale deployment is worked out. Every Dask result is
checked equal to the one-machine ``Calibration.transfer`` of the same scores.

    python benches/dask_bench.py [--cli target/release/qtvpr-cli] [--work DIR] [--no-readme]

Writes its figures into docs/dask.md between <!-- dask-bench:start --> and
<!-- dask-bench:end -->. Needs the wheel with its dask extra (pip install ".[dask]") and
a release CLI (cargo build --release -p qtvpr-cli). The inputs (about 1.6 GB) are
written under --work (default: a temporary directory) and deleted at the end.
"""

from __future__ import annotations

import os

# One core per worker process: the workers inherit this (the CLI runs are given their
# own environment).
os.environ["RAYON_NUM_THREADS"] = "1"
os.environ["OPENBLAS_NUM_THREADS"] = "1"
os.environ["OMP_NUM_THREADS"] = "1"

import argparse
import math
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

import dask.array as da
import numpy as np
from distributed import Client, LocalCluster

import qtvpr
import qtvpr.dask

sys.path.insert(0, str(Path(__file__).resolve().parent))
import synthetic  # noqa: E402
from compare import run_cli  # noqa: E402
from report import machine, write_block  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
N_DB, N_Q = 18871, 11084  # MSLS val


def peak_mib() -> float:
    """This process's peak RSS in MiB: VmHWM, whose count starts at the process's exec
    (ru_maxrss, the fallback, carries over the peak of the process that spawned it)."""
    try:
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:")) / 1024
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def same(got: qtvpr.TransferResult, want: qtvpr.TransferResult) -> None:
    assert got.segments == want.segments
    for name in ("thresholds", "quantiles", "query_quantiles", "query_thresholds", "query_weights", "neighbours"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name


IDLE: list[float] = []  # the peak RSS of every worker before its first task


def on_cluster(workers: int, run) -> tuple[float, list[float], object]:
    """Wall seconds of ``run()`` on a fresh cluster of ``workers`` one-thread worker
    processes, each worker's peak RSS (MiB) afterwards, and the result."""
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        IDLE.extend(client.run(peak_mib).values())
        t = time.perf_counter()
        out = run()
        wall = time.perf_counter() - t
        peaks = sorted(client.run(peak_mib).values())
    return wall, peaks, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cli", type=Path, default=REPO / "target" / "release" / "qtvpr-cli")
    ap.add_argument("--work", type=Path, default=None, help="where to write the inputs (deleted afterwards)")
    ap.add_argument("--no-readme", action="store_true", help="print only; leave docs/dask.md alone")
    ap.add_argument("--db", type=int, default=N_DB, help="|DB| (a smaller case, to try the script)")
    ap.add_argument("--queries", type=int, default=N_Q, help="|Q|, calibration included")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(dir=args.work))
    try:
        lines = measure(args.cli, work, args.db, args.queries)
    finally:
        shutil.rmtree(work)
    text = "\n".join(lines)
    print(text)
    if not args.no_readme:
        write_block(REPO / "docs" / "dask.md", "dask-bench", text)


def measure(cli: Path, work: Path, n_db: int, n_q: int) -> list[str]:
    n_cal, segment = n_q // 10, math.ceil(0.01 * n_q)
    chunk = 2 * segment
    load = os.getloadavg()[0]
    synthetic.make(work, n_db, n_q)
    cal_s, cal_gt, val = work / "cal" / "S.npy", work / "cal" / "GT.npy", work / "val" / "S.npy"
    store = str(work / "val.zarr")
    s_val = np.load(val, mmap_mode="r")
    n_val = s_val.shape[1]
    da.from_array(s_val, chunks=(n_db, chunk)).to_zarr(store)
    cal = qtvpr.Calibration(np.load(cal_s), np.load(cal_gt))
    want = cal.transfer(s_val, segment_size=segment)

    rows = []
    all_cores = {k: v for k, v in os.environ.items() if k != "RAYON_NUM_THREADS"}
    for label, env in ((f"qtvpr-cli threshold, {os.cpu_count()} threads", all_cores),
                       ("qtvpr-cli threshold, 1 thread", {**all_cores, "RAYON_NUM_THREADS": "1"})):
        saved = dict(os.environ)
        os.environ.clear()
        os.environ.update(env)
        try:
            runs = [run_cli(cli, cal_s, cal_gt, val, "--segment-size", str(segment)) for _ in range(2)]
        finally:
            os.environ.clear()
            os.environ.update(saved)
        wall, rss = min(r[0] for r in runs), max(r[1] for r in runs)
        rows.append((label, wall, f"{rss / 2**20:.0f} MiB"))

    walls = {}
    for workers in (1, 2):
        wall, peaks, got = on_cluster(workers, lambda: qtvpr.dask.transfer(
            cal, da.from_zarr(store), segment_size=segment))
        same(got, want)
        walls[workers] = wall
        rows.append((f"qtvpr.dask.transfer, zarr, {workers} worker{'s' * (workers > 1)} x 1 thread", wall,
                     " / ".join(f"{p:.0f}" for p in peaks) + " MiB"))

    # The lazy path: unit descriptors, S = db @ q.T computed block by block on the workers.
    rng = np.random.default_rng(0)
    db = rng.normal(size=(n_db, 256)).astype(np.float32)
    q = rng.normal(size=(n_val, 256)).astype(np.float32)
    db /= np.linalg.norm(db, axis=1, keepdims=True)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    lazy = da.from_array(db, chunks=(n_db, -1)) @ da.from_array(q, chunks=(chunk, -1)).T
    wall, peaks, got = on_cluster(2, lambda: qtvpr.dask.transfer(cal, lazy, segment_size=segment))
    same(got, cal.transfer(lazy.compute(), segment_size=segment))
    rows.append(("qtvpr.dask.transfer, lazy db @ q.T, 2 workers x 1 thread", wall,
                 " / ".join(f"{p:.0f}" for p in peaks) + " MiB"))

    cli_1 = rows[1][1]
    blocks = math.ceil(n_val / chunk)
    # One worker runs the blocks one after another: its wall time per block, overheads
    # included (scheduling, reading, the worker rebuilding the calibration once).
    per_block = walls[1] / blocks
    per_score = walls[1] / (n_db * n_val)
    big_db, big_q = 2_800_000, 100_000
    big_segment = math.ceil(0.01 * big_q)
    big_blocks = math.ceil(big_q / big_segment)
    total = per_score * big_db * big_q
    one_block = per_score * big_db * big_segment
    lines = [
        f"Measured by `benches/dask_bench.py` on {machine()}: synthetic {n_db} x {n_q} float32 "
        f"(benches/synthetic.py), the first {n_cal} queries calibrate, {n_val} deploy in segments of {segment}, "
        f"k = 10, tau = 1; zarr chunks of {n_db} x {chunk} ({n_db * chunk * 4 / 2**20:.0f} MiB, one block each, "
        f"{blocks} blocks). Wall time includes reading (the CLI memory-maps the .npy; the workers decompress zarr), "
        "not the cluster's start. Every Dask result equals `Calibration.transfer` bit for bit. The machine's "
        f"load average was {load:.1f} before and {os.getloadavg()[0]:.1f} after (other jobs share its cores: "
        "above the number of cores, the runs of several threads or workers gain little).",
        "",
        "| run | wall | peak RSS (per worker) |",
        "|---|--:|--:|",
        *(f"| {label} | {wall:.2f} s | {mem} |" for label, wall, mem in rows),
        "",
        f"On one machine Dask costs: one worker takes {walls[1] / cli_1:.2f}x the one-thread CLI's time "
        f"({walls[1]:.2f} s against {cli_1:.2f} s: scheduling, zarr decompression, moving blocks between "
        "processes, each worker rebuilding the calibration from its bytes), and two workers "
        f"{walls[2]:.2f} s, {walls[1] / walls[2]:.2f}x faster than one; an idle worker process already holds "
        f"{'-'.join(sorted({f'{min(IDLE):.0f}', f'{max(IDLE):.0f}'}, key=float))} MiB. "
        f"Dask is for data that do not fit one machine, not a speed-up on one. Per block of {chunk} queries, one "
        f"worker spent {per_block:.2f} s, overheads included: {per_score * 1e9:.2f} ns per score.",
        "",
        f"**A city-scale estimate, not a measurement.** {big_db:,} DB x {big_q:,} queries is "
        f"{big_db * big_q:.1e} scores; at {per_score * 1e9:.2f} ns each, {total:,.0f} worker-seconds "
        f"({total / 3600:.0f} worker-hours). With segments of 1% ({big_segment} queries) there are "
        f"{big_blocks} blocks of one segment, so at most {big_blocks} workers are busy: N = {big_blocks} workers "
        f"take one block's time, {one_block:,.0f} s ({one_block / 60:.0f} min); N = 10 take "
        f"{math.ceil(big_blocks / 10)} blocks each, {math.ceil(big_blocks / 10) * one_block / 3600:.1f} h. Each "
        f"such block is {big_db:,} x {big_segment} float32 = {big_db * big_segment * 4 / 2**30:.1f} GiB on its "
        "worker; smaller segments give smaller blocks and more of them. The cost per score was measured at "
        f"|DB| = {n_db} with {n_cal} calibration queries: it grows with log |DB| (each column is sorted) and with "
        "the calibration (each query is correlated with every calibration profile), so read these as lower "
        "bounds.",
    ]
    return lines


if __name__ == "__main__":
    main()
