"""``semmatch reconstruct SEQ [--labels DIR] --out MAP.ply``: semantic TSDF reconstruction."""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Iterator

import numpy as np


def register(sub) -> None:
    """Add ``semmatch reconstruct``."""
    from semmatch.cli.common import add_output_flags, add_recording_options, number
    from semmatch.io.outputs import declare_paths

    p = sub.add_parser(
        "reconstruct",
        help="fuse a posed RGB-D sequence and its labels into a semantic mesh (PLY)",
        description="Fuse a sequence folder (or a TUM RGB-D folder) into a semantic TSDF "
        "reconstruction; write the semantic mesh (label colours + 'label' property), optionally "
        "the RGB mesh and the semantic point cloud.",
    )
    p.add_argument("seq", help="sequence folder or recording (TUM RGB-D, 7-Scenes, plain folder, any registered "
                   "layout)")
    p.add_argument("--labels", help="labels folder (000000.png ...) to fuse instead of SEQ/labels")
    p.add_argument("--out", required=True, help="semantic mesh PLY")
    p.add_argument("--rgb-out", help="also write the RGB mesh here")
    p.add_argument("--points-out", help="also write the semantic point cloud here")
    p.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.04,
                   help="voxel edge in metres; the TSDF's memory is estimated from it and the "
                        "scene's extent before any allocation and refused above --memory-budget")
    p.add_argument("--depth-max", type=number(float, lo=0.0, lo_open=True), default=6.0, help="ignore depth beyond this (m)")
    p.add_argument("--trunc-voxels", type=number(float, lo=1.0, hi=64.0), default=4.0,
                   help="TSDF truncation in voxels")
    p.add_argument("--label-stride", type=number(int, lo=1), default=2, help="label evidence every Nth pixel")
    p.add_argument("--min-weight", type=number(float, lo=0.0, hi=1e6), default=1.0,
                   help="minimum surface weight")
    p.add_argument("--memory-budget", type=number(float, lo=0.0, lo_open=True), default=None, metavar="GIB",
                   help="largest estimated TSDF memory in GiB (default: 80 %% of the memory available now)")
    add_recording_options(p, estimate_help="ignore the recorded poses and estimate them by RGB-D odometry, starting "
                          "at the ground-truth first pose when known (prints ATE/RPE against poses_gt.txt or the "
                          "TUM ground truth); cached in the user cache folder, keyed by the frames and settings")
    p.add_argument("--prior", action="store_true",
                   help="with --estimate-poses: seed the odometry with the recorded (rough) poses")
    p.add_argument("--poses-out", help="with --estimate-poses: write the estimated trajectory (TUM)")
    from semmatch.poses.rgbd_odometry import METHODS

    p.add_argument("--residual", choices=METHODS, default="hybrid",
                   help="with --estimate-poses: residual of the frame-to-frame odometry; point-to-plane is the "
                        "fallback where it fails")
    p.add_argument("--no-pose-graph", dest="pose_graph", action="store_false",
                   help="with --estimate-poses: chained odometry only, no pose-graph refinement")
    p.add_argument("--device", help="Open3D device (default: CUDA:0 when available, else CPU:0)")
    add_output_flags(p, json_what="the summary (vertices, faces; ATE/RPE with --estimate-poses)",
                     quiet="the progress bars")
    declare_paths(p, inputs=("seq", "labels", "intrinsics"), outputs=("out", "rgb_out", "points_out", "poses_out"))
    p.set_defaults(func=run)


@contextlib.contextmanager
def _plain_warnings(verb: str) -> Iterator[None]:
    """Print warnings as one line each, ``semmatch VERB: warning: ...`` (no Python source lines)."""
    import sys
    import warnings

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"semmatch {verb}: warning: {message}", file=file or sys.stderr)

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


