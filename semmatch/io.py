"""Files of the data contract: sequence folders, TUM poses, PLY semantic maps, atomic writes.

A sequence folder (docs/data.md)::

    <sequence>/intrinsics.json  poses.txt  rgb/000000.png  depth/000000.png  labels/000000.png

Writers never leave a half-written file behind: files are written to a temporary name in the
same folder and renamed; a sequence is written into a hidden temporary folder and renamed to
its final name only when complete, so an interrupted run leaves nothing that reads as a
complete sequence.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
import uuid
import warnings
from collections.abc import Iterator
from collections.abc import Sequence as _SequenceABC
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .geometry import Intrinsics, check_pose, pose_from_tum, pose_to_tum
from .labels import NUM_CLASSES, colors_to_labels, labels_to_colors

#: largest instance id a map or an instance image may hold (PLY ``instance`` is int32)
INSTANCE_MAX = 2**31 - 1

__all__ = [
    "Frame",
    "SequenceReader",
    "InMemorySequence",
    "SequenceWriter",
    "SemanticMap",
    "INSTANCE_MAX",
    "atomic_path",
    "atomic_write_text",
    "save_figure",
    "write_json",
    "read_intrinsics",
    "write_intrinsics",
    "read_tum",
    "write_tum",
    "read_image",
    "write_image",
    "read_label_image",
    "write_label_image",
    "read_depth",
    "write_depth",
    "read_labels_folder",
    "write_labels_folder",
    "OUTPUT_MARKER",
    "output_kind",
    "check_output_dir",
    "replace_output_dir",
    "frame_index",
    "is_sequence",
    "read_sequence",
    "read_map",
    "write_map",
]

PathLike = str | os.PathLike


# ----------------------------------------------------------------------------- atomic writes
@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` when the block succeeds.

    The temporary file keeps the suffix of ``path`` so that libraries choosing a format by
    extension (OpenCV, Open3D, matplotlib) still work. On error it is removed.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: is a folder; give the name of the file to write")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:8]}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as e:
        if e.filename is not None and Path(e.filename).name == tmp.name:  # name the file the user asked for
            raise type(e)(e.errno, f"cannot write {path}: {e.strerror}", str(path)) from None
        raise
    finally:
        if tmp.exists():
            tmp.unlink()


def atomic_write_text(path: PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def save_figure(fig, path: PathLike, *, dpi: int = 120, close: bool = True, **kwargs) -> Path:
    """Save a matplotlib figure (format from the suffix) atomically; close it by default."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, **kwargs)
    if close:
        import matplotlib.pyplot as plt

        plt.close(fig)
    return path


def write_json(path: PathLike, obj) -> None:
    """Write ``obj`` as indented JSON, atomically."""
    atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n")


# ----------------------------------------------------------------------------- images
def write_image(path: PathLike, image: np.ndarray) -> None:
    """Write an RGB ``uint8 (H,W,3)``, a ``uint8``/``uint16 (H,W)`` image as PNG, atomically."""
    image = np.asarray(image)
    if image.ndim == 3:
        if image.shape[2] != 3 or image.dtype != np.uint8:
            raise ValueError(f"{path}: RGB must be uint8 (H,W,3), got {image.dtype} {image.shape}")
        image = image[..., ::-1]
    elif image.ndim != 2 or image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{path}: expected uint8/uint16 (H,W), got {image.dtype} {image.shape}")
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(image), [cv2.IMWRITE_PNG_COMPRESSION, 1]):
            raise OSError(f"could not write image {path}")


def _png_palette() -> list[int]:
    from .labels import PALETTE

    pal = np.zeros((256, 3), np.uint8)
    pal[: len(PALETTE)] = PALETTE
    return pal.reshape(-1).tolist()


def write_label_image(path: PathLike, labels: np.ndarray) -> None:
    """Write category ids (uint8 (H,W)) as a palette PNG, atomically.

    The pixel values are the ids (read back id-exact by :func:`read_label_image`); the PNG's
    palette holds the category colours, so any image viewer shows the labels in colour.
    """
    from PIL import Image

    lab = np.asarray(labels)
    if lab.ndim != 2 or lab.dtype != np.uint8:
        raise ValueError(f"{path}: labels must be uint8 (H,W), got {lab.dtype} {lab.shape}")
    img = Image.fromarray(np.ascontiguousarray(lab), mode="P")
    img.putpalette(_png_palette())
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG", compress_level=1)


