"""Rebuild ``../shared/data`` from the public releases, or check a copy of it; and read it.

    python scripts/shared_data.py --build DIR [--frames FRAMES_DIR]   # needs the network
    python scripts/shared_data.py --check DIR                         # offline

The Python tests and the benches read the data through this module's readers (the last
section): the matrices it holds (``DATASETS``, ``TECHNIQUES``, :func:`vprbench`; the
22 real matrices of the benches, :func:`matrices`) and the Nordland HOG descriptors and
their similarity (:func:`nordland_hog`, :func:`nordland_similarity`), written once.
``crates/qtvpr-testkit/src/data.rs`` is the Rust tests' side of the same.

``--build`` downloads, converts and writes the files ``../shared/data/README.md``
describes, with the same names, shapes and dtypes, then checks them as ``--check`` does.
It NEEDS NETWORK ACCESS (GitHub for VPR-Bench; the Nordland frames' host, unless
``--frames`` points at a local copy). The machine this script was written on reaches
package registries only, so ``--build`` has never run end to end; what did run there is
written below. ``--check`` verifies an existing folder offline: every file's shape,
dtype and SHA-256 against the values measured on ``../shared/data``.

Sources and what was verified:

- ``vprbench-corridor/`` and ``vprbench-spedtest/``: VPR-Bench's precomputed matching
  data (Zaffar et al., IJCV 2021; MIT), in the GitHub repository
  MubarizZaffar/VPR-Bench at ``precomputed_matches/<dataset>/<technique>/
  precomputed_data_corrected.npy`` (datasets ``corridor``, ``SPEDTEST``) and the ground
  truth at ``datasets/<dataset>/ground_truth_new.npy``, fetched from the pinned commit
  ``VPRBENCH_COMMIT`` through raw.githubusercontent.com (the URL form is GitHub's; the
  files were read from a snapshot of that commit, not downloaded). Each matching file is
  a pickled object array of 6 entries; entry 3 is the |Q| x |DB| similarity, which is
  transposed to |DB| x |Q| and saved in its own dtype. ``ground_truth_new.npy`` holds
  ``(query, [database indices])`` rows. Both need ``allow_pickle``, so each download is
  checked against its SHA-256 (``VPRBENCH_SOURCES``) before it is unpickled. Converting
  the snapshot's files this way reproduced all 22 files of ``../shared/data``
  byte for byte.
- ``nordland-hog/``: HOG descriptors (scikit-image ``hog``: 9 orientations, 8x8-pixel
  cells, 2x2-cell blocks, its default L2-Hys block norm; 756 values for a 64x32 frame) of
  every 10th frame (``images-00001.png``, ``images-00011.png``, ...: the first 3576 in
  name order) of the 64x32 grayscale Nordland frames (NRK, CC BY 3.0) that OpenSeqSLAM's
  test-data script downloads, ``NORDLAND_URL``; winter is the database, summer the
  queries. That URL is the one OpenSeqSLAM's ``datasets/nordland/getDataset.bash``
  names; it could not be fetched here, and which copy of the frames ``../shared/data``
  was made from is not recorded, so the frame selection and the HOG settings are the
  README's description, not a verified recipe: ``--check`` (the SHA-256) says whether a
  rebuild matches. ``--frames DIR`` takes an extracted copy (``DIR/winter``,
  ``DIR/summer``). Needs scikit-image and Pillow, besides NumPy.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import sys
import tarfile
import tempfile
import urllib.request
from pathlib import Path

import numpy as np

VPRBENCH_COMMIT = "77ad30f3684476717188c67d7f3f66be19f832af"  # main, 2023-04-13
VPRBENCH_RAW = "https://raw.githubusercontent.com/MubarizZaffar/VPR-Bench/{commit}/{path}"
NORDLAND_URL = "http://www.tu-chemnitz.de/etit/proaut/datasets/nordland/64x32-grayscale-1fps.tar"

TECHNIQUES = (
    "AMOSNet", "AlexNet_VPR", "CALC", "CoHOG", "HOG", "HybridNet", "NetVLAD", "RegionVLAD",
    "ap-gem-r101", "denseVLAD",
)
# folder of ../shared/data -> VPR-Bench's dataset name
VPRBENCH_DATASETS = {"vprbench-corridor": "corridor", "vprbench-spedtest": "SPEDTEST"}

# SHA-256 of VPR-Bench's files at VPRBENCH_COMMIT, checked before they are unpickled.
VPRBENCH_SOURCES = {
    "corridor/AMOSNet": "f96e2261ef958a8be58d80a30fb082ca0ae0874bca264e9acc611b854ac7f83f",
    "corridor/AlexNet_VPR": "966f8edf6b02c9dbd0ba376f6bc4b26d5385bec6377f34eca70a1a1951f0f55c",
    "corridor/CALC": "6e71fb638a463348e13ccd61460009f1ec69f97bdc90eab825efc96ec1a64dfc",
    "corridor/CoHOG": "1221f3db4f63c4153ee23b62effca52cb8dafcbc49e1372fa2c74032bbba31f2",
    "corridor/HOG": "abde0657c3fbb29ac380e9eb5a0fdb670c6192d3f266fa90d0a03a3b02304d23",
    "corridor/HybridNet": "fb81af17d1bb6b059dbcdbe0dbb0da33ffb58a7d7d28fe0495feaf4769c00b4e",
    "corridor/NetVLAD": "a5b52279e7a2eb82c4693dbdc42965312c49b6115e38638e28ee739a60bcfc65",
    "corridor/RegionVLAD": "d2cbe72394aa9d5d5e9589516db8148a977af7739991b9a4e968d847898b53dc",
    "corridor/ap-gem-r101": "200b1025491ebb38fe85b7fe32b50cf652df0893a4dc83cd7bcb2c09fda74c3b",
    "corridor/denseVLAD": "2eb496da39fc2e823a6cc6b6354a5b7a91144e1475ca935b50b37fdfb4c535cc",
    "corridor/GT": "0b45a4e8aa884462e43f4fa6f61439ab4a71ec79933ec63c10bf6a4ccc70cd75",
    "SPEDTEST/AMOSNet": "3f6cae211220de0bfc929f1e0c6e089854818c8acf476a42035dd014a58ed447",
    "SPEDTEST/AlexNet_VPR": "c5f85d9f4410715db5467532b5f52bcf839594b1d5e900983cdd37afb6d5f494",
    "SPEDTEST/CALC": "e3c45df86efa22bfd6e32544a44e28cb844b93abadbebe25d8477b7f4aed53f0",
    "SPEDTEST/CoHOG": "c64dfb69bece33ee5651509dd6aed8154e6913b7096e93fc8be360820c75b67f",
    "SPEDTEST/HOG": "bee95f7e6f449c5db3cd782d5d0e6fbaeae72bebaf92113177c7b43c340fd8ce",
    "SPEDTEST/HybridNet": "7a88a5408a1e96e4fb576ca8a4c30e544bcb01d69aa199910509437531490d40",
    "SPEDTEST/NetVLAD": "cef10420251a9eab38e8397441867f8111514e10c2402ded94bb6a8a7b547bac",
    "SPEDTEST/RegionVLAD": "f9336db54f412b5d1cdad5d255ecc03106fc4db49751812dfca65ace17c9e43a",
    "SPEDTEST/ap-gem-r101": "ceecc7095252b46f46e22e44dfbf2a249f63ded028eb1233e7ae422d11c7d357",
    "SPEDTEST/denseVLAD": "22605a074180bff0f6db0344407947ee77a153fd125eb64f82ddcc02e0a2e20f",
    "SPEDTEST/GT": "4948ed660fb1c95904678c4ddb20b23aa81f1de5faff922c133ad64b116be865",
}

_F64, _F32, _BOOL = "float64", "float32", "bool"
_C, _S, _N = (111, 111), (607, 607), (3576, 756)

# Every file of ../shared/data: (shape, dtype, SHA-256 of the file).
EXPECTED: dict[str, tuple[tuple[int, int], str, str]] = {
    "nordland-hog/db_winter.npy": (_N, _F32,
        "087541aed70dd62d3ff1e4a7f7911a1151a460d60a9ad1693ec94ff30acc3eff"),
    "nordland-hog/query_summer.npy": (_N, _F32,
        "340a773fa5e0bbb7d1428ec9ffecce6dda6be44731c949225e3f88fd4de91735"),
    "vprbench-corridor/GT.npy": (_C, _BOOL,
        "a337703dec2788e6cf8681315b41d53b66bd02140fdaf6335721bb49ad486fe7"),
    "vprbench-corridor/S_AMOSNet.npy": (_C, _F64,
        "49aebea57d17f4eacb68e3f80d144c9d7be9307e8c69721836b80dac8f8a781f"),
    "vprbench-corridor/S_AlexNet_VPR.npy": (_C, _F64,
        "ff11846cb6c2ae46392c0640c63a447f2a8ddef191a224205eed42377ad107a5"),
    "vprbench-corridor/S_CALC.npy": (_C, _F64,
        "d3dc35fb495c0649ae97d97117b2b3bac3e1dd25243fd4a6220b082c37457cbc"),
    "vprbench-corridor/S_CoHOG.npy": (_C, _F32,
        "962dde5599428a2e6c9affceb615ed1ab64604a19e21732a69b973914f0f8960"),
    "vprbench-corridor/S_HOG.npy": (_C, _F64,
        "df5e590f5839b71f9fd88dac6610eb4baa242ee9512b1b4448cfcbd4f2845d09"),
    "vprbench-corridor/S_HybridNet.npy": (_C, _F64,
        "8f35b6358d2710fa8a1d884888b9770ceecd7687783c22e4b518dfd81839c699"),
    "vprbench-corridor/S_NetVLAD.npy": (_C, _F64,
        "fc8b3a0c51c34dd9ec1e8a87fee84587dc85a41f71f7544ae61d11e513056956"),
    "vprbench-corridor/S_RegionVLAD.npy": (_C, _F64,
        "c188ec84b03433f1291d74e1f0735f6d8e378792c08789041d0f983bcecc8a71"),
    "vprbench-corridor/S_ap-gem-r101.npy": (_C, _F64,
        "b16ba9ba1ba17976d273a8b59f204ddaef6e18f5fa2621a4a561ce411b04b0a0"),
    "vprbench-corridor/S_denseVLAD.npy": (_C, _F64,
        "54ae520acdbbe154e0120580e912d3bb96667d281527356bbe48033dfc373bca"),
    "vprbench-spedtest/GT.npy": (_S, _BOOL,
        "fe4fc0b6de3c1c1f433ff3d68915a6dd91f1815ad0df8ac202906e9c22508c70"),
    "vprbench-spedtest/S_AMOSNet.npy": (_S, _F64,
        "93845f98762f3e42125454eb482bd7013665c9bef6b9e5735f7437f0f0c0d036"),
    "vprbench-spedtest/S_AlexNet_VPR.npy": (_S, _F64,
        "ddb790f23392f2cd59072af3517a0d8d6d5ad4d0ed230693a13fe8449242de0d"),
    "vprbench-spedtest/S_CALC.npy": (_S, _F32,
        "56434b10238f4bea912078acd0d284872f434a89d8dd9c9482402d46e6c8e0e6"),
    "vprbench-spedtest/S_CoHOG.npy": (_S, _F32,
        "8e1e07be894cc31a21264cf465ffb302d63cb0d98574b7551093ad26b3f09e3a"),
    "vprbench-spedtest/S_HOG.npy": (_S, _F64,
        "ddad0458aa0b4c8cc7667d9f4925c53619c526c1c34b710b18cac6738363499e"),
    "vprbench-spedtest/S_HybridNet.npy": (_S, _F64,
        "70435d4f8b191ac1dae2fdded22ff05575a5364fdf4e78967e735850bfc0cb11"),
    "vprbench-spedtest/S_NetVLAD.npy": (_S, _F32,
        "36e321e5cfe81022efb97bf46a53c818bc92e1da6aad5ee1a0b0b69e33f254d1"),
    "vprbench-spedtest/S_RegionVLAD.npy": (_S, _F64,
        "71c041442167f11d9d840ac4acb98b129625133672e884c4981078db56c8c090"),
    "vprbench-spedtest/S_ap-gem-r101.npy": (_S, _F64,
        "98490e295657588afc2ac7692bac263e7eedfa118659d5447436eca43a30ae8d"),
    "vprbench-spedtest/S_denseVLAD.npy": (_S, _F64,
        "b536a1ffd79c8f1569ecbc64eb792f989589f1ab88f60c882c5ea638d5865d94"),
}

NORDLAND_FRAMES = 3576
NORDLAND_STEP = 10


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def npy_bytes(a: np.ndarray) -> bytes:
    """The bytes ``np.save`` writes for ``a`` (C order)."""
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(a), allow_pickle=False)
    return buf.getvalue()


# ---------------------------------------------------------------------------------------
# The conversions (tested offline on tiny inputs)
# ---------------------------------------------------------------------------------------


def similarity_from_vprbench(entries: np.ndarray) -> np.ndarray:
    """|DB| x |Q| scores from a VPR-Bench ``precomputed_data_corrected.npy`` array: its
    entry 3 is the |Q| x |DB| matrix (one row per query), kept in its dtype."""
    s = np.asarray(entries[3])
    if s.ndim != 2 or s.dtype not in (np.float32, np.float64):
        raise ValueError(f"entry 3 is {s.dtype} of shape {s.shape}, not a 2-D float matrix")
    return np.ascontiguousarray(s.T)


def ground_truth_from_vprbench(rows: np.ndarray, n_db: int, n_q: int) -> np.ndarray:
    """|DB| x |Q| bool ground truth from VPR-Bench's ``(query, [database indices])`` rows."""
    gt = np.zeros((n_db, n_q), dtype=bool)
    for query, matches in rows:
        gt[np.asarray(list(matches), dtype=np.int64), int(query)] = True
    return gt


