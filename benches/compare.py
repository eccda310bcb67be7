"""End-to-end benchmark of qtvpr: the wheel against qtvpr.reference in one process, the
CLI as a whole process, and paper-scale synthetic matrices. Prints a Markdown report and
writes it into docs/performance.md between the markers <!-- bench:start --> and <!-- bench:end -->.

    python benches/compare.py [--cli PATH] [--work DIR] [--no-readme] [--skip-scale]

Needs the wheel installed (pip install .), numpy, ../shared/data, and the release CLI
(cargo build --release -p qtvpr-cli). Paper-scale inputs (about 1.5 GB of .npy) are
generated once into --work (default: a temporary directory).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import qtvpr
from qtvpr import reference

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))  # shared_data: the data
import synthetic  # noqa: E402
from report import machine, write_block  # noqa: E402
from shared_data import nordland_similarity  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"


def best_of(n: int, f):
    """(result, best wall seconds of n runs)."""
    best, out = math.inf, None
    for _ in range(n):
        t = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t)
    return out, best


def run_cli(cli: Path, cal: Path, gt: Path, val: Path, *extra: str) -> tuple[float, int, dict]:
    """Wall seconds, peak RSS in bytes and JSON output of one CLI process."""
    # Peak RSS of this child alone: run it through a tiny wrapper that reports getrusage.
    code = (
        "import resource, subprocess, sys, time, json;"
        "t = time.perf_counter(); p = subprocess.run(sys.argv[1:], capture_output=True, text=True);"
        "w = time.perf_counter() - t; r = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss;"
        "print(json.dumps({'wall': w, 'rss_kb': r, 'rc': p.returncode, 'out': p.stdout, 'err': p.stderr}))"
    )
    args = [str(cli), "threshold", "--quiet", "--cal", str(cal), "--cal-gt", str(gt), "--val", str(val), *extra]
    proc = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, check=True)
    res = json.loads(proc.stdout)
    if res["rc"] != 0:
        raise RuntimeError(res["err"])
    return res["wall"], res["rss_kb"] * 1024, json.loads(res["out"])


def real_case(cli: Path, work: Path) -> list[str]:
    s, gt = nordland_similarity(SHARED)
    n_cal, seg = s.shape[1] // 10, math.ceil(0.01 * s.shape[1])
    s_cal, gt_cal, s_val = s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:]
    for name, a in (("cal", s_cal), ("gt", gt_cal), ("val", s_val)):
        np.save(work / f"nordland_{name}.npy", np.ascontiguousarray(a))
    rows = [
        "| matching | wheel | reference | speed-up | CLI process | thresholds equal (1e-9) |",
        "|---|---|---|---|---|---|",
    ]
    for matching in ("single", "multi"):
        kw = dict(matching=matching, segment_size=seg)
        wheel, t_wheel = best_of(5, lambda kw=kw: qtvpr.quantile_transfer(s_cal, gt_cal, s_val, **kw))
        ref, t_ref = best_of(1, lambda kw=kw: reference.quantile_transfer(s_cal, gt_cal, s_val, **kw))
        same = np.allclose(wheel.thresholds, ref.thresholds, rtol=0, atol=1e-9)
        t_cli = min(run_cli(cli, *(work / f"nordland_{n}.npy" for n in ("cal", "gt", "val")),
                            "--matching", matching, "--segment-size", str(seg))[0] for _ in range(5))
        rows.append(f"| {matching} | {t_wheel * 1e3:.0f} ms | {t_ref:.2f} s | **{t_ref / t_wheel:.0f}x** "
                    f"| {t_cli * 1e3:.0f} ms | {'yes' if same else 'NO'} |")
    return rows


def threads_case() -> list[str]:
    """Does a call release the GIL? Two ways to look, in a child process:
    1. two Python threads each calling the wheel with a one-thread core
       (RAYON_NUM_THREADS=1), against the same two calls in sequence;
    2. a pure-Python counting thread's rate while the wheel runs, against its rate alone."""
    code = r"""
import threading, time, numpy as np, qtvpr
rng = np.random.default_rng(0)
s = rng.random((3000, 1500), dtype=np.float32)
gt = np.zeros((3000, 150), bool); gt[np.arange(150) * 20, np.arange(150)] = True
call = lambda: qtvpr.quantile_transfer(s[:, :150], gt, s[:, 150:], segment_size=15)
call()
t = time.perf_counter(); call(); call(); seq = time.perf_counter() - t
ts = [threading.Thread(target=call) for _ in range(2)]
t = time.perf_counter(); [x.start() for x in ts]; [x.join() for x in ts]; par = time.perf_counter() - t
def count(stop, out):
    n = 0
    while not stop.is_set():
        n += 1
    out.append(n)
def rate(during):
    stop, out = threading.Event(), []
    th = threading.Thread(target=count, args=(stop, out)); th.start()
    t = time.perf_counter(); during(); dt = time.perf_counter() - t
    stop.set(); th.join(); return out[0] / dt
alone = rate(lambda: time.sleep(0.3))
busy = rate(lambda: [call() for _ in range(3)])
print(seq, par, busy / alone)
"""
    env = dict(os.environ, RAYON_NUM_THREADS="1")
    seq, par, ratio = map(float, subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                                                text=True, check=True).stdout.split())
    return [f"with a one-thread core (`RAYON_NUM_THREADS=1`), two calls in sequence take {seq * 1e3:.0f} ms "
            f"and the same two calls from two Python threads at once {par * 1e3:.0f} ms ({seq / par:.2f}x: "
            f"the calls share the core's one worker pool, so they overlap only in their serial parts). A pure-Python "
            f"thread counting while the wheel runs keeps {ratio:.0%} of its speed alone: the GIL is released while the "
            f"core runs."]


