"""Seeded procedural indoor scenes: living room, bedroom, office, an apartment of connected
rooms, and an analytic box room for tests.

Every object is a composition of (subdivided) boxes: tables on legs with free space under
them, chairs with seat, legs and back, sofas with arms and back, beds with a mattress and
pillows, cabinets, monitors, trash cans and small objects. Objects are placed without
intersecting, against walls or free standing, and keep passages free for the trajectories.
Albedo comes from materials (:mod:`semmatch.sim.materials`), not from categories.

``scene.meta`` holds what the trajectories and the renderer need: ``rooms`` (list of
``[xmin, ymin, xmax, ymax]``), ``ceiling_height``, ``floor_z``, ``lights`` and ``kind``.

Size: one module of about 660 lines, on purpose. The room and furniture builders share the box
helpers and one seeded random stream per scene, and the order of its draws defines each scene:
kept together, that order reads top to bottom; a builder moved elsewhere that drew once more or
once less would change every scene generated after it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..io.labels import id_of
from .materials import MATERIALS, ROLE_CHOICES
from .scene import Scene

__all__ = ["generate_scene", "box_room", "SCENE_KINDS"]

SCENE_KINDS = ("living_room", "bedroom", "office", "apartment", "box_room")

#: faces of a box: (axis, side) with side 0 = min, 1 = max
_FACES = [(a, s) for a in range(3) for s in range(2)]


def _face_grid(a: int, s: int, lo: np.ndarray, hi: np.ndarray, cell: float, inward: bool):
    b, c = [x for x in range(3) if x != a]
    nu = max(1, int(np.ceil((hi[b] - lo[b]) / cell)))
    nv = max(1, int(np.ceil((hi[c] - lo[c]) / cell)))
    u = np.linspace(lo[b], hi[b], nu + 1)
    v = np.linspace(lo[c], hi[c], nv + 1)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    verts = np.empty((uu.size, 3))
    verts[:, a] = hi[a] if s else lo[a]
    verts[:, b] = uu.ravel()
    verts[:, c] = vv.ravel()
    idx = np.arange(uu.size).reshape(nu + 1, nv + 1)
    i00, i10, i01, i11 = idx[:-1, :-1], idx[1:, :-1], idx[:-1, 1:], idx[1:, 1:]
    tris = np.concatenate(
        [np.stack([i00, i10, i11], -1).reshape(-1, 3), np.stack([i00, i11, i01], -1).reshape(-1, 3)]
    )
    # winding: e_b x e_c = +e_a (b, c in cyclic order) or -e_a
    sign = 1.0 if (b, c) in ((1, 2), (2, 0), (0, 1)) else -1.0
    want = (1.0 if s else -1.0) * (-1.0 if inward else 1.0)
    if sign != want:
        tris = tris[:, ::-1]
    return verts, tris


@dataclass
class _Builder:
    """Accumulates boxes into a :class:`Scene`."""

    cell: float = 0.3
    verts: list = field(default_factory=list)
    tris: list = field(default_factory=list)
    labels: list = field(default_factory=list)
    instances: list = field(default_factory=list)
    albedo: list = field(default_factory=list)
    texture: list = field(default_factory=list)
    n_vert: int = 0
    next_instance: int = 1

    def new_instance(self) -> int:
        self.next_instance += 1
        return self.next_instance - 1

    def box(
        self,
        lo,
        hi,
        label: str | dict,
        material: tuple[np.ndarray, int],
        instance: int = 0,
        *,
        yaw: float = 0.0,
        origin=(0.0, 0.0, 0.0),
        inward: bool = False,
        skip: tuple[tuple[int, int], ...] = (),
    ) -> None:
        """Add a box ``lo..hi`` (local frame), rotated by ``yaw`` about z and moved to ``origin``.

        ``label`` is a category name or a dict ``{(axis, side): name}`` per face (walls/floor).
        """
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        if np.any(hi - lo <= 0):
            return
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        for a, side in _FACES:
            if (a, side) in skip:
                continue
            v, t = _face_grid(a, side, lo, hi, self.cell, inward)
            v = v @ R.T + np.asarray(origin, float)
            name = label[(a, side)] if isinstance(label, dict) else label
            mat = material[(a, side)] if isinstance(material, dict) else material
            self.verts.append(v)
            self.tris.append(t + self.n_vert)
            self.n_vert += len(v)
            n = len(t)
            self.labels.append(np.full(n, id_of(name), np.uint8))
            self.instances.append(np.full(n, instance, np.int32))
            self.albedo.append(np.broadcast_to(np.asarray(mat[0], np.float32), (n, 3)))
            self.texture.append(np.full(n, mat[1], np.uint8))

    def build(self, name: str, meta: dict) -> Scene:
        return Scene(
            vertices=np.concatenate(self.verts),
            triangles=np.concatenate(self.tris),
            labels=np.concatenate(self.labels),
            instances=np.concatenate(self.instances),
            albedo=np.concatenate(self.albedo),
            name=name,
            meta=meta,
            texture=np.concatenate(self.texture),
        )


class _Palette:
    """Per-scene material choices with a little colour jitter (seeded)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self._cache: dict[str, tuple[np.ndarray, int]] = {}

    def get(self, name: str) -> tuple[np.ndarray, int]:
        if name not in self._cache:
            m = MATERIALS[name]
            jitter = self.rng.uniform(0.93, 1.05) * self.rng.uniform(0.97, 1.03, 3)
            self._cache[name] = (np.clip(np.asarray(m.albedo) * jitter, 0, 1), m.texture)
        return self._cache[name]

    def role(self, role: str) -> tuple[np.ndarray, int]:
        return self.get(str(self.rng.choice(ROLE_CHOICES[role])))

    def colour(self) -> tuple[np.ndarray, int]:
        """A random art colour (pictures, small objects), untextured noise kind."""
        return self.rng.uniform(0.1, 0.9, 3), 1


