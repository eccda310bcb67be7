"""Positions from image names (an extension beyond the paper): ``qtvpr.utm_positions``,
``qtvpr.image_paths`` and the CLI's ``--db-images`` / ``--query-images``.

- Names parse as VPR-methods-evaluation parses them (``path.split("@")[1:3]``), but
  from the file name only, so an ``@`` in a directory does not shift the fields.
- A directory lists as VPR-methods-evaluation's ``read_images_paths`` lists it (its
  code is restated below as the reference), sidecar ``DIR_images_paths.txt`` included.
- Bad names and lists raise ``ValueError`` naming the index or the line.
- Ground truth from names equals ground truth from position files, in the wheel and in
  the CLI; a VPR-methods-evaluation-style folder of the Nordland HOG descriptors gives
  the evaluate table of the dataset's frame-aligned truth.
"""

from __future__ import annotations

import json
import os
from glob import glob
from pathlib import Path

import numpy as np
import pytest

import qtvpr
from test_cli import run_cli


def vpr_methods_evaluation_paths(folder: str) -> list[str]:
    """``read_images_paths`` of VPR-methods-evaluation's test_dataset.py, restated."""
    sidecar = folder + "_images_paths.txt"
    if os.path.exists(sidecar):
        with open(sidecar) as f:
            return [folder + "/" + p for p in f.read().splitlines()]
    paths = sorted(glob(f"{folder}/**/*", recursive=True))
    return [p for p in paths if os.path.isfile(p) and os.path.splitext(p)[1].lower() in [".jpg", ".jpeg", ".png"]]


def touch(root: Path, *names: str) -> None:
    for name in names:
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(b"")


def names(points) -> list[str]:
    return [f"@{e}@{n}@33@W@0@0@pano@.jpg" for e, n in points]


def test_parses_east_and_north_of_the_file_name():
    got = qtvpr.utm_positions([
        "@549373.55@4178869.56@10@S@37.7556@-122.4409@pano@.jpg",
        Path("x/@-12.5@+3@.png"),
        "@4e5@7@",
        # A directory with '@' in its name does not count; the whole-path split of
        # VPR-methods-evaluation would read "weird" and "dir" here.
        "data/@weird@dir@/@1.5@2.25@.jpg",
    ])
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, [[549373.55, 4178869.56], [-12.5, 3.0], [4e5, 7.0], [1.5, 2.25]])
    # Without '@' in directories, the same numbers as VPR-methods-evaluation's split.
    path = "db/@549373.55@4178869.56@10@S@.jpg"
    assert qtvpr.utm_positions([path]).tolist() == [[float(path.split("@")[1]), float(path.split("@")[2])]]
    assert qtvpr.utm_positions([]).shape == (0, 2)


@pytest.mark.parametrize(("name", "problem"), [
    ("d/img.jpg", "has fewer than two '@'"),
    ("@12.jpg", "has fewer than two '@'"),
    ("@east@2@.jpg", "has utm_east 'east', which is not a number"),
    ("@1@nan@.jpg", "has utm_north 'nan', which is not finite"),
    ("@1e999@2@.jpg", "has utm_east '1e999', which is not finite"),
    ("@1@2.jpg", "has utm_north '2.jpg', which is not a number"),
])
def test_bad_names_name_the_index(name, problem):
    with pytest.raises(ValueError) as e:
        qtvpr.utm_positions(["@1@2@.jpg", name])
    assert str(e.value) == (f"paths[1]: image name '{name}' {problem}; "
                            "names must look like @utm_east@utm_north@...@.jpg")


def test_paths_must_be_a_list_of_paths():
    with pytest.raises(TypeError):
        qtvpr.utm_positions("@1@2@.jpg")  # a str, not a list of them
    with pytest.raises(TypeError):
        qtvpr.utm_positions([1.0])


def test_directories_list_as_vpr_methods_evaluation_does(tmp_path):
    db = tmp_path / "database"
    touch(db, "@2@0@.jpg", "@1@0@.JPG", "b/@3@0@.png", "b.@4@0@.jpeg", "c/d/@5@0@.jpg",
          ".@9@9@.jpg", ".hidden/@9@9@.jpg", "@9@9@.txt", "@25@0@.jpg", "@25.5@0@.jpg")
    (db / "@8@8@.jpg").mkdir()  # a directory named like an image is not one
    got = qtvpr.image_paths(db)
    assert got == vpr_methods_evaluation_paths(str(db))
    # Byte order, not numeric: '.' (0x2E) < '/' (0x2F) < digits < '@' (0x40), so
    # "@25.5@" < "@25@" < "@2@" ('.' < '@' after "@25"; '5' < '@' after "@2").
    assert [p[len(str(db)) + 1:] for p in got] == [
        "@1@0@.JPG", "@25.5@0@.jpg", "@25@0@.jpg", "@2@0@.jpg", "b.@4@0@.jpeg", "b/@3@0@.png", "c/d/@5@0@.jpg"]
    want = [[1, 0], [25.5, 0], [25, 0], [2, 0], [4, 0], [3, 0], [5, 0]]
    np.testing.assert_array_equal(qtvpr.utm_positions(got), want)

    # DIR_images_paths.txt next to the directory gives the order instead.
    (tmp_path / "database_images_paths.txt").write_text("b/@3@0@.png\n@2@0@.jpg\n")
    assert qtvpr.image_paths(str(db)) == vpr_methods_evaluation_paths(str(db)) == [
        str(db / "b/@3@0@.png"), str(db / "@2@0@.jpg")]


