"""Train a segmentation network on simulated human-height views.

Training views are upper views (camera 1.2-1.8 m, tilting +-20 deg) of training scenes only;
validation uses held-out scenes. Augmentations: horizontal flip, colour jitter and a random
scale/crop window (depth rescaled with the zoom). The loss is cross-entropy with
square-root median-frequency class weights (void ignored). The best validation checkpoint (mIoU over
classes 1..10) is kept. Everything is seeded: the same config gives the same weights on the
same machine (``torch.use_deterministic_algorithms``; data rendered single-threaded).

One module (over 500 lines): the configuration, augmentation and training loop form one recipe, and
the checkpoint records them together.
"""

from __future__ import annotations

import copy
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np
import pandas as pd
import torch
import torch.nn.functional as F

from ..geometry import DEFAULT_INTRINSICS
from ..io import atomic_path
from ..labels import table_fingerprint
from ..progress import tqdm
from ..sim.trajectory import TRAJECTORY_VERSION
from . import data as D
from .models import CHECKPOINT_FORMAT, ModelConfig, build_network, count_parameters
from .predict import Segmenter, load_model
from .scores import confusion, scores

__all__ = [
    "TrainConfig", "PROFILES", "make_config", "network_spec", "pipeline_configs", "train", "train_or_load", "validation_table", "augment",
    "evaluate_views", "build_views", "optimisation_step", "CHECKPOINT_FORMAT", "config_differences", "config_record",
    "views_digest", "machine_record",
]



