"""Figures made of images: frames (RGB, depth, labels), grids of label images and renders, floor plans."""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from ..io import save_figure
from ..io.labels import EVAL_CLASSES, NAMES, PALETTE, labels_to_colors

__all__ = ["frame_figure", "image_grid", "floor_plans_figure"]


def _palette_legend(fig, labels: Iterable[int], *, fontsize: float, mark_non_eval: bool = False) -> None:
    """A legend of category colours below the panels (``*`` marks categories not evaluated)."""
    from matplotlib.patches import Patch

    handles = [Patch(color=PALETTE[i] / 255.0, label=NAMES[i] + ("*" if mark_non_eval and i not in EVAL_CLASSES else ""))
               for i in sorted(labels)]
    fig.legend(handles=handles, loc="lower center", ncol=min(8, max(len(handles), 1)), fontsize=fontsize,
               frameon=False)


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
    present = set().union(*[np.unique(f.labels).tolist() for f in frames]) - {0}
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
    _palette_legend(fig, present, fontsize=8, mark_non_eval=True)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    return save_figure(fig, path, dpi=dpi)


def image_grid(
    images: Sequence[Sequence[np.ndarray]],
    path: str | os.PathLike,
    *,
    col_titles: Sequence[str] = (),
    row_titles: Sequence[str] = (),
    legend: Iterable[int] | None = None,
    suptitle: str = "",
    cell: tuple[float, float] = (2.6, 2.2),
    fontsize: float = 9,
    suptitle_fontsize: float | None = None,
    dpi: int = 110,
) -> Path:
    """Save a grid of images (RGB, or label images already in palette colours), one list per row.

    Parameters
    ----------
    images : sequence of sequences of uint8 (H, W, 3)
        Row by row; rows may be shorter than the longest (the rest stays empty).
    path : path
        Figure file (format from the suffix), written atomically.
    col_titles, row_titles : sequence of str
        Titles above the first row's panels and beside each row's first panel.
    legend : iterable of int, optional
        Category ids to list with their palette colours below the grid (None: no legend).
    suptitle : str
    cell : (width, height)
        Inches per panel.
    fontsize : float
        Of the titles (the legend's is two points smaller).
    suptitle_fontsize : float, optional
    dpi : int

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        No images, or more column titles than columns.
    """
    import matplotlib.pyplot as plt

    rows = [list(r) for r in images]
    cols = max((len(r) for r in rows), default=0)
    if not rows or cols == 0:
        raise ValueError("image_grid: no images given")
    if len(col_titles) > cols:
        raise ValueError(f"image_grid: {len(col_titles)} column titles for {cols} columns")
    extra = 0.6 if legend is not None or suptitle else 0.0
    fig, axes = plt.subplots(len(rows), cols, figsize=(cell[0] * cols, cell[1] * len(rows) + extra), squeeze=False)
    for r, row in enumerate(rows):
        for c in range(cols):
            ax = axes[r][c]
            ax.set_xticks([])
            ax.set_yticks([])
            if c >= len(row):
                ax.axis("off")
                continue
            ax.imshow(row[c])
            if r == 0 and c < len(col_titles):
                ax.set_title(col_titles[c], fontsize=fontsize)
        if r < len(row_titles):
            axes[r][0].set_ylabel(row_titles[r], fontsize=fontsize)
    bottom = 0.0
    if legend is not None:
        _palette_legend(fig, legend, fontsize=fontsize - 2)
        bottom = 0.08
    if suptitle:
        fig.suptitle(suptitle, fontsize=suptitle_fontsize)
    fig.tight_layout(rect=(0, bottom, 1, 1))
    return save_figure(fig, path, dpi=dpi)


def floor_plans_figure(
    plans: Sequence[Mapping],
    path: str | os.PathLike,
    *,
    suptitle: str = "",
    cols: int = 4,
) -> Path:
    """Floor plans seen from above: the scene's obstacles as grey points and camera paths on top.

    Parameters
    ----------
    plans : sequence of mappings
        One per panel: ``title`` (str), ``obstacles`` (float (N, 2) x/y points), ``paths``
        (mapping name -> float (M, 2) x/y positions, in drawing order). The paths ``upper``,
        ``lower`` and ``lower_shared`` have fixed colours and line styles.
    path : path
        Figure file, written atomically.
    suptitle : str
    cols : int
        Panels per row (at most).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        No plans.
    """
    import matplotlib.pyplot as plt

    if not plans:
        raise ValueError("floor_plans_figure: no plans given")
    cols = max(1, min(int(cols), len(plans)))
    rows = -(-len(plans) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.4 * rows), squeeze=False)
    styles = {"upper": ("#1f77b4", "-"), "lower": ("#ff7f0e", "-"), "lower_shared": ("#2ca02c", ":")}
    for ax, plan in zip(axes.flat, plans):
        obstacles = np.asarray(plan["obstacles"], dtype=np.float64).reshape(-1, 2)
        ax.scatter(obstacles[:, 0], obstacles[:, 1], s=0.2, c="0.75", rasterized=True)
        for name, xy in plan["paths"].items():
            color, ls = styles.get(name, (None, "-"))
            xy = np.asarray(xy, dtype=np.float64)
            (line,) = ax.plot(xy[:, 0], xy[:, 1], ls, color=color, lw=1.2, label=name)
            ax.plot(xy[0, 0], xy[0, 1], "o", color=line.get_color(), ms=4)
        ax.set_title(plan.get("title", ""), fontsize=8)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in list(axes.flat)[len(plans):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7, loc="lower left", framealpha=0.8)
    if suptitle:
        fig.suptitle(suptitle, fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)
