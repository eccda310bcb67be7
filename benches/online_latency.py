"""Per-query latency of online thresholds (``qtvpr.Online.push``) on one thread.

A robot decides each query as it arrives, so what matters is the time of one ``push``:
one column of |DB| scores in, one accept/reject out. This measures it at three scales,
with the core on one thread (``RAYON_NUM_THREADS=1``, set before the wheel starts its
pool):

1. Nordland HOG (real): 3576 DB, the first 357 queries calibrate, window 36, k = 10;
2. paper scale (synthetic, benches/synthetic.py): 27,592 DB, 276 calibration queries,
   window 28;
3. MSLS val scale (synthetic): 18,871 DB, 1,108 calibration queries, window 111.

Each query is pushed in two ways: as a column view of a C-order float32 |DB| x |Q|
matrix (strided: a score a cache line), and contiguous (one query's |DB| scores, as an
online front end receives them, or a row of a query-major matrix). Reported: the
median and 99th percentile of the pushes once the window is full (the steady state),
and beside them, measured in the same run with NumPy on one thread
of the same machine:

- the *float32 pass*: one float32 dot product of the column with every calibration
  profile (4 x |DB| x |Qcal| bytes read), the yardstick a push is measured against
  (the target is a push of at most half of it);
- the *k-profile floor*: one sort of the column and one float64 dot product with k
  calibration profiles, what any exact push must pay at least (the k neighbours'
  correlations are their weights, so they are read in full).

    python benches/online_latency.py [--no-readme] [--queries N] [--cases paper,msls]

Writes the table into docs/deployment.md between <!-- online-bench:start --> and
<!-- online-bench:end -->. Needs the wheel (pip install .) and ../shared/data.
"""

from __future__ import annotations

import os

# One thread everywhere, before any pool starts: qtvpr's (rayon) and NumPy's BLAS, so
# that the NumPy yardstick is one core's too.
os.environ["RAYON_NUM_THREADS"] = "1"
os.environ["OPENBLAS_NUM_THREADS"] = "1"
os.environ["OMP_NUM_THREADS"] = "1"
os.environ["MKL_NUM_THREADS"] = "1"

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import qtvpr

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))  # shared_data: the data
import synthetic  # noqa: E402
from report import machine, write_block  # noqa: E402
from shared_data import nordland_similarity  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"


def synthetic_case(work: Path, n_db: int, n_q: int, n_val: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Calibration scores and labels (the first 10% of n_q) and the first n_val deployment columns."""
    rng = np.random.default_rng(0)
    n_cal = n_q // 10
    for part, cols, gt in (("cal", range(n_cal), True), ("val", range(n_cal, n_cal + n_val), False)):
        (work / part).mkdir(parents=True, exist_ok=True)
        synthetic.write(work / part, n_db, n_q, cols, rng, gt)
    return np.load(work / "cal" / "S.npy"), np.load(work / "cal" / "GT.npy"), np.load(work / "val" / "S.npy")


def yardsticks_ms(s_cal: np.ndarray, column: np.ndarray, k: int, reps: int = 20) -> dict:
    """NumPy's times (ms, one thread, best of ``reps``) on one column: its sort; one
    float32 pass of dot products over every calibration profile; and the k-profile
    floor, the sort plus one float64 dot product with k profiles."""
    profiles = np.sort(s_cal.astype(np.float64), axis=0)
    profiles -= profiles.mean(axis=0)
    profiles /= np.linalg.norm(profiles, axis=0)
    profiles64 = np.ascontiguousarray(profiles.T[:k])  # k calibration profiles, one per row
    profiles = np.ascontiguousarray(profiles.T, dtype=np.float32)  # one row per calibration query
    u64 = np.sort(column.astype(np.float64))
    u64 -= u64.mean()
    u64 /= np.linalg.norm(u64)
    u = u64.astype(np.float32)

    def best(f) -> float:
        out = np.inf
        for _ in range(reps):
            t = time.perf_counter()
            f()
            out = min(out, time.perf_counter() - t)
        return out * 1e3

    sort = best(lambda: np.sort(column))
    return {"sort": sort, "pass": best(lambda: profiles @ u), "floor": sort + best(lambda: profiles64 @ u64)}


def measure(name: str, s_cal, gt_cal, s_val, window: int, contiguous: bool, k: int = 10) -> dict:
    cal = qtvpr.Calibration(s_cal, gt_cal)
    online = qtvpr.Online(cal, k=k, precision=1.0, window=window)
    columns = np.ascontiguousarray(s_val.T) if contiguous else s_val.T  # row j: query j's scores
    times = []
    for column in columns:
        t = time.perf_counter_ns()
        online.push(column)
        times.append(time.perf_counter_ns() - t)
    steady = np.array(times[window:], dtype=np.float64) / 1e6
    return {
        "name": name,
        "layout": "contiguous" if contiguous else "strided",
        "db": s_cal.shape[0],
        "cal": s_cal.shape[1],
        "window": window,
        "pushes": len(steady),
        "median": float(np.median(steady)),
        "p99": float(np.percentile(steady, 99)),
        **yardsticks_ms(s_cal, s_val[:, 0], k),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--no-readme", action="store_true", help="print only; leave docs/deployment.md alone")
    ap.add_argument("--queries", type=int, default=1000, help="deployment queries pushed at the synthetic scales")
    ap.add_argument(
        "--cases", default="nordland,paper,msls", help="comma-separated cases to run: nordland, paper, msls"
    )
    args = ap.parse_args()

    cases = set(args.cases.split(","))
    rows = []
    if "nordland" in cases:
        s, gt = nordland_similarity(SHARED)
        n_cal = s.shape[1] // 10
        for contiguous in (False, True):
            rows.append(
                measure("Nordland HOG (real)", s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:], 36, contiguous)
            )
    scales = (
        ("paper", "paper scale (synthetic)", 27592, 2760, 28),
        ("msls", "MSLS val scale (synthetic)", 18871, 11084, 111),
    )
    for key, name, n_db, n_q, window in scales:
        if key not in cases:
            continue
        with tempfile.TemporaryDirectory() as tmp:
            s_cal, gt_cal, s_val = synthetic_case(Path(tmp), n_db, n_q, min(args.queries, n_q - n_q // 10))
            for contiguous in (False, True):
                rows.append(measure(name, s_cal, gt_cal, s_val, window, contiguous))

    lines = [
        f"Measured by `benches/online_latency.py` on one thread, on {machine()}; float32 columns, k = 10, tau = 1; "
        "the pushes after the window first fills. Beside them, NumPy's time on one thread of the same machine, in "
        "the same run: one sort of the column; the *float32 pass*, one float32 dot product of the column with every "
        "calibration profile (4 x |DB| x |Qcal| bytes, the yardstick); and the *k-profile floor*, the sort plus one "
        "float64 dot product with k profiles (what an exact push pays at least).",
        "",
        "| case | \\|DB\\| | calibration queries | window | column | pushes | median | 99th percentile "
        "| NumPy sort | NumPy float32 pass | median / pass | k-profile floor |",
        "|---|--:|--:|--:|---|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['db']} | {r['cal']} | {r['window']} | {r['layout']} | {r['pushes']} "
            f"| {r['median']:.3f} ms | "
            f"{r['p99']:.3f} ms | {r['sort']:.3f} ms | {r['pass']:.3f} ms | {r['median'] / r['pass']:.2f}x | "
            f"{r['floor']:.3f} ms |"
        )
    text = "\n".join(lines)
    print(text)
    if not args.no_readme:
        write_block(REPO / "docs" / "deployment.md", "online-bench", text)


if __name__ == "__main__":
    main()
