"""Sequence folders (docs/data.md): intrinsics, TUM poses, frames, readers, the writer, label folders.

A sequence folder::

    <sequence>/intrinsics.json  poses.txt  rgb/000000.png  depth/000000.png  labels/000000.png

A sequence is written into a hidden temporary folder and renamed to its final name only when
complete, so an interrupted run leaves nothing that reads as a complete sequence.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
from collections.abc import Iterator
from collections.abc import Sequence as _SequenceABC
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .files import (
    OUTPUT_MARKER,
    _recover,
    _writer_lock,
    atomic_write_text,
    output_dir_writer,
    output_kind,
    replace_output_dir,
    write_json,
)
from .geometry import Intrinsics, check_pose, pose_from_tum, pose_to_tum
from .images import (
    read_depth,
    read_image,
    read_label_image,
    read_rgb,
    write_depth,
    write_image,
    write_label_image,
)
from .outputs import temp_dir
from .reading_checks import MAX_POSITION, check_depth_scale, check_label_ids, check_poses

__all__ = ['Frame', 'SequenceReader', 'InMemorySequence', 'SequenceWriter', 'read_intrinsics', 'write_intrinsics', 'read_tum', 'write_tum', 'read_labels_folder', 'write_labels_folder', 'frame_index', 'is_sequence', 'read_sequence', 'listed_file', 'sequence_scene']

PathLike = str | os.PathLike


# ----------------------------------------------------------------------------- intrinsics, poses
def read_intrinsics(path: PathLike) -> Intrinsics:
    """Read ``intrinsics.json``."""
    path = Path(path)
    try:
        d = json.loads(path.read_text())
        return Intrinsics.from_dict(d)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no intrinsics file") from None
    except (ValueError, TypeError) as e:
        raise ValueError(f"{path}: {e}") from None


def write_intrinsics(path: PathLike, intr: Intrinsics) -> None:
    """Write ``intrinsics.json`` atomically."""
    write_json(path, intr.to_dict())


def read_tum(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory file (``t tx ty tz qx qy qz qw`` per line, ``#`` comments).

    Positions must be finite and within :data:`MAX_POSITION` metres of the origin; the
    rotation is the normalised quaternion (always rigid).

    Returns
    -------
    timestamps : ndarray (N,) float64
    poses : ndarray (N, 4, 4) float64, ``T_world_camera``
    """
    path = Path(path)
    stamps, poses = [], []
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.replace(",", " ").split()
        if len(parts) != 8:
            raise ValueError(f"{path}:{lineno}: expected 8 values 't tx ty tz qx qy qz qw', got {len(parts)}")
        try:
            v = np.array([float(p) for p in parts])
        except ValueError:
            raise ValueError(f"{path}:{lineno}: not a number in {line!r}") from None
        if not np.isfinite(v).all():
            raise ValueError(f"{path}:{lineno}: NaN or inf in pose")
        if np.abs(v[1:4]).max() > MAX_POSITION:
            raise ValueError(f"{path}:{lineno} (pose {len(poses)}): camera position {v[1:4].tolist()} lies beyond "
                             f"{MAX_POSITION:g} m of the origin: a corrupt pose, or a trajectory in other units")
        try:
            poses.append(pose_from_tum(v[1:]))
        except ValueError as e:
            raise ValueError(f"{path}:{lineno}: {e}") from None
        stamps.append(v[0])
    return np.asarray(stamps, dtype=np.float64), np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)


def write_tum(path: PathLike, timestamps: np.ndarray, poses: np.ndarray) -> None:
    """Write poses (N,4,4) with timestamps (N,) in TUM format, atomically."""
    poses = np.asarray(poses)
    lines = ["# timestamp tx ty tz qx qy qz qw (T_world_camera)"]
    for t, T in zip(np.asarray(timestamps, dtype=np.float64), poses, strict=True):
        v = pose_to_tum(T)
        lines.append(f"{t:.6f} " + " ".join(f"{x:.9f}" for x in v))
    atomic_write_text(path, "\n".join(lines) + "\n")


