"""Panoptic transfer: instance ids from the person's map into the robot's frames and map.

The paper's semantic maps tell categories apart, not instances (its stated future work). This
module carries instances along the same chain as the labels:

1. **An instance layer on the upper map** (``SemanticMap.instances``, the PLY ``instance``
   vertex property): from ground truth (:func:`fuse_instances` votes the frames' instance
   images onto the map's vertices) or, for a network-built map, by 3D instance segmentation:
   :func:`segment_instances` clusters each thing class's vertices (Open3D DBSCAN).
2. **Transfer** (:func:`transfer_panoptic`): any transfer method labels a lower frame; a thing
   pixel then takes the instance of the nearest map vertex of its class
   (:meth:`~semmatch.transfer.index.MapIndex.instances_at`), and the group methods give each
   superpixel / supervoxel / cluster the majority instance of its pixels.
3. **Panoptic fusion of the lower view** (:func:`fuse_instances`): the transferred instance
   images are voted onto the vertices of the lower semantic map (a vertex counts a frame's
   vote where it is visible, in front of the depth within ``tolerance``, and the pixel has
   the vertex's class). Ids come from the upper map, so association across frames is by id.
   :func:`clean_instances` then handles the splits the map's clustering produced: fragments
   below ``min_vertices`` (a split's small piece) join the touching instance of their class.
   Merges (two touching objects clustered as one) cannot be told from one object by geometry
   alone and stay merged.
4. **Measures** (:func:`panoptic_quality`): panoptic quality PQ = SQ x RQ (Kirillov et al.,
   CVPR 2019) on voxels: segments are (class, instance) voxel sets for things and one set per
   class for stuff; a predicted and a ground-truth segment of one class match when their IoU
   exceeds 0.5 (unique by construction). Ground-truth voxels that are void or things without
   an instance are ignored: removed from the predicted segments' areas, and a predicted segment
   lying mostly (> 50 %) on them is not a false positive.

One module (over 500 lines): instance segmentation of maps, instance transfer, panoptic fusion and
voxel PQ share one convention for instance ids.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..io import Frame, SemanticMap, read_map, require_instances
from ..io.geometry import Intrinsics, check_pose, pack_keys, voxel_keys
from ..io.labels import NAMES, NUM_CLASSES, STUFF_CLASSES, THING_CLASSES
from .dbscan import dbscan_labels
from .frames import check_frame
from .index import MapIndex, as_map_index
from .registry import transfer_frame

__all__ = [
    "PanopticFrame",
    "segment_instances",
    "clean_instances",
    "fuse_instances",
    "transfer_panoptic",
    "panoptic_voxels",
    "panoptic_quality",
    "sequence_panoptic_frames",
]

_THINGS = np.zeros(NUM_CLASSES, bool)
_THINGS[list(THING_CLASSES)] = True


def _with_instances(m: SemanticMap, instances: np.ndarray) -> SemanticMap:
    return SemanticMap(m.points, m.labels, colors=m.colors, faces=m.faces, normals=m.normals,
                       source=m.source, instances=instances)


# ----------------------------------------------------------------------------- 3D instance segmentation
def segment_instances(
    m: SemanticMap,
    *,
    eps: float = 0.05,
    min_points: int = 5,
    min_vertices: int = 50,
) -> SemanticMap:
    """Give a semantic map an instance layer by clustering each thing class's vertices.

    Every thing class (:data:`~semmatch.io.labels.THING_CLASSES`) is clustered on its own with
    Open3D DBSCAN; each cluster of at least ``min_vertices`` vertices becomes one instance
    (ids 1, 2, ... in class order, then by cluster size). Stuff, DBSCAN noise and small clusters
    keep instance 0.

    Parameters
    ----------
    m : SemanticMap
        A semantic map (mesh or points), e.g. the network-built upper map.
    eps : float
        DBSCAN neighbourhood radius in metres (vertices closer than this link up). Larger radii
        bridge label holes and occlusion gaps within an object, but merge objects of one class
        that stand closer than ``eps``; the pipeline chooses it on validation scenes.
    min_points : int
        DBSCAN core-point threshold.
    min_vertices : int
        Smallest instance kept.

    Returns
    -------
    SemanticMap
        The same map with ``instances`` set.

    Raises
    ------
    ValueError
        Empty map, non-positive ``eps``.
    """
    m.check()
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be > 0 (metres), got {eps}")
    inst = np.zeros(len(m.points), np.int32)
    nxt = 1
    for c in THING_CLASSES:
        sel = np.flatnonzero(m.labels == c)
        if len(sel) < max(int(min_vertices), 1):
            continue
        cl = dbscan_labels(m.points[sel], eps, min_points)
        if (cl >= 0).sum() == 0:
            continue
        sizes = np.bincount(cl[cl >= 0])
        keep = np.flatnonzero(sizes >= int(min_vertices))
        keep = keep[np.argsort(-sizes[keep], kind="stable")]
        new = np.zeros(len(sizes), np.int32)
        new[keep] = np.arange(nxt, nxt + len(keep), dtype=np.int32)
        nxt += len(keep)
        inst[sel[cl >= 0]] = new[cl[cl >= 0]]
    return _with_instances(m, inst)


def clean_instances(
    points: np.ndarray,
    labels: np.ndarray,
    instances: np.ndarray,
    *,
    eps: float = 0.05,
    min_vertices: int = 50,
) -> np.ndarray:
    """Join small instance fragments to the touching instance of their class.

    Each (class, instance) vertex set is cut into spatial components (single linkage at
    ``eps``: Open3D DBSCAN with one point per core). A component of fewer than
    ``min_vertices`` vertices that has a vertex of another instance of its class within ``eps``
    joins that instance (the majority of the touching vertices): the small piece of an object
    the upper map's clustering split in two, or a few pixels that took a neighbour's id. Larger
    components, and fragments touching nothing of their class, keep their id (one object seen
    in parts because something occludes its middle stays one instance).

    Parameters
    ----------
    points : float (N,3)
    labels : uint8 (N,)
    instances : int (N,)
    eps : float
        Linking distance, metres.
    min_vertices : int
        Fragments below this size may join a neighbour.

    Returns
    -------
    int32 (N,)
        The cleaned instance ids (0 for stuff and unassigned vertices).
    """
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    lab = np.asarray(labels).reshape(-1)
    inst = np.where(_THINGS[lab], np.asarray(instances, dtype=np.int64).reshape(-1), 0).astype(np.int32)
    out = inst.copy()
    for c in np.unique(lab[inst > 0]):
        in_c = np.flatnonzero((lab == c) & (inst > 0))
        ids = np.unique(inst[in_c])
        if len(ids) < 2:
            continue
        tree = cKDTree(pts[in_c])
        for i in ids:
            sel = in_c[inst[in_c] == i]
            if len(sel) >= min_vertices * 50:
                continue  # a large instance: its fragments are rare and harmless, skip the DBSCAN
            comp = dbscan_labels(pts[sel], eps, 1)
            sizes = np.bincount(comp)
            for k in np.flatnonzero(sizes < min_vertices):
                part = sel[comp == k]
                near = tree.query_ball_point(pts[part], eps)
                j = np.unique(np.concatenate([np.asarray(n, np.int64) for n in near]))
                other = inst[in_c[j]]
                other = other[other != i]
                if len(other):
                    vals, counts = np.unique(other, return_counts=True)
                    out[part] = vals[np.argmax(counts)]
    return out


# ----------------------------------------------------------------------------- panoptic fusion
@dataclass
class PanopticFrame:
    """One frame's panoptic evidence: depth, pose, intrinsics, class and instance images."""

    depth: np.ndarray
    pose: np.ndarray
    intrinsics: Intrinsics
    labels: np.ndarray
    instances: np.ndarray
    name: str = "frame"

    @classmethod
    def of(cls, frame: Frame, labels: np.ndarray, instances: np.ndarray, name: str | None = None) -> PanopticFrame:
        """The evidence of a posed :class:`~semmatch.io.Frame` with its class and instance images."""
        return cls(frame.depth, frame.pose, frame.intrinsics, labels, instances,
                   name or f"frame {getattr(frame, 'index', '?')}")


