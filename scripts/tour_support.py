"""How much of the robot's view the person's map supports, for tours of a given frame count and
camera step, on **validation** scenes only (docs/protocol.md "Time budget").

``python scripts/tour_support.py OUT --config 120:0.15 60:0.15 60:0.3025 [--scenes 8]``

For each validation scene of the full profile (seeds 501.., kinds in turn) and each
``frames:camera_step``: the person's and the robot's own coverage-matched tours
(:func:`semmatch.sim.simulate_pair`, 320x240), the person's map fused from the upper frames with
ground-truth labels (4 cm), and the share of the robot's pixels with depth that
``3d-neighborhood`` labels from it (the support of ``support_per_scene.md``). Writes
``OUT/tour_support.csv`` and prints the per-configuration mean and minimum.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import pandas as pd


def main() -> None:
    from semmatch.experiments.pipeline import notebook_parameters
    from semmatch.fusion import extract, fuse_sequence
    from semmatch.io import read_sequence, write_map
    from semmatch.io.geometry import DEFAULT_INTRINSICS
    from semmatch.sim import generate_scene, simulate_pair
    from semmatch.transfer import load_index, transfer_sequence

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--config", nargs="+", default=["120:0.15", "60:0.15", "60:0.3025"],
                    help="frames:camera_step pairs (default %(default)s)")
    ap.add_argument("--scenes", type=int, default=8, help="validation scenes (default %(default)s)")
    ap.add_argument("--profile", default="full")
    args = ap.parse_args()

    p = notebook_parameters("01_simulate", args.profile)
    kinds, seeds = p["kinds"], p["val_seeds"][: args.scenes]
    intr = DEFAULT_INTRINSICS.scaled(p["image_width"], p["image_height"])
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for i, seed in enumerate(seeds):
        scene = generate_scene(kinds[i % len(kinds)], seed)
        for cfg in args.config:
            n, step = int(cfg.split(":")[0]), float(cfg.split(":")[1])
            t0 = time.time()
            with tempfile.TemporaryDirectory() as tmp:
                up, low = simulate_pair(scene, tmp, n_frames=n, camera_step=step, seed=seed, intrinsics=intr,
                                        progress=False)
                vol = fuse_sequence(read_sequence(up), voxel_size=p["voxel_size"], progress=False)
                write_map(Path(tmp) / "upper.ply", extract(vol, "mesh"))
                index = load_index(Path(tmp) / "upper.ply", cache=False)
                stats = transfer_sequence("3d-neighborhood", read_sequence(low), index, Path(tmp) / "lab",
                                          progress=False)
            rows.append(dict(scene=scene.name, frames=n, camera_step=step, support=float(stats["coverage"]),
                             seconds=time.time() - t0))
            print(rows[-1], flush=True)
    df = pd.DataFrame(rows)
    df.to_csv(args.out / "tour_support.csv", index=False)
    print(df.groupby(["frames", "camera_step"])["support"].agg(["mean", "min", "max"]).round(3).to_string())


if __name__ == "__main__":
    main()
