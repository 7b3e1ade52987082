"""The reader registry (semmatch.io.readers): one door for every recording layout, and the reading checks."""

from __future__ import annotations

import json
import sys
import textwrap

import numpy as np
import pytest
from test_recordings import H, W, write_7scenes, write_tum_folder

from semmatch.io import (
    SequenceWriter,
    write_depth,
    write_image,
    write_intrinsics,
    write_label_image,
    write_tum,
)
from semmatch.io import readers as registry
from semmatch.io.geometry import Intrinsics, look_at
from semmatch.io.readers import LAYOUTS, SequenceView, find_layout, open_recording, register_layout

CAMERA = Intrinsics(W, H, 50.0, 50.0, 32.0, 24.0, 1000.0)


def _poses(n: int) -> np.ndarray:
    return np.stack([look_at([0.1 * i, 0.0, 1.0], [0.1 * i, 5.0, 1.0]) for i in range(n)])


def write_plain(root, n=4, *, poses=False):
    """A plain folder: rgb/, depth/ (mm), intrinsics.json, optional poses.txt."""
    for i in range(n):
        write_image(root / "rgb" / f"{i:04d}.png", np.full((H, W, 3), 30 * i, np.uint8))
        write_depth(root / "depth" / f"{i:04d}.png", np.full((H, W), 2.0, np.float32))
    write_intrinsics(root / "intrinsics.json", CAMERA)
    if poses:
        write_tum(root / "poses.txt", np.arange(n, dtype=float), _poses(n))
    return root


def write_sequence(root, n=4, *, depth_scale=1000.0, labels=None):
    """A semmatch sequence folder (what the simulator writes) of flat frames 2 m away."""
    cam = Intrinsics(W, H, 50.0, 50.0, 32.0, 24.0, depth_scale)
    with SequenceWriter(root, cam) as w:
        for i, T in enumerate(_poses(n)):
            w.add(np.full((H, W, 3), 20 * i, np.uint8), np.full((H, W), 2.0, np.float32), T,
                  labels=None if labels is None else np.full((H, W), labels, np.uint8))
    return root


@pytest.fixture
def recordings(tmp_path):
    """One small recording of every built-in layout."""
    t = 100.0 + np.arange(4) * 0.1
    write_tum_folder(tmp_path / "tum", t, t, gt_t=99.9 + np.arange(30) * 0.03)
    write_intrinsics(tmp_path / "tum" / "intrinsics.json", Intrinsics(W, H, 50, 50, 32, 24, 5000.0))
    write_7scenes(tmp_path / "7scenes", 4)
    return {"7scenes": tmp_path / "7scenes", "tum-rgbd": tmp_path / "tum",
            "sequence": write_sequence(tmp_path / "seq"), "plain": write_plain(tmp_path / "plain")}


def test_every_layout_is_detected_and_read(recordings):
    assert [lay.name for lay in LAYOUTS][:4] == ["7scenes", "tum-rgbd", "sequence", "plain"]
    for name, path in recordings.items():
        assert find_layout(path).name == name
        seq = open_recording(path)
        assert seq.layout == name and len(seq) == 4, name
        f = seq[3]
        assert f.rgb.shape == (H, W, 3) and np.allclose(f.depth, 2.0, atol=1e-3) and f.index == 3, name
        assert (seq.poses is None) == (name == "plain"), name


def test_a_frame_range_applies_to_every_layout(recordings):
    for name, path in recordings.items():
        seq = open_recording(path, frames=slice(1, 3))
        assert len(seq) == 2, name
        full = open_recording(path)
        assert np.array_equal(seq[0].rgb, full[1].rgb) and seq[0].index == 0, name
        assert np.allclose(seq.timestamps, full.timestamps[1:3]), name
        if full.poses is not None:
            assert np.allclose(seq.poses, full.poses[1:3], equal_nan=True), name
    seq = open_recording(recordings["sequence"], frames=slice(2, None))  # the sequence reader takes no range
    assert isinstance(seq, SequenceView) and len(seq) == 2 and seq.path == recordings["sequence"]
    with pytest.raises(ValueError, match=r"no frame in 9:12 \(the recording has 4\)"):
        open_recording(recordings["sequence"], frames=slice(9, 12))


