"""``semmatch bench transfer [--repeat R] [--json]``: every method and the reference timed on
640x480 frames, on one core, with the rate from the CPU time of the method beside the wall rate
and the load; with ``--repeat``, each method's spread over runs in a row and how many runs reached
the sensor rate with every method."""

from __future__ import annotations

import os
import time

from semmatch.cli.common import add_camera_height, add_json, emit, number


def register(sub) -> None:
    """Add ``semmatch bench transfer``."""
    from semmatch.transfer import available_methods

    p = sub.add_parser(
        "transfer",
        help="time the transfer methods and the published reference on 640x480 frames",
        description="Renders lower-view 640x480 frames of a generated scene, indexes its "
        "ground-truth semantic mesh and the person's fused ground-truth map of it (--map), then times each method on one thread (OpenCV, torch, "
        "Open3D, OpenMP/BLAS at 1). FPS is the rate from the method's CPU time (median per "
        "frame): what one free core delivers. The wall rate and the machine's 1-minute load "
        "average stand beside it; on a busy machine the wall rate falls. The reference (per-pixel "
        "Open3D closest point, the authors' approach) runs in the same process. fused runs on "
        "3d-projected-sp with a stand-in network's 21-class probabilities.",
    )
    p.add_argument("--frames", type=number(int, lo=1), default=10, help="frames per method")
    p.add_argument("--seed", type=number(int, lo=0), default=0, help="scene and trajectory seed")
    add_camera_height(p, default=0.25, help="lower camera height in metres", old=("--height",))
    p.add_argument("--methods", nargs="*", default=None, choices=available_methods(), metavar="METHOD",
                   help=f"subset of methods, of {', '.join(available_methods())} (default: the paper's five and "
                        "fused)")
    p.add_argument("--map", choices=("mesh", "fused", "both"), default="both",
                   help="what the methods transfer from: the scene's own mesh, the person's fused ground-truth map "
                        "of it (a TSDF reconstruction of the upper tour, as Table 1 indexes: denser, so slower), "
                        "or both")
    p.add_argument("--repeat", type=number(int, lo=1), default=1,
                   help="time every method this many times in a row against each map (index built once) and "
                        "report each method's median and range over the runs, and in how many runs every method "
                        "reached the analysis plan's sensor rate (P3); the main table is the first run's")
    p.add_argument("--variant", action="append", default=[], metavar="METHOD:KEY=VALUE[,KEY=VALUE]",
                   help="time METHOD again with these parameters (JSON values) beside its plain row, in the same "
                        "runs, e.g. --variant 2d-slic:iterations=3; repeatable (rows are summarised, not counted "
                        "for the sensor rate)")
    p.add_argument("--param", action="append", default=[], metavar="METHOD:KEY=VALUE[,KEY=VALUE]",
                   help="run METHOD's main row with these parameters (JSON values), e.g. --param 2d-slic:iterations=3 "
                        "(the analysis plan v2's lever; counted for the sensor rate); repeatable, one per method")
    add_json(p, "the timings")
    p.set_defaults(func=run)


def parse_variant(text: str) -> tuple[str, str, dict]:
    """``METHOD:KEY=VALUE[,KEY=VALUE]`` -> ``(row name, method, parameters)`` for
    :func:`semmatch.transfer.benchmark.time_methods`.

    Raises
    ------
    ValueError
        No ``METHOD:`` prefix, an unknown method, or a parameter without ``=``.
    """
    from semmatch.cli.transfer import _parse_params
    from semmatch.transfer import available_methods

    method, sep, rest = text.partition(":")
    if not sep or not rest:
        raise ValueError(f"--variant expects METHOD:KEY=VALUE[,KEY=VALUE], got {text!r}")
    if method not in available_methods():
        raise ValueError(f"--variant {text!r}: unknown method {method!r}; valid: {', '.join(available_methods())}")
    params = _parse_params(rest.split(","))
    return f"{method} [{rest}]", method, params


def method_settings(texts: list[str]) -> dict[str, dict]:
    """``--param`` values (``METHOD:KEY=VALUE[,KEY=VALUE]``) -> ``{method: {parameter: value}}``.

    Raises
    ------
    ValueError
        A malformed value, an unknown method or parameter, or one method given twice.
    """
    from semmatch.transfer import settings_for

    out: dict[str, dict] = {}
    for text in texts:
        _, method, params = parse_variant(text)
        if method in out:
            raise ValueError(f"--param names {method} twice; give all its parameters in one: METHOD:K=V,K=V")
        out[method] = params
    for method in out:
        settings_for(method, out)  # unknown parameters named here, before any frame is rendered
    return out