# ----------------------------------------------------------------------------- furniture
# each builder adds parts in a local frame (x across, y depth with the back at +y, z up,
# footprint centred on the origin) and returns the footprint (w, d)

def _table(b, P, rng, inst, yaw, org, *, w=None, d=None, h=None, mat=None):
    w = w or rng.uniform(1.0, 1.8)
    d = d or rng.uniform(0.7, 1.0)
    h = h or rng.uniform(0.72, 0.78)
    mat = mat or P.role("wood")
    top = rng.uniform(0.03, 0.05)
    b.box((-w / 2, -d / 2, h - top), (w / 2, d / 2, h), "table", mat, inst, yaw=yaw, origin=org)
    leg = 0.05
    legmat = mat if rng.random() < 0.6 else P.role("metal")
    for sx in (-1, 1):
        for sy in (-1, 1):
            cx, cy = sx * (w / 2 - 0.08), sy * (d / 2 - 0.08)
            b.box((cx - leg / 2, cy - leg / 2, 0), (cx + leg / 2, cy + leg / 2, h - top), "table", legmat, inst,
                  yaw=yaw, origin=org, skip=((2, 0),))
    return w, d, h, mat


def _chair(b, P, rng, inst, yaw, org, *, mat=None):
    w, d = rng.uniform(0.42, 0.5), rng.uniform(0.42, 0.5)
    sh, bh = rng.uniform(0.43, 0.48), rng.uniform(0.85, 1.0)
    mat = mat or (P.role("wood") if rng.random() < 0.6 else P.role("fabric"))
    legmat = mat if rng.random() < 0.5 else P.role("metal")
    b.box((-w / 2, -d / 2, sh - 0.05), (w / 2, d / 2, sh), "chair", mat, inst, yaw=yaw, origin=org)
    leg = 0.035
    for sx in (-1, 1):
        for sy in (-1, 1):
            cx, cy = sx * (w / 2 - 0.03), sy * (d / 2 - 0.03)
            b.box((cx - leg / 2, cy - leg / 2, 0), (cx + leg / 2, cy + leg / 2, sh - 0.05), "chair", legmat, inst,
                  yaw=yaw, origin=org, skip=((2, 0),))
    b.box((-w / 2, d / 2 - 0.05, sh), (w / 2, d / 2, bh), "chair", mat, inst, yaw=yaw, origin=org)
    return w, d


def _sofa(b, P, rng, inst, yaw, org, *, w=None, mat=None, pillows=True):
    w, d = w or rng.uniform(1.6, 2.4), rng.uniform(0.8, 0.95)
    mat = mat or P.role("fabric")
    seat, back_h, arm = rng.uniform(0.4, 0.46), rng.uniform(0.75, 0.9), 0.16
    b.box((-w / 2, -d / 2, 0.08), (w / 2, d / 2, seat), "sofa", mat, inst, yaw=yaw, origin=org)
    b.box((-w / 2, d / 2 - 0.2, seat), (w / 2, d / 2, back_h), "sofa", mat, inst, yaw=yaw, origin=org)
    for sx in (-1, 1):
        x0 = w / 2 - arm if sx > 0 else -w / 2
        b.box((x0, -d / 2, seat), (x0 + arm, d / 2 - 0.2, seat + 0.2), "sofa", mat, inst, yaw=yaw, origin=org)
    feet = P.role("metal")
    for sx in (-1, 1):
        for sy in (-1, 1):
            cx, cy = sx * (w / 2 - 0.06), sy * (d / 2 - 0.06)
            b.box((cx - 0.03, cy - 0.03, 0), (cx + 0.03, cy + 0.03, 0.08), "sofa", feet, inst, yaw=yaw, origin=org,
                  skip=((2, 0),))
    if pillows:
        pmat = P.role("fabric")
        for i in range(int(rng.integers(1, 4))):
            px = -w / 2 + arm + 0.25 + i * 0.5
            if px + 0.2 > w / 2 - arm:
                break
            b.box((px - 0.2, d / 2 - 0.32, seat), (px + 0.2, d / 2 - 0.2, seat + 0.38), "pillow", pmat,
                  b.new_instance(), yaw=yaw, origin=org)
    return w, d


