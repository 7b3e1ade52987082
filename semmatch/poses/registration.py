"""Register two reconstructions of one room without ground truth, as a real user must.

The person's upper map and the robot's lower reconstruction are each built in the frame of its
own recording (the first camera pose), so before labels can be transferred the lower map must be
registered onto the upper one from geometry alone. :func:`register_maps` does what Open3D's
global-registration pipeline does [1]_ [2]_:

1. both maps' vertices (sorted, so that their order does not matter) are voxel-downsampled
   (``voxel_size``), with normals (from the mesh triangles when there are any, so that they
   point to the side the camera saw);
2. FPFH features (radius ``5 * voxel_size``) are matched and a rigid transform is found by
   RANSAC (``registration_ransac_based_on_feature_matching``, mutual filter, edge-length and
   distance checkers), seeded through ``o3d.utility.random.seed``;
3. each RANSAC result is refined by point-to-plane ICP at ``voxel_size`` (correspondences up
   to twice the voxel);
4. every distinct result (restarts that agree within ``2 * voxel_size`` and 2 degrees share
   one) is refined from coarse to fine (``icp_voxels``: 4, 2, 1 cm), and the one that fits best
   at the finest level (highest fitness, then lowest inlier RMSE) is kept. A fit at the coarse
   level alone also rewards wrong alignments of a small room (a 90-degree turn of a 24-frame
   bedroom map scored 0.93 at 20 cm).

The same inputs and seed give the same transform up to the rounding of Open3D's parallel sums
(1e-9 on the matrix entries in the tests).

The two maps of this project overlap only partly (the robot at 0.2 m sees under tables, the
person at 1.6 m sees the tops; often 30-70 % of either map), so ``fitness`` is a share of the
*source* points that found a target surface, not a proof of success; ``agreement`` (how many
restarts reached the kept transform) is a better sign of a unique solution. How it fares on the validation scenes:
docs/protocol.md ("Registration").

References
----------
.. [1] R. B. Rusu, N. Blodow, M. Beetz, "Fast Point Feature Histograms (FPFH) for 3D
   registration", ICRA 2009.
.. [2] Open3D, "Global registration" (``open3d.pipelines.registration``).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..io import SemanticMap

__all__ = ["Registration", "register_maps", "rigid_perturbation", "transform_error", "MapClouds", "map_clouds",
           "fpfh_features", "ransac_starts", "refine_starts"]


@dataclass(frozen=True)
class Registration:
    """The result of :func:`register_maps`.

    Attributes
    ----------
    transform : ndarray (4, 4)
        Rigid transform taking the source map into the target map's frame.
    fitness : float
        Share of the (finest-level) source points with a target point within the finest ICP
        correspondence distance (twice the finest voxel of ``icp_voxels``) after the transform.
    inlier_rmse : float
        RMSE (m) of those correspondences.
    global_transform : ndarray (4, 4)
        The RANSAC transform the kept candidate's ICP started from.
    global_fitness : float
        RANSAC fitness of that transform (correspondence distance ``1.5 * voxel_size``).
    restarts : int
        RANSAC runs made (seeds ``seed .. seed + restarts - 1``).
    agreement : int
        How many of them ended, after the ICP at ``voxel_size``, within ``2 * voxel_size`` and 2
        degrees of the kept one (itself included), counting only restarts whose RANSAC found a
        transform (fitness > 0): restarts that found none all start their ICP from the identity
        and would agree with each other by construction. 0 when the kept transform comes from
        such restarts only (before 2026-11-27 they counted, so a failure could read as agreement).
    candidates : list of dict
        Per restart: ``seed``, ``global_fitness`` (RANSAC), ``coarse_fitness``, ``coarse_rmse``,
        ``coarse_transform`` (ICP at ``voxel_size``), ``fitness``, ``inlier_rmse``, ``transform``
        (after the finest level; shared by restarts that agree).
    n_source, n_target : int
        Points after downsampling at ``voxel_size`` (those the features describe).
    seconds : float
        Wall time.
    """

    transform: np.ndarray
    fitness: float
    inlier_rmse: float
    global_transform: np.ndarray
    global_fitness: float
    restarts: int
    agreement: int
    candidates: list = field(repr=False)
    n_source: int = 0
    n_target: int = 0
    seconds: float = 0.0


def _point_cloud(m: SemanticMap, what: str):
    """Legacy Open3D point cloud of a map's vertices, with normals when they can be had.

    The vertices are sorted (lexicographically), so that two maps holding the same vertices in
    another order (two Open3D fusions of the same frames) give the same cloud, hence the same
    features and the same RANSAC samples.
    """
    import open3d as o3d

    if not isinstance(m, SemanticMap):
        raise TypeError(f"{what}: expected a SemanticMap, got {type(m).__name__}")
    m.check()
    pts = m.points.astype(np.float64)
    normals = None
    if m.is_mesh:  # normals from the triangles: they point to the side the camera saw
        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(pts), o3d.utility.Vector3iVector(m.faces))
        mesh.compute_vertex_normals()
        normals = np.asarray(mesh.vertex_normals)
    elif m.normals is not None and len(m.normals) == len(m.points):
        normals = m.normals.astype(np.float64)
    order = np.lexsort(pts.T[::-1])
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts[order]))
    if normals is not None:
        pc.normals = o3d.utility.Vector3dVector(normals[order])
    return pc


def _downsample(pc, voxel: float):
    """Voxel-downsampled cloud with normals re-estimated at this scale (orientation kept)."""
    import open3d as o3d

    d = pc.voxel_down_sample(voxel)
    d.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2.0 * voxel, max_nn=30))
    return d


def _close(a: np.ndarray, b: np.ndarray, voxel_size: float) -> bool:
    """Whether two transforms agree within ``2 * voxel_size`` and 2 degrees."""
    dt, dr = transform_error(a, b)
    return dt <= 2.0 * voxel_size and dr <= 2.0


def transform_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation (degrees) of ``inv(truth) @ estimate``.

    Parameters
    ----------
    estimate, truth : ndarray (4, 4)
        Rigid transforms.

    Returns
    -------
    translation_m, rotation_deg : float
        The translation is the displacement of the origin of the transforms' source frame.
    """
    E = np.linalg.inv(np.asarray(truth, dtype=np.float64)) @ np.asarray(estimate, dtype=np.float64)
    cos = np.clip((np.trace(E[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.linalg.norm(E[:3, 3])), float(np.degrees(np.arccos(cos)))


def register_maps(
    source: SemanticMap,
    target: SemanticMap,
    *,
    voxel_size: float = 0.1,
    seed: int = 0,
    restarts: int = 3,
    max_iterations: int = 100_000,
    confidence: float = 0.999,
    icp_voxels: Sequence[float] = (0.04, 0.02, 0.01),
    icp_iterations: int = 50,
    threads: int | None = 1,
) -> Registration:
    """Rigid transform taking ``source`` into ``target``'s frame, from geometry alone.

    FPFH features + RANSAC (global, seeded), refined by coarse-to-fine point-to-plane ICP; see
    the module documentation. Labels are ignored.

    Parameters
    ----------
    source, target : SemanticMap
        Reconstructions (meshes or point clouds) of overlapping parts of one scene, in metres.
    voxel_size : float
        Downsampling voxel (m) of the features; FPFH radius ``5 * voxel_size``, RANSAC
        correspondence distance ``1.5 * voxel_size``.
    seed : int
        Seed of the first RANSAC run (``o3d.utility.random.seed``); restart ``k`` uses
        ``seed + k``. The same inputs and seed give the same result.
    restarts : int
        RANSAC runs; the best refined candidate is kept.
    max_iterations : int
        RANSAC iterations per run.
    confidence : float
        RANSAC stops early once this confidence is reached.
    icp_voxels : sequence of float
        Finer ICP levels (m) after the one at ``voxel_size``; those not below ``voxel_size``
        are skipped. Each level downsamples both maps at its voxel and takes correspondences
        up to twice its voxel. The finest level sets the accuracy (on noise-free rendered maps
        of a bedroom, features at 5 cm and a finest level of 1.25 cm: 0.3 cm and 0.04 degrees;
        features at 10 cm and a finest level of 2.5 cm: 0.9 cm and 0.12 degrees).
    icp_iterations : int
        ICP iterations per level.
    threads : int or None
        Open3D threads for the run (:func:`semmatch.poses.rgbd_odometry.open3d_threads`). RANSAC's
        result depends on the thread count and, with more than one thread, differs between runs
        (two threads: two runs of one scene, two transforms); one thread (the default) repeats
        itself run to run. None: every core, faster on a machine to oneself, not repeatable.

    Returns
    -------
    Registration

    Raises
    ------
    TypeError
        Inputs that are not :class:`~semmatch.io.SemanticMap`.
    ValueError
        An empty map or NaN vertices (naming the map's file), non-positive ``voxel_size``,
        ``restarts`` below 1, or too few points left after downsampling.
    """
    import contextlib

    from .rgbd_odometry import open3d_threads

    if threads is not None and int(threads) < 1:
        raise ValueError(f"threads must be >= 1 or None, got {threads}")
    with open3d_threads(int(threads)) if threads is not None else contextlib.nullcontext():
        return _register(source, target, voxel_size=voxel_size, seed=seed, restarts=restarts,
                         max_iterations=max_iterations, confidence=confidence, icp_voxels=icp_voxels,
                         icp_iterations=icp_iterations)


def _register(source: SemanticMap, target: SemanticMap, *, voxel_size: float, seed: int, restarts: int,
              max_iterations: int, confidence: float, icp_voxels: Sequence[float], icp_iterations: int) -> Registration:
    """:func:`register_maps` under its thread limit."""
    t0 = time.perf_counter()
    clouds = map_clouds(source, target, voxel_size)
    starts = ransac_starts(clouds, voxel_size, seed=seed, restarts=restarts, max_iterations=max_iterations,
                           confidence=confidence)
    return refine_starts(clouds, starts, voxel_size, icp_voxels=icp_voxels, icp_iterations=icp_iterations, t0=t0)


@dataclass
class MapClouds:
    """Both maps of a registration as Open3D clouds: in full (``source``, ``target``) and
    downsampled at the feature voxel with normals (``source_down``, ``target_down``)."""

    source: object
    target: object
    source_down: object
    target_down: object


def map_clouds(source: SemanticMap, target: SemanticMap, voxel_size: float) -> MapClouds:
    """The clouds :func:`register_maps` works on (step 1 of the module documentation).

    Parameters
    ----------
    source, target : SemanticMap
    voxel_size : float
        Feature voxel (m).

    Returns
    -------
    MapClouds

    Raises
    ------
    ValueError
        Non-positive ``voxel_size``, an empty map, or fewer than 10 points left at ``voxel_size``
        (naming the map's file).
    """
    if not voxel_size > 0:
        raise ValueError(f"voxel_size must be > 0, got {voxel_size}")
    src_full = _point_cloud(source, "source")
    dst_full = _point_cloud(target, "target")
    src, dst = _downsample(src_full, voxel_size), _downsample(dst_full, voxel_size)
    for pc, m, what in ((src, source, "source"), (dst, target, "target")):
        if len(pc.points) < 10:
            raise ValueError(f"{what} map {m.source}: only {len(pc.points)} points at a {voxel_size} m voxel; "
                             "too few to register")
    return MapClouds(src_full, dst_full, src, dst)


def fpfh_features(cloud, voxel_size: float):
    """FPFH features (radius ``5 * voxel_size``, up to 100 neighbours) of a downsampled cloud with normals."""
    import open3d as o3d

    feature = o3d.geometry.KDTreeSearchParamHybrid(radius=5.0 * voxel_size, max_nn=100)
    return o3d.pipelines.registration.compute_fpfh_feature(cloud, feature)


def ransac_starts(clouds: MapClouds, voxel_size: float, *, seed: int, restarts: int, max_iterations: int,
                  confidence: float) -> list[dict]:
    """Global starts of :func:`register_maps`: FPFH + RANSAC, once per restart (step 2).

    Returns
    -------
    list of dict
        Per restart: ``seed``, ``global_fitness`` (0: RANSAC found nothing; its transform is then
        the identity), ``global_transform``.
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    if int(restarts) < 1:
        raise ValueError(f"restarts must be >= 1, got {restarts}")
    src, dst = clouds.source_down, clouds.target_down
    f_src, f_dst = fpfh_features(src, voxel_size), fpfh_features(dst, voxel_size)
    dist = 1.5 * voxel_size
    starts = []
    for k in range(int(restarts)):
        o3d.utility.random.seed(int(seed) + k)
        ransac = reg.registration_ransac_based_on_feature_matching(
            src, dst, f_src, f_dst, True, dist, reg.TransformationEstimationPointToPoint(False), 3,
            [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(dist)],
            reg.RANSACConvergenceCriteria(int(max_iterations), float(confidence)),
        )
        starts.append(dict(seed=int(seed) + k, global_fitness=float(ransac.fitness),
                           global_transform=np.asarray(ransac.transformation).copy()))
    return starts


def refine_starts(clouds: MapClouds, starts: list[dict], voxel_size: float, *, icp_voxels: Sequence[float],
                  icp_iterations: int, t0: float | None = None) -> Registration:
    """ICP from every global start, coarse to fine, and the best fit kept (steps 3 and 4).

    Parameters
    ----------
    clouds : MapClouds
    starts : list of dict
        ``seed``, ``global_fitness`` (a start with fitness 0 is no vote in ``agreement``) and
        ``global_transform`` each (:func:`ransac_starts`, or another global search).
    voxel_size : float
        Feature voxel (m): the first ICP level, and the scale of agreement (``2 * voxel_size``, 2 degrees).
    icp_voxels, icp_iterations
        As :func:`register_maps`.
    t0 : float, optional
        ``time.perf_counter()`` at the start of the registration (for ``seconds``).

    Returns
    -------
    Registration
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    t0 = time.perf_counter() if t0 is None else t0
    levels = sorted((float(v) for v in icp_voxels if 0 < float(v) < voxel_size), reverse=True)
    src_full, dst_full, src, dst = clouds.source, clouds.target, clouds.source_down, clouds.target_down
    point_to_plane = reg.TransformationEstimationPointToPlane()
    criteria = reg.ICPConvergenceCriteria(max_iteration=int(icp_iterations))

    def icp(s, d, v: float, T: np.ndarray):
        res = reg.registration_icp(s, d, 2.0 * v, T, point_to_plane, criteria)
        return np.asarray(res.transformation).copy(), float(res.fitness), float(res.inlier_rmse)

    # every restart: ICP at the feature voxel (cheap)
    candidates = []
    for start in starts:
        T0 = np.asarray(start["global_transform"], dtype=np.float64).copy()
        T, fit, rmse = icp(src, dst, voxel_size, T0)
        candidates.append(dict(seed=int(start["seed"]), global_fitness=float(start["global_fitness"]),
                               global_transform=T0, coarse_fitness=fit, coarse_rmse=rmse, coarse_transform=T))
    # the finer levels for every distinct candidate (restarts that agree share one refinement):
    # a coarse fit, with correspondences up to twice the feature voxel, also rewards wrong
    # alignments of a small room; the finest level tells them apart
    pyramid: list = []
    refined: list[dict] = []  # distinct candidates: coarse transform, refined result, members
    for c in sorted(candidates, key=lambda c: -c["coarse_fitness"]):
        same = next((r for r in refined if _close(c["coarse_transform"], r["coarse_transform"], voxel_size)), None)
        if same is None:
            if not pyramid:
                pyramid = [(src_full.voxel_down_sample(v), _downsample(dst_full, v), v) for v in levels]
            T, fit, rmse = c["coarse_transform"], c["coarse_fitness"], c["coarse_rmse"]
            for s, d, v in pyramid:  # the source needs no normals for point-to-plane ICP
                T, fit, rmse = icp(s, d, v, T)
            same = dict(coarse_transform=c["coarse_transform"], transform=T, fitness=fit, inlier_rmse=rmse,
                        first=c, members=0)
            refined.append(same)
        same["members"] += c["global_fitness"] > 0  # a failed RANSAC (identity, fitness 0) is no vote
        c.update(transform=same["transform"], fitness=same["fitness"], inlier_rmse=same["inlier_rmse"])
    best = max(refined, key=lambda r: (round(r["fitness"], 6), -r["inlier_rmse"]))
    T, fit, rmse, agreement = best["transform"], best["fitness"], best["inlier_rmse"], best["members"]
    best = best["first"]
    return Registration(
        transform=T, fitness=fit, inlier_rmse=rmse,
        global_transform=best["global_transform"], global_fitness=best["global_fitness"],
        restarts=len(starts), agreement=agreement,
        candidates=[{k: v for k, v in c.items() if k not in ("global_transform",)} for c in candidates],
        n_source=len(src.points), n_target=len(dst.points), seconds=time.perf_counter() - t0,
    )


def rigid_perturbation(
    translation_m: float,
    rotation_deg: float,
    *,
    center: np.ndarray,
    seed: int = 0,
) -> np.ndarray:
    """A rigid transform of known size: a rotation about a random axis through ``center``, then a shift.

    The axis and the shift's direction are drawn (uniformly on the sphere) from ``seed`` in
    that order, independently of the magnitudes, so that a series of magnitudes with one seed
    moves along the same axis and direction.

    Parameters
    ----------
    translation_m : float
        Length (m) of the translation, >= 0.
    rotation_deg : float
        Rotation angle (degrees), >= 0.
    center : array-like (3,)
        A point of the rotation axis (e.g. the map's centroid), so that the rotation does not
        also move the map by ``|center| * angle``.
    seed : int

    Returns
    -------
    ndarray (4, 4)
        ``T`` with ``T[:3, :3]`` a rotation by ``rotation_deg`` and
        ``|T @ center - center| = translation_m``.
    """
    import open3d as o3d

    if not (np.isfinite(translation_m) and translation_m >= 0 and np.isfinite(rotation_deg) and rotation_deg >= 0):
        raise ValueError(f"translation_m and rotation_deg must be finite and >= 0, got {translation_m}, {rotation_deg}")
    c = np.asarray(center, dtype=np.float64).reshape(-1)
    if c.shape != (3,) or not np.isfinite(c).all():
        raise ValueError(f"center must be a finite 3-vector, got {center!r}")
    rng = np.random.default_rng(seed)
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    direction = rng.standard_normal(3)
    direction /= np.linalg.norm(direction)
    R = o3d.geometry.get_rotation_matrix_from_axis_angle(axis * np.radians(rotation_deg))
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = c - R @ c + float(translation_m) * direction
    return T
