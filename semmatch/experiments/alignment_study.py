"""A person and a robot: the robot's recording placed in the person's map, measured (issue 51).

Two studies of :func:`semmatch.poses.alignment.align_to_map`, each recording posed by its own
odometry from the identity (no ground truth enters the chain; it only scores):

- **real** (:func:`kitchen_study`): the development frames of the 7-Scenes red kitchen split
  into two sessions, frames 0-249 ("person") and 250-499 ("robot"), each tracked by
  :func:`semmatch.poses.odometry.estimate_poses` (hybrid residual, chained, no pose graph: the
  better trajectory on these frames, docs/recordings.md) and fused; the robot's map aligned
  into the person's; the alignment's error against the 7-Scenes poses, and the share of the
  robot session's pixels that land within 5 cm of the person's map;
- **two heights** (:func:`two_height_study`): simulated scenes, the person's (1.6 m) and the
  robot's (0.2 m) noisy recordings tracked as the real-like chain tracks them
  (:func:`semmatch.experiments.real_poses.cached_odometry`: seeded by their own drifting
  odometry), aligned, labels transferred and fused
  (:func:`semmatch.experiments.real.chain_from_poses`), against the same chain at true poses.

The refusal thresholds of :data:`semmatch.poses.alignment.DEFAULT_CHECKS` are chosen on
validation scenes (:func:`simulate_validation_pairs`, seeds of ``val_seeds``) and the kitchen's
development frames, never on the evaluation scenes. ``python -m semmatch.experiments.alignment_study
--help`` runs each part; docs/recordings.md ("A person and a robot") has the results.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..io import read_tum, write_json, write_tum

__all__ = [
    "session_poses",
    "simulate_validation_pairs",
    "kitchen_study",
    "two_height_study",
    "pixels_near_map",
    "alignment_figure",
    "main",
]

#: the kitchen's two sessions (development frames only: 500-999 are held out)
KITCHEN_SESSIONS = {"person": slice(0, 250), "robot": slice(250, 500)}


def session_poses(seq, cache: Path, *, pose_graph: bool = False, downsample: int = 1,
                  progress: bool = True) -> tuple[np.ndarray, float]:
    """A recording's poses by its own RGB-D odometry from the identity, cached as TUM in ``cache``.

    Parameters
    ----------
    seq : sequence of Frame
        E.g. a :class:`~semmatch.io.recordings.SevenScenesSequence`.
    cache : path
        TUM file (written atomically); ``cache.with_suffix(".json")`` keeps the settings and the
        odometry's wall time. A cache of other settings or another frame count is recomputed.
    pose_graph, downsample, progress
        As :func:`semmatch.poses.odometry.estimate_poses` (hybrid residual, its default).

    Returns
    -------
    poses : ndarray (N, 4, 4)
        ``poses[0]`` is the identity.
    seconds : float
        Wall time of the odometry (of the run that wrote the cache).
    """
    from ..poses.odometry import estimate_poses

    cache = Path(cache)
    info_file = cache.with_suffix(".json")
    settings = {"pose_graph": bool(pose_graph), "downsample": int(downsample), "frames": len(seq)}
    if cache.is_file() and info_file.is_file():
        info = json.loads(info_file.read_text())
        if info.get("settings") == settings:
            return read_tum(cache)[1], float(info["seconds"])
    t0 = time.perf_counter()
    est = estimate_poses(seq, init_pose=np.eye(4), pose_graph=pose_graph, downsample=downsample, progress=progress)
    seconds = time.perf_counter() - t0
    write_tum(cache, np.asarray(getattr(seq, "timestamps", np.arange(len(est))), dtype=np.float64), est)
    write_json(info_file, {"settings": settings, "seconds": seconds})
    return read_tum(cache)[1], seconds


def simulate_validation_pairs(out: Path, seeds: Sequence[int], *, params: dict | None = None,
                              progress: bool = False) -> list[Path]:
    """Validation scenes for choosing the refusal thresholds: noisy person/robot pairs of ``val_seeds``.

    Seed ``s`` gives one scene of kind ``kinds[s % len(kinds)]`` (as the pipeline's validation
    split does); its person's (1.6 m) and robot's (0.2 m) tours rendered with the full
    profile's image size, frame count, camera step and Kinect-like noise (``poses.txt`` a
    drifting simulated odometry, ``poses_gt.txt`` the truth) into ``out/<scene>/upper_noisy`` and
    ``lower_noisy`` (the layout of the pipeline's scenes). Complete scenes are skipped.

    Parameters
    ----------
    out : path
    seeds : sequence of int
        Validation seeds (``val_seeds`` of params.yaml); never evaluation seeds.
    params : dict, optional
        A profile of params.yaml (:func:`semmatch.experiments.pipeline.load_params`; default ``full``).
    progress : bool

    Returns
    -------
    list of Path
        The scene folders.
    """
    from ..geometry import DEFAULT_INTRINSICS
    from ..sim import generate_scene
    from ..sim.noise import NoiseConfig
    from ..sim.simulate import simulate_pair
    from .pipeline import load_params

    p = params or load_params(profile="full")
    common, sim = p["common"], p["simulate"]
    bad = sorted(set(int(s) for s in seeds) - set(int(s) for s in common["val_seeds"]))
    if bad:
        raise ValueError(f"seeds {bad} are not validation seeds ({common['val_seeds']}); thresholds are "
                         "chosen on validation scenes only")
    kinds = list(common["kinds"])
    intrinsics = DEFAULT_INTRINSICS.scaled(sim["image_width"], sim["image_height"])
    dirs = []
    for s in seeds:
        scene = generate_scene(kinds[int(s) % len(kinds)], int(s))
        sdir = Path(out) / scene.name
        dirs.append(sdir)
        if all((sdir / n / "poses_gt.txt").is_file() for n in ("upper_noisy", "lower_noisy")):
            continue
        tmp = sdir / ".pair"
        simulate_pair(scene, tmp, n_frames=int(sim["n_frames_upper"]), seed=int(s), intrinsics=intrinsics,
                      noise=NoiseConfig.from_dict(sim["noise"]), overwrite=True, progress=progress,
                      camera_step=float(sim["camera_step"]))
        scene.save(sdir / "scene.ply")
        for n in ("upper", "lower"):
            (tmp / n).rename(sdir / f"{n}_noisy")
        tmp.rmdir()
    return dirs
