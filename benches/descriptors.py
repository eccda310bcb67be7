"""Thresholds straight from descriptors at scale: the fused `threshold --db-descriptors`
(the similarity computed chunk by chunk, never written) against its floor and against
`similarity` + `threshold --similarity`. Prints a Markdown report and writes it into
docs/performance.md between <!-- descriptors-bench:start --> and <!-- descriptors-bench:end -->.

    python benches/descriptors.py --cli target/release/qtvpr-cli \
        --floor target/release/examples/descriptor_floor [--work DIR] [--scale F] [--smoke] [--no-docs]

Build both first: cargo build --release -p qtvpr-cli && cargo build --release -p qtvpr
--example descriptor_floor. Cases (synthetic float32 descriptors, 512-D; query j is a
noisy copy of database row j, positives |i - j| <= 1 (--cal-gt-tolerance 1); the first
10% of the queries calibrate, segments of 1%):
- SF-XL-like: 1,000,000 x 2,000, 512-D (2 GB of database descriptors; --scale shrinks
  |DB|), and the same at 256-D;
- MSLS val: 18,871 x 11,084, fused against similarity + matrix path.
Beside each fused run's peak RSS: its memory target, the descriptors + 1 GiB.
The descriptors are written into --work (default: a temporary directory) and deleted
at the end. Wall time and peak RSS are those of the CLI process (/usr/bin/time -v).
--smoke runs tiny sizes only (a check that the script works, seconds).
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from report import machine, write_block  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def write_case(work: Path, name: str, n_db: int, n_q: int, dim: int, seed: int) -> dict[str, Path]:
    """Database and query descriptors (float32, C order): query j is database row j
    plus noise."""
    rng = np.random.default_rng(seed)
    paths = {k: work / f"{name}_{k}.npy" for k in ("db", "q")}
    db = np.lib.format.open_memmap(paths["db"], mode="w+", dtype=np.float32, shape=(n_db, dim))
    step = 65536
    for i in range(0, n_db, step):
        db[i : i + step] = rng.standard_normal((min(step, n_db - i), dim), dtype=np.float32)
    q = db[:n_q] + 0.8 * rng.standard_normal((n_q, dim), dtype=np.float32)
    np.save(paths["q"], q.astype(np.float32))
    db.flush()
    del db
    return paths


def timed(cmd: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MiB) of one process, by /usr/bin/time -v."""
    out = subprocess.run(["/usr/bin/time", "-v", *cmd], capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{out.stderr}")
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", out.stderr).group(1)
    parts = [float(p) for p in wall.split(":")]
    seconds = sum(p * 60**i for i, p in enumerate(reversed(parts)))
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", out.stderr).group(1)) / 1024
    return seconds, rss


def threshold_args(n_q: int) -> list[str]:
    seg = max(n_q // 100, 1)
    return ["--cal-gt-tolerance", "1", "--cal-fraction", "0.1", "--segment-size", str(seg), "-q"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cli", type=Path, default=ROOT / "target/release/qtvpr-cli")
    ap.add_argument("--floor", type=Path, default=ROOT / "target/release/examples/descriptor_floor")
    ap.add_argument("--work", type=Path)
    ap.add_argument("--scale", type=float, default=1.0, help="fraction of the 1,000,000 database rows")
    ap.add_argument("--smoke", action="store_true")
    ap.add_argument("--no-docs", action="store_true")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(dir=args.work))
    n_large = 2000 if args.smoke else int(1_000_000 * args.scale)
    msls = (400, 300) if args.smoke else (18871, 11084)
    cases = [
        ("SF-XL-like", n_large, 200 if args.smoke else 2000, 512),
        ("SF-XL-like", n_large, 200 if args.smoke else 2000, 256),
        ("MSLS val", *msls, 512),
    ]
    cli = str(args.cli)
    try:
        floor = json.loads(subprocess.run([str(args.floor)], capture_output=True, text=True, check=True).stdout)
        lines = [
            f"Measured by `benches/descriptors.py` on {machine()}. "
            f"Floor: faer's f32 GEMM reaches {floor['gemm_f32_gflops']:.1f} GFLOP/s on a "
            f"{' x '.join(map(str, floor['gemm_shape']))} product, one sort of a column (the core's) takes "
            f"{floor['sort_ns_per_score']:.2f} ns per score.",
            "",
            "| case | \\|DB\\| x \\|Q\\| x D | f32 descriptors | path | wall | per deployment query "
            "| peak RSS | descriptors + 1 GiB | floor |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for case, n_db, n_q, dim in cases:
            p = write_case(work, case.split()[0], n_db, n_q, dim, seed=n_db + dim)
            desc_mib = (n_db + n_q) * dim * 4 / 2**20
            n_val = n_q - n_q // 10
            floor_s = 2 * n_db * n_q * dim / (floor["gemm_f32_gflops"] * 1e9) + n_db * n_q * floor[
                "sort_ns_per_score"
            ] * 1e-9
            common = threshold_args(n_q)
            fused = ["threshold", "--db-descriptors", str(p["db"]), "--query-descriptors", str(p["q"])]
            wall, rss = timed([cli, *fused, *common, "-o", str(work / "fused.json")])
            shape = f"{n_db} x {n_q} x {dim}"
            target = desc_mib + 1024
            lines.append(
                f"| {case} | {shape} | {desc_mib:.0f} MiB | fused | {wall:.1f} s | "
                f"{wall / n_val * 1e3:.2f} ms | {rss:.0f} MiB | {target:.0f} MiB "
                f"({'met' if rss <= target else 'not met'}) | {floor_s:.1f} s |"
            )
            if case == "MSLS val":
                s = work / "S.npy"
                w1, r1 = timed([cli, "similarity", "--db", str(p["db"]), "--queries", str(p["q"]), "-o", str(s), "-q"])
                w2, r2 = timed([cli, "threshold", "--similarity", str(s), *common, "-o", str(work / "matrix.json")])
                # The matrix path also says how it read the matrix's layout (`orientation`,
                # issue 49); descriptors have no layout to read. Everything else is equal.
                fused_out = json.loads((work / "fused.json").read_text())
                matrix_out = json.loads((work / "matrix.json").read_text())
                matrix_out.pop("orientation")
                same = "orientation" not in fused_out and fused_out == matrix_out
                lines.append(
                    f"| {case} | {shape} | {desc_mib:.0f} MiB | similarity + threshold --similarity "
                    f"({s.stat().st_size / 2**20:.0f} MiB matrix written) | {w1:.1f} + {w2:.1f} s | "
                    f"{(w1 + w2) / n_val * 1e3:.2f} ms | {max(r1, r2):.0f} MiB | | |"
                )
                lines.append("")
                lines.append(
                    f"MSLS: fused and matrix-path JSON equal but for the matrix path's `orientation`: "
                    f"{'yes' if same else 'NO'}."
                )
                s.unlink()
            for f in p.values():
                f.unlink()
        report = "\n".join(lines)
        print(report)
        if not args.no_docs and not args.smoke:
            write_block(ROOT / "docs/performance.md", "descriptors-bench", report)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
