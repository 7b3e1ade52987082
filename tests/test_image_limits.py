"""Images are measured from their headers before they are decoded: a small file that claims a
canvas larger than the frame contract allows (an "image bomb") is refused with a message naming
the file and both sizes, and Pillow's own bomb limit gives the same clear error."""

from __future__ import annotations

import resource
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from semmatch.io import read_depth, read_label_image, read_rgb
from semmatch.io.contract import MAX_FRAME_PIXELS
from semmatch.io.images import image_size


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def _blank_png(path: Path, width: int, height: int, *, bit_depth: int, colour_type: int) -> Path:
    """A valid PNG of zeros: a large canvas in a small file, made in little time and memory.

    The pixel stream (a zero filter byte and zero pixels per row) is deflated in blocks of rows
    separated by full flushes, so one compressed block stands for every later one; the zlib
    checksum of n zero bytes is ``(n % 65521) << 16 | 1``.
    """
    channels = {0: 1, 2: 3, 3: 1}[colour_type]
    row = 1 + width * channels * bit_depth // 8
    rows = next(k for k in (100, 50, 16, 8, 4, 2, 1) if height % k == 0)
    z = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = bytes(row * rows)
    first = z.compress(block) + z.flush(zlib.Z_FULL_FLUSH)
    again = z.compress(block) + z.flush(zlib.Z_FULL_FLUSH)
    total = row * height
    idat = (b"\x78\x9c" + first + again * (height // rows - 1) + z.flush()
            + struct.pack(">I", (total % 65521) << 16 | 1))
    header = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
    palette = _chunk(b"PLTE", b"\0\0\0") if colour_type == 3 else b""
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + palette + _chunk(b"IDAT", idat)
                     + _chunk(b"IEND", b""))
    return path


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def test_a_16_bit_20000x20000_depth_png_is_refused_without_decoding(tmp_path):
    bomb = _blank_png(tmp_path / "000000.png", 20000, 20000, bit_depth=16, colour_type=0)
    assert bomb.stat().st_size < 2_000_000  # 800 MB of pixels in a small file
    before = _peak_mb()
    with pytest.raises(ValueError) as e:
        read_depth(bomb)
    msg = str(e.value)
    assert str(bomb) in msg and "20000x20000" in msg and "400,000,000 pixels" in msg, msg
    assert f"{MAX_FRAME_PIXELS:,} pixels" in msg and "refusing to decode" in msg, msg
    assert _peak_mb() - before < 200, "the image was decoded before it was refused"


def test_a_15000x15000_label_png_is_refused_with_the_same_message(tmp_path):
    bomb = _blank_png(tmp_path / "labels.png", 15000, 15000, bit_depth=8, colour_type=3)
    with pytest.raises(ValueError, match=r"labels\.png: the image is 15000x15000 \(225,000,000 pixels\), larger than"):
        read_label_image(bomb)
    with pytest.raises(ValueError, match=r"15000x15000"):
        read_rgb(bomb)


def test_images_within_the_contract_are_read_as_before(tmp_path):
    small = _blank_png(tmp_path / "d.png", 64, 48, bit_depth=16, colour_type=0)
    assert image_size(small) == (64, 48)
    assert (read_depth(small) == 0).all() and read_depth(small).shape == (48, 64)  # the test's PNGs are valid
    labels = _blank_png(tmp_path / "l.png", 300, 200, bit_depth=8, colour_type=3)
    assert (read_label_image(labels) == 0).all() and read_label_image(labels).shape == (200, 300)
    edge = 8192  # 64 Mi pixels: the largest frame
    assert edge * edge == MAX_FRAME_PIXELS
    header = struct.pack(">IIBBBBB", edge, edge, 8, 0, 0, 0, 0)
    (tmp_path / "edge.png").write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header))  # the header is all it reads
    assert image_size(tmp_path / "edge.png") == (edge, edge)
    (tmp_path / "over.png").write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", edge, edge + 1,
                                                                                          8, 0, 0, 0, 0)))
    with pytest.raises(ValueError, match="8192x8193"):
        image_size(tmp_path / "over.png")
    assert image_size(tmp_path / "d.png") == (64, 48)
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(FileNotFoundError, match="cannot read image"):
        read_rgb(tmp_path / "text.png")


@pytest.mark.parametrize("side", [40, 100])  # Pillow warns above its limit, refuses above twice it
def test_pillows_bomb_limit_becomes_the_same_clear_error(tmp_path, monkeypatch, side):
    from PIL import Image

    jpg = tmp_path / "frame.jpg"
    assert cv2.imwrite(str(jpg), np.zeros((side, side, 3), np.uint8))
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 1000)
    with pytest.raises(ValueError, match=r"frame\.jpg: the image is larger than Pillow decodes safely .*refusing"):
        read_rgb(jpg)