# ----------------------------------------------------------------------------- sequences
@dataclass
class Frame:
    """One posed RGB-D frame.

    Attributes
    ----------
    rgb : uint8 (H,W,3)
    depth : float32 (H,W), metres, 0 = no measurement
    labels : uint8 (H,W) category ids, or None when unknown
    pose : float64 (4,4) ``T_world_camera``, or None when unknown
    intrinsics : Intrinsics
    index : int
        Position in its sequence.
    timestamp : float
    """

    rgb: np.ndarray
    depth: np.ndarray
    labels: np.ndarray | None
    pose: np.ndarray | None
    intrinsics: Intrinsics
    index: int = 0
    timestamp: float = 0.0
    extras: dict = field(default_factory=dict)


def _frame_name(i: int) -> str:
    return f"{i:06d}.png"


def listed_file(folder: PathLike, name: str, where: str) -> Path:
    """The file ``name`` of a list inside a recording ``folder`` (TUM ``rgb.txt``, ``depth.txt``).

    Parameters
    ----------
    folder : path
        The recording folder.
    name : str
        The entry as written in the list.
    where : str
        The list and line, for messages (e.g. ``"rgb.txt:12"``).

    Returns
    -------
    Path
        ``folder / name``.

    Raises
    ------
    ValueError
        An absolute entry, or one with ``..``: recordings are read from inside their folder only.
    """
    p = Path(name)
    if p.is_absolute() or ".." in p.parts:
        raise ValueError(f"{where}: {name!r} lies outside the recording folder {folder}; list entries must be "
                         "relative paths inside it (no absolute paths, no '..')")
    return Path(folder) / p


def frame_index(i: int, n: int) -> int:
    """Normalise a frame index (negative counts from the end) for a sequence of ``n`` frames.

    Raises
    ------
    IndexError
        When ``i`` is out of range.
    """
    if not -n <= i < n:
        raise IndexError(f"frame {i} out of range for a sequence of {n} frames")
    return i % n


def is_sequence(path: PathLike) -> bool:
    """True when ``path`` holds a (complete) sequence folder."""
    p = Path(path)
    return (p / "intrinsics.json").is_file() and (p / "poses.txt").is_file()


def sequence_scene(path: PathLike) -> str | None:
    """The scene (home) a sequence folder says it shows: ``scene`` of its ``meta.json``.

    Parameters
    ----------
    path : path
        A sequence folder (``semmatch simulate`` writes ``meta.json``; a recording may have none).

    Returns
    -------
    str or None
        The scene name, or None without a readable ``meta.json`` naming one.
    """
    p = Path(path) / "meta.json"
    try:
        scene = json.loads(p.read_text()).get("scene")
    except (OSError, ValueError, AttributeError):
        return None
    return scene if isinstance(scene, str) and scene.strip() else None


