"""Pose-graph refinement of chained RGB-D odometry (neighbour and loop-closure edges).

Edges to the previous few frames and loop-closure edges to earlier keyframes that see the same
surfaces, each a point-to-plane RGB-D registration started from the chained estimate and kept
only when it converged close to it, optimised by Open3D's ``global_optimization``
(Levenberg-Marquardt with line-process pruning of wrong loop closures), as Open3D's
reconstruction system does for its fragments.

Memory does not grow with the pyramids: a frame's depth pyramid (about 14 MB at 640x480 with its
normal maps) is rebuilt on demand and only the most recently used ``cache`` of them are kept
(the current frame, its neighbours, the keyframes it is registered to); the graph keeps the
16-bit depth of the keyframes (0.6 MB each at 640x480, one frame in ``loop_stride``) for the
overlap tests and of the last ``neighbours`` frames. A pyramid is a deterministic function of
its depth image, so the poses do not depend on ``cache``.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Sequence

import numpy as np

from ..runtime.engine import default_device
from .rgbd_odometry import multi_scale_odometry, open3d_threads, rgbd_pyramid
from .trajectory_metrics import rotation_deg

__all__ = ["refine_pose_graph", "CompressedDepths"]


class CompressedDepths(Sequence):
    """16-bit depth images kept PNG-compressed in memory (lossless; a third to a fifth of the raw size).

    ``append`` a (H, W) uint16 image; ``depths[i]`` decodes it again.
    """

    def __init__(self) -> None:
        self._png: list[bytes] = []

    def append(self, depth: np.ndarray) -> None:
        """Compress and keep one (H, W) uint16 depth image."""
        import cv2

        ok, buf = cv2.imencode(".png", np.ascontiguousarray(depth, dtype=np.uint16), [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:
            raise RuntimeError("could not compress a depth image")
        self._png.append(buf.tobytes())

    def __len__(self) -> int:
        return len(self._png)

    def __getitem__(self, i):  # type: ignore[override]
        import cv2

        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        return cv2.imdecode(np.frombuffer(self._png[i], np.uint8), cv2.IMREAD_UNCHANGED)

    @property
    def nbytes(self) -> int:
        """Bytes held."""
        return sum(len(b) for b in self._png)


def _open3d_optimise(poses: np.ndarray, edges: list) -> np.ndarray:
    """Open3D's Levenberg-Marquardt with line process on nodes ``poses`` and ``edges``
    ``(source, target, T_target_source, information, uncertain)``; node 0 is the reference."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    graph = reg.PoseGraph()
    for p in poses:
        graph.nodes.append(reg.PoseGraphNode(p))
    for i, j, T, info, uncertain in edges:
        graph.edges.append(reg.PoseGraphEdge(i, j, T, info, uncertain=uncertain))
    option = reg.GlobalOptimizationOption(max_correspondence_distance=0.03, edge_prune_threshold=0.25,
                                          preference_loop_closure=1.0, reference_node=0)
    level = o3d.utility.get_verbosity_level()
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    try:
        reg.global_optimization(graph, reg.GlobalOptimizationLevenbergMarquardt(),
                                reg.GlobalOptimizationConvergenceCriteria(), option)
    finally:
        o3d.utility.set_verbosity_level(level)
    out = np.stack([np.asarray(node.pose) for node in graph.nodes])
    return poses[0] @ np.linalg.inv(out[0]) @ out  # node 0 stays where it was


def _optimise(poses: np.ndarray, edges: list, max_nodes: int | None) -> np.ndarray:
    """Optimise a pose graph; above ``max_nodes`` nodes in fragments, as Open3D's reconstruction system.

    Open3D's optimiser solves dense normal equations (6N x 6N): +1.1 GB at 1000 nodes, growing
    with the square of N. Above ``max_nodes`` the frames are cut into fragments of ``max_nodes``
    consecutive frames; each fragment's own edges are optimised with its first frame fixed, then
    one node per fragment is optimised with the edges that join fragments (each expressed as a
    motion between the two fragments' first frames), and every frame keeps its place in its
    fragment.
    """
    n = len(poses)
    if max_nodes is None or n <= max_nodes:
        return _open3d_optimise(poses, edges)
    size = max(2, int(max_nodes))
    frag = np.arange(n) // size
    starts = np.arange(0, n, size)
    local = poses.copy()  # optimised within fragments
    for k, s0 in enumerate(starts):
        idx = np.arange(s0, min(s0 + size, n))
        inner = [(i - s0, j - s0, T, info, u) for i, j, T, info, u in edges if frag[i] == k and frag[j] == k]
        if len(idx) > 1 and inner:
            local[idx] = _open3d_optimise(poses[idx], inner)
    anchors = poses[starts]
    Q = np.linalg.inv(anchors[frag]) @ local  # each frame relative to its fragment's first frame
    cross = [(frag[i], frag[j], Q[j] @ T @ np.linalg.inv(Q[i]), info, u) for i, j, T, info, u in edges
             if frag[i] != frag[j]]
    A = _open3d_optimise(anchors, cross) if len(starts) > 1 and cross else anchors
    return A[frag] @ Q


