"""Small analytic scenes and camera poses for the tests (not part of the package).

:func:`box` is an axis-aligned box as a :class:`Scene`; :func:`furnished_room` a closed room with
a few pieces of furniture (instances) on known footprints; :func:`orbit_poses` cameras inside a
room looking across it.
"""

from __future__ import annotations

import numpy as np

from semmatch.io.geometry import look_at
from semmatch.sim import Scene

_FACES = np.array(
    [
        [0, 2, 1], [0, 3, 2],  # bottom (z = lo)
        [4, 5, 6], [4, 6, 7],  # top
        [0, 1, 5], [0, 5, 4],  # y = lo
        [2, 3, 7], [2, 7, 6],  # y = hi
        [1, 2, 6], [1, 6, 5],  # x = hi
        [3, 0, 4], [3, 4, 7],  # x = lo
    ],
    dtype=np.int32,
)


def box(lo, hi, label: int, albedo, instance: int = 0, *, faces: slice | list | None = None) -> Scene:
    """An axis-aligned box ``lo..hi`` as a :class:`Scene` (12 triangles, or a subset of faces)."""
    lo, hi = np.asarray(lo, dtype=np.float32), np.asarray(hi, dtype=np.float32)
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array(
        [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
         [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],
        dtype=np.float32,
    )
    tri = _FACES if faces is None else _FACES[faces]
    n = len(tri)
    return Scene(v, tri, np.full(n, label), np.full(n, instance), np.tile(albedo, (n, 1)))


def furnished_room(seed: int = 0, size: tuple[float, float, float] = (5.0, 4.0, 2.6)) -> Scene:
    """A closed room (floor, ceiling, walls) with a few pieces of furniture.

    Parameters
    ----------
    seed : int
        Places the furniture and picks the materials (repeatable).
    size : (float, float, float)
        Room extent in metres (x, y, height); the floor is at z = 0.
    """
    rng = np.random.default_rng(seed)
    X, Y, Z = size
    parts = [
        box((0, 0, -0.05), (X, Y, 0.0), 2, (0.75, 0.7, 0.5), faces=[2, 3]),  # floor (top face)
        box((0, 0, Z), (X, Y, Z + 0.05), 3, (0.95, 0.95, 0.95), faces=[0, 1]),  # ceiling
        box((0, -0.05, 0), (X, 0.0, Z), 1, (0.8, 0.8, 0.85), faces=[6, 7]),  # walls
        box((0, Y, 0), (X, Y + 0.05, Z), 1, (0.8, 0.8, 0.85), faces=[4, 5]),
        box((-0.05, 0, 0), (0.0, Y, Z), 1, (0.85, 0.8, 0.8), faces=[8, 9]),
        box((X, 0, 0), (X + 0.05, Y, Z), 1, (0.85, 0.8, 0.8), faces=[10, 11]),
    ]
    # furniture: (label, footprint x, footprint y, height)
    furniture = [(5, 1.2, 0.8, 0.75), (4, 0.5, 0.5, 0.9), (4, 0.5, 0.5, 0.9), (10, 1.8, 0.8, 0.8),
                 (9, 1.6, 1.2, 0.5), (19, 0.6, 0.4, 1.4)]
    inst = 1
    obstacles = []
    for label, fx, fy, h in furniture:
        x = rng.uniform(0.3, X - fx - 0.3)
        y = rng.uniform(0.3, Y - fy - 0.3)
        col = rng.uniform(0.15, 0.9, 3)
        parts.append(box((x, y, 0.0), (x + fx, y + fy, h), label, col, inst))
        obstacles.append([x, y, x + fx, y + fy])
        inst += 1
    # a picture and a window on the walls
    parts.append(box((1.0, Y - 0.02, 1.2), (1.8, Y, 1.8), 8, (0.9, 0.3, 0.2), inst, faces=[4, 5]))
    parts.append(box((X - 0.02, 1.0, 0.9), (X, 2.2, 2.0), 6, (0.3, 0.6, 0.9), inst + 1, faces=[10, 11]))
    return Scene.merge(parts, name=f"box_room_{seed}", meta={"size": list(size), "obstacles": obstacles})


def orbit_poses(scene: Scene, n: int, height: float, seed: int = 0, *, margin: float = 0.6) -> np.ndarray:
    """``n`` camera poses at ``height`` inside the scene bounds, each looking across the room."""
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds
    centre = (lo + hi) / 2
    obstacles = np.asarray(scene.meta.get("obstacles", []), dtype=np.float64).reshape(-1, 4)
    poses = []
    while len(poses) < n:
        eye = np.array([rng.uniform(lo[0] + margin, hi[0] - margin),
                        rng.uniform(lo[1] + margin, hi[1] - margin), height])
        inside = (
            (eye[0] > obstacles[:, 0] - 0.3) & (eye[0] < obstacles[:, 2] + 0.3)
            & (eye[1] > obstacles[:, 1] - 0.3) & (eye[1] < obstacles[:, 3] + 0.3)
        )
        if inside.any():
            continue
        target = np.array([2 * centre[0] - eye[0] + rng.normal(0, 0.3),
                           2 * centre[1] - eye[1] + rng.normal(0, 0.3), rng.uniform(0.0, 1.0)])
        poses.append(look_at(eye, target))
    return np.asarray(poses)
