"""``semmatch bench render [--json]``: frames per second of the renderer.

The scene is a generated one (``--scene-kind``, ``--seed``) whose flat faces are subdivided
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

import tempfile
import time
from pathlib import Path

from semmatch.cli.common import (
    ImageSize,
    add_camera_height,
    add_image_size,
    add_json,
    add_scene_kind,
    emit,
    number,
)


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
    p = sub.add_parser("render", help="renderer frames/s (RGB + depth + labels)")
    add_scene_kind(p, default="apartment", old=("--kind",))
    p.add_argument("--seed", type=number(int, lo=0), default=0, help="scene seed")
    p.add_argument("--triangles", type=number(int, lo=0), default=200_000, help="densify the scene to at least this many")
    p.add_argument("--frames", type=number(int, lo=1), default=30, help="timed frames")
    add_image_size(p, default=ImageSize(640, 480), old=("--size",))
    p.add_argument("--threads", type=number(int, lo=0), default=1, help="ray-casting threads (0 = all cores)")
    add_camera_height(p, default=1.6, old=("--height",))
    p.add_argument("--mode", choices=("exact", "fast", "raster"), default="exact",
                   help="which renderer mode 'fps' reports (both are measured)")
    p.add_argument("--stream", type=number(int, lo=0), default=0, help="also stream this many frames to disk, report memory")
    add_json(p, "the timings")
    p.set_defaults(func=run)


def _renderers(scene, intr, args) -> tuple[list, float, dict]:
    """The renderers to time: the exact and the fast ray caster, and the rasteriser where an
    OpenGL context can be made; the exact one's set-up seconds; the rasteriser's status."""
    from ...sim import Renderer
    from ...sim.raster import RasterRenderer, gl_available

    t0 = time.perf_counter()
    renderer = Renderer(scene, intr, nthreads=args.threads)
    init_s = time.perf_counter() - t0
    renderers = [("exact", renderer), ("fast", Renderer(scene, intr, nthreads=args.threads, fast=True))]
    gl_ok, gl_info = gl_available()
    if args.mode == "raster" and not gl_ok:
        raise ValueError(f"--mode raster: cannot rasterise here ({gl_info})")
    gl = {"ok": gl_ok, "info": gl_info}
    if gl_ok:
        t0 = time.perf_counter()
        renderers.append(("raster", RasterRenderer(scene, intr, nthreads=args.threads)))
        gl["init_s"] = time.perf_counter() - t0
    return renderers, init_s, gl


def _time_modes(renderers, poses) -> dict:
    """Per mode: median wall ms, median CPU ms per frame (after one warm-up) and the cast fraction."""
    import numpy as np

    modes = {}
    for mode, r in renderers:
        r.render(poses[0])  # warm-up
        wall, cpu = [], []
        for pose in poses:
            t0, c0 = time.perf_counter(), time.process_time()
            r.render(pose)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        modes[mode] = (1000 * float(np.median(wall)), 1000 * float(np.median(cpu)),
                       getattr(r, "last_cast_fraction", 1.0))
    return modes


def _raster_agreement(renderers, poses, modes: dict, gl: dict) -> dict:
    """The rasteriser against the exact ray caster on the timed camera path (or why it is missing)."""
    import numpy as np

    if not gl["ok"]:
        return {"raster": "unavailable: " + gl["info"]}
    exact, raster = renderers[0][1], renderers[-1][1]
    depth_ok, labels_ok = [], []
    for pose in poses:
        a, b = exact.render(pose), raster.render(pose)
        depth_ok.append(float((np.abs(a.depth - b.depth) < 1e-3).mean()))
        labels_ok.append(float((a.labels == b.labels).mean()))
    return {
        "raster_speedup_vs_exact": round(modes["exact"][0] / modes["raster"][0], 2),
        "raster_depth_within_1mm": round(float(np.mean(depth_ok)), 5),
        "raster_labels_equal": round(float(np.mean(labels_ok)), 5),
        "raster_init_s": round(gl["init_s"], 3),
        "gl_renderer": gl["info"],
    }


def _stream_memory(scene, intr, args) -> dict:
    """``--stream N``: write an N-frame sequence to a temporary folder; resident memory before,
    at 10 % and at the end of it."""
    from ...sim import Renderer, make_trajectory, simulate_sequence

    short = make_trajectory(scene, args.camera_height, args.stream, seed=args.seed)
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
        return {
            "stream_frames": args.stream,
            "stream_fps_with_png": round(args.stream / (time.perf_counter() - t0), 2),
            "rss_mb_before": round(before, 1),
            "rss_mb_at_10pct": round(rss[len(rss) // 10], 1),
            "rss_mb_at_end": round(rss[-1], 1),
        }


def run(args) -> int:
    """Run the benchmark."""
    from ...io.geometry import DEFAULT_INTRINSICS
    from ...sim import generate_scene, make_trajectory

    w, h = args.image_size
    if args.frames < 1:
        raise ValueError(f"--frames must be >= 1, got {args.frames}")
    intr = DEFAULT_INTRINSICS.scaled(w, h)
    t0 = time.perf_counter()
    generate_scene(args.scene_kind, args.seed)
    gen_s = time.perf_counter() - t0
    scene, cell = dense_scene(args.scene_kind, args.seed, args.triangles)
    poses = make_trajectory(scene, args.camera_height, max(args.frames, 2), seed=args.seed)
    renderers, init_s, gl = _renderers(scene, intr, args)
    modes = _time_modes(renderers, poses[: args.frames])
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
    res.update(_raster_agreement(renderers, poses[: args.frames], modes, gl))
    if args.stream:
        res.update(_stream_memory(scene, intr, args))
    table = "\n".join(f"{k:>22}: {v}" for k, v in res.items())
    return emit(res, args.json, table)
