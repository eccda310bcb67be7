"""Quantile transfer calibrated on self-motion labels (semantics §16) against ground truth.

The data of the sequence gate's issue: VPR-Bench Corridor (10 techniques), Nordland HOG's
11-frame sequence average, and the control, SPEDTest (10 techniques) with its database rows
permuted (one permutation, seed 0), so that no database neighbour is a route neighbour. The
paper's protocol (the first 10% of the queries calibrate, segments of 1%, precision 1,
single matching, k = 10). For each matrix, quantile transfer (QT) calibrated on the ground
truth, and on the self-motion labels of its calibration queries under three rules: the
shipped one (the library's defaults, 0.7 / 0.3 with abstention), the majority rule (at
least half agree, else negative) and the strict one (0.8 / 0.2 with abstention); the
deployment queries are counted on the real ground truth. Also the pseudo-positives and the
false ones (a pseudo-positive whose best match the ground truth calls wrong), summed over
a dataset's matrices, and the targets of issue 50, PASS or FAIL.

Uses the installed wheel (labels: ``qtvpr.ground_truth_from_sequence``; figures:
``qtvpr.evaluate`` with the labels as the calibration columns' ground truth) and NumPy
only. Writes the table between ``<!-- labels:start -->`` and ``<!-- labels:end -->`` in
docs/self-motion-labels.md and prints it.

    python benches/self_motion_labels.py [--data ../shared/data] [--output docs/self-motion-labels.md]
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
from report import machine, write_block  # noqa: E402
from shared_data import DATASETS, TECHNIQUES, nordland_similarity, sequence_average, vprbench  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
#: (label, ground_truth_from_sequence() keyword arguments). The shipped rule is the
#: library's defaults; majority: f >= 0.5 positive, anything below negative (the largest
#: share below 1/2 with at most 10 neighbours is 4/9, under 0.49).
RULES = [
    ("shipped: 0.7 / 0.3, abstain between", {}),
    ("majority: >= 0.5, else negative", {"positive_level": 0.5, "negative_level": 0.49}),
    ("strict: 0.8 / 0.2, abstain between", {"positive_level": 0.8, "negative_level": 0.2}),
]
SHIPPED = RULES[0][0]
#: The seed of the control's permutation of database rows (the sequence gate's bench's).
CONTROL_SEED = 0


def datasets(root: Path):
    """(dataset, [(name, S, GT)]): Corridor, Nordland 11-frame, the permuted control."""
    corridor, spedtest = DATASETS
    yield "Corridor", [(t, *vprbench(root, corridor, t)) for t in TECHNIQUES]
    s, gt = nordland_similarity(root, np.float32)
    yield "Nordland HOG 11-frame", [("HOG 11-frame", sequence_average(s), gt)]
    control = []
    for t in TECHNIQUES:
        s, gt = vprbench(root, spedtest, t)
        rows = np.random.default_rng(CONTROL_SEED).permutation(s.shape[0])
        control.append((t, s[rows], gt[rows]))
    yield "SPEDTest, rows permuted", control


def qt(s, gt, gt_soft=None) -> dict:
    """QT's figures in the paper's protocol."""
    return qtvpr.evaluate(s, gt, gt_soft=gt_soft, methods=["quantile-transfer"])


def on_labels(s, gt, n_cal: int, rule: dict) -> dict:
    """QT calibrated on the self-motion labels of the first ``n_cal`` queries (their
    columns' hard and soft ground truth replaced by the labels'), with the label counts."""
    hard, soft = gt.copy(), gt.copy()
    try:
        labels = qtvpr.ground_truth_from_sequence(s[:, :n_cal], **rule)
    except ValueError as e:
        if "no pseudo-positive" not in str(e):
            raise
        # Refused: a calibration without a positive, which rejects every query, counts.
        hard[:, :n_cal] = soft[:, :n_cal] = False
        figures = qt(s, hard, soft)["methods"]["quantile-transfer"]
        return {"positive": 0, "false": 0, "refused": 1, "figures": figures}
    hard[:, :n_cal], soft[:, :n_cal] = labels.hard, labels.soft
    positive = labels.labels == "positive"
    false = positive & ~gt[labels.best, np.arange(n_cal)]
    figures = qt(s, hard, soft)["methods"]["quantile-transfer"]
    return {"positive": int(positive.sum()), "false": int(false.sum()), "refused": 0, "figures": figures}


def mean(values) -> float:
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else float("nan")


def summary(runs: list[dict]) -> tuple[float, float]:
    """Mean %Segs and AvgR@100P."""
    return mean(r["pct_segs"] for r in runs), mean(r["avg_recall"] for r in runs)


def cell(figures: tuple[float, float]) -> str:
    return f"{figures[0]:.1f} / {figures[1]:.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--output", type=Path, default=REPO / "docs" / "self-motion-labels.md")
    args = parser.parse_args()

    start = time.perf_counter()
    results = {}  # dataset -> {"gt": [...], rule: [...]}
    for dataset, mats in datasets(args.data):
        res = results[dataset] = {"gt": [], **{label: [] for label, _ in RULES}}
        for name, s, gt in mats:
            t = time.perf_counter()
            on_gt = qt(s, gt)
            n_cal = on_gt["params"]["calibration_queries"]
            res["gt"].append(on_gt["methods"]["quantile-transfer"])
            for label, rule in RULES:
                res[label].append(on_labels(s, gt, n_cal, rule))
            print(f"{dataset} {name}: {n_cal} calibration queries, {time.perf_counter() - t:.2f} s", flush=True)

    names = list(results)
    lines = ["| calibration labels |" + "".join(f" {d} |" for d in names), "|:--|" + "--:|" * len(names)]
    lines.append("| ground truth |" + "".join(f" {cell(summary(results[d]['gt']))} |" for d in names))
    for label, _ in RULES:
        cells = []
        for d in names:
            runs = results[d][label]
            pos, false = sum(r["positive"] for r in runs), sum(r["false"] for r in runs)
            refused = sum(r["refused"] for r in runs)
            figures = cell(summary([r["figures"] for r in runs]))
            cells.append(f" {figures} ; +{pos} (false {false}), refused {refused} |")
        lines.append(f"| self-motion labels, {label} |" + "".join(cells))

    checks = []
    for d in names[:2]:
        on_gt, shipped = summary(results[d]["gt"]), results[d][SHIPPED]
        on_labels_ = summary([r["figures"] for r in shipped])
        pos, false = sum(r["positive"] for r in shipped), sum(r["false"] for r in shipped)
        ok = on_labels_[0] >= on_gt[0]
        checks.append((f"{d}: %Segs on labels {on_labels_[0]:.1f} >= on GT {on_gt[0]:.1f}", ok))
        ok = on_labels_[1] >= 0.85 * on_gt[1]
        checks.append((f"{d}: AvgR on labels {on_labels_[1]:.3f} >= 0.85 x on GT {0.85 * on_gt[1]:.3f}", ok))
        checks.append((f"{d}: false pseudo-positives {false} of {pos} <= 5%", pos > 0 and false <= 0.05 * pos))
    control = sum(r["positive"] for r in results[names[2]][SHIPPED])
    checks.append((f"{names[2]}: pseudo-positives {control} = 0", control == 0))

    text = (
        "%Segs / AvgR@100P, the mean over a dataset's matrices (Corridor and the control: 10 "
        "techniques each), in the paper's protocol (single matching, k = 10), then the "
        "pseudo-positives summed over the matrices and how many of them the ground truth calls "
        "wrong, and on how many matrices no label is positive, which `ground-truth --from-sequence` "
        "refuses: such a matrix counts as a calibration that rejects every query (100% of segments, "
        "recall 0). Deployment queries are counted on the ground truth. "
        f"qtvpr {qtvpr.__version__}, {machine()}. Regenerate with "
        "`python benches/self_motion_labels.py`.\n\n"
        + "\n".join(lines)
        + "\n\nTargets (issue 50, the shipped rule):\n\n"
        + "\n".join(f"- {'PASS' if ok else 'FAIL'}: {what}" for what, ok in checks)
        + "\n"
    )
    print(f"\n{text}")
    write_block(args.output, "labels", text)
    print(f"total {time.perf_counter() - start:.1f} s; written to {args.output}")


if __name__ == "__main__":
    main()
