"""RGB, metric depth, category and instance images of a :class:`Scene` by ray casting.

Built on Open3D's ``RaycastingScene`` (Embree). Depth is the z-distance along the optical axis
(the contract's depth), obtained directly by casting rays whose camera-frame direction has
``z = 1``. RGB is albedo x Lambert shading from a few point lights plus ambient.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import DEFAULT_INTRINSICS, Intrinsics, check_pose, pixel_rays
from .scene import Scene

__all__ = ["Renderer", "RenderResult"]


@dataclass
class RenderResult:
    """One rendered view: ``rgb`` uint8 (H,W,3), ``depth`` float32 metres (0 = miss),
    ``labels`` uint8, ``instances`` int32, ``triangle`` int64 hit triangle (-1 = miss)."""

    rgb: np.ndarray
    depth: np.ndarray
    labels: np.ndarray
    instances: np.ndarray
    triangle: np.ndarray


class Renderer:
    """Render a scene from posed pinhole cameras.

    Parameters
    ----------
    scene : Scene
    intrinsics : Intrinsics
        Default camera: 640x480, fx = fy = 268.51 (the paper's Habitat camera).
    lights : ndarray (L,3), optional
        Point-light positions; default: from ``scene.meta["lights"]`` or a grid under the
        ceiling of the scene's bounds.
    ambient : float
        Ambient term added to the Lambert shading.
    nthreads : int
        Ray-casting threads (0 = all cores).
    """

    def __init__(
        self,
        scene: Scene,
        intrinsics: Intrinsics = DEFAULT_INTRINSICS,
        *,
        lights: np.ndarray | None = None,
        ambient: float = 0.3,
        nthreads: int = 1,
    ) -> None:
        import open3d as o3d

        self.scene = scene
        self.intrinsics = intrinsics
        self.nthreads = int(nthreads)
        self._rc = o3d.t.geometry.RaycastingScene()
        self._rc.add_triangles(
            o3d.core.Tensor(scene.vertices), o3d.core.Tensor(scene.triangles.astype(np.uint32))
        )
        self._normals = scene.triangle_normals()
        self._rays_cam = pixel_rays(intrinsics).reshape(-1, 3)
        if lights is None:
            lights = scene.meta.get("lights")
        if lights is None:
            lo, hi = scene.bounds
            xs = np.linspace(lo[0], hi[0], 4)[1:-1]
            ys = np.linspace(lo[1], hi[1], 4)[1:-1]
            lights = np.array([[x, y, hi[2] - 0.3] for x in xs for y in ys])
        self.lights = np.asarray(lights, dtype=np.float32).reshape(-1, 3)
        self.ambient = float(ambient)

    def rays(self, pose: np.ndarray) -> np.ndarray:
        """World rays ``(H*W, 6)`` of a pose, direction scaled so that t = z-depth."""
        T = check_pose(pose)
        R = T[:3, :3].astype(np.float32)
        d = self._rays_cam @ R.T
        o = np.broadcast_to(T[:3, 3].astype(np.float32), d.shape)
        return np.concatenate([o, d], axis=1)

    def render(self, pose: np.ndarray) -> RenderResult:
        """Render the view of camera pose ``pose`` (``T_world_camera``)."""
        import open3d as o3d

        H, W = self.intrinsics.shape
        rays = self.rays(pose)
        ans = self._rc.cast_rays(o3d.core.Tensor(rays), nthreads=self.nthreads)
        t = ans["t_hit"].numpy()
        prim = ans["primitive_ids"].numpy().astype(np.int64)
        hit = np.isfinite(t)
        prim = np.where(hit, prim, -1)
        depth = np.where(hit, t, 0.0).astype(np.float32)
        tri = np.where(hit, prim, 0)
        labels = np.where(hit, self.scene.labels[tri], 0).astype(np.uint8)
        instances = np.where(hit, self.scene.instances[tri], 0).astype(np.int32)
        rgb = self._shade(rays, t, tri, hit)
        return RenderResult(
            rgb=rgb.reshape(H, W, 3),
            depth=depth.reshape(H, W),
            labels=labels.reshape(H, W),
            instances=instances.reshape(H, W),
            triangle=prim.reshape(H, W),
        )

    def _shade(self, rays: np.ndarray, t: np.ndarray, tri: np.ndarray, hit: np.ndarray) -> np.ndarray:
        idx = np.nonzero(hit)[0]
        out = np.zeros((len(rays), 3), dtype=np.uint8)
        if len(idx) == 0:
            return out
        n = self._normals[tri[idx]]
        d = rays[idx, 3:]
        p = rays[idx, :3] + d * t[idx, None]
        # face the normal towards the camera
        flip = np.einsum("ij,ij->i", n, d) > 0
        n[flip] *= -1
        shade = np.full(len(idx), self.ambient, dtype=np.float32)
        for light in self.lights:
            v = light - p
            dist = np.linalg.norm(v, axis=1)
            lam = np.einsum("ij,ij->i", n, v) / np.maximum(dist, 1e-6)
            shade += np.clip(lam, 0, None) * (1.5 / (1.0 + 0.1 * dist * dist)) / len(self.lights)
        col = self.scene.albedo[tri[idx]] * shade[:, None]
        out[idx] = np.clip(col * 255.0, 0, 255).astype(np.uint8)
        return out
