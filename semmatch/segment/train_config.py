"""What decides a trained segmentation network: its configuration and the record of it.

:class:`TrainConfig` holds everything that decides the trained weights; :data:`PROFILES` names
sized starting points (:func:`make_config`), :func:`network_spec` reads the pipeline's network
names (``compact``, ``compact@2``) and :func:`pipeline_configs` gives each network of a profile
its configuration. A checkpoint stores :func:`config_record` of its configuration;
:func:`config_differences` says in what two records differ (nothing: the same training run).
:mod:`semmatch.segment.training` trains with it, and exports these names too.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

from . import data as D
from .models import ModelConfig

__all__ = ["TrainConfig", "PROFILES", "network_spec", "make_config", "pipeline_configs", "config_record",
           "config_differences"]


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
                    f"set net_width/net_height (--net-size WxH) or zoom (--zoom LO HI) so that it lies inside"
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



def _config_record(config: TrainConfig) -> dict:
    """The ``train_config`` entry a checkpoint stores for ``config``."""
    return _plain(asdict(replace(config, progress=False)))


#: config fields that are not part of the training recipe (ignored when matching checkpoints):
#: ``threads`` and ``device`` change only the order of the floating-point sums, but rounding
#: differences grow over the steps, so the learned weights differ (a one-thread CPU run
#: reproduces a one-thread CPU run's weights exactly; ``shipping.provide_networks`` retrains with
#: the shipped run's threads);
#: ``eval_seeds`` is only checked for disjointness, so a network serves any evaluation scenes
#: (a confirmatory run's too) that its training and validation scenes leave apart
_NOT_IDENTITY = ("out", "progress", "threads", "cache_dir", "device", "eval_seeds")


def config_differences(stored: dict, wanted: dict) -> list[str]:
    """The training-configuration entries in which two ``train_config`` records differ.

    Fields that are not part of the training recipe (output path, progress, threads, cache,
    device, evaluation seeds) are ignored; threads and device still change the learned weights
    through the rounding of their sums (:data:`_NOT_IDENTITY`).

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



def _plain(obj):
    """Tuples -> lists, recursively (checkpoints load with ``weights_only=True``)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    return obj
