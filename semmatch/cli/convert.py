"""``semmatch convert RECORDING --out SEQ``: write any recording as a semmatch sequence folder."""

from __future__ import annotations

import argparse
import json


def register(sub) -> None:
    """Add ``semmatch convert``."""
    from semmatch.cli.common import add_output_flags, add_recording_options
    from semmatch.io.outputs import declare_paths

    p = sub.add_parser(
        "convert",
        help="write a recording (TUM RGB-D, 7-Scenes, plain folder, any registered layout) as a sequence folder",
        description="Read RECORDING through the reader registry (its layout chosen from the path) and write "
        "the frames as a semmatch sequence folder (intrinsics.json, poses.txt, rgb/, depth/, labels/ when the "
        "recording has labels, meta.json) that every verb reads. The folder is written under a temporary name "
        "and renamed when complete; what semmatch did not write is never replaced. Every frame needs a pose: "
        "give a recording with poses, or --estimate-poses (the recording's ground truth, if any, then goes to "
        "poses_gt.txt).",
    )
    p.add_argument("sequence", metavar="RECORDING", help="recording folder or file (any registered layout)")
    p.add_argument("--out", required=True, metavar="SEQ", help="sequence folder to write")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a sequence semmatch wrote at --out (anything else is refused)")
    add_recording_options(p)
    add_output_flags(p, json_what="what was written", quiet="the progress bar")
    declare_paths(p, inputs=("sequence", "intrinsics"), outputs=("out",))
    p.set_defaults(func=run)


def _ground_truth(seq):
    """The recording's ground truth to keep beside estimated poses (None: none for every frame)."""
    import numpy as np

    gt = getattr(seq, "pose_estimate", {}).get("ground_truth")
    if gt is None or len(gt) != len(seq) or not np.isfinite(gt).all():
        return None
    return gt


def run(args: argparse.Namespace) -> int:
    """Convert and print where the sequence went."""
    from semmatch.cli.common import emit, open_sequence
    from semmatch.io import SequenceWriter, check_output_dir
    from semmatch.io.sequences import sequence_scene
    from semmatch.runtime.progress import tqdm

    # before any work (reading, odometry): never replace what semmatch did not write, nor the input
    check_output_dir(args.out, "sequence", overwrite=args.overwrite, inputs=[args.sequence])
    seq = open_sequence(args, args.sequence, needs_poses=True)
    layout = getattr(seq, "layout", None) or getattr(getattr(seq, "base", None), "layout", None)
    instances = bool(getattr(seq, "has_instances", False))
    gt = _ground_truth(seq) if args.estimate_poses else None
    with SequenceWriter(args.out, seq.intrinsics, overwrite=args.overwrite) as w:
        n_labels = 0
        for i in tqdm(range(len(seq)), desc=f"convert {args.sequence}", disable=args.quiet, unit="frame"):
            f = seq[i]
            extra = {"instances": seq.read_instances(i).astype("uint16")} if instances else {}
            w.add(f.rgb, f.depth, f.pose, labels=f.labels, timestamp=f.timestamp, **extra)
            n_labels += f.labels is not None
        frames = args.frames
        meta = {"converted_from": str(args.sequence), "layout": layout,
                "frames": None if frames is None else [frames.start, frames.stop],
                "poses": "estimated (RGB-D odometry)" if args.estimate_poses else "recorded"}
        scene = sequence_scene(args.sequence)
        if scene:
            meta["scene"] = scene
        w.write_extra("meta.json", json.dumps(meta, indent=2) + "\n")
        if gt is not None:
            w.write_poses("poses_gt.txt", seq.timestamps, gt)
    result = {"out": str(args.out), "frames": len(seq), "layout": layout, "labels": n_labels,
              "poses": meta["poses"]}
    return emit(result, args.json, f"{args.out}: {len(seq)} frames from {args.sequence} ({layout}; poses "
                f"{meta['poses']}{'; labels' if n_labels else ''})")
