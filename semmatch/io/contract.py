"""The frame contract: what a frame's arrays must be, checked in one place.

A frame (:class:`semmatch.io.Frame`) holds ``rgb`` uint8 (H,W,3), ``depth`` float metres (H,W)
(0, NaN, inf or a negative value: no measurement), ``labels`` category ids (H,W) (or, where a
labeling is fused, per-pixel class probabilities (H,W,C)) and its
:class:`~semmatch.io.geometry.Intrinsics`, whose ``shape`` is (H,W). Segmentation
(:mod:`semmatch.segment.predict`), label transfer (:func:`semmatch.transfer.frames.check_frame`)
and fusion (:meth:`semmatch.fusion.SemanticTSDF.integrate`) check their inputs with these
functions, so a frame is accepted or refused alike everywhere, with the same messages. Each
message starts with ``where``: what the array is (``"frame 3"``, ``"rgb[0]"``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .geometry import MAX_PIXELS, Intrinsics
from .images import check_depth_units

__all__ = ["check_intrinsics", "check_rgb", "check_depth", "check_labels", "MAX_FRAME_PIXELS"]

#: the largest frame semmatch reads or makes, in pixels (64 Mi, e.g. 8192 x 8192: beyond any RGB-D
#: camera); the same limit as :class:`~semmatch.io.geometry.Intrinsics`. Image files are measured
#: from their headers and refused above it before they are decoded (:func:`semmatch.io.images.image_size`).
MAX_FRAME_PIXELS = MAX_PIXELS


def _wxh(shape: tuple[int, ...]) -> str:
    return f"{shape[1]}x{shape[0]}" if len(shape) >= 2 else str(tuple(shape))


def check_intrinsics(intrinsics: Any, *, where: str = "frame") -> Intrinsics:
    """``intrinsics``, checked to be a :class:`~semmatch.io.geometry.Intrinsics`.

    Raises
    ------
    ValueError
        Anything else.
    """
    if not isinstance(intrinsics, Intrinsics):
        raise ValueError(f"{where}: intrinsics must be a semmatch.io.geometry.Intrinsics, got {type(intrinsics).__name__}")
    return intrinsics


def check_rgb(
    rgb: Any,
    shape: tuple[int, int] | None = None,
    *,
    where: str = "rgb",
    against: str = "the intrinsics say",
    floats: bool = False,
) -> np.ndarray:
    """An RGB image of the contract: uint8 (H,W,3), of size ``shape`` when given.

    Parameters
    ----------
    rgb : array or None
        The image (None: none; refused).
    shape : (H, W), optional
        The size it must have.
    where : str
        What the image is, for messages.
    against : str
        What ``shape`` comes from, for messages (``"the intrinsics say"``).
    floats : bool
        Also accept floating-point images with values in [0, 1] (segmentation's documented
        conversion).

    Returns
    -------
    ndarray
        ``rgb`` as an array (not copied).

    Raises
    ------
    ValueError
        No image, not (H,W,3), another size than ``shape``, another dtype, or (``floats``) a
        float image with NaN/inf or values outside [0, 1].
    """
    if rgb is None:
        raise ValueError(f"{where}: no RGB image; expected uint8 (H,W,3)")
    a = np.asarray(rgb)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"{where}: expected an (H,W,3) RGB image, got shape {a.shape}")
    if shape is not None and a.shape[:2] != tuple(shape):
        raise ValueError(f"{where}: RGB is {_wxh(a.shape)} (WxH) but {against} {_wxh(tuple(shape))}")
    if a.dtype == np.uint8:
        return a
    if floats and np.issubdtype(a.dtype, np.floating):
        if not np.isfinite(a).all():
            raise ValueError(f"{where}: holds NaN or inf")
        if a.size and (a.min() < 0.0 or a.max() > 1.0):
            raise ValueError(f"{where}: float images must lie in [0, 1], got {a.min():.3g}..{a.max():.3g}")
        return a
    allowed = "uint8 (or float in [0, 1])" if floats else "uint8"
    raise ValueError(f"{where}: expected {allowed} RGB, got dtype {a.dtype}")


def check_depth(
    depth: Any,
    shape: tuple[int, int],
    *,
    where: str = "depth",
    against: str = "the intrinsics say",
    units: bool = True,
) -> np.ndarray:
    """A depth image of the contract, with every "no measurement" value set to 0.

    Parameters
    ----------
    depth : array
        Float metres (H,W).
    shape : (H, W)
        The size it must have (the intrinsics', or the RGB image's).
    where : str
        What the image is, for messages.
    against : str
        What ``shape`` comes from, for messages (``"the intrinsics say"``, ``"the RGB image is"``).
    units : bool
        Check that the median valid depth is plausible in metres
        (:func:`semmatch.io.check_depth_units`): millimetres read as metres would silently
        find nothing.

    Returns
    -------
    float32 ndarray (H,W)
        Metres, 0 where there is no measurement (NaN, inf, <= 0); ``depth`` itself when it is
        float32 and clean already.

    Raises
    ------
    ValueError
        Another size than ``shape``, an integer dtype (convert with the recording's
        ``depth_scale`` first), a median depth outside the plausible range in metres.
    """
    d = np.asarray(depth)
    if d.shape != tuple(shape):
        raise ValueError(f"{where}: depth is {_wxh(d.shape)} (WxH) but {against} {_wxh(tuple(shape))}")
    if not np.issubdtype(d.dtype, np.floating):
        raise ValueError(f"{where}: depth must be float metres, got dtype {d.dtype} (divide by depth_scale first)")
    d = d.astype(np.float32, copy=False)
    if units:
        check_depth_units(d, where=where)
    valid = d > 0  # NaN compares False
    if np.isinf(d).any():
        valid &= np.isfinite(d)
    if not (valid | (d == 0)).all():
        d = np.where(valid, d, np.float32(0.0))
    return d


def check_labels(
    labels: Any,
    shape: tuple[int, int],
    *,
    n_classes: int,
    where: str = "labels",
    stride: int = 1,
) -> np.ndarray:
    """A frame's labels of the contract, at every ``stride``-th pixel (each direction).

    Parameters
    ----------
    labels : array
        Category ids (H,W) (integers, 0 = none) or class probabilities (H,W,``n_classes``).
    shape : (H, W)
        The frame's size.
    n_classes : int
        Number of categories (ids 0 .. n_classes - 1).
    where : str
        What the labels are, for messages.
    stride : int
        The pixels used (and checked): every ``stride``-th row and column.

    Returns
    -------
    ndarray
        The used pixels' ids (M,) or probabilities (M, n_classes), raster order.

    Raises
    ------
    ValueError
        Another shape, non-integer ids, an id >= ``n_classes``, probabilities with NaN/inf or
        negative values.
    """
    a = np.asarray(labels)
    probs = a.ndim == 3
    if a.shape[:2] != tuple(shape) or (probs and a.shape[2] != n_classes) or a.ndim not in (2, 3):
        raise ValueError(f"{where}: labels must be (H,W) ids or (H,W,{n_classes}) probabilities with "
                         f"(H,W)={tuple(shape)}, got {a.shape}")
    s = int(stride)
    if probs:
        p = a[::s, ::s].reshape(-1, n_classes)
        if not np.isfinite(p).all() or p.min() < 0:
            raise ValueError(f"{where}: label probabilities hold NaN/inf or negative values")
        return p
    lab = a[::s, ::s].reshape(-1)
    if not np.issubdtype(lab.dtype, np.integer):
        raise ValueError(f"{where}: label ids must be integers, got {lab.dtype}")
    if lab.size and int(lab.max()) >= n_classes:
        raise ValueError(f"{where}: label id {int(lab.max())} outside 0..{n_classes - 1}")
    return lab
