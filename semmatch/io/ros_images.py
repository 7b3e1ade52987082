"""ROS image messages and numpy images: ``sensor_msgs`` Image, CompressedImage and CameraInfo, both ways.

Decoding (what :class:`semmatch.io.bags.RosBagSequence` reads): :func:`decode_colour` (raw
``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``, ``mono8``; compressed JPEG/PNG) to uint8 RGB,
:func:`decode_depth` (raw ``16UC1``/``mono16`` millimetres or ``32FC1`` metres; image_transport's
``compressedDepth`` PNG of either) to float32 metres, :func:`camera_info_intrinsics` to
:class:`~semmatch.io.geometry.Intrinsics`. Encoding (what :func:`semmatch.io.bags.write_rosbag`
writes): :func:`colour_message`, :func:`depth_message`, :func:`camera_info_message`, given the
message classes of a rosbags typestore (``typestore.types``).

image_transport's ``compressedDepth``: a 12-byte header (int32 format, float32 depthQuantA,
depthQuantB), then a 16-bit PNG: millimetres for ``16UC1``; for ``32FC1`` the quantised inverse
depth ``A / d + B`` (0 = none), decoded as ``d = A / (v - B)``.
"""

from __future__ import annotations

import struct
import warnings

import cv2
import numpy as np

from .geometry import Intrinsics
from .images import depth_to_uint16
from .reading_checks import DEPTH_HOLE

__all__ = [
    "IMAGE",
    "COMPRESSED_IMAGE",
    "CAMERA_INFO",
    "decode_colour",
    "decode_depth",
    "camera_info_intrinsics",
    "colour_message",
    "depth_message",
    "camera_info_message",
]

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"

#: colour encodings of raw images: channels and the OpenCV conversion to RGB
_COLOUR_ENCODINGS = {
    "rgb8": (3, None),
    "bgr8": (3, cv2.COLOR_BGR2RGB),
    "rgba8": (4, cv2.COLOR_RGBA2RGB),
    "bgra8": (4, cv2.COLOR_BGRA2RGB),
    "mono8": (1, cv2.COLOR_GRAY2RGB),
}
#: image_transport's compressedDepth header: int32 format, float32 depthQuantA, depthQuantB
_DEPTH_HEADER = struct.Struct("<iff")
#: image_transport's compressedDepth defaults for 32FC1 (depth_quantization 100, depth_max 10 m)
QUANT_A = 100.0 * 101.0
QUANT_B = 1.0 - QUANT_A / 10.0


def _raw_pixels(msg, dtype: np.dtype, channels: int) -> np.ndarray:
    """The pixels of a ``sensor_msgs/Image`` as (H, W[, C]), row padding (``step``) removed."""
    h, w = int(msg.height), int(msg.width)
    dtype = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")
    row = w * channels * dtype.itemsize
    data = np.asarray(msg.data, dtype=np.uint8)
    if msg.step < row or data.size < msg.step * h:
        raise ValueError(f"{msg.encoding} image of {w}x{h} has step {msg.step} and {data.size} bytes; "
                         f"it needs {row} bytes a row")
    px = data[: msg.step * h].reshape(h, msg.step)[:, :row].copy().view(dtype)
    px = px.astype(dtype.newbyteorder("="), copy=False)
    return px.reshape(h, w, channels) if channels > 1 else px.reshape(h, w)


def _decompress(msg, where: str) -> np.ndarray:
    """A ``CompressedImage``'s JPEG/PNG data decoded by OpenCV (unchanged depth and channels)."""
    buf = np.asarray(msg.data, dtype=np.uint8)
    img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if buf.size else None
    if img is None:
        raise ValueError(f"{where}: the compressed image ({msg.format!r}, {buf.size} bytes) does not decode")
    return img


def decode_colour(msg, where: str = "colour") -> np.ndarray:
    """A colour ``sensor_msgs/Image`` or ``CompressedImage`` message as uint8 RGB (H, W, 3).

    Parameters
    ----------
    msg : Image or CompressedImage message
        Raw images in ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8`` or ``mono8``; compressed JPEG or PNG
        (8 bits; decoded as OpenCV does, BGR, as image_transport encodes them).
    where : str
        What the message is (bag, topic, stamp), for the messages.

    Raises
    ------
    ValueError
        Another encoding, a size that does not fit the data, or data that does not decode.
    """
    if hasattr(msg, "format"):
        img = _decompress(msg, where)
        if img.dtype != np.uint8:
            raise ValueError(f"{where}: compressed colour images must be 8-bit, got {img.dtype} ({msg.format!r})")
        code = {2: cv2.COLOR_GRAY2RGB, 3: cv2.COLOR_BGR2RGB, 4: cv2.COLOR_BGRA2RGB}[img.ndim if img.ndim == 2
                                                                                   else img.shape[2]]
        return cv2.cvtColor(img, code)
    if msg.encoding not in _COLOUR_ENCODINGS:
        raise ValueError(f"{where}: colour encoding {msg.encoding!r} is not read; expected one of "
                         f"{', '.join(_COLOUR_ENCODINGS)} (or a CompressedImage topic)")
    channels, code = _COLOUR_ENCODINGS[msg.encoding]
    try:
        px = _raw_pixels(msg, np.uint8, channels)
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None
    return np.ascontiguousarray(px if code is None else cv2.cvtColor(px, code))


