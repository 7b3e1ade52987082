"""Notebook 10: panoptic transfer on the evaluation scenes (the paper's second future work).

For every evaluation scene and upper-map source, the upper map gets an instance layer, each
transfer method carries classes and instances into the robot's frames, the instances are
fused onto the lower semantic maps of 05 (same geometry, same classes), and panoptic quality
is measured against the robot's frames fused with ground-truth classes and instances.

Upper-map sources (``source`` column):

* ``oracle``: the ground-truth upper map (05's ``gt``) with instances fused from the person's
  ground-truth instance images;
* ``gt+clustering``: the same classes, instances by 3D clustering (:func:`segment_instances`);
* ``<network>``: the network-built upper map, instances by 3D clustering.

The clustering radius is chosen on validation scenes only (:func:`choose_clustering`): the
person's frames of each validation scene fused with ground-truth classes, clustered at each
candidate radius, scored by PQ over thing classes against the same map with ground-truth
instances.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from ..io import read_map, read_sequence, write_map
from ..io.labels import THING_CLASSES
from ..transfer.index import MapIndex
from ..transfer.panoptic import (
    PanopticFrame,
    fuse_instances,
    panoptic_quality,
    panoptic_voxels,
    segment_instances,
    sequence_panoptic_frames,
    transfer_panoptic,
)
from .layout import GT, Layout
from .synthetic import eval_grid_origin

__all__ = [
    "PANOPTIC_MEASURES", "choose_clustering", "panoptic_scene", "panoptic_study", "panoptic_summary",
    "panoptic_figure",
]

#: the headline panoptic measures, in table order
PANOPTIC_MEASURES = ("pq_things", "sq_things", "rq_things", "pq_stuff", "pq")

ORACLE = "oracle"
GT_CLUSTERED = "gt+clustering"


def _pq_row(q: dict) -> dict:
    return {k: q[k] for k in PANOPTIC_MEASURES}


def choose_clustering(
    data_root: str | Path,
    eps_grid: Sequence[float],
    *,
    voxel_size: float = 0.04,
    eval_voxel_size: float = 0.05,
    frame_step: int = 4,
    min_vertices: int = 50,
    scenes: int | None = None,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
) -> tuple[float, pd.DataFrame]:
    """Pick the clustering radius of :func:`segment_instances` on the validation scenes.

    Each validation scene's upper frames (every ``frame_step``-th) are fused with ground-truth
    classes; the map is clustered at every radius of ``eps_grid`` and scored (PQ over thing
    classes, voxels of ``eval_voxel_size``) against the same map with instances fused from the
    ground-truth instance images. The scenes are tasks of :func:`semmatch.runtime.engine.map_tasks`
    (``jobs`` local worker processes, or the cluster at ``scheduler``).

    Returns
    -------
    eps : float
        The radius with the best mean PQ over thing classes (ties: the smaller radius).
    scores : DataFrame
        ``scene``, ``eps``, ``pq_things``, ``sq_things``, ``rq_things``.
    """
    layout = Layout(data_root)
    val = layout.scene_dirs("val")
    if scenes is not None:
        # spread over the kinds: the validation folders sort by kind, then seed
        kinds = sorted({sd.name.rsplit("_", 1)[0] for sd in val})
        val = [sd for k in kinds for sd in val if sd.name.rsplit("_", 1)[0] == k][:: max(1, len(val) // scenes)][:scenes]
    # one engine task per validation scene (jobs local processes or the cluster at scheduler)
    rows = layout.map_scenes(_clustering_scene, tuple(float(e) for e in eps_grid), float(voxel_size),
                             float(eval_voxel_size), int(frame_step), int(min_vertices), scenes=val, jobs=jobs,
                             scheduler=scheduler, desc="clustering (validation)", progress=progress)
    scores = pd.DataFrame(rows)
    if scores.empty:
        raise ValueError(f"{layout.scenes / 'val'}: no validation scene to choose the clustering radius on")
    mean = scores.groupby("eps", sort=True)["pq_things"].mean()
    return float(mean.idxmax()), scores


def _clustering_scene(data_root: str, eps_grid: tuple[float, ...], voxel_size: float, eval_voxel_size: float,
                      frame_step: int, min_vertices: int, sid: str) -> list[dict]:
    """PQ of every clustering radius on one validation scene (a task of :func:`choose_clustering`)."""
    from ..fusion import reconstruct

    sd = Layout(data_root).scenes / "val" / sid
    origin = eval_grid_origin(eval_voxel_size)
    seq = read_sequence(sd / "upper")
    frames = [seq[i] for i in range(0, len(seq), int(frame_step))]
    m = reconstruct(frames, voxel_size=voxel_size)
    ref = fuse_instances(m, sequence_panoptic_frames(seq, step=frame_step), clean=False)
    gvox = panoptic_voxels(ref, eval_voxel_size, grid_origin=origin)
    rows = []
    for eps in eps_grid:
        q = panoptic_quality(gvox, segment_instances(m, eps=float(eps), min_vertices=min_vertices),
                             eval_voxel_size, grid_origin=origin)
        rows.append({"scene": sd.name, "eps": float(eps), **{k: q[k] for k in ("pq_things", "sq_things", "rq_things")}})
    return rows


def _upper_panoptic(layout: Layout, sd: Path, source: str, *, eps: float, min_vertices: int,
                    frame_step: int):
    """The upper map of ``source`` with its instance layer (written beside the upper maps)."""
    sid = sd.name
    if source == ORACLE:
        m = fuse_instances(read_map(layout.upper_map(sid, GT)),
                           sequence_panoptic_frames(read_sequence(sd / "upper"), step=frame_step), clean=False)
    else:
        base = GT if source == GT_CLUSTERED else source
        m = segment_instances(read_map(layout.upper_map(sid, base)), eps=eps, min_vertices=min_vertices)
    write_map(layout.panoptic(sid) / f"upper_{_folder(source)}.ply", m)
    return m


def _folder(source: str) -> str:
    return source.replace("+", "_")


def panoptic_scene(
    data_root: str | Path,
    scene: str,
    methods: Sequence[str],
    networks: Sequence[str],
    *,
    eps: float,
    min_vertices: int = 50,
    frame_step: int = 4,
    tolerance: float = 0.05,
    eval_voxel_size: float = 0.05,
    link_radius: float = 0.08,
) -> list[dict]:
    """The rows of :func:`panoptic_study` for one evaluation scene (folder name ``scene``)."""
    layout = Layout(data_root)
    sd = layout.scenes / "eval" / scene
    origin = eval_grid_origin(eval_voxel_size)
    lower = read_sequence(layout.lower_sequence(sd))
    step_frames = [lower[i] for i in range(0, len(lower), int(frame_step))]
    out_dir = layout.panoptic(scene)
    ref = fuse_instances(read_map(layout.lower_reference(scene)),
                         sequence_panoptic_frames(lower, step=frame_step), tolerance=tolerance, clean=False)
    write_map(out_dir / "reference.ply", ref)
    gvox = panoptic_voxels(ref, eval_voxel_size, grid_origin=origin)
    rows = []
    indexes: dict[str, MapIndex] = {}
    for source in [ORACLE, GT_CLUSTERED, *networks]:
        upper = _upper_panoptic(layout, sd, source, eps=eps, min_vertices=min_vertices, frame_step=frame_step)
        class_source = GT if source in (ORACLE, GT_CLUSTERED) else source
        # the two ground-truth-class sources differ in instances only: one label grid serves both
        if class_source in indexes:
            index = indexes[class_source].with_instances(upper.instances)
        else:
            index = indexes[class_source] = MapIndex(upper)
        for method in methods:
            res = [transfer_panoptic(method, f, index) for f in step_frames]
            evidence = (PanopticFrame.of(f, lab, inst) for f, (lab, inst) in zip(step_frames, res))
            pm = fuse_instances(read_map(layout.lower_map(scene, class_source, method)), evidence,
                                tolerance=tolerance, eps=link_radius, min_vertices=min_vertices)
            write_map(out_dir / _folder(source) / f"{method}.ply", pm)
            q = panoptic_quality(gvox, pm, eval_voxel_size, grid_origin=origin)
            per_class = {f"pq_{k}": v["pq"] for k, v in q["per_class"].items() if v["class"] in THING_CLASSES}
            rows.append({"scene": scene, "source": source, "method": method, **_pq_row(q), **per_class})
    return rows


def panoptic_study(
    data_root: str | Path,
    methods: Sequence[str],
    networks: Sequence[str],
    *,
    eps: float,
    min_vertices: int = 50,
    frame_step: int = 4,
    tolerance: float = 0.05,
    eval_voxel_size: float = 0.05,
    link_radius: float = 0.08,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
) -> pd.DataFrame:
    """Panoptic quality of every (scene, upper-map source, method) on the evaluation scenes.

    The lower semantic maps of 05 (``lower_maps/<scene>/<source>/<method>.ply``) get an instance
    layer from the transferred instances of every ``frame_step``-th robot frame; the reference
    is 05's ``reference.ply`` with instances from the robot's ground-truth instance images. The
    panoptic maps are written under ``panoptic/<scene>/`` (the upper maps with their instance
    layers as ``upper_<source>.ply``). Scenes are tasks of :func:`semmatch.runtime.engine.map_tasks`
    (``jobs`` local worker processes, or the cluster at ``scheduler``); the result does not
    depend on where they run.

    Returns
    -------
    DataFrame
        ``scene``, ``source``, ``method`` and :data:`PANOPTIC_MEASURES`, plus the per-class PQ of
        the thing classes as ``pq_<class>`` (NaN where the class is absent from both maps).
    """
    kw = dict(eps=eps, min_vertices=min_vertices, frame_step=frame_step, tolerance=tolerance,
              eval_voxel_size=eval_voxel_size, link_radius=link_radius)
    rows = Layout(data_root).map_scenes(_panoptic_task, methods, networks, kw, jobs=jobs, scheduler=scheduler,
                                        desc="panoptic", progress=progress)
    return pd.DataFrame(rows)


def _panoptic_task(data_root, methods, networks, kw: dict, sid: str) -> list[dict]:
    """One scene of :func:`panoptic_study` as an engine task."""
    return panoptic_scene(data_root, sid, methods, networks, **kw)


def panoptic_summary(per_scene: pd.DataFrame, *, seed: int = 0) -> pd.DataFrame:
    """Mean over scenes with the analysis plan's 95 % intervals per (source, method)."""
    from .summaries import summarize_over_scenes

    return summarize_over_scenes(per_scene, PANOPTIC_MEASURES, by=("source", "method"), seed=seed)


