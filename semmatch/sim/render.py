"""RGB, metric depth, category and instance images of a :class:`Scene` by ray casting.

Built on Open3D's ``RaycastingScene`` (Embree). Depth is the z-distance along the optical axis
(the contract's depth), obtained directly by casting rays whose camera-frame direction has
``z = 1``. RGB is albedo x Lambert shading from a few point lights (with shadows, precomputed
per triangle corner) plus ambient, times a per-pixel procedural material texture.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io.geometry import DEFAULT_INTRINSICS, Intrinsics, check_pose, pixel_rays
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
    fast : bool
        Coarse-to-fine rendering: cast every second pixel and fill the pixels between
        samples on one plane group without casting (exact depth, same category; colour
        interpolated; thin objects under two pixels wide can be missed, and ``triangle``
        there names a neighbouring triangle of the same plane). Default: every pixel is
        ray cast (exact).

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
        fast: bool = False,
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
        self.fast = bool(fast)
        self._groups: np.ndarray | None = None
        self.last_cast_fraction = 1.0
        self.use_texture = bool(texture) and scene.texture is not None
        # (2T, 3): irradiance at the three corners of each triangle, front sides then back sides
        self._irradiance = np.concatenate([self._corner_irradiance(side) for side in (1.0, -1.0)])
        self._plane_d = np.einsum("ij,ij->i", self._normals, scene.vertices[scene.triangles[:, 0]])
        # per-triangle tables with a last "miss" entry (indexed by triangle id -1)
        self._labels_ext = np.append(scene.labels, np.uint8(0))
        self._instances_ext = np.append(scene.instances, np.int32(0))
        self._albedo_ext = np.vstack([scene.albedo * np.float32(4095.0), np.zeros((1, 3), np.float32)])
        # 12-bit linear -> 8-bit sRGB-like display curve
        self._lut = np.clip(np.rint(255.0 * np.linspace(0, 1, 4096) ** (1 / 2.2)), 0, 255).astype(np.uint8)

    def _corner_irradiance(self, side: float) -> np.ndarray:
        """Lambert irradiance (with shadows) at the corners of each triangle, one side.

        Computed per vertex with the area-weighted vertex normal (smooth shading on curved
        meshes; the procedural scenes give each face its own vertices) and gathered to the
        triangle corners.
        """
        import open3d as o3d

        sc = self.scene
        tri = sc.triangles
        v = sc.vertices[tri]
        area_n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]) * np.float32(side)
        vn = np.zeros_like(sc.vertices)
        for k in range(3):
            np.add.at(vn, tri[:, k], area_n)
        vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-12)
        used = np.zeros(len(sc.vertices), dtype=bool)
        used[tri.reshape(-1)] = True
        p = (sc.vertices + 0.004 * vn).astype(np.float32)
        shade = np.full(len(p), self.ambient, dtype=np.float32)
        for light in self.lights:
            d = light[None, :] - p
            dist = np.linalg.norm(d, axis=1)
            lam = np.einsum("ij,ij->i", vn, d) / np.maximum(dist, 1e-6)
            lit = (lam > 0) & used
            if self.shadows and lit.any():
                rays = np.concatenate([p[lit], d[lit]], axis=1).astype(np.float32)
                occ = self._rc.test_occlusions(
                    o3d.core.Tensor(rays), tnear=0.0, tfar=0.999, nthreads=self.nthreads
                ).numpy()
                idx = np.nonzero(lit)[0]
                lit[idx[occ]] = False
            gain = 1.15 / (1.0 + 0.08 * dist * dist) / np.sqrt(len(self.lights))
            shade += np.where(lit, lam * gain, 0.0).astype(np.float32)
        return shade[tri]

    def rays(self, pose: np.ndarray, index: np.ndarray | None = None) -> np.ndarray:
        """World rays ``(N, 6)`` of a pose (all pixels, or the flat pixel ``index``);
        directions are scaled so that the ray parameter t is the z-depth."""
        T = check_pose(pose)
        cam = self._rays_cam if index is None else self._rays_cam[index]
        out = np.empty((len(cam), 6), dtype=np.float32)
        out[:, :3] = T[:3, 3].astype(np.float32)
        out[:, 3:] = cam @ T[:3, :3].T.astype(np.float32)
        return out

    def render(self, pose: np.ndarray) -> RenderResult:
        """Render the view of camera pose ``pose`` (``T_world_camera``).

        Raises
        ------
        ValueError
            If ``pose`` is not a 4x4 rigid transform.
        """
        H, W = self.intrinsics.shape
        T = check_pose(pose)
        # index offset into the irradiance table: back sides for triangles facing away
        self._side = np.where(self._normals @ T[:3, 3].astype(np.float32) < self._plane_d,
                              len(self._normals), 0)
        if self.fast and H >= 4 and W >= 4:
            depth, prim, labels, instances, rgb = self._render_fast(T)
        else:
            depth, prim, labels, instances, rgb = self._cast(self.rays(T))
        return RenderResult(
            rgb=rgb.reshape(H, W, 3),
            depth=depth.reshape(H, W),
            labels=labels.reshape(H, W),
            instances=instances.reshape(H, W),
            triangle=prim.reshape(H, W),
        )

    def _cast(self, rays: np.ndarray):
        """Exact ray cast of (N,6) rays: depth, triangle, labels, instances, rgb (flat)."""
        import open3d as o3d

        ans = self._rc.cast_rays(o3d.core.Tensor(np.ascontiguousarray(rays)), nthreads=self.nthreads)
        t = ans["t_hit"].numpy()
        miss = ~np.isfinite(t)
        prim = ans["primitive_ids"].numpy().astype(np.int64)
        prim[miss] = -1  # the tables below end with a "miss" entry, indexed by -1
        t[miss] = 0.0
        labels = self._labels_ext[prim]
        instances = self._instances_ext[prim]
        rgb = self._shade(rays, t, prim, ans["primitive_uvs"].numpy())
        return t, prim, labels, instances, rgb

    def _plane_groups(self) -> np.ndarray:
        """Id per triangle of its group: same plane, category, instance and material."""
        sc = self.scene
        key = np.concatenate(
            [
                np.rint(self._normals * 1e3),
                np.rint(self._plane_d * 1e3)[:, None],
                sc.labels[:, None], sc.instances[:, None],
                np.rint(sc.albedo * 1e3),
                (sc.texture if sc.texture is not None else np.zeros(len(sc.labels)))[:, None],
            ],
            axis=1,
        ).astype(np.int64)
        _u, inv = np.unique(key, axis=0, return_inverse=True)
        return inv.reshape(-1)

    def _render_fast(self, pose: np.ndarray):
        """Coarse-to-fine rendering (``fast=True``).

        Every second pixel in both directions is ray cast. A pixel between coarse samples
        that all hit the same plane group (same plane, category, instance, material) takes
        their category and instance, the exact depth of that plane (1/z is affine in the
        pixel coordinates on a plane, so averaging the samples' 1/z is exact) and their mean
        colour; every other pixel is ray cast. Objects thinner than two pixels that fall
        entirely between samples can be missed.
        """
        H, W = self.intrinsics.shape
        hc, wc = (H + 1) // 2, (W + 1) // 2
        if self._groups is None:
            self._groups = self._plane_groups()
            self._coarse_index = np.arange(H * W).reshape(H, W)[0::2, 0::2].reshape(-1)
        d_c, p_c, l_c, i_c, rgb_c = self._cast(self.rays(pose, self._coarse_index))

        def padded(a, fill):
            # coarse image with one extra row and column (never equal: group -1)
            out = np.full((hc + 1, wc + 1) + a.shape[1:], fill, dtype=a.dtype)
            out[:hc, :wc] = a.reshape((hc, wc) + a.shape[1:])
            return out

        g = padded(np.where(p_c >= 0, self._groups[np.maximum(p_c, 0)], -1), -1)
        inv = padded(1.0 / np.maximum(d_c, np.float32(1e-9)), np.float32(0))
        col = padded(rgb_c.astype(np.uint16), 0)
        A, B = (slice(0, hc), slice(0, wc)), (slice(0, hc), slice(1, wc + 1))
        C, D = (slice(1, hc + 1), slice(0, wc)), (slice(1, hc + 1), slice(1, wc + 1))
        gA = g[A]
        ok_ab = (gA >= 0) & (g[B] == gA)
        ok_ac = (gA >= 0) & (g[C] == gA)
        ok_all = ok_ab & ok_ac & (g[D] == gA)
        # fine image as (hc, 2, wc, 2) blocks: [:, 0, :, 0] are the coarse samples
        depth = np.zeros((hc, 2, wc, 2), np.float32)
        prim = np.full((hc, 2, wc, 2), -1, np.int64)
        labels = np.zeros((hc, 2, wc, 2), np.uint8)
        inst = np.zeros((hc, 2, wc, 2), np.int32)
        rgb = np.zeros((hc, 2, wc, 2, 3), np.uint8)
        todo = np.zeros((hc, 2, wc, 2), bool)
        pA, lA, iA = p_c.reshape(hc, wc), l_c.reshape(hc, wc), i_c.reshape(hc, wc)
        depth[:, 0, :, 0], prim[:, 0, :, 0], labels[:, 0, :, 0] = d_c.reshape(hc, wc), pA, lA
        inst[:, 0, :, 0], rgb[:, 0, :, 0] = iA, rgb_c.reshape(hc, wc, 3)
        for (r, c), ok, nbs in (((0, 1), ok_ab, (A, B)), ((1, 0), ok_ac, (A, C)), ((1, 1), ok_all, (A, B, C, D))):
            s_inv = sum(inv[n] for n in nbs)
            depth[:, r, :, c] = np.divide(np.float32(len(nbs)), s_inv, out=np.zeros_like(s_inv), where=ok)
            prim[:, r, :, c] = np.where(ok, pA, -1)
            labels[:, r, :, c] = np.where(ok, lA, 0)
            inst[:, r, :, c] = np.where(ok, iA, 0)
            mean = (sum(col[n] for n in nbs) + len(nbs) // 2) // len(nbs)
            rgb[:, r, :, c] = np.where(ok[..., None], mean, 0)
            todo[:, r, :, c] = ~ok
        out = [x.reshape((2 * hc, 2 * wc) + x.shape[4:])[:H, :W].reshape((H * W,) + x.shape[4:])
               for x in (depth, prim, labels, inst, rgb, todo)]
        depth, prim, labels, inst, rgb, todo = out
        idx = np.flatnonzero(todo)
        if len(idx):
            d2, p2, l2, i2, rgb2 = self._cast(self.rays(pose, idx))
            depth[idx], prim[idx], labels[idx], inst[idx], rgb[idx] = d2, p2, l2, i2, rgb2
        self.last_cast_fraction = (hc * wc + len(idx)) / (H * W)
        return depth, prim, labels, inst, rgb

    def _shade(self, rays, t, prim, uv) -> np.ndarray:
        """RGB of hit points: albedo x interpolated irradiance x texture (misses: black)."""
        tri = np.maximum(prim, 0)
        # the camera sees the back side of triangles whose plane it is behind (self._side)
        corners = self._irradiance[tri + self._side[tri]]
        u, v = uv[:, 0], uv[:, 1]
        shade = corners[:, 0] + (corners[:, 1] - corners[:, 0]) * u + (corners[:, 2] - corners[:, 0]) * v
        if self.use_texture:
            p = rays[:, :3] + rays[:, 3:] * t[:, None]
            shade *= texture_factor(p, self.scene.texture[tri])
        col = self._albedo_ext[prim] * shade[:, None]  # albedo x 4095, 0 for misses
        np.minimum(col, 4095.0, out=col)
        return self._lut[col.astype(np.int16)]
