"""Outputs never harm inputs, caches never lie, no score is a silent zero.

Every case runs the command line in this process (``semmatch.cli.main``) and checks its exit
code, its message and the files: the inputs of a tiny simulated data set are hashed before and
after every case, hidden files included.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from semmatch.cli import build_parser, main

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    from test_bad_input import make_corpus

    d = make_corpus(tmp_path_factory.mktemp("outputs"))
    assert main(["predict", str(d / "low"), "--model", "noisy:0.1", "--probs", "--out", str(d / "pred"), "--quiet"]) == 0
    (d / "model.pt").write_bytes(b"stands for a checkpoint: the paths are checked before anything is read")
    return d


def _digest(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _run(argv: list[str], capsys) -> tuple[int, str]:
    try:
        rc = main(argv)
    except SystemExit as e:  # argparse
        rc = e.code
    return rc, capsys.readouterr().err


def _user_folder(w: Path) -> Path:
    d = w / "mine"
    d.mkdir()
    (d / "precious.txt").write_text("the user's file")
    return d


def _user_pair(w: Path) -> Path:
    """A folder whose ``upper/`` is the user's (``simulate --pair`` would write DIR/upper)."""
    (w / "pair").mkdir()
    _user_folder(w).rename(w / "pair" / "upper")
    return w / "pair"


def _hard_link(b: Path, w: Path) -> Path:
    os.link(b / "map.ply", w / "hard.ply")
    return w / "hard.ply"


def _sym_link(b: Path, w: Path) -> Path:
    (w / "sym.ply").symlink_to(b / "map.ply")
    return w / "sym.ply"


IS, INSIDE, CONTAINS, OTHER = (r"is the input", r"lies inside the input", r"contains the input",
                               r"the other output")
DID_NOT_WRITE = r"did not write"

