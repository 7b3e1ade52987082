"""Camera trajectories through the free space of a scene at a given height.

The carrier of the camera (a person for the upper view, a robot for the lower one) occupies
the vertical column under the camera, so a floor cell is free at height ``h`` when no
obstacle (anything but floor and ceiling) lies within ``margin`` of it between the floor
and ``h + 0.1`` m, the cell is inside the scene (a ray down or up hits the mesh) and the ceiling
is above the camera. The path visits waypoints spread over the free space (farthest-point
sampling), joins them by least-cost grid paths that keep away from obstacles
(:class:`skimage.graph.MCP_Geometric`), is smoothed and resampled to ``n_frames``. A tour
shorter than the frames allow is walked there and back (the way back sees what the way out
turned its back on). The camera looks along the path with a slow side-to-side sweep and tilts
periodically by ``±tilt_deg`` (paper §4.2).

Two carriers can share a route: :func:`route_waypoints` gives the waypoints a trajectory of
one kind visits, and ``make_trajectory(..., waypoints=...)`` flies them at another height (the
robot follows the person's route through the room, so that the upper map covers what the
lower camera sees).

Size: one module of about 640 lines, on purpose. Free space, route planning, coverage and the
camera paths are one planner working on one free-space grid (:class:`FreeSpace`), and one
version number (:data:`TRAJECTORY_VERSION`, which the caches of rendered training views key on)
covers all of it: a change in any part changes the tours, so the parts stay where that is seen.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from ..io.geometry import sample_mesh_at_random
from ..io.labels import id_of
from .scene import Scene

__all__ = [
    "FreeSpace",
    "scene_levels",
    "free_space",
    "limit_turn_rate",
    "TRAJECTORY_VERSION",
    "route_waypoints",
    "make_trajectory",
    "make_sweep_trajectories",
    "camera_elevation_deg",
    "tour_coverage",
]

_FLOOR, _CEILING = id_of("floor"), id_of("ceiling")

#: bumped whenever :func:`make_trajectory` returns other poses for the same arguments (caches of
#: rendered views key on it); 2: heading turn rate limited (``max_turn_deg``); 3: short tours
#: walked there and back
TRAJECTORY_VERSION = 3


@dataclass
class FreeSpace:
    """A floor grid of free cells.

    Attributes
    ----------
    free : bool (ny, nx)
        Cells where the camera may be (largest connected free region).
    clearance : float (ny, nx)
        Distance (m) from each cell centre to the nearest obstacle cell.
    origin : float (2,)
        World ``(x, y)`` of the centre of cell ``[0, 0]``.
    resolution : float
        Cell size (m).
    floor_z, ceiling_z : float
        World heights of the floor and the ceiling.
    """

    free: np.ndarray
    clearance: np.ndarray
    origin: np.ndarray
    resolution: float
    floor_z: float
    ceiling_z: float

    def cell_of(self, xy: np.ndarray) -> np.ndarray:
        """Integer ``(row, col)`` cells of world ``(x, y)`` points, (N,2)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        rc = np.rint((xy - self.origin) / self.resolution).astype(np.int64)[:, ::-1]
        return rc

    def clearance_at(self, xy: np.ndarray) -> np.ndarray:
        """Clearance (m) at world points; 0 outside the grid or outside free space."""
        rc = self.cell_of(xy)
        ok = (rc[:, 0] >= 0) & (rc[:, 0] < self.free.shape[0]) & (rc[:, 1] >= 0) & (rc[:, 1] < self.free.shape[1])
        out = np.zeros(len(rc))
        r, c = rc[ok, 0], rc[ok, 1]
        out[ok] = np.where(self.free[r, c], self.clearance[r, c], 0.0)
        return out

    def xy_of(self, rc: np.ndarray) -> np.ndarray:
        """World ``(x, y)`` of cells ``(row, col)``."""
        rc = np.asarray(rc, dtype=np.float64).reshape(-1, 2)
        return rc[:, ::-1] * self.resolution + self.origin


