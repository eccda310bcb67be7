"""The evaluation protocol (semantics §7 and §8): the wheel's ``qtvpr.evaluate`` and
``qtvpr-cli evaluate --format json`` equal ``qtvpr.reference.evaluate``.

On the real VPR-Bench matrices in ../shared/data: every method, both matching modes,
precision targets 1.0 and 0.9, soft ground truth, query-major input, and the
fixed-deployment protocol of the calibration-size ablation. Then hypothesis parity on
small random matrices, and the bad inputs both implementations must refuse alike.
"""

from __future__ import annotations

import functools
import inspect
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import qtvpr
from qtvpr import reference as ref
from shared_data import TECHNIQUES, vprbench
from test_cli import run_cli

SEGMENT_KEYS = ["start", "end", "threshold", "oracle_threshold", "tp", "fp", "accepted", "positives",
                "precision", "recall", "precision_lower95", "meets"]
METHOD_KEYS = ["pct_segs", "avg_recall", "segments_counted", "segments_skipped", "threshold_mse",
               "pooled_tp", "pooled_fp", "pooled_accepted", "pooled_positives", "pooled_precision",
               "pooled_recall", "pooled_precision_lower95", "segments"]
RUN_KEYS = ["params", "recall_at_1", "methods"]
#: The methods of a gate alone, whose threshold is -inf (null in JSON, as reject-all's
#: inf is).
GATE_ALONE = {("margin", "threshold"), ("sequence", "threshold")}
#: Semantics §14's signals: a run's last key, in single matching only.
SIGNALS = {"score": ["auroc"], "margin": ["auroc"], "pa_score": ["auroc"], "consistency": ["auroc"],
           "confidence": ["auroc", "brier", "ece", "bins"]}


def run_of(d: dict) -> dict:
    """The run's keys of an evaluate() dict, the confidence's where there is one."""
    return {k: d[k] for k in [*RUN_KEYS, "confidence"] if k in d}


#: The real matrices, read once per worker.
load = functools.cache(vprbench)


def soft_of(gt: np.ndarray) -> np.ndarray:
    """Every hard match widened by one database image either side."""
    soft = gt.copy()
    soft[1:] |= gt[:-1]
    soft[:-1] |= gt[1:]
    return soft


