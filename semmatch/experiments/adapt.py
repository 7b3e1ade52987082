"""Notebook 09: adapt a network to the robot's viewpoint with transferred labels, and score it.

Adaptation happens on training scenes only (:mod:`semmatch.segment.adapt`); the adapted networks are
scored on the **evaluation** scenes: the height sweep of Fig. 3 (every adapted network beside
the unadapted one), a table at 0.2 m and 1.6 m with the share of the viewpoint gap closed and
the change at human height (paired per-scene differences with 95 % intervals), and the adapted
networks' own lower-view semantic maps as new rows of Table 2 (does the robot now beat transfer
from the person's map on its own?).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..evaluate.metrics import MEASURES, compare
from ..evaluate.stats import bootstrap_ci, paired_difference_ci, ratio_lower_bound, ratio_of_means_ci
from ..io import read_sequence
from ..segment.adapt import AdaptRecipe, RobotViews, adapted_name, fine_tune, robot_training_views
from .layout import Layout
from .synthetic import eval_grid_origin, reference_grid

__all__ = ["robot_views", "adapt_networks", "recipe_candidates", "choose_adaptation_recipe", "score_recipe_candidates", "pick_recipe",
           "chosen_recipe_checkpoint", "load_adapted", "adapted_height_study", "gap_table", "adapted_lower_maps",
           "robot_map_comparison", "gap_bounds", "per_scene_changes"]


def _adapt_dir(data_root: str | Path) -> Path:
    return Path(data_root) / "adapted"


def robot_views(
    data_root: str | Path,
    network: str,
    sources: Sequence[str],
    *,
    kinds: Sequence[str],
    seeds: Sequence[int],
    n_frames: int = 40,
    voxel_size: float = 0.04,
    fused_base: str = "3d-neighborhood",
    seed: int = 0,
    progress: bool = True,
) -> tuple[RobotViews, pd.DataFrame]:
    """The robot's frames of the adaptation (training) scenes, labelled by every source.

    Returns
    -------
    robot : RobotViews
        :func:`semmatch.segment.adapt.robot_training_views` of ``network``.
    quality : DataFrame
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
    return robot, pd.DataFrame(rows)


def adapt_networks(
    data_root: str | Path,
    network: str,
    robot: RobotViews,
    sources: Sequence[str],
    recipe: AdaptRecipe | None = None,
    *,
    reuse: dict[str, Path] | None = None,
    out_dir: str | Path | None = None,
    progress: bool = True,
    **changes: Any,
) -> dict[str, Path]:
    """Fine-tune ``network`` once per label source on the robot's frames (:func:`robot_views`).

    Parameters
    ----------
    data_root, network, robot, sources
        The pipeline's data root, the network to adapt, :func:`robot_views` and the label sources.
    recipe : AdaptRecipe, optional
        The fine-tuning recipe (default :class:`semmatch.segment.adapt.AdaptRecipe`'s).
    reuse : dict, optional
        ``{source: checkpoint}`` already fine-tuned with this very recipe from the same network
        (e.g. :func:`chosen_recipe_checkpoint`): copied instead of trained again.
    out_dir : path, optional
        Where the checkpoints go (default: ``data/<profile>/adapted/``, the stage's output).
    progress : bool
    **changes
        Fields of the recipe set over ``recipe`` (``lr=4e-3``).

    Returns
    -------
    dict
        ``{adapted name: checkpoint path}`` (under ``out_dir``).

    Raises
    ------
    ValueError
        A checkpoint in ``reuse`` was adapted from another network, with another label source or
        with another recipe.
    TypeError
        A change that is not a field of the recipe.
    """
    layout = Layout(data_root)
    recipe = AdaptRecipe.of(recipe, **changes)
    out = {}
    for s in sources:
        name = adapted_name(network, s)
        target = Path(out_dir or _adapt_dir(data_root)) / f"{name}.pt"
        if reuse and s in reuse:
            out[name] = _reuse_checkpoint(Path(reuse[s]), target, layout.model(network), s, recipe, robot)
            continue
        out[name] = fine_tune(layout.model(network), robot, s, target, recipe, progress=progress)
    return out


