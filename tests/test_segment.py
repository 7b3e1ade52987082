"""Segmentation networks: training, checkpoints, prediction, bad input, CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from semmatch.experiments.layout import Layout
from semmatch.io import SequenceWriter, read_label_image, read_labels_folder, read_sequence
from semmatch.io.geometry import DEFAULT_INTRINSICS
from semmatch.io.labels import NUM_CLASSES
from semmatch.segment import load_model, make_config, predict_sequence, train
from semmatch.segment.data import Views, class_weights, make_scenes, render_views
from semmatch.segment.models import ModelConfig, build_network
from semmatch.segment.predict import Segmenter
from semmatch.segment.scores import confusion, scores

W, H = 96, 72
INTR = DEFAULT_INTRINSICS.scaled(W, H)


@pytest.fixture(scope="module")
def views() -> tuple[Views, Views]:
    """Tiny training (2 scenes) and held-out validation (1 scene) sets from the simulator."""
    tr = render_views(make_scenes(["living_room", "office"], [11, 12]), [1.4, 1.7], 8, intrinsics=INTR,
                      seed=0, progress=False)
    va = render_views(make_scenes(["living_room"], [511]), [1.5], 8, intrinsics=INTR, seed=1, progress=False)
    return tr, va


def _config(tmp, **kw):
    base = dict(out=str(tmp / "net.pt"), width=W, height=H, kinds=("living_room", "office"), train_seeds=(11, 12),
                val_seeds=(511,), steps=60, batch_size=6, eval_every=20, lr=5e-3, progress=False)
    base.update(kw)
    return make_config("smoke", **base)


@pytest.fixture(scope="module")
def trained(views, tmp_path_factory) -> str:
    tmp = tmp_path_factory.mktemp("seg")
    return str(train(_config(tmp), views=views))


def test_training_drives_loss_down_and_beats_chance(trained, views):
    net = load_model(trained)
    hist = net.info["history"]
    assert hist[-1]["train_loss"] < 0.7 * hist[0]["train_loss"]
    _, va = views
    pred = net.predict_labels_batch(va.rgb)
    s = scores(confusion(va.labels, pred))
    present = np.unique(va.labels[va.labels > 0])
    chance = 1.0 / len(present)  # uniform guessing among the classes that occur
    assert s["pixel_acc"] > 2 * chance, s
    assert net.metrics["miou"] > 0 and 0 < net.metrics["pixel_acc"] <= 1


def test_checkpoint_contents_and_reload_predicts_identically(trained, views, tmp_path):
    ckpt = torch.load(trained, weights_only=True)
    assert ckpt["model"]["arch"] == "compact" and ckpt["categories"][10][1] == "sofa"
    assert {"miou", "pixel_acc", "per_class_iou"} <= set(ckpt["metrics"])
    a, b = load_model(trained), load_model(trained)
    rgb = views[1].rgb[0]
    pa, pb = a.predict(rgb), b.predict(rgb)
    assert pa.shape == (H, W, NUM_CLASSES) and pa.dtype == np.float32
    np.testing.assert_array_equal(pa, pb)
    np.testing.assert_allclose(pa.sum(-1), 1.0, atol=1e-5)
    assert (pa >= 0).all()


def test_training_is_deterministic(views, tmp_path):
    tr, va = views
    small = (tr.subset(np.arange(8)), va.subset(np.arange(2)))
    p1 = train(_config(tmp_path, out=str(tmp_path / "a.pt"), steps=4, eval_every=4), views=small)
    p2 = train(_config(tmp_path, out=str(tmp_path / "b.pt"), steps=4, eval_every=4), views=small)
    s1 = torch.load(p1, weights_only=True)["state_dict"]
    s2 = torch.load(p2, weights_only=True)["state_dict"]
    assert all(torch.equal(s1[k], s2[k]) for k in s1)
    p3 = train(_config(tmp_path, out=str(tmp_path / "c.pt"), steps=4, eval_every=4, seed=1), views=small)
    s3 = torch.load(p3, weights_only=True)["state_dict"]
    assert not all(torch.equal(s1[k], s3[k]) for k in s1)


def test_other_sizes_are_resized_in_and_restored_out(trained, views):
    net = load_model(trained)
    rgb = views[1].rgb[0]
    big = np.repeat(np.repeat(rgb, 2, axis=0), 2, axis=1)  # 2x the network size
    p = net.predict(big)
    assert p.shape == (2 * H, 2 * W, NUM_CLASSES)
    np.testing.assert_allclose(p.sum(-1), 1.0, atol=1e-5)
    # same picture at twice the size: labels agree with the native prediction almost everywhere
    small_lab = net.predict_labels(rgb)
    assert (p.argmax(-1)[::2, ::2] == small_lab).mean() > 0.9
    # float input in [0, 1] is the documented equivalent of uint8
    np.testing.assert_allclose(net.predict(rgb.astype(np.float32) / 255), net.predict(rgb), atol=1e-5)


def test_bad_inputs_raise_clear_errors(trained, views):
    net = load_model(trained)
    rgb = views[1].rgb[0]
    bad = rgb.astype(np.float32) / 255
    bad[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        net.predict(bad)
    with pytest.raises(ValueError, match="dtype uint16"):
        net.predict(rgb.astype(np.uint16))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        net.predict(rgb.astype(np.float32))
    with pytest.raises(ValueError, match=r"\(H,W,3\)"):
        net.predict(rgb[..., 0])


def test_checkpoints_for_another_table_or_architecture_are_refused(trained, tmp_path):
    ckpt = torch.load(trained, weights_only=True)
    bad = dict(ckpt, categories=[list(c) for c in ckpt["categories"]])
    bad["categories"][5][1] = "desk"
    torch.save(bad, tmp_path / "table.pt")
    with pytest.raises(ValueError, match="another category table.*id 5"):
        load_model(tmp_path / "table.pt")
    with pytest.raises(ValueError, match="holds a 'compact' network, not 'strong'"):
        load_model(trained, arch="strong")
    wrong = dict(ckpt, model=dict(ckpt["model"], arch="strong"))
    torch.save(wrong, tmp_path / "arch.pt")
    with pytest.raises(ValueError, match="weights do not fit the 'strong' architecture"):
        load_model(tmp_path / "arch.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="junk.pt: not (a readable PyTorch|loadable as a weights-only) checkpoint"):
        load_model(tmp_path / "junk.pt")
    with pytest.raises(FileNotFoundError):
        load_model(tmp_path / "missing.pt")


def test_predict_sequence_writes_labels_and_probabilities(trained, views, tmp_path):
    _, va = views
    with SequenceWriter(tmp_path / "seq", INTR) as w:
        for i in range(3):
            w.add(va.rgb[i], va.depth[i], np.eye(4), labels=va.labels[i])
    net = load_model(trained)
    out = predict_sequence(net, tmp_path / "seq", tmp_path / "pred", probs=True, progress=False)
    files = read_labels_folder(out)
    assert [f.name for f in files] == ["000000.png", "000001.png", "000002.png"]
    lab = read_label_image(files[1])
    assert lab.dtype == np.uint8 and lab.shape == (H, W)
    np.testing.assert_array_equal(lab, net.predict_labels(va.rgb[1]))
    p = np.load(out / "probs" / "000001.npy")
    assert p.shape == (H, W, NUM_CLASSES)
    # the labels folder reads back through the contract's reader
    assert read_sequence(tmp_path / "seq", labels=out)[2].labels.shape == (H, W)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary leftovers


def test_both_architectures_give_probabilities_with_depth():
    for arch in ("compact", "strong"):
        cfg = ModelConfig(arch=arch, use_depth=True, width=64, height=48)
        torch.manual_seed(0)
        seg = Segmenter(build_network(cfg), cfg, device="cpu")
        rgb = np.random.default_rng(0).integers(0, 256, (50, 70, 3), dtype=np.uint8)
        depth = np.full((50, 70), 2.0, np.float32)
        depth[0, 0] = np.nan  # documented: reads as no measurement
        p = seg.predict(rgb, depth)
        assert p.shape == (50, 70, NUM_CLASSES)
        np.testing.assert_allclose(p.sum(-1), 1.0, atol=1e-5)
        with pytest.raises(ValueError, match="uses depth"):
            seg.predict(rgb)
        with pytest.raises(ValueError, match="float metres"):
            seg.predict(rgb, np.full((50, 70), 2000, np.uint16))


def test_class_weights_favour_rare_classes():
    lab = np.zeros((10, 10), np.uint8)
    lab[:8] = 1
    lab[8:, :] = 2
    lab[9, 9] = 4
    w = class_weights(lab)
    assert w[0] == 0 and w[3] == 0
    assert w[4] > w[2] > w[1]


def test_class_weight_power_softens_the_balancing():
    lab = np.zeros((10, 10), np.uint8)
    lab[:8] = 1
    lab[8:, :] = 2
    lab[9, 9] = 4
    full, root, flat = (class_weights(lab, power=p, clip=100.0) for p in (1.0, 0.5, 0.0))
    present = [1, 2, 4]
    np.testing.assert_allclose(root[present], np.sqrt(full[present]), rtol=1e-6)
    np.testing.assert_array_equal(flat[present], 1.0)
    assert flat[0] == 0 and root[3] == 0
    with pytest.raises(ValueError, match="power must lie in"):
        class_weights(lab, power=2.0)


def test_config_validation():
    with pytest.raises(ValueError, match="train and eval scene seeds overlap: \\[1001\\]"):
        make_config("smoke", train_seeds=(1, 1001))
    with pytest.raises(ValueError, match="unknown training profile"):
        make_config("huge")
    with pytest.raises(ValueError, match="unknown architecture"):
        make_config("smoke", arch="resnet")


def test_cli_predict_with_the_noisy_oracle(views, tmp_path):
    from semmatch.cli import main

    _, va = views
    with SequenceWriter(tmp_path / "seq", INTR) as w:
        for i in range(2):
            w.add(va.rgb[i], va.depth[i], np.eye(4), labels=va.labels[i])
    assert main(["predict", str(tmp_path / "seq"), "--model", "noisy:0.25", "--out", str(tmp_path / "lab"),
                 "--quiet"]) == 0
    lab = read_label_image(tmp_path / "lab" / "000001.png")
    gt = va.labels[1]
    assert abs((lab != gt)[gt > 0].mean() - 0.25) < 1e-3
    assert main(["predict", str(tmp_path / "seq"), "--model", "noisy:x", "--out", str(tmp_path / "l2")]) == 2


def test_cli_train_and_bench(tmp_path, capsys):
    import json

    from semmatch.cli import main

    out = tmp_path / "m.pt"
    assert main(["train", "--recipe", "smoke", "--arch", "strong", "--out", str(out), "--steps", "2",
                 "--width", "64", "--height", "48", "--net-width", "32", "--net-height", "24", "--zoom", "1.5", "2",
                 "--kinds", "living_room", "--train-seeds", "11", "--val-seeds", "511", "--quiet"]) == 0
    assert "val mIoU" in capsys.readouterr().out
    assert load_model(out, arch="strong").config.width == 32
    assert main(["train", "--out", str(out), "--net-width", "32"]) == 2
    assert "give both --net-width and --net-height" in capsys.readouterr().err
    assert main(["train", "--out", str(out), "--net-width", "40", "--net-height", "30"]) == 2  # 160x120 views
    assert "outside the training zoom range" in capsys.readouterr().err
    assert main(["train", "--out", str(out), "--train-seeds", "1001"]) == 2  # overlaps the eval scenes
    assert "overlap" in capsys.readouterr().err
    assert main(["bench", "segment", "--json", "--frames", "1", "--model", str(out)]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["networks"]["m"]["fps_320x240"] > 0 and res["networks"]["m"]["fps_640x480"] > 0
    assert res["networks"]["m"]["flip"] is True and res["networks"]["m"]["input"] == "32x24"
    assert main(["bench", "segment", "--json", "--frames", "1", "--no-flip"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["networks"]["compact"]["flip"] is False and res["networks"]["strong"]["input"] == "160x120"


def test_viewpoint_gap_table_and_figure(trained, tmp_path):
    from semmatch.plots import plot_height_study, plot_training_curves
    from semmatch.segment import training_histories
    from semmatch.segment.viewpoint import gap_summary, viewpoint_gap

    net = load_model(trained)
    df = viewpoint_gap({"tiny": net}, make_scenes(["living_room"], [1001]), heights=(0.2, 1.6), n_frames=2,
                       intrinsics=INTR, progress=False)
    assert list(df["height"]) == [0.2, 1.6] and (df["n_frames"] == 2).all()
    assert ((df[["miou", "pixel_acc", "mean_acc"]] >= 0) & (df[["miou", "pixel_acc", "mean_acc"]] <= 1)).all().all()
    g = gap_summary(df)
    assert np.isclose(g["gap"].iloc[0], df["miou"].iloc[1] - df["miou"].iloc[0])
    plot_height_study(df.groupby(["model", "height"], as_index=False)[["mean_acc", "miou"]].mean(), tmp_path / "fig3.png")
    histories = training_histories({"tiny": trained})
    assert [h["step"] for h in histories["tiny"]] == sorted(h["step"] for h in histories["tiny"])
    plot_training_curves(histories, tmp_path / "curves.png")
    assert (tmp_path / "fig3.png").stat().st_size > 1000 and (tmp_path / "curves.png").stat().st_size > 1000


def test_network_smaller_than_the_views_sees_whole_frames(views, tmp_path):
    tr, va = views
    small = (tr.subset(np.arange(8)), va.subset(np.arange(2)))
    cfg = _config(tmp_path, net_width=W // 2, net_height=H // 2, zoom=(1.5, 2.0), steps=4, eval_every=4)
    assert cfg.crop_size == (W // 2, H // 2) and cfg.model_config().width == W // 2
    net = load_model(train(cfg, views=small))
    assert (net.config.width, net.config.height) == (W // 2, H // 2)
    p = net.predict(va.rgb[0])  # view-sized input: resized in, restored out
    assert p.shape == (H, W, NUM_CLASSES)
    with pytest.raises(ValueError, match="crop 200x72 must lie within"):
        _config(tmp_path, crop_width=200, crop_height=72)
    # views 4x the network, trained at zoom 1.5-2: training never sees the prediction scale
    with pytest.raises(ValueError, match=r"seen at scale 4 \(width\) when predicting, outside the training zoom"):
        _config(tmp_path, width=4 * (W // 2), height=4 * (H // 2), net_width=W // 2, net_height=H // 2,
                zoom=(1.5, 2.0))


def test_augment_scales_depth_relative_to_the_prediction_zoom():
    from semmatch.segment.models import DEPTH_NORM
    from semmatch.segment.training import augment

    rgb = np.zeros((2, 48, 64, 3), np.uint8)
    depth = np.full((2, 48, 64), 2.0, np.float32)
    lab = np.ones((2, 48, 64), np.uint8)
    for base, want in ((1.0, 4.0), (2.0, 2.0)):
        x, y = augment(rgb, depth, lab, np.random.default_rng(0), crop=(32, 24), zoom=(2.0, 2.0), jitter=0,
                       use_depth=True, base_zoom=base)
        assert x.shape == (2, 4, 24, 32) and y.shape == (2, 24, 32)
        # a window twice the crop seen at the prediction zoom keeps the measured depth
        np.testing.assert_allclose(x[:, 3].numpy(), want / DEPTH_NORM, rtol=1e-6)


def test_flip_average_is_mirror_symmetric_and_sums_to_one(trained, views):
    rgb = views[1].rgb[0]
    mirror = rgb[:, ::-1].copy()
    one = load_model(trained, flip=False)
    q, qm = one.predict(rgb), one.predict(mirror)
    assert not np.allclose(qm, q[:, ::-1], atol=1e-4)  # a single pass is not mirror symmetric
    both = load_model(trained)
    assert both.flip and not one.flip
    p, pm = both.predict(rgb), both.predict(mirror)
    np.testing.assert_allclose(p, 0.5 * (q + qm[:, ::-1]), atol=1e-5)
    np.testing.assert_allclose(pm, p[:, ::-1], atol=1e-5)
    np.testing.assert_allclose(p.sum(-1), 1.0, atol=1e-5)


def test_network_names_carry_architecture_and_seed():
    import pandas as pd

    from semmatch.experiments.tables import spread_over_training_seeds
    from semmatch.segment import network_spec

    assert network_spec("compact", 0) == ("compact", 0)
    assert network_spec("compact@2", 0) == ("compact", 2)
    assert network_spec("strong@11", 5) == ("strong", 11)
    with pytest.raises(ValueError, match="unknown architecture 'tiny'"):
        network_spec("tiny")
    with pytest.raises(ValueError, match="must be an integer"):
        network_spec("compact@x")
    summary = pd.DataFrame(dict(model=["compact", "compact@1", "compact@2", "strong", "ground truth"],
                                method=["lower"] * 5, mean_acc=[0.7, 0.8, 0.9, 0.5, 1.0]))
    spread = spread_over_training_seeds(summary)
    assert list(spread["arch"]) == ["compact"] and spread["seeds"].iloc[0] == 3
    assert spread["mean"].iloc[0] == pytest.approx(0.8) and spread["sd"].iloc[0] == pytest.approx(0.1)
    assert spread_over_training_seeds(summary[summary["model"] == "strong"]).empty


def test_cli_bench_train(capsys):
    import json

    import torch

    from semmatch.cli import main

    before = torch.are_deterministic_algorithms_enabled()
    assert main(["bench", "train", "--json", "--recipe", "smoke", "--arch", "compact", "--steps", "1",
                 "--schedule", "compact=600"]) == 0
    res = json.loads(capsys.readouterr().out)["networks"]["compact"]
    assert torch.are_deterministic_algorithms_enabled() == before  # the benchmark restores the setting
    assert res["seconds_per_step"] > 0 and res["schedule_steps"] == 600 and res["batch_size"] == 8
    assert abs(res["projected_minutes"] - res["seconds_per_step"] * 600 / 60.0) <= 0.06
    assert main(["bench", "train", "--recipe", "smoke", "--arch", "compact", "--steps", "1",
                 "--schedule", "strong=10"]) == 2
    assert "not timed" in capsys.readouterr().err
    assert main(["bench", "train", "--recipe", "smoke", "--arch", "compact", "--schedule", "compact=x"]) == 2
    assert "ARCH=STEPS" in capsys.readouterr().err


def test_pipeline_configs_name_seed_and_steps_per_network(tmp_path):
    from semmatch.segment import pipeline_configs

    common = dict(train_profile="smoke", seed=0, kinds=("living_room",), train_seeds=(1,), val_seeds=(501,),
                  eval_seeds=(7001,), width=160, height=120, out_dir=tmp_path, cache_dir=tmp_path / "cache")
    cfgs = pipeline_configs(["compact", "compact@2"], steps={"compact": 30, "compact@2": 40}, **common)
    assert [c.seed for c in cfgs.values()] == [0, 2]
    assert [c.steps for c in cfgs.values()] == [30, 40]  # a name's entry wins over its architecture's
    assert cfgs["compact@2"].out == str(tmp_path / "compact@2.pt")
    assert pipeline_configs(["compact@2"], steps={"compact": 30}, **common)["compact@2"].steps == 30
    assert pipeline_configs(["compact"], steps=None, **common)["compact"].steps == 100  # the smoke profile's



@pytest.fixture(scope="module")
def shipped_tiny(views, tmp_path_factory):
    """A 2-step network trained from the tiny views and shipped (ship_networks) with its recipe."""
    import json

    from semmatch.segment.shipping import ship_networks

    tmp = tmp_path_factory.mktemp("ship")
    tr, va = views
    small = (tr.subset(np.arange(8)), va.subset(np.arange(2)))
    trained = train(_config(tmp, out=str(tmp / "trained" / "compact.pt"), steps=2, eval_every=2), views=small)
    recipe = tmp / "trained" / "recipe.json"
    recipe.write_text(json.dumps({"flip": {"compact": True, "other": False}}))
    ship_networks({"compact": trained}, tmp / "models" / "x", recipe=recipe, code_version="abc123")
    return small, tmp / "models" / "x"


def _copy_shipped(shipped_tiny, tmp_path):
    import shutil

    small, shipped = shipped_tiny
    return small, Path(shutil.copytree(shipped, tmp_path / "shipped"))


def test_a_shipped_network_of_the_same_config_is_used_without_training(shipped_tiny, tmp_path, monkeypatch):
    import json
    from dataclasses import replace

    from semmatch.segment import shipping, training
    from semmatch.segment.training import views_digest

    small, shipped = _copy_shipped(shipped_tiny, tmp_path)
    manifest = json.loads((shipped / "compact.json").read_text())
    assert manifest["checkpoint_sha256"] == shipping.file_sha256(shipped / "compact.pt")
    assert manifest["training_data"]["views_sha256"] == views_digest(*small)
    assert manifest["train_config"]["steps"] == 2 and manifest["code_version"] == "abc123"
    assert manifest["trained_on"]["device"] == "cpu" and manifest["trained_on"]["cpu_count"] >= 1
    assert manifest["train_seconds"] > 0 and manifest["validation"]["best_step"] == 2
    assert json.loads((shipped / "recipe.json").read_text())["flip"] == {"compact": True}  # only shipped networks

    trained = []
    monkeypatch.setattr(training, "train", lambda config, views=None: trained.append(config) or Path(config.out))
    # other evaluation scenes (a confirmatory run's) do not change the weights: still the shipped network
    cfg = _config(tmp_path, out=str(tmp_path / "data" / "models" / "compact.pt"), steps=2, eval_every=2,
                  eval_seeds=(9101,))
    ckpts, from_shipped = shipping.provide_networks({"compact": cfg}, shipped_dir=shipped, views={0: small},
                                                    log=lambda s: None)
    assert from_shipped == ["compact"] and not trained
    assert (tmp_path / "data" / "models" / "compact.pt").read_bytes() == (shipped / "compact.pt").read_bytes()
    load_model(ckpts["compact"])  # weights_only loading of the installed copy
    assert shipping.apply_shipped_recipe(tmp_path / "data", shipped, ["compact"]) == {"compact": True}
    assert json.loads((tmp_path / "data" / "models" / "recipe.json").read_text())["flip"] == {"compact": True}
    assert json.loads(Layout(tmp_path / "data").recipe.read_text())["flip"] == {"compact": True}  # the layout's file
    # retrain (make repro TRAIN=1) trains even a network whose shipped copy matches
    lines = []
    _, from_shipped = shipping.provide_networks({"compact": cfg}, shipped_dir=shipped, retrain=True,
                                                views={0: small}, log=lines.append)
    threads = manifest["trained_on"]["torch_threads"]  # a CPU run's thread count is kept (see below)
    assert from_shipped == [] and trained == [replace(cfg, threads=threads)] and "retraining" in lines[-1]


def test_weights_digest_ignores_when_and_where_a_network_was_trained(shipped_tiny, tmp_path):
    import json

    import torch

    from semmatch.segment import shipping

    small, shipped = _copy_shipped(shipped_tiny, tmp_path)
    manifest = json.loads((shipped / "compact.json").read_text())
    digest = shipping.weights_sha256(shipped / "compact.pt")
    assert manifest["weights_sha256"] == digest
    ckpt = torch.load(shipped / "compact.pt", weights_only=True)
    ckpt["finished_at"], ckpt["train_seconds"] = "2000-01-01T00:00:00Z", 1.0  # another run, same weights
    torch.save(ckpt, tmp_path / "again.pt")
    assert shipping.file_sha256(tmp_path / "again.pt") != manifest["checkpoint_sha256"]
    assert shipping.weights_sha256(tmp_path / "again.pt") == digest
    name = sorted(ckpt["state_dict"])[0]
    ckpt["state_dict"][name] = ckpt["state_dict"][name].clone()
    ckpt["state_dict"][name].view(-1)[0] += 1e-6  # one weight moves
    torch.save(ckpt, tmp_path / "moved.pt")
    assert shipping.weights_sha256(tmp_path / "moved.pt") != digest


@pytest.mark.parametrize("network", ["compact", "strong"])
def test_the_committed_manifests_describe_their_checkpoints(network):
    import json

    from semmatch.segment import shipping

    folder = Path(__file__).resolve().parents[1] / "models" / "full"
    manifest = json.loads((folder / f"{network}.json").read_text())
    assert manifest["checkpoint_sha256"] == shipping.file_sha256(folder / f"{network}.pt")
    assert manifest["weights_sha256"] == shipping.weights_sha256(folder / f"{network}.pt")


def test_retraining_uses_the_shipped_cpu_runs_threads_and_reports_the_same_weights(shipped_tiny, tmp_path):
    import json
    from dataclasses import replace

    import torch

    from semmatch.segment import shipping

    small, shipped = _copy_shipped(shipped_tiny, tmp_path)
    manifest = json.loads((shipped / "compact.json").read_text())
    assert manifest["trained_on"]["device"] == "cpu"
    threads = manifest["trained_on"]["torch_threads"]
    cfg = _config(tmp_path, out=str(tmp_path / "data" / "models" / "compact.pt"), steps=2, eval_every=2, device="cpu")
    got, found, why = shipping.shipped_run(cfg, shipped)
    assert got.threads == threads and found["weights_sha256"] == manifest["weights_sha256"] and "thread" in why
    assert shipping.shipped_run(replace(cfg, threads=3), shipped)[0].threads == 3  # its own count stays
    assert shipping.shipped_run(replace(cfg, steps=1), shipped)[1:] == (None, "")  # another recipe: nothing
    assert shipping.shipped_run(cfg, None) == (cfg, None, "")
    gpu = dict(manifest, trained_on=dict(manifest["trained_on"], device="cuda"))
    (shipped / "compact.json").write_text(json.dumps(gpu))
    got, found, why = shipping.shipped_run(cfg, shipped)
    assert got.threads is None and found is not None and why == ""  # a GPU run is compared with, not copied
    (shipped / "compact.json").write_text(json.dumps(manifest))
    # the real retraining: the shipped run's thread count gives its weights again, and the
    # process keeps its own thread count afterwards
    before = torch.get_num_threads()
    torch.set_num_threads(threads + 1)
    try:
        lines = []
        ckpts, _ = shipping.provide_networks({"compact": cfg}, shipped_dir=shipped, retrain=True,
                                             views={0: small}, log=lines.append)
        assert torch.get_num_threads() == threads + 1
    finally:
        torch.set_num_threads(before)
    assert "the same weights as the shipped network" in lines[-1], lines
    assert shipping.weights_sha256(ckpts["compact"]) == manifest["weights_sha256"]
    moved = dict(manifest, weights_sha256="0" * 64)
    (shipped / "compact.json").write_text(json.dumps(moved))
    lines = []
    shipping.provide_networks({"compact": cfg}, shipped_dir=shipped, retrain=True, views={0: small},
                              log=lines.append)
    assert "other weights than the shipped network" in lines[-1], lines
    del moved["weights_sha256"]  # a manifest from before the weights digest
    (shipped / "compact.json").write_text(json.dumps(moved))
    lines = []
    shipping.provide_networks({"compact": cfg}, shipped_dir=shipped, retrain=True, views={0: small},
                              log=lines.append)
    assert "no weights digest" in lines[-1], lines


def test_a_network_whose_config_differs_from_the_shipped_one_is_trained(shipped_tiny, tmp_path):
    import json

    from semmatch.segment import shipping

    small, shipped = _copy_shipped(shipped_tiny, tmp_path)
    cfg = _config(tmp_path, out=str(tmp_path / "data" / "models" / "compact.pt"), steps=1, eval_every=1)
    path, why = shipping.shipped_checkpoint(cfg, shipped)
    assert path is None and "steps: 2 -> 1" in why
    lines = []
    ckpts, from_shipped = shipping.provide_networks({"compact": cfg}, shipped_dir=shipped, views={0: small},
                                                    log=lines.append)
    assert from_shipped == [] and "steps: 2 -> 1" in lines[0]
    assert load_model(ckpts["compact"]).info["train_config"]["steps"] == 1
    # a shipped file that is not the one its manifest describes (a Git LFS pointer, a truncated copy) is refused
    same = _config(tmp_path, out=str(tmp_path / "again" / "compact.pt"), steps=2, eval_every=2)
    (shipped / "compact.pt").write_bytes((shipped / "compact.pt").read_bytes()[:-10])
    with pytest.raises(ValueError, match="SHA-256 differs"):
        shipping.shipped_checkpoint(same, shipped)
    (shipped / "compact.json").unlink()
    with pytest.raises(ValueError, match="without its manifest"):
        shipping.shipped_checkpoint(same, shipped)
    (shipped / "recipe.json").write_text(json.dumps({"flip": {}}))
    with pytest.raises(ValueError, match="no flip choice for compact"):
        shipping.apply_shipped_recipe(tmp_path / "data", shipped, ["compact"])


def test_rendered_and_cached_views_are_the_same_training_data(views, tmp_path):
    """The views cache stores depth as float16; rendered views carry depth at that precision, so a
    run that renders and a run that reads the cache train on the same arrays and record the same
    ``views_sha256`` (before 2026-11-27 a fresh clone's retraining recorded another digest than
    the shipped manifests, from the same views)."""
    from semmatch.segment.data import cached_views
    from semmatch.segment.training import views_digest

    tr, _ = views
    made = cached_views(tmp_path, {"k": 1}, lambda: tr)
    again = cached_views(tmp_path, {"k": 1}, lambda: pytest.fail("the cache was not used"))
    for a, b in ((made, again), (tr, again)):
        for name in ("rgb", "depth", "labels", "scene", "height"):
            x, y = getattr(a, name), getattr(b, name)
            assert x.dtype == y.dtype and np.array_equal(x, y), name
    assert views_digest(tr) == views_digest(again)
    assert (tr.depth > 0).any() and np.array_equal(tr.depth, tr.depth.astype(np.float16).astype(np.float32))
