"""``semmatch adapt --home LOWER_SEQ --map PERSON_MAP``: adapting a network in a home the person mapped."""

from __future__ import annotations

import hashlib
import shutil

import numpy as np
import pytest

from semmatch.cli import main
from semmatch.segment import load_model


@pytest.fixture(scope="module")
def home(tmp_path_factory):
    """A tiny home: the person's and the robot's tours, the person's map (reconstructed from the
    person's tour, so it names its scene) and a tiny network."""
    from semmatch.segment.training import make_config, train

    d = tmp_path_factory.mktemp("home")
    assert main(["simulate", "--kind", "bedroom", "--seed", "3", "--pair", "--frames", "6", "--size", "64x48",
                 "--camera-step", "0.4", "--out", str(d / "pair"), "--quiet"]) == 0
    assert main(["reconstruct", str(d / "pair" / "upper"), "--out", str(d / "map.ply"), "--quiet"]) == 0
    cfg = make_config("smoke", out=str(d / "net.pt"), kinds=("living_room",), train_seeds=(1,), val_seeds=(501,),
                      eval_seeds=(9001,), steps=2, eval_every=2, frames=2, val_frames=2, progress=False)
    return {"dir": d, "lower": d / "pair" / "lower", "map": d / "map.ply", "net": train(cfg)}


def _argv(home, out, *extra):
    return ["adapt", "--home", str(home["lower"]), "--map", str(home["map"]), "--model", str(home["net"]),
            "--out", str(out), "--steps", "2", "--batch-size", "4", "--quiet", *extra]


def test_adapt_in_home_writes_a_checkpoint_naming_the_home_the_map_and_the_recipe(home, tmp_path, capsys):
    out = tmp_path / "adapted.pt"
    assert main(_argv(home, out, "--lr", "0.002", "--upper-share", "0.25", "--seed", "3")) == 0
    assert "adapted in bedroom_0003" in capsys.readouterr().out
    m = load_model(out)
    a = m.info["adapted"]
    assert a["mode"] == "home" and a["scenes"] == ["bedroom_0003"]
    assert a["home"] == {"sequence": str(home["lower"]), "scene": "bedroom_0003", "frames": list(range(6))}
    assert a["map"] == {"path": str(home["map"]),
                        "sha256": hashlib.sha256(home["map"].read_bytes()).hexdigest()[:16]}
    assert (a["label_source"], a["steps"], a["lr"], a["batch_size"], a["upper_share"], a["seed"]) == (
        "3d-neighborhood", 2, 0.002, 4, 0.25, 3)
    assert 0 < a["label_coverage"] <= 1 and a["from"] == str(home["net"])
    before = load_model(home["net"])
    assert any(not np.allclose(p.detach().numpy(), q.detach().numpy())
               for p, q in zip(m.net.parameters(), before.net.parameters(), strict=True))


def test_adapt_in_home_frame_choice_and_fused_source(home, tmp_path):
    out = tmp_path / "fused.pt"
    cache = tmp_path / "views"
    assert main(_argv(home, out, "--source", "fused", "--frames", "2", "--frame-step", "2", "--views-cache",
                      str(cache))) == 0
    a = load_model(out).info["adapted"]
    assert a["label_source"] == "fused" and a["home"]["frames"] == [0, 2] and a["frames"] == 2
    assert list(cache.glob("views-*.npz"))  # the network's human-height views, cached for the next home


def test_home_views_label_the_robot_frames_as_the_training_views_do(home):
    """The in-home labels are :func:`label_robot_frame`'s: transfer labels only where there is depth,
    resized to the network's training size (160x120 here; the home is 64x48)."""
    from semmatch.segment.adapt import home_views

    robot = home_views(home["net"], home["lower"], home["map"], progress=False)
    lab = robot.pseudo["3d-neighborhood"]
    assert lab.shape == (6, 120, 160) and robot.views.rgb.shape == (6, 120, 160, 3)
    assert ((lab == 0) | (robot.views.depth > 0)).all()
    assert robot.frames == list(range(6)) and robot.scenes == ["bedroom_0003"]


def _copy_home(home, tmp_path):
    seq = tmp_path / "lower"
    shutil.copytree(home["lower"], seq)
    return seq


def _edited_map(home, tmp_path, *, scene=None, shift=0.0, void=False):
    from semmatch.io import read_map, write_map

    m = read_map(home["map"])
    m.points = m.points + np.float32(shift)
    if void:
        m.labels = np.zeros_like(m.labels)
    return write_map(tmp_path / "edited.ply", m, scene=scene)


def _no_depth(home, tmp_path):
    seq = _copy_home(home, tmp_path)
    shutil.rmtree(seq / "depth")
    return seq


