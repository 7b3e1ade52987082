"""Semantic TSDF reconstruction on Open3D's tensor ``VoxelBlockGrid``.

Depth and colour are integrated by Open3D (``VoxelBlockGrid.integrate``); label evidence lives
in the same grid as an extra per-voxel attribute ``label`` with one float channel per category
(a log-probability up to a per-voxel constant). Every surface point of a frame (the
back-projected pixel) adds its evidence to the voxel sample nearest to it, a Bayesian update as
in Kimera-Semantics:

* a hard label ``l`` (uint8 image) adds ``log(p * (C - 1) / (1 - p))`` to channel ``l``, which is
  the update of the symmetric measurement model ``P(obs = l | true = l) = p`` (``p`` =
  ``match_probability``) with the class-independent term dropped; void pixels (0) add nothing;
* per-pixel probabilities ``(H, W, C)`` add ``log(max(prob, eps))`` to every channel.

``softmax(evidence)`` is therefore the posterior under a uniform prior and the voxel label is
its arg-max (ties: the smallest id). With hard labels only, the arg-max is the majority vote
of the observations. Memory grows with the observed surface (allocated 8x8x8 blocks), not with
the room volume.

References
----------
.. [1] A. Rosinol, M. Abate, Y. Chang, L. Carlone, "Kimera: an open-source library for
   real-time metric-semantic localization and mapping", ICRA 2020.
.. [2] Open3D tensor reconstruction system, ``open3d.t.geometry.VoxelBlockGrid``.

The drivers that fuse whole sequences with it are in :mod:`semmatch.fusion.reconstruction`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..io import SemanticMap, check_depth, check_labels, check_rgb, depth_to_uint16
from ..io.geometry import Intrinsics, check_pose, pixel_rays
from ..io.labels import NUM_CLASSES
from ..runtime.engine import default_device

__all__ = ["SemanticTSDF", "EvidencePixels"]


def _as_o3d(arr: np.ndarray, device):
    import open3d.core as o3c

    t = o3c.Tensor(np.ascontiguousarray(arr))
    return t if device.get_type() == o3c.Device.DeviceType.CPU else t.to(device)


def _torch_view(t):
    """Zero-copy torch view of an Open3D tensor."""
    import torch.utils.dlpack

    return torch.utils.dlpack.from_dlpack(t.to_dlpack())


@dataclasses.dataclass(frozen=True)
class EvidencePixels:
    """The label-evidence pixels of one integrated frame (:meth:`SemanticTSDF.evidence_pixels`).

    Attributes
    ----------
    depth : float32 (M_all,)
        Depth of every ``label_stride``-th pixel (flat).
    pose : float64 (4, 4)
    index : int32 (M,)
        The pixels (into ``depth``) that carry evidence.
    intrinsics : Intrinsics
    """

    depth: np.ndarray
    pose: np.ndarray
    index: np.ndarray
    intrinsics: Intrinsics


class SemanticTSDF:
    """A TSDF volume with colour and per-voxel label evidence (incremental use).

    Parameters
    ----------
    voxel_size : float
        Voxel edge in metres.
    n_classes : int
        Number of label channels (category ids ``0 .. n_classes - 1``).
    trunc_voxels : float
        TSDF truncation in voxels.
    depth_max : float
        Ignore depth beyond this distance (metres).
    label_stride : int
        Use every ``label_stride``-th pixel (each direction) as label evidence. At 4 cm voxels a
        voxel covers several pixels, so 2 loses nothing in practice and is 4x cheaper.
    match_probability : float
        Probability that a hard label is right (Kimera's measurement model), in (1/C, 1).
    block_resolution : int
        Voxels per block edge.
    block_count : int
        Initial hash-map capacity in blocks (grows on demand).
    device : str, optional
        Open3D device, e.g. ``"CPU:0"`` or ``"CUDA:0"``; default
        :func:`semmatch.runtime.engine.default_device`.

    Examples
    --------
    >>> vol = SemanticTSDF(voxel_size=0.04)                       # doctest: +SKIP
    >>> for f in frames: vol.integrate(f.depth, f.rgb, f.pose, f.intrinsics, labels=f.labels)
    >>> mesh = vol.extract_mesh()                                 # SemanticMap with faces
    """

    #: smallest share of a frame's pixels with valid depth for it to be integrated
    MIN_VALID_DEPTH = 0.001

    def __init__(
        self,
        voxel_size: float = 0.04,
        *,
        n_classes: int = NUM_CLASSES,
        trunc_voxels: float = 4.0,
        depth_max: float = 6.0,
        label_stride: int = 2,
        match_probability: float = 0.9,
        block_resolution: int = 8,
        block_count: int = 1024,
        device: str | None = None,
    ) -> None:
        import open3d.core as o3c

        if not (np.isfinite(voxel_size) and voxel_size > 0):
            raise ValueError(f"voxel_size must be > 0 (metres), got {voxel_size}")
        if voxel_size < 1e-3:
            raise ValueError(f"voxel_size {voxel_size:g} m is below 1 mm, finer than any depth camera resolves "
                             "(sizes are in metres: 0.04 is 4 cm)")
        if not 2 <= int(n_classes) <= 256:
            raise ValueError(f"n_classes must lie in 2..256, got {n_classes}")
        if int(label_stride) < 1:
            raise ValueError(f"label_stride must be >= 1, got {label_stride}")
        if not 1.0 / n_classes < match_probability < 1.0:
            raise ValueError(f"match_probability must lie in (1/{n_classes}, 1), got {match_probability}")
        if not depth_max > 0 or not trunc_voxels > 0:
            raise ValueError("depth_max and trunc_voxels must be > 0")
        res = int(block_resolution)
        if res < 2 or res & (res - 1):
            raise ValueError(f"block_resolution must be a power of two >= 2, got {block_resolution}")
        self.voxel_size = float(voxel_size)
        self.n_classes = int(n_classes)
        self.trunc_voxels = float(trunc_voxels)
        self.depth_max = float(depth_max)
        self.label_stride = int(label_stride)
        self.match_probability = float(match_probability)
        self.hard_weight = float(np.log(match_probability * (n_classes - 1) / (1.0 - match_probability)))
        self.res = res
        self._shift = res.bit_length() - 1
        self.device = o3c.Device(device or default_device())
        self.vbg = self._new_grid(int(block_count))
        self._rays: dict[tuple[Intrinsics, int], np.ndarray] = {}
        self._K: dict[Intrinsics, object] = {}
        self.n_frames = 0
        self.name = "sequence"  # what was fused, for messages (set by fuse_sequence())
        self.n_label_points = 0
        #: frames skipped for lack of valid depth (sensor dropouts), by their ``where`` names
        self.skipped: list[str] = []

    _ATTRS = ("tsdf", "weight", "color", "label")

    def _new_grid(self, capacity: int):
        import open3d as o3d
        import open3d.core as o3c

        return o3d.t.geometry.VoxelBlockGrid(
            attr_names=self._ATTRS,
            attr_dtypes=(o3c.float32,) * 4,
            attr_channels=(1, 1, 3, self.n_classes),
            voxel_size=self.voxel_size,
            block_resolution=self.res,
            block_count=max(int(capacity), 16),
            device=self.device,
        )

    def _reserve(self, n_new: int) -> None:
        """Grow the grid before Open3D would rehash it (its CPU rehash takes seconds).

        A grid of four (small grids) or two times the capacity is allocated and the active blocks are copied over with
        one vectorised gather/scatter per attribute.
        """
        hm = self.vbg.hashmap()
        size, cap = int(hm.size()), int(hm.capacity())
        if size + n_new <= cap:
            return
        factor = 4 if cap < 8192 else 2  # few growths while small, bounded overshoot when large
        new = self._new_grid(max(factor * cap, int(1.5 * (size + n_new))))
        if size:
            old_buf = hm.active_buf_indices()
            keys = hm.key_tensor()[old_buf.to(hm.key_tensor().device)]
            new_buf, ok = new.hashmap().activate(keys)
            if not bool(ok.all().item()):  # pragma: no cover - fresh grid, unique keys
                raise RuntimeError("could not move voxel blocks into the grown grid")
            src = _torch_view(old_buf).long()
            dst = _torch_view(new_buf).long()
            for name in self._ATTRS:
                _torch_view(new.attribute(name))[dst] = _torch_view(self.vbg.attribute(name))[src]
        self.vbg = new

    # ------------------------------------------------------------------ integration
    def integrate(
        self,
        depth: np.ndarray,
        rgb: np.ndarray | None,
        pose: np.ndarray,
        intrinsics: Intrinsics,
        *,
        labels: np.ndarray | None = None,
        where: str = "frame",
    ) -> bool:
        """Integrate one posed RGB-D frame and its label evidence.

        A frame with (almost) no valid depth (fewer than :attr:`MIN_VALID_DEPTH` of its pixels
        within range: a sensor dropout) touches no voxel: it is skipped, named in
        :attr:`skipped`, and False is returned.

        Parameters
        ----------
        depth : float32 (H, W)
            Metres, 0 = no measurement.
        rgb : uint8 (H, W, 3), optional
            Colour (grey when None).
        pose : (4, 4)
            ``T_world_camera``.
        intrinsics : Intrinsics
        labels : uint8 (H, W) or float (H, W, C), optional
            Category ids (0 = no evidence) or per-pixel class probabilities.
        where : str
            Name of the frame for error messages.

        Returns
        -------
        bool
            True when the frame was integrated.

        Raises
        ------
        ValueError
            Arrays that break the frame contract (:mod:`semmatch.io.contract`: shapes that
            disagree with the intrinsics, depth that is not float or in the wrong unit, RGB
            that is not uint8), a bad pose, label ids or probability channels that do not fit
            ``n_classes``.
        """
        import open3d as o3d
        import open3d.core as o3c

        H, W = intrinsics.shape
        depth = check_depth(depth, (H, W), where=where)  # 0 = no measurement
        T = check_pose(pose, what=f"{where} pose")
        if np.count_nonzero((depth > 0) & (depth <= self.depth_max)) < self.MIN_VALID_DEPTH * H * W:
            self.skipped.append(where)
            return False
        if rgb is None:
            color = np.full((H, W, 3), 128, dtype=np.uint8)
        else:
            color = np.ascontiguousarray(check_rgb(rgb, (H, W), where=where))
        K = self._K.get(intrinsics)
        if K is None:
            K = self._K[intrinsics] = o3c.Tensor(intrinsics.K)
        dev = self.device
        # Open3D integrates (uint16 depth, uint8 colour) without float conversions: depth in mm
        depth_mm = depth_to_uint16(depth)
        d_img = o3d.t.geometry.Image(_as_o3d(depth_mm, dev))
        c_img = o3d.t.geometry.Image(_as_o3d(color, dev))
        ext = o3c.Tensor(np.linalg.inv(T))
        blocks = self.vbg.compute_unique_block_coordinates(
            d_img, K, ext, 1000.0, self.depth_max, self.trunc_voxels
        )
        if int(blocks.shape[0]) == 0:
            self.skipped.append(where)
            return False
        self._reserve(int(blocks.shape[0]))
        self.vbg.integrate(blocks, d_img, c_img, K, ext, 1000.0, self.depth_max, self.trunc_voxels)
        if labels is not None:
            self._add_evidence(depth, np.asarray(labels), T, intrinsics, where)
        self.n_frames += 1
        return True

    def _add_evidence(
        self, depth: np.ndarray, labels: np.ndarray, T: np.ndarray, intr: Intrinsics, where: str
    ) -> None:
        values, has = self._sampled_labels(labels, intr, where)
        d = self._sampled_depth(depth)
        valid = (d > 0) & (d <= self.depth_max)
        if has is not None:
            valid &= has
        sel = np.flatnonzero(valid)
        if sel.size:
            self._add_at(self._voxels_of(d, sel, T, intr), values[sel])

    def _sampled_depth(self, depth: np.ndarray) -> np.ndarray:
        """Depth (metres) of the label-evidence pixels (every ``label_stride``-th), flat."""
        s = self.label_stride
        return np.ascontiguousarray(depth[::s, ::s]).reshape(-1)

    def _sampled_labels(
        self, labels: np.ndarray, intr: Intrinsics, where: str
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Checked labels of the evidence pixels (:func:`semmatch.io.check_labels`): ids (M,)
        and their ``id > 0`` mask, or probabilities (M, C) and None."""
        values = check_labels(labels, intr.shape, n_classes=self.n_classes, where=where, stride=self.label_stride)
        return (values, None) if values.ndim == 2 else (values, values > 0)

    def _voxels_of(self, d: np.ndarray, sel: np.ndarray, T: np.ndarray, intr: Intrinsics):
        """Flat index into the ``label`` attribute of the voxel sample nearest to the surface
        point of each evidence pixel ``sel`` (sampled depth ``d``); -1 where its block is not
        allocated. A torch int64 tensor on the grid's device."""
        import torch

        if len(sel) == 0:  # a skipped frame or one without evidence: nothing to look up
            return torch.zeros(0, dtype=torch.int64, device=_torch_view(self.vbg.attribute("label")).device)
        key = (intr, self.label_stride)
        rays = self._rays.get(key)
        if rays is None:  # (2, M) contiguous rows: x/z and y/z of every sampled pixel
            rays = self._rays[key] = np.ascontiguousarray(pixel_rays(intr, self.label_stride).reshape(-1, 3)[:, :2].T)
        # nearest voxel sample of each surface point: round(world / voxel_size); column-wise
        # arithmetic on contiguous 1-D arrays, then one selection (cheaper than (N,3) gathers)
        A = (T / self.voxel_size).astype(np.float32)
        x = rays[0] * d
        y = rays[1] * d
        k = np.empty((len(sel), 3), dtype=np.int32)
        for a in range(3):
            col = A[a, 0] * x
            col += A[a, 1] * y
            col += A[a, 2] * d
            col += A[a, 3]
            k[:, a] = np.rint(col[sel])
        blk = k >> self._shift
        loc = k & (self.res - 1)
        buf, found = self.vbg.hashmap().find(_as_o3d(blk, self.device))
        buf = _torch_view(buf).to(torch.int64)
        found = _torch_view(found).to(torch.bool)
        r = self.res
        lin = torch.from_numpy(((loc[:, 2] * r + loc[:, 1]) * r + loc[:, 0]).astype(np.int64)).to(buf.device)
        return torch.where(found, buf * (r**3) + lin, -1)

    def _add_at(self, voxel, values: np.ndarray) -> None:
        """Add the evidence of pixels with labels ``values`` (ids (M,) or probabilities (M, C))
        to their voxels ``voxel`` (M,) from :meth:`_voxels_of` (-1: skipped)."""
        import torch

        C = self.n_classes
        found = voxel >= 0
        voxel = voxel[found]
        ev = _torch_view(self.vbg.attribute("label")).view(-1, C)
        if values.ndim == 2:
            logp = np.log(np.maximum(values, 1e-4, dtype=np.float32))
            ev.index_add_(0, voxel, torch.from_numpy(logp).to(ev.device)[found])
        else:
            flat = voxel * C + torch.from_numpy(values.astype(np.int64)).to(ev.device)[found]
            ev.view(-1).index_add_(
                0, flat, torch.full((len(flat),), self.hard_weight, dtype=torch.float32, device=ev.device)
            )
        self.n_label_points += int(len(voxel))

    # ------------------------------------------------------------------ labels after geometry
    def evidence_pixels(self, depth: np.ndarray, pose: np.ndarray, intrinsics: Intrinsics) -> EvidencePixels:
        """The label-evidence pixels of a frame already integrated (geometry first, labels later).

        Every ``label_stride``-th pixel with depth in range whose voxel block exists now (as
        :meth:`integrate` with ``labels`` adds them). Keep these for each frame while the
        geometry is integrated; once it is complete, :meth:`locate` finds their voxels and
        :meth:`add_labels` adds any number of labelings, each after :meth:`clear_labels`.

        Parameters
        ----------
        depth : float32 (H, W)
            The frame's depth (metres; NaN and 0 = no measurement).
        pose : (4, 4)
            ``T_world_camera`` it was integrated with.
        intrinsics : Intrinsics

        Returns
        -------
        EvidencePixels
        """
        depth = np.where(np.isfinite(depth), depth, 0).astype(np.float32, copy=False)
        d, T = self._sampled_depth(depth), np.asarray(pose, dtype=np.float64)
        sel = np.flatnonzero((d > 0) & (d <= self.depth_max))
        sel = sel[(self._voxels_of(d, sel, T, intrinsics) >= 0).cpu().numpy()].astype(np.int32)
        return EvidencePixels(d, T, sel, intrinsics)

    def locate(self, pixels: EvidencePixels):
        """Voxels (flat label-attribute indices, a torch tensor) of evidence pixels. Call once the
        geometry is complete: allocating blocks moves the voxels."""
        return self._voxels_of(pixels.depth, pixels.index, pixels.pose, pixels.intrinsics)

    def clear_labels(self) -> None:
        """Drop all label evidence (the geometry stays): start the next labeling."""
        _torch_view(self.vbg.attribute("label")).zero_()
        self.n_label_points = 0

    def add_labels(self, labels: np.ndarray, pixels: EvidencePixels, voxels=None, *, where: str = "frame") -> None:
        """Add one frame's labels at its evidence pixels.

        Parameters
        ----------
        labels : uint8 (H, W) or float (H, W, C)
            Category ids (0 = no evidence) or class probabilities of the frame.
        pixels : EvidencePixels
            From :meth:`evidence_pixels` of that frame.
        voxels : torch tensor, optional
            ``locate(pixels)``, when already computed (several labelings share it).
        where : str
            Name of the frame (and labeling) for error messages.

        Raises
        ------
        ValueError
            Labels of another size than the intrinsics, ids or channels that do not fit.
        """
        import torch

        voxels = self.locate(pixels) if voxels is None else voxels
        values, has = self._sampled_labels(np.asarray(labels), pixels.intrinsics, where)
        values = values[pixels.index]
        if has is not None:
            keep = has[pixels.index]
            values, voxels = values[keep], voxels[torch.from_numpy(keep).to(voxels.device)]
        if len(values):
            self._add_at(voxels, values)

    # ------------------------------------------------------------------ queries
    def _evidence_at(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Evidence rows (N, C) and an observed flag (N,) of voxel samples ``keys`` (N,3) int."""
        import open3d.core as o3c

        keys = np.asarray(keys, dtype=np.int32)
        blk = keys >> self._shift
        loc = (keys & (self.res - 1)).astype(np.int64)
        buf, found = self.vbg.hashmap().find(o3c.Tensor(blk).to(self.device))
        buf = buf.cpu().numpy().astype(np.int64)
        found = found.cpu().numpy().astype(bool)
        r = self.res
        voxel = buf * r**3 + (loc[:, 2] * r + loc[:, 1]) * r + loc[:, 0]
        ev_all = self.vbg.attribute("label").cpu().numpy().reshape(-1, self.n_classes)
        out = np.zeros((len(keys), self.n_classes), dtype=np.float32)
        out[found] = ev_all[voxel[found]]
        return out, out.any(axis=1)

    def labels_at(self, points: np.ndarray) -> np.ndarray:
        """Category of surface points (N,3): arg-max evidence of the nearest voxel sample.

        Points whose nearest sample holds no evidence pool the evidence of the 8 samples of the
        voxel cell around them; points without any evidence get 0 (void).
        """
        p = np.asarray(points, dtype=np.float64) / self.voxel_size
        if len(p) == 0:
            return np.zeros(0, dtype=np.uint8)
        ev, seen = self._evidence_at(np.rint(p))
        miss = np.flatnonzero(~seen)
        if miss.size:
            base = np.floor(p[miss]).astype(np.int64)
            pooled = np.zeros((miss.size, self.n_classes), dtype=np.float32)
            seen_any = np.zeros(miss.size, dtype=bool)
            for off in np.ndindex(2, 2, 2):
                e, s = self._evidence_at(base + np.asarray(off))
                pooled += e
                seen_any |= s
            ev[miss] = pooled
            seen[miss] = seen_any
        lab = np.argmax(ev, axis=1).astype(np.uint8)
        lab[~seen] = 0
        return lab

    @property
    def n_blocks(self) -> int:
        """Allocated voxel blocks."""
        return int(self.vbg.hashmap().size())

    @property
    def memory_bytes(self) -> int:
        """Bytes held by the voxel attributes (capacity, all blocks)."""
        cap = int(self.vbg.hashmap().capacity())
        return cap * self.res**3 * 4 * (1 + 1 + 3 + self.n_classes)

    def extract_mesh(self, *, min_weight: float = 1.0) -> SemanticMap:
        """Marching-cubes mesh: vertices with labels, RGB colours, normals and faces, in canonical
        order (:meth:`~semmatch.io.SemanticMap.canonical`: the same frames give the same arrays and
        the same file bytes, although Open3D's hash map orders its blocks differently each run)."""
        mesh = self.vbg.extract_triangle_mesh(weight_threshold=float(min_weight)).cpu()
        pts = mesh.vertex.positions.numpy() if "positions" in mesh.vertex else np.zeros((0, 3))
        if len(pts) == 0:
            return SemanticMap(np.zeros((0, 3)), np.zeros(0), faces=np.zeros((0, 3)), source="fusion:mesh")
        return SemanticMap(
            pts,
            self.labels_at(pts),
            colors=_to_uint8(mesh.vertex.colors.numpy()),
            faces=mesh.triangle.indices.numpy(),
            normals=mesh.vertex.normals.numpy(),
            source="fusion:mesh",
        ).canonical()

    def extract_point_cloud(self, *, min_weight: float = 1.0) -> SemanticMap:
        """Surface points (TSDF zero crossings) with labels and RGB colours, in canonical order."""
        pcd = self.vbg.extract_point_cloud(weight_threshold=float(min_weight)).cpu()
        pts = pcd.point.positions.numpy() if "positions" in pcd.point else np.zeros((0, 3))
        if len(pts) == 0:
            return SemanticMap(np.zeros((0, 3)), np.zeros(0), source="fusion:points")
        cols = _to_uint8(pcd.point.colors.numpy()) if "colors" in pcd.point else None
        normals = pcd.point.normals.numpy() if "normals" in pcd.point else None
        return SemanticMap(pts, self.labels_at(pts), colors=cols, normals=normals, source="fusion:points").canonical()


def _to_uint8(c: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(c, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)

