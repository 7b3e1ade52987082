"""How much a misregistration between the person's map and the robot's frames costs (07).

On the clean synthetic data of the pipeline (ground-truth upper map, clean lower frames at their
true poses) the upper map is moved by a rigid transform of known size
(:func:`semmatch.poses.registration.rigid_perturbation`, about the map's centroid): a series of
translations alone and a series of rotations alone, from the same seeded axis and direction.
Every transfer method labels the lower frames from the moved map; the labelings of a scene are
fused in one :func:`semmatch.fusion.reconstruct_many` call at the true lower poses and scored
against the lower reference (the lower frames fused with ground-truth labels), so the measures
drop only because of the misregistration.

Moving the map by ``P`` is, to every transfer method, the same as placing the lower cameras at
``inv(P) @ T`` in the unmoved map (the map's points reach the image through
``inv(T) @ P``), which is what is done: the map is indexed once per scene.
"""

from __future__ import annotations

import tempfile
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..evaluate.metrics import MEASURES
from ..io import read_map, read_sequence
from .layout import GT, Layout
from .synthetic import eval_grid_origin, reference_grid

__all__ = ["misregistration_study", "clean_scene_inputs"]


def _perturbations(translations: Sequence[float], rotations_deg: Sequence[float]) -> list[tuple[float, float]]:
    """(translation_m, rotation_deg) pairs: the unperturbed case once, then each series."""
    out = [(0.0, 0.0)]
    for t in translations:
        if float(t) < 0 or not np.isfinite(t):
            raise ValueError(f"translations must be finite and >= 0, got {t}")
        if (float(t), 0.0) not in out:
            out.append((float(t), 0.0))
    for r in rotations_deg:
        if float(r) < 0 or not np.isfinite(r):
            raise ValueError(f"rotations_deg must be finite and >= 0, got {r}")
        if (0.0, float(r)) not in out:
            out.append((0.0, float(r)))
    return out


def _scene_dirs(layout: Layout, scenes: int | Sequence[str] | None) -> list[Path]:
    dirs = layout.scene_dirs("eval")
    if scenes is None:
        return dirs
    if isinstance(scenes, int | np.integer):
        if scenes < 0:
            raise ValueError(f"scenes must be >= 0, got {scenes}")
        return dirs[: int(scenes)]
    by_id = {d.name: d for d in dirs}
    missing = [s for s in scenes if s not in by_id]
    if missing:
        raise FileNotFoundError(f"{layout.scenes / 'eval'}: no evaluation scene(s) {missing}; "
                                f"available: {sorted(by_id)}")
    return [by_id[s] for s in scenes]


def misregistration_study(
    data_root: str | Path,
    methods: Sequence[str],
    *,
    translations: Sequence[float] = (0.0, 0.02, 0.05, 0.10),
    rotations_deg: Sequence[float] = (0.0, 1.0, 2.0, 5.0),
    scenes: int | Sequence[str] | None = None,
    voxel_size: float = 0.04,
    eval_voxel_size: float = 0.05,
    seed: int = 0,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    method_settings: Mapping[str, Mapping] | None = None,
) -> pd.DataFrame:
    """Scores of every transfer method when the upper map is misregistered by known amounts.

    Parameters
    ----------
    data_root : path
        A pipeline data root (:class:`~semmatch.experiments.layout.Layout`) with, per evaluation
        scene, the ground-truth upper map (``upper/<id>/gt.ply``, 03), the clean lower sequence
        (``scenes/eval/<id>/lower/``) and the lower reference (``lower_maps/<id>/reference.ply``, 05).
    methods : sequence of str
        Transfer methods.
    translations : sequence of float
        Translations (m) of the translation-only series.
    rotations_deg : sequence of float
        Angles (degrees) of the rotation-only series (about an axis through the map's centroid).
    scenes : int, sequence of str or None
        None: every evaluation scene; an int ``n``: the first ``n`` (sorted); or scene ids.
    voxel_size, eval_voxel_size : float
        Fusion and evaluation voxel sizes (m).
    seed : int
        Seed of the perturbations: each scene draws its own axis and direction from
        ``(seed, scene id)``, the same for all sizes, so a series grows along one direction.
    jobs : int
        Scenes run as tasks of :func:`semmatch.runtime.engine.map_tasks` on ``jobs`` local worker
        processes (with one scene: its label transfer in ``jobs`` processes).
    scheduler : str, optional
        Dask scheduler address to run the scenes on (default ``SEMMATCH_SCHEDULER``; none: local).
    progress : bool
    method_settings : mapping, optional
        The methods' parameters, ``{method: {parameter: value}}`` (the notebooks' ``slic_2d``).

    Returns
    -------
    DataFrame
        scene, method, translation_m, rotation_deg, jaccard, sorensen, color_acc, mean_acc,
        coverage (share of lower pixels the transfer labelled). The unperturbed case
        (0, 0) appears once per scene and method.

    Raises
    ------
    FileNotFoundError
        A missing upper map, lower sequence or reference (naming the file and the stage that
        writes it), or an unknown scene id.
    ValueError
        Negative or non-finite perturbation sizes.
    """
    from ..runtime.engine import resolve_scheduler

    layout = Layout(data_root)
    cases = _perturbations(translations, rotations_deg)
    sids = [sd.name for sd in _scene_dirs(layout, scenes)]
    frame_jobs = int(jobs) if resolve_scheduler(scheduler) is None and len(sids) == 1 else 1
    # scenes are engine tasks (jobs local processes or a scheduler); one scene: its frames in jobs processes
    rows = layout.map_scenes(_misregistration_scene, tuple(methods), tuple(cases),
                             dict(voxel_size=voxel_size, eval_voxel_size=eval_voxel_size, seed=int(seed),
                                  frame_jobs=frame_jobs, method_settings=dict(method_settings or {})),
                             scenes=sids, jobs=jobs, scheduler=scheduler, desc="misregistration scenes",
                             progress=progress)
    cols = ["scene", "method", "translation_m", "rotation_deg", *MEASURES, "coverage"]
    return pd.DataFrame(rows, columns=cols)