def _bed(b, P, rng, inst, yaw, org, *, w=1.45):
    d = rng.uniform(2.0, 2.15)
    frame = P.role("wood")
    sheet = P.role("sheet")
    b.box((-w / 2, -d / 2, 0.0), (w / 2, d / 2, 0.3), "bed", frame, inst, yaw=yaw, origin=org, skip=((2, 0),))
    b.box((-w / 2 + 0.02, -d / 2 + 0.02, 0.3), (w / 2 - 0.02, d / 2 - 0.02, 0.52), "bed", sheet, inst,
          yaw=yaw, origin=org)
    b.box((-w / 2, d / 2 - 0.06, 0.0), (w / 2, d / 2, rng.uniform(0.9, 1.2)), "bed", frame, inst, yaw=yaw,
          origin=org)
    pmat = P.role("fabric") if rng.random() < 0.5 else sheet
    n = 1 if w < 1.2 else 2
    for i in range(n):
        px = (i - (n - 1) / 2) * (w / n)
        b.box((px - 0.3, d / 2 - 0.5, 0.52), (px + 0.3, d / 2 - 0.12, 0.66), "pillow", pmat, b.new_instance(),
              yaw=yaw, origin=org)
    return w, d


def _cabinet(b, P, rng, inst, yaw, org, *, w=None, d=None, h=None):
    w = w or rng.uniform(0.5, 1.4)
    d = d or rng.uniform(0.35, 0.6)
    h = h or rng.choice([rng.uniform(0.45, 0.9), rng.uniform(1.6, 2.0)])
    mat = P.role("cabinet")
    b.box((-w / 2, -d / 2, 0.0), (w / 2, d / 2, h), "cabinet", mat, inst, yaw=yaw, origin=org, skip=((2, 0),))
    # a door gap line and handle make it read as furniture
    b.box((-0.01, -d / 2 - 0.01, 0.1), (0.01, -d / 2, h - 0.1), "cabinet", P.role("metal"), inst, yaw=yaw,
          origin=org)
    return w, d, h


def _monitor(b, P, rng, yaw, org, z):
    w = rng.uniform(0.5, 0.7)
    inst = b.new_instance()
    m = P.get("metal_black")
    b.box((-0.1, -0.05, z), (0.1, 0.1, z + 0.02), "monitor", m, inst, yaw=yaw, origin=org)
    b.box((-0.03, 0.04, z), (0.03, 0.07, z + 0.15), "monitor", m, inst, yaw=yaw, origin=org)
    b.box((-w / 2, 0.0, z + 0.12), (w / 2, 0.04, z + 0.12 + w * 0.6), "monitor", m, inst, yaw=yaw, origin=org)


def _small_objects(b, P, rng, yaw, org, z, w, d, n):
    for _ in range(n):
        sx, sy = rng.uniform(0.05, 0.25) * min(1.0, w), rng.uniform(0.05, 0.25) * min(1.0, d)
        sz = rng.uniform(0.04, 0.3)
        cx = rng.uniform(-w / 2 + sx, w / 2 - sx)
        cy = rng.uniform(-d / 2 + sy, d / 2 - sy)
        b.box((cx - sx / 2, cy - sy / 2, z), (cx + sx / 2, cy + sy / 2, z + sz), "object", P.colour(),
              b.new_instance(), yaw=yaw, origin=org)


def _trashcan(b, P, rng, yaw, org):
    s, h = rng.uniform(0.25, 0.35), rng.uniform(0.3, 0.5)
    b.box((-s / 2, -s / 2, 0.0), (s / 2, s / 2, h), "trashcan", P.role("metal"), b.new_instance(), yaw=yaw,
          origin=org, skip=((2, 0),))
    return s, s