def _dominant_level(z: np.ndarray, area: np.ndarray, bin_size: float = 0.02) -> float | None:
    """Height holding the most triangle area (area-weighted mode over ``bin_size`` bins, refined
    to the area-weighted mean within one bin of it), or None without area."""
    if len(z) == 0 or not area.sum() > 0:
        return None
    k = np.floor((z - z.min()) / bin_size).astype(np.int64)
    hist = np.bincount(k, weights=area)
    top = int(np.argmax(hist))
    near = np.abs(k - top) <= 1
    return float(np.average(z[near], weights=area[near]))


def scene_levels(scene: Scene) -> tuple[float, float]:
    """World heights ``(floor_z, ceiling_z)`` of a scene.

    From ``scene.meta`` (``floor_z``, ``ceiling_height``) when present. Otherwise the level
    holding most of the floor- (ceiling-) labelled triangle area: robust to stray labels (a few
    mislabelled triangles on a table do not lower the ceiling), checked against the mesh extent
    (a "ceiling" less than 1.5 m above the floor, or a floor more than 1 m above the mesh's
    lowest point, is ignored); without usable labels, the scene bounds.
    """
    lo, hi = scene.bounds
    v = scene.vertices[scene.triangles]
    cz = v.mean(axis=1)[:, 2]
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    if "floor_z" in scene.meta:
        floor = float(scene.meta["floor_z"])
    else:
        m = scene.labels == _FLOOR
        level = _dominant_level(cz[m], area[m])
        floor = level if level is not None and level <= lo[2] + 1.0 else float(lo[2])
    if "ceiling_height" in scene.meta:
        ceiling = floor + float(scene.meta["ceiling_height"])
    else:
        m = scene.labels == _CEILING
        level = _dominant_level(cz[m], area[m])
        ceiling = level if level is not None and level >= floor + 1.5 else float(hi[2])
    return floor, ceiling


def _sample_surface(scene: Scene, mask: np.ndarray, density: float, rng: np.random.Generator) -> np.ndarray:
    """Points on the triangles selected by ``mask``, about ``density`` per m² (at least the corners)."""
    faces = scene.triangles[mask]
    v = scene.vertices[faces].astype(np.float64)
    if len(v) == 0:
        return np.zeros((0, 3))
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    pts, _ = sample_mesh_at_random(scene.vertices, faces, area * density, rng, form="weights", chunk=None,
                                   dtype=np.float64)
    edges = np.concatenate([0.5 * (v[:, 0] + v[:, 1]), 0.5 * (v[:, 1] + v[:, 2]), 0.5 * (v[:, 0] + v[:, 2])])
    return np.concatenate([pts, v.reshape(-1, 3), edges])


