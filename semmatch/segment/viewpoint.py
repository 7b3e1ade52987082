"""The viewpoint gap (paper Fig. 3): segmentation accuracy against camera height.

One path per evaluation scene is flown at every height (0.2, 0.4, ..., 1.6 m) with the camera
tilting up and down by 20 deg (:func:`semmatch.sim.make_sweep_trajectories`); every network
labels the rendered views and is scored against the ground truth with the 2D pixel measures of
:mod:`semmatch.segment.scores` (mIoU over classes 1..10 and the pixel analogues of the paper's
Jaccard, Sorensen, Color Acc. and Mean Acc.). Also: the training-curve figure.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..evaluate.metrics import MEASURES
from ..io import read_sequence
from ..io.geometry import DEFAULT_INTRINSICS, Intrinsics
from ..runtime.progress import tqdm
from .scores import confusion, scores

__all__ = [
    "HEIGHTS",
    "viewpoint_gap",
    "viewpoint_gap_sequences",
    "gap_summary",
]

#: the paper's camera heights (metres)
HEIGHTS: tuple[float, ...] = (0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6)
_COLUMNS = ["miou", "pixel_acc", *MEASURES]


def _predict_labels(model, rgb: np.ndarray, depth: np.ndarray) -> np.ndarray:
    if hasattr(model, "predict_labels_batch"):
        return model.predict_labels_batch(rgb, depth if getattr(model, "uses_depth", False) else None)
    return np.stack([np.asarray(model.predict(r)).argmax(-1) for r in rgb]).astype(np.uint8)


def _accumulate(models: Mapping, batches: Iterable[tuple[float, str, np.ndarray, np.ndarray, np.ndarray]],
                per_scene: bool) -> tuple[dict, dict]:
    """Confusion matrices (int64) and frame counts per (model, scene or ``all``, height)."""
    if not models:
        raise ValueError("viewpoint gap: no models given")
    conf: dict[tuple[str, str, float], np.ndarray] = {}
    frames: dict[tuple[str, str, float], int] = {}
    for height, scene, rgb, depth, labels in batches:
        for name, model in models.items():
            pred = _predict_labels(model, rgb, depth)
            key = (name, scene if per_scene else "all", round(float(height), 3))
            c = confusion(labels, pred)
            conf[key] = conf[key] + c if key in conf else c
            frames[key] = frames.get(key, 0) + len(rgb)
    return conf, frames


def _rows(conf: dict, frames: dict) -> pd.DataFrame:
    """One row per (model, scene, height) from :func:`_accumulate`'s counts."""
    rows = []
    for (name, scene, height), c in conf.items():
        s = scores(c)
        rows.append(dict(model=name, scene=scene, height=height, n_frames=frames[(name, scene, height)],
                         **{k: s[k] for k in _COLUMNS}))
    return pd.DataFrame(rows).sort_values(["model", "scene", "height"]).reset_index(drop=True)


def _score(models: Mapping, batches: Iterable[tuple[float, str, np.ndarray, np.ndarray, np.ndarray]],
           per_scene: bool) -> pd.DataFrame:
    """Accumulate confusion matrices per (model, scene, height) and turn them into rows."""
    return _rows(*_accumulate(models, batches, per_scene))


def viewpoint_gap(
    models: Mapping,
    scenes: Sequence,
    *,
    heights: Sequence[float] = HEIGHTS,
    n_frames: int = 40,
    tilt_deg: float = 20.0,
    tilt_period: int | None = None,
    intrinsics: Intrinsics | None = None,
    seed: int = 0,
    batch_size: int = 8,
    per_scene: bool = False,
    progress: bool = True,
) -> pd.DataFrame:
    """Accuracy of each network against camera height on (evaluation) scenes.

    Parameters
    ----------
    models : mapping name -> Segmenter
        Networks (anything with ``predict_labels_batch`` or ``predict``).
    scenes : sequence of Scene
        Evaluation scenes (their seeds must be disjoint from the training scenes).
    heights : sequence of float
        Camera heights in metres (default 0.2, 0.4, ..., 1.6).
    n_frames : int
        Frames per (scene, height); the same path at every height.
    tilt_deg : float
        Up/down tilt amplitude of the camera.
    tilt_period : int, optional
        Frames per tilt cycle; default ``n_frames`` (one whole up-and-down cycle per path).
    intrinsics : Intrinsics, optional
        Render camera; default the paper's camera scaled to 320x240.
    seed : int
        Trajectory seed (scene ``i`` uses ``seed + i``).
    batch_size : int
    per_scene : bool
        One row per (model, scene, height) instead of pooling the scenes.
    progress : bool

    Returns
    -------
    pandas.DataFrame
        Columns ``model, scene, height, n_frames, miou, pixel_acc, jaccard, sorensen,
        color_acc, mean_acc`` (pixel measures over classes 1..10).
    """
    from ..sim import Renderer, make_sweep_trajectories

    if not scenes:
        raise ValueError("viewpoint_gap: no scenes given")
    hs = tuple(float(h) for h in heights)
    if not hs or min(hs) <= 0:
        raise ValueError(f"heights must be positive, got {heights}")
    intr = intrinsics or DEFAULT_INTRINSICS.scaled(320, 240)
    period = max(2, int(tilt_period or n_frames))

    def batches() -> Iterator:
        bar = tqdm(total=len(scenes) * len(hs) * n_frames, desc="viewpoint gap", disable=not progress)
        for i, scene in enumerate(scenes):
            sweep = make_sweep_trajectories(scene, hs, n_frames, tilt_deg=tilt_deg, tilt_period=period,
                                            seed=seed + i)
            renderer = Renderer(scene, intr)
            for h in hs:
                poses = np.asarray(sweep[h])
                for j in range(0, len(poses), batch_size):
                    rs = [renderer.render(p) for p in poses[j : j + batch_size]]
                    bar.update(len(rs))
                    yield (h, scene.name, np.stack([r.rgb for r in rs]), np.stack([r.depth for r in rs]),
                           np.stack([r.labels for r in rs]))
        bar.close()

    return _score(models, batches(), per_scene)


