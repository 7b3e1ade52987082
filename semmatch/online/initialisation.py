"""How a robot session finds its first pose in the person's map (pluggable).

An *initialiser* is any callable ``init(frame, person_map) -> Initialisation``: the session calls
it on its first frame and, while tracking is lost, again as a relocalisation attempt. Two are
provided: :func:`given_pose` (a known start pose, e.g. from the robot's docking station or a
recording's first ground-truth pose) and :func:`register_frame` (the frame's point cloud
registered onto the person's map by :func:`semmatch.poses.registration.register_maps`, FPFH +
RANSAC + ICP). A floor-constrained global registration can replace it by passing another callable.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..io import Frame, SemanticMap
from ..io.geometry import backproject, check_pose

__all__ = ["Initialisation", "Initialiser", "given_pose", "register_frame", "align_frame"]


@dataclass(frozen=True)
class Initialisation:
    """An initialiser's answer.

    Attributes
    ----------
    pose : (4, 4) or None
        ``T_world_camera`` in the person's map frame; None: not found (try again later).
    quality : float
        The initialiser's own score (registration fitness; 1 for a given pose).
    method : str
        Which initialiser answered.
    """

    pose: np.ndarray | None
    quality: float
    method: str


#: the signature of an initialiser
Initialiser = Callable[[Frame, "SemanticMap | None"], Initialisation]


def given_pose(pose: np.ndarray) -> Initialiser:
    """An initialiser that returns a known pose (checked once).

    Parameters
    ----------
    pose : (4, 4)
        ``T_world_camera`` of the first frame.

    Returns
    -------
    callable
    """
    T = check_pose(pose, what="initial pose").copy()

    def init(frame: Frame, person_map: SemanticMap | None) -> Initialisation:
        return Initialisation(T.copy(), 1.0, "given")

    return init



def _frame_cloud(frame: Frame, depth_max: float) -> SemanticMap | None:
    """The frame's point cloud in its camera frame (every 2nd pixel up to ``depth_max``), or None
    when it has fewer than 100 points (the initialisers' input)."""
    pts, _ = backproject(np.where(np.isfinite(frame.depth), frame.depth, 0), frame.intrinsics, stride=2,
                         max_depth=depth_max)
    if len(pts) < 100:
        return None
    return SemanticMap(pts, np.zeros(len(pts), np.uint8), source=f"frame {frame.index}")

def register_frame(frame: Frame, person_map: SemanticMap | None, *, voxel_size: float = 0.05,
                   min_fitness: float = 0.3, depth_max: float = 4.0, seed: int = 0,
                   restarts: int = 3) -> Initialisation:
    """The frame's pose in the person's map by global registration of its point cloud.

    Parameters
    ----------
    frame : Frame
    person_map : SemanticMap
    voxel_size : float
        Feature voxel of :func:`~semmatch.poses.registration.register_maps` (metres).
    min_fitness : float
        Below this registration fitness the answer is "not found".
    depth_max : float
    seed, restarts : int
        As :func:`~semmatch.poses.registration.register_maps`.

    Returns
    -------
    Initialisation
    """
    from ..poses.registration import register_maps

    cloud = _frame_cloud(frame, depth_max) if person_map is not None else None
    if cloud is None:
        return Initialisation(None, 0.0, "register")
    try:
        reg = register_maps(cloud, person_map, voxel_size=voxel_size, seed=seed, restarts=restarts)
    except ValueError:  # too few points after downsampling
        return Initialisation(None, 0.0, "register")
    if reg.fitness < min_fitness:
        return Initialisation(None, float(reg.fitness), "register")
    return Initialisation(np.asarray(reg.transform, dtype=np.float64), float(reg.fitness), "register")


def align_frame(frame: Frame, person_map: SemanticMap | None, *, depth_max: float = 4.0, seed: int = 0,
                restarts: int = 4) -> Initialisation:
    """The frame's pose in the person's map by ``semmatch align``'s checked global alignment.

    The frame's point cloud (camera frame; its up hint the camera's -y, a level robot camera) is
    aligned into the person's map by :func:`semmatch.poses.alignment.align_to_map` (floors levelled
    where both see one, yaw and floor shift searched, ICP, the alignment checks); an alignment
    that fails its checks is "not found" (tried again on a later frame), never used.

    Parameters
    ----------
    frame : Frame
    person_map : SemanticMap
    depth_max : float
    seed, restarts : int
        As :func:`~semmatch.poses.alignment.align_to_map`.

    Returns
    -------
    Initialisation
        ``quality`` is the alignment's structure fitness.
    """
    from ..poses.alignment import align_to_map, label_up

    cloud = _frame_cloud(frame, depth_max) if person_map is not None else None
    if cloud is None:
        return Initialisation(None, 0.0, "align")
    try:
        res = align_to_map(cloud, person_map, source_up=np.array([0.0, -1.0, 0.0]), target_up=label_up(person_map),
                           seed=seed, restarts=restarts)
    except ValueError:  # too few points after downsampling
        return Initialisation(None, 0.0, "align")
    if not res.accepted:
        return Initialisation(None, float(res.structure_fitness), "align")
    return Initialisation(np.asarray(res.transform, dtype=np.float64), float(res.structure_fitness), "align")