def read_label_image(path: PathLike) -> np.ndarray:
    """Read a label PNG as category ids (uint8 (H,W)): palette PNGs (their indices) and 8-bit
    grayscale PNGs (their values).

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        The file is not a single-channel 8-bit or palette image.
    """
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as img:
            if img.mode not in ("P", "L"):
                raise ValueError(f"{path}: labels must be an 8-bit single-channel or palette PNG, got mode {img.mode}")
            return np.asarray(img, dtype=np.uint8).copy()
    except FileNotFoundError:
        raise FileNotFoundError(f"cannot read image {path}") from None
    except (UnidentifiedImageError, OSError) as e:
        raise ValueError(f"{path}: not a readable image ({e})") from None


def read_image(path: PathLike, *, flags: int = cv2.IMREAD_UNCHANGED) -> np.ndarray:
    """Read a PNG/JPEG; colour images come back as RGB."""
    img = cv2.imread(str(path), flags)
    if img is None:
        raise FileNotFoundError(f"cannot read image {path}")
    if img.ndim == 3:
        img = img[..., 2::-1] if img.shape[2] >= 3 else img
        img = np.ascontiguousarray(img)
    return img


def write_depth(path: PathLike, depth: np.ndarray, depth_scale: float = 1000.0) -> None:
    """Write metric depth as a 16-bit PNG (``value = metres * depth_scale``, 0 = none)."""
    d = np.asarray(depth, dtype=np.float64)
    d = np.where(np.isfinite(d) & (d > 0), d, 0.0) * depth_scale
    write_image(path, np.clip(np.rint(d), 0, 65535).astype(np.uint16))


def read_depth(path: PathLike, depth_scale: float = 1000.0) -> np.ndarray:
    """Read a 16-bit depth PNG as float32 metres."""
    raw = read_image(path)
    if raw.ndim != 2 or raw.dtype != np.uint16:
        raise ValueError(f"{path}: depth must be a 16-bit single-channel PNG, got {raw.dtype} {raw.shape}")
    return raw.astype(np.float32) / np.float32(depth_scale)


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


