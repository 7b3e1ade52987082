"""2D pixel scores of label images: confusion matrix, per-class IoU, mIoU over classes 1..10.

Kept inside :mod:`semmatch.segment` for validation during training and for the viewpoint
study. The 2D analogues of the paper's measures (docs/metrics.md) are computed over pixels:
G = ground-truth pixels of an evaluation class, P = predicted pixels of an evaluation class,
C = pixels in both with equal labels.
"""

from __future__ import annotations

import numpy as np

from ..evaluate.metrics import class_iou
from ..io.labels import EVAL_CLASSES, NUM_CLASSES, VOID

__all__ = ["confusion", "scores"]


def confusion(gt: np.ndarray, pred: np.ndarray, num_classes: int = NUM_CLASSES) -> np.ndarray:
    """Confusion matrix ``M[g, p]`` (int64, rows = ground truth) of label images.

    A thin alias of :func:`semmatch.evaluate.metrics.pixel_confusion` (one image pair or ``(N,H,W)``
    stacks).

    Raises
    ------
    ValueError
        If the shapes differ or a label lies outside ``0..num_classes-1``.
    """
    from ..evaluate.metrics import pixel_confusion

    return pixel_confusion(np.asarray(gt), np.asarray(pred), n_classes=num_classes)


def scores(conf: np.ndarray, classes: tuple[int, ...] = EVAL_CLASSES) -> dict:
    """Pixel measures of a confusion matrix, restricted to ``classes``.

    Parameters
    ----------
    conf : ndarray (C, C)
        From :func:`confusion`, rows = ground truth.
    classes : tuple of int
        Evaluation classes (default 1..10).

    Returns
    -------
    dict
        ``miou`` (mean IoU over the classes present in the ground truth or the prediction,
        as :func:`semmatch.evaluate.metrics.pixel_metrics`; ground-truth void is not scored), ``pixel_acc``
        (fraction of ground-truth evaluation pixels labelled correctly), ``jaccard``
        (|C| / |G u P|), ``sorensen`` (2|C| / (|G| + |P|)), ``color_acc`` (|C| / |G n P|),
        ``mean_acc`` (mean of the last three, as the paper's Mean Acc.) and ``per_class_iou``
        (dict class id -> IoU, NaN when absent from both).
    """
    conf = np.array(conf, dtype=np.float64)
    conf[VOID, :] = 0  # ground-truth void pixels (no geometry) are not scored
    cls = np.asarray(classes, dtype=np.intp)
    tp = conf[cls, cls]
    gt_n = conf[cls].sum(axis=1)
    pred_n = conf[:, cls].sum(axis=0)
    iou = class_iou(conf, cls)
    G = gt_n.sum()
    P = pred_n.sum()
    C = tp.sum()
    both = conf[np.ix_(cls, cls)].sum()  # pixels in G n P (any pair of evaluation labels)
    jac = C / (G + P - both) if G + P - both > 0 else np.nan
    sor = 2 * C / (G + P) if G + P > 0 else np.nan
    col = C / both if both > 0 else np.nan
    return {
        "miou": float(np.nanmean(iou)) if np.isfinite(iou).any() else float("nan"),
        "pixel_acc": float(C / G) if G > 0 else float("nan"),
        "jaccard": float(jac),
        "sorensen": float(sor),
        "color_acc": float(col),
        "mean_acc": float(np.nanmean([jac, sor, col])) if G + P > 0 else float("nan"),
        "per_class_iou": {int(c): float(v) for c, v in zip(cls, iou, strict=True)},
    }