def clean_scene_inputs(layout: Layout, sid: str, eval_voxel_size: float):
    """The clean synthetic inputs of the studies on one evaluation scene.

    Parameters
    ----------
    layout : Layout
    sid : str
        Evaluation scene id.
    eval_voxel_size : float
        Evaluation voxel size (m) of the reference grid.

    Returns
    -------
    tuple
        ``(upper, lower, reference, index)``: the ground-truth upper map, the clean lower sequence
        decoded once, the lower reference voxelised once, and the map's index (cached beside it).

    Raises
    ------
    FileNotFoundError
        A missing input, naming the file and the stage that writes it.
    """
    from ..transfer import load_index

    sd = layout.scenes / "eval" / sid
    need = [(layout.upper_map(sid, GT), "03_reconstruct_upper"), (sd / "lower" / "poses.txt", "01_simulate"),
            (layout.lower_reference(sid), "05_evaluate_synthetic")]
    for path, stage in need:
        if not path.is_file():
            raise FileNotFoundError(f"{path}: missing; run {stage} first")
    upper = read_map(layout.upper_map(sid, GT))
    lower = read_sequence(sd / "lower").load()
    reference = reference_grid(layout.lower_reference(sid), eval_voxel_size)  # voxelised once
    index = load_index(layout.upper_map(sid, GT), semantic_map=upper)  # cached beside the map
    return upper, lower, reference, index


def _misregistration_scene(data_root: str, methods: tuple[str, ...], cases: tuple[tuple[float, float], ...],
                           o: dict, sid: str) -> list[dict]:
    """The score rows of one scene (a task of :func:`misregistration_study`)."""
    from ..evaluate.metrics import compare
    from ..fusion import reconstruct_many
    from ..poses.registration import rigid_perturbation
    from ..transfer import settings_for, transfer_sequence

    layout = Layout(data_root)
    upper, lower, reference, index = clean_scene_inputs(layout, sid, o["eval_voxel_size"])
    center = upper.points.astype(np.float64).mean(axis=0)
    scene_seed = int(np.random.SeedSequence([o["seed"], zlib.crc32(sid.encode())]).generate_state(1)[0])
    labelings = []  # (translation, rotation, method, labels folder, coverage)
    with tempfile.TemporaryDirectory(prefix=f".misregistration_{sid}.", dir=layout.root) as tmp:
        for t, r in cases:
            P = rigid_perturbation(t, r, center=center, seed=scene_seed)
            poses = np.linalg.inv(P) @ lower.poses  # the cameras in the unmoved map = the map moved by P
            for method in methods:
                out = Path(tmp) / f"t{t:g}_r{r:g}" / method
                res = transfer_sequence(method, lower, index, out, poses=poses, jobs=o["frame_jobs"], progress=False,
                                        **settings_for(method, o["method_settings"]))
                labelings.append((t, r, method, out, res["coverage"]))
        # one fusion of the lower frames at their true poses for every labeling
        maps = reconstruct_many(lower, [j[3] for j in labelings], o["voxel_size"])
    rows = []
    for (t, r, method, _, cov), pred in zip(labelings, maps, strict=True):
        s = compare(reference, pred, voxel_size=o["eval_voxel_size"],
                    grid_origin=eval_grid_origin(o["eval_voxel_size"]))
        rows.append(dict(scene=sid, method=method, translation_m=t, rotation_deg=r,
                         **{k: float(s[k]) for k in MEASURES}, coverage=float(cov)))
    return rows
