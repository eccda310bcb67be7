"""How well the confidence of semantics §14 ranks and is calibrated, on every real matrix.

For each of the 22 real matrices of benches/results_table.py (VPR-Bench Corridor and
SPEDTest, 10 techniques each; Nordland HOG single frame and 11-frame sequence), single
matching, in the five protocol settings of docs/margin-gate.md (the paper's: the first
10% of the queries calibrate, 1% segments, tau 1; then one change each: 5% or 20%
calibrate, 2% segments, tau 0.95, which no signal depends on): section 14's signals
over the protocol's deployment decisions as `qtvpr.evaluate` reports them (the AUROC
of the best match's correctness c for the best score s1, the margin, the PA-score and
the confidence; the confidence's Brier score, ECE and reliability bins), and the Brier
score of the constant calibration hit rate, computed here: what a map that knows
nothing but the calibration's hit rate would score.

It also measures the maps section 14 was chosen among, written here in NumPy on the
same decisions (the shipped one is the core's, and its row must equal the core's
figures): the previous release's step function of the least-squares isotonic fit on the
margin; the shipped centred map (two pooling passes, Laplace values, linear between
centres, on to the Clopper-Pearson bounds) on the margin (its lower tail ends at margin
0; the margin has no upper end, so the map is flat beyond its last centre); on the
PA-score (shipped); and on whichever of the two ranks the calibration pairs better
(AUROC on the calibration alone, the PA-score on a tie).

Uses the installed wheel and NumPy only. Writes the tables between
``<!-- confidence:start -->`` and ``<!-- confidence:end -->`` in docs/margin-gate.md
and the figure docs/confidence.svg (mean AUROC per signal and dataset; the reliability
diagram of each dataset's bins pooled over its matrices; a hand-written SVG, no
plotting package), and prints the tables.

    python benches/confidence.py [--data ../shared/data] [--output docs/margin-gate.md]
                                 [--figure docs/confidence.svg]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

import qtvpr
import qtvpr.reference

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))  # shared_data: the data
from margin_gate import SETTINGS  # noqa: E402
from report import machine, write_block  # noqa: E402
from shared_data import matrices  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
#: Figure columns: (key of a row, label).
AUROCS = [("auroc_score", "score s1"), ("auroc_margin", "margin"), ("auroc_confidence", "confidence"),
          ("auroc_pa", "PA-score")]
CALIBRATION = [("brier", "Brier"), ("brier_constant", "Brier of the constant"), ("ece", "ECE")]
#: Datasets of the figure and of the means: (label, prefix of the matrix names).
GROUPS = [("Corridor", "Corridor"), ("SPEDTest", "SPEDTest"), ("Nordland", "Nordland"), ("all", "")]


def auroc(x: np.ndarray, c: np.ndarray) -> float | None:
    """P(x of a right decision > x of a wrong one), ties one half; None without both."""
    right, wrong = x[c], x[~c]
    if len(right) == 0 or len(wrong) == 0:
        return None
    above = np.count_nonzero(right[:, None] > wrong[None, :])
    ties = np.count_nonzero(right[:, None] == wrong[None, :])
    return float((above + ties / 2) / (len(right) * len(wrong)))


def pooled(x: np.ndarray, c: np.ndarray, prior: int, points: list | None = None) -> list[list]:
    """Pool-adjacent-violators by ascending x (more confident last) on the value
    (x + prior) / (n + 2 prior); blocks are [sum of x, n, successes], maximal."""
    if points is None:
        points = []
        for i in np.argsort(x, kind="stable"):
            if points and points[-1][3] == x[i]:
                points[-1][0] += x[i]
                points[-1][1] += 1
                points[-1][2] += int(c[i])
            else:
                points.append([float(x[i]), 1, int(c[i]), x[i]])
    out: list[list] = []
    for p in points:
        out.append(list(p))
        while len(out) > 1 and (out[-2][2] + prior) * (out[-1][1] + 2 * prior) >= \
                (out[-1][2] + prior) * (out[-2][1] + 2 * prior):
            last = out.pop()
            for i in range(3):
                out[-1][i] += last[i]
    return out


def step_map(x_cal: np.ndarray, c_cal: np.ndarray, x: np.ndarray) -> np.ndarray:
    """0.1.0's map: the least-squares blocks' x/n, looked up by the largest lowest x <= x."""
    order = np.sort(x_cal)
    blocks, lows, seen = pooled(x_cal, c_cal, 0), [], 0
    for b in blocks:
        lows.append(order[seen])
        seen += b[1]
    values = np.array([b[2] / b[1] for b in blocks])
    return values[np.maximum(np.searchsorted(lows, x, side="right") - 1, 0)]


def centred_map(x_cal: np.ndarray, c_cal: np.ndarray, x: np.ndarray, low: float, high: float | None) -> np.ndarray:
    """Section 14's map on a signal x (more confident when higher), its range from low
    to high (None: unbounded, flat beyond the last centre)."""
    blocks = pooled(x_cal, c_cal, 1, pooled(x_cal, c_cal, 0))
    xs = [b[0] / b[1] for b in blocks]
    ys = [(b[2] + 1) / (b[1] + 2) for b in blocks]
    first, last = blocks[0], blocks[-1]
    if xs[0] > low:
        xs, ys = [low] + xs, [qtvpr.reference.precision_lower95(first[2], first[1] - first[2])] + ys
    if high is not None and xs[-1] < high:
        xs, ys = xs + [high], ys + [1 - qtvpr.reference.precision_lower95(last[1] - last[2], last[2])]
    return np.interp(x, xs, ys)


def figures(p: np.ndarray, c: np.ndarray) -> tuple:
    """AUROC, Brier and ECE of confidences p."""
    return auroc(p, c), float(np.mean((p - c) ** 2)), qtvpr.reference._ece(p, c)


#: The maps measured: (key, label).
MAPS = [("step_margin", "step, margin (0.1.0)"), ("centred_margin", "centred, margin"),
        ("centred_pa", "centred, PA-score (shipped)"), ("centred_either", "centred, the better of the two")]


def candidates(s: np.ndarray, gt: np.ndarray, n_cal: int, dep: slice) -> dict:
    """Each map of MAPS on the same calibration pairs and deployment decisions."""
    best = s.argmax(axis=0)
    c = gt[best, np.arange(s.shape[1])]
    margin = np.asarray(qtvpr.margins(s), dtype=np.float64)
    distinct = 1 - qtvpr.reference._pa_scores(s.astype(np.float64))  # higher is more confident
    cal = slice(0, n_cal)
    out = {
        "step_margin": step_map(margin[cal], c[cal], margin[dep]),
        "centred_margin": centred_map(margin[cal], c[cal], margin[dep], 0.0, None),
        "centred_pa": centred_map(distinct[cal], c[cal], distinct[dep], 0.0, 1.0),
    }
    by_margin, by_pa = auroc(margin[cal], c[cal]), auroc(distinct[cal], c[cal])
    either = "centred_margin" if None not in (by_margin, by_pa) and by_margin > by_pa else "centred_pa"
    out["centred_either"] = out[either]
    return {key: figures(p, c[dep]) for key, p in out.items()}


def signals(s: np.ndarray, gt: np.ndarray, kwargs: dict) -> dict:
    """The core's signals of one run, and the constant's Brier score on the same decisions."""
    r = qtvpr.evaluate(s, gt, methods=["oracle"], **kwargs)
    p, sig = r["params"], r["confidence"]["signals"]
    n_cal, start = p["calibration_queries"], p["deployment_start"]
    dep = slice(start, start + p["segments"] * p["segment_size"])
    s_dep, gt_dep = s[:, dep], gt[:, dep]
    cols = np.arange(s_dep.shape[1])
    best = s_dep.argmax(axis=0)
    c = gt_dep[best, cols]
    # The same decisions as the core's (no soft ground truth here): its score AUROC.
    mine = auroc(s_dep[best, cols].astype(np.float64), c)
    assert mine == sig["score"]["auroc"] or abs(mine - sig["score"]["auroc"]) < 1e-12, (mine, sig)
    cal_best = s[:, :n_cal].argmax(axis=0)
    rate = gt[cal_best, np.arange(n_cal)].mean()
    maps = candidates(s, gt, n_cal, dep)
    # The shipped map, written here, gives the core's figures.
    core = (sig["confidence"]["auroc"], sig["confidence"]["brier"], sig["confidence"]["ece"])
    assert all(abs(a - b) < 1e-9 for a, b in zip(maps["centred_pa"], core, strict=True)), (maps["centred_pa"], core)
    return {
        "maps": maps,
        "blocks": len(qtvpr.Calibration(s[:, :n_cal], gt[:, :n_cal]).confidence_blocks()),
        "auroc_score": sig["score"]["auroc"],
        "auroc_margin": sig["margin"]["auroc"],
        "auroc_confidence": sig["confidence"]["auroc"],
        "auroc_pa": sig["pa_score"]["auroc"],
        "brier": sig["confidence"]["brier"],
        "brier_constant": float(np.mean((rate - c) ** 2)),
        "ece": sig["confidence"]["ece"],
        "bins": sig["confidence"]["bins"],
    }


def mean(rows: list[dict], key: str) -> float:
    """The mean of the figures that exist."""
    values = [r[key] for r in rows if r[key] is not None]
    return float(np.mean(values)) if values else math.nan


def group(rows: list[tuple[str, dict]], prefix: str) -> list[dict]:
    return [r for name, r in rows if name.startswith(prefix)]


def fmt(x) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.3f}"


def tables(results: dict[str, list[tuple[str, dict]]]) -> str:
    keys = [k for k, _ in AUROCS + CALIBRATION]
    heads = " | ".join(f"AUROC {label}" for _, label in AUROCS) + " | " + " | ".join(label for _, label in CALIBRATION)
    paper = results[SETTINGS[0][0]]
    lines = [
        f"Section 14's signals (single matching; qtvpr {qtvpr.__version__}). Regenerate with "
        "`python benches/confidence.py`, which also draws the figure. The mean over the "
        f"{len(paper)} real matrices in each setting of the gate's table above:",
        "",
        f"| protocol | {heads} |",
        "|:--|" + "--:|" * len(keys),
    ]
    for label, _ in SETTINGS:
        rows = [r for _, r in results[label]]
        lines.append(f"| {label} | " + " | ".join(fmt(mean(rows, k)) for k in keys) + " |")
    lines += [
        "",
        "The maps measured (AUROC / Brier / ECE of the confidence, the mean over the "
        f"{len(paper)} matrices; benches/confidence.py writes the others in NumPy):",
        "",
        "| protocol | " + " | ".join(label for _, label in MAPS) + " |",
        "|:--|" + "--:|" * len(MAPS),
    ]
    for label, _ in SETTINGS:
        rows = [r["maps"] for _, r in results[label]]
        cells = []
        for key, _ in MAPS:
            auroc_, brier, ece = (float(np.mean([r[key][i] for r in rows if r[key][i] is not None])) for i in range(3))
            cells.append(f"{auroc_:.3f} / {brier:.3f} / {ece:.3f}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Per matrix, in the paper's setting (blocks: of the confidence map):",
        "",
        f"| matrix | blocks | {heads} |",
        "|:--|--:|" + "--:|" * len(keys),
    ]
    for name, r in paper:
        lines.append(f"| {name} | {r['blocks']} | " + " | ".join(fmt(r[k]) for k in keys) + " |")
    for label, prefix in GROUPS:
        if label != "Nordland":
            rows = group(paper, prefix)
            name = label if prefix else f"all {len(rows)}"
            lines.append(f"| **mean, {name}** | | " + " | ".join(fmt(mean(rows, k)) for k in keys) + " |")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------
# The figure, a hand-written SVG
# ---------------------------------------------------------------------------------------

SIGNAL_COLOURS = ["#7f7f7f", "#2ca02c", "#1f77b4", "#ff7f0e"]
GROUP_COLOURS = {"Corridor": "#d62728", "SPEDTest": "#9467bd", "Nordland": "#8c564b"}
FONT = 'font-family="sans-serif"'


def text(x: float, y: float, s: str, size: int = 12, anchor: str = "middle", extra: str = "") -> str:
    s = s.replace("&", "&amp;").replace("<", "&lt;")
    return f'<text x="{x:.1f}" y="{y:.1f}" {FONT} font-size="{size}" text-anchor="{anchor}"{extra}>{s}</text>'


def pooled_bins(rows: list[dict]) -> list[tuple[float, float, int]]:
    """(mean confidence, hit rate, n) per bin, pooled over the matrices' bins: each
    bin's means weighted by its counts."""
    pooled: dict[float, list[float]] = {}
    for r in rows:
        for b in r["bins"] or []:
            acc = pooled.setdefault(b["lower"], [0.0, 0.0, 0])
            acc[0] += b["n"] * b["mean_confidence"]
            acc[1] += b["n"] * b["hit_rate"]
            acc[2] += b["n"]
    return [(a[0] / a[2], a[1] / a[2], a[2]) for _, a in sorted(pooled.items())]


