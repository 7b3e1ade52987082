"""Shipped networks: checkpoints committed under ``models/<profile>/`` with a manifest each.

A shipped folder holds, per network, ``<name>.pt`` (the checkpoint, loaded with
``weights_only=True``) and ``<name>.json`` (its manifest: training configuration, SHA-256 of the
training data, of the checkpoint file and of its weights, training time, where it was trained,
validation scores, date), plus ``recipe.json`` (the test-time flip choice made on the validation sweeps).

Notebook 02 (:func:`provide_networks`) uses a shipped checkpoint when its training
configuration equals the one the profile asks for, and trains otherwise; ``make repro TRAIN=1``
(``SEMMATCH_TRAIN=1``) trains every network, a network shipped from a CPU run with that run's
torch thread count (the thread count sets the order of the floating-point sums, and one thread
reproduces a one-thread run's weights bit for bit), and says whether the weights came out the
same as the shipped ones (:func:`weights_sha256`). ``python -m semmatch.experiments ship`` writes a
shipped folder from trained checkpoints.

Several training seeds of an architecture are shipped under the pipeline's network names
(:func:`~semmatch.segment.train_config.network_spec`): ``compact.pt`` is training seed 0,
``compact@1.pt`` and ``compact@2.pt`` seeds 1 and 2 of the same configuration, each with its
manifest (``compact@1.json``). Notebook 02 finds them as it finds ``compact.pt`` (a network
``compact@1`` of ``params.yaml`` looks for ``compact@1.pt``); :func:`shipped_seeds` lists an
architecture's seeds and :func:`load_shipped_network` loads one after checking its digests.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

from ..io import atomic_path, atomic_write_text

__all__ = [
    "MANIFEST_FORMAT", "file_sha256", "weights_sha256", "network_manifest", "ship_networks", "shipped_checkpoint",
    "install_checkpoint", "provide_networks", "shipped_run", "apply_shipped_recipe",
    "check_shipped_checkpoint", "shipped_seeds", "load_shipped_network",
]

#: the ``format`` entry of a manifest
MANIFEST_FORMAT = "semmatch-shipped-network-1"

#: what the manifest's ``training_data.views_sha256`` is computed over
DATA_HASH_NOTE = ("SHA-256 over the rendered training views, then the validation views: for each, the rgb (uint8), "
                  "depth (float32) and labels (uint8) arrays with their dtype and shape "
                  "(semmatch.segment.training.views_digest). The views are generated from train_config "
                  "(scene seeds, kinds, heights, frames, resolution, seed) by the code at code_version.")


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def weights_sha256(checkpoint: str | os.PathLike) -> str:
    """SHA-256 (hex) of a checkpoint's weights: every tensor of its ``state_dict`` in key order,
    each with its name, dtype and shape.

    A checkpoint file also stores when, where and how long its network was trained, so two runs
    that learn the same weights write different files (:func:`file_sha256`); this digest is the
    same for them.

    Parameters
    ----------
    checkpoint : path
        A checkpoint written by :func:`semmatch.segment.train` (loaded with ``weights_only=True``).

    Returns
    -------
    str
    """
    import torch

    state = torch.load(checkpoint, map_location="cpu", weights_only=True)["state_dict"]
    h = hashlib.sha256()
    for name in sorted(state):
        t = state[name].detach().cpu().contiguous()
        h.update(f"{name}|{t.dtype}|{tuple(t.shape)}|".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())
    return h.hexdigest()


def network_manifest(checkpoint: str | os.PathLike, *, code_version: str | None = None) -> dict:
    """The manifest of a trained checkpoint (what :func:`ship_networks` writes beside it).

    Parameters
    ----------
    checkpoint : path
        A checkpoint written by :func:`semmatch.segment.train`.
    code_version : str, optional
        The git commit the network was trained with.

    Returns
    -------
    dict
        ``format``, ``network``, ``checkpoint``, ``checkpoint_sha256``, ``weights_sha256``,
        ``size_bytes``,
        ``train_config``, ``training_data`` (``views_sha256`` and what it hashes),
        ``code_version``, ``train_seconds``, ``trained_on`` (device, CPU/GPU model, threads,
        load average), ``trained_at`` (UTC), ``validation`` (best step and its scores).

    Raises
    ------
    ValueError
        The checkpoint records no hash of its training data (trained before it was stored).
    """
    from .predict import load_model

    path = Path(checkpoint)
    info = load_model(path).info
    if not info.get("views_sha256"):
        raise ValueError(f"{path}: the checkpoint records no hash of its training data (views_sha256): "
                         f"retrain it with this version of semmatch before shipping it")
    m = info["metrics"]
    finished = info.get("finished_at") or time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(path.stat().st_mtime))
    return {
        "format": MANIFEST_FORMAT,
        "network": path.stem,
        "checkpoint": path.name,
        "checkpoint_sha256": file_sha256(path),
        "weights_sha256": weights_sha256(path),
        "size_bytes": path.stat().st_size,
        "train_config": info["train_config"],
        "training_data": {"views_sha256": info["views_sha256"], "hashed": DATA_HASH_NOTE},
        "code_version": code_version,
        "train_seconds": round(float(info["train_seconds"]), 1),
        "trained_on": info.get("machine") or {"device": info.get("device")},
        "trained_at": finished,
        "validation": {"best_step": m["step"], "miou": m["miou"], "pixel_acc": m["pixel_acc"],
                       "mean_acc": m["mean_acc"], "per_class_iou": m["per_class_iou"]},
    }


def ship_networks(checkpoints: Mapping[str, str | os.PathLike], dest: str | os.PathLike, *,
                  recipe: str | os.PathLike | None = None, code_version: str | None = None,
                  note: str | None = None) -> list[Path]:
    """Copy trained checkpoints into a shipped folder with a manifest each and the flip recipe.

    Parameters
    ----------
    checkpoints : mapping
        Network name -> checkpoint path.
    dest : path
        The shipped folder (e.g. ``models/full``).
    recipe : path, optional
        The ``recipe.json`` notebook 02 wrote for these networks; its flip choices for them are
        copied (other networks' entries are dropped).
    code_version : str, optional
        Recorded in each manifest.
    note : str, optional
        Recorded in each manifest as ``note`` (how the training run went, e.g. how busy the
        machine was and why its thread count was chosen).

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    ValueError
        The recipe has no flip choice for one of the networks, or a checkpoint cannot be shipped
        (:func:`network_manifest`).
    """
    dest = Path(dest)
    written = []
    flips = {}
    if recipe is not None:
        known = json.loads(Path(recipe).read_text()).get("flip", {})
        missing = [n for n in checkpoints if n not in known]
        if missing:
            raise ValueError(f"{recipe}: no flip choice for {', '.join(missing)}")
        flips = {n: bool(known[n]) for n in checkpoints}
    for name, src in checkpoints.items():
        manifest = network_manifest(src, code_version=code_version)
        manifest["network"] = name
        out = dest / f"{name}.pt"
        with atomic_path(out) as tmp:
            shutil.copyfile(src, tmp)
        manifest["checkpoint"] = out.name
        if note:
            manifest["note"] = note
        atomic_write_text(dest / f"{name}.json", json.dumps(manifest, indent=2) + "\n")
        written += [out, dest / f"{name}.json"]
    if recipe is not None:
        old = json.loads((dest / "recipe.json").read_text()).get("flip", {}) if (dest / "recipe.json").is_file() else {}
        atomic_write_text(dest / "recipe.json", json.dumps(
            {"flip": {**old, **flips}, "chosen_on": "validation height sweeps"}, indent=2) + "\n")
        written.append(dest / "recipe.json")
    return written


def shipped_checkpoint(config, shipped_dir: str | os.PathLike | None) -> tuple[Path | None, str]:
    """The shipped checkpoint of a network when it was trained with ``config``'s configuration.

    Parameters
    ----------
    config : TrainConfig
        The network's configuration; its file name (``config.out``) names the network.
    shipped_dir : path or None
        The shipped folder (None or empty: none).

    Returns
    -------
    (Path or None, str)
        The checkpoint, or None and why not (no such file, or the configuration entries that
        differ).

    Raises
    ------
    ValueError
        The shipped checkpoint has no manifest, its bytes do not match the manifest's SHA-256
        (e.g. a Git LFS pointer or a truncated download), or it cannot be loaded.
    """
    from .predict import load_model
    from .training import config_differences, config_record

    if not shipped_dir:
        return None, "no shipped folder"
    path = Path(shipped_dir) / Path(config.out).name
    if not path.is_file():
        return None, f"no shipped checkpoint {path}"
    check_shipped_checkpoint(path)
    stored = load_model(path).info.get("train_config") or {}
    diff = config_differences(stored, config_record(config))
    if diff:
        return None, f"{path} was trained with another configuration ({'; '.join(diff)})"
    return path, ""


def install_checkpoint(shipped: str | os.PathLike, out: str | os.PathLike) -> Path:
    """Copy a shipped checkpoint to ``out`` (nothing to do when ``out`` holds the same bytes)."""
    shipped, out = Path(shipped), Path(out)
    if out.is_file() and file_sha256(out) == file_sha256(shipped):
        return out
    with atomic_path(out) as tmp:
        shutil.copyfile(shipped, tmp)
    return out


def provide_networks(configs: Mapping, *, shipped_dir: str | os.PathLike | None, retrain: bool = False,
                     jobs: int | None = None, views: dict | None = None,
                     log=print) -> tuple[dict[str, Path], list[str]]:
    """Notebook 02's networks: the shipped checkpoint where its configuration matches, else trained.

    Parameters
    ----------
    configs : mapping
        Network name -> :class:`~semmatch.segment.training.TrainConfig`
        (:func:`~semmatch.segment.training.pipeline_configs`).
    shipped_dir : path or None
        The shipped folder (``models/<profile>``); None: train (or reuse ``config.out``).
    retrain : bool
        Train every network (``make repro TRAIN=1``). A network whose shipped copy has the same
        configuration and was trained on the CPU is retrained with that run's torch thread count
        when training on the CPU too (unless its config sets ``threads``), and the log says
        whether the retrained weights equal the shipped ones (:func:`shipped_run`).
    jobs : int, optional
        Scenes rendered in parallel when views must be rendered
        (:func:`~semmatch.segment.training.build_views`).
    views : dict, optional
        Training seed -> (training views, validation views), filled as views are rendered (the
        networks of one seed share them); pass one in to reuse views.
    log : callable
        Receives one line per network saying where it came from.

    Returns
    -------
    (dict, list)
        Network name -> checkpoint path; the names that came from ``shipped_dir``.
    """
    from .training import build_views, train_or_load

    views = {} if views is None else views
    checkpoints, shipped = {}, []

    def views_of(cfg):
        if cfg.seed not in views:
            views[cfg.seed] = build_views(cfg, jobs=jobs)
            tr, va = views[cfg.seed]
            log(f"seed {cfg.seed}: {len(tr)} training views, {len(va)} validation views, "
                f"{tr.shape[1]}x{tr.shape[0]} px")
        return views[cfg.seed]

    for net, cfg in configs.items():
        manifest = None
        if retrain:
            cfg, manifest, why = shipped_run(cfg, shipped_dir)
            src, why = None, f"retraining (TRAIN=1){why}"
        else:
            src, why = shipped_checkpoint(cfg, shipped_dir)
        t0 = time.perf_counter()
        if src is not None:  # copied to cfg.out (unless that already holds the same bytes) instead of training
            checkpoints[net] = install_checkpoint(src, cfg.out)
            shipped.append(net)
            log(f"{net}: shipped network {src}")
            continue
        checkpoints[net] = train_or_load(cfg, retrain=retrain, views=lambda cfg=cfg: views_of(cfg))
        if manifest is not None and not manifest.get("weights_sha256"):
            why += "; the shipped manifest has no weights digest to compare with"
        elif manifest is not None:
            same = manifest["weights_sha256"] == weights_sha256(checkpoints[net])
            ran = manifest.get("trained_on") or {}
            why += ("; the same weights as the shipped network" if same else
                    f"; other weights than the shipped network (trained on {ran.get('device', '?')} with "
                    f"{ran.get('torch_threads', '?')} torch threads)")
        log(f"{net}: {checkpoints[net]} ({why}; {time.perf_counter() - t0:.0f} s)")
    return checkpoints, shipped


def shipped_run(config, shipped_dir: str | os.PathLike | None) -> tuple:
    """How to retrain a shipped network so that its weights can come out the same.

    The thread count of a CPU training sets the order of its floating-point sums, and the rounding
    differences grow over the steps; one thread reproduces a one-thread run's weights bit for
    bit. A GPU run's weights cannot be reproduced on the CPU.

    Parameters
    ----------
    config : TrainConfig
        The network's configuration (``config.out`` names the network).
    shipped_dir : path or None
        The shipped folder.

    Returns
    -------
    (TrainConfig, dict or None, str)
        ``config``, with the shipped run's ``threads`` when the shipped network has the same
        configuration, was trained on the CPU and this one trains on the CPU with no thread count
        of its own; the shipped manifest (None: no shipped network of this configuration); and
        what was done, for a log line ("" when nothing).

    Raises
    ------
    ValueError
        The shipped manifest is not valid JSON.
    """
    from dataclasses import replace

    from .training import config_differences, config_record, resolve_device

    path = Path(shipped_dir) / Path(config.out).with_suffix(".json").name if shipped_dir else None
    if path is None or not path.is_file():
        return config, None, ""
    try:
        manifest = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from None
    if config_differences(manifest.get("train_config") or {}, config_record(config)):
        return config, None, ""
    ran = manifest.get("trained_on") or {}
    threads = ran.get("torch_threads")
    if (config.threads is None and ran.get("device") == "cpu" and isinstance(threads, int) and threads > 0
            and resolve_device(config.device).type == "cpu"):
        return replace(config, threads=threads), manifest, f", {threads} torch thread(s) as the shipped run"
    return config, manifest, ""


def apply_shipped_recipe(data_root: str | os.PathLike, shipped_dir: str | os.PathLike,
                         networks: Sequence[str]) -> dict[str, bool]:
    """Put the shipped flip choice of ``networks`` into ``data_root``'s ``models/recipe.json``.

    A shipped network keeps the choice made when it was trained (on the validation sweeps);
    entries of other networks are kept.

    Returns
    -------
    dict
        ``{network: flip}`` for ``networks``.

    Raises
    ------
    FileNotFoundError, ValueError
        No ``recipe.json`` in the shipped folder, or no choice in it for one of the networks.
    """
    src = Path(shipped_dir) / "recipe.json"
    if not src.is_file():
        raise FileNotFoundError(f"{src}: shipped networks without their recipe.json (flip choice)")
    shipped = json.loads(src.read_text()).get("flip", {})
    missing = [n for n in networks if n not in shipped]
    if missing:
        raise ValueError(f"{src}: no flip choice for {', '.join(missing)}")
    # the data layout's recipe file (semmatch.experiments.layout.Layout.recipe; the segmentation
    # code does not import the pipeline's layout, which imports it)
    recipe = Path(data_root) / "models" / "recipe.json"
    known = json.loads(recipe.read_text()) if recipe.is_file() else {}
    choice = {n: bool(shipped[n]) for n in networks}
    flips = {**known.get("flip", {}), **choice}
    chosen_on = dict(known.get("chosen_on_by_network", {}), **{n: f"shipped ({src})" for n in networks})
    atomic_write_text(recipe, json.dumps({"flip": flips, "chosen_on": "validation height sweeps",
                                          "chosen_on_by_network": chosen_on}, indent=2) + "\n")
    return choice


def check_shipped_checkpoint(path: str | os.PathLike, *, weights: bool = False) -> dict:
    """The manifest of a shipped checkpoint, after checking that the file matches it.

    Parameters
    ----------
    path : path
        ``<shipped folder>/<name>.pt``; its manifest is ``<name>.json`` beside it.
    weights : bool, optional
        Also compare the weights' digest (:func:`weights_sha256`; loads the checkpoint) with the
        manifest's ``weights_sha256``.

    Returns
    -------
    dict
        The manifest.

    Raises
    ------
    FileNotFoundError
        No such checkpoint.
    ValueError
        No manifest, a manifest that is not valid JSON, or a digest that differs from the
        manifest's (a changed, truncated or Git LFS pointer file).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such shipped checkpoint")
    manifest_path = path.with_suffix(".json")
    if not manifest_path.is_file():
        raise ValueError(f"{path}: shipped checkpoint without its manifest {manifest_path.name}")
    try:
        manifest = json.loads(manifest_path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{manifest_path}: not valid JSON ({e})") from None
    if manifest.get("checkpoint_sha256") != file_sha256(path):
        raise ValueError(f"{path}: its SHA-256 differs from the one in {manifest_path.name} (a changed, truncated or "
                         f"Git LFS pointer file); restore it from git or retrain (make repro TRAIN=1)")
    if weights and manifest.get("weights_sha256") != weights_sha256(path):
        raise ValueError(f"{path}: its weights' SHA-256 differs from weights_sha256 in {manifest_path.name}")
    return manifest


def shipped_seeds(shipped_dir: str | os.PathLike, arch: str) -> dict[int, Path]:
    """The shipped training seeds of an architecture: seed -> checkpoint.

    Seed 0 is ``<arch>.pt``, seed ``s`` is ``<arch>@<s>.pt`` (the pipeline's network names,
    :func:`~semmatch.segment.train_config.network_spec`). Only checkpoints with a manifest count;
    their digests are not checked here (:func:`check_shipped_checkpoint`).

    Parameters
    ----------
    shipped_dir : path
        The shipped folder (``models/<profile>``).
    arch : {"compact", "strong"}

    Returns
    -------
    dict
        Training seed -> checkpoint path, in seed order (empty when none is shipped).

    Raises
    ------
    FileNotFoundError
        No such folder.
    ValueError
        A shipped file name that is not a network name (e.g. ``compact@x.pt``), or a manifest
        whose training seed differs from its file name's.
    """
    from .train_config import network_spec

    folder = Path(shipped_dir)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no such shipped folder")
    seeds: dict[int, Path] = {}
    for path in sorted(folder.glob(f"{arch}*.pt")):
        if path.stem != arch and not path.stem.startswith(f"{arch}@"):
            continue
        if not path.with_suffix(".json").is_file():
            continue
        _, seed = network_spec(path.stem)
        manifest = json.loads(path.with_suffix(".json").read_text())
        recorded = (manifest.get("train_config") or {}).get("seed")
        if recorded is not None and int(recorded) != seed:
            raise ValueError(f"{path}: named for training seed {seed} but its manifest records seed {recorded}")
        seeds[seed] = path
    return dict(sorted(seeds.items()))


def load_shipped_network(shipped_dir: str | os.PathLike, name: str, *, device=None, flip: bool | None = None):
    """Load a shipped network by its pipeline name (``compact``, ``strong@2``), digests checked.

    Parameters
    ----------
    shipped_dir : path
        The shipped folder (``models/<profile>``).
    name : str
        Network name (:func:`~semmatch.segment.train_config.network_spec`).
    device : str or torch.device, optional
        As :func:`~semmatch.segment.predict.load_model`.
    flip : bool, optional
        Mirror averaging; default: the folder's ``recipe.json`` choice for ``name``, else for its
        architecture (the seeds share their architecture's choice), else on.

    Returns
    -------
    Segmenter

    Raises
    ------
    FileNotFoundError, ValueError
        No such shipped network, or its file does not match its manifest
        (:func:`check_shipped_checkpoint`, weights included).
    """
    from .predict import load_model
    from .train_config import network_spec

    arch, _ = network_spec(name)
    path = Path(shipped_dir) / f"{name}.pt"
    check_shipped_checkpoint(path, weights=True)
    if flip is None:
        recipe = Path(shipped_dir) / "recipe.json"
        flips = json.loads(recipe.read_text()).get("flip", {}) if recipe.is_file() else {}
        flip = bool(flips.get(name, flips.get(arch, True)))
    return load_model(path, arch=arch, device=device, flip=flip)
