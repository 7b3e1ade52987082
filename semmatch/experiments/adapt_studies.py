"""Side studies of stage 09 (robot-view adaptation): what they share, and the held-out scenes.

The stage fine-tunes a network on the robot's frames of its own training scenes. Its side
studies (``scripts/adapt_seeds.py``, ``scripts/adapt_equal_tuning.py``,
``scripts/adapt_heldout.py``) start from the stage's parameters and chosen recipe
(:func:`stage_parameters`, :func:`stage_recipe`). The held-out study adapts on scenes the network
never saw (:data:`HELDOUT_ADAPT_SEEDS`), so that the person's maps there come from out-of-sample
predictions; :func:`label_quality_by_class` says how good the transferred labels are per class,
and :func:`heldout_vs_in_sample` compares what the two adaptations achieve on the evaluation
sweeps, paired per scene.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["HELDOUT_ADAPT_SEEDS", "HELDOUT_SUFFIX", "stage_parameters", "stage_recipe", "check_heldout_seeds",
           "label_quality_by_class", "heldout_vs_in_sample"]

#: the held-out adaptation scenes (issue 38 item 2): 24 scenes, 6 per kind (scene ``i`` of kind
#: ``kinds[i % 4]``, as ``make_scenes``), fixed before any was generated; no profile lists them
#: and ``make confirm`` refuses them
HELDOUT_ADAPT_SEEDS: tuple[int, ...] = tuple(range(8301, 8325))

#: appended to the adapted model's name (``compact~3d-neighborhood (held-out scenes)``)
HELDOUT_SUFFIX = " (held-out scenes)"


def stage_parameters(profile: str | None = None, data_root: str | Path | None = None) -> dict:
    """Notebook 09's papermill parameters for ``profile`` (default: params.yaml's), optionally on
    another ``data_root``."""
    from .pipeline import notebook_parameters

    kw = {"data_root": str(data_root)} if data_root else {}
    return notebook_parameters("09_adapt_robot_view", profile, **kw)


def stage_recipe(stage_figures: str | Path, **changes):
    """The recipe stage 09 chose (the ``chosen`` row of its ``validation_adapt_recipe.csv``).

    Parameters
    ----------
    stage_figures : path
        The stage's figures folder.
    **changes
        Recipe fields to set over the chosen ones (``seed=1``).

    Returns
    -------
    semmatch.segment.adapt.AdaptRecipe

    Raises
    ------
    FileNotFoundError
        The stage's table is missing (run stage 09 first).
    ValueError
        The table has no chosen row.
    """
    from ..segment.adapt import AdaptRecipe

    table = Path(stage_figures) / "validation_adapt_recipe.csv"
    if not table.is_file():
        raise FileNotFoundError(f"{table}: run stage 09 (dvc repro -s adapt_robot_view) first")
    chosen = pd.read_csv(table)
    chosen = chosen[chosen["chosen"].astype(bool)]
    if chosen.empty:
        raise ValueError(f"{table}: no row is marked chosen")
    return AdaptRecipe.from_mapping({**chosen.iloc[0].to_dict(), **changes})


def check_heldout_seeds(seeds: Sequence[int], train_config: Mapping) -> None:
    """Refuse held-out adaptation seeds that the network saw or that decide anything.

    Parameters
    ----------
    seeds : sequence of int
        The adaptation scenes' seeds.
    train_config : mapping
        The network's ``train_config`` (its ``train_seeds``, ``val_seeds``, ``eval_seeds``).

    Raises
    ------
    ValueError
        Naming the seeds that are training, validation or evaluation seeds of the network, or
        seeds of a profile (training, validation, development, evaluation).
    """

    from .pipeline import ROOT, read_params
    from .protocol import used_seeds

    seeds = {int(s) for s in seeds}
    for key, what in (("train_seeds", "training"), ("val_seeds", "validation"), ("eval_seeds", "evaluation")):
        common = sorted(seeds & {int(s) for s in train_config.get(key) or ()})
        if common:
            raise ValueError(f"held-out adaptation seeds {common} are {what} seeds of the network")
    used = used_seeds(read_params(ROOT / "params.yaml")["profiles"])
    common = sorted(seeds & set(used))
    if common:
        raise ValueError(f"held-out adaptation seeds {common} are used by params.yaml: "
                         + "; ".join(f"{s}: {used[s]}" for s in common))


def label_quality_by_class(robot, sources: Sequence[str]) -> pd.DataFrame:
    """Per label source and category: how good the robot's labels are.

    Parameters
    ----------
    robot : semmatch.segment.adapt.RobotViews
        The labelled robot frames (their ground truth in ``robot.views.labels``).
    sources : sequence of str
        Label sources of ``robot.pseudo``.

    Returns
    -------
    DataFrame
        ``source``, ``category``, ``gt_share`` (the category's share of the robot's labelled
        ground-truth pixels with depth), ``labelled`` (pixels the source gave this category),
        ``precision`` (share of them that are the category), ``recall`` (share of the category's
        pixels with depth that the source labelled correctly). Categories absent from both the
        ground truth and the labels are left out.
    """
    from ..io.labels import NAMES

    gt = np.asarray(robot.views.labels)
    valid = (np.asarray(robot.views.depth) > 0) & (gt > 0)
    g = gt[valid].astype(np.intp)
    n = len(NAMES)
    gt_count = np.bincount(g, minlength=n)
    rows = []
    for s in sources:
        lab = np.asarray(robot.pseudo[s])[valid].astype(np.intp)
        on = lab > 0
        given = np.bincount(lab[on], minlength=n)
        right = np.bincount(lab[on & (lab == g)], minlength=n)
        for c in range(1, n):
            if gt_count[c] == 0 and given[c] == 0:
                continue
            rows.append({"source": s, "category": NAMES[c], "gt_share": gt_count[c] / max(int(gt_count[1:].sum()), 1),
                         "labelled": int(given[c]),
                         "precision": right[c] / given[c] if given[c] else float("nan"),
                         "recall": right[c] / gt_count[c] if gt_count[c] else float("nan")})
    return pd.DataFrame(rows, columns=["source", "category", "gt_share", "labelled", "precision", "recall"])


def heldout_vs_in_sample(per_scene: pd.DataFrame, network: str, sources: Sequence[str], *, measure: str = "miou",
                         low: float = 0.2, high: float = 1.6) -> pd.DataFrame:
    """Held-out minus in-sample adaptation, per source, paired over the evaluation scenes.

    Parameters
    ----------
    per_scene : DataFrame
        Per-scene scores (:func:`semmatch.experiments.adapt.adapted_height_study`) of ``network``,
        of each source's in-sample adaptation (``network~source``) and of its held-out one
        (``network~source`` + :data:`HELDOUT_SUFFIX`).
    network, sources
        The unadapted network and the label sources.
    measure, low, high
        As :func:`semmatch.experiments.adapt.gap_table`.

    Returns
    -------
    DataFrame
        Per source: the gap closed in-sample and held-out, and the held-out minus in-sample
        difference of the gain at ``low`` and of the change at ``high`` (paired over scenes, one-sample
        t interval as the analysis plan's; ``*_lo``/``*_hi`` the 95 % interval).

    Raises
    ------
    ValueError
        A source without both adapted models in ``per_scene``.
    """
    from ..evaluate.stats import interval
    from ..segment.adapt import adapted_name
    from .adapt import per_scene_changes

    ch = per_scene_changes(per_scene, network, low=low, high=high, measure=measure).set_index(["model", "scene"])
    have = set(ch.index.get_level_values(0))
    rows = []
    for s in sources:
        inside, out = adapted_name(network, s), adapted_name(network, s) + HELDOUT_SUFFIX
        missing = [m for m in (inside, out) if m not in have]
        if missing:
            raise ValueError(f"heldout_vs_in_sample: no scores of {missing} (have {sorted(have)})")
        a, b = ch.loc[inside], ch.loc[out].reindex(ch.loc[inside].index)
        row = {"source": s, "scenes": len(a),
               "gap_closed_in_sample": float(a["gain_low"].mean() / a["gap"].mean()),
               "gap_closed_held_out": float(b["gain_low"].mean() / b["gap"].mean())}
        for col in ("gain_low", "change_high"):
            d = interval(b[col].to_numpy() - a[col].to_numpy(), method="t")
            row.update({f"{col}_diff": d[0], f"{col}_diff_lo": d[1], f"{col}_diff_hi": d[2]})
        rows.append(row)
    return pd.DataFrame(rows)