def free_space(
    scene: Scene,
    height: float,
    *,
    margin: float = 0.3,
    resolution: float = 0.05,
    min_enclosure: int = 3,
) -> FreeSpace:
    """The floor cells where a camera carried at ``height`` above the floor may be.

    A cell is inside the scene when a ray down or up from the camera hits the mesh (gaps
    up to ~0.5 m closed, enclosed holes filled: reconstructed floors have holes).

    Parameters
    ----------
    scene : Scene
    height : float
        Camera height above the floor (m).
    margin : float
        Smallest distance (m) kept from obstacles and walls.
    resolution : float
        Grid cell size (m).
    min_enclosure : int
        Of 8 horizontal rays from the camera, how many must hit the mesh (closed rooms:
        all 8; partial reconstructions such as the Replica meshes of ``../shared`` have
        few walls).

    Returns
    -------
    FreeSpace

    Raises
    ------
    ValueError
        ``height <= 0``, a camera height at or above the ceiling, or no free cell at all.
    """
    import open3d as o3d
    from scipy import ndimage

    if not np.isfinite(height) or height <= 0:
        raise ValueError(f"scene {scene.name!r}: camera height must be > 0 m, got {height}")
    floor_z, ceiling_z = scene_levels(scene)
    if floor_z + height >= ceiling_z - 0.05:
        raise ValueError(
            f"scene {scene.name!r}: camera height {height:.2f} m is above the ceiling "
            f"({ceiling_z - floor_z:.2f} m above the floor)"
        )
    lo, hi = scene.bounds
    origin = lo[:2].astype(np.float64) + resolution / 2
    nx = int(np.ceil((hi[0] - lo[0]) / resolution)) + 1
    ny = int(np.ceil((hi[1] - lo[1]) / resolution)) + 1
    rng = np.random.default_rng(0)
    # obstacles in the carrier's column: anything but floor/ceiling between floor+8 cm and h+10 cm
    obst = (scene.labels != _FLOOR) & (scene.labels != _CEILING)
    pts = _sample_surface(scene, obst, density=(2.0 / resolution) ** 2, rng=rng)
    band = (pts[:, 2] > floor_z + 0.08) & (pts[:, 2] < floor_z + height + 0.1)
    occ = np.zeros((ny, nx), dtype=bool)
    rc = np.floor((pts[band, :2] - lo[:2]) / resolution).astype(np.int64)
    rc = np.clip(rc, 0, [nx - 1, ny - 1])
    occ[rc[:, 1], rc[:, 0]] = True
    # inside: mesh below or above the camera, and the camera enclosed by the mesh (at
    # least min_enclosure of 8 horizontal rays hit it); the ceiling must leave room
    gy, gx = np.mgrid[0:ny, 0:nx]
    xy = np.stack([gx.ravel(), gy.ravel()], axis=1) * resolution + origin
    z = floor_z + height
    rc_scene = o3d.t.geometry.RaycastingScene()
    rc_scene.add_triangles(o3d.core.Tensor(scene.vertices), o3d.core.Tensor(scene.triangles.astype(np.uint32)))
    o = np.concatenate([xy, np.full((len(xy), 1), z)], axis=1).astype(np.float32)
    down = np.concatenate([o, np.tile(np.float32([0, 0, -1]), (len(o), 1))], axis=1)
    up = np.concatenate([o, np.tile(np.float32([0, 0, 1]), (len(o), 1))], axis=1)
    ans_d = rc_scene.cast_rays(o3d.core.Tensor(down))
    ans_u = rc_scene.cast_rays(o3d.core.Tensor(up))
    td, tu = ans_d["t_hit"].numpy(), ans_u["t_hit"].numpy()
    # reconstructed meshes have holes in the floor (or no floor at all): a cell with mesh
    # below or above is inside; gaps up to ~0.5 m are closed, enclosed holes filled
    below = np.isfinite(td) | np.isfinite(tu)
    ang = np.arange(8) * (np.pi / 4)
    dirs = np.stack([np.cos(ang), np.sin(ang), np.zeros(8)], axis=1).astype(np.float32)
    horiz = np.concatenate([np.repeat(o, 8, axis=0), np.tile(dirs, (len(o), 1))], axis=1)
    t_h = rc_scene.cast_rays(o3d.core.Tensor(horiz))["t_hit"].numpy().reshape(-1, 8)
    below = (below & (np.isfinite(t_h).sum(axis=1) >= min_enclosure)).reshape(ny, nx)
    k = max(1, int(round(0.25 / resolution)))
    below = ndimage.binary_closing(np.pad(below, k), structure=np.ones((2 * k + 1, 2 * k + 1)))[k:-k, k:-k]
    inside = ndimage.binary_fill_holes(below)
    headroom = (~np.isfinite(tu) | (tu > 0.05)).reshape(ny, nx)
    blocked = occ | ~inside
    clearance = ndimage.distance_transform_edt(~blocked) * resolution
    free = inside & headroom & (clearance >= margin)
    lab, n = ndimage.label(free)
    if n == 0:
        raise ValueError(f"scene {scene.name!r}: no free space at camera height {height:.2f} m with a "
                         f"{margin:.2f} m margin: {_why_not_free(scene, inside, headroom, clearance, margin)}")
    sizes = ndimage.sum(free, lab, index=np.arange(1, n + 1))
    free = lab == (1 + int(np.argmax(sizes)))
    return FreeSpace(free, clearance, origin, float(resolution), floor_z, ceiling_z)