def test_text_files_list_one_path_per_line(tmp_path):
    f = tmp_path / "q.txt"
    f.write_bytes(b"a/@1@2@.jpg\r\n@3@4@.jpg\n/x/@-5.5@6@.png")
    assert qtvpr.image_paths(f) == ["a/@1@2@.jpg", "@3@4@.jpg", "/x/@-5.5@6@.png"]
    f.write_text("@1@2@.jpg\n")
    assert qtvpr.image_paths(f) == ["@1@2@.jpg"]
    for text, message in [
        (b"@1@2@.jpg\n\n@3@4@.jpg\n", "line 2 is empty; every line must be an image path (one per descriptor row)"),
        (b"@1@2@.jpg\n\n", "line 2 is empty; every line must be an image path (one per descriptor row)"),
        (b"", "is empty; it must list one image path per line"),
        (b"@1@2@.jpg\n@\xff@2@.jpg\n", "line 2 is not valid UTF-8"),
    ]:
        f.write_bytes(text)
        with pytest.raises(ValueError) as e:
            qtvpr.image_paths(f)
        assert str(e.value) == f"{f} {message}"
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="contains no images"):
        qtvpr.image_paths(tmp_path / "empty")
    with pytest.raises(FileNotFoundError):
        qtvpr.image_paths(tmp_path / "missing")


