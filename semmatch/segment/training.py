"""Train a segmentation network on simulated human-height views.

Training views are upper views (camera 1.2-1.8 m, tilting +-20 deg) of training scenes only;
validation uses held-out scenes. Augmentations: horizontal flip, colour jitter and a random
scale/crop window (depth rescaled with the zoom). The loss is cross-entropy with
square-root median-frequency class weights (void ignored). The best validation checkpoint (mIoU over
classes 1..10) is kept. Everything is seeded: the same config gives the same weights on the
same machine (``torch.use_deterministic_algorithms``; data rendered single-threaded).

The configuration (:class:`TrainConfig`, the named profiles, the record a checkpoint stores of
it) is :mod:`semmatch.segment.train_config`; its names are importable from here as before.
"""

from __future__ import annotations

import copy
import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import torch
import torch.nn.functional as F

from ..io import atomic_path
from ..io.geometry import DEFAULT_INTRINSICS
from ..io.labels import table_fingerprint
from ..runtime.progress import tqdm
from ..sim.trajectory import TRAJECTORY_VERSION
from . import data as D
from .models import CHECKPOINT_FORMAT, build_network, count_parameters
from .predict import Segmenter, load_model
from .scores import confusion, scores
from .train_config import (
    PROFILES,
    TrainConfig,
    _config_record,
    config_differences,
    config_record,
    make_config,
    network_spec,
    pipeline_configs,
)

__all__ = [
    "TrainConfig", "PROFILES", "make_config", "network_spec", "pipeline_configs", "train", "train_or_load", "validation_table", "augment",
    "evaluate_views", "build_views", "optimisation_step", "CHECKPOINT_FORMAT", "config_differences", "config_record",
    "views_digest", "machine_record", "resolve_device",
]



def resolve_device(name: str) -> torch.device:
    """The torch device ``name`` names: ``cpu``, ``cuda`` or ``auto`` (CUDA when available).

    Raises
    ------
    ValueError
        ``cuda`` requested where CUDA is not available.
    """
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
        pass (a regulariser, e.g. distillation in :func:`semmatch.segment.adapt.fine_tune`).

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
        ``categories`` (:func:`semmatch.io.labels.table_fingerprint`), ``metrics`` (best
        validation scores), ``history`` (per evaluation: step, train loss, val mIoU/accuracy,
        learning rate, seconds), ``train_config``, ``class_weights``, ``n_parameters``.

    Notes
    -----
    ``config.threads`` holds for the training only: the process's torch thread count is restored
    afterwards (so that a one-thread training does not slow what runs after it).
    """
    config.validate()
    before = torch.get_num_threads()
    if config.threads:
        torch.set_num_threads(int(config.threads))
    try:
        return _train(config, views)
    finally:
        torch.set_num_threads(before)


def _train(config: TrainConfig, views: tuple[D.Views, D.Views] | None) -> Path:
    """:func:`train` on the thread count already set."""
    device = resolve_device(config.device)
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
    from ..io.labels import EVAL_CLASSES, NAMES

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