# (id, argv with {b} = inputs, {w} = a scratch folder, expected message)
CASES = [
    ("reconstruct-out-on-poses", "reconstruct {b}/seq --out {b}/seq/poses.txt", INSIDE),
    ("reconstruct-out-on-labels-input", "reconstruct {b}/low --labels {b}/pred --out {b}/pred", IS),
    ("reconstruct-rgb-out-is-out", "reconstruct {b}/seq --out {w}/a.ply --rgb-out {w}/a.ply", OTHER),
    ("reconstruct-poses-out-in-seq", "reconstruct {b}/seq --estimate-poses --poses-out {b}/seq/poses.txt "
     "--out {w}/a.ply", INSIDE),
    ("reconstruct-out-contains-seq", "reconstruct {b}/seq --out {b}", CONTAINS),
    ("show-html-on-map", "show {b}/map.ply --html {b}/map.ply", IS),
    ("show-html-on-reference", "show {b}/map.ply --reference {b}/scene.ply --html {b}/scene.ply", IS),
    ("show-html-in-trajectory", "show {b}/map.ply --trajectory {b}/seq --html {b}/seq/x.html", INSIDE),
    ("show-html-hard-link-of-map", lambda b, w: f"show {b}/map.ply --html {_hard_link(b, w)}", IS),
    ("show-html-symlink-to-map", lambda b, w: f"show {b}/map.ply --html {_sym_link(b, w)}", IS),
    ("evaluate-csv-on-gt", "evaluate {b}/scene.ply {b}/map.ply --csv {b}/scene.ply", IS),
    ("evaluate-markdown-on-pred", "evaluate {b}/scene.ply {b}/map.ply --markdown {b}/map.ply", IS),
    ("evaluate-figure-on-pred", "evaluate {b}/scene.ply {b}/map.ply {b}/map.ply --figure {b}/map.ply", IS),
    ("evaluate-csv-is-markdown", "evaluate {b}/scene.ply {b}/map.ply --csv {w}/t --markdown {w}/t", OTHER),
    ("simulate-out-holds-ply", "simulate --ply {b}/scene.ply --out {b} --overwrite --frames 2 --size 40x30", CONTAINS),
    ("simulate-pair-holds-ply", "simulate --ply {b}/scene.ply --pair --out {b} --overwrite --frames 2 --size 40x30",
     CONTAINS),
    ("simulate-out-holds-intrinsics", "simulate --intrinsics {b}/seq/intrinsics.json --out {b}/seq --overwrite "
     "--frames 2", CONTAINS),
    ("simulate-save-scene-in-out", "simulate --out {w}/s --save-scene {w}/s/scene.ply --frames 2 --size 40x30", OTHER),
    ("simulate-overwrite-user-folder", lambda b, w: f"simulate --out {_user_folder(w)} --overwrite --frames 2 "
     "--size 40x30 --quiet", DID_NOT_WRITE),
    ("simulate-pair-overwrite-user-folder", lambda b, w: f"simulate --pair --out {_user_pair(w)} --overwrite "
     "--frames 2 --size 40x30 --quiet", DID_NOT_WRITE),
    ("transfer-fused-probs-inside-out", "transfer {b}/low --map {b}/map.ply --method fused --probs {b}/pred/probs "
     "--out {b}/pred --overwrite", CONTAINS),
    ("transfer-out-on-map", "transfer {b}/low --map {b}/map.ply --method 3d-neighborhood --out {b}/map.ply", IS),
    ("transfer-sequence-flag-out-inside", "transfer --sequence {b}/low --map {b}/map.ply --method 3d-neighborhood "
     "--out {b}/low/labels --overwrite", INSIDE),
    ("predict-out-in-seq", "predict {b}/seq --model noisy:0.1 --out {b}/seq/labels --overwrite", INSIDE),
    ("predict-out-on-model", "predict {b}/seq --model {b}/model.pt --out {b}/model.pt", IS),
    ("predict-overwrite-user-folder", lambda b, w: f"predict {b}/seq --model noisy:0.1 --out {_user_folder(w)} "
     "--overwrite --quiet", DID_NOT_WRITE),
    ("predict-overwrite-a-sequence", "predict {b}/low --model noisy:0.1 --out {b}/seq --overwrite --quiet",
     r"holds a semmatch sequence output"),
    ("panoptic-segment-out-on-map", "panoptic segment {b}/map.ply --out {b}/map.ply", IS),
    ("panoptic-reference-out-in-seq", "panoptic reference {b}/seq --out {b}/seq/pan.ply", INSIDE),
    ("panoptic-transfer-out-in-low", "panoptic transfer {b}/low --map {b}/map.ply --method 3d-neighborhood "
     "--out {b}/low/pan.ply", INSIDE),
    ("panoptic-evaluate-csv-on-gt", "panoptic evaluate {b}/scene.ply {b}/map.ply --csv {b}/scene.ply", IS),
    ("adapt-out-on-model", "adapt --model {b}/model.pt --source 3d-neighborhood --out {b}/model.pt --seeds 1", IS),
]


def test_no_verb_writes_over_into_or_around_an_input(base, tmp_path, capsys):
    """Every case: exit 2, a message naming both paths, no input changed, nothing written."""
    before = _digest(base)
    verbs = set()
    for name, argv, pattern in CASES:
        w = tmp_path / name
        w.mkdir()
        text = argv(base, w) if callable(argv) else argv.format(b=base, w=w)
        argv_list = text.split()
        verbs.add(argv_list[0])
        scratch = _digest(w)
        rc, err = _run(argv_list, capsys)
        assert rc == 2, f"{name}: exit {rc}; {err[-400:]}"
        assert "Traceback" not in err and re.search(pattern, err), f"{name}: {err[-400:]}"
        assert _digest(base) == before, f"{name}: an input changed"
        assert _digest(w) == scratch, f"{name}: wrote {sorted(set(_digest(w)) - set(scratch))}"
        assert not list(base.rglob("*.partial")) and not list(w.rglob("*.partial")), name
    assert verbs >= {"reconstruct", "show", "evaluate", "simulate", "transfer", "predict", "panoptic", "adapt"}


