"""Hostile calibration files and paths, through the wheel (docs/semantics.md §10, files
and processes, and §12, integrity).

``qtvpr.Calibration.load``, ``qtvpr.Online`` on what it loads, and ``Calibration.save``
go through the core's reader and writer; these tests hold the Python surface to the
contract that the Rust and CLI tests hold the core to:

- a bit flip anywhere in a calibration file is an error naming the file (and, inside a
  member, the member), or loads a calibration whose decisions are bit-identical;
- members other than stored or deflated (bzip2, LZMA, zstd) are refused by name, before
  anything is decompressed;
- a 1 GB bzip2 bomb of a few kB is refused in under a second with a small peak RSS, and
  under a 1 GB address-space cap it raises instead of killing the interpreter;
- a FIFO input with no writer raises at once, one with a writer is read as a stream;
- a save through a symbolic link replaces the target and keeps the link; a save to a
  FIFO writes into it (or raises when nobody reads it), a save to a device writes into
  it, never replacing either with a regular file.

Every FIFO, link and device is made in ``tmp_path``. Calls that a regression would
block forever run in a subprocess with a timeout, or in a thread that the test releases
after a timeout, so that they fail instead of hanging.
"""

from __future__ import annotations

import io
import json
import os
import random
import resource
import stat
import struct
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

import qtvpr

# A small calibration with ties and soft ground truth, and a deployment traverse.
_rng = np.random.default_rng(19)
S = _rng.integers(0, 50, size=(6, 9)) / 50 - 0.3
GT = np.arange(6)[:, None] == np.arange(9)[None, :] % 6
SOFT = GT | (np.arange(6)[:, None] == (np.arange(9)[None, :] + 1) % 6)
DEP = _rng.integers(0, 40, size=(6, 20)) / 40 - 0.3
PARAMS = dict(k=3, precision=0.9, window=4)

# What a subprocess prints about one call: its exception (or none), the time it took and
# the peak RSS of the process before and after it (ru_maxrss: KiB on Linux).
CHILD = """
import json, resource, sys, time
import numpy as np
import qtvpr
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
start = time.perf_counter()
try:
    {call}
    out = {{"error": None}}
except BaseException as e:
    out = {{"error": type(e).__name__, "message": str(e), "oserror": isinstance(e, OSError)}}
out["seconds"] = time.perf_counter() - start
out["rss_before_kib"] = before
out["rss_kib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps(out))
"""

#: The address-space cap of the issue (``ulimit -v 1000000``, in bytes).
ADDRESS_SPACE = 1_000_000 * 1024


def run_child(call: str, *args: str, address_space: int | None = None, timeout: float = 30) -> dict:
    """Run ``call`` (a statement using ``sys.argv``) in a fresh interpreter; a hang fails
    with ``TimeoutExpired`` (the child is killed), a death of the interpreter fails on
    its exit status."""

    def cap() -> None:
        if address_space is not None:
            resource.setrlimit(resource.RLIMIT_AS, (address_space, address_space))

    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", RAYON_NUM_THREADS="2")
    proc = subprocess.run(
        [sys.executable, "-c", CHILD.format(call=call), *args],
        capture_output=True, text=True, timeout=timeout, preexec_fn=cap, env=env,
    )
    assert proc.returncode == 0, f"the interpreter died ({proc.returncode}): {proc.stderr[-2000:]}"
    return json.loads(proc.stdout.splitlines()[-1])


def load_in_time(path: Path, timeout: float = 10) -> qtvpr.Calibration:
    """``qtvpr.Calibration.load(path)`` of a FIFO, in a thread: a load that blocks in
    open(2) (what a FIFO with no writer did) fails the test instead of hanging it, and
    is released by a writer opened and closed at once."""
    result: list = []

    def load() -> None:
        try:
            result.append(qtvpr.Calibration.load(path))
        except BaseException as e:  # noqa: BLE001 - re-raised below
            result.append(e)

    thread = threading.Thread(target=load, daemon=True)
    thread.start()
    thread.join(timeout)
    if thread.is_alive():
        os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))  # the blocked open returns
        thread.join(5)
        pytest.fail(f"Calibration.load({path}) blocked for {timeout} s")
    if isinstance(result[0], BaseException):
        raise result[0]
    return result[0]


