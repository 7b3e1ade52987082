"""Images of the data contract: RGB, 16-bit depth and palette label PNGs, written atomically.

Every image is measured from its header before it is decoded (:func:`image_size`): one larger
than the frame contract's maximum (:data:`semmatch.io.contract.MAX_FRAME_PIXELS`) is refused
with a message naming the file and both sizes, so a small file that claims a huge canvas (an
"image bomb") never reaches the decoder.
"""

from __future__ import annotations

import os
import struct
import warnings

import cv2
import numpy as np

from .files import atomic_path
from .geometry import MAX_PIXELS as MAX_FRAME_PIXELS  # semmatch.io.contract.MAX_FRAME_PIXELS

__all__ = ['read_image', 'read_rgb', 'write_image', 'read_label_image', 'write_label_image', 'read_depth', 'write_depth',
           'depth_to_uint16', 'check_depth_units', 'DEPTH_UNIT_RANGE', 'image_size']

PathLike = str | os.PathLike


# ----------------------------------------------------------------------------- images
def write_image(path: PathLike, image: np.ndarray) -> None:
    """Write an RGB ``uint8 (H,W,3)``, a ``uint8``/``uint16 (H,W)`` image as PNG, atomically."""
    image = np.asarray(image)
    if image.ndim == 3:
        if image.shape[2] != 3 or image.dtype != np.uint8:
            raise ValueError(f"{path}: RGB must be uint8 (H,W,3), got {image.dtype} {image.shape}")
        image = image[..., ::-1]
    elif image.ndim != 2 or image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{path}: expected uint8/uint16 (H,W), got {image.dtype} {image.shape}")
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(image), [cv2.IMWRITE_PNG_COMPRESSION, 1]):
            raise OSError(f"could not write image {path}")


def _png_palette() -> list[int]:
    from .labels import PALETTE

    pal = np.zeros((256, 3), np.uint8)
    pal[: len(PALETTE)] = PALETTE
    return pal.reshape(-1).tolist()


def write_label_image(path: PathLike, labels: np.ndarray) -> None:
    """Write category ids (uint8 (H,W)) as a palette PNG, atomically.

    The pixel values are the ids (read back id-exact by :func:`read_label_image`); the PNG's
    palette holds the category colours, so any image viewer shows the labels in colour.
    """
    from PIL import Image

    lab = np.asarray(labels)
    if lab.ndim != 2 or lab.dtype != np.uint8:
        raise ValueError(f"{path}: labels must be uint8 (H,W), got {lab.dtype} {lab.shape}")
    img = Image.fromarray(np.ascontiguousarray(lab), mode="P")
    img.putpalette(_png_palette())
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG", compress_level=1)


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _too_large(path: PathLike, size: str, pixels: int | None) -> ValueError:
    count = f" ({pixels:,} pixels)" if pixels is not None else ""
    return ValueError(f"{path}: the image is {size}{count}, larger than the largest frame semmatch reads "
                      f"({MAX_FRAME_PIXELS:,} pixels, semmatch.io.contract.MAX_FRAME_PIXELS); refusing to decode it")


def image_size(path: PathLike) -> tuple[int, int] | None:
    """The ``(width, height)`` of an image file, read from its header only, checked against the
    frame contract's maximum before anything is decoded.

    PNG headers are read directly; other formats through Pillow, which opens files lazily (its
    decompression-bomb limit, an error or a warning, becomes the same clear error).

    Parameters
    ----------
    path : path
        A regular file.

    Returns
    -------
    tuple of int, or None
        None when the header is not one of an image format Pillow knows (the reader then
        reports the file as unreadable).

    Raises
    ------
    ValueError
        More pixels than :data:`semmatch.io.contract.MAX_FRAME_PIXELS` (the message names the file,
        the image's size and the maximum).
    FileNotFoundError
        No such file.
    """
    from PIL import Image, UnidentifiedImageError

    with open(path, "rb") as fh:
        head = fh.read(24)
    if head[:8] == _PNG_SIGNATURE and head[12:16] == b"IHDR":
        width, height = struct.unpack(">II", head[16:24])
    else:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", Image.DecompressionBombWarning)
                with Image.open(path) as img:
                    width, height = img.size
        except (Image.DecompressionBombError, Image.DecompressionBombWarning) as e:
            raise _too_large(path, f"larger than Pillow decodes safely ({e})", None) from None
        except (UnidentifiedImageError, OSError):
            return None  # not an image Pillow knows: its reader says so
    if width * height > MAX_FRAME_PIXELS:
        raise _too_large(path, f"{width}x{height}", width * height)
    return width, height


