"""Interactive 3D views (plotly) of semantic maps, errors and trajectories, for JupyterLab and HTML.

* :func:`map_figure`: a semantic (or panoptic) map in label or instance colours; large meshes
  are decimated for display (Open3D vertex clustering), point maps subsampled (seeded);
* :func:`error_figure`: a predicted map against a reference on voxels: correct, wrong,
  unsupported (the reference has a label, the prediction void), in colours that colour-blind
  readers can tell apart (blue / orange / grey);
* :func:`trajectory_trace`: a camera path to add to a figure (:func:`trajectory_name` names a
  simulated sequence "person" or "robot");
* :func:`write_html`: one page, plotly.js inlined (self-contained), shared from a file beside
  the pages, or loaded from a CDN; written atomically.

The legends (categories of the label view, the error classes, the camera paths) use markers of
one readable size, whatever the size of the points in the view.

``semmatch show MAP.ply [--reference GT.ply] --html OUT.html`` wraps them.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..io import SemanticMap, atomic_path, read_map, require_instances
from ..io.labels import NAMES, PALETTE, instance_colors

__all__ = ["map_figure", "error_figure", "trajectory_trace", "trajectory_name", "write_html", "decimate",
           "ERROR_COLOURS", "PLOTLYJS_MODES"]

#: vertices kept for display by default (a 500k-vertex map is decimated to about this)
MAX_DISPLAY_VERTICES = 150_000

#: correct / wrong / unsupported voxels: blue and orange of the Okabe-Ito palette (told apart with
#: any colour vision deficiency) and grey
ERROR_COLOURS = {"correct": "rgb(0,114,178)", "wrong": "rgb(230,159,0)", "unsupported": "rgb(150,150,150)"}

#: how a page gets plotly.js (:func:`write_html`)
PLOTLYJS_MODES = ("inline", "directory", "cdn")

#: legends: every entry drawn with a marker of this size, and room for it
_LEGEND = dict(itemsizing="constant", font=dict(size=13), bgcolor="rgba(255,255,255,0.8)")


def _as_map(m: SemanticMap | str | os.PathLike) -> SemanticMap:
    return (read_map(m) if isinstance(m, str | os.PathLike) else m).check()


def decimate(m: SemanticMap, max_vertices: int = MAX_DISPLAY_VERTICES, *, seed: int = 0) -> SemanticMap:
    """A lighter copy of ``m`` for display, with at most about ``max_vertices`` vertices.

    Meshes: Open3D vertex clustering at the cell size whose count of surface cells matches
    ``max_vertices``; every new vertex takes the label (and instance) of the nearest original
    vertex. Point maps: a seeded random subset.

    Raises
    ------
    ValueError
        ``max_vertices`` below 1.
    """
    if not max_vertices >= 1:
        raise ValueError(f"max_vertices must be >= 1, got {max_vertices}")
    if len(m) <= max_vertices:
        return m
    if not m.is_mesh:
        keep = np.sort(np.random.default_rng(seed).choice(len(m), int(max_vertices), replace=False))
        return SemanticMap(m.points[keep], m.labels[keep], source=m.source,
                           instances=None if m.instances is None else m.instances[keep])
    import open3d as o3d
    from scipy.spatial import cKDTree

    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(m.points.astype(np.float64)),
                                     o3d.utility.Vector3iVector(m.faces))
    cell = float(np.sqrt(mesh.get_surface_area() / max_vertices)) * 1.2
    small = mesh.simplify_vertex_clustering(cell, o3d.geometry.SimplificationContraction.Average)
    pts = np.asarray(small.vertices, dtype=np.float32)
    _, near = cKDTree(m.points).query(pts, workers=-1)
    return SemanticMap(pts, m.labels[near], faces=np.asarray(small.triangles), source=m.source,
                       instances=None if m.instances is None else m.instances[near])


def _hover(labels: np.ndarray, instances: np.ndarray | None) -> np.ndarray:
    names = np.asarray(NAMES, dtype=object)[labels]
    if instances is None:
        return names
    return np.array([f"{n} #{i}" if i else n for n, i in zip(names, instances)], dtype=object)


def _colors(m: SemanticMap, by: str) -> np.ndarray:
    if by == "labels":
        return PALETTE[m.labels]
    if by == "instances":
        require_instances(m, "an instance view")
        return instance_colors(m.instances, m.labels)
    raise ValueError(f"colour by 'labels' or 'instances', got {by!r}")


def _rgb(c: np.ndarray) -> list[str]:
    return [f"rgb({r},{g},{b})" for r, g, b in c]


def _legend_entry(name: str, colour: str, group: str):
    """A legend-only trace: one square marker of ``colour`` named ``name`` (draws nothing)."""
    import plotly.graph_objects as go

    return go.Scatter3d(x=[None], y=[None], z=[None], mode="markers", name=name, legendgroup=group,
                        marker=dict(size=12, color=colour, symbol="square"), hoverinfo="skip", showlegend=True)


def map_figure(
    m: SemanticMap | str | os.PathLike,
    *,
    color_by: str = "labels",
    max_vertices: int = MAX_DISPLAY_VERTICES,
    hide: tuple[str, ...] = ("ceiling",),
    title: str | None = None,
):
    """An interactive 3D view of a semantic map (plotly ``Figure``).

    Parameters
    ----------
    m : SemanticMap or PLY path
    color_by : {"labels", "instances"}
        Category colours, or one colour per instance (stuff in its category colour).
    max_vertices : int
        Display budget (see :func:`decimate`).
    hide : tuple of str
        Categories left out of the view (default the ceiling, so that the room can be seen
        from above).
    title : str, optional

    Returns
    -------
    plotly.graph_objects.Figure
        The map as its first trace; in the label view a legend of the categories shown follows
        (legend-only traces, in label order).
    """
    import plotly.graph_objects as go

    from ..io.labels import id_of

    m = decimate(_as_map(m), max_vertices)
    if hide:
        gone = np.isin(m.labels, [id_of(n) for n in hide])
        if m.is_mesh:
            m = SemanticMap(m.points, m.labels, faces=m.faces[~gone[m.faces].all(axis=1)], source=m.source,
                            instances=m.instances)
        else:
            keep = ~gone
            m = SemanticMap(m.points[keep], m.labels[keep], source=m.source,
                            instances=None if m.instances is None else m.instances[keep])
    col = _colors(m, color_by)
    hover = _hover(m.labels, m.instances)
    x, y, z = m.points.T
    if m.is_mesh:
        i, j, k = m.faces.T
        trace = go.Mesh3d(x=x, y=y, z=z, i=i, j=j, k=k, vertexcolor=_rgb(col), hovertext=hover,
                          hoverinfo="text", flatshading=True, lighting=dict(ambient=0.6, diffuse=0.6),
                          name=Path(m.source).name)
    else:
        trace = go.Scatter3d(x=x, y=y, z=z, mode="markers", marker=dict(size=1.5, color=_rgb(col)),
                             hovertext=hover, hoverinfo="text", name=Path(m.source).name)
    trace.showlegend = False
    fig = go.Figure(trace)
    if color_by == "labels":
        for lab in np.unique(m.labels[np.unique(m.faces)] if m.is_mesh else m.labels):
            fig.add_trace(_legend_entry(NAMES[lab], _rgb(PALETTE[[lab]])[0], "categories"))
    fig.update_layout(title=title or Path(m.source).name, scene=dict(aspectmode="data"),
                      margin=dict(l=0, r=0, t=40, b=0), showlegend=True, legend=_LEGEND)
    return fig


def error_figure(
    pred: SemanticMap | str | os.PathLike,
    reference: SemanticMap | str | os.PathLike,
    voxel_size: float = 0.05,
    *,
    grid_origin=None,
    title: str | None = None,
):
    """Voxels of a prediction against a reference: correct (blue), wrong (orange), unsupported
    (grey: the reference has a category there, the prediction void); voxels only one map has are
    left out. Returns a plotly ``Figure`` (one trace per class, :data:`ERROR_COLOURS`); the
    counts are in its title and legend."""
    import plotly.graph_objects as go

    from ..evaluate.metrics import voxelize
    from ..io.geometry import unpack_keys

    g = voxelize(_as_map(reference), voxel_size, grid_origin=grid_origin)
    p = voxelize(_as_map(pred), voxel_size, grid_origin=grid_origin)
    common, gi, pi = np.intersect1d(g.keys, p.keys, return_indices=True)
    gl, pl = g.labels[gi], p.labels[pi]
    keep = gl > 0
    common, gl, pl = common[keep], gl[keep], pl[keep]
    status = np.where(pl == 0, 2, np.where(pl == gl, 0, 1))
    k = unpack_keys(common)
    origin = np.zeros(3) if grid_origin is None else np.broadcast_to(np.asarray(grid_origin, float), (3,))
    centres = (k + 0.5) * voxel_size + origin
    names = tuple(ERROR_COLOURS)
    fig = go.Figure()
    for s, (name, colour) in enumerate(ERROR_COLOURS.items()):
        sel = status == s
        hover = [f"{name}: {NAMES[a]} -> {NAMES[b]}" for a, b in zip(gl[sel], pl[sel])]
        fig.add_trace(go.Scatter3d(x=centres[sel, 0], y=centres[sel, 1], z=centres[sel, 2], mode="markers",
                                   marker=dict(size=2, color=colour), name=f"{name} ({int(sel.sum())})",
                                   hovertext=hover, hoverinfo="text"))
    counts = ", ".join(f"{n} {int((status == s).sum())}" for s, n in enumerate(names))
    fig.update_layout(title=title or f"{Path(p.source).name} vs {Path(g.source).name}: {counts}",
                      scene=dict(aspectmode="data"), margin=dict(l=0, r=0, t=40, b=0), showlegend=True,
                      legend=_LEGEND)
    return fig


def trajectory_name(sequence: str | os.PathLike) -> str:
    """A legend name for the camera path of a sequence folder.

    Simulated sequences say in ``meta.json`` whose they are: the person's (``upper``) or the
    robot's (``lower``; ``lower_shared``: the robot replaying the person's route). Any other
    sequence is named by its folder.

    Parameters
    ----------
    sequence : path
        A sequence folder.

    Returns
    -------
    str
    """
    seq = Path(sequence)
    try:
        meta = json.loads((seq / "meta.json").read_text())
    except (OSError, ValueError):
        meta = {}
    who = str(meta.get("trajectory", "")) if isinstance(meta, dict) else ""
    scene = f" ({meta['scene']})" if isinstance(meta, dict) and meta.get("scene") else ""
    if who == "upper":
        return f"person{scene}"
    if who == "lower_shared":
        return f"robot on the person's route{scene}"
    if who.startswith("lower"):
        return f"robot{scene}"
    return seq.name or str(seq)


def trajectory_trace(poses: np.ndarray, name: str, color: str = "black"):
    """A camera path (positions of ``T_world_camera`` poses, (N,4,4)) as a plotly line trace
    named ``name`` in the legend."""
    import plotly.graph_objects as go

    p = np.asarray(poses, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (N,4,4), got {p.shape}")
    t = p[:, :3, 3]
    return go.Scatter3d(x=t[:, 0], y=t[:, 1], z=t[:, 2], mode="lines+markers", name=name, showlegend=True,
                        line=dict(color=color, width=4), marker=dict(size=2, color=color))


def write_html(fig, path: str | os.PathLike, *, plotlyjs: str = "inline") -> Path:
    """Write a figure as one HTML page, atomically.

    Parameters
    ----------
    fig : plotly.graph_objects.Figure
    path : path
        The page.
    plotlyjs : {"inline", "directory", "cdn"}
        ``inline``: plotly.js inside the page (self-contained, works offline; several MB each);
        ``directory``: one shared ``plotly.min.js`` beside the pages (written when missing or of
        another plotly version; the pages stay small and work offline as long as it is there);
        ``cdn``: loaded from plotly's CDN (small pages, need a network).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        An unknown ``plotlyjs``.
    """
    if plotlyjs not in PLOTLYJS_MODES:
        raise ValueError(f"plotlyjs must be one of {', '.join(PLOTLYJS_MODES)}, got {plotlyjs!r}")
    path = Path(path)
    if plotlyjs == "directory":
        _write_shared_plotlyjs(path.parent / "plotly.min.js")
    include = {"inline": True, "directory": "directory", "cdn": "cdn"}[plotlyjs]
    with atomic_path(path) as tmp:  # beside the page: plotly finds the shared copy there and keeps it
        fig.write_html(str(tmp), include_plotlyjs=include, full_html=True)
    return path


def _write_shared_plotlyjs(target: Path) -> None:
    """Write plotly.min.js (of the installed plotly) to ``target`` unless that exact file is there."""
    from plotly.offline import get_plotlyjs

    js = get_plotlyjs()
    if target.is_file() and target.stat().st_size == len(js.encode("utf-8")) and target.read_text(encoding="utf-8") == js:
        return
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(target) as tmp:
        Path(tmp).write_text(js, encoding="utf-8")
