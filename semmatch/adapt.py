"""The robot learns: adapt a segmentation network to the robot's viewpoint with transferred labels.

The paper ends where this begins ("label transfer and the fine-tuning of semantic segmentation
networks to these perspectives becomes possible"). On **training scenes only**, the person
(1.6 m) and the robot (0.2 m) each tour the room; the network builds the person's semantic map,
its labels are transferred into the robot's frames, and the network is fine-tuned on those
frames (:func:`fine_tune`). Label sources (:data:`LABEL_SOURCES`):

* a transfer method (the paper's five): its labels where the map supports a pixel and the
  pixel's group agreed (vote purity >= ``min_purity``); everything else is ignored by the loss;
* ``fused``: the transferred label where the map supports a pixel, the network's elsewhere;
* ``self-training`` (the standard domain-adaptation baseline): the network's own predictions on
  the robot's frames where its confidence is >= ``self_threshold``;
* ``ground-truth`` (the ceiling): the simulator's labels of the robot's frames.

Forgetting the human view is guarded against by mixing each batch: ``upper_share`` of it comes
from the network's own human-height training views with their ground truth.
The adapted checkpoint records what it was adapted from and with (``adapted``); it loads with
:func:`semmatch.segment.load_model` like any other.
"""

from __future__ import annotations

import copy
import hashlib
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .io import Frame, atomic_path

__all__ = ["LABEL_SOURCES", "RobotViews", "robot_training_views", "fine_tune", "adapted_name"]

#: label sources besides the transfer methods
BASELINES = ("self-training", "ground-truth")


def _label_sources() -> tuple[str, ...]:
    from .transfer import METHODS

    return (*METHODS, "fused", *BASELINES)


#: every label source: the paper's transfer methods, ``fused``, self-training, ground truth
LABEL_SOURCES: tuple[str, ...] = _label_sources()


def adapted_name(network: str, source: str) -> str:
    """Name of ``network`` adapted with ``source`` labels (``compact~3d-neighborhood``)."""
    return f"{network}~{source}"


@dataclass
class RobotViews:
    """The robot's frames of the adaptation scenes with one pseudo-label image per source.

    Attributes
    ----------
    views : Views
        RGB, depth, ground-truth labels, scene index, camera height.
    pseudo : dict
        ``{source: uint8 (N,H,W)}``; 0 = ignored by the loss.
    coverage : dict
        ``{source: share of the pixels with depth that carry a label}``.
    scenes : list of str
        Scene names, in the order of ``views.scene``.
    """

    views: object
    pseudo: dict[str, np.ndarray]
    coverage: dict[str, float] = field(default_factory=dict)
    scenes: list[str] = field(default_factory=list)


def _check_sources(sources: Sequence[str]) -> None:
    bad = [s for s in sources if s not in LABEL_SOURCES]
    if bad:
        raise ValueError(f"unknown label source(s) {', '.join(bad)}; valid: {', '.join(LABEL_SOURCES)}")


