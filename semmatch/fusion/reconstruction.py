"""Fuse whole RGB-D sequences into semantic maps with :class:`~semmatch.fusion.tsdf.SemanticTSDF`.

:func:`fuse_sequence` integrates a posed sequence and its labels (the frames' own, a labels folder, or
one label or probability image per frame) into a volume, :func:`extract` takes its mesh or point
cloud, :func:`reconstruct` does both, and :func:`reconstruct_many` fuses the geometry once for
several labelings of the same frames. The sequence is checked as it is read: poses, label
counts, frames without usable depth.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

import numpy as np

from ..io import Frame, SemanticMap, read_label_image, read_labels_folder, write_map
from .tsdf import SemanticTSDF

__all__ = ["fuse_frame", "fuse_sequence", "extract", "reconstruct", "reconstruct_many"]


def _label_source(labels, n: int | None) -> Iterator[np.ndarray | None] | None:
    """Normalise the ``labels`` argument of :func:`reconstruct` into an iterator (None = own)."""
    if labels is None:
        return None
    if isinstance(labels, str | os.PathLike):
        paths = read_labels_folder(labels)
        if n is not None and len(paths) != n:
            raise ValueError(f"{labels}: labels folder has {len(paths)} images for {n} frames")
        return (read_label_image(p) for p in paths)
    if isinstance(labels, np.ndarray) and (
        labels.ndim == 2 or (labels.ndim == 3 and np.issubdtype(labels.dtype, np.floating))
    ):
        raise ValueError(
            f"labels: got one array of shape {labels.shape}; pass one label image (H,W) or "
            "probability image (H,W,C) per frame"
        )
    return iter(labels)


def _check_poses(seq, poses) -> tuple[int | None, np.ndarray | None]:
    """The sequence length (None: unknown) and ``poses`` as (N, 4, 4) float64, checked."""
    n = len(seq) if hasattr(seq, "__len__") else None
    if poses is not None:
        poses = np.asarray(poses, dtype=np.float64)
        if poses.ndim != 3 or poses.shape[1:] != (4, 4):
            raise ValueError(f"poses must have shape (N,4,4), got {poses.shape}")
        if n is not None and len(poses) != n:
            raise ValueError(f"{len(poses)} poses for a sequence of {n} frames")
    return n, poses


def _check_dropouts(vol: SemanticTSDF, count: int, name: str) -> None:
    """One warning for the frames skipped for lack of depth; an error when none was usable."""
    if not vol.skipped:
        return
    if vol.n_frames == 0:
        raise ValueError(f"{name}: none of its {count} frame(s) has usable depth (all empty or out of range)")
    shown = ", ".join(vol.skipped[:3]) + (" ..." if len(vol.skipped) > 3 else "")
    warnings.warn(f"{name}: {len(vol.skipped)} of {count} frame(s) had (almost) no valid depth and were "
                  f"skipped (sensor dropouts): {shown}", stacklevel=3)


def _posed_frames(seq, poses, n: int | None, name: str, progress: bool):
    """Yield ``(i, where, frame, pose)``: the pose is ``poses[i]`` or the frame's own."""
    from ..runtime.progress import tqdm

    for i, frame in enumerate(tqdm(seq, total=n, desc="fuse", disable=not progress, leave=False)):
        where = f"{name} frame {getattr(frame, 'index', i)}"
        pose = frame.pose if poses is None else (poses[i] if i < len(poses) else None)
        if pose is None:
            raise ValueError(f"{where}: no pose (estimate poses first, e.g. semmatch.poses.odometry.estimate_poses)")
        yield i, where, frame, pose


def fuse_frame(vol: SemanticTSDF, frame: Frame, pose: np.ndarray, labels: np.ndarray | None = None, *,
               where: str = "") -> bool:
    """Integrate one posed frame (and its labels) into ``vol``: the step :func:`fuse_sequence`
    repeats and the online session (:class:`semmatch.online.RobotSession`) takes per frame, so
    that the batch map and the streamed one cannot drift apart.

    Parameters
    ----------
    vol : SemanticTSDF
    frame : Frame
        Metric depth, RGB and intrinsics (its own pose is not used).
    pose : (4, 4)
        ``T_world_camera``.
    labels : uint8 (H, W) or float (H, W, C), optional
        Label or probability image; None: geometry only.
    where : str
        Names the frame in errors.

    Returns
    -------
    bool
        False when the frame had no usable depth (a sensor dropout; skipped).
    """
    return vol.integrate(frame.depth, frame.rgb, pose, frame.intrinsics, labels=labels, where=where)


def _next_labels(lab_iter: Iterator, i: int, where: str) -> np.ndarray:
    try:
        return next(lab_iter)
    except StopIteration:
        raise ValueError(f"labels end at frame {i}, before the sequence ({where})") from None


