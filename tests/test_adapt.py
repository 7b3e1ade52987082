"""Adapting a network to the robot's viewpoint with transferred labels."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.adapt import LABEL_SOURCES, adapted_name, fine_tune, robot_training_views
from semmatch.segment import load_model
from semmatch.segment.training import make_config, train


@pytest.fixture(scope="module")
def tiny_network(tmp_path_factory):
    d = tmp_path_factory.mktemp("adapt")
    cfg = make_config("smoke", out=str(d / "net.pt"), kinds=("living_room",), train_seeds=(1,), val_seeds=(501,),
                      eval_seeds=(9001,), steps=2, eval_every=2, frames=2, val_frames=2, progress=False)
    return train(cfg)


@pytest.fixture(scope="module")
def robot(tiny_network):
    return robot_training_views(tiny_network, kinds=["living_room"], seeds=[1], n_frames=3,
                                sources=["3d-neighborhood", "self-training", "ground-truth"], progress=False)


def test_label_sources_are_every_method_fused_and_the_baselines():
    from semmatch.transfer import METHODS

    assert LABEL_SOURCES == (*METHODS, "fused", "self-training", "ground-truth")
    assert adapted_name("compact", "fused") == "compact~fused"


def test_robot_views_carry_one_label_image_per_source(robot):
    v = robot.views
    assert len(v) == 3 and v.rgb.shape[1:3] == v.labels.shape[1:]
    np.testing.assert_array_equal(robot.pseudo["ground-truth"], v.labels)
    nb = robot.pseudo["3d-neighborhood"]
    assert ((nb == 0) | (v.depth > 0)).all()  # nothing labelled without depth
    assert 0 < robot.coverage["3d-neighborhood"] <= 1 and robot.coverage["ground-truth"] > 0.9
    assert robot.coverage["self-training"] <= 1 and robot.scenes == ["living_room_0001"]


def test_adaptation_refuses_held_out_scenes_and_unknown_sources(tiny_network, robot, tmp_path):
    with pytest.raises(ValueError, match="validation/evaluation seeds"):
        robot_training_views(tiny_network, kinds=["living_room"], seeds=[501], n_frames=2, progress=False)
    with pytest.raises(ValueError, match="unknown label source"):
        robot_training_views(tiny_network, kinds=["living_room"], seeds=[1], sources=["magic"], progress=False)
    with pytest.raises(ValueError, match="carry no 'fused' labels"):
        fine_tune(tiny_network, robot, "fused", tmp_path / "x.pt", steps=1, progress=False)


def test_adapted_checkpoint_says_what_it_was_adapted_from_and_loads(tiny_network, robot, tmp_path):
    out = fine_tune(tiny_network, robot, "3d-neighborhood", tmp_path / "a.pt", steps=2, batch_size=4,
                    progress=False)
    m = load_model(out)
    a = m.info["adapted"]
    assert a["label_source"] == "3d-neighborhood" and a["scenes"] == robot.scenes and a["steps"] == 2
    assert a["from"] == str(tiny_network) and len(a["from_sha256"]) == 16
    before = load_model(tiny_network)
    changed = any(not np.allclose(p.detach().numpy(), q.detach().numpy())
                  for p, q in zip(m.net.parameters(), before.net.parameters(), strict=True))
    assert changed
    # same inputs, same seed: the same weights
    again = load_model(fine_tune(tiny_network, robot, "3d-neighborhood", tmp_path / "b.pt", steps=2, batch_size=4,
                                 progress=False))
    for p, q in zip(m.net.parameters(), again.net.parameters(), strict=True):
        np.testing.assert_array_equal(p.detach().numpy(), q.detach().numpy())


def test_gap_table_on_a_hand_made_sweep():
    import pandas as pd

    from semmatch.experiments.adapt import gap_table

    rows = []
    for scene, base_lo, base_hi, ad_lo, ad_hi in (("a", 0.4, 0.8, 0.6, 0.78), ("b", 0.5, 0.9, 0.7, 0.88)):
        rows += [dict(model="net", scene=scene, height=0.2, miou=base_lo), dict(model="net", scene=scene, height=1.6, miou=base_hi),
                 dict(model="net~x", scene=scene, height=0.2, miou=ad_lo), dict(model="net~x", scene=scene, height=1.6, miou=ad_hi)]
    t = gap_table(pd.DataFrame(rows), "net").set_index("model")
    assert t.loc["net~x", "gain_low"] == pytest.approx(0.2)
    assert t.loc["net~x", "change_high"] == pytest.approx(-0.02)
    assert t.loc["net~x", "gap_closed"] == pytest.approx(0.5)
    assert t.loc["net", "source"] == "none (unadapted)"
