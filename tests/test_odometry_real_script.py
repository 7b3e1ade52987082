"""scripts/odometry_real.py opens only the frames of ``--frames`` (a held-out half is never read)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import cv2
import numpy as np

from semmatch.io.geometry import look_at

_spec = importlib.util.spec_from_file_location("odometry_real", Path(__file__).parents[1] / "scripts" / "odometry_real.py")
odometry_real = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(odometry_real)


def write_kitchen(root: Path, n: int, readable: int) -> None:
    """A 7-Scenes folder of ``n`` textured frames; frames from ``readable`` on are broken files."""
    rng = np.random.default_rng(0)
    root.mkdir()
    np.savetxt(root / "camera-intrinsics.txt", [[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]])
    texture = cv2.resize(rng.integers(0, 255, (12, 16, 3), dtype=np.uint8), (64, 48), interpolation=cv2.INTER_LINEAR)
    for i in range(n):
        name = root / f"frame-{i:06d}"
        np.savetxt(f"{name}.pose.txt", look_at([0.01 * i, 0.0, 1.0], [0.01 * i, 5.0, 1.0]))
        if i >= readable:  # a held-out frame: reading it fails loudly
            Path(f"{name}.color.png").write_bytes(b"not a png")
            Path(f"{name}.depth.png").write_bytes(b"not a png")
            continue
        cv2.imwrite(f"{name}.color.png", np.roll(texture, i, axis=1))
        cv2.imwrite(f"{name}.depth.png", np.full((48, 64), 2000, np.uint16))


def test_only_the_frames_asked_for_are_read(tmp_path, capsys):
    write_kitchen(tmp_path / "kitchen", 8, readable=4)
    assert odometry_real.main([str(tmp_path / "kitchen"), "--frames", "0:4", "--variants", "open3d", "--quiet"]) == 0
    table = capsys.readouterr().out
    assert "| open3d | 0-3 |" in table


def test_a_range_over_broken_frames_fails(tmp_path):
    import pytest

    write_kitchen(tmp_path / "kitchen", 8, readable=4)
    with pytest.raises((ValueError, OSError), match="frame-00000[4-7]"):
        odometry_real.main([str(tmp_path / "kitchen"), "--frames", "2:8", "--variants", "open3d", "--quiet"])
