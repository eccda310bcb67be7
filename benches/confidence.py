"""How well the confidence of semantics §14 is calibrated, on every real matrix.

For each of the 22 real matrices of benches/results_table.py (VPR-Bench Corridor and
SPEDTest, 10 techniques each; Nordland HOG single frame and 11-frame sequence), in the
paper's protocol (the first 10% of the queries calibrate; the deployment queries are
the n_seg x seg of the full 1% segments, from the first deployment query; soft-only
best matches left out; single matching): the AUROC of the best match's correctness c
for three signals (the best score s1, the margin, the confidence; ties count one
half), and for the confidence its Brier score, the Brier score of the constant
calibration hit rate (what a map of one block gives), and the expected calibration
error over 10 equal-width bins (the last holds 1.0), each bin's |mean confidence -
mean c| weighted by its share of queries. These are section 14's evaluation signals,
computed here in NumPy from the wheel's per-query confidences (`evaluate` does not
report them yet).

Uses the installed wheel and NumPy only. Writes the table between
``<!-- confidence:start -->`` and ``<!-- confidence:end -->`` in docs/margin-gate.md
and prints it.

    python benches/confidence.py [--data ../shared/data] [--output docs/margin-gate.md]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

import qtvpr

sys.path.insert(0, str(Path(__file__).resolve().parent))
from report import write_block  # noqa: E402
from results_table import matrices  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def auroc(x: np.ndarray, c: np.ndarray) -> float:
    """P(x of a correct query > x of a wrong one), ties one half; NaN without both."""
    pos, neg = x[c], x[~c]
    if len(pos) == 0 or len(neg) == 0:
        return math.nan
    greater = (pos[:, None] > neg[None, :]).sum()
    ties = (pos[:, None] == neg[None, :]).sum()
    return float((greater + 0.5 * ties) / (len(pos) * len(neg)))


def ece(p: np.ndarray, c: np.ndarray) -> float:
    """Expected calibration error over 10 equal-width bins of [0, 1]."""
    bins = np.minimum((p * 10).astype(int), 9)
    return float(sum(abs(p[bins == b].mean() - c[bins == b].mean()) * (bins == b).mean()
                     for b in range(10) if (bins == b).any()))


def signals(s: np.ndarray, gt: np.ndarray) -> dict:
    n_q = s.shape[1]
    n_cal = n_q // 10
    seg = math.ceil(0.01 * n_q)
    n_dep = (n_q - n_cal) // seg * seg
    cal = qtvpr.Calibration(s[:, :n_cal], gt[:, :n_cal])
    s_val, gt_val = s[:, n_cal:n_cal + n_dep], gt[:, n_cal:n_cal + n_dep]
    p = cal.transfer(s_val).query_confidences
    best = s_val.argmax(axis=0)
    c = gt_val[best, np.arange(n_dep)]
    # The calibration's own hit rate: the constant a one-block map gives.
    cal_best = s[:, :n_cal].argmax(axis=0)
    rate = gt[cal_best, np.arange(n_cal)].mean()
    return {
        "blocks": len(cal.confidence_blocks()),
        "auroc_score": auroc(s_val.max(axis=0).astype(np.float64), c),
        "auroc_margin": auroc(qtvpr.margins(s_val), c),
        "auroc_confidence": auroc(p, c),
        "brier": float(np.mean((p - c) ** 2)),
        "brier_constant": float(np.mean((rate - c) ** 2)),
        "ece": ece(p, c),
    }


def table(rows: list[tuple[str, dict]]) -> str:
    keys = ["auroc_score", "auroc_margin", "auroc_confidence", "brier", "brier_constant", "ece"]
    lines = [
        f"Section 14's signals in the paper's protocol (single matching; qtvpr {qtvpr.__version__}). "
        "Regenerate with `python benches/confidence.py`.",
        "",
        "| matrix | blocks | AUROC score | AUROC margin | AUROC confidence | Brier | Brier of the constant | ECE |",
        "|:--|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for name, r in rows:
        lines.append(f"| {name} | {r['blocks']} | " + " | ".join(f"{r[k]:.3f}" for k in keys) + " |")
    for label, prefix in (("Corridor", "Corridor"), ("SPEDTest", "SPEDTest"), ("all 22", "")):
        part = [r for name, r in rows if name.startswith(prefix)]
        means = " | ".join(f"{np.nanmean([r[k] for r in part]):.3f}" for k in keys)
        lines.append(f"| **mean, {label}** | | {means} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--output", type=Path, default=REPO / "docs" / "margin-gate.md")
    args = parser.parse_args()
    rows = [(name, signals(s, gt)) for name, s, gt in matrices(args.data)]
    text = table(rows)
    print(text)
    write_block(args.output, "confidence", text)


if __name__ == "__main__":
    main()
