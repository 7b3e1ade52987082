"""The reader registry: one door for recordings, one reader per folder (or file) layout.

Each layout is a module with a detector ``is_<layout>(path) -> bool`` and a reader class
(``len(seq)``, ``seq[i] -> Frame``, ``intrinsics``, ``timestamps``, ``poses`` (N,4,4) with NaN
rows or None, ``has_poses``), registered here in one line::

    register_layout("tum-rgbd", "semmatch.io.readers.tum", "is_tum_rgbd", "TumRgbdSequence",
                    "a TUM RGB-D folder (rgb.txt, depth.txt)")

Modules are imported when a recording is opened, so a layout whose module is absent costs
nothing until then. :func:`open_recording` picks the first layout whose detector accepts the
path (a folder or a file), passes the options the reader takes (``frames``, ``intrinsics``,
``labels``, bag topics ...) and refuses the ones it does not, applies a frame range to readers
that take none (:class:`~semmatch.io.readers.base.SequenceView`), and checks every recording's
poses (:func:`~semmatch.io.reading_checks.check_poses`). A path of no known layout gets an error
that lists every registered layout (:func:`layouts_text`).
"""

from __future__ import annotations

import importlib
import inspect
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..reading_checks import check_poses
from .base import SequenceView, frame_files, missing_poses

__all__ = ["Layout", "LAYOUTS", "register_layout", "find_layout", "open_recording", "layouts_text",
           "SequenceView", "frame_files", "missing_poses"]

PathLike = str | os.PathLike


@dataclass(frozen=True)
class Layout:
    """One registered recording layout.

    Attributes
    ----------
    name : str
        Short name (``"tum-rgbd"``), shown in messages and ``--json`` outputs.
    module : str
        The module holding the detector and the reader (imported on first use).
    detector, reader : str
        Names of the detector function and the reader class in ``module``.
    description : str
        What a recording of this layout looks like, for the error that lists the layouts.
    """

    name: str
    module: str
    detector: str
    reader: str
    description: str

    def _get(self, attr: str) -> Any:
        return getattr(importlib.import_module(self.module), attr)

    def detects(self, path: PathLike) -> bool:
        """True when the layout's detector accepts ``path``."""
        return bool(self._get(self.detector)(path))

    def reader_class(self) -> type:
        """The reader class."""
        return self._get(self.reader)

    def options(self) -> tuple[str, ...]:
        """The keyword options the reader takes (besides the path)."""
        params = list(inspect.signature(self.reader_class()).parameters.values())[1:]
        return tuple(p.name for p in params if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD))


#: the registered layouts, in the order their detectors are tried
LAYOUTS: list[Layout] = []


def register_layout(name: str, module: str, detector: str, reader: str, description: str) -> Layout:
    """Register a recording layout (see :class:`Layout`); a second registration of ``name`` replaces the first.

    Parameters
    ----------
    name, module, detector, reader, description : str
        As :class:`Layout`.

    Returns
    -------
    Layout
    """
    layout = Layout(name, module, detector, reader, description)
    for k, old in enumerate(LAYOUTS):
        if old.name == name:
            LAYOUTS[k] = layout
            return layout
    LAYOUTS.append(layout)
    return layout


# ---- the layouts (detectors are tried in this order: a sequence folder before a plain one)
register_layout("7scenes", "semmatch.io.readers.seven_scenes", "is_7scenes", "SevenScenesSequence",
                "a 7-Scenes folder (frame-XXXXXX.color.png|jpg, frame-XXXXXX.depth.png [.pose.txt])")
register_layout("tum-rgbd", "semmatch.io.readers.tum", "is_tum_rgbd", "TumRgbdSequence",
                "a TUM RGB-D folder (rgb.txt, depth.txt [groundtruth.txt])")
register_layout("sequence", "semmatch.io.readers.sequence_folder", "is_sequence_folder", "SequenceReader",
                "a semmatch sequence folder (intrinsics.json, poses.txt, rgb/, depth/)")
register_layout("plain", "semmatch.io.readers.plain", "is_plain_folder", "PlainFolderSequence",
                "a plain folder (rgb/ or color/, depth/, intrinsics.json [poses.txt])")
register_layout("rosbag", "semmatch.io.bags", "is_rosbag", "RosBagSequence",
                "a ROS bag (a ROS 1 .bag file, a ROS 2 bag folder with metadata.yaml and *.db3 or *.mcap, or an "
                ".mcap file)")


def layouts_text() -> str:
    """Every registered layout as ``name: description``, joined by ``; `` (for messages)."""
    return "; ".join(f"{lay.name}: {lay.description}" for lay in LAYOUTS)


def find_layout(path: PathLike) -> Layout:
    """The first registered layout whose detector accepts ``path``.

    Raises
    ------
    FileNotFoundError
        Nothing at ``path``.
    ValueError
        A folder or file of no registered layout (the message lists them all).
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such sequence folder or recording file")
    for layout in LAYOUTS:
        if layout.detects(p):
            return layout
    if not p.is_dir():
        raise ValueError(f"{p}: no such folder, and not a recording file of any known layout; expected one of: "
                         f"{layouts_text()}")
    raise ValueError(f"{p}: not a recording folder (or file) of any known layout; expected one of: {layouts_text()}")


def _flag(option: str) -> str:
    return "--" + option.replace("_", "-")


def open_recording(path: PathLike, *, frames: slice | None = None, **options: Any):
    """Open a recording of any registered layout as a sequence of :class:`~semmatch.io.Frame`.

    Parameters
    ----------
    path : path
        A recording folder or file.
    frames : slice, optional
        Use only these frames: passed to a reader that takes ``frames`` (it then reads only
        their files), applied by a :class:`~semmatch.io.readers.base.SequenceView` otherwise.
    **options
        Reader options (``intrinsics``, ``labels``, ``color_topic`` ...); None values are left
        out. An option the layout's reader does not take is refused.

    Returns
    -------
    sequence of Frame
        The reader (or a view of it); ``seq.layout`` names the layout.

    Raises
    ------
    FileNotFoundError, ValueError
        No such path; no known layout (the message lists them); an option the reader does not
        take (the message names it as a flag and the layout); a frame range that selects no
        frame; a pose that is not rigid or lies beyond 10 km (the frame named); the reader's own.
    """
    layout = find_layout(path)
    options = {k: v for k, v in options.items() if v is not None}
    takes = layout.options()
    bad = [k for k in options if k not in takes]
    if bad:
        raise ValueError(f"{path}: {layout.name} recordings take no {', '.join(_flag(k) for k in bad)} (that reader "
                         f"takes: {', '.join(_flag(k) for k in takes) or 'no option'})")
    native = frames is not None and "frames" in takes
    seq = layout.reader_class()(path, **options, **({"frames": frames} if native else {}))
    if frames is not None and not native:
        keep = range(len(seq))[frames]
        if not len(keep):
            raise ValueError(f"{path}: no frame in {frames.start}:{frames.stop} (the recording has {len(seq)})")
        seq = SequenceView(seq, keep)
    check_poses(getattr(seq, "poses", None), where=str(path))
    try:
        seq.layout = layout.name
    except AttributeError:  # a reader with slots: the layout stays unnamed
        pass
    return seq