def calibration() -> qtvpr.Calibration:
    return qtvpr.Calibration(S, GT, gt_soft=SOFT)


def decisions(cal: qtvpr.Calibration) -> tuple:
    """Everything a loaded calibration decides, as bytes: online decisions at the file's
    defaults and batch thresholds, so that equal means bit-identical."""
    online = qtvpr.Online(cal).push_many(DEP)
    batch = cal.transfer(DEP, k=3, precision=0.9, segment_size=5)
    fields = ("thresholds", "quantiles", "query_quantiles", "weights", "best", "score", "accept", "accepted")
    arrays = [getattr(online, f) for f in fields] + [batch.thresholds, batch.quantiles]
    assert arrays[0].shape == (20,) and arrays[4] is not None  # decisions, not just thresholds
    return (
        cal.matching, len(cal), cal.db_size, tuple(sorted(cal.defaults.items())),
        *(None if a is None else a.tobytes() for a in arrays),
    )


@pytest.fixture(scope="module")
def saved(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("saved") / "cal.npz"
    calibration().save(path, **PARAMS)
    return path


@pytest.fixture(scope="module")
def original(saved) -> tuple:
    return decisions(qtvpr.Calibration.load(saved))


def member_ranges(data: bytes) -> dict[str, range]:
    """Where each member's (stored) bytes lie in the archive, from its local header."""
    ranges = {}
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        for info in z.infolist():
            at = info.header_offset
            assert data[at : at + 4] == b"PK\x03\x04"
            name_len, extra_len = struct.unpack("<HH", data[at + 26 : at + 30])
            start = at + 30 + name_len + extra_len
            ranges[info.filename.removesuffix(".npy")] = range(start, start + info.compress_size)
    return ranges


# ---------------------------------------------------------------------------------------
# Bit flips
# ---------------------------------------------------------------------------------------


def test_every_byte_flipped_is_an_error_or_changes_nothing(tmp_path, saved, original):
    """Each byte of the file in turn, one bit of it (bit i % 8) and then all of it: the
    load raises naming the file (and the member, for a byte inside one), or decides
    bit-identically (a field the reader does not use: times, versions, a local header's
    copy of the name or sizes)."""
    data = saved.read_bytes()
    assert 1000 < len(data) < 3000, len(data)
    inside = member_ranges(data)
    assert sorted(inside) == ["gt", "gt_soft", "meta", "s"]
    path = tmp_path / "flipped.npz"
    refused, loaded = 0, 0
    for i in range(len(data)):
        member = next((name for name, r in inside.items() if i in r), None)
        for mask in (1 << (i % 8), 0xFF):
            flipped = bytearray(data)
            flipped[i] ^= mask
            path.write_bytes(flipped)
            try:
                cal = qtvpr.Calibration.load(path)
            except (ValueError, TypeError, OSError) as e:
                refused += 1
                assert str(path) in str(e), (i, mask, str(e))
                if member is not None:
                    assert f"(array {member})" in str(e), (i, mask, member, str(e))
                continue
            loaded += 1
            assert member is None, f"byte {i} of member {member} flipped by {mask:#x} loaded"
            assert decisions(cal) == original, (i, mask)
    # The member data is most of the file, and the zip directory's fields that the reader
    # uses are checked too: far more flips are refused than load.
    assert refused > 3 * loaded, (refused, loaded)


def test_random_multi_byte_corruption(tmp_path, saved, original):
    """A few hundred files with 1 to 8 random bytes changed (fixed seed), each an error
    naming the file or bit-identical decisions."""
    data = saved.read_bytes()
    inside = member_ranges(data)
    rng = random.Random(1919)
    path = tmp_path / "random.npz"
    refused = 0
    for case in range(300):
        flipped = bytearray(data)
        where = rng.sample(range(len(data)), rng.randint(1, 8))
        for i in where:
            flipped[i] ^= rng.randint(1, 255)
        path.write_bytes(flipped)
        try:
            cal = qtvpr.Calibration.load(path)
        except (ValueError, TypeError, OSError) as e:
            refused += 1
            assert str(path) in str(e), (case, str(e))
            continue
        assert not any(i in r for i in where for r in inside.values()), (case, where)
        assert decisions(cal) == original, (case, where)
    assert refused > 200, refused


def test_a_bad_crc_names_the_file_and_the_member(tmp_path, saved):
    data = bytearray(saved.read_bytes())
    s = member_ranges(bytes(data))["s"]
    data[s.stop - 3] ^= 0x10  # in the last score
    path = tmp_path / "crc.npz"
    path.write_bytes(data)
    with pytest.raises(ValueError) as info:
        qtvpr.Calibration.load(path)
    assert str(info.value).endswith(f"{path} (array s) is corrupt: its CRC-32 does not match its data")


# ---------------------------------------------------------------------------------------
# Compression methods and bombs
# ---------------------------------------------------------------------------------------


def rewrite(source: Path, target: Path, methods: dict[str, int]) -> Path:
    """``source``'s members written again with zipfile, member NAME compressed with
    ``methods.get(NAME, ZIP_STORED)``."""
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(target, "w") as dst:
        for info in src.infolist():
            name = info.filename.removesuffix(".npy")
            dst.writestr(info.filename, src.read(info), compress_type=methods.get(name, zipfile.ZIP_STORED))
    return target


def mark_method(path: Path, member: str, method: int) -> Path:
    """Set member ``member``'s compression method field to ``method`` in its local header
    and in the central directory, its bytes left stored: what a stored member marked
    zstd (93) looks like (zipfile of Python < 3.14 cannot write zstd)."""
    data = bytearray(path.read_bytes())
    name = f"{member}.npy".encode()
    with zipfile.ZipFile(path) as z:
        at = z.getinfo(name.decode()).header_offset
    data[at + 8 : at + 10] = struct.pack("<H", method)
    cd = data.find(b"PK\x01\x02")
    while cd >= 0:
        (n,) = struct.unpack("<H", data[cd + 28 : cd + 30])
        if data[cd + 46 : cd + 46 + n] == name:
            data[cd + 10 : cd + 12] = struct.pack("<H", method)
        cd = data.find(b"PK\x01\x02", cd + 4)
    path.write_bytes(data)
    return path


def test_deflated_members_load_identically(tmp_path, saved, original):
    all_deflated = {n: zipfile.ZIP_DEFLATED for n in ("s", "gt", "gt_soft", "meta")}
    path = rewrite(saved, tmp_path / "deflated.npz", all_deflated)
    assert decisions(qtvpr.Calibration.load(path)) == original


@pytest.mark.parametrize(
    ("member", "method", "name"),
    [
        ("s", zipfile.ZIP_BZIP2, "12 (bzip2)"),
        ("gt", zipfile.ZIP_LZMA, "14 (LZMA)"),  # was the zip reader's "Compression method not supported"
        ("meta", zipfile.ZIP_BZIP2, "12 (bzip2)"),
        ("s", 93, "93 (zstd)"),
        ("gt_soft", 93, "93 (zstd)"),
    ],
)
def test_members_neither_stored_nor_deflated_are_refused_by_name(tmp_path, saved, member, method, name):
    path = tmp_path / f"{member}-{method}.npz"
    if method == 93:
        mark_method(rewrite(saved, path, {}), member, 93)  # a stored member marked zstd
    else:
        rewrite(saved, path, {member: method})
    with pytest.raises(ValueError) as info:
        qtvpr.Calibration.load(path)
    # Not "is shorter than the magic string", nor a decompressor's own words.
    assert str(info.value) == (
        f"{path} (array {member}) cannot be decompressed: compression method {name} is not supported; "
        "an .npz holds stored or deflated members"
    )


def npy_header(descr: str, shape: tuple) -> bytes:
    header = repr({"descr": descr, "fortran_order": False, "shape": shape})
    header += " " * ((-(10 + len(header) + 1)) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode("latin1")


META = json.dumps({"format": "qtvpr-calibration", "version": 1, "matching": "single",
                   "params": {"k": 1, "precision": 1.0, "window": None}})


def bomb(path: Path, method: int, s_shape: tuple, gt_shape: tuple = (1, 1)) -> Path:
    """A calibration whose ``s.npy`` (float64 zeros of ``s_shape``) is compressed with
    ``method``, with a stored ``gt`` (zeros of ``gt_shape``) and a good ``meta``."""
    n = s_shape[0] * s_shape[1] * 8
    zeros = bytes(1 << 20)
    with zipfile.ZipFile(path, "w") as z:
        info = zipfile.ZipInfo("s.npy")
        info.compress_type = method
        with z.open(info, "w", force_zip64=True) as f:
            f.write(npy_header("<f8", s_shape))
            for _ in range(n >> 20):
                f.write(zeros)
            f.write(bytes(n & ((1 << 20) - 1)))
        z.writestr("gt.npy", npy_header("|b1", gt_shape) + bytes(gt_shape[0] * gt_shape[1]))
        z.writestr("meta.npy", npy_header(f"<U{len(META)}", ()) + META.encode("utf-32-le"))
    return path


@pytest.fixture(scope="module")
def bzip2_bomb(tmp_path_factory) -> Path:
    """A few kB whose ``s.npy`` expands to 1 GiB (about 10 s to make)."""
    path = bomb(tmp_path_factory.mktemp("bomb") / "bomb.npz", zipfile.ZIP_BZIP2, (1 << 17, 1 << 10))
    assert path.stat().st_size < 4096, path.stat().st_size
    return path


def test_the_bzip2_bomb_is_refused_fast_and_small(bzip2_bomb):
    out = run_child("qtvpr.Calibration.load(sys.argv[1])", str(bzip2_bomb))
    assert out["error"] == "ValueError", out
    assert out["message"].startswith(f"{bzip2_bomb} (array s) cannot be decompressed: compression method 12 (bzip2)")
    assert out["seconds"] < 1.0, out
    # The load's own growth: an absolute peak would measure the process it was forked
    # from too (ru_maxrss is not reset by exec on every kernel).
    assert out["rss_kib"] - out["rss_before_kib"] < 100 * 1024, out


def test_the_bzip2_bomb_raises_under_an_address_space_cap(bzip2_bomb):
    out = run_child("qtvpr.Calibration.load(sys.argv[1])", str(bzip2_bomb), address_space=ADDRESS_SPACE)
    assert out["error"] in ("ValueError", "MemoryError"), out
    assert str(bzip2_bomb) in out["message"] and "(array s)" in out["message"], out


def test_a_deflate_bomb_is_refused_before_it_is_decompressed(tmp_path):
    """40 MB of zeros deflated to about 40 kB, whose shape disagrees with ``gt``: the
    headers are compared before any data is decompressed."""
    path = bomb(tmp_path / "deflate.npz", zipfile.ZIP_DEFLATED, (5000, 1000))
    assert path.stat().st_size < 100_000, path.stat().st_size
    for cap in (None, ADDRESS_SPACE):
        out = run_child("qtvpr.Calibration.load(sys.argv[1])", str(path), address_space=cap)
        assert out["error"] == "ValueError", out
        assert out["message"] == (
            f"{path}: ground truth shape 1x1 does not match calibration similarity shape 5000x1000"
        ), out
        assert out["seconds"] < 1.0, out
        assert out["rss_kib"] - out["rss_before_kib"] < 20 * 1024, out


def test_a_member_larger_than_its_directory_entry_is_refused(tmp_path):
    """An ``s.npy`` header that declares 80 GB over 8 bytes of data: refused from the
    header and the zip directory, before anything is allocated, even under a cap."""
    path = tmp_path / "claim.npz"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("s.npy", npy_header("<f8", (100_000, 100_000)) + bytes(8), compress_type=zipfile.ZIP_DEFLATED)
        z.writestr("gt.npy", npy_header("|b1", (1, 1)) + b"\x01")
        z.writestr("meta.npy", npy_header(f"<U{len(META)}", ()) + META.encode("utf-32-le"))
    out = run_child("qtvpr.Calibration.load(sys.argv[1])", str(path), address_space=ADDRESS_SPACE)
    assert out["error"] == "ValueError", out
    assert out["message"] == (
        f"{path} (array s) is corrupt: the zip directory says it holds 136 bytes, its .npy header "
        "declares 80000000128"
    ), out


# ---------------------------------------------------------------------------------------
# FIFO inputs
# ---------------------------------------------------------------------------------------


def test_a_fifo_without_a_writer_raises_at_once(tmp_path):
    fifo = tmp_path / "cal.fifo"
    os.mkfifo(fifo)
    out = run_child("qtvpr.Calibration.load(sys.argv[1])", str(fifo), timeout=20)
    assert out["oserror"], out
    assert out["message"] == f"cannot read {fifo}: is a FIFO with no writer", out
    assert out["seconds"] < 1.0, out
    assert stat.S_ISFIFO(fifo.stat().st_mode)


def test_a_fifo_with_a_writer_is_read_as_a_stream(tmp_path):
    """A calibration larger than a pipe's buffer (64 kB), written into the FIFO by a
    thread while it is loaded: the same decisions as the file."""
    rng = np.random.default_rng(7)
    s = rng.random((100, 120))
    gt = np.arange(100)[:, None] == np.arange(120)[None, :] % 100
    cal = qtvpr.Calibration(s, gt)
    path = tmp_path / "big.npz"
    cal.save(path, **PARAMS)
    data = path.read_bytes()
    assert len(data) > 1 << 16, len(data)
    fifo = tmp_path / "big.fifo"
    os.mkfifo(fifo)
    # A reader held open first (it never reads), so that the writer opens without
    # waiting and is a writer before the load looks for one.
    holder = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    writer = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
    os.set_blocking(writer, True)
    failed: list[BaseException] = []

    def write() -> None:
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(writer, view) :]
        except BaseException as e:  # noqa: BLE001 - reported by the test
            failed.append(e)
        finally:
            os.close(writer)

    thread = threading.Thread(target=write, daemon=True)
    thread.start()
    try:
        loaded = load_in_time(fifo)
    finally:
        os.close(holder)
        thread.join(timeout=10)
    assert not thread.is_alive() and not failed, failed
    want = qtvpr.Calibration.load(path)
    assert loaded.defaults == want.defaults
    sequence_gate = {"window": 5, "level": 0.8, "speed": 1.0, "tolerance": 2.0, "drift": 0.2}
    assert loaded.defaults == {"k": 3, "precision": 0.9, "window": 4, "gate": "none", "sequence_gate": sequence_gate}
    deployment = rng.random((100, 30))
    a, b = qtvpr.Online(loaded).push_many(deployment), qtvpr.Online(want).push_many(deployment)
    assert a.thresholds.tobytes() == b.thresholds.tobytes()
    assert a.best.tobytes() == b.best.tobytes() and a.accept.tobytes() == b.accept.tobytes()


def test_a_fifo_stream_that_is_not_a_zip_is_refused_at_its_first_bytes(tmp_path):
    fifo = tmp_path / "npy.fifo"
    os.mkfifo(fifo)
    holder = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    writer = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
    try:
        os.write(writer, b"\x93NUMPY and so on")
        os.close(writer)
        with pytest.raises(ValueError) as info:
            load_in_time(fifo)
    finally:
        os.close(holder)
    assert str(info.value) == (
        f"{fifo} is not a valid .npz archive: a stream must start with a zip local header (PK\\x03\\x04)"
    )


# ---------------------------------------------------------------------------------------
# Outputs that are links, FIFOs or devices
# ---------------------------------------------------------------------------------------


def test_save_through_a_symlink_replaces_the_target_and_keeps_the_link(tmp_path, original):
    target = tmp_path / "target.npz"
    target.write_bytes(b"old content")
    link = tmp_path / "link.npz"
    link.symlink_to("target.npz")  # relative, as `ln -s` makes it
    chain = tmp_path / "chain.npz"
    chain.symlink_to(link)
    calibration().save(chain, **PARAMS)
    assert chain.is_symlink() and link.is_symlink()
    assert os.readlink(link) == "target.npz"
    assert target.is_file() and not target.is_symlink()
    assert decisions(qtvpr.Calibration.load(target)) == original
    assert decisions(qtvpr.Calibration.load(chain)) == original
    # A dangling link: its target is created.
    dangling = tmp_path / "dangling.npz"
    dangling.symlink_to("made.npz")
    calibration().save(dangling, **PARAMS)
    assert dangling.is_symlink() and (tmp_path / "made.npz").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "chain.npz", "dangling.npz", "link.npz", "made.npz", "target.npz",
    ]  # no temporary file left


