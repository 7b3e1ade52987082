"""``semmatch adapt``: fine-tune a segmentation network to the robot's view.

Two modes::

    semmatch adapt --model NET.pt --source METHOD --seeds S [S ...] --out ADAPTED.pt   # training scenes
    semmatch adapt --home LOWER_SEQ --map PERSON_MAP --model NET.pt --out ADAPTED.pt    # in a home
"""

from __future__ import annotations

import argparse

_EPILOG = """\
modes (--home selects the second):
  training scenes  --model --source --seeds [--scene-kinds --frames]
                   the person and the robot tour rendered training scenes of the network; the
                   network's map of each is transferred into the robot's frames.
  in a home        --home LOWER_SEQ --map PERSON_MAP --model [--source --frames --frame-step
                   --views-cache]
                   the robot's recorded tour LOWER_SEQ (RGB, depth, poses in the map's frame) is
                   labelled from the person's map of the same home PERSON_MAP (default source
                   3d-neighborhood); --frames N uses the first N frames (after --frame-step),
                   --frames START:STOP that range of the recording. LOWER_SEQ may be any
                   recording layout (TUM RGB-D, 7-Scenes, plain folder ...; --intrinsics,
                   --estimate-poses and the bag topics as for every verb that reads one).
                   Refused: --seeds/--scene-kinds, a sequence without depth, a map without labels, a
                   map naming another scene than the sequence, labels covering too little of the
                   robot's view.
both: --out, --steps, --batch-size, --lr, --upper-share, --seed; --out must not be an input.
"""


