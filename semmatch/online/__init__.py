"""The robot online: localise each RGB-D frame in the person's map, transfer labels, fuse, one frame at a time.

:class:`~semmatch.online.session.RobotSession` takes frames one by one (pose from frame-to-model
tracking, :mod:`~semmatch.online.tracking`, against model views from
:mod:`~semmatch.online.rendering`; first pose from a pluggable initialiser,
:mod:`~semmatch.online.initialisation`); :mod:`~semmatch.online.replay` plays a recording through a
session at a sensor rate, dropping frames as a live robot would, and reports latency, drops,
losses and trajectory error (``semmatch replay``, ``semmatch bench online``). docs/online.md.
"""

from .initialisation import Initialisation, align_frame, given_pose, register_frame
from .session import STATUSES, FrameResult, RobotSession
from .tracking import ModelTracker, TrackingResult

__all__ = ["RobotSession", "FrameResult", "STATUSES", "ModelTracker", "TrackingResult", "Initialisation",
           "given_pose", "register_frame", "align_frame"]