def test_save_to_a_fifo_with_a_reader_sends_the_whole_file(tmp_path, saved, original):
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    os.set_blocking(reader, True)
    got = bytearray()

    def read() -> None:
        # Until the writer opens, a read finds no writer and returns b"" at once: read
        # until something came and then the end.
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            chunk = os.read(reader, 1 << 16)
            if chunk:
                got.extend(chunk)
            elif got:
                return
            else:
                time.sleep(0.001)

    thread = threading.Thread(target=read, daemon=True)
    thread.start()
    try:
        calibration().save(fifo, **PARAMS)
        thread.join(timeout=15)
    finally:
        os.close(reader)
    assert stat.S_ISFIFO(fifo.stat().st_mode), "the FIFO was replaced"
    assert got.startswith(b"PK\x03\x04") and len(got) == saved.stat().st_size  # the zip's times differ
    received = tmp_path / "received.npz"
    received.write_bytes(got)
    assert decisions(qtvpr.Calibration.load(received)) == original
    with np.load(received, allow_pickle=False) as z:
        assert sorted(z.files) == ["gt", "gt_soft", "meta", "s"]


def test_save_to_a_fifo_without_a_reader_raises_at_once(tmp_path):
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    out = run_child(
        "qtvpr.Calibration(np.array([[0.5, 0.2]]), np.array([[True, False]])).save(sys.argv[1])", str(fifo),
        timeout=20,
    )
    assert out["oserror"], out
    assert out["message"] == f"cannot write {fifo}: is a FIFO that nobody reads", out
    assert out["seconds"] < 1.0, out
    assert stat.S_ISFIFO(fifo.stat().st_mode)
    assert os.listdir(tmp_path) == ["out.fifo"]