class _LRU:
    """The ``size`` most recently used values of ``make(key)``."""

    def __init__(self, make: Callable, size: int) -> None:
        self.make, self.size, self.items = make, max(1, int(size)), OrderedDict()

    def __call__(self, key):
        if key in self.items:
            self.items.move_to_end(key)
        else:
            self.items[key] = self.make(key)
            if len(self.items) > self.size:
                self.items.popitem(last=False)
        return self.items[key]


def _overlap(points_i: np.ndarray, depth_j: np.ndarray, T_j_i: np.ndarray, intr, tol: float = 0.1) -> float:
    """Share of frame i's sample points (camera i) that frame j (depth in mm) sees at the same depth (within ``tol`` m)."""
    from ..io.geometry import project

    if len(points_i) == 0:
        return 0.0
    uv, z = project(points_i @ T_j_i[:3, :3].T + T_j_i[:3, 3], intr)
    u = np.rint(uv[:, 0]).astype(np.int64)
    v = np.rint(uv[:, 1]).astype(np.int64)
    H, W = intr.shape
    ok = (z > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
    dz = depth_j[v[ok], u[ok]].astype(np.float32) / 1000.0
    return float(((dz > 0) & (np.abs(dz - z[ok]) < tol)).sum() / len(points_i))


def refine_pose_graph(
    depths: Sequence[np.ndarray],
    intrinsics,
    poses: np.ndarray,
    *,
    neighbours: int = 3,
    loop_stride: int = 3,
    loop_candidates: int = 3,
    min_overlap: float = 0.3,
    loop_overlap: float = 0.4,
    max_correction: tuple[float, float] = (0.1, 5.0),
    min_fitness: float = 0.3,
    depth_max: float = 5.0,
    device: str | None = None,
    cache: int = 8,
    max_nodes: int | None = 500,
    progress: bool = False,
    name: str = "sequence",
) -> np.ndarray:
    """Refine chained poses by a pose graph with neighbour and loop-closure edges (Open3D).

    Edges ``(i, j)``: every consecutive pair (the chained motion, with its information matrix);
    the ``neighbours`` previous frames whose view
    overlaps frame i's by ``min_overlap`` (share of i's depth samples that j sees at the same
    depth under the current poses); every ``loop_stride``-th frame, up to ``loop_candidates``
    earlier keyframes (every ``loop_stride``-th frame, more than ``neighbours + 5`` frames
    back) overlapping by ``loop_overlap``, best first. Each edge is a multi-scale point-to-plane
    RGB-D registration (``open3d.t.pipelines.odometry``) started from the current relative
    pose, with Open3D's information matrix; an edge whose result moves more than
    ``max_correction`` from its start, fits fewer than ``min_fitness`` of the pixels, or does not
    converge is dropped. Non-consecutive
    edges are "uncertain" (Open3D's line process may prune them). The graph is optimised by
    Levenberg-Marquardt with frame 0 fixed.

    Parameters
    ----------
    depths : sequence of ndarray (H, W) uint16
        Depth images in millimetres (0 = no measurement), one per pose; read once each, in
        order (e.g. a :class:`CompressedDepths`, or a lazy reader).
    intrinsics : Intrinsics
        Camera intrinsics shared by all frames.
    poses : (N, 4, 4)
        Chained ``T_world_camera`` estimates (e.g. frame-to-frame odometry).
    neighbours : int
        Previous frames tried as edges of every frame.
    loop_stride, loop_candidates : int
        Loop closures: tried from every ``loop_stride``-th frame to at most ``loop_candidates``
        earlier keyframes.
    min_overlap, loop_overlap : float
        Least view overlap (0..1) of a neighbour / loop-closure pair.
    max_correction : (float, float)
        Largest change of a relative pose by its registration (metres, degrees).
    min_fitness : float
        Least share of matched pixels of a registration.
    depth_max : float
        Ignore depth beyond this (metres).
    device : str, optional
        Open3D device of the registrations.
    cache : int
        Depth pyramids kept (least recently used dropped); the result does not depend on it.
    max_nodes : int or None
        Longer recordings are optimised in fragments of this many frames (Open3D's optimiser
        needs memory growing with the square of the frames: 1.1 GB at 1000); None: never.
    progress : bool
        Show a tqdm bar.
    name : str
        What the sequence is, for messages.

    Returns
    -------
    ndarray (N, 4, 4) float64
        Refined poses; the first equals ``poses[0]``.

    Raises
    ------
    ValueError
        ``depths`` and ``poses`` of different lengths, fewer than 2 frames, depth of other
        than the first frame's size.
    """
    import open3d as o3d
    import open3d.core as o3c

    from ..io.geometry import backproject
    from ..runtime.progress import tqdm

    poses = np.asarray(poses, dtype=np.float64)
    n = len(poses)
    if len(depths) != n or n < 2:
        raise ValueError(f"{name}: need one depth image per pose and at least 2 ({len(depths)} depths, {n} poses)")
    H, W = intrinsics.shape

    def _checked(d: np.ndarray, i: int) -> np.ndarray:
        if d.shape != (H, W):
            raise ValueError(f"{name} frame {i}: depth is {d.shape}, the intrinsics say {(H, W)}")
        return d

    dev = o3c.Device(device or default_device())
    K = o3c.Tensor(intrinsics.K)
    criteria = [o3d.t.pipelines.odometry.OdometryConvergenceCriteria(k) for k in (30, 15, 8)]
    kept: dict[int, np.ndarray] = {}  # depth (mm) of the keyframes and the last `neighbours` frames

    def depth(i: int) -> np.ndarray:
        return kept[i]

    def image(i: int):
        return o3d.t.geometry.Image(o3c.Tensor(depth(i))).to(dev)

    # depth-only pyramids (point-to-plane), least recently used dropped
    pyramid = _LRU(lambda i: rgbd_pyramid(depth(i), None, intrinsics.K, levels=len(criteria), depth_max=depth_max,
                                          device=str(dev)), cache)
    odo = o3d.t.pipelines.odometry
    max_t, max_r = max_correction

    def register(i: int, j: int) -> tuple[np.ndarray, np.ndarray] | None:
        init = np.linalg.inv(poses[j]) @ poses[i]  # T_j_i
        try:
            T, fitness, _ = multi_scale_odometry(pyramid(i), pyramid(j), init, method="point-to-plane",
                                                 iterations=criteria)
        except RuntimeError:  # no correspondences (singular system)
            return None
        D = np.linalg.inv(init) @ T
        if (not np.isfinite(T).all() or fitness < min_fitness or np.linalg.norm(D[:3, 3]) > max_t
                or rotation_deg(D[:3, :3]) > max_r):
            return None
        info = odo.compute_odometry_information_matrix(image(i), image(j), K, o3c.Tensor(T), 0.07, 1000.0, depth_max)
        return T, info.cpu().numpy().astype(np.float64)

    with open3d_threads(1):  # repeatable sums (semmatch.poses.rgbd_odometry)
        edges: list = []
        kept[0] = _checked(depths[0], 0)
        for i in tqdm(range(1, n), desc="pose graph", disable=not progress, leave=False):
            kept[i] = _checked(depths[i], i)
            for old in [k for k in kept if k < i - neighbours and k % loop_stride]:
                del kept[old]  # neither a keyframe nor a neighbour of any later frame
            m_i = depth(i).astype(np.float32) / 1000.0
            samples = backproject(np.where(m_i <= depth_max, m_i, 0), intrinsics, stride=8)[0]
            pairs = [j for j in range(max(0, i - neighbours), i - 1)
                     if _overlap(samples, depth(j), np.linalg.inv(poses[j]) @ poses[i], intrinsics) >= min_overlap]
            if i % loop_stride == 0:
                loops = [(_overlap(samples, depth(j), np.linalg.inv(poses[j]) @ poses[i], intrinsics), j)
                         for j in range(0, i - neighbours - 5, loop_stride)]
                pairs += [j for ov, j in sorted(loops, reverse=True)[:loop_candidates] if ov >= loop_overlap]
            for j in [i - 1] + pairs:
                if j == i - 1:  # the chained motion itself (chosen robustly by the tracker, not re-registered)
                    T = np.linalg.inv(poses[j]) @ poses[i]
                    info = odo.compute_odometry_information_matrix(image(i), image(j), K, o3c.Tensor(T), 0.07, 1000.0,
                                                                   depth_max).cpu().numpy().astype(np.float64)
                    edge = (T, info if np.isfinite(info).all() and info.any() else np.eye(6))
                else:
                    edge = register(i, j)
                if edge is not None:
                    edges.append((i, j, edge[0], edge[1], j != i - 1))
        kept.clear()  # free the depth and pyramids before the optimiser allocates
        pyramid.items.clear()
        out = _optimise(poses, edges, max_nodes)
    if not np.isfinite(out).all():
        raise RuntimeError(f"{name}: the pose graph optimisation returned non-finite poses")
    return out