def fuse_instances(
    m: SemanticMap,
    frames: Iterable[PanopticFrame],
    *,
    tolerance: float = 0.05,
    clean: bool = True,
    eps: float = 0.05,
    min_vertices: int = 50,
) -> SemanticMap:
    """Vote the frames' instance images onto the vertices of a semantic map.

    A vertex takes a frame's vote when it projects into the image, lies within ``tolerance``
    of the measured depth along the ray (visible, not occluded), and the pixel's class equals
    the vertex's class; the vertex's instance is the plurality of its votes (ties: the smaller
    id), 0 without votes and for stuff. With ``clean`` the result goes through
    :func:`clean_instances`.

    Parameters
    ----------
    m : SemanticMap
        The semantic map (its classes decide which votes count).
    frames : iterable of PanopticFrame
    tolerance : float
        Visibility tolerance in metres.
    clean, eps, min_vertices
        See :func:`clean_instances`.

    Returns
    -------
    SemanticMap
        ``m`` with ``instances`` set.

    Raises
    ------
    ValueError
        A frame whose images disagree with its intrinsics, a bad pose, no frame at all.
    """
    m.check()
    pts = m.points.astype(np.float64)
    thing_v = np.flatnonzero(_THINGS[m.labels])
    votes: list[np.ndarray] = []
    n = 0
    for f in frames:
        n += 1
        shape = f.intrinsics.shape
        for what, img in (("depth", f.depth), ("labels", f.labels), ("instances", f.instances)):
            if np.asarray(img).shape[:2] != shape:
                raise ValueError(f"{f.name}: {what} is {np.asarray(img).shape[:2]}, intrinsics say {shape}")
        if len(thing_v) == 0:
            continue
        T = check_pose(f.pose, what=f"{f.name} pose")
        Tinv = np.linalg.inv(T)
        cam = pts[thing_v] @ Tinv[:3, :3].T + Tinv[:3, 3]
        z = cam[:, 2]
        ok = z > 1e-6
        u = np.full(len(z), -1, np.int64)
        v = np.full(len(z), -1, np.int64)
        zz = np.where(ok, z, 1.0)
        u[ok] = np.floor(f.intrinsics.fx * cam[ok, 0] / zz[ok] + f.intrinsics.cx).astype(np.int64)
        v[ok] = np.floor(f.intrinsics.fy * cam[ok, 1] / zz[ok] + f.intrinsics.cy).astype(np.int64)
        H, W = shape
        ok &= (u >= 0) & (u < W) & (v >= 0) & (v < H)
        sel = np.flatnonzero(ok)
        d = np.asarray(f.depth, dtype=np.float32)[v[sel], u[sel]]
        inst = np.asarray(f.instances)[v[sel], u[sel]].astype(np.int64)
        lab = np.asarray(f.labels)[v[sel], u[sel]]
        good = (d > 0) & (np.abs(d - z[sel]) <= tolerance) & (inst > 0) & (lab == m.labels[thing_v[sel]])
        votes.append((thing_v[sel[good]].astype(np.int64) << 32) | inst[good])
    if n == 0:
        raise ValueError(f"{m.source}: no frames to fuse instances from")
    out = np.zeros(len(pts), np.int32)
    if votes:
        pairs = np.concatenate(votes)
        vert, winner = _plurality(pairs >> 32, pairs & 0xFFFFFFFF)
        out[vert] = winner
    if clean:
        out = clean_instances(m.points, m.labels, out, eps=eps, min_vertices=min_vertices)
    return _with_instances(m, out)


