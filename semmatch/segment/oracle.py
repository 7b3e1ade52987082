"""Ground-truth oracle segmenters for ablations: perfect, and noisy with a controlled error rate.

The noisy oracle corrupts whole superpixels (SLIC on the RGB image, scikit-image) rather than
single pixels, so that its errors look like a network's: coherent blobs labelled as a
*plausible* other class (a picture read as wall, a sofa as chair...; :data:`CONFUSIONS`). The
fraction of wrong labels among the non-void pixels equals the requested ``error_rate`` up to
one pixel: whole superpixels are flipped in random order and the last one only partly.
"""

from __future__ import annotations

import numpy as np

from ..io import Frame
from ..io.labels import NUM_CLASSES, VOID, id_of

__all__ = ["CONFUSIONS", "OracleSegmenter", "NoisyOracle", "noisy_labels", "one_hot"]

#: plausible confusions, by category name: what a network mistakes each class for
_CONFUSION_NAMES: dict[str, tuple[str, ...]] = {
    "wall": ("ceiling", "picture", "window", "cabinet"),
    "floor": ("wall", "table"),
    "ceiling": ("wall",),
    "chair": ("sofa", "table"),
    "table": ("cabinet", "chair", "floor"),
    "window": ("curtain", "wall", "picture"),
    "curtain": ("window", "wall"),
    "picture": ("wall", "window", "monitor"),
    "bed": ("sofa", "pillow"),
    "sofa": ("chair", "bed", "pillow"),
    "pillow": ("sofa", "bed"),
    "monitor": ("picture", "object"),
    "sink": ("cabinet", "bathtub"),
    "trashcan": ("object", "cabinet"),
    "toilet": ("sink", "bathtub"),
    "refrigerator": ("cabinet", "wall"),
    "oven": ("cabinet",),
    "bathtub": ("floor", "sink"),
    "cabinet": ("table", "refrigerator", "wall"),
    "object": ("table", "cabinet"),
}

#: ``CONFUSIONS[c]``: tuple of category ids class ``c`` may be mistaken for (never ``c`` or void)
CONFUSIONS: dict[int, tuple[int, ...]] = {
    id_of(k): tuple(id_of(v) for v in vs) for k, vs in _CONFUSION_NAMES.items()
}
_MAXC = max(len(v) for v in CONFUSIONS.values())
_TABLE = np.zeros((NUM_CLASSES, _MAXC), np.int64)
_COUNT = np.ones(NUM_CLASSES, np.int64)
for _c, _vs in CONFUSIONS.items():
    _TABLE[_c, : len(_vs)] = _vs
    _COUNT[_c] = len(_vs)


def one_hot(labels: np.ndarray, num_classes: int = NUM_CLASSES) -> np.ndarray:
    """``(H,W)`` category ids -> ``(H,W,num_classes)`` float32 probabilities (void pixels: void)."""
    lab = np.asarray(labels)
    if lab.ndim != 2:
        raise ValueError(f"labels: expected an (H,W) image, got shape {lab.shape}")
    if lab.size and (lab.min() < 0 or lab.max() >= num_classes):
        raise ValueError(f"labels: ids must lie in 0..{num_classes - 1}")
    return np.eye(num_classes, dtype=np.float32)[lab.astype(np.intp)]