def test_save_to_a_character_device_writes_into_it(tmp_path):
    if os.geteuid() != 0:
        pytest.skip("making a device node (os.mknod) needs root; this test runs only as root")
    null = tmp_path / "null"
    os.mknod(null, stat.S_IFCHR | 0o666, os.makedev(1, 3))  # a copy of /dev/null, in tmp_path
    calibration().save(null, **PARAMS)
    mode = null.stat(follow_symlinks=False).st_mode
    assert stat.S_ISCHR(mode), "the device was replaced by a regular file"
    assert os.major(null.stat().st_rdev) == 1 and os.minor(null.stat().st_rdev) == 3
    assert os.listdir(tmp_path) == ["null"]


# ---------------------------------------------------------------------------------------
# Issue 35: the hostile set as calibration and as ground truth, memory, arguments
# ---------------------------------------------------------------------------------------

from hostile_npz import hostile, members_of  # noqa: E402


def tutorial_gt(path: Path) -> Path:
    np.savez(path, GThard=GT, GTsoft=SOFT)
    return path


def test_every_hostile_npz_is_one_error_as_calibration_and_as_ground_truth(tmp_path, saved):
    """The same set as the core's and the CLI's tests: ``Calibration.load`` and a
    ``gt=`` path each raise one ``ValueError`` naming the file and the member (never a
    ``PanicException``, which ``except Exception`` would not catch)."""
    cal = members_of(saved.read_bytes())
    gt = members_of(tutorial_gt(tmp_path / "gt.npz").read_bytes())
    qtvpr.quantile_transfer(S, tmp_path / "gt.npz", DEP, k=3)  # the good file is read
    n = 0
    path = tmp_path / "h.npz"
    for members, descr, prefix, load in (
        (cal, "<f8", f"{path}", qtvpr.Calibration.load),
        (gt, "|b1", f"gt_cal: {path}", lambda p: qtvpr.quantile_transfer(S, p, DEP, k=3)),
    ):
        for case, data, error in hostile(members, descr, (6, 9), 30):
            path.write_bytes(data)
            with pytest.raises(ValueError) as info:
                load(path)
            message = str(info.value)
            assert message.startswith(prefix) and error in message, (case, message)
            n += 1
    assert n == 2 * 54, n