def test_every_verb_declares_its_inputs_and_outputs():
    """A verb that writes files opts into the output policy (semmatch.io.outputs.declare_paths)."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "verb")
    missing = []
    for verb, p in sub.choices.items():
        if verb == "bench":
            continue  # prints numbers, writes nothing
        nested = [a for a in p._actions if a.dest == "action"]
        for name, q in (nested[0].choices.items() if nested else [(verb, p)]):
            if "_semmatch_outputs" not in q._defaults:
                missing.append(name)
    assert not missing, f"verbs without declared inputs/outputs: {missing}"


def test_overwrite_replaces_only_what_semmatch_wrote(base, tmp_path, capsys):
    out = tmp_path / "s"
    args = ["simulate", "--frames", "2", "--size", "40x30", "--quiet", "--out", str(out)]
    assert main(args) == 0
    assert json.loads((out / ".semmatch-output").read_text()) == {"kind": "sequence"}
    rc, err = _run(args, capsys)
    assert rc == 2 and "--overwrite" in err
    assert main([*args, "--overwrite", "--seed", "1"]) == 0  # its own output: replaced
    assert json.loads((out / "meta.json").read_text())["seed"] == 1
    # a sequence semmatch did not write (no marker) is not replaced
    (out / ".semmatch-output").unlink()
    rc, err = _run([*args, "--overwrite"], capsys)
    assert rc == 2 and re.search(rf"{re.escape(str(out))}: output folder already holds another sequence that "
                                 r"semmatch did not write", err)


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_stale_temporary_folders_are_swept_live_ones_kept(base, tmp_path):
    """Temporary folders of dead writers of this machine are swept, with or without the host in
    their name; those of a live writer or of another machine stay."""
    from semmatch.io.outputs import HOST_TAG

    dead = _dead_pid()
    out = tmp_path / "p"
    stale = [tmp_path / f".p.{dead}-abc123.partial", tmp_path / f".p.probs.{dead}-x_y9.partial",
             tmp_path / f".p.{HOST_TAG}_{dead}-abc124.partial"]
    live = tmp_path / f".p.{os.getppid()}-live00.partial"
    # a writer on another machine sharing the folder: its process id means nothing here
    other = tmp_path / f".p.{HOST_TAG}x_{dead}-abc125.partial"
    for d in (*stale, live, other):
        d.mkdir()
        (d / "000000.npy").write_bytes(b"x" * 100)
    assert main(["predict", str(base / "low"), "--model", "noisy:0.1", "--probs", "--out", str(out), "--quiet"]) == 0
    assert not any(d.exists() for d in stale)
    assert live.exists() and other.exists()
    assert sorted(p.name for p in out.iterdir()) == [".semmatch-output", "000000.png", "000001.png", "000002.png",
                                                     "000003.png", "probs"]


def test_stale_temporary_files_of_atomic_writes_are_swept_live_ones_kept(tmp_path):
    """A SIGKILLed writer leaves ``.NAME.HOST_PID-RANDOM.tmp.EXT``; the next process that writes into
    the folder removes it and any other dead writer's of this machine (not those of a live writer,
    of another machine, nor other files; names without a host, as before 2026-11-27, are this
    machine's)."""
    from semmatch.io import atomic_write_text
    from semmatch.io.outputs import HOST_TAG

    dead = _dead_pid()
    stale = [tmp_path / f".map.{dead}-0123abcd.tmp.ply", tmp_path / f".other.{dead}-0123abcd.tmp",
             tmp_path / f".a.b.{dead}-89abcdef.tmp.png", tmp_path / f".map.{HOST_TAG}_{dead}-0123abce.tmp.ply"]
    live = tmp_path / f".map.{os.getppid()}-89abcdef.tmp.ply"
    keep = [tmp_path / f".map.{dead}-xyz.tmp.ply", tmp_path / "map.1234-0123abcd.tmp.ply", tmp_path / ".hidden",
            tmp_path / f".map.other{HOST_TAG}_{dead}-0123abcf.tmp.ply"]  # another machine's writer
    for f in (*stale, live, *keep):
        f.write_bytes(b"partial")
    atomic_write_text(tmp_path / "map.ply", "ply\n")
    assert (tmp_path / "map.ply").read_text() == "ply\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, *(k.name for k in keep), "map.ply"])
    # a killed writer's file in a folder this process has swept already waits for the next process
    late = tmp_path / f".late.{dead}-0123abcd.tmp"
    late.write_bytes(b"partial")
    atomic_write_text(tmp_path / "map.ply", "ply 2\n")
    assert late.exists()
    code = f"from semmatch.io import atomic_write_text; atomic_write_text({str(tmp_path / 'x.txt')!r}, 'x')"
    subprocess.run([sys.executable, "-c", code], check=True)
    assert not late.exists() and live.exists()


