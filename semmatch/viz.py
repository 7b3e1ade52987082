"""Interactive 3D views (plotly) of semantic maps, errors and trajectories, for JupyterLab and HTML.

* :func:`map_figure`: a semantic (or panoptic) map in label or instance colours; large meshes
  are decimated for display (Open3D vertex clustering), point maps subsampled (seeded);
* :func:`error_figure`: a predicted map against a reference on voxels: correct, wrong,
  unsupported (the reference has a label, the prediction void);
* :func:`trajectory_trace`: a camera path to add to a figure;
* :func:`write_html`: one self-contained page (plotly.js inlined), written atomically.

``semmatch show MAP.ply [--reference GT.ply] --html OUT.html`` wraps them.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .io import SemanticMap, atomic_path, read_map
from .labels import NAMES, PALETTE

__all__ = ["map_figure", "error_figure", "trajectory_trace", "write_html", "decimate"]

#: vertices kept for display by default (a 500k-vertex map is decimated to about this)
MAX_DISPLAY_VERTICES = 150_000


def _as_map(m: SemanticMap | str | os.PathLike) -> SemanticMap:
    return read_map(m) if isinstance(m, str | os.PathLike) else m.check()


def decimate(m: SemanticMap, max_vertices: int = MAX_DISPLAY_VERTICES, *, seed: int = 0) -> SemanticMap:
    """A lighter copy of ``m`` for display, with at most about ``max_vertices`` vertices.

    Meshes: Open3D vertex clustering at the cell size whose count of surface cells matches
    ``max_vertices``; every new vertex takes the label (and instance) of the nearest original
    vertex. Point maps: a seeded random subset.
    """
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
        from .panoptic import instance_colors, require_instances

        require_instances(m, "an instance view")
        return instance_colors(m.instances, m.labels)
    raise ValueError(f"colour by 'labels' or 'instances', got {by!r}")


def _rgb(c: np.ndarray) -> list[str]:
    return [f"rgb({r},{g},{b})" for r, g, b in c]


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
    """
    import plotly.graph_objects as go

    from .labels import id_of

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
    fig = go.Figure(trace)
    fig.update_layout(title=title or Path(m.source).name, scene=dict(aspectmode="data"),
                      margin=dict(l=0, r=0, t=40, b=0), showlegend=False)
    return fig


def error_figure(
    pred: SemanticMap | str | os.PathLike,
    reference: SemanticMap | str | os.PathLike,
    voxel_size: float = 0.05,
    *,
    grid_origin=None,
    title: str | None = None,
):
    """Voxels of a prediction against a reference: correct (green), wrong (red), unsupported
    (grey: the reference has a category there, the prediction void); voxels only one map has are
    left out. Returns a plotly ``Figure``; the counts are in its title."""
    import plotly.graph_objects as go

    from .geometry import unpack_keys
    from .metrics import voxelize

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
    names = ("correct", "wrong", "unsupported")
    colours = ("rgb(40,170,60)", "rgb(220,40,40)", "rgb(150,150,150)")
    fig = go.Figure()
    for s, (name, colour) in enumerate(zip(names, colours)):
        sel = status == s
        hover = [f"{name}: {NAMES[a]} -> {NAMES[b]}" for a, b in zip(gl[sel], pl[sel])]
        fig.add_trace(go.Scatter3d(x=centres[sel, 0], y=centres[sel, 1], z=centres[sel, 2], mode="markers",
                                   marker=dict(size=2, color=colour), name=f"{name} ({int(sel.sum())})",
                                   hovertext=hover, hoverinfo="text"))
    counts = ", ".join(f"{n} {int((status == s).sum())}" for s, n in enumerate(names))
    fig.update_layout(title=title or f"{Path(p.source).name} vs {Path(g.source).name}: {counts}",
                      scene=dict(aspectmode="data"), margin=dict(l=0, r=0, t=40, b=0))
    return fig


def trajectory_trace(poses: np.ndarray, name: str, color: str = "black"):
    """A camera path (positions of ``T_world_camera`` poses, (N,4,4)) as a plotly line trace."""
    import plotly.graph_objects as go

    p = np.asarray(poses, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (N,4,4), got {p.shape}")
    t = p[:, :3, 3]
    return go.Scatter3d(x=t[:, 0], y=t[:, 1], z=t[:, 2], mode="lines+markers", name=name,
                        line=dict(color=color, width=4), marker=dict(size=2, color=color))


def write_html(fig, path: str | os.PathLike) -> Path:
    """Write a figure as one self-contained HTML page (plotly.js inlined), atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.write_html(str(tmp), include_plotlyjs=True, full_html=True)
    return path
