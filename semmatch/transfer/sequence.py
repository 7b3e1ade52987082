"""Transfer a whole sequence into a labels folder (atomic), optionally with several processes."""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from concurrent.futures.process import BrokenProcessPool
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..io import (
    InMemorySequence,
    SemanticMap,
    SequenceReader,
    check_output_dir,
    read_sequence,
    write_label_image,
    write_labels_folder,
)
from ..io.files import output_dir_writer
from ..io.sequences import _frame_name
from ..runtime.progress import tqdm
from ..runtime.workers import process_pool
from .index import MapIndex, as_map_index
from .registry import available_methods, check_params, transfer_frame

__all__ = ["transfer_sequence", "transfer_posed_frame", "LOW_SUPPORT", "LowSupportWarning"]

_WORKER: dict = {}


#: mean coverage below which :func:`transfer_sequence` warns that the map barely overlaps the frames
LOW_SUPPORT = 0.01


class LowSupportWarning(UserWarning):
    """The map supports (almost) no pixel of the frames: the labels are (almost) all void."""


def _frame_params(params: dict, i: int) -> dict:
    """Per-frame parameters: a ``probs`` folder becomes frame ``i``'s ``NNNNNN.npy`` array."""
    probs = params.get("probs")
    if isinstance(probs, (str, os.PathLike)):
        path = Path(probs) / f"{i:06d}.npy"
        if not path.is_file():
            raise FileNotFoundError(f"{path}: probabilities of frame {i} are missing")
        try:
            probs = np.load(path)
        except (EOFError, ValueError, OSError) as e:  # empty, truncated, pickled or not an .npy file
            raise ValueError(f"{path}: probabilities of frame {i} are not a readable .npy array ({e})") from None
        if not isinstance(probs, np.ndarray) or probs.ndim != 3 or not probs.size:
            raise ValueError(f"{path}: probabilities of frame {i} must be a non-empty 3-D array, "
                             f"got shape {getattr(probs, 'shape', None)}")
        return {**params, "probs": probs}
    return params


def transfer_posed_frame(method: str, frame, index: MapIndex, *, pose: np.ndarray | None = None,
                         max_distance: float | None = None, **params):
    """One frame's transfer, as :func:`transfer_sequence` and the online session make it.

    The per-frame step both share (:class:`semmatch.online.RobotSession` calls it for each
    frame with a pose), so that the batch verb and the stream cannot drift apart.

    Parameters
    ----------
    method : str
        A registered method.
    frame : Frame
        The frame (its own pose is used unless ``pose`` is given).
    index : MapIndex
        The person's map's index.
    pose : (4, 4), optional
        ``T_world_camera`` to transfer at instead of the frame's own pose.
    max_distance : float, optional
        As :func:`~semmatch.transfer.transfer_frame` (checked against the index's).
    **params
        Method parameters of this frame (``fused``: ``probs`` as an (H, W, C) array).

    Returns
    -------
    TransferResult
    """
    f = frame if pose is None else replace(frame, pose=np.array(pose, dtype=np.float64))
    return transfer_frame(method, f, index, max_distance=max_distance, **params)


def _init_worker(index: MapIndex, source, method: str, params: dict, poses, out: Path) -> None:
    seq = source if isinstance(source, InMemorySequence) else read_sequence(source)
    _WORKER.update(index=index, seq=seq, method=method, params=params, poses=poses, out=out)


#: a frame with fewer valid depth pixels than this share is a sensor dropout (as in fusion)
MIN_VALID_DEPTH = 0.001


def _transfer_one(frames, poses, index, method: str, params: dict, i: int):
    """``(i, labels, coverage, seconds, dropout)`` of frame ``i``."""
    f = frames[i]
    r = transfer_posed_frame(method, f, index, pose=None if poses is None else poses[i], **_frame_params(params, i))
    d = np.asarray(f.depth)
    dropout = np.count_nonzero(np.isfinite(d) & (d > 0)) < MIN_VALID_DEPTH * d.size
    return i, r.labels, r.coverage, r.seconds, dropout


def _run_one(i: int):
    """In a worker: transfer frame ``i``, write its labels into the output's temporary folder
    (an image is not sent back through the pool's pipe), and return ``(i, None, coverage,
    seconds, dropout)``."""
    w = _WORKER
    i, labels, coverage, seconds, dropout = _transfer_one(w["seq"], w["poses"], w["index"], w["method"],
                                                          w["params"], i)
    write_label_image(w["out"] / _frame_name(i), labels)
    return i, None, coverage, seconds, dropout


