"""A corpus of bad inputs: every case is a clear error (exit 2, a message naming what is wrong),
never a traceback, never a silent result, and nothing half-written is left behind.

The cases run the command line in this process (``semmatch.cli.main``) on a tiny simulated
sequence, its ground-truth mesh and a reconstruction of it, each mutated in one way.
"""

from __future__ import annotations

import json
import os
import pickle
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from semmatch.cli import main

pytestmark = pytest.mark.slow

# ------------------------------------------------------------------------------------------
# fixtures: one valid sequence, scene mesh and map; each case copies and breaks one thing


def make_corpus(d: Path) -> Path:
    """Into ``d``: a person's sequence ``seq``, its scene mesh ``scene.ply``, its map ``map.ply``, and
    a robot's sequence ``low`` of the same room (four 80x60 frames each)."""
    args = ["--kind", "living_room", "--seed", "3", "--frames", "4", "--size", "80x60", "--quiet"]
    assert main(["simulate", *args, "--out", str(d / "seq"), "--save-scene", str(d / "scene.ply")]) == 0
    assert main(["simulate", *args, "--height", "0.3", "--out", str(d / "low")]) == 0
    assert main(["reconstruct", str(d / "seq"), "--out", str(d / "map.ply"), "--quiet"]) == 0
    return d


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    return make_corpus(tmp_path_factory.mktemp("corpus"))


def _copy(base: Path, w: Path, name: str = "seq") -> Path:
    dst = w / name
    shutil.copytree(base / name, dst)
    return dst


def _edit_poses(seq: Path, fn) -> None:
    lines = (seq / "poses.txt").read_text().splitlines()
    (seq / "poses.txt").write_text("\n".join(fn(lines)) + "\n")


def _frame(seq: Path, kind: str, i: int = 0) -> Path:
    return sorted((seq / kind).iterdir())[i]


def _intrinsics(seq: Path, **kw) -> None:
    d = json.loads((seq / "intrinsics.json").read_text())
    d.update(kw)
    (seq / "intrinsics.json").write_text(json.dumps(d))


def _map_variant(base: Path, w: Path, name: str, fn) -> Path:
    import open3d as o3d

    m = o3d.io.read_triangle_mesh(str(base / "map.ply"))
    fn(m)
    o3d.io.write_triangle_mesh(str(w / name), m)
    return w / name


def _scaled_map(base: Path, w: Path, name: str, factor: float, points_only: bool = False) -> Path:
    from semmatch.io import SemanticMap, read_map, write_map

    m = read_map(base / "map.ply")
    m.points = m.points * factor
    if points_only:  # a point cloud map: no mesh sampling budget stops it
        m = SemanticMap(m.points, m.labels, source=m.source)
    write_map(w / name, m)
    return w / name


def _odd_map(base: Path, w: Path, name: str, kind: str) -> Path:
    """``base/map.ply`` with one vertex at 1e30 m (``far``), or with no vertex at all (``empty``)."""
    from semmatch.io import SemanticMap, read_map, write_map

    m = read_map(base / "map.ply")
    if kind == "far":
        m.points[0] = 1e30
    else:
        m = SemanticMap(m.points[:0], m.labels[:0], source=m.source)
    write_map(w / name, m)
    return w / name


def _empty_probs(base: Path, w: Path) -> Path:
    (w / "probs").mkdir()
    (w / "probs" / "000000.npy").write_bytes(b"")
    return w / "probs"


def _checkpoint(w: Path, kind: str) -> Path:
    p = w / f"{kind}.pt"
    if kind == "junk":
        p.write_bytes(b"garbage, not a checkpoint")
    elif kind == "evil":
        class Evil:
            def __reduce__(self):
                return (os.system, ("echo pwned",))
        p.write_bytes(pickle.dumps(Evil()))
    elif kind == "foreign":
        import torch

        torch.save({"hello": 1}, p)
    return p


def _user_folder(w: Path) -> Path:
    d = w / "mine"
    d.mkdir()
    (d / "precious.txt").write_text("the user's file")
    return d


# ------------------------------------------------------------------------------------------
# the corpus: (id, setup(base, w) -> argv, expected message regex)

