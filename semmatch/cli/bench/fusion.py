"""``semmatch bench fusion``: semantic TSDF integration speed (frames/s) and memory."""

from __future__ import annotations

import argparse
import os
import resource
import time


def register(sub) -> None:
    """Add ``semmatch bench fusion``."""
    from semmatch.cli.common import (
        ImageSize,
        add_camera_height,
        add_image_size,
        add_json,
        add_scene_kind,
        number,
    )

    p = sub.add_parser(
        "fusion",
        help="semantic TSDF integration: frames/s at 640x480 with labels, peak memory",
        description="Render consecutive frames of a procedural scene (not timed), then time their "
        "integration (depth, colour and label evidence) into the semantic TSDF. fps is wall-clock; "
        "cpu_fps counts CPU seconds of this process (closer to an idle machine when others load "
        "the CPU; on one thread, semmatch's default, both measure one core). --thread-rows compares "
        "thread settings, each in a fresh process.",
    )
    p.add_argument("--frames", type=number(int, lo=1), default=60, help="timed frames")
    p.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.04, help="voxel edge, metres")
    add_image_size(p, default=ImageSize(640, 480), old_split=("--width", "--height"))
    add_camera_height(p, default=0.2, help="camera height above the floor in metres; 0.2: the robot view")
    add_scene_kind(p, default="living_room", old=("--scene",))
    p.add_argument("--trunc-voxels", type=number(float, lo=1.0, hi=64.0), default=4.0, help="TSDF truncation in voxels")
    p.add_argument("--label-stride", type=number(int, lo=1), default=2, help="label evidence every Nth pixel")
    p.add_argument("--probabilities", action="store_true",
                   help="fuse (H,W,21) class probabilities instead of label images")
    p.add_argument("--labelings", type=number(int, lo=0), default=0,
                   help="also fuse this many labelings of the frames (the labels with 0%%, 10%%, ... "
                   "of the pixels set to random ids) as separate reconstruct() calls and as one "
                   "reconstruct_many() call, and time both; 0: skip")
    p.add_argument("--seed", type=number(int, lo=0), default=0, help="scene seed")
    from semmatch.cli.bench import add_thread_flags

    add_thread_flags(p, "fusion")
    add_json(p, "the timings")
    p.set_defaults(func=run)


def render_frames(
    scene_kind: str, n: int, width: int, height: int, camera_height: float, seed: int, *, path_frames: int = 300
):
    """The first ``n`` frames (semmatch.io.Frame) of a ``path_frames``-frame trajectory through a
    seeded procedural scene (consecutive frames a few centimetres apart, as a video stream)."""
    from semmatch.io.geometry import DEFAULT_INTRINSICS
    from semmatch.sim import generate_scene, make_trajectory
    from semmatch.sim import render_frames as render

    intr = DEFAULT_INTRINSICS.scaled(width, height)
    scene = generate_scene(scene_kind, seed)
    poses = make_trajectory(scene, camera_height, max(n, path_frames), seed=seed, kind="bench")[:n]
    return render(scene, poses, intr)


def run(args: argparse.Namespace) -> int:
    """Time the integration and print a table or JSON."""
    if args.frames < 1:
        raise ValueError("--frames must be >= 1")
    from semmatch.cli.bench import apply_threads
    from semmatch.cli.common import emit

    if args.thread_rows:
        return _print_thread_rows(args)
    apply_threads(args)  # before Open3D and torch load
    from semmatch.fusion import SemanticTSDF
    from semmatch.runtime.threads import current

    width, height = args.image_size
    frames = render_frames(args.scene_kind, args.frames, width, height, args.camera_height, args.seed)
    labels = [_as_probabilities(f.labels) if args.probabilities else f.labels for f in frames]
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    # warm-up volume (first calls allocate and load kernels), then the timed one
    opts = {"label_stride": args.label_stride, "trunc_voxels": args.trunc_voxels, "device": "CPU:0"}
    warm = SemanticTSDF(args.voxel_size, **opts)
    for f, lab in list(zip(frames, labels))[:2]:
        warm.integrate(f.depth, f.rgb, f.pose, f.intrinsics, labels=lab)
    del warm
    vol = SemanticTSDF(args.voxel_size, **opts)
    t0, c0 = time.perf_counter(), time.process_time()
    for f, lab in zip(frames, labels):
        vol.integrate(f.depth, f.rgb, f.pose, f.intrinsics, labels=lab)
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    t1 = time.perf_counter()
    mesh = vol.extract_mesh()
    t_mesh = time.perf_counter() - t1
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    result = {
        "fps": args.frames / dt,
        "ms_per_frame": 1000 * dt / args.frames,
        "cpu_fps": args.frames / cpu,  # frames per CPU-second: less sensitive to other processes
        "load_average": os.getloadavg()[0],
        "voxel_size": args.voxel_size,
        "width": width,
        "height": height,
        "frames": args.frames,
        "labels": "probabilities" if args.probabilities else "ids",
        "label_stride": args.label_stride,
        "trunc_voxels": args.trunc_voxels,
        "threads": current(),  # the limits in force while the frames were fused
        "blocks": vol.n_blocks,
        "volume_mb": vol.memory_bytes / 2**20,
        "peak_rss_mb": peak / 1024,
        "rss_growth_mb": (peak - rss0) / 1024,
        "mesh_vertices": len(mesh),
        "extract_seconds": t_mesh,
        "scene": args.scene_kind,
        "camera_height": args.camera_height,
    }
    if args.labelings > 0:
        result.update(_time_labelings(frames, args))
    table = "\n".join(
        f"{k:16s} {v:.3f}" if isinstance(v, float) else f"{k:16s} {v}" for k, v in result.items()
    )
    return emit(result, args.json, table)


