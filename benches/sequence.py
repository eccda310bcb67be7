"""The sequence gate (semantics §15) on the real sequential data, and its cost online.

1. **Targets**: on the 10 VPR-Bench Corridor techniques, Nordland HOG single frame and
   11-frame sequence, and the control (SPEDTest's 10 techniques with their database rows
   permuted, seed 0: SPEDTest is not a sequence, and with its identity ground truth the
   matches would otherwise line up through the index alone), the paper's protocol
   (first 10% calibrate, segments of 1%, tau = 1, single matching, k = 10): mean %Segs and
   AvgR@100P of quantile transfer (QT), the gate alone, QT with the gate, QT with the margin
   gate (with and without the sequence gate) and the oracle; pooled precision (true /
   accepted matches over every technique's segments). The targets of issue 48 are
   checked and printed.
2. **Sweep**: QT with the gate, one parameter changed at a time from the defaults, on
   Corridor, Nordland 11-frame and the control, so a user sees how sensitive it is.
3. **What a robot does**: Nordland 11-frame's deployment queries reordered as a robot
   would stream them (stops, a slower and a faster robot, a reverse traverse, jumps), the
   gate alone and QT with the gate.
4. **Push latency**: ``qtvpr.Online.push`` with online sequence matching (L = 11) at the
   paper's scale (synthetic, benches/synthetic.py), with the sequence gate and without,
   on one thread, in the same run.

Uses the installed wheel and NumPy only. Writes its tables between ``<!-- sequence-...:start -->``
and ``<!-- sequence-...:end -->`` markers in docs/sequence.md, and prints them.

    python benches/sequence.py [--data ../shared/data] [--output docs/sequence.md] [--queries N]
"""

from __future__ import annotations

import os

# The push latency is one core's: set before the wheel starts its pool.
os.environ.setdefault("RAYON_NUM_THREADS", "1")

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
from shared_data import DATASETS, TECHNIQUES, nordland_similarity, sequence_average, vprbench  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
METHODS = {
    "quantile-transfer": "QT",
    "sequence": "gate alone",
    "quantile-transfer-sequence": "**QT + gate**",
    "quantile-transfer-margin": "QT + margin",
    "quantile-transfer-margin-sequence": "QT + margin + gate",
    "oracle": "oracle",
}
#: The sweep: (label, evaluate() keyword arguments), one change each from the defaults.
SWEEP = [
    ("defaults (window 5, level 0.8, tolerance 2, drift 0.2, speed 1)", {}),
    ("level 0.4 (2 of 5)", {"sequence_level": 0.4}),
    ("level 0.6 (3 of 5)", {"sequence_level": 0.6}),
    ("level 1.0 (5 of 5)", {"sequence_level": 1.0}),
    ("window 3", {"sequence_window": 3}),
    ("window 8", {"sequence_window": 8}),
    ("window 10", {"sequence_window": 10}),
    ("tolerance 1", {"sequence_tolerance": 1.0}),
    ("tolerance 3", {"sequence_tolerance": 3.0}),
    ("tolerance 4", {"sequence_tolerance": 4.0}),
    ("drift 0", {"sequence_drift": 0.0}),
    ("drift 0.5", {"sequence_drift": 0.5}),
    ("speed 2 (a robot twice as fast as the database's)", {"sequence_speed": 2.0}),
]
SEED = 0