# ----------------------------------------------------------------------------- placement
class _Room:
    """A rectangular room with footprint bookkeeping for non-intersecting placement."""

    def __init__(self, rect, rng: np.random.Generator, keep_free=()):
        self.rect = np.asarray(rect, float)
        self.rng = rng
        self.taken: list[np.ndarray] = [np.asarray(k, float) for k in keep_free]

    def _fits(self, fp: np.ndarray, gap: float) -> bool:
        x0, y0, x1, y1 = self.rect
        if fp[0] < x0 - 1e-6 or fp[1] < y0 - 1e-6 or fp[2] > x1 + 1e-6 or fp[3] > y1 + 1e-6:
            return False
        for t in self.taken:
            if fp[0] < t[2] + gap and t[0] < fp[2] + gap and fp[1] < t[3] + gap and t[1] < fp[3] + gap:
                return False
        return True

    def against_wall(self, w: float, d: float, *, gap: float = 0.15, tries: int = 40):
        """Pose (yaw, origin) of a ``w x d`` footprint with its back (+y) against a wall."""
        x0, y0, x1, y1 = self.rect
        for _ in range(tries):
            side = int(self.rng.integers(4))
            if side == 0:  # north wall y1, back to +y
                c = self.rng.uniform(x0 + w / 2, x1 - w / 2) if x1 - x0 > w else None
                org, yaw, fp = (c, y1 - d / 2), 0.0, (c - w / 2, y1 - d, c + w / 2, y1) if c is not None else None
            elif side == 1:  # south wall y0, back to -y
                c = self.rng.uniform(x0 + w / 2, x1 - w / 2) if x1 - x0 > w else None
                org, yaw, fp = (c, y0 + d / 2), np.pi, (c - w / 2, y0, c + w / 2, y0 + d) if c is not None else None
            elif side == 2:  # east wall x1, back to +x
                c = self.rng.uniform(y0 + w / 2, y1 - w / 2) if y1 - y0 > w else None
                org, yaw, fp = (x1 - d / 2, c), -np.pi / 2, (x1 - d, c - w / 2, x1, c + w / 2) if c is not None else None
            else:  # west wall x0, back to -x
                c = self.rng.uniform(y0 + w / 2, y1 - w / 2) if y1 - y0 > w else None
                org, yaw, fp = (x0 + d / 2, c), np.pi / 2, (x0, c - w / 2, x0 + d, c + w / 2) if c is not None else None
            if fp is None:
                continue
            fp = np.asarray(fp)
            if self._fits(fp, gap):
                self.taken.append(fp)
                return yaw, np.array([org[0], org[1], 0.0])
        return None

    def free_standing(self, w: float, d: float, *, gap: float = 0.8, wall_gap: float = 0.8, tries: int = 40):
        """Pose (yaw, origin) of a free-standing ``w x d`` footprint (axis-aligned, random flip)."""
        x0, y0, x1, y1 = self.rect
        for _ in range(tries):
            yaw = float(self.rng.choice([0.0, np.pi / 2, np.pi, -np.pi / 2]))
            ew, ed = (w, d) if abs(np.sin(yaw)) < 0.5 else (d, w)
            lox, hix = x0 + wall_gap + ew / 2, x1 - wall_gap - ew / 2
            loy, hiy = y0 + wall_gap + ed / 2, y1 - wall_gap - ed / 2
            if lox > hix or loy > hiy:
                return None
            cx, cy = self.rng.uniform(lox, hix), self.rng.uniform(loy, hiy)
            fp = np.array([cx - ew / 2, cy - ed / 2, cx + ew / 2, cy + ed / 2])
            if self._fits(fp, gap):
                self.taken.append(fp)
                return yaw, np.array([cx, cy, 0.0])
        return None


def _local_to_world(yaw: float, org: np.ndarray, xy) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([c * xy[0] - s * xy[1] + org[0], s * xy[0] + c * xy[1] + org[1], 0.0])


def _dining_group(b, P, rng, room: _Room, n_chairs: int) -> None:
    w, d = rng.uniform(1.0, 1.6), rng.uniform(0.75, 0.95)
    pose = room.free_standing(w + 0.9, d + 0.9)
    if pose is None:
        return
    yaw, org = pose
    _w, _d, h, _mat = _table(b, P, rng, b.new_instance(), yaw, org, w=w, d=d)
    _small_objects(b, P, rng, yaw, org, h, w * 0.7, d * 0.7, int(rng.integers(0, 3)))
    chair_mat = P.role("wood") if rng.random() < 0.5 else P.role("fabric")
    spots = [(-w / 4, -d / 2 - 0.2, 0.0), (w / 4, -d / 2 - 0.2, 0.0), (-w / 4, d / 2 + 0.2, np.pi),
             (w / 4, d / 2 + 0.2, np.pi), (-w / 2 - 0.2, 0.0, -np.pi / 2), (w / 2 + 0.2, 0.0, np.pi / 2)]
    order = rng.permutation(len(spots))[:n_chairs]
    for k in order:
        x, y, cyaw = spots[k]
        # a chair at (x, y) faces the table: its back (+y local) points away from it
        jitter = rng.uniform(-0.25, 0.25)
        _chair(b, P, rng, b.new_instance(), yaw + cyaw + np.pi + jitter, _local_to_world(yaw, org, (x, y)),
               mat=chair_mat)