def run(args) -> int:
    """Run the benchmark."""
    from semmatch.sim import render_frames
    from semmatch.transfer import METHODS
    from semmatch.transfer.benchmark import bench_scene, bench_upper_map

    if args.frames < 1:
        raise ValueError("--frames must be >= 1")
    if args.repeat < 1:
        raise ValueError("--repeat must be >= 1")
    methods = list(args.methods or (*METHODS, "fused"))  # argparse checked the names
    variants = [parse_variant(v) for v in args.variant]
    settings = method_settings(args.param)
    scene, poses = bench_scene(args.seed, args.frames, args.camera_height)
    frames = render_frames(scene, poses)
    names = ["mesh", "fused"] if args.map == "both" else [args.map]
    maps = {}
    for name in names:  # the scene's mesh; the person's fused ground-truth map of it (as Table 1)
        maps[name] = scene.to_semantic_map() if name == "mesh" else bench_upper_map(scene, seed=args.seed)
    target = sensor_rate_fps()
    result: dict = {"maps": {name: _time_map(m, frames, methods, args.repeat, target, variants, settings)
                             for name, m in maps.items()},
                    "frames": len(frames), "scene": scene.name,
                    "size": [frames[0].intrinsics.width, frames[0].intrinsics.height],
                    "repeat": args.repeat, "target_fps": target, "settings": settings}
    first = names[0]
    result.update(map=first, **{k: result["maps"][first][k] for k in ("methods", "reference", "threads")})
    blocks = [_table(name, r) for name, r in result["maps"].items()]
    if args.repeat > 1:
        blocks += [_spread_table(name, r, target) for name, r in result["maps"].items()]
    blocks.append(f"{len(frames)} frames {result['size'][0]}x{result['size'][1]} of {scene.name}, one thread; "
                  f"FPS = 1000 / median CPU ms of the method per frame (one core); wall FPS and the 1-minute "
                  f"load average beside it ({os.cpu_count()} CPUs); paper: its Table 1; x ref: against the "
                  "reference timed in this run on the same map; accuracy on labelled pixels vs ground truth. "
                  "mesh: the scene's own labelled mesh; fused: the person's tour fused with its ground-truth "
                  "labels (what Table 1 indexes)")
    return emit(result, args.json, "\n\n".join(blocks))


def sensor_rate_fps() -> float:
    """The sensor rate every method should reach: the analysis plan's P3 threshold (``min_fps``)."""
    from semmatch.experiments.analysis_plan import load_analysis_plan

    rates = [float(c["min_fps"]) for c in load_analysis_plan().speed_claims if c.get("id") == "P3"]
    if len(rates) != 1:
        raise ValueError("the analysis plan states no single sensor-rate claim P3 with min_fps")
    return rates[0]


def rate_spread(runs: list[dict], methods, target: float) -> dict:
    """Each method's CPU rate over repeated runs, and how often every method reached ``target``.

    Parameters
    ----------
    runs : list of dict
        One :func:`semmatch.transfer.benchmark.time_methods` result per run.
    methods : sequence of str
        The methods that must reach ``target`` (the reference and variants are summarised, not
        counted).
    target : float
        CPU FPS.

    Returns
    -------
    dict
        ``{"spread": {method: {median, min, max, runs_at_target}}, "runs_all_at_target": int}``
        (the reference under ``"reference (closest point)"``).
    """
    import numpy as np

    rates = {key: [r["methods"][key]["cpu_fps"] for r in runs] for key in runs[0]["methods"]}
    rates["reference (closest point)"] = [r["reference"]["cpu_fps"] for r in runs]
    spread = {key: {"median": float(np.median(v)), "min": float(min(v)), "max": float(max(v)),
                    "runs_at_target": int(sum(x >= target for x in v))} for key, v in rates.items()}
    every = sum(all(r["methods"][m]["cpu_fps"] >= target for m in methods) for r in runs)
    return {"spread": spread, "runs_all_at_target": int(every)}


