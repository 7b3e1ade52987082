"""``semmatch adapt --model NET.pt --source METHOD --out ADAPTED.pt``: fine-tune to the robot's view."""

from __future__ import annotations

import argparse


def register(sub) -> None:
    """Add ``semmatch adapt``."""
    from semmatch.adapt import LABEL_SOURCES
    from semmatch.cli import add_quiet
    from semmatch.io.outputs import declare_paths

    p = sub.add_parser(
        "adapt",
        help="fine-tune a segmentation network to the robot's viewpoint with transferred labels",
        description="On training scenes, the person and the robot tour each room; the network builds "
        "the person's map, its labels are transferred into the robot's frames (or another label "
        "source) and the network is fine-tuned on them, half of each batch staying human-height views.",
    )
    p.add_argument("--model", required=True, help="checkpoint of the network to adapt (.pt)")
    p.add_argument("--source", required=True, choices=list(LABEL_SOURCES),
                   help="labels of the robot's frames: a transfer method, fused, self-training or ground-truth")
    p.add_argument("--out", required=True, help="adapted checkpoint to write (.pt)")
    p.add_argument("--kinds", nargs="+", default=["living_room", "bedroom", "office", "apartment"],
                   help="scene kinds (scene i has kind i mod len(kinds))")
    p.add_argument("--seeds", nargs="+", type=int, required=True,
                   help="training scenes to adapt on (never the network's validation/evaluation seeds)")
    p.add_argument("--frames", type=int, default=40, help="frames of each camera's tour (default %(default)s)")
    p.add_argument("--steps", type=int, default=400, help="fine-tuning steps (default %(default)s)")
    p.add_argument("--batch-size", type=int, default=16, help="default %(default)s")
    p.add_argument("--lr", type=float, default=1e-3, help="peak learning rate (default %(default)s)")
    p.add_argument("--upper-share", type=float, default=0.5,
                   help="share of each batch from human-height training views (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="default %(default)s")
    add_quiet(p)
    declare_paths(p, inputs=("model",), outputs=("out",))
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Prepare the robot's labelled frames and fine-tune."""
    from pathlib import Path

    from semmatch.adapt import fine_tune, robot_training_views

    if Path(args.out).resolve() == Path(args.model).resolve():
        raise ValueError(f"--out {args.out}: refusing to overwrite the network being adapted")
    robot = robot_training_views(args.model, kinds=args.kinds, seeds=args.seeds, sources=[args.source],
                                 n_frames=args.frames, seed=args.seed, progress=not args.quiet)
    out = fine_tune(args.model, robot, args.source, args.out, steps=args.steps, batch_size=args.batch_size,
                    lr=args.lr, upper_share=args.upper_share, seed=args.seed, progress=not args.quiet)
    print(f"{out}: {args.model} adapted with {args.source} labels on {len(robot.views)} robot frames "
          f"({robot.coverage[args.source]:.0%} of their pixels labelled)")
    return 0
