"""Camera geometry (intrinsics, poses, back-projection, projection, voxel keys) and the sampling of
labelled triangle meshes (a barycentric grid, uniform random points, per-triangle labels).

Conventions (docs/data.md): world in metres with z up; camera frame OpenCV (x right, y down,
z forward); a pose is ``T_world_camera`` (4x4, camera to world).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = [
    "Intrinsics",
    "DEFAULT_INTRINSICS",
    "check_pose",
    "quat_to_rotation",
    "rotation_to_quat",
    "pose_from_tum",
    "pose_to_tum",
    "look_at",
    "backproject",
    "pixel_rays",
    "project",
    "transform",
    "voxel_keys",
    "pack_keys",
    "unpack_keys",
    "MAX_MESH_SAMPLES",
    "triangle_labels",
    "longest_edges",
    "mesh_sample_count",
    "mesh_sample_pieces",
    "sample_mesh",
    "sample_mesh_at_random",
]


#: largest image (pixels) an :class:`Intrinsics` accepts: 8K is 33 M; a frame costs ~40 bytes a pixel
MAX_PIXELS = 64 * 2**20


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a depth-registered RGB-D camera.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    fx, fy, cx, cy : float
        Focal lengths and principal point in pixels.
    depth_scale : float
        Depth PNG value per metre (1000 = millimetres).
    """

    width: int = 640
    height: int = 480
    fx: float = 268.51
    fy: float = 268.51
    cx: float = 320.0
    cy: float = 240.0
    depth_scale: float = 1000.0

    def __post_init__(self) -> None:
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        if int(self.width) * int(self.height) > MAX_PIXELS:
            raise ValueError(f"image size {self.width}x{self.height} ({int(self.width) * int(self.height):,} pixels) "
                             f"is larger than any RGB-D camera's (limit {MAX_PIXELS:,} pixels)")
        for name in ("fx", "fy"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"focal length {name} must be > 0, got {v}")
        for name in ("cx", "cy"):
            if not np.isfinite(float(getattr(self, name))):
                raise ValueError(f"principal point {name} must be finite")
        if not float(self.depth_scale) > 0:
            raise ValueError(f"depth_scale must be > 0, got {self.depth_scale}")

    @property
    def K(self) -> np.ndarray:
        """The 3x3 camera matrix."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``."""
        return int(self.height), int(self.width)

    def to_dict(self) -> dict:
        """Return the ``intrinsics.json`` dictionary."""
        d = asdict(self)
        d["width"], d["height"] = int(self.width), int(self.height)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Intrinsics:
        """Build from an ``intrinsics.json`` dictionary (``depth_scale`` defaults to 1000)."""
        missing = [k for k in ("width", "height", "fx", "fy", "cx", "cy") if k not in d]
        if missing:
            raise ValueError(f"intrinsics lack {', '.join(missing)}")
        return cls(
            width=int(d["width"]),
            height=int(d["height"]),
            fx=float(d["fx"]),
            fy=float(d["fy"]),
            cx=float(d["cx"]),
            cy=float(d["cy"]),
            depth_scale=float(d.get("depth_scale", 1000.0)),
        )

    def scaled(self, width: int, height: int) -> Intrinsics:
        """Intrinsics of the same camera resampled to ``width`` x ``height``."""
        sx, sy = width / self.width, height / self.height
        return Intrinsics(
            width, height, self.fx * sx, self.fy * sy,
            (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5, self.depth_scale,
        )


#: The paper's Habitat camera: 640x480, fx = fy = 268.51, principal point at the centre.
DEFAULT_INTRINSICS = Intrinsics()


def check_pose(pose: np.ndarray, *, what: str = "pose", atol: float = 1e-4) -> np.ndarray:
    """Validate a 4x4 rigid transform and return it as float64.

    Raises
    ------
    ValueError
        If the matrix is not 4x4, holds NaN/inf, its last row is not ``0 0 0 1`` or its
        rotation block is not a rotation (orthonormal with determinant +1).
    """
    T = np.asarray(pose, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"{what}: expected a 4x4 matrix, got shape {T.shape}")
    if not np.isfinite(T).all():
        raise ValueError(f"{what}: holds NaN or inf")
    if not np.allclose(T[3], [0, 0, 0, 1], atol=atol):
        raise ValueError(f"{what}: last row must be [0 0 0 1], got {T[3]}")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-3) or np.linalg.det(R) < 0:
        raise ValueError(f"{what}: the 3x3 block is not a rotation matrix")
    return T


