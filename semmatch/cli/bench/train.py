"""``semmatch bench train``: seconds per training step of the segmentation networks on this machine.

Training is most of the full profile's time (README "Benchmarks"), and 2-core machines of the
same kind differ up to two-fold in it; this is the speed reference printed beside a pipeline's
stage times, so that two runs' budgets can be compared.
"""

from __future__ import annotations

import argparse
import time

from semmatch.cli.common import add_alias, add_json, emit, number


def register(sub) -> None:
    """Add ``semmatch bench train``."""
    p = sub.add_parser("train", help="segmentation networks: seconds per training step (the machine's speed "
                                     "reference for pipeline budgets)")
    p.add_argument("--arch", nargs="*", default=["compact", "strong"],
                   help="architectures to time (default: compact strong)")
    p.add_argument("--recipe", choices=("smoke", "full"), default="full",
                   help="training recipe whose batch, crop and schedule are timed (semmatch train --recipe)")
    add_alias(p, "--profile", canonical="--recipe", dest="recipe", choices=("smoke", "full"))
    p.add_argument("--steps", type=number(int, lo=1), default=20, help="timed steps per network, after 3 warm-up steps")
    p.add_argument("--schedule", nargs="*", default=[], metavar="ARCH=STEPS",
                   help="steps to project the training time for, e.g. compact=2000 strong=1000 (the pipeline's "
                        "full profile) (default: the training recipe's steps)")
    p.add_argument("--threads", type=number(int, lo=1), help="torch threads (default: torch's choice)")
    add_json(p, "the timings")
    p.set_defaults(func=run)


def time_training_steps(arch: str, profile: str = "full", steps: int = 20, *, warmup: int = 3,
                        schedule: int | None = None, seed: int = 0) -> dict:
    """Time ``steps`` training steps of ``arch`` at ``profile``'s batch size, crop and zoom.

    The steps are those of :func:`semmatch.segment.training.train` (augmentation, class-weighted
    cross-entropy, AdamW with a one-cycle schedule, channels-last, deterministic algorithms) on
    random full-size views; speed does not depend on the pixels.

    Parameters
    ----------
    arch : str
        Architecture (:data:`semmatch.segment.models.ARCHITECTURES`).
    profile : str
        Training profile (:data:`semmatch.segment.training.PROFILES`).
    steps : int
        Timed steps (>= 1), after ``warmup`` untimed ones.
    warmup : int
    schedule : int, optional
        Steps to project the training time for (default: the profile's).
    seed : int

    Returns
    -------
    dict
        ``seconds_per_step``, ``batch_size``, ``crop`` ("WxH"), ``schedule_steps`` and
        ``projected_minutes`` (those steps at this speed, validation passes excluded).

    Raises
    ------
    ValueError
        ``steps`` < 1, unknown architecture or profile.
    """
    import torch

    from semmatch.segment.training import make_config

    if int(steps) < 1 or int(warmup) < 0:
        raise ValueError(f"need steps >= 1 and warmup >= 0, got {steps}, {warmup}")
    cfg = make_config(profile, arch=arch)
    # training's settings, restored afterwards (the benchmark leaves the process as it found it)
    was = torch.are_deterministic_algorithms_enabled(), torch.utils.deterministic.fill_uninitialized_memory
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True)
    torch.utils.deterministic.fill_uninitialized_memory = False
    try:
        per_step = _timed_steps(cfg, arch, int(steps), int(warmup), seed)
    finally:
        torch.use_deterministic_algorithms(was[0])
        torch.utils.deterministic.fill_uninitialized_memory = was[1]
    planned = int(schedule if schedule is not None else cfg.steps)
    return {"seconds_per_step": round(per_step, 4), "batch_size": int(cfg.batch_size),
            "crop": f"{cfg.crop_size[0]}x{cfg.crop_size[1]}", "schedule_steps": planned,
            "projected_minutes": round(per_step * planned / 60.0, 1)}


def _timed_steps(cfg, arch: str, steps: int, warmup: int, seed: int) -> float:
    """Seconds per step of ``steps`` training steps after ``warmup`` untimed ones."""
    import numpy as np
    import torch

    from semmatch.io.labels import NUM_CLASSES
    from semmatch.segment.models import build_network
    from semmatch.segment.training import augment, make_optimiser, optimisation_step

    net = build_network(cfg.model_config()).to(memory_format=torch.channels_last)
    total = steps + warmup
    opt, sched = make_optimiser(net, cfg.lr, cfg.weight_decay, total)
    weights = torch.ones(NUM_CLASSES, dtype=torch.float32)
    rng = np.random.default_rng(seed)
    n = 2 * cfg.batch_size
    rgb = rng.integers(0, 256, (n, cfg.height, cfg.width, 3), dtype=np.uint8)
    depth = rng.uniform(0.5, 5.0, (n, cfg.height, cfg.width)).astype(np.float32)
    labels = rng.integers(0, NUM_CLASSES, (n, cfg.height, cfg.width), dtype=np.uint8)
    net.train()
    t0 = 0.0
    for step in range(total):
        if step == warmup:
            t0 = time.perf_counter()
        idx = np.sort(rng.choice(n, cfg.batch_size, replace=False))
        x, y = augment(rgb[idx], depth[idx], labels[idx], rng, crop=cfg.crop_size, zoom=cfg.zoom,
                       jitter=cfg.jitter, base_zoom=cfg.width / cfg.net_size[0], use_depth=cfg.use_depth)
        optimisation_step(net, x.contiguous(memory_format=torch.channels_last), y, weights, opt, sched,
                          what=f"benchmark loss ({arch})")
    return (time.perf_counter() - t0) / steps


def parse_schedule(items: list[str]) -> dict[str, int]:
    """``["compact=4000", ...]`` as ``{"compact": 4000}``; a malformed item is a clear error."""
    out = {}
    for item in items:
        arch, sep, n = item.partition("=")
        if not sep or not n.strip().isdigit() or int(n) < 1:
            raise ValueError(f"--schedule {item!r}: expected ARCH=STEPS with STEPS a positive integer")
        out[arch.strip()] = int(n)
    return out


def run(args: argparse.Namespace) -> int:
    """Time every architecture and print a table or JSON."""
    import torch

    if args.threads:
        torch.set_num_threads(args.threads)
    schedule = parse_schedule(args.schedule)
    unknown = set(schedule) - set(args.arch)
    if unknown:
        raise ValueError(f"--schedule names {', '.join(sorted(unknown))}, not timed (--arch {' '.join(args.arch)})")
    result = {"networks": {a: time_training_steps(a, args.recipe, args.steps, schedule=schedule.get(a))
                           for a in args.arch},
              "threads": torch.get_num_threads(), "recipe": args.recipe, "steps": args.steps}
    rows = [f"{a:<10} {r['crop']:>8} {r['batch_size']:>6} {r['seconds_per_step']:>8.3f} "
            f"{r['schedule_steps']:>6} {r['projected_minutes']:>9.1f}" for a, r in result["networks"].items()]
    table = "\n".join([f"{'network':<10} {'crop':>8} {'batch':>6} {'s/step':>8} {'steps':>6} {'minutes':>9}", *rows,
                       f"(torch threads: {result['threads']}; minutes: the steps at this speed, validation passes "
                       f"excluded)"])
    return emit(result, args.json, table)
