"""Shared pytest setup.

- Makes ``qtvpr`` importable from the source tree (``<repo>/py``) only when it is not
  importable otherwise, so that an installed package, once there is one, wins.
- ``shared_data``: the directory of real VPR data that sits next to the repository
  (``<repo>/../shared/data``); tests that need it are skipped when it is missing.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"

if importlib.util.find_spec("qtvpr") is None:
    sys.path.insert(0, str(REPO / "py"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ``../shared/data``; skips the test when the directory is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared data not found at {SHARED_DATA}")
    return SHARED_DATA
