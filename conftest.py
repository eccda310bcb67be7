"""The examples of README.md and docs/*.md, run as tests (Sybil): every ``python``
block of a document runs in order, in one namespace per document, in a fresh temporary
directory that holds the repository's ``data/`` (so ``data/corridor/...`` reads the
embedded real data, and what an example writes stays out of the repository). A block
that needs inputs a reader would have (a calibration file, descriptors) gets them from
an invisible block just before it (``<!--- invisible-code-block: python``); a block
that cannot run here says why in a ``<!--- skip: next`` comment.

scripts/test.sh runs them with the other tests: ``pytest ... ../README.md ../docs``.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from sybil import Sybil
from sybil.parsers.markdown import PythonCodeBlockParser, SkipParser

ROOT = Path(__file__).resolve().parent


def _setup(namespace: dict) -> None:
    work = Path(tempfile.mkdtemp(prefix="qtvpr-docs-"))
    (work / "data").symlink_to(ROOT / "data", target_is_directory=True)
    namespace["_docs_cwd"] = (os.getcwd(), work)
    os.chdir(work)


def _teardown(namespace: dict) -> None:
    cwd, work = namespace["_docs_cwd"]
    os.chdir(cwd)
    shutil.rmtree(work, ignore_errors=True)


pytest_collect_file = Sybil(
    parsers=[PythonCodeBlockParser(), SkipParser()],
    patterns=["README.md", "docs/*.md"],
    setup=_setup,
    teardown=_teardown,
).pytest()
