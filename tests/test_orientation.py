"""Orientation (semantics §1): what ``qtvpr.evaluate`` assumed of a matrix's layout, and
the core's warning when the ground truth contradicts it, on the embedded Corridor
deployment traverse (111 database images x 100 queries) and its transpose."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import qtvpr

DATA = Path(__file__).resolve().parents[1] / "data" / "corridor"
S, GT = np.load(DATA / "deploy_S.npy"), np.load(DATA / "deploy_GT.npy")
METHODS = ["oracle"]


def test_a_transposed_pair_read_as_is_is_warned_about() -> None:
    # Read as is, the transposed pair is 100 "database images" (the queries, each with a
    # positive) x 111 "queries", 9 of which (database images 0..8) have none.
    with pytest.warns(UserWarning, match="9 of the 111 queries have no positive") as record:
        out = qtvpr.evaluate(S.T, GT.T, methods=METHODS)
    assert str(record[0].message).endswith(
        "the matrices may be query-major (|Q| x |DB|, as VPR-Bench stores them); if so, pass query_major=True"
    )
    assert out["orientation"] == {
        "db": 100, "queries": 111, "query_major": False,
        "evidence": {"labelled_queries": 111, "queries_without_positive": 9, "db_without_positive": 0,
                     "verdict": "contradicts"},
    }


def test_the_right_layout_is_not_warned_about() -> None:
    consistent = {"labelled_queries": 100, "queries_without_positive": 0, "db_without_positive": 9,
                  "verdict": "consistent"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        as_is = qtvpr.evaluate(S, GT, methods=METHODS)
        transposed = qtvpr.evaluate(S.T, GT.T, methods=METHODS, query_major=True)
    assert as_is["orientation"] == {"db": 111, "queries": 100, "query_major": False, "evidence": consistent}
    assert transposed["orientation"] == {"db": 111, "queries": 100, "query_major": True, "evidence": consistent}
    assert transposed["methods"] == as_is["methods"]


def test_errors_of_a_layout_that_fits_only_the_other_way_round() -> None:
    with pytest.raises(ValueError, match=r"the ground truth is the similarity's transpose .* query_major=True reads"):
        qtvpr.evaluate(S.T, GT, methods=METHODS)
    with pytest.raises(ValueError, match=r"got 105; the similarity has 111 database images but only 100 queries: "
                                         r"if it is query-major .*, pass query_major=True$"):
        qtvpr.evaluate(S, GT, methods=METHODS, cal_queries=105)