def test_a_path_of_no_layout_gets_every_layout_listed(tmp_path):
    (tmp_path / "junk").mkdir()
    with pytest.raises(ValueError, match="not a recording folder") as e:
        open_recording(tmp_path / "junk")
    for layout in LAYOUTS:
        assert f"{layout.name}: {layout.description}" in str(e.value)
    with pytest.raises(FileNotFoundError, match="no such sequence folder or recording file"):
        open_recording(tmp_path / "none")


def test_an_option_the_reader_does_not_take_is_refused(recordings):
    with pytest.raises(ValueError, match=r"sequence recordings take no --color-topic \(that reader takes: --labels"):
        open_recording(recordings["sequence"], color_topic="/camera/color")
    with pytest.raises(ValueError, match=r"7scenes recordings take no --depth-topic"):
        open_recording(recordings["7scenes"], depth_topic="/d")
    assert len(open_recording(recordings["plain"], color_topic=None)) == 4  # not given: not passed


TOY_MODULE = '''
"""A toy layout: one .toy file (an .npz of rgb (N,H,W,3) and depth (N,H,W) in metres)."""
from pathlib import Path

import numpy as np

from semmatch.io.geometry import Intrinsics
from semmatch.io import Frame


def is_toy(path):
    return Path(path).is_file() and Path(path).suffix == ".toy"


class ToySequence:
    def __init__(self, path, *, fx=50.0):
        self.path = Path(path)
        with open(self.path, "rb") as fh:
            z = np.load(fh)
            self.rgb, self.depth = z["rgb"], z["depth"]
        n, h, w = self.depth.shape
        self.intrinsics = Intrinsics(w, h, fx, fx, w / 2, h / 2)
        self.timestamps = np.arange(n, dtype=float)
        self.poses = None
        self.has_poses = False

    def __len__(self):
        return len(self.depth)

    def __getitem__(self, i):
        return Frame(self.rgb[i], self.depth[i], None, None, self.intrinsics, index=i, timestamp=float(i))
'''