def panoptic_figure(
    data_root: str | Path,
    path: str | Path,
    networks: Sequence[str],
    *,
    scene: int = 0,
    method: str = "3d-neighborhood",
    size: tuple[int, int] = (480, 360),
) -> Path:
    """Renders of one scene's lower panoptic maps, instances coloured (stuff in its class colour).

    Columns: the reference (robot frames with ground-truth instances), then ``method``'s map from
    each upper-map source (written by :func:`panoptic_study`).
    """
    from ..io.geometry import Intrinsics
    from ..io.labels import instance_colors
    from ..plots import image_grid
    from .qualitative import overview_pose, render_map

    layout = Layout(data_root)
    sid = layout.scene_dir(scene).name
    base = layout.panoptic(sid)
    panels = [("reference", base / "reference.ply")] + [
        (f"{s}\n{method}", base / _folder(s) / f"{method}.ply") for s in (ORACLE, GT_CLUSTERED, *networks)
    ]
    w, h = size
    intr = Intrinsics(w, h, 0.9 * w, 0.9 * w, w / 2, h / 2)
    pose, row = None, []
    for _, p in panels:
        m = read_map(p)
        if m.instances is None:
            raise ValueError(f"{p}: no instance layer; run panoptic_study first")
        pose = overview_pose(m) if pose is None else pose
        row.append(render_map(m, pose, intr, colors=instance_colors(m.instances, m.labels)))
    return image_grid([row], path, col_titles=[t for t, _ in panels], cell=(2.8, 2.6), suptitle_fontsize=10,
                      suptitle=f"Instances in the robot's map of {sid} (one colour per instance; stuff in its "
                               "class colour)")