def test_sigterm_removes_the_temporary_folders(base, tmp_path, capsys, monkeypatch):
    """SIGTERM mid-run (as Ctrl-C): exit 143, no output, no temporary folder left."""
    import semmatch.cli.predict as cli_predict
    from semmatch.segment.oracle import NoisyOracle

    class Killed(NoisyOracle):
        calls = 0

        def predict_frame(self, frame):
            Killed.calls += 1
            if Killed.calls == 2:
                os.kill(os.getpid(), signal.SIGTERM)
            return super().predict_frame(frame)

    monkeypatch.setattr(cli_predict, "make_segmenter", lambda *a, **k: Killed(0.1))
    handler = signal.getsignal(signal.SIGTERM)
    rc, err = _run(["predict", str(base / "low"), "--model", "noisy:0.1", "--probs", "--out",
                    str(tmp_path / "p"), "--quiet"], capsys)
    assert rc == 143 and "terminated" in err
    assert Killed.calls == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    assert signal.getsignal(signal.SIGTERM) == handler  # restored


# ------------------------------------------------------------------------------------------ inputs
def _bomb_ply(w: Path) -> Path:
    """An 87 KB ASCII PLY whose header, padded past 64 KiB with comments, claims 3*10^8 faces."""
    head = ["ply", "format ascii 1.0", *["comment " + "x" * 70] * 1100, "element vertex 3", "property float x",
            "property float y", "property float z", "property uchar red", "property uchar green",
            "property uchar blue", "element face 300000000", "property list uchar int vertex_indices", "end_header"]
    p = w / "bomb.ply"
    p.write_text("\n".join([*head, "0 0 0 1 1 1", "1 0 0 1 1 1", "0 1 0 1 1 1", "3 0 1 2"]) + "\n")
    assert p.stat().st_size > 64 * 1024
    return p


def _huge_checkpoint(w: Path) -> Path:
    import torch

    from semmatch.io.labels import table_fingerprint
    from semmatch.segment.models import CHECKPOINT_FORMAT

    p = w / "huge.pt"
    torch.save({"format": CHECKPOINT_FORMAT, "categories": table_fingerprint(), "state_dict": {},
                "model": {"arch": "compact", "use_depth": False, "width": 100000, "height": 100000,
                          "num_classes": 21}}, p)
    return p


def _void_map(b: Path, w: Path) -> Path:
    from semmatch.io import read_map, write_map

    m = read_map(b / "scene.ply")
    m.labels = np.zeros_like(m.labels)
    write_map(w / "void.ply", m)
    return w / "void.ply"


def _empty_sequence(b: Path, w: Path) -> Path:
    s = w / "empty"
    for sub in ("rgb", "depth"):
        (s / sub).mkdir(parents=True)
    shutil.copy(b / "seq" / "intrinsics.json", s)
    (s / "poses.txt").write_text("# no frames\n")
    return s


def _far_pose(b: Path, w: Path) -> Path:
    """A copy of the sequence whose second pose lies 10^30 m away."""
    s = w / "far"
    shutil.copytree(b / "seq", s)
    lines = (s / "poses.txt").read_text().splitlines()
    k = [i for i, ln in enumerate(lines) if ln and not ln.startswith("#")][1]
    v = lines[k].split()
    lines[k] = " ".join([v[0], "1e30", *v[2:]])
    (s / "poses.txt").write_text("\n".join(lines) + "\n")
    return s