def _zero_depth(home, tmp_path):
    from semmatch.io.images import write_depth

    seq = _copy_home(home, tmp_path)
    for p in sorted((seq / "depth").glob("*.png")):
        write_depth(p, np.zeros((48, 64), np.float32))
    return seq


@pytest.mark.parametrize("case, edit, message", [
    ("sequence-without-depth", lambda h, t: {"--home": _no_depth(h, t)}, r"lower: the sequence has no depth/ folder"),
    ("sequence-with-empty-depth", lambda h, t: {"--home": _zero_depth(h, t)},
     r"lower/depth: no depth in any of the 6 frames used \(frame 0: .*000000\.png\)"),
    ("map-of-another-scene", lambda h, t: {"--map": _edited_map(h, t, scene="office_0002")},
     r"edited\.ply: the map is of scene 'office_0002' but the robot's sequence .* is of 'bedroom_0003': a map of "
     r"another home"),
    ("map-not-covering-the-view", lambda h, t: {"--map": _edited_map(h, t, shift=50.0)},
     r"edited\.ply: the map's labels cover 0\.00% .* the map does not cover this robot's view"),
    ("map-without-labels", lambda h, t: {"--map": _edited_map(h, t, void=True)}, r"edited\.ply: the map carries no labels"),
    ("out-is-the-model", lambda h, t: {"--out": h["net"]}, r"--out .*net\.pt"),
    ("out-is-the-map", lambda h, t: {"--out": h["map"]}, r"map\.ply"),
    ("out-inside-the-home", lambda h, t: {"--out": h["lower"] / "a.pt"}, r"lower"),
    ("mixed-with-seeds", lambda h, t: {"--seeds": "1"}, r"--seeds: training-scene options cannot be mixed with --home"),
    ("home-without-map", lambda h, t: {"--map": None}, r"--home needs --map PERSON_MAP"),
    ("self-training-in-a-home", lambda h, t: {"--source": "self-training"},
     r"source must be one of .*fused, got 'self-training'"),
])
def test_adapt_in_home_refuses_bad_input_in_one_line(home, tmp_path, capsys, case, edit, message):
    import re

    args = {"--home": home["lower"], "--map": home["map"], "--model": home["net"], "--out": tmp_path / "a.pt"}
    args.update(edit(home, tmp_path))
    argv = ["adapt", "--steps", "2", "--batch-size", "4", "--quiet"]
    for flag, value in args.items():
        if value is not None:
            argv += [flag, str(value)]
    before = {p: p.stat().st_mtime_ns for p in (home["net"], home["map"])}
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("semmatch adapt: error:"), err
    assert re.search(message, err), err
    assert not (tmp_path / "a.pt").exists()
    assert before == {p: p.stat().st_mtime_ns for p in (home["net"], home["map"])}


def test_training_scene_mode_still_works_and_refuses_home_options(home, tmp_path, capsys):
    out = tmp_path / "scenes.pt"
    assert main(["adapt", "--model", str(home["net"]), "--source", "ground-truth", "--seeds", "1", "--kinds",
                 "living_room", "--frames", "2", "--steps", "1", "--batch-size", "2", "--out", str(out),
                 "--quiet"]) == 0
    a = load_model(out).info["adapted"]
    assert a["scenes"] == ["living_room_0001"] and "home" not in a
    for extra, msg in ((["--map", str(home["map"])], "--map is the person's map of a home"),
                       (["--frame-step", "2"], "--frame-step is for --home"),
                       (["--views-cache", str(tmp_path / "c")], "--views-cache is for --home"),
                       ([], "needs --seeds")):
        argv = ["adapt", "--model", str(home["net"]), "--source", "3d-neighborhood", "--out", str(tmp_path / "x.pt"),
                *(["--seeds", "1"] if extra else []), *extra]
        assert main(argv) == 2
        assert msg in capsys.readouterr().err


def test_help_names_both_modes(capsys):
    with pytest.raises(SystemExit):
        main(["adapt", "--help"])
    out = capsys.readouterr().out
    assert "--home LOWER_SEQ --map PERSON_MAP" in out and "training scenes  --model --source --seeds" in out


def test_maps_and_sequences_name_their_scene(home, tmp_path):
    from semmatch.io import read_map, write_map
    from semmatch.io.maps import map_scene
    from semmatch.io.sequences import sequence_scene

    assert map_scene(home["map"]) == "bedroom_0003" == sequence_scene(home["lower"])
    m = read_map(home["map"])
    assert map_scene(write_map(tmp_path / "plain.ply", m)) is None
    assert sequence_scene(tmp_path) is None
    with pytest.raises(ValueError, match="single line"):
        write_map(tmp_path / "bad.ply", m, scene="a\nb")
