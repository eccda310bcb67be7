"""Helpers of scripts/capi.sh, in plain Python (no NumPy: the script runs before the wheel).

    capi_check.py split S.npy N_CAL CAL.npy DEPLOY.npy
        Write the first N_CAL columns of the |DB| x |Q| C-order matrix S.npy to CAL.npy
        and the others to DEPLOY.npy: a calibration and a deployment traverse.
    capi_check.py raw S.npy OUT.f32
        Write the |DB| x |Q| C-order matrix S.npy query-major as raw little-endian
        float32: each query's |DB| scores in turn, as a camera would deliver them.
    capi_check.py compare EXPECTED.jsonl ACTUAL.jsonl [TOLERANCE]
        Check that two `qtvpr-cli stream --format jsonl` outputs have the same lines: the
        same keys, equal integers and booleans, and numbers within TOLERANCE (default
        1e-12) of each other. Prints the largest difference; exits 1 on a mismatch.
    capi_check.py small S.npy GT.npy
        Write a small calibration traverse: a 6 x 9 float64 similarity with ties (a fixed
        LCG) and its bool ground truth (row i matches column j when i == j % 6).
    capi_check.py flip CAL.npz MEMBER OUT.npz
        Copy CAL.npz with one bit flipped in the last byte of MEMBER's data (stored), so
        that only the member's CRC-32 tells.
    capi_check.py bomb OUT.npz bzip2|deflate
        A hostile calibration file: bzip2, an s.npy of 1 GiB of zeros in a few kB (its
        shape agrees with nothing, but it has to be decompressed to find out); deflate,
        40 MB of zeros in about 40 kB whose shape 5000x1000 disagrees with gt's 1x1.
    capi_check.py hostile-set CAL.npz OUT_DIR
        The hostile set of tests/hostile_npz.py made from CAL.npz (OUT_DIR/NNN.npz, and
        OUT_DIR/manifest.tsv: each file and a part of its error), and OUT_DIR/big.npz, a
        valid calibration too large for a 1 GB address-space cap.
"""

from __future__ import annotations

import ast
import json
import struct
import sys
import zipfile
from pathlib import Path


def read_npy(path: str) -> tuple[dict, bytes]:
    """The header dictionary and the data of a .npy file."""
    with open(path, "rb") as f:
        return read_npy_bytes(f.read(), path)


def read_npy_bytes(raw: bytes, path: str = "member") -> tuple[dict, bytes]:
    """The header dictionary and the data of the bytes of a .npy file."""
    if raw[:6] != b"\x93NUMPY":
        sys.exit(f"{path}: not a .npy file")
    if raw[6] == 1:
        (n,) = struct.unpack("<H", raw[8:10])
        start = 10
    else:
        (n,) = struct.unpack("<I", raw[8:12])
        start = 12
    header = ast.literal_eval(raw[start : start + n].decode("latin1"))
    return header, raw[start + n :]