def available_memory() -> int:
    """Bytes of memory available to a new allocation now (``MemAvailable``; free pages elsewhere)."""
    import os

    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def estimate_tsdf_bytes(seq, voxel_size: float, *, depth_max: float = 6.0, trunc_voxels: float = 4.0,
                        poses=None, samples: int = 8) -> tuple[float, np.ndarray]:
    """An upper estimate of the semantic TSDF's memory, from a few frames, before any allocation.

    The scene's extent is the box holding the 1st to 99th percentile of the points of up to
    ``samples`` frames spread over the sequence (depth up to ``depth_max``); its surface area,
    divided into blocks of 8x8 voxels and widened by the truncation band, gives the blocks the
    grid may allocate (capped by one band of blocks per depth pixel of every frame). Each voxel
    holds 5 + 21 float32 values (TSDF, weight, colour, class evidence).

    Returns
    -------
    bytes : float
    extent : ndarray (3,)
        Metres.
    """
    from semmatch.io.labels import NUM_CLASSES

    n = len(seq)
    band = 1.0 + 2.0 * trunc_voxels / 8.0  # blocks a surface patch allocates across its truncation band
    pts = []
    for i in np.unique(np.linspace(0, n - 1, min(samples, n)).round().astype(int)):
        f = seq[int(i)]
        pose = f.pose if poses is None else poses[int(i)]
        if pose is None or not np.isfinite(pose).all():
            continue
        d = f.depth[::4, ::4]
        v, u = np.nonzero((d > 0) & (d <= depth_max))
        z = d[v, u].astype(np.float64)
        K = f.intrinsics
        cam = np.c_[(4 * u - K.cx) * z / K.fx, (4 * v - K.cy) * z / K.fy, z]
        pts.append(cam @ pose[:3, :3].T + pose[:3, 3])
    if not pts or not sum(len(p) for p in pts):
        return 0.0, np.zeros(3)
    P = np.concatenate(pts)
    lo, hi = np.percentile(P, [1, 99], axis=0)
    block = 8 * voxel_size
    e = np.maximum(hi - lo, block)
    area = 2 * (e[0] * e[1] + e[1] * e[2] + e[0] * e[2])
    h, w = seq[0].depth.shape
    blocks = min(area / block**2, n * h * w) * band
    return float(blocks * 512 * (5 + NUM_CLASSES) * 4), e


def _check_memory(seq, args: argparse.Namespace, poses) -> None:
    """Refuse a reconstruction whose estimated TSDF exceeds the memory budget (before allocation)."""
    if not args.voxel_size > 0:
        return  # the fusion's own message
    need, extent = estimate_tsdf_bytes(seq, args.voxel_size, depth_max=args.depth_max,
                                       trunc_voxels=args.trunc_voxels, poses=poses)
    budget = args.memory_budget * 2**30 if args.memory_budget else 0.8 * available_memory()
    if need > budget:
        x, y, z = extent
        raise ValueError(
            f"{args.seq}: a {args.voxel_size:g} m voxel grid over this scene ({x:.1f} x {y:.1f} x {z:.1f} m) is "
            f"estimated at {need / 2**30:.1f} GiB, above the budget of {budget / 2**30:.1f} GiB; choose a larger "
            "--voxel-size (the default is 0.04), or raise --memory-budget if the machine has the memory"
        )


def run(args: argparse.Namespace) -> int:
    """Reconstruct and print a one-line summary, JSON with ``--json`` (warnings as plain lines)."""
    with _plain_warnings("reconstruct"):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    from semmatch.cli.common import emit, open_sequence
    from semmatch.fusion import extract, fuse_sequence
    from semmatch.io import write_map

    seq = open_sequence(args, args.seq, needs_poses=True, odometry={
        "residual": args.residual, "pose_graph": args.pose_graph, "prior": args.prior, "device": args.device})
    poses = None
    info: dict = {}
    if args.estimate_poses:
        from semmatch.io import write_tum
        from semmatch.poses.trajectory_metrics import rpe_pairs, trajectory_errors

        poses, gt, first = seq.poses, seq.pose_estimate["ground_truth"], seq.pose_estimate["gt_first_frame"]
        info["poses_cached"] = seq.pose_estimate["cached"]
        if args.poses_out:
            write_tum(args.poses_out, getattr(seq, "timestamps", range(len(poses))), poses)
        scorable = gt is not None and len(gt) == len(poses) and len(rpe_pairs(poses, gt)) and int(
            np.isfinite(gt).all(axis=(1, 2)).sum()) >= 3
        if scorable:
            info.update(trajectory_errors(poses, gt), gt_first_frame=first)
        elif gt is not None:
            import warnings

            warnings.warn(f"{args.seq}: the ground truth has fewer than 3 frames or no two consecutive ones; "
                          "no ATE/RPE is reported", UserWarning, stacklevel=2)
    _check_memory(seq, args, poses)
    vol = fuse_sequence(
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
    from semmatch.io.sequences import sequence_scene

    scene = sequence_scene(args.seq)  # the map names the home it is of (semmatch adapt --home checks it)
    write_map(args.out, m, scene=scene)
    if args.rgb_out:
        write_map(args.rgb_out, m, colors="rgb")
    if args.points_out:
        write_map(args.points_out, extract(vol, "points", min_weight=args.min_weight))
    info = {"out": str(args.out), "vertices": len(m), "faces": int(len(m.faces)), **info}
    return emit(info, args.json, _summary(info))


def _summary(info: dict) -> str:
    """The sentence of ``semmatch reconstruct`` without ``--json``."""
    text = f"{info['out']}: {info['vertices']} vertices, {info['faces']} faces"
    if "ate_rmse" in info:
        text += (f"; estimated poses against the ground truth: ATE RMSE {info['ate_rmse']:.3f} m, RPE "
                 f"{info['rpe_trans']:.3f} m / {info['rpe_rot_deg']:.2f} deg over {info['n_frames']} frames")
        if info.get("gt_first_frame"):
            text += f" (ground truth from frame {info['gt_first_frame']})"
    return text
