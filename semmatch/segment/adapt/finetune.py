"""Fine-tune a network on the robot's labelled frames: the recipe and the training loop.

:class:`AdaptRecipe` holds the recipe and its defaults; :func:`fine_tune` fine-tunes on
:class:`~semmatch.segment.adapt.views.RobotViews` (half of each batch, by default, the network's own
human-height training views), :func:`adapt_in_home` does it in one home the person has mapped.
"""

from __future__ import annotations

import copy
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from ...io import atomic_path
from .views import MIN_COVERAGE, RobotViews, _check_sources, home_views

__all__ = ["AdaptRecipe", "fine_tune", "adapt_in_home", "file_digest"]


@dataclass(frozen=True)
class AdaptRecipe:
    """The fine-tuning recipe of :func:`fine_tune`: the one place its defaults live.

    Every function that fine-tunes (:func:`fine_tune`, :func:`adapt_in_home`,
    :func:`semmatch.experiments.adapt.adapt_networks`, ``semmatch adapt``) takes its recipe from
    here; a profile of params.yaml sets its own (``adapt_robot_view``: ``steps``, ``batch_size``;
    the learning rate, ``upper_share`` and ``distill`` are chosen on validation scenes) and
    :meth:`from_mapping` reads it. Values are stored as ``int`` / ``float``.

    Attributes
    ----------
    steps : int
        Optimisation steps (AdamW, one-cycle schedule peaking at ``lr``).
    batch_size : int
        Images per step (at least 2).
    lr : float
        Peak learning rate.
    upper_share : float
        Share of each batch from the network's own human-height training views, in [0, 1).
    distill : float
        Weight of the distillation term (0: none; > 0 needs human-height views in the batch).
    seed : int
        Seed of the batch draws, the augmentation and the weights' updates.

    Raises
    ------
    ValueError
        ``steps`` < 1, ``batch_size`` < 2, ``upper_share`` outside [0, 1), ``distill`` < 0, or
        ``distill`` > 0 without a human-height view in the batch.
    """

    steps: int = 400
    batch_size: int = 16
    lr: float = 1e-3
    upper_share: float = 0.5
    distill: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):  # 400 or 400.0 or "400" from a table: the field's type
            object.__setattr__(self, f.name, type(f.default)(getattr(self, f.name)))
        steps, batch_size, upper_share, distill = self.steps, self.batch_size, self.upper_share, self.distill
        if steps < 1 or batch_size < 2 or not 0.0 <= upper_share < 1.0:
            raise ValueError(f"need steps >= 1, batch_size >= 2 and 0 <= upper_share < 1, got {steps}, {batch_size}, "
                             f"{upper_share}")
        if not distill >= 0 or (distill > 0 and int(round(batch_size * upper_share)) == 0):
            raise ValueError(f"distill must be >= 0 and needs human-height views in the batch (upper_share > 0), "
                             f"got distill={distill}, upper_share={upper_share}")

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The recipe's field names, in order."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], **changes: Any) -> AdaptRecipe:
        """The recipe whose fields are found in ``values``, the defaults elsewhere.

        Parameters
        ----------
        values : mapping
            A params.yaml section or a notebook's parameters
            (:func:`semmatch.experiments.pipeline.notebook_parameters`), a row of a recipe table;
            keys that are not fields of the recipe are ignored.
        **changes
            Fields set over ``values``.

        Returns
        -------
        AdaptRecipe
        """
        return cls(**{k: values[k] for k in cls.names() if k in values}, **changes)

    @classmethod
    def of(cls, recipe: AdaptRecipe | None = None, **changes: Any) -> AdaptRecipe:
        """``recipe`` (default: the default recipe) with ``changes`` to its fields.

        Raises
        ------
        TypeError
            A change that is not a field of the recipe.
        """
        return replace(recipe if recipe is not None else cls(), **changes)

    def as_dict(self) -> dict[str, int | float]:
        """The fields as a dict, in order (the checkpoint's ``adapted`` record holds them)."""
        return {k: getattr(self, k) for k in self.names()}