def _print_thread_rows(args: argparse.Namespace) -> int:
    """``--thread-rows``: the benchmark in a fresh process per thread environment, one row each."""
    from semmatch.cli.bench import thread_rows
    from semmatch.cli.common import emit

    rows = thread_rows(args, "fusion")
    lines = [f"{'environment':<30} {'FPS':>7} {'CPU-FPS':>8} {'load':>5} {'torch':>5} {'Open3D':>6} {'BLAS/OpenMP':>12}"]
    for r in rows:
        th = r["threads"]
        rt = "/".join(str(v) for v in th.get("runtimes", {}).values()) or "-"
        lines.append(f"{r['row']:<30} {r['fps']:7.1f} {r['cpu_fps']:8.1f} {r['load_average']:5.1f} "
                     f"{th.get('torch', '-')!s:>5} {th.get('open3d', '-')!s:>6} {rt:>12}")
    base = rows[1]["cpu_fps"]
    lines.append(f"({args.frames} frames {args.image_size}, voxel {args.voxel_size} m; default "
                 f"environment at {rows[0]['cpu_fps'] / base:.2f}x and no limit at {rows[2]['cpu_fps'] / base:.2f}x "
                 f"the CPU-FPS of OMP_NUM_THREADS=1; {os.cpu_count()} CPUs)")
    return emit({"rows": rows}, args.json, "\n".join(lines))


def _as_probabilities(labels):
    """(H,W,C) class probabilities: 0.8 + 0.2/C on the label's class, 0.2/C elsewhere."""
    import numpy as np

    from semmatch.io.labels import NUM_CLASSES

    eye = np.eye(NUM_CLASSES, dtype=np.float32) * 0.8 + 0.2 / NUM_CLASSES
    return eye[labels]


def _time_labelings(frames, args: argparse.Namespace) -> dict:
    """Seconds to fuse ``args.labelings`` labelings one ``reconstruct`` call each, and in one
    ``reconstruct_many`` call (the geometry fused once); both give the same maps."""
    import numpy as np

    from semmatch.fusion import reconstruct, reconstruct_many
    from semmatch.io.labels import NUM_CLASSES

    rng = np.random.default_rng(args.seed)
    sets = []
    for j in range(args.labelings):
        rate = 0.1 * j
        noisy = [np.where(rng.random(f.labels.shape) < rate, rng.integers(1, NUM_CLASSES, f.labels.shape),
                          f.labels).astype(np.uint8) for f in frames]
        sets.append([_as_probabilities(lab) for lab in noisy] if args.probabilities else noisy)
    opts = {"label_stride": args.label_stride, "trunc_voxels": args.trunc_voxels, "device": "CPU:0"}
    t0 = time.perf_counter()
    for lab in sets:
        reconstruct(frames, lab, args.voxel_size, **opts)
    separate = time.perf_counter() - t0
    t0 = time.perf_counter()
    reconstruct_many(frames, sets, args.voxel_size, **opts)
    many = time.perf_counter() - t0
    return {"labelings": args.labelings, "separate_seconds": separate, "many_seconds": many,
            "many_speedup": separate / many}