def _reuse_checkpoint(path: Path, target: Path, source_net: Path, source: str, recipe: AdaptRecipe,
                      robot: RobotViews) -> Path:
    """Copy an adapted checkpoint to ``target`` after checking that its provenance is the request's."""
    import shutil

    from ..io.files import atomic_path
    from ..segment.adapt.finetune import file_digest
    from ..segment.models import read_checkpoint

    ckpt = read_checkpoint(path)  # weights only: a checkpoint found in the data folder is data, never code
    got = (ckpt.get("adapted") if isinstance(ckpt, dict) else None) or {}
    want = {**recipe.as_dict(), "label_source": source, "from_sha256": file_digest(Path(source_net)),
            "scenes": list(robot.scenes), "frames": int(len(robot.views))}
    diff = {k: (got.get(k), v) for k, v in want.items() if got.get(k) != v}
    if diff:
        raise ValueError(f"{path}: cannot reuse it as the {source!r} adaptation; it differs in "
                         + ", ".join(f"{k} (has {a!r}, asked {b!r})" for k, (a, b) in diff.items()))
    with atomic_path(target) as tmp:
        shutil.copyfile(path, tmp)
    return target


def chosen_recipe_checkpoint(data_root: str | Path, table: pd.DataFrame) -> Path:
    """The checkpoint :func:`choose_adaptation_recipe` fine-tuned with the chosen recipe (its
    ``source``'s labels): ``reuse`` for :func:`adapt_networks`.

    Raises
    ------
    ValueError
        ``table`` has not exactly one chosen row.
    """
    chosen = table[table["chosen"].astype(bool)]
    if len(chosen) != 1:
        raise ValueError(f"the recipe table has {len(chosen)} chosen rows; need exactly one")
    return _adapt_dir(data_root) / "recipe" / f"candidate{int(chosen['candidate'].iloc[0])}.pt"


def recipe_candidates(grid: dict) -> list[dict]:
    """Every combination of a recipe grid (``{"lr": [...], "upper_share": [...], "steps": [...],
    "distill": [...]}``),
    in the grid's order (the first key varies slowest).

    Raises
    ------
    ValueError
        An empty grid, a key that is not a field of :class:`semmatch.segment.adapt.AdaptRecipe` (the seed
        aside), or an empty list.
    """
    import itertools

    known = tuple(k for k in AdaptRecipe.names() if k != "seed")  # the seed is the run's, never chosen
    if not grid:
        raise ValueError("the adaptation recipe grid is empty")
    bad = [k for k in grid if k not in known]
    if bad:
        raise ValueError(f"recipe grid keys {bad} unknown; allowed: {', '.join(known)}")
    values = {k: list(v) if isinstance(v, list | tuple) else [v] for k, v in grid.items()}
    empty = [k for k, v in values.items() if not v]
    if empty:
        raise ValueError(f"recipe grid key(s) {empty} have no values")
    return [dict(zip(values, combo, strict=True)) for combo in itertools.product(*values.values())]


def choose_adaptation_recipe(
    data_root: str | Path,
    network: str,
    robot: RobotViews,
    candidates: Sequence[dict],
    *,
    source: str = "3d-neighborhood",
    defaults: dict | None = None,
    max_forgetting: float = 0.02,
    low: float = 0.2,
    high: float = 1.6,
    seed: int = 0,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
) -> tuple[dict, pd.DataFrame]:
    """Choose the fine-tuning recipe on the **validation** scenes' height sweeps.

    Each candidate fine-tunes ``network`` with ``source`` labels of the robot's training frames;
    the adapted network and the unadapted one label the validation sweeps at ``low`` and
    ``high``; per candidate, the paired per-scene mIoU differences to the unadapted network give
    ``gain_low`` and ``change_high`` (:func:`gap_table`). The rule, fixed before any run: among
    the candidates that lose at most ``max_forgetting`` mIoU at ``high`` on average, the one with
    the largest gain at ``low``; when none does, the one that loses least at ``high``. Ties: the
    first listed. No evaluation scene takes part.

    Parameters
    ----------
    data_root : path
        The pipeline's data root (validation sweeps ``scenes/val/<scene>/h020 ..``).
    network : str
    robot : RobotViews
        :func:`robot_views` (must carry ``source``).
    candidates : sequence of dict
        Fields of :class:`semmatch.segment.adapt.AdaptRecipe` (``lr``, ``upper_share``, ``steps``,
        ``batch_size``, ``distill``), e.g. :func:`recipe_candidates`.
    source : str
        The label source the recipe is chosen with (one recipe for every source).
    defaults : dict, optional
        Fields every candidate starts from (the profile's ``steps``, ``batch_size`` ...); the
        rest are :class:`semmatch.segment.adapt.AdaptRecipe`'s defaults.
    max_forgetting : float
        Largest acceptable mean mIoU loss at ``high``.
    low, high : float
        The robot's and the person's camera heights (m); both must be in the sweeps.
    seed, jobs, scheduler, progress
        As for :func:`adapted_height_study`.

    Returns
    -------
    chosen : dict
        The chosen candidate merged into ``defaults``.
    table : DataFrame
        One row per candidate: its keywords, ``miou@low``/``miou@high`` with intervals, ``gain_low``,
        ``change_high`` and ``gap_closed`` (with intervals), ``within_forgetting``, ``chosen``.

    Raises
    ------
    ValueError
        No candidates, or ``max_forgetting`` < 0.
    FileNotFoundError
        The validation scenes have no sweep at ``low`` or ``high``.
    """
    if not candidates:
        raise ValueError("no adaptation recipes to choose from")
    if not max_forgetting >= 0:
        raise ValueError(f"max_forgetting must be >= 0, got {max_forgetting}")
    layout = Layout(data_root)
    validation_gap_sweeps(data_root, low, high)  # before any fine-tuning: the sweeps exist
    base = dict(defaults or {})
    trials = [base | dict(c) for c in candidates]
    recipe_dir = _adapt_dir(data_root) / "recipe"
    checkpoints = [fine_tune(layout.model(network), robot, source, recipe_dir / f"candidate{i}.pt", seed=seed,
                             progress=progress, **kw) for i, kw in enumerate(trials)]
    table = score_recipe_candidates(data_root, network, trials, checkpoints, source=source,
                                    max_forgetting=max_forgetting, low=low, high=high, jobs=jobs,
                                    scheduler=scheduler, progress=progress)
    return trials[int(np.flatnonzero(table["chosen"])[0])], table