def _compressed_depth(msg, where: str) -> np.ndarray:
    """image_transport's ``compressedDepth`` (header + 16-bit PNG) as float32 metres (0 = none)."""
    fmt = str(msg.format)
    encoding = fmt.split(";")[0].strip()
    if "rvl" in fmt.lower():
        raise ValueError(f"{where}: compressedDepth in RVL ({fmt!r}) is not read; record the PNG "
                         "compressedDepth format or raw depth")
    data = bytes(np.asarray(msg.data, dtype=np.uint8))
    if len(data) <= _DEPTH_HEADER.size:
        raise ValueError(f"{where}: compressedDepth message of {len(data)} bytes has no image")
    _, quant_a, quant_b = _DEPTH_HEADER.unpack_from(data)
    img = cv2.imdecode(np.frombuffer(data, np.uint8, offset=_DEPTH_HEADER.size), cv2.IMREAD_UNCHANGED)
    if img is None or img.dtype != np.uint16 or img.ndim != 2:
        raise ValueError(f"{where}: compressedDepth ({fmt!r}) does not hold a 16-bit single-channel PNG")
    if encoding in ("16UC1", "mono16"):
        return _millimetres(img)
    if encoding == "32FC1":
        inv = img.astype(np.float32)
        out = np.zeros(img.shape, np.float32)
        ok = img > 0
        out[ok] = np.float32(quant_a) / (inv[ok] - np.float32(quant_b))
        return _metres(out)
    raise ValueError(f"{where}: compressedDepth of {encoding!r} is not read; expected 16UC1 or 32FC1")


def _millimetres(raw: np.ndarray) -> np.ndarray:
    """16-bit millimetres as float32 metres; 0 and 65535 are holes (0)."""
    out = raw.astype(np.float32) / np.float32(1000.0)
    out[raw == DEPTH_HOLE] = 0.0
    return out


def _metres(depth: np.ndarray) -> np.ndarray:
    """float metres with NaN, inf and non-positive values as holes (0), float32."""
    depth = depth.astype(np.float32, copy=False)
    return np.where(np.isfinite(depth) & (depth > 0), depth, np.float32(0.0)).astype(np.float32)


def decode_depth(msg, where: str = "depth") -> np.ndarray:
    """A depth ``sensor_msgs/Image`` or ``CompressedImage`` (``compressedDepth``) as float32 metres.

    Parameters
    ----------
    msg : Image or CompressedImage message
        Raw ``16UC1``/``mono16`` (millimetres) or ``32FC1`` (metres); image_transport's
        ``compressedDepth`` PNG of either; or a 16-bit PNG ``CompressedImage`` (millimetres).
    where : str
        What the message is, for the messages.

    Returns
    -------
    float32 (H, W)
        Metres; 0 = no measurement (0, NaN, inf and 16-bit 65535 in the message).

    Raises
    ------
    ValueError
        Another encoding (e.g. a colour topic given as depth), or data that does not fit.
    """
    if hasattr(msg, "format"):
        if "compresseddepth" in str(msg.format).lower():
            return _compressed_depth(msg, where)
        img = _decompress(msg, where)  # image_transport's plain "compressed" of a 16UC1 image: a 16-bit PNG
        if img.dtype != np.uint16 or img.ndim != 2:
            raise ValueError(f"{where}: a compressed depth topic must hold 16-bit single-channel PNGs (millimetres) or "
                             f"image_transport's compressedDepth; {msg.format!r} decodes to {img.dtype} {img.shape}")
        return _millimetres(img)
    try:
        if msg.encoding in ("16UC1", "mono16"):
            return _millimetres(_raw_pixels(msg, np.uint16, 1))
        if msg.encoding == "32FC1":
            return _metres(_raw_pixels(msg, np.float32, 1))
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None
    raise ValueError(f"{where}: depth encoding {msg.encoding!r} is not read; expected 16UC1 (millimetres) or "
                     "32FC1 (metres)")