def _check_counts(count: int, lab_iter: Iterator | None, name: str) -> None:
    if count == 0:
        raise ValueError(f"{name}: the sequence has no frames")
    if lab_iter is not None and next(lab_iter, None) is not None:
        raise ValueError(f"more label images than the {count} frames of {name}")


def fuse_sequence(
    seq: Iterable[Frame],
    labels: str | os.PathLike | Iterable[np.ndarray] | None = None,
    voxel_size: float = 0.04,
    *,
    poses: np.ndarray | None = None,
    progress: bool = False,
    **tsdf_options,
) -> SemanticTSDF:
    """Fuse posed RGB-D frames and their labels into a semantic TSDF volume.

    Parameters
    ----------
    seq : sequence or iterable of Frame
        E.g. :func:`semmatch.io.read_sequence` or
        :func:`semmatch.io.recordings.read_tum_rgbd`; frames need metric depth and a pose
        (or ``poses``).
    labels : None, path or iterable
        None: each frame's own ``labels`` (frames without labels add geometry only);
        a labels folder (``000000.png ...``, one per frame); or an iterable with one item per
        frame: a uint8 (H,W) label image or float (H,W,C) class probabilities.
    voxel_size : float
        Voxel edge in metres (default 4 cm).
    poses : ndarray (N, 4, 4), optional
        ``T_world_camera`` per frame, replacing the frames' poses (e.g. estimated ones).
    progress : bool
        Show a progress bar.
    **tsdf_options
        Passed to :class:`SemanticTSDF` (``trunc_voxels``, ``depth_max``, ``label_stride``,
        ``match_probability``, ``device`` ...).

    Returns
    -------
    SemanticTSDF
        Extract a map with :meth:`SemanticTSDF.extract_mesh` / ``extract_point_cloud``.

    Raises
    ------
    ValueError
        A frame without pose, depth in the wrong unit, mismatching label count or shape, an
        empty sequence, no frame with usable depth.
    """
    n, poses = _check_poses(seq, poses)
    name = str(getattr(seq, "path", "sequence"))
    lab_iter = _label_source(labels, n)
    vol = SemanticTSDF(voxel_size, **tsdf_options)
    count = 0
    for i, where, frame, pose in _posed_frames(seq, poses, n, name, progress):
        lab = frame.labels if lab_iter is None else _next_labels(lab_iter, i, where)
        fuse_frame(vol, frame, pose, lab, where=where)
        count += 1
    _check_counts(count, lab_iter, name)
    _check_dropouts(vol, count, name)
    if vol.n_label_points == 0:
        warnings.warn(f"{name}: no label evidence was integrated; all labels are 0 (void)", stacklevel=2)
    vol.name = name
    return vol


def reconstruct(
    seq: Iterable[Frame],
    labels: str | os.PathLike | Iterable[np.ndarray] | None = None,
    voxel_size: float = 0.04,
    *,
    poses: np.ndarray | None = None,
    output: str = "mesh",
    min_weight: float = 1.0,
    progress: bool = False,
    **tsdf_options,
) -> SemanticMap:
    """Fuse posed RGB-D frames and their labels into a semantic map (:func:`fuse_sequence`, then extract).

    Parameters
    ----------
    seq, labels, voxel_size, poses, progress, **tsdf_options
        As :func:`fuse_sequence`.
    output : {"mesh", "points"}
        What to extract: the marching-cubes mesh or the surface point cloud.
    min_weight : float
        Minimum integration weight of a surface voxel in the extracted mesh/points.

    Returns
    -------
    SemanticMap
        Mesh (``faces``) or points with ``labels`` (0 = no evidence) and RGB ``colors``. Write
        it with :func:`semmatch.io.write_map` (``colors="rgb"`` for the appearance mesh).

    Raises
    ------
    ValueError
        As :func:`fuse_sequence`; also a reconstruction with no surface.

    Examples
    --------
    >>> from semmatch.io import read_sequence, write_map           # doctest: +SKIP
    >>> m = reconstruct(read_sequence("data/scenes/eval/s0/lower"), voxel_size=0.04)
    >>> write_map("lower.ply", m)
    """
    if output not in ("mesh", "points"):
        raise ValueError(f"output must be 'mesh' or 'points', got {output!r}")
    vol = fuse_sequence(seq, labels, voxel_size, poses=poses, progress=progress, **tsdf_options)
    return extract(vol, output, min_weight=min_weight)


def extract(vol: SemanticTSDF, output: str = "mesh", *, min_weight: float = 1.0) -> SemanticMap:
    """The mesh or point cloud of a fused volume; an empty one is a clear error.

    Parameters
    ----------
    vol : SemanticTSDF
    output : {"mesh", "points"}
    min_weight : float
        Minimum integration weight of a surface voxel.

    Returns
    -------
    SemanticMap

    Raises
    ------
    ValueError
        No surface with weight >= ``min_weight`` (named with the sequence the volume fused).
    """
    m = vol.extract_mesh(min_weight=min_weight) if output == "mesh" else vol.extract_point_cloud(min_weight=min_weight)
    if len(m) == 0:
        raise ValueError(f"{getattr(vol, 'name', 'sequence')}: the reconstruction is empty "
                         f"(no surface with weight >= {min_weight})")
    return m


