"""Real recordings: TUM RGB-D, 7-Scenes and plain image folders as sequences of :class:`semmatch.io.Frame`.

Every reader is lazy and random access (``len(seq)``, ``seq[i] -> Frame``); :func:`read_recording`
picks the reader from the folder's layout through the reader registry (:mod:`semmatch.io.readers`:
one module per layout, importable from here too). No camera is assumed silently: a folder without its
calibration gets the published calibration of the camera its layout names, with a warning that
names it, and a depth scale that contradicts the depth statistics (millimetre PNGs read as TUM's
1/5000 m, which shrinks the room five times) is refused (:func:`check_depth_scale`), and so is a
pose beyond 10 km or not rigid (:mod:`semmatch.io.reading_checks`). 16-bit depth
value 65535 (and 0) is "no measurement". Ground-truth poses are NaN where a frame has none.

A TUM RGB-D folder (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats)::

    <folder>/rgb.txt            "timestamp filename" per line, '#' comments
    <folder>/depth.txt          the same for 16-bit depth PNGs (value / 5000 = metres)
    <folder>/groundtruth.txt    optional: "timestamp tx ty tz qx qy qz qw" (T_world_camera)
    <folder>/intrinsics.json    optional: our intrinsics file (wins over the defaults)

A 7-Scenes folder (Microsoft 7-Scenes; also the layout of andyzeng/tsdf-fusion-python's data)::

    <folder>/frame-000000.color.png|jpg   colour
    <folder>/frame-000000.depth.png       16-bit depth in millimetres (65535 = no measurement)
    <folder>/frame-000000.pose.txt        optional: 4x4 T_world_camera (inf/NaN = unknown)
    <folder>/camera-intrinsics.txt        optional: the 3x3 camera matrix
    <folder>/intrinsics.json              optional: our intrinsics file (wins over both)

A plain folder: ``rgb/`` (or ``color/``) and ``depth/`` images paired by sorted file name,
``intrinsics.json`` required, optional ``poses.txt`` (TUM format, one line per frame).

Colour and depth images are associated by timestamp as TUM's ``associate.py`` does (greedy,
closest pairs first, each image used once, ``|dt| <= max_difference``); ground-truth poses are
interpolated at the colour timestamps (linear translation, slerp rotation) when the frame lies
between two ground-truth samples at most ``max_gt_gap`` apart (:mod:`semmatch.io.timestamps`:
the list files, the association and the interpolation, importable from here too).
"""

from __future__ import annotations

import os

from .readers import open_recording
from .readers.base import ImageSequence as _ImageSequence  # noqa: F401  (the readers' base, old name)
from .readers.plain import PlainFolderSequence, is_plain_folder
from .readers.seven_scenes import SEVEN_SCENES_INTRINSICS, SevenScenesSequence, is_7scenes
from .readers.tum import TUM_INTRINSICS, TumRgbdSequence, is_tum_rgbd, read_tum_rgbd, tum_camera
from .reading_checks import DEPTH_HOLE, NEAREST_MEDIAN_DEPTH, check_depth_scale, read_raw_depth
from .timestamps import associate, interpolate_poses, read_file_list

__all__ = [
    "TUM_INTRINSICS",
    "SEVEN_SCENES_INTRINSICS",
    "DEPTH_HOLE",
    "NEAREST_MEDIAN_DEPTH",
    "TumRgbdSequence",
    "SevenScenesSequence",
    "PlainFolderSequence",
    "is_tum_rgbd",
    "is_7scenes",
    "is_plain_folder",
    "read_recording",
    "check_depth_scale",
    "read_raw_depth",
    "tum_camera",
    "read_tum_rgbd",
    "read_file_list",
    "associate",
    "interpolate_poses",
]

PathLike = str | os.PathLike


def read_recording(path: PathLike, **kwargs):
    """Open any supported recording (folder or file), choosing the reader from its layout.

    The layouts are those of the reader registry (:data:`semmatch.io.readers.LAYOUTS`):
    7-Scenes (``frame-*.depth.png``): :class:`SevenScenesSequence`; TUM RGB-D (``rgb.txt``,
    ``depth.txt``): :class:`TumRgbdSequence`; a semmatch sequence folder (``intrinsics.json``
    and ``poses.txt``): :class:`semmatch.io.SequenceReader`; ``rgb/`` + ``depth/``:
    :class:`PlainFolderSequence`; and any layout registered since.

    Parameters
    ----------
    path : path
    **kwargs
        ``frames`` (a slice, for every layout) and the reader's options (e.g. ``labels``,
        ``intrinsics``); see :func:`semmatch.io.readers.open_recording`.

    Raises
    ------
    ValueError
        A folder of none of these layouts (the message lists every registered layout), an
        option the reader does not take, a bad pose or depth scale.
    """
    return open_recording(path, **kwargs)