def noisy_labels(
    labels: np.ndarray,
    error_rate: float,
    *,
    rgb: np.ndarray | None = None,
    seed: int | np.random.Generator = 0,
    n_segments: int = 300,
) -> np.ndarray:
    """Corrupt a ground-truth label image with plausible, blob-shaped errors.

    Parameters
    ----------
    labels : uint8 (H,W)
        Ground-truth category ids (0 = void, never changed nor counted).
    error_rate : float in [0, 1]
        Fraction of the non-void pixels that come back wrong.
    rgb : uint8 (H,W,3), optional
        Image the superpixels are computed on (SLIC); without it a label-aware regular grid
        of blocks is used.
    seed : int or numpy Generator
        Repeatable randomness.
    n_segments : int
        Approximate number of superpixels.

    Returns
    -------
    uint8 (H,W)
        Labels where exactly ``round(error_rate * n_non_void)`` pixels differ from ``labels``,
        each relabelled as one of :data:`CONFUSIONS` of its true class.

    Raises
    ------
    ValueError
        ``error_rate`` outside [0, 1], labels not (H,W) ids, ``rgb`` of another size.
    """
    from skimage.segmentation import slic

    lab = np.asarray(labels)
    if lab.ndim != 2 or not np.issubdtype(lab.dtype, np.integer):
        raise ValueError(f"labels: expected integer (H,W) ids, got {lab.dtype} {lab.shape}")
    if lab.size and (lab.min() < 0 or lab.max() >= NUM_CLASSES):
        raise ValueError(f"labels: ids must lie in 0..{NUM_CLASSES - 1}")
    if not 0.0 <= float(error_rate) <= 1.0:
        raise ValueError(f"error_rate must lie in [0, 1], got {error_rate}")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    H, W = lab.shape
    if rgb is not None:
        rgb = np.asarray(rgb)
        if rgb.shape != (H, W, 3):
            raise ValueError(f"rgb: shape {rgb.shape} does not match labels {lab.shape}")
        seg = slic(rgb, n_segments=n_segments, compactness=10.0, start_label=0)
    else:
        step = max(2, int(np.sqrt(H * W / max(n_segments, 1))))
        yy, xx = np.mgrid[0:H, 0:W]
        seg = (yy // step) * (W // step + 1) + xx // step
    # split superpixels by true class, so each blob takes one confusion per class
    seg = seg.astype(np.int64) * NUM_CLASSES + lab
    flat_seg = seg.reshape(-1)
    valid = lab.reshape(-1) != VOID
    n_valid = int(valid.sum())
    target = int(round(float(error_rate) * n_valid))
    out = lab.astype(np.uint8).copy().reshape(-1)
    if target == 0:
        return out.reshape(H, W)
    ids, inverse = np.unique(flat_seg[valid], return_inverse=True)
    sizes = np.bincount(inverse)
    order = rng.permutation(len(ids))
    cum = np.cumsum(sizes[order])
    k = int(np.searchsorted(cum, target))  # segments order[:k] flipped whole, order[k] partly
    flip = np.zeros(len(ids), dtype=np.int64)  # pixels to flip per segment
    flip[order[:k]] = sizes[order[:k]]
    if k < len(ids):
        flip[order[k]] = target - (cum[k - 1] if k > 0 else 0)
    cls = ids % NUM_CLASSES
    pick = rng.integers(0, 1 << 30, len(ids)) % _COUNT[cls]
    new_cls = _TABLE[cls, pick]
    # within a segment flip its first `flip` pixels in raster order (a contiguous-ish part)
    vidx = np.nonzero(valid)[0]
    order_px = np.argsort(inverse, kind="stable")
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    rank = np.empty(len(inverse), np.int64)
    rank[order_px] = np.arange(len(inverse)) - np.repeat(starts, sizes)
    sel = rank < flip[inverse]
    out[vidx[sel]] = new_cls[inverse[sel]]
    return out.reshape(H, W)


class OracleSegmenter:
    """The ground truth as a segmenter: ``predict_frame(frame)`` -> one-hot of ``frame.labels``."""

    name = "oracle"

    def predict_labels_frame(self, frame: Frame) -> np.ndarray:
        """The frame's ground-truth labels (uint8 (H,W))."""
        if frame.labels is None:
            raise ValueError(f"frame {frame.index}: the oracle needs ground-truth labels, the frame has none")
        return np.asarray(frame.labels, dtype=np.uint8)

    def predict_frame(self, frame: Frame) -> np.ndarray:
        """One-hot probabilities ``(H,W,21)`` float32 of the frame's (possibly corrupted) labels."""
        return one_hot(self.predict_labels_frame(frame))


class NoisyOracle(OracleSegmenter):
    """Ground truth with a controlled fraction of plausible, blob-shaped errors.

    Parameters
    ----------
    error_rate : float in [0, 1]
        Fraction of non-void pixels of every frame that come back wrong.
    seed : int
        Frame ``i`` uses the seed ``(seed, i)``: repeatable and independent of call order.
    n_segments : int
        Superpixels per frame (smaller blobs: more).
    """

    def __init__(self, error_rate: float, *, seed: int = 0, n_segments: int = 300) -> None:
        if not 0.0 <= float(error_rate) <= 1.0:
            raise ValueError(f"error_rate must lie in [0, 1], got {error_rate}")
        self.error_rate = float(error_rate)
        self.seed = int(seed)
        self.n_segments = int(n_segments)
        self.name = f"noisy-oracle-{self.error_rate:g}"

    def predict_labels_frame(self, frame: Frame) -> np.ndarray:
        """Corrupted ground-truth labels of the frame (see :func:`noisy_labels`)."""
        gt = super().predict_labels_frame(frame)
        rng = np.random.default_rng([self.seed, int(frame.index)])
        return noisy_labels(gt, self.error_rate, rgb=frame.rgb, seed=rng, n_segments=self.n_segments)
