"""``semmatch simulate``: render a scene along a trajectory into a sequence folder, or the
whole generated data set.

Examples
--------
::

    semmatch simulate --scene-kind living_room --seed 3 --camera-height 1.6 --frames 300 --out data/tmp/upper
    semmatch simulate --ply ../shared/scenes/replica/office_3/x.ply --camera-height 0.2 --out data/tmp/low
    semmatch simulate --scene-kind bedroom --camera-height 0.2 --noise kinect --out data/tmp/real_like
    semmatch simulate --dataset data/scenes --train-seeds 0 1 2 --eval-seeds 100 101
"""

from __future__ import annotations

import json
from pathlib import Path

from ..io import read_intrinsics
from ..io.geometry import DEFAULT_INTRINSICS, Intrinsics


def _noise(text: str | None):
    from ..sim.noise import NoiseConfig

    if text in (None, "", "none"):
        return None
    if text == "kinect":
        return NoiseConfig.kinect()
    p = Path(text)
    try:
        d = json.loads(p.read_text()) if p.suffix == ".json" and p.is_file() else json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"--noise: expected 'none', 'kinect', a JSON object or a .json file; {e}") from None
    if not isinstance(d, dict):
        raise ValueError("--noise: the JSON must be an object of NoiseConfig parameters")
    return NoiseConfig.from_dict(d)


def _intrinsics(args) -> Intrinsics:
    if args.intrinsics:
        intr = read_intrinsics(args.intrinsics)
    else:
        intr = DEFAULT_INTRINSICS
        if args.image_size:
            intr = intr.scaled(*args.image_size)
    if args.fx is not None or args.fy is not None:
        intr = Intrinsics(intr.width, intr.height, args.fx if args.fx is not None else intr.fx,
                          args.fy if args.fy is not None else (args.fx if args.fx is not None else intr.fy),
                          intr.cx, intr.cy, intr.depth_scale)
    return intr