@dataclass
class TrainConfig:
    """Everything that decides a trained network (stored in its checkpoint).

    Parameters
    ----------
    out : str
        Checkpoint path (``.pt``).
    arch : {"compact", "strong"}
    use_depth : bool
        Feed depth as a fourth channel.
    width, height : int
        Render resolution of the training and validation views.
    net_width, net_height : int or None
        Resolution the network runs at (None = ``width`` x ``height``). A network smaller than
        the views sees whole frames at reduced scale: at prediction time images are resized to it
        and the probabilities restored (:class:`semmatch.segment.predict.Segmenter`).
    crop_width, crop_height : int or None
        Training crop size (None = the network's resolution).
    kinds : tuple of str
        Scene kinds; scene ``i`` has kind ``kinds[i % len(kinds)]``.
    train_seeds, val_seeds : tuple of int
        Training and validation scenes (must be disjoint, and disjoint from ``eval_seeds``).
    eval_seeds : tuple of int
        Evaluation scenes, only checked for disjointness.
    heights : (float, float)
        Camera height range of training views (metres).
    n_heights : int
        Trajectories per training scene, at heights spread over ``heights``.
    frames : int
        Frames per training trajectory.
    val_frames : int
        Frames per validation scene (one trajectory at the middle of ``heights``).
    tilt_deg : float
        Tilt amplitude of the trajectories.
    steps, batch_size, lr, weight_decay : training schedule (AdamW + one-cycle).
    eval_every : int
        Validate every this many steps (and at the end).
    zoom : (float, float)
        Range of the scale augmentation: a training window covers ``zoom`` times the crop in
        view pixels (>1 zooms out). With a network smaller than the views, ``width / net_width``
        is the scale seen at prediction time.
    jitter : float
        Colour-jitter strength.
    class_weight_power : float
        Exponent of the median-frequency class weights (1 = median frequency balancing,
        0.5 = its square root, 0 = unweighted); see :func:`semmatch.segment.data.class_weights`.
    seed : int
    device : str
        ``"auto"`` (CUDA when present, else CPU), ``"cpu"`` or ``"cuda"``.
    threads : int or None
        ``torch.set_num_threads`` for the run (None = leave as is).
    cache_dir : str or None
        Cache rendered views here (``.npz``).
    progress : bool
    """

    out: str = "data/models/compact.pt"
    arch: str = "compact"
    use_depth: bool = False
    width: int = 160
    height: int = 120
    net_width: int | None = None
    net_height: int | None = None
    crop_width: int | None = None
    crop_height: int | None = None
    kinds: tuple[str, ...] = ("living_room", "bedroom", "office", "apartment")
    train_seeds: tuple[int, ...] = (1, 2)
    val_seeds: tuple[int, ...] = (501,)
    eval_seeds: tuple[int, ...] = (1001, 1002, 1003)
    heights: tuple[float, float] = (1.2, 1.8)
    n_heights: int = 3
    frames: int = 6
    val_frames: int = 8
    tilt_deg: float = 20.0
    steps: int = 120
    batch_size: int = 8
    lr: float = 4e-3
    weight_decay: float = 1e-4
    eval_every: int = 40
    zoom: tuple[float, float] = (0.75, 1.5)
    jitter: float = 0.25
    class_weight_power: float = 0.5
    seed: int = 0
    device: str = "auto"
    threads: int | None = None
    cache_dir: str | None = None
    progress: bool = True
    extra: dict = field(default_factory=dict)

    def model_config(self) -> ModelConfig:
        """The architecture this config trains."""
        nw, nh = self.net_size
        return ModelConfig(arch=self.arch, use_depth=self.use_depth, width=nw, height=nh)

    def validate(self) -> TrainConfig:
        """Raise ``ValueError`` for an inconsistent config; return self."""
        self.model_config()
        D.check_disjoint(train=self.train_seeds, val=self.val_seeds, eval=self.eval_seeds)
        if not self.train_seeds or not self.val_seeds:
            raise ValueError("train_seeds and val_seeds must not be empty")
        cw, ch = self.crop_size
        if not (16 <= cw <= self.width and 16 <= ch <= self.height):
            raise ValueError(f"crop {cw}x{ch} must lie within 16x16 .. {self.width}x{self.height}")
        for name in ("steps", "batch_size", "eval_every", "frames", "val_frames", "n_heights"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if not 0 < self.zoom[0] <= self.zoom[1]:
            raise ValueError(f"zoom range must satisfy 0 < lo <= hi, got {self.zoom}")
        nw, nh = self.net_size
        for axis, scale in (("width", self.width / nw), ("height", self.height / nh)):
            if not self.zoom[0] - 1e-6 <= scale <= self.zoom[1] + 1e-6:
                raise ValueError(
                    f"views {self.width}x{self.height} on a {nw}x{nh} network are seen at scale {scale:g} "
                    f"({axis}) when predicting, outside the training zoom range {tuple(self.zoom)}: "
                    f"set net_width/net_height (--net-width/--net-height) or zoom so that it lies inside"
                )
        if self.device not in ("auto", "cpu", "cuda"):
            raise ValueError(f"device must be auto, cpu or cuda, got {self.device!r}")
        return self

    @property
    def net_size(self) -> tuple[int, int]:
        """``(net_width, net_height)``: the network's input resolution."""
        return int(self.net_width or self.width), int(self.net_height or self.height)

    @property
    def crop_size(self) -> tuple[int, int]:
        """``(crop_width, crop_height)``."""
        nw, nh = self.net_size
        return int(self.crop_width or nw), int(self.crop_height or nh)


#: named training profiles (``semmatch train --profile``); ``smoke`` is CI sized
PROFILES: dict[str, dict] = {
    "smoke": dict(width=160, height=120, n_heights=2, frames=6, val_frames=6, steps=100, batch_size=8,
                  eval_every=50),
    # whole frames at half resolution: the network sees the room's context (val mIoU 0.64 vs
    # 0.55 for 160x120 crops at full resolution, same cost per step; GPU sweep of 2026-11-23)
    "full": dict(width=320, height=240, net_width=160, net_height=120, zoom=(1.4, 2.0), n_heights=2,
                 frames=16, val_frames=30, steps=4000, batch_size=16, eval_every=200,
                 train_seeds=tuple(range(1, 13)), val_seeds=(501, 502)),
}


def network_spec(name: str, default_seed: int = 0) -> tuple[str, int]:
    """Architecture and training seed of a network name of the pipeline.

    ``"compact"`` is the compact architecture trained with ``default_seed``; ``"compact@2"`` the
    same architecture trained with seed 2 (the training-variance study lists several seeds of
    one architecture as separate networks).

    Raises
    ------
    ValueError
        An unknown architecture or a seed that is not an integer; the message names both.
    """
    from .models import ARCHITECTURES

    arch, sep, seed = str(name).partition("@")
    if arch not in ARCHITECTURES:
        raise ValueError(f"network {name!r}: unknown architecture {arch!r}; valid: {', '.join(ARCHITECTURES)} "
                         f"(optionally with @SEED, e.g. compact@2)")
    if not sep:
        return arch, int(default_seed)
    try:
        return arch, int(seed)
    except ValueError:
        raise ValueError(f"network {name!r}: the training seed after '@' must be an integer") from None


def make_config(profile: str = "smoke", **overrides) -> TrainConfig:
    """A :class:`TrainConfig` from a named profile plus overrides (None values are ignored).

    Raises
    ------
    ValueError
        Unknown profile or unknown override key.
    """
    if profile not in PROFILES:
        raise ValueError(f"unknown training profile {profile!r}; valid: {', '.join(PROFILES)}")
    names = {f.name for f in fields(TrainConfig)}
    unknown = set(overrides) - names
    if unknown:
        raise ValueError(f"unknown training option(s): {', '.join(sorted(unknown))}")
    kw = dict(PROFILES[profile])
    kw.update({k: v for k, v in overrides.items() if v is not None})
    for k in ("kinds", "train_seeds", "val_seeds", "eval_seeds", "heights", "zoom"):
        if k in kw:
            kw[k] = tuple(kw[k])
    kw["extra"] = dict(kw.get("extra") or {}, profile=profile)
    return TrainConfig(**kw).validate()


def pipeline_configs(
    networks: Sequence[str],
    *,
    train_profile: str,
    seed: int,
    kinds: Sequence[str],
    train_seeds: Sequence[int],
    val_seeds: Sequence[int],
    eval_seeds: Sequence[int],
    width: int,
    height: int,
    steps: dict | None,
    out_dir: str | Path,
    cache_dir: str | Path,
) -> dict[str, TrainConfig]:
    """The training configuration of each network of a pipeline profile (notebook 02's parameters).

    Parameters
    ----------
    networks : sequence of str
        Network names (:func:`network_spec`: ``"compact"``, ``"compact@2"``, ...).
    train_profile : str
        Named training profile (:data:`PROFILES`).
    seed : int
        Training seed of a name without ``@SEED``.
    kinds, train_seeds, val_seeds, eval_seeds, width, height
        As in :class:`TrainConfig`.
    steps : dict or None
        Steps per network name or architecture (a name's entry wins); missing: the profile's.
    out_dir : path
        Checkpoints go to ``out_dir/<network>.pt``.
    cache_dir : path
        Cache of the rendered views.

    Returns
    -------
    dict
        Network name -> validated :class:`TrainConfig`.
    """
    steps = steps or {}
    configs = {}
    for net in networks:
        arch, net_seed = network_spec(net, seed)
        configs[net] = make_config(
            train_profile, arch=arch, out=str(Path(out_dir) / f"{net}.pt"), kinds=tuple(kinds),
            train_seeds=tuple(train_seeds), val_seeds=tuple(val_seeds), eval_seeds=tuple(eval_seeds),
            width=width, height=height, seed=net_seed, steps=steps.get(net, steps.get(arch)),
            cache_dir=str(cache_dir), progress=False,
        )
    return configs


def _device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise ValueError("device 'cuda' requested but CUDA is not available")
    return torch.device(name)


def augment(
    rgb: np.ndarray,
    depth: np.ndarray,
    labels: np.ndarray,
    rng: np.random.Generator,
    *,
    crop: tuple[int, int],
    zoom: tuple[float, float] = (0.75, 1.5),
    jitter: float = 0.25,
    flip: bool = True,
    use_depth: bool = False,
    base_zoom: float = 1.0,
    device: torch.device | str = "cpu",
) -> tuple[torch.Tensor, torch.Tensor]:
    """Augment a batch: random scale/crop window, horizontal flip and colour jitter.

    Parameters
    ----------
    rgb : uint8 (B,H,W,3)
    depth : float32 (B,H,W)
    labels : uint8 (B,H,W)
    rng : numpy Generator
        All random draws come from it (repeatable).
    crop : (width, height)
        Output size.
    zoom : (lo, hi)
        The window covers ``zoom * crop`` input pixels (clipped to the image): > 1 zooms out.
        Depth is multiplied by ``zoom / base_zoom`` (a smaller object looks farther away).
    jitter : float
        Brightness, contrast, saturation (+-jitter) and per-channel gain (+-jitter/3).
    flip : bool
    use_depth : bool
        Append depth as a fourth input channel.
    base_zoom : float
        The zoom at which objects appear at prediction time (view width / network width):
        depth keeps its measured scale there.
    device : torch device

    Returns
    -------
    x : float32 tensor (B, 3 or 4, crop_h, crop_w)
        Normalised network input (:func:`semmatch.segment.models.normalise_inputs`).
    y : int64 tensor (B, crop_h, crop_w)
    """
    from .models import normalise_inputs

    B, H, W = labels.shape
    cw, ch = crop
    zmax = min(W / cw, H / ch)
    z = np.minimum(rng.uniform(zoom[0], zoom[1], B), zmax)
    ww, wh = cw * z, ch * z
    cx = rng.uniform(ww / 2, W - ww / 2)
    cy = rng.uniform(wh / 2, H - wh / 2)
    sign = np.where(rng.uniform(size=B) < 0.5, -1.0, 1.0) if flip else np.ones(B)
    theta = np.zeros((B, 2, 3), np.float32)
    theta[:, 0, 0] = sign * ww / W
    theta[:, 0, 2] = 2 * cx / W - 1
    theta[:, 1, 1] = wh / H
    theta[:, 1, 2] = 2 * cy / H - 1
    grid = F.affine_grid(torch.from_numpy(theta).to(device), [B, 1, ch, cw], align_corners=False)

    img = torch.from_numpy(rgb).to(device).permute(0, 3, 1, 2).float() / 255.0
    img = F.grid_sample(img, grid, mode="bilinear", padding_mode="border", align_corners=False)
    lab = torch.from_numpy(labels).to(device)[:, None].float()
    y = F.grid_sample(lab, grid, mode="nearest", padding_mode="border", align_corners=False)[:, 0].long()

    if jitter > 0:
        j = float(jitter)
        bright = torch.from_numpy(rng.uniform(1 - j, 1 + j, (B, 1, 1, 1)).astype(np.float32)).to(device)
        contrast = torch.from_numpy(rng.uniform(1 - j, 1 + j, (B, 1, 1, 1)).astype(np.float32)).to(device)
        sat = torch.from_numpy(rng.uniform(1 - j, 1 + j, (B, 1, 1, 1)).astype(np.float32)).to(device)
        gain = torch.from_numpy(rng.uniform(1 - j / 3, 1 + j / 3, (B, 3, 1, 1)).astype(np.float32)).to(device)
        img = img * bright * gain
        mean = img.mean(dim=(1, 2, 3), keepdim=True)
        img = (img - mean) * contrast + mean
        gray = img.mean(dim=1, keepdim=True)
        img = ((img - gray) * sat + gray).clamp(0.0, 1.0)
    dep = None
    if use_depth:
        d = torch.from_numpy(depth).to(device)[:, None].float()
        d = F.grid_sample(d, grid, mode="nearest", padding_mode="border", align_corners=False)
        dep = d * torch.from_numpy((z / base_zoom).astype(np.float32)).to(device)[:, None, None, None]
    return normalise_inputs(img, dep), y


def make_optimiser(net: torch.nn.Module, lr: float, weight_decay: float, steps: int):
    """The training schedule of every network here: AdamW and a one-cycle schedule peaking at ``lr``.

    Parameters
    ----------
    net : torch.nn.Module
    lr : float
        Peak learning rate.
    weight_decay : float
    steps : int
        Length of the schedule (optimiser steps).

    Returns
    -------
    (torch.optim.AdamW, torch.optim.lr_scheduler.OneCycleLR)
    """
    # foreach: the same updates as the per-parameter loop PyTorch picks on CPU, 3x cheaper
    # (strong: 15 -> 5 ms a step); fused would be cheaper still but rounds differently
    opt = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=weight_decay, foreach=True)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=int(steps), pct_start=0.1)
    return opt, sched