def register(sub) -> None:
    """Add ``semmatch adapt``."""
    from semmatch.cli.common import (
        RawDescriptionHelpFormatter,
        add_output_flags,
        add_recording_options,
        add_scene_kinds,
        number,
    )
    from semmatch.io.outputs import declare_paths
    from semmatch.segment.adapt import HOME_SOURCES, LABEL_SOURCES, AdaptRecipe

    p = sub.add_parser(
        "adapt",
        help="fine-tune a segmentation network to the robot's viewpoint with transferred labels",
        description="Fine-tune a network on the robot's frames labelled from the person's semantic map,\n"
        "half of each batch staying the network's human-height training views. Either on rendered\n"
        "training scenes (--seeds) or in one home the person has mapped (--home LOWER_SEQ --map PERSON_MAP).",
        epilog=_EPILOG,
        formatter_class=RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", required=True, help="checkpoint of the network to adapt (.pt)")
    p.add_argument("--source", default=None, choices=list(LABEL_SOURCES), metavar="SOURCE",
                   help=f"labels of the robot's frames: training scenes (required): one of {', '.join(LABEL_SOURCES)}; "
                        f"in a home: one of {', '.join(HOME_SOURCES)} (default: 3d-neighborhood)")
    p.add_argument("--out", required=True, help="adapted checkpoint to write (.pt)")
    home = p.add_argument_group("in a home")
    home.add_argument("--home", default=None, metavar="LOWER_SEQ",
                      help="the robot's sequence folder of the home (selects this mode)")
    home.add_argument("--map", default=None, metavar="PERSON_MAP", help="the person's semantic map of the home (PLY)")
    home.add_argument("--frame-step", type=number(int, lo=1), default=1,
                      help="use every N-th frame of LOWER_SEQ")
    train = p.add_argument_group("training scenes")
    add_scene_kinds(train, default=None, nargs="+",
                    help="scene kinds; scene i has kind i mod len(kinds) (default: living_room bedroom office "
                         "apartment)")
    train.add_argument("--seeds", nargs="+", type=number(int, lo=0), default=None,
                       help="training scenes to adapt on (never the network's validation/evaluation seeds)")
    p.add_argument("--frames", type=_count_or_range, default=None, metavar="N|START:STOP",
                   help="training scenes: frames of each camera's tour (40 when not given); in a home: use at most N "
                        "frames of LOWER_SEQ, or its frames START..STOP-1 (all when not given)")
    p.add_argument("--steps", type=number(int, lo=1), default=AdaptRecipe.steps,
                   help="fine-tuning steps")
    p.add_argument("--batch-size", type=number(int, lo=2), default=AdaptRecipe.batch_size, help="views per step")
    p.add_argument("--lr", type=number(float, lo=0.0, lo_open=True), default=AdaptRecipe.lr,
                   help="peak learning rate")
    p.add_argument("--upper-share", type=number(float, lo=0.0, hi=1.0), default=AdaptRecipe.upper_share,
                   help="share of each batch from human-height training views")
    p.add_argument("--seed", type=number(int, lo=0), default=AdaptRecipe.seed, help="seed of the batches")
    home.add_argument("--views-cache", default=None, metavar="DIR",
                      help="cache of the network's human-height training views (rendered on the first run, "
                           "minutes) (default: the folder recorded in the checkpoint where it exists on this "
                           "machine, else none: rendered each run)")
    add_recording_options(home, frames=False)
    add_output_flags(p, json_what="the adapted checkpoint and its data", quiet="the progress bars")
    declare_paths(p, inputs=("model", "home", "map", "intrinsics"), outputs=("out", "views_cache"))
    p.set_defaults(func=run)


def _count_or_range(text: str) -> int | slice:
    """``--frames``: a count N (>= 1), or in a home a frame range ``START:STOP`` of the recording."""
    from semmatch.cli.common import frame_range, number

    return frame_range(text) if ":" in text else number(int, lo=1)(text)


_count_or_range.__name__ = "N or START:STOP"  # argparse names the type in its messages


def _check_mode(args: argparse.Namespace) -> None:
    """Refuse arguments of one mode given in the other."""
    if args.home is not None:
        mixed = [f for f, v in (("--seeds", args.seeds), ("--scene-kinds", args.scene_kinds)) if v is not None]
        if mixed:
            raise ValueError(f"{' and '.join(mixed)}: training-scene options cannot be mixed with --home (in a home "
                             "the robot's own tour is the adaptation data)")
        if args.map is None:
            raise ValueError("--home needs --map PERSON_MAP (the person's semantic map of that home)")
        return
    if args.views_cache is not None:
        raise ValueError("--views-cache is for --home LOWER_SEQ (on training scenes the checkpoint's cache is used)")
    if isinstance(args.frames, slice):
        raise ValueError("--frames START:STOP is a range of the recording --home LOWER_SEQ; on training scenes give "
                         "--frames N (frames of each camera's tour)")
    if args.map is not None:
        raise ValueError("--map is the person's map of a home: give it with --home LOWER_SEQ")
    if args.frame_step != 1:
        raise ValueError("--frame-step is for --home LOWER_SEQ")
    missing = [f for f, v in (("--source", args.source), ("--seeds", args.seeds)) if v is None]
    if missing:
        raise ValueError(f"adapting on training scenes needs {' and '.join(missing)} (or adapt in a home with "
                         "--home LOWER_SEQ --map PERSON_MAP)")


def run(args: argparse.Namespace) -> int:
    """Prepare the robot's labelled frames and fine-tune."""
    from pathlib import Path

    from semmatch.cli.common import emit
    from semmatch.segment.adapt import fine_tune, robot_training_views

    _check_mode(args)
    if Path(args.out).resolve() == Path(args.model).resolve():
        raise ValueError(f"--out {args.out}: refusing to overwrite the network being adapted")
    if args.home is not None:
        return _run_home(args)
    kinds = args.scene_kinds or ["living_room", "bedroom", "office", "apartment"]
    robot = robot_training_views(args.model, kinds=kinds, seeds=args.seeds, sources=[args.source],
                                 n_frames=args.frames or 40, seed=args.seed, progress=not args.quiet)
    out = fine_tune(args.model, robot, args.source, args.out, steps=args.steps, batch_size=args.batch_size,
                    lr=args.lr, upper_share=args.upper_share, seed=args.seed, progress=not args.quiet)
    result = {"out": str(out), "model": str(args.model), "source": args.source, "frames": len(robot.views),
              "label_coverage": robot.coverage[args.source]}
    return emit(result, args.json, f"{out}: {args.model} adapted with {args.source} labels on {len(robot.views)} "
                f"robot frames ({robot.coverage[args.source]:.0%} of their pixels labelled)")


def _run_home(args: argparse.Namespace) -> int:
    import torch

    from semmatch.cli.common import emit, open_sequence
    from semmatch.segment.adapt import adapt_in_home
    from semmatch.segment.adapt.views import check_home_depth

    source = args.source or "3d-neighborhood"
    check_home_depth(args.home)
    recording = open_sequence(args, args.home, needs_poses=True)
    out = adapt_in_home(args.model, args.home, args.map, args.out, source=source, recording=recording,
                        frames=None if isinstance(args.frames, slice) else args.frames,
                        frame_step=args.frame_step, steps=args.steps, batch_size=args.batch_size, lr=args.lr,
                        upper_share=args.upper_share, seed=args.seed, progress=not args.quiet,
                        cache_dir=args.views_cache or "checkpoint-if-present")
    a = torch.load(out, map_location="cpu", weights_only=True)["adapted"]
    result = {"out": str(out), "model": str(args.model), "source": source, "map": str(args.map),
              "home": a["scenes"][0], "frames": a["frames"], "label_coverage": a["label_coverage"],
              "steps": a["steps"], "seconds": a["seconds"]}
    return emit(result, args.json, f"{out}: {args.model} adapted in {a['scenes'][0]} with {source} labels from "
                f"{args.map} on {a['frames']} robot frames ({a['label_coverage']:.0%} of their pixels with depth "
                f"labelled), {a['steps']} steps in {a['seconds']:.0f} s")
