"""semmatch.fusion: semantic TSDF on Open3D's VoxelBlockGrid (geometry, label evidence, I/O)."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.fusion import (
    SemanticTSDF,
    check_depth_units,
    extract,
    fuse_sequence,
    reconstruct,
    reconstruct_many,
)
from semmatch.io import Frame, SequenceWriter, read_map, read_sequence, write_labels_folder, write_map
from semmatch.io.geometry import DEFAULT_INTRINSICS, look_at
from semmatch.io.labels import NUM_CLASSES
from semmatch.sim import Renderer, box_room

INTR = DEFAULT_INTRINSICS.scaled(160, 120)
SIZE = (4.0, 3.0, 2.5)
VS = 0.05


@pytest.fixture(scope="module")
def room_frames() -> list[Frame]:
    """A camera in the middle of a 4 x 3 x 2.5 m box room turning round, tilted up and down."""
    scene = box_room(SIZE)
    r = Renderer(scene, INTR)
    frames = []
    centre = np.array([2.0, 1.5, 1.25])
    for i, a in enumerate(np.linspace(0, 2 * np.pi, 16, endpoint=False)):
        tilt = (-0.9, 0.0, 0.9)[i % 3]
        target = centre + [np.cos(a), np.sin(a), tilt]
        pose = look_at(centre, target)
        res = r.render(pose)
        frames.append(Frame(res.rgb, res.depth, res.labels, pose, INTR, index=i))
    return frames


def nearest_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance to the nearest box face, its label, and the distance to the second nearest."""
    W, D, H = SIZE
    x, y, z = points.T
    d = np.stack([x, W - x, y, D - y, z, H - z], axis=1)
    lab = np.array([1, 1, 1, 1, 2, 3])
    order = np.argsort(d, axis=1)
    rows = np.arange(len(points))
    return d[rows, order[:, 0]], lab[order[:, 0]], d[rows, order[:, 1]]


def test_box_room_walls_within_one_voxel_with_right_labels(room_frames):
    m = reconstruct(room_frames, voxel_size=VS)
    assert m.is_mesh and len(m) > 1000
    dist, lab, second = nearest_plane(m.points.astype(np.float64))
    assert np.percentile(dist, 99) < VS and dist.max() < 2 * VS
    clear = second > 2 * VS  # away from the room's edges, where two faces meet
    assert clear.mean() > 0.8
    acc = (m.labels[clear] == lab[clear]).mean()
    assert acc > 0.98, acc
    # all three classes are present, nothing outside them
    assert set(np.unique(m.labels)) <= {0, 1, 2, 3} and {1, 2, 3} <= set(np.unique(m.labels))
    assert m.colors is not None and m.colors.dtype == np.uint8 and m.normals is not None
    seen_rgb = np.concatenate([f.rgb[f.depth > 0] for f in room_frames]).mean(axis=0)
    assert np.abs(m.colors.mean(axis=0) - seen_rgb).max() < 20  # the RGB mesh keeps the colours


def test_conflicting_evidence_resolves_to_majority(room_frames):
    f = room_frames[1]
    a = np.where(f.depth > 0, 4, 0).astype(np.uint8)  # chair
    b = np.where(f.depth > 0, 9, 0).astype(np.uint8)  # bed
    for order in ([a, b, a, b, a], [b, b, a, a, a]):  # 3 x chair vs 2 x bed, any order
        vol = SemanticTSDF(VS, label_stride=1)
        for lab in order:
            vol.integrate(f.depth, f.rgb, f.pose, INTR, labels=lab)
        m = vol.extract_mesh()
        seen = m.labels > 0
        assert seen.mean() > 0.9 and (m.labels[seen] == 4).all()
    # probabilities: two confident "bed" frames beat one confident "chair" frame
    p_bed = np.full(f.depth.shape + (21,), 0.01, np.float32)
    p_bed[..., 9] = 0.8
    p_chair = np.full(f.depth.shape + (21,), 0.01, np.float32)
    p_chair[..., 4] = 0.8
    m = reconstruct([f, f, f], labels=[p_chair, p_bed, p_bed], voxel_size=VS)
    seen = m.labels > 0
    assert seen.mean() > 0.9 and (m.labels[seen] == 9).all()


