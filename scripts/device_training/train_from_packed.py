"""Train the full profile's networks on a lent GPU from views packed by ``pack_views.py``.

Depth is not an input of these networks and is carried as zeros; each checkpoint records the
digest of the full cached views. Trains strong (2400 steps, the analysis plan's decision rule)
first, then the training-seed spread (compact seed 0, then seeds 1 and 2 of both), skipping a
run that would not fit the time budget. Run from the repository root on the device machine
(2026-11-26: NVIDIA H200, 372 s for all six)::

    python3 scripts/device_training/train_from_packed.py [BUDGET_SECONDS]   # writes $OUT/<arch>_s<seed>.pt
"""
import json
import lzma
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, os.getcwd())
from semmatch.segment import data as D  # noqa: E402
from semmatch.segment import training as T  # noqa: E402

PACKED = Path(".devcarry")


def load(meta: dict, name: str) -> D.Views:
    shp = meta[name]["shape"]
    rgb = np.frombuffer(lzma.decompress((PACKED / f"{name}_rgb.xz").read_bytes()), np.uint8).reshape(shp)
    lab = np.frombuffer(lzma.decompress((PACKED / f"{name}_labels.xz").read_bytes()), np.uint8).reshape(shp[:3])
    m = np.load(PACKED / f"{name}_meta.npz")
    return D.Views(rgb=rgb, depth=np.zeros(shp[:3], np.float16), labels=lab, scene=m["scene"], height=m["height"])


def main(budget: float) -> None:
    out = Path(os.environ.get("OUT", "/tmp/out"))
    out.mkdir(parents=True, exist_ok=True)
    meta = json.loads((PACKED / "meta.json").read_text())
    T.views_digest = lambda *v: meta["digest"]  # the packed views are the cached ones
    t0 = time.time()
    views = (load(meta, "train"), load(meta, "val"))
    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "cpu"
    print("views", views[0].rgb.shape, views[1].rgb.shape, f"{time.time() - t0:.1f} s", gpu, torch.__version__, flush=True)
    spent: dict[str, float] = {}
    for arch, seed in [("strong", 0), ("compact", 0), ("strong", 1), ("compact", 1), ("strong", 2), ("compact", 2)]:
        if time.time() - t0 + 1.2 * spent.get(arch, 0) > budget:
            print("skip", arch, seed, "(budget)", flush=True)
            continue
        cfg = T.TrainConfig(**{**meta["configs"][arch], "seed": seed, "out": str(out / f"{arch}_s{seed}.pt")})
        t = time.time()
        T.train(cfg, views=views)
        spent[arch] = time.time() - t
        ck = torch.load(out / f"{arch}_s{seed}.pt", weights_only=True)
        print(arch, seed, f"{spent[arch]:.0f} s", "best", ck["metrics"]["step"], round(ck["metrics"]["miou"], 4),
              [(h["step"], round(h["val_miou"], 4)) for h in ck["history"]], flush=True)
    print("total", f"{time.time() - t0:.0f} s")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 500.0)