RECON = ["reconstruct", "--quiet"]


def recon_of(mutate):
    def setup(base, w):
        seq = _copy(base, w)
        mutate(seq)
        return [*RECON, str(seq), "--out", str(w / "out.ply")]
    return setup


def transfer_with(map_setup, *extra, method="3d-neighborhood"):
    def setup(base, w):
        m = map_setup(base, w) if callable(map_setup) else map_setup.format(base=base, w=w)
        return ["transfer", str(base / "low"), "--map", str(m), "--method", method, "--out", str(w / "out"),
                "--quiet", *extra]
    return setup


def argv_of(*argv):
    def setup(base, w):
        return [a.format(base=base, w=w) for a in argv]
    return setup


CASES = [
    # sequences
    ("seq-no-poses", recon_of(lambda s: (s / "poses.txt").unlink()), r"(no poses\.txt|has no recorded poses)"),
    ("seq-short-poses", recon_of(lambda s: _edit_poses(s, lambda t: t[:1])), r"does not match poses\.txt"),
    ("seq-nan-pose", recon_of(lambda s: _edit_poses(s, lambda t: ["0 nan 0 0 0 0 0 1", *t[1:]])),
     r"poses\.txt.*(NaN|finite|not a rigid)"),
    ("seq-garbage-poses", recon_of(lambda s: (s / "poses.txt").write_text("hello world\n")), r"poses\.txt:1: expected 8 values"),
    ("seq-broken-intrinsics", recon_of(lambda s: (s / "intrinsics.json").write_text("{")), r"intrinsics\.json"),
    ("seq-negative-fx", recon_of(lambda s: _intrinsics(s, fx=-1)), r"fx must be > 0"),
    ("seq-missing-depth-frame", recon_of(lambda s: _frame(s, "depth", 1).unlink()), r"frame 1 .*is missing"),
    ("seq-corrupt-depth", recon_of(lambda s: _frame(s, "depth").write_bytes(b"\x89PNG garbage")),
     r"cannot read image .*000000\.png"),
    ("seq-rgb-other-size", recon_of(lambda s: cv2.imwrite(str(_frame(s, "rgb")), np.zeros((10, 10, 3), np.uint8))),
     r"frame 0 is 10x10 but intrinsics\.json says 80x60"),
    ("seq-8bit-depth", recon_of(lambda s: cv2.imwrite(str(_frame(s, "depth")), np.zeros((60, 80), np.uint8))),
     r"depth must be a 16-bit"),
    ("seq-all-depth-zero", recon_of(lambda s: [cv2.imwrite(str(f), np.zeros((60, 80), np.uint16))
                                              for f in (s / "depth").iterdir()]), r"none of its 4 frame\(s\) has usable depth"),
    ("seq-label-out-of-table", recon_of(lambda s: cv2.imwrite(str(_frame(s, "labels")), np.full((60, 80), 200, np.uint8))),
     r"label id 200 outside 0\.\.20"),
    ("seq-empty-folder", lambda b, w: [*RECON, str((w / "e").mkdir() or w / "e"), "--out", str(w / "out.ply")],
     r"(not a sequence folder \(no intrinsics\.json\)|not a recording folder)"),
    ("seq-missing-folder", argv_of(*RECON, "{w}/nope", "--out", "{w}/out.ply"), r"no such (sequence )?folder"),
    ("seq-is-a-file", argv_of(*RECON, "{base}/map.ply", "--out", "{w}/out.ply"), r"map\.ply: no such (sequence )?folder"),
    ("recon-voxel-zero", argv_of(*RECON, "{base}/seq", "--out", "{w}/out.ply", "--voxel-size", "0"), r"--voxel-size: must be > 0"),
    ("recon-voxel-negative", argv_of(*RECON, "{base}/seq", "--out", "{w}/out.ply", "--voxel-size", "-1"), r"--voxel-size: must be > 0"),
    ("recon-voxel-in-mm", argv_of(*RECON, "{base}/seq", "--out", "{w}/out.ply", "--voxel-size", "1e-6"), r"below 1 mm"),
    ("recon-depth-max-zero", argv_of(*RECON, "{base}/seq", "--out", "{w}/out.ply", "--depth-max", "0"), r"--depth-max: must be > 0"),
    ("recon-label-stride-zero", argv_of(*RECON, "{base}/seq", "--out", "{w}/out.ply", "--label-stride", "0"),
     r"--label-stride: must be >= 1"),
    ("recon-out-is-a-folder", argv_of(*RECON, "{base}/seq", "--out", "{w}"), r"is a folder; give the name of the file"),
    ("recon-out-unwritable", argv_of(*RECON, "{base}/seq", "--out", "/proc/semmatch-test.ply"), r"cannot write /proc/semmatch-test\.ply"),
    ("recon-missing-labels", argv_of(*RECON, "{base}/seq", "--labels", "{w}/nolabels", "--out", "{w}/out.ply"),
     r"no such labels folder"),
    # maps given to transfer
    ("map-not-ply", transfer_with(lambda b, w: (w / "t.ply").write_text("not a ply") and w / "t.ply"), r"not a readable PLY"),
    ("map-truncated", transfer_with(lambda b, w: (w / "t.ply").write_bytes((b / "map.ply").read_bytes()[:-12000]) and w / "t.ply"),
     r"(PLY header claims .* but the file holds|not a readable PLY file \(element 'face')"),
    ("map-empty-file", transfer_with(lambda b, w: (w / "t.ply").write_bytes(b"") or w / "t.ply"), r"not a readable PLY"),
    ("map-missing", transfer_with("{w}/none.ply"), r"no such map file"),
    ("map-no-labels", transfer_with(lambda b, w: _map_variant(b, w, "n.ply", lambda m: m.vertex_colors.clear())),
     r"neither vertex colours nor a 'label' property"),
    ("map-off-palette", transfer_with(lambda b, w: _map_variant(
        b, w, "o.ply", lambda m: setattr(m, "vertex_colors", __import__("open3d").utility.Vector3dVector(
            np.random.default_rng(0).random((len(m.vertices), 3)))))), r"not colours of the category palette"),
    ("transfer-map-in-mm", transfer_with(lambda b, w: _scaled_map(b, w, "mm.ply", 1000.0)),
     r"mm\.ply: sampling the mesh every .* is the map in metres \(not millimetres\)"),
    ("transfer-point-map-in-mm", transfer_with(lambda b, w: _scaled_map(b, w, "mm.ply", 1000.0, points_only=True)),
     r"mm\.ply: the map spans .* blocks .* is the map in metres \(not millimetres\)"),
    ("transfer-unknown-method", transfer_with("{base}/map.ply", method="bogus"), r"invalid choice: 'bogus'"),
    ("transfer-out-is-input", lambda b, w: ["transfer", str(b / "low"), "--map", str(b / "map.ply"), "--method",
                                            "3d-neighborhood", "--out", str(b / "low")], r"outside the inputs"),
    ("transfer-out-inside-input", lambda b, w: ["transfer", str(b / "low"), "--map", str(b / "map.ply"), "--method",
                                                "3d-neighborhood", "--out", str(b / "low" / "labels")], r"outside the inputs"),
    ("transfer-out-user-folder", lambda b, w: ["transfer", str(b / "low"), "--map", str(b / "map.ply"), "--method",
                                               "3d-neighborhood", "--out", str(_user_folder(w))],
     r"holds files semmatch did not write"),
    ("transfer-negative-distance", transfer_with("{base}/map.ply", "--max-distance", "-1"), r"--max-distance: must be > 0"),
    ("transfer-fused-without-probs", transfer_with("{base}/map.ply", method="fused"), r"--method fused needs --probs"),
    ("transfer-jobs-zero", transfer_with("{base}/map.ply", "--jobs", "0"), r"--jobs: must be >= 1"),
    ("transfer-empty-probabilities", lambda b, w: transfer_with("{base}/map.ply", "--probs", str(_empty_probs(b, w)),
                                                                method="fused")(b, w),
     r"000000\.npy: probabilities of frame 0 are not a readable \.npy array"),
    ("transfer-vertex-at-1e30", transfer_with(lambda b, w: _odd_map(b, w, "far.ply", "far")),
     r"far\.ply: 1 vertices lie beyond 10000 m of the origin"),
    ("transfer-missing-sequence", argv_of("transfer", "{w}/nope", "--map", "{base}/map.ply", "--method",
                                          "3d-neighborhood", "--out", "{w}/out"), r"nope: no such sequence folder"),
    # evaluate
    ("evaluate-missing-gt", argv_of("evaluate", "{w}/none.ply", "{base}/map.ply"), r"none\.ply: no such map file"),
    ("evaluate-text-prediction", lambda b, w: ["evaluate", str(b / "scene.ply"),
                                               str((w / "t.ply").write_text("x") and w / "t.ply")], r"not a readable PLY"),
    ("evaluate-voxel-zero", argv_of("evaluate", "{base}/scene.ply", "{base}/map.ply", "--voxel-size", "0"),
     r"--voxel-size: must be > 0"),
    ("evaluate-bad-transform", lambda b, w: ["evaluate", str(b / "scene.ply"), str(b / "map.ply"), "--transform",
                                             str((w / "T.txt").write_text("not a matrix") and w / "T.txt")],
     r"T\.txt: not a 4x4 transform"),
    ("evaluate-missing-transform", argv_of("evaluate", "{base}/scene.ply", "{base}/map.ply", "--transform", "{w}/T.txt"),
     r"no such transform file"),
    ("evaluate-off-palette", lambda b, w: ["evaluate", str(b / "scene.ply"), str(_map_variant(
        b, w, "o.ply", lambda m: setattr(m, "vertex_colors", __import__("open3d").utility.Vector3dVector(
            np.random.default_rng(1).random((len(m.vertices), 3))))))], r"not colours of the category palette"),
    ("evaluate-map-in-mm", lambda b, w: ["evaluate", str(b / "scene.ply"), str(_scaled_map(b, w, "mm.ply", 1000.0))],
     r"(in metres|overlap)"),
    ("evaluate-min-overlap-above-one", argv_of("evaluate", "{base}/scene.ply", "{base}/map.ply", "--min-overlap", "2"),
     r"overlap"),
    # checkpoints
    ("predict-junk-checkpoint", lambda b, w: ["predict", str(b / "seq"), "--model", str(_checkpoint(w, "junk")),
                                              "--out", str(w / "p")], r"junk\.pt: not loadable as a weights-only"),
    ("predict-malicious-pickle", lambda b, w: ["predict", str(b / "seq"), "--model", str(_checkpoint(w, "evil")),
                                               "--out", str(w / "p")], r"evil\.pt: not loadable .*refuses to load"),
    ("predict-foreign-checkpoint", lambda b, w: ["predict", str(b / "seq"), "--model", str(_checkpoint(w, "foreign")),
                                                 "--out", str(w / "p")], r"not a semmatch segmentation checkpoint"),
    ("predict-missing-checkpoint", argv_of("predict", "{base}/seq", "--model", "{w}/none.pt", "--out", "{w}/p"),
     r"none\.pt: no such checkpoint"),
    ("train-zero-steps", argv_of("train", "--out", "{w}/m.pt", "--steps", "0"), r"--steps: must be >= 1"),
    ("train-negative-lr", argv_of("train", "--out", "{w}/m.pt", "--steps", "1", "--lr", "-1"), r"--lr: must be > 0"),
    ("adapt-foreign-checkpoint", lambda b, w: ["adapt", "--model", str(_checkpoint(w, "foreign")), "--source",
                                               "3d-neighborhood", "--out", str(w / "a.pt"), "--seeds", "1"],
     r"not a semmatch segmentation checkpoint"),
    # simulate
    ("simulate-huge-image", argv_of("simulate", "--out", "{w}/s", "--size", "100000x100000", "--frames", "1"),
     r"(out of memory|too large|pixels)"),
    ("simulate-bad-size", argv_of("simulate", "--out", "{w}/s", "--image-size", "axb"),
     r"--image-size: must look like WxH, e\.g\. 640x480"),
    ("simulate-zero-frames", argv_of("simulate", "--out", "{w}/s", "--frames", "0"), r"--frames: must be >= 1"),
    ("simulate-unknown-kind", argv_of("simulate", "--out", "{w}/s", "--kind", "castle"), r"unknown scene kind 'castle'"),
    ("simulate-above-ceiling", argv_of("simulate", "--out", "{w}/s", "--height", "10", "--frames", "2", "--size", "40x30"),
     r"above the ceiling"),
    ("simulate-negative-height", argv_of("simulate", "--out", "{w}/s", "--height", "-1", "--frames", "2", "--size", "40x30"),
     r"--height: must be > 0"),
    ("simulate-noise-garbage", argv_of("simulate", "--out", "{w}/s", "--noise", "{{bad json", "--frames", "2"),
     r"--noise: expected"),
    ("simulate-noise-unknown-key", argv_of("simulate", "--out", "{w}/s", "--noise", '{{"bogus": 1}}', "--frames", "2"),
     r"unknown noise parameter\(s\) bogus"),
    ("simulate-ply-text", lambda b, w: ["simulate", "--out", str(w / "s"), "--ply",
                                        str((w / "t.ply").write_text("x") and w / "t.ply"), "--frames", "2"],
     r"not a readable PLY"),
    ("simulate-out-user-folder", lambda b, w: ["simulate", "--out", str(_user_folder(w)), "--frames", "2", "--size", "40x30"],
     r"already holds other files"),  # and with --overwrite: test_bad_input_outputs
    ("simulate-fx-zero", argv_of("simulate", "--out", "{w}/s", "--fx", "0", "--frames", "2", "--size", "40x30"),
     r"--fx: must be > 0"),
    ("simulate-missing-intrinsics", argv_of("simulate", "--out", "{w}/s", "--intrinsics", "{w}/none.json", "--frames", "2"),
     r"none\.json: no intrinsics file"),
    # show / panoptic
    ("show-missing-map", argv_of("show", "{w}/none.ply", "--html", "{w}/x.html"), r"no such map file"),
    ("show-empty-map", lambda b, w: ["show", str(_odd_map(b, w, "empty.ply", "empty")), "--html", str(w / "x.html")],
     r"empty\.ply: the map is empty \(no vertices\)"),
    ("evaluate-vertex-at-1e30", lambda b, w: ["evaluate", str(b / "scene.ply"), str(_odd_map(b, w, "far.ply", "far"))],
     r"far\.ply: 1 vertices lie beyond 10000 m"),
    ("show-html-is-a-folder", argv_of("show", "{base}/map.ply", "--html", "{w}"), r"is a folder"),
    ("panoptic-evaluate-missing", argv_of("panoptic", "evaluate", "{w}/none.ply", "{base}/map.ply"), r"no such map file"),
    ("panoptic-evaluate-no-instances", argv_of("panoptic", "evaluate", "{base}/scene.ply", "{base}/map.ply"),
     r"scene\.ply: the map has no instance layer"),
    ("panoptic-transfer-no-instances", argv_of("panoptic", "transfer", "{base}/low", "--map", "{base}/map.ply",
                                               "--method", "3d-neighborhood", "--out", "{w}/pt"), r"no instance layer"),
]


def _files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*")}


@pytest.mark.parametrize("setup,pattern", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_a_clear_error(base, tmp_path, capsys, setup, pattern):
    import re

    w = tmp_path / "w"
    w.mkdir()
    argv = setup(base, w)
    before_w, before_base = _files(w), _files(base)
    try:
        rc = main(argv)
    except SystemExit as e:  # argparse errors
        rc = e.code
    err = capsys.readouterr().err
    assert rc == 2, f"exit {rc}; stderr: {err[-500:]}"
    assert "Traceback" not in err
    assert re.search(pattern, err), f"expected /{pattern}/ in: {err[-500:]}"
    # nothing half-written: no new file anywhere except what the case set up, inputs untouched
    assert _files(w) == before_w, f"left behind: {sorted(_files(w) - before_w)}"
    assert _files(base) == before_base


def test_the_corpus_is_large_and_has_unique_names():
    names = [c[0] for c in CASES]
    assert len(names) >= 60 and len(set(names)) == len(names)