def test_labels_from_folder_and_outputs(tmp_path, room_frames):
    seq_dir = tmp_path / "seq"
    with SequenceWriter(seq_dir, INTR) as w:
        for f in room_frames[:6]:
            w.add(f.rgb, f.depth, f.pose, labels=f.labels)
    # a labels folder that says "sofa" everywhere replaces the sequence's own labels
    write_labels_folder(tmp_path / "sofa", [np.full(INTR.shape, 10, np.uint8)] * 6)
    out, rgb_out, pts_out = tmp_path / "m.ply", tmp_path / "rgb.ply", tmp_path / "p.ply"
    vol = fuse_sequence(read_sequence(seq_dir), labels=tmp_path / "sofa", voxel_size=VS)
    m = extract(vol)
    write_map(out, m)
    write_map(rgb_out, m, colors="rgb")
    write_map(pts_out, extract(vol, "points"))
    back = read_map(out)
    assert len(back) == len(m) and back.is_mesh and set(np.unique(back.labels)) <= {0, 10}
    assert (back.labels == 10).mean() > 0.9
    rgb = read_map(rgb_out, require_labels=False)
    assert (rgb.labels == back.labels).all()  # the label property wins over the RGB colours
    assert len(read_map(pts_out)) > 100
    # the frames decoded once into memory fuse to the same map (vertex order may differ)
    mem = reconstruct(read_sequence(seq_dir).load(), labels=tmp_path / "sofa", voxel_size=VS)
    o_m, o_mem = np.lexsort(m.points.T), np.lexsort(mem.points.T)
    assert np.allclose(m.points[o_m], mem.points[o_mem]) and (m.labels[o_m] == mem.labels[o_mem]).all()
    with pytest.raises(ValueError, match="5 images for 6 frames"):
        write_labels_folder(tmp_path / "short", [np.zeros(INTR.shape, np.uint8)] * 5)
        reconstruct(read_sequence(seq_dir), labels=tmp_path / "short")


def _same_map(a, b) -> bool:
    """Equal vertices (in any order) with equal labels."""
    oa, ob = np.lexsort(a.points.T), np.lexsort(b.points.T)
    return (len(a) == len(b) and np.allclose(a.points[oa], b.points[ob], atol=1e-5)
            and bool((a.labels[oa] == b.labels[ob]).all()))


def test_reconstruct_many_equals_one_fusion_per_labeling(tmp_path, room_frames):
    rng = np.random.default_rng(3)
    frames = room_frames[:10]
    noisy = [rng.integers(0, 4, INTR.shape, dtype=np.uint8) for _ in frames]  # votes that disagree
    probs = [rng.dirichlet(np.ones(NUM_CLASSES), INTR.shape).astype(np.float32) for _ in frames]
    write_labels_folder(tmp_path / "noisy", noisy)
    poses = np.stack([f.pose for f in frames])
    poses[:, 0, 3] += np.linspace(0, 0.1, len(frames))  # other poses than the frames' own
    labelings = [None, tmp_path / "noisy", probs, [np.zeros(INTR.shape, np.uint8)] * len(frames)]
    outs = [tmp_path / "own.ply", None, tmp_path / "probs.ply", None]
    # a small grid grows while fusing: the voxel lookups must survive the moved blocks
    with pytest.warns(UserWarning, match="no label evidence"):
        many = reconstruct_many(frames, labelings, VS, poses=poses, outs=outs, block_count=16)
        singles = [reconstruct(frames, lab, VS, poses=poses, block_count=16) for lab in labelings]
    assert len(many) == 4
    for m, one in zip(many, singles, strict=True):
        assert _same_map(m, one) and m.faces.shape == one.faces.shape
    assert (many[3].labels == 0).all() and len(np.unique(many[1].labels)) > 1
    assert _same_map(read_map(tmp_path / "own.ply"), many[0]) and _same_map(read_map(tmp_path / "probs.ply"), many[2])
    assert not (tmp_path / "noisy.ply").exists()
    assert reconstruct_many(frames, [], VS) == []
    with pytest.raises(ValueError, match="2 output paths for 1 labelings"):
        reconstruct_many(frames, [None], VS, outs=[None, None])
    write_labels_folder(tmp_path / "short", noisy[:9])
    with pytest.raises(ValueError, match="short: labels folder has 9 images for 10 frames"):
        reconstruct_many(frames, [None, tmp_path / "short"], VS)
    with pytest.raises(ValueError, match="frame 2: label id 30"):
        reconstruct_many(frames[:3], [[f.labels for f in frames[:2]] + [np.full(INTR.shape, 30, np.uint8)]], VS)
    with pytest.raises(ValueError, match="more label images than the 2 frames"):
        reconstruct_many(frames[:2], [noisy[:3]], VS)
    write_labels_folder(tmp_path / "bad", [noisy[0], np.full(INTR.shape, 30, np.uint8)])
    with pytest.raises(ValueError, match=r"bad \(sequence frame 1\): label id 30"):
        reconstruct_many(frames[:2], [None, tmp_path / "bad"], VS)


def test_bad_input_is_named(room_frames):
    f = room_frames[0]
    no_pose = Frame(f.rgb, f.depth, f.labels, None, INTR, index=7)
    with pytest.raises(ValueError, match="frame 7: no pose"):
        reconstruct([no_pose])
    mm = Frame(f.rgb, f.depth * 1000, f.labels, f.pose, INTR, index=3)
    with pytest.raises(ValueError, match="frame 3: median depth .* wrong unit"):
        reconstruct([mm])
    with pytest.raises(ValueError, match="label id 30"):
        reconstruct([f], labels=[np.full(INTR.shape, 30, np.uint8)])
    with pytest.raises(ValueError, match="labels end at frame 1"):
        reconstruct([f, f], labels=[f.labels])
    with pytest.raises(ValueError, match="no frames"):
        reconstruct([])
    with pytest.raises(ValueError, match="wrong unit"):
        check_depth_units(np.full((10, 10), 2000.0))
    assert check_depth_units(np.full((10, 10), 2.0)) == 2.0


