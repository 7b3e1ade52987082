"""The paper's five label-projection methods (§3.2, Alg. 1-3), on a :class:`MapIndex`.

Every method takes a validated frame (:class:`~semmatch.transfer.frames.FrameData`) and an
index and returns ``(labels, purity, groups)``: ``uint8 (H,W)`` labels (0 = no support), the
per-pixel share of its group's votes that agreed (``float32 (H,W)``), which ``fused`` uses,
and the method's grouping of the pixels (``int64 (H,W)`` superpixel / supervoxel / cluster
id, -1 = in no group; None for the per-pixel ``3d-neighborhood``), which panoptic transfer
uses to give a group one instance (:mod:`semmatch.transfer.panoptic`).

Common rules: pixels without depth get 0; a pixel whose own 3D point is farther than the
index's ``max_distance`` from the map gets 0 even when its group has a label (the group vote
fills label gaps and fixes edges, it never extends the map to unmapped geometry). The group
methods look their votes up with the index's voxel-centre answers (``exact=False``: a vote
within about one voxel of a class edge may go to the neighbouring class, which the majority
vote absorbs; ``exact=True`` resolves them with exact queries).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..io.geometry import Intrinsics, pixel_rays
from .dbscan import dbscan_labels
from .frames import FrameData
from .index import MapIndex
from .mask_slic import mask_slic
from .planes import ransac_plane
from .superpixels import superpixels
from .voting import paint, vote
from .voxels import voxel_downsample

__all__ = ["slic_2d", "projected_sp_3d", "slic_3d", "dbscan", "neighborhood_3d", "render_labels"]


@lru_cache(maxsize=16)
def _strided_rays(intr: Intrinsics, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """Ray directions (``z = 1``) of every ``stride``-th pixel, (h*w, 3), and their lengths
    (h, w): read-only, cached per camera and stride."""
    rays = pixel_rays(intr, stride)
    length = np.linalg.norm(rays, axis=2)
    rays = np.ascontiguousarray(rays.reshape(-1, 3))
    rays.flags.writeable = False
    length.flags.writeable = False
    return rays, length


def _mapped_points(fd: FrameData, index: MapIndex) -> tuple[np.ndarray, np.ndarray]:
    """World points of the valid pixels that lie within the map's reach (the others have no
    support in any case; dropping them bounds the voxel grids of 3d-slic and dbscan)."""
    pts, pix = fd.points()
    keep = index.inside(pts)
    if not keep.all():
        pts, pix = pts[keep], pix[keep]
    return pts, pix


def _finish(fd: FrameData, index: MapIndex, labels: np.ndarray, purity: np.ndarray, groups: np.ndarray):
    """Apply the per-pixel support mask shared by the group methods."""
    support = index.support_depth(fd.depth, fd.pose, fd.intrinsics).reshape(-1)
    labels = np.asarray(labels).reshape(-1).astype(np.uint8)
    purity = np.asarray(purity).reshape(-1).astype(np.float32)
    labels[~support] = 0
    purity[~support] = 0
    return labels.reshape(fd.shape), purity.reshape(fd.shape), np.asarray(groups, dtype=np.int64).reshape(fd.shape)


def _finish_points(
    fd: FrameData, index: MapIndex, pix: np.ndarray, group_of_point: np.ndarray, winner: np.ndarray,
    purity: np.ndarray,
):
    """Paint the votes of point groups (``-1`` = none) into their pixels, then apply the
    per-pixel support mask (:func:`_finish`)."""
    g = np.full(fd.shape[0] * fd.shape[1], -1, np.int64)
    g[pix] = group_of_point
    return _finish(fd, index, paint(g, winner), paint(g, purity, 0.0), g)


def render_labels(
    index: MapIndex, fd: FrameData, stride: int = 1, splat_radius: float = 3.0
) -> tuple[np.ndarray, np.ndarray]:
    """Render the upper map into the lower camera at every ``stride``-th pixel.

    Meshes are ray cast with Open3D ``RaycastingScene`` (label of the hit triangle's vertex
    nearest to the hit point); point maps are projected with a z-buffer (the nearest point per
    pixel wins) and gaps up to ``splat_radius`` pixels take their nearest rendered pixel.

    Returns
    -------
    labels : uint8 (h,w)
        Rendered label (0 where nothing was hit).
    depth : float32 (h,w)
        Rendered z-depth (0 where nothing was hit).
    """
    intr, T = fd.intrinsics, fd.pose
    rays, length = _strided_rays(intr, int(stride))
    h, w = length.shape
    if index.is_mesh:
        import open3d as o3d

        d = rays @ T[:3, :3].T.astype(np.float32)
        o = np.broadcast_to(T[:3, 3].astype(np.float32), d.shape)
        ans = index.raycasting_scene.cast_rays(
            o3d.core.Tensor(np.ascontiguousarray(np.concatenate([o, d], axis=1))), nthreads=index.workers
        )
        t = ans["t_hit"].numpy()
        hit = np.isfinite(t)
        prim = np.where(hit, ans["primitive_ids"].numpy().astype(np.int64), 0)
        uv = ans["primitive_uvs"].numpy()
        bary = np.stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
        vert = index.map.faces[prim, np.argmax(bary, axis=1)]
        lab = np.where(hit, index.map.labels[vert], 0).astype(np.uint8)
        return lab.reshape(h, w), np.where(hit, t, 0).astype(np.float32).reshape(h, w)
    pts = index.map.points
    Tinv = np.linalg.inv(T)
    cam = pts @ Tinv[:3, :3].T.astype(np.float32) + Tinv[:3, 3].astype(np.float32)
    z = cam[:, 2]
    front = z > 1e-6
    cam, z, lab = cam[front], z[front], index.map.labels[front]
    u = np.floor((intr.fx * cam[:, 0] / z + intr.cx + 0.5) / stride).astype(np.int64)
    v = np.floor((intr.fy * cam[:, 1] / z + intr.cy + 0.5) / stride).astype(np.int64)
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    pix, z, lab = v[inside] * w + u[inside], z[inside], lab[inside]
    order = np.lexsort((z, pix))  # by pixel, nearest first
    pix, z, lab = pix[order], z[order], lab[order]
    first = np.r_[True, pix[1:] != pix[:-1]] if len(pix) else np.zeros(0, bool)
    out_l = np.zeros(h * w, np.uint8)
    out_z = np.zeros(h * w, np.float32)
    out_l[pix[first]] = lab[first]
    out_z[pix[first]] = z[first]
    out_l, out_z = out_l.reshape(h, w), out_z.reshape(h, w)
    if splat_radius > 0 and (out_z == 0).any() and (out_z > 0).any():
        # close the gaps between projected points: an empty pixel takes its nearest rendered
        # pixel within splat_radius (the depth test of the caller rejects wrong fills)
        from scipy import ndimage

        dist, (iy, ix) = ndimage.distance_transform_edt(out_z == 0, return_indices=True)
        fill = (out_z == 0) & (dist <= splat_radius)
        out_l[fill] = out_l[iy[fill], ix[fill]]
        out_z[fill] = out_z[iy[fill], ix[fill]]
    return out_l, out_z


def slic_2d(
    fd: FrameData,
    index: MapIndex,
    *,
    n_segments: int = 512,
    backend: str = "cv2-slic",
    compactness: float = 10.0,
    iterations: int = 4,
    scale: float = 0.5,
    render_stride: int | None = None,
    occlusion_votes: bool | None = None,
):
    """``2d-slic``: render the upper map into the lower camera, vote per 2D superpixel.

    A rendered pixel votes with its rendered label when the rendered surface lies within
    ``max_distance`` of the observed point along the ray, and with void when the rendered
    surface lies in front of the observed point (the map has another surface there, e.g. a
    table top the robot looks under). Pixels without depth, without a rendered surface, or whose
    rendered surface lies behind the observed point (a gap between splatted map points, or
    geometry the map lacks: the per-pixel support mask decides those) do not vote.
    ``render_stride`` renders every n-th pixel in each direction; the default picks the largest
    stride that leaves about 50 votes per superpixel (3 for 512 superpixels at 640x480: 9x
    fewer rays). ``occlusion_votes`` (default: True for meshes, False for point
    maps) turns the void votes of a map surface in front of the observed point on or off: a
    splatted point map seen at a grazing angle (the floor from a robot) puts points in front of
    the observed surface in one pixel although nothing occludes it.
    Superpixel parameters: see :func:`superpixels`.
    """
    seg = superpixels(fd.rgb, n_segments, backend=backend, compactness=compactness,
                      iterations=iterations, scale=scale)
    if render_stride is None:
        H, W = fd.shape
        render_stride = max(1, int(np.sqrt(H * W / (max(int(n_segments), 1) * 50))))
    s = int(render_stride)
    if s < 1:
        raise ValueError(f"render_stride must be >= 1, got {render_stride}")
    rl, rz = render_labels(index, fd, s)
    obs = fd.depth[::s, ::s]
    ray_len = _strided_rays(fd.intrinsics, s)[1]
    gap = (rz - obs) * ray_len  # > 0: the map surface lies behind the observed point
    agree = np.abs(gap) <= index.max_distance
    if occlusion_votes is None:
        occlusion_votes = index.is_mesh
    rendered = (rz > 0) & (obs > 0) & (agree | ((gap < 0) & bool(occlusion_votes)))
    votes = np.where(agree, rl, 0)
    g = seg[::s, ::s][rendered]
    n = int(seg.max()) + 1
    winner, purity = vote(g, votes[rendered], n)
    return _finish(fd, index, paint(seg, winner), paint(seg, purity, 0.0), seg)


def projected_sp_3d(
    fd: FrameData,
    index: MapIndex,
    *,
    n_segments: int = 512,
    backend: str = "cv2-slic",
    compactness: float = 10.0,
    iterations: int = 4,
    scale: float = 0.5,
    subsample: int = 4,
    exact: bool = False,
):
    """``3d-projected-sp`` (Alg. 1): superpixels on RGB, back-project with depth, keep every
    ``subsample``-th point, look labels up in 3D, vote per superpixel.

    Superpixel parameters: see :func:`superpixels`."""
    if int(subsample) < 1:
        raise ValueError(f"subsample must be >= 1, got {subsample}")
    seg = superpixels(fd.rgb, n_segments, backend=backend, compactness=compactness,
                      iterations=iterations, scale=scale)
    pts, pix = fd.points(int(subsample))
    lab = index.lookup(pts, exact=exact)
    winner, purity = vote(seg.reshape(-1)[pix], lab, int(seg.max()) + 1)
    return _finish(fd, index, paint(seg, winner), paint(seg, purity, 0.0), seg)


def slic_3d(
    fd: FrameData,
    index: MapIndex,
    *,
    voxel_size: float = 0.10,
    n_segments: int = 128,
    compactness: float = 10.0,
    iterations: int = 3,
    exact: bool = False,
):
    """``3d-slic`` (Alg. 2): voxelise the coloured lower point cloud (``voxel_size``), run
    maskSLIC (scikit-image ``slic`` with the occupied voxels as mask) on the voxel grid for
    ``n_segments`` supervoxels, label each voxel centroid from the map, vote per supervoxel.

    maskSLIC runs through :func:`~semmatch.transfer.mask_slic.mask_slic`: scikit-image's steps and
    kernels with an exact, pruned search in its k-means seeding (the supervoxels are bit-identical
    to ``slic``'s; since 2026-11-27, about 6 ms a frame less).

    ``iterations`` (3; 5 before 2026-11-26) bounds both of scikit-image's k-means passes over
    the grid, which make most of the method's time; 3 was chosen on the validation scenes for
    sensor rate (docs/speed.md: 2.5 % of the pixels change, pixel accuracy -0.4 points)."""

    out = np.zeros(fd.shape, np.uint8), np.zeros(fd.shape, np.float32), np.full(fd.shape, -1, np.int64)
    pts, pix = _mapped_points(fd, index)
    if len(pts) == 0:
        return out
    vkeys, cen, inv, col = voxel_downsample(pts, voxel_size, fd.rgb, pix)
    dims = tuple(vkeys.max(axis=0) + 1)
    grid = np.zeros(dims + (3,), np.float32)
    mask = np.zeros(dims, bool)
    grid[tuple(vkeys.T)] = col
    mask[tuple(vkeys.T)] = True
    if len(vkeys) < 2:
        sv = np.zeros(len(vkeys), np.int64)
    else:
        sv_grid = mask_slic(grid, mask, n_segments=int(n_segments), compactness=float(compactness),
                            max_num_iter=int(iterations))
        sv = sv_grid[tuple(vkeys.T)].astype(np.int64) - 1
    winner, purity = vote(sv, index.lookup(cen, exact=exact), int(sv.max()) + 1)
    return _finish_points(fd, index, pix, sv[inv], winner, purity)


def _peel_planes(
    points: np.ndarray,
    *,
    distance: float,
    iterations: int,
    max_planes: int,
    eps: float,
    min_points: int,
    sample: int,
    rng: np.random.Generator,
):
    """RANSAC planes, each cut to its largest DBSCAN cluster (Alg. 3 step 4).

    The plane comes from :func:`semmatch.transfer.planes.ransac_plane` (Open3D ``segment_plane``'s
    algorithm, seeded by ``rng``) on at most ``sample`` random points of the remaining cloud;
    its inliers are then taken from the whole remaining cloud.

    Returns the cluster id of every point (planes first), the number of planes and the
    indices of the points left for the final DBSCAN.
    """
    n = len(points)
    cluster = np.full(n, -1, np.int64)
    remaining = np.arange(n)
    k = 0
    for _ in range(int(max_planes)):
        if len(remaining) < max(3, int(min_points)):
            break
        rest = points[remaining]
        sub = rest if len(rest) <= sample else rest[rng.choice(len(rest), int(sample), replace=False)]
        model, _ = ransac_plane(sub, float(distance), int(iterations), rng)
        if not model[:3].any():
            break  # every sample degenerate (collinear points): no plane to peel
        dist = np.abs(rest.astype(np.float64) @ model[:3] + model[3]) / max(np.linalg.norm(model[:3]), 1e-12)
        inliers = np.flatnonzero(dist <= distance)
        if len(inliers) < int(min_points):
            break
        lab = dbscan_labels(rest[inliers], eps, min_points)
        if (lab >= 0).sum() == 0:
            break  # too much noise: stop peeling (as the authors' code)
        best = np.bincount(lab[lab >= 0]).argmax()
        take = remaining[inliers[lab == best]]
        cluster[take] = k
        k += 1
        keep = np.ones(n, bool)
        keep[take] = False
        remaining = remaining[keep[remaining]]
    return cluster, k, remaining


def dbscan(
    fd: FrameData,
    index: MapIndex,
    *,
    voxel_size: float = 0.04,
    eps: float = 0.10,
    min_points: int = 10,
    ransac_distance: float = 0.03,
    ransac_iterations: int = 300,
    ransac_sample: int = 500,
    max_planes: int = 5,
    seed: int = 0,
    exact: bool = False,
):
    """``dbscan`` (Alg. 3): voxel-downsample the lower cloud, peel up to ``max_planes`` RANSAC
    planes (each cut to its largest DBSCAN cluster), cluster the rest with DBSCAN (Open3D's labels),
    label each voxel centroid from the map and vote per cluster. DBSCAN noise stays void.
    RANSAC scores its hypotheses on ``ransac_sample`` random points (seeded by ``seed``)."""
    out = np.zeros(fd.shape, np.uint8), np.zeros(fd.shape, np.float32), np.full(fd.shape, -1, np.int64)
    pts, pix = _mapped_points(fd, index)
    if len(pts) == 0:
        return out
    _, cen, inv, _ = voxel_downsample(pts, voxel_size)
    cluster, k, remaining = _peel_planes(
        cen, distance=ransac_distance, iterations=ransac_iterations, max_planes=max_planes,
        eps=eps, min_points=min_points, sample=int(ransac_sample), rng=np.random.default_rng(seed),
    )
    if len(remaining):
        lab = dbscan_labels(cen[remaining], eps, min_points)
        cluster[remaining] = np.where(lab >= 0, lab + k, -1)
    n = int(cluster.max()) + 1
    winner, purity = vote(cluster, index.lookup(cen, exact=exact), n)
    return _finish_points(fd, index, pix, cluster[inv], winner, purity)


def neighborhood_3d(fd: FrameData, index: MapIndex, *, exact: bool = False, backend: str = "grid"):
    """``3d-neighborhood``: each lower point takes the label of the nearest upper-map surface.

    ``backend="grid"`` (default): one gather per pixel in the index's voxel label grid: the
    label of the surface nearest to the voxel centre (2 cm voxels by default), so a point within
    about one voxel of a class edge may take the neighbouring class (about 1% of the pixels of
    a generated room); ``exact=True`` resolves every pixel in such an ambiguous voxel with an
    exact closest-point query, which makes the result identical to the reference (3-4x slower).
    ``backend="reference"``: the published approach, a closest-point query per pixel
    (:func:`semmatch.transfer.reference.reference_neighborhood`).
    """
    if backend == "reference":
        from .reference import reference_neighborhood

        labels = reference_neighborhood(fd, index)
    elif backend == "grid":
        labels = index.lookup_depth(fd.depth, fd.pose, fd.intrinsics, exact=exact)
    else:
        raise ValueError(f"unknown 3d-neighborhood backend {backend!r}; valid: grid, reference")
    return labels, (labels > 0).astype(np.float32), None
