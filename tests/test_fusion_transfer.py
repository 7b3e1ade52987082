"""End to end: a lower-view map fused from 3d-neighborhood labels (transferred from a ground-truth
upper map) matches the lower-view map fused from ground-truth labels (paper Table 2: 0.949)."""

from __future__ import annotations

from semmatch.evaluate.metrics import compare
from semmatch.fusion import reconstruct
from semmatch.io import Frame
from semmatch.io.geometry import DEFAULT_INTRINSICS
from semmatch.sim import Renderer, generate_scene, make_trajectory
from semmatch.transfer import MapIndex, transfer


def _frames(renderer, scene, height, n, kind):
    poses = make_trajectory(scene, height, n, kind=kind, seed=0)
    out = []
    for i, p in enumerate(poses):
        r = renderer.render(p)
        out.append(Frame(r.rgb, r.depth, r.labels, p, renderer.intrinsics, index=i))
    return out


def test_lower_map_from_3d_neighborhood_labels_reaches_paper_accuracy():
    intr = DEFAULT_INTRINSICS.scaled(160, 120)
    scene = generate_scene("living_room", 0)
    r = Renderer(scene, intr)
    upper_frames = _frames(r, scene, 1.6, 120, "upper")
    lower_frames = _frames(r, scene, 0.2, 40, "lower")
    upper = reconstruct(upper_frames, voxel_size=0.04)  # ground-truth labels of the upper view
    lower_gt = reconstruct(lower_frames, voxel_size=0.04)
    index = MapIndex(upper)
    labels = [transfer("3d-neighborhood", f, index) for f in lower_frames]
    lower = reconstruct(lower_frames, labels=labels, voxel_size=0.04)
    s = compare(lower_gt, lower)
    assert s["mean_acc"] >= 0.95, s
    assert s["color_acc"] >= 0.95