def figure(paper: list[tuple[str, dict]]) -> str:
    w, h = 980, 430
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}">',
           f'<rect width="{w}" height="{h}" fill="white"/>']
    # Left: mean AUROC per signal, one group of bars per dataset.
    x0, y0, pw, ph = 60, 50, 400, 290  # plot area: left, top, width, height
    out.append(text(x0 + pw / 2, 24, "Mean AUROC of c per signal (paper's protocol)", 15))

    def y_of(v: float) -> float:
        return y0 + ph * (1 - v)

    for t in np.linspace(0, 1, 6):
        out.append(f'<line x1="{x0}" x2="{x0 + pw}" y1="{y_of(t):.1f}" y2="{y_of(t):.1f}" stroke="#e1e1e1"/>')
        out.append(text(x0 - 6, y_of(t) + 4, f"{t:.1f}", 11, "end"))
    out.append(f'<line x1="{x0}" x2="{x0 + pw}" y1="{y_of(0.5):.1f}" y2="{y_of(0.5):.1f}" stroke="#555" '
               'stroke-dasharray="5,4"/>')
    out.append(text(x0 + pw + 4, y_of(0.5) + 4, "chance", 11, "start", ' fill="#555"'))
    slot = pw / len(GROUPS)
    bar = slot * 0.8 / len(AUROCS)
    for g, (label, prefix) in enumerate(GROUPS):
        rows = group(paper, prefix)
        for i, (key, _) in enumerate(AUROCS):
            v = mean(rows, key)
            x = x0 + g * slot + slot * 0.1 + i * bar
            out.append(f'<rect x="{x:.1f}" y="{y_of(v):.1f}" width="{bar - 2:.1f}" height="{ph * v:.1f}" '
                       f'fill="{SIGNAL_COLOURS[i]}"><title>{label}, {key}: {v:.3f}</title></rect>')
        out.append(text(x0 + (g + 0.5) * slot, y0 + ph + 18, f"{label} ({len(rows)})", 12))
    out.append(text(18, y0 + ph / 2, "AUROC", 13, "middle", f' transform="rotate(-90 18 {y0 + ph / 2})"'))
    for i, (_, label) in enumerate(AUROCS):
        lx = x0 + i * 100
        out.append(f'<rect x="{lx}" y="{y0 + ph + 34}" width="14" height="14" fill="{SIGNAL_COLOURS[i]}"/>')
        out.append(text(lx + 19, y0 + ph + 46, label, 12, "start"))

    # Right: the reliability diagram, each dataset's bins pooled over its matrices.
    x0, y0, pw, ph = 580, 50, 290, 290
    out.append(text(x0 + pw / 2 + 30, 24, "Reliability of the confidence (bins pooled)", 15))

    def px(v: float) -> float:
        return x0 + pw * v

    def py(v: float) -> float:
        return y0 + ph * (1 - v)

    for t in np.linspace(0, 1, 6):
        out.append(f'<line x1="{px(t):.1f}" x2="{px(t):.1f}" y1="{y0}" y2="{y0 + ph}" stroke="#e1e1e1"/>')
        out.append(f'<line x1="{x0}" x2="{x0 + pw}" y1="{py(t):.1f}" y2="{py(t):.1f}" stroke="#e1e1e1"/>')
        out.append(text(px(t), y0 + ph + 16, f"{t:.1f}", 11))
        out.append(text(x0 - 6, py(t) + 4, f"{t:.1f}", 11, "end"))
    out.append(f'<line x1="{px(0)}" y1="{py(0)}" x2="{px(1)}" y2="{py(1)}" stroke="#555" stroke-dasharray="5,4"/>')
    out.append(text(x0 + pw / 2, y0 + ph + 34, "mean confidence of the bin", 13))
    out.append(text(x0 - 40, y0 + ph / 2, "hit rate of the bin", 13, "middle",
                    f' transform="rotate(-90 {x0 - 40} {y0 + ph / 2})"'))
    for g, (label, prefix) in enumerate(GROUPS[:3]):
        pts = pooled_bins(group(paper, prefix))
        colour = GROUP_COLOURS[label]
        path = " ".join(f"{px(p):.1f},{py(q):.1f}" for p, q, _ in pts)
        out.append(f'<polyline points="{path}" fill="none" stroke="{colour}" stroke-width="1.5"/>')
        for p, q, n in pts:
            # Area by count: a radius from 2.5 (one decision) to about 9 (thousands).
            r = 2.5 + 1.6 * math.log10(n)
            out.append(f'<circle cx="{px(p):.1f}" cy="{py(q):.1f}" r="{r:.1f}" fill="{colour}" fill-opacity="0.75">'
                       f"<title>{label}: confidence {p:.3f}, hit rate {q:.3f}, n = {n}</title></circle>")
        ly = y0 + 14 + 18 * g
        out.append(f'<circle cx="{x0 + pw + 18}" cy="{ly - 4}" r="5" fill="{colour}"/>')
        out.append(text(x0 + pw + 28, ly, label, 12, "start"))
    for i, line in enumerate(["dot size: the", "decisions in", "the bin (log)", "", "dashed: perfect", "calibration"]):
        out.append(text(x0 + pw + 12, y0 + 76 + 14 * i, line, 11, "start", ' fill="#555"'))
    out.append(text(w / 2, h - 8, f"qtvpr {qtvpr.__version__}, python benches/confidence.py; single matching, "
                    "10% calibrate, 1% segments", 11, "middle", ' fill="#555"'))
    out.append("</svg>")
    return "\n".join(out) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--output", type=Path, default=REPO / "docs" / "margin-gate.md")
    parser.add_argument("--figure", type=Path, default=REPO / "docs" / "confidence.svg")
    args = parser.parse_args()
    start = time.perf_counter()
    results: dict[str, list[tuple[str, dict]]] = {label: [] for label, _ in SETTINGS}
    for name, s, gt in matrices(args.data):
        for label, kwargs in SETTINGS:
            results[label].append((name, signals(s, gt, kwargs)))
        print(f"{name}: done", flush=True)
    text_ = tables(results)
    print(f"\n{text_}")
    write_block(args.output, "confidence", text_)
    args.figure.write_text(figure(results[SETTINGS[0][0]]))
    print(f"total {time.perf_counter() - start:.1f} s on {machine()}; written to {args.output} and {args.figure}")


if __name__ == "__main__":
    main()