def _desk_group(b, P, rng, room: _Room) -> None:
    for scale in (1.0, 0.8, 0.65):
        w, d = rng.uniform(1.2, 1.6) * scale, rng.uniform(0.65, 0.8) * max(scale, 0.8)
        pose = room.against_wall(w, d + 0.7, gap=0.3 * scale)
        if pose is not None:
            break
    else:
        return
    yaw, org = pose
    torg = _local_to_world(yaw, org, (0.0, 0.35))
    _w, _d, h, _m = _table(b, P, rng, b.new_instance(), yaw, torg, w=w, d=d)
    _monitor(b, P, rng, yaw, _local_to_world(yaw, torg, (rng.uniform(-0.2, 0.2), 0.1)), h)
    _small_objects(b, P, rng, yaw, torg, h, w * 0.8, d * 0.5, int(rng.integers(0, 3)))
    _chair(b, P, rng, b.new_instance(), yaw + rng.uniform(-0.4, 0.4), _local_to_world(yaw, org, (0.0, -0.15)))


def _wall_items(b, P, rng, rect, H, outer: tuple[bool, bool, bool, bool], door_spans) -> None:
    """Windows with curtains on outer walls, pictures on the others."""
    x0, y0, x1, y1 = rect
    walls = [  # (start xy, direction xy, inward normal xy, length)
        ((x0, y1), (1, 0), (0, -1), x1 - x0),
        ((x1, y0), (-1, 0), (0, 1), x1 - x0),
        ((x1, y1), (0, -1), (-1, 0), y1 - y0),
        ((x0, y0), (0, 1), (1, 0), y1 - y0),
    ]
    glass, frame = P.get("glass"), P.role("frame")
    curtain = P.role("fabric")
    for k, (st, dr, _nrm, length) in enumerate(walls):
        yaw = np.arctan2(dr[1], dr[0])  # local x along the wall, local -y into the room

        def org_at(t, st=st, dr=dr):
            return np.array([st[0] + dr[0] * t, st[1] + dr[1] * t, 0.0])

        spans = [s for (kk, s) in door_spans if kk == k]
        if outer[k] and length > 1.8:
            n_win = 1 if length < 4.5 else 2
            for i in range(n_win):
                ww = rng.uniform(0.9, 1.5)
                t = length * (i + 1) / (n_win + 1)
                if any(abs(t - (a + bb) / 2) < (bb - a) / 2 + ww / 2 + 0.5 for a, bb in spans):
                    continue
                o = org_at(t)
                bot, top = rng.uniform(0.7, 1.0), min(H - 0.25, rng.uniform(2.0, 2.3))
                inst = b.new_instance()
                b.box((-ww / 2, -0.03, bot), (ww / 2, 0.0, top), "window", glass, inst, yaw=yaw, origin=o)
                for (lx0, lx1, lz0, lz1) in ((-ww / 2 - 0.05, ww / 2 + 0.05, bot - 0.05, bot),
                                             (-ww / 2 - 0.05, ww / 2 + 0.05, top, top + 0.05),
                                             (-ww / 2 - 0.05, -ww / 2, bot, top), (ww / 2, ww / 2 + 0.05, bot, top)):
                    b.box((lx0, -0.04, lz0), (lx1, 0.0, lz1), "window", frame, inst, yaw=yaw, origin=o)
                if rng.random() < 0.8:
                    cw = rng.uniform(0.3, 0.45)
                    ctop = min(H - 0.05, top + 0.15)
                    for sx in (-1, 1):
                        cx = sx * (ww / 2 + cw / 2 - 0.1)
                        b.box((cx - cw / 2, -0.16, 0.03), (cx + cw / 2, -0.08, ctop), "curtain", curtain,
                              b.new_instance(), yaw=yaw, origin=o)
        elif length > 1.5 and rng.random() < 0.8:
            pw, ph = rng.uniform(0.4, 1.0), rng.uniform(0.3, 0.8)
            t = rng.uniform(pw, length - pw)
            if any(abs(t - (a + bb) / 2) < (bb - a) / 2 + pw / 2 + 0.2 for a, bb in spans):
                continue
            zc = rng.uniform(1.3, 1.7)
            b.box((-pw / 2, -0.03, zc - ph / 2), (pw / 2, 0.0, zc + ph / 2), "picture", P.colour(),
                  b.new_instance(), yaw=yaw, origin=org_at(t))


