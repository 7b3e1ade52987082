"""``semmatch train``: train a segmentation network on simulated human-height views."""

from __future__ import annotations

import argparse


def register(sub) -> None:
    """Add ``semmatch train``."""
    from semmatch.cli import add_quiet
    from semmatch.io.outputs import declare_paths

    p = sub.add_parser(
        "train",
        help="train a segmentation network (compact | strong) on simulated upper views",
        description="Train a segmentation network on upper views (camera 1.2-1.8 m, tilting) of "
        "training scenes; validate on held-out scenes; write a checkpoint.",
    )
    p.add_argument("--profile", choices=("smoke", "full"), default="smoke", help="size of the run (default smoke)")
    p.add_argument("--arch", choices=("compact", "strong"), default="compact", help="network architecture (default %(default)s)")
    p.add_argument("--out", required=True, help="checkpoint path (.pt)")
    p.add_argument("--depth", action="store_true", help="add the depth channel to the input")
    p.add_argument("--steps", type=int, help="optimisation steps (profile default otherwise)")
    p.add_argument("--batch-size", type=int, help="views per step (profile default otherwise)")
    p.add_argument("--lr", type=float, help="peak learning rate (profile default otherwise)")
    p.add_argument("--eval-every", type=int, help="validate every N steps")
    p.add_argument("--width", type=int, help="render width of the views (profile default otherwise)")
    p.add_argument("--height", type=int, help="render height of the views")
    p.add_argument("--net-width", type=int, help="network input width (default: the profile's, else --width); "
                   "smaller than the views = whole frames at reduced scale")
    p.add_argument("--net-height", type=int, help="network input height")
    p.add_argument("--zoom", nargs=2, type=float, metavar=("LO", "HI"),
                   help="scale augmentation range; must hold width / net-width (profile default otherwise)")
    p.add_argument("--kinds", nargs="+", help="scene kinds")
    p.add_argument("--train-seeds", nargs="+", type=int, help="training scene seeds")
    p.add_argument("--val-seeds", nargs="+", type=int, help="validation scene seeds")
    p.add_argument("--eval-seeds", nargs="+", type=int, help="evaluation scene seeds (checked to be disjoint)")
    p.add_argument("--seed", type=int, default=0, help="seed of the views, the weights and the batches (default 0)")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto", help="auto: CUDA when present (default %(default)s)")
    p.add_argument("--threads", type=int, help="torch threads")
    p.add_argument("--cache-dir", help="cache rendered views here")
    p.add_argument("--jobs", type=int, default=1, help="scenes rendered in parallel (local worker processes; default 1)")
    p.add_argument("--scheduler", default=None,
                   help="Dask scheduler address (tcp://host:8786) to render the views on; default "
                        "SEMMATCH_SCHEDULER, else --jobs local processes")
    add_quiet(p)
    declare_paths(p, outputs=("out",))  # no file inputs (the views are rendered; --cache-dir is read and written)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Train and print the checkpoint path and validation scores."""
    from semmatch.segment.training import build_views, make_config, train

    for flag in ("lr", "steps", "batch_size", "eval_every", "width", "height", "jobs"):
        v = getattr(args, flag, None)
        if v is not None and v <= 0:
            raise ValueError(f"--{flag.replace('_', '-')} must be > 0, got {v}")
    for a, b in (("width", "height"), ("net_width", "net_height")):
        if bool(getattr(args, a)) != bool(getattr(args, b)):
            raise ValueError(f"give both --{a.replace('_', '-')} and --{b.replace('_', '-')}")
    cfg = make_config(
        args.profile, out=args.out, arch=args.arch, use_depth=args.depth or None, steps=args.steps,
        batch_size=args.batch_size, lr=args.lr, eval_every=args.eval_every, width=args.width, height=args.height,
        net_width=args.net_width, net_height=args.net_height, zoom=args.zoom, kinds=args.kinds,
        train_seeds=args.train_seeds, val_seeds=args.val_seeds, eval_seeds=args.eval_seeds, seed=args.seed,
        device=args.device, threads=args.threads, cache_dir=args.cache_dir, progress=not args.quiet,
    )
    path = train(cfg, views=build_views(cfg, jobs=args.jobs, scheduler=args.scheduler))
    from semmatch.segment import load_model

    m = load_model(path).info
    met = m["metrics"]
    print(f"{path}: {cfg.arch} ({m['n_parameters']} parameters), best at step {met['step']}: "
          f"val mIoU(1..10) {met['miou']:.3f}, pixel acc {met['pixel_acc']:.3f}, "
          f"{m['train_seconds']:.0f} s on {m['device']}")
    return 0
