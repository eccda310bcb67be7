"""The margin gate (semantics §13) against quantile transfer on every real matrix.

For five protocol settings (the paper's, then one change each: 5% or 20% of the queries
calibrate, segments of 2%, tau = 0.95), the mean over the 22 real matrices of
benches/results_table.py (VPR-Bench Corridor and SPEDTest, 10 techniques each; Nordland
HOG single frame and 11-frame sequence) of %Segs and AvgR@tauP for quantile transfer
(QT), the gate alone (margin), QT with the gate, and the calibration threshold; single
matching, k = 10. Also lists, for the paper's setting, every matrix on which a gated
method is worse than QT on both figures, and those whose m* is reject-all.

Uses the installed wheel and NumPy only. Writes the tables between
``<!-- margin:start -->`` and ``<!-- margin:end -->`` in docs/margin-gate.md and prints
them.

    python benches/margin_gate.py [--data ../shared/data] [--output docs/margin-gate.md]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import qtvpr

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))  # shared_data: the data
from report import write_block  # noqa: E402
from shared_data import matrices  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
METHODS = {
    "quantile-transfer": "QT",
    "margin": "margin gate",
    "quantile-transfer-margin": "QT and gate",
    "calibration-threshold": "calibration threshold",
}
#: (label, evaluate() keyword arguments): the paper's protocol, then one change each.
SETTINGS = [
    ("paper: 10% calibrate, 1% segments, tau 1", {}),
    ("5% calibrate", {"cal_fraction": 0.05}),
    ("20% calibrate", {"cal_fraction": 0.20}),
    ("2% segments", {"segment_fraction": 0.02}),
    ("tau 0.95", {"precision": 0.95}),
]


def mean(values) -> float:
    """The mean of the figures that exist (a matrix without a counted segment has none)."""
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--output", type=Path, default=REPO / "docs" / "margin-gate.md")
    args = parser.parse_args()

    start = time.perf_counter()
    data = list(matrices(args.data))
    results = {label: [] for label, _ in SETTINGS}
    for name, s, gt in data:
        t = time.perf_counter()
        for label, kwargs in SETTINGS:
            results[label].append((name, qtvpr.evaluate(s, gt, methods=list(METHODS), **kwargs)))
        print(f"{name}: {time.perf_counter() - t:.2f} s", flush=True)

    head = "| protocol |" + "".join(f" {short} |" for short in METHODS.values())
    lines = [head, "|:--|" + "--:|" * len(METHODS)]
    for label, _ in SETTINGS:
        cells = []
        for method in METHODS:
            runs = [r["methods"][method] for _, r in results[label]]
            pct = mean(m["pct_segs"] for m in runs)
            recall = mean(m["avg_recall"] for m in runs)
            cells.append(f" {pct:.1f} / {recall:.3f} |")
        lines.append(f"| {label} |" + "".join(cells))

    worse = []
    for name, r in results[SETTINGS[0][0]]:
        qt = r["methods"]["quantile-transfer"]
        for method in ("margin", "quantile-transfer-margin"):
            gated = r["methods"][method]
            if None in (qt["pct_segs"], gated["pct_segs"]):
                continue
            if gated["pct_segs"] < qt["pct_segs"] and gated["avg_recall"] < qt["avg_recall"]:
                worse.append(
                    f"| {name} | {METHODS[method]} | {qt['pct_segs']:.1f} / {qt['avg_recall']:.3f} | "
                    f"{gated['pct_segs']:.1f} / {gated['avg_recall']:.3f} |"
                )
    reject_all = [
        name
        for name, r in results[SETTINGS[0][0]]
        if r["methods"]["margin"]["segments"] and r["methods"]["margin"]["segments"][0]["gate"] == float("inf")
    ]
    version = qtvpr.__version__
    text = (
        f"%Segs / AvgR@tauP, the mean over the {len(data)} real matrices (single matching, k = 10; "
        f"qtvpr {version}). Regenerate with `python benches/margin_gate.py`.\n\n"
        + "\n".join(lines)
        + "\n\nIn the paper's setting, a gated method is worse than QT on both figures "
        + (f"{len(worse)} times:\n\n| matrix | method | QT | the method |\n|:--|:--|--:|--:|\n"
           + "\n".join(worse) + "\n"
           if worse else "on no matrix.\n")
        + "\nMatrices whose m* is reject-all in the paper's setting (no calibration decision clears it): "
        + (", ".join(reject_all) if reject_all else "none")
        + ".\n"
    )
    print(f"\n{text}")
    write_block(args.output, "margin", text)
    print(f"total {time.perf_counter() - start:.1f} s; written to {args.output}")


if __name__ == "__main__":
    main()