def _time_map(semantic_map, frames, methods, repeat: int, target: float, variants=(), settings=None) -> dict:
    """Index one map and time every method against it ``repeat`` times in a row
    (:func:`semmatch.transfer.benchmark.time_methods`); the first run's timings, with the
    spread over the runs (:func:`rate_spread`) when ``repeat > 1``; ``variants`` and
    ``settings`` as in :func:`~semmatch.transfer.benchmark.time_methods`."""
    from tqdm import tqdm

    from semmatch.transfer import as_map_index
    from semmatch.transfer.benchmark import time_methods

    t, c = time.perf_counter(), time.process_time()
    index = as_map_index(semantic_map)
    build_s, build_cpu_s = time.perf_counter() - t, time.process_time() - c
    runs = [time_methods(frames, index, methods, variants=variants, settings=settings)
            for _ in tqdm(range(repeat), desc="bench runs", disable=repeat == 1, leave=False)]
    out = dict(runs[0])
    if repeat > 1:
        out.update(rate_spread(runs, methods, target), runs=[
            {**{k: m["cpu_fps"] for k, m in r["methods"].items()}, "reference (closest point)": r["reference"]["cpu_fps"],
             "load_average": max(m["load_average"] for m in r["methods"].values())} for r in runs])
    out.update(vertices=len(semantic_map.points), faces=0 if semantic_map.faces is None else len(semantic_map.faces),
               index_build_s=build_s, index_build_cpu_s=build_cpu_s,
               index_build_peak_mb=_build_peak_mb(semantic_map), index_mb=index.nbytes / 2**20,
               index_blocks=index.n_blocks)
    return out


def _table(name: str, result: dict) -> str:
    """The text table of one map's timings."""
    ref = result["reference"]
    rows = [f"map: {name} ({result['vertices']} vertices, {result['faces']} faces; index built in "
            f"{result['index_build_s']:.1f} s, {result['index_build_cpu_s']:.1f} s CPU, peak "
            f"{result['index_build_peak_mb']:.0f} MB allocated, {result['index_blocks']} blocks, "
            f"{result['index_mb']:.0f} MB kept)",
            f"{'method':28s} {'CPU ms':>7s} {'FPS':>7s} {'paper':>6s} {'x paper':>8s} {'x ref':>6s} "
            f"{'wall FPS':>9s} {'load':>5s} {'acc':>6s} {'cov':>6s}"]
    for key, r in [*result["methods"].items(), ("reference (closest point)", ref)]:
        paper = r.get("paper_fps", float("nan"))
        rows.append(f"{key:28s} {r['ms_median']:7.1f} {r['fps']:7.1f} {paper:6.2f} "
                    f"{r.get('speedup_vs_paper', float('nan')):8.1f} {r['fps'] / ref['fps']:6.1f} "
                    f"{r['wall_fps']:9.1f} {r['load_average']:5.1f} {r['accuracy']:6.3f} {r['coverage']:6.3f}")
    return "\n".join(rows)


def _spread_table(name: str, result: dict, target: float) -> str:
    """The text table of one map's repeated runs."""
    runs = result["runs"]
    loads = [r["load_average"] for r in runs]
    rows = [f"map: {name}, {len(runs)} runs in a row (load {min(loads):.1f}-{max(loads):.1f}): CPU FPS per run",
            f"{'method':28s} {'median':>7s} {'min':>7s} {'max':>7s} {'runs >= ' + format(target, 'g'):>11s}"]
    for key, r in result["spread"].items():
        hits = "-" if key.startswith("reference") else f"{r['runs_at_target']} of {len(runs)}"
        rows.append(f"{key:28s} {r['median']:7.1f} {r['min']:7.1f} {r['max']:7.1f} {hits:>11s}")
    rows.append(f"runs with every method at >= {target:g} CPU FPS (the analysis plan's P3): "
                f"{result['runs_all_at_target']} of {len(runs)}")
    return "\n".join(rows)


def _build_peak_mb(semantic_map) -> float:
    """Peak memory allocated while indexing ``semantic_map`` (MiB, traced by ``tracemalloc``: NumPy
    arrays and Python objects; a second build, not the timed one)."""
    import tracemalloc

    from semmatch.transfer import MapIndex

    tracemalloc.start()
    try:
        MapIndex(semantic_map)
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()
