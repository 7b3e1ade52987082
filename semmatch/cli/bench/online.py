"""``semmatch bench online RECORDING``: the robot online on a real recording, beside plain odometry.

Plays frames of a recording with ground truth (e.g. 7-Scenes kitchen frames 0-499) through a
:class:`~semmatch.online.session.RobotSession` that tracks against its own map (KinectFusion
style) and transfers labels from a stand-in person's map, and prints frames per CPU-second of
the whole chain (pose + transfer + fusion), latency, where the time goes, peak memory and the
ATE beside plain Open3D frame-to-frame hybrid odometry and the offline ``reconstruct
--estimate-poses`` trajectory, all computed in the same command.
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import numpy as np


def register(sub) -> None:
    """Add ``semmatch bench online``."""
    from semmatch.cli.common import add_json, frame_range, number
    from semmatch.transfer import available_methods

    p = sub.add_parser(
        "online",
        help="the robot online (pose + transfer + fusion per frame): CPU rate, latency, ATE beside plain Open3D",
        description="Play RECORDING (with ground-truth poses; e.g. 7-Scenes kitchen, --frames 0:500) through the "
        "online robot session: poses by frame-to-model tracking against the robot's own map, labels transferred "
        "from a stand-in person's map (the recording's every 10th frame fused with its ground-truth poses, "
        "labelled by depth bands: it measures speed, not accuracy; the tracking never sees it), fusion into the "
        "robot's semantic TSDF. Prints frames per CPU-second of the whole chain, latency (median, p95), the "
        "mean CPU time of each stage, peak RSS, tracking losses and the ATE beside plain Open3D frame-to-frame "
        "hybrid odometry (Open3D's legacy compute_rgbd_odometry, default options but depth_max 4 m, a failed "
        "pair reusing the previous motion) and the offline estimate (reconstruct --estimate-poses).",
    )
    p.add_argument("recording", metavar="RECORDING", help="recording folder with ground-truth poses")
    p.add_argument("--frames", type=frame_range, default="0:500", metavar="START:STOP",
                   help="frames of the recording to play (only these are read)")
    p.add_argument("--passes", type=number(int, lo=1), default=1,
                   help="play the frames this many times, forwards then backwards (a continuous path), for "
                        "the memory of a longer run")
    p.add_argument("--methods", nargs="+", default=["3d-neighborhood"], choices=list(available_methods())[:-1],
                   metavar="METHOD",
                   help="transfer methods: the first runs in the chain; the others are timed on every 10th "
                        "tracked frame and their chain rate is that of the first with their transfer time "
                        "(default: %(default)s)")
    p.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.04,
                   help="the robot map's voxel, metres")
    p.add_argument("--track-downsample", type=number(int, lo=1), default=None,
                   help="tracking image shrink factor (default: width nearest 160 pixels)")
    p.add_argument("--track-iterations", default="10,5", metavar="N,N,...",
                   help="tracking iterations per pyramid level, coarsest first")
    p.add_argument("--residual", default="point-to-plane", choices=["hybrid", "point-to-plane", "intensity"],
                   help="tracking residual")
    p.add_argument("--no-baseline", action="store_true", help="skip plain Open3D frame-to-frame odometry")
    p.add_argument("--no-offline", action="store_true",
                   help="skip the offline estimate (estimate_poses with its pose graph: about 0.7 CPU-s per frame)")
    p.add_argument("--figure", default=None, metavar="PNG",
                   help="draw each frame's CPU time by stage (pose, transfer, fusion) and wall latency over the replay")
    from semmatch.cli.bench import add_thread_flags

    add_thread_flags(p, "online")
    add_json(p, "the numbers")
    p.set_defaults(func=run)


def _played(seq, sl: slice, passes: int) -> list[int]:
    """Recording indices in playing order: forwards, backwards, forwards ..."""
    idx = list(range(*sl.indices(len(seq))))
    out: list[int] = []
    for k in range(passes):
        seg = idx if k % 2 == 0 else idx[::-1]
        out += seg[1:] if out else seg  # the turning frame once
    return out


class _Frames:
    """Frames of ``seq`` at ``order`` (random access, read when asked)."""

    def __init__(self, seq, order: list[int]) -> None:
        self.seq, self.order = seq, order

    def __len__(self) -> int:
        return len(self.order)

    def __getitem__(self, i: int):
        import dataclasses

        f = self.seq[self.order[i]]
        return dataclasses.replace(f, index=i, timestamp=float(i) / 30.0)


def standin_map(seq, indices: list[int], voxel_size: float):
    """The stand-in person's map: every 10th frame (every frame of a recording under 100 frames)
    fused with its ground-truth pose, labelled by depth bands of 0.5 m (ids 1..20; the labels'
    content does not change the transfer's cost)."""
    from semmatch.fusion import reconstruct

    frames = [seq[i] for i in indices[:: 10 if len(indices) >= 100 else 1]]
    labels = [np.clip(1 + (f.depth / 0.5).astype(np.int64), 1, 20).astype(np.uint8) * (f.depth > 0) for f in frames]
    return reconstruct(frames, labels=labels, voxel_size=voxel_size)


def plain_open3d_odometry(frames, start: np.ndarray, depth_max: float = 4.0) -> tuple[np.ndarray, int, float]:
    """Open3D's legacy RGB-D odometry with the hybrid Jacobian, frame to frame, chained from
    ``start``: default ``OdometryOption`` but ``depth_max``; a failed pair reuses the previous
    motion. Returns the poses (N, 4, 4), the failures and the CPU seconds."""
    import numpy as np
    import open3d as o3d

    from semmatch.io import depth_to_uint16

    opt = o3d.pipelines.odometry.OdometryOption()
    opt.depth_max = depth_max
    jac = o3d.pipelines.odometry.RGBDOdometryJacobianFromHybridTerm()
    intr = None

    def load(f):
        c = o3d.geometry.Image(np.ascontiguousarray(f.rgb))
        z = o3d.geometry.Image(depth_to_uint16(f.depth))
        return o3d.geometry.RGBDImage.create_from_color_and_depth(c, z, depth_scale=1000.0, depth_trunc=depth_max,
                                                                  convert_rgb_to_intensity=True)

    T, motion, fails = np.asarray(start, dtype=np.float64).copy(), np.eye(4), 0
    poses, cpu = [T.copy()], 0.0
    prev = None
    for i in range(len(frames)):
        f = frames[i]
        c0 = time.process_time()
        if intr is None:
            k = f.intrinsics
            intr = o3d.camera.PinholeCameraIntrinsic(k.width, k.height, k.fx, k.fy, k.cx, k.cy)
        cur = load(f)
        if prev is not None:
            ok, Tpc, _ = o3d.pipelines.odometry.compute_rgbd_odometry(cur, prev, intr, np.eye(4), jac, opt)
            if not ok:
                fails += 1
                Tpc = motion
            motion = Tpc
            T = T @ Tpc
            poses.append(T.copy())
        prev = cur
        cpu += time.process_time() - c0
    return np.stack(poses), fails, cpu


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print a table or JSON."""
    from semmatch.cli.bench import apply_threads
    from semmatch.cli.common import emit
    from semmatch.cli.replay import _iterations

    if args.thread_rows:
        from semmatch.cli.bench import thread_rows

        rows = thread_rows(args, "online")
        return emit({"rows": rows}, args.json, "\n".join(
            f"{r['row']:32s} {r['frames_per_cpu_second']:6.1f} frames/CPU-s  p95 {r['latency_ms_p95']:6.1f} ms"
            for r in rows))
    threads = apply_threads(args)
    import numpy as np

    from semmatch.io.readers import open_recording
    from semmatch.online import ModelTracker, RobotSession, given_pose
    from semmatch.online.replay import replay, trajectory_error
    from semmatch.poses.trajectory_metrics import ate
    from semmatch.transfer import MapIndex

    iterations = _iterations(args.track_iterations)
    seq = open_recording(args.recording, frames=args.frames)  # the other frames are never read
    sl = slice(0, len(seq))
    gt_all = getattr(seq, "poses", None)
    if gt_all is None or not np.isfinite(np.asarray(gt_all)[list(range(*sl.indices(len(seq))))]).all():
        raise ValueError(f"{args.recording}: frames {sl.start}:{sl.stop} of --frames need ground-truth poses (for the ATE and the "
                         "stand-in map)")
    order = _played(seq, sl, args.passes)
    if len(order) < 3:
        raise ValueError(f"{args.recording}: --frames gives fewer than 3 frames")
    frames = _Frames(seq, order)
    gt = np.asarray(gt_all)[order]
    method = args.methods[0]
    t0 = time.process_time()
    index = MapIndex(standin_map(seq, order[: len(range(*sl.indices(len(seq))))], args.voxel_size))
    build_s = time.process_time() - t0
    session = RobotSession(None, method=method, index=index, voxel_size=args.voxel_size,
                           tsdf_options={"depth_max": 4.0}, initialiser=given_pose(gt[0]),
                           tracker=ModelTracker(None, downsample=args.track_downsample, iterations=iterations,
                                                residual=args.residual))
    # one warm-up frame in a throw-away session (first calls load kernels), then the timed replay
    RobotSession(None, method=method, index=index, voxel_size=args.voxel_size, initialiser=given_pose(gt[0])).step(
        frames[0])
    rss: dict[int, float] = {}

    def sample_rss(i, frame, result) -> None:
        if i % 100 == 0 or i == len(frames) - 1:
            rss[i] = current_rss_gb()

    report = replay(session, frames, rate=0, on_frame=sample_rss)
    s = report.summary(gt)
    s["peak_rss_gb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    s["rss_gb_by_frame"] = rss
    s.update(recording=str(args.recording), played=len(order), method=method, threads=threads,
             standin_map_cpu_s=build_s)
    # other methods: their transfer on every 10th tracked frame, in the chain of the first
    s["chain_frames_per_cpu_second"] = {method: s["frames_per_cpu_second"],
                                        **_other_rates(report, frames, index, args.methods[1:], s["cpu_seconds"])}
    s["online_ate_m"] = s.get("ate_m")
    if not args.no_baseline:
        P, fails, cpu = plain_open3d_odometry(frames, gt[0])
        s["plain_open3d"] = {"ate_m": ate(P, gt), "failures": fails, "frames_per_cpu_second": len(P) / cpu}
    if not args.no_offline:
        import warnings

        from semmatch.poses.odometry import estimate_poses

        c0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # its per-frame notes; the ATE says how it did
            P = estimate_poses([frames[i] for i in range(len(frames))], init_pose=gt[0])
        cpu = time.process_time() - c0
        s["offline_estimate"] = {"ate_m": ate(P, gt), "frames_per_cpu_second": len(P) / cpu}
    s["ate_frames"] = trajectory_error(report, gt).get("ate_frames", 0)
    if args.figure:
        fr = args.frames
        shown = f"{fr.start or 0}:{'' if fr.stop is None else fr.stop}" if isinstance(fr, slice) else fr
        latency_figure(report, args.figure, title=f"{Path(args.recording).name} frames {shown}"
                       + (f" x{args.passes}" if args.passes > 1 else "") + f", {method}, one thread")
    return emit(s, args.json, _table(s))


def _other_rates(report, frames, index, methods, cpu_seconds: float) -> dict:
    """Chain rate of each of ``methods``: the replay's CPU per frame without its own transfer, plus
    the method's transfer CPU on every 10th frame with a pose."""
    from semmatch.transfer import transfer_frame

    base = (cpu_seconds - sum(r.cpu["transfer"] for r in report.results)) / max(len(report.results), 1)
    rates = {}
    for other in methods:
        cpu = []
        for r in report.results[::10]:
            if r.pose is None:
                continue
            f = frames[r.index]
            f.pose = r.pose
            c0 = time.process_time()
            transfer_frame(other, f, index)
            cpu.append(time.process_time() - c0)
        rates[other] = 1.0 / (base + float(np.mean(cpu))) if cpu else float("nan")
    return rates


def current_rss_gb() -> float:
    """This process's resident memory now (GB; from /proc/self/statm), or NaN where there is none."""
    import os

    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e9
    except (OSError, ValueError, IndexError):
        return float("nan")


def latency_figure(report, path, *, title: str = "") -> Path:
    """Per-frame CPU time by stage (stacked) and wall latency (line) of a replay, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from semmatch.io import save_figure

    res = report.results
    x = np.arange(len(res))
    fig, ax = plt.subplots(figsize=(7.0, 2.8))
    bottom = np.zeros(len(res))
    for stage, colour in (("pose", "#4477aa"), ("transfer", "#ee6677"), ("fusion", "#228833")):
        v = np.array([r.cpu.get(stage, 0.0) * 1000.0 for r in res])
        ax.fill_between(x, bottom, bottom + v, step="mid", color=colour, alpha=0.8, lw=0, label=f"{stage} (CPU)")
        bottom += v
    ax.plot(x, report.latencies_ms(), color="k", lw=0.5, alpha=0.6, label="latency (wall)")
    ax.axhline(100, color="grey", ls="--", lw=0.8)
    ax.set_xlabel("frame")
    ax.set_ylabel("ms")
    ax.set_ylim(0, max(120.0, float(np.percentile(report.latencies_ms(), 99)) * 1.1))
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, ncol=4, loc="upper right")
    fig.tight_layout()
    return save_figure(fig, path, dpi=100)


def _table(s: dict) -> str:
    cm = lambda v: "-" if v is None else f"{v * 100:.2f} cm"  # noqa: E731
    lines = [
        f"{s['recording']}: {s['played']} frames played (self-tracking; transfer {s['method']}; "
        f"{s['threads']} threads)",
        f"  whole chain: {s['frames_per_cpu_second']:.1f} frames per CPU-second; latency median "
        f"{s['latency_ms_median']:.1f} ms, p95 {s['latency_ms_p95']:.1f} ms wall (CPU p95 {s['cpu_ms_p95']:.1f} ms)",
        "  mean CPU per frame: " + ", ".join(f"{k} {v:.1f} ms" for k, v in s["mean_cpu_ms"].items()),
        "  chain rate by method: " + ", ".join(f"{k} {v:.1f}" for k, v in s["chain_frames_per_cpu_second"].items()),
        f"  tracking losses {s['tracking_losses']} ({s['lost_frames']} lost frames); peak RSS {s['peak_rss_gb']:.2f} GB"
        " (RSS by frame: " + ", ".join(f"{k} {v:.2f}" for k, v in s["rss_gb_by_frame"].items()) + ")",
        f"  ATE: online {cm(s.get('online_ate_m'))}"
        + (f" | plain Open3D frame-to-frame {cm(s['plain_open3d']['ate_m'])}" if "plain_open3d" in s else "")
        + (f" | offline estimate {cm(s['offline_estimate']['ate_m'])}" if "offline_estimate" in s else ""),
    ]
    return "\n".join(lines)
