"""Synthetic similarity matrices at the paper's scale, for benchmarks only.

Real data backs every claim about behaviour (../shared/data); these matrices exist to
measure speed and memory where no real matrix of that size is at hand. Each is a
|DB| x |Q| float32 .npy in C order (what ``np.save(db @ q.T)`` writes), with:

- a true match near the diagonal: query j shows database place round(j * |DB| / |Q|),
  with a peak that decays over a few neighbouring places;
- noise, and a score drift along the traverse (offset and contrast change with j, as
  with changing light or season);
- ground truth: hard within 2 places of the true one.

Usage: python benches/synthetic.py OUT_DIR DB Q [SEED] writes the calibration part (the
first 10% of the queries) as OUT_DIR/cal/S.npy and OUT_DIR/cal/GT.npy (bool) and the
deployment part as OUT_DIR/val/S.npy, a column chunk at a time so memory stays small.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np


def write(path: Path, n_db: int, n_q: int, cols: range, rng, with_gt: bool) -> None:
    """Scores (and ground truth) of queries ``cols`` of an |DB| x |Q| traverse."""
    s = np.lib.format.open_memmap(path / "S.npy", mode="w+", dtype=np.float32, shape=(n_db, len(cols)))
    if with_gt:
        gt = np.lib.format.open_memmap(path / "GT.npy", mode="w+", dtype=np.bool_, shape=(n_db, len(cols)))
    rows = np.arange(n_db)[:, None]
    step = max(1, (1 << 24) // n_db)
    for start in range(0, len(cols), step):
        local = np.arange(start, min(start + step, len(cols)))
        q = np.asarray(cols)[local]
        true = np.round(q * (n_db / n_q)).astype(np.int64)[None, :]
        dist = np.abs(rows - true)
        drift = q / n_q  # 0 .. 1 along the traverse
        offset = 0.25 + 0.15 * np.sin(2 * np.pi * drift)
        contrast = 0.35 - 0.2 * drift
        block = rng.normal(0.0, 0.05, size=(n_db, q.size)).astype(np.float32)
        peak = np.exp(-dist / 3.0) * rng.uniform(0.3, 1.0, size=q.size)
        block += (offset + contrast * peak).astype(np.float32)
        s[:, local] = block
        if with_gt:
            gt[:, local] = dist <= 2
    s.flush()


def make(out: Path, n_db: int, n_q: int, seed: int = 0) -> None:
    """``out/cal/{S,GT}.npy``: the first 10% of the queries; ``out/val/S.npy``: the rest."""
    rng = np.random.default_rng(seed)
    n_cal = n_q // 10
    for part, cols, with_gt in (("cal", range(0, n_cal), True), ("val", range(n_cal, n_q), False)):
        (out / part).mkdir(parents=True, exist_ok=True)
        write(out / part, n_db, n_q, cols, rng, with_gt)


if __name__ == "__main__":
    out, n_db, n_q = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
    make(out, n_db, n_q, int(sys.argv[4]) if len(sys.argv) > 4 else 0)
