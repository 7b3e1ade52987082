"""The paper's benchmark measures on semantic voxel grids, and 2D pixel measures.

Both maps are voxelised (``key = floor(xyz / voxel_size)``); a voxel's label is the majority
label of the points in it (ties: the smallest id). With

* ``G``: ground-truth voxels whose label is an evaluation class (1..10),
* ``P``: predicted voxels whose label is an evaluation class,
* ``O``: all occupied ground-truth voxels (any label),
* ``C``: voxels of ``G ∩ P`` with equal labels (the *colour intersection*),

the measures are (docs/metrics.md, as the authors' evaluator computes them)::

    jaccard   = |C| / (|G| + |P \\ O|)        union="restrict" (default)
              = |C| / |G ∪ P|                union="plain"
    sorensen  = 2 |C| / (|G| + |P|)
    color_acc = |C| / |G ∩ P|
    mean_acc  = (jaccard + sorensen + color_acc) / 3

A ratio whose denominator is 0 is reported as 0.0. Per-class IoU and the confusion matrix are
computed over ``G ∩ P`` (rows: ground truth, columns: prediction, classes 1..10).

Everything is vectorised NumPy: voxel keys are packed into one int64
(:func:`semmatch.io.geometry.pack_keys`), the majority comes from one ``np.unique`` and a
``bincount`` over (voxel, label) pairs, set operations are sorted-array intersections.
:func:`compare_dict_loop` is the plain per-point Python dictionary version of the authors'
evaluator, kept only as the speed and correctness reference of ``semmatch bench metrics``.
"""

from __future__ import annotations

import math
import os
import warnings
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ..io import SemanticMap, read_map
from ..io.geometry import longest_edges, pack_keys, sample_mesh, transform, voxel_keys
from ..io.labels import EVAL_CLASSES, NAMES, NUM_CLASSES

__all__ = [
    "VoxelGrid",
    "voxelize",
    "compare",
    "compare_dict_loop",
    "pixel_confusion",
    "pixel_metrics",
    "class_iou",
    "MEASURES",
]

#: the four headline measures, in table order
MEASURES = ("jaccard", "sorensen", "color_acc", "mean_acc")

_EVAL = np.asarray(EVAL_CLASSES, dtype=np.int64)


@dataclass
class VoxelGrid:
    """A semantic voxel grid: sorted packed voxel keys and their majority labels.

    Attributes
    ----------
    keys : int64 (V,)
        Packed voxel coordinates, sorted ascending, unique.
    labels : uint8 (V,)
        Majority label of each voxel (ties: smallest id).
    voxel_size : float
    source : str
    """

    keys: np.ndarray
    labels: np.ndarray
    voxel_size: float
    source: str = "<memory>"

    def __len__(self) -> int:
        return len(self.keys)


def _as_map(m: SemanticMap | str | os.PathLike, what: str) -> SemanticMap:
    if isinstance(m, str | os.PathLike):
        m = read_map(m)
    if not isinstance(m, SemanticMap):
        raise TypeError(f"{what}: expected a SemanticMap or a PLY path, got {type(m).__name__}")
    if len(m.points) == 0 or not np.isfinite(m.points).all():
        m.check()  # raises with the file name and the number of bad vertices
    return m


