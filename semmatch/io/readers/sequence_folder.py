"""semmatch's own sequence folders (docs/data.md) as a layout of the reader registry::

    <sequence>/intrinsics.json  poses.txt  rgb/000000.png  depth/000000.png  [labels/ instances/ meta.json]

The reader is :class:`semmatch.io.SequenceReader`; a folder semmatch wrote as a sequence (its
output marker) without ``poses.txt`` is read as one, so that it is reported as incomplete.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..files import output_kind
from ..sequences import SequenceReader, is_sequence

__all__ = ["is_sequence_folder", "SequenceReader"]

PathLike = str | os.PathLike


def is_sequence_folder(path: PathLike) -> bool:
    """True when ``path`` is a sequence folder: ``intrinsics.json`` and ``poses.txt``, or semmatch's marker.

    A folder with ``intrinsics.json`` and no ``depth/`` folder counts too (a damaged sequence is
    reported by :class:`~semmatch.io.SequenceReader`, not taken for another layout); one with
    ``poses.txt`` whose depth images are not named ``000000.png ...`` is a plain folder.
    """
    p = Path(path)
    if output_kind(p) == "sequence":
        return True
    depth = p / "depth"
    if is_sequence(p):  # a plain folder with poses.txt names its frames otherwise (0000.png, 1305031102.png ...)
        return not depth.is_dir() or (depth / "000000.png").is_file() or next(depth.glob("*.png"), None) is None
    return (p / "intrinsics.json").is_file() and not depth.is_dir()
