"""Interactive 3D views: figures, decimation, self-contained pages drawn by a real browser."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from semmatch.io import SemanticMap, write_map
from semmatch.plots.views import (
    ERROR_COLOURS,
    decimate,
    error_figure,
    map_figure,
    trajectory_name,
    trajectory_trace,
    write_html,
)


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
    colours = {t.name.split(" (")[0]: t.marker.color for t in fig.data}
    assert colours == ERROR_COLOURS and colours["correct"] == "rgb(0,114,178)"  # blue / orange, not green / red
    assert fig.layout.legend.itemsizing == "constant"  # legend markers readable whatever the point size


def test_label_view_has_a_category_legend():
    from semmatch.io.labels import NAMES

    fig = map_figure(_room_mesh())
    entries = [t.name for t in fig.data if t.showlegend]
    assert entries == [NAMES[2], NAMES[4]]  # floor and the block; the hidden ceiling is not listed
    assert fig.data[0].showlegend is False and fig.layout.showlegend
    assert all(t.marker.size >= 10 for t in fig.data[1:])
    inst = map_figure(_room_mesh(), color_by="instances")
    assert [t.name for t in inst.data if t.showlegend] == []  # instance colours are not categories


def test_trajectory_names_say_whose_path(tmp_path):
    import json

    for folder, who in (("upper", "upper"), ("lower", "lower"), ("lower_shared", "lower_shared")):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "meta.json").write_text(json.dumps({"trajectory": who, "scene": "office_7001"}))
    assert trajectory_name(tmp_path / "upper") == "person (office_7001)"
    assert trajectory_name(tmp_path / "lower") == "robot (office_7001)"
    assert trajectory_name(tmp_path / "lower_shared") == "robot on the person's route (office_7001)"
    (tmp_path / "rec").mkdir()
    assert trajectory_name(tmp_path / "rec") == "rec"  # no meta.json: the folder's name


def test_plotlyjs_modes(tmp_path):
    from semmatch.cli import main

    write_map(tmp_path / "m.ply", _room_mesh())
    for mode in ("directory", "cdn"):
        out = tmp_path / mode
        out.mkdir()
        for name in ("a", "b"):
            assert main(["show", str(tmp_path / "m.ply"), "--html", str(out / f"{name}.html"),
                         "--plotlyjs", mode]) == 0
    shared = tmp_path / "directory" / "plotly.min.js"
    assert shared.stat().st_size > 1_000_000 and len(list((tmp_path / "directory").glob("*.js"))) == 1
    for name in ("a", "b"):
        page = (tmp_path / "directory" / f"{name}.html").read_text()
        assert 'src="plotly.min.js"' in page and "src=\"http" not in page
        assert len(page) < shared.stat().st_size / 4  # the library is not inside the page
        assert 'src="https://cdn.plot.ly/' in (tmp_path / "cdn" / f"{name}.html").read_text()
    assert not list((tmp_path / "cdn").glob("*.js"))
    with pytest.raises(ValueError, match="plotlyjs must be one of"):
        write_html(map_figure(_room_mesh()), tmp_path / "x.html", plotlyjs="embedded")


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


def _legend(dom: str) -> dict[str, float]:
    """Legend text -> size (px) of its marker, from a page's rendered DOM."""
    import re

    out = {}
    for item in re.findall(r'<g class="traces".*?</g></g></g>', dom):
        text = re.search(r'class="legendtext"[^>]*>([^<]*)', item)
        mark = re.search(r'class="scatterpts"[^>]*d="M([\d.]+),', item)
        if text:
            out[text.group(1)] = 2 * float(mark.group(1)) if mark else 0.0
    return out


@pytest.mark.skipif(shutil.which("chromium") is None, reason="chromium not installed (make test installs it)")
def test_show_pages_have_readable_legends_in_a_browser(tmp_path):
    """Label view (category legend, named camera paths) and error view, sharing one plotly.min.js."""
    import json

    from semmatch.cli import main
    from semmatch.io import SequenceWriter
    from semmatch.io.geometry import Intrinsics

    m = _room_mesh()
    write_map(tmp_path / "m.ply", m)
    ref = m.labels.copy()
    ref[: len(ref) // 8] = 5  # some wrong, some unsupported (void in the map)
    write_map(tmp_path / "ref.ply", SemanticMap(m.points, ref, faces=m.faces))
    write_map(tmp_path / "m.ply", SemanticMap(m.points, np.where(np.arange(len(ref)) % 7 == 0, 0, m.labels),
                                              faces=m.faces))
    seq = tmp_path / "upper"
    with SequenceWriter(seq, Intrinsics(8, 6, 5.0, 5.0, 4.0, 3.0)) as w:
        for x in (0.5, 1.5, 2.5):
            pose = np.eye(4)
            pose[:3, 3] = [x, 1.0, 1.6]
            w.add(np.zeros((6, 8, 3), np.uint8), np.ones((6, 8), np.float32), pose)
        w.write_extra("meta.json", json.dumps({"trajectory": "upper"}))
    pages = {}
    for name, extra in (("labels", ["--trajectory", str(seq)]), ("errors", ["--reference", str(tmp_path / "ref.ply")])):
        pages[name] = tmp_path / "site" / f"{name}.html"
        pages[name].parent.mkdir(exist_ok=True)
        assert main(["show", str(tmp_path / "m.ply"), "--html", str(pages[name]), "--plotlyjs", "directory",
                     *extra]) == 0
    legends = {}
    for name, page in pages.items():
        run = subprocess.run(["chromium", "--headless=new", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
                              "--use-angle=swiftshader", "--window-size=900,600", "--virtual-time-budget=15000",
                              "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120)
        legends[name] = _legend(run.stdout)
    assert {"floor", "chair", "person"} <= set(legends["labels"]), legends
    assert {k.split(" (")[0] for k in legends["errors"]} == {"correct", "wrong", "unsupported"}, legends
    assert min(v for d in legends.values() for v in d.values()) >= 10  # no 1-2 px legend markers