def reconstruct_many(
    seq: Iterable[Frame],
    labelings: Sequence[str | os.PathLike | Iterable[np.ndarray] | None],
    voxel_size: float = 0.04,
    *,
    poses: np.ndarray | None = None,
    outs: Sequence[str | os.PathLike | None] | None = None,
    min_weight: float = 1.0,
    progress: bool = False,
    **tsdf_options,
) -> list[SemanticMap]:
    """Fuse one sequence with several labelings: the geometry once, then each one's labels.

    The semantic meshes of, e.g., one lower sequence labelled by every transfer method share
    their geometry (depth, colour and poses are the same); only the label evidence differs.
    The TSDF is integrated once; then, for each labeling, the evidence of every frame is added
    to the voxels its surface points were found to fall in, and the mesh vertices are labelled.
    Each map equals ``reconstruct(seq, labels, voxel_size, ...)`` of that labeling (the same
    evidence in the same order; vertex order may differ, as between two Open3D runs), at the
    cost of one fusion plus a cheap label pass per labeling.

    Parameters
    ----------
    seq : sequence or iterable of Frame
        As :func:`reconstruct` (read once; the voxel of every evidence pixel is kept in
        memory, 12 bytes each: with ``label_stride`` 2 about 25 MB per 100 frames at 320x240,
        90 MB at 640x480; plus the frames' own labels when a labeling is None).
    labelings : sequence
        Each item one ``labels`` argument of :func:`reconstruct`: None (the frames' own
        labels), a labels folder, or an iterable with one label or probability image per frame.
    voxel_size : float
    poses : ndarray (N, 4, 4), optional
        ``T_world_camera`` per frame, replacing the frames' poses.
    outs : sequence of path or None, optional
        One per labeling: write that semantic mesh there (PLY, atomically); None: do not.
    min_weight : float
    progress : bool
    **tsdf_options
        Passed to :class:`SemanticTSDF`.

    Returns
    -------
    list of SemanticMap
        The semantic meshes, in the order of ``labelings``.

    Raises
    ------
    ValueError
        As :func:`reconstruct`, naming the labeling's folder and frame; ``outs`` of another
        length than ``labelings``.
    """

    labelings = list(labelings)
    outs = [None] * len(labelings) if outs is None else list(outs)
    if len(outs) != len(labelings):
        raise ValueError(f"{len(outs)} output paths for {len(labelings)} labelings")
    if not labelings:
        return []
    n, poses = _check_poses(seq, poses)
    name = str(getattr(seq, "path", "sequence"))
    vol = SemanticTSDF(voxel_size, **tsdf_options)
    own_labels = any(lab is None for lab in labelings)
    frames = []  # per frame: (where, own labels)
    pixels = []  # per frame: its evidence pixels (voxel blocks that exist when it is integrated)
    for _, where, frame, pose in _posed_frames(seq, poses, n, name, progress):
        used = fuse_frame(vol, frame, pose, where=where)
        ev = vol.evidence_pixels(frame.depth, pose, frame.intrinsics)
        pixels.append(ev if used else dataclasses.replace(ev, index=ev.index[:0]))
        frames.append((where, frame.labels if own_labels else None))
    _check_counts(len(frames), None, name)
    _check_dropouts(vol, len(frames), name)
    voxels = [vol.locate(ev) for ev in pixels]  # the grid is final now (growing it moves blocks)
    mesh = None
    maps = []
    for labels, out in zip(labelings, outs, strict=True):
        folder = labels if isinstance(labels, str | os.PathLike) else None
        what = name if folder is None else f"{name} with {folder}"
        lab_iter = _label_source(labels, len(frames))
        vol.clear_labels()
        for i, ((where, own), ev, vox) in enumerate(zip(frames, pixels, voxels, strict=True)):
            lab = own if lab_iter is None else _next_labels(lab_iter, i, where)
            if lab is not None:
                vol.add_labels(lab, ev, vox, where=where if folder is None else f"{folder} ({where})")
        _check_counts(len(frames), lab_iter, what)
        if vol.n_label_points == 0:
            warnings.warn(f"{what}: no label evidence was integrated; all labels are 0 (void)", stacklevel=2)
        if mesh is None:
            mesh = vol.extract_mesh(min_weight=min_weight)
            if len(mesh) == 0:
                raise ValueError(f"{name}: the reconstruction is empty (no surface with weight >= {min_weight})")
            m = mesh
        else:
            m = dataclasses.replace(mesh, labels=vol.labels_at(mesh.points))
        if out is not None:
            write_map(Path(out), m)
        maps.append(m)
    return maps
