"""What ``semmatch replay`` writes while and after it plays: labels, poses, a Rerun log.

Per processed frame the labels go to a scratch folder (and the Rerun log gets the frame); when the
replay ends, the labels folder is written atomically with one image per frame of the recording
(void for frames that were dropped or lost), the poses as TUM, and the Rerun log is closed.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from ..io import read_label_image, write_label_image, write_labels_folder, write_tum

__all__ = ["ReplayOutputs"]


class ReplayOutputs:
    """The outputs of one replay (``--labels-out``, ``--poses-out``, ``--rerun``), as a context manager.

    Parameters
    ----------
    labels_out, poses_out, rerun : path or None
    frames : sequence of Frame
        The played frames (their count and camera).
    inputs : sequence of paths
        The command's inputs (an output may not be one).
    overwrite : bool
        Replace an existing labels folder semmatch wrote.
    session : RobotSession, optional
        Its growing map goes into the Rerun log.
    """

    def __init__(self, *, labels_out=None, poses_out=None, rerun=None, frames=(), inputs=(), overwrite=False,
                 session=None) -> None:
        self.labels_out = None if labels_out is None else Path(labels_out)
        self.poses_out = None if poses_out is None else Path(poses_out)
        self.rerun_path = None if rerun is None else Path(rerun)
        self.frames, self.inputs, self.overwrite = frames, list(inputs), overwrite
        self._scratch: tempfile.TemporaryDirectory | None = None
        self._stamps: dict[int, float] = {}
        self.log = None
        self.session = session

    def __enter__(self) -> ReplayOutputs:
        if self.labels_out is not None:
            self.labels_out.parent.mkdir(parents=True, exist_ok=True)
            self._scratch = tempfile.TemporaryDirectory(prefix=".replay-labels-", dir=self.labels_out.parent)
        if self.rerun_path is not None:
            from .rerun_log import RerunLog

            self.log = RerunLog(self.rerun_path)
        return self

    def __exit__(self, *exc) -> None:
        if self._scratch is not None:
            self._scratch.cleanup()
        if self.log is not None:
            self.log.close(keep=exc[0] is None)

    def on_frame(self, i: int, frame, result) -> None:
        """Keep frame ``i``'s labels and timestamp, log it."""
        self._stamps[i] = float(getattr(frame, "timestamp", i))
        if self._scratch is not None and result.labels is not None:
            write_label_image(Path(self._scratch.name) / f"{i:06d}.png", result.labels)
        if self.log is not None:
            self.log.frame(i, frame, result, self.session)

    def _labels(self):
        shape = None
        for i in range(len(self.frames)):
            p = Path(self._scratch.name) / f"{i:06d}.png"
            if p.is_file():
                lab = read_label_image(p)
                shape = lab.shape
                yield lab
            else:  # dropped (or never labelled): void
                if shape is None:
                    shape = self.frames[i].intrinsics.shape
                yield np.zeros(shape, np.uint8)

    def finish(self, report, session) -> None:
        """Write the labels folder and the poses; close the Rerun log with the final map."""
        if self.labels_out is not None:
            write_labels_folder(self.labels_out, self._labels(), overwrite=self.overwrite, inputs=self.inputs)
        if self.poses_out is not None:
            done = [(k, r) for k, r in enumerate(report.results) if r.pose is not None]
            if not done:
                raise ValueError("no frame has a pose: nothing to write to --poses-out")
            positions = report.processed_positions()
            write_tum(self.poses_out, np.array([self._stamps.get(positions[k], positions[k]) for k, _ in done]),
                      np.stack([r.pose for _, r in done]))
        if self.log is not None:
            self.log.final_map(session)