def optimisation_step(net, x: torch.Tensor, y: torch.Tensor, weights: torch.Tensor, opt, sched, *,
                      what: str = "loss", aux_loss=None) -> float:
    """One step: class-weighted cross-entropy (void ignored), backward, optimiser and schedule.

    Parameters
    ----------
    net, x, y, weights, opt, sched
        Network, batch (images, labels), class weights, optimiser and schedule.
    what : str
        Names the loss in the error message.
    aux_loss : callable, optional
        ``aux_loss(x, logits) -> scalar tensor`` added to the cross-entropy before the backward
        pass (a regulariser, e.g. distillation in :func:`semmatch.adapt.fine_tune`).

    Returns
    -------
    float
        The cross-entropy (without ``aux_loss``).

    Raises
    ------
    FloatingPointError
        The loss is not finite (``what`` names it in the message).
    """
    logits = net(x)
    loss = F.cross_entropy(logits, y, weight=weights, ignore_index=0)
    total = loss if aux_loss is None else loss + aux_loss(x, logits)
    if not torch.isfinite(total):
        raise FloatingPointError(f"{what} became {total.item()}")
    opt.zero_grad(set_to_none=True)
    total.backward()
    opt.step()
    sched.step()
    return float(loss.item())


def evaluate_views(segmenter, views: D.Views, *, batch_size: int = 16) -> dict:
    """Pixel scores (:func:`semmatch.segment.scores.scores`) of a segmenter on rendered views.

    Parameters
    ----------
    segmenter : Segmenter-like
        Has ``predict_batch(rgb, depth) -> (N,H,W,C)`` probabilities.
    views : Views
    batch_size : int

    Returns
    -------
    dict
        ``miou``, ``pixel_acc``, ``jaccard``, ``sorensen``, ``color_acc``, ``mean_acc``,
        ``per_class_iou`` and the raw ``confusion`` (list of lists).
    """
    conf = None
    for i in range(0, len(views), batch_size):
        sl = slice(i, i + batch_size)
        pred = segmenter.predict_labels_batch(views.rgb[sl], views.depth[sl])
        c = confusion(views.labels[sl], pred)
        conf = c if conf is None else conf + c
    if conf is None:
        raise ValueError("evaluate_views: no views")
    out = scores(conf)
    out["confusion"] = conf.tolist()
    return out