def batch_ms(d: Path, n_val: int, seg: int) -> float:
    """The batch transfer from Python (``Calibration.transfer``) of the first ``n_val``
    deployment queries, an in-memory C-order float32 matrix: ms per query, best of 3."""
    cal = qtvpr.Calibration(np.load(d / "cal" / "S.npy"), np.load(d / "cal" / "GT.npy"))
    s_val = np.ascontiguousarray(np.load(d / "val" / "S.npy", mmap_mode="r")[:, :n_val])
    return best_of(3, lambda: cal.transfer(s_val, segment_size=seg))[1] * 1e3 / n_val


def scale_case(cli: Path, work: Path) -> list[str]:
    rows = [
        "| case | |DB| x |Q| | f32 input | wall | per deployment query | peak RSS | RSS / input "
        "| `Calibration.transfer`, 1,000 queries in memory: per query |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, n_db, n_q in (("Nordland (paper)", 27592, 2760), ("MSLS val", 18871, 11084)):
        d = work / f"synthetic_{n_db}x{n_q}"
        if not (d / "val" / "S.npy").exists():
            synthetic.make(d, n_db, n_q)
        n_val = n_q - n_q // 10
        seg = math.ceil(0.01 * n_q)
        runs = [run_cli(cli, d / "cal" / "S.npy", d / "cal" / "GT.npy", d / "val" / "S.npy", "--segment-size", str(seg))
                for _ in range(3)]
        wall, rss = min(r[0] for r in runs), max(r[1] for r in runs)
        size = n_db * n_q * 4
        batch = batch_ms(d, 1000, seg)
        rows.append(f"| {name} | {n_db} x {n_q} | {size / 2**20:.0f} MiB | {wall:.2f} s "
                    f"| {wall / n_val * 1e3:.3f} ms | {rss / 2**20:.0f} MiB | {rss / size:.2f} | {batch:.3f} ms |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cli", type=Path, default=REPO / "target" / "release" / "qtvpr-cli")
    ap.add_argument("--work", type=Path, default=None, help="where to keep generated inputs")
    ap.add_argument("--no-readme", action="store_true", help="print only; leave docs/performance.md alone")
    ap.add_argument("--skip-scale", action="store_true", help="skip the paper-scale synthetic cases")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        report = [f"Measured by `benches/compare.py` on {machine()}.", "",
                  "**Real: Nordland HOG** (3576 x 3576 float32 cosine; first 10% calibrate, segments of 36, "
                  "k = 10, tau = 1). Wheel and reference in the same process; best of 5 for the wheel and the CLI:", ""]
        report += real_case(args.cli, work)
        report += ["", "**Threads:** " + threads_case()[0], ""]
        if not args.skip_scale:
            report += ["**Paper scale, synthetic** (benches/synthetic.py: a true match near the diagonal, "
                       "score drift along the traverse; C-order float32 .npy, memory-mapped; first 10% "
                       "calibrate, segments of 1%; the CLI as a whole process, reading included; best wall and "
                       "largest peak RSS of 3 runs):", ""]
            report += scale_case(args.cli, work)
    text = "\n".join(report)
    print(text)
    if not args.no_readme:
        write_block(REPO / "docs" / "performance.md", "bench", text)


if __name__ == "__main__":
    main()