INPUT_CASES = [
    ("pose-far-away", lambda b, w: f"reconstruct {_far_pose(b, w)} --out {w}/m.ply",
     r"far/poses\.txt:\d+ \(pose 1\): camera position \[1e\+30, .* beyond 10000 m"),
    ("ply-header-padded-past-64k", lambda b, w: f"show {_bomb_ply(w)} --html {w}/x.html",
     r"bomb\.ply: PLY header claims 300,000,000 face elements"),
    ("show-max-vertices-zero", "show {b}/map.ply --html {w}/x.html --max-vertices 0", r"--max-vertices: must be >= 1"),
    ("show-max-vertices-negative", "show {b}/map.ply --html {w}/x.html --max-vertices=-5",
     r"--max-vertices: must be >= 1"),
    ("reconstruct-trunc-voxels-huge", "reconstruct {b}/seq --out {w}/m.ply --trunc-voxels 10000",
     r"--trunc-voxels: must be <= 64"),
    ("reconstruct-min-weight-negative", "reconstruct {b}/seq --out {w}/m.ply --min-weight=-1",
     r"--min-weight: must be >= 0"),
    ("reconstruct-trunc-voxels-nan", "reconstruct {b}/seq --out {w}/m.ply --trunc-voxels nan",
     r"--trunc-voxels: must be a finite number"),
    ("reconstruct-voxel-over-budget", "reconstruct {b}/seq --out {w}/m.ply --voxel-size 0.0015 --memory-budget 0.25",
     r"seq: a 0\.0015 m voxel grid over this scene .* is estimated at .* GiB, above the budget of 0\.2 GiB"),
    ("checkpoint-100000-pixels", lambda b, w: f"predict {b}/seq --model {_huge_checkpoint(w)} --out {w}/p",
     r"huge\.pt: bad architecture config \(network input must be 16\.\.4096 pixels a side, got 100000x100000\)"),
    ("evaluate-all-void-reference", lambda b, w: f"evaluate {_void_map(b, w)} {b}/map.ply",
     r"void\.ply: the ground truth has no voxel of an evaluated class"),
    ("evaluate-void-prediction-strict", lambda b, w: f"evaluate {b}/scene.ply {_void_map(b, w)} --strict",
     r"void\.ply: no voxel with an evaluated class .* \(--strict\)"),
    ("predict-sequence-without-frames", lambda b, w: f"predict {_empty_sequence(b, w)} --model noisy:0.1 --out {w}/p",
     r"empty: the sequence has no frames"),
]


def test_bad_inputs_are_refused_before_any_work(base, tmp_path, capsys):
    before = _digest(base)
    for name, argv, pattern in INPUT_CASES:
        w = tmp_path / name
        w.mkdir()
        text = argv(base, w) if callable(argv) else argv.format(b=base, w=w)
        scratch = _digest(w)
        rc, err = _run(text.split(), capsys)
        assert rc == 2, f"{name}: exit {rc}; {err[-400:]}"
        assert "Traceback" not in err and re.search(pattern, err), f"{name}: {err[-400:]}"
        assert _digest(w) == scratch, f"{name}: wrote {sorted(set(_digest(w)) - set(scratch))}"
    assert _digest(base) == before


def test_void_prediction_warns_without_strict(base, tmp_path, capsys):
    void = _void_map(base, tmp_path)
    with pytest.warns(UserWarning, match=r"void\.ply: no voxel with an evaluated class"):
        assert main(["evaluate", str(base / "scene.ply"), str(void)]) == 0


def test_panoptic_evaluate_warns_on_low_overlap(base, tmp_path):
    from semmatch.io import read_map, write_map

    pan = tmp_path / "pan.ply"
    m = read_map(base / "map.ply")
    m.instances = m.labels.astype(np.int32)  # one instance per class: enough to score
    write_map(pan, m)
    far = read_map(pan)
    far.points = far.points + 100.0  # another frame: no voxel in common
    write_map(tmp_path / "far.ply", far)
    with pytest.warns(UserWarning, match=r"far\.ply vs .*pan\.ply: only 0 of .* overlap"):
        assert main(["panoptic", "evaluate", str(pan), str(tmp_path / "far.ply")]) == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # full overlap: no warning
        assert main(["panoptic", "evaluate", str(pan), str(pan)]) == 0


def test_a_killed_worker_is_a_clear_error_naming_the_frame(base, tmp_path, capsys, monkeypatch):
    """transfer --jobs 2 whose worker is killed at frame 2 (as by the out-of-memory killer): a message
    naming the sequence and the first frame not transferred, exit 2, no output, no traceback."""
    import semmatch.transfer.sequence as ts

    monkeypatch.setattr(ts, "_run_one", _killed_at_frame_2)
    rc, err = _run(["transfer", str(base / "low"), "--map", str(base / "map.ply"), "--method", "3d-neighborhood",
                    "--out", str(tmp_path / "out"), "--jobs", "2", "--quiet"], capsys)
    assert rc == 2 and "Traceback" not in err, err
    assert re.search(r"a worker process died .*low: frame [0-2] of 4 \(3d-neighborhood\) and those after it were not "
                     r"transferred.* rerun with fewer worker processes \(--jobs 2 now\)", err), err
    assert sorted(tmp_path.iterdir()) == []