def hog_descriptors(frames: list[np.ndarray]) -> np.ndarray:
    """float32 HOG descriptors, one row per 2-D grayscale frame: 9 orientations, 8x8-pixel
    cells, 2x2-cell blocks, L2-Hys (756 values for 32 x 64 pixels)."""
    from skimage.feature import hog  # scikit-image, needed for Nordland only

    rows = [
        hog(f, orientations=9, pixels_per_cell=(8, 8), cells_per_block=(2, 2), block_norm="L2-Hys")
        for f in frames
    ]
    return np.asarray(rows, dtype=np.float32)


def every_nth(names: list[str], step: int = NORDLAND_STEP, count: int = NORDLAND_FRAMES) -> list[str]:
    """The first ``count`` of every ``step``-th name, in name order from the first."""
    chosen = sorted(names)[::step][:count]
    if len(chosen) < count:
        raise ValueError(f"{len(names)} frames give {len(chosen)} at a step of {step}, not {count}")
    return chosen


# ---------------------------------------------------------------------------------------
# Checking a folder
# ---------------------------------------------------------------------------------------


def check(root: Path, hashes: bool = True) -> list[str]:
    """Every difference between the files under ``root`` and ``EXPECTED``: a missing file,
    a shape, dtype or SHA-256 that differs. Empty when the folder is the shared data."""
    problems = []
    for name, (shape, dtype, digest) in EXPECTED.items():
        path = root / name
        if not path.is_file():
            problems.append(f"{name}: missing")
            continue
        a = np.load(path, mmap_mode="r", allow_pickle=False)
        if a.shape != shape or str(a.dtype) != dtype:
            problems.append(f"{name}: {a.dtype} {a.shape}, expected {dtype} {shape}")
        elif hashes and sha256(path.read_bytes()) != digest:
            problems.append(f"{name}: SHA-256 differs from the shared data's")
    return problems


