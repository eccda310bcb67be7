"""`qtvpr-cli threshold` against the NumPy reference, on the real matrices in
../shared/data: both matching modes, tau 1.0 and 0.9, with and without segments,
DB x Q and query-major input, .npy and .npz ground truth, JSON and CSV output."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

from qtvpr import reference
from shared_data import DATASETS, TECHNIQUES, nordland_similarity

REPO = Path(__file__).resolve().parents[1]


def run_cli(cli: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True)


def split(shared_data: Path, dataset: str, technique: str):
    """The paper's protocol: the first floor(10%) queries calibrate, the rest deploy."""
    s = np.load(shared_data / dataset / f"S_{technique}.npy")
    gt = np.load(shared_data / dataset / "GT.npy")
    n_cal = s.shape[1] // 10
    return s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:], math.ceil(0.01 * s.shape[1])


def write(tmp: Path, **arrays) -> dict[str, Path]:
    paths = {}
    for name, a in arrays.items():
        paths[name] = tmp / f"{name}.npy"
        np.save(paths[name], a)
    return paths


def assert_matches_reference(out: dict, ref: reference.TransferResult) -> None:
    segs = out["segments"]
    assert [(s["start"], s["end"]) for s in segs] == [tuple(x) for x in ref.segments]
    np.testing.assert_allclose([s["quantile"] for s in segs], ref.quantiles, rtol=0, atol=1e-9)
    np.testing.assert_allclose([s["threshold"] for s in segs], ref.thresholds, rtol=0, atol=1e-9)


@pytest.mark.parametrize("dataset", DATASETS)
@pytest.mark.parametrize("technique", TECHNIQUES)
def test_threshold_equals_reference(cli, shared_data, tmp_path, dataset, technique):
    s_cal, gt_cal, s_val, seg = split(shared_data, dataset, technique)
    f = write(tmp_path, cal=s_cal, gt=gt_cal, val=s_val)
    for matching in ("single", "multi"):
        for precision in (1.0, 0.9):
            for segment_size in (seg, None):
                args = ["threshold", "--cal", f["cal"], "--cal-gt", f["gt"], "--val", f["val"],
                        "--matching", matching, "--precision", precision]
                if segment_size is not None:
                    args += ["--segment-size", segment_size]
                res = run_cli(cli, *args)
                assert res.returncode == 0, res.stderr
                out = json.loads(res.stdout)
                assert out["method"] == "quantile-transfer"
                assert out["params"] == {
                    "k": 10, "precision": precision, "matching": matching,
                    "segment_size": segment_size or s_val.shape[1], "gate": "none",
                }
                ref = reference.quantile_transfer(
                    s_cal, gt_cal, s_val, matching=matching, precision=precision,
                    segment_size=segment_size,
                )
                assert_matches_reference(out, ref)


@pytest.mark.parametrize("dataset", DATASETS)
@pytest.mark.parametrize("technique", ["CoHOG", "NetVLAD", "HOG"])
def test_query_major_input(cli, shared_data, tmp_path, dataset, technique):
    """VPR-Bench stores Q x DB: --query-major reads it, Fortran order included."""
    s_cal, gt_cal, s_val, seg = split(shared_data, dataset, technique)
    f = write(tmp_path, cal=np.asfortranarray(s_cal.T), gt=gt_cal.T.astype(np.uint8), val=s_val.T)
    res = run_cli(cli, "threshold", "--query-major", "--cal", f["cal"], "--cal-gt", f["gt"],
                  "--val", f["val"], "--segment-size", seg, "--k", 5, "--matching", "multi")
    assert res.returncode == 0, res.stderr
    ref = reference.quantile_transfer(
        s_cal.T, gt_cal.T, s_val.T, k=5, matching="multi", segment_size=seg, query_major=True
    )
    assert_matches_reference(json.loads(res.stdout), ref)


def test_npz_ground_truth_csv_output_and_output_file(cli, shared_data, tmp_path):
    """VPR_Tutorial GT.npz (GThard + GTsoft), CSV format, and --output."""
    s_cal, gt_cal, s_val, seg = split(shared_data, "vprbench-corridor", "NetVLAD")
    soft = gt_cal.copy()
    soft[1:, :] |= gt_cal[:-1, :]  # widen every match by one database image
    f = write(tmp_path, cal=s_cal, val=s_val)
    np.savez(tmp_path / "GT.npz", GThard=gt_cal, GTsoft=soft)
    out_file = tmp_path / "out" / "t.csv"
    out_file.parent.mkdir()
    res = run_cli(cli, "threshold", "--cal", f["cal"], "--cal-gt", tmp_path / "GT.npz", "--val",
                  f["val"], "--segment-size", seg, "--format", "csv", "--output", out_file)
    assert res.returncode == 0, res.stderr
    assert res.stdout == ""
    ref = reference.quantile_transfer(s_cal, gt_cal, s_val, gt_soft=soft, segment_size=seg)
    lines = out_file.read_text().splitlines()
    assert lines[0] == "start,end,quantile,threshold"
    rows = [line.split(",") for line in lines[1:]]
    assert [(int(r[0]), int(r[1])) for r in rows] == [tuple(x) for x in ref.segments]
    np.testing.assert_allclose([float(r[2]) for r in rows], ref.quantiles, rtol=0, atol=1e-9)
    np.testing.assert_allclose([float(r[3]) for r in rows], ref.thresholds, rtol=0, atol=1e-9)
    assert sorted(p.name for p in out_file.parent.iterdir()) == ["t.csv"]


@pytest.mark.parametrize("matching", ["single", "multi"])
def test_nordland_hog(cli, shared_data, tmp_path, matching):
    """The mid-size real case: 3576 x 3576, deployment processed in several chunks."""
    s, gt = nordland_similarity(shared_data)
    n_cal, seg = s.shape[1] // 10, math.ceil(0.01 * s.shape[1])
    f = write(tmp_path, cal=s[:, :n_cal], gt=gt[:, :n_cal], val=s[:, n_cal:])
    res = run_cli(cli, "threshold", "--cal", f["cal"], "--cal-gt", f["gt"], "--val", f["val"],
                  "--segment-size", seg, "--matching", matching)
    assert res.returncode == 0, res.stderr
    ref = reference.quantile_transfer(s[:, :n_cal], gt[:, :n_cal], s[:, n_cal:], matching=matching,
                                      segment_size=seg)
    assert_matches_reference(json.loads(res.stdout), ref)
