"""``semmatch reconstruct SEQ [--labels DIR] --out MAP.ply``: semantic TSDF reconstruction."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(sub) -> None:
    """Add ``semmatch reconstruct``."""
    from semmatch.cli import add_quiet

    p = sub.add_parser(
        "reconstruct",
        help="fuse a posed RGB-D sequence and its labels into a semantic mesh (PLY)",
        description="Fuse a sequence folder (or a TUM RGB-D folder) into a semantic TSDF "
        "reconstruction; write the semantic mesh (label colours + 'label' property), optionally "
        "the RGB mesh and the semantic point cloud.",
    )
    p.add_argument("seq", help="sequence folder, or a TUM RGB-D folder (rgb.txt, depth.txt)")
    p.add_argument("--labels", help="labels folder (000000.png ...) to fuse instead of SEQ/labels")
    p.add_argument("--out", required=True, help="semantic mesh PLY")
    p.add_argument("--rgb-out", help="also write the RGB mesh here")
    p.add_argument("--points-out", help="also write the semantic point cloud here")
    p.add_argument("--voxel-size", type=float, default=0.04, help="voxel edge in metres (default 0.04)")
    p.add_argument("--depth-max", type=float, default=6.0, help="ignore depth beyond this (m, default 6)")
    p.add_argument("--trunc-voxels", type=float, default=4.0, help="TSDF truncation in voxels (default 4)")
    p.add_argument("--label-stride", type=int, default=2, help="label evidence every Nth pixel (default 2)")
    p.add_argument("--min-weight", type=float, default=1.0, help="minimum surface weight (default 1)")
    p.add_argument(
        "--estimate-poses", action="store_true",
        help="ignore the recorded poses and estimate them by RGB-D odometry, starting at the "
        "ground-truth first pose when known (prints ATE/RPE against poses_gt.txt or the TUM "
        "ground truth)",
    )
    p.add_argument("--prior", action="store_true",
                   help="with --estimate-poses: seed the odometry with the recorded (rough) poses")
    p.add_argument("--poses-out", help="with --estimate-poses: write the estimated trajectory (TUM)")
    p.add_argument("--device", help="Open3D device (default: CUDA:0 when available, else CPU:0)")
    add_quiet(p)
    p.set_defaults(func=run)


def open_any_sequence(path: str | Path):
    """A sequence folder (``intrinsics.json``) or a TUM RGB-D folder (``rgb.txt``)."""
    from semmatch.io import read_sequence
    from semmatch.recordings import is_tum_rgbd, read_tum_rgbd

    return read_tum_rgbd(path) if is_tum_rgbd(path) else read_sequence(path)


def run(args: argparse.Namespace) -> int:
    """Reconstruct and print a one-line JSON summary."""
    from semmatch.fusion import extract, fuse
    from semmatch.io import write_map

    seq = open_any_sequence(args.seq)
    poses = None
    info: dict = {}
    if args.estimate_poses:

        from semmatch.io import write_tum
        from semmatch.odometry import estimate_poses, ground_truth_poses, start_pose
        from semmatch.trajectory_metrics import trajectory_errors

        gt = ground_truth_poses(seq)  # for the start pose and the report only
        prior = seq.poses if args.prior and getattr(seq, "poses", None) is not None else None
        poses = estimate_poses(seq, init_pose=start_pose(gt), prior=prior, progress=not args.quiet)
        if args.poses_out:
            write_tum(args.poses_out, getattr(seq, "timestamps", range(len(poses))), poses)
        if gt is not None and len(gt) == len(poses):
            info.update(trajectory_errors(poses, gt))
    vol = fuse(
        seq,
        labels=args.labels,
        voxel_size=args.voxel_size,
        poses=poses,
        progress=not args.quiet,
        depth_max=args.depth_max,
        trunc_voxels=args.trunc_voxels,
        label_stride=args.label_stride,
        device=args.device,
    )
    m = extract(vol, "mesh", min_weight=args.min_weight)
    write_map(args.out, m)
    if args.rgb_out:
        write_map(args.rgb_out, m, colors="rgb")
    if args.points_out:
        write_map(args.points_out, extract(vol, "points", min_weight=args.min_weight))
    info = {"out": str(args.out), "vertices": len(m), "faces": int(len(m.faces)), **info}
    print(json.dumps(info))
    return 0