def transfer_sequence(
    method: str,
    sequence,
    semantic_map: SemanticMap | MapIndex,
    out_dir,
    *,
    jobs: int = 1,
    progress: bool = True,
    max_distance: float | None = None,
    poses: np.ndarray | None = None,
    overwrite: bool = True,
    inputs: Sequence[str | os.PathLike] = (),
    **params,
) -> dict:
    """Transfer labels into every frame of a sequence and write a labels folder.

    Parameters
    ----------
    method : str
        A registered method (:func:`~semmatch.transfer.available_methods`).
    sequence : path or sequence of Frame
        A sequence folder, a :class:`~semmatch.io.SequenceReader`, an
        :class:`~semmatch.io.InMemorySequence` (workers share its decoded frames instead of
        reading the folder again) or a list of frames.
    semantic_map : SemanticMap or MapIndex
        The upper map (indexed once here) or a prebuilt index.
    out_dir : path
        Labels folder ``000000.png ...``; each frame's labels are written as soon as they are
        made (memory does not grow with the sequence) into a temporary folder that is renamed
        when complete (:func:`semmatch.io.write_labels_folder`), so an interrupted run leaves no
        partial folder.
    jobs : int
        Worker processes (for a sequence folder, :class:`~semmatch.io.SequenceReader` or
        :class:`~semmatch.io.InMemorySequence`; other sequences, and 1, run in this process).
    progress : bool
        Show a tqdm progress bar.
    max_distance : float, optional
        Distance threshold (see :func:`~semmatch.transfer.transfer_frame`).
    poses : ndarray (N,4,4), optional
        ``T_world_camera`` poses to use instead of the sequence's own, e.g. poses estimated
        by RGB-D odometry for a recording whose ``poses.txt`` drifts.
    overwrite : bool
        Replace an existing semmatch labels output at ``out_dir``; anything else there is
        refused before any work (:func:`semmatch.io.check_output_dir`).
    inputs : sequence of paths
        Folders ``out_dir`` may not be, lie inside or contain (the sequence, the map).
    **params
        Method parameters. For ``fused``, ``probs`` may be a folder of per-frame
        ``000000.npy ...`` arrays (H,W,C) (e.g. written by ``semmatch predict``).

    Returns
    -------
    dict
        ``frames``, ``coverage`` (mean), ``coverage_per_frame``, ``ms_median``, ``fps``
        (1000 / median ms), ``out`` (the folder).
    """
    if method not in available_methods():
        raise ValueError(f"unknown transfer method {method!r}; valid: {', '.join(available_methods())}")
    if int(jobs) < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    check_params(method, params)
    check_output_dir(out_dir, "labels", overwrite=overwrite, inputs=inputs)
    seq_path = None
    source = None  # what the workers open: a folder, or frames already in memory
    if isinstance(sequence, (str, os.PathLike)):
        seq_path = Path(sequence)
        frames: Sequence = read_sequence(seq_path)
        source = seq_path
    else:
        frames = sequence
        # workers re-open the folder: only a plain reader of one reads the same frames and poses
        if type(sequence) is SequenceReader and sequence.labels_dir == sequence.path / "labels":
            seq_path = source = sequence.path
        elif isinstance(sequence, InMemorySequence):
            seq_path, source = sequence.path, sequence  # forked workers share the frames' memory
    n = len(frames)
    if n == 0:
        raise ValueError("the sequence has no frames")
    if poses is not None:
        poses = np.asarray(poses, dtype=np.float64)
        if poses.shape != (n, 4, 4):
            raise ValueError(f"{seq_path or 'sequence'}: poses must have shape ({n}, 4, 4), got {poses.shape}")
    index = as_map_index(semantic_map, max_distance=max_distance)
    cov = np.zeros(n)
    secs = np.zeros(n)
    dropouts = np.zeros(n, dtype=bool)
    bar = tqdm(total=n, desc=f"transfer {method}", disable=not progress, unit="frame")

    def streamed(results):
        """Each frame's labels as they come (None where a worker wrote them), their statistics kept:
        each image is saved at once, so memory does not grow with the sequence; nothing is swapped
        in if this raises."""
        done = 0  # results come in frame order: the first missing one names where a dead worker stopped
        try:
            for i, lab, c, s, d in results:
                cov[i], secs[i], dropouts[i] = c, s, d
                done = i + 1
                bar.update()
                yield lab
        except BrokenProcessPool:
            raise BrokenProcessPool(f"{seq_path or 'sequence'}: frame {done} of {n} ({method}) and those after it "
                                    "were not transferred") from None
        if dropouts.all():
            raise ValueError(f"{seq_path or 'sequence'}: none of its {n} frame(s) has usable depth (all empty)")

    write = dict(overwrite=overwrite, inputs=inputs)
    try:
        if int(jobs) > 1 and source is not None:
            # the workers write the label images into the output's temporary folder themselves and
            # send back a few numbers per frame; the pool ends before the folder is swapped in or
            # removed (on an error, Ctrl-C or SIGTERM its workers are stopped at once)
            with output_dir_writer(out_dir, "labels", **write) as tmp, \
                    process_pool(int(jobs), initializer=_init_worker,
                                 initargs=(index, source, method, params, poses, tmp)) as ex:
                for _ in streamed(ex.ordered(_run_one, range(n))):
                    pass
            out = Path(out_dir)
        else:
            results = (_transfer_one(frames, poses, index, method, params, i) for i in range(n))
            out = write_labels_folder(out_dir, streamed(results), **write)
    finally:
        bar.close()
    if dropouts.any():
        first = np.flatnonzero(dropouts)[:5].tolist()
        warnings.warn(f"{seq_path or 'sequence'}: {int(dropouts.sum())} of {n} frame(s) had (almost) no valid depth "
                      f"(sensor dropouts; first: {first}); their labels are all void", UserWarning, stacklevel=2)
    if cov[~dropouts].mean() < LOW_SUPPORT:  # over the frames that had depth
        warnings.warn(
            f"{seq_path or 'sequence'}: the map supports only {cov[~dropouts].mean():.2%} of the pixels with depth "
            f"({method}); does the map overlap these frames (same world frame, same units)?",
            LowSupportWarning, stacklevel=2)
    ms = float(np.median(secs) * 1000)
    return {
        "method": method,
        "frames": n,
        "coverage": float(cov.mean()),
        "coverage_per_frame": cov.round(6).tolist(),
        "ms_median": ms,
        "fps": 1000.0 / ms if ms > 0 else float("inf"),
        "out": str(out),
    }