def score_recipe_candidates(
    data_root: str | Path,
    network: str,
    trials: Sequence[dict],
    checkpoints: Sequence[str | Path],
    *,
    source: str,
    max_forgetting: float = 0.02,
    low: float = 0.2,
    high: float = 1.6,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
) -> pd.DataFrame:
    """Score fine-tuned candidates on the **validation** sweeps and pick one (:func:`pick_recipe`).

    The scoring and rule of :func:`choose_adaptation_recipe`, for checkpoints fine-tuned
    beforehand (``checkpoints[i]`` with the recipe ``trials[i]`` and ``source`` labels).

    Returns
    -------
    DataFrame
        One row per candidate, as :func:`choose_adaptation_recipe`'s table.

    Raises
    ------
    ValueError
        ``trials`` and ``checkpoints`` differ in length, or are empty.
    """
    if len(trials) != len(checkpoints) or not trials:
        raise ValueError(f"{len(trials)} recipes for {len(checkpoints)} checkpoints")
    heights = validation_gap_sweeps(data_root, low, high)
    named = {f"candidate{i}": Path(c) for i, c in enumerate(checkpoints)}
    per_scene = score_on_sweeps(data_root, network, named, heights, jobs=jobs, scheduler=scheduler,
                                progress=progress)
    gaps = gap_table(per_scene, network, low=low, high=high).set_index("model")
    rows = []
    for i, kw in enumerate(trials):
        g = gaps.loc[f"candidate{i}"]
        # lr as text: a table's fixed decimals would print 1e-4 as 0.000
        rows.append({"candidate": i, **{k: (f"{kw[k]:g}" if k == "lr" else kw[k]) for k in sorted(kw)}, "source": source,
                     **{k: float(g[k]) for k in g.index if k not in ("source",)}})
    return pick_recipe(pd.DataFrame(rows), max_forgetting)


def pick_recipe(table: pd.DataFrame, max_forgetting: float = 0.02) -> pd.DataFrame:
    """The rule of :func:`choose_adaptation_recipe` on a table of candidates.

    Among the rows whose ``change_high`` is >= ``-max_forgetting``, the largest ``gain_low``;
    when no row is, the largest ``change_high``. Ties: the first row.

    Parameters
    ----------
    table : DataFrame
        One row per candidate with ``gain_low`` and ``change_high``.
    max_forgetting : float

    Returns
    -------
    DataFrame
        ``table`` (index reset) with ``within_forgetting`` and ``chosen`` (exactly one True).

    Raises
    ------
    ValueError
        An empty table, or non-finite ``gain_low`` / ``change_high``.
    """
    t = table.reset_index(drop=True).copy()
    if t.empty:
        raise ValueError("no adaptation recipes to choose from")
    vals = t[["gain_low", "change_high"]].to_numpy(dtype=np.float64)
    if not np.isfinite(vals).all():
        raise ValueError("recipe table has non-finite gain_low/change_high (a candidate scored no validation scene)")
    t["within_forgetting"] = t["change_high"] >= -max_forgetting
    ok = t[t["within_forgetting"]]
    best = int(ok["gain_low"].idxmax()) if len(ok) else int(t["change_high"].idxmax())
    t["chosen"] = t.index == best
    return t


