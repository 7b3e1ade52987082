"""Support of a profile's robot frames in the person's map, without running the notebooks.

Simulates only the evaluation scenes of a profile (params.yaml), fuses the person's frames with
their ground-truth labels and transfers them onto the robot's frames with the profile's
``fused_base`` method: the numbers notebook 04 writes to ``support_per_scene.csv``
(semmatch.experiments.synthetic.support_table), for the robot's own tour and for the robot
replaying the person's route. Used to choose the smoke profile's scene and camera step:

    python scripts/smoke_support.py                                # the smoke profile as it is
    python scripts/smoke_support.py --camera-step 0.3 --seeds 9001 9002 --frames 8
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from tqdm import tqdm


def main(argv: list[str] | None = None) -> None:
    from semmatch.experiments.pipeline import ROOT, load_params

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default="smoke")
    ap.add_argument("--seeds", type=int, nargs="+", help="evaluation seeds (default: the profile's)")
    ap.add_argument("--camera-step", type=float, help="metres (default: the profile's simulate.camera_step)")
    ap.add_argument("--frames", type=int, help="frames of both tours (default: the profile's)")
    args = ap.parse_args(argv)

    from semmatch.fusion import reconstruct_many
    from semmatch.io import read_sequence
    from semmatch.io.geometry import DEFAULT_INTRINSICS
    from semmatch.sim import generate_dataset
    from semmatch.transfer import load_index, transfer_sequence

    p = load_params(ROOT / "params.yaml", args.profile)
    c, s = p["common"], p["simulate"]
    step = args.camera_step if args.camera_step is not None else s["camera_step"]
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        t = time.time()
        generate_dataset(root / "scenes", train_seeds=(), val_seeds=(), dev_seeds=(),
                         eval_seeds=args.seeds or c["eval_seeds"], kinds=c["kinds"],
                         n_frames_upper=args.frames or s["n_frames_upper"],
                         n_frames_lower=args.frames or s["n_frames_lower"], heights_sweep=None, noise=s["noise"],
                         intrinsics=DEFAULT_INTRINSICS.scaled(s["image_width"], s["image_height"]), progress=False,
                         routes=s["routes"], route_ablation=True, renderer=s["renderer"], camera_step=step)
        scenes = sorted((root / "scenes" / "eval").iterdir())
        for sd in tqdm(scenes, desc="support", unit="scene"):
            upper = read_sequence(sd / "upper").load()
            reconstruct_many(upper, [None], c["voxel_size"], outs=[root / f"{sd.name}.ply"])
            index = load_index(root / f"{sd.name}.ply")
            for route, folder in (("own", "lower"), ("shared", "lower_shared")):
                st = transfer_sequence(c["fused_base"], read_sequence(sd / folder).load(), index,
                                       root / sd.name / route, progress=False)
                tqdm.write(f"{sd.name} camera_step={step} route={route}: support {float(st['coverage']):.3f}")
        print(f"{len(scenes)} scene(s) in {time.time() - t:.0f} s")


if __name__ == "__main__":
    main()