def build_views(config: TrainConfig, *, jobs: int = 1, scheduler: str | None = None) -> tuple[D.Views, D.Views]:
    """Render (or load from the cache) the training and validation views of ``config``.

    Parameters
    ----------
    config : TrainConfig
    jobs : int
        Scenes rendered in parallel (:func:`semmatch.segment.data.render_views`); the views do
        not depend on it.
    scheduler : str, optional
        Dask scheduler address to render the scenes on (default ``SEMMATCH_SCHEDULER``; none: local).

    Returns
    -------
    (Views, Views)
        Training and validation views.
    """
    intr = DEFAULT_INTRINSICS.scaled(config.width, config.height)
    rng = np.random.default_rng(config.seed)
    train_heights = np.stack(
        [D.sample_heights(rng, config.heights[0], config.heights[1], config.n_heights) for _ in config.train_seeds]
    )
    val_h = [0.5 * (config.heights[0] + config.heights[1])]
    common = dict(tilt_deg=config.tilt_deg, intrinsics=intr, progress=config.progress, jobs=jobs,
                  scheduler=scheduler)

    def make_train() -> D.Views:
        scenes = D.make_scenes(config.kinds, config.train_seeds)
        return D.render_views(scenes, train_heights, config.frames, seed=config.seed, **common)

    def make_val() -> D.Views:
        scenes = D.make_scenes(config.kinds, config.val_seeds)
        return D.render_views(scenes, val_h, config.val_frames, seed=config.seed + 1, **common)

    key = dict(kinds=config.kinds, width=config.width, height=config.height, tilt=config.tilt_deg,
               tilt_period="n_frames", trajectories=TRAJECTORY_VERSION)
    tr = D.cached_views(config.cache_dir, dict(key, seeds=config.train_seeds, h=train_heights.round(4).tolist(),
                                               frames=config.frames, seed=config.seed), make_train)
    va = D.cached_views(config.cache_dir, dict(key, seeds=config.val_seeds, h=val_h, frames=config.val_frames,
                                               seed=config.seed + 1), make_val)
    return tr, va


