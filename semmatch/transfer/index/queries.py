"""The map index and its queries: :class:`MapIndex` looks labels up in the sparse label grid
(:mod:`.label_grid`) and answers exact nearest-surface queries where the grid cannot decide.

A lookup is one gather per point (two through the block table for a large box); points in
*ambiguous* voxels (label edges, the ``max_distance`` shell) get an exact query: the closest
point on the mesh (Open3D ``RaycastingScene.compute_closest_points``, what the authors' code
does) or the nearest map point (SciPy ``cKDTree``) for point maps.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

from ...io import SemanticMap
from ...io.geometry import Intrinsics, check_pose, pixel_rays
from ...io.labels import NUM_CLASSES, THING_CLASSES
from .label_grid import AMBIGUOUS, BLOCK, BSHIFT, LABEL_BITS, SHELL, LabelGrid, build_label_grid
from .reach import ReachTest

__all__ = ["MapIndex", "DEFAULT_MAX_DISTANCE", "DENSE_LOOKUP_VOXELS"]

#: Default distance threshold (metres): a lower-view point farther than this from every surface
#: of the upper map has no support and gets label 0. 10 cm is above the depth noise of an RGB-D
#: camera at room range (~1-3 cm) plus the surface error of a TSDF map at 4-5 cm voxels, and
#: below the gap between furniture and the wall/floor it stands near, so unmapped objects
#: (never seen from above) stay void instead of borrowing a neighbour's label.
DEFAULT_MAX_DISTANCE = 0.10

#: a box of at most this many voxels also keeps its grid dense for lookups (one byte a voxel)
DENSE_LOOKUP_VOXELS = 48_000_000


class MapIndex:
    """A semantic map indexed for fast nearest-label lookups (build once, query per frame).

    Parameters
    ----------
    semantic_map : SemanticMap
        Points + labels, or a semantic mesh (``faces``).
    max_distance : float
        Distance threshold in metres: points farther than this from the map read as void (0).
    voxel_size : float
        Edge of the label-grid voxels in metres. Smaller voxels flag fewer points as ambiguous
        (faster lookups) at the cost of memory and build time.
    max_voxels : int
        Memory budget: most voxels the sparse grid may allocate (one byte each, in blocks of
        ``BLOCK**3`` near the map surface). Checked before the blocks are allocated; a map that
        needs more is refused with a ValueError (a map in millimetres, a voxel too small).
    workers : int
        Threads for SciPy KD-tree queries and Open3D queries (1 = single thread).

    Raises
    ------
    ValueError
        Empty map, NaN vertices, label ids outside the category table, or a non-positive
        parameter.

    Examples
    --------
    >>> index = MapIndex(read_map("upper.ply"))            # doctest: +SKIP
    >>> labels = index.lookup(points)                      # doctest: +SKIP
    """

    def __init__(
        self,
        semantic_map: SemanticMap,
        *,
        max_distance: float = DEFAULT_MAX_DISTANCE,
        voxel_size: float = 0.02,
        max_voxels: int = 1_000_000_000,
        workers: int = 1,
    ) -> None:
        if not isinstance(semantic_map, SemanticMap):
            raise TypeError(f"expected a SemanticMap, got {type(semantic_map).__name__}")
        semantic_map.check()
        if semantic_map.labels.max(initial=0) >= NUM_CLASSES:
            raise ValueError(
                f"{semantic_map.source}: label id {int(semantic_map.labels.max())} outside "
                f"0..{NUM_CLASSES - 1}"
            )
        if not (np.isfinite(max_distance) and max_distance > 0):
            raise ValueError(f"max_distance must be > 0, got {max_distance}")
        if not (np.isfinite(voxel_size) and voxel_size > 0):
            raise ValueError(f"voxel_size must be > 0, got {voxel_size}")
        self._set_map(semantic_map, max_distance, workers)
        self._build_grid(float(voxel_size), int(max_voxels))  # budgets first
        self._tree = None if self.is_mesh else cKDTree(self.samples)

    @classmethod
    def _from_grid(cls, semantic_map: SemanticMap, grid: LabelGrid, *, max_distance: float,
                   workers: int = 1) -> MapIndex:
        """An index of ``semantic_map`` over a label grid already built for it (read from a cache
        file: :func:`~semmatch.transfer.index.load_index`), without building one."""
        self = cls.__new__(cls)
        self._set_map(semantic_map, max_distance, workers)
        self._set_grid(grid)
        self._tree = None if self.is_mesh else cKDTree(self.samples)
        return self

    # ------------------------------------------------------------------ construction
    def _set_map(self, semantic_map: SemanticMap, max_distance: float, workers: int) -> None:
        self.map = semantic_map
        self.source = semantic_map.source
        self.max_distance = float(max_distance)
        self.workers = int(workers)
        self.is_mesh = semantic_map.is_mesh
        self.samples = None if self.is_mesh else semantic_map.points
        self.sample_labels = None if self.is_mesh else semantic_map.labels
        self._rc = None
        self._class_trees: dict | None = None  # per-class KD-trees of instance lookups
        self._rays: dict[Intrinsics, tuple[np.ndarray, np.ndarray]] = {}

    def _build_grid(self, voxel_size: float, max_voxels: int) -> None:
        """Build the sparse label grid (:func:`~.label_grid.build_label_grid`)."""
        self._set_grid(build_label_grid(self.map, max_distance=self.max_distance, voxel_size=voxel_size,
                                        max_voxels=max_voxels))

    def _set_grid(self, grid: LabelGrid) -> None:
        self.voxel_size = float(grid.voxel_size)
        self.origin = np.asarray(grid.origin, dtype=np.float64)
        self.shape = tuple(int(x) for x in grid.shape)
        self._table = grid.table
        self._blocks = grid.blocks
        self.n_samples = int(grid.n_samples)
        self._reach: ReachTest | None = None  # the shell's support test (memoised centre distances)
        self._set_tables()

    @property
    def label_grid(self) -> LabelGrid:
        """The index's label grid (what a cache file stores)."""
        return LabelGrid(self.origin, self.shape, self.voxel_size, self._table, self._blocks, self.n_samples)


    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_rc"] = None  # Open3D scenes do not pickle; rebuilt on first use
        state["_reach"] = None  # rebuilt on first use (smaller pickles)
        state["_dense"] = None  # the expanded grid is rebuilt from the blocks (smaller pickles)
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._set_tables()

    def _set_tables(self) -> None:
        """Derived lookup tables: the flat block table and, for a box of at most
        :data:`DENSE_LOOKUP_VOXELS`, the grid expanded (one gather per lookup instead of two)."""
        self._table_flat = self._table.reshape(-1)
        self._dense = self.grid.reshape(-1) if np.prod(self.shape) <= DENSE_LOOKUP_VOXELS else None

    @property
    def n_blocks(self) -> int:
        """Allocated blocks of ``BLOCK**3`` voxels (the all-void block not counted)."""
        return len(self._blocks) // BLOCK**3 - 1

    @property
    def nbytes(self) -> int:
        """Bytes held by the label grid (block table, blocks and, for a small box, its dense copy)
        and, once support tests have run, the shell voxels' centre distances (one byte a voxel)."""
        extra = (0 if self._dense is None else self._dense.nbytes) + (0 if self._reach is None else self._reach.nbytes)
        return self._table.nbytes + self._blocks.nbytes + extra

    @property
    def grid(self) -> np.ndarray:
        """The label grid expanded over the whole bounding box (uint8, :attr:`shape`; for tests and
        small maps: it allocates the box)."""
        if getattr(self, "_dense", None) is not None:
            return self._dense.reshape(self.shape).copy()
        nb = self._table.shape
        blocks = self._blocks.reshape(-1, BLOCK, BLOCK, BLOCK)
        out = np.empty(self.shape, np.uint8)
        for bx in range(nb[0]):  # a slab of blocks at a time: the box plus one slab in memory
            slab = blocks[self._table[bx]].transpose(2, 0, 3, 1, 4).reshape(BLOCK, nb[1] * BLOCK, nb[2] * BLOCK)
            x0 = bx * BLOCK
            n = min(BLOCK, self.shape[0] - x0)
            out[x0 : x0 + n] = slab[:n, : self.shape[1], : self.shape[2]]
        return out

    def _values(self, i: np.ndarray, j: np.ndarray, k: np.ndarray, flags: bool = True) -> np.ndarray:
        """Grid values of voxels (i, j, k) (int32 arrays, inside the grid)."""
        nb = self._table.shape
        if self._blocks.size >= 2**31:
            i, j, k = (x.astype(np.int64) for x in (i, j, k))
        t = self._table_flat[((i >> BSHIFT) * nb[1] + (j >> BSHIFT)) * nb[2] + (k >> BSHIFT)]
        m = BLOCK - 1
        off = (((i & m) << BSHIFT) + (j & m) << BSHIFT) + (k & m)
        off += t << (3 * BSHIFT)
        out = self._blocks[off]
        if not flags:
            out &= np.uint8(LABEL_BITS)
        return out

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Which points lie inside the grid bounds (outside: farther than ``max_distance``
        from every map surface, so without support)."""
        p = np.asarray(points).reshape(-1, 3)
        hi = self.origin + np.asarray(self.shape) * self.voxel_size
        if p.dtype == np.float32 and len(p):
            # one OpenCV pass with the float32 bounds that decide exactly as the float64 ones:
            # p >= lo  <=>  p >= the smallest float32 >= lo;  p < hi  <=>  p <= the largest
            # float32 < hi
            lo32 = self.origin.astype(np.float32)
            lo32 = np.where(lo32 < self.origin, np.nextafter(lo32, np.float32(np.inf)), lo32)
            hi32 = hi.astype(np.float32)
            hi32 = np.where(hi32 >= hi, np.nextafter(hi32, np.float32(-np.inf)), hi32)
            inside = cv2.inRange(np.ascontiguousarray(p).reshape(-1, 1, 3),
                                 tuple(float(x) for x in lo32), tuple(float(x) for x in hi32))
            return inside.reshape(-1) > 0
        ok = np.ones(len(p), bool)
        for a in range(3):
            ok &= (p[:, a] >= self.origin[a]) & (p[:, a] < hi[a])
        return ok

    @property
    def n_points(self) -> int:
        """Number of map points (mesh vertices)."""
        return len(self.map.points)

    @property
    def raycasting_scene(self):
        """Open3D ``RaycastingScene`` of the mesh (built on first use); None for point maps."""
        if not self.is_mesh:
            return None
        if self._rc is None:
            import open3d as o3d

            rc = o3d.t.geometry.RaycastingScene()
            rc.add_triangles(
                o3d.core.Tensor(np.ascontiguousarray(self.map.points, dtype=np.float32)),
                o3d.core.Tensor(np.ascontiguousarray(self.map.faces, dtype=np.uint32)),
            )
            self._rc = rc
        return self._rc

    # ------------------------------------------------------------------ queries
    def nearest(
        self, points: np.ndarray, max_distance: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Exact nearest-surface label and distance of each point.

        Meshes: the closest point on the triangles (Open3D ``compute_closest_points``); the label
        is that of the hit triangle's vertex nearest to the closest point. Point maps: the
        nearest map point (``cKDTree``).

        Parameters
        ----------
        points : float (N,3)
            World coordinates.
        max_distance : float, optional
            Points with no surface within this distance get label 0 and distance ``inf`` (this
            also bounds the KD-tree search, which is much faster).

        Returns
        -------
        labels : uint8 (N,)
        distance : float32 (N,)
        """
        p = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0, np.uint8), np.zeros(0, np.float32)
        if not self.is_mesh:
            ub = np.inf if max_distance is None else float(max_distance)
            d, i = self._tree.query(p, distance_upper_bound=ub, workers=self.workers)
            hit = np.isfinite(d)
            lab = np.zeros(len(p), np.uint8)
            lab[hit] = self.map.labels[i[hit]]
            return lab, d.astype(np.float32)
        import open3d as o3d

        ans = self.raycasting_scene.compute_closest_points(o3d.core.Tensor(p), nthreads=self.workers)
        prim = ans["primitive_ids"].numpy().astype(np.int64)
        uv = ans["primitive_uvs"].numpy()
        bary = np.stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
        vert = self.map.faces[prim, np.argmax(bary, axis=1)]
        d = np.linalg.norm(ans["points"].numpy() - p, axis=1).astype(np.float32)
        lab = self.map.labels[vert]
        if max_distance is not None:
            far = d > max_distance
            lab = np.where(far, 0, lab).astype(np.uint8)
            d[far] = np.inf
        return lab, d

    @property
    def has_instances(self) -> bool:
        """True when the indexed map carries an instance layer."""
        return self.map.instances is not None

    def with_instances(self, instances: np.ndarray) -> MapIndex:
        """This index over the same map with another instance layer (the label grid is shared,
        not rebuilt).

        Parameters
        ----------
        instances : int (N,)
            One instance id per map vertex.
        """
        import copy

        m = self.map
        other = copy.copy(self)
        other.map = SemanticMap(m.points, m.labels, colors=m.colors, faces=m.faces, normals=m.normals,
                                source=m.source, instances=instances)
        other._class_trees = None
        return other

    def instances_at(self, points: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """Instance id of the nearest map vertex of each point's own class.

        The panoptic lookup: a point labelled ``c`` takes the instance of the nearest map vertex
        labelled ``c`` within ``max_distance`` (0 when there is none, or when ``c`` is void or a
        stuff class). One KD-tree per class, built on first use.

        Parameters
        ----------
        points : float (N,3)
        labels : uint8 (N,)
            The class each point was given (e.g. by a transfer method).

        Returns
        -------
        int32 (N,)

        Raises
        ------
        ValueError
            The map has no instance layer, or ``points`` and ``labels`` differ in length.
        """
        if self.map.instances is None:
            raise ValueError(
                f"{self.source}: the map has no instance layer (no 'instance' vertex property); "
                "add one with semmatch.transfer.panoptic.segment_instances or `semmatch panoptic segment`"
            )
        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        lab = np.asarray(labels).reshape(-1)
        if len(p) != len(lab):
            raise ValueError(f"{len(p)} points but {len(lab)} labels")
        out = np.zeros(len(p), np.int32)
        if self._class_trees is None:
            self._class_trees = {}
        for c in np.unique(lab):
            if int(c) not in THING_CLASSES:
                continue
            if int(c) not in self._class_trees:
                verts = np.flatnonzero((self.map.labels == c) & (self.map.instances > 0))
                tree = cKDTree(self.map.points[verts]) if len(verts) else None
                self._class_trees[int(c)] = (tree, self.map.instances[verts])
            tree, inst = self._class_trees[int(c)]
            if tree is None:
                continue
            sel = np.flatnonzero(lab == c)
            d, i = tree.query(p[sel], distance_upper_bound=self.max_distance, workers=self.workers)
            hit = np.isfinite(d)
            out[sel[hit]] = inst[i[hit]]
        return out

    def lookup(self, points: np.ndarray, *, exact: bool = True) -> np.ndarray:
        """Label of the nearest map surface, 0 where it is farther than ``max_distance``.

        Parameters
        ----------
        points : float (N,3)
            World coordinates (non-finite rows read as void).
        exact : bool
            Resolve points in ambiguous voxels (label edges, threshold shell) with an exact
            query. False: take the voxel-centre answer there too (faster; a point within about
            one voxel of a class boundary may take the neighbouring class).

        Returns
        -------
        uint8 (N,)
        """
        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0, np.uint8)
        q = (p - self.origin.astype(np.float32)) / np.float32(self.voxel_size)
        ks = []
        for a in range(3):
            qa = np.nan_to_num(q[:, a], nan=-1.0, posinf=-1.0, neginf=-1.0)
            np.clip(qa, 0, self.shape[a] - 1, out=qa)
            ks.append(qa.astype(np.int32))
        if self._dense is not None:
            out = self._dense[(ks[0].astype(np.int64) * self.shape[1] + ks[1]) * self.shape[2] + ks[2]]
        else:
            out = self._values(*ks)
        return self._resolve(out, lambda sel: p[sel], exact)

    def _gather_depth(
        self, depth: np.ndarray, pose: np.ndarray, intrinsics: Intrinsics, *, flags: bool = True
    ):
        """Grid values of every pixel (with the flag bits, or the voxel-centre labels only) and a
        function giving the world points of selected pixels."""
        T = check_pose(pose)
        rx, ry = self._pixel_rays(intrinsics)
        z = np.asarray(depth, dtype=np.float32)
        if z.shape != intrinsics.shape:
            raise ValueError(f"depth is {z.shape} but the intrinsics say {intrinsics.shape}")
        valid = z > 0  # NaN compares False
        if not (valid | (z == 0)).all() or np.isinf(z).any():
            valid &= np.isfinite(z)
            z = np.where(valid, z, 0).astype(np.float32)
        inv = 1.0 / self.voxel_size
        R = T[:3, :3] * inv
        t = (T[:3, 3] - self.origin) * inv
        dense = self._dense is not None  # one gather: the voxel's linear index, exact in floats
        exact_dtype = np.float32 if np.prod(self.shape) < 2**24 else np.float64
        ks, lin = [], None
        for a in range(3):
            qa = cv2.addWeighted(rx, R[a, 0], ry, R[a, 1], R[a, 2])
            qa = cv2.multiply(qa, z)
            qa += np.float32(t[a])
            np.clip(qa, 0, self.shape[a] - 1, out=qa)
            if not dense:
                ks.append(qa.astype(np.int32))  # truncation = floor (clipped to >= 0)
                continue
            np.floor(qa, out=qa)
            if lin is None:
                lin = qa.astype(exact_dtype, copy=False)
            else:
                lin *= self.shape[a]
                lin += qa
        if dense:
            out = self._dense[lin.astype(np.int64 if exact_dtype is np.float64 else np.int32)]
            if not flags:
                out &= np.uint8(LABEL_BITS)
        else:
            out = self._values(*ks, flags=flags)
        out[~valid] = 0

        def world(sel: tuple[np.ndarray, ...]) -> np.ndarray:
            zz = z[sel]
            cam = np.stack([rx[sel] * zz, ry[sel] * zz, zz], axis=1)
            return cam @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32)

        return out, world

    def lookup_depth(
        self, depth: np.ndarray, pose: np.ndarray, intrinsics: Intrinsics, *, exact: bool = True
    ) -> np.ndarray:
        """:meth:`lookup` for every pixel of a depth image (the fast path of ``3d-neighborhood``).

        Parameters
        ----------
        depth : float32 (H,W)
            Metres; 0 or non-finite = no measurement (label 0).
        pose : (4,4)
            ``T_world_camera``.
        intrinsics : Intrinsics
        exact : bool
            See :meth:`lookup`.

        Returns
        -------
        uint8 (H,W)
        """
        if not exact:
            return self._gather_depth(depth, pose, intrinsics, flags=False)[0]
        out, world = self._gather_depth(depth, pose, intrinsics)
        return self._resolve(out, world, exact)

    def support_depth(self, depth: np.ndarray, pose: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
        """Which pixels have a map surface within ``max_distance`` of their 3D point.

        Only voxels of the ``max_distance`` shell need an exact query, so this is cheaper than
        :meth:`lookup_depth`.

        Returns
        -------
        bool (H,W)
        """
        out, world = self._gather_depth(depth, pose, intrinsics)
        sup = (out & np.uint8(LABEL_BITS)) > 0
        shell = (out & np.uint8(SHELL)) > 0
        if shell.any():
            sel = np.nonzero(shell)
            sup[sel] = self._within_reach(world(sel))
        return sup

    def _within_reach(self, points: np.ndarray) -> np.ndarray:
        """Whether each point has a map surface within ``max_distance`` (as :meth:`nearest`):
        :class:`~.reach.ReachTest`, made on first use and kept."""
        if self._reach is None:
            self._reach = ReachTest(self)
        return self._reach.within(points)

    def _resolve(self, out: np.ndarray, points_of, exact: bool) -> np.ndarray:
        """Replace ambiguous grid answers by exact queries (or by the voxel-centre answer)."""
        amb = out >= AMBIGUOUS
        if not amb.any():
            out &= np.uint8(LABEL_BITS)
            return out
        if not exact:
            out &= np.uint8(LABEL_BITS)
            return out
        sel = np.nonzero(amb)
        lab, _ = self.nearest(points_of(sel), self.max_distance)
        out &= np.uint8(LABEL_BITS)
        out[sel] = lab
        return out

    def _pixel_rays(self, intr: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
        if intr not in self._rays:
            r = pixel_rays(intr)
            self._rays[intr] = (np.ascontiguousarray(r[..., 0]), np.ascontiguousarray(r[..., 1]))
        return self._rays[intr]

    def __repr__(self) -> str:
        kind = "mesh" if self.is_mesh else "points"
        return (
            f"MapIndex({self.source!r}, {kind}, {self.n_points} vertices, grid {self.shape} at "
            f"{self.voxel_size:.3f} m, max_distance={self.max_distance})"
        )
