"""What every benchmark prints beside its figures, and how it writes them into the docs.

Shared by the scripts of benches/ so that the machine is described one way (the CPU is
named beside every absolute figure) and a marked block of a document is replaced one way.
"""

from __future__ import annotations

import os
import platform
import re
import sys
from pathlib import Path


def machine() -> str:
    """The cores, CPU model, OS and Python of this machine, for the heading of a figure."""
    cpu = "unknown CPU"
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{os.cpu_count()} cores ({cpu}), {platform.system()}, Python {platform.python_version()}"


def write_block(doc: Path, marker: str, text: str) -> None:
    """Replace what lies between ``<!-- marker:start -->`` and ``<!-- marker:end -->`` in
    ``doc`` by ``text``; exit with a message naming the file when the block is missing."""
    start, end = f"<!-- {marker}:start -->", f"<!-- {marker}:end -->"
    block = f"({re.escape(start)}\n).*?({re.escape(end)})"
    new, n = re.subn(block, lambda m: m[1] + text.rstrip("\n") + "\n" + m[2], doc.read_text(), flags=re.S)
    if n != 1:
        sys.exit(f"{doc} has no {start} ... {end} block")
    doc.write_text(new)
