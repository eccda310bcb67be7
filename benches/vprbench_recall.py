"""VPR-Bench's "recall at 100% precision" against ours, on every real matrix.

VPR-Bench (Zaffar et al., IJCV 2021, ``performance_comparison.py``) marks each query's
best match correct or not, runs scikit-learn's ``precision_recall_curve`` on those
marks against the best-match scores, and reports the recall of the lowest threshold
whose precision is 1 (0 when the top-scoring match is wrong). Its recall divides by
the number of *correct best matches*. Ours (single matching, tau = 1, the exact sweep
of docs/semantics.md) divides by the number of *queries with a hard match*. The
numerators are the same (the most correct best matches accepted with no false one),
so VPR-Bench's figure should be ours divided by R@1 = correct best matches / queries
with a match.

This script computes VPR-Bench's figure directly in NumPy and ours from
``qtvpr.evaluate``'s JSON keys (one deployment segment holding every query but the
first, which must calibrate; the oracle's recall is then our recall at 100% precision
and ``recall_at_1`` is R@1 of the same queries), and prints both. Matrices: those of
``scripts/shared_data.py`` (20 VPR-Bench, Nordland HOG single frame and 11-frame
sequence).

    python benches/vprbench_recall.py [--data ../shared/data]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import qtvpr
from qtvpr.reference import vprbench_recall_at_100p

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
from shared_data import matrices  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def ours(s: np.ndarray, gt: np.ndarray) -> tuple[float, float | None]:
    """(our recall at 100% precision, R@1) of every query but the first, from the JSON keys."""
    out = qtvpr.evaluate(s, gt, cal_queries=1, segment_size=s.shape[1] - 1, methods=["oracle"])
    (segment,) = out["methods"]["oracle"]["segments"]
    return segment["recall"], out["recall_at_1"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    args = parser.parse_args()
    print("| matrix | R@1 | ours R@100P | ours / R@1 | VPR-Bench R@100P | agree |")
    print("|:--|--:|--:|--:|--:|:-:|")
    agree = total = 0
    for name, s, gt in matrices(args.data):
        recall, r1 = ours(s, gt)
        theirs = vprbench_recall_at_100p(s[:, 1:], gt[:, 1:])
        rescaled = recall / r1 if r1 else float("nan")
        same = abs(rescaled - theirs) <= 1e-12
        agree += same
        total += 1
        print(f"| {name} | {r1:.4f} | {recall:.4f} | {rescaled:.4f} | {theirs:.4f} | {'yes' if same else 'NO'} |")
    print(f"\n{agree} of {total} agree to 1e-12.")


if __name__ == "__main__":
    main()
