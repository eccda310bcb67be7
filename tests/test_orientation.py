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
    with pytest.warns(UserWarning, match="the layout is contradicted by the ground truth: 9 of the 111 queries "
                                         "have no positive") as record:
        out = qtvpr.evaluate(S.T, GT.T, methods=METHODS)
    assert str(record[0].message).endswith(
        "the matrices may be query-major (|Q| x |DB|, as VPR-Bench stores them); if so, pass query_major=True"
    )
    assert out["orientation"] == {
        "db": 100, "queries": 111, "query_major": False,
        "layout": "contradicted by the ground truth (queries without a positive: 9 of 111, while every database "
                  "image has one)",
        "evidence": {"labelled_queries": 111, "queries_without_positive": 9, "db_without_positive": 0,
                     "verdict": "contradicts"},
    }
    assert out["orientation"] == qtvpr.reference.orientation((100, 111), GT.T, False)


def test_the_right_layout_is_not_warned_about() -> None:
    consistent = {"labelled_queries": 100, "queries_without_positive": 0, "db_without_positive": 9,
                  "verdict": "consistent"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        as_is = qtvpr.evaluate(S, GT, methods=METHODS)
        transposed = qtvpr.evaluate(S.T, GT.T, methods=METHODS, query_major=True)
    confirmed = "confirmed by the ground truth (every query has a positive; database images without one: 9 of 111)"
    assert as_is["orientation"] == {"db": 111, "queries": 100, "query_major": False, "layout": confirmed,
                                    "evidence": consistent}
    assert transposed["orientation"] == {"db": 111, "queries": 100, "query_major": True, "layout": confirmed,
                                         "evidence": consistent}
    assert transposed["methods"] == as_is["methods"]


def test_a_layout_the_ground_truth_cannot_tell_is_said_to_be_assumed() -> None:
    # A square traverse with symmetric ground truth (query j matches database image j):
    # the matrix and its transpose are both valid, nothing tells them apart, and the
    # results differ; so the layout is "assumed", the same words either way round.
    n = 12
    rng = np.random.default_rng(7)
    s = rng.random((n, n)) + 2 * np.eye(n)
    gt = np.eye(n, dtype=bool)
    assumed = "assumed (the ground truth cannot tell: every query and every database image has a positive)"
    for impl in (qtvpr, qtvpr.reference):
        for query_major in (False, True):
            out = impl.evaluate(s, gt, methods=METHODS, cal_queries=3, segment_size=3, query_major=query_major)
            assert out["orientation"]["layout"] == assumed, (impl, query_major)
            assert out["orientation"]["evidence"]["verdict"] == "cannot-tell"


def test_errors_of_a_layout_that_fits_only_the_other_way_round() -> None:
    with pytest.raises(ValueError, match=r"the ground truth is the similarity's transpose .* query_major=True reads"):
        qtvpr.evaluate(S.T, GT, methods=METHODS)
    with pytest.raises(ValueError, match=r"got 105; the similarity has 111 database images but only 100 queries: "
                                         r"if it is query-major .*, pass query_major=True$"):
        qtvpr.evaluate(S, GT, methods=METHODS, cal_queries=105)
