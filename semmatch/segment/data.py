"""Training and evaluation views rendered from the simulator, held in memory (optionally cached).

Views come from procedural scenes (:func:`semmatch.sim.generate_scene`) along trajectories of
:func:`semmatch.sim.make_trajectory` rendered by :class:`semmatch.sim.Renderer`. Training uses
upper views (camera 1.2-1.8 m, tilting) of *training* scenes only; the seeds of training,
validation and evaluation scenes are disjoint (``params.yaml``), which :func:`make_scenes` and
:func:`check_disjoint` help keep.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io import atomic_path
from ..io.geometry import DEFAULT_INTRINSICS, Intrinsics
from ..io.labels import NUM_CLASSES, VOID
from ..runtime.progress import tqdm

__all__ = [
    "Views",
    "make_scenes",
    "check_disjoint",
    "sample_heights",
    "render_views",
    "cached_views",
    "class_weights",
]


@dataclass
class Views:
    """A stack of rendered views.

    Attributes
    ----------
    rgb : uint8 (N,H,W,3)
    depth : float32 (N,H,W), metres, 0 = no hit; at float16 precision (as :meth:`save` stores it,
        so that rendered and cached views are the same arrays)
    labels : uint8 (N,H,W)
    scene : int64 (N,)
        Index of the view's scene in the list it was rendered from.
    height : float32 (N,)
        Nominal camera height of the view's trajectory (metres).
    """

    rgb: np.ndarray
    depth: np.ndarray
    labels: np.ndarray
    scene: np.ndarray
    height: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.rgb)
        if self.rgb.ndim != 4 or self.rgb.shape[-1] != 3 or self.rgb.dtype != np.uint8:
            raise ValueError(f"views: rgb must be uint8 (N,H,W,3), got {self.rgb.dtype} {self.rgb.shape}")
        for what, arr in (("depth", self.depth), ("labels", self.labels)):
            if arr.shape != self.rgb.shape[:3]:
                raise ValueError(f"views: {what} is {arr.shape}, rgb is {self.rgb.shape[:3]}")
        for what, arr in (("scene", self.scene), ("height", self.height)):
            if len(arr) != n:
                raise ValueError(f"views: {len(arr)} {what} entries for {n} views")

    def __len__(self) -> int:
        return len(self.rgb)

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the views."""
        return int(self.rgb.shape[1]), int(self.rgb.shape[2])

    def subset(self, index: np.ndarray) -> Views:
        """The views at ``index`` (boolean mask or integer indices)."""
        return Views(self.rgb[index], self.depth[index], self.labels[index], self.scene[index], self.height[index])

    def save(self, path: str | Path) -> Path:
        """Write the views to a compressed ``.npz``, atomically."""
        path = Path(path)
        with atomic_path(path) as tmp:
            np.savez_compressed(tmp, rgb=self.rgb, depth=self.depth.astype(np.float16), labels=self.labels,
                                scene=self.scene, height=self.height)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Views:
        """Read views written by :meth:`save`."""
        path = Path(path)
        try:
            with np.load(path) as z:
                return cls(z["rgb"], z["depth"].astype(np.float32), z["labels"], z["scene"], z["height"])
        except (KeyError, ValueError, OSError) as e:
            raise ValueError(f"{path}: not a views file ({e})") from None


def make_scenes(kinds: Sequence[str], seeds: Sequence[int]) -> list:
    """Generate one procedural scene per seed; scene ``i`` is of kind ``kinds[i % len(kinds)]``.

    Returns
    -------
    list of semmatch.sim.Scene
    """
    from ..sim import generate_scene

    if not kinds:
        raise ValueError("make_scenes: no scene kinds given")
    return [generate_scene(kinds[i % len(kinds)], int(s)) for i, s in enumerate(seeds)]


def check_disjoint(**seed_lists: Sequence[int]) -> None:
    """Raise ``ValueError`` when two named seed lists share a seed (e.g. train and eval scenes)."""
    names = list(seed_lists)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            common = sorted(set(map(int, seed_lists[a])) & set(map(int, seed_lists[b])))
            if common:
                raise ValueError(f"{a} and {b} scene seeds overlap: {common}; they must be disjoint")