def load_adapted(data_root: str | Path, network: str, checkpoints: dict[str, Path]) -> dict:
    """The adapted networks (``{name: Segmenter}``) with the source network's inference recipe
    (mirror averaging as chosen for it on validation)."""
    from ..segment import load_model

    flip = Layout(data_root).inference_flip(network)
    return {name: load_model(p) if flip is None else load_model(p, flip=flip) for name, p in checkpoints.items()}


def adapted_height_study(data_root: str | Path, network: str, checkpoints: dict[str, Path], *, frame_step: int = 1,
                         jobs: int = 1, scheduler: str | None = None, progress: bool = True) -> pd.DataFrame:
    """Per-scene pixel scores of the unadapted and every adapted network on the evaluation
    scenes' height sweeps (:func:`semmatch.segment.viewpoint.viewpoint_gap_sequences`, every
    ``frame_step``-th frame of each sweep; the scenes are engine tasks on ``jobs`` local worker
    processes or the cluster at ``scheduler``)."""
    from .height import sweep_sequences

    return score_on_sweeps(data_root, network, checkpoints, sweep_sequences(data_root), frame_step=frame_step,
                           jobs=jobs, scheduler=scheduler, progress=progress)


def validation_gap_sweeps(data_root: str | Path, low: float = 0.2, high: float = 1.6) -> dict:
    """The validation scenes' sweeps at ``low`` and ``high`` (``{height: sequences}``).

    Raises
    ------
    FileNotFoundError
        The validation sweeps lack one of the two heights.
    """
    from .height import sweep_sequences

    sweeps = sweep_sequences(data_root, "val")
    heights = {h: p for h, p in sweeps.items() if np.isclose(h, low) or np.isclose(h, high)}
    if len(heights) != 2:
        raise FileNotFoundError(f"{Layout(data_root).scenes / 'val'}: the validation sweeps have heights "
                                f"{sorted(sweeps)}; need {low:g} m and {high:g} m")
    return heights


def score_on_sweeps(data_root: str | Path, network: str, checkpoints: dict[str, Path], sweeps: dict, *,
                    frame_step: int = 1, jobs: int = 1, scheduler: str | None = None,
                    progress: bool = True) -> pd.DataFrame:
    """Per-scene pixel scores of ``network`` and its adapted ``checkpoints`` on ``sweeps``
    (``{height: sequences}``, every ``frame_step``-th frame;
    :func:`semmatch.segment.viewpoint.viewpoint_gap_sequences`)."""
    from ..segment.viewpoint import viewpoint_gap_sequences

    models = {network: Layout(data_root).load_network(network), **load_adapted(data_root, network, checkpoints)}
    return viewpoint_gap_sequences(models, sweeps, per_scene=True, frame_step=frame_step, jobs=jobs,
                                   scheduler=scheduler, progress=progress)


def _at_height(per_scene: pd.DataFrame, model: str, height: float, measure: str) -> pd.Series:
    """``measure`` of ``model`` at camera ``height`` per scene (indexed by scene)."""
    sel = per_scene[(per_scene["model"] == model) & np.isclose(per_scene["height"], height)]
    return sel.set_index("scene")[measure]