# ---------------------------------------------------------------------------------------
# Building (needs the network)
# ---------------------------------------------------------------------------------------


def download(url: str) -> bytes:
    print(f"downloading {url}", file=sys.stderr)
    with urllib.request.urlopen(url, timeout=120) as response:  # noqa: S310 (fixed https/http URLs)
        return response.read()


def vprbench_file(path: str, key: str) -> np.ndarray:
    data = download(VPRBENCH_RAW.format(commit=VPRBENCH_COMMIT, path=path))
    if sha256(data) != VPRBENCH_SOURCES[key]:
        raise ValueError(f"{path}: SHA-256 {sha256(data)} is not the pinned one; not unpickling it")
    # A pickled object array, from Python 2: latin1 decodes its byte strings.
    return np.load(io.BytesIO(data), allow_pickle=True, encoding="latin1")


def build_vprbench(out: Path) -> None:
    for folder, dataset in VPRBENCH_DATASETS.items():
        (out / folder).mkdir(parents=True, exist_ok=True)
        shape = None
        for technique in TECHNIQUES:
            path = f"precomputed_matches/{dataset}/{technique}/precomputed_data_corrected.npy"
            s = similarity_from_vprbench(vprbench_file(path, f"{dataset}/{technique}"))
            shape = s.shape
            (out / folder / f"S_{technique}.npy").write_bytes(npy_bytes(s))
        rows = vprbench_file(f"datasets/{dataset}/ground_truth_new.npy", f"{dataset}/GT")
        gt = ground_truth_from_vprbench(rows, *shape)
        (out / folder / "GT.npy").write_bytes(npy_bytes(gt))