def test_a_refused_shape_costs_no_more_than_its_header(tmp_path, saved):
    """A member whose header cannot be this calibration's (3-D, 10^13 values; or a
    40 MB deflate bomb of the wrong shape) is refused from its header: fast, and the
    process's peak RSS grows by less than 200 MiB."""
    cases = {case: data for case, data, _ in hostile(members_of(saved.read_bytes()), "<f8", (6, 9))}
    for case in ("a 3-D array of 10^13 values", "a deflate bomb with its true size"):
        path = tmp_path / "refused.npz"
        path.write_bytes(cases[case])
        out = run_child("qtvpr.Calibration.load(sys.argv[1])", str(path))
        assert out["error"] == "ValueError", (case, out)
        assert out["rss_kib"] - out["rss_before_kib"] < 200 * 1024, (case, out)
        assert out["seconds"] < 2, (case, out)


def test_a_calibration_too_large_for_the_address_space_raises_memory_error(tmp_path):
    """A valid calibration of 60 x 1,000,000 float64 zeros (480 MB, 0.5 MB deflated):
    under a 1 GB address-space cap, loading it raises ``MemoryError`` naming the file,
    never aborts the interpreter."""
    from hostile_npz import npy_header

    db, queries = 1_000_000, 60
    path = tmp_path / "big.npz"
    meta = json.dumps({"format": "qtvpr-calibration", "version": 1, "matching": "single",
                       "params": {"k": 1, "precision": 1.0, "window": None}})
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("s.npy", npy_header("<f8", (db, queries)) + bytes(db * queries * 8))
        z.writestr("gt.npy", npy_header("|b1", (db, queries)) + bytes(db * queries))
        z.writestr("meta.npy", npy_header(f"<U{len(meta)}", ()) + meta.encode("utf-32-le"))
    assert path.stat().st_size < 1 << 20
    out = run_child("qtvpr.Calibration.load(sys.argv[1])", str(path), address_space=ADDRESS_SPACE, timeout=60)
    assert out["error"] == "MemoryError", out
    assert out["message"].startswith(str(path)) and "cannot allocate" in out["message"], out