def test_a_new_layout_is_one_module_and_one_registration_line(tmp_path, monkeypatch):
    """A file layout (like a ROS bag): its module, one ``register_layout`` line, and every door opens it."""
    (tmp_path / "toy_layout.py").write_text(textwrap.dedent(TOY_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "LAYOUTS", list(LAYOUTS))  # the registration is undone after the test
    toy = tmp_path / "rec.toy"
    with open(toy, "wb") as fh:
        np.savez(fh, rgb=np.zeros((5, H, W, 3), np.uint8), depth=np.full((5, H, W), 1.5, np.float32))
    with pytest.raises(ValueError, match="not a recording file of any known layout"):
        open_recording(toy)

    register_layout("toy", "toy_layout", "is_toy", "ToySequence", "a .toy file (npz of rgb and depth)")

    seq = open_recording(toy, frames=slice(1, 4))
    assert seq.layout == "toy" and len(seq) == 3 and seq[0].index == 0 and np.allclose(seq[2].depth, 1.5)
    assert open_recording(toy, fx=80.0).intrinsics.fx == 80.0  # the reader's own option
    with pytest.raises(ValueError, match=r"toy recordings take no --color-topic \(that reader takes: --fx\)"):
        open_recording(toy, color_topic="/c")
    with pytest.raises(ValueError, match="toy: a .toy file"):
        open_recording(tmp_path / "toy_layout.py")  # the listing names the new layout
    from semmatch.io.recordings import read_recording

    assert len(read_recording(toy)) == 5
    sys.modules.pop("toy_layout", None)


# ----------------------------------------------------------------------------- reading checks
@pytest.mark.parametrize("t", [1e30, 2e5])
def test_a_7scenes_pose_far_away_is_refused_with_its_file(tmp_path, t):
    write_7scenes(tmp_path / "k", 3)
    T = np.eye(4)
    T[0, 3] = t
    np.savetxt(tmp_path / "k" / "frame-000002.pose.txt", T)
    with pytest.raises(ValueError, match=r"frame-000002\.pose\.txt: camera position .* lies beyond 10000 m"):
        open_recording(tmp_path / "k")


def test_a_pose_that_is_no_rotation_is_refused(tmp_path):
    write_7scenes(tmp_path / "k", 3)
    T = np.eye(4)
    T[:3, :3] *= 1.1  # scaled
    np.savetxt(tmp_path / "k" / "frame-000000.pose.txt", T)
    with pytest.raises(ValueError, match=r"frame-000000\.pose\.txt: the pose's 3x3 block is not a rotation"):
        open_recording(tmp_path / "k")
    T = np.diag([1.0, 1.0, -1.0, 1.0])  # a reflection: det -1
    np.savetxt(tmp_path / "k" / "frame-000000.pose.txt", T)
    with pytest.raises(ValueError, match=r"not a rotation .* det -1"):
        open_recording(tmp_path / "k")


def test_a_sequence_folder_with_a_depth_scale_against_its_depth_is_refused(tmp_path):
    # millimetre PNGs (2 m -> 2000) whose intrinsics.json says 5000 per metre: a room five times too small
    seq = write_sequence(tmp_path / "s", 3)
    d = json.loads((seq / "intrinsics.json").read_text())
    (seq / "intrinsics.json").write_text(json.dumps({**d, "depth_scale": 5000}))
    with pytest.raises(ValueError, match=r"s \(intrinsics\.json\): at depth_scale 5000 the median depth .* 0\.40 m"
                                         r".*millimetres it is 2\.00 m"):
        open_recording(seq)
    from semmatch.io import read_sequence

    with pytest.raises(ValueError, match="at depth_scale 5000"):
        read_sequence(seq)
    assert len(read_sequence(write_sequence(tmp_path / "ok", 3, depth_scale=5000.0))) == 3  # right scale: read


def test_label_images_outside_the_category_table_are_refused(tmp_path):
    seq = open_recording(write_sequence(tmp_path / "s", 2, labels=200))
    with pytest.raises(ValueError, match=r"labels/000000\.png: label id 200 outside 0\.\.\d+ .*another label table"):
        seq[0]
    t = np.arange(2) * 0.1
    write_tum_folder(tmp_path / "tum", t, t)
    write_label_image(tmp_path / "lab" / "000000.png", np.full((H, W), 250, np.uint8))
    tum = open_recording(tmp_path / "tum", labels=tmp_path / "lab", intrinsics=Intrinsics(W, H, 50, 50, 32, 24, 5000.0))
    with pytest.raises(ValueError, match=r"lab/000000\.png: label id 250 outside"):
        tum[0]


def test_evaluate_refuses_a_map_of_another_label_table(tmp_path, capsys):
    from semmatch.cli import main
    from semmatch.io import SemanticMap, write_map

    pts = np.random.default_rng(0).uniform(0, 2, (4000, 3)).astype(np.float32)
    write_map(tmp_path / "gt.ply", SemanticMap(pts, np.where(pts[:, 0] < 1, 1, 2).astype(np.uint8)))
    write_map(tmp_path / "other.ply", SemanticMap(pts, np.where(pts[:, 0] < 1, 5, 6).astype(np.uint8)))
    assert main(["evaluate", str(tmp_path / "gt.ply"), str(tmp_path / "other.ply")]) == 2
    err = capsys.readouterr().err
    assert "other.ply: its labels (" in err and "have no label in common" in err and "another label table" in err
    assert main(["evaluate", str(tmp_path / "gt.ply"), str(tmp_path / "gt.ply"), "--json"]) == 0  # same table
