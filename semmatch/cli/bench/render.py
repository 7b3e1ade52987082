"""``semmatch bench render [--json]``: frames per second of the renderer.

The scene is a generated one (``--kind``, ``--seed``) whose flat faces are subdivided
(``generate_scene(..., cell=...)``) until it has at least ``--triangles`` triangles; the
frames follow an upper trajectory through it. The ray caster's two modes are timed, ``exact``
(every pixel ray cast) and ``fast`` (coarse-to-fine, see :class:`semmatch.sim.Renderer`), and the
OpenGL rasteriser (:class:`semmatch.sim.RasterRenderer`, when a context can be made) on the same
camera path, with its agreement with the exact ray caster (depth within 1 mm, labels equal);
``fps`` reports ``--mode``. The rasteriser's threads are Mesa's (``LP_NUM_THREADS``; all cores by
default); ``--threads`` sets the ray caster's. ``fps_cpu_time_*`` divide by the process CPU time instead of the
wall time: on a shared, loaded machine they estimate what one free core would do. ``--stream N`` also writes an N-frame sequence
to a temporary folder and reports the resident memory before and after (it must not grow
with the number of frames).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from . import add_json_flag, emit


def _rss_mb() -> float:
    """Resident memory of this process (MB), from /proc (0 where unavailable)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, ValueError, IndexError):
        return 0.0
    import os

    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def dense_scene(kind: str, seed: int, triangles: int):
    """A generated scene subdivided to at least ``triangles`` triangles (and its cell size)."""
    from ...sim import generate_scene

    cell = 0.3
    scene = generate_scene(kind, seed, cell=cell)
    for _ in range(8):
        if scene.n_triangles >= triangles:
            break
        cell *= max(0.5, 0.97 * (scene.n_triangles / triangles) ** 0.5)
        scene = generate_scene(kind, seed, cell=cell)
    return scene, cell


def register(sub) -> None:
    """Add ``semmatch bench render``."""
    p = sub.add_parser("render", help="renderer frames/s (RGB + depth + labels)",
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--kind", default="apartment", help="procedural scene kind (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="scene seed (default 0)")
    p.add_argument("--triangles", type=int, default=200_000, help="densify the scene to at least this many")
    p.add_argument("--frames", type=int, default=30, help="timed frames (default %(default)s)")
    p.add_argument("--size", default="640x480", help="image size WxH (default %(default)s)")
    p.add_argument("--threads", type=int, default=1, help="ray-casting threads (0 = all cores)")
    p.add_argument("--height", type=float, default=1.6, help="camera height in metres (default %(default)s)")
    p.add_argument("--mode", choices=("exact", "fast", "raster"), default="exact",
                   help="which renderer mode 'fps' reports (both are measured)")
    p.add_argument("--stream", type=int, default=0, help="also stream this many frames to disk, report memory")
    add_json_flag(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Run the benchmark."""
    import numpy as np

    from ...geometry import DEFAULT_INTRINSICS
    from ...sim import Renderer, generate_scene, make_trajectory, simulate_sequence

    try:
        w, h = (int(x) for x in args.size.lower().split("x"))
    except ValueError:
        raise ValueError(f"--size must look like 640x480, got {args.size!r}") from None
    if args.frames < 1:
        raise ValueError(f"--frames must be >= 1, got {args.frames}")
    intr = DEFAULT_INTRINSICS.scaled(w, h)
    t0 = time.perf_counter()
    generate_scene(args.kind, args.seed)
    gen_s = time.perf_counter() - t0
    scene, cell = dense_scene(args.kind, args.seed, args.triangles)
    poses = make_trajectory(scene, args.height, max(args.frames, 2), seed=args.seed)
    t0 = time.perf_counter()
    renderer = Renderer(scene, intr, nthreads=args.threads)
    init_s = time.perf_counter() - t0
    from ...sim.raster import RasterRenderer, gl_available

    renderers = [("exact", renderer), ("fast", Renderer(scene, intr, nthreads=args.threads, fast=True))]
    gl_ok, gl_info = gl_available()
    if args.mode == "raster" and not gl_ok:
        raise ValueError(f"--mode raster: cannot rasterise here ({gl_info})")
    if gl_ok:
        t0 = time.perf_counter()
        renderers.append(("raster", RasterRenderer(scene, intr, nthreads=args.threads)))
        raster_init_s = time.perf_counter() - t0
    modes = {}
    for mode, r in renderers:
        r.render(poses[0])  # warm-up
        wall, cpu = [], []
        for pose in poses[: args.frames]:
            t0, c0 = time.perf_counter(), time.process_time()
            r.render(pose)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        modes[mode] = (1000 * float(np.median(wall)), 1000 * float(np.median(cpu)),
                       getattr(r, "last_cast_fraction", 1.0))
    ms, cpu_ms, _f = modes[args.mode]
    res = {
        "fps": round(1000.0 / ms, 2),
        "mode": args.mode,
        "ms_per_frame": round(ms, 2),
        "fps_cpu_time": round(1000.0 / cpu_ms, 2),
        **{f"fps_{m}": round(1000.0 / v[0], 2) for m, v in modes.items()},
        **{f"fps_cpu_time_{m}": round(1000.0 / v[1], 2) for m, v in modes.items()},
        "fast_cast_fraction": round(modes["fast"][2], 3),
        "width": w,
        "height": h,
        "triangles": int(scene.n_triangles),
        "threads": args.threads,
        "frames": args.frames,
        "scene": scene.name,
        "cell_m": round(cell, 4),
        "renderer_init_s": round(init_s, 3),
        "generate_scene_s": round(gen_s, 3),
        "outputs": "rgb+depth+labels+instances",
    }
    if gl_ok:
        # agreement of the rasteriser with the exact ray caster on the timed camera path
        depth_ok, labels_ok = [], []
        for pose in poses[: args.frames]:
            a, b = renderer.render(pose), renderers[-1][1].render(pose)
            depth_ok.append(float((np.abs(a.depth - b.depth) < 1e-3).mean()))
            labels_ok.append(float((a.labels == b.labels).mean()))
        res.update(
            raster_speedup_vs_exact=round(modes["exact"][0] / modes["raster"][0], 2),
            raster_depth_within_1mm=round(float(np.mean(depth_ok)), 5),
            raster_labels_equal=round(float(np.mean(labels_ok)), 5),
            raster_init_s=round(raster_init_s, 3),
            gl_renderer=gl_info,
        )
    else:
        res.update(raster="unavailable: " + gl_info)
    if args.stream:
        short = make_trajectory(scene, args.height, args.stream, seed=args.seed)
        with tempfile.TemporaryDirectory() as d:
            before = _rss_mb()
            rss = []

            class _Probe(Renderer):
                def render(self, pose):
                    rss.append(_rss_mb())
                    return super().render(pose)

            probe = _Probe(scene, intr, nthreads=args.threads)
            t0 = time.perf_counter()
            simulate_sequence(scene, short, Path(d) / "seq", intrinsics=intr, renderer=probe, progress=False)
            res.update(
                stream_frames=args.stream,
                stream_fps_with_png=round(args.stream / (time.perf_counter() - t0), 2),
                rss_mb_before=round(before, 1),
                rss_mb_at_10pct=round(rss[len(rss) // 10], 1),
                rss_mb_at_end=round(rss[-1], 1),
            )
    table = "\n".join(f"{k:>22}: {v}" for k, v in res.items())
    return emit(res, args.json, table)
