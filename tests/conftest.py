"""Shared fixtures: the shared folder (optional), small synthetic frames and maps."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("SEMMATCH_SHARED", ROOT.parent / "shared"))


@pytest.fixture(scope="session", autouse=True)
def _index_cache_in_a_temp_folder(tmp_path_factory):
    """Map index caches (:func:`semmatch.transfer.load_index`) go to a session temp folder, never to
    the user's cache folder; commands run in subprocesses inherit the variable."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SEMMATCH_CACHE_DIR", str(tmp_path_factory.mktemp("semmatch-cache")))
        yield


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared`` beside the project; tests using it skip when it is absent."""
    if not (SHARED / "scenes" / "replica").is_dir():
        pytest.skip("../shared/scenes/replica is not present")
    return SHARED


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)
