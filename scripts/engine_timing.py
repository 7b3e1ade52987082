"""Time a profile's per-scene work serially and on a local Dask cluster; check the outputs are equal.

Run ``python scripts/engine_timing.py OUT [--profile smoke] [--jobs 2]``: the simulate stage
(``generate_dataset`` with the profile's 01 parameters, written under ``OUT/jobs1``,
``OUT/jobsN``, ``OUT/jobsN_warm``) and the training views (``build_views`` with the profile's
02 parameters, no cache), each serially, on a fresh local cluster (its start included) and on the
running one; file digests and view arrays are compared. See docs/cluster.md.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import time
from pathlib import Path

import numpy as np


def digests(root: Path) -> dict[str, str]:
    """SHA-256 of every file under ``root``, by relative path."""
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def main() -> None:
    from semmatch.experiments.pipeline import notebook_parameters
    from semmatch.io.geometry import DEFAULT_INTRINSICS
    from semmatch.runtime import engine
    from semmatch.segment import make_config
    from semmatch.segment.training import build_views
    from semmatch.sim import generate_dataset

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--profile", default="smoke")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    n = args.jobs

    P = notebook_parameters("01_simulate", args.profile)
    kw = dict(train_seeds=P["train_seeds"], val_seeds=P["val_seeds"], eval_seeds=P["eval_seeds"],
              dev_seeds=P["dev_seeds"], kinds=P["kinds"], n_frames_upper=P["n_frames_upper"],
              n_frames_lower=P["n_frames_lower"], n_frames_train=P["n_frames_train"],
              heights_sweep=P["heights_sweep"] or None, n_frames_sweep=P["n_frames_sweep"], noise=P["noise"],
              intrinsics=DEFAULT_INTRINSICS.scaled(P["image_width"], P["image_height"]), progress=False,
              routes=P["routes"], route_ablation=P["route_ablation"], renderer=P["renderer"])
    runs = []
    for name, jobs in (("jobs1", 1), (f"jobs{n}", n), (f"jobs{n}_warm", n)):
        d = args.out / name
        shutil.rmtree(d, ignore_errors=True)
        t = time.perf_counter()
        r = generate_dataset(d, jobs=jobs, **kw)
        runs.append(d)
        print(f"01 simulate, {name}: {len(r['written'])} scene tasks in {time.perf_counter() - t:.1f} s", flush=True)
    ref = digests(runs[0])
    same = all(digests(d) == ref for d in runs[1:])
    print(f"01 simulate: {len(ref)} files, byte-identical: {same}")
    engine.close_local_cluster()

    T = notebook_parameters("02_train_segmentation", args.profile)
    cfg = make_config(T["train_profile"], kinds=tuple(T["kinds"]), train_seeds=tuple(T["train_seeds"]),
                      val_seeds=tuple(T["val_seeds"]), eval_seeds=tuple(T["eval_seeds"]), width=T["width"],
                      height=T["height"], seed=T["seed"], cache_dir=None, progress=False)
    views = []
    for name, jobs in (("jobs1", 1), (f"jobs{n}", n), (f"jobs{n}_warm", n)):
        t = time.perf_counter()
        tr, va = build_views(cfg, jobs=jobs)
        views.append((tr, va))
        print(f"02 training views, {name}: {len(tr)} + {len(va)} views in {time.perf_counter() - t:.1f} s",
              flush=True)
    fields = ("rgb", "depth", "labels", "scene", "height")
    same = all(np.array_equal(getattr(a, f), getattr(b, f)) for other in views[1:]
               for a, b in zip(views[0], other) for f in fields)
    print(f"02 training views identical: {same}; load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