def same_figure(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return abs(a - b) <= 1e-9


def same_bins(a, b) -> bool:
    """Reliability bins: the same bins and counts, their means to 1e-9."""
    if a is None or b is None:
        return a is None and b is None
    return [(x["lower"], x["upper"], x["n"]) for x in a] == [(x["lower"], x["upper"], x["n"]) for x in b] and all(
        same_figure(x[k], y[k]) for x, y in zip(a, b, strict=True) for k in ("mean_confidence", "hit_rate")
    )


def key_tree(value):
    """The keys of ``value``, recursively and in order (a list by its elements)."""
    if isinstance(value, dict):
        return [(k, key_tree(v)) for k, v in value.items()]
    if isinstance(value, list):
        return [key_tree(v) for v in value]
    return None


def assert_same_run(got: dict, want: dict) -> None:
    """One run: the same keys in the same order; parameters and counts exactly,
    thresholds and figures to 1e-9."""
    assert list(got) == [*RUN_KEYS, *(["confidence"] if "confidence" in want else [])]
    assert key_tree(got) == key_tree(want)
    if "confidence" in want:
        signals = want["confidence"]["signals"]
        assert {k: list(v) for k, v in signals.items()} == SIGNALS
        for signal, keys in SIGNALS.items():
            for key in keys:
                g, w = got["confidence"]["signals"][signal][key], signals[signal][key]
                assert (same_bins if key == "bins" else same_figure)(g, w), (signal, key, g, w)
    assert got["params"] == want["params"]
    assert same_figure(got["recall_at_1"], want["recall_at_1"])
    assert list(got["methods"]) == list(want["methods"])
    for name, w in want["methods"].items():
        g = got["methods"][name]
        assert list(g) == METHOD_KEYS, name
        for key in ("segments_counted", "segments_skipped", "pooled_tp", "pooled_fp", "pooled_accepted",
                    "pooled_positives"):
            assert g[key] == w[key], (name, key, g[key], w[key])
        for key in ("pct_segs", "avg_recall", "threshold_mse", "pooled_precision", "pooled_recall",
                    "pooled_precision_lower95"):
            assert same_figure(g[key], w[key]), (name, key, g[key], w[key])
        assert len(g["segments"]) == len(w["segments"]), name
        for gs, ws in zip(g["segments"], w["segments"], strict=True):
            # The gated methods' segments also have their gates' levels (semantics §13, §15).
            levels = (["gate"] if name in ref.MARGIN_GATED else []) + (
                ["consistency_level"] if name in ref.SEQUENCE_GATED else [])
            keys = SEGMENT_KEYS[:4] + levels + SEGMENT_KEYS[4:]
            assert list(gs) == keys, name
            for key in ("start", "end", "tp", "fp", "accepted", "positives", "meets"):
                assert gs[key] == ws[key], (name, key, gs, ws)
            for key in ("threshold", "oracle_threshold", "recall"):
                a, b = gs[key], ws[key]
                assert (math.isinf(a) and a == b) or abs(a - b) <= 1e-9, (name, key, gs, ws)
            for key in ("precision", "precision_lower95"):  # None where nothing is accepted
                assert same_figure(gs[key], ws[key]), (name, key, gs, ws)


def same_layout(got: dict, want: dict) -> bool:
    """The same ``orientation`` record, whether or not it was read query-major (which
    the callers compare themselves)."""
    return {**got, "query_major": None} == {**want, "query_major": None}


def assert_same_evaluation(got: dict, want: dict) -> None:
    """``evaluate``'s dicts: ``dataset`` (whatever its value) and one run."""
    assert list(got) == ["dataset", "orientation", *run_of(want)]
    assert same_layout(got["orientation"], want["orientation"])
    assert_same_run(run_of(got), run_of(want))


def assert_same_ablation(got: dict, want: dict) -> None:
    assert list(got) == ["dataset", "orientation", "ablation"]
    assert same_layout(got["orientation"], want["orientation"])
    assert len(got["ablation"]) == len(want["ablation"])
    for g, w in zip(got["ablation"], want["ablation"], strict=True):
        assert_same_run(g, w)


@functools.cache
def expected(root: Path, dataset: str, technique: str, matching: str, precision: float):
    s, gt = load(root, dataset, technique)
    return ref.evaluate(s, gt, matching=matching, precision=precision)


# ---------------------------------------------------------------------------------------
# Wheel vs reference on real data
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("technique", TECHNIQUES)
@pytest.mark.parametrize("matching", ["single", "multi"])
@pytest.mark.parametrize("precision", [1.0, 0.9])
def test_corridor_every_method(shared_data, technique, matching, precision):
    s, gt = load(shared_data, "vprbench-corridor", technique)
    got = qtvpr.evaluate(s, gt, matching=matching, precision=precision)
    assert_same_evaluation(got, expected(shared_data, "vprbench-corridor", technique, matching, precision))


@pytest.mark.parametrize("technique", TECHNIQUES)
@pytest.mark.parametrize("matching", ["single", "multi"])
def test_spedtest_every_method(shared_data, technique, matching):
    # tau = 0.9 on three of them keeps the run short; the sweep differs from tau = 1.
    for precision in (1.0, 0.9) if technique in ("CoHOG", "NetVLAD", "HOG") else (1.0,):
        s, gt = load(shared_data, "vprbench-spedtest", technique)
        got = qtvpr.evaluate(s, gt, matching=matching, precision=precision)
        assert_same_evaluation(got, expected(shared_data, "vprbench-spedtest", technique, matching, precision))


@pytest.mark.parametrize("technique", ["AMOSNet", "CoHOG", "NetVLAD"])
@pytest.mark.parametrize("matching", ["single", "multi"])
def test_soft_ground_truth_and_query_major(shared_data, technique, matching):
    s, gt = load(shared_data, "vprbench-corridor", technique)
    soft = soft_of(gt)
    kwargs = dict(matching=matching, precision=0.9, k=5, segment_size=4)
    want = ref.evaluate(s, gt, gt_soft=soft, **kwargs)
    assert_same_evaluation(qtvpr.evaluate(s, gt, gt_soft=soft, **kwargs), want)
    # VPR-Bench's own layout, |Q| x |DB|, in Fortran order and with integer labels.
    got = qtvpr.evaluate(np.asfortranarray(s.T), gt.T.astype(np.uint8), gt_soft=soft.T,
                         query_major=True, **kwargs)
    assert_same_evaluation(got, want)
    assert got["orientation"]["query_major"] and not want["orientation"]["query_major"]
    assert_same_evaluation(
        ref.evaluate(s.T, gt.T, gt_soft=soft.T, query_major=True, **kwargs), want)


@pytest.mark.parametrize("cal_fraction", [0.01, 0.05, 0.2, 0.5])
def test_fixed_deployment_protocol(shared_data, cal_fraction):
    """The calibration-size ablation: the last 50% deploy whatever the calibration size."""
    s, gt = load(shared_data, "vprbench-spedtest", "NetVLAD")
    kwargs = dict(cal_fraction=cal_fraction, deploy_fraction=0.5)
    want = ref.evaluate(s, gt, **kwargs)
    got = qtvpr.evaluate(s, gt, **kwargs)
    assert_same_evaluation(got, want)
    # 607 queries: the last floor(303.5) = 303 deploy, in floor(303 / 7) = 43 segments of 7.
    assert [(r["start"], r["end"]) for r in got["methods"]["oracle"]["segments"]][-1] == (294, 301)
    # The oracle and per-segment Schubert depend on the deployment set only.
    base = qtvpr.evaluate(s, gt, cal_fraction=0.1, deploy_fraction=0.5, methods=["oracle", "schubert"])
    for name in ("oracle", "schubert"):
        assert got["methods"][name] == base["methods"][name]


def test_methods_subset_and_order(shared_data):
    s, gt = load(shared_data, "vprbench-corridor", "HOG")
    methods = ["oracle", "schubert", "quantile-transfer"]
    got = qtvpr.evaluate(s, gt, methods=methods, cal_queries=20, segment_fraction=0.05)
    assert list(got["methods"]) == methods
    assert_same_evaluation(got, ref.evaluate(s, gt, methods=methods, cal_queries=20, segment_fraction=0.05))


def test_schubert_threshold(shared_data):
    for technique in ("CoHOG", "HOG"):  # float32 and float64
        s, _ = load(shared_data, "vprbench-spedtest", technique)
        assert abs(qtvpr.schubert_threshold(s) - ref.schubert_threshold(s)) <= 1e-12
        assert qtvpr.schubert_threshold(s.T) == qtvpr.schubert_threshold(s)


# ---------------------------------------------------------------------------------------
# CLI vs reference
# ---------------------------------------------------------------------------------------


def from_json(out: dict) -> dict:
    """The CLI's JSON (an evaluation, an ablation or one run of it) in Python's form:
    null thresholds are reject-all, inf, except the margin method's, which is always
    -inf (semantics §13), and null gates are reject-all too. Every key is kept."""
    if "ablation" in out:
        return {**out, "ablation": [from_json(run) for run in out["ablation"]]}
    methods = {}
    for name, m in out["methods"].items():
        segments = []
        for seg in m["segments"]:
            seg = dict(seg)
            for key in ("threshold", "oracle_threshold", "gate"):
                if key in seg and seg[key] is None:
                    seg[key] = -math.inf if (name, key) in GATE_ALONE else math.inf
            segments.append(seg)
        methods[name] = {**m, "segments": segments}
    return {**out, "methods": methods}


@pytest.mark.parametrize(
    ("dataset", "technique", "matching", "precision"),
    [
        ("vprbench-corridor", "AMOSNet", "single", 1.0),
        ("vprbench-corridor", "CoHOG", "multi", 0.9),
        ("vprbench-spedtest", "NetVLAD", "single", 0.9),
        ("vprbench-spedtest", "HOG", "multi", 1.0),
    ],
)
def test_cli_json_equals_reference(cli, shared_data, dataset, technique, matching, precision):
    d = shared_data / dataset
    # Every method the reference knows that applies (the CLI's `all` may know more).
    methods = [m for m in ref.METHODS if matching == "single" or m not in ref.GATED]
    res = run_cli(cli, "evaluate", "--format", "json", "--similarity", d / f"S_{technique}.npy", "--gt", d / "GT.npy",
                  "--matching", matching, "--precision", precision, "--method", ",".join(methods))
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    n_q = load(shared_data, dataset, technique)[0].shape[1]
    assert out["params"]["calibration_queries"] == n_q // 10
    assert out["params"]["segment_size"] == math.ceil(0.01 * n_q)
    assert_same_evaluation(from_json(out), expected(shared_data, dataset, technique, matching, precision))


def test_cli_query_major_soft_ground_truth_and_protocol_options(cli, shared_data, tmp_path):
    s, gt = load(shared_data, "vprbench-corridor", "NetVLAD")
    soft = soft_of(gt)
    for name, a in {"S": s.T, "GT": gt.T, "soft": soft.T}.items():
        np.save(tmp_path / f"{name}.npy", a)
    res = run_cli(cli, "evaluate", "--format", "json", "--query-major", "--similarity", tmp_path / "S.npy",
                  "--gt", tmp_path / "GT.npy", "--gt-soft", tmp_path / "soft.npy",
                  "--cal-queries", 30, "--segment-size", 5, "--k", 3,
                  "--method", "quantile-transfer,oracle,schubert-calibrated")
    assert res.returncode == 0, res.stderr
    want = ref.evaluate(s, gt, gt_soft=soft, cal_queries=30, segment_size=5, k=3,
                        methods=["quantile-transfer", "oracle", "schubert-calibrated"])
    assert_same_evaluation(from_json(json.loads(res.stdout)), want)


def test_cli_ablation_rows_equal_reference(cli, shared_data):
    d = shared_data / "vprbench-corridor"
    res = run_cli(cli, "evaluate", "--format", "json", "--similarity", d / "S_HOG.npy", "--gt", d / "GT.npy",
                  "--cal-fraction", "0.05,0.3", "--method", "quantile-transfer,calibration-threshold")
    assert res.returncode == 0, res.stderr
    runs = json.loads(res.stdout)["ablation"]
    s, gt = load(shared_data, "vprbench-corridor", "HOG")
    for run, f in zip(runs, (0.05, 0.3), strict=True):
        # 111 queries: the first floor(f x 111) calibrate, the last floor(55.5) = 55 deploy.
        assert run["params"]["calibration_queries"] == math.floor(f * 111)
        assert run["params"]["deployment_start"] == 111 - 55
        want = ref.evaluate(s, gt, cal_fraction=f, deploy_fraction=0.5,
                            methods=["quantile-transfer", "calibration-threshold"])
        assert_same_run(from_json(run), run_of(want))


# ---------------------------------------------------------------------------------------
# One schema: the CLI's JSON and the wheel's dicts have the same keys
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("flags", "kwargs"),
    [
        ([], {}),
        (["--matching", "multi", "--precision", "0.9", "--method", "oracle,schubert"],
         dict(matching="multi", precision=0.9, methods=["oracle", "schubert"])),
    ],
)
def test_cli_json_and_python_dict_have_the_same_keys(cli, shared_data, flags, kwargs):
    d = shared_data / "vprbench-corridor"
    s, gt = d / "S_CoHOG.npy", d / "GT.npy"
    res = run_cli(cli, "evaluate", "--format", "json", "--similarity", s, "--gt", gt, *flags)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    # Paths in, so that even `dataset` is the same.
    got = qtvpr.evaluate(str(s), str(gt), **kwargs)
    assert key_tree(out) == key_tree(got)
    assert out["dataset"] == got["dataset"] == str(s)
    assert from_json(out) == got
    # The reference has the same keys too; from arrays, dataset is None.
    want = ref.evaluate(*load(shared_data, "vprbench-corridor", "CoHOG"), **kwargs)
    assert key_tree(want) == key_tree(got)
    assert qtvpr.evaluate(*load(shared_data, "vprbench-corridor", "CoHOG"), **kwargs)["dataset"] is None


