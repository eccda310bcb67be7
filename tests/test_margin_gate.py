"""The margin gate (semantics §13) in Python: the wheel against the NumPy reference on
the real VPR-Bench matrices (margins, m*, the batch and online transfer, the protocol's
two gated methods), against the CLI and Dask on one calibration file, and its errors.

The same scenarios are tested in Rust (crates/qtvpr/tests/margin_gate.rs,
crates/qtvpr-cli/tests/online.rs) and in C (scripts/capi.sh).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import qtvpr
from qtvpr import reference as ref
from test_cli import run_cli

DATASETS = {"corridor": "vprbench-corridor", "spedtest": "vprbench-spedtest"}
TECHNIQUES = ["AlexNet_VPR", "CALC", "HOG", "NetVLAD", "denseVLAD"]
MULTI_WHY = "gate margin needs single matching"


def load(shared_data, dataset: str, technique: str):
    d = shared_data / DATASETS[dataset]
    return np.load(d / f"S_{technique}.npy"), np.load(d / "GT.npy")


def close(a, b, tol=1e-9):
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    assert a.shape == b.shape
    assert np.allclose(a, b, rtol=tol, atol=tol, equal_nan=True), np.max(np.abs(a - b))


# ---------------------------------------------------------------------------------------
# By hand
# ---------------------------------------------------------------------------------------


def test_margins_by_hand():
    # Column 0: mean 2, population variance 1.5, s1 - s2 = 2. Column 1: the largest
    # twice. Column 2: constant. Column 3: shifted and scaled column 0.
    s = np.array([[4.0, 3.0, 0.5, 9.0], [2.0, 1.0, 0.5, 5.0], [1.0, 3.0, 0.5, 3.0], [1.0, 0.0, 0.5, 3.0]])
    want = [2.0 / math.sqrt(1.5), 0.0, 0.0, 2.0 / math.sqrt(1.5)]
    close(qtvpr.margins(s), want, 1e-15)
    close(ref.margins(s), want, 1e-15)
    close(qtvpr.margins(s.T.copy(), query_major=True), want, 1e-15)


def test_gate_by_hand():
    # Four calibration queries: best matches with margins 2.31 (correct), 1.62 (wrong),
    # 1.22 (correct); the fourth's best match is soft-only, left out.
    s = np.array([[0.9, 0.5, 0.6, 0.8], [0.1, 0.1, 0.5, 0.1], [0.1, 0.2, 0.4, 0.3]])
    gt = np.array([[1, 0, 1, 0], [0, 1, 0, 1], [0, 0, 0, 0]], dtype=bool)
    soft = gt.copy()
    soft[0, 3] = True
    m = ref.margins(s)
    for cal in (qtvpr.Calibration(s, gt, gt_soft=soft), ref.Calibration(s, gt, gt_soft=soft)):
        assert cal.gate(1.0) == pytest.approx(m[0], rel=1e-15)  # only the highest is clean
        assert cal.gate(0.6) == pytest.approx(m[2], rel=1e-15)  # 2 of 3 accepted correct
        assert cal.defaults["gate"] == "none"


def test_a_gated_decision_shows_its_margin_and_gate():
    s = np.array([[0.9, 0.5, 0.6, 0.8], [0.1, 0.1, 0.5, 0.1], [0.1, 0.2, 0.4, 0.3]])
    gt = np.array([[1, 0, 1, 0], [0, 1, 0, 1], [0, 0, 0, 0]], dtype=bool)
    cal = qtvpr.Calibration(s, gt)
    gated = qtvpr.Online(cal, window=2, gate="margin").push(s[:, 0])
    m = ref.margins(s)
    assert (gated.margin, gated.gate) == (pytest.approx(m[0], rel=1e-15), pytest.approx(cal.gate(1.0), rel=1e-15))
    assert f", accepted={gated.accepted}, margin={gated.margin!r}, gate={gated.gate!r}, accept=" in repr(gated)
    plain = qtvpr.Online(cal, window=2).push(s[:, 0])
    assert plain.margin is None and "margin=" not in repr(plain)


# ---------------------------------------------------------------------------------------
# The wheel against the reference on real data
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("technique", TECHNIQUES)
@pytest.mark.parametrize("dataset", DATASETS)
def test_wheel_equals_reference_on_real_data(shared_data, dataset, technique):
    s, gt = load(shared_data, dataset, technique)
    n_cal = s.shape[1] // 10
    s_cal, gt_cal, s_val = s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:]
    close(qtvpr.margins(s), ref.margins(s))
    cal, want_cal = qtvpr.Calibration(s_cal, gt_cal), ref.Calibration(s_cal, gt_cal)
    for tau in (1.0, 0.9):
        m_star = cal.gate(tau)
        assert m_star == pytest.approx(want_cal.gate(tau), rel=1e-9)
        # The batch transfer: thresholds unchanged, m* and every query's margin.
        got = cal.transfer(s_val, precision=tau, segment_size=10, gate="margin")
        want = want_cal.transfer(s_val, precision=tau, segment_size=10, gate="margin")
        plain = cal.transfer(s_val, precision=tau, segment_size=10)
        assert np.array_equal(got.thresholds, plain.thresholds)
        assert plain.gate is None and plain.query_margins is None
        assert got.gate == m_star
        close(got.query_margins, want.query_margins)
        close(got.thresholds, want.thresholds)
        # Online: the record gains margin and gate, and accept needs both conditions.
        d = qtvpr.Online(cal, precision=tau, window=7, gate="margin").push_many(s_val)
        w = ref.Online(want_cal, precision=tau, window=7, gate="margin").push_many(s_val)
        close(d.margins, w.margins)
        close(d.gates, w.gates)
        assert d.accept.tolist() == w.accept.tolist()
        assert np.array_equal(d.accept, (d.score >= d.thresholds) & (d.margins >= m_star))
        one = qtvpr.Online(cal, precision=tau, window=7, gate="margin").push(s_val[:, 0])
        assert (one.margin, one.gate) == (d.margins[0], m_star)
        ungated = qtvpr.Online(cal, precision=tau, window=7).push_many(s_val)
        assert ungated.margins is None and ungated.gates is None
        assert not (d.accept & ~ungated.accept).any()  # the gate only takes away


@pytest.mark.parametrize("technique", TECHNIQUES)
@pytest.mark.parametrize("dataset", DATASETS)
def test_evaluate_gated_methods_equal_the_reference(shared_data, dataset, technique):
    s, gt = load(shared_data, dataset, technique)
    methods = ["quantile-transfer", "quantile-transfer-margin", "margin"]
    got = qtvpr.evaluate(s, gt, methods=methods)
    want = ref.evaluate(s, gt, methods=methods)
    for name in methods:
        g, w = got["methods"][name], want["methods"][name]
        for key in ("pct_segs", "avg_recall", "pooled_tp", "pooled_fp", "segments_counted"):
            assert g[key] == pytest.approx(w[key], abs=1e-9), (name, key)
        assert g["threshold_mse"] == pytest.approx(w["threshold_mse"], abs=1e-9)
        for gs, ws in zip(g["segments"], w["segments"], strict=True):
            assert (gs["tp"], gs["fp"], gs["positives"]) == (ws["tp"], ws["fp"], ws["positives"])
            assert ("gate" in gs) == (name != "quantile-transfer")
            if "gate" in gs:
                assert gs["gate"] == pytest.approx(ws["gate"], rel=1e-9)
    assert got["methods"]["margin"]["threshold_mse"] is None
    assert all(g["threshold"] == -math.inf for g in got["methods"]["margin"]["segments"])
    # The default methods are every method that applies: the gated ones in single
    # matching, not in multi.
    assert "margin" in qtvpr.evaluate(s, gt)["methods"]
    assert "margin" not in qtvpr.evaluate(s, gt, matching="multi")["methods"]
    assert "margin" not in ref.evaluate(s, gt, matching="multi")["methods"]


# ---------------------------------------------------------------------------------------
# One calibration file in every front end
# ---------------------------------------------------------------------------------------


def test_one_gated_file_in_python_the_cli_and_dask(shared_data, cli, tmp_path):
    da = pytest.importorskip("dask.array")
    import qtvpr.dask

    s, gt = load(shared_data, "spedtest", "NetVLAD")
    s_cal, gt_cal, s_val = s[:, :60], gt[:, :60], s[:, 60:]
    path = tmp_path / "cal.npz"
    qtvpr.Calibration(s_cal, gt_cal).save(path, k=5, window=9, gate="margin")
    np.save(tmp_path / "val.npy", s_val)
    cal = qtvpr.Calibration.load(path)
    assert cal.defaults == {"k": 5, "precision": 1.0, "window": 9, "gate": "margin",
                            "sequence_gate": ref.SEQUENCE_DEFAULTS}
    assert ref.Calibration.load(path).defaults == cal.defaults
    online = qtvpr.Online(cal)
    assert online.gate == "margin"
    d = online.push_many(s_val)
    m_star = cal.gate()
    assert np.all(d.gates == m_star)

    # The CLI's stream: the same thirteen fields, the same values.
    out = run_cli(cli, "stream", "--calibration", str(path), "--val", str(tmp_path / "val.npy"))
    assert out.returncode == 0, out.stderr
    lines = [json.loads(line) for line in out.stdout.splitlines()]
    assert list(lines[0]) == ["query", "query_quantile", "weight", "quantile", "threshold", "best", "score",
                              "accepted", "accept", "confidence", "confidence_lower95", "margin", "gate"]
    close([line["confidence"] for line in lines], d.confidences, 1e-15)
    close([line["margin"] for line in lines], d.margins, 1e-15)
    close([line["gate"] for line in lines], d.gates, 1e-15)
    assert [line["accept"] for line in lines] == d.accept.tolist()
    # threshold --cal: the file's gate, m* in the document.
    out = run_cli(cli, "threshold", "--cal", str(path), "--val", str(tmp_path / "val.npy"), "--segment-size", "20")
    doc = json.loads(out.stdout)
    assert doc["params"]["gate"] == "margin" and doc["gate"] == pytest.approx(m_star, rel=1e-15)
    batch = cal.transfer(s_val, segment_size=20)
    assert batch.gate == m_star
    close([g["threshold"] for g in doc["segments"]], batch.thresholds, 1e-15)

    # Dask: the file's gate by default, identical results.
    lazy = da.from_array(s_val, chunks=(s_val.shape[0], 50))
    dd = qtvpr.dask.online(cal, lazy)
    assert np.array_equal(dd.margins, d.margins) and np.array_equal(dd.gates, d.gates)
    assert np.array_equal(dd.accept, d.accept)
    dt = qtvpr.dask.transfer(cal, lazy, segment_size=20)
    assert dt.gate == m_star and np.array_equal(dt.query_margins, batch.query_margins)
    assert qtvpr.dask.transfer(cal, lazy, segment_size=20, gate="none").gate is None


# ---------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------


def test_multi_matching_and_bad_names_are_errors(tmp_path):
    s = np.array([[0.9, 0.2, 0.3], [0.1, 0.8, 0.2], [0.3, 0.4, 0.7]])
    gt = np.eye(3, dtype=bool)
    multi = qtvpr.Calibration(s, gt, matching="multi")
    calls = [
        lambda: multi.transfer(s, gate="margin"),
        lambda: multi.gate(),
        lambda: qtvpr.Online(multi, window=2, gate="margin"),
        lambda: multi.save(tmp_path / "m.npz", gate="margin"),
        lambda: qtvpr.quantile_transfer(s, gt, s, matching="multi", gate="margin"),
        lambda: qtvpr.evaluate(np.tile(s, (1, 40)), np.tile(gt, (1, 40)), matching="multi", methods=["margin"]),
        lambda: ref.quantile_transfer(s, gt, s, matching="multi", gate="margin"),
        lambda: ref.Online(ref.Calibration(s, gt, matching="multi"), window=2, gate="margin"),
    ]
    for call in calls:
        with pytest.raises(ValueError, match=MULTI_WHY):
            call()
    assert not (tmp_path / "m.npz").exists()
    single = qtvpr.Calibration(s, gt)
    for call in (lambda: single.transfer(s, gate="ratio"), lambda: qtvpr.Online(single, window=2, gate="ratio")):
        why = 'gate must be none, or one or more of margin, sequence joined by commas, got "ratio"'
        with pytest.raises(ValueError, match=why):
            call()
    with pytest.raises(ValueError, match="at least 2 database images"):
        qtvpr.margins(np.array([[0.5, 0.2]]))
    with pytest.raises(ValueError, match="NaN"):
        qtvpr.margins(np.array([[0.5, np.nan], [0.1, 0.2]]))
