"""A Rerun (``.rrd``) log of a replay: what happens to the robot over time.

Per processed frame (timeline ``frame``): the camera (pinhole and pose), its colour, depth and
transferred labels (a segmentation image with the category colours), the tracking status
(a text log) and quality (fitness and residual as scalars), the trajectory so far and, every
``map_every`` frames and at the end, the robot's semantic map as coloured points. Open the file
with ``rerun OUT.rrd``; ``semmatch show`` stays the page for a finished map.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["RerunLog"]


class RerunLog:
    """Write a replay's Rerun log (atomically: a temporary file renamed on :meth:`close`).

    Parameters
    ----------
    path : path
        The ``.rrd`` file.
    map_every : int
        Log the semantic map every this many processed frames.
    """

    def __init__(self, path, *, map_every: int = 10) -> None:
        import rerun as rr

        from ..io.labels import CATEGORIES
        from ..io.outputs import temp_dir

        self.path = Path(path)
        if self.path.suffix != ".rrd":
            raise ValueError(f"{self.path}: a Rerun log must end in .rrd")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp_dir = temp_dir(self.path)
        self._tmp = self._tmp_dir / self.path.name
        self.rec = rr.RecordingStream("semmatch_replay")
        self.rec.save(str(self._tmp))
        self.rec.log("/", rr.AnnotationContext([(c.id, c.name, tuple(int(x) for x in c.color)) for c in CATEGORIES]),
                     static=True)
        self.map_every = int(map_every)
        self.track: list[np.ndarray] = []
        self.n = 0

    def frame(self, i: int, frame, result, session=None) -> None:
        """Log processed frame ``i`` and its :class:`~semmatch.online.session.FrameResult` (and,
        every ``map_every`` frames, the semantic map of ``session``)."""
        import rerun as rr

        rec = self.rec
        rec.set_time("frame", sequence=int(i))
        intr = frame.intrinsics
        rec.log("world/camera/image", rr.Pinhole(image_from_camera=intr.K, resolution=[intr.width, intr.height]))
        if result.pose is not None:
            rec.log("world/camera", rr.Transform3D(translation=result.pose[:3, 3], mat3x3=result.pose[:3, :3]))
            self.track.append(result.pose[:3, 3].copy())
            rec.log("world/trajectory", rr.LineStrips3D([np.asarray(self.track)]))
        if frame.rgb is not None:
            rec.log("world/camera/image/rgb", rr.Image(frame.rgb))
        rec.log("world/camera/image/depth", rr.DepthImage(frame.depth, meter=1.0))
        if result.labels is not None:
            rec.log("world/camera/image/labels", rr.SegmentationImage(result.labels))
        level = "INFO" if result.pose is not None else "WARN"
        text = result.status + (f": {result.reason}" if result.reason else "")
        rec.log("tracking/status", rr.TextLog(text, level=level))
        if result.tracking is not None:
            rec.log("tracking/fitness", rr.Scalars(result.tracking.fitness))
            if np.isfinite(result.tracking.rmse):
                rec.log("tracking/rmse", rr.Scalars(result.tracking.rmse))
        rec.log("latency_ms", rr.Scalars(result.seconds.get("total", 0.0) * 1000.0))
        self.n += 1
        if session is not None and self.n % self.map_every == 0:
            self.final_map(session)

    def _map(self, semantic_map) -> None:
        import rerun as rr

        from ..io.labels import labels_to_colors

        self.rec.log("world/map", rr.Points3D(semantic_map.points, colors=labels_to_colors(semantic_map.labels),
                                              radii=0.01))

    def final_map(self, session) -> None:
        """Log the session's semantic map as it is now (points)."""
        try:
            m = session.semantic_map("points")
        except ValueError:  # nothing fused yet
            return
        self._map(m)

    def close(self, *, keep: bool = True) -> None:
        """Flush and move the log into place (``keep``), or drop it."""
        import shutil

        self.rec.flush()
        self.rec.disconnect()
        if keep and self._tmp.is_file():
            self._tmp.replace(self.path)
        shutil.rmtree(self._tmp_dir, ignore_errors=True)