def train(config: TrainConfig, *, views: tuple[D.Views, D.Views] | None = None) -> Path:
    """Train a network and write its checkpoint; return the checkpoint path.

    Parameters
    ----------
    config : TrainConfig
        See :func:`make_config` for the named profiles.
    views : (Views, Views), optional
        Training and validation views to use instead of rendering them from ``config``
        (tests, notebooks that render once for several networks).

    Returns
    -------
    Path
        The checkpoint: ``format``, ``model`` (architecture config), ``state_dict``,
        ``categories`` (:func:`semmatch.labels.table_fingerprint`), ``metrics`` (best
        validation scores), ``history`` (per evaluation: step, train loss, val mIoU/accuracy,
        learning rate, seconds), ``train_config``, ``class_weights``, ``n_parameters``.
    """
    config.validate()
    if config.threads:
        torch.set_num_threads(int(config.threads))
    device = _device(config.device)
    if device.type == "cuda":
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.manual_seed(config.seed)
    torch.use_deterministic_algorithms(True, warn_only=device.type == "cuda")
    # deterministic mode also fills every new tensor with NaN (a guard against reading
    # uninitialised memory, which no op here does): 5-13% of a CPU training step, so off
    torch.utils.deterministic.fill_uninitialized_memory = False
    t0 = time.perf_counter()
    machine = machine_record(device)
    train_views, val_views = views if views is not None else build_views(config)
    if train_views.shape != (config.height, config.width):
        raise ValueError(f"training views are {train_views.shape}, config says {config.height}x{config.width}")
    weights = D.class_weights(train_views.labels, power=config.class_weight_power)
    mc = config.model_config()
    # channels-last: the depthwise convolutions of the compact net train ~1.6x faster on CPU
    net = build_network(mc).to(device, memory_format=torch.channels_last)
    opt, sched = make_optimiser(net, config.lr, config.weight_decay, config.steps)
    w_t = torch.from_numpy(weights).to(device)
    rng = np.random.default_rng(config.seed)
    n = len(train_views)
    history: list[dict] = []
    best: dict | None = None
    best_state = None
    running: list[float] = []
    seg = Segmenter(net, mc, device=device, flip=False)  # validation measures the single pass
    bar = tqdm(range(config.steps), desc=f"train {config.arch}", disable=not config.progress)
    for step in bar:
        net.train()
        idx = np.sort(rng.choice(n, config.batch_size, replace=n < config.batch_size))
        x, y = augment(train_views.rgb[idx], train_views.depth[idx], train_views.labels[idx], rng,
                       crop=config.crop_size, zoom=config.zoom, jitter=config.jitter,
                       base_zoom=config.width / config.net_size[0],
                       use_depth=config.use_depth, device=device)
        running.append(optimisation_step(net, x, y, w_t, opt, sched, what=f"training loss at step {step}"))
        if (step + 1) % config.eval_every == 0 or step + 1 == config.steps:
            net.eval()
            val = evaluate_views(seg, val_views)
            rec = dict(step=step + 1, train_loss=float(np.mean(running)), val_miou=val["miou"],
                       val_pixel_acc=val["pixel_acc"], val_mean_acc=val["mean_acc"],
                       lr=float(sched.get_last_lr()[0]), seconds=time.perf_counter() - t0)
            history.append(rec)
            running = []
            bar.set_postfix(loss=f"{rec['train_loss']:.3f}", miou=f"{val['miou']:.3f}")
            if best is None or val["miou"] > best["miou"] or np.isnan(best["miou"]):
                best = dict(val, step=step + 1)
                best_state = copy.deepcopy({k: v.detach().cpu() for k, v in net.state_dict().items()})
    bar.close()
    assert best is not None and best_state is not None
    ckpt = {
        "format": CHECKPOINT_FORMAT,
        "model": mc.to_dict(),
        "state_dict": best_state,
        "categories": table_fingerprint(),
        "metrics": best,
        "history": history,
        "train_config": _config_record(config),
        "class_weights": weights.tolist(),
        "n_parameters": count_parameters(net),
        "train_seconds": time.perf_counter() - t0,
        "device": str(device),
        "views_sha256": views_digest(train_views, val_views),
        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        # load average at the start and at the end of training (a busy machine trains slower)
        "machine": dict(machine, load_average_end=machine_record(device)["load_average"]),
    }
    out = Path(config.out)
    with atomic_path(out) as tmp:
        torch.save(ckpt, tmp)
    return out


