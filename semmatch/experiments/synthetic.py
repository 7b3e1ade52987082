"""The synthetic experiments: upper maps (03), label transfer (04), Table 2 (05).

Each function does one notebook's work on the data layout of :mod:`.layout` and returns a
DataFrame the notebook shows and plots.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import pandas as pd

from ..evaluate.metrics import MEASURES, VoxelGrid
from ..io import SemanticMap, read_map, read_sequence
from .layout import GT, ROUTES, Layout, model_name

__all__ = [
    "eval_grid_origin",
    "reconstruct_upper_maps",
    "transfer_lower_labels",
    "support_table",
    "reconstruct_lower_maps",
    "evaluate_synthetic",
    "reference_grid",
    "main_rows",
    "average_over_scenes",
]


def eval_grid_origin(voxel_size: float) -> tuple[float, float, float]:
    """Corner of the evaluation grid: half a voxel off the world origin in every axis.

    The procedural rooms put floors, walls and many furniture faces on multiples of 5 cm, where
    the faces of a grid anchored at the origin also lie; a reconstruction a few millimetres off
    (the TSDF's bias) would then split each such surface between two voxel layers and score
    aliasing rather than labels. The protocol therefore evaluates on a grid offset by half a voxel.
    """
    return (0.5 * voxel_size,) * 3


def _scores(gt, pred, voxel_size: float) -> dict:
    from ..evaluate.metrics import compare

    s = compare(gt, pred, voxel_size=voxel_size, grid_origin=eval_grid_origin(voxel_size))
    return {k: float(s[k]) for k in MEASURES}


def reconstruct_upper_maps(
    data_root: str | Path,
    networks: Sequence[str],
    *,
    voxel_size: float = 0.04,
    eval_voxel_size: float = 0.05,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
) -> pd.DataFrame:
    """Upper-view semantic maps of every evaluation scene: from ground truth and each network.

    For each scene the upper sequence is fused with its ground-truth labels (``upper/<id>/gt.ply``)
    and with the labels each network predicts on the upper frames (``upper/<id>/<net>.ply``).
    Scenes are tasks of :func:`semmatch.runtime.engine.map_tasks` (``jobs`` local processes or the
    cluster at ``scheduler``).

    Returns
    -------
    DataFrame
        One row per (scene, network): the network's upper map scored against the ground-truth
        upper map (the paper's "Upper" rows), plus the 2D pixel accuracy / mIoU on the frames.
    """
    rows = Layout(data_root).map_scenes(_upper_maps_scene, tuple(networks), float(voxel_size), float(eval_voxel_size),
                                        jobs=jobs, scheduler=scheduler, desc="upper maps", progress=progress)
    return pd.DataFrame(rows)


def _upper_maps_scene(data_root: str, networks: tuple[str, ...], voxel_size: float, eval_voxel_size: float,
                      sid: str) -> list[dict]:
    """The upper maps of one scene and their scores (a task of :func:`reconstruct_upper_maps`)."""
    from ..evaluate.metrics import pixel_metrics
    from ..fusion import reconstruct_many
    from ..segment import predict_sequence

    layout = Layout(data_root)
    models = {net: layout.load_network(net) for net in networks}
    sd = layout.scenes / "eval" / sid
    rows = []
    upper = read_sequence(sd / "upper").load()  # predicted 2x: decode once
    lab_dirs = [layout.upper_labels(sid, net) for net in networks]
    for net, lab_dir in zip(networks, lab_dirs, strict=True):
        predict_sequence(models[net], upper, lab_dir, progress=False)
    # one fusion, the ground-truth labels and each network's as labelings
    gt_map, *net_maps = reconstruct_many(upper, [None, *lab_dirs], voxel_size,
                                         outs=[layout.upper_map(sid, s) for s in (GT, *networks)])
    for net, lab_dir, net_map in zip(networks, lab_dirs, net_maps, strict=True):
        pred = read_sequence(sd / "upper", labels=lab_dir)
        pix = pixel_metrics((upper.read_labels(i) for i in range(len(upper))),
                            (pred.read_labels(i) for i in range(len(pred))))
        rows.append(
            dict(scene=sid, model=net, method="upper", **_scores(gt_map, net_map, eval_voxel_size),
                 pixel_acc=float(pix["pixel_acc"]), miou=float(pix["miou"]))
        )
    return rows


def _routes(layout: Layout, sd: Path) -> list[str]:
    """Route modes with a robot sequence in scene folder ``sd`` (``own`` first)."""
    return [r for r in ROUTES if layout.lower_sequence(sd, r).is_dir()]


def _route_methods(route: str, methods: Sequence[str], fused_base: str) -> list[str]:
    """Transfer methods run on a route: all of them on the robot's own tour, the fused base on the ablation."""
    return list(methods) if route == "own" else [fused_base]


def transfer_lower_labels(
    data_root: str | Path,
    methods: Sequence[str],
    networks: Sequence[str],
    *,
    fused_base: str = "3d-neighborhood",
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    method_settings: Mapping[str, Mapping] | None = None,
) -> pd.DataFrame:
    """Labels for every lower frame: each method from each upper map, each network directly, fused.

    Writes ``lower_labels/<scene>/<source>/<method>/`` (source: ``gt`` or a network),
    ``lower_labels/<scene>/<network>/lower/`` (the network applied to the lower frames: the
    baseline) and ``lower_labels/<scene>/<network>/fused/`` (``fused_base`` from the network's
    own upper map where it supports a pixel, the network elsewhere). Where the scene has the
    route ablation (``lower_shared/``), the same for ``fused_base`` under ``shared_route/``.
    Scenes are tasks of :func:`semmatch.runtime.engine.map_tasks` (``jobs`` local worker processes,
    or the cluster at ``scheduler``); the labels do not depend on where they ran. ``method_settings``:
    the methods' parameters, ``{method: {parameter: value}}`` (the notebooks' ``slic_2d``).

    Returns
    -------
    DataFrame
        scene, route, model, method, coverage (share of pixels with depth that got a label;
        for the ground-truth map and ``fused_base``: the share of the robot's view the person's
        map supports), fps.
    """
    if fused_base not in methods:
        raise ValueError(f"fused_base {fused_base!r} is not among the methods {list(methods)}")
    # scenes are engine tasks; with one local job the frames of a scene are not split either
    rows = Layout(data_root).map_scenes(_transfer_scene, tuple(methods), tuple(networks), fused_base,
                                        dict(method_settings or {}), jobs=jobs,
                                        scheduler=scheduler, desc="transfer (scenes)", progress=progress)
    return pd.DataFrame(rows)


def _transfer_scene(data_root: str, methods: tuple[str, ...], networks: tuple[str, ...], fused_base: str,
                    method_settings: dict, sid: str) -> list[dict]:
    """The labels of one scene's robot frames (a task of :func:`transfer_lower_labels`)."""
    from ..segment import predict_sequence
    from ..transfer import load_index, settings_for, transfer_sequence, write_fused_labels

    layout = Layout(data_root)
    sd = layout.scenes / "eval" / sid
    models = {net: layout.load_network(net) for net in networks}
    rows = []
    indexes = {source: load_index(layout.upper_map(sid, source)) for source in (GT, *networks)}  # cached beside
    for route in _routes(layout, sd):
        lower = read_sequence(layout.lower_sequence(sd, route)).load()  # read by every method
        for source in (GT, *networks):
            for method in _route_methods(route, methods, fused_base):
                st = transfer_sequence(method, lower, indexes[source], layout.lower_labels(sid, source, method, route),
                                       progress=False, **settings_for(method, method_settings))
                rows.append(dict(scene=sid, route=route, model=model_name(source), method=method,
                                 coverage=float(st["coverage"]), fps=float(st["fps"])))
        for net in networks:
            low = predict_sequence(models[net], lower, layout.lower_labels(sid, net, "lower", route),
                                   progress=False)
            write_fused_labels(layout.lower_labels(sid, net, fused_base, route), low,
                               layout.lower_labels(sid, net, "fused", route))
    return rows


def support_table(coverage: pd.DataFrame, fused_base: str = "3d-neighborhood") -> pd.DataFrame:
    """Per scene and route: the share of the robot's pixels (with depth) the person's map supports.

    From the coverage of :func:`transfer_lower_labels`: ``fused_base`` transferred from the
    ground-truth upper map (its geometry is the upper camera's; the labels do not matter).
    """
    sel = coverage[(coverage["model"] == model_name(GT)) & (coverage["method"] == fused_base)]
    return sel[["scene", "route", "coverage"]].rename(columns={"coverage": "support"}).reset_index(drop=True)


def _labelings(route: str, methods: Sequence[str], networks: Sequence[str], fused_base: str) -> list[tuple[str, str]]:
    meths = _route_methods(route, methods, fused_base)
    return [(GT, m) for m in meths] + [(n, m) for n in networks for m in ("lower", *meths, "fused")]


def reconstruct_lower_maps(
    data_root: str | Path,
    methods: Sequence[str],
    networks: Sequence[str],
    *,
    voxel_size: float = 0.04,
    fused_base: str = "3d-neighborhood",
    mesh_spacing: float = 0.01,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
) -> None:
    """Fuse the lower sequence of every scene with each labels folder of 04, and build references.

    Writes ``lower_maps/<scene>/reference.ply`` (the lower frames fused with ground-truth labels),
    ``lower_maps/<scene>/<source>/<method>.ply`` and the independent references
    ``mesh_reference.ply`` / ``upper_mesh_reference.ply``: the ground-truth scene mesh sampled
    every ``mesh_spacing`` metres and kept where the lower / upper camera observed it
    (:func:`semmatch.evaluate.reference.observed_reference`), which shares no geometry with any fusion.
    The same under ``shared_route/`` for the route ablation. Scenes are tasks of
    :func:`semmatch.runtime.engine.map_tasks` (``jobs`` local processes or the cluster at ``scheduler``).
    """
    Layout(data_root).map_scenes(_lower_maps_scene, tuple(methods), tuple(networks), float(voxel_size), fused_base,
                                 float(mesh_spacing), flatten=False, jobs=jobs, scheduler=scheduler,
                                 desc="lower maps", progress=progress)


def _lower_maps_scene(data_root: str, methods: tuple[str, ...], networks: tuple[str, ...], voxel_size: float,
                      fused_base: str, mesh_spacing: float, sid: str) -> None:
    """The lower maps and references of one scene (a task of :func:`reconstruct_lower_maps`)."""
    from ..evaluate.reference import observed_reference
    from ..fusion import reconstruct_many
    from ..io import write_map

    layout = Layout(data_root)
    sd = layout.scenes / "eval" / sid
    mesh = read_map(sd / "scene.ply")
    write_map(layout.mesh_reference(sid, "upper"),
              observed_reference(mesh, read_sequence(sd / "upper"), spacing=mesh_spacing))
    for route in _routes(layout, sd):
        lower = read_sequence(layout.lower_sequence(sd, route)).load()
        labelings = _labelings(route, methods, networks, fused_base)
        # one fusion of the lower frames; the reference (ground-truth labels) and every
        # labels folder as labelings of it
        reconstruct_many(lower, [None, *(layout.lower_labels(sid, s, m, route) for s, m in labelings)], voxel_size,
                         outs=[layout.lower_reference(sid, route),
                               *(layout.lower_map(sid, s, m, route) for s, m in labelings)])
        write_map(layout.mesh_reference(sid, "lower", route), observed_reference(mesh, lower, spacing=mesh_spacing))


def evaluate_synthetic(
    data_root: str | Path,
    methods: Sequence[str],
    networks: Sequence[str],
    *,
    eval_voxel_size: float = 0.05,
    fused_base: str = "3d-neighborhood",
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = False,
) -> pd.DataFrame:
    """Table 2, per scene: every lower map against both references, plus the upper rows.

    Each reference is voxelised once per scene and compared with every map as a
    :class:`~semmatch.evaluate.metrics.VoxelGrid` (the same numbers as voxelising it per comparison).
    Scenes are tasks of :func:`semmatch.runtime.engine.map_tasks` (``jobs`` local processes or the
    cluster at ``scheduler``); the rows come back in scene order.

    Parameters
    ----------
    data_root : path
        The profile's data folder (the lower maps and references of notebook 05's first step).
    methods, networks : sequences of str
    eval_voxel_size : float
        Evaluation voxel (m).
    fused_base : str
        The transfer method the ``fused`` rows build on.
    jobs : int
        Local worker processes (1: in this process).
    scheduler : str, optional
        Dask scheduler address (default ``SEMMATCH_SCHEDULER``).
    progress : bool

    Returns
    -------
    DataFrame
        scene, route (``own``: the robot's own tour, ``shared``: the ablation), reference
        (``fusion``: the robot's frames fused with ground-truth labels, as the paper;
        ``mesh``: the ground-truth mesh where the camera observed it), model (``ground truth``
        or a network), method (a transfer method, ``lower`` = the network on the lower frames,
        ``fused``, ``upper`` = the network's upper map scored against the upper references),
        the four measures.
    """
    rows = Layout(data_root).map_scenes(_evaluate_scene, tuple(methods), tuple(networks), float(eval_voxel_size),
                                        fused_base, jobs=jobs, scheduler=scheduler, desc="Table 2 scenes",
                                        progress=progress)
    return pd.DataFrame(rows)


def reference_grid(ref: SemanticMap | str | Path, voxel_size: float) -> VoxelGrid:
    """A reference map voxelised once on the evaluation grid (:func:`eval_grid_origin`).

    Pass the result to :func:`semmatch.evaluate.metrics.compare` as ``gt_map`` for every map scored
    against that reference: the numbers equal voxelising it per comparison.

    Parameters
    ----------
    ref : SemanticMap or path
        The reference map (a PLY path is read).
    voxel_size : float
        Evaluation voxel (m).

    Returns
    -------
    VoxelGrid
    """
    from ..evaluate.metrics import voxelize

    return voxelize(ref, voxel_size, grid_origin=eval_grid_origin(voxel_size))


def _evaluate_scene(data_root: str, methods: tuple[str, ...], networks: tuple[str, ...], eval_voxel_size: float,
                    fused_base: str, sid: str) -> list[dict]:
    """The Table 2 rows of one scene (a task of :func:`evaluate_synthetic`)."""
    layout = Layout(data_root)
    sd = layout.scenes / "eval" / sid
    rows = []
    up_refs = {"fusion": reference_grid(layout.upper_reference(sid), eval_voxel_size),
               "mesh": reference_grid(layout.mesh_reference(sid, "upper"), eval_voxel_size)}
    for net in networks:
        up = read_map(layout.upper_map(sid, net))
        for ref_name, ref in up_refs.items():
            rows.append(dict(scene=sid, route="own", reference=ref_name, model=net, method="upper",
                             **_scores(ref, up, eval_voxel_size)))
    for route in _routes(layout, sd):
        refs = {"fusion": reference_grid(layout.lower_reference(sid, route), eval_voxel_size),
                "mesh": reference_grid(layout.mesh_reference(sid, "lower", route), eval_voxel_size)}
        for source, method in _labelings(route, methods, networks, fused_base):
            pred = read_map(layout.lower_map(sid, source, method, route))
            for ref_name, ref in refs.items():
                rows.append(dict(scene=sid, route=route, reference=ref_name, model=model_name(source),
                                 method=method, **_scores(ref, pred, eval_voxel_size)))
    return rows


def main_rows(per_scene: pd.DataFrame, *, reference: str = "fusion", route: str = "own") -> pd.DataFrame:
    """The rows of one table: one reference and one route of :func:`evaluate_synthetic`'s output."""
    sel = per_scene
    if "reference" in sel.columns:
        sel = sel[sel["reference"] == reference]
    if "route" in sel.columns:
        sel = sel[sel["route"] == route]
    return sel.reset_index(drop=True)


def average_over_scenes(df: pd.DataFrame) -> pd.DataFrame:
    """Mean of the measures over scenes per (model, method), in the paper's row order."""
    cols = [c for c in MEASURES if c in df.columns]
    out = df.groupby(["model", "method"], sort=False)[cols].mean().reset_index()
    out.insert(2, "scenes", df.groupby(["model", "method"], sort=False).size().values)
    return out
