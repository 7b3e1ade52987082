"""Semantic maps: points or mesh vertices with category labels (and instances), read and written as PLY.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .files import atomic_path
from .labels import NUM_CLASSES, colors_to_labels, labels_to_colors

#: largest instance id a map or an instance image may hold (PLY ``instance`` is int32)
INSTANCE_MAX = 2**31 - 1

__all__ = ['SemanticMap', 'INSTANCE_MAX', 'check_ply_header', 'read_map', 'write_map', 'require_instances']

PathLike = str | os.PathLike


# ----------------------------------------------------------------------------- PLY maps
@dataclass
class SemanticMap:
    """A semantic map: points (or mesh vertices) with category labels.

    Attributes
    ----------
    points : float32 (N,3)
    labels : uint8 (N,)
    colors : uint8 (N,3) or None
        Appearance colours (RGB meshes); label colours are derived from ``labels``.
    faces : int32 (M,3) or None
        Triangles when the map is a mesh.
    normals : float32 (N,3) or None
    source : str
        File it was read from, for messages.
    instances : int32 (N,) or None
        Instance id of every vertex (0 = none: stuff, or a thing without an instance), the
        panoptic layer; None when the map has no instance layer.
    """

    points: np.ndarray
    labels: np.ndarray
    colors: np.ndarray | None = None
    faces: np.ndarray | None = None
    normals: np.ndarray | None = None
    source: str = "<memory>"
    instances: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.points = np.ascontiguousarray(self.points, dtype=np.float32).reshape(-1, 3)
        self.labels = np.ascontiguousarray(self.labels, dtype=np.uint8).reshape(-1)
        if len(self.labels) != len(self.points):
            raise ValueError(f"{self.source}: {len(self.points)} points but {len(self.labels)} labels")
        if self.faces is not None:
            self.faces = np.ascontiguousarray(self.faces, dtype=np.int32).reshape(-1, 3)
            if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= len(self.points)):
                raise ValueError(f"{self.source}: face index outside the vertex list")
        if self.instances is not None:
            inst = np.asarray(self.instances).reshape(-1)
            if len(inst) != len(self.points):
                raise ValueError(f"{self.source}: {len(self.points)} points but {len(inst)} instance ids")
            if inst.size and (inst.min() < 0 or inst.max() > INSTANCE_MAX):
                raise ValueError(
                    f"{self.source}: instance ids must lie in 0..{INSTANCE_MAX} (the PLY property is "
                    f"int32), got {int(inst.min())}..{int(inst.max())}"
                )
            self.instances = np.ascontiguousarray(inst, dtype=np.int32)

    def __len__(self) -> int:
        return len(self.points)

    @property
    def is_mesh(self) -> bool:
        """True when the map has triangles."""
        return self.faces is not None and len(self.faces) > 0

    @property
    def has_instances(self) -> bool:
        """True when the map carries an instance layer."""
        return self.instances is not None

    @property
    def label_colors(self) -> np.ndarray:
        """Palette colours of the labels, uint8 (N,3)."""
        return labels_to_colors(self.labels)

    def check(self) -> SemanticMap:
        """Raise ``ValueError`` for an empty map or NaN/inf vertices; return self."""
        if len(self.points) == 0:
            raise ValueError(f"{self.source}: the map is empty (no vertices)")
        _check_vertices(self.points, self.source)
        return self

    def canonical(self) -> SemanticMap:
        """The same map with vertices sorted by (x, y, z) and triangles by their vertex indices
        (each rotated to start at its smallest index, orientation kept).

        Reconstructions are deterministic in content but not in order (Open3D's parallel hash
        map); written in canonical order, the same content gives the same bytes.
        """
        p = self.points
        order = np.lexsort((p[:, 2], p[:, 1], p[:, 0]))

        def take(a):
            return None if a is None else np.asarray(a)[order]

        faces = None
        if self.faces is not None:
            inv = np.empty(len(order), np.int64)
            inv[order] = np.arange(len(order))
            f = inv[self.faces]
            shift = np.argmin(f, axis=1)
            rows = np.arange(len(f))[:, None]
            f = f[rows, (shift[:, None] + np.arange(3)) % 3]
            faces = f[np.lexsort((f[:, 2], f[:, 1], f[:, 0]))]
        return SemanticMap(p[order], self.labels[order], colors=take(self.colors), faces=faces,
                           normals=take(self.normals), source=self.source, instances=take(self.instances))

    def to_open3d(self, *, label_colors: bool = True):
        """Legacy ``open3d.geometry.TriangleMesh`` (mesh) or ``PointCloud`` with colours."""
        import open3d as o3d

        col = (self.label_colors if label_colors or self.colors is None else self.colors) / 255.0
        if self.is_mesh:
            m = o3d.geometry.TriangleMesh(
                o3d.utility.Vector3dVector(self.points.astype(np.float64)),
                o3d.utility.Vector3iVector(self.faces),
            )
            m.vertex_colors = o3d.utility.Vector3dVector(col)
            return m
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.points.astype(np.float64)))
        pc.colors = o3d.utility.Vector3dVector(col)
        return pc


_PLY_SIZES = {"char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2, "ushort": 2, "uint16": 2,
              "int": 4, "int32": 4, "uint": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}


#: longest header line accepted (comments included); a header has any number of lines
_PLY_MAX_LINE = 64 * 1024


#: header comment naming the scene a map is of (``comment scene NAME``)
_SCENE_COMMENT = "scene"


def map_scene(path: PathLike) -> str | None:
    """The scene (home) a semantic PLY map says it is of: its header comment ``scene NAME``.

    Parameters
    ----------
    path : path
        A PLY map (:func:`write_map` with ``scene=`` writes the comment; ``semmatch reconstruct``
        does when its sequence names its scene).

    Returns
    -------
    str or None
        The scene name, or None when the header has no such comment (or is not a PLY header).
    """
    with open(path, "rb") as fh:
        if fh.read(3) != b"ply":
            return None
        fh.seek(0)
        for _ in range(10_000):
            ln = fh.readline(_PLY_MAX_LINE + 1)
            if not ln or ln.strip() == b"end_header":
                return None
            tok = ln.decode("ascii", errors="replace").split(None, 2)
            if len(tok) == 3 and tok[0] == "comment" and tok[1] == _SCENE_COMMENT:
                return tok[2].strip()
    return None


def require_instances(m: SemanticMap, what: str = "panoptic output") -> SemanticMap:
    """Raise a clear ``ValueError`` when ``m`` has no instance layer; return ``m``."""
    if m.instances is None:
        raise ValueError(
            f"{m.source}: the map has no instance layer (no 'instance' vertex property), needed for "
            f"{what}; add one with `semmatch panoptic segment` (clustering) or from ground-truth "
            "instance images"
        )
    return m


def check_ply_header(path: PathLike) -> None:
    """Refuse a PLY whose header claims more elements than the file can hold, before parsing it.

    A 250-byte file claiming 3*10^8 faces would otherwise make the parser allocate gigabytes.
    The header is read to its ``end_header`` line, however many comment lines pad it. The
    smallest possible size of every element (binary: its fixed properties plus each list's
    count; ASCII: two characters per value) times its count must fit in the bytes after the
    header.

    Raises
    ------
    ValueError
        The header is unreadable or claims more than the file holds (names the element, its
        count and the file size).
    """
    path = Path(path)
    size = path.stat().st_size
    if not path.is_file():
        raise ValueError(f"{path}: not a regular file (a PLY map must be a file)")
    raw: list[bytes] = []
    with open(path, "rb") as fh:  # the header read to its end, however long (comments can pad it)
        if fh.read(3) != b"ply":
            return  # not a PLY header we can read: the parser gives its own error
        fh.seek(0)
        while True:
            ln = fh.readline(_PLY_MAX_LINE + 1)
            if not ln:
                return  # no end_header: the parser gives its own error
            if len(ln) > _PLY_MAX_LINE:
                raise ValueError(f"{path}: PLY header line {len(raw) + 1} is longer than {_PLY_MAX_LINE:,} bytes: "
                                 "not a PLY map")
            if ln.strip() == b"end_header":
                break
            raw.append(ln)
        body = size - fh.tell()
    lines = [ln.decode("ascii", errors="replace") for ln in raw]
    fmt = next((ln.split()[1] for ln in lines if ln.startswith("format")), "ascii")
    need, elements = 0, []
    for ln in lines:
        tok = ln.split()
        if not tok:
            continue
        if tok[0] == "element" and len(tok) >= 3:
            try:
                elements.append([tok[1], int(tok[2]), 0])
            except ValueError:
                raise ValueError(f"{path}: bad PLY element line {ln!r}") from None
        elif tok[0] == "property" and elements:
            if fmt == "ascii":
                elements[-1][2] += 2
            elif tok[1] == "list" and len(tok) >= 5:
                elements[-1][2] += _PLY_SIZES.get(tok[2], 1)
            else:
                elements[-1][2] += _PLY_SIZES.get(tok[1], 1)
    for name, count, per in elements:
        if count < 0:
            raise ValueError(f"{path}: PLY header claims {count} {name} elements")
        need += count * per
        if need > body:
            raise ValueError(
                f"{path}: PLY header claims {count:,} {name} elements (at least {count * per:,} bytes) but the "
                f"file holds {body:,} bytes after its header: truncated or corrupt"
            )


def read_map(path: PathLike, *, require_labels: bool = True) -> SemanticMap:
    """Read a semantic PLY (mesh or point cloud).

    The ``label`` vertex property wins when present; otherwise labels come from the vertex
    colours through the palette (colours outside it read as void and are counted in a
    ``UserWarning``; with ``require_labels``, a map whose colours are mostly outside the palette
    is refused: it is not a semantic map of this label table).

    Raises
    ------
    ValueError
        The file is not a PLY with vertices, has neither colours nor ``label`` or mostly
        off-palette colours (with ``require_labels``), or holds NaN vertices.
    """
    from plyfile import PlyData, PlyParseError

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such map file")
    check_ply_header(path)
    errors = (PlyParseError, ValueError, IndexError, EOFError, TypeError)
    try:
        # fast path for triangle meshes: fixed-length face lists read as one array
        ply = PlyData.read(str(path), known_list_len={"face": {"vertex_indices": 3}})
    except errors:
        try:
            ply = PlyData.read(str(path))
        except errors as e:
            raise ValueError(f"{path}: not a readable PLY file ({e})") from None
    if "vertex" not in ply:
        raise ValueError(f"{path}: PLY has no vertex element")
    v = ply["vertex"].data
    names = v.dtype.names or ()
    if not {"x", "y", "z"} <= set(names):
        raise ValueError(f"{path}: PLY vertices lack x, y, z")
    pts = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float32)
    colors = None
    for rgb in (("red", "green", "blue"), ("r", "g", "b"), ("diffuse_red", "diffuse_green", "diffuse_blue")):
        if set(rgb) <= set(names):
            c = np.stack([v[k] for k in rgb], axis=1)
            if np.issubdtype(c.dtype, np.floating):
                c = np.clip(np.rint(c * 255.0 if c.max(initial=0) <= 1.0 else c), 0, 255)
            colors = c.astype(np.uint8)
            break
    if "label" in names:
        labels = np.asarray(v["label"]).astype(np.int64)
        if labels.size and (labels.min() < 0 or labels.max() >= NUM_CLASSES):
            raise ValueError(f"{path}: label property outside 0..{NUM_CLASSES - 1}")
        labels = labels.astype(np.uint8)
    elif colors is not None:
        labels, n_unknown = colors_to_labels(colors, source=str(path), warn=False)
        if require_labels and n_unknown * 2 > len(colors):
            bad = colors[np.flatnonzero(labels == 0)[0]] if n_unknown else colors[0]
            raise ValueError(
                f"{path}: {n_unknown:,} of {len(colors):,} vertex colours are not colours of the category "
                f"palette (e.g. RGB {tuple(int(x) for x in bad)}); this is not a semantic map of this label "
                "table (an RGB map? another palette?). Write labels as palette colours or a 'label' property")
        if n_unknown:
            warnings.warn(f"{n_unknown} of {len(colors)} colours in {path} are not in the category palette; "
                          "they read as void (0)", UserWarning, stacklevel=2)
    elif require_labels:
        raise ValueError(f"{path}: PLY has neither vertex colours nor a 'label' property")
    else:
        labels = np.zeros(len(pts), dtype=np.uint8)
    instances = None
    if "instance" in names:
        instances = np.asarray(v["instance"])
        if not np.issubdtype(instances.dtype, np.integer):
            raise ValueError(f"{path}: the 'instance' property must be an integer type, got {instances.dtype}")
        instances = instances.astype(np.int64)
        if instances.size and (instances.min() < 0 or instances.max() > INSTANCE_MAX):
            raise ValueError(
                f"{path}: instance ids outside 0..{INSTANCE_MAX} "
                f"({int(instances.min())}..{int(instances.max())})"
            )
    normals = None
    if {"nx", "ny", "nz"} <= set(names):
        normals = np.stack([v["nx"], v["ny"], v["nz"]], axis=1).astype(np.float32)
    faces = None
    if "face" in ply and ply["face"].count:
        fd = ply["face"].data
        key = "vertex_indices" if "vertex_indices" in fd.dtype.names else fd.dtype.names[0]
        col = fd[key]
        try:
            faces = (np.stack(col) if col.dtype == object else np.asarray(col)).astype(np.int32)
        except ValueError:
            raise ValueError(f"{path}: only triangle faces are supported") from None
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise ValueError(f"{path}: only triangle faces are supported")
    m = SemanticMap(pts, labels, colors=colors, faces=faces, normals=normals, source=str(path),
                    instances=instances)
    _check_vertices(m.points, path)
    return m


def _check_vertices(points: np.ndarray, where: PathLike | str) -> None:
    """Refuse NaN/inf vertices and vertices beyond :data:`~semmatch.io.reading_checks.MAX_POSITION`
    of the origin (no mapped room spans 10 km; such a vertex is a corrupt or foreign file)."""
    from .reading_checks import MAX_POSITION

    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise ValueError(f"{where}: {int(bad.sum())} vertices hold NaN or inf")
    far = np.abs(points).max(axis=1, initial=0.0) > MAX_POSITION
    if far.any():
        k = int(np.flatnonzero(far)[0])
        raise ValueError(f"{where}: {int(far.sum())} vertices lie beyond {MAX_POSITION:g} m of the origin "
                         f"(first: vertex {k} at {points[k].tolist()}); is this a map in metres?")


def write_map(
    path: PathLike,
    m: SemanticMap,
    *,
    colors: str = "labels",
    binary: bool = True,
    canonical: bool = False,
    scene: str | None = None,
) -> Path:
    """Write a semantic map as PLY: vertex colours + ``label`` (uchar) property, atomically.

    A map with an instance layer also gets an ``instance`` (int32) vertex property.

    Parameters
    ----------
    path : path
    m : SemanticMap
    colors : {"labels", "rgb"}
        Vertex colours: palette colours of the labels (the contract's semantic map) or the
        map's appearance colours (an RGB mesh; ``label`` is written in both cases).
    binary : bool
        Binary little-endian (default) or ASCII.
    canonical : bool
        Write vertices and triangles in canonical order (:meth:`SemanticMap.canonical`), so that
        the same content always gives the same bytes (the reconstructions of
        :mod:`semmatch.fusion` are written so). Off by default: a mesh whose triangle order means
        something (a scene's per-triangle data) keeps it.
    scene : str, optional
        The scene (home) the map is of, written as the header comment ``scene NAME`` and read
        back by :func:`map_scene`; none by default.
    """
    from plyfile import PlyData, PlyElement

    if colors not in ("labels", "rgb"):
        raise ValueError(f"colors must be 'labels' or 'rgb', got {colors!r}")
    if canonical:
        m = m.canonical()
    if colors == "rgb" and m.colors is None:
        raise ValueError("colors='rgb' needs a map with appearance colours")
    col = m.label_colors if colors == "labels" else np.asarray(m.colors, dtype=np.uint8)
    fields = [("x", "f4"), ("y", "f4"), ("z", "f4")]
    if m.normals is not None:
        fields += [("nx", "f4"), ("ny", "f4"), ("nz", "f4")]
    fields += [("red", "u1"), ("green", "u1"), ("blue", "u1"), ("label", "u1")]
    if m.instances is not None:
        fields += [("instance", "i4")]
    arr = np.empty(len(m.points), dtype=fields)
    arr["x"], arr["y"], arr["z"] = m.points.T
    if m.normals is not None:
        arr["nx"], arr["ny"], arr["nz"] = np.asarray(m.normals, dtype=np.float32).T
    arr["red"], arr["green"], arr["blue"] = col.T
    arr["label"] = m.labels
    if m.instances is not None:
        arr["instance"] = m.instances
    elements = [PlyElement.describe(arr, "vertex")]
    if m.is_mesh:
        f = np.empty(len(m.faces), dtype=[("vertex_indices", "i4", (3,))])
        f["vertex_indices"] = m.faces
        elements.append(PlyElement.describe(f, "face"))
    comments = ["semmatch semantic map; label = category id"]
    if scene is not None:
        if not scene.strip() or any(c in scene for c in "\r\n"):
            raise ValueError(f"scene must be a non-empty single line, got {scene!r}")
        comments.append(f"{_SCENE_COMMENT} {scene.strip()}")
    ply = PlyData(elements, text=not binary, byte_order="<", comments=comments)
    path = Path(path)
    with atomic_path(path) as tmp:
        if binary and m.is_mesh:
            # plyfile writes a list property face by face (~2 s for a 300k-face mesh); the same
            # bytes as one block: plyfile's header, the vertex records, then per face a uchar
            # count (3) and three little-endian int32 indices
            faces = np.empty(len(m.faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
            faces["n"] = 3
            faces["v"] = m.faces
            with open(tmp, "wb") as fh:
                fh.write(ply.header.encode("ascii") + b"\n")
                fh.write(arr.astype(arr.dtype.newbyteorder("<"), copy=False).tobytes())
                fh.write(faces.tobytes())
        else:
            ply.write(str(tmp))
    return path

