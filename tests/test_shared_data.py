"""scripts/shared_data.py: the offline parts (the check of a folder, the conversions)."""

from __future__ import annotations

import importlib.util
import io
import shutil
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "shared_data.py"
spec = importlib.util.spec_from_file_location("shared_data_script", SCRIPT)
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)


def test_the_shared_data_is_what_the_script_expects(shared_data: Path) -> None:
    # Every one of the 24 files: shape, dtype and SHA-256.
    assert len(script.EXPECTED) == 24
    assert script.check(shared_data) == []
    assert script.main(["--check", str(shared_data)]) == 0


def test_check_names_each_difference(shared_data: Path, tmp_path: Path) -> None:
    for name in script.EXPECTED:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(shared_data / name, tmp_path / name)
    # A missing file, a wrong dtype, and the same shape and dtype with one score changed.
    (tmp_path / "vprbench-corridor" / "S_HOG.npy").unlink()
    s = np.load(shared_data / "vprbench-spedtest" / "S_CALC.npy")
    np.save(tmp_path / "vprbench-spedtest" / "S_CALC.npy", s.astype(np.float64))
    gt = np.load(shared_data / "vprbench-corridor" / "GT.npy")
    gt[0, 0] = not gt[0, 0]
    np.save(tmp_path / "vprbench-corridor" / "GT.npy", gt)
    assert script.check(tmp_path) == [
        "vprbench-corridor/GT.npy: SHA-256 differs from the shared data's",
        "vprbench-corridor/S_HOG.npy: missing",
        "vprbench-spedtest/S_CALC.npy: float64 (607, 607), expected float32 (607, 607)",
    ]
    assert script.main(["--check", str(tmp_path)]) == 1


def test_a_vprbench_file_is_transposed_in_its_dtype() -> None:
    # VPR-Bench's layout: 6 entries (query indices, best matches, their scores, the
    # |Q| x |DB| scores, two times), pickled as an object array.
    q_by_db = np.array([[0.9, 0.1, 0.2], [0.3, 0.8, 0.4]], dtype=np.float32)  # 2 queries, 3 images
    entries = np.empty(6, dtype=object)
    entries[:] = [np.arange(2), np.array([0, 1]), np.array([0.9, 0.8]), q_by_db, 0.0, 0.0]
    buf = io.BytesIO()
    np.save(buf, entries, allow_pickle=True)
    buf.seek(0)
    s = script.similarity_from_vprbench(np.load(buf, allow_pickle=True, encoding="latin1"))
    assert s.dtype == np.float32 and s.flags["C_CONTIGUOUS"]
    np.testing.assert_array_equal(s, q_by_db.T)
    entries[3] = np.arange(3)
    with pytest.raises(ValueError, match="not a 2-D float matrix"):
        script.similarity_from_vprbench(entries)


def test_vprbench_ground_truth_rows_become_columns() -> None:
    rows = np.empty((2, 2), dtype=object)
    rows[0] = [0, [0, 1]]
    rows[1] = [1, [2]]
    gt = script.ground_truth_from_vprbench(rows, 3, 2)
    np.testing.assert_array_equal(gt, [[True, False], [True, False], [False, True]])
    assert gt.dtype == bool


def test_every_tenth_frame_from_the_first() -> None:
    names = [f"images-{i:05d}.png" for i in range(35, 0, -1)]  # 35 frames, any order
    assert script.every_nth(names, step=10, count=4) == [
        "images-00001.png", "images-00011.png", "images-00021.png", "images-00031.png",
    ]
    with pytest.raises(ValueError, match="35 frames give 4 at a step of 10, not 5"):
        script.every_nth(names, step=10, count=5)


def test_hog_of_a_64x32_frame_has_756_values() -> None:
    pytest.importorskip("skimage", reason="scikit-image builds the Nordland descriptors")
    flat = np.full((32, 64), 128, dtype=np.uint8)
    # A vertical edge at column 20: horizontal gradients, orientation bin 0.
    edge = flat.copy()
    edge[:, 20:] = 255
    d = script.hog_descriptors([flat, edge])
    # 64 x 32 pixels: 8 x 4 cells of 8x8, 7 x 3 blocks of 2x2 cells, 9 bins: 21 * 4 * 9.
    assert d.shape == (2, 756) and d.dtype == np.float32
    assert not d[0].any()  # no gradient, no histogram
    # Each block that sees the edge is L2-Hys normalised: its histogram is concentrated in
    # bin 0, clipped at 0.2 and renormalised, so its values are within [0, 1].
    assert d[1].max() <= 1.0 and d[1].max() > 0.2
    blocks = d[1].reshape(3, 7, 2, 2, 9)
    assert blocks[..., 0].sum() == pytest.approx(d[1].sum())