def build_nordland(out: Path, frames: Path | None) -> None:
    from PIL import Image  # Pillow, to read the PNG frames

    with tempfile.TemporaryDirectory() as tmp:
        if frames is None:
            archive = Path(tmp) / "frames.tar"
            archive.write_bytes(download(NORDLAND_URL))
            with tarfile.open(archive) as tar:
                tar.extractall(tmp, filter="data")
            # The folder holding the season folders of images-NNNNN.png.
            seasons = {png.parent.parent for png in Path(tmp).rglob("images-*.png")}
            frames = min(seasons, key=lambda p: len(p.parts))
        (out / "nordland-hog").mkdir(parents=True, exist_ok=True)
        for season, name in (("winter", "db_winter.npy"), ("summer", "query_summer.npy")):
            names = every_nth([p.name for p in (frames / season).glob("images-*.png")])
            images = [np.asarray(Image.open(frames / season / n).convert("L")) for n in names]
            (out / "nordland-hog" / name).write_bytes(npy_bytes(hog_descriptors(images)))


# ---------------------------------------------------------------------------------------
# Reading the data: what the tests and the benches load

# The VPR-Bench folders of ../shared/data.
DATASETS = tuple(VPRBENCH_DATASETS)


def vprbench(root: Path, dataset: str, technique: str) -> tuple[np.ndarray, np.ndarray]:
    """(S, GT) of one VPR-Bench matrix of ``root`` (``../shared/data``): |DB| x |Q|, the
    similarity in the technique's own dtype, the ground truth bool."""
    d = root / dataset
    return np.load(d / f"S_{technique}.npy"), np.load(d / "GT.npy")


