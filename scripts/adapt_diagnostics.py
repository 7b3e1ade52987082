"""Validation-only diagnostics of the robot-view adaptation recipe (docs/adapt.md).

Run ``python scripts/adapt_diagnostics.py OUT --which steps [--profile full]`` after the
profile's stages 01-02 (trained networks, validation sweeps at 0.2 m and 1.6 m). Each variant
fine-tunes a network on the robot's frames of the profile's adaptation (training) scenes, as
notebook 09 does, with the variant's recipe, and scores the adapted and the unadapted network on
the **validation** sweeps only (paired per-scene mIoU differences, 95 % intervals:
``semmatch.experiments.adapt.gap_table``). Checkpoints and ``<variant>_<network>.csv`` go to
``OUT``; nothing under the profile's data root is written. Variants (docs/adapt.md, 2026-11-25):

- ``steps``: compact, 400 vs 1600 steps, ground-truth and ``3d-neighborhood`` labels;
- ``strong``: the strong network, 400 steps, ground-truth and ``3d-neighborhood`` labels;
- ``bn-frozen``: compact with batch-norm statistics frozen during fine-tuning;
- ``strong-lr``: the strong network at a smaller learning rate;
- ``distill``: compact with a per-pixel KL term to the unadapted network (weight 1) on the
  human-height part of each batch (``fine_tune(distill=1.0)``);
- ``scenes``: compact, the chosen recipe, ground-truth and ``3d-neighborhood`` labels of the
  profile's adaptation scenes (8 in the full profile) against three times as many training
  scenes (is the amount of robot data the limit?);
- ``robot-only``: compact, every batch from the robot's frames (``upper_share`` 0: no guard
  against forgetting), ground-truth and ``3d-neighborhood`` labels: how much of the gap at 0.2 m
  fine-tuning alone can close (the robot-height expert of a height-routed pair);
- ``long``: compact, the most a 10-minute adaptation allows here: 1600 steps at the network's
  own training learning rate (4e-3), half of each batch human-height, the robot's frames of three
  times the profile's adaptation scenes; ground-truth and ``3d-neighborhood`` labels;
- ``long-short``: as ``long`` with ``3d-neighborhood`` labels, 400 and 800 steps (what fits the
  pipeline's budget?);
- ``lr``: the pipeline's 400 steps and 8 scenes at the network's own learning rate (4e-3),
  half or a quarter of each batch from the robot;
- ``scratch``: no adaptation: the compact network trained from scratch with its own training
  config (steps, scenes, frames per scene) on views at robot heights (0.1-0.3 m) and at every
  height (0.1-1.8 m) instead of human heights (1.2-1.8 m). What a compact network of this
  budget reaches at 0.2 m when it sees only the robot's view, with ground truth throughout:
  the ceiling of any adaptation of it.

Frozen batch-norm statistics are not an option of :func:`semmatch.segment.adapt.fine_tune`: for that
variant this script swaps the optimisation step it uses for the length of one run.
"""

from __future__ import annotations

import argparse
import contextlib
import time
from pathlib import Path

#: variant -> runs: (network, label source, steps, lr, upper_share, mode[, adaptation scenes as a
#: multiple of the profile's adapt_scenes])
VARIANTS = {
    "steps": [("compact", "ground-truth", 400, 3e-4, 0.75, "plain"),
              ("compact", "ground-truth", 1600, 3e-4, 0.75, "plain"),
              ("compact", "3d-neighborhood", 1600, 3e-4, 0.75, "plain")],
    "strong": [("strong", "ground-truth", 400, 3e-4, 0.75, "plain"),
               ("strong", "3d-neighborhood", 400, 3e-4, 0.75, "plain")],
    "bn-frozen": [("compact", "3d-neighborhood", 400, 1e-3, 0.5, "bn-frozen"),
                  ("compact", "3d-neighborhood", 400, 3e-4, 0.75, "bn-frozen")],
    "strong-lr": [("strong", "3d-neighborhood", 400, 1e-4, 0.75, "plain")],
    "distill": [("compact", "3d-neighborhood", 400, 1e-3, 0.5, "distill"),
                ("compact", "3d-neighborhood", 400, 3e-4, 0.75, "distill")],
    "robot-only": [("compact", "ground-truth", 400, 1e-3, 0.0, "plain"),
                   ("compact", "3d-neighborhood", 400, 1e-3, 0.0, "plain"),
                   ("compact", "3d-neighborhood", 400, 3e-4, 0.0, "plain")],
    "long": [("compact", "ground-truth", 1600, 4e-3, 0.5, "plain", 3),
             ("compact", "3d-neighborhood", 1600, 4e-3, 0.5, "plain", 3)],
    "long-short": [("compact", "3d-neighborhood", 400, 4e-3, 0.5, "plain", 3),
                   ("compact", "3d-neighborhood", 800, 4e-3, 0.5, "plain", 3)],
    "lr": [("compact", "3d-neighborhood", 400, 4e-3, 0.5, "plain"),
           ("compact", "3d-neighborhood", 400, 4e-3, 0.75, "plain")],
    "scenes": [("compact", "ground-truth", 400, 3e-4, 0.75, "plain", 1),
               ("compact", "3d-neighborhood", 400, 3e-4, 0.75, "plain", 1),
               ("compact", "ground-truth", 400, 3e-4, 0.75, "plain", 3),
               ("compact", "3d-neighborhood", 400, 3e-4, 0.75, "plain", 3)],
}