def npy_header(descr: str, shape: tuple) -> bytes:
    """A version 1 .npy header, padded to a multiple of 64 bytes."""
    header = repr({"descr": descr, "fortran_order": False, "shape": shape})
    header += " " * (63 - (10 + len(header)) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode("latin1")


def write_npy(path: str, descr: str, shape: tuple[int, int], data: bytes) -> None:
    """A version 1 .npy file."""
    with open(path, "wb") as f:
        f.write(npy_header(descr, shape) + data)


def split(source: str, n_cal: str, cal: str, deploy: str) -> None:
    header, data = read_npy(source)
    if header["fortran_order"] or len(header["shape"]) != 2:
        sys.exit(f"{source}: expected a 2-D C-order matrix")
    rows, cols = header["shape"]
    item = int(header["descr"][2:])
    c = int(n_cal)
    row_bytes = cols * item
    rows_of = [data[i * row_bytes : (i + 1) * row_bytes] for i in range(rows)]
    write_npy(cal, header["descr"], (rows, c), b"".join(r[: c * item] for r in rows_of))
    write_npy(deploy, header["descr"], (rows, cols - c), b"".join(r[c * item :] for r in rows_of))


def raw(source: str, out: str) -> None:
    header, data = read_npy(source)
    if header["fortran_order"] or len(header["shape"]) != 2 or header["descr"] not in ("<f4", "<f8"):
        sys.exit(f"{source}: expected a 2-D C-order float32/float64 matrix")
    rows, cols = header["shape"]
    values = struct.unpack(f"<{rows * cols}{header['descr'][1:].replace('f4', 'f').replace('f8', 'd')}", data)
    with open(out, "wb") as f:
        f.write(struct.pack(f"<{rows * cols}f", *(values[i * cols + j] for j in range(cols) for i in range(rows))))


def compare(expected: str, actual: str, tolerance: str = "1e-12") -> None:
    tol = float(tolerance)
    with open(expected) as f:
        want = [json.loads(line) for line in f]
    with open(actual) as f:
        got = [json.loads(line) for line in f]
    if len(want) != len(got):
        sys.exit(f"{actual}: {len(got)} lines, expected {len(want)} ({expected})")
    worst = 0.0
    for n, (w, g) in enumerate(zip(want, got, strict=True), 1):
        if list(w) != list(g):
            sys.exit(f"{actual}:{n}: keys {list(g)}, expected {list(w)}")
        for key, value in w.items():
            other = g[key]
            if isinstance(value, float) or isinstance(other, float):
                diff = abs(value - other)
                worst = max(worst, diff)
                ok = diff <= tol * max(1.0, abs(value))
            else:
                ok = value == other and type(value) is type(other)
            if not ok:
                sys.exit(f"{actual}:{n}: {key} is {other!r}, expected {value!r} ({expected})")
    print(f"{actual}: {len(got)} decisions equal {expected} (largest difference {worst:.3g})")


def small(s_path: str, gt_path: str) -> None:
    x, values = 3, []
    for _ in range(6 * 9):
        x = (x * 6364136223846793005 + 1442695040888963407) % (1 << 64)
        values.append((x >> 33) % 50 / 50 - 0.3)
    write_npy(s_path, "<f8", (6, 9), struct.pack("<54d", *values))
    write_npy(gt_path, "|b1", (6, 9), bytes(int(i == j % 6) for i in range(6) for j in range(9)))


def flip(source: str, member: str, out: str) -> None:
    with open(source, "rb") as f:
        data = bytearray(f.read())
    with zipfile.ZipFile(source) as z:
        info = z.getinfo(f"{member}.npy")
    if info.compress_type != zipfile.ZIP_STORED:
        sys.exit(f"{source}: {member}.npy is not stored")
    at = info.header_offset
    name_len, extra_len = struct.unpack("<HH", data[at + 26 : at + 30])
    data[at + 30 + name_len + extra_len + info.compress_size - 1] ^= 0x10
    with open(out, "wb") as f:
        f.write(data)


META = json.dumps({"format": "qtvpr-calibration", "version": 1, "matching": "single",
                   "params": {"k": 1, "precision": 1.0, "window": 2}})


def bomb(out: str, method: str) -> None:
    compression, shape = {
        "bzip2": (zipfile.ZIP_BZIP2, (1 << 17, 1 << 10)),
        "deflate": (zipfile.ZIP_DEFLATED, (5000, 1000)),
    }[method]
    n = shape[0] * shape[1] * 8
    zeros = bytes(1 << 20)
    with zipfile.ZipFile(out, "w") as z:
        info = zipfile.ZipInfo("s.npy")
        info.compress_type = compression
        with z.open(info, "w", force_zip64=True) as f:
            f.write(npy_header("<f8", shape))
            for _ in range(n >> 20):
                f.write(zeros)
            f.write(bytes(n & ((1 << 20) - 1)))
        z.writestr("gt.npy", npy_header("|b1", (1, 1)) + b"\x01")
        z.writestr("meta.npy", npy_header(f"<U{len(META)}", ()) + META.encode("utf-32-le"))


def hostile_set(source: str, out_dir: str) -> None:
    """The hostile set of tests/hostile_npz.py made from calibration file ``source``:
    ``out_dir``/NNN.npz, and ``out_dir``/manifest.tsv with each file's path and a part of
    the error it must get; and ``out_dir``/big.npz, a valid calibration of 60 x 1,000,000
    float64 zeros (0.5 MB deflated) that does not fit under a 1 GB address-space cap."""
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from hostile_npz import hostile, members_of

    with open(source, "rb") as f:
        members = members_of(f.read())
    shape = tuple(read_npy_bytes(members[0][1])[0]["shape"])
    lines = []
    for i, (_, data, error) in enumerate(hostile(members, "<f8", shape, 30)):
        path = f"{out_dir}/{i:03}.npz"
        with open(path, "wb") as f:
            f.write(data)
        lines.append(f"{path}\t{error}\n")
    with open(f"{out_dir}/manifest.tsv", "w") as f:
        f.writelines(lines)
    db, queries = 1_000_000, 60
    with zipfile.ZipFile(f"{out_dir}/big.npz", "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("s.npy", npy_header("<f8", (db, queries)) + bytes(db * queries * 8))
        z.writestr("gt.npy", npy_header("|b1", (db, queries)) + bytes(db * queries))
        z.writestr("meta.npy", npy_header(f"<U{len(META)}", ()) + META.encode("utf-32-le"))


if __name__ == "__main__":
    commands = {"split": split, "raw": raw, "compare": compare, "small": small, "flip": flip, "bomb": bomb,
                "hostile-set": hostile_set}
    if len(sys.argv) < 2 or sys.argv[1] not in commands:
        sys.exit(__doc__)
    commands[sys.argv[1]](*sys.argv[2:])
