"""Accuracy cost of each `2d-slic` speed lever on the validation scenes (issue 52; docs/speed.md,
"The 2d-slic lever, chosen on validation scenes").

Usage::

    python scripts/slic_lever_validation.py DATA_ROOT [N_FRAMES] [OUT_CSV]   # e.g. data/full 8

For every validation scene under DATA_ROOT/scenes/val (seeds 501-508 of params.yaml), the scene's
fused ground-truth upper map (its upper tour fused at 4 cm, as stage 03 makes Table 1's map) is
indexed, and `2d-slic` labels N_FRAMES evenly spaced lower frames at 640x480 with the current
setting and with each candidate of LEVERS. Per scene and setting: pixel accuracy and mIoU (classes
1-10) against the rendered ground truth (`pixel_metrics`), and the share of pixels whose label
differs from the current setting's. Prints the per-setting means over the scenes and the loss
against the current setting; writes the per-scene rows to OUT_CSV (default
/tmp/slic_lever_validation.csv). Only validation scenes are read.
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from semmatch.evaluate.metrics import pixel_metrics
from semmatch.experiments.speed import _frames_at
from semmatch.fusion import reconstruct
from semmatch.io import read_sequence
from semmatch.runtime.threads import limit_threads
from semmatch.transfer import as_map_index, transfer_frame

#: the candidates of docs/speed.md's rule (the current setting first)
LEVERS = {
    "current (cv2-slic, 4 iterations, scale 0.5)": {},
    "3 iterations": {"iterations": 3},
    "2 iterations": {"iterations": 2},
    "scale 0.375": {"scale": 0.375},
    "scale 0.25": {"scale": 0.25},
    "cv2-seeds (full resolution)": {"backend": "cv2-seeds"},
    "cv2-lsc (scale 0.5)": {"backend": "cv2-lsc"},
}


def main(data_root: str, n_frames: int = 8, out: str = "/tmp/slic_lever_validation.csv") -> None:
    with limit_threads(1):
        _run(data_root, n_frames, out)


def _run(data_root: str, n_frames: int, out: str) -> None:
    scenes = sorted((Path(data_root) / "scenes" / "val").iterdir())
    rows = []
    for sd in scenes:
        upper = list(read_sequence(sd / "upper"))
        index = as_map_index(reconstruct(upper, [f.labels for f in upper], 0.04))
        frames = _frames_at(sd, n_frames, 640, 480)
        base = None
        for name, params in LEVERS.items():
            labels = [transfer_frame("2d-slic", f, index, **params).labels for f in frames]
            if base is None:
                base = labels
            m = pixel_metrics([f.labels for f in frames], labels)
            changed = float(np.mean([(a != b).mean() for a, b in zip(labels, base, strict=True)]))
            rows.append(dict(scene=sd.name, setting=name, pixel_acc=m["pixel_acc"], miou=m["miou"], changed=changed))
            print(sd.name, name, f"acc {m['pixel_acc']:.4f} mIoU {m['miou']:.4f} changed {changed:.4f}", flush=True)
    df = pd.DataFrame(rows)
    df.to_csv(out, index=False)
    mean = df.groupby("setting", sort=False)[["pixel_acc", "miou", "changed"]].mean()
    cur = mean.iloc[0]
    mean["acc_loss"] = cur["pixel_acc"] - mean["pixel_acc"]
    mean["miou_loss"] = cur["miou"] - mean["miou"]
    print(f"\n{len(scenes)} validation scenes x {n_frames} frames 640x480, fused GT upper maps (4 cm)")
    print(mean.to_string(float_format=lambda v: f"{v:.4f}"))


if __name__ == "__main__":
    main(sys.argv[1], *(int(a) if i == 0 else a for i, a in enumerate(sys.argv[2:])))