def voxelize(
    m: SemanticMap | str | os.PathLike,
    voxel_size: float = 0.05,
    *,
    transform_matrix: np.ndarray | None = None,
    densify: bool = True,
    grid_origin: float | np.ndarray | None = None,
) -> VoxelGrid:
    """Voxelise a semantic map: majority label per voxel (ties: smallest id).

    Parameters
    ----------
    m : SemanticMap or path
        Points or mesh vertices with labels (a PLY path is read with :func:`semmatch.io.read_map`).
    voxel_size : float
        Voxel edge, metres.
    transform_matrix : (4, 4), optional
        Rigid transform applied to the points first.
    densify : bool
        For meshes: triangles whose longest edge exceeds two voxels (coarse meshes such as the
        simulator's ``scene.ply``, whose vertices alone leave most voxels of a wall empty) are
        sampled at half-voxel spacing; samples take the triangle's majority vertex label.
        Dense meshes (TSDF reconstructions) are unaffected.
    grid_origin : float or (3,), optional
        Corner of voxel ``(0, 0, 0)`` (metres; default the world origin): keys are
        ``floor((xyz - grid_origin) / voxel_size)``. Grids compared with each other must share it.

    Returns
    -------
    VoxelGrid

    Raises
    ------
    ValueError
        Empty map, NaN/inf vertices, non-positive voxel size.
    """
    if not (np.isfinite(voxel_size) and voxel_size > 0):
        raise ValueError(f"voxel_size must be > 0 (metres), got {voxel_size}")
    m = _as_map(m, "map")
    pts, labels = m.points, m.labels
    if densify and m.is_mesh:
        extra_p, extra_l = _densify(m, 2.0 * voxel_size, 0.5 * voxel_size)
        if len(extra_p):
            pts = np.concatenate([pts, extra_p])
            labels = np.concatenate([labels, extra_l])
    if transform_matrix is not None:
        from ..io.geometry import check_pose

        pts = transform(pts.astype(np.float64), check_pose(transform_matrix, what="transform"))
    origin = None if grid_origin is None else np.broadcast_to(np.asarray(grid_origin, dtype=np.float64), (3,))
    vk = voxel_keys(pts, voxel_size, origin)
    keys, labels = _majority(vk, labels)
    try:
        packed = pack_keys(keys)
    except ValueError:
        raise ValueError(
            f"{m.source}: coordinates too large for {voxel_size} m voxels (|xyz| up to "
            f"{np.abs(pts).max():.3g}); is the map in metres?"
        ) from None
    return VoxelGrid(packed, labels, float(voxel_size), m.source)