def register(sub) -> None:
    """Add ``semmatch simulate``."""
    from semmatch.cli.common import (
        add_camera_height,
        add_image_size,
        add_output_flags,
        add_scene_kind,
        add_scene_kinds,
        number,
    )
    from semmatch.io.outputs import declare_paths

    p = sub.add_parser(
        "simulate",
        help="render scenes into sequence folders (procedural scene or PLY; or the whole data set)",
        description="Render RGB, depth, labels and instances of a scene along a trajectory.",
    )
    src = p.add_mutually_exclusive_group()
    add_scene_kind(src, default="living_room", old=("--kind",))
    src.add_argument("--ply", type=Path, help="semantic PLY mesh to use as the scene")
    p.add_argument("--seed", type=number(int, lo=0), default=0, help="scene seed (and trajectory seed)")
    add_camera_height(p, default=1.6, old=("--height",))
    p.add_argument("--frames", type=number(int, lo=1), default=300, help="frames of the trajectory")
    p.add_argument("--tilt", type=number(float, lo=0.0, hi=90.0), default=20.0, help="periodic camera tilt amplitude (degrees)")
    p.add_argument("--trajectory", default=None,
                   help="trajectory name (upper/lower/...) (default: upper above 1 m, else lower)")
    p.add_argument("--margin", type=number(float, lo=0.0), default=0.3, help="clearance from obstacles (m)")
    p.add_argument("--noise", default=None, help="none | kinect | JSON of NoiseConfig parameters | file.json")
    add_image_size(p, help="image size in pixels (intrinsics scaled from those of the 640x480 camera)",
                   old=("--size",))
    p.add_argument("--fx", type=number(float, lo=0.0, lo_open=True), default=None, help="focal length (pixels)")
    p.add_argument("--fy", type=number(float, lo=0.0, lo_open=True), default=None,
                   help="vertical focal length (pixels) (default: --fx)")
    p.add_argument("--intrinsics", type=Path, default=None, help="intrinsics.json to use")
    p.add_argument("--save-scene", type=Path, default=None, help="also write the GT semantic mesh here")
    p.add_argument("--fast", action="store_true",
                   help="coarse-to-fine rendering (about 2x faster; thin objects under 2 px can be missed)")
    p.add_argument("--renderer", choices=("raycast", "raster", "auto"), default="raycast",
                   help="raycast: Open3D ray casting (the reference); raster: OpenGL rasterising (headless EGL, "
                        "CPU or GPU); auto: raster where an OpenGL context can be made")
    p.add_argument("--pair", action="store_true",
                   help="with --out DIR: write the person's and the robot's sequences DIR/upper (--camera-height) "
                        "and DIR/lower (--lower-camera-height) of one scene, routes as --routes")
    add_camera_height(p, default=0.2, flag="--lower-camera-height", old=("--lower-height",),
                      help="robot camera height for --pair in metres")
    p.add_argument("--camera-step", type=number(float, lo=0.0, lo_open=True), default=0.15,  # sim.DEFAULT_CAMERA_STEP (not imported at start-up)
                   help="largest camera step between frames (m): a tour is at most (frames - 1) x this long, so fewer "
                        "frames at a larger step fly the same tour")
    p.add_argument("--overwrite", action="store_true", help="replace an existing sequence at --out")
    add_output_flags(p, json_what="what was written", quiet="the progress bars")
    dst = p.add_mutually_exclusive_group(required=True)
    dst.add_argument("--out", type=Path, help="sequence folder to write")
    dst.add_argument("--dataset", type=Path, help="write the generated data layout under this root")
    d = p.add_argument_group("data set (--dataset)")
    d.add_argument("--train-seeds", type=number(int, lo=0), nargs="*", default=[0, 1],
                   help="training scenes: the i-th seed gives one scene of kind KINDS[i %% len(KINDS)] "
                        "(KINDS: --scene-kinds)")
    d.add_argument("--eval-seeds", type=number(int, lo=0), nargs="*", default=[100], help="evaluation scenes: every kind per seed")
    add_scene_kinds(d, default=["living_room", "bedroom", "office"], help="scene kinds of the data set")
    d.add_argument("--frames-lower", type=number(int, lo=1), default=None,
                   help="frames of each lower sequence (default: --frames)")
    d.add_argument("--frames-sweep", type=number(int, lo=1), default=100, help="frames of each height-sweep sequence")
    d.add_argument("--sweep", type=number(float, lo=0.0, lo_open=True), nargs="*", default=None,
                   help="height-sweep heights (m); give none to skip (default: 0.2 .. 1.6)")
    d.add_argument("--jobs", type=number(int, lo=1), default=1, help="scenes written in parallel (local worker processes)")
    d.add_argument("--scheduler", default=None,
                   help="Dask scheduler address (tcp://host:8786) to write the scenes on (default: "
                        "SEMMATCH_SCHEDULER, else --jobs local processes)")
    d.add_argument("--val-seeds", type=number(int, lo=0), nargs="*", default=[],
                   help="validation scenes (laid out as evaluation scenes): the i-th seed gives one scene "
                        "of kind KINDS[i %% len(KINDS)]")
    d.add_argument("--routes", choices=("own", "shared"), default="own",
                   help="own: each camera plans its own coverage-matched tour (the paper's setup); shared: "
                        "the lower camera follows the upper route there and back (ablation); also for --pair")
    d.add_argument("--route-ablation", action="store_true",
                   help="with --routes own, also write lower_shared/: the robot replaying the person's tour")
    declare_paths(p, inputs=("ply", "intrinsics", "noise"), outputs=("out", "dataset", "save_scene"))
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``semmatch simulate``."""
    from .. import sim
    from ..sim.trajectory import check_camera_step
    from .common import emit

    intr = _intrinsics(args)
    noise = _noise(args.noise)
    progress = not args.quiet
    check_camera_step(args.camera_step, "--camera-step")
    if args.dataset is not None:
        sweep = sim.DEFAULT_SWEEP if args.sweep is None else (tuple(args.sweep) or None)
        res = sim.generate_dataset(
            args.dataset, train_seeds=args.train_seeds, eval_seeds=args.eval_seeds, kinds=args.scene_kinds,
            n_frames_upper=args.frames, n_frames_lower=args.frames_lower or args.frames,
            heights_sweep=sweep, n_frames_sweep=args.frames_sweep, tilt_deg=args.tilt, noise=noise,
            intrinsics=intr, progress=progress, jobs=args.jobs, routes=args.routes,
            route_ablation=args.route_ablation, val_seeds=args.val_seeds, renderer=args.renderer,
            scheduler=args.scheduler, camera_step=args.camera_step,
        )
        return emit({"dataset": str(args.dataset), "written": res["written"], "skipped": res["skipped"]}, args.json,
                    f"{args.dataset}: wrote {len(res['written'])}, skipped {len(res['skipped'])} complete item(s)")
    if args.ply is not None:
        from ..sim.plyscene import scene_from_ply

        scene = scene_from_ply(args.ply, seed=args.seed)
    else:
        scene = sim.generate_scene(args.scene_kind, args.seed)
    where = args.ply if args.ply is not None else f"{args.scene_kind} seed {args.seed}"
    if args.pair:
        if args.save_scene is not None:
            scene.save(args.save_scene)
        try:
            up, low = sim.simulate_pair(scene, args.out, n_frames=args.frames, upper_height=args.camera_height,
                                        lower_height=args.lower_camera_height, routes=args.routes,
                                        tilt_deg=args.tilt, seed=args.seed, intrinsics=intr, noise=noise,
                                        overwrite=args.overwrite, progress=progress, backend=args.renderer,
                                        camera_step=args.camera_step)
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None
        result = {"upper": str(up), "lower": str(low), "frames": args.frames, "scene": scene.name,
                  "camera_height": args.camera_height, "lower_camera_height": args.lower_camera_height,
                  "routes": args.routes}
        return emit(result, args.json, f"{up}, {low}: {args.frames} frames each of {scene.name} at "
                    f"{args.camera_height:.2f} / {args.lower_camera_height:.2f} m ({args.routes} routes)")
    kind = args.trajectory or ("upper" if args.camera_height > 1.0 else "lower")
    try:
        poses = sim.make_trajectory(scene, args.camera_height, args.frames, tilt_deg=args.tilt, seed=args.seed,
                                    kind=kind, margin=args.margin, max_step=args.camera_step)
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None
    if args.save_scene is not None:
        scene.save(args.save_scene)
    out = sim.simulate_sequence(scene, poses, args.out, intrinsics=intr, noise=noise, overwrite=args.overwrite,
                                progress=progress, fast=args.fast, backend=args.renderer,
                                meta={"trajectory": kind, "seed": args.seed, "tilt_deg": args.tilt,
                                      "height": args.camera_height, "fast_render": args.fast})
    result = {"out": str(out), "frames": len(poses), "scene": scene.name, "camera_height": args.camera_height,
              "trajectory": kind}
    return emit(result, args.json, f"{out}: {len(poses)} frames of {scene.name} at {args.camera_height:.2f} m")