def adapt_in_home(
    checkpoint: str | Path,
    sequence: str | Path,
    person_map: str | Path,
    out: str | Path,
    recipe: AdaptRecipe | None = None,
    *,
    source: str = "3d-neighborhood",
    frames: int | None = None,
    frame_step: int = 1,
    min_purity: float = 0.5,
    min_coverage: float = MIN_COVERAGE,
    cache_dir: str | Path | None = "checkpoint-if-present",
    progress: bool = True,
    recording=None,
    **changes: Any,
) -> Path:
    """Adapt a network in a home: the robot's tour labelled from the person's map of it.

    :func:`~semmatch.segment.adapt.views.home_views` labels the robot's frames, :func:`fine_tune` fine-tunes on them (half of
    each batch, by default, the network's own human-height training views).

    Parameters
    ----------
    checkpoint : path
        The network to adapt.
    sequence, person_map : paths
        The robot's tour of the home and the person's semantic map of it (:func:`~semmatch.segment.adapt.views.home_views`).
    out : path
        The adapted checkpoint (never ``checkpoint`` nor an input).
    recipe : AdaptRecipe, optional
        The fine-tuning recipe (default :class:`AdaptRecipe`'s).
    source, frames, frame_step, min_purity, min_coverage
        As :func:`~semmatch.segment.adapt.views.home_views`.
    cache_dir : path, "checkpoint", "checkpoint-if-present" or None
        The cache of the network's human-height training views (:func:`fine_tune`); by default
        the checkpoint's recorded folder where it exists, else the views are rendered each run.
    progress : bool
    recording : sequence of Frame, optional
        ``sequence`` already opened (:func:`~semmatch.segment.adapt.views.home_views`).
    **changes
        Fields of the recipe set over ``recipe`` (``steps=800``).

    Returns
    -------
    Path
        The checkpoint; its ``adapted`` record holds, besides :func:`fine_tune`'s fields (the
        recipe: ``steps``, ``lr``, ``batch_size``, ``upper_share``, ``seed``, ``label_source``;
        ``label_coverage``; ``scenes``: the home), ``home`` (``sequence``, ``scene`` or None,
        ``frames``: the frame indices used) and ``map`` (``path``, ``sha256``: the first 16 hex
        digits).

    Raises
    ------
    ValueError
        ``out`` is the network or an input; the errors of :func:`~semmatch.segment.adapt.views.home_views` and
        :func:`fine_tune`.
    TypeError
        A change that is not a field of the recipe.
    """
    from ...io.sequences import sequence_scene

    recipe = AdaptRecipe.of(recipe, **changes)
    out = Path(out)
    for flag, p in (("--model", checkpoint), ("--home", sequence), ("--map", person_map)):
        if out.resolve() == Path(p).resolve() or Path(p).resolve() in out.resolve().parents:
            raise ValueError(f"--out {out}: it is the input {flag} {p} (or inside it); refusing to overwrite an input")
    robot = home_views(checkpoint, sequence, person_map, source=source, frames=frames, frame_step=frame_step,
                       min_purity=min_purity, min_coverage=min_coverage, progress=progress, recording=recording)
    extra = {
        "mode": "home",
        "home": {"sequence": str(sequence), "scene": sequence_scene(sequence), "frames": list(robot.frames)},
        "map": {"path": str(person_map), "sha256": file_digest(Path(person_map))},
        "min_purity": float(min_purity),
    }
    return fine_tune(checkpoint, robot, source, out, recipe, min_coverage=min_coverage, extra=extra,
                     cache_dir=cache_dir, progress=progress)


def file_digest(path: str | Path) -> str:
    """The first 16 hex digits of a file's SHA-256 (:func:`semmatch.segment.shipping.file_sha256`): how
    an adapted checkpoint's record names the network and the map it came from."""
    from ..shipping import file_sha256

    return file_sha256(path)[:16]