def nordland_hog(root: Path) -> tuple[np.ndarray, np.ndarray]:
    """The Nordland HOG descriptors of ``root``: the database (winter) and the queries
    (summer), 3576 x 756 float32 each, frame i of one the place of frame i of the other."""
    d = root / "nordland-hog"
    return np.load(d / "db_winter.npy"), np.load(d / "query_summer.npy")


def nordland_ground_truth(n_db: int, n_q: int) -> np.ndarray:
    """The ground truth of Nordland (``../shared/data/README.md``): database frame i
    matches query frame j when |i - j| <= 1."""
    return np.abs(np.arange(n_db)[:, None] - np.arange(n_q)[None, :]) <= 1


def unit_rows(x: np.ndarray) -> np.ndarray:
    """``x`` with every row scaled to unit L2 norm, in ``x``'s dtype."""
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def nordland_similarity(root: Path, dtype: type = np.float64) -> tuple[np.ndarray, np.ndarray]:
    """The cosine similarity of the Nordland HOG descriptors (rows normalised in
    ``dtype``), |DB| x |Q| float32, and its ground truth."""
    db, q = (unit_rows(a.astype(dtype)) for a in nordland_hog(root))
    s = (db @ q.T).astype(np.float32)
    return s, nordland_ground_truth(*s.shape)


def sequence_average(s: np.ndarray, half: int = 5) -> np.ndarray:
    """S_seq[i, j] = mean of S[i + d, j + d] for d in -half..half inside the matrix."""
    n, m = s.shape
    total = np.zeros((n, m), dtype=np.float64)
    count = np.zeros((n, m), dtype=np.float64)
    for d in range(-half, half + 1):
        # rows i with 0 <= i + d < n, columns j with 0 <= j + d < m
        i0, i1 = max(0, -d), min(n, n - d)
        j0, j1 = max(0, -d), min(m, m - d)
        total[i0:i1, j0:j1] += s[i0 + d:i1 + d, j0 + d:j1 + d]
        count[i0:i1, j0:j1] += 1
    return (total / count).astype(np.float32)


def matrices(root: Path):
    """(name, S, GT) of the 22 real matrices the benches report on, |DB| x |Q|: the 20
    VPR-Bench ones (Corridor and SPEDTest, 10 techniques each), then Nordland HOG's
    single-frame similarity (rows normalised in float32) and its 11-frame sequence
    average."""
    for dataset, label in zip(DATASETS, ("Corridor", "SPEDTest"), strict=True):
        for technique in TECHNIQUES:
            yield f"{label} {technique}", *vprbench(root, dataset, technique)
    s, gt = nordland_similarity(root, np.float32)
    yield "Nordland HOG (single frame)", s, gt
    yield "Nordland HOG (11-frame sequence)", sequence_average(s), gt


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", type=Path, metavar="DIR", help="verify DIR's files offline")
    mode.add_argument("--build", type=Path, metavar="DIR", help="download and rebuild into DIR")
    parser.add_argument("--frames", type=Path, help="extracted 64x32 Nordland frames (winter/, summer/)")
    args = parser.parse_args(argv)
    if args.build is not None:
        build_vprbench(args.build)
        build_nordland(args.build, args.frames)
    root = args.check if args.check is not None else args.build
    problems = check(root)
    for p in problems:
        print(p, file=sys.stderr)
    print(f"{root}: {len(EXPECTED) - len(problems)} of {len(EXPECTED)} files as expected")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
