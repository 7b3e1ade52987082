"""The networks a confirmatory run evaluates under its analysis plan, and the per-scene tables' ``training_seed`` column.

The v1 plan judges one shipped network per architecture (``compact``, ``strong``: training seed
0). The v2 plan (``analysis_plan_v2.yaml``, ``networks:``) judges every shipped training seed of
each architecture (``compact``, ``compact@1``, ``compact@2`` ...: the pipeline's network names,
:func:`~semmatch.segment.train_config.network_spec`; ``models/<profile>/compact@1.pt`` beside
``compact.pt``, :func:`semmatch.segment.shipping.shipped_seeds`). :func:`plan_networks` lists them
for the run's parameters, so notebooks 03-07 evaluate each one as they evaluate ``compact``;
:func:`label_training_seeds` then rewrites the run's per-scene tables with the architecture in
``model`` and the seed in ``training_seed``, the form the v2 rules read
(:data:`semmatch.experiments.rules_v2.NETWORK_COLUMN`). A v1 run's networks and tables stay as
they are.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from .analysis_plan import AnalysisPlan

__all__ = ["PER_SCENE_TABLES", "plan_networks", "with_training_seed", "label_training_seeds"]

#: the per-scene tables whose rows come from one network each (Table 2, Table 3, Fig. 3)
PER_SCENE_TABLES = ("table2_per_scene", "table3_per_scene", "fig3_height_per_scene")


def plan_networks(networks: Sequence[str], plan: AnalysisPlan, shipped_dir: str | os.PathLike, *,
                  default_seed: int = 0) -> list[str]:
    """The networks a run judged by ``plan`` evaluates.

    Parameters
    ----------
    networks : sequence of str
        The profile's networks (``[compact, strong]``: training seed 0 of each architecture).
    plan : AnalysisPlan
        A plan with a ``networks`` section (v2) adds, after each architecture's own name, every
        training seed of ``networks.training_seeds`` that ``shipped_dir`` holds (``compact@1`` ...);
        other plans (v1) keep ``networks`` as they are.
    shipped_dir : path
        The shipped folder (``models/<profile>``).
    default_seed : int, optional
        The training seed of a name without ``@SEED`` (the profile's ``seed``).

    Returns
    -------
    list of str
        Network names; seeds the plan names that are not shipped are left out (the v2 rules label
        an architecture with fewer than ``networks.min_networks`` networks "provisional"; a
        message on stderr names them).

    Raises
    ------
    ValueError
        An unknown architecture in ``networks``.
    """
    spec = plan.raw.get("networks") if plan.rules == "v2" else None
    if not spec:
        return list(networks)
    from ..segment.shipping import shipped_seeds
    from ..segment.train_config import network_spec

    wanted = [int(s) for s in spec.get("training_seeds", ())]
    archs = set(spec.get("architectures") or ())
    out: list[str] = []
    for net in networks:
        arch, seed = network_spec(net, default_seed)
        out.append(net)
        if "@" in str(net) or (archs and arch not in archs):
            continue
        have = shipped_seeds(shipped_dir, arch)
        extra = [s for s in wanted if s != seed and s in have]
        missing = [s for s in wanted if s != seed and s not in have]
        out += [f"{arch}@{s}" for s in extra]
        if missing:
            print(f"[networks] {arch}: training seeds {missing} of the plan are not shipped in {shipped_dir}; "
                  f"{1 + len(extra)} network(s) evaluated", file=sys.stderr)
    return out


def with_training_seed(per_scene: pd.DataFrame, *, default_seed: int = 0) -> pd.DataFrame:
    """A per-scene table with each network row's architecture in ``model`` and its seed in ``training_seed``.

    ``compact@2`` becomes ``model = compact``, ``training_seed = 2``; ``compact`` is seed
    ``default_seed``; rows of other models (``ground truth``) get no seed (empty). The column
    follows ``model``. A table that has the column already is returned as it is.

    Parameters
    ----------
    per_scene : DataFrame
        With a ``model`` column.
    default_seed : int, optional
        The training seed of a network name without ``@SEED`` (the profile's ``seed``).

    Returns
    -------
    DataFrame

    Raises
    ------
    ValueError
        No ``model`` column.
    """
    from ..segment.models import ARCHITECTURES
    from ..segment.train_config import network_spec
    from .rules_v2 import NETWORK_COLUMN

    if "model" not in per_scene.columns:
        raise ValueError(f"with_training_seed: a per-scene table needs a 'model' column, got {list(per_scene.columns)}")
    if NETWORK_COLUMN in per_scene.columns:
        return per_scene
    specs = {m: (network_spec(m, default_seed) if str(m).partition("@")[0] in ARCHITECTURES else (m, None))
             for m in per_scene["model"].unique()}
    out = per_scene.copy()
    out["model"] = per_scene["model"].map(lambda m: specs[m][0])
    seeds = per_scene["model"].map(lambda m: specs[m][1])
    out.insert(out.columns.get_loc("model") + 1, NETWORK_COLUMN, pd.array(seeds, dtype="Int64"))
    return out


def label_training_seeds(figures_dir: str | os.PathLike, *, default_seed: int = 0) -> list[Path]:
    """Rewrite a run's per-scene tables (:data:`PER_SCENE_TABLES`, CSV and Markdown) with
    :func:`with_training_seed`; tables that have the column already are left alone.

    Returns
    -------
    list of Path
        The CSV files rewritten.
    """
    from .tables import save_table

    figures_dir, done = Path(figures_dir), []
    for name in PER_SCENE_TABLES:
        csv = figures_dir / f"{name}.csv"
        if not csv.is_file():
            continue
        table = pd.read_csv(csv)
        labelled = with_training_seed(table, default_seed=default_seed)
        if labelled is not table:
            done.append(save_table(labelled, figures_dir, name)[0])
    return done