def _why_not_free(scene: Scene, inside: np.ndarray, headroom: np.ndarray, clearance: np.ndarray,
                  margin: float) -> str:
    """The reason a free-space grid came out empty, for the error message."""
    if not inside.any():
        if not (scene.labels == _FLOOR).any():
            return ("no cell lies inside the mesh, and the mesh has no floor-labelled triangles (is the floor "
                    "missing from the scan, or labelled as another class?)")
        return ("no cell lies inside the mesh: the camera is not enclosed by walls at this height (an open or "
                "partial scan: lower min_enclosure)")
    if not (inside & headroom).any():
        return "every cell inside the mesh has a ceiling or an obstacle less than 5 cm above the camera"
    best = float(clearance[inside & headroom].max())
    return (f"{int((inside & headroom).sum())} cells are inside, but the largest distance to an obstacle or "
            f"wall is {best:.2f} m (< margin); lower the margin, or check for clutter labelled across the room")


def _waypoints(fs: FreeSpace, rng: np.random.Generator, spacing: float) -> np.ndarray:
    """Farthest-point sampled free cells, ordered as a greedy tour from a random start."""
    cells = np.argwhere(fs.free)
    area = len(cells) * fs.resolution**2
    k = int(np.clip(round(area / spacing**2), 5, 30))
    # prefer cells with room around them
    cl = fs.clearance[cells[:, 0], cells[:, 1]]
    cand = cells[cl >= np.quantile(cl, 0.3)]
    chosen = [cand[rng.integers(len(cand))]]
    d = np.linalg.norm(cand - chosen[0], axis=1)
    for _ in range(k - 1):
        nxt = cand[int(np.argmax(d))]
        chosen.append(nxt)
        d = np.minimum(d, np.linalg.norm(cand - nxt, axis=1))
    pts = np.asarray(chosen)
    order = [0]
    left = set(range(1, len(pts)))
    while left:
        last = pts[order[-1]]
        j = min(left, key=lambda i: float(np.linalg.norm(pts[i] - last)))
        order.append(j)
        left.remove(j)
    return pts[order]


def _snap_to_free(fs: FreeSpace, xy: np.ndarray) -> np.ndarray:
    """The free cells ``(row, col)`` nearest to world points ``xy`` (N,2) (consecutive repeats dropped)."""
    from scipy import ndimage

    _d, (ri, ci) = ndimage.distance_transform_edt(~fs.free, return_indices=True)
    rc = np.clip(fs.cell_of(xy), 0, np.array(fs.free.shape) - 1)
    cells = np.stack([ri[rc[:, 0], rc[:, 1]], ci[rc[:, 0], rc[:, 1]]], axis=1)
    keep = np.concatenate([[True], (np.diff(cells, axis=0) != 0).any(axis=1)])
    return cells[keep]


def _rng(seed: int, kind: str) -> np.random.Generator:
    return np.random.default_rng([int(seed), _kind_seed(kind)])


def route_waypoints(
    scene: Scene,
    height: float,
    *,
    seed: int = 0,
    kind: str = "upper",
    margin: float = 0.3,
    spacing: float = 1.2,
    free: FreeSpace | None = None,
) -> np.ndarray:
    """The waypoints, in visiting order, of the trajectory :func:`make_trajectory` plans.

    Parameters
    ----------
    scene : Scene
    height : float
        Camera height (m) whose free space the route is planned in.
    seed, kind, margin, spacing, free
        As for :func:`make_trajectory`.

    Returns
    -------
    ndarray (K, 2)
        World ``(x, y)`` of the waypoints. ``make_trajectory(scene, other_height, n,
        waypoints=route_waypoints(scene, height, ...))`` flies the same route at another height.
    """
    fs = free or free_space(scene, height, margin=margin)
    return fs.xy_of(_waypoints(fs, _rng(seed, kind), spacing))


def _grid_path(fs: FreeSpace, waypoints: np.ndarray) -> np.ndarray:
    from skimage.graph import MCP_Geometric

    cost = np.where(fs.free, 1.0 + 4.0 * np.exp(-fs.clearance / 0.35), np.inf)
    mcp = MCP_Geometric(cost, fully_connected=True)
    path = [waypoints[0]]
    for a, b in zip(waypoints[:-1], waypoints[1:]):
        mcp.find_costs([tuple(a)], [tuple(b)])
        seg = np.asarray(mcp.traceback(tuple(b)))
        path.extend(seg[1:])
    return np.asarray(path, dtype=np.float64)


