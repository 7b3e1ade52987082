"""Shipped adapted networks: stage 09's fine-tuned checkpoints and its recipe choice, committed
under ``models/<profile>/adapted/`` so that ``make repro`` scores them instead of fine-tuning again.

A shipped adaptation holds, per label source, ``<network>~<source>.pt`` (loaded with
``weights_only=True``), the validation table of the recipe choice (``validation_adapt_recipe.csv``)
and ``adaptation.json``: the *request* the checkpoints answer (the source network's SHA-256 prefix,
the adaptation scenes and frame count, the sources, the recipe grid, the recipe's label source,
the fixed fields, the forgetting bound and the seed), the chosen recipe, each checkpoint's SHA-256,
the code version and where the fine-tuning ran. Notebook 09 (:func:`provide_adaptation`) uses it
when its request equals the one the profile makes, and fine-tunes otherwise (and always with
``make repro TRAIN=1``); each reused checkpoint is checked once more against its own provenance
record (:func:`semmatch.experiments.adapt.adapt_networks`). ``python -m semmatch.experiments
ship-adapted`` writes the folder from a pipeline run.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from ..io import atomic_path, atomic_write_text
from ..segment.adapt import AdaptRecipe, RobotViews, adapted_name
from .adapt import adapt_networks, choose_adaptation_recipe, chosen_recipe_checkpoint, recipe_candidates
from .layout import Layout

__all__ = ["ADAPTATION_FORMAT", "MANIFEST", "RECIPE_TABLE", "adaptation_request", "ship_adaptation",
           "shipped_adaptation", "provide_adaptation"]

#: the ``format`` entry of ``adaptation.json``
ADAPTATION_FORMAT = "semmatch-shipped-adaptation-1"
#: the manifest's file name in a shipped adaptation folder
MANIFEST = "adaptation.json"
#: the recipe choice's validation table in a shipped adaptation folder
RECIPE_TABLE = "validation_adapt_recipe.csv"


def _plain(value: Any) -> Any:
    """``value`` as JSON reads it back (tuples as lists, numpy numbers as Python numbers)."""
    return json.loads(json.dumps(value, default=lambda o: o.item() if hasattr(o, "item") else str(o)))


def adaptation_request(*, network_sha256: str, scenes: Sequence[str], frames: int, sources: Sequence[str],
                       recipe_grid: Mapping, recipe_source: str, defaults: Mapping, max_forgetting: float,
                       seed: int) -> dict:
    """What stage 09 asks of its adapted networks, in the form ``adaptation.json`` stores.

    Parameters
    ----------
    network_sha256 : str
        SHA-256 prefix of the source network's checkpoint (as the adapted checkpoints record it).
    scenes, frames
        The adaptation scenes and the number of robot frames fine-tuned on.
    sources, recipe_grid, recipe_source, defaults, max_forgetting, seed
        Notebook 09's parameters of the same names (``defaults``: the fields every recipe
        candidate starts from, ``steps`` and ``batch_size``).

    Returns
    -------
    dict
    """
    return _plain({"network_sha256": network_sha256, "scenes": list(scenes), "frames": int(frames),
                   "sources": list(sources), "recipe_grid": dict(recipe_grid), "recipe_source": recipe_source,
                   "defaults": dict(defaults), "max_forgetting": float(max_forgetting), "seed": int(seed)})


def ship_adaptation(data_root: str | os.PathLike, network: str, dest: str | os.PathLike, *,
                    parameters: Mapping[str, Any], recipe_table: str | os.PathLike,
                    code_version: str | None = None, note: str | None = None,
                    checkpoints_dir: str | os.PathLike | None = None,
                    trained_on: str = "CPU (notebook 09 of a make repro run)") -> list[Path]:
    """Copy a pipeline run's adapted checkpoints and recipe choice into a shipped folder.

    Parameters
    ----------
    data_root : path
        The run's data root (``adapted/<network>~<source>.pt``).
    network : str
        The adapted network's name.
    dest : path
        The shipped folder (e.g. ``models/full/adapted``); a former shipped adaptation there is
        replaced as a whole, any other non-empty folder is refused.
    parameters : mapping
        Notebook 09's parameters of that run (``sources``, ``recipe_grid``, ``recipe_source``,
        ``steps``, ``batch_size``, ``max_forgetting``, ``seed``).
    recipe_table : path
        The run's ``validation_adapt_recipe.csv``.
    code_version, note : str, optional
        Recorded in the manifest.
    checkpoints_dir : path, optional
        Where the checkpoints are (default ``data_root/adapted``, the stage's), e.g. another
        fine-tuning seed's (``parameters["seed"]`` is then that seed).
    trained_on : str
        Where the fine-tuning ran, recorded in the manifest.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    FileNotFoundError
        A source's checkpoint or the recipe table is missing.
    FileExistsError
        ``dest`` is a non-empty folder that holds no shipped adaptation.
    ValueError
        The checkpoints disagree on what they were adapted from, or the recipe table has no
        single chosen row.
    """
    from ..segment.models import read_checkpoint
    from ..segment.shipping import file_sha256

    sources = list(parameters["sources"])
    adapted = Path(checkpoints_dir) if checkpoints_dir is not None else Path(data_root) / "adapted"
    paths = {s: adapted / f"{adapted_name(network, s)}.pt" for s in sources}
    missing = [str(p) for p in paths.values() if not p.is_file()]
    if missing or not Path(recipe_table).is_file():
        raise FileNotFoundError(f"cannot ship the adaptation: missing {', '.join(missing or [str(recipe_table)])}")
    records = {s: read_checkpoint(p).get("adapted") or {} for s, p in paths.items()}
    common = {(r.get("from_sha256"), tuple(r.get("scenes") or ()), r.get("frames")) for r in records.values()}
    if len(common) != 1:
        raise ValueError(f"{adapted}: the checkpoints were adapted from different networks, scenes or frames")
    table = pd.read_csv(recipe_table)
    if int(table["chosen"].astype(bool).sum()) != 1:
        raise ValueError(f"{recipe_table}: need exactly one chosen recipe")
    first = records[sources[0]]
    seeds = {int(r.get("seed", -1)) for r in records.values()}
    if seeds != {int(parameters["seed"])}:
        raise ValueError(f"{adapted}: the checkpoints were fine-tuned with seed(s) {sorted(seeds)}, "
                         f"not the request's {int(parameters['seed'])}")
    recipe = {k: first[k] for k in AdaptRecipe.names() if k != "seed"}
    request = adaptation_request(
        network_sha256=first["from_sha256"], scenes=first["scenes"], frames=first["frames"], sources=sources,
        recipe_grid=parameters["recipe_grid"], recipe_source=parameters["recipe_source"],
        defaults={"steps": parameters["steps"], "batch_size": parameters["batch_size"]},
        max_forgetting=parameters["max_forgetting"], seed=parameters["seed"])
    dest = Path(dest)
    if dest.exists():
        if not (dest / MANIFEST).is_file() and any(dest.iterdir()):  # replace only what this function wrote
            raise FileExistsError(f"{dest}: not empty and not a shipped adaptation (no {MANIFEST}); "
                                  "choose an empty or new folder")
        shutil.rmtree(dest)
    dest.mkdir(parents=True)
    written = []
    for p in paths.values():
        with atomic_path(dest / p.name) as tmp:
            shutil.copyfile(p, tmp)
        written.append(dest / p.name)
    with atomic_path(dest / RECIPE_TABLE) as tmp:
        shutil.copyfile(recipe_table, tmp)
    written.append(dest / RECIPE_TABLE)
    manifest = {
        "format": ADAPTATION_FORMAT, "network": network, "request": request, "recipe": _plain(recipe),
        "checkpoints": {s: {"file": p.name, "sha256": file_sha256(p), "size_bytes": p.stat().st_size,
                            "seconds": records[s].get("seconds"), "final_loss": records[s].get("final_loss"),
                            "label_coverage": records[s].get("label_coverage")} for s, p in paths.items()},
        "code_version": code_version, "trained_on": trained_on,
        "shipped_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), **({"note": note} if note else {}),
    }
    atomic_write_text(dest / MANIFEST, json.dumps(_plain(manifest), indent=2) + "\n")
    written.append(dest / MANIFEST)
    return written


def shipped_adaptation(shipped_dir: str | os.PathLike, request: Mapping) -> tuple[tuple | None, str]:
    """The shipped adaptation that answers ``request``, or why there is none.

    Returns
    -------
    shipped : (recipe, recipe_table, checkpoints) or None
        The chosen recipe (fields of :class:`semmatch.segment.adapt.AdaptRecipe`, the seed aside), the
        validation table of the choice and ``{source: checkpoint path}``.
    why : str
        Why nothing is shipped for ``request`` ("" when something is).
    """
    from ..segment.shipping import file_sha256

    folder = Path(shipped_dir)
    man = folder / MANIFEST
    if not man.is_file():
        return None, f"no shipped adaptation in {folder}"
    try:
        m = json.loads(man.read_text())
    except (OSError, json.JSONDecodeError) as e:
        return None, f"{man}: unreadable ({e})"
    if m.get("format") != ADAPTATION_FORMAT:
        return None, f"{man}: format {m.get('format')!r}, not {ADAPTATION_FORMAT!r}"
    want = _plain(dict(request))
    diff = sorted(k for k in set(want) | set(m.get("request", {})) if m.get("request", {}).get(k) != want.get(k))
    if diff:
        return None, f"{man}: shipped for another request (differs in {', '.join(diff)})"
    paths = {}
    for s in want["sources"]:
        entry = m.get("checkpoints", {}).get(s) or {}
        name = str(entry.get("file", ""))
        if not name or Path(name).name != name:  # a bare file name inside the folder, nothing else
            return None, f"{man}: the checkpoint of {s!r} is named {name!r}, not a file of {folder}"
        p = folder / name
        if not p.is_file() or file_sha256(p) != entry.get("sha256"):
            return None, f"{folder}: the checkpoint of {s!r} is missing or not the one the manifest names"
        paths[s] = p
    if not (folder / RECIPE_TABLE).is_file():
        return None, f"{folder}: the recipe table {RECIPE_TABLE} is missing"
    return (dict(m["recipe"]), pd.read_csv(folder / RECIPE_TABLE), paths), ""


def provide_adaptation(
    data_root: str | os.PathLike,
    network: str,
    robot: RobotViews,
    sources: Sequence[str],
    *,
    recipe_grid: Mapping,
    recipe_source: str,
    defaults: Mapping,
    max_forgetting: float,
    seed: int = 0,
    shipped_dir: str | os.PathLike | None = None,
    retrain: bool = False,
    require_shipped: bool = False,
    jobs: int = 1,
    progress: bool = True,
) -> tuple[dict, pd.DataFrame, dict[str, Path], str]:
    """Notebook 09's adapted networks: the shipped ones when they answer this very request,
    else chosen on validation and fine-tuned here.

    Parameters
    ----------
    data_root, network, robot, sources
        As :func:`semmatch.experiments.adapt.adapt_networks`.
    recipe_grid, recipe_source, defaults, max_forgetting, seed, jobs
        As :func:`semmatch.experiments.adapt.choose_adaptation_recipe` (``recipe_grid`` through
        :func:`~semmatch.experiments.adapt.recipe_candidates`).
    shipped_dir : path, optional
        The shipped adaptation folder (``models/<profile>/adapted``; None: none).
    retrain : bool
        Fine-tune even when a shipped adaptation answers the request (``make repro TRAIN=1``).
    require_shipped : bool
        Never fine-tune: without a shipped adaptation that answers the request, raise (a
        confirmatory run scores what was shipped and trains nothing).
    progress : bool

    Returns
    -------
    recipe : dict
        The chosen recipe's fields.
    recipe_table : DataFrame
        The validation table of the choice (shipped, or made here).
    checkpoints : dict
        ``{adapted name: checkpoint path}`` under ``data_root/adapted``.
    how : str
        Where they came from, for the notebook to print.

    Raises
    ------
    ValueError
        ``require_shipped`` and no shipped adaptation answers the request (naming why), or
        ``retrain`` with ``require_shipped``.
    """
    from ..segment.adapt.finetune import file_digest

    request = adaptation_request(
        network_sha256=file_digest(Layout(data_root).model(network)), scenes=robot.scenes, frames=len(robot.views),
        sources=sources, recipe_grid=recipe_grid, recipe_source=recipe_source, defaults=defaults,
        max_forgetting=max_forgetting, seed=seed)
    if retrain and require_shipped:
        raise ValueError("retrain and require_shipped exclude each other")
    why = "make repro TRAIN=1 asks for it"
    if not retrain:
        shipped, why = shipped_adaptation(shipped_dir, request) if shipped_dir else (None, "no shipped folder given")
        if shipped is not None:
            recipe, table, paths = shipped
            checkpoints = adapt_networks(data_root, network, robot, sources, seed=seed, reuse=paths,
                                         progress=progress, **recipe)
            return recipe, table, checkpoints, f"shipped ({shipped_dir}): nothing fine-tuned here"
        if require_shipped:
            raise ValueError(f"the shipped adapted networks are required here (a confirmatory run fine-tunes nothing), "
                             f"but {why}")
    recipe, table = choose_adaptation_recipe(
        data_root, network, robot, recipe_candidates(dict(recipe_grid)), source=recipe_source,
        defaults=dict(defaults), max_forgetting=max_forgetting, seed=seed, jobs=jobs, progress=progress)
    checkpoints = adapt_networks(data_root, network, robot, sources, seed=seed, progress=progress,
                                 reuse={recipe_source: chosen_recipe_checkpoint(data_root, table)}, **recipe)
    return recipe, table, checkpoints, f"fine-tuned here ({why})"