def quat_to_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrices from unit quaternions ``(qx, qy, qz, qw)``; shape (..., 4) -> (..., 3, 3)."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < 1e-12) or not np.isfinite(q).all():
        raise ValueError("quaternion must be finite and non-zero")
    x, y, z, w = np.moveaxis(q / n, -1, 0)
    R = np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    )
    return R.reshape(q.shape[:-1] + (3, 3))


def rotation_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(qx, qy, qz, qw)`` with ``qw >= 0`` of a 3x3 rotation matrix."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        q = [0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif R[1, 1] > R[2, 2]:
        s = np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        q = [(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s]
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def pose_from_tum(values: np.ndarray) -> np.ndarray:
    """4x4 pose from TUM values ``tx ty tz qx qy qz qw``."""
    v = np.asarray(values, dtype=np.float64)
    T = np.eye(4)
    T[:3, :3] = quat_to_rotation(v[3:7])
    T[:3, 3] = v[:3]
    return T


def pose_to_tum(pose: np.ndarray) -> np.ndarray:
    """TUM values ``tx ty tz qx qy qz qw`` of a 4x4 pose."""
    T = check_pose(pose)
    return np.concatenate([T[:3, 3], rotation_to_quat(T[:3, :3])])


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera pose ``T_world_camera`` at ``eye`` looking at ``target`` (OpenCV camera axes)."""
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: viewing direction is parallel to the up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T


def pixel_rays(intr: Intrinsics, stride: int = 1) -> np.ndarray:
    """Camera-frame ray directions with ``z = 1`` for every ``stride``-th pixel, shape (h, w, 3)."""
    v, u = np.mgrid[0 : intr.height : stride, 0 : intr.width : stride].astype(np.float32)
    x = (u - np.float32(intr.cx)) / np.float32(intr.fx)
    y = (v - np.float32(intr.cy)) / np.float32(intr.fy)
    return np.stack([x, y, np.ones_like(x)], axis=-1)


def transform(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Apply a 4x4 rigid transform to (N,3) points (float32 result for float32 input)."""
    T = np.asarray(T)
    dtype = points.dtype if np.issubdtype(points.dtype, np.floating) else np.float64
    return (points @ T[:3, :3].T.astype(dtype)) + T[:3, 3].astype(dtype)


def backproject(
    depth: np.ndarray,
    intr: Intrinsics,
    pose: np.ndarray | None = None,
    *,
    stride: int = 1,
    max_depth: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Back-project a depth image to 3D points.

    Parameters
    ----------
    depth : ndarray, shape (H, W)
        Metric depth (float, metres); 0 or non-finite = no measurement.
    intr : Intrinsics
        Camera intrinsics; ``(H, W)`` must match.
    pose : ndarray (4, 4), optional
        ``T_world_camera``; points are returned in the world frame when given.
    stride : int
        Keep every ``stride``-th pixel in each direction.
    max_depth : float, optional
        Ignore measurements beyond this distance.

    Returns
    -------
    points : ndarray of float32, shape (N, 3)
    index : ndarray of int64, shape (N,)
        Flat pixel index ``v * W + u`` of each point in the full-resolution image.
    """
    depth = np.asarray(depth)
    if depth.shape != intr.shape:
        raise ValueError(f"depth is {depth.shape[::-1]} (WxH) but intrinsics say {intr.width}x{intr.height}")
    d = depth[::stride, ::stride].astype(np.float32, copy=False)
    valid = np.isfinite(d) & (d > 0)
    if max_depth is not None:
        valid &= d <= max_depth
    rows, cols = np.nonzero(valid)
    z = d[rows, cols]
    v = rows * stride
    u = cols * stride
    x = (u.astype(np.float32) - np.float32(intr.cx)) * (z / np.float32(intr.fx))
    y = (v.astype(np.float32) - np.float32(intr.cy)) * (z / np.float32(intr.fy))
    pts = np.stack([x, y, z], axis=1)
    if pose is not None:
        pts = transform(pts, check_pose(pose)).astype(np.float32)
    return pts, v.astype(np.int64) * intr.width + u


def project(
    points: np.ndarray, intr: Intrinsics, pose: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Project 3D points into the image.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        World points (camera points when ``pose`` is None).
    intr : Intrinsics
    pose : ndarray (4, 4), optional
        ``T_world_camera``.

    Returns
    -------
    uv : ndarray of float64, shape (N, 2)
        Pixel coordinates ``(u, v)``; ``(u, v) = (0, 0)`` is the centre of the top-left pixel.
    z : ndarray of float64, shape (N,)
        Depth along the optical axis (<= 0: behind the camera).
    """
    p = np.asarray(points, dtype=np.float64)
    if pose is not None:
        p = transform(p, np.linalg.inv(check_pose(pose)))
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = intr.fx * p[:, 0] / z + intr.cx
        v = intr.fy * p[:, 1] / z + intr.cy
    return np.stack([u, v], axis=1), z


def voxel_keys(points: np.ndarray, voxel_size: float, origin: np.ndarray | None = None) -> np.ndarray:
    """Integer voxel coordinates ``floor((xyz - origin) / voxel_size)``, shape (N, 3) int64."""
    if not voxel_size > 0:
        raise ValueError(f"voxel_size must be > 0, got {voxel_size}")
    p = np.asarray(points, dtype=np.float64)
    if origin is not None:
        p = p - np.asarray(origin, dtype=np.float64)
    return np.floor(p / voxel_size).astype(np.int64)


def pack_keys(keys: np.ndarray) -> np.ndarray:
    """Pack (N,3) int64 voxel coordinates into one int64 per voxel (21 bits per axis).

    Coordinates must lie in ``[-2**20, 2**20)``: about ±52 km at 5 cm voxels.
    """
    k = np.asarray(keys, dtype=np.int64)
    lim = 1 << 20
    if k.size and (k.min() < -lim or k.max() >= lim):
        raise ValueError("voxel coordinates out of the packable range ±2**20")
    k = k + lim
    return (k[:, 0] << 42) | (k[:, 1] << 21) | k[:, 2]


def unpack_keys(packed: np.ndarray) -> np.ndarray:
    """Inverse of :func:`pack_keys`: (N,) int64 packed keys to (N,3) int64 voxel coordinates."""
    p = np.asarray(packed, dtype=np.int64)
    mask = (1 << 21) - 1
    return np.stack([(p >> 42) & mask, (p >> 21) & mask, p & mask], axis=1) - (1 << 20)


# ------------------------------------------------------------------ labelled triangle meshes
# One barycentric-grid sampler (the map index, the measures' densifying of coarse meshes, the
# point map of a mesh), one random surface sampler (the observed reference, the obstacles of a
# trajectory) and one triangle-label rule, shared by every part that samples a mesh.

#: most samples :func:`sample_mesh` makes by default (held in memory at once; a map in millimetres
#: would ask for billions). Callers that reduce the samples piece by piece (the map index) pass
#: their own limit.
MAX_MESH_SAMPLES = 60_000_000

_TIES = ("smallest", "first")
_LABEL_RULES = ("vertex", "triangle")
_FORMS = ("weights", "edges")


def triangle_labels(faces: np.ndarray, vertex_labels: np.ndarray, *, ties: str = "smallest") -> np.ndarray:
    """Per-triangle labels of a vertex-labelled mesh: the majority of the three vertex labels.

    Parameters
    ----------
    faces : int (T,3)
        Vertex indices of the triangles.
    vertex_labels : uint8 (V,)
        Label of each vertex.
    ties : {"smallest", "first"}
        The label of a triangle whose three labels all differ: the smallest id (the rule of the
        measures and the observed reference) or the first vertex's (the simulator's PLY scenes).

    Returns
    -------
    uint8 (T,)
    """
    lab = np.asarray(vertex_labels)[np.asarray(faces)]
    if ties == "smallest":
        lab3 = np.sort(lab.astype(np.int64), axis=1)
        # sorted (a, b, c): a majority exists iff a == b or b == c, and then it is b
        return np.where(lab3[:, 1] == lab3[:, 2], lab3[:, 1], lab3[:, 0]).astype(np.uint8)
    if ties == "first":
        l0, l1, l2 = lab[:, 0], lab[:, 1], lab[:, 2]
        return np.where((l0 == l1) | (l0 == l2), l0, np.where(l1 == l2, l1, l0)).astype(np.uint8)
    raise ValueError(f"ties must be one of {_TIES}, got {ties!r}")


def longest_edges(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Length of each triangle's longest edge (float64 (T,))."""
    v = np.asarray(points, dtype=np.float64)[faces]
    edges = np.stack([v[:, 1] - v[:, 0], v[:, 2] - v[:, 1], v[:, 0] - v[:, 2]], axis=1)
    return np.linalg.norm(edges, axis=2).max(axis=1)


def _subdivisions(points: np.ndarray, faces: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """``n = max(1, ceil(longest edge / spacing))`` of each triangle, and its longest edge."""
    if not spacing > 0:
        raise ValueError(f"spacing must be > 0, got {spacing}")
    longest = longest_edges(points, faces)
    return np.maximum(1, np.ceil(longest / spacing)).astype(np.int64), longest


def mesh_sample_count(points: np.ndarray, faces: np.ndarray, spacing: float, *, limit: int = MAX_MESH_SAMPLES,
                      source: str = "") -> int:
    """Number of samples :func:`sample_mesh` makes, refused above ``limit`` before any is made.

    Parameters
    ----------
    points : float (V,3)
    faces : int (T,3)
    spacing : float
        As :func:`sample_mesh`.
    limit : int
        Most samples allowed.
    source : str
        The mesh's name, for the message.

    Returns
    -------
    int

    Raises
    ------
    ValueError
        A non-positive spacing, or more than ``limit`` samples (a map in millimetres, a spacing
        too small).
    """
    n_sub, longest = _subdivisions(points, faces, spacing)
    total = int(((n_sub + 1) * (n_sub + 2) // 2).sum())
    if total > limit:
        raise ValueError(
            f"{source + ': ' if source else ''}sampling the mesh every {spacing:g} m would make {total:,} points "
            f"(limit {limit:,}); its longest edge is {longest.max():.3g}: is the map in metres (not "
            "millimetres)? is the voxel size too small?")
    return total


def mesh_sample_pieces(
    points: np.ndarray, faces: np.ndarray, labels: np.ndarray, spacing: float, *, label: str = "vertex",
    form: str = "weights", chunk_samples: int = 4_000_000, limit: int = MAX_MESH_SAMPLES, source: str = "",
) -> list:
    """:func:`sample_mesh`'s samples as functions that each make one piece when called.

    The pieces (at most about ``chunk_samples`` samples each) can be made one at a time or in
    worker threads; concatenated in order they are :func:`sample_mesh`'s arrays. The sample count
    is checked against ``limit`` at once, before any piece is made.

    Parameters
    ----------
    points, faces, labels, spacing, label, form
        As :func:`sample_mesh`.
    chunk_samples : int
        About the most samples of one piece.
    limit, source
        As :func:`mesh_sample_count`.

    Returns
    -------
    list of callables
        Each returns ``(samples float32 (S,3), sample_labels uint8 (S,))``.
    """
    if label not in _LABEL_RULES or form not in _FORMS:
        raise ValueError(f"label must be one of {_LABEL_RULES} and form one of {_FORMS}, got {label!r}, {form!r}")
    mesh_sample_count(points, faces, spacing, limit=limit, source=source)
    v = np.asarray(points, dtype=np.float64)[faces]  # (T,3,3)
    n_sub = _subdivisions(points, faces, spacing)[0]
    flab = triangle_labels(faces, labels) if label == "triangle" else np.asarray(labels)[faces]
    pieces = []
    for n in np.unique(n_sub):
        sel = np.nonzero(n_sub == n)[0]
        i, j = np.mgrid[0 : n + 1, 0 : n + 1]
        keep = i + j <= n
        bary = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], axis=1).astype(np.float64) / n
        chunk = max(1, chunk_samples // len(bary))
        for s in range(0, len(sel), chunk):
            pieces.append(_GridPiece(v, flab, bary, sel[s : s + chunk], label, form))
    return pieces


class _GridPiece:
    """One piece of :func:`mesh_sample_pieces`: the grid nodes ``bary`` on the triangles ``f``."""

    def __init__(self, v, flab, bary, f, label, form) -> None:
        self.v, self.flab, self.bary, self.f, self.label, self.form = v, flab, bary, f, label, form

    def __call__(self) -> tuple[np.ndarray, np.ndarray]:
        v, bary, f = self.v, self.bary, self.f
        if self.form == "weights":  # node weights (i, j, n-i-j) / n on the corners (v0, v1, v2)
            pts = np.einsum("kc,fcd->fkd", bary, v[f])
        else:  # v0 + i/n (v1 - v0) + j/n (v2 - v0)
            w = bary[:, :2]
            pts = (v[f, 0][:, None] + w[None, :, :1] * (v[f, 1] - v[f, 0])[:, None]
                   + w[None, :, 1:] * (v[f, 2] - v[f, 0])[:, None])
        if self.label == "vertex":  # the corner of largest weight (the nearest vertex)
            lab = self.flab[f][:, np.argmax(bary, axis=1)]
        else:
            lab = np.repeat(self.flab[f], len(bary))
        return pts.reshape(-1, 3).astype(np.float32), lab.reshape(-1).astype(np.uint8)


def sample_mesh(
    points: np.ndarray, faces: np.ndarray, labels: np.ndarray, spacing: float, *, label: str = "vertex",
    form: str = "weights", limit: int = MAX_MESH_SAMPLES, source: str = "",
) -> tuple[np.ndarray, np.ndarray]:
    """Sample a labelled triangle mesh on a barycentric grid.

    Every triangle is split into ``n**2`` sub-triangles with ``n = ceil(longest edge / spacing)``
    and sampled at the grid nodes, triangle by triangle, triangles grouped by ``n`` (ascending).

    Parameters
    ----------
    points : float (V,3)
    faces : int (T,3)
    labels : uint8 (V,)
        Per-vertex labels.
    spacing : float
        Largest distance between neighbouring samples along an edge (metres).
    label : {"vertex", "triangle"}
        A sample's label: that of the triangle vertex with the largest barycentric weight (the
        nearest vertex), or the triangle's majority label (:func:`triangle_labels`).
    form : {"weights", "edges"}
        How a node's point is computed: ``i/n v0 + j/n v1 + (n-i-j)/n v2`` or
        ``v0 + i/n (v1 - v0) + j/n (v2 - v0)``. The same grid, nodes in another order and other
        rounding; each user keeps the form its results were computed with (bit-identical).
    limit, source
        As :func:`mesh_sample_count`.

    Returns
    -------
    samples : float32 (S,3)
    sample_labels : uint8 (S,)

    Raises
    ------
    ValueError
        A non-positive spacing, or more than ``limit`` samples.
    """
    made = [make() for make in mesh_sample_pieces(points, faces, labels, spacing, label=label, form=form,
                                                  limit=limit, source=source)]
    if not made:
        return np.zeros((0, 3), np.float32), np.zeros(0, np.uint8)
    return np.concatenate([p for p, _ in made]), np.concatenate([lab for _, lab in made])


def sample_mesh_at_random(
    points: np.ndarray, faces: np.ndarray, expected: np.ndarray, rng: np.random.Generator, *,
    form: str = "edges", chunk: int | None = 1 << 21, dtype=np.float32,
) -> tuple[np.ndarray, np.ndarray]:
    """Sample triangles uniformly on their surface, a given expected number of points each.

    Triangle ``t`` receives ``floor(expected[t] + U)`` points (``U`` uniform in [0, 1): the
    expected count is exact, with less spread than drawing triangles at random), placed with
    barycentric weights ``(1 - sqrt(r1), sqrt(r1) (1 - r2), sqrt(r1) r2)``. Random numbers are
    drawn in this order: ``U`` for every triangle, then ``r1`` and ``r2`` for each chunk.

    Parameters
    ----------
    points : float (V,3)
    faces : int (T,3)
    expected : float (T,)
        Expected number of points of each triangle (e.g. its area / spacing**2).
    rng : numpy.random.Generator
    form : {"edges", "weights"}
        ``v0 + w1 (v1 - v0) + w2 (v2 - v0)`` or ``w0 v0 + w1 v1 + w2 v2`` (as :func:`sample_mesh`).
    chunk : int or None
        Points made (and random numbers drawn) at a time; None: all at once.
    dtype : numpy dtype
        Of the points returned.

    Returns
    -------
    points : (N,3) of ``dtype``
    triangle : int32 (N,)
        The triangle each point lies on.
    """
    if form not in _FORMS:
        raise ValueError(f"form must be one of {_FORMS}, got {form!r}")
    v = np.asarray(points, dtype=np.float64)[faces]  # (T,3,3)
    counts = np.floor(expected + rng.random(len(v))).astype(np.int64)
    n = int(counts.sum())
    tri = np.repeat(np.arange(len(v), dtype=np.int32 if len(v) < 2**31 else np.int64), counts)
    out = np.empty((n, 3), dtype)
    step = max(1, n if chunk is None else int(chunk))
    for s in range(0, n, step):
        t = tri[s : s + step]
        sq = np.sqrt(rng.random(len(t)))
        r2 = rng.random(len(t))
        c = v[t]
        if form == "edges":
            out[s : s + step] = c[:, 0] + (sq * (1.0 - r2))[:, None] * (c[:, 1] - c[:, 0]) \
                + (sq * r2)[:, None] * (c[:, 2] - c[:, 0])
        else:
            out[s : s + step] = (1 - sq)[:, None] * c[:, 0] + (sq * (1 - r2))[:, None] * c[:, 1] \
                + (sq * r2)[:, None] * c[:, 2]
    return out, tri