def test_cli_ablation_json_and_python_dict_have_the_same_keys(cli, shared_data):
    d = shared_data / "vprbench-corridor"
    s, gt = d / "S_NetVLAD.npy", d / "GT.npy"
    res = run_cli(cli, "evaluate", "--format", "json", "--similarity", s, "--gt", gt,
                  "--k", "1,3", "--cal-fraction", "0.05,0.2")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    got = qtvpr.ablation(str(s), str(gt), k=[1, 3], cal_fraction=[0.05, 0.2])
    assert list(got) == ["dataset", "orientation", "ablation"]
    assert key_tree(out) == key_tree(got)
    assert from_json(out) == got
    want = ref.ablation(*load(shared_data, "vprbench-corridor", "NetVLAD"), k=[1, 3], cal_fraction=[0.05, 0.2])
    assert key_tree(want) == key_tree(got)


# ---------------------------------------------------------------------------------------
# Ablations (the paper's Fig. 5)
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("technique", ["NetVLAD", "CoHOG"])
def test_ablation_over_k_and_calibration_size_equals_reference(shared_data, technique):
    s, gt = load(shared_data, "vprbench-spedtest", technique)
    ks, fractions = [1, 10, 40], [0.01, 0.3]
    kwargs = dict(k=ks, cal_fraction=fractions, methods=["quantile-transfer", "calibration-threshold", "oracle"])
    got = qtvpr.ablation(s, gt, **kwargs)
    assert_same_ablation(got, ref.ablation(s, gt, **kwargs))
    # Calibration sizes outer, k inner; 607 queries: floor(f x 607) calibrate and the
    # last floor(303.5) = 303 deploy in every run.
    runs = got["ablation"]
    assert [(r["params"]["calibration"]["fraction"], r["params"]["k"]) for r in runs] == [
        (f, k) for f in fractions for k in ks]
    assert [r["params"]["calibration_queries"] for r in runs[::3]] == [6, 182]
    assert {(r["params"]["deployment_start"], r["params"]["deploy_fraction"]) for r in runs} == {(304, 0.5)}
    # Each run is evaluate() with that setting on the last half.
    one = qtvpr.evaluate(s, gt, k=10, cal_fraction=0.3, deploy_fraction=0.5, methods=kwargs["methods"])
    assert run_of(one) == runs[4]
    # The oracle depends on the deployment set only.
    assert all(r["methods"]["oracle"] == runs[0]["methods"]["oracle"] for r in runs)