def _smooth_path(fs: FreeSpace, xy: np.ndarray, margin: float) -> np.ndarray:
    """Resample to 2 cm steps and smooth as much as the free space allows."""
    from scipy.ndimage import gaussian_filter1d

    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    if s[-1] < 1e-6:
        return xy[:1]
    n = max(2, int(s[-1] / 0.02))
    si = np.linspace(0, s[-1], n)
    raw = np.stack([np.interp(si, s, xy[:, 0]), np.interp(si, s, xy[:, 1])], axis=1)
    for sigma_m in (0.5, 0.35, 0.25, 0.15, 0.1, 0.06, 0.03):
        sm = gaussian_filter1d(raw, sigma=sigma_m / 0.02, axis=0, mode="nearest")
        if (fs.clearance_at(sm) >= margin).all():  # every point stays in a free cell
            return sm
    return raw


def _resample(xy: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    si = np.linspace(0, s[-1], n)
    out = np.stack([np.interp(si, s, xy[:, 0]), np.interp(si, s, xy[:, 1])], axis=1)
    return out, si


def _path_length(xy: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()) if len(xy) > 1 else 0.0


#: waypoint spacings tried by ``make_trajectory(cover=True)``, as multiples of ``spacing``
_COVER_SPACINGS = (1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0)


def _covering_tour(fs: FreeSpace, seed: int, kind: str, spacing: float, margin: float,
                   budget: float) -> tuple[np.random.Generator, np.ndarray]:
    """The smoothed tour at the finest waypoint spacing whose length fits ``budget`` (metres).

    Returns the random stream after the chosen tour's waypoints were drawn (the heading sweep
    draws from it next) and the path; the coarsest tour when none fits (then cut by the caller).
    """
    for mult in _COVER_SPACINGS:
        rng = _rng(seed, kind)
        path = _smooth_path(fs, fs.xy_of(_grid_path(fs, _waypoints(fs, rng, spacing * mult))), margin)
        if _path_length(path) <= budget:
            break
    return rng, path


def tour_coverage(fs: FreeSpace, poses: np.ndarray, radius: float = 1.5) -> float:
    """Share of the free cells within ``radius`` (m) of a trajectory's camera positions.

    Parameters
    ----------
    fs : FreeSpace
    poses : ndarray (N,4,4)
    radius : float

    Returns
    -------
    float
        In [0, 1]; how broadly a tour visits the free space (the protocol reports it for both
        carriers of a scene).
    """
    from scipy import ndimage

    near = np.zeros_like(fs.free)
    rc = np.clip(fs.cell_of(np.asarray(poses)[:, :2, 3]), 0, np.array(fs.free.shape) - 1)
    near[rc[:, 0], rc[:, 1]] = True
    dist = ndimage.distance_transform_edt(~near) * fs.resolution
    free = int(fs.free.sum())
    return float(((dist <= radius) & fs.free).sum() / free) if free else 0.0


def camera_elevation_deg(poses: np.ndarray) -> np.ndarray:
    """Elevation (degrees, + = up) of the optical axis of poses (N,4,4)."""
    z = np.asarray(poses)[:, :3, 2]
    return np.degrees(np.arcsin(np.clip(z[:, 2], -1, 1)))


def _kind_seed(kind: str) -> int:
    return zlib.crc32(kind.encode()) & 0x7FFFFFFF


#: largest camera step between frames (m) of a tour, unless told otherwise
DEFAULT_CAMERA_STEP = 0.15


def check_camera_step(step: float, name: str = "camera_step") -> float:
    """``step`` as a float if it is a usable camera step (0 < step <= 1 m).

    Raises
    ------
    ValueError
        ``step`` outside (0, 1] m (the message names it ``name``).
    """
    if not 0 < float(step) <= 1.0:
        raise ValueError(f"{name} must lie in (0, 1] m, got {step}")
    return float(step)


def make_trajectory(
    scene: Scene,
    height: float,
    n_frames: int,
    *,
    tilt_deg: float = 20.0,
    tilt_period: int | None = None,
    seed: int = 0,
    kind: str = "upper",
    margin: float = 0.3,
    spacing: float = 1.2,
    plan_height: float | None = None,
    free: FreeSpace | None = None,
    max_step: float | None = DEFAULT_CAMERA_STEP,
    max_turn_deg: float | None = 30.0,
    waypoints: np.ndarray | None = None,
    there_and_back: bool = True,
    cover: bool = False,
) -> np.ndarray:
    """A smooth, collision-free camera trajectory at ``height`` above the floor.

    Parameters
    ----------
    scene : Scene
    height : float
        Camera height above the floor (m), e.g. 1.6 (upper, human) or 0.2 (lower, robot).
    n_frames : int
        Number of poses.
    tilt_deg : float
        Amplitude of the periodic up/down tilt of the camera (degrees).
    tilt_period : int, optional
        Frames per tilt cycle; default ``min(60, n_frames)`` so that even a short trajectory
        tilts both up and down (a 60-frame cycle on a 24-frame path only looks up).
    seed : int
        Same seed (and kind), same trajectory.
    kind : str
        Names the path; different kinds (``"upper"``, ``"lower"``, ...) start and run
        differently through the same scene.
    margin : float
        Clearance (m) from obstacles and walls.
    spacing : float
        Waypoint spacing (m) used to cover the free space.
    plan_height : float, optional
        Plan in the free space of this height instead (the height sweep plans one path at
        the largest height and flies it at every height).
    free : FreeSpace, optional
        Precomputed free space (of ``plan_height`` or ``height``).
    max_step : float, optional
        Largest camera step between frames (m): when the tour is longer than
        ``(n_frames - 1) * max_step`` only its first part is flown. None = no limit (the
        whole tour, however few the frames).
        A shorter tour is walked there and back (see ``there_and_back``).
    max_turn_deg : float, optional
        Largest change of heading between consecutive frames (degrees): where the path
        doubles back the camera turns at this rate instead of flipping round in one frame
        (which no RGB-D odometry could follow). None = no limit.
    waypoints : ndarray (K, 2), optional
        World ``(x, y)`` points to visit in this order instead of the kind's own tour, e.g.
        :func:`route_waypoints` of another height (each is moved to the nearest free cell of
        this height). The side-to-side sweep still depends on ``seed`` and ``kind``.
    there_and_back : bool
        With ``max_step``, a tour shorter than ``(n_frames - 1) * max_step`` continues back
        along itself up to that length (a small room is otherwise seen only facing one way).
    cover : bool
        Fit the tour to the frames (the evaluation protocol's coverage-matched tours): the
        waypoints are spread over the whole free space at the finest spacing (``spacing``,
        then 1.25x, 1.5x, ... 4x) whose tour is at most ``(n_frames - 1) * max_step`` long,
        so every carrier's tour spans the room instead of stopping part-way. Ignored with
        ``waypoints`` or without ``max_step``.

    Returns
    -------
    ndarray (n_frames, 4, 4)
        ``T_world_camera`` poses (OpenCV camera), camera at ``floor_z + height``.

    Raises
    ------
    ValueError
        Bad ``n_frames``/``tilt_deg``, a height at or above the ceiling, or no free space.
    """
    if int(n_frames) < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    if not 0 <= tilt_deg < 89:
        raise ValueError(f"tilt_deg must lie in [0, 89), got {tilt_deg}")
    if tilt_period is None:
        tilt_period = max(2, min(60, int(n_frames)))
    if tilt_period < 2:
        raise ValueError(f"tilt_period must be >= 2 frames, got {tilt_period}")
    n_frames = int(n_frames)
    fs = free or free_space(scene, plan_height or height, margin=margin)
    if plan_height is not None:
        _f, ceiling = scene_levels(scene)
        if fs.floor_z + height >= ceiling - 0.05:
            raise ValueError(
                f"scene {scene.name!r}: camera height {height:.2f} m is above the ceiling "
                f"({ceiling - fs.floor_z:.2f} m above the floor)"
            )
    rng = _rng(seed, kind)
    wp = _waypoints(fs, rng, spacing)  # drawn even when replaced: the sweep phase below stays the same
    if waypoints is not None:
        waypoints = np.asarray(waypoints, dtype=np.float64)
        if waypoints.ndim != 2 or waypoints.shape[1] != 2 or len(waypoints) == 0 or not np.isfinite(waypoints).all():
            raise ValueError(f"waypoints must be finite world (x, y) points (K, 2), got shape {waypoints.shape}")
        wp = _snap_to_free(fs, waypoints)
        path = _smooth_path(fs, fs.xy_of(_grid_path(fs, wp)), margin)
    elif cover and max_step is not None and n_frames > 1:
        rng, path = _covering_tour(fs, seed, kind, spacing, margin, max_step * (n_frames - 1))
    else:
        path = _smooth_path(fs, fs.xy_of(_grid_path(fs, wp)), margin)
    if len(path) < 2:
        path = np.concatenate([path, path])
    if max_step is not None and n_frames > 1:
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        if there_and_back and seg.sum() < max_step * (n_frames - 1):  # back along itself, cut below
            path = np.concatenate([path, path[-2::-1]])
            seg = np.concatenate([seg, seg[::-1]])
        keep = np.concatenate([[0.0], np.cumsum(seg)]) <= max_step * (n_frames - 1)
        path = path[: max(2, int(keep.sum()))]
    xy, s = _resample(path, n_frames)
    # heading: along the (heavily smoothed) path, plus a slow look-around sweep
    from scipy.ndimage import gaussian_filter1d

    dense, _ = _resample(path, max(2, len(path)))
    tang = np.gradient(gaussian_filter1d(dense, sigma=20, axis=0, mode="nearest"), axis=0)
    yaw_dense = np.unwrap(np.arctan2(tang[:, 1], tang[:, 0]))
    s_dense = np.linspace(0, s[-1], len(dense))
    yaw = np.interp(s, s_dense, yaw_dense)
    phase = rng.uniform(0, 2 * np.pi)
    yaw = yaw + np.radians(35.0) * np.sin(2 * np.pi * s / 3.0 + phase)
    if max_turn_deg is not None:
        yaw = limit_turn_rate(yaw, np.radians(max_turn_deg))
    t = np.arange(n_frames)
    pitch = np.radians(tilt_deg) * np.sin(2 * np.pi * t / tilt_period)
    fwd = np.stack([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)], axis=1)
    z_world = np.array([0.0, 0.0, 1.0])
    x = np.cross(fwd, z_world)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(fwd, x)
    poses = np.tile(np.eye(4), (n_frames, 1, 1))
    poses[:, :3, 0], poses[:, :3, 1], poses[:, :3, 2] = x, y, fwd
    poses[:, :2, 3] = xy
    poses[:, 2, 3] = fs.floor_z + height
    return poses