def gap_table(per_scene: pd.DataFrame, network: str, *, low: float = 0.2, high: float = 1.6,
              measure: str = "miou") -> pd.DataFrame:
    """The viewpoint gap closed by each adapted network, with 95 % intervals over scenes.

    Per model: ``measure`` at ``low`` and ``high`` (mean [interval]); ``gain_low`` (adapted minus
    unadapted at ``low``, paired over scenes) and ``change_high`` (the same at ``high``: negative
    = forgetting); ``gap_closed``: ``gain_low`` over the unadapted network's gap ``high - low``
    (mean gain over mean gap; its interval resamples the scenes with their gain and gap together,
    :func:`semmatch.evaluate.stats.ratio_of_means_ci`)."""
    def at(model: str, h: float) -> pd.Series:
        return _at_height(per_scene, model, h, measure)

    base_lo, base_hi = at(network, low), at(network, high)
    gap = float((base_hi - base_lo).mean())
    rows = []
    for model in dict.fromkeys(per_scene["model"]):
        lo, hi = at(model, low), at(model, high)
        row = {"model": model, "source": model.split("~", 1)[1] if "~" in model else "none (unadapted)"}
        for name, s in ((f"{measure}@{low:g}", lo), (f"{measure}@{high:g}", hi)):
            m, a, b = bootstrap_ci(s.values)
            row.update({name: m, f"{name}_lo": a, f"{name}_hi": b})
        lo_paired = lo.reindex(base_lo.index).values
        g = paired_difference_ci(lo_paired, base_lo.values)
        c = paired_difference_ci(hi.reindex(base_hi.index).values, base_hi.values)
        r = (ratio_of_means_ci(lo_paired - base_lo.values, (base_hi - base_lo).reindex(base_lo.index).values)
             if gap > 0 else (float("nan"),) * 3)
        row.update({"gain_low": g[0], "gain_low_lo": g[1], "gain_low_hi": g[2],
                    "change_high": c[0], "change_high_lo": c[1], "change_high_hi": c[2],
                    "gap_closed": r[0], "gap_closed_lo": r[1], "gap_closed_hi": r[2]})
        rows.append(row)
    return pd.DataFrame(rows)


def per_scene_changes(per_scene: pd.DataFrame, network: str, *, low: float = 0.2, high: float = 1.6,
                      measure: str = "miou") -> pd.DataFrame:
    """Per adapted model and scene: the unadapted network's gap (``high`` minus ``low``), the
    adapted network's gain at ``low`` and its change at ``high`` (paired with the unadapted
    network on the same scene)."""
    def at(model: str, h: float) -> pd.Series:
        return _at_height(per_scene, model, h, measure)

    base_lo, base_hi = at(network, low), at(network, high)
    rows = []
    for model in dict.fromkeys(per_scene["model"]):
        if model == network:
            continue
        lo, hi = at(model, low).reindex(base_lo.index), at(model, high).reindex(base_hi.index)
        for sc in base_lo.index:
            rows.append({"model": model, "source": model.split("~", 1)[-1], "scene": sc,
                         "gap": float(base_hi[sc] - base_lo[sc]), "gain_low": float(lo[sc] - base_lo[sc]),
                         "change_high": float(hi[sc] - base_hi[sc])})
    return pd.DataFrame(rows, columns=["model", "source", "scene", "gap", "gain_low", "change_high"])