class SequenceReader(_SequenceABC):
    """Lazy, random-access reader of a sequence folder: ``len(seq)``, ``seq[i] -> Frame``.

    Parameters
    ----------
    path : path
        The sequence folder.
    labels : path, optional
        A labels folder to use instead of ``<path>/labels`` (e.g. transferred labels).
    """

    def __init__(self, path: PathLike, labels: PathLike | None = None) -> None:
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
        lab = read_label_image(p)
        self._check_shape(lab, p, i)
        if lab.max(initial=0) >= NUM_CLASSES:
            raise ValueError(f"{p}: label id {lab.max()} outside 0..{NUM_CLASSES - 1}")
        return lab

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
        rgb = read_image(rp)
        if rgb.ndim != 3:
            raise ValueError(f"{rp}: RGB frame must have 3 channels")
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
        transfer method: a 640x480 frame takes ~2.4 MB and ~10 ms to decode from PNG.
        """
        return InMemorySequence(self, progress=progress)


class InMemorySequence(_SequenceABC):
    """The decoded frames of a :class:`SequenceReader`, read once (:meth:`SequenceReader.load`).

    Has the reader's ``path``, ``intrinsics``, ``poses``, ``timestamps`` and ``read_labels``;
    indexing returns the stored :class:`Frame` objects, whose arrays are read-only (a consumer
    that modifies a frame in place gets an error instead of changing later reads).

    Parameters
    ----------
    reader : SequenceReader
    progress : bool
        Show a tqdm bar while decoding.
    """

    def __init__(self, reader: SequenceReader, *, progress: bool = False) -> None:
        from .progress import tqdm

        self.path, self.intrinsics = reader.path, reader.intrinsics
        self.timestamps, self.poses = reader.timestamps, reader.poses
        self.labels_dir, self.has_labels = reader.labels_dir, reader.has_labels
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
        Replace an existing sequence at ``path``. Without it an existing non-empty folder is an
        error that names it.
    """

    def __init__(self, path: PathLike, intrinsics: Intrinsics, *, overwrite: bool = False) -> None:
        self.path = Path(path)
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            if not overwrite:
                kind = "another sequence" if is_sequence(self.path) else "other files"
                raise FileExistsError(
                    f"{self.path}: output folder already holds {kind}; choose another folder "
                    "or pass overwrite"
                )
        self.intrinsics = intrinsics
        self.overwrite = overwrite
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # one writer at a time (a second one gets a clear error); what a killed writer left is cleaned
        self._lock = contextlib.ExitStack()
        self._lock.enter_context(_writer_lock(self.path))
        _recover(self.path)
        self._tmp = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", suffix=".partial", dir=self.path.parent))
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

    def close(self) -> Path:
        """Finish: write intrinsics and poses, then move the folder into place."""
        if self._closed:
            return self.path
        if not self._poses:
            raise ValueError(f"{self.path}: refusing to write a sequence with no frames")
        write_intrinsics(self._tmp / "intrinsics.json", self.intrinsics)
        write_tum(self._tmp / "poses.txt", np.asarray(self._stamps), np.asarray(self._poses))
        if self.path.exists():
            old = self.path.with_name(f".{self.path.name}.{uuid.uuid4().hex[:6]}.old")
            os.replace(self.path, old)
            os.replace(self._tmp, self.path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(self._tmp, self.path)
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


#: marker file of a folder semmatch wrote (``{"kind": ...}``); only such folders are ever replaced
OUTPUT_MARKER = ".semmatch-output"


def output_kind(path: PathLike) -> str | None:
    """The kind of semmatch output folder ``path`` is (its :data:`OUTPUT_MARKER`), else None."""
    marker = Path(path) / OUTPUT_MARKER
    try:
        return str(json.loads(marker.read_text()).get("kind"))
    except (OSError, ValueError, AttributeError):
        return None


def check_output_dir(path: PathLike, kind: str, *, overwrite: bool = False, inputs: _SequenceABC[PathLike] = ()) -> Path:
    """Refuse an output folder whose replacement could destroy what semmatch did not write.

    Parameters
    ----------
    path : path
        The folder to write.
    kind : str
        The kind of output (e.g. ``"labels"``).
    overwrite : bool
        Allow replacing an existing complete semmatch output of the same kind.
    inputs : sequence of paths
        Inputs of the command: the output may be neither one of them, nor inside one, nor
        contain one.

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        The output is, lies inside or contains an input.
    FileExistsError
        ``path`` exists and is not an empty folder or a semmatch output of this kind, or it is
        one and ``overwrite`` is False (the message names ``--overwrite``).
    """
    path = Path(path)
    target = path.resolve()
    for inp in inputs:
        src = Path(inp).resolve()
        if target == src or src in target.parents or target in src.parents:
            raise ValueError(f"{path}: the output folder is, lies inside or contains the input {inp}; "
                             f"choose an --out outside the inputs")
    if not path.exists() and not path.is_symlink():
        return path
    if not path.is_dir() or path.is_symlink():
        raise FileExistsError(f"{path} exists and is not a folder; choose another --out")
    if not any(path.iterdir()):
        return path
    have = output_kind(path)
    if have != kind:
        what = f"a semmatch {have} output" if have else "files semmatch did not write"
        raise FileExistsError(f"{path} holds {what}; refusing to replace it with {kind} (choose another --out)")
    if not overwrite:
        raise FileExistsError(f"{path} already holds semmatch {kind}; pass --overwrite to replace it")
    return path


@contextlib.contextmanager
def _writer_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive lock for writing ``path`` (a second writer gets a clear error)."""
    import fcntl

    lock = path.parent / f".{path.name}.lock"
    fd = os.open(lock, os.O_CREAT | os.O_RDWR, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise FileExistsError(f"{path}: another semmatch process is writing it right now") from None
        try:
            yield
        finally:
            lock.unlink(missing_ok=True)  # still held: a writer waiting on this file fails clearly
    finally:
        os.close(fd)


def _recover(path: Path) -> None:
    """Clean up after a writer of ``path`` that was killed: drop partial folders, and bring back
    the previous output when the kill fell between moving it aside and moving the new one in."""
    olds = sorted(path.parent.glob(f".{path.name}.*.old"))
    if olds and not path.exists():
        os.replace(olds[-1], path)
        olds = olds[:-1]
    for junk in [*path.parent.glob(f".{path.name}.*.partial"), *olds]:
        shutil.rmtree(junk, ignore_errors=True)


def replace_output_dir(tmp: PathLike, path: PathLike, kind: str) -> Path:
    """Move the complete folder ``tmp`` to ``path``, replacing a previous output of ``kind``.

    The new folder gets the :data:`OUTPUT_MARKER`; an existing ``path`` is moved aside, the
    new one moved in, then the old one removed: a kill at any point leaves the old or the new
    output complete (a later writer restores the old one if the kill fell between the moves).
    """
    tmp, path = Path(tmp), Path(path)
    (tmp / OUTPUT_MARKER).write_text(json.dumps({"kind": kind}) + "\n")
    old = None
    if path.exists():
        old = path.parent / f".{path.name}.{uuid.uuid4().hex[:8]}.old"
        os.replace(path, old)
    os.replace(tmp, path)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return path


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
    check_output_dir(path, "labels", overwrite=overwrite, inputs=inputs)
    path.parent.mkdir(parents=True, exist_ok=True)
    with _writer_lock(path):
        _recover(path)
        check_output_dir(path, "labels", overwrite=overwrite, inputs=inputs)
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent))
        try:
            # PNG encoding releases the GIL: a writer thread overlaps it with making the next label
            # image (a prediction, a transfer) or with the other writer
            with ThreadPoolExecutor(max_workers=2) as ex:
                pending = [ex.submit(write_label_image, tmp / _frame_name(i), np.asarray(lab, dtype=np.uint8))
                           for i, lab in enumerate(labels)]
                for fut in pending:
                    fut.result()
            for name, src in (extra_dirs or {}).items():
                os.replace(src, tmp / name)
            replace_output_dir(tmp, path, "labels")
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return path


def read_labels_folder(path: PathLike) -> list[Path]:
    """Sorted label image paths of a labels folder."""
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: no such labels folder")
    return sorted(path.glob("*.png"))


# ----------------------------------------------------------------------------- PLY maps
@dataclass
class SemanticMap:
    """A semantic map: points (or mesh vertices) with category labels.

    Attributes
    ----------
    points : float32 (N,3)
    labels : uint8 (N,)
    colors : uint8 (N,3) or None
        Appearance colours (RGB meshes); label colours are derived from ``labels``.
    faces : int32 (M,3) or None
        Triangles when the map is a mesh.
    normals : float32 (N,3) or None
    source : str
        File it was read from, for messages.
    instances : int32 (N,) or None
        Instance id of every vertex (0 = none: stuff, or a thing without an instance), the
        panoptic layer; None when the map has no instance layer.
    """

    points: np.ndarray
    labels: np.ndarray
    colors: np.ndarray | None = None
    faces: np.ndarray | None = None
    normals: np.ndarray | None = None
    source: str = "<memory>"
    instances: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.points = np.ascontiguousarray(self.points, dtype=np.float32).reshape(-1, 3)
        self.labels = np.ascontiguousarray(self.labels, dtype=np.uint8).reshape(-1)
        if len(self.labels) != len(self.points):
            raise ValueError(f"{self.source}: {len(self.points)} points but {len(self.labels)} labels")
        if self.faces is not None:
            self.faces = np.ascontiguousarray(self.faces, dtype=np.int32).reshape(-1, 3)
            if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= len(self.points)):
                raise ValueError(f"{self.source}: face index outside the vertex list")
        if self.instances is not None:
            inst = np.asarray(self.instances).reshape(-1)
            if len(inst) != len(self.points):
                raise ValueError(f"{self.source}: {len(self.points)} points but {len(inst)} instance ids")
            if inst.size and (inst.min() < 0 or inst.max() > INSTANCE_MAX):
                raise ValueError(
                    f"{self.source}: instance ids must lie in 0..{INSTANCE_MAX} (the PLY property is "
                    f"int32), got {int(inst.min())}..{int(inst.max())}"
                )
            self.instances = np.ascontiguousarray(inst, dtype=np.int32)

    def __len__(self) -> int:
        return len(self.points)

    @property
    def is_mesh(self) -> bool:
        """True when the map has triangles."""
        return self.faces is not None and len(self.faces) > 0

    @property
    def has_instances(self) -> bool:
        """True when the map carries an instance layer."""
        return self.instances is not None

    @property
    def label_colors(self) -> np.ndarray:
        """Palette colours of the labels, uint8 (N,3)."""
        return labels_to_colors(self.labels)

    def check(self) -> SemanticMap:
        """Raise ``ValueError`` for an empty map or NaN/inf vertices; return self."""
        if len(self.points) == 0:
            raise ValueError(f"{self.source}: the map is empty (no vertices)")
        bad = ~np.isfinite(self.points).all(axis=1)
        if bad.any():
            raise ValueError(f"{self.source}: {int(bad.sum())} vertices hold NaN or inf")
        return self

    def canonical(self) -> SemanticMap:
        """The same map with vertices sorted by (x, y, z) and triangles by their vertex indices
        (each rotated to start at its smallest index, orientation kept).

        Reconstructions are deterministic in content but not in order (Open3D's parallel hash
        map); written in canonical order, the same content gives the same bytes.
        """
        p = self.points
        order = np.lexsort((p[:, 2], p[:, 1], p[:, 0]))

        def take(a):
            return None if a is None else np.asarray(a)[order]

        faces = None
        if self.faces is not None:
            inv = np.empty(len(order), np.int64)
            inv[order] = np.arange(len(order))
            f = inv[self.faces]
            shift = np.argmin(f, axis=1)
            rows = np.arange(len(f))[:, None]
            f = f[rows, (shift[:, None] + np.arange(3)) % 3]
            faces = f[np.lexsort((f[:, 2], f[:, 1], f[:, 0]))]
        return SemanticMap(p[order], self.labels[order], colors=take(self.colors), faces=faces,
                           normals=take(self.normals), source=self.source, instances=take(self.instances))

    def to_open3d(self, *, label_colors: bool = True):
        """Legacy ``open3d.geometry.TriangleMesh`` (mesh) or ``PointCloud`` with colours."""
        import open3d as o3d

        col = (self.label_colors if label_colors or self.colors is None else self.colors) / 255.0
        if self.is_mesh:
            m = o3d.geometry.TriangleMesh(
                o3d.utility.Vector3dVector(self.points.astype(np.float64)),
                o3d.utility.Vector3iVector(self.faces),
            )
            m.vertex_colors = o3d.utility.Vector3dVector(col)
            return m
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.points.astype(np.float64)))
        pc.colors = o3d.utility.Vector3dVector(col)
        return pc


_PLY_SIZES = {"char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2, "ushort": 2, "uint16": 2,
              "int": 4, "int32": 4, "uint": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}


def check_ply_header(path: PathLike) -> None:
    """Refuse a PLY whose header claims more elements than the file can hold, before parsing it.

    A 250-byte file claiming 3*10^8 faces would otherwise make the parser allocate gigabytes.
    The smallest possible size of every element (binary: its fixed properties plus each list's
    count; ASCII: two characters per value) times its count must fit in the bytes after the
    header.

    Raises
    ------
    ValueError
        The header is unreadable or claims more than the file holds (names the element, its
        count and the file size).
    """
    path = Path(path)
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(64 * 1024)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return  # not a PLY header we can read: the parser gives its own error
    body = size - (head.index(b"\n", end) + 1 if b"\n" in head[end:] else end + 10)
    lines = head[:end].decode("ascii", errors="replace").splitlines()
    fmt = next((ln.split()[1] for ln in lines if ln.startswith("format")), "ascii")
    need, elements = 0, []
    for ln in lines:
        tok = ln.split()
        if not tok:
            continue
        if tok[0] == "element" and len(tok) >= 3:
            try:
                elements.append([tok[1], int(tok[2]), 0])
            except ValueError:
                raise ValueError(f"{path}: bad PLY element line {ln!r}") from None
        elif tok[0] == "property" and elements:
            if fmt == "ascii":
                elements[-1][2] += 2
            elif tok[1] == "list" and len(tok) >= 5:
                elements[-1][2] += _PLY_SIZES.get(tok[2], 1)
            else:
                elements[-1][2] += _PLY_SIZES.get(tok[1], 1)
    for name, count, per in elements:
        if count < 0:
            raise ValueError(f"{path}: PLY header claims {count} {name} elements")
        need += count * per
        if need > body:
            raise ValueError(
                f"{path}: PLY header claims {count:,} {name} elements (at least {count * per:,} bytes) but the "
                f"file holds {body:,} bytes after its header: truncated or corrupt"
            )


def read_map(path: PathLike, *, require_labels: bool = True) -> SemanticMap:
    """Read a semantic PLY (mesh or point cloud).

    The ``label`` vertex property wins when present; otherwise labels come from the vertex
    colours through the palette (colours outside it read as void and are counted in a
    ``UserWarning``; with ``require_labels``, a map whose colours are mostly outside the palette
    is refused: it is not a semantic map of this label table).

    Raises
    ------
    ValueError
        The file is not a PLY with vertices, has neither colours nor ``label`` or mostly
        off-palette colours (with ``require_labels``), or holds NaN vertices.
    """
    from plyfile import PlyData, PlyParseError

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such map file")
    check_ply_header(path)
    errors = (PlyParseError, ValueError, IndexError, EOFError, TypeError)
    try:
        # fast path for triangle meshes: fixed-length face lists read as one array
        ply = PlyData.read(str(path), known_list_len={"face": {"vertex_indices": 3}})
    except errors:
        try:
            ply = PlyData.read(str(path))
        except errors as e:
            raise ValueError(f"{path}: not a readable PLY file ({e})") from None
    if "vertex" not in ply:
        raise ValueError(f"{path}: PLY has no vertex element")
    v = ply["vertex"].data
    names = v.dtype.names or ()
    if not {"x", "y", "z"} <= set(names):
        raise ValueError(f"{path}: PLY vertices lack x, y, z")
    pts = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float32)
    colors = None
    for rgb in (("red", "green", "blue"), ("r", "g", "b"), ("diffuse_red", "diffuse_green", "diffuse_blue")):
        if set(rgb) <= set(names):
            c = np.stack([v[k] for k in rgb], axis=1)
            if np.issubdtype(c.dtype, np.floating):
                c = np.clip(np.rint(c * 255.0 if c.max(initial=0) <= 1.0 else c), 0, 255)
            colors = c.astype(np.uint8)
            break
    if "label" in names:
        labels = np.asarray(v["label"]).astype(np.int64)
        if labels.size and (labels.min() < 0 or labels.max() >= NUM_CLASSES):
            raise ValueError(f"{path}: label property outside 0..{NUM_CLASSES - 1}")
        labels = labels.astype(np.uint8)
    elif colors is not None:
        labels, n_unknown = colors_to_labels(colors, source=str(path), warn=False)
        if require_labels and n_unknown * 2 > len(colors):
            bad = colors[np.flatnonzero(labels == 0)[0]] if n_unknown else colors[0]
            raise ValueError(
                f"{path}: {n_unknown:,} of {len(colors):,} vertex colours are not colours of the category "
                f"palette (e.g. RGB {tuple(int(x) for x in bad)}); this is not a semantic map of this label "
                "table (an RGB map? another palette?). Write labels as palette colours or a 'label' property")
        if n_unknown:
            warnings.warn(f"{n_unknown} of {len(colors)} colours in {path} are not in the category palette; "
                          "they read as void (0)", UserWarning, stacklevel=2)
    elif require_labels:
        raise ValueError(f"{path}: PLY has neither vertex colours nor a 'label' property")
    else:
        labels = np.zeros(len(pts), dtype=np.uint8)
    instances = None
    if "instance" in names:
        instances = np.asarray(v["instance"])
        if not np.issubdtype(instances.dtype, np.integer):
            raise ValueError(f"{path}: the 'instance' property must be an integer type, got {instances.dtype}")
        instances = instances.astype(np.int64)
        if instances.size and (instances.min() < 0 or instances.max() > INSTANCE_MAX):
            raise ValueError(
                f"{path}: instance ids outside 0..{INSTANCE_MAX} "
                f"({int(instances.min())}..{int(instances.max())})"
            )
    normals = None
    if {"nx", "ny", "nz"} <= set(names):
        normals = np.stack([v["nx"], v["ny"], v["nz"]], axis=1).astype(np.float32)
    faces = None
    if "face" in ply and ply["face"].count:
        fd = ply["face"].data
        key = "vertex_indices" if "vertex_indices" in fd.dtype.names else fd.dtype.names[0]
        col = fd[key]
        try:
            faces = (np.stack(col) if col.dtype == object else np.asarray(col)).astype(np.int32)
        except ValueError:
            raise ValueError(f"{path}: only triangle faces are supported") from None
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise ValueError(f"{path}: only triangle faces are supported")
    m = SemanticMap(pts, labels, colors=colors, faces=faces, normals=normals, source=str(path),
                    instances=instances)
    bad = ~np.isfinite(m.points).all(axis=1)
    if bad.any():
        raise ValueError(f"{path}: {int(bad.sum())} vertices hold NaN or inf")
    return m


def write_map(
    path: PathLike,
    m: SemanticMap,
    *,
    colors: str = "labels",
    binary: bool = True,
    canonical: bool = False,
) -> Path:
    """Write a semantic map as PLY: vertex colours + ``label`` (uchar) property, atomically.

    A map with an instance layer also gets an ``instance`` (int32) vertex property.

    Parameters
    ----------
    path : path
    m : SemanticMap
    colors : {"labels", "rgb"}
        Vertex colours: palette colours of the labels (the contract's semantic map) or the
        map's appearance colours (an RGB mesh; ``label`` is written in both cases).
    binary : bool
        Binary little-endian (default) or ASCII.
    canonical : bool
        Write vertices and triangles in canonical order (:meth:`SemanticMap.canonical`), so that
        the same content always gives the same bytes (the reconstructions of
        :mod:`semmatch.fusion` are written so). Off by default: a mesh whose triangle order means
        something (a scene's per-triangle data) keeps it.
    """
    from plyfile import PlyData, PlyElement

    if colors not in ("labels", "rgb"):
        raise ValueError(f"colors must be 'labels' or 'rgb', got {colors!r}")
    if canonical:
        m = m.canonical()
    if colors == "rgb" and m.colors is None:
        raise ValueError("colors='rgb' needs a map with appearance colours")
    col = m.label_colors if colors == "labels" else np.asarray(m.colors, dtype=np.uint8)
    fields = [("x", "f4"), ("y", "f4"), ("z", "f4")]
    if m.normals is not None:
        fields += [("nx", "f4"), ("ny", "f4"), ("nz", "f4")]
    fields += [("red", "u1"), ("green", "u1"), ("blue", "u1"), ("label", "u1")]
    if m.instances is not None:
        fields += [("instance", "i4")]
    arr = np.empty(len(m.points), dtype=fields)
    arr["x"], arr["y"], arr["z"] = m.points.T
    if m.normals is not None:
        arr["nx"], arr["ny"], arr["nz"] = np.asarray(m.normals, dtype=np.float32).T
    arr["red"], arr["green"], arr["blue"] = col.T
    arr["label"] = m.labels
    if m.instances is not None:
        arr["instance"] = m.instances
    elements = [PlyElement.describe(arr, "vertex")]
    if m.is_mesh:
        f = np.empty(len(m.faces), dtype=[("vertex_indices", "i4", (3,))])
        f["vertex_indices"] = m.faces
        elements.append(PlyElement.describe(f, "face"))
    ply = PlyData(elements, text=not binary, byte_order="<", comments=["semmatch semantic map; label = category id"])
    path = Path(path)
    with atomic_path(path) as tmp:
        if binary and m.is_mesh:
            # plyfile writes a list property face by face (~2 s for a 300k-face mesh); the same
            # bytes as one block: plyfile's header, the vertex records, then per face a uchar
            # count (3) and three little-endian int32 indices
            faces = np.empty(len(m.faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
            faces["n"] = 3
            faces["v"] = m.faces
            with open(tmp, "wb") as fh:
                fh.write(ply.header.encode("ascii") + b"\n")
                fh.write(arr.astype(arr.dtype.newbyteorder("<"), copy=False).tobytes())
                fh.write(faces.tobytes())
        else:
            ply.write(str(tmp))
    return path