def sequence_panoptic_frames(seq, *, labels=None, step: int = 1) -> Iterator[PanopticFrame]:
    """Every ``step``-th frame of a sequence with its ground-truth classes and instances.

    Parameters
    ----------
    seq : SequenceReader
        A sequence with ``instances/`` (the simulator writes them).
    labels : callable, optional
        ``labels(i) -> uint8 (H,W)`` replacing the sequence's own labels.
    step : int
    """
    for i in range(0, len(seq), int(step)):
        f = seq[i]
        lab = f.labels if labels is None else labels(i)
        if lab is None:
            raise ValueError(f"{seq.path}: frame {i} has no labels")
        yield PanopticFrame.of(f, lab, seq.read_instances(i), f"{seq.path} frame {i}")


# ----------------------------------------------------------------------------- transfer
def _plurality(keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per distinct key (>= 0, < 2**31) the most frequent value (ids < 2**32; ties: the smaller).

    Returns the distinct keys (sorted) and their winning values (int32).
    """
    pair, counts = np.unique((np.asarray(keys, np.int64) << 32) | np.asarray(values, np.int64), return_counts=True)
    key = pair >> 32
    order = np.lexsort((pair & 0xFFFFFFFF, -counts, key))
    key_o = key[order]
    first = np.r_[True, key_o[1:] != key_o[:-1]] if len(key_o) else np.zeros(0, bool)
    return key_o[first], (pair[order][first] & 0xFFFFFFFF).astype(np.int32)


def _group_majority(groups: np.ndarray, instances: np.ndarray) -> np.ndarray:
    """Per pixel: the majority non-zero instance of its group (ties: smaller id)."""
    g = groups.reshape(-1)
    inst = instances.reshape(-1).astype(np.int64)
    out = np.zeros(g.shape, np.int32)
    sel = np.flatnonzero((g >= 0) & (inst > 0))
    if len(sel) == 0:
        return out.reshape(groups.shape)
    best = np.zeros(int(g.max()) + 1, np.int32)
    grp, winner = _plurality(g[sel], inst[sel])
    best[grp] = winner
    has = g >= 0
    out[has] = best[g[has]]
    return out.reshape(groups.shape)


def transfer_panoptic(
    name: str, frame: Frame, semantic_map: SemanticMap | MapIndex, **params
) -> tuple[np.ndarray, np.ndarray]:
    """Transfer classes and instances of an upper map with an instance layer into one frame.

    Parameters
    ----------
    name : str
        A transfer method (:data:`semmatch.transfer.METHODS`; ``fused`` too: pixels the network
        labelled without map support get no instance).
    frame : Frame
    semantic_map : SemanticMap or MapIndex
        The upper map, with ``instances``.
    **params
        The method's parameters (:func:`semmatch.transfer.transfer_frame`).

    Returns
    -------
    labels : uint8 (H,W)
        As :func:`semmatch.transfer.transfer`.
    instances : int32 (H,W)
        Instance id of every thing pixel (0 for void, stuff, or no instance nearby).
        ``3d-neighborhood``: the nearest vertex of the pixel's class; group methods: the
        majority of those per group, given to the group's pixels of a thing class.

    Raises
    ------
    ValueError
        The map has no instance layer (and every error of ``transfer_frame``).
    """
    max_distance = params.pop("max_distance", None)
    index = as_map_index(semantic_map, max_distance=max_distance)
    require_instances(index.map, "panoptic transfer")
    r = transfer_frame(name, frame, index, **params)
    fd = check_frame(frame, need_rgb=False)
    thing = _THINGS[r.labels] & fd.valid
    pix = np.flatnonzero(thing)
    inst = np.zeros(r.labels.shape, np.int32)
    if len(pix):
        inst.reshape(-1)[pix] = index.instances_at(fd.world_points(pix), r.labels.reshape(-1)[pix])
    if r.groups is not None:
        inst = np.where(thing, _group_majority(np.where(thing, r.groups, -1), inst), 0).astype(np.int32)
    return r.labels, inst


# ----------------------------------------------------------------------------- measures
@dataclass
class PanopticVoxels:
    """Voxels of a panoptic map: sorted packed keys, majority class, instance, segment id.

    ``segment`` is ``class << 32 | instance`` for things with an instance, ``class << 32`` for
    stuff, -1 for void and for things without an instance.
    """

    keys: np.ndarray
    labels: np.ndarray
    instances: np.ndarray
    segment: np.ndarray


def panoptic_voxels(
    m: SemanticMap | str | os.PathLike, voxel_size: float = 0.05, *, grid_origin=None
) -> PanopticVoxels:
    """Voxelise a panoptic map: majority class per voxel (ties: smallest id), then the
    majority instance among the voxel's points of that class (ties: smaller id).

    Raises
    ------
    ValueError
        The map has no instance layer, is empty, or ``voxel_size`` is not positive.
    """
    if isinstance(m, str | os.PathLike):
        m = read_map(m)
    require_instances(m.check(), "panoptic measures")
    if not (np.isfinite(voxel_size) and voxel_size > 0):
        raise ValueError(f"voxel_size must be > 0 (metres), got {voxel_size}")
    origin = None if grid_origin is None else np.broadcast_to(np.asarray(grid_origin, dtype=np.float64), (3,))
    packed = pack_keys(voxel_keys(m.points, voxel_size, origin))
    keys, inv = np.unique(packed, return_inverse=True)
    counts = np.bincount(inv * NUM_CLASSES + m.labels, minlength=len(keys) * NUM_CLASSES)
    labels = counts.reshape(len(keys), NUM_CLASSES).argmax(axis=1).astype(np.uint8)
    inst = np.zeros(len(keys), np.int32)
    sel = np.flatnonzero((m.instances > 0) & (m.labels == labels[inv]) & _THINGS[m.labels])
    if len(sel):
        inst = _group_majority(inv[sel].astype(np.int64), m.instances[sel])
        full = np.zeros(len(keys), np.int32)
        full[inv[sel]] = inst
        # _group_majority gives every point its voxel's winner; any point of a voxel carries it
        inst = full
    seg = np.full(len(keys), -1, np.int64)
    stuff = np.isin(labels, STUFF_CLASSES)
    seg[stuff] = labels[stuff].astype(np.int64) << 32
    thing = _THINGS[labels] & (inst > 0)
    seg[thing] = (labels[thing].astype(np.int64) << 32) | inst[thing]
    return PanopticVoxels(keys, labels, inst, seg)


def panoptic_quality(
    gt_map: SemanticMap | str | os.PathLike | PanopticVoxels,
    pred_map: SemanticMap | str | os.PathLike | PanopticVoxels,
    voxel_size: float = 0.05,
    *,
    grid_origin=None,
    iou_threshold: float = 0.5,
) -> dict:
    """Panoptic quality of a predicted panoptic map against ground truth, on voxels.

    Parameters
    ----------
    gt_map, pred_map : SemanticMap with instances, PLY path, or PanopticVoxels
    voxel_size : float
        Voxel edge (metres).
    grid_origin : float or (3,), optional
        Corner of voxel (0, 0, 0), as :func:`semmatch.evaluate.metrics.voxelize`.
    iou_threshold : float
        Matching threshold (0.5: matches are unique).

    Returns
    -------
    dict
        ``pq``, ``sq``, ``rq`` (means over the classes with a segment in either map; SQ over
        those with a match, as it is undefined without one),
        ``pq_things``/``sq_things``/``rq_things`` and ``pq_stuff``/``sq_stuff``/``rq_stuff``,
        and ``per_class``: ``{name: {pq, sq, rq, tp, fp, fn}}``. Means over an empty class
        set are NaN.
    """
    if not 0.0 <= iou_threshold < 1.0:
        raise ValueError(f"iou_threshold must lie in [0, 1), got {iou_threshold}")
    g = gt_map if isinstance(gt_map, PanopticVoxels) else panoptic_voxels(gt_map, voxel_size, grid_origin=grid_origin)
    p = pred_map if isinstance(pred_map, PanopticVoxels) else panoptic_voxels(pred_map, voxel_size, grid_origin=grid_origin)
    # where each predicted voxel falls in the ground truth
    pos = np.searchsorted(g.keys, p.keys)
    pos_c = np.minimum(pos, max(len(g.keys) - 1, 0))
    in_gt = (pos < len(g.keys)) & (g.keys[pos_c] == p.keys) if len(g.keys) else np.zeros(len(p.keys), bool)
    g_seg_at_p = np.where(in_gt, g.segment[pos_c] if len(g.keys) else -1, -2)  # -2: not in gt
    on_void = g_seg_at_p == -1
    pred_has = p.segment >= 0
    # areas: ground truth segments; predicted segments without their gt-void voxels
    g_ids, g_area = np.unique(g.segment[g.segment >= 0], return_counts=True)
    p_ids, p_total = np.unique(p.segment[pred_has], return_counts=True)
    p_void = np.zeros(len(p_ids), np.int64)
    if len(p_ids):
        vi, vc = np.unique(p.segment[pred_has & on_void], return_counts=True)
        p_void[np.searchsorted(p_ids, vi)] = vc
    p_area = p_total - p_void
    both = pred_has & (g_seg_at_p >= 0)
    pairs, inter = np.unique(np.stack([g_seg_at_p[both], p.segment[both]], axis=1), axis=0, return_counts=True) \
        if both.any() else (np.zeros((0, 2), np.int64), np.zeros(0, np.int64))
    ga = g_area[np.searchsorted(g_ids, pairs[:, 0])] if len(pairs) else np.zeros(0)
    pa = p_area[np.searchsorted(p_ids, pairs[:, 1])] if len(pairs) else np.zeros(0)
    iou = inter / np.maximum(ga + pa - inter, 1)
    match = (iou > iou_threshold) & ((pairs[:, 0] >> 32) == (pairs[:, 1] >> 32))
    m_g, m_p, m_iou = pairs[match, 0], pairs[match, 1], iou[match]
    # a predicted segment mostly on ignored ground truth is no false positive
    ignored = p_void > 0.5 * p_total
    per_class = {}
    for c in range(1, NUM_CLASSES):
        g_c = g_ids[(g_ids >> 32) == c]
        p_sel = (p_ids >> 32) == c
        tp_iou = m_iou[(m_g >> 32) == c]
        tp = len(tp_iou)
        fn = len(g_c) - tp
        matched_p = np.isin(p_ids, m_p)
        fp = int((p_sel & ~matched_p & ~ignored).sum())
        if tp + fp + fn == 0:
            continue
        sq = float(tp_iou.mean()) if tp else float("nan")  # no match: SQ undefined, PQ 0
        rq = tp / (tp + 0.5 * fp + 0.5 * fn)
        per_class[NAMES[c]] = {"pq": sq * rq if tp else 0.0, "sq": sq, "rq": rq, "tp": tp, "fp": fp, "fn": fn,
                               "class": c}
    out: dict = {"per_class": per_class}
    for suffix, classes in (("", range(1, NUM_CLASSES)), ("_things", THING_CLASSES), ("_stuff", STUFF_CLASSES)):
        rows = [v for v in per_class.values() if v["class"] in classes]
        for k in ("pq", "sq", "rq"):
            vals = [r[k] for r in rows if not np.isnan(r[k])]
            out[k + suffix] = float(np.mean(vals)) if vals else float("nan")
    return out
