"""RGB, metric depth, category and instance images of a :class:`Scene` by ray casting.

Built on Open3D's ``RaycastingScene`` (Embree). Depth is the z-distance along the optical axis
(the contract's depth), obtained directly by casting rays whose camera-frame direction has
``z = 1``. RGB is albedo x Lambert shading from a few point lights (with shadows, precomputed
per triangle corner) plus ambient, times a per-pixel procedural material texture.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import DEFAULT_INTRINSICS, Intrinsics, check_pose, pixel_rays
from .materials import texture_factor
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

    Lighting (Lambert from point lights, with shadows, plus ambient) is view independent, so
    it is computed once per triangle corner and side when the renderer is built; a frame
    then costs one ray cast plus a barycentric interpolation, the material albedo and a
    per-pixel procedural texture (:func:`semmatch.sim.materials.texture_factor`).

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
    shadows : bool
        Occlusion-test each triangle corner against each light (cast shadows, e.g. under
        tables).
    texture : bool
        Apply the procedural material textures (``scene.texture``).
    nthreads : int
        Ray-casting threads (0 = all cores).

    Raises
    ------
    ValueError
        Intrinsics that are not an :class:`Intrinsics`, or a light position with NaN.
    """

    def __init__(
        self,
        scene: Scene,
        intrinsics: Intrinsics = DEFAULT_INTRINSICS,
        *,
        lights: np.ndarray | None = None,
        ambient: float = 0.3,
        shadows: bool = True,
        texture: bool = True,
        nthreads: int = 1,
    ) -> None:
        import open3d as o3d

        if not isinstance(intrinsics, Intrinsics):
            raise ValueError(f"intrinsics must be an Intrinsics, got {type(intrinsics).__name__}")
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
        if not np.isfinite(self.lights).all():
            raise ValueError(f"scene {scene.name!r}: light positions hold NaN or inf")
        self.ambient = float(ambient)
        self.shadows = bool(shadows)
        self.use_texture = bool(texture) and scene.texture is not None
        # (2, T, 3): irradiance at the three corners of each triangle, front (0) and back (1)
        self._irradiance = np.stack([self._corner_irradiance(side) for side in (1.0, -1.0)])
        # 12-bit linear -> 8-bit sRGB-like display curve
        self._lut = np.clip(np.rint(255.0 * np.linspace(0, 1, 4096) ** (1 / 2.2)), 0, 255).astype(np.uint8)

    def _corner_irradiance(self, side: float) -> np.ndarray:
        """Lambert irradiance (with shadows) at the corners of each triangle, one side."""
        import open3d as o3d

        v = self.scene.vertices[self.scene.triangles]  # (T,3,3)
        n = self._normals * np.float32(side)
        centre = v.mean(axis=1, keepdims=True)
        p = (0.97 * v + 0.03 * centre + 0.004 * n[:, None, :]).reshape(-1, 3).astype(np.float32)
        n3 = np.repeat(n, 3, axis=0)
        shade = np.full(len(p), self.ambient, dtype=np.float32)
        for light in self.lights:
            d = light[None, :] - p
            dist = np.linalg.norm(d, axis=1)
            lam = np.einsum("ij,ij->i", n3, d) / np.maximum(dist, 1e-6)
            lit = lam > 0
            if self.shadows and lit.any():
                rays = np.concatenate([p[lit], d[lit]], axis=1).astype(np.float32)
                occ = self._rc.test_occlusions(
                    o3d.core.Tensor(rays), tnear=0.0, tfar=0.999, nthreads=self.nthreads
                ).numpy()
                idx = np.nonzero(lit)[0]
                lit[idx[occ]] = False
            gain = 1.6 / (1.0 + 0.08 * dist * dist) / np.sqrt(len(self.lights))
            shade += np.where(lit, lam * gain, 0.0).astype(np.float32)
        return shade.reshape(-1, 3)

    def rays(self, pose: np.ndarray) -> np.ndarray:
        """World rays ``(H*W, 6)`` of a pose, direction scaled so that t = z-depth."""
        T = check_pose(pose)
        R = T[:3, :3].astype(np.float32)
        d = self._rays_cam @ R.T
        o = np.broadcast_to(T[:3, 3].astype(np.float32), d.shape)
        return np.concatenate([o, d], axis=1)

    def render(self, pose: np.ndarray) -> RenderResult:
        """Render the view of camera pose ``pose`` (``T_world_camera``).

        Raises
        ------
        ValueError
            If ``pose`` is not a 4x4 rigid transform.
        """
        import open3d as o3d

        H, W = self.intrinsics.shape
        rays = self.rays(pose)
        ans = self._rc.cast_rays(o3d.core.Tensor(rays), nthreads=self.nthreads)
        t = ans["t_hit"].numpy()
        hit = np.isfinite(t)
        prim = np.where(hit, ans["primitive_ids"].numpy().astype(np.int64), -1)
        tri = np.maximum(prim, 0)
        depth = np.where(hit, t, 0.0).astype(np.float32)
        labels = np.where(hit, self.scene.labels[tri], 0).astype(np.uint8)
        instances = np.where(hit, self.scene.instances[tri], 0).astype(np.int32)
        rgb = self._shade(rays, np.where(hit, t, 0.0), tri, hit, ans["primitive_uvs"].numpy(),
                          ans["primitive_normals"].numpy())
        return RenderResult(
            rgb=rgb.reshape(H, W, 3),
            depth=depth.reshape(H, W),
            labels=labels.reshape(H, W),
            instances=instances.reshape(H, W),
            triangle=prim.reshape(H, W),
        )

    def _shade(self, rays, t, tri, hit, uv, normals) -> np.ndarray:
        d = rays[:, 3:]
        back = np.einsum("ij,ij->i", normals, d) > 0
        corners = np.where(back[:, None], self._irradiance[1][tri], self._irradiance[0][tri])
        w0 = 1.0 - uv[:, 0] - uv[:, 1]
        shade = corners[:, 0] * w0 + corners[:, 1] * uv[:, 0] + corners[:, 2] * uv[:, 1]
        if self.use_texture:
            p = rays[:, :3] + d * t[:, None].astype(np.float32)
            shade *= texture_factor(p, self.scene.texture[tri])
        shade = np.where(hit, shade, 0.0).astype(np.float32)
        col = self.scene.albedo[tri] * shade[:, None]
        idx = np.clip(col * 4095.0, 0, 4095).astype(np.int16)
        return self._lut[idx]