def robot_training_views(
    checkpoint: str | Path,
    *,
    kinds: Sequence[str],
    seeds: Sequence[int],
    sources: Sequence[str] = LABEL_SOURCES,
    n_frames: int = 40,
    upper_height: float = 1.6,
    lower_height: float = 0.2,
    voxel_size: float = 0.04,
    min_purity: float = 0.5,
    self_threshold: float = 0.9,
    fused_base: str = "3d-neighborhood",
    seed: int = 0,
    progress: bool = True,
) -> RobotViews:
    """Render the person's and the robot's tours of training scenes and label the robot's frames.

    Frames are rendered at the resolution the network was trained on (its checkpoint's
    ``train_config``). Each camera plans its own coverage-matched tour (the evaluation protocol);
    the person's map is the network's predictions fused (TSDF, ``voxel_size``).

    Parameters
    ----------
    checkpoint : path
        The network to adapt.
    kinds, seeds : sequences
        The training scenes (``make_scenes(kinds, seeds)``): must be scenes the network was
        trained on, never validation or evaluation scenes.
    sources : sequence of str
        Label sources to prepare (:data:`LABEL_SOURCES`).
    n_frames : int
        Frames per tour.
    min_purity : float
        Transferred labels of pixels whose group vote was less pure are ignored.
    self_threshold : float
        Self-training keeps predictions at least this confident.

    Raises
    ------
    ValueError
        Unknown source, or seeds that are validation/evaluation seeds of the network.
    """
    from .fusion import reconstruct
    from .geometry import DEFAULT_INTRINSICS
    from .progress import tqdm
    from .segment import load_model
    from .segment.data import Views, make_scenes
    from .sim import Renderer
    from .sim.trajectory import make_trajectory
    from .transfer import MapIndex, transfer_frame

    _check_sources(sources)
    seg = load_model(checkpoint)
    cfg = seg.info.get("train_config") or {}
    held_out = set(cfg.get("val_seeds", ())) | set(cfg.get("eval_seeds", ()))
    if held_out & set(seeds):
        raise ValueError(f"adaptation seeds {sorted(held_out & set(seeds))} are validation/evaluation seeds of "
                         f"{checkpoint}; adapt on training scenes only")
    intr = DEFAULT_INTRINSICS.scaled(int(cfg.get("width", 320)), int(cfg.get("height", 240)))
    scenes = make_scenes(kinds, seeds)
    rgb, depth, gt, scene_of, pseudo = [], [], [], [], {s: [] for s in sources}
    valid_px, labelled = 0, dict.fromkeys(sources, 0)
    names = []
    for k, scene in enumerate(tqdm(scenes, desc="adaptation scenes", disable=not progress)):
        names.append(scene.name)
        r = Renderer(scene, intr)
        up_poses = make_trajectory(scene, upper_height, n_frames, seed=seed + k, kind="upper", cover=True)
        lo_poses = make_trajectory(scene, lower_height, n_frames, seed=seed + k, kind="lower", cover=True)
        up = [r.render(T) for T in up_poses]
        lo = [r.render(T) for T in lo_poses]
        up_frames = [Frame(v.rgb, v.depth, None, np.asarray(T), intr, index=i)
                     for i, (v, T) in enumerate(zip(up, up_poses))]
        probs_up = [seg.predict(v.rgb) for v in up]
        index = MapIndex(reconstruct(up_frames, labels=probs_up, voxel_size=voxel_size))
        for i, (v, T) in enumerate(zip(lo, lo_poses)):
            frame = Frame(v.rgb, v.depth, v.labels, np.asarray(T), intr, index=i)
            p = seg.predict(v.rgb) if {"fused", "self-training"} & set(sources) else None
            valid = v.depth > 0
            valid_px += int(valid.sum())
            for s in sources:
                if s == "ground-truth":
                    lab = v.labels
                elif s == "self-training":
                    lab = np.where(p.max(axis=2) >= self_threshold, p.argmax(axis=2), 0).astype(np.uint8)
                elif s == "fused":
                    lab = transfer_frame("fused", frame, index, probs=p, base=fused_base).labels
                else:
                    res = transfer_frame(s, frame, index)
                    lab = np.where(res.purity >= min_purity, res.labels, 0).astype(np.uint8)
                lab = np.where(valid | (s in ("ground-truth", "self-training", "fused")), lab, 0).astype(np.uint8)
                pseudo[s].append(lab)
                labelled[s] += int(np.count_nonzero(lab[valid]))
            rgb.append(v.rgb)
            depth.append(v.depth)
            gt.append(v.labels)
            scene_of.append(k)
    views = Views(np.stack(rgb), np.stack(depth).astype(np.float32), np.stack(gt), np.asarray(scene_of, np.int64),
                  np.full(len(rgb), lower_height, np.float32))
    return RobotViews(views, {s: np.stack(v) for s, v in pseudo.items()},
                      {s: labelled[s] / max(valid_px, 1) for s in sources}, names)


def _file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:16]