def sample_heights(rng: np.random.Generator, low: float, high: float, n: int) -> np.ndarray:
    """``n`` camera heights spread over ``[low, high]`` (stratified uniform draws)."""
    if not 0 < low <= high:
        raise ValueError(f"heights must satisfy 0 < low <= high, got {low}, {high}")
    edges = np.linspace(low, high, n + 1)
    return edges[:-1] + rng.uniform(0, 1, n) * np.diff(edges)


def render_views(
    scenes: Sequence,
    heights: Sequence[float] | np.ndarray,
    n_frames: int,
    *,
    tilt_deg: float = 20.0,
    tilt_period: int | None = None,
    intrinsics: Intrinsics = DEFAULT_INTRINSICS,
    seed: int = 0,
    same_path: bool = False,
    progress: bool = True,
    jobs: int = 1,
    scheduler: str | None = None,
) -> Views:
    """Render ``n_frames`` views per (scene, height) along the simulator's trajectories.

    Parameters
    ----------
    scenes : sequence of Scene
    heights : sequence of float or ndarray (n_scenes, k)
        Camera heights in metres, the same for every scene, or one row per scene.
    n_frames : int
        Frames per trajectory.
    tilt_deg : float
        Amplitude of the up/down tilt of the trajectories.
    tilt_period : int, optional
        Frames per tilt cycle; default ``n_frames``, so that every trajectory covers a whole
        cycle (a short trajectory with a long period would only look up, or only down).
    intrinsics : Intrinsics
        Render resolution (use ``Intrinsics.scaled`` for small training images).
    seed : int
        Base seed of the trajectories.
    same_path : bool
        Use one trajectory seed per scene for all heights (the paper's height study: same
        path, only the height changes); otherwise every (scene, height) gets its own seed.
    progress : bool
        Show a tqdm bar.
    jobs : int
        Scenes rendered in parallel: tasks of :func:`semmatch.runtime.engine.map_tasks` on ``jobs`` local
        worker processes (1: in this process); the views do not depend on it.
    scheduler : str, optional
        Dask scheduler address to render the scenes on (default ``SEMMATCH_SCHEDULER``; none: local).

    Returns
    -------
    Views
    """
    from functools import partial

    from ..runtime.engine import map_tasks

    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    h = np.asarray(heights, dtype=np.float64)
    if h.ndim == 1:
        h = np.broadcast_to(h, (len(scenes), len(h)))
    if h.ndim != 2 or len(h) != len(scenes):
        raise ValueError(f"heights must be (k,) or (n_scenes, k), got {np.shape(heights)} for {len(scenes)} scenes")
    if not np.isfinite(h).all() or (h <= 0).any():
        raise ValueError("camera heights must be finite and > 0")
    period = max(2, int(tilt_period or n_frames))
    task = partial(_render_scene, n_frames=int(n_frames), tilt_deg=float(tilt_deg), period=period,
                   intrinsics=intrinsics, seed=int(seed), same_path=bool(same_path))
    # one engine task per scene; serial: the bar counts frames, otherwise scenes
    inner = progress and int(jobs) == 1 and len(scenes) > 0
    parts = map_tasks(task, [(si, scene, h[si], inner) for si, scene in enumerate(scenes)], jobs=jobs,
                      scheduler=scheduler, desc="render views", progress=progress and not inner)
    H, W = intrinsics.shape
    total = sum(len(part[0]) for part in parts)
    rgb = np.empty((total, H, W, 3), np.uint8)
    depth = np.empty((total, H, W), np.float32)
    labels = np.empty((total, H, W), np.uint8)
    scene_idx = np.empty(total, np.int64)
    height = np.empty(total, np.float32)
    k = 0
    for si in range(len(parts)):  # copied scene by scene, each part freed once copied
        prgb, pdepth, plabels, pheight = parts[si]
        n = len(prgb)
        # depth at the precision the views cache stores (float16): rendered and cached views are
        # then the same arrays, and so is their digest (a checkpoint's views_sha256)
        rgb[k:k + n], labels[k:k + n], height[k:k + n] = prgb, plabels, pheight
        depth[k:k + n] = np.asarray(pdepth, np.float32).astype(np.float16)
        scene_idx[k:k + n] = si
        k += n
        parts[si] = None
    return Views(rgb, depth, labels, scene_idx, height)