def _furnish(b, P, rng, kind: str, room: _Room) -> None:
    def wall_obj(fn, w, d, **kw):
        pose = room.against_wall(w, d, **kw)
        if pose is not None:
            fn(*pose)
        return pose

    if kind == "living_room":
        sofa_pose = None
        for _ in range(10):
            w_probe = rng.uniform(1.6, 2.4)
            sofa_pose = room.against_wall(w_probe + 0.1, 0.95 + 1.0, gap=0.2)
            if sofa_pose is not None:
                break
        if sofa_pose is not None:
            yaw, org = sofa_pose
            _sofa(b, P, rng, b.new_instance(), yaw, _local_to_world(yaw, org, (0.0, 0.5)), w=w_probe)
            # coffee table in front of the sofa (free space under it)
            corg = _local_to_world(yaw, org, (0.0, -0.55))
            _w, _d, h, _m = _table(b, P, rng, b.new_instance(), yaw, corg, w=rng.uniform(0.8, 1.2),
                                   d=rng.uniform(0.45, 0.6), h=rng.uniform(0.38, 0.48))
            _small_objects(b, P, rng, yaw, corg, h, 0.6, 0.3, int(rng.integers(0, 3)))
        tv = room.against_wall(1.4, 0.45, gap=0.2)
        if tv is not None:
            yaw, org = tv
            _w, _d, h = _cabinet(b, P, rng, b.new_instance(), yaw, org, w=1.4, d=0.45, h=0.5)
            _monitor(b, P, rng, yaw, _local_to_world(yaw, org, (0.0, 0.0)), h)
        _dining_group(b, P, rng, room, int(rng.integers(2, 5)))
        for _ in range(int(rng.integers(1, 3))):
            wall_obj(lambda yaw, org: _chair(b, P, rng, b.new_instance(), yaw, org), 0.6, 0.6, gap=0.3)
        for _ in range(int(rng.integers(1, 3))):
            w, d, h = rng.uniform(0.5, 1.2), rng.uniform(0.35, 0.5), rng.uniform(0.5, 1.9)
            wall_obj(lambda yaw, org, w=w, d=d, h=h: _cabinet(b, P, rng, b.new_instance(), yaw, org, w=w, d=d, h=h),
                     w, d, gap=0.2)
        wall_obj(lambda yaw, org: _trashcan(b, P, rng, yaw, org), 0.35, 0.35, gap=0.2)
    elif kind == "bedroom":
        bed_w = float(rng.choice([0.95, 1.45, 1.65]))
        pose = room.against_wall(bed_w + 1.0, 2.15, gap=0.2)
        if pose is not None:
            yaw, org = pose
            _bed(b, P, rng, b.new_instance(), yaw, _local_to_world(yaw, org, (0.0, 0.0)), w=bed_w)
        for _ in range(2):
            w, d, h = 0.45, 0.4, 0.55
            p = room.against_wall(w, d, gap=0.05)
            if p is not None:
                yaw, org = p
                _cabinet(b, P, rng, b.new_instance(), yaw, org, w=w, d=d, h=h)
                _small_objects(b, P, rng, yaw, org, h, w * 0.8, d * 0.8, int(rng.integers(0, 2)))
        _desk_group(b, P, rng, room)
        w = rng.uniform(1.0, 1.8)
        wall_obj(lambda yaw, org: _cabinet(b, P, rng, b.new_instance(), yaw, org, w=w, d=0.6,
                                           h=rng.uniform(1.8, 2.1)), w, 0.6, gap=0.2)
        wall_obj(lambda yaw, org: _chair(b, P, rng, b.new_instance(), yaw, org), 0.6, 0.6, gap=0.3)
        wall_obj(lambda yaw, org: _trashcan(b, P, rng, yaw, org), 0.35, 0.35, gap=0.2)
    elif kind == "office":
        for _ in range(int(rng.integers(2, 5))):
            _desk_group(b, P, rng, room)
        _dining_group(b, P, rng, room, int(rng.integers(3, 7)))
        for _ in range(int(rng.integers(1, 4))):
            w, d, h = rng.uniform(0.6, 1.2), rng.uniform(0.4, 0.6), rng.uniform(0.7, 2.0)
            wall_obj(lambda yaw, org, w=w, d=d, h=h: _cabinet(b, P, rng, b.new_instance(), yaw, org, w=w, d=d, h=h),
                     w, d, gap=0.2)
        if rng.random() < 0.7:
            pose = room.against_wall(2.0, 0.95, gap=0.3)
            if pose is not None:
                _sofa(b, P, rng, b.new_instance(), *pose, w=2.0)
        for _ in range(int(rng.integers(1, 3))):
            wall_obj(lambda yaw, org: _trashcan(b, P, rng, yaw, org), 0.35, 0.35, gap=0.2)
    else:  # pragma: no cover - guarded by generate_scene
        raise ValueError(kind)


