"""Is DBSCAN more sensitive to depth noise than the other transfer methods? (07, claim C13-noise)

The paper explains DBSCAN's drop on its real recordings by "the lack of robustness to noise"
(§4.4). This study tests that explanation with everything else fixed: on the clean synthetic data
of the pipeline (ground-truth upper map, lower frames at their true poses), the robot's depth
images get Gaussian depth noise of the simulator's Kinect-like model
(:func:`semmatch.sim.noise.noisy_depth`: ``sigma = a + b z^2``, the profile's ``depth_a`` and
``depth_b``) scaled by each ``level`` (0 = clean). Every method transfers labels with the noisy
depth; the labels are fused at the **clean** depth and true poses and scored against the lower
reference, so a score drops only because the method's labels got worse.

Per scene and method, ``drop = score(level 0) - score(top level)``; the claim "DBSCAN is the
most sensitive" compares DBSCAN's drop with each other method's on paired scenes
(:func:`noise_drops`, judged by :func:`semmatch.experiments.claims.check_claims`).
"""

from __future__ import annotations

import dataclasses
import tempfile
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..evaluate.metrics import MEASURES
from .layout import GT, Layout, model_name
from .misregistration import _scene_dirs, clean_scene_inputs
from .synthetic import eval_grid_origin

__all__ = ["KINECT_DEPTH_A", "KINECT_DEPTH_B", "depth_noise_study", "noise_drops"]

#: the simulator's Kinect-like depth noise (m and 1/m; the profiles' ``noise.depth_a/b``)
KINECT_DEPTH_A, KINECT_DEPTH_B = 0.0012, 0.0019


def depth_noise_study(
    data_root: str | Path,
    methods: Sequence[str],
    *,
    levels: Sequence[float] = (0.0, 1.0, 2.0, 4.0),
    scenes: int | Sequence[str] | None = None,
    depth_a: float = KINECT_DEPTH_A,
    depth_b: float = KINECT_DEPTH_B,
    voxel_size: float = 0.04,
    eval_voxel_size: float = 0.05,
    seed: int = 0,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    method_settings: Mapping[str, Mapping] | None = None,
) -> pd.DataFrame:
    """Scores of every transfer method when the robot's depth gets more and more noise.

    Parameters
    ----------
    data_root : path
        A pipeline data root with, per evaluation scene, the ground-truth upper map (03), the
        clean lower sequence (01) and the lower reference (05).
    methods : sequence of str
        Transfer methods.
    levels : sequence of float
        Multiples of the Kinect-like depth noise (0: clean); finite and >= 0.
    scenes : int, sequence of str or None
        None: every evaluation scene; an int ``n``: the first ``n``; or scene ids.
    depth_a, depth_b : float
        The noise model at level 1 (``sigma = a + b z^2``, m).
    voxel_size, eval_voxel_size : float
        Fusion and evaluation voxel sizes (m).
    seed : int
        Seed of the noise: each scene and level draws from ``(seed, scene id, level)``; every
        method sees the same noisy frames.
    jobs : int
        Scenes as tasks of :func:`semmatch.runtime.engine.map_tasks` on ``jobs`` local processes.
    scheduler : str, optional
        Dask scheduler address (default ``SEMMATCH_SCHEDULER``; none: local).
    progress : bool
    method_settings : mapping, optional
        The methods' parameters, ``{method: {parameter: value}}`` (the notebooks' ``slic_2d``).

    Returns
    -------
    DataFrame
        scene, method, level, depth_sigma_2m (the noise's standard deviation at 2 m), the four
        measures and coverage.

    Raises
    ------
    ValueError
        A negative or non-finite level, or no level.
    FileNotFoundError
        A missing input (naming the file and the stage that writes it).
    """
    lv = [float(v) for v in levels]
    if not lv or any(not np.isfinite(v) or v < 0 for v in lv):
        raise ValueError(f"levels must be finite numbers >= 0 (at least one), got {list(levels)}")
    layout = Layout(data_root)
    rows = layout.map_scenes(_depth_noise_scene, tuple(methods), tuple(dict.fromkeys(lv)),
                             dict(depth_a=float(depth_a), depth_b=float(depth_b), voxel_size=voxel_size,
                                  eval_voxel_size=eval_voxel_size, seed=int(seed),
                                  method_settings=dict(method_settings or {})),
                             scenes=_scene_dirs(layout, scenes), jobs=jobs, scheduler=scheduler,
                             desc="depth-noise scenes", progress=progress)
    cols = ["scene", "method", "level", "depth_sigma_2m", *MEASURES, "coverage"]
    return pd.DataFrame(rows, columns=cols)


