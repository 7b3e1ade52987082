"""An independent evaluation reference: the ground-truth mesh where the lower camera saw it.

The default reference of a lower-view semantic map is the same frames fused with ground-truth
labels, so the prediction and its reference share the geometry and registration (errors of the
depth, the poses or the TSDF never count). :func:`observed_reference` builds a reference that
shares nothing with the prediction but the set of surfaces the camera looked at:

1. the ground-truth semantic mesh (``scene.ply``, a :class:`semmatch.sim.Scene`) is sampled
   uniformly on its surface, about one point per ``spacing**2`` of area, each point carrying
   the label of its triangle (:func:`sample_surface`);
2. a sample point is kept when at least one frame observed it: it projects into the image in
   front of the camera, the depth measured there is valid and equals the point's depth within
   ``tolerance`` (so occluded points, those outside the frustum and those beyond the sensor's
   range are dropped).

Score a lower-view map against it with :func:`semmatch.evaluate.metrics.compare`::

    ref = observed_reference("data/.../scenes/eval/s0/scene.ply", read_sequence(".../lower"))
    compare(ref, "lower_3d-neighborhood.ply", 0.05)

Everything is vectorised NumPy. The samples are sorted into spatial blocks; for each frame,
only the blocks whose bounding box meets the frame's viewing frustum (between the nearest and
the farthest valid depth) and only the points not yet observed are projected.

One module (over 500 lines): surface sampling, the block store of observed points and the reference
built from them share one sampling of the mesh.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..fusion.reconstruction import _check_poses
from ..io import Frame, SemanticMap, check_depth_units, read_map
from ..io.geometry import Intrinsics, check_pose, sample_mesh_at_random, triangle_labels

if TYPE_CHECKING:
    from ..sim.scene import Scene

__all__ = ["SurfaceSamples", "triangle_labels", "sample_surface", "observed_reference"]

#: refuse surface samples beyond this many points (about 1.3 GB at the peak, ~1 min of work)
MAX_POINTS = 20_000_000

#: steepest surface (angle between its normal and the viewing ray) whose depth is interpolated
#: between pixels; depth edges steeper than this are not interpolated across
_MAX_INCIDENCE_DEG = 85.0

#: points generated per step while sampling (bounds the float64 temporaries)
_CHUNK = 1 << 21


class SurfaceSamples(NamedTuple):
    """Points sampled on the surface of a mesh (see :func:`sample_surface`).

    Attributes
    ----------
    points : float32 (N,3)
        World coordinates.
    labels : uint8 (N,)
        Label of each point's triangle.
    triangle : int32 (N,)
        Index of the triangle each point lies on.
    face_normals : float32 (T,3)
        Unit normal of every triangle (its winding order); ``face_normals[triangle]`` are the
        points' normals.
    source : str
        The mesh sampled (file name or ``scene:<name>``), for messages.
    """

    points: np.ndarray
    labels: np.ndarray
    triangle: np.ndarray
    face_normals: np.ndarray
    source: str


def _mesh_arrays(
    mesh: SemanticMap | Scene | str | os.PathLike,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """``(vertices float64 (V,3), faces int64 (T,3), triangle labels uint8 (T,), source)``."""
    if isinstance(mesh, str | os.PathLike):
        mesh = read_map(Path(mesh))
    # a semmatch.sim.Scene, known by its per-triangle labels (the evaluation does not import the
    # simulator: its figures are drawn by semmatch.plots, which draws the measures' intervals)
    if not isinstance(mesh, SemanticMap) and all(hasattr(mesh, a) for a in ("vertices", "triangles", "labels")):
        vertices, faces, labels = mesh.vertices, mesh.triangles, mesh.labels
        source = f"scene:{mesh.name}"
        if not np.isfinite(vertices).all():
            n_bad = int((~np.isfinite(vertices).all(axis=1)).sum())
            raise ValueError(f"{source}: {n_bad} vertices hold NaN or inf")
    elif isinstance(mesh, SemanticMap):
        source = mesh.source
        if not mesh.is_mesh:
            raise ValueError(
                f"{source}: the ground-truth map has no faces ({len(mesh)} points); the reference "
                "needs a triangle mesh such as scene.ply"
            )
        mesh.check()  # empty / NaN vertices, with the file name
        vertices, faces = mesh.points, mesh.faces
        labels = triangle_labels(faces, mesh.labels)
    else:
        raise TypeError(
            f"mesh: expected a SemanticMap with faces, a PLY path or a semmatch.sim.Scene, got "
            f"{type(mesh).__name__}"
        )
    return np.asarray(vertices, np.float64), np.asarray(faces, np.int64), labels, source


def sample_surface(
    mesh: SemanticMap | Scene | str | os.PathLike,
    spacing: float = 0.01,
    *,
    seed: int = 0,
    max_points: int = MAX_POINTS,
) -> SurfaceSamples:
    """Sample a labelled mesh uniformly on its surface, about one point per ``spacing**2``.

    Each triangle receives ``floor(area / spacing**2 + U)`` points (``U`` uniform in [0, 1):
    the expected count is exactly proportional to its area, with less spread than drawing the
    triangles at random), placed uniformly with barycentric coordinates
    ``(1 - sqrt(r1), sqrt(r1) (1 - r2), sqrt(r1) r2)`` (:func:`semmatch.io.geometry.sample_mesh_at_random`).

    Parameters
    ----------
    mesh : SemanticMap, path or semmatch.sim.Scene
        Semantic triangle mesh: per-vertex labels (a triangle takes the majority, see
        :func:`triangle_labels`) or a Scene with per-triangle labels.
    spacing : float
        Mean distance between neighbouring samples (metres).
    seed : int
        Seed of the sampler (same seed, same points).
    max_points : int
        Refuse when the expected number of points exceeds this.

    Returns
    -------
    SurfaceSamples

    Raises
    ------
    ValueError
        A mesh without faces, with NaN vertices or without area; a non-positive spacing; more
        than ``max_points`` samples (the message gives the area and a spacing that fits).
    """
    if not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing must be > 0 (metres), got {spacing}")
    vertices, faces, tri_labels, source = _mesh_arrays(mesh)
    a = vertices[faces[:, 0]]
    cross = np.cross(vertices[faces[:, 1]] - a, vertices[faces[:, 2]] - a)
    double_area = np.linalg.norm(cross, axis=1)
    total = 0.5 * float(double_area.sum())
    expected = total / spacing**2
    if expected > max_points:
        raise ValueError(
            f"{source}: {total:.1f} m² of surface at {spacing} m spacing is about {expected:,.0f} "
            f"points, more than the limit of {max_points:,}; use spacing >= "
            f"{np.sqrt(total / max_points):.3g} m"
        )
    points, tri = sample_mesh_at_random(vertices, faces, 0.5 * double_area / spacing**2, np.random.default_rng(seed),
                                        form="edges", chunk=_CHUNK, dtype=np.float32)
    if len(points) == 0:
        raise ValueError(
            f"{source}: no surface sample ({total:.3g} m² of triangles at {spacing} m spacing); "
            "is the mesh degenerate or the spacing too large?"
        )
    normals = (cross / np.maximum(double_area, 1e-300)[:, None]).astype(np.float32)
    return SurfaceSamples(points, tri_labels[tri], tri, normals, source)


def _affine(R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Float32 ``(A, b)`` with camera coordinates ``A @ p + b`` for ``T_world_camera = [R | t]``."""
    A = R.T.astype(np.float32)
    return A, (-(R.T @ t)).astype(np.float32)