def _killed_at_frame_2(i: int):
    """A transfer worker's task that dies (SIGKILL) on frame 2 (runs in a forked worker)."""
    import semmatch.transfer.sequence as ts

    if i == 2:
        os.kill(os.getpid(), signal.SIGKILL)
    w = ts._WORKER
    return ts._transfer_one(w["seq"], w["poses"], w["index"], w["method"], w["params"], i)


# ------------------------------------------------------------------------------------------ caches
def _cache_of(map_path: Path) -> Path:
    from semmatch.transfer.index import index_cache_path

    cf = index_cache_path(map_path)
    assert cf.is_file()
    return cf


def _rewrite(cf: Path, **change) -> None:
    with np.load(cf) as z:
        data = {k: z[k] for k in z.files}
    data.update(change)
    cf.unlink()
    with open(cf, "wb") as fh:
        np.savez_compressed(fh, **data)


def test_index_cache_that_lies_is_rebuilt_with_a_warning(base, tmp_path):
    from semmatch.io import read_map
    from semmatch.transfer import MapIndex, load_index

    pts = read_map(base / "scene.ply").points[::7]
    m = tmp_path / "map.ply"
    shutil.copy(base / "map.ply", m)
    truth = MapIndex(read_map(m)).lookup(pts)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_index(m)  # writes the cache
        np.testing.assert_array_equal(load_index(m).lookup(pts), truth)  # read from it, no warning
    cf = _cache_of(m)
    # tampered: labels changed in the blocks, the stored digest left as it was
    with np.load(cf) as z:
        blocks = z["blocks"].copy()
    blocks[blocks > 0] = (blocks[blocks > 0] % 20) + 1
    _rewrite(cf, blocks=blocks)
    with pytest.warns(UserWarning, match="do not match their stored digest"):
        np.testing.assert_array_equal(load_index(m).lookup(pts), truth)
    # foreign: the cache of another map under this map's cache name
    other = tmp_path / "other.ply"
    from semmatch.io import write_map

    om = read_map(base / "map.ply")
    om.labels = (om.labels % 20) + 1
    write_map(other, om)
    load_index(other)
    shutil.copy(_cache_of(other), cf)
    with pytest.warns(UserWarning, match="made for another map"):
        np.testing.assert_array_equal(load_index(m).lookup(pts), truth)
    # a decompression bomb: 128 MiB of zeros in 130 KB, refused before it is decompressed
    import zipfile

    cf.unlink()
    with zipfile.ZipFile(cf, "w", zipfile.ZIP_DEFLATED) as zf, zf.open("blocks.npy", "w", force_zip64=True) as fh:
        np.lib.format.write_array_header_1_0(fh, {"descr": "|u1", "fortran_order": False, "shape": (1 << 27,)})
        chunk = bytes(1 << 24)
        for _ in range(8):
            fh.write(chunk)
    assert cf.stat().st_size < 1 << 20
    with pytest.warns(UserWarning, match=r"would decompress to 134,217,856 bytes, more than the"):
        np.testing.assert_array_equal(load_index(m).lookup(pts), truth)


def test_a_folder_at_the_index_caches_path_means_no_cache_not_a_failed_transfer(base, tmp_path):
    from semmatch.io import read_map
    from semmatch.transfer import MapIndex, load_index
    from semmatch.transfer.index import index_cache_path

    m = tmp_path / "map.ply"
    shutil.copy(base / "map.ply", m)
    cf = index_cache_path(m)
    cf.unlink(missing_ok=True)  # another test's transfer of the same map bytes
    cf.mkdir(parents=True)
    try:
        with pytest.warns(UserWarning, match=r"index cache not written \(.*is a folder"):
            index = load_index(m)
    finally:
        cf.rmdir()
    pts = read_map(base / "scene.ply").points[::7]
    np.testing.assert_array_equal(index.lookup(pts), MapIndex(read_map(m)).lookup(pts))


# ------------------------------------------------------------------------------------------ code from data
def test_no_checkpoint_is_loaded_with_pickle_code():
    """The package, the scripts and the notebooks load checkpoints as data only (weights_only=True)."""
    root = Path(__file__).resolve().parents[1]
    files = [p for d in ("semmatch", "scripts", "notebooks") for p in (root / d).rglob("*")
             if p.suffix in (".py", ".ipynb") and ".ipynb_checkpoints" not in p.parts]
    hits = [f"{p.relative_to(root)}:{n}" for p in files
            for n, line in enumerate(p.read_text().splitlines(), 1) if re.search(r"weights_only\W*=\W*False", line)]
    assert not hits, f"checkpoints loaded with weights_only=False: {hits}"