def _depth_noise_scene(data_root: str, methods: tuple[str, ...], levels: tuple[float, ...], o: dict,
                       sid: str) -> list[dict]:
    """The score rows of one scene (a task of :func:`depth_noise_study`)."""
    from ..evaluate.metrics import compare
    from ..fusion import reconstruct_many
    from ..sim.noise import NoiseConfig, noisy_depth
    from ..transfer import settings_for, transfer_sequence

    layout = Layout(data_root)
    _, lower, reference, index = clean_scene_inputs(layout, sid, o["eval_voxel_size"])
    labelings = []  # (level, method, labels folder, coverage)
    with tempfile.TemporaryDirectory(prefix=f".depth_noise_{sid}.", dir=layout.root) as tmp:
        for level in levels:
            noisy = lower
            if level > 0:
                cfg = NoiseConfig(depth_a=level * o["depth_a"], depth_b=level * o["depth_b"])
                rng = np.random.default_rng([o["seed"], zlib.crc32(sid.encode()), int(round(level * 1000))])
                noisy = [dataclasses.replace(f, depth=noisy_depth(f.depth, cfg, rng)) for f in lower]
            for method in methods:
                out = Path(tmp) / f"level{level:g}" / method
                res = transfer_sequence(method, noisy, index, out, poses=lower.poses, progress=False,
                                        **settings_for(method, o["method_settings"]))
                labelings.append((level, method, out, res["coverage"]))
        # every labeling fused at the clean depth and true poses: only the labels differ
        maps = reconstruct_many(lower, [j[2] for j in labelings], o["voxel_size"])
    rows = []
    for (level, method, _, cov), pred in zip(labelings, maps, strict=True):
        s = compare(reference, pred, voxel_size=o["eval_voxel_size"], grid_origin=eval_grid_origin(o["eval_voxel_size"]))
        rows.append(dict(scene=sid, method=method, level=level,
                         depth_sigma_2m=level * (o["depth_a"] + 4.0 * o["depth_b"]),
                         **{k: float(s[k]) for k in MEASURES}, coverage=float(cov)))
    return rows


def noise_drops(study: pd.DataFrame, *, model: str = model_name(GT)) -> pd.DataFrame:
    """Per scene and method, each measure's drop from the clean level to the noisiest one.

    Parameters
    ----------
    study : DataFrame
        :func:`depth_noise_study`'s result.
    model : str, optional
        The ``model`` column of the result (the upper map's source: ``"ground truth"``).

    Returns
    -------
    DataFrame
        scene, model, method and, per measure, ``score(lowest level) - score(highest level)``
        (positive: the noise hurt), in the layout :func:`semmatch.experiments.claims.check_claims`
        takes as its ``noise`` table.
    """
    if study.empty:
        raise ValueError("noise_drops: the study has no rows")
    lo, hi = study["level"].min(), study["level"].max()
    if lo == hi:
        raise ValueError(f"noise_drops: one noise level only ({lo:g}); a drop needs two")
    measures = [m for m in MEASURES if m in study.columns]
    a = study[study["level"] == lo].set_index(["scene", "method"])[measures]
    b = study[study["level"] == hi].set_index(["scene", "method"])[measures]
    out = (a - b).reset_index()
    out.insert(1, "model", model)
    return out
