"""ATE/RPE of semmatch's RGB-D odometry and of Open3D's plain frame-to-frame hybrid odometry, side by side.

Usage::

    python scripts/odometry_real.py RECORDING [--frames 0:500] [--variants default,chained,...]

Every method tracks the same frames of RECORDING (7-Scenes, TUM, plain or simulated sequence
folder) from the first frame's true pose, and is scored against the recording's ground truth
(ATE after rigid alignment, RPE over one frame; frames without ground truth are skipped and no
RPE pair spans a gap). Methods (``--variants``, comma-separated):

- ``default``: :func:`semmatch.poses.odometry.estimate_poses` with its defaults (hybrid residual,
  point-to-plane as fallback, pose graph);
- ``chained``: the same without the pose graph;
- ``ptp-misfit``: the earlier default (point-to-plane first, the point-to-plane/hybrid estimate
  with the smaller photometric + depth misfit kept, pose graph);
- ``ptp-misfit-chained``: the same without the pose graph;
- ``open3d``: Open3D's ``t.pipelines.odometry.rgbd_odometry_multi_scale`` with its defaults
  (hybrid, 10/5/3 iterations, started at the identity for every pair), chained; depth beyond
  ``--depth-max`` ignored as in semmatch.

With ``--prior`` every method is seeded by the recording's recorded (rough) poses, as the
real-like chain seeds the tracker of a simulated recording with its drifting odometry: semmatch
through ``estimate_poses(prior=...)`` (and its gate), Open3D by starting each pair at the
prior's motion.

Prints a Markdown table (and, with ``--json``, writes the rows). The table in
docs/recordings.md was produced by this script on frames 0-499 of the 7-Scenes red kitchen;
frames 500-999 are held out (nothing was chosen on them).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from semmatch.cli.common import frame_range

VARIANTS = {
    "default": dict(),
    "chained": dict(pose_graph=False),
    "ptp-misfit": dict(residual="point-to-plane", select="misfit"),
    "ptp-misfit-chained": dict(residual="point-to-plane", select="misfit", pose_graph=False),
}


def open3d_plain(seq, init: np.ndarray, *, depth_max: float, prior: np.ndarray | None = None,
                 progress: bool = True) -> np.ndarray:
    """Open3D's frame-to-frame hybrid RGB-D odometry with its defaults, chained from ``init``.

    Each pair starts at the identity, or at the motion of ``prior`` (N, 4, 4) when given.
    """
    import open3d as o3d
    import open3d.core as o3c

    from semmatch.io import depth_to_uint16
    from semmatch.runtime.progress import tqdm

    odo = o3d.t.pipelines.odometry
    poses, prev = [np.asarray(init, dtype=np.float64)], None
    K = None
    for k, f in enumerate(tqdm(seq, total=len(seq), desc="open3d", disable=not progress, leave=False)):
        rgbd = o3d.t.geometry.RGBDImage(o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(f.rgb))),
                                        o3d.t.geometry.Image(o3c.Tensor(depth_to_uint16(f.depth))))
        if K is None:
            K = o3c.Tensor(f.intrinsics.K)
        if prev is not None:
            try:
                guess = np.eye(4) if prior is None else np.linalg.inv(prior[k - 1]) @ prior[k]
                res = odo.rgbd_odometry_multi_scale(rgbd, prev, K, o3c.Tensor(guess), 1000.0, depth_max)
                T = res.transformation.cpu().numpy().astype(np.float64)  # T_prev_cur
                if not np.isfinite(T).all():
                    T = np.eye(4)
            except RuntimeError:  # no correspondences: stand still, as a plain chain would
                T = np.eye(4)
            poses.append(poses[-1] @ T)
        prev = rgbd
    return np.stack(poses)


def main(argv: list[str] | None = None) -> int:
    """Run the methods and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording")
    ap.add_argument("--frames", type=frame_range, default=None,
                    help="START:STOP of the frames used; the reader opens only these (default: all)")
    ap.add_argument("--variants", default="default,chained,ptp-misfit-chained,open3d",
                    help=f"comma-separated, of {', '.join([*VARIANTS, 'open3d'])}")
    ap.add_argument("--depth-max", type=float, default=5.0, help="ignore depth beyond this (m, default 5)")
    ap.add_argument("--downsample", type=int, default=1, help="semmatch tracks on frames shrunk by this factor")
    ap.add_argument("--prior", action="store_true", help="seed every method with the recorded (rough) poses")
    ap.add_argument("--json", help="also write the rows here")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)

    from semmatch.io.recordings import read_recording
    from semmatch.poses.odometry import ground_truth_poses
    from semmatch.poses.trajectory_metrics import trajectory_errors

    # the reader opens only the frames asked for (a held-out half is never read)
    frames = args.frames or slice(None)
    seq = read_recording(args.recording, **({"frames": frames} if args.frames else {}))
    start = frames.start or 0
    span = f"{start}-{start + len(seq) - 1}"
    gt = ground_truth_poses(seq)
    if gt is None:
        print(f"error: {args.recording} has no ground truth to score against", file=sys.stderr)
        return 2
    if len(gt) != len(seq):  # a simulated folder's poses_gt.txt holds every frame of the recording
        gt = gt[frames]
    first = np.flatnonzero(np.isfinite(gt).all(axis=(1, 2)))
    if len(first) == 0 or first[0] != 0:
        print(f"error: frame {start} has no ground truth; start --frames at a frame that has", file=sys.stderr)
        return 2
    prior = None
    if args.prior:
        if getattr(seq, "poses", None) is None:
            print(f"error: {args.recording} has no recorded poses for --prior", file=sys.stderr)
            return 2
        prior = np.asarray(seq.poses, dtype=np.float64)
    names = [v.strip() for v in args.variants.split(",") if v.strip()]
    unknown = [v for v in names if v not in VARIANTS and v != "open3d"]
    if unknown:
        print(f"error: unknown variants {unknown}", file=sys.stderr)
        return 2
    rows = []
    for name in names:
        t0 = time.perf_counter()
        if name == "open3d":
            est = open3d_plain(seq, gt[0], depth_max=args.depth_max, prior=prior, progress=not args.quiet)
        else:
            from semmatch.poses.odometry import estimate_poses

            est = estimate_poses(seq, init_pose=gt[0], depth_max=args.depth_max, downsample=args.downsample,
                                 prior=prior, progress=not args.quiet, **VARIANTS[name])
        e = trajectory_errors(est, gt)
        rows.append({"method": name + (" +prior" if args.prior else ""), "frames": span, **{k: float(v) for k, v in e.items()},
                     "seconds": time.perf_counter() - t0})
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    print("| method | frames | ATE (cm) | RPE trans. (cm/frame) | RPE rot. (deg/frame) | s/frame |\n|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['method']} | {r['frames']} | {100 * r['ate_rmse']:.2f} | {100 * r['rpe_trans']:.3f} | "
              f"{r['rpe_rot_deg']:.3f} | {r['seconds'] / len(seq):.2f} |")
    if args.json:
        from semmatch.io.files import write_json

        write_json(args.json, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
