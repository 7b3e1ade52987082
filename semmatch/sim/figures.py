"""The simulator's figures (frames of a scene, camera tours) and a summary table of a generated dataset.

The frames and tours are gathered here; :mod:`semmatch.plots` draws them.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..io.labels import EVAL_CLASSES
from ..plots import frame_figure

__all__ = ["scene_frames_figure", "sequence_frames_figure", "dataset_summary", "routes_figure"]


def scene_frames_figure(
    scene,
    path: str | os.PathLike,
    *,
    heights: Sequence[float] = (1.6, 0.2),
    frame: int | None = None,
    n_frames: int = 60,
    seed: int = 0,
    intrinsics=None,
) -> Path:
    """Render one frame per height (upper and lower trajectories) of a scene and save
    :func:`frame_figure` of them (the README figure).

    Parameters
    ----------
    scene : Scene
    path : path
    heights : sequence of float
        Camera heights; the first is flown as the "upper", the others as "lower" paths.
    frame : int, optional
        Which frame of each ``n_frames`` trajectory to show; default: the one showing the
        most evaluation categories (of every 5th frame).
    n_frames, seed : int
    intrinsics : Intrinsics, optional
    """
    from ..io.geometry import DEFAULT_INTRINSICS
    from .render import Renderer
    from .trajectory import make_trajectory

    intr = intrinsics or DEFAULT_INTRINSICS
    if frame is not None and not 0 <= frame < n_frames:
        raise ValueError(f"frame {frame} outside 0..{n_frames - 1}")
    r = Renderer(scene, intr)
    frames, titles = [], []
    for i, h in enumerate(heights):
        kind = "upper" if i == 0 else "lower"
        poses = make_trajectory(scene, float(h), n_frames, seed=seed, kind=kind)
        if frame is not None:
            best = r.render(poses[frame])
        else:
            cands = [r.render(p) for p in poses[::5]]
            best = max(cands, key=lambda c: len(set(np.unique(c.labels).tolist()) & set(EVAL_CLASSES)))
        frames.append(best)
        titles.append(f"{kind} {h:.1f} m")
    return frame_figure(frames, path, titles=titles)


def _best_frame(seq, stride: int = 5):
    """The frame of a sequence showing the most evaluation categories (every ``stride``-th)."""
    best, score = None, -1
    for i in range(0, len(seq), max(1, stride)):
        lab = seq.read_labels(i)
        if lab is None:
            continue
        s = len(set(np.unique(lab).tolist()) & set(EVAL_CLASSES))
        if s > score:
            best, score = i, s
    if best is None:
        raise ValueError(f"{seq.path}: no labelled frame to show")
    return seq[best]


def sequence_frames_figure(
    scene_dir: str | os.PathLike,
    path: str | os.PathLike,
    *,
    sequences: Sequence[str] = ("upper", "lower"),
    stride: int = 5,
) -> Path:
    """:func:`frame_figure` of the written sequences of one scene folder (the README figure).

    For each sequence (``<scene_dir>/upper``, ``<scene_dir>/lower``) the frame showing the
    most evaluation categories is drawn, with the camera height in the row title.

    Raises
    ------
    FileNotFoundError, ValueError
        A missing or incomplete sequence, named.
    """
    from ..io import read_sequence

    scene_dir = Path(scene_dir)
    frames, titles = [], []
    for name in sequences:
        seq = read_sequence(scene_dir / name)
        f = _best_frame(seq, stride)
        frames.append(f)
        titles.append(f"{name} {f.pose[2, 3]:.1f} m (frame {f.index})")
    return frame_figure(frames, path, titles=titles)


def dataset_summary(root: str | os.PathLike, *, stride: int = 5):
    """One row per sequence under ``root/<split>/<scene>/``: frames, camera height, share of
    floor pixels and of void (no depth), categories seen (every ``stride``-th frame).

    Returns
    -------
    pandas.DataFrame
    """
    import pandas as pd

    from ..io import is_sequence, read_sequence
    from ..io.labels import id_of

    rows = []
    for seq_dir in sorted(Path(root).glob("*/*/*")):
        if not is_sequence(seq_dir):
            continue
        seq = read_sequence(seq_dir)
        labs = [seq.read_labels(i) for i in range(0, len(seq), max(1, stride))]
        labs = [x for x in labs if x is not None]
        allv = np.concatenate([x.reshape(-1) for x in labs]) if labs else np.zeros(0, np.uint8)
        rows.append({
            "split": seq_dir.parts[-3], "scene": seq_dir.parts[-2], "sequence": seq_dir.name,
            "frames": len(seq), "height_m": round(float(np.median(seq.poses[:, 2, 3])), 2),
            "floor_share": round(float((allv == id_of("floor")).mean()) if allv.size else 0.0, 3),
            "categories": int(len(set(np.unique(allv).tolist()) - {0})),
        })
    return pd.DataFrame(rows)


def routes_figure(split_dir: str | os.PathLike, path: str | os.PathLike, *, max_scenes: int = 12,
                  radius: float = 1.5) -> Path:
    """Floor plans of the scenes of a split with each camera's path, and how broadly each covers the room.

    Per scene (``<split_dir>/<scene>/``): the ground-truth mesh seen from above (walls and
    furniture as grey points), the ``upper`` and ``lower`` camera paths and, when present, the
    ``lower_shared`` ablation path; the title gives each tour's coverage
    (:func:`semmatch.sim.trajectory.tour_coverage`: share of the free space within ``radius``).

    Raises
    ------
    FileNotFoundError
        No scene with an upper and a lower sequence under ``split_dir``.
    """
    import json

    from ..io import read_map, read_sequence
    from ..io.labels import id_of
    from ..plots import floor_plans_figure
    from .procedural import generate_scene
    from .trajectory import free_space, tour_coverage

    scenes = [d for d in sorted(Path(split_dir).iterdir())
              if (d / "upper").is_dir() and (d / "lower").is_dir() and (d / "scene.ply").is_file()][:max_scenes]
    if not scenes:
        raise FileNotFoundError(f"{split_dir}: no scene with upper and lower sequences")
    plans = []
    for sd in scenes:
        m = read_map(sd / "scene.ply")
        keep = (m.labels != id_of("floor")) & (m.labels != id_of("ceiling"))
        meta = json.loads((sd / "scene.json").read_text()) if (sd / "scene.json").is_file() else {}
        scene = generate_scene(meta["kind"], int(meta["seed"])) if "kind" in meta and "seed" in meta else None
        paths, cover = {}, []
        for name in ("upper", "lower", "lower_shared"):
            if not (sd / name).is_dir():
                continue
            poses = read_sequence(sd / name).poses
            paths[name] = poses[:, :2, 3]
            if scene is not None:
                fs = free_space(scene, float(np.median(poses[:, 2, 3]) - scene.meta.get("floor_z", 0.0)))
                cover.append(f"{name} {tour_coverage(fs, poses, radius):.0%}")
        plans.append({"title": f"{sd.name}\n" + ", ".join(cover), "obstacles": m.points[keep, :2], "paths": paths})
    return floor_plans_figure(plans, path, suptitle=f"Camera tours\n(coverage: share of the free space within "
                                                    f"{radius:g} m of the path)")
