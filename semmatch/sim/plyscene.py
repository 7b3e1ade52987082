"""Scenes from any semantic PLY mesh (e.g. the Replica-derived meshes of ``../shared``).

Labels come from the palette (or the ``label`` property) through :func:`semmatch.io.read_map`;
colours outside the palette are counted in a warning and read as void. The mesh carries no
texture, so RGB comes from shading: every connected same-label part of the mesh gets a
material drawn from one pool shared by all categories (colour does not give the label).

The file's up axis is checked against the data: the floor triangles' mean normal (or minus
the ceiling's) must point up; when it points along another axis the mesh is rotated so that
z is up, and a warning says so.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from ..io import read_map
from ..io.geometry import triangle_labels as _triangle_labels
from ..io.labels import NUM_CLASSES, STUFF_CLASSES, id_of
from .materials import MATERIALS
from .scene import Scene

__all__ = ["scene_from_ply", "triangle_labels", "up_rotation"]

_STUFF = STUFF_CLASSES


def triangle_labels(faces: np.ndarray, vertex_labels: np.ndarray) -> np.ndarray:
    """Majority label of each triangle's three vertices (first vertex when all differ):
    :func:`semmatch.io.geometry.triangle_labels` with ``ties="first"``, the rule of these scenes."""
    return _triangle_labels(faces, vertex_labels, ties="first")


def _face_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    p = v[f]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def up_rotation(vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, str]:
    """Rotation that brings the mesh's measured up axis to +z, and a description of it.

    The up direction is the mean normal of the floor triangles, else minus that of the
    ceiling triangles, snapped to the nearest signed coordinate axis; without either, +z
    is trusted.
    """
    n = _face_normals(vertices, faces)
    up = None
    for lab, sign in ((id_of("floor"), 1.0), (id_of("ceiling"), -1.0)):
        m = labels == lab
        if m.sum() >= 10:
            mean = sign * n[m].mean(axis=0)
            if np.linalg.norm(mean) > 0.3:
                up = mean
                break
    if up is None:
        return np.eye(3), "+z (no floor/ceiling to check)"
    axis = int(np.argmax(np.abs(up)))
    sgn = float(np.sign(up[axis]))
    name = f"{'+' if sgn > 0 else '-'}{'xyz'[axis]}"
    if axis == 2 and sgn > 0:
        return np.eye(3), name
    target = np.zeros(3)
    target[axis] = sgn
    z = np.array([0.0, 0.0, 1.0])
    if axis == 2:  # -z: rotate 180 degrees about x
        return np.diag([1.0, -1.0, -1.0]), name
    k = np.cross(target, z)
    k /= np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + K + K @ K  # 90 degrees about k (target is orthogonal to z)
    return R, name


def _components(faces: np.ndarray, labels: np.ndarray, vertices: np.ndarray, weld: float = 2e-3) -> np.ndarray:
    """Connected parts of same-label triangles: component id per face.

    Vertices closer than ``weld`` are merged first (TSDF meshes such as voxblox's repeat the
    vertices on block borders).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    _u, welded = np.unique(np.floor(vertices / weld).astype(np.int64), axis=0, return_inverse=True)
    node = welded.reshape(-1)[faces].astype(np.int64) * NUM_CLASSES + labels[:, None]
    a = np.concatenate([node[:, 0], node[:, 1]])
    b = np.concatenate([node[:, 1], node[:, 2]])
    uniq, inv = np.unique(np.concatenate([a, b, node[:, 0]]), return_inverse=True)
    m = len(a)
    g = coo_matrix((np.ones(m), (inv[:m], inv[m : 2 * m])), shape=(len(uniq), len(uniq)))
    _n, comp = connected_components(g, directed=False)
    return comp[inv[2 * m :]]


def scene_from_ply(path: str | os.PathLike, *, seed: int = 0, min_part: int = 20) -> Scene:
    """Build a :class:`Scene` from a semantic PLY triangle mesh.

    Parameters
    ----------
    path : path
        PLY mesh with palette vertex colours or a ``label`` property.
    seed : int
        Seed of the material draw.
    min_part : int
        Parts with fewer triangles keep instance 0 (noise of the reconstruction).

    Returns
    -------
    Scene
        ``meta`` holds ``kind="ply"``, ``source``, ``up_axis``, ``floor_z``,
        ``ceiling_height`` and ``lights``.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Not a readable PLY, no faces (a point cloud), an empty mesh, NaN vertices.
    """
    from .trajectory import scene_levels

    path = Path(path)
    m = read_map(path)
    if len(m.points) == 0:
        raise ValueError(f"{path}: the mesh is empty (no vertices)")
    if not m.is_mesh:
        raise ValueError(f"{path}: a scene needs a triangle mesh; this PLY has no faces")
    faces = m.faces
    tri_lab = triangle_labels(faces, m.labels)
    v = m.points.astype(np.float64)
    R, up_name = up_rotation(v, faces, tri_lab)
    if up_name not in ("+z", "+z (no floor/ceiling to check)"):
        warnings.warn(f"{path}: the floor says the up axis is {up_name}, not +z; rotating the mesh",
                      UserWarning, stacklevel=2)
    v = v @ R.T
    comp = _components(faces, tri_lab, v)
    rng = np.random.default_rng(seed)
    names = list(MATERIALS)
    n_comp = int(comp.max()) + 1
    pick = rng.integers(len(names), size=n_comp)
    mats = [MATERIALS[n] for n in names]
    albedo_tab = np.array([m_.albedo for m_ in mats], dtype=np.float32)
    tex_tab = np.array([m_.texture for m_ in mats], dtype=np.uint8)
    albedo = albedo_tab[pick[comp]] * rng.uniform(0.9, 1.08, size=(n_comp, 1)).astype(np.float32)[comp]
    size = np.bincount(comp, minlength=n_comp)
    instances = np.where((size[comp] >= min_part) & ~np.isin(tri_lab, _STUFF), comp + 1, 0)
    scene = Scene(
        vertices=v.astype(np.float32), triangles=faces, labels=tri_lab, instances=instances,
        albedo=np.clip(albedo, 0, 1), name=path.stem, texture=tex_tab[pick[comp]],
        meta={"kind": "ply", "source": str(path), "up_axis": up_name},
    )
    floor, ceiling = scene_levels(scene)
    lo, hi = scene.bounds
    xs = np.linspace(lo[0], hi[0], 4)[1:-1]
    ys = np.linspace(lo[1], hi[1], 4)[1:-1]
    scene.meta.update(
        floor_z=float(floor), ceiling_height=float(ceiling - floor),
        lights=[[float(x), float(y), float(ceiling - 0.3)] for x in xs for y in ys],
    )
    return scene