def test_reused_adaptation_checkpoint_cannot_run_code(tmp_path):
    import pickle

    from semmatch.experiments.adapt import _reuse_checkpoint

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {tmp_path / 'pwned'}",))

    evil = tmp_path / "evil.pt"
    evil.write_bytes(pickle.dumps({"adapted": Evil()}))
    with pytest.raises(ValueError, match="refuses to load"):
        _reuse_checkpoint(evil, tmp_path / "t.pt", tmp_path / "net.pt", "3d-neighborhood", {}, None)
    assert not (tmp_path / "pwned").exists() and not (tmp_path / "t.pt").exists()


# ------------------------------------------------------------------------------------------ recordings
def _tum(root: Path) -> Path:
    """A two-frame TUM RGB-D folder (grey frames, flat depth at 2 m)."""
    from semmatch.io import write_depth, write_image

    lines: dict[str, list[str]] = {"rgb": [], "depth": []}
    for t in (1.0, 1.1):
        write_image(root / f"rgb/{t:.6f}.png", np.full((48, 64, 3), 100, np.uint8))
        write_depth(root / f"depth/{t:.6f}.png", np.full((48, 64), 2.0, np.float32), 5000.0)
        for k in lines:
            lines[k].append(f"{t:.6f} {k}/{t:.6f}.png")
    for k, v in lines.items():
        (root / f"{k}.txt").write_text("\n".join(v) + "\n")
    return root


@pytest.mark.parametrize("entry", ["../outside.png", "/etc/hostname", "rgb/../../outside.png"])
def test_tum_list_entries_outside_the_folder_are_refused(tmp_path, entry):
    from semmatch.io.recordings import read_tum_rgbd

    root = _tum(tmp_path / "tum")
    shutil.copy(next((root / "rgb").iterdir()), tmp_path / "outside.png")
    lines = (root / "rgb.txt").read_text().splitlines()
    lines[-1] = f"{lines[-1].split()[0]} {entry}"
    (root / "rgb.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=rf"rgb\.txt: {re.escape(repr(entry))} lies outside the recording folder"):
        read_tum_rgbd(root)


def test_a_fifo_in_a_recording_is_refused_not_waited_on(tmp_path):
    from semmatch.io.recordings import read_tum_rgbd

    root = _tum(tmp_path / "tum")
    frame = sorted((root / "rgb").iterdir())[0]
    frame.unlink()
    os.mkfifo(frame)
    seq = read_tum_rgbd(root)
    with pytest.raises(ValueError, match=rf"{re.escape(frame.name)}: not a regular file"):
        seq[0]


def test_16_bit_colour_is_scaled_not_wrapped(base, tmp_path):
    import cv2

    from semmatch.io import read_rgb, read_sequence

    seq = tmp_path / "seq"
    shutil.copytree(base / "seq", seq)
    p = sorted((seq / "rgb").iterdir())[0]
    rgb8 = read_rgb(p)
    cv2.imwrite(str(p), rgb8[..., ::-1].astype(np.uint16) * 257)  # the same picture at 16 bits
    np.testing.assert_array_equal(read_sequence(seq)[0].rgb, rgb8)
    np.testing.assert_array_equal(read_rgb(p), rgb8)


# ------------------------------------------------------------------------------------------ fuzzing
def _tiny_plys(d: Path) -> dict[str, bytes]:
    from semmatch.io import SemanticMap, write_map

    rng = np.random.default_rng(0)
    pts = rng.random((12, 3)).astype(np.float32)
    m = SemanticMap(pts, rng.integers(0, 21, 12).astype(np.uint8), faces=np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]]))
    out = {}
    for binary in (True, False):
        p = d / f"t{int(binary)}.ply"
        write_map(p, m, binary=binary)
        out["binary" if binary else "ascii"] = p.read_bytes()
    return out