def fine_tune(
    checkpoint: str | Path,
    robot: RobotViews,
    source: str,
    out: str | Path,
    recipe: AdaptRecipe | None = None,
    *,
    min_coverage: float = MIN_COVERAGE,
    extra: dict | None = None,
    cache_dir: str | Path | None = "checkpoint",
    progress: bool = True,
    device: str = "cpu",
    **changes: Any,
) -> Path:
    """Fine-tune a network on the robot's frames labelled by ``source``; write the checkpoint.

    The recipe (:class:`AdaptRecipe`): each step takes ``round(batch_size * upper_share)`` of the
    network's own human-height training views (ground truth) and the rest from the robot's frames
    (``source`` labels, 0 ignored), with the network's training augmentation and class weights;
    AdamW with a one-cycle schedule peaking at ``lr``. With ``distill`` > 0 the loss also has ``distill`` times the
    per-pixel KL divergence from the unadapted network's class distribution to the adapted one's
    on the human-height part of each batch (distillation, a guard against forgetting the human
    view besides the mix itself). The final weights are kept (no selection on any scene).

    Parameters
    ----------
    checkpoint : path
        The network to adapt (:func:`semmatch.segment.load_model`: a checkpoint of another
        category table is refused).
    robot : RobotViews
        :func:`~semmatch.segment.adapt.views.robot_training_views`, prepared with ``source``.
    source : str
        Label source (:data:`~semmatch.segment.adapt.views.LABEL_SOURCES`).
    out : path
        Where the adapted checkpoint goes (written to a temporary file, then renamed).
    recipe : AdaptRecipe, optional
        The schedule (AdamW, one-cycle peaking at ``lr``), the share of each batch from the
        network's human-height training views and the distillation weight (default
        :class:`AdaptRecipe`'s).
    min_coverage : float
        Smallest share of the robot's pixels with depth that ``source`` must label: below it the
        person's map barely overlaps the robot's view and there is nothing to learn from.
    extra : dict, optional
        More entries for the checkpoint's ``adapted`` record (:func:`adapt_in_home`: the home
        and the map).
    cache_dir : path, "checkpoint", "checkpoint-if-present" or None
        Where the network's human-height training views are cached: the folder recorded in the
        checkpoint (``"checkpoint"``, the default), that folder only when it exists on this
        machine (``"checkpoint-if-present"``: a shipped network's training folder is never
        created elsewhere), another folder, or None (rendered, not cached).
    progress : bool
    device : str
        Where to fine-tune: ``cpu`` (the pipeline's), ``cuda`` or ``auto`` (a lent GPU: the
        checkpoint's ``adapted`` record then names the device; GPU kernels are not bit-for-bit
        deterministic, so a GPU fine-tuning repeats only approximately).
    **changes
        Fields of the recipe set over ``recipe`` (``steps=2, batch_size=4``).

    Returns
    -------
    Path
        The checkpoint: the source network's format and fields, the new ``state_dict``, and
        ``adapted``: the source checkpoint (path and SHA-256 prefix), the label source, the
        adaptation scenes, the coverage of the labels and the schedule.

    Raises
    ------
    ValueError
        Unknown source (or one ``robot`` was not prepared with), bad schedule, labels covering
        less than ``min_coverage`` of the robot's pixels, a checkpoint of another category table.
    TypeError
        A change that is not a field of the recipe.
    """
    import torch

    from ...runtime.progress import tqdm
    from .. import load_model
    from ..training import TrainConfig, augment, build_views, make_optimiser, optimisation_step

    _check_sources([source])
    if source not in robot.pseudo:
        raise ValueError(f"the robot views carry no {source!r} labels (prepared: {', '.join(robot.pseudo)})")
    recipe = AdaptRecipe.of(recipe, **changes)
    steps, batch_size, lr, upper_share, distill, seed = (getattr(recipe, k) for k in AdaptRecipe.names())
    coverage = robot.coverage.get(source)
    if coverage is not None and coverage < min_coverage:
        raise ValueError(f"{source}: its labels cover {coverage:.2%} of the robot's pixels with depth (fewer than "
                         f"{min_coverage:.2%}): the person's map barely overlaps the robot's view of the adaptation "
                         f"scenes ({', '.join(robot.scenes)}); use longer tours, more scenes or another source")
    checkpoint = Path(checkpoint)
    seg = load_model(checkpoint, device="cpu", flip=False)
    info = seg.info
    rec = dict(info.get("train_config") or {})
    known = {f for f in TrainConfig.__dataclass_fields__}
    cfg = TrainConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in rec.items() if k in known})
    cfg.progress = False
    if cache_dir == "checkpoint-if-present":
        cfg.cache_dir = cfg.cache_dir if cfg.cache_dir and Path(cfg.cache_dir).is_dir() else None
    elif cache_dir != "checkpoint":
        cfg.cache_dir = None if cache_dir is None else str(cache_dir)
    upper_views, _ = build_views(cfg)
    dev = _seeded_device(device, seed)
    net = seg.net.to(dev)
    opt, sched = make_optimiser(net, lr, cfg.weight_decay, steps)
    w_t = torch.tensor(info["class_weights"], dtype=torch.float32, device=dev)
    rng = np.random.default_rng(seed)
    n_up = int(round(batch_size * upper_share))
    n_lo = batch_size - n_up
    aux = _distillation(copy.deepcopy(net), n_up, distill) if distill > 0 else None
    lab_lo = robot.pseudo[source]
    usable = np.flatnonzero((lab_lo > 0).reshape(len(lab_lo), -1).any(axis=1))
    if len(usable) == 0:
        raise ValueError(f"{source}: no robot frame carries a label")
    aug = dict(crop=cfg.crop_size, zoom=cfg.zoom, jitter=cfg.jitter, base_zoom=cfg.width / cfg.net_size[0],
               use_depth=cfg.use_depth, device=dev)
    t0 = time.perf_counter()
    losses = []
    net.train()
    for _ in tqdm(range(steps), desc=f"adapt {source}", disable=not progress):
        xs, ys = [], []
        if n_up:
            i = np.sort(rng.choice(len(upper_views), n_up, replace=len(upper_views) < n_up))
            x, y = augment(upper_views.rgb[i], upper_views.depth[i], upper_views.labels[i], rng, **aug)
            xs.append(x)
            ys.append(y)
        j = np.sort(rng.choice(usable, n_lo, replace=len(usable) < n_lo))
        x, y = augment(robot.views.rgb[j], robot.views.depth[j], lab_lo[j], rng, **aug)
        xs.append(x)
        ys.append(y)
        x = torch.cat(xs).contiguous(memory_format=torch.channels_last)
        losses.append(optimisation_step(net, x, torch.cat(ys), w_t, opt, sched, what=f"adaptation loss ({source})",
                                        aux_loss=aux))
    net.eval()
    ckpt = {k: copy.deepcopy(v) for k, v in info.items()}
    ckpt["state_dict"] = {k: v.detach().cpu() for k, v in net.state_dict().items()}
    ckpt["adapted"] = {
        "from": str(checkpoint), "from_sha256": file_digest(checkpoint), "label_source": source,
        "scenes": list(robot.scenes), "frames": int(len(robot.views)), "label_coverage": robot.coverage.get(source),
        **recipe.as_dict(), "final_loss": float(np.mean(losses[-20:])), "seconds": time.perf_counter() - t0,
        **({"device": str(dev), "device_name": torch.cuda.get_device_name(dev)} if dev.type == "cuda" else {}),
        **(extra or {}),
    }
    out = Path(out)
    with atomic_path(out) as tmp:
        torch.save(ckpt, tmp)
    return out


def _seeded_device(device: str, seed: int):
    """The torch device of a fine-tuning (:func:`semmatch.segment.training.resolve_device`), torch
    seeded and deterministic (on a GPU: where its kernels allow, with a warning otherwise)."""
    import torch

    from ..training import resolve_device

    dev = resolve_device(device)
    if dev.type == "cuda":
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True, warn_only=dev.type == "cuda")
    return dev


def _distillation(teacher, n_upper: int, weight: float):
    """``loss(x, logits)`` for :func:`fine_tune`: ``weight`` times the per-pixel KL divergence
    from the frozen ``teacher`` (the unadapted network) to the adapted network's ``logits`` on
    the first ``n_upper`` images of batch ``x``."""
    import torch
    import torch.nn.functional as F

    teacher.eval()
    for p in teacher.parameters():
        p.requires_grad_(False)

    def loss(x, logits):
        with torch.no_grad():
            t = F.log_softmax(teacher(x[:n_upper]), 1)
        return weight * (t.exp() * (t - F.log_softmax(logits[:n_upper], 1))).sum(1).mean()
    return loss
