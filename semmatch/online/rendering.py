"""Model views for frame-to-model tracking: depth and colour images rendered from a pose.

Two models can be rendered at a camera pose:

* the person's map (a mesh), ray cast with Embree (``open3d.t.geometry.RaycastingScene``): depth
  from the hit distance, colour interpolated from the vertex colours at the hit's barycentric
  coordinates;
* the robot's own semantic TSDF (:class:`~semmatch.fusion.tsdf.SemanticTSDF`), ray cast by Open3D's
  ``VoxelBlockGrid.ray_cast`` (KinectFusion's model view).

:func:`render_view` renders the person's map and fills the pixels it misses from the robot's TSDF
(only when the person's map covers too little of the view, since ray casting the TSDF is the more
expensive of the two).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..io import SemanticMap
from ..io.geometry import Intrinsics

__all__ = ["ModelView", "MeshRenderer", "render_tsdf", "render_view"]


@dataclass
class ModelView:
    """A rendered model view.

    Attributes
    ----------
    depth : float32 (H, W)
        Metres along the optical axis, 0 where the model has no surface.
    rgb : uint8 (H, W, 3) or None
        None when rendered without colour.
    source : str
        ``"person"``, ``"robot"`` or ``"person+robot"`` (which model(s) filled it).
    person_share : float
        Share of the pixels with depth that came from the person's map.
    """

    depth: np.ndarray
    rgb: np.ndarray
    source: str
    person_share: float

    @property
    def n_valid(self) -> int:
        """Pixels with depth."""
        return int(np.count_nonzero(self.depth > 0))


class MeshRenderer:
    """Ray caster of a (person's) mesh map.

    Parameters
    ----------
    semantic_map : SemanticMap
        A mesh (``faces``) with RGB ``colors`` (grey when it has none).

    Raises
    ------
    ValueError
        A map without faces (a point cloud cannot be ray cast; track against the robot's own map).
    """

    def __init__(self, semantic_map: SemanticMap) -> None:
        import open3d as o3d
        import open3d.core as o3c

        if semantic_map.faces is None or len(semantic_map.faces) == 0:
            raise ValueError(f"{semantic_map.source}: the person's map has no faces; frame-to-model tracking "
                             "ray casts a mesh (reconstruct it with output='mesh')")
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3c.Tensor(np.ascontiguousarray(semantic_map.points, dtype=np.float32)),
                                 o3c.Tensor(np.ascontiguousarray(semantic_map.faces, dtype=np.uint32)))
        cols = semantic_map.colors
        self.colors = (np.full((len(semantic_map.points), 3), 128, np.float32) if cols is None
                       else np.asarray(cols, dtype=np.float32))
        self.faces = np.asarray(semantic_map.faces, dtype=np.int64)

    def render(self, pose: np.ndarray, intrinsics: Intrinsics, depth_max: float, *,
               colour: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Depth (metres, 0 = no hit) and colour (uint8; None without ``colour``) of the mesh seen
        from ``pose`` (``T_world_camera``)."""
        import open3d.core as o3c

        H, W = intrinsics.shape
        # the pinhole rays' directions have z = 1 in the camera: the hit distance is the depth
        rays = self.scene.create_rays_pinhole(o3c.Tensor(intrinsics.K), o3c.Tensor(np.linalg.inv(pose)), W, H)
        ans = self.scene.cast_rays(rays)
        t = ans["t_hit"].numpy()
        hit = np.isfinite(t)
        depth = np.where(hit, t, 0).astype(np.float32)
        depth[depth > depth_max] = 0
        hit &= depth > 0
        if not colour:
            return depth, None
        rgb = np.zeros((H, W, 3), np.uint8)
        if hit.any():
            prim = ans["primitive_ids"].numpy()[hit].astype(np.int64)
            uv = ans["primitive_uvs"].numpy()[hit]
            tri = self.faces[prim]
            w = np.stack([1 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)[..., None]
            rgb[hit] = np.clip(np.rint((self.colors[tri] * w).sum(axis=1)), 0, 255).astype(np.uint8)
        return depth, rgb


@contextlib.contextmanager
def _quiet_open3d() -> Iterator[None]:
    """Open3D's messages below errors silenced inside the block."""
    import open3d as o3d

    level = o3d.utility.get_verbosity_level()
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    try:
        yield
    finally:
        o3d.utility.set_verbosity_level(level)


def render_tsdf(vol, pose: np.ndarray, intrinsics: Intrinsics, depth_max: float, *,
                colour: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """Depth (metres, 0 = no surface) and colour (uint8; None without ``colour``) of a
    :class:`~semmatch.fusion.tsdf.SemanticTSDF` ray cast from ``pose`` (``T_world_camera``), as
    KinectFusion renders its model.

    All allocated blocks are offered to the ray caster (which culls them to the view); every
    integrated voxel counts (weight >= 1).
    """
    import open3d.core as o3c

    H, W = intrinsics.shape
    hm = vol.vbg.hashmap()
    # Open3D's ray caster places voxel k's sample half a voxel lower (in x, y and z) than its
    # integration does (measured: rendered depth 0.6 voxel behind the frame's own at its pose,
    # 0 after this shift): render from the camera moved by half a voxel instead
    shift = np.eye(4)
    shift[:3, 3] = 0.5 * vol.voxel_size
    pose = shift @ np.asarray(pose, dtype=np.float64)
    if int(hm.size()) == 0:
        return np.zeros((H, W), np.float32), np.zeros((H, W, 3), np.uint8) if colour else None
    keys = hm.key_tensor()[hm.active_buf_indices().to(o3c.int64)]
    with _quiet_open3d():  # it reports every growth of its range-map buffer
        r = vol.vbg.ray_cast(keys, o3c.Tensor(intrinsics.K), o3c.Tensor(np.linalg.inv(pose)), W, H,
                             render_attributes=["depth", "color"] if colour else ["depth"], depth_scale=1000.0, depth_min=0.1,
                             depth_max=float(depth_max), weight_threshold=1.0,
                             trunc_voxel_multiplier=float(vol.trunc_voxels), range_map_down_factor=8)
    depth = np.nan_to_num(r["depth"].numpy()[..., 0] / 1000.0, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)
    if not colour:
        return depth, None
    rgb = np.clip(np.rint(np.nan_to_num(r["color"].numpy()) * 255.0), 0, 255).astype(np.uint8)
    return depth, rgb


def render_view(pose: np.ndarray, intrinsics: Intrinsics, *, person: MeshRenderer | None, robot=None,
                depth_max: float = 4.0, min_person_share: float = 0.6, frame_valid: int | None = None,
                colour: bool = True) -> ModelView:
    """The model view at ``pose``: the person's map, filled from the robot's TSDF where it is empty.

    Parameters
    ----------
    pose : (4, 4)
        ``T_world_camera`` of the view.
    intrinsics : Intrinsics
        Camera of the view (a tracking size, typically the frame shrunk).
    person : MeshRenderer or None
        The person's map (None: the robot's own map only, KinectFusion style).
    robot : SemanticTSDF or None
        The robot's map, used where the person's map has no surface.
    depth_max : float
    min_person_share : float
        Ray cast the robot's map too when the person's map fills fewer pixels than this share of
        ``frame_valid`` (the frame's pixels with depth; default: all pixels).
    frame_valid : int, optional
    colour : bool
        Render colour too (the photometric residuals need it; without it ``rgb`` is None).

    Returns
    -------
    ModelView
    """
    H, W = intrinsics.shape
    need = (H * W if frame_valid is None else int(frame_valid)) * float(min_person_share)
    depth = rgb = None
    n_person = 0
    if person is not None:
        depth, rgb = person.render(pose, intrinsics, depth_max, colour=colour)
        n_person = int(np.count_nonzero(depth > 0))
        if n_person >= need or robot is None or robot.n_frames == 0:
            return ModelView(depth, rgb, "person", 1.0 if n_person else 0.0)
    if robot is None or robot.n_frames == 0:
        return ModelView(np.zeros((H, W), np.float32), np.zeros((H, W, 3), np.uint8) if colour else None, "none", 0.0)
    d_r, c_r = render_tsdf(robot, pose, intrinsics, depth_max, colour=colour)
    if depth is None:
        return ModelView(d_r, c_r, "robot", 0.0)
    fill = (depth == 0) & (d_r > 0)
    depth = np.where(fill, d_r, depth)
    if colour:
        rgb = np.where(fill[..., None], c_r, rgb)
    n = int(np.count_nonzero(depth > 0))
    return ModelView(depth, rgb, "person+robot", n_person / n if n else 0.0)