def limit_turn_rate(yaw: np.ndarray, max_turn: float) -> np.ndarray:
    """Follow an (unwrapped) heading sequence turning at most ``max_turn`` radians per step.

    Parameters
    ----------
    yaw : ndarray (N,)
        Unwrapped headings (radians).
    max_turn : float
        Largest change between consecutive entries (radians, > 0).

    Returns
    -------
    ndarray (N,)
        ``out[0] = yaw[0]``; each later entry moves from the previous one towards ``yaw[i]`` by
        at most ``max_turn``.
    """
    if not max_turn > 0:
        raise ValueError(f"max_turn must be > 0, got {max_turn}")
    out = np.array(yaw, dtype=np.float64)
    for i in range(1, len(out)):
        out[i] = out[i - 1] + np.clip(yaw[i] - out[i - 1], -max_turn, max_turn)
    return out


def make_sweep_trajectories(
    scene: Scene,
    heights: tuple[float, ...],
    n_frames: int,
    **kwargs,
) -> dict[float, np.ndarray]:
    """One path flown at several heights (the paper's height sweep, Fig. 3).

    The path is planned in the free space of the largest height (whose carrier column
    contains those of the smaller heights), so it is collision-free at every height.

    Returns
    -------
    dict
        ``{height: poses (n_frames, 4, 4)}``.
    """
    if not heights:
        raise ValueError("heights must not be empty")
    top = float(max(heights))
    kwargs.setdefault("kind", "sweep")
    fs = free_space(scene, top, margin=kwargs.get("margin", 0.3))
    return {
        float(h): make_trajectory(scene, float(h), n_frames, plan_height=top, free=fs, **kwargs)
        for h in heights
    }
