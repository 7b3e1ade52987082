"""semmatch.evaluate.metrics: the paper's voxel measures (hand-counted cases), 2D pixel measures."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.evaluate.metrics import compare, compare_dict_loop, pixel_metrics, voxelize
from semmatch.io import SemanticMap, write_map

VS = 0.05


def at_voxels(keys, labels, *, per_voxel: int = 1, rng=None) -> SemanticMap:
    """Points inside the given voxels (``per_voxel`` each, jittered inside the voxel)."""
    keys = np.repeat(np.asarray(keys, dtype=np.float64), per_voxel, axis=0)
    labels = np.repeat(np.asarray(labels), per_voxel)
    off = 0.5 if rng is None else rng.uniform(0.1, 0.9, keys.shape)
    return SemanticMap((keys + off) * VS, labels)


def headline(s: dict) -> tuple:
    return tuple(round(s[k], 9) for k in ("jaccard", "sorensen", "color_acc", "mean_acc"))


def test_identical_maps_score_one(rng):
    m = at_voxels(rng.integers(0, 40, (300, 3)), rng.integers(1, 11, 300), per_voxel=3, rng=rng)
    s = compare(m, m, VS)
    assert headline(s) == (1.0, 1.0, 1.0, 1.0)
    assert s["counts"]["pred_outside_gt"] == 0
    assert np.trace(s["confusion"]) == s["counts"]["color"] == s["counts"]["intersection"]


def test_disjoint_maps_score_zero():
    a = at_voxels([[0, 0, 0], [1, 0, 0]], [1, 2])
    b = at_voxels([[5, 5, 5], [6, 5, 5]], [1, 2])
    s = compare(a, b, VS, min_overlap=0)
    assert s["jaccard"] == 0 and s["sorensen"] == 0 and s["mean_acc"] == 0
    assert s["counts"]["union"] == 4 and s["overlap"] == 0


def test_hand_counted_partial_overlap():
    v = [[i, 0, 0] for i in range(7)]
    # ground truth: v0 wall, v1 floor, v2 ceiling, v3 void, v4 oven (id 17, not evaluated)
    gt = at_voxels(v[:5], [1, 2, 3, 0, 17])
    # prediction: v0 wall (right), v1 table (wrong), v3 chair (GT has a void voxel there),
    # v4 floor (GT voxel of a non-evaluated class), v5 wall (outside GT), v6 void (ignored)
    pred = at_voxels([v[0], v[1], v[3], v[4], v[5], v[6]], [1, 5, 4, 2, 1, 0])
    # G = {v0,v1,v2}, O = {v0..v4}, P = {v0,v1,v3,v4,v5}, G∩P = {v0,v1}, C = {v0}, P\O = {v5}
    s = compare(gt, pred, VS, min_overlap=0)
    c = s["counts"]
    assert (c["gt"], c["pred"], c["gt_occupied"], c["intersection"], c["color"], c["pred_outside_gt"]) == (
        3, 5, 5, 2, 1, 1
    )
    assert s["jaccard"] == pytest.approx(1 / 4)
    assert s["sorensen"] == pytest.approx(2 / 8)
    assert s["color_acc"] == pytest.approx(1 / 2)
    assert s["mean_acc"] == pytest.approx((1 / 4 + 1 / 4 + 1 / 2) / 3)
    plain = compare(gt, pred, VS, union="plain", min_overlap=0)
    assert plain["jaccard"] == pytest.approx(1 / 6)  # |G ∪ P| = 3 + 5 - 2
    # confusion over G ∩ P: wall->wall, floor->table
    assert s["confusion"][0, 0] == 1 and s["confusion"][1, 4] == 1 and s["confusion"].sum() == 2
    assert s["per_class_iou"]["wall"] == 1.0 and s["per_class_iou"]["floor"] == 0.0
    assert np.isnan(s["per_class_iou"]["sofa"])
    assert headline(compare_dict_loop(gt, pred, VS)) == pytest.approx(headline(s))


def test_majority_label_per_voxel_ties_to_smallest_id():
    g = voxelize(SemanticMap(np.full((5, 3), 0.01), [3, 2, 3, 2, 5]), VS)
    assert g.labels.tolist() == [2]  # 2 and 3 tie with two votes each
    g = voxelize(SemanticMap(np.full((4, 3), 0.01), [7, 4, 7, 9]), VS)
    assert g.labels.tolist() == [7]


def test_invariant_to_point_order_and_duplication(rng):
    keys = rng.integers(0, 30, (400, 3))
    gt = at_voxels(keys, rng.integers(0, 21, 400), per_voxel=2, rng=rng)
    pred = at_voxels(keys + rng.integers(0, 2, keys.shape), rng.integers(0, 21, 400), per_voxel=2, rng=rng)
    ref = headline(compare(gt, pred, VS))
    perm = rng.permutation(len(pred.points))
    shuffled = SemanticMap(pred.points[perm], pred.labels[perm])
    doubled = SemanticMap(np.concatenate([pred.points] * 2), np.concatenate([pred.labels] * 2))
    assert headline(compare(gt, shuffled, VS)) == ref
    assert headline(compare(gt, doubled, VS)) == ref
    assert headline(compare_dict_loop(gt, pred, VS)) == pytest.approx(ref, abs=1e-12)


def test_transform_brings_prediction_into_gt_frame(rng):
    gt = at_voxels(rng.integers(0, 40, (500, 3)), rng.integers(1, 11, 500), rng=rng)
    T = np.eye(4)
    c, s_ = np.cos(0.7), np.sin(0.7)
    T[:3, :3] = [[c, -s_, 0], [s_, c, 0], [0, 0, 1]]
    T[:3, 3] = [10.0, -3.0, 1.0]
    moved = SemanticMap(gt.points @ T[:3, :3].T + T[:3, 3], gt.labels)
    with pytest.raises(ValueError, match="different units or frames"):
        compare(gt, moved, VS)
    s = compare(gt, moved, VS, transform=np.linalg.inv(T))
    assert s["mean_acc"] > 0.99


def test_bad_inputs_name_the_problem(tmp_path, rng):
    good = at_voxels(rng.integers(0, 40, (200, 3)), rng.integers(1, 11, 200))
    with pytest.raises(ValueError, match="empty"):
        compare(good, SemanticMap(np.zeros((0, 3)), np.zeros(0)), VS)
    bad = SemanticMap(good.points.copy(), good.labels, source="bad.ply")
    bad.points[3] = np.nan
    with pytest.raises(ValueError, match=r"bad.ply: 1 vertices hold NaN"):
        compare(good, bad, VS)
    # the same room in millimetres: overlap is meaningless, the numbers are in the message
    mm = SemanticMap(good.points * 1000, good.labels, source="mm.ply")
    with pytest.raises(ValueError, match=r"mm.ply vs .*overlap"):
        compare(good, mm, VS)
    # a PLY without colours or label
    from plyfile import PlyData, PlyElement

    arr = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    p = tmp_path / "plain.ply"
    PlyData([PlyElement.describe(arr, "vertex")]).write(str(p))
    with pytest.raises(ValueError, match="plain.ply: PLY has neither vertex colours nor a 'label'"):
        compare(p, good, VS)
    with pytest.raises(ValueError, match="union"):
        compare(good, good, VS, union="strange")


def test_reads_ply_paths_with_palette_colours(tmp_path, rng):
    m = at_voxels(rng.integers(0, 40, (200, 3)), rng.integers(1, 11, 200))
    write_map(tmp_path / "m.ply", m)
    assert compare(tmp_path / "m.ply", m, VS)["mean_acc"] == 1.0


def test_coarse_mesh_triangles_are_sampled():
    # one 1 m x 1 m wall square made of two triangles: 4 vertices, but ~400 voxels of surface
    pts = np.array([[0, 0.01, 0], [1, 0.01, 0], [1, 0.01, 1], [0, 0.01, 1]], dtype=np.float32)
    wall = SemanticMap(pts, [1, 1, 1, 1], faces=[[0, 1, 2], [0, 2, 3]])
    assert len(voxelize(wall, VS, densify=False)) == 4
    g = voxelize(wall, VS)
    assert 400 <= len(g) <= 441 and set(g.labels.tolist()) == {1}


def test_pixel_metrics_hand_counted():
    gt = np.array([[1, 1, 2, 2], [0, 0, 3, 3]], dtype=np.uint8)
    pred = np.array([[1, 2, 2, 2], [5, 1, 3, 0]], dtype=np.uint8)
    s = pixel_metrics(gt, pred)
    # counted: gt != 0 -> 6 pixels, 4 right
    assert s["n_pixels"] == 6 and s["pixel_acc"] == pytest.approx(4 / 6)
    iou = s["per_class_iou"]
    assert iou["wall"] == pytest.approx(1 / 2)  # tp 1, gt 2, pred 1 (void-gt pixel ignored)
    assert iou["floor"] == pytest.approx(2 / 3)
    assert iou["ceiling"] == pytest.approx(1 / 2)
    assert np.isnan(iou["sofa"])
    assert s["miou"] == pytest.approx((1 / 2 + 2 / 3 + 1 / 2) / 3)
    # a list of frames accumulates
    both = pixel_metrics([gt, gt], [pred, pred])
    assert both["n_pixels"] == 12 and both["pixel_acc"] == pytest.approx(4 / 6)
    with pytest.raises(ValueError, match="image 0"):
        pixel_metrics(gt, pred[:, :3])


def test_replica_map_against_itself_and_a_model_map(shared_dir):
    from semmatch.io import read_map

    room = shared_dir / "scenes" / "replica" / "room_2"
    gt = read_map(room / "high_3d_neighbor_using_GT_mesh_1_noise.ply")
    s = compare(gt, gt)
    assert headline(s) == (1.0, 1.0, 1.0, 1.0)
    m = compare(gt, room / "high_3d_nb_model_final_0_noise.ply")
    assert 0.2 < m["mean_acc"] < 0.95 and m["overlap"] > 0.3


def test_evaluate_cli_table_files_and_errors(tmp_path, rng, capsys):
    from semmatch.cli import main

    gt = at_voxels(rng.integers(0, 40, (400, 3)), rng.integers(1, 11, 400))
    pred = SemanticMap(gt.points, np.where(rng.random(400) < 0.2, 5, gt.labels))
    write_map(tmp_path / "gt.ply", gt)
    write_map(tmp_path / "pred.ply", pred)
    write_map(tmp_path / "mm.ply", SemanticMap(gt.points * 1000, gt.labels))
    rc = main(["evaluate", str(tmp_path / "gt.ply"), str(tmp_path / "gt.ply"), str(tmp_path / "pred.ply"),
               "--csv", str(tmp_path / "t.csv"), "--markdown", str(tmp_path / "t.md"),
               "--figure", str(tmp_path / "c.png"), "--per-class"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "mean_acc" in out and "pred.ply" in out
    import pandas as pd

    df = pd.read_csv(tmp_path / "t.csv", index_col=0)
    assert df.loc["gt.ply", "mean_acc"] == 1.0
    expected = compare(gt, pred, VS)["mean_acc"]
    assert df.loc["pred.ply", "mean_acc"] == pytest.approx(expected, abs=1e-6)
    assert "| pred.ply" in (tmp_path / "t.md").read_text()
    assert (tmp_path / "c.png").stat().st_size > 1000
    rc = main(["evaluate", str(tmp_path / "gt.ply"), str(tmp_path / "mm.ply")])
    assert rc == 2 and "different units or frames" in capsys.readouterr().err


def test_grid_origin_moves_both_grids():
    """A surface on a voxel boundary, reconstructed 5 mm low, splits between two voxel layers;
    half a voxel off the boundary it does not."""
    from semmatch.evaluate.metrics import compare
    from semmatch.io import SemanticMap

    xy = np.stack(np.meshgrid(np.arange(0, 1, 0.01), np.arange(0, 1, 0.01)), -1).reshape(-1, 2)
    floor = SemanticMap(np.c_[xy, np.zeros(len(xy))], np.full(len(xy), 2))
    low = SemanticMap(np.c_[xy, np.full(len(xy), -0.005)], np.full(len(xy), 2))
    on_boundary = compare(floor, low, 0.05, min_overlap=0)
    offset = compare(floor, low, 0.05, grid_origin=0.025)
    assert on_boundary["mean_acc"] < 0.5 and offset["mean_acc"] == pytest.approx(1.0)


def test_a_reference_voxelised_once_scores_like_the_map_itself(rng):
    """Table 2 / 3 voxelise each reference once (reference_grid); the numbers must not change."""
    from semmatch.experiments.synthetic import eval_grid_origin, reference_grid

    keys = rng.integers(0, 30, (400, 3))
    ref = at_voxels(keys, rng.integers(1, 11, 400), per_voxel=2, rng=rng)
    labels = np.where(rng.random(400) < 0.7, ref.labels[::2], rng.integers(1, 11, 400))
    pred = at_voxels(keys + (rng.random(keys.shape) < 0.05), labels, per_voxel=2, rng=rng)
    T = np.eye(4)
    T[:3, 3] = [0.013, -0.02, 0.007]
    grid = reference_grid(ref, VS)
    for transform in (None, T):
        direct = compare(ref, pred, VS, transform=transform, grid_origin=eval_grid_origin(VS))
        once = compare(grid, pred, VS, transform=transform, grid_origin=eval_grid_origin(VS))
        assert headline(once) == headline(direct)
        assert np.array_equal(once["confusion"], direct["confusion"])
