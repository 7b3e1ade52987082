"""A rasterising renderer: the contract's RGB, depth, labels and instances through OpenGL.

:class:`RasterRenderer` draws a :class:`~semmatch.sim.scene.Scene` with OpenGL 3.3 through
``moderngl`` on a headless EGL context: Mesa's llvmpipe on a CPU-only machine, the GPU's driver
where there is one, with the same code. It produces what the ray caster
(:class:`~semmatch.sim.render.Renderer`, the reference and the fallback) produces, from the same
lighting tables (it is built by the same constructor):

* **depth**: the camera-space z of the visible surface, interpolated perspective-correctly per
  pixel centre (exact on planar triangles up to float rounding);
* **triangle**: ``gl_PrimitiveID`` of the visible triangle (each triangle drawn with its own three
  corners, in scene order), hence **labels** and **instances** from the scene's tables;
* **RGB**: albedo x corner irradiance (interpolated, front or back side as the ray caster picks
  it) x the procedural material texture at the world point, through the same 12-bit display
  curve (:func:`semmatch.sim.materials.texture_factor` ported to GLSL).

Pixel ``(u, v)`` samples the camera ray through ``((u - cx) / fx, (v - cy) / fy, 1)``, as
:func:`semmatch.io.geometry.pixel_rays`. The depth range is ``[near, far]`` with ``near = 1 cm`` and
``far`` the farthest corner of the scene's bounds seen from anywhere inside them (plus a metre):
nothing of the scene is clipped.

Use :func:`make_renderer` to pick the backend: ``"auto"`` rasterises when an OpenGL context can
be made and falls back to ray casting with one warning otherwise; :func:`render_frames` renders
posed frames with the backend it picks.
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from ..io.geometry import DEFAULT_INTRINSICS, Intrinsics, check_pose
from .materials import _TEX
from .render import Renderer, RenderResult
from .scene import Scene

__all__ = ["RasterRenderer", "make_renderer", "render_frames", "gl_available", "BACKENDS"]

#: renderer backends: rasterise (OpenGL), ray cast (Open3D), or rasterise when possible
BACKENDS = ("auto", "raster", "raycast")

_NEAR = 0.01
_CHUNK = 0.5  # metres: floor-plan cell of a chunk of triangles (frustum culling)


def moderngl_nearest() -> int:
    """OpenGL's NEAREST filter constant (the per-triangle table is fetched texel by texel)."""
    import moderngl

    return moderngl.NEAREST

_VERTEX = """
#version 330
uniform mat4 view_proj;       // world -> clip
in vec3 in_pos;
in vec2 in_irr;               // corner irradiance: front side, back side
out vec3 v_world;
out vec2 v_irr;
void main() {
    gl_Position = view_proj * vec4(in_pos, 1.0);
    v_world = in_pos;
    v_irr = in_irr;
}
"""

_FRAGMENT = """
#version 330
uniform vec3 cam_pos;
uniform vec4 cam_z;           // row of world -> camera giving the camera-space z
uniform int use_texture;
uniform int base;             // first triangle of this draw call (in drawing order)
uniform sampler2D tri_data;   // per triangle (drawing order): plane (n, d); albedo, texture kind
uniform vec4 tex_a[8];        // amplitude, frequency, warp, -
uniform vec3 tex_dir[8];      // unit direction of the texture's phase
in vec3 v_world;
in vec2 v_irr;
layout(location = 0) out vec4 out_rgb;
layout(location = 1) out float out_depth;
layout(location = 2) out int out_tri;
void main() {
    int t = base + gl_PrimitiveID;
    int tw = textureSize(tri_data, 0).x / 2;
    vec4 plane = texelFetch(tri_data, ivec2(2 * (t % tw), t / tw), 0);
    vec4 mat = texelFetch(tri_data, ivec2(2 * (t % tw) + 1, t / tw), 0);
    // the side the camera sees: back when the camera is behind the triangle's plane
    bool back = dot(plane.xyz, cam_pos) < plane.w;
    float shade = back ? v_irr.y : v_irr.x;
    if (use_texture == 1) {
        int k = int(mat.w + 0.5);
        vec4 a = tex_a[k];
        float phase = a.y * dot(v_world, tex_dir[k]);
        float warp = a.z * sin(dot(v_world, vec3(3.1, 4.03, 2.17)));
        shade *= 1.0 + a.x * sin(phase + warp);
    }
    vec3 lin = min(mat.rgb * 4095.0 * shade, vec3(4095.0));
    vec3 idx = floor(lin);   // the 12-bit index of the ray caster's lookup table
    vec3 disp = floor(255.0 * pow(idx / 4095.0, vec3(1.0 / 2.2)) + 0.5);
    out_rgb = vec4(clamp(disp, 0.0, 255.0) / 255.0, 1.0);
    out_depth = dot(cam_z.xyz, v_world) + cam_z.w;
    out_tri = t + 1;
}
"""
_CONTEXT: dict = {}  # pid -> moderngl context (a forked child makes its own)
_WARNED: list[bool] = []