#: ``scratch`` variant: run name -> camera height range of the training views (m)
SCRATCH = {"scratch-robot-heights": (0.1, 0.3), "scratch-all-heights": (0.1, 1.8)}


def train_from_scratch(checkpoint: Path, heights: tuple[float, float], out: Path) -> Path:
    """Train ``checkpoint``'s architecture anew with its training config, views at ``heights``.

    The views are rendered into ``out.parent / "cache"`` (not the profile's cache); the training
    scenes, frames, steps and seeds are the checkpoint's.
    """
    from semmatch.segment.models import read_checkpoint
    from semmatch.segment.training import TrainConfig, train

    rec = dict(read_checkpoint(checkpoint)["train_config"])  # weights only: data, never code
    known = set(TrainConfig.__dataclass_fields__)
    cfg = TrainConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in rec.items() if k in known})
    cfg.heights, cfg.out, cfg.cache_dir, cfg.progress = tuple(heights), str(out), str(out.parent / "cache"), False
    return train(cfg)


@contextlib.contextmanager
def recipe_mode(mode: str):
    """Swap ``semmatch.segment.training.optimisation_step`` (used by ``fine_tune``) for ``mode``."""
    import torch

    import semmatch.segment.training as training

    original = training.optimisation_step

    def bn_frozen(net, *args, **kwargs):
        for m in net.modules():
            if isinstance(m, torch.nn.modules.batchnorm._BatchNorm):
                m.eval()
        return original(net, *args, **kwargs)

    training.optimisation_step = {"plain": original, "distill": original, "bn-frozen": bn_frozen}[mode]
    try:
        yield
    finally:
        training.optimisation_step = original


def main() -> None:
    from semmatch.experiments.adapt import gap_table, robot_views, score_on_sweeps, validation_gap_sweeps
    from semmatch.experiments.layout import Layout
    from semmatch.experiments.pipeline import notebook_parameters
    from semmatch.segment.adapt import fine_tune

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="folder for the checkpoints and tables")
    ap.add_argument("--which", choices=sorted([*VARIANTS, "scratch"]), required=True)
    ap.add_argument("--profile", default=None, help="profile of params.yaml (default: its 'profile')")
    ap.add_argument("--max-steps", type=int, help="cap every run's steps (a quick check, not the documented runs)")
    args = ap.parse_args()

    p = notebook_parameters("09_adapt_robot_view", args.profile)
    root = p["data_root"]
    layout = Layout(root)
    heights = validation_gap_sweeps(root, 0.2, 1.6)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.which == "scratch":
        ckpts = {}
        for name, hs in SCRATCH.items():
            t0 = time.time()
            ckpts[name] = train_from_scratch(layout.model("compact"), hs, args.out / f"{name}.pt")
            print(f"trained {name} ({hs[0]:g}-{hs[1]:g} m): {time.time() - t0:.0f} s", flush=True)
        per_scene = score_on_sweeps(root, "compact", ckpts, heights, jobs=p["jobs"], progress=False)
        table = gap_table(per_scene, "compact", low=0.2, high=1.6).drop(columns=["source"])
        table.to_csv(args.out / "scratch_compact.csv", index=False)
        print(table.round(3).to_string(), flush=True)
        return
    runs = [(*r, 1)[:7] for r in VARIANTS[args.which]]  # the profile's adaptation scenes unless a multiple is given
    need = p["adapt_scenes"] * max(r[6] for r in runs)
    if need > len(p["train_seeds"]):
        raise ValueError(f"{args.which}: needs {need} training scenes, the profile has {len(p['train_seeds'])}")
    for network in dict.fromkeys(r[0] for r in runs):
        ckpts = {}
        for mult in dict.fromkeys(r[6] for r in runs if r[0] == network):
            mine = [r for r in runs if r[0] == network and r[6] == mult]
            seeds = p["train_seeds"][:p["adapt_scenes"] * mult]
            t0 = time.time()
            robot, _ = robot_views(root, network, sorted({r[1] for r in mine}), kinds=p["kinds"], seeds=seeds,
                                   n_frames=p["n_frames"], voxel_size=p["voxel_size"], fused_base=p["fused_base"],
                                   seed=p["seed"], progress=False)
            print(f"{network}: robot views of {len(robot.scenes)} scenes {time.time() - t0:.0f} s", flush=True)
            for _, source, steps, lr, share, mode, _ in mine:
                steps = min(steps, args.max_steps or steps)
                name = f"{network}_{source}_{steps}_lr{lr:g}_s{share:g}_{mode}" + (f"_{len(robot.scenes)}scenes"
                                                                                   if mult != 1 else "")
                t0 = time.time()
                with recipe_mode(mode):
                    ckpts[name] = fine_tune(layout.model(network), robot, source, args.out / f"{name}.pt",
                                            steps=steps, batch_size=p["batch_size"], lr=lr, upper_share=share,
                                            distill=1.0 if mode == "distill" else 0.0, seed=p["seed"],
                                            progress=False)
                print(f"fine-tuned {name}: {time.time() - t0:.0f} s", flush=True)
        per_scene = score_on_sweeps(root, network, ckpts, heights, jobs=p["jobs"], progress=False)
        table = gap_table(per_scene, network, low=0.2, high=1.6).drop(columns=["source"])
        table.to_csv(args.out / f"{args.which}_{network}.csv", index=False)
        print(table.round(3).to_string(), flush=True)


if __name__ == "__main__":
    main()