def small_case(tmp_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Queries at (0, 0), (10, 0); database at (3, 4), (7, 0), (10, -5); sorted by name,
    the database is (10, -5), (3, 4), (7, 0) ('1' < '3' < '7'). Returns the positions in
    that order."""
    touch(tmp_path / "database", *names([(3, 4), (7, 0), (10, -5)]))
    touch(tmp_path / "queries", *names([(0, 0), (10, 0)]))
    return np.array([[10.0, -5.0], [3.0, 4.0], [7.0, 0.0]]), np.array([[0.0, 0.0], [10.0, 0.0]])


def test_ground_truth_from_names_equals_ground_truth_from_positions(cli, tmp_path):
    dbp, qp = small_case(tmp_path)
    db = qtvpr.utm_positions(qtvpr.image_paths(tmp_path / "database"))
    q = qtvpr.utm_positions(qtvpr.image_paths(tmp_path / "queries"))
    np.testing.assert_array_equal(db, dbp)
    np.testing.assert_array_equal(q, qp)
    # Radius 5: (10, -5) is 5 from (10, 0); (3, 4) is 5 from (0, 0); (7, 0) is 3 from (10, 0).
    gt = qtvpr.ground_truth_positions(db, q, 5.0)
    np.testing.assert_array_equal(gt, [[False, True], [True, False], [False, True]])
    res = run_cli(cli, "ground-truth", "--db-images", tmp_path / "database", "--query-images", tmp_path / "queries",
                  "--radius", 5, "--soft-radius", 8, "-o", tmp_path / "gt.npz")
    assert res.returncode == 0, res.stderr
    with np.load(tmp_path / "gt.npz") as z:
        np.testing.assert_array_equal(z["GThard"], gt)
        # Soft, 8: (7, 0) is also 7 from (0, 0).
        np.testing.assert_array_equal(z["GTsoft"], qtvpr.ground_truth_positions(dbp, qp, 8.0))
        np.testing.assert_array_equal(z["GTsoft"], [[False, True], [True, False], [True, True]])


def test_cli_errors_name_the_list_and_the_line(cli, tmp_path):
    small_case(tmp_path)
    (tmp_path / "bad.txt").write_text("@1@2@.jpg\n@3@4@.jpg\nq/img_0003.jpg\n")
    np.save(tmp_path / "s.npy", np.array([[0.2, 0.9], [0.8, 0.1], [0.3, 0.7]]))
    res = run_cli(cli, "ground-truth", "--db-images", tmp_path / "bad.txt", "--query-images", tmp_path / "queries",
                  "-o", tmp_path / "gt.npy")
    assert res.returncode == 2
    assert "bad.txt line 3: image name 'q/img_0003.jpg' has fewer than two '@'" in res.stderr
    assert not (tmp_path / "gt.npy").exists()
    res = run_cli(cli, "evaluate", "--format", "json", "--similarity", tmp_path / "s.npy",
                  "--db-images", tmp_path / "queries", "--query-images", tmp_path / "queries",
                  "--cal-queries", 1, "--segment-size", 1)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1
    assert "lists 2 images but the similarity matrix has 3 database images" in res.stderr


def nordland_folder(shared_data: Path, root: Path) -> tuple[np.ndarray, np.ndarray]:
    """The Nordland HOG descriptors as a VPR-methods-evaluation output folder. Query j
    and database image j show the same place, so place j is put at UTM (500000 + 20 j,
    7000000), the queries 3 m north: within 25 m, query j matches database images j-1,
    j, j+1 (distances 3, sqrt(20² + 3²) = 20.2; two apart sqrt(40² + 3²) = 40.1), the
    dataset's |i - j| <= 1. All easts have 6 digits, so sorted names are sorted places."""
    db = np.load(shared_data / "nordland-hog" / "db_winter.npy")
    q = np.load(shared_data / "nordland-hog" / "query_summer.npy")
    n = db.shape[0]
    touch(root / "database", *names((500000 + 20 * j, 7000000) for j in range(n)))
    touch(root / "queries", *names((500000 + 20 * j, 7000003) for j in range(n)))
    np.save(root / "database_descriptors.npy", db)
    np.save(root / "queries_descriptors.npy", q)
    return db, q


def test_vpr_methods_evaluation_folder_to_the_evaluate_table(cli, shared_data, tmp_path):
    db, q = nordland_folder(shared_data, tmp_path)
    n = db.shape[0]
    i = np.arange(n)
    truth = np.abs(i[:, None] - i[None, :]) <= 1
    pos_db = qtvpr.utm_positions(qtvpr.image_paths(tmp_path / "database"))
    pos_q = qtvpr.utm_positions(qtvpr.image_paths(tmp_path / "queries"))
    gt = qtvpr.ground_truth_positions(pos_db, pos_q, 25.0)
    np.testing.assert_array_equal(gt, truth)

    s = tmp_path / "S.npy"
    assert run_cli(cli, "similarity", "--db", tmp_path / "database_descriptors.npy",
                   "--queries", tmp_path / "queries_descriptors.npy", "-o", s).returncode == 0
    by_names = run_cli(cli, "evaluate", "--format", "json", "--similarity", s, "--db-images", tmp_path / "database",
                       "--query-images", tmp_path / "queries")
    assert by_names.returncode == 0, by_names.stderr
    by_tolerance = run_cli(cli, "evaluate", "--format", "json", "--similarity", s, "--gt-tolerance", 1)
    assert json.loads(by_names.stdout) == json.loads(by_tolerance.stdout)
    # The wheel on the same matrix and names gives the CLI's numbers.
    wheel = qtvpr.evaluate(np.load(s), gt)
    cli_methods = json.loads(by_names.stdout)["methods"]
    assert list(wheel["methods"]) == list(cli_methods)
    for name, m in wheel["methods"].items():
        assert (m["pct_segs"], m["avg_recall"]) == (cli_methods[name]["pct_segs"], cli_methods[name]["avg_recall"])


# The on-ramp in one command: descriptors and image names to the evaluation, equal to
# similarity followed by evaluate --similarity with the dataset's truth.
def test_vpr_methods_evaluation_folder_in_one_command(cli, shared_data, tmp_path):
    nordland_folder(shared_data, tmp_path)
    one = run_cli(cli, "evaluate", "--format", "json", "--db-descriptors", tmp_path / "database_descriptors.npy",
                  "--query-descriptors", tmp_path / "queries_descriptors.npy",
                  "--db-images", tmp_path / "database", "--query-images", tmp_path / "queries")
    assert one.returncode == 0, one.stderr
    s = tmp_path / "S.npy"
    run_cli(cli, "similarity", "--db", tmp_path / "database_descriptors.npy",
            "--queries", tmp_path / "queries_descriptors.npy", "-o", s)
    got = json.loads(one.stdout)
    want = json.loads(run_cli(cli, "evaluate", "--format", "json", "--similarity", s, "--gt-tolerance", 1).stdout)
    # The dataset line names the inputs (the two descriptor files, or S.npy); all else agrees.
    assert got.pop("dataset").endswith("database_descriptors.npy x " + str(tmp_path / "queries_descriptors.npy"))
    want.pop("dataset")
    # Only the matrix has an orientation to report (ground truth made for it: no evidence).
    assert want.pop("orientation") == {"db": 3576, "queries": 3576, "query_major": False,
                                       "layout": "assumed (no ground truth was read in the matrix's layout to tell)"}
    assert got == want


def test_docstrings_and_signatures_for_help():
    assert qtvpr.utm_positions.__text_signature__ == "(paths)"
    assert qtvpr.image_paths.__text_signature__ == "(source)"
    assert "paths[" in qtvpr.utm_positions.__doc__
    assert "_images_paths.txt" in qtvpr.image_paths.__doc__