class SequenceReader(_SequenceABC):
    """Lazy, random-access reader of a sequence folder: ``len(seq)``, ``seq[i] -> Frame``.

    Parameters
    ----------
    path : path
        The sequence folder.
    labels : path, optional
        A labels folder to use instead of ``<path>/labels`` (e.g. transferred labels).
    check_units : bool
        Check the depth scale of ``intrinsics.json`` against the depth statistics when the
        folder is opened (:func:`~semmatch.io.reading_checks.check_depth_scale`: ``depth_scale``
        5000 on millimetre depth is refused), like every recording reader.

    Raises
    ------
    ValueError
        Not a sequence folder, no ``poses.txt`` (an interrupted write), a pose that is not
        rigid or lies beyond 10 km, frames missing, a depth scale that contradicts the depth.
    """

    def __init__(self, path: PathLike, labels: PathLike | None = None, *, check_units: bool = True) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path}: no such sequence folder")
        if not (self.path / "intrinsics.json").is_file():
            raise ValueError(f"{self.path}: not a sequence folder (no intrinsics.json)")
        if not (self.path / "poses.txt").is_file():
            raise ValueError(
                f"{self.path}: no poses.txt; the sequence is incomplete (interrupted write?)"
            )
        self.intrinsics = read_intrinsics(self.path / "intrinsics.json")
        self.timestamps, self.poses = read_tum(self.path / "poses.txt")
        self.labels_dir = Path(labels) if labels is not None else self.path / "labels"
        n = len(self.poses)
        for sub in ("rgb", "depth"):
            d = self.path / sub
            have = len(list(d.glob("*.png"))) if d.is_dir() else 0
            if have != n:
                missing = [i for i in range(n) if not (d / _frame_name(i)).is_file()]
                what = f"frame {missing[0]} ({d / _frame_name(missing[0])}) is missing" if missing else (
                    f"{have} files for {n} poses"
                )
                raise ValueError(f"{self.path}: {sub}/ does not match poses.txt: {what}")
        self.has_labels = self.labels_dir.is_dir() and any(self.labels_dir.glob("*.png"))
        check_poses(self.poses, where=str(self.path / "poses.txt"))
        if check_units and n:
            check_depth_scale([self.path / "depth" / _frame_name(i) for i in range(n)], self.intrinsics.depth_scale,
                              where=f"{self.path} (intrinsics.json)")

    def __len__(self) -> int:
        return len(self.poses)

    def _check_shape(self, arr: np.ndarray, path: Path, i: int) -> None:
        if arr.shape[:2] != self.intrinsics.shape:
            raise ValueError(
                f"{path}: frame {i} is {arr.shape[1]}x{arr.shape[0]} but intrinsics.json says "
                f"{self.intrinsics.width}x{self.intrinsics.height}"
            )

    def read_labels(self, i: int) -> np.ndarray | None:
        """Label image of frame ``i`` or None when the labels folder has none."""
        i = frame_index(i, len(self))
        p = self.labels_dir / _frame_name(i)
        if not p.is_file():
            if self.has_labels:
                raise ValueError(f"{self.labels_dir}: frame {i} ({p.name}) is missing")
            return None
        lab = check_label_ids(read_label_image(p), where=p)
        self._check_shape(lab, p, i)
        return lab

    def frame_files(self, i: int) -> tuple[Path, Path]:
        """The files frame ``i`` is read from (colour, depth): what a cache of results keys on."""
        i = frame_index(i, len(self))
        return self.path / "rgb" / _frame_name(i), self.path / "depth" / _frame_name(i)

    @property
    def has_instances(self) -> bool:
        """True when the sequence has an ``instances/`` folder (16-bit instance ids)."""
        return (self.path / "instances").is_dir()

    def read_instances(self, i: int) -> np.ndarray:
        """Instance image of frame ``i`` (int32 (H,W), 0 = none).

        Raises
        ------
        FileNotFoundError
            The sequence has no ``instances/`` folder or lacks this frame's image.
        ValueError
            The image is not single-channel 8/16-bit or has another size.
        """
        i = frame_index(i, len(self))
        p = self.path / "instances" / _frame_name(i)
        if not p.is_file():
            what = "has no instances/ folder" if not self.has_instances else f"lacks frame {i} ({p.name})"
            raise FileNotFoundError(f"{self.path}: the sequence {what}; panoptic work needs instance images")
        inst = read_image(p)
        if inst.ndim != 2 or inst.dtype not in (np.uint8, np.uint16):
            raise ValueError(f"{p}: instance ids must be an 8- or 16-bit single-channel PNG")
        self._check_shape(inst, p, i)
        return inst.astype(np.int32)

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        i = frame_index(i, len(self))
        rp = self.path / "rgb" / _frame_name(i)
        dp = self.path / "depth" / _frame_name(i)
        rgb = read_rgb(rp)
        depth = read_depth(dp, self.intrinsics.depth_scale)
        self._check_shape(rgb, rp, i)
        self._check_shape(depth, dp, i)
        return Frame(
            rgb=rgb,
            depth=depth,
            labels=self.read_labels(i),
            pose=self.poses[i].copy(),
            intrinsics=self.intrinsics,
            index=i,
            timestamp=float(self.timestamps[i]),
        )

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    def __repr__(self) -> str:
        return f"SequenceReader({str(self.path)!r}, frames={len(self)})"

    def load(self, *, progress: bool = False) -> InMemorySequence:
        """Decode every frame once and keep it in memory (see :class:`InMemorySequence`).

        Worth it when a sequence is read many times, e.g. fused with one labels folder per
        transfer method (a 640x480 frame holds about 2.4 MB decoded).
        """
        return InMemorySequence(self, progress=progress)


