"""Render trajectories into sequence folders and generate the default data set.

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

One module (over 500 lines): writing one sequence and laying out a whole data set share the
sequence folder format, its completeness check and its handling of partial writes.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import warnings
import zlib
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from ..geometry import DEFAULT_INTRINSICS, Intrinsics
from ..io import SequenceWriter, is_sequence, read_intrinsics, write_json, write_tum
from ..progress import tqdm
from .noise import NoiseConfig, estimated_poses, exposure_gains, noisy_depth, noisy_rgb
from .procedural import SCENE_KINDS, generate_scene
from .raster import make_renderer
from .render import Renderer
from .scene import Scene
from .trajectory import (
    DEFAULT_CAMERA_STEP,
    check_camera_step,
    make_sweep_trajectories,
    make_trajectory,
    route_waypoints,
)

__all__ = ["simulate_sequence", "simulate_sequences", "simulate_pair", "carrier_poses", "generate_dataset",
           "sweep_name", "DEFAULT_SWEEP", "check_seed_splits"]

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


def check_seed_splits(train_seeds: Sequence[int] = (), val_seeds: Sequence[int] = (),
                      eval_seeds: Sequence[int] = (), *, dev_seeds: Sequence[int] = ()) -> None:
    """Refuse scene seeds that overlap between splits, and an empty evaluation list.

    Parameters
    ----------
    train_seeds, val_seeds, eval_seeds : sequences of int
        Scene seeds of the training, validation and evaluation splits.
    dev_seeds : sequence of int
        Seeds looked at while the recipes were developed: they may be neither evaluation
        seeds nor anything else's (they are only checked against ``eval_seeds``).

    Raises
    ------
    ValueError
        An empty ``eval_seeds``, a seed listed twice in one split, or a seed in two splits;
        the message names the splits and the seeds.
    """
    splits = {"train": list(map(int, train_seeds)), "val": list(map(int, val_seeds)),
              "eval": list(map(int, eval_seeds))}
    if not splits["eval"]:
        raise ValueError("eval_seeds is empty: the protocol needs at least one evaluation seed")
    for name, seeds in splits.items():
        dup = sorted({s for s in seeds if seeds.count(s) > 1})
        if dup:
            raise ValueError(f"{name} seeds list {dup} more than once")
    names = list(splits)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            both = sorted(set(splits[a]) & set(splits[b]))
            if both:
                raise ValueError(f"{a} and {b} seeds must be disjoint; both hold {both}")
    dev = sorted(set(map(int, dev_seeds)) & set(splits["eval"]))
    if dev:
        raise ValueError(f"evaluation seeds {dev} were looked at during development (dev_seeds): "
                         f"choose evaluation seeds that were never looked at")


def _path_waypoints(xy: np.ndarray, every: float = 0.5) -> np.ndarray:
    """Points every ``every`` metres along a camera path (N,2): waypoints to replay it."""
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    keep = np.unique(np.searchsorted(s, np.arange(0.0, s[-1] + 1e-9, every)).clip(0, len(xy) - 1))
    return np.asarray(xy)[np.append(keep, len(xy) - 1) if keep[-1] != len(xy) - 1 else keep]


def _noise_for(noise: NoiseConfig, seed: int, kind: str, name: str) -> NoiseConfig:
    """The noise of one recording: its own random stream (two recordings never drift in lockstep)."""
    from dataclasses import replace

    ss = np.random.SeedSequence([int(noise.seed), int(seed), zlib.crc32(kind.encode()), zlib.crc32(name.encode())])
    return replace(noise, seed=int(ss.generate_state(1)[0]))


def _scene_task(root: Path, o: dict, progress: bool, job: tuple[str, int, str]) -> tuple[list[str], list[str]]:
    """One scene of :func:`generate_dataset` as an engine task (``job``: split, seed, kind)."""
    return _write_scene(root, o, *job, progress=progress)


def _write_scene(root: Path, o: dict, split: str, seed: int, kind: str,
                 progress: bool = False) -> tuple[list[str], list[str]]:
    """Write one scene of :func:`generate_dataset` (its mesh and sequences); return (written, skipped)."""
    intrinsics, noise = o["intrinsics"], o["noise"]
    tilt_deg = o["tilt_deg"]
    written: list[str] = []
    skipped: list[str] = []
    scene = generate_scene(kind, seed)
    sdir = root / split / scene.name
    ply = sdir / "scene.ply"
    if ply.is_file():
        skipped.append(str(ply))
    else:
        scene.save(ply)
        write_json(sdir / "scene.json", scene.meta)
        written.append(str(ply))
    # (folder, height, frames, trajectory kind, noise)
    todo: list[tuple[str, float, int, str, NoiseConfig | None]] = []
    if split == "train":
        todo.append(("upper", o["upper_height"], o["n_train"], "upper", None))
    else:
        todo += [("upper", o["upper_height"], o["n_frames_upper"], "upper", None),
                 ("lower", o["lower_height"], o["n_frames_lower"], "lower", None)]
        if o["route_ablation"] and split == "eval":
            todo.append(("lower_shared", o["lower_height"], o["n_frames_lower"], "lower_shared", None))
        if noise is not None and noise.enabled:
            todo += [("upper_noisy", o["upper_height"], o["n_frames_upper"], "upper",
                      _noise_for(noise, seed, kind, "upper_noisy")),
                     ("lower_noisy", o["lower_height"], o["n_frames_lower"], "lower",
                      _noise_for(noise, seed, kind, "lower_noisy"))]
    done = {t[0] for t in todo if _complete(sdir / t[0], t[2], intrinsics)}
    pending = [t for t in todo if t[0] not in done]
    skipped += [str(sdir / t[0]) for t in todo if t[0] in done]
    sweep = {}
    if split in ("eval", "val") and o["heights_sweep"]:
        names = {sweep_name(h): float(h) for h in o["heights_sweep"]}
        missing = [n for n in names if not _complete(sdir / n, o["n_frames_sweep"], intrinsics)]
        skipped += [str(sdir / n) for n in names if n not in missing]
        if missing:
            traj = make_sweep_trajectories(scene, tuple(names.values()), o["n_frames_sweep"],
                                           tilt_deg=tilt_deg, seed=seed)
            sweep = {n: traj[names[n]] for n in missing}
    if not pending and not sweep:
        return written, skipped
    renderer = make_renderer(scene, intrinsics, backend=o["renderer"])
    shared = o["routes"] == "shared"
    # "shared": the robot (lower) follows the person's (upper) route, walked there and back (the
    # ablation); "own": each carrier plans its own coverage-matched tour (the paper's setup)
    route = None
    if any(t[3] == "lower" for t in pending) and shared:
        route = route_waypoints(scene, o["upper_height"], seed=seed, kind="upper")
    elif any(t[3] == "lower_shared" for t in pending):  # the ablation replays the person's actual tour
        up = carrier_poses(scene, o["upper_height"], o["n_frames_upper"], carrier="upper", tilt_deg=tilt_deg,
                           seed=seed, camera_step=o["camera_step"])
        route = _path_waypoints(up[:, :2, 3])
    # a clean sequence and its noisy copy follow one trajectory: render it once for both
    paths: dict[tuple[float, int, str], list[tuple[str, NoiseConfig | None]]] = {}
    for name, height, n, tkind, cfg in pending:
        paths.setdefault((height, n, tkind), []).append((name, cfg))
    for (height, n, tkind), outs in paths.items():
        for name, _ in outs:
            _drop_partials(sdir, name)
        follow = tkind == "lower_shared" or (shared and tkind == "lower")
        poses = carrier_poses(scene, height, n, carrier=tkind, routes=o["routes"], route=route if follow else None,
                              tilt_deg=tilt_deg, seed=seed, camera_step=o["camera_step"])
        route_meta = {"route": "upper route, there and back" if follow else
                      ("own tour" if shared else "own coverage-matched tour")}
        simulate_sequences(scene, poses, [(sdir / name, cfg, {"trajectory": name, "seed": seed, "tilt_deg": tilt_deg,
                                                              **route_meta})
                                          for name, cfg in outs],
                           intrinsics=intrinsics, overwrite=True, progress=progress, renderer=renderer)
        written += [str(sdir / name) for name, _ in outs]
    for name, poses in sweep.items():
        _drop_partials(sdir, name)
        simulate_sequence(scene, poses, sdir / name, intrinsics=intrinsics, overwrite=True,
                          progress=progress, renderer=renderer,
                          meta={"trajectory": name, "seed": seed, "tilt_deg": tilt_deg,
                                "height": float(poses[0, 2, 3])})
        written.append(str(sdir / name))
    return written, skipped


def generate_dataset(
    root: str | os.PathLike,
    *,
    train_seeds: Sequence[int] = (0, 1),
    eval_seeds: Sequence[int] = (100,),
    kinds: Sequence[str] = ("living_room", "bedroom", "office"),
    n_frames_upper: int = 300,
    n_frames_lower: int = 300,
    n_frames_train: int | None = None,
    heights_sweep: Sequence[float] | None = DEFAULT_SWEEP,
    n_frames_sweep: int = 100,
    upper_height: float = 1.6,
    lower_height: float = 0.2,
    tilt_deg: float = 20.0,
    noise: NoiseConfig | dict | None = None,
    intrinsics: Intrinsics = DEFAULT_INTRINSICS,
    progress: bool = True,
    jobs: int = 1,
    routes: str = "own",
    route_ablation: bool = False,
    val_seeds: Sequence[int] = (),
    dev_seeds: Sequence[int] = (),
    renderer: str = "raycast",
    scheduler: str | None = None,
    camera_step: float = DEFAULT_CAMERA_STEP,
) -> dict:
    """Write the generated data layout of docs/data.md (resumable).

    ::

        <root>/<split>/<scene_id>/scene.ply         GT semantic mesh (split: train | eval)
        <root>/<split>/<scene_id>/upper/            sequence at ``upper_height``
        <root>/eval/<scene_id>/lower/               sequence at ``lower_height`` (its own tour)
        <root>/eval/<scene_id>/lower_shared/        with ``route_ablation``: the upper route replayed
        <root>/val/<scene_id>/...                   validation scenes, laid out as eval scenes
        <root>/eval/<scene_id>/h020 .. h160/        height sweep: one path at every height
        <root>/eval/<scene_id>/upper_noisy/, lower_noisy/   with ``noise``: the same paths,
                                                    sensor noise and estimated poses

    ``<scene_id>`` is ``<kind>_<seed:04d>``. A scene file, or a sequence already complete
    with the requested number of frames and intrinsics, is skipped, so an interrupted run
    resumes where it stopped (temporary folders of interrupted writes are removed).

    Parameters
    ----------
    root : path
        Usually ``data/scenes``.
    train_seeds, eval_seeds : sequences of int
        Scene seeds per split; they must be disjoint. Every evaluation seed gives one scene
        of every kind; training seed ``i`` gives one scene of kind ``kinds[i % len(kinds)]``
        (the scenes :mod:`semmatch.segment` trains on: many seeds, varied materials).
    val_seeds : sequence of int
        Validation scenes (``<root>/val/``), written like evaluation scenes (upper, lower,
        noisy copies, height sweep); seed ``i`` gives one scene of kind
        ``kinds[i % len(kinds)]``, the scenes :mod:`semmatch.segment` validates on. Recipes are
        chosen on these, never on the evaluation scenes.
    dev_seeds : sequence of int
        Seeds looked at during development; refused as evaluation seeds.
    kinds : sequence of str
        Scene kinds (see :data:`semmatch.sim.procedural.SCENE_KINDS`).
    n_frames_upper, n_frames_lower, n_frames_train, n_frames_sweep : int
        Frames per sequence (``n_frames_train`` defaults to ``n_frames_upper``).
    heights_sweep : sequence of float or None
        Heights (m) of the sweep sequences of eval scenes; None = no sweep.
    upper_height, lower_height, tilt_deg : float
    noise : NoiseConfig or dict, optional
        Also write noisy ("real-like") copies of the eval upper/lower sequences.
    intrinsics : Intrinsics
    progress : bool
    jobs : int
        Scenes written in parallel by this many worker processes (each renders on one
        thread); the output does not depend on it.
    routes : {"own", "shared"}
        ``"own"`` (the paper's setup, the default): each camera plans its own tour through its
        own free space, coverage-matched (``make_trajectory(cover=True)``: waypoints spread over
        the whole room at the finest spacing the frames allow, no walking back), so the two
        tours differ and both see the room broadly. ``"shared"``: the lower camera visits the
        waypoints of the upper route and walks there and back (the earlier protocol).
    route_ablation : bool
        With ``routes="own"``, also write ``lower_shared/`` in evaluation and validation scenes:
        the robot replaying the person's actual tour, there and back (the shared-route ablation).
    renderer : {"raycast", "raster", "auto"}
        Renderer backend (:func:`semmatch.sim.raster.make_renderer`).
    scheduler : str, optional
        Dask scheduler address to run the scenes on (default ``SEMMATCH_SCHEDULER``; none: ``jobs``
        local worker processes, see :func:`semmatch.engine.map_tasks`).
    camera_step : float
        Largest camera step between frames of the upper and lower tours (m,
        :func:`carrier_poses`): the tours are at most ``(frames - 1) * camera_step`` long. Fewer
        frames at a proportionally larger step keep the tours (and so the room they see) as long.
        A resumed dataset does not re-render sequences written at another step.

    Returns
    -------
    dict
        ``{"written": [paths], "skipped": [paths]}``. ``<root>/manifest.json`` lists the
        scene ids per split and the parameters.

    Raises
    ------
    ValueError
        Overlapping seeds, an empty evaluation seed list, an unknown kind or route mode, or
        bad frame counts or camera step.
    """
    check_seed_splits(train_seeds, val_seeds, eval_seeds, dev_seeds=dev_seeds)
    if routes not in ("own", "shared"):
        raise ValueError(f"routes must be 'own' or 'shared', got {routes!r}")
    for k in kinds:
        if k not in SCENE_KINDS:
            raise ValueError(f"unknown scene kind {k!r}; valid: {', '.join(SCENE_KINDS)}")
    for name, n in (("n_frames_upper", n_frames_upper), ("n_frames_lower", n_frames_lower),
                    ("n_frames_sweep", n_frames_sweep)):
        if int(n) < 1:
            raise ValueError(f"{name} must be >= 1, got {n}")
    check_camera_step(camera_step)
    if isinstance(noise, dict):
        noise = NoiseConfig.from_dict(noise)
    n_train = int(n_frames_train or n_frames_upper)
    root = Path(root)
    written: list[str] = []
    skipped: list[str] = []
    # evaluation scenes first: they hold most frames, so a pool of workers finishes together
    todo = [("eval", int(s), k) for s in eval_seeds for k in kinds]
    val = [(int(s), kinds[i % len(kinds)]) for i, s in enumerate(val_seeds)]
    todo += [("val", s, k) for s, k in val]
    train = [(int(s), kinds[i % len(kinds)]) for i, s in enumerate(train_seeds)]
    todo += [("train", s, k) for s, k in train]
    opts = dict(n_train=n_train, n_frames_upper=int(n_frames_upper), n_frames_lower=int(n_frames_lower),
                heights_sweep=tuple(heights_sweep or ()), n_frames_sweep=int(n_frames_sweep),
                upper_height=upper_height, lower_height=lower_height, tilt_deg=tilt_deg, noise=noise,
                intrinsics=intrinsics, routes=routes, route_ablation=bool(route_ablation), renderer=str(renderer),
                camera_step=float(camera_step))
    from functools import partial

    from ..engine import map_tasks, resolve_scheduler

    # scenes are independent tasks (own seeds, atomic writes): serial, a local cluster or a
    # scheduler's workers give the same files
    inner = progress and int(jobs) == 1 and resolve_scheduler(scheduler) is None
    results = map_tasks(partial(_scene_task, root.resolve(), opts, inner), todo, jobs=jobs, scheduler=scheduler,
                        desc="scenes", progress=progress)
    for w, sk in results:
        written += w
        skipped += sk
    manifest = {"written": written, "skipped": skipped}
    write_json(root / "manifest.json", {
        "train": sorted({f"{k}_{s:04d}" for s, k in train}),
        "val": sorted({f"{k}_{s:04d}" for s, k in val}),
        "eval": sorted({f"{k}_{int(s):04d}" for s in eval_seeds for k in kinds}),
        "params": {"n_frames_upper": n_frames_upper, "n_frames_lower": n_frames_lower,
                   "n_frames_train": n_train, "heights_sweep": list(heights_sweep or []),
                   "n_frames_sweep": n_frames_sweep, "upper_height": upper_height,
                   "lower_height": lower_height, "tilt_deg": tilt_deg, "routes": routes,
                   "route_ablation": bool(route_ablation), "camera_step": float(camera_step),
                   "noise": noise.to_dict() if noise is not None else None,
                   "intrinsics": intrinsics.to_dict()},
    })
    return manifest