def gap_bounds(per_scene: pd.DataFrame, network: str, *, low: float = 0.2, high: float = 1.6, measure: str = "miou",
               target: float = 0.6, forgetting: float = 0.02, confidence: float = 0.95) -> pd.DataFrame:
    """One-sided bounds on what each adapted network achieved, per scene and over scenes.

    Per adapted model: ``gap_closed`` (mean gain at ``low`` over mean gap, as :func:`gap_table`)
    and its one-sided ``confidence`` lower bound (:func:`semmatch.evaluate.stats.ratio_lower_bound`:
    Fieller's bound from the one-sample t over scenes, the analysis plan's method), whether that
    bound clears ``target``; the change at ``high`` per scene (median, smallest, largest), the
    number of scenes that lose more than ``forgetting`` there, and the one-sided lower bound of
    the mean change (t over scenes).
    """
    from scipy import stats as st

    d = per_scene_changes(per_scene, network, low=low, high=high, measure=measure)
    rows = []
    for model, g in d.groupby("model", sort=False):
        g = g.dropna()
        n = len(g)
        ch = g["change_high"].to_numpy()
        se = float(ch.std(ddof=1) / np.sqrt(n)) if n > 1 else float("nan")
        lb = ratio_lower_bound(g["gain_low"], g["gap"], confidence=confidence) if n > 1 else float("nan")
        rows.append({"model": model, "source": g["source"].iloc[0], "scenes": n,
                     "gap_closed": float(g["gain_low"].mean() / g["gap"].mean()),
                     "gap_closed_lower": lb, "clears_target": bool(lb >= target), "target": target,
                     "change_high": float(ch.mean()),
                     "change_high_lower": float(ch.mean() - st.t.ppf(confidence, n - 1) * se) if n > 1 else float("nan"),
                     "change_high_median": float(np.median(ch)), "change_high_min": float(ch.min()),
                     "change_high_max": float(ch.max()), "scenes_losing": int((ch < -forgetting).sum()),
                     "confidence": confidence})
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
        Scenes run as tasks of :func:`semmatch.runtime.engine.map_tasks` on ``jobs`` local worker
        processes (1: in this process).
    scheduler : str, optional
        Dask scheduler address to run the scenes on (default ``SEMMATCH_SCHEDULER``; none: local).
    progress : bool

    Returns
    -------
    DataFrame
        ``scene``, ``model``, ``method`` (``lower``) and the paper's measures.
    """
    rows = Layout(data_root).map_scenes(_adapted_lower_scene, networks, float(voxel_size), float(eval_voxel_size),
                                        jobs=jobs, scheduler=scheduler, desc="adapted lower maps", progress=progress)
    return pd.DataFrame(rows)


def _adapted_lower_scene(data_root: str, networks: dict[str, object], voxel_size: float, eval_voxel_size: float,
                         sid: str) -> list[dict]:
    """The rows of one scene (a task of :func:`adapted_lower_maps`)."""
    from ..fusion import reconstruct_many

    layout = Layout(data_root)
    seq = read_sequence(layout.lower_sequence(layout.scenes / "eval" / sid)).load()
    labelings = [[m.predict_labels(f.rgb) for f in seq] for m in networks.values()]
    maps = reconstruct_many(seq, labelings, voxel_size)
    ref = reference_grid(layout.lower_reference(sid), eval_voxel_size)  # voxelised once for every network
    origin = eval_grid_origin(eval_voxel_size)
    rows = []
    for name, pred in zip(networks, maps, strict=True):
        s = compare(ref, pred, eval_voxel_size, grid_origin=origin)
        rows.append({"scene": sid, "model": name, "method": "lower", **{k: float(s[k]) for k in MEASURES}})
    return rows


def robot_map_comparison(table2: pd.DataFrame, network: str, *, against: Sequence[str] = ("3d-neighborhood", "fused"),
                         measures: Sequence[str] = ("mean_acc",), seed: int = 0) -> pd.DataFrame:
    """Does the adapted robot beat transfer from the person's map on its own? Paired per-scene
    differences of each adapted network's own lower map against ``network``'s rows.

    Parameters
    ----------
    table2 : DataFrame
        Per-scene Table 2 rows (``scene``, ``model``, ``method`` and the measures): ``network``'s
        rows (``lower`` and the ``against`` methods) and the adapted networks' ``lower`` rows
        (models ``<network>~<source>``), as notebook 09's ``table2_adapted_per_scene``.
    network : str
        The unadapted network.
    against : sequence of str
        ``network``'s methods to compare with besides its own ``lower`` map (transfer methods,
        ``fused``).
    measures : sequence of str
    seed : int
        Seed of the bootstrap.

    Returns
    -------
    DataFrame
        One row per adapted network, compared method and measure: ``model``, ``against``,
        ``measure``, ``diff`` (adapted minus the other, mean over scenes), ``lo``, ``hi`` (95 %
        paired bootstrap interval), ``scenes`` and ``verdict``: ``beats`` when the interval lies
        above 0, ``loses`` below, otherwise ``not resolved``.

    Raises
    ------
    ValueError
        ``table2`` has no adapted network's ``lower`` rows, or lacks a compared method of ``network``.
    """
    adapted = [m for m in dict.fromkeys(table2["model"]) if str(m).startswith(f"{network}~")]
    if not adapted:
        raise ValueError(f"the table has no adapted {network} rows (models {network}~<source>)")
    base = table2[table2["model"] == network]
    missing = [m for m in ("lower", *against) if m not in set(base["method"])]
    if missing:
        raise ValueError(f"the table has no {network} rows of {', '.join(missing)}")
    rows = []
    for model in adapted:
        own = table2[(table2["model"] == model) & (table2["method"] == "lower")].set_index("scene")
        for other in ("lower", *against):
            ref = base[base["method"] == other].set_index("scene")
            scenes = own.index.intersection(ref.index)
            for m in measures:
                d, lo, hi = paired_difference_ci(own.loc[scenes, m].to_numpy(np.float64),
                                                 ref.loc[scenes, m].to_numpy(np.float64), seed=seed)
                verdict = "beats" if lo > 0 else "loses" if hi < 0 else "not resolved"
                rows.append({"model": model, "against": f"{network} {other}", "measure": m, "diff": d, "lo": lo,
                             "hi": hi, "scenes": int(len(scenes)), "verdict": verdict})
    return pd.DataFrame(rows)
