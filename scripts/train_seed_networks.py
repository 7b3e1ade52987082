"""Train other training seeds of the shipped networks with exactly their recipe (issue 52).

Usage::

    OMP_NUM_THREADS=1 python scripts/train_seed_networks.py SEED ARCH[,ARCH] OUT_DIR [DEVICE] [THREADS]
    # e.g. 1 compact,strong /tmp/seeds/ckpt cpu 1   -> OUT_DIR/compact~s1.pt, OUT_DIR/strong~s1.pt
    python -m semmatch.experiments ship --models DIR --to models/full --networks compact@1 ...

The configuration is notebook 02's for the network ``ARCH@SEED`` of the full profile
(``pipeline_configs`` with params.yaml's kinds, scene seeds, sizes and steps), the same as the
shipped ``ARCH`` (seed 0) in everything but the seed, which also seeds the rendered training and
validation views (checked against the shipped manifest before training). The views are rendered
once per seed and shared by the architectures. Used on 2026-11-28 for ``compact@1`` and
``compact@2`` (CPU, one thread; models/full/*.json record where and how long).
"""
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

from semmatch.experiments.pipeline import ROOT, notebook_parameters
from semmatch.segment.training import build_views, config_differences, config_record, pipeline_configs, train


def main(seed: int, archs: list[str], out: str, device: str = "cpu", threads: int = 1) -> None:
    p = notebook_parameters("02_train_segmentation", "full", ROOT / "params.yaml", data_root=str(Path(out) / "data"))
    nets = [*archs, *(f"{a}@{seed}" for a in archs)]
    configs = pipeline_configs(
        nets, train_profile=p["train_profile"], seed=p["seed"], kinds=p["kinds"], train_seeds=p["train_seeds"],
        val_seeds=p["val_seeds"], eval_seeds=p["eval_seeds"], width=p["width"], height=p["height"],
        steps=p.get("steps"), out_dir=out, cache_dir=str(Path(out) / "cache" / "segment"))
    for a in archs:
        shipped = json.loads((ROOT / "models" / "full" / f"{a}.json").read_text())["train_config"]
        diff = config_differences(shipped, config_record(configs[a]))
        if diff:
            raise SystemExit(f"{a}: notebook 02's configuration is not the shipped one ({'; '.join(diff)})")
    views = None
    for a in archs:
        cfg = replace(configs[f"{a}@{seed}"], threads=threads, device=device, out=str(Path(out) / f"{a}~s{seed}.pt"))
        print(a, seed, "steps", cfg.steps, time.strftime("%H:%M:%S"), flush=True)
        if views is None:
            t = time.time()
            views = build_views(cfg, jobs=1)
            print("views", f"{time.time() - t:.0f} s", flush=True)
        t = time.time()
        train(cfg, views=views)
        print(a, seed, "done", f"{time.time() - t:.0f} s", time.strftime("%H:%M:%S"), flush=True)


if __name__ == "__main__":
    if len(sys.argv) < 4:
        raise SystemExit(__doc__)
    main(int(sys.argv[1]), sys.argv[2].split(","), sys.argv[3], *sys.argv[4:5],
         *(int(a) for a in sys.argv[5:6]))