def _shell(b, P, rect, H, wall_mat, floor_mat, ceil_mat, *, walls: bool = True, floors: bool = True) -> None:
    """Inward-facing room box: walls and/or floor + ceiling."""
    x0, y0, x1, y1 = rect
    labels = {(0, 0): "wall", (0, 1): "wall", (1, 0): "wall", (1, 1): "wall", (2, 0): "floor", (2, 1): "ceiling"}
    mats = {k: wall_mat for k in labels}
    mats[(2, 0)], mats[(2, 1)] = floor_mat, ceil_mat
    skip = () if walls else ((0, 0), (0, 1), (1, 0), (1, 1))
    skip += () if floors else ((2, 0), (2, 1))
    b.box((x0, y0, 0.0), (x1, y1, H), labels, mats, 0, inward=True, skip=skip)


def _lights(rects, H) -> np.ndarray:
    out = []
    for x0, y0, x1, y1 in rects:
        nx = 2 if x1 - x0 > 4.5 else 1
        ny = 2 if y1 - y0 > 4.5 else 1
        for i in range(nx):
            for j in range(ny):
                out.append([x0 + (x1 - x0) * (i + 0.5) / nx, y0 + (y1 - y0) * (j + 0.5) / ny, H - 0.25])
    return np.asarray(out, dtype=np.float32)


def _single_room(kind: str, seed: int, rng: np.random.Generator, cell: float) -> Scene:
    sizes = {"living_room": ((5.0, 7.5), (4.0, 6.0)), "bedroom": ((3.6, 5.0), (3.4, 4.5)),
             "office": ((5.0, 7.5), (4.0, 6.0))}
    (wl, wh), (dl, dh) = sizes[kind]
    W, D = rng.uniform(wl, wh), rng.uniform(dl, dh)
    H = rng.uniform(2.5, 2.8)
    rect = (-W / 2, -D / 2, W / 2, D / 2)
    b, P = _Builder(cell), _Palette(rng)
    _shell(b, P, rect, H, P.role("wall"), P.role("floor"), P.role("ceiling"))
    outer = tuple(bool(v) for v in rng.random(4) < 0.6)
    if not any(outer):
        outer = (True, False, False, False)
    _wall_items(b, P, rng, rect, H, outer, [])
    _furnish(b, P, rng, kind, _Room(rect, rng))
    meta = {"kind": kind, "seed": int(seed), "rooms": [list(map(float, rect))], "ceiling_height": float(H),
            "floor_z": 0.0, "lights": _lights([rect], H).tolist()}
    return b.build(f"{kind}_{seed:04d}", meta)


def _apartment(seed: int, rng: np.random.Generator, cell: float) -> Scene:
    W, D = rng.uniform(8.0, 10.0), rng.uniform(6.5, 8.0)
    H = rng.uniform(2.5, 2.75)
    xs = rng.uniform(0.45, 0.55) * W  # living room left, bedroom + office right
    ys = rng.uniform(0.45, 0.55) * D
    t = 0.1  # interior wall thickness
    living = (0.0, 0.0, xs - t / 2, D)
    bedroom = (xs + t / 2, ys + t / 2, W, D)
    office = (xs + t / 2, 0.0, W, ys - t / 2)
    b, P = _Builder(cell), _Palette(rng)
    wall_mat, ceil = P.role("wall"), P.role("ceiling")
    _shell(b, P, (0.0, 0.0, W, D), H, wall_mat, None, None, floors=False)
    for rect in (living, bedroom, office):
        _shell(b, P, rect, H, None, P.role("floor"), ceil, walls=False)
    door_w, door_h = 0.9, 2.05
    doors = []  # (axis-aligned door rectangles as floor footprint to keep free)
    wall_lab = {k: "wall" for k in _FACES}
    # interior wall x = xs (two doors: living<->bedroom, living<->office) as boxes with gaps
    d1 = rng.uniform(ys + t + 0.3, D - door_w - 0.3)
    d2 = rng.uniform(0.3, ys - door_w - t - 0.3)
    d3 = rng.uniform(xs + t + 0.3, W - door_w - 0.3)  # bedroom <-> office in wall y = ys
    x_lo, x_hi = xs - t / 2, xs + t / 2
    for (ya, yb) in ((0.0, d2), (d2 + door_w, d1), (d1 + door_w, D)):
        b.box((x_lo, ya, 0.0), (x_hi, yb, H), wall_lab, wall_mat)
    only_top = tuple(f for f in _FACES if f != (2, 1))
    floor_mat = P.role("floor")
    for ya in (d1, d2):
        b.box((x_lo, ya, door_h), (x_hi, ya + door_w, H), wall_lab, wall_mat)
        b.box((x_lo, ya, -0.01), (x_hi, ya + door_w, 0.0), "floor", floor_mat, skip=only_top)
        doors.append((x_lo - 0.6, ya, x_hi + 0.6, ya + door_w))
    y_lo, y_hi = ys - t / 2, ys + t / 2
    for (xa, xb) in ((x_hi, d3), (d3 + door_w, W)):
        b.box((xa, y_lo, 0.0), (xb, y_hi, H), wall_lab, wall_mat)
    b.box((d3, y_lo, door_h), (d3 + door_w, y_hi, H), wall_lab, wall_mat)
    b.box((d3, y_lo, -0.01), (d3 + door_w, y_hi, 0.0), "floor", floor_mat, skip=only_top)
    doors.append((d3, y_lo - 0.6, d3 + door_w, y_hi + 0.6))
    # walls: 0 north (y1), 1 south (y0), 2 east (x1), 3 west (x0); door spans along each wall's direction
    _wall_items(b, P, rng, living, H, (True, True, False, True),
                [(2, (D - d1 - door_w, D - d1)), (2, (D - d2 - door_w, D - d2))])
    _wall_items(b, P, rng, bedroom, H, (True, False, True, False),
                [(1, (W - d3 - door_w, W - d3)), (3, (d1 - bedroom[1], d1 + door_w - bedroom[1]))])
    _wall_items(b, P, rng, office, H, (False, True, True, False),
                [(0, (d3 - office[0], d3 + door_w - office[0])), (3, (d2, d2 + door_w))])
    for kind, rect in (("living_room", living), ("bedroom", bedroom), ("office", office)):
        keep = [d for d in doors if d[0] < rect[2] and rect[0] < d[2] and d[1] < rect[3] and rect[1] < d[3]]
        _furnish(b, P, rng, kind, _Room(rect, rng, keep_free=keep))
    rooms = [living, bedroom, office]
    meta = {"kind": "apartment", "seed": int(seed), "rooms": [list(map(float, r)) for r in rooms],
            "ceiling_height": float(H), "floor_z": 0.0, "lights": _lights(rooms, H).tolist(),
            "doors": [list(map(float, d)) for d in doors]}
    return b.build(f"apartment_{seed:04d}", meta)