def views_digest(*views: D.Views) -> str:
    """SHA-256 (hex) over the arrays of rendered views: rgb, depth and labels of each, in order.

    Identifies the exact training data of a checkpoint (``views_sha256``: the training views,
    then the validation views). Rendering is seeded, so the same configuration and code give
    the same digest on one machine; another machine's floating point may change a few pixels
    and with them the digest, which the stored configuration and code version then explain.
    """
    import hashlib

    h = hashlib.sha256()
    for v in views:
        for arr in (v.rgb, v.depth, v.labels):
            a = np.ascontiguousarray(arr)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(memoryview(a).cast("B"))
    return h.hexdigest()


def machine_record(device: torch.device | str) -> dict:
    """Where a network is trained: device, CPU model, cores, torch threads and the load average.

    Stored in each checkpoint (``machine``) so that its training time can be read against the
    machine and how busy it was (``load_average``: 1, 5 and 15 minutes, ``None`` where the
    platform has none).

    Parameters
    ----------
    device : torch.device or str

    Returns
    -------
    dict
        ``device``, ``device_name`` (the GPU's or the CPU's model), ``cpu_count``,
        ``torch_threads``, ``load_average``, ``platform``, ``torch``.
    """
    import platform

    device = torch.device(device)
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else cpu
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    return dict(device=str(device), device_name=name, cpu_count=os.cpu_count(), torch_threads=torch.get_num_threads(),
                load_average=load, platform=platform.platform(), torch=str(torch.__version__))


