"""Ground-truth oracle, noisy oracle and the detectron2 adapter."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.io import Frame
from semmatch.io.geometry import DEFAULT_INTRINSICS
from semmatch.io.labels import NUM_CLASSES, id_of
from semmatch.segment.detectron2 import class_map, instances_to_semantic
from semmatch.segment.oracle import CONFUSIONS, NoisyOracle, OracleSegmenter, noisy_labels


@pytest.fixture(scope="module")
def frame() -> Frame:
    from semmatch.segment.data import make_scenes
    from semmatch.sim import Renderer, make_trajectory

    intr = DEFAULT_INTRINSICS.scaled(160, 120)
    scene = make_scenes(["living_room"], [21])[0]
    r = Renderer(scene, intr).render(make_trajectory(scene, 1.5, 3, seed=0)[1])
    return Frame(r.rgb, r.depth, r.labels, np.eye(4), intr, index=1)


@pytest.mark.parametrize("rate", [0.0, 0.05, 0.2, 0.5, 1.0])
def test_noisy_oracle_hits_its_error_rate(frame, rate):
    noisy = NoisyOracle(rate, seed=3).predict_labels_frame(frame)
    gt = frame.labels
    valid = gt > 0
    assert abs((noisy != gt)[valid].mean() - rate) <= 1.0 / valid.sum()
    assert (noisy[~valid] == 0).all()


def test_noisy_oracle_confusions_are_plausible_and_blobby(frame):
    gt = frame.labels
    noisy = noisy_labels(gt, 0.3, rgb=frame.rgb, seed=0)
    wrong = noisy != gt
    for g, p in set(zip(gt[wrong].tolist(), noisy[wrong].tolist(), strict=True)):
        assert p in CONFUSIONS[g], (g, p)
    # errors come in blobs: most wrong pixels have a wrong 4-neighbour
    nb = np.zeros_like(wrong)
    nb[1:] |= wrong[:-1]
    nb[:-1] |= wrong[1:]
    nb[:, 1:] |= wrong[:, :-1]
    nb[:, :-1] |= wrong[:, 1:]
    assert (nb & wrong).sum() > 0.9 * wrong.sum()


def test_noisy_oracle_is_repeatable_and_validates(frame):
    a = NoisyOracle(0.2, seed=5).predict_labels_frame(frame)
    b = NoisyOracle(0.2, seed=5).predict_labels_frame(frame)
    c = NoisyOracle(0.2, seed=6).predict_labels_frame(frame)
    assert (a == b).all() and not (a == c).all()
    with pytest.raises(ValueError, match=r"error_rate must lie in \[0, 1\]"):
        NoisyOracle(1.5)
    with pytest.raises(ValueError, match="does not match labels"):
        noisy_labels(frame.labels, 0.1, rgb=frame.rgb[:10])


def test_oracle_is_one_hot_ground_truth(frame):
    p = OracleSegmenter().predict_frame(frame)
    assert p.shape == frame.labels.shape + (NUM_CLASSES,) and p.dtype == np.float32
    assert (p.argmax(-1) == frame.labels).all() and np.allclose(p.sum(-1), 1)
    nolab = Frame(frame.rgb, frame.depth, None, None, frame.intrinsics, index=4)
    with pytest.raises(ValueError, match="frame 4: the oracle needs ground-truth labels"):
        OracleSegmenter().predict_frame(nolab)


def test_instances_to_semantic_maps_classes_and_resolves_overlaps():
    names = ["person", "couch", "dining table", "tv", "chair"]
    cmap = class_map(names)
    assert cmap.tolist() == [0, id_of("sofa"), id_of("table"), id_of("monitor"), id_of("chair")]
    masks = np.zeros((3, 4, 5), bool)
    masks[0, :2] = True     # couch, score .9
    masks[1, 1:3] = True    # table, score .6: row 1 overlaps and goes to the couch
    masks[2, 3] = True      # person: no category -> stays void
    out = instances_to_semantic(masks, [1, 2, 0], [0.9, 0.6, 0.99], cmap)
    assert (out[0] == id_of("sofa")).all() and (out[1] == id_of("sofa")).all()
    assert (out[2] == id_of("table")).all() and (out[3] == 0).all()
    low = instances_to_semantic(masks, [1, 2, 0], [0.9, 0.4, 0.99], cmap, score_thresh=0.5)
    assert (low[2] == 0).all()
    assert instances_to_semantic(np.zeros((0, 4, 5), bool), [], [], cmap, shape=(4, 5)).max() == 0
    with pytest.raises(ValueError, match="do not agree"):
        instances_to_semantic(masks, [1, 2], [0.9, 0.6, 0.99], cmap)


def test_detectron2_segmenter_end_to_end():
    pytest.importorskip("detectron2")
    import torch
    from detectron2.structures import Instances

    from semmatch.segment.detectron2 import Detectron2Segmenter

    def predictor(img):
        inst = Instances(img.shape[:2])
        m = torch.zeros((1,) + img.shape[:2], dtype=torch.bool)
        m[0, :5] = True
        inst.pred_masks, inst.pred_classes, inst.scores = m, torch.tensor([0]), torch.tensor([0.9])
        return {"instances": inst}

    seg = Detectron2Segmenter(predictor, class_names=["bed"])
    lab = seg.predict_labels(np.zeros((10, 12, 3), np.uint8))
    assert (lab[:5] == id_of("bed")).all() and (lab[5:] == 0).all()


def test_pixel_scores_agree_with_semmatch_metrics():
    from semmatch.evaluate.metrics import pixel_metrics
    from semmatch.segment.scores import confusion, scores

    rng = np.random.default_rng(0)
    gt = rng.integers(0, 12, (3, 20, 30)).astype(np.uint8)
    pred = np.where(rng.uniform(size=gt.shape) < 0.7, gt, rng.integers(0, 14, gt.shape)).astype(np.uint8)
    ours, ref = scores(confusion(gt, pred)), pixel_metrics(gt, pred)
    assert np.isclose(ours["miou"], ref["miou"]) and np.isclose(ours["pixel_acc"], ref["pixel_acc"])
    # 2D Sorensen and Jaccard from their definitions
    G, P = np.isin(gt, range(1, 11)), np.isin(pred, range(1, 11)) & (gt > 0)  # GT void is not scored
    C = (G & P & (gt == pred)).sum()
    assert np.isclose(ours["sorensen"], 2 * C / (G.sum() + P.sum()))
    assert np.isclose(ours["color_acc"], C / (G & P).sum())
