"""``semmatch train``: train a segmentation network on simulated human-height views."""

from __future__ import annotations

import argparse


def register(sub) -> None:
    """Add ``semmatch train``."""
    from semmatch.cli.common import add_alias, add_image_size, add_output_flags, add_scene_kinds, number
    from semmatch.io.outputs import declare_paths

    p = sub.add_parser(
        "train",
        help="train a segmentation network (compact | strong) on simulated upper views",
        description="Train a segmentation network on upper views (camera 1.2-1.8 m, tilting) of "
        "training scenes; validate on held-out scenes; write a checkpoint.",
    )
    p.add_argument("--recipe", choices=("smoke", "full"), default="smoke",
                   help="training recipe: the size of the run (semmatch.segment.PROFILES; not a params.yaml profile)")
    add_alias(p, "--profile", canonical="--recipe", dest="recipe", choices=("smoke", "full"))
    p.add_argument("--arch", choices=("compact", "strong"), default="compact", help="network architecture")
    p.add_argument("--out", required=True, help="checkpoint path (.pt)")
    p.add_argument("--depth", action="store_true", help="add the depth channel to the input")
    p.add_argument("--steps", type=number(int, lo=1), help="optimisation steps (default: the recipe's)")
    p.add_argument("--batch-size", type=number(int, lo=1), help="views per step (default: the recipe's)")
    p.add_argument("--lr", type=number(float, lo=0.0, lo_open=True), help="peak learning rate (default: the recipe's)")
    p.add_argument("--eval-every", type=number(int, lo=1), help="validate every N steps (default: the recipe's)")
    add_image_size(p, help="render size of the views (default: the recipe's)", old_split=("--width", "--height"))
    add_image_size(p, flag="--net-size", dest="net_size", old_split=("--net-width", "--net-height"),
                   help="network input size; smaller than the views = whole frames at reduced scale (default: the "
                        "recipe's, else --image-size)")
    p.add_argument("--zoom", nargs=2, type=number(float, lo=0.0, lo_open=True), metavar=("LO", "HI"),
                   help="scale augmentation range; must hold view width / network width (default: the recipe's)")
    add_scene_kinds(p, default=None, nargs="+", help="scene kinds")
    p.add_argument("--train-seeds", nargs="+", type=number(int, lo=0), help="training scene seeds")
    p.add_argument("--val-seeds", nargs="+", type=number(int, lo=0), help="validation scene seeds")
    p.add_argument("--eval-seeds", nargs="+", type=number(int, lo=0), help="evaluation scene seeds (checked to be disjoint)")
    p.add_argument("--seed", type=number(int, lo=0), default=0, help="seed of the views, the weights and the batches")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto", help="auto: CUDA when present")
    p.add_argument("--threads", type=number(int, lo=1), help="torch threads (default: left as the command set them, semmatch.runtime.threads)")
    p.add_argument("--cache-dir", help="cache rendered views here")
    p.add_argument("--jobs", type=number(int, lo=1), default=1, help="scenes rendered in parallel (local worker processes)")
    p.add_argument("--scheduler", default=None,
                   help="Dask scheduler address (tcp://host:8786) to render the views on (default: "
                        "SEMMATCH_SCHEDULER, else --jobs local processes)")
    add_output_flags(p, json_what="the checkpoint and its validation scores", quiet="the progress bars")
    declare_paths(p, outputs=("out",))  # no file inputs (the views are rendered; --cache-dir is read and written)
    p.set_defaults(func=run)


def _check_sizes(args: argparse.Namespace) -> None:
    """Refuse a size given by half (an old ``--width`` without ``--height``, ...)."""
    for size, flag, half in ((args.image_size, "--image-size", ("--width", "--height")),
                             (args.net_size, "--net-size", ("--net-width", "--net-height"))):
        if size is not None and None in size:
            raise ValueError(f"give both {half[0]} and {half[1]} (better: {flag} WxH)")


def run(args: argparse.Namespace) -> int:
    """Train and print the checkpoint path and validation scores."""
    from semmatch.cli.common import emit
    from semmatch.segment.training import build_views, make_config, train

    for flag in ("lr", "steps", "batch_size", "eval_every", "jobs"):
        v = getattr(args, flag, None)
        if v is not None and v <= 0:
            raise ValueError(f"--{flag.replace('_', '-')} must be > 0, got {v}")
    _check_sizes(args)
    width, height = args.image_size or (None, None)
    net_width, net_height = args.net_size or (None, None)
    cfg = make_config(
        args.recipe, out=args.out, arch=args.arch, use_depth=args.depth or None, steps=args.steps,
        batch_size=args.batch_size, lr=args.lr, eval_every=args.eval_every, width=width, height=height,
        net_width=net_width, net_height=net_height, zoom=args.zoom, kinds=args.scene_kinds,
        train_seeds=args.train_seeds, val_seeds=args.val_seeds, eval_seeds=args.eval_seeds, seed=args.seed,
        device=args.device, threads=args.threads, cache_dir=args.cache_dir, progress=not args.quiet,
    )
    path = train(cfg, views=build_views(cfg, jobs=args.jobs, scheduler=args.scheduler))
    from semmatch.segment import load_model

    m = load_model(path).info
    met = m["metrics"]
    result = {"checkpoint": str(path), "arch": cfg.arch, "n_parameters": m["n_parameters"], "metrics": met,
              "train_seconds": m["train_seconds"], "device": m["device"]}
    return emit(result, args.json,
                f"{path}: {cfg.arch} ({m['n_parameters']} parameters), best at step {met['step']}: "
                f"val mIoU(1..10) {met['miou']:.3f}, pixel acc {met['pixel_acc']:.3f}, "
                f"{m['train_seconds']:.0f} s on {m['device']}")