def box_room(
    size: tuple[float, float, float] = (4.0, 3.0, 2.5), *, cell: float = 0.5, seed: int = 0
) -> Scene:
    """An empty box room ``[0, W] x [0, D] x [0, H]`` (analytic test scene).

    Walls, floor and ceiling face inwards; depth from any inside camera is analytic.

    Parameters
    ----------
    size : (float, float, float)
        Width (x), depth (y) and height (z) in metres.
    cell : float
        Grid cell of the subdivided faces (m).
    seed : int
        Seed of the material colour jitter.

    Returns
    -------
    Scene

    Raises
    ------
    ValueError
        A non-positive size.
    """
    W, D, H = (float(s) for s in size)
    if min(W, D, H) <= 0:
        raise ValueError(f"box_room: size must be positive, got {size}")
    b, P = _Builder(cell), _Palette(np.random.default_rng(seed))
    _shell(b, P, (0.0, 0.0, W, D), H, P.get("paint_white"), P.get("floor_oak"), P.get("paint_white"))
    meta = {"kind": "box_room", "seed": int(seed), "rooms": [[0.0, 0.0, W, D]], "ceiling_height": H,
            "floor_z": 0.0, "lights": _lights([(0.0, 0.0, W, D)], H).tolist()}
    return b.build(f"box_room_{seed:04d}", meta)


def generate_scene(kind: str, seed: int, *, cell: float = 0.3) -> Scene:
    """Generate a seeded procedural indoor scene.

    Parameters
    ----------
    kind : {"living_room", "bedroom", "office", "apartment", "box_room"}
        Room type; ``apartment`` connects a living room, a bedroom and an office by doors;
        ``box_room`` is an empty analytic room.
    seed : int
        Same seed, same scene (vertices, labels, materials).
    cell : float
        Largest edge of the grid that flat faces are subdivided into (metres). The renderer
        interpolates lighting between vertices, so smaller cells light more smoothly.

    Returns
    -------
    Scene
        With ``meta`` keys ``kind``, ``seed``, ``rooms``, ``ceiling_height``, ``floor_z``,
        ``lights``.

    Raises
    ------
    ValueError
        Unknown ``kind`` or a non-positive ``cell``.

    Examples
    --------
    >>> s = generate_scene("bedroom", 3)
    >>> s.meta["kind"], s.n_triangles > 1000
    ('bedroom', True)
    """
    if kind not in SCENE_KINDS:
        raise ValueError(f"unknown scene kind {kind!r}; valid: {', '.join(SCENE_KINDS)}")
    if not cell > 0:
        raise ValueError(f"cell must be > 0, got {cell}")
    seed = int(seed)
    rng = np.random.default_rng([seed, SCENE_KINDS.index(kind)])
    if kind == "box_room":
        return box_room(seed=seed, cell=cell)
    if kind == "apartment":
        return _apartment(seed, rng, cell)
    return _single_room(kind, seed, rng, cell)
