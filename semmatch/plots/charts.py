"""Charts: curves against height or perturbation, bars per method, confusion matrices, training curves."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..io import save_figure

__all__ = ["confusion_figure", "plot_height_study", "plot_misregistration", "plot_depth_noise", "plot_panoptic", "plot_speed",
           "plot_support", "plot_table", "plot_training_curves", "plot_measure_bars", "plot_per_scene_change"]


def confusion_figure(results: dict[str, dict], path: str | Path) -> Path:
    """Row-normalised confusion matrices (one panel per prediction), written atomically."""
    import matplotlib.pyplot as plt

    from ..io.labels import NAMES

    n = len(results)
    fig, axes = plt.subplots(1, n, figsize=(5.2 * n, 4.8), squeeze=False)
    for ax, (name, s) in zip(axes[0], results.items()):
        conf = np.asarray(s["confusion"], dtype=np.float64)
        rows = conf.sum(axis=1, keepdims=True)
        norm = np.divide(conf, rows, out=np.zeros_like(conf), where=rows > 0)
        names = [NAMES[c] for c in s["classes"]]
        im = ax.imshow(norm, vmin=0, vmax=1, cmap="Blues")
        ax.set_xticks(range(len(names)), names, rotation=60, ha="right", fontsize=8)
        ax.set_yticks(range(len(names)), names, fontsize=8)
        ax.set_xlabel("predicted")
        ax.set_ylabel("ground truth")
        ax.set_title(f"{name}\nMean Acc. {s['mean_acc']:.3f}", fontsize=9)
        for (i, j), v in np.ndenumerate(norm):
            if conf[i, j]:
                ax.text(j, i, f"{v:.2f}", ha="center", va="center", fontsize=6,
                        color="white" if v > 0.5 else "black")
        fig.colorbar(im, ax=ax, fraction=0.046)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_height_study(summary: pd.DataFrame, path: str | Path, *, metrics: Sequence[str] = ("mean_acc", "miou"),
                      title: str = "Segmentation accuracy against camera height (tilting ±20°), "
                                   "mean over scenes with 95% interval") -> Path:
    """Fig. 3: each measure against camera height, one line per model, with its interval where given.

    Parameters
    ----------
    summary : DataFrame
        Columns ``model``, ``height`` and each of ``metrics`` (one row per model and height, e.g.
        :func:`semmatch.experiments.summaries.summarize_over_scenes`), optionally ``<metric>_lo`` and
        ``<metric>_hi`` (drawn as a band).
    path : path
        Figure file, written atomically.
    metrics : sequence of str
        One panel each.
    title : str

    Returns
    -------
    Path
    """
    import matplotlib.pyplot as plt

    names = {"mean_acc": "Mean Acc.", "miou": "mIoU (classes 1..10)"}
    fig, axes = plt.subplots(1, len(metrics), figsize=(4.8 * len(metrics), 3.6), squeeze=False)
    for ax, m in zip(axes[0], metrics, strict=True):
        for model, g in summary.groupby("model", sort=False):
            g = g.sort_values("height")
            ax.plot(g["height"], g[m], marker="o", label=str(model))
            if f"{m}_lo" in g:
                ax.fill_between(g["height"], g[f"{m}_lo"], g[f"{m}_hi"], alpha=0.2)
        ax.set_xlabel("camera height [m]")
        ax.set_ylabel(names.get(m, m))
        ax.grid(alpha=0.3)
    axes[0][-1].legend(title="network", fontsize=7, title_fontsize=8, loc="lower right")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def _require_columns(df: pd.DataFrame, need: set[str], fn: str) -> None:
    """Refuse an empty table or one without the columns ``need`` (naming ``fn``)."""
    if df.empty or not need <= set(df.columns):
        raise ValueError(f"{fn} needs a non-empty table with {sorted(need)}, "
                         f"got columns {list(df.columns)} and {len(df)} rows")


def _method_curves(ax, df: pd.DataFrame, x: str, measure: str, *, scale: float, confidence: float,
                   alpha: float) -> None:
    """One line per method: the mean of ``measure`` over scenes at each ``x`` (times ``scale``),
    with its t-interval band (the analysis plan's interval)."""
    from ..evaluate.stats import stratified_t_ci

    for method, g in df.groupby("method", sort=False):
        xs = sorted(g[x].unique())
        stats = np.array([stratified_t_ci(g.loc[g[x] == v, measure].to_numpy(), confidence=confidence) for v in xs])
        xv = np.asarray(xs) * scale
        (line,) = ax.plot(xv, stats[:, 0], marker="o", label=method)
        ax.fill_between(xv, stats[:, 1], stats[:, 2], color=line.get_color(), alpha=alpha)


def plot_misregistration(df: pd.DataFrame, path: str | Path, *, measure: str = "mean_acc",
                         confidence: float = 0.95, seed: int = 0) -> Path:
    """Two panels: ``measure`` against translation and against rotation, one line per method.

    Each point is the mean over scenes with a ``confidence`` t-interval band over scenes (the
    analysis plan's interval, :func:`semmatch.evaluate.stats.stratified_t_ci`); the unperturbed case
    starts both series.

    Parameters
    ----------
    df : DataFrame
        :func:`misregistration_study`'s result.
    path : path
        Figure file (format from the suffix), written atomically.
    measure : str
        A column of ``df`` (default Mean Acc.).
    confidence : float
    seed : int
        Unused (kept for callers of the former bootstrap band).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        An empty ``df`` or a missing column.
    """
    import matplotlib.pyplot as plt

    _require_columns(df, {"method", "translation_m", "rotation_deg", measure}, "plot_misregistration")
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    series = (("translation_m", "rotation_deg", 100.0, "translation (cm)"),
              ("rotation_deg", "translation_m", 1.0, "rotation (degrees)"))
    for ax, (x, other, scale, label) in zip(axes, series, strict=True):
        _method_curves(ax, df[df[other] == 0], x, measure, scale=scale, confidence=confidence, alpha=0.2)
        ax.set_xlabel(label)
        ax.grid(alpha=0.3)
    n = df["scene"].nunique() if "scene" in df.columns else 0
    axes[0].set_ylabel(f"{measure} (mean over {n} scenes, {confidence:.0%} t interval)")
    axes[0].set_title("map translated")
    axes[1].set_title("map rotated about its centroid")
    axes[1].legend(fontsize="small")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_depth_noise(df: pd.DataFrame, path: str | Path, *, measure: str = "mean_acc",
                     confidence: float = 0.95) -> Path:
    """``measure`` of every method against the depth-noise level (mean over scenes, t band).

    Parameters
    ----------
    df : DataFrame
        :func:`semmatch.experiments.depth_noise.depth_noise_study`'s result.
    path : path
        Figure file (format from the suffix), written atomically.
    measure : str
        A column of ``df`` (default Mean Acc.).
    confidence : float
        Level of the band (t interval over scenes).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        An empty ``df`` or a missing column.
    """
    import matplotlib.pyplot as plt

    _require_columns(df, {"method", "level", "depth_sigma_2m", measure}, "plot_depth_noise")
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    _method_curves(ax, df, "depth_sigma_2m", measure, scale=100.0, confidence=confidence, alpha=0.15)
    n = df["scene"].nunique() if "scene" in df.columns else 0
    ax.set_xlabel("depth noise: standard deviation at 2 m (cm)")
    ax.set_ylabel(f"{measure} (mean over {n} scenes, {confidence:.0%} t interval)")
    ax.set_title("labels transferred from noisy depth, fused at clean depth")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_panoptic(summary: pd.DataFrame, path: str | Path, *, measure: str = "pq_things") -> Path:
    """Grouped bars of ``measure`` per method and upper-map source, with 95 % intervals."""
    import matplotlib.pyplot as plt

    sources = list(dict.fromkeys(summary["source"]))
    methods = list(dict.fromkeys(summary["method"]))
    fig, ax = plt.subplots(figsize=(1.6 + 1.3 * len(methods), 3.6))
    w = 0.8 / max(len(sources), 1)
    for k, s in enumerate(sources):
        sel = summary[summary["source"] == s].set_index("method").reindex(methods)
        x = np.arange(len(methods)) + (k - (len(sources) - 1) / 2) * w
        err = np.vstack([sel[measure] - sel[f"{measure}_lo"], sel[f"{measure}_hi"] - sel[measure]])
        ax.bar(x, sel[measure], w, yerr=err, capsize=2, label=s)
    ax.set_xticks(np.arange(len(methods)), methods, rotation=20)
    ax.set_ylabel(measure.replace("_", " "))
    ax.set_ylim(0, 1)
    ax.legend(title="upper map", fontsize=8)
    ax.set_title("Panoptic transfer into the robot's map (mean over scenes, 95 % CI)")
    return save_figure(fig, path)


def plot_speed(df: pd.DataFrame, path: str | Path) -> Path:
    """Bar chart (log scale) of our FPS beside the paper's, per method."""
    import matplotlib.pyplot as plt

    x = np.arange(len(df))
    fig, ax = plt.subplots(figsize=(6.5, 3.4))
    ax.bar(x - 0.2, df["fps"], 0.4, label="semmatch (this machine, 1 process)", color="#3b75af")
    ax.bar(x + 0.2, df["paper_fps"], 0.4, label="paper Table 1 (server CPU + GPUs)", color="#bbbbbb")
    ref = df.attrs.get("reference_fps")
    if ref:
        ax.axhline(ref, color="k", ls="--", lw=1, label=f"reference closest-point backend ({ref:.1f} FPS)")
    ax.set_yscale("log")
    ax.set_xticks(x, df["method"], rotation=20, ha="right")
    ax.set_ylabel("frames per second (640x480)")
    ax.legend(fontsize=7)
    ax.grid(axis="y", alpha=0.3, which="both")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_table(df: pd.DataFrame, path: str | Path, *, title: str, methods: Sequence[str]) -> Path:
    """Bar chart of Mean Acc. per upper map and method with 95 % intervals (``mean_acc_lo/hi``
    when present) and the paper's values as markers."""
    import matplotlib.pyplot as plt

    models = list(dict.fromkeys(df["model"]))
    order = ["upper", "lower", *methods, "fused"]
    fig, axes = plt.subplots(1, len(models), figsize=(4.2 * len(models), 3.6), sharey=True, squeeze=False)
    for ax, model in zip(axes[0], models, strict=True):
        sub = df[df["model"] == model].set_index("method")
        names = [m for m in order if m in sub.index]
        x = np.arange(len(names))
        colors = ["#999999" if n in ("upper", "lower") else "#d08c2f" if n == "fused" else "#3b75af" for n in names]
        mean = sub.loc[names, "mean_acc"].to_numpy(dtype=float)
        err = None
        if "mean_acc_lo" in sub.columns:
            lo, hi = sub.loc[names, "mean_acc_lo"].to_numpy(dtype=float), sub.loc[names, "mean_acc_hi"].to_numpy(dtype=float)
            err = np.vstack([mean - lo, hi - mean])
        ax.bar(x, mean, color=colors, yerr=err, capsize=3, label="semmatch (95% interval)")
        if "paper_mean_acc" in sub.columns:
            ax.plot(x, sub.loc[names, "paper_mean_acc"], "k_", markersize=18, mew=2, label="paper")
        ax.set_xticks(x, names, rotation=45, ha="right")
        ax.set_title(model)
        ax.set_ylim(0, 1)
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel("Mean Acc.")
    axes[0][0].legend(loc="lower left", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)



def plot_support(support: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Bars of the share of the robot's pixels that the person's map supports, per scene and route.

    Parameters
    ----------
    support : DataFrame
        Columns ``scene``, ``route``, ``support`` (:func:`semmatch.experiments.synthetic.support_table`).
    path : path
        Figure file, written atomically.

    Returns
    -------
    Path
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(max(5, 0.5 * support["scene"].nunique()), 3))
    support.pivot(index="scene", columns="route", values="support").plot.bar(ax=ax)
    ax.set_ylabel("share of robot pixels supported")
    ax.set_ylim(0, 1)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_training_curves(histories: Mapping[str, Sequence[Mapping]], path: str | os.PathLike) -> Path:
    """Training loss and validation mIoU against step, one line per network.

    Parameters
    ----------
    histories : mapping name -> list of dicts
        Each network's evaluations as :func:`semmatch.segment.train` stores them (``step``,
        ``train_loss``, ``val_miou``); :func:`semmatch.segment.training_histories` reads them
        from checkpoints.
    path : path
        Figure file, written atomically.

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        A network without history.
    """
    import matplotlib.pyplot as plt

    fig, (a0, a1) = plt.subplots(1, 2, figsize=(9.5, 3.6))
    for name, hist in histories.items():
        if not hist:
            raise ValueError(f"{name}: no training history")
        h = pd.DataFrame(list(hist))
        a0.plot(h["step"], h["train_loss"], marker=".", label=name)
        a1.plot(h["step"], h["val_miou"], marker=".", label=name)
    a0.set(xlabel="step", ylabel="training loss (weighted CE)", yscale="log")
    a1.set(xlabel="step", ylabel="validation mIoU (classes 1..10)", ylim=(0, 1))
    for a in (a0, a1):
        a.grid(alpha=0.3)
        a.legend()
    fig.tight_layout()
    return save_figure(fig, path, dpi=130, bbox_inches="tight")


def plot_measure_bars(table: pd.DataFrame, path: str | os.PathLike, *, index: str, columns: Sequence[str],
                      title: str = "", ylim: tuple[float, float] | None = (0.0, 1.0)) -> Path:
    """Grouped bars: one group per row of ``table`` (named by its ``index`` column), one bar per column.

    Parameters
    ----------
    table : DataFrame
    path : path
        Figure file, written atomically.
    index : str
        The column naming the groups (e.g. ``model``).
    columns : sequence of str
        The measures to draw side by side (e.g. ``mean_acc``, ``paper_mean_acc``).
    title : str
    ylim : (low, high) or None

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        A column that ``table`` lacks.
    """
    import matplotlib.pyplot as plt

    missing = [c for c in (index, *columns) if c not in table.columns]
    if missing:
        raise ValueError(f"plot_measure_bars: no column {missing} in the table (columns: {list(table.columns)})")
    fig, ax = plt.subplots(figsize=(6, 3))
    table.set_index(index)[list(columns)].plot.bar(ax=ax)
    if ylim is not None:
        ax.set_ylim(*ylim)
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_per_scene_change(changes: pd.DataFrame, path: str | os.PathLike, *, column: str = "change_high",
                          by: str = "source", threshold: float | None = None, title: str = "") -> Path:
    """Every scene's value of ``column`` per group (one dot per scene, the median as a bar), with
    zero and an optional ``-threshold`` line: the per-scene spread behind a mean.

    Parameters
    ----------
    changes : DataFrame
        One row per (group, scene) with ``by``, ``scene`` and ``column``.
    path : path
    column, by : str
    threshold : float, optional
        Drawn at ``-threshold`` (e.g. the largest acceptable loss).
    title : str
    """
    import matplotlib.pyplot as plt

    _require_columns(changes, {by, "scene", column}, "plot_per_scene_change")
    groups = list(dict.fromkeys(changes[by]))
    fig, ax = plt.subplots(figsize=(1.6 + 1.4 * len(groups), 4.0))
    rng = np.random.default_rng(0)  # horizontal jitter only
    for i, name in enumerate(groups):
        v = changes.loc[changes[by] == name, column].to_numpy(dtype=np.float64)
        ax.scatter(i + rng.uniform(-0.15, 0.15, v.size), v, s=18, alpha=0.8, color="#0072B2", zorder=3)
        if v.size:
            ax.hlines(np.median(v), i - 0.3, i + 0.3, color="black", lw=2, zorder=4)
    ax.axhline(0.0, color="grey", lw=1)
    if threshold is not None:
        ax.axhline(-threshold, color="#D55E00", lw=1, ls="--", label=f"-{threshold:g}")
        ax.legend(loc="lower right", fontsize=8)
    ax.set_xticks(range(len(groups)), groups, rotation=20, ha="right", fontsize=8)
    ax.set_ylabel(column.replace("_", " "))
    ax.set_title(title or f"{column} per scene (dots), median (bar)", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)