def read_label_image(path: PathLike) -> np.ndarray:
    """Read a label PNG as category ids (uint8 (H,W)): palette PNGs (their indices) and 8-bit
    grayscale PNGs (their values).

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        The file is not a single-channel 8-bit or palette image.
    """
    from PIL import Image, UnidentifiedImageError

    try:
        image_size(path)
        with Image.open(path) as img:
            if img.mode not in ("P", "L"):
                raise ValueError(f"{path}: labels must be an 8-bit single-channel or palette PNG, got mode {img.mode}")
            return np.asarray(img, dtype=np.uint8).copy()
    except FileNotFoundError:
        raise FileNotFoundError(f"cannot read image {path}") from None
    except (UnidentifiedImageError, OSError) as e:
        raise ValueError(f"{path}: not a readable image ({e})") from None


def read_image(path: PathLike, *, flags: int = cv2.IMREAD_UNCHANGED) -> np.ndarray:
    """Read a PNG/JPEG; colour images come back as RGB.

    Raises
    ------
    FileNotFoundError
        No such file, or not an image OpenCV can read.
    ValueError
        Not a regular file (a FIFO would block the reader forever, a device never end), or an
        image larger than the frame contract allows (:func:`image_size`).
    """
    if os.path.exists(path) and not os.path.isfile(path):
        raise ValueError(f"{path}: not a regular file (a folder, a FIFO or a device); refusing to read it as an image")
    if os.path.isfile(path):
        image_size(path)  # before decoding: an image larger than any frame is refused
    img = cv2.imread(str(path), flags)
    if img is None:
        raise FileNotFoundError(f"cannot read image {path}")
    if img.ndim == 3:
        img = img[..., 2::-1] if img.shape[2] >= 3 else img
        img = np.ascontiguousarray(img)
    return img


def read_rgb(path: PathLike) -> np.ndarray:
    """Read a colour frame as uint8 RGB (H,W,3), whatever its storage.

    Grey images are repeated over three channels, alpha is dropped, and 16-bit images are
    scaled to 8 bits (``round(v / 257)``: 65535 -> 255), never wrapped to their low byte.

    Raises
    ------
    FileNotFoundError
        Not a readable image.
    ValueError
        Not 8- or 16-bit, or not 1, 3 or 4 channels (the message names the file).
    """
    img = read_image(path)
    if img.dtype == np.uint16:
        img = ((img.astype(np.uint32) + 128) // 257).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise ValueError(f"{path}: colour frames must be 8- or 16-bit, got {img.dtype}")
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4):
        raise ValueError(f"{path}: colour frames must have 1, 3 or 4 channels, got shape {img.shape}")
    if img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    return np.ascontiguousarray(img[..., :3])


def depth_to_uint16(depth: np.ndarray, depth_scale: float = 1000.0) -> np.ndarray:
    """Metric depth as 16-bit integers: ``rint(metres * depth_scale)`` clipped to 65535; 0 = none.

    Non-finite and non-positive depths become 0. The arithmetic is done in ``depth``'s float type.

    Parameters
    ----------
    depth : float array
        Metres.
    depth_scale : float
        Units per metre (1000: millimetres).

    Returns
    -------
    uint16 array
    """
    d = np.where(np.isfinite(depth) & (depth > 0), depth, 0.0) * depth_scale
    return np.clip(np.rint(d), 0, 65535).astype(np.uint16)


#: median depths outside this range (metres) mean the depth unit is wrong
DEPTH_UNIT_RANGE = (0.05, 20.0)


def check_depth_units(depth: np.ndarray, *, where: str = "depth") -> float:
    """Check that a depth image is in metres; return its median valid depth.

    Parameters
    ----------
    depth : ndarray (H, W)
        Depth in metres, 0 or non-finite = no measurement.
    where : str
        What the image is (file, frame), for the message.

    Returns
    -------
    float
        The median valid depth (NaN when the image has no valid pixel).

    Raises
    ------
    ValueError
        When the median valid depth lies outside 0.05 .. 20 m: the depth was most likely saved
        in another unit (millimetres read as metres, or a wrong ``depth_scale``).
    """
    d = np.asarray(depth)[::4, ::4]
    d = d[np.isfinite(d) & (d > 0)]
    if d.size == 0:
        return float("nan")
    med = float(np.median(d))
    lo, hi = DEPTH_UNIT_RANGE
    if not lo <= med <= hi:
        raise ValueError(
            f"{where}: median depth is {med:.4g} m, outside {lo}..{hi} m; the depth is most likely "
            "in the wrong unit (check depth_scale: 1000 for millimetre PNGs, 5000 for TUM)"
        )
    return med


def write_depth(path: PathLike, depth: np.ndarray, depth_scale: float = 1000.0) -> None:
    """Write metric depth as a 16-bit PNG (``value = metres * depth_scale``, 0 = none)."""
    write_image(path, depth_to_uint16(np.asarray(depth, dtype=np.float64), depth_scale))


def read_depth(path: PathLike, depth_scale: float = 1000.0) -> np.ndarray:
    """Read a 16-bit depth PNG as float32 metres."""
    raw = read_image(path)
    if raw.ndim != 2 or raw.dtype != np.uint16:
        raise ValueError(f"{path}: depth must be a 16-bit single-channel PNG, got {raw.dtype} {raw.shape}")
    return raw.astype(np.float32) / np.float32(depth_scale)


