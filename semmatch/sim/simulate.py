"""Render a camera's trajectory into a sequence folder: one recording, or the person's and the
robot's pair of one scene.

Files of a simulated sequence (docs/data.md plus extras)::

    intrinsics.json, poses.txt, rgb/, depth/, labels/   the data contract
    instances/NNNNNN.png   16-bit instance ids (ground truth)
    poses_gt.txt           the true poses (TUM)
    meta.json              scene, trajectory and noise parameters

For a noise-free sequence ``poses.txt`` and ``poses_gt.txt`` are equal. With pose noise,
``poses.txt`` holds the *estimated* (drifting, jittered) poses, what a real recording gives,
while RGB, depth, labels and instances are rendered from the *true* poses of
``poses_gt.txt``: labels stay aligned with the images, and a method using ``poses.txt``
sees realistic pose error.

:func:`simulate_sequence` renders one trajectory (:func:`simulate_sequences`: several of one
scene, each scene mesh shared); :func:`carrier_poses` plans a carrier's tour and
:func:`simulate_pair` renders the person's and the robot's tours of a scene.
:mod:`semmatch.sim.sequence` lays out a whole data set of such folders.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import warnings
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from ..io import SequenceWriter, is_sequence, read_intrinsics, write_tum
from ..io.geometry import DEFAULT_INTRINSICS, Intrinsics
from ..runtime.progress import tqdm
from .noise import NoiseConfig, estimated_poses, exposure_gains, noisy_depth, noisy_rgb
from .raster import make_renderer
from .render import Renderer
from .scene import Scene
from .trajectory import DEFAULT_CAMERA_STEP, make_trajectory, route_waypoints

__all__ = ["simulate_sequence", "simulate_sequences", "simulate_pair", "carrier_poses", "sweep_name", "DEFAULT_SWEEP"]

DEFAULT_SWEEP = (0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6)


def sweep_name(height: float) -> str:
    """Folder name of a height-sweep sequence: 0.2 m -> ``h020``."""
    return f"h{round(height * 100):03d}"


def simulate_sequence(
    scene: Scene,
    poses: np.ndarray,
    out_dir: str | os.PathLike,
    *,
    intrinsics: Intrinsics = DEFAULT_INTRINSICS,
    noise: NoiseConfig | None = None,
    overwrite: bool = False,
    progress: bool = True,
    renderer: Renderer | None = None,
    meta: dict | None = None,
    fast: bool = False,
    backend: str = "raycast",
) -> Path:
    """Render ``poses`` of ``scene`` and stream the frames into a sequence folder.

    Frames are written one by one (memory does not grow with the number of frames) into a
    hidden temporary folder that is renamed to ``out_dir`` only when complete
    (:class:`semmatch.io.SequenceWriter`): an interrupted run leaves nothing that reads as a
    sequence.

    Parameters
    ----------
    scene : Scene
    poses : ndarray (N,4,4)
        True ``T_world_camera`` poses.
    out_dir : path
        The sequence folder to create.
    intrinsics : Intrinsics
    noise : NoiseConfig, optional
        Sensor noise; None or an all-zero config renders clean frames.
    overwrite : bool
        Replace an existing sequence at ``out_dir``.
    progress : bool
        Show a tqdm progress bar.
    renderer : Renderer, optional
        Reuse a renderer of ``scene`` (must have the same intrinsics).
    meta : dict, optional
        Extra entries for ``meta.json``.
    fast : bool
        Build the renderer in its coarse-to-fine mode (see :class:`Renderer`); ignored when
        ``renderer`` is given.
    backend : {"raycast", "raster", "auto"}
        Renderer backend when ``renderer`` is not given (:func:`semmatch.sim.raster.make_renderer`):
        the ray caster (the reference), the OpenGL rasteriser, or the rasteriser where a context
        can be made.

    Returns
    -------
    Path
        The sequence folder.

    Raises
    ------
    FileExistsError
        ``out_dir`` holds another sequence or other files and ``overwrite`` is False.
    ValueError
        Poses that are not (N,4,4) rigid transforms, or a renderer with other intrinsics.
    """
    return simulate_sequences(scene, poses, [(out_dir, noise, meta)], intrinsics=intrinsics,
                              overwrite=overwrite, progress=progress, renderer=renderer, fast=fast,
                              backend=backend)[0]


def simulate_sequences(
    scene: Scene,
    poses: np.ndarray,
    targets: Sequence[tuple[str | os.PathLike, NoiseConfig | None, dict | None]],
    *,
    intrinsics: Intrinsics = DEFAULT_INTRINSICS,
    overwrite: bool = False,
    progress: bool = True,
    renderer: Renderer | None = None,
    fast: bool = False,
    backend: str = "raycast",
) -> list[Path]:
    """Render ``poses`` once and write several sequence folders from the same frames.

    E.g. a clean and a noisy copy of one trajectory (``upper`` and ``upper_noisy``): every
    frame is rendered once and each target adds its own sensor noise (its own random stream
    from its noise seed), so each folder equals what :func:`simulate_sequence` writes for it.

    Parameters
    ----------
    scene : Scene
    poses : ndarray (N,4,4)
        True ``T_world_camera`` poses.
    targets : sequence of (out_dir, noise, meta)
        The folders to create, each with its :class:`NoiseConfig` (None: clean) and extra
        ``meta.json`` entries (None: none).
    intrinsics, overwrite, progress, renderer, fast, backend
        As in :func:`simulate_sequence`.

    Returns
    -------
    list of Path
        The sequence folders, in the order of ``targets``.

    Raises
    ------
    FileExistsError, ValueError
        As :func:`simulate_sequence`; also no targets, or one folder named twice.
    """
    poses = np.asarray(poses, dtype=np.float64)
    outs = [Path(t[0]) for t in targets]
    if not outs:
        raise ValueError("simulate_sequences: no target folders")
    if len({o.resolve() for o in outs}) != len(outs):
        raise ValueError(f"simulate_sequences: a folder is named twice in {[str(o) for o in outs]}")
    where = outs[0] if len(outs) == 1 else outs[0].parent
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) == 0:
        raise ValueError(f"{where}: poses must have shape (N, 4, 4) with N >= 1, got {poses.shape}")
    if renderer is None:
        renderer = make_renderer(scene, intrinsics, backend=backend, fast=fast)
    elif renderer.intrinsics != intrinsics:
        raise ValueError(f"{where}: the renderer's intrinsics differ from the requested ones")
    streams = []  # per target: (noise config, its random stream, estimated poses, exposure gains)
    for _, noise, _ in targets:
        cfg = noise or NoiseConfig()
        rng = np.random.default_rng(cfg.seed)
        est = estimated_poses(poses, cfg, rng)
        streams.append((cfg, rng, est, exposure_gains(len(poses), cfg, rng)))
    scene_meta = {k: v for k, v in scene.meta.items() if k in ("kind", "seed", "ceiling_height", "floor_z")}
    with ExitStack() as stack:
        writers = [stack.enter_context(SequenceWriter(o, intrinsics, overwrite=overwrite)) for o in outs]
        desc = outs[0].name if len(outs) == 1 else "+".join(o.name for o in outs)
        empty = 0  # frames in which less than half of the pixels see the scene
        for i in tqdm(range(len(poses)), desc=desc, disable=not progress, leave=False):
            try:
                r = renderer.render(poses[i])
            except ValueError as e:
                raise ValueError(f"{where}: frame {i}: {e}") from None
            empty += int(np.count_nonzero(r.depth > 0) * 2 < r.depth.size)
            inst = np.clip(r.instances, 0, 65535).astype(np.uint16)
            for w, (cfg, rng, est, gains) in zip(writers, streams, strict=True):
                depth, rgb = r.depth, r.rgb
                if cfg.enabled:
                    depth = noisy_depth(depth, cfg, rng)
                    rgb = noisy_rgb(rgb, cfg, rng, float(gains[i]))
                w.add(rgb, depth, est[i], labels=r.labels, instances=inst)
        for w, (_, _, meta), (cfg, *_) in zip(writers, targets, streams, strict=True):
            info = {
                "scene": scene.name,
                "scene_meta": scene_meta,
                "frames": len(poses),
                "noise": cfg.to_dict() if cfg.enabled else None,
                "poses": "poses.txt = estimated poses" + (" (noisy)" if cfg.pose_noise else " (= poses_gt.txt)"),
                **(meta or {}),
            }
            w.write_extra("poses_gt.txt", _tum_text(poses))
            w.write_extra("meta.json", json.dumps(info, indent=2) + "\n")
    if empty * 4 > len(poses):
        warnings.warn(f"{where}: {empty} of {len(poses)} frames are mostly empty (less than half of the pixels "
                      f"see the scene of {scene.name!r}): a partial scan seen from a height it was not "
                      "recorded at, or a camera outside the mesh?", UserWarning, stacklevel=2)
    return outs


def carrier_poses(scene: Scene, height: float, n: int, *, carrier: str = "upper", routes: str = "own",
                  route: np.ndarray | None = None, tilt_deg: float = 20.0, seed: int = 0,
                  camera_step: float = DEFAULT_CAMERA_STEP) -> np.ndarray:
    """The poses of one carrier (person or robot) through a scene, as the protocol plans them.

    Parameters
    ----------
    scene : Scene
    height : float
        Camera height above the floor (m).
    n : int
        Frames.
    carrier : {"upper", "lower"}
        Whose tour (sets the trajectory's style: speed, tilt, turn rate).
    routes : {"own", "shared"}
        ``own``: a coverage-matched tour of the carrier's own free space (the paper's setup);
        ``shared``: a tour visiting the carrier's route waypoints there and back.
    route : ndarray (K, 2), optional
        Waypoints to follow instead (the robot replaying the person's route).
    tilt_deg : float
    seed : int
    camera_step : float
        Largest camera step between frames (m; ``make_trajectory``'s ``max_step``): a tour is at
        most ``(n - 1) * camera_step`` long, so fewer frames at a larger step fly the same tour.

    Returns
    -------
    ndarray (n, 4, 4)
    """
    if routes not in ("own", "shared"):
        raise ValueError(f"routes must be 'own' or 'shared', got {routes!r}")
    if route is not None:
        return make_trajectory(scene, height, n, tilt_deg=tilt_deg, seed=seed, kind="lower", waypoints=route,
                               max_step=camera_step)
    if routes == "shared":
        return make_trajectory(scene, height, n, tilt_deg=tilt_deg, seed=seed, kind=carrier, max_step=camera_step)
    return make_trajectory(scene, height, n, tilt_deg=tilt_deg, seed=seed, kind=carrier, cover=True,
                           there_and_back=False, max_step=camera_step)


def simulate_pair(
    scene: Scene,
    out_dir: str | os.PathLike,
    *,
    n_frames: int,
    upper_height: float = 1.6,
    lower_height: float = 0.2,
    routes: str = "own",
    tilt_deg: float = 20.0,
    seed: int = 0,
    intrinsics: Intrinsics = DEFAULT_INTRINSICS,
    noise: NoiseConfig | None = None,
    overwrite: bool = False,
    progress: bool = True,
    backend: str = "raycast",
    camera_step: float = DEFAULT_CAMERA_STEP,
) -> tuple[Path, Path]:
    """The person's and the robot's sequences of one scene: ``<out_dir>/upper`` and ``/lower``.

    Parameters
    ----------
    scene : Scene
        E.g. :func:`semmatch.sim.scene_from_ply` of a scanned room.
    out_dir : path
    n_frames : int
        Frames of each sequence.
    upper_height, lower_height : float
        Camera heights above the floor (m).
    routes : {"own", "shared"}
        ``own``: each carrier tours its own free space (the paper's setup); ``shared``: the robot
        visits the person's route waypoints, there and back.
    tilt_deg, seed, intrinsics, noise, overwrite, progress, backend
        As :func:`simulate_sequence`.
    camera_step : float
        Largest camera step between frames (m, :func:`carrier_poses`).

    Returns
    -------
    (Path, Path)
        The upper and the lower sequence folders.
    """
    out_dir = Path(out_dir)
    kw = dict(tilt_deg=tilt_deg, seed=seed, camera_step=camera_step)
    up = carrier_poses(scene, upper_height, n_frames, carrier="upper", routes=routes, **kw)
    route = route_waypoints(scene, upper_height, seed=seed, kind="upper") if routes == "shared" else None
    low = carrier_poses(scene, lower_height, n_frames, carrier="lower", routes=routes, route=route, **kw)
    renderer = make_renderer(scene, intrinsics, backend=backend)
    label = {"own": "own coverage-matched tour", "shared": "the person's route, there and back"}[routes]
    outs = []
    for name, poses, height, what in (("upper", up, upper_height, "own coverage-matched tour" if routes == "own"
                                       else "own tour"), ("lower", low, lower_height, label)):
        outs.append(simulate_sequence(scene, poses, out_dir / name, intrinsics=intrinsics, noise=noise,
                                      overwrite=overwrite, progress=progress, renderer=renderer,
                                      meta={"trajectory": name, "seed": seed, "tilt_deg": tilt_deg, "height": height,
                                            "route": what}))
    return outs[0], outs[1]


def _tum_text(poses: np.ndarray) -> str:
    """TUM text of poses (through :func:`semmatch.io.write_tum`)."""
    with tempfile.TemporaryDirectory() as d:
        write_tum(Path(d) / "p.txt", np.arange(len(poses), dtype=np.float64), poses)
        return (Path(d) / "p.txt").read_text()


def _complete(path: Path, n_frames: int, intrinsics: Intrinsics) -> bool:
    """True when ``path`` holds a complete sequence of ``n_frames`` frames with ``intrinsics``."""
    if not is_sequence(path):
        return False
    try:
        same = read_intrinsics(path / "intrinsics.json") == intrinsics
        n = sum(1 for line in (path / "poses.txt").read_text().splitlines() if line.strip() and line[0] != "#")
    except (OSError, ValueError):
        return False
    return same and n == n_frames


def _drop_partials(folder: Path, name: str) -> None:
    """Remove temporary folders an interrupted writer of ``folder/name`` left behind."""
    for tmp in folder.glob(f".{name}.*.partial"):
        shutil.rmtree(tmp, ignore_errors=True)