def test_fig5_series_from_python(shared_data):
    """What a user plots for Fig. 5: %Segs and AvgR of each method against k."""
    s, gt = load(shared_data, "vprbench-corridor", "AMOSNet")
    ks = [1, 3, 5, 10, 20, 40]
    runs = qtvpr.ablation(s, gt, k=ks)["ablation"]
    series = {(r["params"]["k"], name): (m["pct_segs"], m["avg_recall"])
              for r in runs for name, m in r["methods"].items()}
    assert sorted({k for k, _ in series}) == ks
    # Only quantile transfer depends on k.
    for name in ("schubert", "schubert-calibrated", "calibration-threshold", "oracle"):
        assert len({series[(k, name)] for k in ks}) == 1, name
    # The default deployment set is the last half: floor(55.5) = 55 of 111 queries.
    assert runs[0]["params"]["deployment_start"] == 56
    # A given deploy fraction is kept.
    assert qtvpr.ablation(s, gt, k=[1, 2], deploy_fraction=0.6)["ablation"][1]["params"]["deployment_start"] == 45


def test_cli_embedded_data_matches_the_reference(cli):
    """The README's main command runs the reference protocol on data/corridor."""
    res = run_cli(cli, "evaluate", "--format", "json", "--method", ",".join(ref.METHODS))
    assert res.returncode == 0, res.stderr
    data = Path(__file__).resolve().parents[1] / "data" / "corridor"
    s = np.concatenate([np.load(data / "cal_S.npy"), np.load(data / "deploy_S.npy")], axis=1)
    gt = np.concatenate([np.load(data / "cal_GT.npy"), np.load(data / "deploy_GT.npy")], axis=1)
    got, want = from_json(json.loads(res.stdout)), ref.evaluate(s, gt)
    # The embedded data has but one layout: no orientation is reported.
    assert list(got) == ["dataset", *run_of(want)]
    assert_same_run(run_of(got), run_of(want))