def viewpoint_gap_sequences(
    models: Mapping,
    sweeps: Mapping[float, Sequence[str | os.PathLike]],
    *,
    batch_size: int = 8,
    per_scene: bool = False,
    frame_step: int = 1,
    progress: bool = True,
    jobs: int = 1,
    scheduler: str | None = None,
) -> pd.DataFrame:
    """:func:`viewpoint_gap` on sequence folders written by ``semmatch simulate``.

    Parameters
    ----------
    models : mapping name -> Segmenter
    sweeps : mapping height -> list of sequence folders
        E.g. ``{0.2: ["data/full/scenes/eval/s1001/h020", ...], ...}``; every frame needs
        ground-truth labels. The scene name is the folder's parent name.
    batch_size, per_scene, progress : see :func:`viewpoint_gap`.
    frame_step : int
        Every ``frame_step``-th frame of each sequence (1: all), the first included.
    jobs : int
        Scenes (all their heights) run as tasks of :func:`semmatch.runtime.engine.map_tasks` on ``jobs``
        local worker processes (1: in this process; the models are pickled to the workers). The
        confusion counts are integers, summed over scenes in the same way wherever they ran.
    scheduler : str, optional
        Dask scheduler address to run the scenes on (default ``SEMMATCH_SCHEDULER``; none: local).

    Returns
    -------
    pandas.DataFrame
        As :func:`viewpoint_gap`.
    """
    from functools import partial

    from ..runtime.engine import map_tasks

    if not models:
        raise ValueError("viewpoint gap: no models given")
    if int(frame_step) < 1:
        raise ValueError(f"viewpoint gap: frame_step must be >= 1, got {frame_step}")
    by_scene: dict[str, list[tuple[float, str]]] = {}
    for h, paths in sweeps.items():
        for path in paths:
            by_scene.setdefault(Path(path).parent.name, []).append((float(h), str(path)))
    task = partial(_sweep_counts, dict(models), int(batch_size), bool(per_scene), int(frame_step))
    parts = map_tasks(task, list(by_scene.values()), jobs=jobs, scheduler=scheduler, desc="viewpoint gap (scenes)",
                      progress=progress)
    conf: dict = {}
    frames: dict = {}
    for c, f in parts:
        for key, m in c.items():
            conf[key] = conf[key] + m if key in conf else m
            frames[key] = frames.get(key, 0) + f[key]
    if not conf:
        raise ValueError("viewpoint gap: no frames in the sweeps")
    return _rows(conf, frames)


def _sweep_counts(models: dict, batch_size: int, per_scene: bool, frame_step: int,
                  sweeps: list[tuple[float, str]]) -> tuple[dict, dict]:
    """Confusions and frame counts of one scene's height sweeps (a task of :func:`viewpoint_gap_sequences`)."""

    def batches() -> Iterator:
        for h, path in sweeps:
            seq = read_sequence(path)
            if not seq.has_labels:
                raise ValueError(f"{path}: the sequence has no ground-truth labels")
            keep = range(0, len(seq), frame_step)
            for j in range(0, len(keep), batch_size):
                fr = [seq[i] for i in keep[j : j + batch_size]]
                yield (h, Path(path).parent.name, np.stack([f.rgb for f in fr]),
                       np.stack([f.depth for f in fr]), np.stack([f.labels for f in fr]))

    return _accumulate(models, batches(), per_scene)


def gap_summary(df: pd.DataFrame, *, low: float = 0.2, high: float = 1.6, metric: str = "miou") -> pd.DataFrame:
    """Per model: ``metric`` at the lowest and highest camera and their difference (the gap)."""
    pooled = df.groupby(["model", "height"], as_index=False)[metric].mean()
    piv = pooled.pivot(index="model", columns="height", values=metric)
    for h in (low, high):
        if round(h, 3) not in piv.columns:
            raise ValueError(f"gap_summary: no rows at height {h} m (have {list(piv.columns)})")
    out = pd.DataFrame({f"{metric}_{low:g}m": piv[round(low, 3)], f"{metric}_{high:g}m": piv[round(high, 3)]})
    out["gap"] = out.iloc[:, 1] - out.iloc[:, 0]
    return out.reset_index()
