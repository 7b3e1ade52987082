"""Fig. 3: segmentation accuracy against camera height on the height-sweep sequences (06), and
the test-time choice made on the validation scenes' sweeps (02).
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from ..io import atomic_write_text
from .layout import Layout
from .tables import save_table

__all__ = ["sweep_sequences", "height_study", "choose_test_time_flip"]

_SWEEP = re.compile(r"^h(\d{3})$")


def sweep_sequences(data_root: str | Path, split: str = "eval") -> dict[float, list[Path]]:
    """Height-sweep sequences of a split's scenes: ``{height_m: [h020 folders ...]}``."""
    sweeps: dict[float, list[Path]] = {}
    for sd in Layout(data_root).scene_dirs(split):
        for d in sorted(sd.iterdir()):
            m = _SWEEP.match(d.name)
            if m and d.is_dir():
                sweeps.setdefault(int(m.group(1)) / 100.0, []).append(d)
    if not sweeps:
        raise FileNotFoundError(f"{data_root}: no height-sweep sequences (h020 ..) of the {split} scenes; "
                                f"run 01_simulate with heights_sweep")
    return dict(sorted(sweeps.items()))


def height_study(
    data_root: str | Path, networks: Sequence[str], *, figures_dir: str | Path, jobs: int = 1,
    scheduler: str | None = None, progress: bool = True,
) -> pd.DataFrame:
    """Score each network on every evaluation scene's height sweep; write Fig. 3.

    The scenes are tasks of :func:`semmatch.runtime.engine.map_tasks` (``jobs`` local worker processes,
    or the cluster at ``scheduler``; the networks are pickled to the workers).

    Writes ``fig3_height_per_scene.csv`` (one row per network, scene and height),
    ``fig3_height.{csv,md}`` (mean over scenes with the analysis plan's 95 % interval) and
    ``fig3_height.png`` (the means with their intervals as bands).

    Returns
    -------
    DataFrame
        Per scene: model, scene, height, n_frames and the pixel measures over classes 1..10
        (see :func:`semmatch.segment.viewpoint.viewpoint_gap_sequences`).
    """
    from ..segment.viewpoint import viewpoint_gap_sequences
    from .summaries import summarize_over_scenes

    layout = Layout(data_root)
    models = {net: layout.load_network(net) for net in networks}
    df = viewpoint_gap_sequences(models, sweep_sequences(data_root), per_scene=True, jobs=jobs, scheduler=scheduler,
                                 progress=progress)
    save_table(df, figures_dir, "fig3_height_per_scene")
    summary = summarize_over_scenes(df, ("mean_acc", "miou"), by=("model", "height"))
    save_table(summary, figures_dir, "fig3_height")
    from ..plots import plot_height_study

    plot_height_study(summary, Path(figures_dir) / "fig3_height.png")
    return df


def choose_test_time_flip(
    data_root: str | Path, networks: Sequence[str], *, figures_dir: str | Path | None = None,
    frame_step: int = 1, progress: bool = True,
) -> tuple[dict[str, bool], pd.DataFrame]:
    """Decide on the VALIDATION scenes whether each network averages its mirror image.

    Every network labels the validation scenes' height sweeps with and without mirror
    averaging; the variant with the higher mIoU averaged over all heights and scenes is kept.
    The choice goes to ``models/recipe.json`` (read by :meth:`Layout.load_network`; the choices
    of networks not in this run are kept), the scores to ``figures_dir/validation_flip.{csv,md}``.

    Parameters
    ----------
    data_root : path
    networks : sequence of str
    figures_dir : path, optional
    frame_step : int
        Every ``frame_step``-th frame of each validation sweep (1: all; the full profile uses 2
        for its time budget).
    progress : bool

    Returns
    -------
    choice : dict
        ``{network: flip}``.
    scores : DataFrame
        model, flip, height, mIoU and Mean Acc. pooled over the validation scenes.
    """
    from ..segment import load_model
    from ..segment.viewpoint import viewpoint_gap_sequences

    layout = Layout(data_root)
    sweeps = sweep_sequences(data_root, "val")
    rows, choice = [], {}
    for net in networks:
        path = layout.model(net)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no trained {net} network")
        models = {f"{net}|{flip}": load_model(path, flip=flip) for flip in (False, True)}
        df = viewpoint_gap_sequences(models, sweeps, frame_step=frame_step, progress=progress)
        df["flip"] = df["model"].str.endswith("True")
        df["model"] = net
        rows.append(df)
        mean = df.groupby("flip")["miou"].mean()
        choice[net] = bool(mean.get(True, float("-inf")) > mean.get(False, float("-inf")))
    scores = pd.concat(rows, ignore_index=True)[["model", "flip", "height", "n_frames", "miou", "mean_acc"]]
    layout.recipe.parent.mkdir(parents=True, exist_ok=True)
    # merge: a run for some networks (e.g. extra training seeds) keeps the others' choices
    known = json.loads(layout.recipe.read_text()).get("flip", {}) if layout.recipe.is_file() else {}
    atomic_write_text(layout.recipe, json.dumps({"flip": {**known, **choice}, "chosen_on": "validation height sweeps"},
                                                indent=2) + "\n")
    if figures_dir is not None:
        save_table(scores, figures_dir, "validation_flip")
    return choice, scores
