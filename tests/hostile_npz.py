"""The hostile ``.npz`` set of issue 35, in Python: the same cases as the core's
``crates/qtvpr-testkit/src/zip.rs`` (which the Rust and CLI tests use), built with
``zipfile`` and patched where a field must lie. Used by ``test_hostile_files.py`` and
by ``scripts/capi_check.py`` (the C library's hostile-file test).

``hostile(members, descr)`` takes a valid archive's members (name, ``.npy`` bytes, in
order), makes its first member hostile and keeps the others valid (two cases instead
add a bad member or move the directory), and returns
``(case, bytes, error)`` triples: ``error`` is a part of the one error message the file
must get (after its path).
"""

from __future__ import annotations

import io
import struct
import warnings
import zipfile

AE2 = bytes([2, 0]) + b"AE" + bytes([3, 8, 0])
AE1 = bytes([1, 0]) + b"AE" + bytes([3, 8, 0])

#: The methods that are neither stored nor deflated tried by name (APPNOTE 4.4.5).
METHODS = {1: "unknown", 9: "deflate64", 12: "bzip2", 14: "LZMA", 93: "zstd", 95: "XZ", 98: "PPMd",
           99: "AES encryption", 0xFFFF: "unknown"}


def npy_header(descr: str, shape: tuple) -> bytes:
    header = repr({"descr": descr, "fortran_order": False, "shape": shape})
    header += " " * ((-(10 + len(header) + 1)) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode("latin1")


def archive(members: list[tuple[str, bytes]], deflated: tuple[str, ...] = (), extra: bytes = b"") -> bytes:
    """``members`` zipped (the first with ``extra`` as its extra field), those named in
    ``deflated`` deflated, the others stored."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as z, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a duplicate name is a case of the set
        for i, (name, data) in enumerate(members):
            info = zipfile.ZipInfo(name)
            info.compress_type = zipfile.ZIP_DEFLATED if name in deflated and i == 0 else zipfile.ZIP_STORED
            if i == 0 and extra:
                info.extra = struct.pack("<HH", 0x9901, len(extra)) + extra
            z.writestr(info, data)
    return out.getvalue()


def headers(data: bytes, name: str) -> tuple[int, int]:
    """The offsets of member ``name``'s local header and directory record."""
    central = data.find(b"PK\x01\x02")
    while central >= 0:
        (n,) = struct.unpack("<H", data[central + 28 : central + 30])
        if data[central + 46 : central + 46 + n] == name.encode():
            (local,) = struct.unpack("<I", data[central + 42 : central + 46])
            return local, central
        central = data.find(b"PK\x01\x02", central + 4)
    raise KeyError(name)


def patch(data: bytes, name: str, local: int, central: int, fmt: str, value: int) -> bytes:
    """Field ``fmt`` at ``local`` in member ``name``'s local header and ``central`` in its
    directory record set to ``value``."""
    b = bytearray(data)
    at_local, at_central = headers(data, name)
    for at in (at_local + local, at_central + central):
        struct.pack_into(fmt, b, at, value)
    return bytes(b)


def hostile(members: list[tuple[str, bytes]], descr: str, shape: tuple[int, int],
            other_methods: int = 0) -> list[tuple[str, bytes, str]]:
    victim, data = members[0]
    array = victim.removesuffix(".npy")
    rest = members[1:]
    item = int(descr[2:])
    rows, cols = shape
    method = lambda n: f"(array {array}) cannot be decompressed: compression method {n} ({METHODS.get(n, 'unknown')})"  # noqa: E731
    encrypted = lambda how: f"(array {array}) is encrypted ({how})"  # noqa: E731
    good = archive(members)
    flags = lambda b, bits: patch(b, victim, 6, 8, "<H", bits)  # noqa: E731
    cases = [
        ("AES without the encryption flag", patch(archive(members, extra=AE2), victim, 8, 10, "<H", 99), method(99)),
        ("AES with the encryption flag", flags(patch(archive(members, extra=AE2), victim, 8, 10, "<H", 99), 1),
         method(99)),
        ("an AE-1 extra field on a deflated member", archive(members, (victim,), AE1), encrypted("WinZip AE-1")),
        ("an AE-2 extra field on a stored member", archive(members, extra=AE2), encrypted("WinZip AE-2")),
        ("ZipCrypto (the encryption flag)", flags(good, 1), encrypted("its encryption flag is set: ZipCrypto or AES")),
        ("strong encryption", flags(good, 1 | 1 << 6), encrypted("strong encryption")),
        ("a masked local header", flags(good, 1 << 13), encrypted("a masked local header")),
    ]
    others = [n for n in range(1, 0x10000) if n not in (8, 99) and n not in METHODS][:other_methods]
    for n in [m for m in METHODS if m != 99] + others:
        cases.append((f"method {n}", patch(good, victim, 8, 10, "<H", n), method(n)))
    cases.append(("a member twice", archive([*members, members[0]]), f"(array {array}) is in the archive twice"))
    (crc,) = struct.unpack("<I", good[headers(good, victim)[0] + 14 :][:4])
    cases.append(("a bad CRC-32", patch(good, victim, 14, 16, "<I", crc ^ 1),
                  f"(array {array}) is corrupt: its CRC-32 does not match its data"))
    b = bytearray(good)
    b[headers(good, victim)[1] + 16] ^= 1
    cases.append(("a CRC-32 changed in the directory only", bytes(b),
                  f"(array {array}) is corrupt: its local header and the zip directory disagree on its CRC-32"))
    big_rows = 40_000_000 // item // cols
    bomb = npy_header(descr, (big_rows, cols)) + bytes(big_rows * cols * item)
    cases.append(("a deflate bomb with its true size", archive([(victim, bomb), *rest], (victim,)),
                  f"shape {big_rows}x{cols}"))
    long = archive([(victim, data + bytes(40_000_000)), *rest], (victim,))
    long = patch(long, victim, 22, 24, "<I", len(data))
    cases.append(("a deflate bomb past its declared size", long,
                  f"(array {array}) is corrupt: it decompresses past its declared {len(data)} bytes"))
    one = npy_header(descr, (rows * cols,)) + data[len(data) - rows * cols * item :]
    cases.append(("a 1-D array", archive([(victim, one), *rest]), f"(array {array}) holds a 1-D array"))
    three = npy_header(descr, (1000, 100_000, 100_000))
    cases.append(("a 3-D array of 10^13 values", archive([(victim, three), *rest], (victim,)),
                  f"(array {array}) holds a 3-D array"))
    # Issue 49: two that np.load and unzip -t reject. A member no reader uses, with a bad
    # CRC-32 (the first member stays valid here).
    extra = archive([*members, ("notes.txt", b"not an array")])
    (crc,) = struct.unpack("<I", extra[headers(extra, "notes.txt")[0] + 14 :][:4])
    cases.append(("an extra member with a bad CRC-32", patch(extra, "notes.txt", 14, 16, "<I", crc ^ 1),
                  "(member notes.txt) is corrupt: its CRC-32 does not match its data"))
    # An end record that puts the directory 10 bytes after where it starts.
    end = good.rfind(b"PK\x05\x06")
    (at,) = struct.unpack("<I", good[end + 16 : end + 20])
    b = bytearray(good)
    struct.pack_into("<I", b, end + 16, at + 10)
    cases.append(("a directory offset 10 bytes off", bytes(b),
                  f"its end record puts the zip directory at byte {at + 10}, but it starts at byte {at}"))
    return cases


def members_of(data: bytes) -> list[tuple[str, bytes]]:
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return [(info.filename, z.read(info)) for info in z.infolist()]