# ---------------------------------------------------------------------------------------
# Property tests on small random matrices
# ---------------------------------------------------------------------------------------

LEVELS = [-1.0, 0.0, 0.25, 0.5, 0.75, 1.0, 2.0]


@st.composite
def evaluate_cases(draw):
    n_db = draw(st.integers(1, 8))
    n_q = draw(st.integers(2, 14))
    dtype = draw(st.sampled_from([np.float32, np.float64]))
    levels = draw(st.lists(st.sampled_from(LEVELS), min_size=1, max_size=4, unique=True))
    s = np.array(draw(st.lists(st.sampled_from(levels), min_size=n_db * n_q, max_size=n_db * n_q)),
                 dtype=dtype).reshape(n_db, n_q)
    p = draw(st.sampled_from([0.2, 0.5]))
    bits = draw(st.lists(st.floats(0, 1), min_size=n_db * n_q, max_size=n_db * n_q))
    gt = (np.array(bits) < p).reshape(n_db, n_q)
    soft = gt | (np.roll(np.array(bits), 1).reshape(n_db, n_q) < 0.3) if draw(st.booleans()) else None
    n_cal = draw(st.integers(1, n_q - 1))
    kwargs = dict(
        gt_soft=soft,
        methods=draw(st.none() | st.lists(st.sampled_from(ref.METHODS), min_size=1, max_size=5)),
        k=draw(st.integers(1, 6)),
        precision=draw(st.sampled_from([1.0, 0.9, 0.5])),
        matching=draw(st.sampled_from(["single", "multi"])),
        cal_queries=n_cal,
        segment_size=draw(st.integers(1, n_q - n_cal)),
    )
    if draw(st.booleans()):
        kwargs["query_major"] = True
        s, gt = s.T.copy(), gt.T.copy()
        kwargs["gt_soft"] = None if soft is None else soft.T.copy()
    return s, gt, kwargs