class InMemorySequence(_SequenceABC):
    """The decoded frames of a :class:`SequenceReader`, read once (:meth:`SequenceReader.load`).

    Has the reader's ``path``, ``intrinsics``, ``poses``, ``timestamps`` and ``read_labels``;
    indexing returns the stored :class:`Frame` objects, whose arrays are read-only (a consumer
    that modifies a frame in place gets an error instead of changing later reads).

    Parameters
    ----------
    reader : SequenceReader or any recording reader
        (:mod:`semmatch.io.readers`: ``labels_dir``/``has_labels`` default to None/False.)
    progress : bool
        Show a tqdm bar while decoding.
    """

    def __init__(self, reader: SequenceReader, *, progress: bool = False) -> None:
        from ..runtime.progress import tqdm

        self.path, self.intrinsics = reader.path, reader.intrinsics
        self.timestamps, self.poses = reader.timestamps, reader.poses
        self.labels_dir = getattr(reader, "labels_dir", None)
        self.has_labels = bool(getattr(reader, "has_labels", False))
        self._frames: list[Frame] = []
        # PNG decoding releases the GIL: two threads decode about twice as fast (frames in order)
        with ThreadPoolExecutor(max_workers=min(2, os.cpu_count() or 1)) as ex:
            frames = ex.map(reader.__getitem__, range(len(reader)))
            for f in tqdm(frames, total=len(reader), desc=f"read {reader.path.name}", disable=not progress,
                          leave=False):
                for a in (f.rgb, f.depth, f.labels, f.pose):
                    if a is not None:
                        a.setflags(write=False)
                self._frames.append(f)

    def __len__(self) -> int:
        return len(self._frames)

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return self._frames[i]
        return self._frames[frame_index(i, len(self))]

    def __iter__(self) -> Iterator[Frame]:
        return iter(self._frames)

    def read_labels(self, i: int) -> np.ndarray | None:
        """Label image of frame ``i`` (None when the sequence has none)."""
        return self[i].labels

    def __repr__(self) -> str:
        return f"InMemorySequence({str(self.path)!r}, frames={len(self)})"


def read_sequence(path: PathLike, labels: PathLike | None = None) -> SequenceReader:
    """Open a sequence folder (lazy; see :class:`SequenceReader`)."""
    return SequenceReader(path, labels=labels)


def _check_sequence_out(path: Path, overwrite: bool) -> None:
    """Refuse a sequence output that would replace what semmatch did not write (or, without
    ``overwrite``, anything at all)."""
    if not path.exists() and not path.is_symlink():
        return
    if path.is_dir() and not path.is_symlink() and not any(path.iterdir()):
        return
    kind = "another sequence" if is_sequence(path) else "other files"
    if not overwrite:
        raise FileExistsError(f"{path}: output folder already holds {kind}; choose another folder "
                              "or pass --overwrite (only a sequence semmatch wrote is replaced)")
    if output_kind(path) != "sequence" or path.is_symlink():
        raise FileExistsError(f"{path}: output folder already holds {kind} that semmatch did not write "
                              f"(no {OUTPUT_MARKER} marker); refusing to replace it, even with --overwrite: "
                              "choose another folder")