def _config_record(config: TrainConfig) -> dict:
    """The ``train_config`` entry a checkpoint stores for ``config``."""
    return _plain(asdict(replace(config, progress=False)))


#: config fields that do not change the trained weights (ignored when matching checkpoints);
#: ``eval_seeds`` is only checked for disjointness, so a network serves any evaluation scenes
#: (a confirmatory run's too) that its training and validation scenes leave apart
_NOT_IDENTITY = ("out", "progress", "threads", "cache_dir", "device", "eval_seeds")


def config_differences(stored: dict, wanted: dict) -> list[str]:
    """The training-configuration entries in which two ``train_config`` records differ.

    Fields that do not change the trained weights (output path, progress, threads, cache,
    device) are ignored.

    Parameters
    ----------
    stored, wanted : dict
        ``train_config`` records (a checkpoint's, and :func:`config_record` of a config).

    Returns
    -------
    list of str
        ``"key: stored -> wanted"`` for every differing key (empty: the same training run).
    """
    keys = sorted((set(stored) | set(wanted)) - set(_NOT_IDENTITY))
    return [f"{k}: {stored.get(k, '(absent)')!r} -> {wanted.get(k, '(absent)')!r}"
            for k in keys if stored.get(k) != wanted.get(k)]


def config_record(config: TrainConfig) -> dict:
    """The ``train_config`` record a checkpoint stores for ``config`` (plain lists and dicts)."""
    return _config_record(config)


def train_or_load(config: TrainConfig, *, retrain: bool = False,
                  views: tuple[D.Views, D.Views] | Callable[[], tuple[D.Views, D.Views]] | None = None) -> Path:
    """Return a checkpoint trained with ``config``: the one at ``config.out``, or train.

    A shipped network is installed by :func:`semmatch.segment.shipping.provide_networks` instead.

    Parameters
    ----------
    config : TrainConfig
    retrain : bool
        Train even when a matching checkpoint exists.
    views : (Views, Views) or callable returning them, optional
        Passed to :func:`train`; a callable is called only when training (the views are then
        rendered only when needed).

    Returns
    -------
    Path
        The checkpoint (``config.out``).
    """
    out = Path(config.out)
    if retrain:
        return train(config, views=views() if callable(views) else views)
    if out.is_file():
        try:
            stored = load_model(out).info.get("train_config")
        except ValueError:
            stored = None
        if stored is not None and not config_differences(stored, _config_record(config)):
            return out
    return train(config, views=views() if callable(views) else views)


def validation_table(checkpoints: dict) -> pd.DataFrame:
    """One row per checkpoint: validation scores on held-out scenes, size and training time.

    Parameters
    ----------
    checkpoints : mapping name -> checkpoint path

    Returns
    -------
    pandas.DataFrame
        ``network, arch, parameters, steps, best_step, train_minutes, val_miou, val_pixel_acc,
        val_mean_acc`` and ``iou_<class>`` for classes 1..10.
    """
    from ..labels import EVAL_CLASSES, NAMES

    rows = []
    for name, path in checkpoints.items():
        info = load_model(path).info
        m = info["metrics"]
        row = dict(network=name, arch=info["model"]["arch"], parameters=info["n_parameters"],
                   steps=info["train_config"]["steps"], best_step=m["step"],
                   train_minutes=info["train_seconds"] / 60, val_miou=m["miou"],
                   val_pixel_acc=m["pixel_acc"], val_mean_acc=m["mean_acc"])
        row.update({f"iou_{NAMES[c]}": m["per_class_iou"][c] for c in EVAL_CLASSES})
        rows.append(row)
    return pd.DataFrame(rows)


def _plain(obj):
    """Tuples -> lists, recursively (checkpoints load with ``weights_only=True``)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    return obj
