"""Time the networks' training of a profile, with notebook 02's configurations, and check that
the weights equal the pipeline's (docs/protocol.md "Time budget").

``python scripts/time_training.py OUT [--profile full]``

When stage 02 of a timed ``dvc repro`` loads its networks (nothing they depend on changed), the
training is not in the run's wall time; this script measures it on the same machine. For each
network of the profile it builds the configuration exactly as notebook 02 does, takes the
training and validation views from the pipeline's cache (``data/<profile>/cache/segment``;
rendered if absent, outside the timing), trains into ``OUT/<network>.pt`` and compares the
weights with ``data/<profile>/models/<network>.pt``. Prints and writes ``OUT/training_time.json``:
minutes per network and whether the weights are bit-identical.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def main() -> None:
    import torch

    from semmatch.experiments.pipeline import ROOT, notebook_parameters
    from semmatch.segment import pipeline_configs
    from semmatch.segment.models import read_checkpoint
    from semmatch.segment.training import build_views, train

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="folder for the trained checkpoints and training_time.json")
    ap.add_argument("--profile", default=None, help="profile of params.yaml (default: its 'profile')")
    args = ap.parse_args()
    p = notebook_parameters("02_train_segmentation", args.profile)
    data_root = ROOT / p["data_root"]
    args.out.mkdir(parents=True, exist_ok=True)
    configs = pipeline_configs(
        p["networks"], train_profile=p["train_profile"], seed=p["seed"], kinds=p["kinds"],
        train_seeds=p["train_seeds"], val_seeds=p["val_seeds"], eval_seeds=p["eval_seeds"], width=p["width"],
        height=p["height"], steps=p.get("steps"), out_dir=args.out, cache_dir=data_root / "cache" / "segment",
    )
    result = {}
    for net, cfg in configs.items():
        views = build_views(cfg)
        t0 = time.perf_counter()
        train(cfg, views=views)
        minutes = (time.perf_counter() - t0) / 60
        mine = read_checkpoint(args.out / f"{net}.pt")["state_dict"]
        theirs_path = data_root / "models" / f"{net}.pt"
        theirs = read_checkpoint(theirs_path)["state_dict"] if theirs_path.is_file() else None
        same = theirs is not None and mine.keys() == theirs.keys() and all(torch.equal(mine[k], theirs[k]) for k in mine)
        result[net] = {"minutes": round(minutes, 2), "identical_to_pipeline": same}
        print(net, result[net], flush=True)
    (args.out / "training_time.json").write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