def _fuzz_settings():
    from hypothesis import HealthCheck, settings

    return settings(max_examples=40, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


def test_fuzzed_ply_files_are_read_or_refused_clearly(tmp_path):
    """Truncations, flipped bytes and rewritten counts: a map or a ValueError, never another error."""
    from hypothesis import given
    from hypothesis import strategies as st

    from semmatch.io import read_map

    plys = _tiny_plys(tmp_path)

    @_fuzz_settings()
    @given(kind=st.sampled_from(sorted(plys)), cut=st.integers(0, 2000),
           flips=st.lists(st.tuples(st.integers(0, 2000), st.integers(0, 255)), max_size=4),
           counts=st.lists(st.integers(-5, 10**12), min_size=2, max_size=2),
           padding=st.integers(0, 4))  # 4 x 20 kB of comments: a header past 64 KiB
    def check(kind, cut, flips, counts, padding):
        data = bytearray(plys[kind])
        head, sep, body = bytes(data).partition(b"end_header\n")
        lines = head.decode().splitlines()
        elements = [i for i, ln in enumerate(lines) if ln.startswith("element")]
        for i, n in zip(elements, counts):
            if n % 3 == 0:  # rewrite some counts only
                name = lines[i].split()[1]
                lines[i] = f"element {name} {n}"
        lines[1:1] = ["comment " + "p" * 20000] * padding
        data = bytearray("\n".join(lines).encode() + b"\n" + sep + body)
        for pos, value in flips:
            if pos < len(data):
                data[pos] = value
        if cut:
            data = data[: max(len(data) - cut, 0)]
        p = tmp_path / "fuzz.ply"
        p.write_bytes(bytes(data))
        try:
            m = read_map(p, require_labels=False)
        except ValueError:
            return
        assert len(m.points) <= 12 + 2000  # nothing larger than the file could hold

    check()


def test_fuzzed_trajectories_are_read_or_refused_clearly(tmp_path):
    from hypothesis import given
    from hypothesis import strategies as st

    from semmatch.io import read_tum

    token = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.sampled_from(["", "#", "x", "1e400"]))

    @_fuzz_settings()
    @given(st.lists(st.lists(token, min_size=0, max_size=9).map(" ".join), max_size=6))
    def check(lines):
        p = tmp_path / "poses.txt"
        p.write_text("\n".join(lines) + "\n")
        try:
            t, poses = read_tum(p)
        except ValueError:
            return
        assert np.isfinite(poses).all() and np.abs(poses[:, :3, 3]).max(initial=0) <= 1e4
        assert np.allclose(poses[:, :3, :3] @ poses[:, :3, :3].transpose(0, 2, 1), np.eye(3), atol=1e-6)

    check()


def test_fuzzed_list_entries_stay_inside_the_folder(tmp_path):
    from hypothesis import given
    from hypothesis import strategies as st

    from semmatch.io import listed_file

    part = st.sampled_from(["..", ".", "rgb", "a.png", "", "/", "~", "x..y"])

    @_fuzz_settings()
    @given(st.lists(part, min_size=1, max_size=5).map("/".join))
    def check(name):
        try:
            p = listed_file(tmp_path, name, "rgb.txt:1")
        except ValueError:
            return
        assert os.path.abspath(p).startswith(str(tmp_path))

    check()


def test_the_index_cache_goes_where_the_cli_says(base, tmp_path, monkeypatch):
    """``transfer --index-cache``: the user cache folder by default, 'beside' the map, or a
    given folder; ``--no-index-cache`` writes none."""
    monkeypatch.setenv("SEMMATCH_CACHE_DIR", str(tmp_path / "usercache"))
    m = tmp_path / "maps" / "map.ply"
    m.parent.mkdir()
    shutil.copy(base / "map.ply", m)

    def run(*extra: str, out: str) -> None:
        assert main(["transfer", str(base / "low"), "--map", str(m), "--method", "3d-neighborhood",
                     "--out", str(tmp_path / out), "--quiet", *extra]) == 0

    run("--no-index-cache", out="o0")
    assert not (tmp_path / "usercache").exists() and sorted(p.name for p in m.parent.iterdir()) == ["map.ply"]
    run(out="o1")
    assert [p.name for p in (tmp_path / "usercache" / "index").iterdir()][0].startswith("map.ply.index-")
    run("--index-cache", "beside", out="o2")
    assert any(p.name.startswith(".map.ply.index-") for p in m.parent.iterdir())
    run("--index-cache", str(tmp_path / "mine"), out="o3")
    assert [p.name for p in (tmp_path / "mine").iterdir()][0].startswith("map.ply.index-")
