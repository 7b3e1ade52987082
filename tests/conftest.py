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


def pytest_collection_finish(session):
    """Start the library-install dry run in the background when its test is selected: it waits on
    the package index for minutes and needs almost no CPU (tests/library_install.py)."""
    import library_install

    if library_install.STARTED is None and any(i.nodeid.endswith(library_install.TEST) for i in session.items):
        library_install.STARTED = library_install.DryRun(ROOT)


def pytest_sessionfinish(session):
    import library_install

    if library_install.STARTED is not None:
        library_install.STARTED.stop()
        library_install.STARTED = None


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared`` beside the project; tests using it skip when it is absent."""
    if not (SHARED / "scenes" / "replica").is_dir():
        pytest.skip("../shared/scenes/replica is not present")
    return SHARED


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


def noisy_scene_root(tmp_path_factory, name: str, n_frames: int) -> Path:
    """A data root with one small evaluation scene, ``bedroom_0003`` (clean and Kinect-like noisy
    recordings of ``n_frames`` frames at 160x120): the real-like chain's test scene."""
    from semmatch.io.geometry import DEFAULT_INTRINSICS
    from semmatch.sim import NoiseConfig, generate_dataset

    root = tmp_path_factory.mktemp(name) / "data"
    generate_dataset(root / "scenes", train_seeds=[], eval_seeds=[3], kinds=["bedroom"], n_frames_upper=n_frames,
                     n_frames_lower=n_frames, heights_sweep=None, intrinsics=DEFAULT_INTRINSICS.scaled(160, 120),
                     noise=NoiseConfig.kinect(3), progress=False)
    return root


@pytest.fixture
def oracle_network(monkeypatch):
    """Every network of a data root is the ground truth with 20 % blob-shaped errors (no checkpoint)."""
    from semmatch.experiments.layout import Layout
    from semmatch.segment.oracle import NoisyOracle

    monkeypatch.setattr(Layout, "load_network", lambda self, net: NoisyOracle(0.2, seed=0))