@pytest.mark.parametrize("value", [2**70, -(2**70), -1])
@pytest.mark.parametrize(
    ("name", "call"),
    [
        ("k", lambda v: qtvpr.Online(calibration(), k=v, window=2)),
        ("window", lambda v: qtvpr.Online(calibration(), window=v)),
        ("min_window", lambda v: qtvpr.Online(calibration(), window=2, min_window=v)),
        ("segment_size", lambda v: calibration().transfer(DEP, segment_size=v)),
        ("k", lambda v: qtvpr.quantile_transfer(S, GT, DEP, k=v)),
        ("cal_queries", lambda v: qtvpr.quantile_transfer(S, GT, cal_queries=v)),
        ("tolerance", lambda v: qtvpr.ground_truth_tolerance(3, 3, v)),
        ("n_db", lambda v: qtvpr.ground_truth_tolerance(v, 3, 1)),
        ("threads", lambda v: qtvpr.set_threads(v)),
        ("start", lambda v: qtvpr.Descriptors(np.eye(3), np.eye(3), start=v)),
        ("stop", lambda v: qtvpr.Descriptors(np.eye(3), np.eye(3), stop=v)),
        ("sequence length", lambda v: qtvpr.sequence_match(S, v)),
    ],
)
def test_integer_arguments_out_of_range_name_the_argument(name, call, value):
    """A huge or negative int is a ``ValueError`` that names the argument, not pyo3's
    ``OverflowError`` that names nothing."""
    with pytest.raises(ValueError) as info:
        call(value)
    assert str(info.value).startswith(f"{name} must be"), str(info.value)
    assert str(abs(value)) in str(info.value)
