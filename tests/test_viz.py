"""Interactive 3D views: figures, decimation, self-contained pages drawn by a real browser."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from semmatch.io import SemanticMap, write_map
from semmatch.viz import decimate, error_figure, map_figure, trajectory_trace, write_html


def _room_mesh(n: int = 60) -> SemanticMap:
    """A floor grid (label 2) with a raised block (label 4) and a ceiling (label 3)."""
    xs, ys = np.meshgrid(np.linspace(0, 3, n), np.linspace(0, 2, n))
    z = np.where((xs > 1) & (xs < 2) & (ys > 0.5) & (ys < 1.5), 0.5, 0.0)
    pts = np.stack([xs.ravel(), ys.ravel(), z.ravel()], axis=1)
    lab = np.where(z.ravel() > 0, 4, 2)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([b, d, c], 1)])
    ceiling = pts + [0, 0, 2.5]
    return SemanticMap(np.vstack([pts, ceiling]), np.r_[lab, np.full(len(ceiling), 3)],
                       faces=np.vstack([faces, faces + n * n]), instances=np.r_[np.where(lab == 4, 7, 0), np.zeros(n * n)])


def test_decimate_keeps_labels_and_the_budget():
    m = _room_mesh(120)
    small = decimate(m, 3000)
    assert len(small) <= 4500 and small.is_mesh
    assert set(np.unique(small.labels)) == {2, 3, 4}
    assert small.instances is not None and set(np.unique(small.instances)) == {0, 7}
    assert decimate(m, len(m)) is m


def test_map_figure_hides_the_ceiling_and_colours_instances():
    fig = map_figure(_room_mesh(), max_vertices=10_000)
    mesh = fig.data[0]
    assert mesh.type == "mesh3d"
    assert max(mesh.z[list(mesh.k)]) < 1.0  # no ceiling face left
    inst = map_figure(_room_mesh(), color_by="instances")
    block = np.flatnonzero(np.asarray(inst.data[0].z) > 0.25)[0]  # a vertex of instance 7
    assert inst.data[0].vertexcolor[block] != fig.data[0].vertexcolor[block]
    with pytest.raises(ValueError, match="no instance layer"):
        map_figure(SemanticMap(np.zeros((3, 3)), np.array([4, 4, 4])), color_by="instances")


def test_error_figure_counts_correct_wrong_unsupported():
    pts = np.array([[0.01, 0.01, 0.01], [0.11, 0.01, 0.01], [0.21, 0.01, 0.01]], np.float32)
    ref = SemanticMap(pts, np.array([4, 5, 2]))
    pred = SemanticMap(pts, np.array([4, 2, 0]))
    fig = error_figure(pred, ref, 0.1)
    counts = {t.name.split(" (")[0]: len(t.x) for t in fig.data}
    assert counts == {"correct": 1, "wrong": 1, "unsupported": 1}


def test_trajectory_trace_and_bad_poses():
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[:, 0, 3] = [0, 1, 2]
    assert list(trajectory_trace(poses, "cam").x) == [0, 1, 2]
    with pytest.raises(ValueError, match="poses must have shape"):
        trajectory_trace(np.eye(4), "cam")


def test_cli_show_writes_a_self_contained_page(tmp_path):
    from semmatch.cli import main

    write_map(tmp_path / "m.ply", _room_mesh())
    assert main(["show", str(tmp_path / "m.ply"), "--html", str(tmp_path / "m.html")]) == 0
    assert main(["show", str(tmp_path / "m.ply"), "--reference", str(tmp_path / "m.ply"),
                 "--html", str(tmp_path / "e.html")]) == 0
    page = (tmp_path / "m.html").read_text()
    assert "<script" in page and "src=\"http" not in page  # plotly.js inlined: works offline


@pytest.mark.skipif(shutil.which("chromium") is None, reason="chromium not installed (make test installs it)")
def test_page_draws_in_a_headless_browser(tmp_path):
    from PIL import Image

    write_html(map_figure(_room_mesh()), tmp_path / "m.html")
    shot = tmp_path / "shot.png"
    run = subprocess.run(
        ["chromium", "--headless=new", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
         "--use-angle=swiftshader", "--enable-logging=stderr", "--v=0", "--window-size=800,600",
         "--virtual-time-budget=15000", f"--screenshot={shot}", (tmp_path / "m.html").as_uri()],
        capture_output=True, text=True, timeout=120)
    assert shot.is_file(), run.stderr[-2000:]
    assert "Uncaught" not in run.stderr, run.stderr[-2000:]
    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    drawn = (np.abs(img - 255).sum(axis=2) > 60).mean()
    assert drawn > 0.05, f"the page looks blank ({drawn:.1%} of the pixels drawn)"
    # the floor's palette colour (label 2) is on screen, shaded
    floor = np.array([244, 243, 131])
    assert (np.abs(img - floor).sum(axis=2) < 120).sum() > 500