def _densify(m: SemanticMap, max_edge: float, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Surface samples (barycentric grid, ``spacing`` apart) of the triangles longer than ``max_edge``;
    a sample takes its triangle's majority label (:func:`semmatch.io.geometry.sample_mesh`)."""
    big = np.flatnonzero(longest_edges(m.points, m.faces) > max_edge)
    if big.size == 0:
        return np.zeros((0, 3), np.float32), np.zeros(0, np.uint8)
    return sample_mesh(m.points, m.faces[big], m.labels, spacing, label="triangle", form="edges", source=m.source)


def _majority(vk: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique voxel coordinates (V,3) in lexicographic order and their majority labels.

    One sort of (voxel, label) pairs packed into int64; the majority with ties to the smallest
    id is the maximum of ``count * 32 + (31 - label)`` over each voxel's run.
    """
    lo = vk.min(axis=0)
    k = vk - lo
    bits = [max(int(v).bit_length(), 1) for v in k.max(axis=0)]
    if sum(bits) + 5 > 62:
        raise ValueError(f"the map spans too many voxels ({k.max(axis=0) + 1}); is it in metres?")
    sy, sx = bits[2], bits[1] + bits[2]
    loc = (k[:, 0] << sx) | (k[:, 1] << sy) | k[:, 2]
    pair, counts = np.unique((loc << 5) | labels.astype(np.int64), return_counts=True)
    vox = pair >> 5
    start = np.flatnonzero(np.r_[True, vox[1:] != vox[:-1]])
    score = (counts << 5) | (31 - (pair & 31))
    best = np.maximum.reduceat(score, start)
    lab = (31 - (best & 31)).astype(np.uint8)
    v = vox[start]
    coords = np.stack([v >> sx, (v >> sy) & ((1 << bits[1]) - 1), v & ((1 << bits[2]) - 1)], axis=1) + lo
    return coords, lab


def _member(a: np.ndarray, sorted_b: np.ndarray) -> np.ndarray:
    """``np.isin(a, sorted_b)`` for a sorted unique ``sorted_b`` (binary search)."""
    if len(sorted_b) == 0:
        return np.zeros(len(a), dtype=bool)
    pos = np.searchsorted(sorted_b, a)
    pos[pos == len(sorted_b)] = 0
    return sorted_b[pos] == a


def _ratio(a: float, b: float) -> float:
    return float(a) / float(b) if b else 0.0


def compare(
    gt_map: SemanticMap | str | os.PathLike | VoxelGrid,
    pred_map: SemanticMap | str | os.PathLike | VoxelGrid,
    voxel_size: float = 0.05,
    *,
    transform: np.ndarray | None = None,
    union: str = "restrict",
    min_overlap: float = 0.1,
    densify: bool = True,
    grid_origin: float | np.ndarray | None = None,
) -> dict:
    """Compare a predicted semantic map with ground truth, exactly as docs/metrics.md.

    Parameters
    ----------
    gt_map, pred_map : SemanticMap, PLY path or VoxelGrid
        Ground truth and prediction (meshes or point clouds with labels or palette colours).
    voxel_size : float
        Voxel edge in metres (default 5 cm, as the paper).
    transform : (4, 4), optional
        Rigid transform taking the prediction into the ground-truth frame.
    union : {"restrict", "plain"}
        Jaccard denominator: ``|G| + |P \\ O|`` (the authors' evaluator) or ``|G ∪ P|``.
    min_overlap : float
        Refuse the comparison when the occupied voxels overlap less than this:
        ``|O ∩ P_all| / min(|O|, |P_all|)`` (``P_all``: all occupied predicted voxels). Maps
        in different units or frames overlap next to nothing. 0 disables the check.
    densify : bool
        Sample coarse mesh triangles (see :func:`voxelize`).
    grid_origin : float or (3,), optional
        Corner of voxel ``(0, 0, 0)`` for both maps (see :func:`voxelize`); e.g. half a voxel
        when the scene's surfaces lie on multiples of the voxel size, where a sub-centimetre
        offset of a reconstruction would split a surface between two voxel layers.

    Returns
    -------
    dict
        ``jaccard, sorensen, color_acc, mean_acc`` (floats), ``per_class_iou``
        (dict class name -> IoU over ``G ∩ P``, NaN for a class absent from both),
        ``confusion`` (10x10 int64, rows = ground truth 1..10, columns = prediction),
        ``classes`` (the ids of the rows), ``counts`` (dict: ``gt`` |G|, ``pred`` |P|,
        ``gt_occupied`` |O|, ``pred_occupied``, ``intersection`` |G ∩ P|, ``color`` |C|,
        ``pred_outside_gt`` |P \\ O|, ``union`` (the Jaccard denominator)),
        ``overlap`` (the occupancy overlap above), ``voxel_size``, ``union_mode``.

    Raises
    ------
    ValueError
        Empty map, NaN vertices, unknown ``union``, overlap below ``min_overlap`` (the message
        gives the numbers and both files).

    Examples
    --------
    >>> s = compare("scene.ply", "lower_3d-neighborhood.ply")      # doctest: +SKIP
    >>> round(s["mean_acc"], 3)
    """
    if union not in ("restrict", "plain"):
        raise ValueError(f"union must be 'restrict' or 'plain', got {union!r}")
    g = (gt_map if isinstance(gt_map, VoxelGrid)
         else voxelize(gt_map, voxel_size, densify=densify, grid_origin=grid_origin))
    p = (
        pred_map
        if isinstance(pred_map, VoxelGrid)
        else voxelize(pred_map, voxel_size, transform_matrix=transform, densify=densify, grid_origin=grid_origin)
    )
    if isinstance(gt_map, VoxelGrid) or isinstance(pred_map, VoxelGrid):
        if not np.isclose(g.voxel_size, p.voxel_size):
            raise ValueError(f"voxel grids of {g.voxel_size} m and {p.voxel_size} m cannot be compared")
    # occupancy overlap (any label): different units or frames give ~0
    n_both_occ = int(_member(p.keys, g.keys).sum())
    overlap = _ratio(n_both_occ, min(len(g), len(p)))
    if overlap < min_overlap:
        raise ValueError(
            f"{p.source} vs {g.source}: only {n_both_occ} of min({len(g)}, {len(p)}) occupied "
            f"voxels overlap ({overlap:.1%} < {min_overlap:.0%}) at {g.voxel_size} m voxels; the maps "
            "are probably in different units or frames (pass transform=..., or min_overlap=0 to "
            "compare anyway)"
        )
    g_eval = np.isin(g.labels, _EVAL)
    p_eval = np.isin(p.labels, _EVAL)
    gk, gl = g.keys[g_eval], g.labels[g_eval]
    pk, pl = p.keys[p_eval], p.labels[p_eval]
    in_g = _member(pk, gk)
    pos = np.searchsorted(gk, pk[in_g])
    a, b = gl[pos].astype(np.int64), pl[in_g].astype(np.int64)
    n_color = int((a == b).sum())
    n_inter = len(a)
    n_g, n_p = len(gk), len(pk)
    # P \ O: predicted evaluation voxels where the ground truth has no voxel at all
    n_p_outside = int((~_member(pk, g.keys)).sum())
    denom = n_g + n_p_outside if union == "restrict" else n_g + n_p - n_inter
    jac = _ratio(n_color, denom)
    sor = _ratio(2 * n_color, n_g + n_p)
    cacc = _ratio(n_color, n_inter)
    k = len(EVAL_CLASSES)
    conf = np.bincount((a - 1) * k + (b - 1), minlength=k * k).reshape(k, k)
    tp = np.diag(conf).astype(np.float64)
    den = conf.sum(0) + conf.sum(1) - tp
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = np.where(den > 0, tp / den, np.nan)
    return {
        "jaccard": jac,
        "sorensen": sor,
        "color_acc": cacc,
        "mean_acc": (jac + sor + cacc) / 3.0,
        "per_class_iou": {NAMES[c]: float(v) for c, v in zip(EVAL_CLASSES, iou)},
        "confusion": conf,
        "classes": list(EVAL_CLASSES),
        "counts": {
            "gt": n_g,
            "pred": n_p,
            "gt_occupied": len(g),
            "pred_occupied": len(p),
            "intersection": n_inter,
            "color": n_color,
            "pred_outside_gt": n_p_outside,
            "union": int(denom),
        },
        "overlap": overlap,
        "voxel_size": float(g.voxel_size),
        "union_mode": union,
    }


def compare_dict_loop(
    gt_map: SemanticMap, pred_map: SemanticMap, voxel_size: float = 0.05, *, union: str = "restrict"
) -> dict:
    """The authors'-style evaluator: per-point Python dictionaries (reference, slow).

    Same measures as :func:`compare` (``jaccard, sorensen, color_acc, mean_acc`` only), used by
    ``semmatch bench metrics`` for the speed comparison and by the tests as an independent check.
    """

    def grid(m: SemanticMap) -> dict:
        votes: dict[tuple[int, int, int], Counter] = {}
        for (x, y, z), lab in zip(m.points.tolist(), m.labels.tolist()):
            key = (math.floor(x / voxel_size), math.floor(y / voxel_size), math.floor(z / voxel_size))
            votes.setdefault(key, Counter())[lab] += 1
        out = {}
        for key, c in votes.items():
            best = max(c.values())
            out[key] = min(lab for lab, n in c.items() if n == best)
        return out

    eval_set = set(EVAL_CLASSES)
    g, p = grid(gt_map), grid(pred_map)
    G = {k: v for k, v in g.items() if v in eval_set}
    P = {k: v for k, v in p.items() if v in eval_set}
    inter = [k for k in P if k in G]
    color = sum(1 for k in inter if G[k] == P[k])
    outside = sum(1 for k in P if k not in g)
    denom = len(G) + outside if union == "restrict" else len(G) + len(P) - len(inter)
    jac = _ratio(color, denom)
    sor = _ratio(2 * color, len(G) + len(P))
    cacc = _ratio(color, len(inter))
    return {"jaccard": jac, "sorensen": sor, "color_acc": cacc, "mean_acc": (jac + sor + cacc) / 3.0}


# ----------------------------------------------------------------------------- 2D measures
def pixel_confusion(
    gt_labels: np.ndarray | Iterable[np.ndarray],
    pred_labels: np.ndarray | Iterable[np.ndarray],
    *,
    n_classes: int = NUM_CLASSES,
) -> np.ndarray:
    """Pixel confusion matrix ``(n_classes, n_classes)`` (rows: ground truth), int64.

    Accepts one label image pair, stacks ``(N,H,W)`` or iterables of images (accumulated).
    """
    if isinstance(gt_labels, np.ndarray) and gt_labels.ndim in (2, 3):
        gt_iter, pred_iter = [gt_labels], [np.asarray(pred_labels)]
    else:
        gt_iter, pred_iter = gt_labels, pred_labels
    conf = np.zeros((n_classes, n_classes), dtype=np.int64)
    n = 0
    for i, (g, p) in enumerate(zip(gt_iter, pred_iter, strict=True)):
        g = np.asarray(g)
        p = np.asarray(p)
        if g.shape != p.shape:
            raise ValueError(f"image {i}: ground truth is {g.shape}, prediction is {p.shape}")
        for what, arr in (("ground truth", g), ("prediction", p)):
            if arr.size and (arr.min() < 0 or arr.max() >= n_classes):
                raise ValueError(f"image {i}: {what} label outside 0..{n_classes - 1}")
        conf += np.bincount(
            g.reshape(-1).astype(np.int64) * n_classes + p.reshape(-1), minlength=n_classes * n_classes
        ).reshape(n_classes, n_classes)
        n += 1
    if n == 0:
        raise ValueError("pixel_confusion: no images")
    return conf


def class_iou(conf: np.ndarray, classes: Iterable[int]) -> np.ndarray:
    """Intersection over union of each class from a confusion matrix (rows: ground truth).

    Parameters
    ----------
    conf : (C, C) array
        Counts, e.g. :func:`pixel_confusion`.
    classes : iterable of int
        The classes to score.

    Returns
    -------
    float64 array
        ``tp / (ground truth + predicted - tp)`` per class; NaN where the class is absent from
        both.
    """
    cls = np.asarray(list(classes), dtype=np.int64)
    conf = np.asarray(conf)
    tp = conf[cls, cls].astype(np.float64)
    den = conf[cls].sum(1) + conf[:, cls].sum(0) - tp
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, tp / den, np.nan)


def pixel_metrics(
    gt_labels: np.ndarray | Iterable[np.ndarray],
    pred_labels: np.ndarray | Iterable[np.ndarray],
    *,
    classes: Iterable[int] = EVAL_CLASSES,
    ignore: int | None = 0,
) -> dict:
    """Per-frame (or accumulated) pixel accuracy and mean IoU.

    Parameters
    ----------
    gt_labels, pred_labels : (H, W) uint8, (N, H, W), or iterables of images
    classes : iterable of int
        Classes averaged by mIoU (default: evaluation classes 1..10); classes absent from both
        ground truth and prediction do not count.
    ignore : int or None
        Ground-truth label whose pixels are skipped (default 0 = void).

    Returns
    -------
    dict
        ``pixel_acc`` (correct / counted pixels, over ground-truth pixels of ``classes``),
        ``miou``, ``per_class_iou`` (name -> IoU or NaN), ``confusion`` (full 21x21 int64),
        ``n_pixels`` (counted).
    """
    conf = pixel_confusion(gt_labels, pred_labels)
    if ignore is not None:
        conf[ignore, :] = 0
    cls = np.asarray(list(classes), dtype=np.int64)
    rows = conf[cls]
    n_pix = int(rows.sum())
    correct = int(conf[cls, cls].sum())
    iou = class_iou(conf, cls)
    if n_pix == 0:
        warnings.warn("pixel_metrics: no ground-truth pixel of the evaluated classes", stacklevel=2)
    return {
        "pixel_acc": _ratio(correct, n_pix),
        "miou": float(np.nanmean(iou)) if np.isfinite(iou).any() else 0.0,
        "per_class_iou": {NAMES[c]: float(v) for c, v in zip(cls, iou)},
        "confusion": conf,
        "n_pixels": n_pix,
    }
