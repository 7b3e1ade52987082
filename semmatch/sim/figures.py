"""Figures of simulated frames: the README figure of an upper and a lower frame."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..io import save_figure
from ..labels import EVAL_CLASSES, NAMES, PALETTE, labels_to_colors

__all__ = ["frame_figure", "scene_frames_figure", "sequence_frames_figure", "dataset_summary", "routes_figure"]


def frame_figure(
    frames: Sequence,
    path: str | os.PathLike,
    *,
    titles: Sequence[str] | None = None,
    max_depth: float | None = None,
    dpi: int = 110,
) -> Path:
    """Save a grid of frames, one row each: RGB, depth, labels (with a category legend).

    Parameters
    ----------
    frames : sequence
        Objects with ``rgb``, ``depth`` and ``labels`` attributes
        (:class:`semmatch.io.Frame` or :class:`semmatch.sim.RenderResult`).
    path : path
        PNG to write (atomically).
    titles : sequence of str, optional
        Row titles (e.g. "upper 1.6 m", "lower 0.2 m").
    max_depth : float, optional
        Top of the depth colour scale (default: the largest depth shown).
    dpi : int

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        No frames, a frame without labels, or titles that do not match the frames.
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    frames = list(frames)
    if not frames:
        raise ValueError("frame_figure: no frames given")
    if titles is not None and len(titles) != len(frames):
        raise ValueError(f"frame_figure: {len(titles)} titles for {len(frames)} frames")
    for i, f in enumerate(frames):
        if getattr(f, "labels", None) is None:
            raise ValueError(f"frame_figure: frame {i} has no labels")
    vmax = max_depth or max(float(np.max(f.depth)) for f in frames) or 1.0
    h, w = frames[0].rgb.shape[:2]
    fig, axes = plt.subplots(len(frames), 3, figsize=(3 * 3.2, len(frames) * 3.2 * h / w + 0.9), squeeze=False)
    present = sorted(set().union(*[np.unique(f.labels).tolist() for f in frames]) - {0})
    for r, f in enumerate(frames):
        d = np.where(f.depth > 0, f.depth, np.nan)
        axes[r, 0].imshow(f.rgb)
        im = axes[r, 1].imshow(d, cmap="turbo", vmin=0, vmax=vmax)
        axes[r, 2].imshow(labels_to_colors(f.labels))
        for c, name in enumerate(("RGB", "depth (m)", "labels")):
            axes[r, c].set_xticks([])
            axes[r, c].set_yticks([])
            if r == 0:
                axes[r, c].set_title(name, fontsize=10)
        if titles is not None:
            axes[r, 0].set_ylabel(titles[r], fontsize=10)
        fig.colorbar(im, ax=axes[r, 1], fraction=0.035, pad=0.02)
    handles = [
        Patch(color=PALETTE[i] / 255.0, label=NAMES[i] + ("" if i in EVAL_CLASSES else "*")) for i in present
    ]
    fig.legend(handles=handles, loc="lower center", ncol=min(8, len(handles)), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    return save_figure(fig, path, dpi=dpi)


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
    from ..geometry import DEFAULT_INTRINSICS
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
    from ..labels import id_of

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

    import matplotlib.pyplot as plt

    from ..io import read_map, read_sequence, save_figure
    from ..labels import id_of
    from .procedural import generate_scene
    from .trajectory import free_space, tour_coverage

    scenes = [d for d in sorted(Path(split_dir).iterdir())
              if (d / "upper").is_dir() and (d / "lower").is_dir() and (d / "scene.ply").is_file()][:max_scenes]
    if not scenes:
        raise FileNotFoundError(f"{split_dir}: no scene with upper and lower sequences")
    cols = min(4, len(scenes))
    rows = -(-len(scenes) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.4 * rows), squeeze=False)
    styles = {"upper": ("#1f77b4", "-"), "lower": ("#ff7f0e", "-"), "lower_shared": ("#2ca02c", ":")}
    for ax, sd in zip(axes.flat, scenes):
        m = read_map(sd / "scene.ply")
        keep = (m.labels != id_of("floor")) & (m.labels != id_of("ceiling"))
        ax.scatter(m.points[keep, 0], m.points[keep, 1], s=0.2, c="0.75", rasterized=True)
        meta = json.loads((sd / "scene.json").read_text()) if (sd / "scene.json").is_file() else {}
        scene = generate_scene(meta["kind"], int(meta["seed"])) if "kind" in meta and "seed" in meta else None
        cover = []
        for name, (color, ls) in styles.items():
            if not (sd / name).is_dir():
                continue
            poses = read_sequence(sd / name).poses
            ax.plot(poses[:, 0, 3], poses[:, 1, 3], ls, color=color, lw=1.2, label=name)
            ax.plot(poses[0, 0, 3], poses[0, 1, 3], "o", color=color, ms=4)
            if scene is not None:
                fs = free_space(scene, float(np.median(poses[:, 2, 3]) - scene.meta.get("floor_z", 0.0)))
                cover.append(f"{name} {tour_coverage(fs, poses, radius):.0%}")
        ax.set_title(f"{sd.name}\n" + ", ".join(cover), fontsize=8)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in list(axes.flat)[len(scenes):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7, loc="lower left", framealpha=0.8)
    fig.suptitle(f"Camera tours\n(coverage: share of the free space within {radius:g} m of the path)", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)
