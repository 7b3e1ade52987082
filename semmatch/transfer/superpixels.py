"""Superpixels from real libraries: OpenCV contrib (``cv2.ximgproc`` SLIC, SLICO, LSC, SEEDS) and
scikit-image (SLIC; maskSLIC through its ``mask`` argument).

The transfer methods' defaults (``cv2-slic``, 4 iterations, half resolution) are unchanged; the
other settings are the levers measured for ``2d-slic``'s speed on the validation scenes
(docs/speed.md, "The 2d-slic lever, chosen on validation scenes")."""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["BACKENDS", "superpixels", "skimage_slic"]

#: Selectable superpixel backends.
BACKENDS = ("cv2-slic", "cv2-slico", "cv2-lsc", "cv2-seeds", "skimage-slic")


def superpixels(
    rgb: np.ndarray,
    n_segments: int = 512,
    *,
    backend: str = "cv2-slic",
    compactness: float = 10.0,
    iterations: int = 4,
    scale: float = 0.5,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Over-segment an RGB image into about ``n_segments`` superpixels.

    Parameters
    ----------
    rgb : uint8 (H,W,3)
    n_segments : int
        Wanted number of superpixels (the paper uses 512).
    backend : {"cv2-slic", "cv2-slico", "cv2-lsc", "cv2-seeds", "skimage-slic"}
        ``cv2-*``: ``cv2.ximgproc`` SLIC / SLICO / LSC (linear spectral clustering, its default
        ratio 0.075) / SEEDS on the CIELAB image (fast);
        ``skimage-slic``: :func:`skimage.segmentation.slic` (maskSLIC when ``mask`` is given).
    compactness : float
        SLIC colour/space trade-off (OpenCV ``ruler``, scikit-image ``compactness``; not used by
        ``cv2-lsc`` and ``cv2-seeds``).
    iterations : int
        SLIC/SEEDS iterations.
    scale : float
        The ``cv2-slic``/``cv2-slico``/``cv2-lsc`` backends run on the image resized by ``scale`` and the
        labels are resized back (nearest): 0.5 segments a quarter of the pixels, with superpixel
        boundaries at 2-pixel precision. 1 = full resolution. Ignored by the other backends.
    mask : bool (H,W), optional
        Only ``skimage-slic``: segment only these pixels (maskSLIC); others get -1.

    Returns
    -------
    int32 (H,W)
        Superpixel ids ``0..S-1`` (-1 outside ``mask``).

    Raises
    ------
    ValueError
        Unknown backend, wrong image shape/dtype, ``mask`` with an OpenCV backend.
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"superpixels need a uint8 (H,W,3) RGB image, got {rgb.dtype} {rgb.shape}")
    if backend not in BACKENDS:
        raise ValueError(f"unknown superpixel backend {backend!r}; valid: {', '.join(BACKENDS)}")
    if int(n_segments) < 1:
        raise ValueError(f"n_segments must be >= 1, got {n_segments}")
    H, W = rgb.shape[:2]
    if backend == "skimage-slic":
        seg = skimage_slic(rgb, n_segments=int(n_segments), compactness=float(compactness),
                           max_num_iter=int(iterations), start_label=1, mask=mask)
        return seg.astype(np.int32) - 1
    if mask is not None:
        raise ValueError(f"mask is only supported by the skimage-slic backend, not {backend!r}")
    lab = cv2.cvtColor(rgb, cv2.COLOR_RGB2LAB)
    if backend == "cv2-seeds":
        se = cv2.ximgproc.createSuperpixelSEEDS(W, H, 3, int(n_segments), 4, 2, 5, False)
        se.iterate(lab, int(iterations))
        return se.getLabels().astype(np.int32)
    small = lab
    if scale != 1:
        if not 0 < scale <= 1:
            raise ValueError(f"scale must lie in (0, 1], got {scale}")
        small = cv2.resize(lab, (max(1, round(W * scale)), max(1, round(H * scale))), interpolation=cv2.INTER_AREA)
    h, w = small.shape[:2]
    region = max(2, int(round(np.sqrt(h * w / int(n_segments)))))
    if backend == "cv2-lsc":
        sp = cv2.ximgproc.createSuperpixelLSC(small, region)
    else:
        algo = cv2.ximgproc.SLICO if backend == "cv2-slico" else cv2.ximgproc.SLIC
        sp = cv2.ximgproc.createSuperpixelSLIC(small, algo, region, float(compactness))
    sp.iterate(int(iterations))
    seg = sp.getLabels()
    if seg.shape != (H, W):
        seg = cv2.resize(seg, (W, H), interpolation=cv2.INTER_NEAREST)
    return seg.astype(np.int32)


def skimage_slic(image: np.ndarray, **kwargs) -> np.ndarray:
    """:func:`skimage.segmentation.slic` without maskSLIC's empty-cluster warning.

    With a ``mask``, scikit-image seeds the superpixel centres by k-means
    (:func:`scipy.cluster.vq.kmeans2`), which warns when one of its initial clusters is empty;
    the empty cluster simply yields one superpixel fewer, so the warning carries no information
    for a caller and is silenced here. Every other warning passes through.

    Parameters
    ----------
    image : ndarray
        Image or 3D grid (with ``channel_axis``), as for ``slic``.
    **kwargs
        Passed to ``slic``.

    Returns
    -------
    ndarray of int
        Superpixel labels.
    """
    import warnings

    from skimage.segmentation import slic

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="One of the clusters is empty", category=UserWarning)
        return slic(image, **kwargs)
