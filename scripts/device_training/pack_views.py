"""Pack the full profile's training and validation views for a training run on a lent GPU.

The device machine has PyTorch but not Open3D, so it cannot render the views; this packs the
cached ones (rgb and labels, lzma; depth is not an input of the shipped networks) with the
training configurations of notebook 02 and the views' digest (depth included), which the
device run records in each checkpoint. Used on 2026-11-26 for the shipped ``strong`` network
(docs/confirm.md). Usage::

    python scripts/device_training/pack_views.py DATA_ROOT OUT_DIR   # e.g. data/full .devcarry
"""
import json
import lzma
import sys
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from semmatch.experiments.pipeline import notebook_parameters  # noqa: E402
from semmatch.segment.training import build_views, pipeline_configs, views_digest  # noqa: E402


def main(data_root: Path, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    p = notebook_parameters("02_train_segmentation", "full", data_root=str(data_root))
    cfgs = pipeline_configs(
        ["compact", "strong"], train_profile=p["train_profile"], seed=p["seed"], kinds=p["kinds"],
        train_seeds=p["train_seeds"], val_seeds=p["val_seeds"], eval_seeds=p["eval_seeds"], width=p["width"],
        height=p["height"], steps=p["steps"], out_dir=data_root / "models_gpu", cache_dir=data_root / "cache" / "segment")
    conf = {k: asdict(replace(c, threads=0, progress=False, device="cuda")) for k, c in cfgs.items()}
    tr, va = build_views(cfgs["strong"])
    if views_digest(tr, va) != views_digest(*build_views(cfgs["compact"])):
        raise SystemExit("compact and strong do not share their training views")
    meta = {"digest": views_digest(tr, va), "configs": conf,
            "train": {"shape": list(tr.rgb.shape)}, "val": {"shape": list(va.rgb.shape)}}
    for name, v in (("train", tr), ("val", va)):
        for k in ("rgb", "labels"):
            data = np.ascontiguousarray(getattr(v, k)).tobytes()
            (out / f"{name}_{k}.xz").write_bytes(lzma.compress(data, preset=9 | lzma.PRESET_EXTREME))
        np.savez(out / f"{name}_meta.npz", scene=v.scene, height=v.height)
    (out / "meta.json").write_text(json.dumps(meta, default=str, indent=1))
    print("digest", meta["digest"], {k: c["steps"] for k, c in conf.items()})


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("data/full"),
         Path(sys.argv[2]) if len(sys.argv) > 2 else Path(".devcarry"))
