"""The robot placed in the person's map: a checked rigid alignment of one map into another.

:func:`align_to_map` registers the robot's map (fused on its own poses) into the person's map
with the machinery of :func:`semmatch.poses.registration.register_maps` (FPFH features, global
starts, coarse-to-fine point-to-plane ICP, restarts that agree share a refinement). Where both
maps see the floor, the global search is constrained by it:

1. each map's floor is fitted (:func:`fit_floor`): among the points whose normals are within
   ``floor_angle`` of the map's up hint (the cameras' up direction, or a known world axis), the
   lowest well-supported layer, refined by a RANSAC plane; its normal fixes roll and pitch, its
   offset the height;
2. both maps are levelled (floor at z = 0, normal +z), so the rigid transform between them is a
   turn about the vertical and a shift along the floor: three degrees of freedom. Mutual FPFH
   matches whose heights above the floor differ by more than the correspondence distance are
   dropped, and a RANSAC over pairs of matches (seeded per restart) finds the yaw and floor
   shift that most matches agree with;
3. each start is refined by the shared ICP pyramid (six degrees of freedom), and the best fit kept.

Without a floor in both maps (or ``floor=False``) the global search is RANSAC over six degrees
of freedom, as :func:`register_maps` does.

The result is checked (:func:`check_alignment`) against :data:`DEFAULT_CHECKS`: the share of the
robot's structure off its large planes that lies on the person's map (a floor and walls fit
any two rooms once levelled), how many restarts agree, the inlier RMSE, and, with floors, whether the floors
still coincide after the free ICP. The thresholds and how they were chosen (validation scenes and
the kitchen's development frames): docs/recordings.md, "A person and a robot".
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..io import SemanticMap
from .floors import Floor, camera_up, fit_floor, label_up
from .registration import (
    Registration,
    fpfh_features,
    map_clouds,
    ransac_starts,
    refine_starts,
    transform_error,
)

__all__ = [
    "Floor",
    "AlignmentResult",
    "AlignmentRefused",
    "DEFAULT_CHECKS",
    "align_to_map",
    "fit_floor",
    "check_alignment",
    "camera_up",
    "label_up",
    "recording_poses",
    "align_recording",
    "write_aligned_poses",
]

#: refusal thresholds of :func:`check_alignment` (docs/recordings.md, "A person and a robot", says
#: how they were chosen: validation scenes and the kitchen's development frames only)
DEFAULT_CHECKS: dict[str, float] = {
    "min_structure_fitness": 0.305,  # share of source points off the large planes within check_distance of the target
    "min_agreement": 0.5,  # share of restarts that reached the kept transform
    "max_inlier_rmse": 0.03,  # m, at the finest ICP level
    "max_floor_angle": 3.0,  # degrees between the aligned floors (with floors only)
    "max_floor_offset": 0.05,  # m, height between the aligned floors (with floors only)
}


class AlignmentRefused(ValueError):
    """An alignment below the thresholds of :data:`DEFAULT_CHECKS` (the message says which and by how much)."""

    def __init__(self, message: str, result: AlignmentResult) -> None:
        super().__init__(message)
        self.result = result


@dataclass(frozen=True)
class AlignmentResult:
    """The result of :func:`align_to_map`.

    Attributes
    ----------
    transform : ndarray (4, 4)
        Rigid transform taking the source (robot) map's frame into the target (person's) map's.
    registration : Registration
        The underlying registration (fitness and inlier RMSE at the finest ICP level, per-restart
        candidates, ...).
    fitness : float
        Share of the source's points (at ``check_voxel``) within ``check_distance`` of the target.
    structure_fitness : float
        The same share among the source's points off its large planes (floor, walls, ceiling:
        planes holding 5 % of the points or more), which fit any two rooms once levelled.
    overlap : float
        Share of the target's points within ``check_distance`` of the aligned source.
    inlier_rmse : float
        RMSE (m) of the finest ICP level's correspondences.
    agreement : float
        Share of restarts whose start reached the kept transform (``registration.agreement /
        restarts``).
    spread_translation_m, spread_rotation_deg : float
        Largest distance of a restart's transform after its first ICP level from the kept one's.
    floors : tuple of Floor or None
        Source and target floors (None: not both found, the global search was six-dimensional).
    floor_angle_deg, floor_offset_m : float
        With floors: the angle between the aligned source floor and the target floor, and the
        source floor's height above the target floor at its points (NaN without floors).
    constrained : bool
        Whether the global search was over yaw and floor shift only.
    checks : dict
        Per check of :data:`DEFAULT_CHECKS`: ``value``, ``threshold``, ``passed``.
    accepted : bool
        Every check passed.
    seconds : float
    """

    transform: np.ndarray
    registration: Registration = field(repr=False)
    fitness: float
    structure_fitness: float
    overlap: float
    inlier_rmse: float
    agreement: float
    spread_translation_m: float
    spread_rotation_deg: float
    floors: tuple[Floor, Floor] | None
    floor_angle_deg: float
    floor_offset_m: float
    constrained: bool
    checks: dict
    accepted: bool
    seconds: float

    def failures(self) -> list[str]:
        """One sentence per failed check, saying by how much."""
        out = []
        for name, c in self.checks.items():
            if not c["passed"]:
                what = name.removeprefix("min_").removeprefix("max_")
                rel = "below the minimum" if name.startswith("min_") else "above the maximum"
                out.append(f"{what} {c['value']:.3g} is {rel} {c['threshold']:.3g}")
        return out

    def as_dict(self) -> dict:
        """JSON-ready report (transform as a nested list)."""
        return {
            "accepted": bool(self.accepted), "transform": self.transform.tolist(),
            "fitness": self.fitness, "structure_fitness": self.structure_fitness, "overlap": self.overlap,
            "inlier_rmse": self.inlier_rmse, "icp_fitness": float(self.registration.fitness),
            "agreement": self.agreement, "restarts": int(self.registration.restarts),
            "spread_translation_m": self.spread_translation_m, "spread_rotation_deg": self.spread_rotation_deg,
            "constrained": bool(self.constrained),
            "floor": None if self.floors is None else {
                "source": self.floors[0].as_dict(), "target": self.floors[1].as_dict(),
                "angle_deg": self.floor_angle_deg, "offset_m": self.floor_offset_m},
            "checks": self.checks, "seconds": self.seconds,
        }


def _mutual_matches(f_src: np.ndarray, f_dst: np.ndarray) -> np.ndarray:
    """Index pairs (i, j) of mutual nearest neighbours in feature space."""
    from scipy.spatial import cKDTree

    a, b = f_src.T, f_dst.T  # Open3D features are (dim, n)
    j = cKDTree(b).query(a, k=1)[1]
    i = cKDTree(a).query(b, k=1)[1]
    keep = i[j] == np.arange(len(a))
    return np.c_[np.flatnonzero(keep), j[keep]]


def _planar_rigid(a: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray]:
    """Least-squares yaw and shift ``(theta, t)`` with ``R(theta) a + t ~ b`` in the plane (2-D Procrustes)."""
    ma, mb = a.mean(0), b.mean(0)
    xa, xb = a - ma, b - mb
    theta = float(np.arctan2((xa[:, 0] * xb[:, 1] - xa[:, 1] * xb[:, 0]).sum(), (xa * xb).sum()))
    c, s = np.cos(theta), np.sin(theta)
    t = mb - np.array([[c, -s], [s, c]]) @ ma
    return theta, t


def _yaw_shift(theta: float, t: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = t
    return T


def _floor_starts(clouds, floors: tuple[Floor, Floor], voxel_size: float, *, seed: int, restarts: int,
                  hypotheses: int) -> list[dict]:
    """Global starts over yaw and floor shift (step 2 of the module documentation), one per restart."""
    src, dst = clouds.source_down, clouds.target_down
    Ls, Lt = floors[0].levelling(), floors[1].levelling()
    a = np.asarray(src.points) @ Ls[:3, :3].T + Ls[:3, 3]
    b = np.asarray(dst.points) @ Lt[:3, :3].T + Lt[:3, 3]
    dist = 1.5 * voxel_size
    m = _mutual_matches(np.asarray(fpfh_features(src, voxel_size).data),
                        np.asarray(fpfh_features(dst, voxel_size).data))
    m = m[np.abs(a[m[:, 0], 2] - b[m[:, 1], 2]) <= dist]  # same height above the floor
    # off the floor only: floor points all look alike
    m = m[(a[m[:, 0], 2] > 2 * voxel_size) | (b[m[:, 1], 2] > 2 * voxel_size)]
    starts = []
    for k in range(int(restarts)):
        rng = np.random.default_rng(int(seed) + k)
        best_n, best = 0, None
        if len(m) >= 2:
            pa, pb = a[m[:, 0]], b[m[:, 1]]
            for _ in range(max(1, int(hypotheses) // 2000)):
                i, j = rng.integers(0, len(m), size=(2, 2000))
                da, db = pa[j, :2] - pa[i, :2], pb[j, :2] - pb[i, :2]
                la, lb = np.linalg.norm(da, axis=1), np.linalg.norm(db, axis=1)
                ok = (la > 2 * voxel_size) & (np.abs(la - lb) <= dist)  # a rigid motion keeps lengths
                i, j, da, db = i[ok], j[ok], da[ok], db[ok]
                if not len(i):
                    continue
                th = np.arctan2(db[:, 1], db[:, 0]) - np.arctan2(da[:, 1], da[:, 0])
                c, s = np.cos(th), np.sin(th)
                t = pb[i, :2] - np.c_[c * pa[i, 0] - s * pa[i, 1], s * pa[i, 0] + c * pa[i, 1]]
                # inliers of every hypothesis, in chunks (hypotheses x matches)
                for h0 in range(0, len(th), 256):
                    cc, ss, tt = c[h0:h0 + 256, None], s[h0:h0 + 256, None], t[h0:h0 + 256]
                    x = cc * pa[None, :, 0] - ss * pa[None, :, 1] + tt[:, :1] - pb[None, :, 0]
                    y = ss * pa[None, :, 0] + cc * pa[None, :, 1] + tt[:, 1:] - pb[None, :, 1]
                    n = ((x * x + y * y) <= dist * dist).sum(axis=1)
                    h = int(np.argmax(n))
                    if n[h] > best_n:
                        best_n, best = int(n[h]), (float(th[h0 + h]), tt[h].copy())
        if best is None:
            starts.append(dict(seed=int(seed) + k, global_fitness=0.0, global_transform=np.eye(4)))
            continue
        theta, t = best
        # least squares on the hypothesis' inliers
        pa, pb = a[m[:, 0]], b[m[:, 1]]
        Tl = _yaw_shift(theta, t)
        moved = pa @ Tl[:3, :3].T + Tl[:3, 3]
        inl = np.sum((moved[:, :2] - pb[:, :2]) ** 2, axis=1) <= dist * dist
        if inl.sum() >= 2:
            Tl = _yaw_shift(*_planar_rigid(pa[inl, :2], pb[inl, :2]))
        T0 = np.linalg.inv(Lt) @ Tl @ Ls
        starts.append(dict(seed=int(seed) + k, global_fitness=float(inl.mean()) if len(m) else 0.0,
                           global_transform=T0))
    return starts


def _near_share(src_pts: np.ndarray, dst_cloud, distance: float) -> np.ndarray:
    """Per source point: whether a target point lies within ``distance``."""
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src_pts))
    return np.asarray(pc.compute_point_cloud_distance(dst_cloud)) <= distance


def _on_large_planes(pts: np.ndarray, distance: float, *, seed: int, min_share: float = 0.05,
                     max_planes: int = 8) -> np.ndarray:
    """Per point: whether it lies on one of the map's large planes (floor, walls, ceiling, ...).

    Planes are peeled off by RANSAC (``segment_plane``) while each holds at least ``min_share``
    of the points. Two rooms' large planes can be laid onto each other whatever the rooms are;
    what is left (furniture, objects, corners) tells a right alignment from a wrong one.
    """
    import open3d as o3d

    on = np.zeros(len(pts), bool)
    left = np.arange(len(pts))
    o3d.utility.random.seed(int(seed))
    for _ in range(int(max_planes)):
        if len(left) < 10:
            break
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts[left]))
        _, inl = pc.segment_plane(distance_threshold=distance, ransac_n=3, num_iterations=500)
        if len(inl) < min_share * len(pts):
            break
        on[left[inl]] = True
        left = np.delete(left, inl)
    return on


def check_alignment(values: dict, checks: dict | None = None) -> dict:
    """The refusal checks of an alignment: per check ``value``, ``threshold``, ``passed``.

    Parameters
    ----------
    values : dict
        ``structure_fitness``, ``agreement``, ``inlier_rmse``, and (with floors) ``floor_angle_deg``,
        ``floor_offset_m`` (NaN or absent: that check is skipped).
    checks : dict, optional
        Thresholds replacing those of :data:`DEFAULT_CHECKS` (same keys).

    Returns
    -------
    dict

    Raises
    ------
    ValueError
        An unknown check name.
    """
    th = dict(DEFAULT_CHECKS)
    unknown = sorted(set(checks or {}) - set(th))
    if unknown:
        raise ValueError(f"unknown alignment checks {unknown}; known: {', '.join(th)}")
    th.update(checks or {})
    source = {"min_structure_fitness": "structure_fitness", "min_agreement": "agreement",
              "max_inlier_rmse": "inlier_rmse", "max_floor_angle": "floor_angle_deg",
              "max_floor_offset": "floor_offset_m"}
    out = {}
    for name, key in source.items():
        v = values.get(key, float("nan"))
        if v is None or not np.isfinite(v):
            if name.startswith("max_floor"):
                continue
            v = float("nan")
        v = abs(float(v)) if name == "max_floor_offset" else float(v)
        passed = bool(v >= th[name]) if name.startswith("min_") else bool(v <= th[name])
        out[name] = {"value": v, "threshold": float(th[name]), "passed": passed}
    return out


def align_to_map(
    source: SemanticMap,
    target: SemanticMap,
    *,
    source_up: np.ndarray | None = None,
    target_up: np.ndarray | None = None,
    floor: bool = True,
    voxel_size: float = 0.1,
    seed: int = 0,
    restarts: int = 4,
    hypotheses: int = 20_000,
    max_iterations: int = 100_000,
    confidence: float = 0.999,
    icp_voxels: Sequence[float] = (0.05, 0.025),
    icp_iterations: int = 50,
    check_voxel: float = 0.02,
    check_distance: float = 0.03,
    checks: dict | None = None,
    threads: int | None = 1,
) -> AlignmentResult:
    """Align the robot's map (``source``) into the person's map (``target``) and check the result.

    See the module documentation. The result is returned whether or not it passes its checks
    (``accepted``; :meth:`AlignmentResult.failures` says why not); the caller refuses.

    Parameters
    ----------
    source, target : SemanticMap
        Maps in metres (meshes or point clouds), each in its own recording's frame.
    source_up, target_up : array-like (3,), optional
        Up hints (e.g. :func:`camera_up` of the recording's poses, :func:`label_up`, or the
        world's +z); without both, no floor constraint.
    floor : bool
        Constrain the global search by the floors when both are found.
    voxel_size : float
        Feature voxel (m): FPFH radius ``5 * voxel_size``, correspondence distance ``1.5 * voxel_size``.
    seed, restarts : int
        Restart ``k`` draws its hypotheses from ``seed + k``.
    hypotheses : int
        Yaw-and-shift hypotheses per restart (floor-constrained search).
    max_iterations, confidence : int, float
        RANSAC of the six-dimensional search (as :func:`register_maps`).
    icp_voxels, icp_iterations
        ICP levels after the one at ``voxel_size`` (as :func:`register_maps`).
    check_voxel, check_distance : float
        The source is downsampled at ``check_voxel`` and a point counts as on the target when one
        lies within ``check_distance`` (m) (``fitness``, ``structure_fitness``, ``overlap``).
    checks : dict, optional
        Thresholds replacing those of :data:`DEFAULT_CHECKS`.
    threads : int or None
        Open3D threads (one: the same result run to run).

    Returns
    -------
    AlignmentResult

    Raises
    ------
    ValueError
        Bad maps or settings (as :func:`register_maps`), an unknown check.
    """
    from .rgbd_odometry import open3d_threads

    check_alignment({}, checks)  # unknown names before any work
    if threads is not None and int(threads) < 1:
        raise ValueError(f"threads must be >= 1 or None, got {threads}")
    if int(restarts) < 1:
        raise ValueError(f"restarts must be >= 1, got {restarts}")
    with open3d_threads(int(threads)) if threads is not None else contextlib.nullcontext():
        return _align(source, target, source_up=source_up, target_up=target_up, floor=floor, voxel_size=voxel_size,
                      seed=seed, restarts=restarts, hypotheses=hypotheses, max_iterations=max_iterations,
                      confidence=confidence, icp_voxels=icp_voxels, icp_iterations=icp_iterations,
                      check_voxel=check_voxel, check_distance=check_distance, checks=checks)


def _align(source, target, *, source_up, target_up, floor, voxel_size, seed, restarts, hypotheses, max_iterations,
           confidence, icp_voxels, icp_iterations, check_voxel, check_distance, checks) -> AlignmentResult:
    """:func:`align_to_map` under its thread limit."""
    t0 = time.perf_counter()
    clouds = map_clouds(source, target, voxel_size)
    floors = None
    if floor and source_up is not None and target_up is not None:
        fs = fit_floor(clouds.source_down, source_up, voxel_size, seed=seed)
        ft = fit_floor(clouds.target_down, target_up, voxel_size, seed=seed)
        floors = (fs, ft) if fs is not None and ft is not None else None
    if floors is not None:
        starts = _floor_starts(clouds, floors, voxel_size, seed=seed, restarts=restarts, hypotheses=hypotheses)
    else:
        starts = ransac_starts(clouds, voxel_size, seed=seed, restarts=restarts, max_iterations=max_iterations,
                               confidence=confidence)
    reg = refine_starts(clouds, starts, voxel_size, icp_voxels=icp_voxels, icp_iterations=icp_iterations, t0=t0)
    T = reg.transform
    # spread: each restart's first ICP level against the kept one's
    kept = next(c for c in reg.candidates if np.array_equal(c["transform"], T))["coarse_transform"]
    errs = np.array([transform_error(c["coarse_transform"], kept) for c in reg.candidates
                     if c["global_fitness"] > 0] or [(0.0, 0.0)])
    # fitness at a fixed distance, on and off the floor, and the target share covered
    src = np.asarray(clouds.source.voxel_down_sample(check_voxel).points)
    moved = src @ T[:3, :3].T + T[:3, 3]
    near = _near_share(moved, clouds.target, check_distance)
    off = ~_on_large_planes(src, check_distance / 2, seed=seed)
    angle, offset = float("nan"), float("nan")
    if floors is not None:
        fs, ft = floors
        on = moved[np.abs(src @ fs.normal + fs.offset) <= check_distance]
        n_moved = T[:3, :3] @ fs.normal
        angle = float(np.degrees(np.arccos(np.clip(n_moved @ ft.normal, -1.0, 1.0))))
        offset = float(np.median(on @ ft.normal + ft.offset)) if len(on) else float("nan")
    dst = np.asarray(clouds.target.voxel_down_sample(check_voxel).points)
    src_pc = clouds.source.voxel_down_sample(check_voxel).transform(T)
    overlap = float(_near_share(dst, src_pc, check_distance).mean())
    values = dict(fitness=float(near.mean()), structure_fitness=float(near[off].mean()) if off.any() else 0.0,
                  overlap=overlap, inlier_rmse=float(reg.inlier_rmse), agreement=reg.agreement / reg.restarts,
                  floor_angle_deg=angle, floor_offset_m=offset)
    result_checks = check_alignment(values, checks)
    return AlignmentResult(
        transform=T, registration=reg, fitness=values["fitness"], structure_fitness=values["structure_fitness"],
        overlap=overlap, inlier_rmse=values["inlier_rmse"], agreement=values["agreement"],
        spread_translation_m=float(errs[:, 0].max()), spread_rotation_deg=float(errs[:, 1].max()),
        floors=floors, floor_angle_deg=angle, floor_offset_m=offset, constrained=floors is not None,
        checks=result_checks, accepted=all(c["passed"] for c in result_checks.values()),
        seconds=time.perf_counter() - t0,
    )


def recording_poses(seq, *, estimate: bool = False, progress: bool = False) -> np.ndarray:
    """A recording's poses in its own frame: the recorded ones, or RGB-D odometry from the identity.

    Parameters
    ----------
    seq : sequence of Frame
        E.g. :func:`semmatch.io.recordings.read_recording`.
    estimate : bool
        Ignore recorded poses and estimate them (:func:`semmatch.poses.odometry.estimate_poses`,
        hybrid residual, pose graph: ``reconstruct --estimate-poses``'s chain, from the identity).
    progress : bool

    Raises
    ------
    ValueError
        No recorded pose for some frame and ``estimate`` off (the message names ``--estimate-poses``).
    """
    if estimate:
        from .odometry import estimate_poses

        return estimate_poses(seq, init_pose=np.eye(4), progress=progress)
    poses = getattr(seq, "poses", None)
    name = getattr(seq, "path", "the recording")
    if poses is None:
        raise ValueError(f"{name} has no recorded poses; pass --estimate-poses to estimate them by RGB-D odometry")
    poses = np.asarray(poses, dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(poses).all(axis=(1, 2)))
    if len(bad):
        raise ValueError(f"{name} has no recorded pose for {len(bad)} of {len(poses)} frames (first: frame "
                         f"{bad[0]}); pass --estimate-poses to estimate them by RGB-D odometry")
    return poses


def align_recording(seq, poses: np.ndarray, person_map: SemanticMap, *, person_up: np.ndarray | str | None = "auto",
                    map_voxel: float = 0.04, progress: bool = False,
                    **settings) -> tuple[AlignmentResult, np.ndarray, SemanticMap]:
    """Fuse a robot's recording on its own poses and align the map into the person's map.

    Parameters
    ----------
    seq : sequence of Frame
    poses : ndarray (N, 4, 4)
        The recording's poses in its own frame (:func:`recording_poses`).
    person_map : SemanticMap
    person_up : array-like (3,), "auto" or None
        The person's map's up hint: a vector, ``"auto"`` (its floor-labelled points,
        :func:`label_up`; none when it has too few) or None (no floor constraint).
    map_voxel : float
        TSDF voxel (m) of the robot's map.
    progress : bool
    **settings
        Passed to :func:`align_to_map`.

    Returns
    -------
    result : AlignmentResult
    poses_in_person : ndarray (N, 4, 4)
        ``result.transform @ poses``.
    robot_map : SemanticMap
        The robot's map in its own frame.
    """
    from ..fusion import extract, fuse_sequence

    vol = fuse_sequence(seq, poses=poses, voxel_size=map_voxel, progress=progress)
    robot_map = extract(vol, "mesh")
    if isinstance(person_up, str):
        if person_up != "auto":
            raise ValueError(f"person_up must be a 3-vector, 'auto' or None, got {person_up!r}")
        person_up = label_up(person_map)
    result = align_to_map(robot_map, person_map, source_up=camera_up(poses), target_up=person_up, **settings)
    return result, result.transform @ np.asarray(poses, dtype=np.float64), robot_map


def write_aligned_poses(path, timestamps: np.ndarray, poses: np.ndarray, result: AlignmentResult, *,
                        forced: bool = False, person_map: str = "") -> dict:
    """Write the robot's poses in the person's frame (TUM, atomic) and the report beside them.

    The TUM file's header comments and the report (``<path>.json``) say whether the alignment
    passed its checks or was forced (``--accept-weak-alignment``). Readers of TUM (evo, semmatch)
    skip the comments.

    Returns
    -------
    dict
        The report as written.
    """
    from pathlib import Path

    from ..io import atomic_write_text, write_json
    from ..io.geometry import pose_to_tum

    path = Path(path)
    status = "accepted" if result.accepted else "FORCED: below the checks (--accept-weak-alignment): " + "; ".join(
        result.failures())
    lines = ["# timestamp tx ty tz qx qy qz qw (T_world_camera)",
             f"# semmatch align: robot poses in the frame of {person_map or 'the person map'}; alignment {status}"]
    for t, T in zip(np.asarray(timestamps, dtype=np.float64), poses, strict=True):
        lines.append(f"{t:.6f} " + " ".join(f"{x:.9f}" for x in pose_to_tum(T)))
    report = {"poses": str(path), "person_map": person_map, "forced": bool(forced and not result.accepted),
              **result.as_dict()}
    write_json(Path(f"{path}.json"), report)
    atomic_write_text(path, "\n".join(lines) + "\n")
    return report
