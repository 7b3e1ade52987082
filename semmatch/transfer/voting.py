"""Shared voting helpers: per-group plurality of labels, painting groups back into images."""

from __future__ import annotations

import numpy as np

from ..io.labels import NUM_CLASSES

__all__ = ["vote", "paint"]


def vote(
    groups: np.ndarray, labels: np.ndarray, n_groups: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Plurality label of every group (superpixel, supervoxel, cluster).

    Every observation votes with its label; void (0) is a candidate like any other, so a group
    whose observations are mostly unsupported by the map stays void (the authors' mode of the
    projected labels). Ties: void wins a tie it is part of; otherwise the tied label observed
    first wins (so the result does not depend on how label ids are numbered). Entries with a
    negative group do not vote.

    Parameters
    ----------
    groups : int (N,)
        Group id of each observation (-1 = none).
    labels : uint8 (N,)
        Label of each observation (0 = no support in the map).
    n_groups : int, optional
        Number of groups (default ``groups.max() + 1``).

    Returns
    -------
    winner : uint8 (n_groups,)
        Plurality label; 0 for groups without votes.
    purity : float32 (n_groups,)
        Share of the group's votes that went to the winner (0 without votes).
    """
    g = np.asarray(groups, dtype=np.int64).reshape(-1)
    lab = np.asarray(labels).reshape(-1)
    if g.shape != lab.shape:
        raise ValueError(f"groups and labels differ in size: {g.shape} vs {lab.shape}")
    if n_groups is None:
        n_groups = int(g.max()) + 1 if g.size else 0
    keep = g >= 0
    if not keep.all():
        g, lab = g[keep], lab[keep]
    counts = np.bincount(g * NUM_CLASSES + lab.astype(np.int64), minlength=n_groups * NUM_CLASSES)
    counts = counts[: n_groups * NUM_CLASSES].reshape(n_groups, NUM_CLASSES)
    winner = counts.argmax(axis=1)
    best = counts[np.arange(n_groups), winner]
    tied = (counts == best[:, None]).sum(axis=1) > 1
    tied &= (counts[:, 0] < best) & (best > 0)
    if tied.any():
        sel = np.flatnonzero(tied[g])
        key = g[sel] * NUM_CLASSES + lab[sel].astype(np.int64)
        uniq, first = np.unique(key, return_index=True)
        order = np.full(n_groups * NUM_CLASSES, np.iinfo(np.int64).max)
        order[uniq] = first
        order = order.reshape(n_groups, NUM_CLASSES)
        cand = np.where(counts == best[:, None], order, np.iinfo(np.int64).max)
        winner = np.where(tied, cand.argmin(axis=1), winner)
    total = counts.sum(axis=1)
    purity = np.where(total > 0, counts[np.arange(n_groups), winner] / np.maximum(total, 1), 0.0)
    return winner.astype(np.uint8), purity.astype(np.float32)


def paint(groups: np.ndarray, values: np.ndarray, fill=0) -> np.ndarray:
    """Per-element ``values[groups]``, ``fill`` where the group is negative.

    With no groups at all (``values`` empty: e.g. a ``dbscan`` frame whose every point is
    clustering noise) every element gets ``fill``.
    """
    g = np.asarray(groups)
    values = np.asarray(values)
    if values.size == 0:
        if g.size and g.max() >= 0:
            raise IndexError(f"paint: group {int(g.max())} of no group values")
        return np.full(g.shape, fill, dtype=values.dtype)
    if g.size == 0 or g.min() >= 0:
        return values[g]
    out = values[np.maximum(g, 0)]
    out[g < 0] = fill
    return out