def fine_tune(
    checkpoint: str | Path,
    robot: RobotViews,
    source: str,
    out: str | Path,
    *,
    steps: int = 500,
    batch_size: int = 16,
    lr: float = 1e-3,
    upper_share: float = 0.5,
    distill: float = 0.0,
    seed: int = 0,
    min_coverage: float = 0.005,
    progress: bool = True,
) -> Path:
    """Fine-tune a network on the robot's frames labelled by ``source``; write the checkpoint.

    Each step takes ``round(batch_size * upper_share)`` of the network's own human-height
    training views (ground truth) and the rest from the robot's frames (``source`` labels, 0
    ignored), with the network's training augmentation and class weights; AdamW with a one-cycle
    schedule peaking at ``lr``. With ``distill`` > 0 the loss also has ``distill`` times the
    per-pixel KL divergence from the unadapted network's class distribution to the adapted one's
    on the human-height part of each batch (distillation, a guard against forgetting the human
    view besides the mix itself). The final weights are kept (no selection on any scene).

    Parameters
    ----------
    checkpoint : path
        The network to adapt (:func:`semmatch.segment.load_model`: a checkpoint of another
        category table is refused).
    robot : RobotViews
        :func:`robot_training_views`, prepared with ``source``.
    source : str
        Label source (:data:`LABEL_SOURCES`).
    out : path
        Where the adapted checkpoint goes (written to a temporary file, then renamed).
    steps, batch_size, lr, upper_share, seed
        The schedule (AdamW, one-cycle peaking at ``lr``) and the share of each batch from the
        network's human-height training views.
    distill : float
        Weight of the distillation term (0: none; needs ``upper_share`` > 0).
    min_coverage : float
        Smallest share of the robot's pixels with depth that ``source`` must label: below it the
        person's map barely overlaps the robot's view and there is nothing to learn from.
    progress : bool

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
    """
    import torch

    from .progress import tqdm
    from .segment import load_model
    from .segment.training import TrainConfig, augment, build_views, make_optimiser, optimisation_step

    _check_sources([source])
    if source not in robot.pseudo:
        raise ValueError(f"the robot views carry no {source!r} labels (prepared: {', '.join(robot.pseudo)})")
    if int(steps) < 1 or int(batch_size) < 2 or not 0.0 <= upper_share < 1.0:
        raise ValueError(f"need steps >= 1, batch_size >= 2 and 0 <= upper_share < 1, got {steps}, {batch_size}, "
                         f"{upper_share}")
    if not distill >= 0 or (distill > 0 and int(round(batch_size * upper_share)) == 0):
        raise ValueError(f"distill must be >= 0 and needs human-height views in the batch (upper_share > 0), "
                         f"got distill={distill}, upper_share={upper_share}")
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
    upper_views, _ = build_views(cfg)
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True)
    net = seg.net
    opt, sched = make_optimiser(net, lr, cfg.weight_decay, steps)
    w_t = torch.tensor(info["class_weights"], dtype=torch.float32)
    rng = np.random.default_rng(seed)
    n_up = int(round(batch_size * upper_share))
    n_lo = int(batch_size) - n_up
    aux = _distillation(copy.deepcopy(net), n_up, float(distill)) if distill > 0 else None
    lab_lo = robot.pseudo[source]
    usable = np.flatnonzero((lab_lo > 0).reshape(len(lab_lo), -1).any(axis=1))
    if len(usable) == 0:
        raise ValueError(f"{source}: no robot frame carries a label")
    aug = dict(crop=cfg.crop_size, zoom=cfg.zoom, jitter=cfg.jitter, base_zoom=cfg.width / cfg.net_size[0],
               use_depth=cfg.use_depth)
    t0 = time.perf_counter()
    losses = []
    net.train()
    for _ in tqdm(range(int(steps)), desc=f"adapt {source}", disable=not progress):
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
        "from": str(checkpoint), "from_sha256": _file_digest(checkpoint), "label_source": source,
        "scenes": list(robot.scenes), "frames": int(len(robot.views)), "label_coverage": robot.coverage.get(source),
        "steps": int(steps), "batch_size": int(batch_size), "lr": float(lr), "upper_share": float(upper_share),
        "distill": float(distill), "seed": int(seed), "final_loss": float(np.mean(losses[-20:])), "seconds": time.perf_counter() - t0,
    }
    out = Path(out)
    with atomic_path(out) as tmp:
        torch.save(ckpt, tmp)
    return out


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
