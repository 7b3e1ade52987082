"""Play a recording through a :class:`~semmatch.online.session.RobotSession` as a live robot would.

Frames arrive at the sensor rate (``rate`` frames per second, frame ``i`` at ``i / rate``); the
session processes one frame at a time and, when it finishes, takes the newest frame that has
arrived by then, so the frames that arrived while it was busy are dropped (a live robot cannot
queue them without falling further behind). The clock is simulated from the measured processing
time of each frame (reading and decoding the recording is not counted: a robot's driver delivers
decoded images), so a replay does not sleep. ``rate`` 0 processes every frame.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from .session import FrameResult, RobotSession

__all__ = ["ReplayReport", "replay", "frame_schedule"]


@dataclass
class ReplayReport:
    """Per-frame results and summary of :func:`replay`.

    Attributes
    ----------
    results : list of FrameResult
        The processed frames, in order (labels dropped unless ``keep_labels``).
    dropped : list of int
        Indices of the frames dropped because the session was busy.
    n_frames : int
        Frames in the recording (played part).
    rate : float
    """

    results: list = field(default_factory=list)
    dropped: list = field(default_factory=list)
    n_frames: int = 0
    rate: float = 0.0

    processed: list = field(default_factory=list)

    def processed_positions(self) -> list:
        """Positions (in the played frames) of :attr:`results`."""
        return list(self.processed)

    def latencies_ms(self) -> np.ndarray:
        """Wall-clock milliseconds of each processed frame."""
        return np.array([r.seconds["total"] * 1000.0 for r in self.results])

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        """``(indices, poses (N, 4, 4))`` of the processed frames (NaN poses where lost)."""
        idx = np.array([r.index for r in self.results], dtype=np.int64)
        P = np.stack([r.pose if r.pose is not None else np.full((4, 4), np.nan) for r in self.results]) \
            if self.results else np.zeros((0, 4, 4))
        return idx, P

    def summary(self, ground_truth: np.ndarray | None = None) -> dict:
        """Counts, latency (wall median and p95, ms), per-stage wall medians and CPU means (ms), the
        CPU p95 (ms), frames per CPU-second, statuses and, with ground
        truth (N, 4, 4) indexed like the recording, the ATE (m) over the frames with a pose."""
        lat = self.latencies_ms()
        cpu = float(sum(r.cpu_seconds for r in self.results))
        statuses: dict[str, int] = {}
        for r in self.results:
            statuses[r.status] = statuses.get(r.status, 0) + 1
        parts = {k: float(np.median([r.seconds[k] for r in self.results]) * 1000.0) if self.results else 0.0
                 for k in ("pose", "transfer", "fusion")}
        cpu_parts = {k: float(np.mean([r.cpu.get(k, 0.0) for r in self.results]) * 1000.0) if self.results else 0.0
                     for k in ("pose", "transfer", "fusion")}
        cpu_ms = np.array([r.cpu_seconds * 1000.0 for r in self.results])
        out = {
            "frames": self.n_frames,
            "processed": len(self.results),
            "dropped": len(self.dropped),
            "rate": self.rate,
            "latency_ms_median": float(np.median(lat)) if len(lat) else 0.0,
            "latency_ms_p95": float(np.percentile(lat, 95)) if len(lat) else 0.0,
            "median_ms": parts,
            "mean_cpu_ms": cpu_parts,
            "cpu_ms_p95": float(np.percentile(cpu_ms, 95)) if len(cpu_ms) else 0.0,
            "cpu_seconds": cpu,
            "frames_per_cpu_second": len(self.results) / cpu if cpu > 0 else float("inf"),
            "statuses": statuses,
            "tracking_losses": sum(1 for a, b in zip([None] + self.results[:-1], self.results)
                                   if b.status == "lost" and (a is None or a.status != "lost")),
            "lost_frames": statuses.get("lost", 0),
        }
        if ground_truth is not None:
            out.update(trajectory_error(self, ground_truth))
        return out


def trajectory_error(report: ReplayReport, ground_truth: np.ndarray) -> dict:
    """``ate_m`` (rigidly aligned RMSE, :func:`semmatch.poses.trajectory_metrics.ate`) and
    ``ate_frames`` over the processed frames with a pose and ground truth ({} when none)."""
    from ..poses.trajectory_metrics import ate

    idx, P = report.poses()
    gt = np.asarray(ground_truth, dtype=np.float64)[idx]
    ok = np.isfinite(P).all(axis=(1, 2)) & np.isfinite(gt).all(axis=(1, 2))
    if ok.sum() < 3:
        return {}
    return {"ate_m": ate(P[ok], gt[ok]), "ate_frames": int(ok.sum())}


def frame_schedule(n: int, rate: float, busy: Callable[[int], float]) -> tuple[list[int], list[int]]:
    """Which frames a live robot processes: ``(processed, dropped)``.

    Parameters
    ----------
    n : int
        Frames; frame ``i`` arrives at ``i / rate`` seconds.
    rate : float
        Frames per second (0: every frame is processed).
    busy : callable
        ``busy(i)`` processes frame ``i`` and returns how long it took (seconds).
    """
    processed, dropped = [], []
    if rate <= 0:
        for i in range(n):
            busy(i)
            processed.append(i)
        return processed, dropped
    clock, i = 0.0, 0
    while i < n:
        clock = max(clock, i / rate)  # wait for the frame when idle
        clock += busy(i)
        processed.append(i)
        newest = int(np.floor(clock * rate + 1e-9))  # the newest frame that has arrived by now
        nxt = max(i + 1, newest)
        dropped.extend(range(i + 1, min(nxt, n)))
        i = nxt
    return processed, dropped


def replay(session: RobotSession, frames: Sequence, *, rate: float = 30.0, poses: np.ndarray | None = None,
           priors: np.ndarray | None = None, probs: Callable[[int], np.ndarray] | None = None, keep_labels: bool = False,
           on_frame: Callable[[int, object, FrameResult], None] | None = None, clock: str = "wall",
           progress: bool = False) -> ReplayReport:
    """Play ``frames`` through ``session`` at ``rate`` frames per second.

    Parameters
    ----------
    session : RobotSession
    frames : sequence of Frame
        A recording (random access: frames are read only when processed).
    rate : float
        Sensor rate in frames per second; 0 processes every frame as fast as it can.
    poses : ndarray (N, 4, 4), optional
        Poses to give the session instead of tracking (e.g. the true ones).
    priors : ndarray (N, 4, 4), optional
        Odometry priors of the frames (:meth:`RobotSession.step`'s ``prior``).
    probs : callable, optional
        ``probs(i)``: class probabilities of frame ``i`` (``fused``).
    keep_labels : bool
        Keep each result's labels (memory grows with the recording); otherwise they are dropped
        after ``on_frame``.
    on_frame : callable, optional
        ``on_frame(i, frame, result)`` after each processed frame ``i`` (writing labels, logging;
        not counted in its latency).
    clock : {"wall", "cpu"}
        What a frame's processing time is on the simulated clock: wall time, or this process's
        CPU time (what one free core would take; for a machine shared with other work).
    progress : bool

    Returns
    -------
    ReplayReport
    """
    from ..runtime.progress import tqdm

    if rate < 0:
        raise ValueError(f"rate must be >= 0 frames per second, got {rate}")
    if clock not in ("wall", "cpu"):
        raise ValueError(f"clock must be 'wall' or 'cpu', got {clock!r}")
    n = len(frames)
    report = ReplayReport(n_frames=n, rate=float(rate))
    bar = tqdm(total=n, desc="replay", disable=not progress, unit="frame")

    def busy(i: int) -> float:
        f = frames[i]
        r = session.step(f, pose=None if poses is None else poses[i], prior=None if priors is None else priors[i],
                         probs=None if probs is None else probs(i))
        if on_frame is not None:
            on_frame(i, f, r)
        if not keep_labels:
            r.labels = None
        if r.tracking is not None:
            r.tracking.view = None  # the rendered view: not kept (memory)
        report.results.append(r)
        bar.update(i + 1 - bar.n)
        return r.seconds["total"] if clock == "wall" else r.cpu_seconds

    try:
        report.processed, report.dropped = frame_schedule(n, rate, busy)
    finally:
        bar.close()
    return report
