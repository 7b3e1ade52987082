"""The synthetic experiments: upper maps (03), label transfer (04), Table 2 (05).

Each function does one notebook's work on the data layout of :mod:`.layout` and returns a
DataFrame the notebook shows and plots.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from ..io import read_map, read_sequence
from .layout import GT, Layout, model_name

__all__ = [
    "MEASURE_COLUMNS",
    "reconstruct_upper_maps",
    "transfer_lower_labels",
    "reconstruct_lower_maps",
    "evaluate_synthetic",
    "average_over_scenes",
    "plot_table",
]

MEASURE_COLUMNS = ("jaccard", "sorensen", "color_acc", "mean_acc")


def _scores(gt, pred, voxel_size: float) -> dict:
    from ..metrics import compare

    s = compare(gt, pred, voxel_size=voxel_size)
    return {k: float(s[k]) for k in MEASURE_COLUMNS}


def reconstruct_upper_maps(
    data_root: str | Path,
    networks: Sequence[str],
    *,
    voxel_size: float = 0.04,
    eval_voxel_size: float = 0.05,
    progress: bool = True,
) -> pd.DataFrame:
    """Upper-view semantic maps of every evaluation scene: from ground truth and each network.

    For each scene the upper sequence is fused with its ground-truth labels (``upper/<id>/gt.ply``)
    and with the labels each network predicts on the upper frames (``upper/<id>/<net>.ply``).

    Returns
    -------
    DataFrame
        One row per (scene, network): the network's upper map scored against the ground-truth
        upper map (the paper's "Upper" rows), plus the 2D pixel accuracy / mIoU on the frames.
    """
    from ..fusion import reconstruct_many
    from ..metrics import pixel_metrics
    from ..segment import predict_sequence

    layout = Layout(data_root)
    models = {net: layout.load_network(net) for net in networks}
    rows = []
    for sd in tqdm(layout.scene_dirs("eval"), desc="upper maps", disable=not progress):
        sid = sd.name
        upper = read_sequence(sd / "upper").load()  # predicted 2x: decode once
        lab_dirs = [layout.upper_labels(sid, net) for net in networks]
        for net, lab_dir in zip(networks, lab_dirs, strict=True):
            predict_sequence(models[net], upper, lab_dir, progress=False)
        # one fusion, the ground-truth labels and each network's as labelings
        gt_map, *net_maps = reconstruct_many(upper, [None, *lab_dirs], voxel_size,
                                             outs=[layout.upper_map(sid, s) for s in (GT, *networks)])
        for net, lab_dir, net_map in zip(networks, lab_dirs, net_maps, strict=True):
            pred = read_sequence(sd / "upper", labels=lab_dir)
            pix = pixel_metrics((upper.read_labels(i) for i in range(len(upper))),
                                (pred.read_labels(i) for i in range(len(pred))))
            rows.append(
                dict(scene=sid, model=net, method="upper", **_scores(gt_map, net_map, eval_voxel_size),
                     pixel_acc=float(pix["pixel_acc"]), miou=float(pix["miou"]))
            )
    return pd.DataFrame(rows)


def transfer_lower_labels(
    data_root: str | Path,
    methods: Sequence[str],
    networks: Sequence[str],
    *,
    jobs: int = 1,
    progress: bool = True,
) -> pd.DataFrame:
    """Labels for every lower frame: each method from each upper map, and each network directly.

    Writes ``lower_labels/<scene>/<source>/<method>/`` (source: ``gt`` or a network) and
    ``lower_labels/<scene>/<network>/lower/`` (the network applied to the lower frames: the
    baseline).

    Returns
    -------
    DataFrame
        scene, model, method, coverage (share of pixels with depth that got a label), fps.
    """
    from ..segment import predict_sequence
    from ..transfer import prepare, transfer_sequence

    layout = Layout(data_root)
    models = {net: layout.load_network(net) for net in networks}
    rows = []
    for sd in layout.scene_dirs("eval"):
        sid = sd.name
        lower = read_sequence(sd / "lower").load()  # 3 sources x 5 methods read every frame
        for source in (GT, *networks):
            index = prepare(read_map(layout.upper_map(sid, source)))
            for method in methods:
                st = transfer_sequence(method, lower, index, layout.lower_labels(sid, source, method),
                                       jobs=jobs, progress=progress)
                rows.append(dict(scene=sid, model=model_name(source), method=method,
                                 coverage=float(st["coverage"]), fps=float(st["fps"])))
        for net in networks:
            predict_sequence(models[net], lower, layout.lower_labels(sid, net, "lower"),
                             progress=progress)
    return pd.DataFrame(rows)


def reconstruct_lower_maps(
    data_root: str | Path,
    methods: Sequence[str],
    networks: Sequence[str],
    *,
    voxel_size: float = 0.04,
    progress: bool = True,
) -> None:
    """Fuse the lower sequence of every scene with each labels folder of 04 (and with GT labels).

    Writes ``lower_maps/<scene>/reference.ply`` (ground-truth labels: the reference) and
    ``lower_maps/<scene>/<source>/<method>.ply``.
    """
    from ..fusion import reconstruct_many

    layout = Layout(data_root)
    for sd in tqdm(layout.scene_dirs("eval"), desc="lower maps", disable=not progress):
        sid = sd.name
        jobs = [(GT, m) for m in methods] + [(n, m) for n in networks for m in ("lower", *methods)]
        # one fusion of the lower frames; the reference (ground-truth labels) and every
        # labels folder as labelings of it
        reconstruct_many(read_sequence(sd / "lower"),
                         [None, *(layout.lower_labels(sid, s, m) for s, m in jobs)], voxel_size,
                         outs=[layout.lower_reference(sid), *(layout.lower_map(sid, s, m) for s, m in jobs)])


def evaluate_synthetic(
    data_root: str | Path,
    methods: Sequence[str],
    networks: Sequence[str],
    *,
    eval_voxel_size: float = 0.05,
) -> pd.DataFrame:
    """Table 2, per scene: every lower map against the lower reference, plus the upper rows.

    Returns
    -------
    DataFrame
        scene, model (``ground truth`` or a network), method (a transfer method, ``lower`` =
        the network on the lower frames, ``upper`` = the network's upper map), the four measures.
    """
    layout = Layout(data_root)
    rows = []
    for sd in layout.scene_dirs("eval"):
        sid = sd.name
        ref = read_map(layout.lower_reference(sid))
        up_ref = read_map(layout.upper_reference(sid))
        for net in networks:
            rows.append(dict(scene=sid, model=net, method="upper",
                             **_scores(up_ref, read_map(layout.upper_map(sid, net)), eval_voxel_size)))
            rows.append(dict(scene=sid, model=net, method="lower",
                             **_scores(ref, read_map(layout.lower_map(sid, net, "lower")), eval_voxel_size)))
        for source in (GT, *networks):
            for method in methods:
                pred = read_map(layout.lower_map(sid, source, method))
                rows.append(dict(scene=sid, model=model_name(source), method=method,
                                 **_scores(ref, pred, eval_voxel_size)))
    return pd.DataFrame(rows)


def average_over_scenes(df: pd.DataFrame) -> pd.DataFrame:
    """Mean of the measures over scenes per (model, method), in the paper's row order."""
    cols = [c for c in MEASURE_COLUMNS if c in df.columns]
    out = df.groupby(["model", "method"], sort=False)[cols].mean().reset_index()
    out.insert(2, "scenes", df.groupby(["model", "method"], sort=False).size().values)
    return out


def plot_table(df: pd.DataFrame, path: str | Path, *, title: str, methods: Sequence[str]) -> Path:
    """Bar chart of Mean Acc. per upper map and method, with the paper's values as markers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import save_figure

    models = list(dict.fromkeys(df["model"]))
    order = ["upper", "lower", *methods]
    fig, axes = plt.subplots(1, len(models), figsize=(4.2 * len(models), 3.6), sharey=True, squeeze=False)
    for ax, model in zip(axes[0], models, strict=True):
        sub = df[df["model"] == model].set_index("method")
        names = [m for m in order if m in sub.index]
        x = np.arange(len(names))
        colors = ["#999999" if n in ("upper", "lower") else "#3b75af" for n in names]
        ax.bar(x, sub.loc[names, "mean_acc"], color=colors, label="semmatch")
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
