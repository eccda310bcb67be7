"""Shared pytest setup.

- Makes ``qtvpr`` importable from the source tree (``<repo>/py``) only when it is not
  importable otherwise, so that an installed package, once there is one, wins.
- Makes ``scripts/shared_data.py`` importable (``from shared_data import ...``): which
  real matrices there are and how to read them.
- ``shared_data``: the directory of real VPR data that sits next to the repository
  (``<repo>/../shared/data``); tests that need it are skipped when it is missing.
- ``cli``: the ``qtvpr-cli`` binary, for every test module that runs it.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"

if importlib.util.find_spec("qtvpr") is None:
    sys.path.insert(0, str(REPO / "py"))
# shared_data: the list of the real matrices and their readers, written once for the
# tests and the benches.
sys.path.insert(0, str(REPO / "scripts"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ``../shared/data``; skips the test when the directory is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared data not found at {SHARED_DATA}")
    return SHARED_DATA


@pytest.fixture(scope="session")
def cli() -> Path:
    """The release binary (built here if need be, or taken from $QTVPR_CLI)."""
    if "QTVPR_CLI" in os.environ:
        return Path(os.environ["QTVPR_CLI"])
    subprocess.run(["cargo", "build", "--release", "--quiet", "-p", "qtvpr-cli"], cwd=REPO, check=True)
    meta = subprocess.run(
        ["cargo", "metadata", "--format-version", "1", "--no-deps"],
        cwd=REPO, check=True, capture_output=True, text=True,
    )
    return Path(json.loads(meta.stdout)["target_directory"]) / "release" / "qtvpr-cli"