def camera_info_intrinsics(msg, where: str = "camera_info") -> Intrinsics:
    """The :class:`~semmatch.io.geometry.Intrinsics` of a ``sensor_msgs/CameraInfo`` (its ``K``).

    ``depth_scale`` is 1000 (millimetres: what a sequence written from the bag stores).

    Warns
    -----
    UserWarning
        Non-zero distortion coefficients: the images are read as undistorted pinhole images.
    """
    K = np.asarray(msg.k if hasattr(msg, "k") else msg.K, dtype=np.float64).reshape(3, 3)  # ROS 2 / ROS 1 names
    D = np.asarray(msg.d if hasattr(msg, "d") else msg.D, dtype=np.float64)
    try:
        intr = Intrinsics(int(msg.width), int(msg.height), K[0, 0], K[1, 1], K[0, 2], K[1, 2], 1000.0)
    except ValueError as e:
        raise ValueError(f"{where}: {e} (K = {K.ravel().tolist()}, {msg.width}x{msg.height})") from None
    if D.size and np.abs(D).max() > 1e-6:
        warnings.warn(f"{where}: distortion {msg.distortion_model} {np.round(D, 4).tolist()} is ignored; semmatch "
                      "reads the images as undistorted pinhole images (record the rectified image_rect topics)",
                      UserWarning, stacklevel=3)
    return intr




def colour_message(types: dict, header, rgb: np.ndarray, compressed: str | None = None):
    """uint8 RGB (H,W,3) as an ``Image`` (``rgb8``) or a ``CompressedImage`` (``"jpeg"``/``"png"`` of BGR,
    as image_transport encodes); ``types``: a rosbags typestore's message classes."""
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    if compressed:
        ok, buf = cv2.imencode(f".{'jpg' if compressed == 'jpeg' else 'png'}", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        return types[COMPRESSED_IMAGE](header, f"rgb8; {compressed} compressed bgr8", buf.ravel())
    h, w = rgb.shape[:2]
    return types[IMAGE](header, h, w, "rgb8", 0, 3 * w, rgb.ravel())


def depth_message(types: dict, header, depth: np.ndarray, encoding: str = "16UC1", compressed: bool = False):
    """Depth in metres (0 = none) as an ``Image`` or an image_transport ``compressedDepth`` ``CompressedImage``.

    Parameters
    ----------
    types : dict
        Message classes of a rosbags typestore.
    header : std_msgs/Header
    depth : float (H,W)
        Metres.
    encoding : {"16UC1", "32FC1"}
        Millimetres (:func:`semmatch.io.depth_to_uint16`) or float metres (NaN where none).
    compressed : bool
        image_transport's ``compressedDepth`` PNG (``32FC1``: its inverse-depth quantisation with
        the defaults, depth_quantization 100 and depth_max 10 m).
    """
    depth = np.asarray(depth, dtype=np.float32)
    h, w = depth.shape
    raw = depth_to_uint16(depth, 1000.0) if encoding == "16UC1" else np.where(depth > 0, depth, np.float32(np.nan))
    if not compressed:
        raw = np.ascontiguousarray(raw, dtype="<u2" if encoding == "16UC1" else "<f4")
        return types[IMAGE](header, h, w, encoding, 0, raw.itemsize * w, raw.ravel().view(np.uint8))
    quant = (0.0, 0.0)
    if encoding == "32FC1":  # 0 = none, also beyond depth_max
        near = np.isfinite(raw) & (raw < 10.0)
        inv = np.zeros(raw.shape, np.uint16)
        inv[near] = np.clip(np.round(QUANT_A / raw[near] + QUANT_B), 0, 65535).astype(np.uint16)
        raw, quant = inv, (QUANT_A, QUANT_B)
    ok, png = cv2.imencode(".png", raw)
    data = np.frombuffer(_DEPTH_HEADER.pack(0, *quant) + png.tobytes(), np.uint8)
    return types[COMPRESSED_IMAGE](header, f"{encoding}; compressedDepth png", data)


def camera_info_message(types: dict, header, intrinsics: Intrinsics):
    """A ``CameraInfo`` of a pinhole camera without distortion (``K``, ``P``; ROS 1 or ROS 2 field names)."""
    i = intrinsics
    K = np.array([i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0])
    P = np.array([i.fx, 0.0, i.cx, 0.0, 0.0, i.fy, i.cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    roi = types["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
    return types[CAMERA_INFO](header, i.height, i.width, "plumb_bob", np.zeros(5), K, np.eye(3).ravel(), P, 0, 0, roi)