class SequenceWriter:
    """Stream frames into a sequence folder; the folder appears only when :meth:`close` runs.

    Frames go to a hidden temporary folder beside ``path``; ``close()`` writes ``poses.txt``
    and renames the folder into place. Use as a context manager: on an exception the
    temporary folder is removed and ``path`` is untouched.

    Parameters
    ----------
    path : path
        Final sequence folder.
    intrinsics : Intrinsics
    overwrite : bool
        Replace an existing sequence at ``path`` that semmatch wrote (its
        :data:`~semmatch.io.OUTPUT_MARKER` says ``sequence``). Anything else there (a user's
        folder, a sequence recorded elsewhere, a file) is refused, with or without it.
    """

    def __init__(self, path: PathLike, intrinsics: Intrinsics, *, overwrite: bool = False) -> None:
        self.path = Path(path)
        _check_sequence_out(self.path, overwrite)
        self.intrinsics = intrinsics
        self.overwrite = overwrite
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # one writer at a time (a second one gets a clear error); what a killed writer left is cleaned
        self._lock = contextlib.ExitStack()
        self._lock.enter_context(_writer_lock(self.path))
        _recover(self.path)
        _check_sequence_out(self.path, overwrite)  # again, under the lock
        self._tmp = temp_dir(self.path)
        for sub in ("rgb", "depth"):
            (self._tmp / sub).mkdir()
        self._poses: list[np.ndarray] = []
        self._stamps: list[float] = []
        self._closed = False

    def __len__(self) -> int:
        return len(self._poses)

    def add(
        self,
        rgb: np.ndarray,
        depth: np.ndarray,
        pose: np.ndarray,
        labels: np.ndarray | None = None,
        timestamp: float | None = None,
        **extra_images: np.ndarray,
    ) -> None:
        """Append one frame. Extra uint8/uint16 images go to ``<name>/NNNNNN.png``."""
        i = len(self._poses)
        shape = self.intrinsics.shape
        for what, arr in (("rgb", rgb), ("depth", depth), ("labels", labels)):
            if arr is not None and np.asarray(arr).shape[:2] != shape:
                raise ValueError(f"frame {i}: {what} is {np.asarray(arr).shape[:2]}, intrinsics say {shape}")
        pose = check_pose(pose, what=f"frame {i} pose")
        name = _frame_name(i)
        write_image(self._tmp / "rgb" / name, np.asarray(rgb, dtype=np.uint8))
        write_depth(self._tmp / "depth" / name, depth, self.intrinsics.depth_scale)
        if labels is not None:
            write_label_image(self._tmp / "labels" / name, np.asarray(labels, dtype=np.uint8))
        for key, img in extra_images.items():
            write_image(self._tmp / key / name, img)
        self._poses.append(pose)
        self._stamps.append(float(i) if timestamp is None else float(timestamp))

    def write_extra(self, name: str, text: str) -> None:
        """Write an extra text file (e.g. ``meta.json``) into the sequence."""
        atomic_write_text(self._tmp / name, text)

    def write_poses(self, name: str, timestamps: np.ndarray, poses: np.ndarray) -> None:
        """Write an extra trajectory (TUM format, e.g. ``poses_gt.txt``) into the sequence."""
        write_tum(self._tmp / name, timestamps, poses)

    def close(self) -> Path:
        """Finish: write intrinsics and poses, then move the folder into place."""
        if self._closed:
            return self.path
        if not self._poses:
            raise ValueError(f"{self.path}: refusing to write a sequence with no frames")
        write_intrinsics(self._tmp / "intrinsics.json", self.intrinsics)
        write_tum(self._tmp / "poses.txt", np.asarray(self._stamps), np.asarray(self._poses))
        replace_output_dir(self._tmp, self.path, "sequence")
        self._closed = True
        self._lock.close()
        return self.path

    def abort(self) -> None:
        """Drop everything written so far."""
        shutil.rmtree(self._tmp, ignore_errors=True)
        self._closed = True
        self._lock.close()

    def __enter__(self) -> SequenceWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()



def write_labels_folder(path: PathLike, labels: Iterator[np.ndarray] | list[np.ndarray], *,
                        overwrite: bool = True, inputs: _SequenceABC[PathLike] = (),
                        extra_dirs: dict[str, PathLike] | None = None) -> Path:
    """Write label images ``000000.png ...`` into ``path`` (temp folder, swapped in when done).

    Parameters
    ----------
    path : path
        The labels folder. An existing one is replaced only when it is a semmatch labels
        output (:func:`check_output_dir`); anything else there is refused, never deleted.
    labels : iterable of uint8 (H,W)
    overwrite : bool
        Replace an existing semmatch labels output (the command line asks for ``--overwrite``).
    inputs : sequence of paths
        Inputs of the command (the output may not be, lie inside or contain one).
    extra_dirs : dict, optional
        Finished folders moved into the output under these names before it is swapped in
        (e.g. ``{"probs": tmp_probs}``).

    Returns
    -------
    Path

    Raises
    ------
    FileExistsError, ValueError
        See :func:`check_output_dir`; also a second process writing the same folder.
    """
    path = Path(path)
    with output_dir_writer(path, "labels", overwrite=overwrite, inputs=inputs) as tmp:
        # PNG encoding releases the GIL: a writer thread overlaps it with making the next label
        # image (a prediction, a transfer) or with the other writer
        with ThreadPoolExecutor(max_workers=2) as ex:
            pending = [ex.submit(write_label_image, tmp / _frame_name(i), np.asarray(lab, dtype=np.uint8))
                       for i, lab in enumerate(labels)]
            for fut in pending:
                fut.result()
        if not pending:
            raise ValueError(f"{path}: no label images to write (a sequence without frames?)")
        for name, src in (extra_dirs or {}).items():
            os.replace(src, tmp / name)
    return path


def read_labels_folder(path: PathLike) -> list[Path]:
    """Sorted label image paths of a labels folder."""
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: no such labels folder")
    return sorted(path.glob("*.png"))


