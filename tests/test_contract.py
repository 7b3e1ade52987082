"""The data contract: labels, geometry, sequences, TUM poses, PLY maps."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.io import (
    SemanticMap,
    SequenceWriter,
    read_map,
    read_sequence,
    read_tum,
    write_map,
    write_tum,
)
from semmatch.io import geometry as g
from semmatch.io import labels as L


def random_pose(rng) -> np.ndarray:
    q = rng.normal(size=4)
    T = np.eye(4)
    T[:3, :3] = g.quat_to_rotation(q)
    T[:3, 3] = rng.uniform(-5, 5, 3)
    return T


def test_palette_round_trip():
    ids = np.arange(L.NUM_CLASSES, dtype=np.uint8)
    back, n_bad = L.colors_to_labels(L.labels_to_colors(ids))
    assert n_bad == 0 and (back == ids).all()
    assert L.id_of("sofa") == 10 and L.EVAL_CLASSES == tuple(range(1, 11))
    # the authors' shared sink/oven colour reads as sink
    assert L.colors_to_labels(np.array([[70, 72, 115]]))[0][0] == L.id_of("sink")


def test_unknown_colours_warn_and_read_void():
    cols = np.array([[119, 119, 119], [1, 2, 3], [4, 5, 6]], dtype=np.uint8)
    with pytest.warns(UserWarning, match="2 of 3 colours in x.ply"):
        lab, n = L.colors_to_labels(cols, source="x.ply")
    assert n == 2 and lab.tolist() == [1, 0, 0]


def test_backproject_then_project_returns_pixels(rng):
    intr = g.DEFAULT_INTRINSICS
    depth = rng.uniform(0.3, 8.0, intr.shape).astype(np.float32)
    depth[::7, ::5] = 0  # holes
    pose = random_pose(rng)
    pts, idx = g.backproject(depth, intr, pose)
    uv, z = g.project(pts, intr, pose)
    v, u = np.divmod(idx, intr.width)
    assert np.abs(uv[:, 0] - u).max() < 1e-2 and np.abs(uv[:, 1] - v).max() < 1e-2
    assert np.allclose(z, depth.reshape(-1)[idx], rtol=1e-5)
    assert len(pts) == int((depth > 0).sum())


def test_intrinsics_validation():
    with pytest.raises(ValueError, match="focal length fx must be > 0"):
        g.Intrinsics(fx=0)
    with pytest.raises(ValueError, match="focal length fy"):
        g.Intrinsics(fy=-3)


def test_pose_validation():
    T = np.eye(4)
    T[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        g.check_pose(T)
    S = np.eye(4)
    S[0, 0] = 2
    with pytest.raises(ValueError, match="not a rotation"):
        g.check_pose(S)


def test_tum_round_trip(tmp_path, rng):
    poses = np.stack([random_pose(rng) for _ in range(20)])
    stamps = np.arange(20) * 0.033 + 1000.0
    write_tum(tmp_path / "p.txt", stamps, poses)
    t2, p2 = read_tum(tmp_path / "p.txt")
    assert np.allclose(t2, stamps, atol=1e-6)
    assert np.allclose(p2, poses, atol=1e-7)


def test_tum_reader_names_bad_line(tmp_path):
    (tmp_path / "p.txt").write_text("# c\n0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n")
    with pytest.raises(ValueError, match=r"p.txt:3: expected 8 values"):
        read_tum(tmp_path / "p.txt")


def _write_seq(path, n=3, rng=None, **kw):
    rng = rng or np.random.default_rng(1)
    intr = g.Intrinsics(64, 48, 50.0, 50.0, 32.0, 24.0)
    frames = []
    with SequenceWriter(path, intr, **kw) as w:
        for _ in range(n):
            rgb = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
            depth = np.round(rng.uniform(0.5, 4.0, (48, 64)), 3).astype(np.float32)
            lab = rng.integers(0, 21, (48, 64), dtype=np.uint8)
            pose = random_pose(rng)
            w.add(rgb, depth, pose, labels=lab)
            frames.append((rgb, depth, lab, pose))
    return intr, frames


def test_sequence_round_trip(tmp_path):
    intr, frames = _write_seq(tmp_path / "seq")
    seq = read_sequence(tmp_path / "seq")
    assert len(seq) == 3 and seq.intrinsics == intr
    for i in (2, 0, -1):
        f = seq[i]
        rgb, depth, lab, pose = frames[i]
        assert (f.rgb == rgb).all() and (f.labels == lab).all()
        assert np.abs(f.depth - depth).max() < 1e-3 + 1e-6
        assert np.allclose(f.pose, pose, atol=1e-6)


def test_loaded_sequence_matches_reader_and_is_read_only(tmp_path):
    _write_seq(tmp_path / "seq", n=4)
    seq = read_sequence(tmp_path / "seq")
    mem = seq.load()
    assert len(mem) == 4 and mem.intrinsics == seq.intrinsics and mem.path == seq.path
    assert np.array_equal(mem.poses, seq.poses)
    for i in (0, 3, -1):
        a, b = seq[i], mem[i]
        assert b.index == a.index and np.array_equal(b.rgb, a.rgb) and np.array_equal(b.depth, a.depth)
        assert np.array_equal(mem.read_labels(i), seq.read_labels(i)) and np.array_equal(b.pose, a.pose)
    assert [f.index for f in mem[1:3]] == [1, 2] and [f.index for f in mem] == [0, 1, 2, 3]
    with pytest.raises(ValueError, match="read-only"):
        mem[0].depth[0, 0] = 1.0
    with pytest.raises(IndexError, match="out of range"):
        mem[4]


def test_sequence_writer_refuses_existing_and_interrupted_leaves_nothing(tmp_path):
    _write_seq(tmp_path / "seq")
    with pytest.raises(FileExistsError, match="already holds another sequence"):
        _write_seq(tmp_path / "seq")
    with pytest.raises(RuntimeError):
        with SequenceWriter(tmp_path / "seq2", g.Intrinsics(64, 48, 50, 50, 32, 24)) as w:
            w.add(np.zeros((48, 64, 3), np.uint8), np.ones((48, 64)), np.eye(4))
            raise RuntimeError("interrupted")
    assert not (tmp_path / "seq2").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["seq"]


def test_sequence_reader_names_missing_frame(tmp_path):
    _write_seq(tmp_path / "seq")
    (tmp_path / "seq" / "depth" / "000001.png").unlink()
    with pytest.raises(ValueError, match=r"depth/ does not match poses.txt: frame 1"):
        read_sequence(tmp_path / "seq")


@pytest.mark.parametrize("binary", [True, False])
def test_map_round_trip(tmp_path, rng, binary):
    pts = rng.normal(size=(50, 3)).astype(np.float32)
    lab = rng.integers(0, 21, 50).astype(np.uint8)
    faces = rng.integers(0, 50, (20, 3))
    write_map(tmp_path / "m.ply", SemanticMap(pts, lab, faces=faces), binary=binary)
    m = read_map(tmp_path / "m.ply")
    assert np.allclose(m.points, pts) and (m.labels == lab).all() and (m.faces == faces).all()
    # the binary mesh is byte for byte what plyfile itself writes (faces go out as one block)
    import io

    from plyfile import PlyData

    buf = io.BytesIO()
    PlyData.read(str(tmp_path / "m.ply")).write(buf)
    assert buf.getvalue() == (tmp_path / "m.ply").read_bytes()
    normals = rng.normal(size=(50, 3))
    write_map(tmp_path / "n.ply", SemanticMap(pts, lab, faces=faces, normals=normals), binary=binary)
    n = PlyData.read(str(tmp_path / "n.ply"))
    assert np.allclose(n["vertex"]["nx"], normals[:, 0], atol=1e-6) and len(n["face"]) == 20


def test_map_without_labels_or_colours_is_refused(tmp_path):
    (tmp_path / "bad.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n0 0 0\n"
    )
    with pytest.raises(ValueError, match="bad.ply: PLY has neither vertex colours nor a 'label'"):
        read_map(tmp_path / "bad.ply")


def test_replica_map_reads_with_palette(shared_dir):
    import warnings

    path = shared_dir / "scenes/replica/office_3/high_3d_neighbor_using_GT_mesh_0_noise.ply"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = read_map(path)
    assert m.is_mesh and len(m) > 10000
    assert set(np.unique(m.labels)) & set(L.EVAL_CLASSES)


def test_label_pngs_are_palette_images_read_back_id_exact(tmp_path):
    from PIL import Image

    from semmatch.io import read_label_image, write_image, write_label_image
    from semmatch.io.labels import NUM_CLASSES, PALETTE

    lab = (np.arange(6 * 7).reshape(6, 7) % NUM_CLASSES).astype(np.uint8)
    write_label_image(tmp_path / "l.png", lab)
    with Image.open(tmp_path / "l.png") as img:
        assert img.mode == "P"  # viewers show the palette colours
        shown = np.asarray(img.convert("RGB"))
    np.testing.assert_array_equal(shown, PALETTE[lab])
    np.testing.assert_array_equal(read_label_image(tmp_path / "l.png"), lab)
    # older grayscale label PNGs still read as ids
    write_image(tmp_path / "g.png", lab)
    np.testing.assert_array_equal(read_label_image(tmp_path / "g.png"), lab)
    # an RGB image is no label image
    write_image(tmp_path / "rgb.png", np.zeros((6, 7, 3), np.uint8))
    with pytest.raises(ValueError, match="8-bit single-channel or palette"):
        read_label_image(tmp_path / "rgb.png")


def test_maps_are_written_in_canonical_order(tmp_path):
    """With canonical=True the same content in another vertex/triangle order gives the same bytes
    (reconstructions are deterministic in content, not in order)."""
    from semmatch.io import SemanticMap, read_map, write_map

    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1, (50, 3)).astype(np.float32)
    faces = rng.integers(0, 50, (80, 3))
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    lab = rng.integers(0, 5, 50).astype(np.uint8)
    a = SemanticMap(pts, lab, faces=faces, instances=np.arange(50))
    perm = rng.permutation(50)
    inv = np.argsort(perm)
    rolled = np.roll(inv[faces], 1, axis=1)[rng.permutation(len(faces))]  # same triangles, same orientation
    b = SemanticMap(pts[perm], lab[perm], faces=rolled, instances=np.arange(50)[perm])
    write_map(tmp_path / "a.ply", a, canonical=True)
    write_map(tmp_path / "b.ply", b, canonical=True)
    assert (tmp_path / "a.ply").read_bytes() == (tmp_path / "b.ply").read_bytes()
    back = read_map(tmp_path / "a.ply")
    assert len(back.faces) == len(a.faces)
    def triangles(m):
        return sorted(tuple(sorted(map(tuple, (m.points[f] * 1e4).round().astype(int).tolist()))) for f in m.faces)

    assert triangles(back) == triangles(a)
    assert dict(zip(map(tuple, back.points.tolist()), back.instances.tolist())) == \
        dict(zip(map(tuple, a.points.tolist()), a.instances.tolist()))


def test_ply_claiming_more_elements_than_it_holds_is_refused_before_parsing(tmp_path):
    from semmatch.io import read_map

    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            "property float z\nproperty uchar label\nelement face 300000000\n"
            "property list uchar int vertex_indices\nend_header\n")
    (tmp_path / "bomb.ply").write_bytes(head.encode() + bytes(3 * 13))
    with pytest.raises(ValueError, match="claims 300,000,000 face elements"):
        read_map(tmp_path / "bomb.ply")
    ascii_head = "ply\nformat ascii 1.0\nelement vertex 1000\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    (tmp_path / "short.ply").write_text(ascii_head + "0 0 0\n")
    with pytest.raises(ValueError, match="truncated or corrupt"):
        read_map(tmp_path / "short.ply")


def test_out_of_memory_is_a_clear_error_not_a_traceback(monkeypatch, capsys):
    from semmatch import cli

    def boom(args):
        raise MemoryError

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    for action in parser._subparsers._group_actions[0].choices.values():
        action.set_defaults(func=boom)
    assert cli.main(["evaluate", "a.ply", "b.ply"]) == 2
    assert "out of memory" in capsys.readouterr().err


def _frame(**changes):
    import dataclasses

    from semmatch.io import Frame

    intr = g.Intrinsics(160, 120, 100.0, 100.0, 80.0, 60.0)
    f = Frame(np.zeros((120, 160, 3), np.uint8), np.full((120, 160), 2.0, np.float32), None, np.eye(4), intr, index=4)
    return dataclasses.replace(f, **changes)


@pytest.mark.parametrize("bad, message", [
    (dict(depth=np.full((120, 160), 2000.0, np.float32)), r"frame 4: median depth is 2000 m.*wrong unit"),
    (dict(depth=np.full((120, 160), 2000, np.uint16)), r"frame 4: depth must be float metres, got dtype uint16"),
    (dict(depth=np.full((119, 160), 2.0, np.float32)), r"frame 4: depth is 160x119 \(WxH\) but the intrinsics say 160x120"),
    (dict(rgb=np.zeros((120, 159, 3), np.uint8)), r"frame 4: RGB is 159x120 \(WxH\) but the intrinsics say 160x120"),
    (dict(rgb=np.zeros((120, 160), np.uint8)), r"frame 4: expected an \(H,W,3\) RGB image, got shape \(120, 160\)"),
    (dict(rgb=np.zeros((120, 160, 3), np.float32)), r"frame 4: expected uint8 RGB, got dtype float32"),
])
def test_transfer_and_fusion_refuse_a_frame_alike(bad, message):
    """The frame contract (semmatch.io.contract) is one check: label transfer and fusion refuse
    the same frame with the same message."""
    from semmatch.fusion import SemanticTSDF
    from semmatch.transfer.frames import check_frame

    f = _frame(**bad)
    with pytest.raises(ValueError, match=message):
        check_frame(f)
    with pytest.raises(ValueError, match=message):
        SemanticTSDF(0.05).integrate(f.depth, f.rgb, f.pose, f.intrinsics, where="frame 4")


def test_frame_contract_cleans_depth_and_checks_labels():
    from semmatch.io import check_depth, check_intrinsics, check_labels, check_rgb

    d = np.full((4, 6), 2.0, np.float32)
    assert check_depth(d, (4, 6)) is d  # clean float32 depth is not copied
    d[0, :3] = [np.nan, np.inf, -1.0]
    out = check_depth(d, (4, 6))
    assert (out[0, :3] == 0).all() and (out[1:] == 2.0).all() and out.dtype == np.float32
    assert check_depth(np.full((4, 6), 2000.0), (4, 6), units=False).max() == 2000.0
    with pytest.raises(ValueError, match=r"depth\[0\]: depth is 6x3 \(WxH\) but the RGB image is 6x4"):
        check_depth(np.ones((3, 6)), (4, 6), where="depth[0]", against="the RGB image is")
    assert check_rgb(np.full((4, 6, 3), 0.5), floats=True).dtype == np.float64
    for img, msg in ((np.full((4, 6, 3), 2.0), r"\[0, 1\]"), (np.full((4, 6, 3), np.nan), "NaN"),
                     (np.zeros((4, 6, 3), np.uint16), r"uint8 \(or float in \[0, 1\]\) RGB, got dtype uint16")):
        with pytest.raises(ValueError, match=msg):
            check_rgb(img, floats=True)
    with pytest.raises(ValueError, match="no RGB image"):
        check_rgb(None)
    with pytest.raises(ValueError, match="intrinsics must be a semmatch.io.geometry.Intrinsics, got tuple"):
        check_intrinsics((160, 120))
    ids = np.arange(24, dtype=np.uint8).reshape(4, 6)
    np.testing.assert_array_equal(check_labels(ids, (4, 6), n_classes=41, stride=2), ids[::2, ::2].ravel())
    assert check_labels(np.full((4, 6, 3), 1 / 3), (4, 6), n_classes=3).shape == (24, 3)
    for lab, msg in ((ids, "label id 23 outside 0..9"), (ids.astype(float), "must be integers"),
                     (ids[:3], r"\(H,W\)=\(4, 6\), got \(3, 6\)"), (np.full((4, 6, 3), -1.0), "negative")):
        with pytest.raises(ValueError, match=msg):
            check_labels(lab, (4, 6), n_classes=10 if lab.ndim == 2 else 3)