def _context():
    """The process's headless OpenGL context (EGL), created on first use."""
    pid = os.getpid()
    ctx = _CONTEXT.get(pid)
    if ctx is None:
        import moderngl

        ctx = moderngl.create_context(standalone=True, backend="egl", require=330)
        _CONTEXT.clear()
        _CONTEXT[pid] = ctx
    return ctx


def gl_available() -> tuple[bool, str]:
    """Whether a headless OpenGL 3.3 context can be made here, and why not.

    Returns
    -------
    (bool, str)
        ``(True, renderer name)`` or ``(False, reason)``.
    """
    try:
        ctx = _context()
    except ImportError as e:
        return False, f"moderngl is not installed ({e})"
    except Exception as e:  # moderngl/glcontext raise plain Exceptions for a missing EGL
        return False, f"no headless OpenGL context ({type(e).__name__}: {str(e).strip()[:200]})"
    return True, str(ctx.info.get("GL_RENDERER", "OpenGL"))


class RasterRenderer(Renderer):
    """Render a scene from posed pinhole cameras by rasterisation (OpenGL, headless EGL).

    Takes the arguments of :class:`~semmatch.sim.render.Renderer` (``fast`` and ``nthreads``
    apply to its shadow rays only) and returns the same :class:`RenderResult`.

    Raises
    ------
    RuntimeError
        No OpenGL 3.3 context can be made (the message says why; :func:`make_renderer` with
        ``backend="auto"`` falls back to ray casting instead).
    """

    def __init__(self, scene: Scene, intrinsics: Intrinsics = DEFAULT_INTRINSICS, **kwargs) -> None:
        ok, why = gl_available()
        if not ok:
            raise RuntimeError(f"cannot rasterise: {why}; use backend='raycast' (or 'auto' to fall back)")
        kwargs.pop("fast", None)
        super().__init__(scene, intrinsics, **kwargs)
        self.gl_renderer = why
        self._setup_gl()

    def _setup_gl(self) -> None:
        ctx = _context()
        sc = self.scene
        T = sc.n_triangles
        # triangles in drawing order: grouped by chunk (a 1 m column of the floor plan), so that
        # each frame draws only the chunks whose bounding box meets the view frustum
        centre = sc.vertices[sc.triangles].mean(axis=1)
        lo = centre.min(axis=0)
        cell = np.floor((centre[:, :2] - lo[:2]) / _CHUNK).astype(np.int64)
        key = cell[:, 0] * (int(cell[:, 1].max()) + 1) + cell[:, 1]
        order = np.argsort(key, kind="stable")
        starts = np.flatnonzero(np.r_[True, np.diff(key[order]) != 0])
        self._order = order
        self._chunks = np.append(starts, T)
        tri = sc.triangles[order]
        corners = sc.vertices[tri]  # (T, 3, 3)
        self._chunk_box = np.stack([
            np.stack([corners[a:b].reshape(-1, 3).min(axis=0), corners[a:b].reshape(-1, 3).max(axis=0)])
            for a, b in zip(self._chunks[:-1], self._chunks[1:], strict=True)])
        # the corner irradiance is a per-vertex quantity (gathered to the corners): shared
        # vertices are drawn indexed, once per vertex cache entry instead of once per corner
        irr = np.zeros((len(sc.vertices), 2), np.float32)
        for side in range(2):
            irr[sc.triangles.reshape(-1), side] = self._irradiance[side * T:(side + 1) * T].reshape(-1)
        data = np.concatenate([sc.vertices, irr], axis=1).astype("f4")
        kinds = sc.texture if sc.texture is not None else np.zeros(T, np.uint8)
        per_tri = np.zeros((T, 2, 4), np.float32)
        per_tri[:, 0, :3] = self._normals[order]
        per_tri[:, 0, 3] = self._plane_d[order]
        per_tri[:, 1, :3] = sc.albedo[order]
        per_tri[:, 1, 3] = np.minimum(kinds[order], len(_TEX) - 1)
        tw = 2048  # triangles per texture row (two texels each)
        rows = -(-T // tw)
        table = np.zeros((rows * tw, 2, 4), np.float32)
        table[:T] = per_tri
        self._tri_tex = ctx.texture((2 * tw, rows), 4, table.tobytes(), dtype="f4")
        self._tri_tex.filter = (moderngl_nearest(), moderngl_nearest())
        self._prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self._vbo = ctx.buffer(np.ascontiguousarray(data).tobytes())
        self._ibo = ctx.buffer(np.ascontiguousarray(tri, dtype="u4").tobytes())
        self._vao = ctx.vertex_array(self._prog, [(self._vbo, "3f 2f", "in_pos", "in_irr")], self._ibo, 4)
        tex_a = np.zeros((8, 4), np.float32)
        tex_dir = np.zeros((8, 3), np.float32)
        tex_a[: len(_TEX), 0] = _TEX[:, 0]
        tex_a[: len(_TEX), 1] = _TEX[:, 1]
        tex_a[: len(_TEX), 2] = _TEX[:, 5]
        tex_dir[: len(_TEX)] = _TEX[:, 2:5]
        self._prog["tex_a"].write(tex_a.tobytes())
        self._prog["tex_dir"].write(tex_dir.tobytes())
        self._prog["use_texture"].value = int(self.use_texture)
        self._prog["tri_data"].value = 0
        W, H = self.intrinsics.width, self.intrinsics.height
        self._rgb = ctx.renderbuffer((W, H), 4)
        self._depth = ctx.renderbuffer((W, H), 1, dtype="f4")
        self._tri = ctx.renderbuffer((W, H), 1, dtype="i4")
        self._zbuf = ctx.depth_renderbuffer((W, H))
        self._fbo = ctx.framebuffer([self._rgb, self._depth, self._tri], self._zbuf)
        # drawing order -> scene triangle, with the "miss" entry last (index -1)
        self._prim_of = np.append(order, -1).astype(np.int64)
        lo, hi = sc.bounds
        self._far = float(np.linalg.norm(np.asarray(hi, np.float64) - np.asarray(lo, np.float64))) + 1.0

    def _visible_ranges(self, vp: np.ndarray) -> list[tuple[int, int]]:
        """Triangle ranges (drawing order) of the chunks whose box meets the view frustum, nearest first."""
        lo, hi = self._chunk_box[:, 0], self._chunk_box[:, 1]
        corners = np.stack([np.where(np.array([(i >> k) & 1 for k in range(3)], bool), hi, lo) for i in range(8)],
                           axis=1)  # (C, 8, 3)
        clip = corners @ vp[:3, :3].T + vp[:3, 3]
        w = corners @ vp[3, :3] + vp[3, 3]
        outside = np.zeros(len(lo), bool)
        for a in range(3):  # all 8 corners beyond one plane of the frustum
            outside |= (clip[..., a] > w).all(axis=1) | (clip[..., a] < -w).all(axis=1)
        # front to back: nearer chunks fill the depth buffer first, so the early depth test
        # rejects the hidden fragments of farther ones before they are shaded
        vis = np.flatnonzero(~outside)
        centre = (lo[vis] + hi[vis]) / 2
        eye = np.linalg.solve(vp, [0.0, 0.0, -1.0, 1.0])  # a point near the camera (clip origin)
        vis = vis[np.argsort(np.linalg.norm(centre - eye[:3] / eye[3], axis=1), kind="stable")]
        return [(int(self._chunks[c]), int(self._chunks[c + 1])) for c in vis]

    def _matrices(self, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(world -> clip, world -> camera) for pose ``T`` (``T_world_camera``)."""
        intr = self.intrinsics
        W, H = intr.width, intr.height
        n, f = _NEAR, self._far
        # window x = fx X/Z + cx + 1/2 (pixel u's centre at u + 1/2); rows are not flipped:
        # OpenGL's bottom row 0 holds image row 0, so the read-back image is top-down
        P = np.zeros((4, 4))
        P[0, 0], P[0, 2] = 2 * intr.fx / W, 2 * (intr.cx + 0.5) / W - 1
        P[1, 1], P[1, 2] = 2 * intr.fy / H, 2 * (intr.cy + 0.5) / H - 1
        P[2, 2], P[2, 3] = (f + n) / (f - n), -2 * f * n / (f - n)
        P[3, 2] = 1.0
        V = np.linalg.inv(T)
        return P @ V, V

    def render(self, pose: np.ndarray) -> RenderResult:
        """Render the view of camera pose ``pose`` (``T_world_camera``).

        Raises
        ------
        ValueError
            If ``pose`` is not a 4x4 rigid transform.
        """
        import moderngl

        T = check_pose(pose)
        H, W = self.intrinsics.shape
        vp, V = self._matrices(T)
        prog = self._prog
        prog["view_proj"].write(vp.T.astype("f4").tobytes())  # column-major for GLSL
        prog["cam_z"].value = tuple(float(x) for x in V[2])
        prog["cam_pos"].value = tuple(float(x) for x in T[:3, 3])
        ctx = _context()
        self._fbo.use()
        ctx.viewport = (0, 0, W, H)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        self._fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self._tri_tex.use(location=0)
        for a, b in self._visible_ranges(vp):
            prog["base"].value = a
            self._vao.render(moderngl.TRIANGLES, vertices=3 * (b - a), first=3 * a)
        rgb = np.frombuffer(self._fbo.read(components=4, attachment=0), np.uint8).reshape(H, W, 4)[..., :3]
        depth = np.frombuffer(self._fbo.read(components=1, attachment=1, dtype="f4"), np.float32).reshape(H, W)
        tri = np.frombuffer(self._fbo.read(components=1, attachment=2, dtype="i4"), np.int32).reshape(H, W)
        prim = self._prim_of[tri.astype(np.int64) - 1]  # -1 = miss; the tables end with the "miss" entry
        depth = np.where(prim >= 0, depth, np.float32(0.0))
        return RenderResult(
            rgb=np.ascontiguousarray(rgb),
            depth=depth,
            labels=self._labels_ext[prim],
            instances=self._instances_ext[prim],
            triangle=prim,
        )

    def release(self) -> None:
        """Free the GL objects of this renderer (the process's context stays for the next one)."""
        for name in ("_vao", "_vbo", "_ibo", "_prog", "_fbo", "_rgb", "_depth", "_tri", "_zbuf", "_tri_tex"):
            obj = getattr(self, name, None)
            if obj is not None:
                obj.release()
                setattr(self, name, None)

    def __del__(self) -> None:
        try:
            self.release()
        except Exception:  # interpreter shutdown: the context may be gone already
            pass


def make_renderer(scene: Scene, intrinsics: Intrinsics = DEFAULT_INTRINSICS, *, backend: str = "auto",
                  **kwargs) -> Renderer:
    """A renderer of ``scene`` with the chosen backend.

    Parameters
    ----------
    scene : Scene
    intrinsics : Intrinsics
    backend : {"auto", "raster", "raycast"}
        ``raster``: OpenGL (an error when no context can be made); ``raycast``: Open3D ray
        casting (the reference); ``auto``: rasterise when possible, else ray cast with one
        warning per process.
    **kwargs
        Passed to the renderer (see :class:`~semmatch.sim.render.Renderer`).

    Returns
    -------
    Renderer
        A :class:`RasterRenderer` or a :class:`~semmatch.sim.render.Renderer`.

    Raises
    ------
    ValueError
        An unknown backend.
    RuntimeError
        ``backend="raster"`` where no OpenGL context can be made.
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown renderer backend {backend!r}; valid: {', '.join(BACKENDS)}")
    if backend == "raycast":
        return Renderer(scene, intrinsics, **kwargs)
    if backend == "auto":
        ok, why = gl_available()
        if not ok:
            if not _WARNED:
                _WARNED.append(True)
                warnings.warn(f"rasteriser unavailable ({why}); rendering by ray casting instead", UserWarning,
                              stacklevel=2)
            return Renderer(scene, intrinsics, **kwargs)
    return RasterRenderer(scene, intrinsics, **kwargs)


def render_frames(scene: Scene, poses: np.ndarray, intrinsics: Intrinsics = DEFAULT_INTRINSICS, *,
                  backend: str = "raycast") -> list:
    """Posed frames (RGB, depth, ground-truth labels) of ``scene`` seen from ``poses``.

    Parameters
    ----------
    scene : Scene
    poses : ndarray (N, 4, 4)
        ``T_world_camera``.
    intrinsics : Intrinsics
    backend : {"raycast", "raster", "auto"}
        See :func:`make_renderer`.

    Returns
    -------
    list of semmatch.io.Frame
        With ``index`` 0..N-1 and the true poses.
    """
    from ..io import Frame

    r = make_renderer(scene, intrinsics, backend=backend)
    out = []
    for i, T in enumerate(np.asarray(poses)):
        res = r.render(T)
        out.append(Frame(res.rgb, res.depth, res.labels, np.asarray(T), intrinsics, index=i))
    return out
