"""semmatch.io.readers.tum.write_tum_rgbd and scripts/sequence_to_tum.py: a recording written as a TUM
RGB-D folder reads back as the same frames (colour exact, depth to 0.1 mm, poses)."""

from __future__ import annotations

import dataclasses
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from semmatch.io import Frame, SequenceWriter
from semmatch.io.geometry import DEFAULT_INTRINSICS, look_at
from semmatch.io.readers.tum import TumRgbdSequence, write_tum_rgbd
from semmatch.io.recordings import read_recording

INTR = DEFAULT_INTRINSICS.scaled(64, 48)


def frames(n=5):
    rng = np.random.default_rng(0)
    return [Frame(rgb=rng.integers(0, 255, (48, 64, 3), dtype=np.uint8),
                  depth=rng.uniform(0.5, 4.0, (48, 64)).astype(np.float32), labels=None,
                  pose=look_at([0.1 * i, 0.0, 1.0], [0.1 * i, 5.0, 1.0]), intrinsics=INTR, index=i, timestamp=float(i))
            for i in range(n)]


def test_round_trip_at_a_camera_rate(tmp_path):
    src = frames()
    write_tum_rgbd(tmp_path / "tum", src, INTR, fps=30)
    seq = read_recording(tmp_path / "tum")
    assert isinstance(seq, TumRgbdSequence) and len(seq) == 5 and seq.intrinsics == dataclasses.replace(
        INTR, depth_scale=5000.0)
    assert np.allclose(seq.timestamps, np.arange(5) / 30)
    for f, g in zip(seq, src):
        assert np.array_equal(f.rgb, g.rgb) and np.abs(f.depth - g.depth).max() <= 1e-4 + 1e-6
        assert np.allclose(f.pose, g.pose, atol=1e-6)
    with pytest.raises(FileExistsError, match="--overwrite"):
        write_tum_rgbd(tmp_path / "tum", src, INTR, fps=30)
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="did not write"):
        write_tum_rgbd(tmp_path / "mine", src, INTR, fps=30)
    with pytest.raises(ValueError, match="does not follow"):
        write_tum_rgbd(tmp_path / "t2", [*src[:2], src[0]], INTR)
    assert not (tmp_path / "t2").exists()  # nothing half-written


def test_script_converts_a_sequence_folder(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("sequence_to_tum", Path(__file__).parents[1] / "scripts" /
                                                  "sequence_to_tum.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    with SequenceWriter(tmp_path / "seq", INTR) as w:
        for f in frames(4):
            w.add(f.rgb, f.depth, f.pose, timestamp=f.timestamp)
    assert script.main([str(tmp_path / "seq"), str(tmp_path / "tum"), "--frames", "3"]) == 0
    assert "3 frames" in capsys.readouterr().out
    seq = read_recording(tmp_path / "tum")
    assert len(seq) == 3 and seq.has_poses
    assert script.main([str(tmp_path / "seq"), str(tmp_path / "seq" / "tum")]) == 2  # inside the input
    assert "outside the inputs" in capsys.readouterr().err
    assert script.main([str(tmp_path / "seq"), str(tmp_path / "tum0"), "--fps", "0"]) == 0
    assert read_recording(tmp_path / "tum0").poses is not None