def _apply(A: np.ndarray, b: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> list[np.ndarray]:
    """``A @ p + b`` for points given as three coordinate arrays.

    Column by column: NumPy's ``(N,3) @ (3,3)`` takes tens of times longer than these six
    vector operations per coordinate.
    """
    return [A[j, 0] * x + A[j, 1] * y + A[j, 2] * z + b[j] for j in range(3)]


class _Blocks:
    """Sample points sorted into spatial blocks, with each block's bounding-box corners.

    Coordinates are kept as three contiguous float32 rows ``xyz`` (3,N) for fast gathers.
    """

    def __init__(self, points: np.ndarray, block: float = 0.25) -> None:
        lo = points.min(axis=0)
        extent = float((points.max(axis=0) - lo).max())
        block = max(block, extent / 1023.0)  # at most 1024 blocks per axis: keys fit in 30 bits
        key = np.zeros(len(points), dtype=np.int64)
        for j in range(3):  # one axis at a time: no (N,3) int64 temporary
            key |= ((points[:, j] - lo[j]) / np.float32(block)).astype(np.int64) << (20 - 10 * j)
        self.order = np.argsort(key, kind="stable")
        key = key[self.order]
        self.xyz = np.empty((3, len(points)), dtype=np.float32)
        for j in range(3):
            self.xyz[j] = points[self.order, j]
        self.starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        self.counts = np.diff(np.r_[self.starts, len(key)])
        del key
        bmin = np.minimum.reduceat(self.xyz, self.starts, axis=1)  # (3,B)
        bmax = np.maximum.reduceat(self.xyz, self.starts, axis=1)
        sel = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=bool).T  # (3,8)
        corners = np.where(sel[:, None], bmax[..., None], bmin[..., None])  # (3,B,8)
        self.corners = corners.reshape(3, -1)

    def __len__(self) -> int:
        return self.xyz.shape[1]

    def in_frustum(
        self, A: np.ndarray, b: np.ndarray, intr: Intrinsics, z_near: float, z_far: float
    ) -> np.ndarray:
        """Bool (B,): blocks whose box is not entirely outside one plane of the frustum.

        The frustum is bounded by the planes through the outer edges of the border pixels
        (``-0.5 <= u < W - 0.5``, same for ``v``) and by ``z_near <= z <= z_far``.
        """
        x, y, z = (c.reshape(-1, 8) for c in _apply(A, b, *self.corners))
        H, W = intr.shape
        fx, fy, cx, cy = (np.float32(v) for v in (intr.fx, intr.fy, intr.cx, intr.cy))
        planes = (
            z - np.float32(z_near),
            np.float32(z_far) - z,
            fx * x + (cx + np.float32(0.5)) * z,
            (np.float32(W - 0.5) - cx) * z - fx * x,
            fy * y + (cy + np.float32(0.5)) * z,
            (np.float32(H - 0.5) - cy) * z - fy * y,
        )
        vis = np.ones(len(x), dtype=bool)
        for p in planes:
            vis &= (p >= 0).any(axis=1)
        return vis

    def observe(
        self,
        observed: np.ndarray,
        depth: np.ndarray,
        valid: np.ndarray,
        pose: np.ndarray,
        intr: Intrinsics,
        tolerance: float,
    ) -> None:
        """Mark in ``observed`` the points that one frame measured (see :func:`observed_reference`)."""
        d_valid = depth[valid]
        z_near = max(float(d_valid.min()) - tolerance, 1e-6)
        z_far = float(d_valid.max()) + tolerance
        A, b = _affine(pose[:3, :3], pose[:3, 3])
        vis = self.in_frustum(A, b, intr, z_near, z_far)
        cand = np.repeat(vis, self.counts)
        cand &= ~observed
        idx = np.flatnonzero(cand)
        if idx.size == 0:
            return
        x, y, z = _apply(A, b, *(np.take(c, idx) for c in self.xyz))
        H, W = intr.shape
        with np.errstate(divide="ignore", invalid="ignore"):
            u = x / z
            u *= np.float32(intr.fx)
            u += np.float32(intr.cx)
            v = y / z
            v *= np.float32(intr.fy)
            v += np.float32(intr.cy)
        half = np.float32(0.5)
        inside = z >= np.float32(z_near)
        inside &= z <= np.float32(z_far)
        inside &= u >= -half
        inside &= u < np.float32(W) - half
        inside &= v >= -half
        inside &= v < np.float32(H) - half
        keep = np.flatnonzero(inside)
        idx, z, u, v = (np.take(a, keep) for a in (idx, z, u, v))
        flat_d, flat_ok = depth.reshape(-1), valid.reshape(-1)
        # nearest pixel (u, v >= -0.5 here, so truncation is the floor)
        pix = (v + half).astype(np.int32) * W + (u + half).astype(np.int32)
        hit = np.take(flat_ok, pix) & (np.abs(z - np.take(flat_d, pix)) <= np.float32(tolerance))
        observed[idx[hit]] = True
        # the rest: inverse depth interpolated between the four surrounding pixels
        rest = np.flatnonzero(~hit)
        if rest.size == 0 or W < 2 or H < 2:
            return
        idx, z, u, v = (np.take(a, rest) for a in (idx, z, u, v))
        u0 = np.clip(np.floor(u), 0, W - 2)
        v0 = np.clip(np.floor(v), 0, H - 2)
        fu = np.clip(u - u0, 0, 1)
        fv = np.clip(v - v0, 0, 1)
        inv = np.zeros_like(flat_d)
        np.divide(1.0, flat_d, out=inv, where=flat_ok)
        p00 = v0.astype(np.int32) * W + u0.astype(np.int32)
        quad = (p00, p00 + 1, p00 + W, p00 + W + 1)
        corner = [np.take(inv, q) for q in quad]  # 0 where the depth is invalid
        lo = np.minimum(np.minimum(corner[0], corner[1]), np.minimum(corner[2], corner[3]))
        hi = np.maximum(np.maximum(corner[0], corner[1]), np.maximum(corner[2], corner[3]))
        # one surface: all four valid and no depth edge between them (a plane at up to
        # _MAX_INCIDENCE_DEG changes depth by at most z tan(angle) / f per pixel, sqrt(2) z
        # tan(angle) / f across the quad); interpolating across an edge would invent depths
        # between the foreground and the background
        spread = np.sqrt(2.0) * np.tan(np.deg2rad(_MAX_INCIDENCE_DEG)) / min(intr.fx, intr.fy)
        spread = np.float32(spread)
        smooth = (lo > 0) & (hi <= lo * (1 + spread))
        w = ((1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv)
        inv_z = sum(wk * ck for wk, ck in zip(w, corner))
        with np.errstate(divide="ignore"):
            hit = smooth & (np.abs(z - 1.0 / inv_z) <= np.float32(tolerance))
        observed[idx[hit]] = True


def _strided_frames(
    frames: Sequence[Frame] | Iterable[Frame], poses: np.ndarray | None, stride: int, name: str
) -> Iterator[tuple[int, Frame, np.ndarray]]:
    """Yield ``(i, frame, pose)`` for every ``stride``-th frame; lazy readers load only those."""
    if isinstance(frames, Sequence) or (hasattr(frames, "__len__") and hasattr(frames, "__getitem__")):
        items: Iterable[tuple[int, Frame]] = ((i, frames[i]) for i in range(0, len(frames), stride))
    else:
        items = ((i, f) for i, f in enumerate(frames) if i % stride == 0)
    for i, frame in items:
        where = f"{name} frame {getattr(frame, 'index', i)}"
        if poses is not None:
            if i >= len(poses):
                raise ValueError(f"{where}: only {len(poses)} poses were given")
            pose = poses[i]
        else:
            pose = getattr(frame, "pose", None)
            if pose is None:
                raise ValueError(f"{where}: no pose (pass poses=..., e.g. the true poses)")
        yield i, frame, check_pose(pose, what=f"{where} pose")


def observed_reference(
    mesh: SemanticMap | Scene | str | os.PathLike,
    frames: Sequence[Frame] | Iterable[Frame],
    *,
    poses: np.ndarray | None = None,
    spacing: float = 0.01,
    tolerance: float = 0.03,
    stride: int = 1,
    max_depth: float | None = None,
    progress: bool = False,
    seed: int = 0,
    max_points: int = MAX_POINTS,
) -> SemanticMap:
    """The ground-truth mesh, sampled on its surface, where the frames observed it.

    A surface sample (:func:`sample_surface`) is observed when, in at least one of the frames
    used (every ``stride``-th), it lies in front of the camera, projects inside the image, and
    the depth measured there is valid (> 0, and <= ``max_depth`` when given) and within
    ``tolerance`` of the point's depth along the optical axis, i.e. the measured surface is the
    point itself (occluded points fail). The measured depth at the point's sub-pixel position
    is taken two ways and either may match: the nearest pixel's depth, and the bilinear
    interpolation of inverse depth over the four surrounding pixels when all four are valid and
    no depth edge lies between them (their depths differ by no more than a plane seen at 85 deg
    from its normal allows). The interpolation is exact on planes, so surfaces seen at grazing
    angles, e.g. the floor from a robot, are not lost to the depth change across one pixel; at
    a crease (a box standing on the floor) it can admit a few points of the hidden face within
    about a pixel's footprint of the visible edge.

    Parameters
    ----------
    mesh : SemanticMap, path or semmatch.sim.Scene
        The ground-truth semantic mesh, e.g. ``read_map(".../scenes/eval/<id>/scene.ply")``
        (per-vertex labels; a triangle takes its vertices' majority label) or the
        :class:`~semmatch.sim.Scene` itself (per-triangle labels).
    frames : sequence of Frame
        Posed depth frames, e.g. :func:`semmatch.io.read_sequence` (only the frames used are
        read) or its ``load()``; depth in metres, 0 = no measurement.
    poses : ndarray (N, 4, 4), optional
        ``T_world_camera`` per frame replacing the frames' poses (e.g. the true poses of a
        recording with pose noise).
    spacing : float
        Surface sample spacing (metres); use at most half the evaluation voxel.
    tolerance : float
        Largest depth difference (metres) between a point and the measured surface.
    stride : int
        Use every ``stride``-th frame.
    max_depth : float, optional
        Ignore depth measurements beyond this distance (metres).
    progress : bool
        Show a tqdm bar over the frames.
    seed : int
        Seed of the surface sampler.
    max_points : int
        Refuse surface samples of more points than this (suggests a larger ``spacing``).

    Returns
    -------
    SemanticMap
        Point cloud (no faces) of the observed samples in the mesh's (world) frame, with
        ``labels`` (their triangles' labels), ``normals`` (their triangles' normals) and a
        ``source`` naming the mesh and the sequence.

    Raises
    ------
    ValueError
        A mesh without faces or area, NaN vertices, too many samples; no frames, a frame
        without pose, a pose that is not a finite rigid transform, ``poses`` of the wrong shape
        or count, depth whose shape disagrees with the intrinsics (all naming the frame);
        non-positive ``spacing``, ``tolerance``, ``stride`` or ``max_depth``; no observed point
        (naming the sequence).

    Notes
    -----
    The reference is exact geometry, so the voxel measures of :func:`semmatch.evaluate.metrics.compare`
    now count every geometric error of a reconstruction, including the TSDF's own: Open3D's
    fusion places surfaces seen at oblique angles up to about a centimetre off (docs/metrics.md),
    so a planar surface lying within that distance of a voxel boundary (axis-aligned walls at round coordinates) is split between
    two voxel layers and even the ground-truth-labelled fusion scores well below 1.

    Examples
    --------
    >>> from semmatch.io import read_sequence                       # doctest: +SKIP
    >>> from semmatch.evaluate.metrics import compare
    >>> ref = observed_reference("data/full/scenes/eval/s0/scene.ply",
    ...                          read_sequence("data/full/scenes/eval/s0/lower"))
    >>> compare(ref, "lower_3d-neighborhood.ply", 0.05)["mean_acc"]
    """
    from ..runtime.progress import tqdm

    if not (np.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance must be > 0 (metres), got {tolerance}")
    if int(stride) != stride or stride < 1:
        raise ValueError(f"stride must be a positive integer, got {stride}")
    stride = int(stride)
    if max_depth is not None and not (np.isfinite(max_depth) and max_depth > 0):
        raise ValueError(f"max_depth must be > 0 (metres) or None, got {max_depth}")
    name = str(getattr(frames, "path", "sequence"))
    try:
        n_frames, poses = _check_poses(frames, poses)
    except ValueError as e:
        raise ValueError(f"{name}: {e}") from None
    if n_frames == 0:
        raise ValueError(f"{name}: the sequence has no frames")

    samples = sample_surface(mesh, spacing, seed=seed, max_points=max_points)
    mesh_source = samples.source
    blocks = _Blocks(samples.points)
    samples = samples._replace(points=None)  # the blocks hold the coordinates now
    observed = np.zeros(len(blocks), dtype=bool)
    used = 0
    total = None if n_frames is None else len(range(0, n_frames, stride))
    it = _strided_frames(frames, poses, stride, name)
    for i, frame, pose in tqdm(it, total=total, desc="reference", disable=not progress, leave=False):
        where = f"{name} frame {getattr(frame, 'index', i)}"
        intr = getattr(frame, "intrinsics", None) or getattr(frames, "intrinsics", None)
        if not isinstance(intr, Intrinsics):
            raise ValueError(f"{where}: no camera intrinsics")
        depth = np.asarray(frame.depth)
        if depth.shape != intr.shape:
            raise ValueError(
                f"{where}: depth has shape {depth.shape} but the intrinsics say (H, W) = {intr.shape}"
            )
        check_depth_units(depth, where=where)
        used += 1
        depth = depth.astype(np.float32, copy=False)
        valid = np.isfinite(depth) & (depth > 0)
        if max_depth is not None:
            valid &= depth <= max_depth
        if not valid.any():
            continue
        blocks.observe(observed, depth, valid, pose, intr, tolerance)
    if used == 0:
        raise ValueError(f"{name}: the sequence has no frames")
    if not observed.any():
        raise ValueError(
            f"{name}: no point of {mesh_source} ({len(blocks):,} surface samples) was observed by "
            f"the {used} frame(s) used within {tolerance} m; are the poses in the mesh's frame "
            "and the depth in metres?"
        )
    keep = blocks.order[observed]  # sample indices, in block order (spatially coherent)
    return SemanticMap(
        blocks.xyz[:, observed].T,
        samples.labels[keep],
        normals=samples.face_normals[samples.triangle[keep]],
        source=f"{mesh_source} observed in {name}",
    )