def test_memory_follows_observed_surface(room_frames):
    vs = 0.02  # blocks of 8^3 voxels = 16 cm: the surface shell is far smaller than the volume
    one = SemanticTSDF(vs, n_classes=4)
    f = room_frames[0]
    one.integrate(f.depth, f.rgb, f.pose, INTR, labels=f.labels)
    full = SemanticTSDF(vs, n_classes=4)
    for g in room_frames:
        full.integrate(g.depth, g.rgb, g.pose, INTR, labels=g.labels)
    block = vs * 8
    volume_blocks = np.prod(np.ceil(np.array(SIZE) / block) + 1)
    assert one.n_blocks < full.n_blocks < 0.6 * volume_blocks


def test_growing_the_grid_keeps_every_voxel(room_frames):
    small = SemanticTSDF(VS, block_count=16)  # grows several times
    big = SemanticTSDF(VS, block_count=4096)
    for f in room_frames[:8]:
        for vol in (small, big):
            vol.integrate(f.depth, f.rgb, f.pose, INTR, labels=f.labels)
    assert small.n_blocks == big.n_blocks
    a, b = small.extract_mesh(), big.extract_mesh()
    assert len(a) == len(b)
    order_a = np.lexsort(a.points.T)
    order_b = np.lexsort(b.points.T)
    assert np.allclose(a.points[order_a], b.points[order_b], atol=1e-5)
    assert (a.labels[order_a] == b.labels[order_b]).all()


def test_reconstruct_cli(tmp_path, room_frames, capsys):
    from semmatch.cli import main

    seq_dir = tmp_path / "seq"
    with SequenceWriter(seq_dir, INTR) as w:
        for f in room_frames[:6]:
            w.add(f.rgb, f.depth, f.pose, labels=f.labels)
    rc = main(["reconstruct", str(seq_dir), "--out", str(tmp_path / "m.ply"), "--rgb-out",
               str(tmp_path / "rgb.ply"), "--voxel-size", "0.05", "--quiet", "--json"])
    assert rc == 0 and '"vertices"' in capsys.readouterr().out
    m = read_map(tmp_path / "m.ply")
    assert m.is_mesh and {1, 2, 3} <= set(np.unique(m.labels))
    rc = main(["reconstruct", str(tmp_path / "nothing"), "--out", str(tmp_path / "x.ply")])
    assert rc == 2 and "nothing: no such" in capsys.readouterr().err  # names the folder


def test_bench_fusion_json_with_labelings(capsys):
    import json

    from semmatch.cli import main

    assert main(["bench", "fusion", "--json", "--frames", "3", "--width", "160", "--height", "120",
                 "--labelings", "2"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["frames"] == 3 and res["fps"] > 0 and res["mesh_vertices"] > 0
    assert res["labelings"] == 2 and res["separate_seconds"] > 0 and res["many_seconds"] > 0


def test_sensor_dropouts_are_skipped_with_one_warning(room_frames):
    import dataclasses
    import warnings

    frames = list(room_frames)
    dropped = [dataclasses.replace(f, depth=np.zeros_like(f.depth)) if i in (1, 2) else f for i, f in enumerate(frames)]
    with pytest.warns(UserWarning, match="2 of .* frame\\(s\\) had \\(almost\\) no valid depth") as rec:
        m = reconstruct(dropped, voxel_size=0.05)
    assert sum("no valid depth" in str(w.message) for w in rec) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        many = reconstruct_many(dropped, [None, None], 0.05)
    assert len(m) > 0 and len(many[0]) == len(many[1]) > 0
    with pytest.raises(ValueError, match="none of its .* frame\\(s\\) has usable depth"):
        reconstruct([dataclasses.replace(f, depth=np.zeros_like(f.depth)) for f in frames], voxel_size=0.05)


def test_reconstructions_are_byte_deterministic(tmp_path):
    """Open3D's hash map orders blocks differently on every run; the maps come out canonical."""
    import hashlib

    from scenes import furnished_room as box_room
    from scenes import orbit_poses

    from semmatch.fusion import reconstruct
    from semmatch.io.geometry import DEFAULT_INTRINSICS
    from semmatch.sim import render_frames

    scene = box_room(0)
    frames = render_frames(scene, orbit_poses(scene, 4, 1.2, 3), DEFAULT_INTRINSICS.scaled(160, 120))
    digests = set()
    for k in range(3):
        write_map(tmp_path / f"m{k}.ply", reconstruct(frames, voxel_size=0.05))
        digests.add(hashlib.sha256((tmp_path / f"m{k}.ply").read_bytes()).hexdigest())
    assert len(digests) == 1
