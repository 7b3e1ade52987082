"""``semmatch bench metrics``: the vectorised voxel comparison vs a per-voxel Python dict loop."""

from __future__ import annotations

import argparse
import time

import numpy as np


def register(sub) -> None:
    """Add ``semmatch bench metrics``."""
    from semmatch.cli.common import add_json, add_scene_kind, number

    p = sub.add_parser(
        "metrics",
        help="seconds to compare two semantic maps of N vertices (vectorised vs dict loop)",
        description="Sample two semantic point maps of N vertices on the surfaces of a procedural "
        "scene (the prediction with 1 cm noise and 10%% wrong labels), then time "
        "semmatch.evaluate.metrics.compare and the plain per-voxel dictionary evaluator on them.",
    )
    p.add_argument("--vertices", type=number(int, lo=1), default=500_000, help="vertices per map")
    p.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.05, help="voxel edge, metres")
    p.add_argument("--repeat", type=number(int, lo=1), default=3, help="timed runs of the vectorised version (best)")
    p.add_argument("--no-dict-loop", action="store_true", help="skip the (slow) dict-loop reference")
    add_scene_kind(p, default="apartment", old=("--scene",))
    p.add_argument("--seed", type=number(int, lo=0), default=0, help="seed of the scene and of the sampled maps")
    add_json(p, "the timings")
    p.set_defaults(func=run)


def surface_maps(n: int, *, scene_kind: str = "apartment", seed: int = 0):
    """Two semantic point maps of ``n`` points sampled on a scene's surfaces (GT, noisy prediction)."""
    from semmatch.io import SemanticMap
    from semmatch.sim import generate_scene

    scene = generate_scene(scene_kind, seed)
    v = scene.vertices[scene.triangles].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    rng = np.random.default_rng(seed)

    def sample(k: int):
        tri = rng.choice(len(area), size=k, p=area / area.sum())
        a, b = rng.random((2, k))
        flip = a + b > 1
        a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
        t = v[tri]
        pts = t[:, 0] + a[:, None] * (t[:, 1] - t[:, 0]) + b[:, None] * (t[:, 2] - t[:, 0])
        return pts, scene.labels[tri]

    gp, gl = sample(n)
    pp, pl = sample(n)
    pp = pp + rng.normal(0, 0.01, pp.shape)
    wrong = rng.random(n) < 0.1
    pl = np.where(wrong, rng.integers(1, 21, n), pl)
    return SemanticMap(gp, gl, source="bench:gt"), SemanticMap(pp, pl, source="bench:pred")


def run(args: argparse.Namespace) -> int:
    """Time both evaluators and print a table or JSON."""
    from semmatch.cli.common import emit
    from semmatch.evaluate.metrics import MEASURES, compare, compare_dict_loop

    if args.vertices < 1 or args.repeat < 1:
        raise ValueError("--vertices and --repeat must be >= 1")
    gt, pred = surface_maps(args.vertices, scene_kind=args.scene_kind, seed=args.seed)
    times = []
    for _ in range(args.repeat):
        t = time.perf_counter()
        s = compare(gt, pred, args.voxel_size)
        times.append(time.perf_counter() - t)
    result = {
        "seconds": min(times),
        "n_vertices": args.vertices,
        "voxel_size": args.voxel_size,
        "gt_voxels": s["counts"]["gt_occupied"],
        "pred_voxels": s["counts"]["pred_occupied"],
        **{k: s[k] for k in MEASURES},
    }
    if not args.no_dict_loop:
        t = time.perf_counter()
        ref = compare_dict_loop(gt, pred, args.voxel_size)
        result["seconds_dict_loop"] = time.perf_counter() - t
        result["speedup"] = result["seconds_dict_loop"] / result["seconds"]
        result["agree"] = bool(all(abs(ref[k] - s[k]) < 1e-12 for k in MEASURES))
    table = "\n".join(
        f"{k:18s} {v:.4f}" if isinstance(v, float) else f"{k:18s} {v}" for k, v in result.items()
    )
    return emit(result, args.json, table)
