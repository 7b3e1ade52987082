"""Notebook 09: adapt a network to the robot's viewpoint with transferred labels, and score it.

Adaptation happens on training scenes only (:mod:`semmatch.adapt`); the adapted networks are
scored on the **evaluation** scenes: the height sweep of Fig. 3 (every adapted network beside
the unadapted one), a table at 0.2 m and 1.6 m with the share of the viewpoint gap closed and
the change at human height (paired per-scene differences with 95 % intervals), and the adapted
networks' own lower-view semantic maps as new rows of Table 2 (does the robot now beat transfer
from the person's map on its own?).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..adapt import adapted_name, fine_tune, robot_training_views
from ..io import read_map, read_sequence
from ..metrics import MEASURES, compare
from ..stats import bootstrap_ci, paired_difference_ci
from .layout import Layout
from .synthetic import eval_grid_origin

__all__ = ["adapt_networks", "load_adapted", "adapted_height_study", "gap_table", "adapted_lower_maps"]


def _adapt_dir(data_root: str | Path) -> Path:
    return Path(data_root) / "adapted"


def adapt_networks(
    data_root: str | Path,
    network: str,
    sources: Sequence[str],
    *,
    kinds: Sequence[str],
    seeds: Sequence[int],
    n_frames: int = 40,
    steps: int = 500,
    batch_size: int = 16,
    lr: float = 1e-3,
    upper_share: float = 0.5,
    voxel_size: float = 0.04,
    fused_base: str = "3d-neighborhood",
    seed: int = 0,
    progress: bool = True,
) -> tuple[dict[str, Path], pd.DataFrame]:
    """Fine-tune ``network`` once per label source on the robot's frames of training scenes.

    Returns
    -------
    checkpoints : dict
        ``{adapted name: checkpoint path}`` (under ``data/<profile>/adapted/``).
    coverage : DataFrame
        ``source``, ``coverage`` (share of the robot's pixels with depth that carry a label),
        ``agreement`` (share of the labelled pixels that match the ground truth).
    """
    layout = Layout(data_root)
    robot = robot_training_views(layout.model(network), kinds=kinds, seeds=seeds, sources=sources,
                                 n_frames=n_frames, voxel_size=voxel_size, fused_base=fused_base, seed=seed,
                                 progress=progress)
    gt = robot.views.labels
    rows = []
    for s in sources:
        lab = robot.pseudo[s]
        on = lab > 0
        rows.append({"source": s, "coverage": robot.coverage[s],
                     "agreement": float((lab[on] == gt[on]).mean()) if on.any() else float("nan")})
    out = {}
    for s in sources:
        name = adapted_name(network, s)
        out[name] = fine_tune(layout.model(network), robot, s, _adapt_dir(data_root) / f"{name}.pt", steps=steps,
                              batch_size=batch_size, lr=lr, upper_share=upper_share, seed=seed, progress=progress)
    return out, pd.DataFrame(rows)


def load_adapted(data_root: str | Path, network: str, checkpoints: dict[str, Path]) -> dict:
    """The adapted networks (``{name: Segmenter}``) with the source network's inference recipe
    (mirror averaging as chosen for it on validation)."""
    from ..segment import load_model

    flip = Layout(data_root).inference_flip(network)
    return {name: load_model(p) if flip is None else load_model(p, flip=flip) for name, p in checkpoints.items()}


def adapted_height_study(data_root: str | Path, network: str, checkpoints: dict[str, Path], *, jobs: int = 1,
                         scheduler: str | None = None, progress: bool = True) -> pd.DataFrame:
    """Per-scene pixel scores of the unadapted and every adapted network on the evaluation
    scenes' height sweeps (:func:`semmatch.segment.viewpoint.viewpoint_gap_sequences`; the scenes
    are engine tasks on ``jobs`` local worker processes or the cluster at ``scheduler``)."""
    from ..segment.viewpoint import viewpoint_gap_sequences
    from .height import sweep_sequences

    models = {network: Layout(data_root).load_network(network), **load_adapted(data_root, network, checkpoints)}
    return viewpoint_gap_sequences(models, sweep_sequences(data_root), per_scene=True, jobs=jobs,
                                   scheduler=scheduler, progress=progress)


def gap_table(per_scene: pd.DataFrame, network: str, *, low: float = 0.2, high: float = 1.6,
              measure: str = "miou") -> pd.DataFrame:
    """The viewpoint gap closed by each adapted network, with 95 % intervals over scenes.

    Per model: ``measure`` at ``low`` and ``high`` (mean [interval]); ``gain_low`` (adapted minus
    unadapted at ``low``, paired over scenes) and ``change_high`` (the same at ``high``: negative
    = forgetting); ``gap_closed``: ``gain_low`` over the unadapted network's gap ``high - low``.
    """
    def at(model: str, h: float) -> pd.Series:
        sel = per_scene[(per_scene["model"] == model) & np.isclose(per_scene["height"], h)]
        return sel.set_index("scene")[measure]

    base_lo, base_hi = at(network, low), at(network, high)
    gap = float((base_hi - base_lo).mean())
    rows = []
    for model in dict.fromkeys(per_scene["model"]):
        lo, hi = at(model, low), at(model, high)
        row = {"model": model, "source": model.split("~", 1)[1] if "~" in model else "none (unadapted)"}
        for name, s in ((f"{measure}@{low:g}", lo), (f"{measure}@{high:g}", hi)):
            m, a, b = bootstrap_ci(s.values)
            row.update({name: m, f"{name}_lo": a, f"{name}_hi": b})
        g = paired_difference_ci(lo.reindex(base_lo.index).values, base_lo.values)
        c = paired_difference_ci(hi.reindex(base_hi.index).values, base_hi.values)
        row.update({"gain_low": g[0], "gain_low_lo": g[1], "gain_low_hi": g[2],
                    "change_high": c[0], "change_high_lo": c[1], "change_high_hi": c[2],
                    "gap_closed": g[0] / gap if gap > 0 else float("nan")})
        rows.append(row)
    return pd.DataFrame(rows)


def adapted_lower_maps(data_root: str | Path, networks: dict[str, object], *, voxel_size: float = 0.04,
                       eval_voxel_size: float = 0.05, jobs: int = 1, scheduler: str | None = None,
                       progress: bool = True) -> pd.DataFrame:
    """Table 2 rows of networks applied to the robot's own frames: per evaluation scene, the
    robot's frames segmented by each network, fused (TSDF) and scored against the reference
    (05's ``reference.ply``, on the protocol's grid).

    Parameters
    ----------
    data_root : path
        The pipeline's data root.
    networks : dict
        ``{name: Segmenter}`` (pickled to the workers when scenes run elsewhere).
    voxel_size, eval_voxel_size : float
        Fusion and evaluation voxel sizes (m).
    jobs : int
        Scenes run as tasks of :func:`semmatch.engine.map_tasks` on ``jobs`` local worker
        processes (1: in this process).
    scheduler : str, optional
        Dask scheduler address to run the scenes on (default ``SEMMATCH_SCHEDULER``; none: local).
    progress : bool

    Returns
    -------
    DataFrame
        ``scene``, ``model``, ``method`` (``lower``) and the paper's measures.
    """
    from functools import partial

    from ..engine import map_tasks

    layout = Layout(data_root)
    scenes = [sd.name for sd in layout.scene_dirs("eval")]
    task = partial(_adapted_lower_scene, str(layout.root.resolve()), networks, float(voxel_size),
                   float(eval_voxel_size))
    per_scene = map_tasks(task, scenes, jobs=jobs, scheduler=scheduler, desc="adapted lower maps", progress=progress)
    return pd.DataFrame([row for rows in per_scene for row in rows])


def _adapted_lower_scene(data_root: str, networks: dict[str, object], voxel_size: float, eval_voxel_size: float,
                         sid: str) -> list[dict]:
    """The rows of one scene (a task of :func:`adapted_lower_maps`)."""
    from ..fusion import reconstruct_many

    layout = Layout(data_root)
    seq = read_sequence(layout.lower_sequence(layout.scenes / "eval" / sid)).load()
    labelings = [[m.predict_labels(f.rgb) for f in seq] for m in networks.values()]
    maps = reconstruct_many(seq, labelings, voxel_size)
    ref = read_map(layout.lower_reference(sid))
    origin = eval_grid_origin(eval_voxel_size)
    rows = []
    for name, pred in zip(networks, maps, strict=True):
        s = compare(ref, pred, eval_voxel_size, grid_origin=origin)
        rows.append({"scene": sid, "model": name, "method": "lower", **{k: float(s[k]) for k in MEASURES}})
    return rows