@settings(max_examples=250, deadline=None, derandomize=True)
@given(evaluate_cases())
@pytest.mark.filterwarnings("ignore:.*queries have no positive:UserWarning")  # random ground truth
def test_random_matrices_equal_reference(case):
    s, gt, kwargs = case
    single = kwargs["matching"] == "single"
    methods = kwargs["methods"]
    # All methods leave out the gated ones in multi matching, the sequence gate's on a
    # database too small for its +-3 rows (semantics §15).
    margin = set(ref.MARGIN_GATED) & set(methods or (ref.MARGIN_GATED if single else []))
    sequence = set(ref.SEQUENCE_GATED) & set(methods or [])
    n_db = s.shape[1] if kwargs.get("query_major") else s.shape[0]
    whys = []
    if (margin or sequence) and not single:
        whys.append("needs single matching")
    if margin and single and n_db < 2:
        # The margin gate needs a second-best score.
        whys.append("needs at least 2 database images")
    if sequence and single and n_db < 8:
        whys.append("cannot tell a line from chance")
    if whys:
        # Both refuse it, with one message (the first gate checked's).
        for evaluate in (ref.evaluate, qtvpr.evaluate):
            with pytest.raises(ValueError, match="|".join(whys)):
                evaluate(s, gt, **kwargs)
        return
    want = ref.evaluate(s, gt, **kwargs)
    assert_same_evaluation(qtvpr.evaluate(s, gt, **kwargs), want)


# ---------------------------------------------------------------------------------------
# API and bad input
# ---------------------------------------------------------------------------------------


def test_signature_matches_reference():
    for name in ("evaluate", "ablation", "schubert_threshold"):
        assert inspect.signature(getattr(qtvpr, name)) == inspect.signature(getattr(ref, name)).replace(
            return_annotation=inspect.Signature.empty
        )
    assert qtvpr.evaluate.__doc__ and "pct_segs" in qtvpr.evaluate.__doc__
    assert qtvpr.ablation.__doc__ and "Fig. 5" in qtvpr.ablation.__doc__


S7 = np.array([
    [0.9, 0.2, 0.7, 0.1, 0.5, 0.2, 0.3],
    [0.1, 0.95, 0.3, 0.6, 0.4, 0.9, 0.3],
    [0.3, 0.4, 0.2, 0.5, 0.3, 0.1, 0.3],
])
G7 = np.zeros((3, 7), bool)
G7[0, 0] = G7[2, 1] = G7[0, 2] = G7[2, 3] = True


