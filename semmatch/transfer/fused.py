"""``fused``: transferred labels where the map is confident, a network's prediction elsewhere."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..io.labels import NUM_CLASSES

__all__ = ["fuse_with_probabilities", "fuse_labels", "write_fused_labels"]


def fuse_with_probabilities(
    labels: np.ndarray,
    probs: np.ndarray,
    *,
    purity: np.ndarray | None = None,
    min_purity: float = 0.5,
) -> np.ndarray:
    """Combine transferred labels with per-pixel class probabilities of a network.

    A pixel keeps its transferred label when the map supports it (label > 0) and, when
    ``purity`` is given, its group's vote agreed at least ``min_purity``; every other pixel
    takes the network's most probable class. So coverage is 100% (wherever the network has an
    answer), the map decides where it is reliable, and the network fills what the map never
    saw from above.

    Parameters
    ----------
    labels : uint8 (H,W)
        Transferred labels, 0 = no support.
    probs : float (H,W,C)
        Class probabilities (or scores) with channel ``c`` = category id ``c``;
        ``C <= NUM_CLASSES``. Channel 0 (void) is ignored when C > 1.
    purity : float (H,W), optional
        Per-pixel agreement of the transferred label's group vote (``TransferResult.purity``).
    min_purity : float
        Below this agreement the network decides.

    Returns
    -------
    uint8 (H,W)

    Raises
    ------
    ValueError
        Shapes that do not match, more than ``NUM_CLASSES`` channels, NaN probabilities.
    """
    labels = np.asarray(labels)
    probs = np.asarray(probs)
    if probs.ndim != 3 or probs.shape[:2] != labels.shape:
        raise ValueError(f"probs must be (H,W,C) with (H,W) = {labels.shape}, got {probs.shape}")
    C = probs.shape[2]
    if not 1 <= C <= NUM_CLASSES:
        raise ValueError(f"probs have {C} channels; expected 1..{NUM_CLASSES} (channel = category id)")
    if not np.isfinite(probs).all():
        raise ValueError("probs hold NaN or inf")
    keep = labels > 0
    if purity is not None:
        purity = np.asarray(purity)
        if purity.shape != labels.shape:
            raise ValueError(f"purity is {purity.shape}, labels are {labels.shape}")
        keep &= purity >= min_purity
    out = np.where(keep, labels, 0).astype(np.uint8)
    if C > 1:
        # the network's class only where it decides: an argmax over a 21-channel image costs
        # more than the transfer itself, and the map keeps most pixels
        need = np.flatnonzero(~keep)
        if len(need):
            rows = probs.reshape(-1, C).take(need, axis=0)
            out.reshape(-1)[need] = np.argmax(rows[:, 1:], axis=1) + 1
    return out


def fuse_labels(transferred: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """Transferred labels where the map supports a pixel (label > 0), a prediction elsewhere.

    The evaluation protocol's ``fused`` rows: what a user deploys when the person's map does not
    cover everything the robot sees (:func:`fuse_with_probabilities` without probabilities or purity).

    Parameters
    ----------
    transferred : uint8 (H,W)
        Labels of a transfer method, 0 = no support.
    predicted : uint8 (H,W)
        The lower-view network's labels.

    Returns
    -------
    uint8 (H,W)

    Raises
    ------
    ValueError
        Shapes that differ.
    """
    transferred = np.asarray(transferred)
    predicted = np.asarray(predicted)
    if transferred.shape != predicted.shape or transferred.ndim != 2:
        raise ValueError(f"transferred labels {transferred.shape} and predictions {predicted.shape} must be "
                         f"(H,W) images of one size")
    return np.where(transferred > 0, transferred, predicted).astype(np.uint8)


def write_fused_labels(transferred: str | os.PathLike, predicted: str | os.PathLike,
                       out: str | os.PathLike) -> Path:
    """Write a labels folder of :func:`fuse_labels`, frame by frame, from two labels folders.

    Parameters
    ----------
    transferred, predicted : path
        Labels folders (``000000.png ...``) of a transfer method and of the lower-view network.
    out : path
        The ``fused`` labels folder (:func:`semmatch.io.write_labels_folder`).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        Folders with different numbers of frames (both named).
    """
    from ..io import read_label_image, read_labels_folder, write_labels_folder

    a, b = read_labels_folder(transferred), read_labels_folder(predicted)
    if len(a) != len(b):
        raise ValueError(f"{transferred} holds {len(a)} label images, {predicted} {len(b)}")
    return write_labels_folder(out, (fuse_labels(read_label_image(x), read_label_image(y)) for x, y in zip(a, b, strict=True)))
