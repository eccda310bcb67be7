"""Regenerate the results table of docs/results.md on every real matrix in ../shared/data.

The paper's protocol (semantics §8) with the project's defaults: the first 10% of the
queries calibrate, segments of ceil(1%) of |Q| deployment queries, target precision
tau = 1, single-best-match decisions, k = 10, every method of semantics §7, §11 and
§13 (the margin gate alone, and with quantile transfer).

Matrices (``scripts/shared_data.py``'s ``matrices``):
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

import qtvpr

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))  # shared_data: the data
from report import write_block  # noqa: E402
from shared_data import matrices  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
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


def fmt(x, digits: int) -> str:
    return "n/a" if x is None else f"{x:.{digits}f}"


#: Beside a %Segs that rests on no accepted match (semantics §8.6: ``pooled_accepted`` 0).
NONE_ACCEPTED = "<sup>0</sup>"


def pct_segs(m: dict) -> str:
    """A method's %Segs, marked when the method accepted nothing on the whole deployment
    set: every counted segment then meets the target by convention (semantics §8.3)."""
    return fmt(m["pct_segs"], 1) + (NONE_ACCEPTED if m["pooled_accepted"] == 0 else "")


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
        cells = "".join(f" {pct_segs(methods[m])} | {fmt(methods[m]['avg_recall'], 3)} |" for m in METHODS)
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
        "%Segs: segments kept at 100% precision (a segment that accepts nothing is kept, as in the paper; "
        f"{NONE_ACCEPTED} marks a method that accepted no match at all, whose precision is undefined); AvgR: mean "
        "recall of the counted segments, 0 for a segment that missed the target. "
        "Regenerate with `python benches/results_table.py`.\n\n" + table(rows)
    )
    print(f"\n{text}")
    write_block(args.output, "results", text)
    print(f"total {time.perf_counter() - start:.1f} s; table written to {args.output}")


if __name__ == "__main__":
    main()