@pytest.mark.parametrize(
    ("kwargs", "exc", "match"),
    [
        (dict(methods=["magic"]), ValueError, "unknown method 'magic'"),
        (dict(cal_queries=7), ValueError, "calibration set must have between 1 and 6"),
        (dict(cal_queries=0), ValueError, "cal_queries must be >= 1"),
        (dict(), ValueError, "calibration set"),  # floor(0.1 x 7) = 0
        (dict(cal_fraction=1.5), ValueError, "cal_fraction must be in"),
        (dict(cal_queries=2, segment_size=6), ValueError, "segment size 6 is larger than the 5"),
        (dict(cal_queries=2, segment_size=0), ValueError, "segment_size must be >= 1"),
        (dict(cal_queries=2, segment_fraction=0.0), ValueError, "segment_fraction must be in"),
        (dict(cal_queries=2, deploy_fraction=1.0), ValueError, "deploy_fraction must be in"),
        (dict(cal_queries=5, deploy_fraction=0.5), ValueError, "overlap"),  # 5 + floor(3.5) > 7
        (dict(cal_queries=2, deploy_fraction=0.1), ValueError, "deployment set has no query"),
        (dict(cal_queries=2, k=0), ValueError, "k must be >= 1"),
        (dict(cal_queries=2, precision=0.0), ValueError, "precision must be in"),
        (dict(cal_queries=2, matching="best"), ValueError, "matching must be"),
        (dict(cal_queries=2, gt=G7[:, :6]), ValueError, "gt.* shape 3x6 does not match .*shape 3x7"),
        (dict(cal_queries=2, s=S7.astype(np.int32)), TypeError, "s must be"),
        (dict(cal_queries=2, gt=G7.astype(float)), TypeError, "gt must be"),
        (dict(cal_queries=2, s=np.where(S7 > 0.8, np.nan, S7)), ValueError, "NaN"),
    ],
)
@pytest.mark.parametrize("impl", [qtvpr, ref], ids=["wheel", "reference"])
def test_bad_input(impl, kwargs, exc, match):
    kwargs = dict(s=S7, gt=G7) | kwargs
    with pytest.raises(exc, match=match):
        impl.evaluate(kwargs.pop("s"), kwargs.pop("gt"), **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "exc", "match"),
    [
        (dict(k=[]), ValueError, "k must have at least one value"),
        (dict(cal_queries=[]), ValueError, "cal_queries must have at least one value"),
        (dict(k=[1, 0], cal_queries=1), ValueError, "k must be >= 1"),
        (dict(cal_queries=[1, 0]), ValueError, "cal_queries must be >= 1"),
        # The last floor(3.5) = 3 deploy: 1 + 3 fits, 5 + 3 overlaps; checked before any run.
        (dict(cal_queries=[1, 5]), ValueError, "overlap"),
        (dict(cal_fraction=[0.2, 1.5]), ValueError, "cal_fraction must be in"),
        (dict(cal_queries=1, deploy_fraction=1.0), ValueError, "deploy_fraction must be in"),
        (dict(cal_queries=1, methods=["magic"]), ValueError, "unknown method 'magic'"),
    ],
)
@pytest.mark.parametrize("impl", [qtvpr, ref], ids=["wheel", "reference"])
def test_bad_ablation_input(impl, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        impl.ablation(S7, G7, segment_size=1, **kwargs)


def test_ablation_of_the_tiny_case_by_hand():
    # |Q| = 7, calibration c0 (1 query), the last floor(3.5) = 3 deploy (d2, d3, d4 in
    # segments of 1). Best matches: d2 0.5 (db0, no match), d3 0.9 (db1), d4 0.3 (db0,
    # first maximum): no deployment query has a hard match -> every segment skipped,
    # figures None, R@1 None.
    for impl in (qtvpr, ref):
        out = impl.ablation(S7, G7, cal_queries=1, k=[1, 2], segment_size=1, methods=["oracle"])
        assert [r["params"]["k"] for r in out["ablation"]] == [1, 2]
        for r in out["ablation"]:
            assert (r["params"]["deployment_start"], r["params"]["segments"]) == (4, 3)
            assert r["recall_at_1"] is None
            o = r["methods"]["oracle"]
            assert (o["segments_counted"], o["segments_skipped"], o["pct_segs"]) == (0, 3, None)
            # Reject-all everywhere: nothing accepted, no precision, no bound.
            assert (o["pooled_tp"], o["pooled_fp"], o["pooled_accepted"]) == (0, 0, 0)
            assert (o["pooled_precision"], o["pooled_precision_lower95"]) == (None, None)
