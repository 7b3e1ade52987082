"""The scene representation shared by the procedural generator, PLY scenes and the renderer."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io import SemanticMap, write_map

__all__ = ["Scene"]


@dataclass
class Scene:
    """A triangle mesh with per-triangle category, instance and albedo.

    Attributes
    ----------
    vertices : float32 (V,3)
        World coordinates, metres, z up.
    triangles : int32 (T,3)
    labels : uint8 (T,)
        Category id of each triangle.
    instances : int32 (T,)
        Instance id of each triangle (0 = stuff without instances).
    albedo : float32 (T,3)
        Material colour in [0, 1] (materials, not classes, decide it).
    name : str
    meta : dict
        Anything trajectories need (room boxes, free-space grid, lights, ceiling height).
    texture : uint8 (T,) or None
        Procedural texture kind of each triangle's material (see
        :mod:`semmatch.sim.materials`); None = untextured.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    labels: np.ndarray
    instances: np.ndarray
    albedo: np.ndarray
    name: str = "scene"
    meta: dict = field(default_factory=dict)
    texture: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float32).reshape(-1, 3)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int32).reshape(-1, 3)
        n = len(self.triangles)
        self.labels = np.ascontiguousarray(self.labels, dtype=np.uint8).reshape(-1)
        self.instances = np.ascontiguousarray(self.instances, dtype=np.int32).reshape(-1)
        self.albedo = np.ascontiguousarray(self.albedo, dtype=np.float32).reshape(-1, 3)
        if self.texture is not None:
            self.texture = np.ascontiguousarray(self.texture, dtype=np.uint8).reshape(-1)
        for what, arr in (
            ("labels", self.labels), ("instances", self.instances), ("albedo", self.albedo),
            ("texture", self.texture if self.texture is not None else self.labels),
        ):
            if len(arr) != n:
                raise ValueError(f"scene {self.name!r}: {len(arr)} {what} for {n} triangles")
        if n == 0:
            raise ValueError(f"scene {self.name!r}: the mesh is empty (no triangles)")
        if self.triangles.min() < 0 or self.triangles.max() >= len(self.vertices):
            raise ValueError(f"scene {self.name!r}: triangle index outside the vertex list")

    @property
    def n_triangles(self) -> int:
        """Number of triangles."""
        return len(self.triangles)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds ``(min_xyz, max_xyz)``."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def triangle_normals(self) -> np.ndarray:
        """Unit normals of the triangles, float32 (T,3)."""
        v = self.vertices[self.triangles]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return (n / np.maximum(norm, 1e-12)).astype(np.float32)

    def to_semantic_map(self) -> SemanticMap:
        """The ground-truth semantic mesh (per-vertex labels).

        Vertices shared by triangles of different categories are split so that every vertex
        carries exactly one label.
        """
        tri = self.triangles
        vert_label = np.zeros(len(self.vertices), dtype=np.int64) - 1
        # vertices whose triangles all agree keep their index; others are duplicated
        flat_v = tri.reshape(-1)
        flat_l = np.repeat(self.labels.astype(np.int64), 3)
        order = np.lexsort((flat_l, flat_v))
        pair = np.stack([flat_v[order], flat_l[order]], axis=1)
        uniq, inv_sorted = np.unique(pair, axis=0, return_inverse=True)
        inv = np.empty_like(inv_sorted)
        inv[order] = inv_sorted.reshape(-1)
        del vert_label
        points = self.vertices[uniq[:, 0]]
        labels = uniq[:, 1].astype(np.uint8)
        faces = inv.reshape(-1, 3)
        colors = np.clip(np.rint(self.albedo * 255), 0, 255).astype(np.uint8)
        vcol = np.zeros((len(points), 3), dtype=np.uint8)
        vcol[faces.reshape(-1)] = np.repeat(colors, 3, axis=0)
        return SemanticMap(points, labels, colors=vcol, faces=faces, source=f"scene:{self.name}")

    def save(self, path: str | Path) -> Path:
        """Write the ground-truth semantic mesh (``scene.ply``) per the data contract."""
        return write_map(path, self.to_semantic_map())

    @staticmethod
    def merge(parts: list[Scene], name: str = "scene", meta: dict | None = None) -> Scene:
        """Concatenate scenes (e.g. a room and its furniture) into one."""
        offs = np.cumsum([0] + [len(p.vertices) for p in parts[:-1]])
        return Scene(
            vertices=np.concatenate([p.vertices for p in parts]),
            triangles=np.concatenate([p.triangles + o for p, o in zip(parts, offs, strict=True)]),
            labels=np.concatenate([p.labels for p in parts]),
            instances=np.concatenate([p.instances for p in parts]),
            albedo=np.concatenate([p.albedo for p in parts]),
            name=name,
            meta=dict(meta or {}),
            texture=None if all(p.texture is None for p in parts) else np.concatenate(
                [p.texture if p.texture is not None else np.zeros(p.n_triangles, np.uint8) for p in parts]
            ),
        )
