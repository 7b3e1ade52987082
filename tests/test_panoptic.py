"""Panoptic transfer: instance layers, transfer of instance ids, fusion, panoptic quality."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.io import Frame, SemanticMap, SequenceWriter, read_map, write_map
from semmatch.io.geometry import Intrinsics
from semmatch.transfer.panoptic import (
    PanopticFrame,
    fuse_instances,
    panoptic_quality,
    panoptic_voxels,
    segment_instances,
    transfer_panoptic,
)

CHAIR, TABLE, WALL = 4, 5, 1


def _voxel_map(labels, instances, voxel=0.05) -> SemanticMap:
    """One point at the centre of voxel (i, 0, 0) per entry."""
    n = len(labels)
    pts = np.zeros((n, 3), np.float32)
    pts[:, 0] = (np.arange(n) + 0.5) * voxel
    pts[:, 1:] = 0.5 * voxel
    return SemanticMap(pts, np.asarray(labels, np.uint8), instances=np.asarray(instances, np.int32))


def _gt():
    # chair A = voxels 0..9, chair B = 10..19, wall = 20..39
    labels = [CHAIR] * 20 + [WALL] * 20
    inst = [1] * 10 + [2] * 10 + [0] * 20
    return _voxel_map(labels, inst)


def test_pq_of_a_map_against_itself_is_one():
    gt = _gt()
    q = panoptic_quality(gt, gt)
    assert q["pq"] == q["pq_things"] == q["pq_stuff"] == 1.0
    assert q["per_class"]["chair"]["tp"] == 2 and q["per_class"]["chair"]["fp"] == 0


def test_pq_of_a_split_is_the_hand_computed_value():
    # chair A split into 7 + 3 voxels (ids 5, 6); chair B exact (id 7)
    pred = _voxel_map([CHAIR] * 20 + [WALL] * 20, [5] * 7 + [6] * 3 + [7] * 10 + [0] * 20)
    q = panoptic_quality(_gt(), pred)
    c = q["per_class"]["chair"]
    assert (c["tp"], c["fp"], c["fn"]) == (2, 1, 0)
    assert c["sq"] == pytest.approx((0.7 + 1.0) / 2)
    assert c["rq"] == pytest.approx(2 / 2.5)
    assert q["pq_things"] == pytest.approx(0.85 * 0.8)
    assert q["pq_stuff"] == 1.0
    assert q["pq"] == pytest.approx((0.68 + 1.0) / 2)


def test_pq_of_a_merge_is_zero_for_the_class():
    # both chairs as one instance: IoU 10/20 = 0.5 with each, not above the threshold
    pred = _voxel_map([CHAIR] * 20 + [WALL] * 20, [3] * 20 + [0] * 20)
    c = panoptic_quality(_gt(), pred)["per_class"]["chair"]
    assert (c["tp"], c["fp"], c["fn"], c["pq"]) == (0, 1, 2, 0.0)


def test_prediction_on_ignored_ground_truth_is_no_false_positive():
    # ground truth: chair voxels 0..9 without an instance (ignored), a table 10..19
    gt = _voxel_map([CHAIR] * 10 + [TABLE] * 10, [0] * 10 + [4] * 10)
    pred = _voxel_map([CHAIR] * 10 + [TABLE] * 10, [9] * 10 + [4] * 10)
    q = panoptic_quality(gt, pred)
    assert "chair" not in q["per_class"]
    assert q["per_class"]["table"]["pq"] == 1.0


def test_panoptic_voxels_take_the_majority_instance_of_the_majority_class():
    pts = np.full((5, 3), 0.025, np.float32)
    m = SemanticMap(pts, np.array([CHAIR, CHAIR, CHAIR, TABLE, TABLE], np.uint8),
                    instances=np.array([3, 3, 8, 2, 2], np.int32))
    v = panoptic_voxels(m)
    assert v.labels.tolist() == [CHAIR] and v.instances.tolist() == [3]
    assert v.segment.tolist() == [(CHAIR << 32) | 3]


def test_maps_without_instances_are_refused_clearly(tmp_path):
    m = SemanticMap(np.zeros((3, 3), np.float32), np.array([4, 4, 4], np.uint8))
    with pytest.raises(ValueError, match="no instance layer"):
        panoptic_voxels(m)
    with pytest.raises(ValueError, match="no instance layer"):
        transfer_panoptic("3d-neighborhood", _dummy_frame(), m)


def _dummy_frame():
    intr = Intrinsics(8, 6, 5.0, 5.0, 4.0, 3.0)
    return Frame(np.zeros((6, 8, 3), np.uint8), np.ones((6, 8), np.float32), None, np.eye(4), intr)


def test_ply_round_trip_keeps_instances(tmp_path):
    m = _voxel_map([CHAIR, CHAIR, WALL], [7, 2**20, 0])
    back = read_map(write_map(tmp_path / "p.ply", m))
    assert back.instances.dtype == np.int32 and back.instances.tolist() == [7, 2**20, 0]
    plain = read_map(write_map(tmp_path / "s.ply", SemanticMap(m.points, m.labels)))
    assert plain.instances is None


def test_instance_ids_out_of_range_are_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="instance ids must lie in"):
        _voxel_map([CHAIR], [-1])
    from plyfile import PlyData, PlyElement

    arr = np.zeros(1, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("label", "u1"), ("instance", "u4")])
    arr["instance"] = 3_000_000_000  # beyond int32
    PlyData([PlyElement.describe(arr, "vertex")]).write(str(tmp_path / "big.ply"))
    with pytest.raises(ValueError, match="instance ids outside"):
        read_map(tmp_path / "big.ply")


def test_segment_instances_separates_two_chairs_and_leaves_stuff():
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 0.4, (300, 3))
    b = rng.uniform(0, 0.4, (300, 3)) + [1.5, 0, 0]
    wall = rng.uniform(0, 2, (300, 3)) * [1, 0.01, 1] + [0, 1.0, 0]
    m = SemanticMap(np.vstack([a, b, wall]), np.r_[[CHAIR] * 600, [WALL] * 300])
    out = segment_instances(m, eps=0.1, min_vertices=50)
    assert len(np.unique(out.instances[:300])) == 1 and len(np.unique(out.instances[300:600])) == 1
    assert out.instances[0] != out.instances[300] and out.instances[0] > 0
    assert (out.instances[600:] == 0).all()


# ----------------------------------------------------------------------------- a two-chair room
@pytest.fixture(scope="module")
def two_chair_room():
    from scenes import furnished_room as box_room
    from scenes import orbit_poses

    from semmatch.fusion import reconstruct
    from semmatch.sim import Renderer

    intr = Intrinsics(160, 120, 67.1, 67.1, 80.0, 60.0)
    scene = box_room(0)  # two chairs: instances 2 and 3
    assert sorted(set(scene.instances[scene.labels == CHAIR].tolist())) == [2, 3]
    r = Renderer(scene, intr)

    def frames(h, n, seed):
        out = []
        for i, T in enumerate(orbit_poses(scene, n, h, seed)):
            res = r.render(T)
            out.append((Frame(res.rgb, res.depth, res.labels, np.asarray(T), intr, index=i), res.instances))
        return out

    up, lo = frames(1.5, 24, 1), frames(0.3, 10, 2)
    upper = reconstruct([f for f, _ in up], voxel_size=0.03)
    upper = fuse_instances(upper, [PanopticFrame(f.depth, f.pose, intr, f.labels, i) for f, i in up], clean=False)
    return upper, lo


@pytest.mark.parametrize("method", ["3d-neighborhood", "3d-projected-sp", "dbscan"])
def test_instance_ids_survive_transfer(two_chair_room, method):
    upper, lower = two_chair_room
    assert {2, 3} <= set(upper.instances[upper.labels == CHAIR].tolist())
    agree, total = 0, 0
    for f, gt_inst in lower:
        lab, inst = transfer_panoptic(method, f, upper)
        assert inst.dtype == np.int32 and inst.shape == lab.shape
        assert (inst[~np.isin(lab, list(range(4, 21)))] == 0).all()  # stuff and void carry none
        sel = (lab == CHAIR) & (f.labels == CHAIR)
        agree += int((inst[sel] == gt_inst[sel]).sum())
        total += int(sel.sum())
    assert total > 500
    assert agree / total > 0.9


def test_group_methods_give_a_group_one_instance(two_chair_room):
    from semmatch.transfer import transfer_frame

    upper, lower = two_chair_room
    f = lower[0][0]
    groups = transfer_frame("3d-projected-sp", f, upper).groups
    lab, inst = transfer_panoptic("3d-projected-sp", f, upper)
    thing = inst > 0
    for g in np.unique(groups[thing]):
        assert len(np.unique(inst[thing & (groups == g)])) == 1


def test_lower_panoptic_fusion_with_ground_truth_instances_matches_itself(two_chair_room):
    from semmatch.fusion import reconstruct

    _, lower = two_chair_room
    ref = reconstruct([f for f, _ in lower], voxel_size=0.03)
    ev = [PanopticFrame(f.depth, f.pose, f.intrinsics, f.labels, i) for f, i in lower]
    ref = fuse_instances(ref, ev, clean=False)
    # chair 2 is seen from 0.6-2 m; chair 3 only from closer than the fusion's depth range
    assert set(ref.instances[ref.labels == CHAIR].tolist()) - {0} == {2}
    assert panoptic_quality(ref, ref)["pq"] == 1.0


def test_cli_reference_transfer_evaluate(two_chair_room, tmp_path, capsys):
    from semmatch.cli import main

    upper, lower = two_chair_room
    write_map(tmp_path / "upper.ply", upper)
    with SequenceWriter(tmp_path / "lower", lower[0][0].intrinsics) as w:
        for f, inst in lower:
            w.add(f.rgb, f.depth, f.pose, labels=f.labels, instances=inst.astype(np.uint16))
    assert main(["panoptic", "reference", "--sequence", str(tmp_path / "lower"), "--out",
                 str(tmp_path / "ref.ply"), "--voxel-size", "0.03"]) == 0
    assert main(["panoptic", "transfer", "--map", str(tmp_path / "upper.ply"), "--sequence",
                 str(tmp_path / "lower"), "--method", "3d-neighborhood", "--out", str(tmp_path / "nb.ply"),
                 "--voxel-size", "0.03", "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["panoptic", "evaluate", str(tmp_path / "ref.ply"), str(tmp_path / "nb.ply"),
                 str(tmp_path / "ref.ply")]) == 0
    out = capsys.readouterr().out
    assert "nb.ply" in out and "pq_things" in out
    assert read_map(tmp_path / "nb.ply").instances is not None
    # a map without instances asked for panoptic output: a clear error naming the file
    write_map(tmp_path / "plain.ply", SemanticMap(upper.points, upper.labels, faces=upper.faces))
    assert main(["panoptic", "transfer", "--map", str(tmp_path / "plain.ply"), "--sequence",
                 str(tmp_path / "lower"), "--method", "3d-neighborhood", "--out", str(tmp_path / "x.ply")]) == 2
    assert "no instance layer" in capsys.readouterr().err
    assert not (tmp_path / "x.ply").exists()
    # a sequence without instances/: a clear error before any fusion
    assert main(["panoptic", "segment", str(tmp_path / "plain.ply"), "--out", str(tmp_path / "seg.ply")]) == 0
    assert read_map(tmp_path / "seg.ply").instances.max() > 0
