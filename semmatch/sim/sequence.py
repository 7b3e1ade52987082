"""Generate the default data set: scene splits, and every scene's sequence folders.

:func:`generate_dataset` lays out ``<root>/<split>/<scene>/`` with the person's and the robot's
tours, their noisy recordings and the height sweep, each a sequence folder written by
:mod:`semmatch.sim.simulate` (whose names, :func:`simulate_sequence` and the others, are
importable from here as before); :func:`check_seed_splits` refuses overlapping scene splits.
"""

from __future__ import annotations

import os
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..io import write_json
from ..io.geometry import DEFAULT_INTRINSICS, Intrinsics
from .noise import NoiseConfig
from .procedural import SCENE_KINDS, generate_scene
from .raster import make_renderer
from .simulate import (
    DEFAULT_SWEEP,
    _complete,
    _drop_partials,
    carrier_poses,
    simulate_pair,
    simulate_sequence,
    simulate_sequences,
    sweep_name,
)
from .trajectory import DEFAULT_CAMERA_STEP, check_camera_step, make_sweep_trajectories, route_waypoints

__all__ = ["simulate_sequence", "simulate_sequences", "simulate_pair", "carrier_poses", "generate_dataset",
           "sweep_name", "DEFAULT_SWEEP", "check_seed_splits"]


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
        local worker processes, see :func:`semmatch.runtime.engine.map_tasks`).
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

    from ..runtime.engine import map_tasks, resolve_scheduler

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