def _render_scene(item: tuple, *, n_frames: int, tilt_deg: float, period: int, intrinsics: Intrinsics, seed: int,
                  same_path: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The views of one scene at its heights (a task of :func:`render_views`): rgb, depth, labels, height."""
    from ..sim import Renderer, make_trajectory

    si, scene, heights, progress = item
    # arrays unpickled on a Dask worker export the buffer format '=f', which Open3D refuses: own copies
    scene = dataclasses.replace(scene, **{f.name: getattr(scene, f.name).copy() for f in dataclasses.fields(scene)
                                          if isinstance(getattr(scene, f.name), np.ndarray)})
    H, W = intrinsics.shape
    total = len(heights) * n_frames
    rgb = np.empty((total, H, W, 3), np.uint8)
    depth = np.empty((total, H, W), np.float32)
    labels = np.empty((total, H, W), np.uint8)
    height = np.empty(total, np.float32)
    k = 0
    renderer = Renderer(scene, intrinsics)
    with tqdm(total=total, desc=f"render views ({si + 1})", disable=not progress, leave=False) as bar:
        for hi, hh in enumerate(heights):
            traj_seed = seed * 100_003 + si * 1009 + (0 if same_path else hi)
            poses = _poses(make_trajectory(scene, float(hh), n_frames, tilt_deg=tilt_deg,
                                           tilt_period=period, seed=traj_seed))
            for pose in poses[:n_frames]:
                r = renderer.render(pose)
                rgb[k], depth[k], labels[k] = r.rgb, r.depth, r.labels
                height[k] = hh
                k += 1
                bar.update()
    return rgb[:k], depth[:k], labels[:k], height[:k]


def _poses(traj) -> np.ndarray:
    """The (N,4,4) poses of whatever :func:`semmatch.sim.make_trajectory` returns."""
    poses = getattr(traj, "poses", traj)
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"make_trajectory returned poses of shape {poses.shape}, expected (N,4,4)")
    return poses


def cached_views(cache_dir: str | Path | None, key: dict, make, *, progress: bool = True) -> Views:
    """Return ``make()``, cached in ``cache_dir/views-<hash of key>.npz`` when a folder is given."""
    if cache_dir is None:
        return make()
    digest = hashlib.sha1(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:12]
    path = Path(cache_dir) / f"views-{digest}.npz"
    if path.is_file():
        return Views.load(path)
    views = make()
    views.save(path)
    return views


def class_weights(
    labels: np.ndarray, num_classes: int = NUM_CLASSES, *, clip: float = 10.0, power: float = 1.0
) -> np.ndarray:
    """Median-frequency balancing weights (Eigen & Fergus, ICCV 2015), optionally softened.

    ``w_c = (median(f) / f_c) ** power`` over the classes present (void excluded), clipped to
    ``[1/clip, clip]``; absent classes and void get weight 0. ``power=1`` is plain median
    frequency balancing, ``0.5`` its square root (large classes such as the floor are not
    starved), ``0`` unweighted cross-entropy.

    Parameters
    ----------
    labels : ndarray of uint8
        Training label images (any shape).
    num_classes : int
    clip : float
    power : float
        Exponent in ``[0, 1]`` applied to the median-frequency ratio.

    Returns
    -------
    ndarray of float32, shape (num_classes,)
    """
    if not 0.0 <= float(power) <= 1.0:
        raise ValueError(f"class weight power must lie in [0, 1], got {power}")
    counts = np.bincount(np.asarray(labels).reshape(-1), minlength=num_classes)[:num_classes].astype(np.float64)
    counts[VOID] = 0
    present = counts > 0
    if not present.any():
        raise ValueError("class_weights: the training labels hold no category other than void")
    freq = counts / counts.sum()
    w = np.zeros(num_classes)
    w[present] = (np.median(freq[present]) / freq[present]) ** float(power)
    w[present] = np.clip(w[present], 1.0 / clip, clip)
    return w.astype(np.float32)
