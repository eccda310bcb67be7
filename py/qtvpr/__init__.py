"""Quantile transfer: automatic operating-point selection for visual place recognition.

A VPR system accepts a match when its similarity score is at or above a threshold.
Quantile transfer (Rajani, Milford, Fischer, IROS 2026) sets that threshold for each
batch of deployment queries without their ground truth, from a calibration traverse
that has ground truth.

Similarity matrices are |DB| x |Q| (one column per query; pass ``query_major=True`` for
|Q| x |DB|), float32 or float64, higher meaning more similar. Ground truth is bool or
integer 0/1 of the same shape. Any matrix argument may also be the path of a ``.npy``
file (ground truth: ``.npy`` or a VPR_Tutorial ``.npz``), read by the CLI's reader;
similarity files are memory-mapped (as with NumPy's ``mmap_mode``, no other process
may truncate such a file while it is read: that is a bus error, not an exception).

Bad input raises ``ValueError`` (``TypeError`` for a wrong dtype; ``FileNotFoundError``,
``IsADirectoryError``, ``PermissionError`` or ``OSError`` for a file that cannot be
read), with a message naming the argument, the file and what is wrong.

>>> import numpy as np, qtvpr
>>> s_cal = np.array([[0.9, 0.2], [0.1, 0.8], [0.3, 0.4]])
>>> gt_cal = np.array([[True, False], [False, True], [False, False]])
>>> s_val = np.array([[0.7, 0.1, 0.2], [0.2, 0.6, 0.3], [0.1, 0.3, 0.5]])
>>> result = qtvpr.quantile_transfer(s_cal, gt_cal, s_val, k=1)
>>> result.segments
[(0, 3)]

A robot decides each query as it arrives: calibrate once, offline, save the
calibration file, and decide every deployment query at the threshold of its last
``window`` queries (docs/semantics.md):

>>> import os, tempfile
>>> path = os.path.join(tempfile.mkdtemp(), "cal.npz")
>>> qtvpr.Calibration(s_cal, gt_cal).save(path, k=1, window=2)
>>> online = qtvpr.Online(qtvpr.Calibration.load(path))  # k and window from the file
>>> decision = online.push(s_val[:, 0])  # one query's |DB| scores
>>> decision.query, decision.best
(0, 0)

The functions are compiled (module ``qtvpr._native``); ``qtvpr.reference`` is a plain
NumPy implementation of the same functions, the executable form of the specification,
imported on first use (``qtvpr.reference.evaluate`` works after a bare ``import qtvpr``).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# The paper's functions, and extensions that meet users where their data is
# (cosine_similarity, sequence_match, ground_truth_*, utm_positions, image_paths:
# descriptors, positions, tolerance, image names, and a traverse's own order).
from qtvpr._native import (
    Calibration,
    Descriptors,
    Online,
    OnlineDecision,
    OnlineDecisions,
    SelfMotionLabels,
    TransferResult,
    __version__,
    ablation,
    best_threshold,
    cosine_similarity,
    counts,
    evaluate,
    ground_truth_from_sequence,
    ground_truth_positions,
    ground_truth_tolerance,
    image_paths,
    margins,
    quantile_transfer,
    ranked_correlation,
    schubert_threshold,
    sequence_match,
    set_threads,
    utm_positions,
)

__all__ = [
    "Calibration",
    "Descriptors",
    "Online",
    "OnlineDecision",
    "OnlineDecisions",
    "SelfMotionLabels",
    "TransferResult",
    "__version__",
    "ablation",
    "best_threshold",
    "counts",
    "evaluate",
    "margins",
    "quantile_transfer",
    "ranked_correlation",
    # Extensions
    "cosine_similarity",
    "ground_truth_from_sequence",
    "ground_truth_positions",
    "ground_truth_tolerance",
    "image_paths",
    "sequence_match",
    "schubert_threshold",
    "set_threads",
    "utm_positions",
]

if TYPE_CHECKING:
    from qtvpr import reference as reference


def __getattr__(name: str) -> Any:
    # `qtvpr.reference` is imported on first access rather than with `qtvpr`: it imports
    # NumPy at once, which took `import qtvpr` from about 20 ms to about 230 ms here
    # (the compiled module loads NumPy only when it first converts an array).
    if name == "reference":
        return importlib.import_module("qtvpr.reference")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), "reference"])
