"""Regenerate the results table of docs/results.md on every real matrix in ../shared/data.

The paper's protocol (semantics §8) with the project's defaults: the first 10% of the
queries calibrate, segments of ceil(1%) of |Q| deployment queries, target precision
tau = 1, single-best-match decisions, k = 10, every method of semantics §7, §11 and
§13 (the margin gate alone, and with quantile transfer).

Matrices:
- the 20 VPR-Bench similarity matrices (Corridor and SPEDTest, 10 techniques each);
- Nordland winter (DB) vs summer (Q) HOG descriptors: single-frame cosine similarity
  S = normalize(db) @ normalize(q).T (float32), and its 11-frame sequence average
  S_seq[i, j] = mean of S[i + d, j + d] over d in -5..5 inside the matrix; ground
  truth |i - j| <= 1.

Uses the installed wheel (``pip install .``) and NumPy only. Writes the table between
``<!-- results:start -->`` and ``<!-- results:end -->`` in docs/results.md and prints it.

    python benches/results_table.py [--data ../shared/data] [--output docs/results.md]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import qtvpr

sys.path.insert(0, str(Path(__file__).resolve().parent))
from report import write_block  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
TECHNIQUES = [
    "AMOSNet", "AlexNet_VPR", "CALC", "CoHOG", "HOG",
    "HybridNet", "NetVLAD", "RegionVLAD", "ap-gem-r101", "denseVLAD",
]
METHODS = [
    "quantile-transfer", "quantile-transfer-online", "quantile-transfer-margin", "margin", "schubert",
    "schubert-calibrated", "calibration-threshold", "oracle",
]
SHORT = {
    "quantile-transfer": "QT",
    "quantile-transfer-online": "QT-online",
    "quantile-transfer-margin": "QT+gate",
    "margin": "Gate",
    "schubert": "Schubert",
    "schubert-calibrated": "Schubert-cal",
    "calibration-threshold": "Cal-thr",
    "oracle": "Oracle",
}


def normalize(x: np.ndarray) -> np.ndarray:
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def sequence_average(s: np.ndarray, half: int = 5) -> np.ndarray:
    """S_seq[i, j] = mean of S[i + d, j + d] for d in -half..half inside the matrix."""
    n, m = s.shape
    total = np.zeros((n, m), dtype=np.float64)
    count = np.zeros((n, m), dtype=np.float64)
    for d in range(-half, half + 1):
        # rows i with 0 <= i + d < n, columns j with 0 <= j + d < m
        i0, i1 = max(0, -d), min(n, n - d)
        j0, j1 = max(0, -d), min(m, m - d)
        total[i0:i1, j0:j1] += s[i0 + d:i1 + d, j0 + d:j1 + d]
        count[i0:i1, j0:j1] += 1
    return (total / count).astype(np.float32)


def matrices(data: Path):
    """(name, S, GT) of every real matrix, |DB| x |Q|."""
    for dataset, label in (("vprbench-corridor", "Corridor"), ("vprbench-spedtest", "SPEDTest")):
        gt = np.load(data / dataset / "GT.npy")
        for technique in TECHNIQUES:
            yield f"{label} {technique}", np.load(data / dataset / f"S_{technique}.npy"), gt
    db = np.load(data / "nordland-hog" / "db_winter.npy")
    q = np.load(data / "nordland-hog" / "query_summer.npy")
    s = (normalize(db) @ normalize(q).T).astype(np.float32)
    i = np.arange(s.shape[0])[:, None]
    j = np.arange(s.shape[1])[None, :]
    gt = np.abs(i - j) <= 1
    yield "Nordland HOG (single frame)", s, gt
    yield "Nordland HOG (11-frame sequence)", sequence_average(s), gt


def fmt(x, digits: int) -> str:
    return "n/a" if x is None else f"{x:.{digits}f}"


def table(rows) -> str:
    head = "| matrix | queries | segments counted |" + "".join(
        f" {SHORT[m]} %Segs | {SHORT[m]} AvgR |" for m in METHODS
    )
    align = "|:--|--:|--:|" + "--:|--:|" * len(METHODS)
    lines = [head, align]
    for name, n_q, res in rows:
        methods = res["methods"]
        counted = methods["oracle"]["segments_counted"]
        total = counted + methods["oracle"]["segments_skipped"]
        cells = "".join(
            f" {fmt(methods[m]['pct_segs'], 1)} | {fmt(methods[m]['avg_recall'], 3)} |" for m in METHODS
        )
        lines.append(f"| {name} | {n_q} | {counted} of {total} |{cells}")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--output", type=Path, default=REPO / "docs" / "results.md")
    args = parser.parse_args()

    rows = []
    start = time.perf_counter()
    for name, s, gt in matrices(args.data):
        t = time.perf_counter()
        res = qtvpr.evaluate(s, gt)  # 10% calibrate, segments of 1%, tau 1, single, k 10
        rows.append((name, s.shape[1], res))
        print(f"{name}: {time.perf_counter() - t:.2f} s", flush=True)
    text = (
        "Protocol: the first 10% of the queries calibrate; the rest are cut into segments of "
        "ceil(1% of |Q|) queries (remainder dropped); target precision 1 (AvgR is AvgR@100P); "
        "single-best-match decisions; k = 10; QT-online decides each query on its window of the last "
        "segment-size queries; QT+gate and Gate add the margin gate (docs/margin-gate.md). "
        "%Segs: segments kept at 100% precision; AvgR: mean "
        "recall of the counted segments, 0 for a segment that missed the target. "
        "Regenerate with `python benches/results_table.py`.\n\n" + table(rows)
    )
    print(f"\n{text}")
    write_block(args.output, "results", text)
    print(f"total {time.perf_counter() - start:.1f} s; table written to {args.output}")


if __name__ == "__main__":
    main()
