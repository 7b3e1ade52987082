"""Adapting a network to the robot's viewpoint with transferred labels."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.segment import load_model
from semmatch.segment.adapt import LABEL_SOURCES, adapted_name, fine_tune, robot_training_views
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


def test_adapted_checkpoint_says_what_it_was_adapted_from_and_loads(tiny_network, robot, tmp_path, monkeypatch):
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
    assert "device" not in a  # a CPU fine-tuning: the pipeline's, recorded as before
    # "auto" without a GPU is the CPU: the same weights
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    auto = load_model(fine_tune(tiny_network, robot, "3d-neighborhood", tmp_path / "c.pt", steps=2, batch_size=4,
                                progress=False, device="auto"))
    for p, q in zip(m.net.parameters(), auto.net.parameters(), strict=True):
        np.testing.assert_array_equal(p.detach().numpy(), q.detach().numpy())


def test_fine_tuning_on_a_missing_gpu_is_refused(tiny_network, robot, tmp_path, monkeypatch):
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(ValueError, match="CUDA is not available"):
        fine_tune(tiny_network, robot, "3d-neighborhood", tmp_path / "x.pt", steps=1, progress=False, device="cuda")
    assert not (tmp_path / "x.pt").exists()


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
    # both scenes close half of their gap: every resample of the scenes does too
    assert t.loc["net~x", ["gap_closed_lo", "gap_closed_hi"]].tolist() == pytest.approx([0.5, 0.5])
    assert t.loc["net", "source"] == "none (unadapted)"


def test_ground_truth_adaptation_raises_lower_view_accuracy(tiny_network, robot, tmp_path):
    """On a tiny generated set: fine-tuning on the robot's frames with their true labels makes the
    network better on other robot frames of the scene (another tour) than it was."""
    from semmatch.segment.scores import confusion, scores

    held_out = robot_training_views(tiny_network, kinds=["living_room"], seeds=[1], n_frames=3, seed=7,
                                    sources=["ground-truth"], progress=False)

    def accuracy(ckpt) -> float:
        m = load_model(ckpt, flip=False)
        pred = np.stack([m.predict_labels(rgb) for rgb in held_out.views.rgb])
        return scores(confusion(held_out.views.labels, pred))["pixel_acc"]

    adapted = fine_tune(tiny_network, robot, "ground-truth", tmp_path / "gt.pt", steps=40, batch_size=4, lr=3e-3,
                        upper_share=0.25, progress=False)
    assert accuracy(adapted) > accuracy(tiny_network) + 0.05


def test_ignored_pixels_do_not_contribute_to_the_adaptation_loss():
    """The loss fine_tune optimises (optimisation_step) ignores pixels labelled 0: any logits
    there change neither the loss nor the gradients."""
    import torch

    from semmatch.io.labels import NUM_CLASSES
    from semmatch.segment.training import optimisation_step

    torch.manual_seed(0)
    conv = torch.nn.Conv2d(3, NUM_CLASSES, 3, padding=1)
    x = torch.randn(2, 3, 8, 8)
    y = torch.randint(1, NUM_CLASSES, (2, 8, 8))
    y[:, :, :4] = 0  # left half ignored
    noise = torch.randn(2, NUM_CLASSES, 8, 8) * 50

    class Scrambled(torch.nn.Module):  # wild logits on the ignored pixels only
        def __init__(self, inner):
            super().__init__()
            self.inner = inner

        def forward(self, x):
            return self.inner(x) + noise * (y == 0).unsqueeze(1)

    w = torch.ones(NUM_CLASSES)
    results = []
    for wrap in (False, True):
        net = torch.nn.Conv2d(3, NUM_CLASSES, 3, padding=1)
        net.load_state_dict(conv.state_dict())
        opt = torch.optim.SGD(net.parameters(), lr=0.1)
        sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda _: 1.0)
        loss = optimisation_step(Scrambled(net) if wrap else net, x, y, w, opt, sched)
        results.append((loss, [p.detach().clone() for p in net.parameters()]))
    assert results[0][0] == pytest.approx(results[1][0], rel=1e-6)
    for p, q in zip(results[0][1], results[1][1], strict=True):
        torch.testing.assert_close(p, q)


def test_adaptation_refuses_a_source_that_labels_almost_nothing(tiny_network, robot, tmp_path):
    from dataclasses import replace

    thin = replace(robot, coverage={**robot.coverage, "3d-neighborhood": 0.001})
    with pytest.raises(ValueError, match=r"3d-neighborhood: its labels cover 0\.10% .*living_room_0001"):
        fine_tune(tiny_network, thin, "3d-neighborhood", tmp_path / "x.pt", steps=1, progress=False)
    assert not (tmp_path / "x.pt").exists()


def test_adaptation_refuses_a_checkpoint_of_another_category_table(tiny_network, robot, tmp_path):
    import torch

    ckpt = torch.load(tiny_network, weights_only=True)
    ckpt["categories"] = [list(c) for c in ckpt["categories"]]
    ckpt["categories"][3][1] = "not-a-ceiling"
    other = tmp_path / "other_table.pt"
    torch.save(ckpt, other)
    with pytest.raises(ValueError, match="another category table"):
        fine_tune(other, robot, "ground-truth", tmp_path / "x.pt", steps=1, progress=False)
    assert not (tmp_path / "x.pt").exists()


def test_recipe_candidates_are_the_grid_in_order():
    from semmatch.experiments.adapt import recipe_candidates

    assert recipe_candidates({"lr": [1e-3, 1e-4], "upper_share": [0.5, 0.75]}) == [
        {"lr": 1e-3, "upper_share": 0.5}, {"lr": 1e-3, "upper_share": 0.75},
        {"lr": 1e-4, "upper_share": 0.5}, {"lr": 1e-4, "upper_share": 0.75}]
    assert recipe_candidates({"lr": 3e-4}) == [{"lr": 3e-4}]
    assert recipe_candidates({"distill": [0.0, 1.0]}) == [{"distill": 0.0}, {"distill": 1.0}]
    for bad, msg in (({}, "empty"), ({"momentum": [0.9]}, "unknown"), ({"lr": []}, "no values")):
        with pytest.raises(ValueError, match=msg):
            recipe_candidates(bad)


def test_recipe_rule_on_hand_made_tables():
    import pandas as pd

    from semmatch.experiments.adapt import pick_recipe

    # within the forgetting bound: the largest gain at 0.2 m wins, not the overall largest gain
    t = pick_recipe(pd.DataFrame({"gain_low": [0.10, 0.08, 0.12], "change_high": [-0.01, 0.0, -0.05]}), 0.02)
    assert t["chosen"].tolist() == [True, False, False]
    assert t["within_forgetting"].tolist() == [True, True, False]
    # none within: the least forgetting wins
    t = pick_recipe(pd.DataFrame({"gain_low": [0.10, 0.05], "change_high": [-0.05, -0.03]}), 0.02)
    assert t["chosen"].tolist() == [False, True]
    # ties: the first listed
    t = pick_recipe(pd.DataFrame({"gain_low": [0.1, 0.1], "change_high": [0.0, 0.0]}), 0.02)
    assert t["chosen"].tolist() == [True, False]
    with pytest.raises(ValueError, match="non-finite"):
        pick_recipe(pd.DataFrame({"gain_low": [float("nan")], "change_high": [0.0]}))


def test_distillation_term_is_zero_at_the_teacher_and_changes_the_weights(tiny_network, robot, tmp_path):
    import torch

    from semmatch.segment.adapt.finetune import _distillation

    teacher = load_model(tiny_network, flip=False).net.eval()
    cin = next(m for m in teacher.modules() if isinstance(m, torch.nn.Conv2d)).in_channels
    x = torch.rand(4, cin, 48, 64)
    term = _distillation(load_model(tiny_network, flip=False).net, 2, 0.5)
    with torch.no_grad():
        same = teacher(x)
    assert abs(float(term(x, same))) < 1e-6  # the adapted network still agrees with the unadapted one
    assert float(term(x, torch.randn_like(same) * 5)) > 0
    plain = load_model(fine_tune(tiny_network, robot, "3d-neighborhood", tmp_path / "p.pt", steps=2, batch_size=4,
                                 progress=False))
    kd = load_model(fine_tune(tiny_network, robot, "3d-neighborhood", tmp_path / "d.pt", steps=2, batch_size=4,
                              distill=1.0, progress=False))
    assert kd.info["adapted"]["distill"] == 1.0 and plain.info["adapted"]["distill"] == 0.0
    assert any(not np.array_equal(p.detach().numpy(), q.detach().numpy())
               for p, q in zip(plain.net.parameters(), kd.net.parameters(), strict=True))
    with pytest.raises(ValueError, match="distill"):
        fine_tune(tiny_network, robot, "3d-neighborhood", tmp_path / "x.pt", steps=1, upper_share=0.0, distill=1.0,
                  progress=False)


def test_adapt_networks_reuses_a_checkpoint_of_the_same_recipe_and_refuses_another(tiny_network, robot, tmp_path):
    import shutil

    from semmatch.experiments.adapt import adapt_networks
    from semmatch.experiments.layout import Layout

    root = tmp_path / "data"
    Layout(root).model("compact").parent.mkdir(parents=True)
    shutil.copyfile(tiny_network, Layout(root).model("compact"))
    recipe = dict(steps=2, batch_size=4, lr=1e-3, upper_share=0.5, seed=0)
    done = fine_tune(Layout(root).model("compact"), robot, "3d-neighborhood", tmp_path / "candidate.pt",
                     progress=False, **recipe)
    out = adapt_networks(root, "compact", robot, ["3d-neighborhood"], reuse={"3d-neighborhood": done},
                         progress=False, **recipe)
    assert out["compact~3d-neighborhood"].read_bytes() == done.read_bytes()  # copied, not trained again
    elsewhere = adapt_networks(root, "compact", robot, ["3d-neighborhood"], reuse={"3d-neighborhood": done},
                               out_dir=tmp_path / "elsewhere", progress=False, **recipe)
    assert elsewhere["compact~3d-neighborhood"] == tmp_path / "elsewhere" / "compact~3d-neighborhood.pt"
    assert elsewhere["compact~3d-neighborhood"].read_bytes() == done.read_bytes()
    with pytest.raises(ValueError, match="cannot reuse.*steps"):
        adapt_networks(root, "compact", robot, ["3d-neighborhood"], reuse={"3d-neighborhood": done},
                       progress=False, **{**recipe, "steps": 3})
    with pytest.raises(ValueError, match="cannot reuse.*label_source"):
        adapt_networks(root, "compact", robot, ["ground-truth"], reuse={"ground-truth": done}, progress=False,
                       **recipe)


def test_robot_map_comparison_pairs_scenes_and_judges_the_interval():
    import pandas as pd

    from semmatch.experiments.adapt import robot_map_comparison

    rows = []
    for k, scene in enumerate("abcdef"):
        rows += [dict(scene=scene, model="net", method="lower", mean_acc=0.80 + 0.01 * k),
                 dict(scene=scene, model="net", method="3d-neighborhood", mean_acc=0.85 + 0.01 * k),
                 dict(scene=scene, model="net", method="fused", mean_acc=0.95 + 0.01 * k),
                 # the adapted network: +0.05 over the unadapted one in every scene, one scene less
                 *([dict(scene=scene, model="net~gt", method="lower", mean_acc=0.85 + 0.01 * k + 0.002 * (-1) ** k)]
                   if scene != "f" else [])]
    t = robot_map_comparison(pd.DataFrame(rows), "net").set_index("against")
    assert list(t.index) == ["net lower", "net 3d-neighborhood", "net fused"]
    assert (t["scenes"] == 5).all()
    assert t.loc["net lower", "diff"] == pytest.approx(0.05, abs=0.002)
    assert t.loc["net lower", "verdict"] == "beats"
    assert t.loc["net 3d-neighborhood", "verdict"] == "not resolved"
    assert t.loc["net fused", "verdict"] == "loses"
    with pytest.raises(ValueError, match="no adapted"):
        robot_map_comparison(pd.DataFrame(rows), "other")
    with pytest.raises(ValueError, match="no net rows of dbscan"):
        robot_map_comparison(pd.DataFrame(rows), "net", against=("dbscan",))


def test_adapt_recipe_is_the_one_source_of_the_fine_tuning_defaults():
    import inspect

    from semmatch.cli import build_parser
    from semmatch.experiments.adapt import adapt_networks
    from semmatch.experiments.pipeline import notebook_parameters
    from semmatch.segment.adapt import AdaptRecipe, adapt_in_home

    r = AdaptRecipe()
    assert r.as_dict() == {"steps": 400, "batch_size": 16, "lr": 1e-3, "upper_share": 0.5, "distill": 0.0, "seed": 0}
    for f in (fine_tune, adapt_in_home, adapt_networks):  # no recipe defaults of their own
        assert not set(inspect.signature(f).parameters) & set(AdaptRecipe.names()), f.__name__
    args = build_parser().parse_args(["adapt", "--model", "m.pt", "--out", "o.pt"])
    assert {k: getattr(args, k) for k in AdaptRecipe.names() if k != "distill"} == {
        k: v for k, v in r.as_dict().items() if k != "distill"}
    # params.yaml fills it: the profile's steps and batch size, its seed; the rest the defaults
    p = notebook_parameters("09_adapt_robot_view", "full")
    assert AdaptRecipe.from_mapping(p) == AdaptRecipe(steps=1600, batch_size=16, seed=p["seed"])
    assert AdaptRecipe.from_mapping({"steps": "3", "lr": 1, "network": "compact"}, seed=2) == AdaptRecipe(
        steps=3, lr=1.0, seed=2)
    assert AdaptRecipe.of(r, steps=2).steps == 2 and AdaptRecipe.of(None) == r
    assert type(AdaptRecipe(lr=1).lr) is float and type(AdaptRecipe(steps=np.int64(5)).steps) is int
    with pytest.raises(TypeError, match="momentum"):
        AdaptRecipe.of(r, momentum=0.9)
    for bad in ({"steps": 0}, {"batch_size": 1}, {"upper_share": 1.0}):
        with pytest.raises(ValueError, match="need steps >= 1"):
            AdaptRecipe(**bad)
    with pytest.raises(ValueError, match="distill"):
        AdaptRecipe(upper_share=0.0, distill=1.0)


def test_a_shipped_adaptation_is_used_only_for_its_own_request(tiny_network, robot, tmp_path):
    """``ship-adapted`` copies a run's adapted checkpoints and recipe choice with a manifest of the
    request they answer; notebook 09 (``provide_adaptation``) copies them instead of fine-tuning
    when its request is the same, and names what differs (or what was damaged) otherwise."""
    import shutil

    import pandas as pd

    from semmatch.experiments.adapt import adapt_networks
    from semmatch.experiments.layout import Layout
    from semmatch.experiments.shipped_adaptation import (
        adaptation_request,
        provide_adaptation,
        ship_adaptation,
    )
    from semmatch.experiments.shipped_adaptation import shipped_adaptation as find_shipped

    sources = ["3d-neighborhood", "ground-truth"]
    params = dict(sources=sources, recipe_grid={"lr": [1e-3]}, recipe_source="3d-neighborhood", steps=2,
                  batch_size=4, max_forgetting=0.02, seed=0)
    roots = [tmp_path / "run", tmp_path / "repro"]
    for root in roots:
        Layout(root).model("compact").parent.mkdir(parents=True)
        shutil.copyfile(tiny_network, Layout(root).model("compact"))
    made = adapt_networks(roots[0], "compact", robot, sources, steps=2, batch_size=4, lr=1e-3, seed=0, progress=False)
    table = tmp_path / "validation_adapt_recipe.csv"
    pd.DataFrame({"candidate": [0], "lr": ["0.001"], "gain_low": [0.1], "change_high": [0.0],
                  "chosen": [True]}).to_csv(table, index=False)
    shipped = tmp_path / "models" / "adapted"
    shipped.mkdir(parents=True)
    (shipped / "notes.txt").write_text("a folder of someone else's")
    with pytest.raises(FileExistsError, match="not a shipped adaptation"):
        ship_adaptation(roots[0], "compact", shipped, parameters=params, recipe_table=table)
    assert (shipped / "notes.txt").is_file()  # left as it was
    (shipped / "notes.txt").unlink()
    ship_adaptation(roots[0], "compact", shipped, parameters=params, recipe_table=table, code_version="test")
    ship_adaptation(roots[0], "compact", shipped, parameters=params, recipe_table=table, code_version="test")  # again

    kw = dict(recipe_grid=params["recipe_grid"], recipe_source="3d-neighborhood", defaults={"steps": 2, "batch_size": 4},
              max_forgetting=0.02, seed=0)
    recipe, got_table, checkpoints, how = provide_adaptation(roots[1], "compact", robot, sources, shipped_dir=shipped,
                                                             progress=False, **kw)
    assert how.startswith("shipped") and recipe["steps"] == 2 and recipe["lr"] == 1e-3
    assert got_table["chosen"].tolist() == [True]
    for name, p in made.items():
        assert checkpoints[name].read_bytes() == p.read_bytes()  # copied, not fine-tuned again
        assert checkpoints[name].parent == roots[1] / "adapted"

    from semmatch.segment.adapt.finetune import file_digest

    request = adaptation_request(network_sha256=file_digest(Layout(roots[1]).model("compact")), scenes=robot.scenes,
                                 frames=len(robot.views), sources=sources, **kw)
    assert find_shipped(shipped, request)[0] is not None
    table_bytes = (shipped / "validation_adapt_recipe.csv").read_bytes()
    (shipped / "validation_adapt_recipe.csv").unlink()  # a damaged folder says what it lacks
    assert find_shipped(shipped, request) == (None, f"{shipped}: the recipe table validation_adapt_recipe.csv is missing")
    (shipped / "validation_adapt_recipe.csv").write_bytes(table_bytes)
    import json

    manifest = json.loads((shipped / "adaptation.json").read_text())
    outside = {**manifest, "checkpoints": {**manifest["checkpoints"],
                                           "3d-neighborhood": {**manifest["checkpoints"]["3d-neighborhood"],
                                                               "file": "../run/adapted/x.pt"}}}
    (shipped / "adaptation.json").write_text(json.dumps(outside))
    found, why = find_shipped(shipped, request)  # the manifest names nothing outside its folder
    assert found is None and "not a file of" in why
    (shipped / "adaptation.json").write_text(json.dumps(manifest))
    found, why = find_shipped(shipped, {**request, "max_forgetting": 0.05})
    assert found is None and "max_forgetting" in why
    found, why = find_shipped(shipped, {**request, "network_sha256": "0" * 16})
    assert found is None and "network_sha256" in why
    (shipped / "compact~ground-truth.pt").write_bytes(b"damaged")
    found, why = find_shipped(shipped, request)
    assert found is None and "'ground-truth'" in why
    assert find_shipped(tmp_path / "nowhere", request) == (None, f"no shipped adaptation in {tmp_path / 'nowhere'}")
    # a confirmatory run never fine-tunes: without a shipped adaptation for its request it stops, saying why
    with pytest.raises(ValueError, match="required here.*'ground-truth'"):
        provide_adaptation(roots[1], "compact", robot, sources, shipped_dir=shipped, require_shipped=True,
                           progress=False, **kw)
    with pytest.raises(ValueError, match="exclude each other"):
        provide_adaptation(roots[1], "compact", robot, sources, shipped_dir=shipped, require_shipped=True,
                           retrain=True, progress=False, **kw)


def test_other_fine_tuning_seeds_are_shipped_beside_and_scored_like_notebook_09s(tiny_network, robot, tmp_path,
                                                                                  monkeypatch):
    """``ship-adapted --seed 1`` ships a seed's checkpoints into ``adapted@1`` (refusing checkpoints of
    another seed); notebook 09 finds it for the same request with that seed (copied, not fine-tuned) and
    scores it as its own seed, the tables over seeds carrying a ``seed`` column."""
    import shutil

    import pandas as pd

    from semmatch.experiments import finetune_seeds
    from semmatch.experiments.adapt import adapt_networks
    from semmatch.experiments.adapt_claims import SEED_TABLES
    from semmatch.experiments.layout import Layout
    from semmatch.experiments.shipped_adaptation import ship_adaptation

    sources = ["3d-neighborhood"]
    params = dict(sources=sources, recipe_grid={"lr": [1e-3]}, recipe_source="3d-neighborhood", steps=2,
                  batch_size=4, max_forgetting=0.02, seed=0)
    roots = [tmp_path / "run", tmp_path / "confirm"]
    for root in roots:
        Layout(root).model("compact").parent.mkdir(parents=True)
        shutil.copyfile(tiny_network, Layout(root).model("compact"))
    made = adapt_networks(roots[0], "compact", robot, sources, steps=2, batch_size=4, lr=1e-3, seed=1, progress=False,
                          out_dir=tmp_path / "seed_1")
    table = tmp_path / "validation_adapt_recipe.csv"
    pd.DataFrame({"candidate": [0], "lr": ["0.001"], "chosen": [True]}).to_csv(table, index=False)
    base = tmp_path / "models" / "adapted"
    with pytest.raises(ValueError, match=r"fine-tuned with seed\(s\) \[1\], not the request's 0"):
        ship_adaptation(roots[0], "compact", base, parameters=params, recipe_table=table,
                        checkpoints_dir=tmp_path / "seed_1")
    ship_adaptation(roots[0], "compact", finetune_seeds.seed_folder(base, 1), parameters={**params, "seed": 1},
                    recipe_table=table, checkpoints_dir=tmp_path / "seed_1", trained_on="CPU (test)")
    assert (tmp_path / "models" / "adapted@1" / "adaptation.json").is_file()
    kw = dict(recipe_grid=params["recipe_grid"], recipe_source="3d-neighborhood", defaults={"steps": 2, "batch_size": 4},
              max_forgetting=0.02)
    more = finetune_seeds.shipped_finetune_seeds(roots[1], "compact", robot, sources, seeds=[0, 1, 2], base_seed=0,
                                                 shipped_dir=base, **kw)
    assert list(more) == [1]
    for name, p in made.items():
        assert more[1][name].read_bytes() == p.read_bytes() and more[1][name].parent == roots[1] / "adapted@1"

    def sweep(data_root, network, checkpoints, **_):  # stand-ins for notebook 09's two scorings
        return pd.DataFrame([dict(model=m, scene="office_9001", height=0.2, miou=0.5) for m in ("compact", *checkpoints)])

    monkeypatch.setattr("semmatch.experiments.adapt.adapted_height_study", sweep)
    monkeypatch.setattr("semmatch.experiments.adapt.adapted_lower_maps", lambda data_root, nets, **_: pd.DataFrame(
        [dict(scene="office_9001", model=m, method="lower", mean_acc=0.7) for m in nets]))
    monkeypatch.setattr("semmatch.experiments.adapt.load_adapted", lambda data_root, network, c: dict(c))
    figures = tmp_path / "figures"
    unadapted = pd.DataFrame([dict(scene="office_9001", model="compact", method="lower", mean_acc=0.6)])
    got = finetune_seeds.score_finetune_seeds(
        roots[1], "compact", figures, base_seed=0, height_rows=sweep(None, None, made), robot_rows=pd.DataFrame(
            [dict(scene="office_9001", model=m, method="lower", mean_acc=0.8) for m in made]),
        unadapted_rows=unadapted, seeds=more)
    sweeps = pd.read_csv(figures / f"{SEED_TABLES['height sweep']}.csv")
    maps = pd.read_csv(figures / f"{SEED_TABLES['robot map']}.csv")
    assert sweeps.groupby("seed")["model"].apply(list).to_dict() == {0: ["compact", *made], 1: ["compact", *made]}
    assert maps[maps["model"] == "compact"]["seed"].tolist() == [0, 1]  # the unadapted rows, once per seed
    assert len(got["robot map"]) == len(maps) == 4
    assert finetune_seeds.score_finetune_seeds(roots[1], "compact", tmp_path / "none", base_seed=0, height_rows=None,
                                               robot_rows=None, unadapted_rows=None, seeds={}) == {}
    assert not (tmp_path / "none").exists()


def test_gap_bounds_and_the_per_scene_change_figure(tmp_path):
    """One-sided bounds on a hand-made sweep: a source that closes 70 % +- a little of every
    scene's gap clears 60 %, one that closes 60 % on average with a wide spread does not; the
    change at 1.6 m is reported per scene (losers counted) and drawn one dot per scene."""
    import pandas as pd

    from semmatch.experiments.adapt import gap_bounds, gap_table, per_scene_changes
    from semmatch.plots import plot_per_scene_change

    rng = np.random.default_rng(0)
    rows = []
    for i in range(12):
        lo, hi = 0.4 + 0.02 * i, 0.75 + 0.01 * i
        gap = hi - lo
        for model, share, loss in (("net", 0.0, 0.0), ("net~tight", 0.7 + rng.normal(0, 0.02), -0.01 * (i % 2)),
                                   ("net~wide", 0.6 + rng.normal(0, 0.4), -0.05 * (i < 3))):
            rows += [dict(model=model, scene=f"s{i}", height=0.2, miou=lo + share * gap),
                     dict(model=model, scene=f"s{i}", height=1.6, miou=hi + loss)]
    per_scene = pd.DataFrame(rows)
    b = gap_bounds(per_scene, "net", target=0.6, forgetting=0.02).set_index("source")
    assert list(b.index) == ["tight", "wide"] and (b["scenes"] == 12).all()
    t = gap_table(per_scene, "net").set_index("source")
    assert b.loc["tight", "gap_closed"] == pytest.approx(t.loc["tight", "gap_closed"])
    assert 0.6 < b.loc["tight", "gap_closed_lower"] < b.loc["tight", "gap_closed"] and b.loc["tight", "clears_target"]
    assert b.loc["wide", "gap_closed_lower"] < 0.6 and not b.loc["wide", "clears_target"]
    assert b.loc["wide", "scenes_losing"] == 3 and b.loc["tight", "scenes_losing"] == 0
    assert b.loc["wide", "change_high_min"] == pytest.approx(-0.05)
    assert b.loc["wide", "change_high_lower"] < b.loc["wide", "change_high"]
    changes = per_scene_changes(per_scene, "net")
    assert len(changes) == 24 and set(changes["source"]) == {"tight", "wide"}
    out = plot_per_scene_change(changes, tmp_path / "change.png", threshold=0.02)
    assert out.stat().st_size > 1000


def test_ship_adapted_command_writes_the_shipped_folder(tmp_path, capsys):
    """``python -m semmatch.experiments ship-adapted`` reads notebook 09's parameters of a profile
    and the run's checkpoints and recipe table, and writes the shipped folder with its manifest;
    a run with a source missing is refused by name."""
    import json

    import pandas as pd
    import torch

    from semmatch.experiments.confirm import add_ship_adapted_parser
    from semmatch.experiments.pipeline import main, notebook_parameters
    from semmatch.segment.adapt import AdaptRecipe

    params = notebook_parameters("09_adapt_robot_view", "smoke")
    data, figures, dest = tmp_path / "data", tmp_path / "figures", tmp_path / "models" / "adapted"
    (data / "adapted").mkdir(parents=True)
    figures.mkdir()
    pd.DataFrame({"candidate": [0, 1], "chosen": [False, True]}).to_csv(figures / "validation_adapt_recipe.csv",
                                                                         index=False)
    recipe = AdaptRecipe(steps=params["steps"], batch_size=params["batch_size"]).as_dict()
    for s in params["sources"][1:]:
        torch.save({"adapted": {"from_sha256": "ab" * 8, "scenes": ["living_room_0001"], "frames": 8,
                                "label_source": s, **recipe}}, data / "adapted" / f"compact~{s}.pt")
    argv = ["ship-adapted", "--profile", "smoke", "--data-root", str(data), "--figures-dir", str(figures),
            "--to", str(dest), "--code-version", "test"]
    assert main(argv, extra_commands=(add_ship_adapted_parser,)) == 1
    assert f"compact~{params['sources'][0]}.pt" in capsys.readouterr().err and not dest.exists()
    s = params["sources"][0]
    torch.save({"adapted": {"from_sha256": "ab" * 8, "scenes": ["living_room_0001"], "frames": 8, "label_source": s,
                            **recipe}}, data / "adapted" / f"compact~{s}.pt")
    assert main(argv, extra_commands=(add_ship_adapted_parser,)) == 0
    m = json.loads((dest / "adaptation.json").read_text())
    assert m["request"]["sources"] == params["sources"] and m["request"]["recipe_grid"] == params["recipe_grid"]
    assert m["request"]["defaults"] == {"steps": params["steps"], "batch_size": params["batch_size"]}
    assert m["recipe"]["steps"] == params["steps"] and m["code_version"] == "test"
    assert sorted(p.name for p in dest.iterdir()) == sorted(
        ["adaptation.json", "validation_adapt_recipe.csv", *(f"compact~{s}.pt" for s in params["sources"])])


def test_recipe_candidates_are_scored_one_checkpoint_each(tmp_path):
    from semmatch.experiments.adapt import score_recipe_candidates

    with pytest.raises(ValueError, match="2 recipes for 1 checkpoints"):
        score_recipe_candidates(tmp_path, "compact", [{"lr": 1e-3}, {"lr": 3e-4}], [tmp_path / "a.pt"],
                                source="self-training")
    with pytest.raises(ValueError, match="0 recipes for 0 checkpoints"):
        score_recipe_candidates(tmp_path, "compact", [], [], source="self-training")