def permuted(s: np.ndarray, gt: np.ndarray, seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    """``s`` and ``gt`` with their database rows in a random order (fixed seed)."""
    order = np.random.default_rng(seed).permutation(s.shape[0])
    return s[order], gt[order]


def datasets(root: Path) -> dict[str, list[tuple[str, np.ndarray, np.ndarray]]]:
    """The four groups of matrices, |DB| x |Q|."""
    corridor, spedtest = DATASETS
    s, gt = nordland_similarity(root, np.float32)
    return {
        "Corridor (10)": [(t, *vprbench(root, corridor, t)) for t in TECHNIQUES],
        "Nordland 1-frame": [("HOG", s, gt)],
        "Nordland 11-frame": [("HOG", sequence_average(s), gt)],
        "SPEDTest permuted (10)": [(t, *permuted(*vprbench(root, spedtest, t))) for t in TECHNIQUES],
    }


def mean(values) -> float:
    """The mean of the figures that exist (a matrix without a counted segment has none)."""
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else float("nan")


class Summary:
    """A method's figures over a group of matrices."""

    def __init__(self, runs: list[dict]):
        self.pct = mean(r["pct_segs"] for r in runs)
        self.recall = mean(r["avg_recall"] for r in runs)
        self.tp = sum(r["pooled_tp"] for r in runs)
        self.accepted = self.tp + sum(r["pooled_fp"] for r in runs)

    @property
    def precision(self) -> float | None:
        """Pooled precision; None when nothing was accepted (it rests on no decision)."""
        return self.tp / self.accepted if self.accepted else None

    def cell(self, pooled: bool = True) -> str:
        text = f"{self.pct:.1f} / {self.recall:.3f}"
        if pooled:
            p = "n/a" if self.precision is None else f"{self.precision:.3f}"
            text += f" ; {p} ({self.tp}/{self.accepted})"
        return text


def evaluate(group, methods, **kwargs) -> dict[str, Summary]:
    runs = {m: [] for m in methods}
    for _, s, gt in group:
        result = qtvpr.evaluate(s, gt, methods=list(methods), **kwargs)
        for m in methods:
            runs[m].append(result["methods"][m])
    return {m: Summary(r) for m, r in runs.items()}


def targets_table(groups) -> tuple[str, bool]:
    results = {}
    for name, group in groups.items():
        t = time.perf_counter()
        results[name] = evaluate(group, METHODS)
        print(f"{name}: {time.perf_counter() - t:.1f} s", flush=True)
    lines = [
        "%Segs / AvgR@100P ; pooled precision (true / accepted matches), means over techniques.",
        "",
        "| method |" + "".join(f" {name} |" for name in groups),
        "|:--|" + "--:|" * len(groups),
    ]
    for method, label in METHODS.items():
        pooled = method != "oracle"
        lines.append(f"| {label} |" + "".join(f" {results[g][method].cell(pooled)} |" for g in groups))

    corridor, nordland, control = (results[g] for g in ("Corridor (10)", "Nordland 11-frame", "SPEDTest permuted (10)"))
    qt, gated = "quantile-transfer", "quantile-transfer-sequence"

    def false_rate(s: Summary) -> float:
        return (s.accepted - s.tp) / s.accepted if s.accepted else 0.0

    checks = [
        ("Corridor: QT + gate %Segs >= 95", corridor[gated].pct, corridor[gated].pct >= 95),
        (
            f"Corridor: QT + gate AvgR >= 0.75 x QT's ({0.75 * corridor[qt].recall:.3f})",
            corridor[gated].recall,
            corridor[gated].recall >= 0.75 * corridor[qt].recall,
        ),
        ("Nordland 11-frame: QT + gate %Segs >= 85", nordland[gated].pct, nordland[gated].pct >= 85),
        (
            f"Nordland 11-frame: QT + gate AvgR >= QT's ({nordland[qt].recall:.3f})",
            nordland[gated].recall,
            nordland[gated].recall >= nordland[qt].recall,
        ),
        (
            f"control: QT + gate's share of false matches <= QT's ({false_rate(control[qt]):.3f})",
            false_rate(control[gated]),
            false_rate(control[gated]) <= false_rate(control[qt]),
        ),
    ]
    lines += ["", "| target | measured | |", "|:--|--:|:--|"]
    lines += [
        f"| {what} | {value:.1f} | {'met' if ok else '**not met**'} |"
        if value > 1
        else f"| {what} | {value:.3f} | {'met' if ok else '**not met**'} |"
        for what, value, ok in checks
    ]
    return "\n".join(lines), all(ok for *_, ok in checks)


def sweep_table(groups) -> str:
    names = ("Corridor (10)", "Nordland 11-frame", "SPEDTest permuted (10)")
    lines = [
        "QT + gate, %Segs / AvgR@100P (means over techniques); the control's pooled precision "
        "(true / accepted), QT's own beside the defaults.",
        "",
        "| change from the defaults | Corridor (10) | Nordland 11-frame | control: pooled precision |",
        "|:--|--:|--:|--:|",
    ]
    method = "quantile-transfer-sequence"
    for label, kwargs in SWEEP:
        r = {n: evaluate(groups[n], [method, "quantile-transfer"] if not kwargs else [method], **kwargs) for n in names}
        control = r[names[2]][method]
        p = "n/a" if control.precision is None else f"{control.precision:.3f}"
        cell = f"{p} ({control.tp}/{control.accepted})"
        if not kwargs:
            qt = r[names[2]]["quantile-transfer"]
            cell += f"; QT {qt.precision:.3f} ({qt.tp}/{qt.accepted})"
        lines.append(f"| {label} | {r[names[0]][method].cell(False)} | {r[names[1]][method].cell(False)} | {cell} |")
        print(lines[-1], flush=True)
    return "\n".join(lines)


def robot_streams(n_q: int, n_cal: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Column orders of a traverse of ``n_q`` queries as a robot would stream them (the
    first ``n_cal``, the calibration, as recorded, then the deployment queries
    reordered), each with the gate's parameters it is evaluated with."""
    deploy = np.arange(n_cal, n_q)
    stops = deploy.copy()
    for at in sorted(rng.choice(len(deploy), 15, replace=False), reverse=True):
        stops = np.insert(stops, at, np.repeat(deploy[at], 20))
    chunks = np.array_split(deploy, 21)
    jumps = np.concatenate([chunks[i] for i in rng.permutation(len(chunks))])
    orders = {
        "as recorded": (deploy, {}),
        "15 stops of 20 frames": (stops, {}),
        "slower (every frame twice)": (np.repeat(deploy, 2), {}),
        "faster (every second frame)": (deploy[::2], {}),
        "faster, speed 2": (deploy[::2], {"sequence_speed": 2.0}),
        "reverse traverse": (deploy[::-1], {}),
        "reverse traverse, speed -1": (deploy[::-1], {"sequence_speed": -1.0}),
        "20 jumps (21 chunks shuffled)": (jumps, {}),
    }
    return {name: (np.concatenate([np.arange(n_cal), order]), kw) for name, (order, kw) in orders.items()}


def robot_table(root: Path) -> str:
    s, gt = nordland_similarity(root, np.float32)
    s = sequence_average(s)
    n_q = s.shape[1]
    n_cal = n_q // 10
    lines = [
        "Nordland 11-frame: the calibration (first 10%) as recorded, then the deployment queries "
        "streamed in another order (each query keeps its own column). Pooled precision "
        "(true / accepted) and the share of deployment queries accepted.",
        "",
        "| stream | gate alone | QT + gate | QT |",
        "|:--|--:|--:|--:|",
    ]
    methods = ["sequence", "quantile-transfer-sequence", "quantile-transfer"]
    for name, (order, kwargs) in robot_streams(n_q, n_cal, np.random.default_rng(SEED)).items():
        result = qtvpr.evaluate(s[:, order], gt[:, order], methods=methods, cal_queries=n_cal, **kwargs)
        cells = []
        deployed = len(order) - n_cal
        for m in methods:
            r = Summary([result["methods"][m]])
            p = "n/a" if r.precision is None else f"{r.precision:.3f}"
            cells.append(f"{p} ({r.tp}/{r.accepted}); {r.accepted / deployed:.0%}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    return "\n".join(lines)


def latency_table(n_queries: int) -> str:
    n_db, n_q, window, length = 27592, 2760, 28, 11
    n_cal = n_q // 10
    rng = np.random.default_rng(SEED)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for part, cols, with_gt in (("cal", range(n_cal), True), ("val", range(n_cal, n_cal + n_queries), False)):
            (work / part).mkdir()
            synthetic.write(work / part, n_db, n_q, cols, rng, with_gt)
        s_cal, gt_cal = np.load(work / "cal" / "S.npy"), np.load(work / "cal" / "GT.npy")
        columns = np.ascontiguousarray(np.load(work / "val" / "S.npy").T)
    cal = qtvpr.Calibration(s_cal, gt_cal, sequence=length)
    gates = ("none", "sequence", "margin,sequence")
    # Paired: each column is pushed into the three states in turn (the order rotating per
    # query), so that the machine's drift and other load fall on all three alike.
    states = [qtvpr.Online(cal, k=10, precision=1.0, window=window, gate=g, sequence=length) for g in gates]
    times = np.zeros((len(columns), len(gates)))
    for j, column in enumerate(columns):
        for i in np.roll(np.arange(len(gates)), j):
            t = time.perf_counter_ns()
            states[i].push(column)
            times[j, i] = time.perf_counter_ns() - t
    steady = times[window + length :] / 1e6
    rows = []
    for i, gate in enumerate(gates):
        ratio = float(np.median(steady[:, i] / steady[:, 0]))
        rows.append((gate, len(steady), float(np.median(steady[:, i])), float(np.percentile(steady[:, i], 99)), ratio))
        print(rows[-1], flush=True)
    lines = [
        f"`qtvpr.Online.push` on one thread, {machine()}: paper scale (synthetic, |DB| = {n_db}, "
        f"{n_cal} calibration queries), window {window}, k = 10, tau = 1, online sequence matching "
        f"L = {length}, contiguous float32 columns; the pushes after the window and the sequence fill, "
        "each column pushed into the three states in turn.",
        "",
        "| gate | pushes | median | 99th percentile | median of the paired ratios to no gate's |",
        "|:--|--:|--:|--:|--:|",
    ]
    lines += [f"| {g} | {n} | {med:.3f} ms | {p99:.3f} ms | {r:.3f}x |" for g, n, med, p99, r in rows]
    ratio = rows[1][4]
    verdict = "met" if ratio <= 1.10 else "**not met**"
    lines += ["", f"Target: a push with the gate within 1.10x of one without: {ratio:.3f}x, {verdict}."]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--output", type=Path, default=REPO / "docs" / "sequence.md")
    parser.add_argument("--queries", type=int, default=400, help="deployment queries pushed at the paper's scale")
    parser.add_argument("--no-write", action="store_true", help="print only; leave the doc alone")
    args = parser.parse_args()

    start = time.perf_counter()
    groups = datasets(args.data)
    blocks = {}
    blocks["sequence-targets"], met = targets_table(groups)
    blocks["sequence-sweep"] = sweep_table(groups)
    blocks["sequence-robot"] = robot_table(args.data)
    blocks["sequence-latency"] = latency_table(args.queries)
    heading = (
        f"Measured by `benches/sequence.py` in {time.perf_counter() - start:.0f} s on {machine()}; "
        f"paper protocol (first 10% calibrate, segments of 1%, tau = 1, single matching, k = 10); "
        f"control: SPEDTest's database rows permuted with seed {SEED}."
    )
    blocks["sequence-targets"] = heading + "\n\n" + blocks["sequence-targets"]
    for marker, text in blocks.items():
        print(f"\n{text}\n")
        if not args.no_write:
            write_block(args.output, marker, text)
    print("targets: all met" if met else "targets: NOT all met")


if __name__ == "__main__":
    main()
