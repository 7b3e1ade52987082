"""The adaptation claims over fine-tuning seeds (analysis plan v2): every seed's shipped adapted networks, scored.

Notebook 09 fine-tunes (or takes the shipped) adapted networks of one seed, the profile's ``seed``.
The v2 plan judges A1-A7 over the fine-tuning seeds it lists (``adaptation.finetune_seeds``:
0, 1, 2), A3 on the per-scene mean over them. The other seeds' adapted networks are shipped
beside seed 0's folder, as the training seeds of the networks are (``compact@1.pt``):
``models/<profile>/adapted@<seed>/`` (:func:`seed_folder`), each a shipped adaptation of its own
(:mod:`semmatch.experiments.shipped_adaptation`: the same request with that seed, the same chosen
recipe). A confirmatory run fine-tunes nothing: a seed that is not shipped is left out and named.

:func:`score_finetune_seeds` scores them as notebook 09 scores its own seed (the height sweeps and
the robot's own map) and writes ``adapt_seeds/adapt_seeds_height_per_scene.csv`` and
``adapt_seeds/table2_adapted_seeds_per_scene.csv`` (every seed, its ``seed`` column), which
:func:`semmatch.experiments.adapt_claims.judge_adaptation` judges under a v2 plan.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import pandas as pd

from ..segment.adapt import RobotViews
from .adapt_claims import SEED_COLUMN, SEED_TABLES
from .layout import Layout

__all__ = ["plan_finetune_seeds", "seed_folder", "shipped_finetune_seeds", "score_finetune_seeds"]


def plan_finetune_seeds(plan, seed: int) -> list[int]:
    """The fine-tuning seeds a plan judges the adaptation claims over (``[seed]`` when it lists none: v1)."""
    listed = ((plan.raw.get("adaptation") or {}).get("finetune_seeds") if plan is not None else None) or [seed]
    return [int(s) for s in listed]


def seed_folder(shipped_dir: str | os.PathLike, seed: int, base_seed: int = 0) -> Path:
    """The shipped adaptation folder of a fine-tuning seed: ``shipped_dir`` itself for the base seed
    (``models/<profile>/adapted``), ``<shipped_dir>@<seed>`` beside it otherwise."""
    d = Path(shipped_dir)
    return d if int(seed) == int(base_seed) else d.with_name(f"{d.name}@{int(seed)}")


def shipped_finetune_seeds(data_root: str | os.PathLike, network: str, robot: RobotViews, sources: Sequence[str], *,
                           seeds: Sequence[int], base_seed: int, shipped_dir: str | os.PathLike,
                           recipe_grid: Mapping, recipe_source: str, defaults: Mapping, max_forgetting: float,
                           progress: bool = False) -> dict[int, dict[str, Path]]:
    """The shipped adapted networks of every fine-tuning seed but ``base_seed`` (notebook 09's own).

    Each seed's folder (:func:`seed_folder`) must answer notebook 09's request with that seed
    (:func:`~semmatch.experiments.shipped_adaptation.shipped_adaptation`); its checkpoints are
    checked against their provenance and copied to ``data_root/adapted@<seed>/``
    (:func:`~semmatch.experiments.adapt.adapt_networks` with ``reuse``: nothing is fine-tuned).

    Returns
    -------
    dict
        ``{seed: {adapted name: checkpoint}}``; a seed without a shipped adaptation is left out,
        and a line on stderr says why.
    """
    from ..segment.adapt.finetune import file_digest
    from .adapt import adapt_networks
    from .shipped_adaptation import adaptation_request, shipped_adaptation

    out: dict[int, dict[str, Path]] = {}
    for s in (int(v) for v in seeds):
        if s == int(base_seed):
            continue
        request = adaptation_request(
            network_sha256=file_digest(Layout(data_root).model(network)), scenes=robot.scenes,
            frames=len(robot.views), sources=sources, recipe_grid=recipe_grid, recipe_source=recipe_source,
            defaults=defaults, max_forgetting=max_forgetting, seed=s)
        shipped, why = shipped_adaptation(seed_folder(shipped_dir, s, base_seed), request)
        if shipped is None:
            print(f"[adapt] fine-tuning seed {s} left out: {why}", file=sys.stderr)
            continue
        recipe, _, paths = shipped
        out[s] = adapt_networks(data_root, network, robot, sources, seed=s, reuse=paths, progress=progress,
                                out_dir=Layout(data_root).root / f"adapted@{s}", **recipe)
    return out


def score_finetune_seeds(data_root: str | os.PathLike, network: str, figures_dir: str | os.PathLike, *,
                         base_seed: int, height_rows: pd.DataFrame, robot_rows: pd.DataFrame,
                         unadapted_rows: pd.DataFrame, seeds: Mapping[int, Mapping[str, Path]], frame_step: int = 1,
                         voxel_size: float = 0.04, eval_voxel_size: float = 0.05,
                         jobs: int = 1) -> dict[str, pd.DataFrame]:
    """Score every other fine-tuning seed as notebook 09 scores its own, and write the tables over seeds.

    Parameters
    ----------
    data_root, network, figures_dir
        Notebook 09's.
    base_seed : int
        Notebook 09's own fine-tuning seed; ``height_rows`` and ``robot_rows`` are its tables.
    height_rows : DataFrame
        Notebook 09's ``adapt_height_per_scene`` (the unadapted network and the base seed's adapted ones).
    robot_rows : DataFrame
        The adapted networks' rows of notebook 09's ``table2_adapted_per_scene``.
    unadapted_rows : DataFrame
        Its rows of the unadapted network (Table 2's ``lower``, ``fused_base`` and ``fused``):
        the same for every seed.
    seeds : mapping
        :func:`shipped_finetune_seeds`.
    frame_step, voxel_size, eval_voxel_size, jobs
        As notebook 09.

    Returns
    -------
    dict
        ``{"height sweep": ..., "robot map": ...}``: every seed's rows with a ``seed`` column,
        written to ``figures_dir/adapt_seeds/`` (:data:`~semmatch.experiments.adapt_claims.SEED_TABLES`).
        Empty (nothing written)
        when ``seeds`` is empty.
    """
    from .adapt import adapted_height_study, adapted_lower_maps, load_adapted
    from .tables import save_table

    if not seeds:
        return {}
    height = [height_rows.assign(**{SEED_COLUMN: int(base_seed)})]
    robot = [pd.concat([unadapted_rows, robot_rows]).assign(**{SEED_COLUMN: int(base_seed)})]
    for s, checkpoints in seeds.items():
        adapted = adapted_height_study(data_root, network, dict(checkpoints), frame_step=frame_step, jobs=jobs,
                                       progress=False)
        height.append(adapted.assign(**{SEED_COLUMN: int(s)}))
        rows = adapted_lower_maps(data_root, load_adapted(data_root, network, dict(checkpoints)),
                                  voxel_size=voxel_size, eval_voxel_size=eval_voxel_size, jobs=jobs, progress=False)
        robot.append(pd.concat([unadapted_rows, rows]).assign(**{SEED_COLUMN: int(s)}))
    tables = {"height sweep": pd.concat(height, ignore_index=True), "robot map": pd.concat(robot, ignore_index=True)}
    for key, table in tables.items():
        where = Path(figures_dir) / SEED_TABLES[key]
        save_table(table, where.parent, where.name)
    return tables
