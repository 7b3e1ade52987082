"""Table 3 on "real-like" sequences: sensor noise on, poses withheld and estimated, maps registered (07).

The simulator writes, for every evaluation scene, ``upper_noisy`` and ``lower_noisy``: the
person's and the robot's recordings seen through a Kinect-like sensor model (depth noise
growing with distance, dropouts, RGB noise and exposure changes), each with its own drifting,
jittered recorded poses (``poses.txt``: what wheel odometry or an IMU would give). Nothing of the
ground truth enters the chain; it is what a real user can do:

1. each recording's poses are estimated in its *own* frame (the first camera pose is the
   identity) by RGB-D odometry (:func:`semmatch.poses.odometry.estimate_poses`: frame-to-frame
   tracking refined by a pose graph with loop closures), seeded by the frame-to-frame motions
   of its recorded poses (the prior; their absolute placement is never used) and gated by
   ``prior_tolerance`` (to be chosen on validation scenes: :func:`select_prior_tolerance`);
2. each recording is fused in its own frame: the upper maps (labelled by ground truth and by
   each network) and the lower geometry;
3. the lower reconstruction is registered onto the upper map from geometry alone
   (:func:`semmatch.poses.registration.register_maps`: FPFH + RANSAC, point-to-plane ICP), giving
   ``T_reg`` (lower frame -> upper frame);
4. every method transfers labels from the upper map into the noisy lower frames placed at
   ``T_reg @ est_lower``; the lower labelings are fused at ``est_lower`` (the robot's own
   frame) and scored against the reference: the noisy lower frames fused at ``est_lower`` with
   ground-truth labels (as in the paper's real-data protocol, where the reconstruction itself
   was annotated). The measures score the labels; the errors of both trajectories and of the
   registration still degrade the transferred labels.

The ground truth (``poses_gt.txt``) is read for the *report* only: trajectory errors, the error
of ``T_reg`` against the true relative transform, and the rigid transform taking the lower
recording's frame into the world, so that the stored lower maps can be scored against a
ground-truth-mesh reference (``compare(ref, pred, transform=lower_to_world)``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..evaluate.metrics import MEASURES
from ..io import (
    read_map,
    read_sequence,
    write_json,
)
from .layout import GT, Layout, model_name, source_dir
from .real_poses import (
    DEFAULT_PRIOR_TOLERANCE,
    PosedSequence,
    check_tolerance,
    estimate_or_load_poses,
    finite_frames,
    pose_cache_name,
    registration_errors,
    world_alignment,
)
from .synthetic import eval_grid_origin, reference_grid

__all__ = ["real_like_lower_map", "evaluate_real_like", "chain_from_poses", "trajectory_row",
           "score_real_like_against_mesh"]


def _moved(m, T: np.ndarray):
    """The map ``m`` moved by the rigid transform ``T`` (points and normals)."""
    R, t = np.asarray(T[:3, :3], dtype=np.float64), np.asarray(T[:3, 3], dtype=np.float64)
    normals = None if m.normals is None else (m.normals @ R.T).astype(np.float32)
    return replace(m, points=(m.points @ R.T + t).astype(np.float32), normals=normals)


def _compact_frame(m) -> np.ndarray:
    """Rigid transform into the frame of a map's minimal oriented bounding box (from its vertices only).

    A map in a camera's frame is tilted against its walls; the label-transfer index is an
    axis-aligned grid, which in this frame holds about half the voxels (and builds in about
    half the time) than in the tilted one.
    """
    import open3d as o3d

    pts = m.points.astype(np.float64)
    pts = pts[np.lexsort(pts.T[::-1])]  # the same vertices in any order: the same box
    box = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)).get_minimal_oriented_bounding_box()
    U = np.eye(4)
    U[:3, :3] = np.asarray(box.R).T
    U[:3, 3] = -U[:3, :3] @ np.asarray(box.center)
    return U


def real_like_lower_map(data_root: str | Path, scene_id: str, source: str, method: str) -> Path:
    """Where :func:`evaluate_real_like` stores a lower map: ``real_like/<scene>/lower_maps/<source>/<method>.ply``.

    ``source`` is ``gt`` (ground truth) or a network; ``method`` a transfer method, ``lower``
    (the network on the lower frames) or ``fused``. The reference is ``real_like/<scene>/reference.ply``.
    """
    return _lower_map_path(Layout(data_root).real_like / scene_id, source, method)


def _lower_map_path(work: Path, source: str, method: str) -> Path:
    """``work/lower_maps/<source>/<method>.ply``: where the chain of one scene stores a lower map."""
    return Path(work) / "lower_maps" / source_dir(source) / f"{method}.ply"


def _matrix(T: np.ndarray) -> list:
    return np.asarray(T, dtype=np.float64).round(9).tolist()


def evaluate_real_like(
    data_root: str | Path,
    methods: Sequence[str],
    networks: Sequence[str],
    *,
    voxel_size: float = 0.04,
    eval_voxel_size: float = 0.05,
    include_ground_truth: bool = True,
    prior_tolerance: tuple[float, float] | None = DEFAULT_PRIOR_TOLERANCE,
    fused_base: str | None = "3d-neighborhood",
    registration_voxel: float = 0.1,
    registration_seed: int = 0,
    registration_restarts: int = 3,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    method_settings: Mapping[str, Mapping] | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """Run the real-like chain (module documentation) for every evaluation scene and score it.

    Per scene: estimate the poses of ``upper_noisy`` and ``lower_noisy``, each in its own
    frame; build the upper map of each source (ground truth, each network's predictions on
    the noisy upper frames); fuse the noisy lower frames at their estimated poses with
    ground-truth labels (the reference; its geometry, labels ignored, is what is registered);
    register it onto the upper map; label the lower frames by each method from each upper map
    (frames at ``T_reg @ est_lower``), by each network directly, and ``fused`` (per network:
    ``fused_base``'s label where the map supports a pixel, the network's elsewhere); fuse each
    labeling at the estimated lower poses and compare it with the reference.

    Written under ``real_like/<scene>/``: the pose caches (:func:`pose_cache_name`), the upper
    maps ``upper_<source>.ply``, ``reference.ply``, every lower map
    (:func:`real_like_lower_map`), the label folders ``lower_labels_<source>/<method>/`` and
    ``registration.json`` (the registration, its errors and ``lower_to_world``).

    Parameters
    ----------
    data_root : path
    methods, networks : sequences of str
    voxel_size, eval_voxel_size : float
        Fusion and evaluation voxel sizes (m).
    include_ground_truth : bool
        Also transfer from a ground-truth upper map (fused from the noisy upper frames).
    prior_tolerance : (metres, degrees) or None
        Odometry gate (:func:`estimate_or_load_poses`); choose it on validation scenes
        (:func:`select_prior_tolerance`).
    fused_base : str or None
        Transfer method whose labels the ``fused`` rows use; None: no ``fused`` rows.
    registration_voxel, registration_seed, registration_restarts
        ``voxel_size``, ``seed`` and ``restarts`` of :func:`semmatch.poses.registration.register_maps`.
    jobs : int
        Scenes run as tasks of :func:`semmatch.runtime.engine.map_tasks` on ``jobs`` local worker
        processes (with one scene: its label transfer in ``jobs`` processes).
    scheduler : str, optional
        Dask scheduler address instead (default ``SEMMATCH_SCHEDULER``).
    progress : bool

    Returns
    -------
    table : DataFrame
        scene, model, method, jaccard, sorensen, color_acc, mean_acc. ``model`` is
        ``ground truth`` or a network; ``method`` a transfer method, ``lower`` (the network on
        the lower frames), ``fused``, or ``upper`` (each network's upper map scored against the
        noisy upper frames fused with ground-truth labels, in the person's frame).
    trajectories : DataFrame
        scene, sequence (upper, lower), poses (recorded prior or estimated), ate_rmse (m,
        after rigid alignment), ate_rmse_unaligned (m, the trajectory placed at the true first
        pose: its drift from the start), rpe_trans (m/frame), rpe_rot_deg (deg/frame), n_frames.
    registration : DataFrame
        One row per scene: scene; fitness, inlier_rmse (m), global_fitness, agreement,
        restarts, seconds (:class:`semmatch.poses.registration.Registration`); reg_trans_err_m,
        reg_rot_err_deg, lower_in_upper_rmse_m (:func:`registration_errors` against the
        truth named in ``truth``: ``mesh``, each map fitted onto the scene's ground-truth mesh
        by :func:`world_alignment`, or ``traj``, the trajectory alignments alone, when the
        scene has no ``scene.ply``); reg_trans_err_traj_m, reg_rot_err_traj_deg (against the
        trajectory alignments; uncertain by about the trajectories' ATE); and (4, 4) ndarrays:
        transform (``T_reg``), true_transform, lower_to_world, upper_to_world (the frames
        placed in the world, as ``truth``), lower_to_world_traj, upper_to_world_traj. Score a
        stored lower map against a world-frame reference with
        ``compare(ref, real_like_lower_map(...), transform=lower_to_world)``.

    Raises
    ------
    FileNotFoundError
        A scene without its noisy sequences, a missing network.
    ValueError
        ``fused_base`` not among ``methods`` (with networks), a bad ``prior_tolerance``.
    """
    tol = check_tolerance(prior_tolerance)
    if fused_base is not None and networks and fused_base not in methods:
        raise ValueError(f"fused_base {fused_base!r} is not among the methods {list(methods)}")
    layout = Layout(data_root)
    sources = ([GT] if include_ground_truth else []) + list(networks)
    if not sources:
        raise ValueError("nothing to evaluate: no networks and include_ground_truth=False")
    from ..runtime.engine import resolve_scheduler

    scenes = [sd.name for sd in layout.scene_dirs("eval")]
    o = dict(voxel_size=voxel_size, eval_voxel_size=eval_voxel_size, tol=tol, fused_base=fused_base,
             registration_voxel=registration_voxel, registration_seed=registration_seed,
             registration_restarts=registration_restarts, method_settings=dict(method_settings or {}),
             frame_jobs=int(jobs) if resolve_scheduler(scheduler) is None and len(scenes) == 1 else 1)
    # scenes are engine tasks (jobs local processes or a scheduler); one scene: its frames in jobs processes
    per_scene = layout.map_scenes(_real_like_scene, tuple(methods), tuple(networks), tuple(sources), o, scenes=scenes,
                                  flatten=False, jobs=jobs, scheduler=scheduler, desc="real-like scenes",
                                  progress=progress)
    rows = [r for scene_rows, _, _ in per_scene for r in scene_rows]
    traj_rows = [r for _, scene_traj, _ in per_scene for r in scene_traj]
    reg_rows = [reg for _, _, reg in per_scene]
    return pd.DataFrame(rows), pd.DataFrame(traj_rows), pd.DataFrame(reg_rows)


def _real_like_scene(data_root: str, methods: tuple[str, ...], networks: tuple[str, ...], sources: tuple[str, ...],
                     o: dict, sid: str) -> tuple[list[dict], list[dict], dict]:
    """The real-like chain of one scene (a task of :func:`evaluate_real_like`): its score rows,
    trajectory rows and registration row. Open3D runs on one thread (its parallel sums and
    RANSAC differ from run to run otherwise; :mod:`semmatch.poses.rgbd_odometry`), so the task repeats
    its numbers run to run, on a pinned worker or not."""
    from ..poses.rgbd_odometry import open3d_threads

    with open3d_threads(1):
        return _real_like_scene_chain(data_root, methods, networks, sources, o, sid)


def _real_like_scene_chain(data_root: str, methods: tuple[str, ...], networks: tuple[str, ...],
                           sources: tuple[str, ...], o: dict, sid: str) -> tuple[list[dict], list[dict], dict]:
    """:func:`_real_like_scene` under its thread limit: poses, then :func:`chain_from_poses`."""
    layout = Layout(data_root)
    models = {net: layout.load_network(net) for net in networks}
    sd = layout.scenes / "eval" / sid
    for need in ("upper_noisy", "lower_noisy"):
        if not (sd / need).is_dir():
            raise FileNotFoundError(f"{sd / need}: no noisy sequence; run 01_simulate with noise on")
    work = layout.real_like / sid
    work.mkdir(parents=True, exist_ok=True)
    seqs, est, true, traj_rows = _posed_recordings(sd, work, sid, o["tol"])
    rows, reg_row = chain_from_poses(sd, work, seqs, est, true, models, methods, sources, o)
    return rows, traj_rows, reg_row


def chain_from_poses(sd: Path, work: Path, seqs: dict, est: dict, true: dict, models: dict,
                     methods: Sequence[str], sources: Sequence[str], o: dict,
                     transform: np.ndarray | None = None,
                     predicted: dict[tuple[str, str], Path] | None = None) -> tuple[list[dict], dict]:
    """The real-like chain of one scene from posed recordings on: upper maps, registration, lower labels, scores.

    :func:`evaluate_real_like` runs it on the noisy recordings at their estimated poses; the
    diagnostic arms of :mod:`semmatch.experiments.real_diagnostics` on other frames and poses.

    Parameters
    ----------
    sd : path
        The scene folder (``scene.ply``, when present, places the maps in the world for the report).
    work : path
        Output folder: the upper maps, ``reference.ply``, ``registration.json``, the label
        folders and ``lower_maps/<source>/<method>.ply``.
    seqs : dict
        ``upper`` and ``lower``: :class:`~semmatch.experiments.real_poses.PosedSequence` each.
    est, true : dict
        ``upper`` and ``lower``: the poses the frames carry and their true poses (N, 4, 4).
    models : dict
        Network name -> model.
    methods, sources : sequences of str
        Transfer methods; upper-map sources (``GT`` and network names).
    o : dict
        voxel_size, eval_voxel_size, tol, fused_base, registration_voxel, registration_seed,
        registration_restarts, frame_jobs (as :func:`evaluate_real_like` builds it).
    transform : ndarray (4, 4), optional
        The lower frame -> upper frame transform to use instead of registering the maps (e.g.
        the identity, for recordings both at their true poses).
    predicted : dict, optional
        ``(recording, network) -> labels folder``: a network's labels of the ``upper`` or
        ``lower`` frames already predicted (labels do not depend on poses); the others are
        predicted into ``work``. ``o["world_truth"] == "traj"`` places the maps in the world
        by the trajectory alignments alone (the mesh fit is skipped; default ``mesh``).

    Returns
    -------
    rows : list of dict
        scene, model, method and the four measures (:func:`evaluate_real_like`'s table).
    registration : dict
        The registration row.
    """
    from ..fusion import reconstruct_many

    sid = sd.name
    methods, sources = tuple(methods), tuple(sources)
    predicted = dict(predicted or {})
    upper_maps, upper_reference = _upper_maps(seqs["upper"], models, sources, work, o["voxel_size"],
                                              {n: d for (r, n), d in predicted.items() if r == "upper"})
    # the lower reference (own frame); its geometry is registered onto the upper map
    (reference,) = reconstruct_many(seqs["lower"], [None], o["voxel_size"], outs=[work / "reference.ply"])
    reg, reg_row = _registration(sd, work, sid, reference, upper_maps[0], est, true, o, transform=transform)
    # the transfer works in the upper map's bounding-box frame U (a compact index grid): the
    # map moved by U, the lower frames at U @ T_reg @ est_lower
    U = _compact_frame(upper_maps[0])
    lower = _lower_labels(seqs["lower"], models, methods, sources, upper_maps, U, U @ reg.transform @ est["lower"],
                          work, o["fused_base"], o["frame_jobs"],
                          {n: d for (r, n), d in predicted.items() if r == "lower"}, o.get("method_settings"))
    rows = _real_like_rows(work, sid, seqs["lower"], lower, reference, upper_maps, upper_reference, sources,
                           o["voxel_size"], o["eval_voxel_size"])
    return rows, reg_row


def _posed_recordings(sd: Path, work: Path, sid: str, tol) -> tuple[dict, dict, dict, list[dict]]:
    """The noisy upper and lower recordings of a scene at their estimated poses (read once, into
    memory: predicted, transferred and fused from there): ``(seqs, est, true, traj_rows)``, the
    trajectory rows scoring the recorded drifting poses and the estimated ones."""
    seqs, est, true, traj_rows = {}, {}, {}, []
    for name in ("upper", "lower"):
        noisy = read_sequence(sd / f"{name}_noisy").load()
        est[name], true[name] = estimate_or_load_poses(sd / f"{name}_noisy", work / pose_cache_name(name, tol),
                                                       seq=noisy, prior_tolerance=tol, progress=False)
        for what, poses in (("recorded (drifting prior)", noisy.poses), ("estimated (RGB-D odometry)", est[name])):
            traj_rows.append(trajectory_row(sid, name, what, poses, true[name]))
        seqs[name] = PosedSequence(noisy, est[name])
    return seqs, est, true, traj_rows


def trajectory_row(scene: str, sequence: str, poses_name: str, poses: np.ndarray, true: np.ndarray) -> dict:
    """One row of :func:`evaluate_real_like`'s trajectory table: a recording's poses against its true ones.

    The poses are placed at the true pose of their first finite frame, so that the unaligned
    errors (``ate_rmse_unaligned``) are the drift from the start; ``ate_rmse`` is after rigid
    alignment (:func:`semmatch.poses.trajectory_metrics.trajectory_errors`).

    Parameters
    ----------
    scene, sequence, poses_name : str
        The row's ``scene``, ``sequence`` (upper, lower) and ``poses`` (what the poses are).
    poses, true : ndarray (N, 4, 4)

    Returns
    -------
    dict
    """
    from ..poses.trajectory_metrics import trajectory_errors

    ok = finite_frames(poses, true)
    first = int(np.flatnonzero(ok)[0])
    anchored = true[first] @ np.linalg.inv(poses[first]) @ poses
    err = trajectory_errors(anchored, true)
    return dict(scene=scene, sequence=sequence, poses=poses_name,
                **{k: float(v) for k, v in err.items() if np.isscalar(v)})


def _upper_maps(upper: PosedSequence, models: dict, sources: tuple[str, ...], work: Path,
                voxel_size: float, predicted: dict[str, Path] | None = None) -> tuple[list, object]:
    """One fusion of the upper frames (own frame), labelled by ground truth and each network:
    the upper map of every source, and the upper reference (the noisy upper frames fused with
    ground-truth labels, which scores each network's own upper map: the ``upper`` rows)."""
    from ..fusion import reconstruct_many
    from ..segment import predict_sequence

    upper_labels = {GT: None}
    for net in models:
        if predicted and net in predicted:
            upper_labels[net] = predicted[net]
        else:
            upper_labels[net] = work / f"upper_labels_{net}"
            predict_sequence(models[net], upper, upper_labels[net], progress=False)
    upper_sources = [*sources, *([] if GT in sources else [GT])]
    upper_maps = reconstruct_many(upper, [upper_labels[s] for s in upper_sources], voxel_size,
                                  outs=[work / f"upper_{s}.ply" for s in upper_sources])
    return upper_maps[:len(sources)], upper_maps[upper_sources.index(GT)]


def _registration(sd: Path, work: Path, sid: str, reference, upper_map, est: dict, true: dict, o: dict,
                  transform: np.ndarray | None = None):
    """The lower reference registered onto the upper map (or placed by the given ``transform``),
    and its row (``registration.json``): the errors against ground truth, each recording placed
    in the world by its trajectory alignment and (with the scene mesh) by its map fitted onto
    the mesh."""
    from ..poses.registration import Registration, register_maps

    tol, registration_voxel, registration_seed = o["tol"], o["registration_voxel"], o["registration_seed"]
    if transform is None:
        reg = register_maps(reference, upper_map, voxel_size=registration_voxel, seed=registration_seed,
                            restarts=o["registration_restarts"])
    else:
        T, nan = np.asarray(transform, dtype=np.float64), float("nan")
        reg = Registration(transform=T, fitness=nan, inlier_rmse=nan, global_transform=T, global_fitness=nan,
                           restarts=0, agreement=0, candidates=[], n_source=0, n_target=0, seconds=0.0)
    use_mesh = o.get("world_truth", "mesh") == "mesh" and (sd / "scene.ply").is_file()
    mesh = read_map(sd / "scene.ply") if use_mesh else None
    placed = {("traj", n): world_alignment(est[n], true[n]) for n in ("upper", "lower")}
    if mesh is not None:
        placed |= {("mesh", n): world_alignment(est[n], true[n], reconstruction=m, scene_mesh=mesh)
                   for n, m in (("upper", upper_map), ("lower", reference))}
    best = "mesh" if ("mesh", "upper") in placed else "traj"
    e_best = registration_errors(reg.transform, placed[best, "upper"], placed[best, "lower"], est["lower"], true["lower"])
    e_traj = registration_errors(reg.transform, placed["traj", "upper"], placed["traj", "lower"], est["lower"],
                                 true["lower"])
    reg_row = dict(scene=sid, fitness=reg.fitness, inlier_rmse=reg.inlier_rmse, global_fitness=reg.global_fitness,
                   agreement=reg.agreement, restarts=reg.restarts, seconds=reg.seconds,
                   reg_trans_err_m=e_best["trans_err_m"], reg_rot_err_deg=e_best["rot_err_deg"],
                   lower_in_upper_rmse_m=e_best["lower_in_upper_rmse_m"],
                   reg_trans_err_traj_m=e_traj["trans_err_m"], reg_rot_err_traj_deg=e_traj["rot_err_deg"],
                   truth=best, transform=reg.transform, true_transform=e_best["true_transform"],
                   lower_to_world=placed[best, "lower"], upper_to_world=placed[best, "upper"],
                   lower_to_world_traj=placed["traj", "lower"], upper_to_world_traj=placed["traj", "upper"])
    write_json(work / "registration.json", {
        k: (_matrix(v) if isinstance(v, np.ndarray) else v) for k, v in reg_row.items()
    } | {"prior_tolerance": None if tol is None else list(tol), "registration_voxel": registration_voxel,
         "registration_seed": registration_seed, "candidates": [
             {k: (_matrix(v) if isinstance(v, np.ndarray) else v) for k, v in c.items()} for c in reg.candidates]})
    return reg, reg_row


def _lower_labels(lower_seq: PosedSequence, models: dict, methods: tuple[str, ...], sources: tuple[str, ...],
                  upper_maps: list, U: np.ndarray, lower_in_upper: np.ndarray, work: Path, fused_base: str | None,
                  jobs: int, predicted: dict[str, Path] | None = None,
                  method_settings: Mapping[str, Mapping] | None = None) -> list[tuple[str, str, Path]]:
    """Labels of the lower frames: each network on them, each method from each upper map (in the
    frame ``U``, the lower frames at ``lower_in_upper``; with its ``method_settings``), and
    ``fused``; ``(source, method, labels folder)`` each."""
    from ..segment import predict_sequence
    from ..transfer import as_map_index, settings_for, transfer_sequence, write_fused_labels

    lower = []
    for source, upper_map in zip(sources, upper_maps, strict=True):
        if source != GT:
            if predicted and source in predicted:
                low_dir = predicted[source]
            else:
                low_dir = work / f"lower_labels_{source}" / "lower"
                predict_sequence(models[source], lower_seq, low_dir, progress=False)
            lower.append((source, "lower", low_dir))
        index = as_map_index(_moved(upper_map, U))
        for method in methods:
            lab_dir = work / f"lower_labels_{source}" / method
            transfer_sequence(method, lower_seq.seq, index, lab_dir, poses=lower_in_upper, jobs=jobs, progress=False,
                              **settings_for(method, method_settings))
            lower.append((source, method, lab_dir))
        if source != GT and fused_base is not None:
            fused = write_fused_labels(work / f"lower_labels_{source}" / fused_base, low_dir,
                                       work / f"lower_labels_{source}" / "fused")
            lower.append((source, "fused", fused))
    return lower


def _real_like_rows(work: Path, sid: str, lower_seq: PosedSequence, lower: list, reference, upper_maps: list,
                    upper_reference, sources: tuple[str, ...], voxel_size: float,
                    eval_voxel_size: float) -> list[dict]:
    """The score rows of a scene: one fusion of the lower frames (own frame) for every labeling,
    each against the lower reference; then the ``upper`` rows (claim C16): each network's upper
    map against the upper reference, in the person's own frame (the human perspective of the
    real-like chain)."""
    from ..evaluate.metrics import compare
    from ..fusion import reconstruct_many

    maps = reconstruct_many(lower_seq, [d for *_, d in lower], voxel_size,
                            outs=[_lower_map_path(work, s, m) for s, m, _ in lower])
    reference_voxels = reference_grid(reference, eval_voxel_size)  # voxelised once for every labeling
    rows = []
    for (source, method, _), pred in zip(lower, maps, strict=True):
        s = compare(reference_voxels, pred, voxel_size=eval_voxel_size, grid_origin=eval_grid_origin(eval_voxel_size))
        rows.append(dict(scene=sid, model=model_name(source), method=method,
                         **{k: float(s[k]) for k in MEASURES}))
    upper_voxels = reference_grid(upper_reference, eval_voxel_size)
    for source, upper_map in zip(sources, upper_maps, strict=True):
        if source != GT:
            s = compare(upper_voxels, upper_map, voxel_size=eval_voxel_size, grid_origin=eval_grid_origin(eval_voxel_size))
            rows.append(dict(scene=sid, model=model_name(source), method="upper",
                             **{k: float(s[k]) for k in MEASURES}))
    return rows


def score_real_like_against_mesh(
    data_root: str | Path,
    per_scene: pd.DataFrame,
    registration: pd.DataFrame,
    *,
    eval_voxel_size: float = 0.05,
    mesh_spacing: float = 0.01,
) -> pd.DataFrame:
    """Score every stored real-like lower map against the ground-truth mesh where the robot looked.

    The reference is the scene's ground-truth mesh sampled every ``mesh_spacing`` metres and kept
    where the robot's camera observed it (:func:`semmatch.evaluate.reference.observed_reference` on the
    clean ``lower`` sequence, which flies the same true poses as ``lower_noisy``; written by
    ``05_evaluate_synthetic`` as ``lower_maps/<scene>/mesh_reference.ply`` and reused when
    present). Each lower map, fused in the robot recording's own frame, is placed in the world
    by the registration table's ``lower_to_world`` (from ground truth: for scoring only) and
    compared on the protocol's evaluation grid (:func:`~semmatch.experiments.synthetic.eval_grid_origin`),
    so odometry, registration and fusion errors all count.

    Parameters
    ----------
    data_root : path
    per_scene : DataFrame
        Rows of :func:`evaluate_real_like` (scene, model, method).
    registration : DataFrame
        Its registration table (scene, lower_to_world).
    eval_voxel_size, mesh_spacing : float

    Returns
    -------
    DataFrame
        scene, model, method, reference (``mesh``) and the four measures.
    """
    from ..evaluate.metrics import compare
    from ..evaluate.reference import observed_reference
    from ..io import read_map, write_map
    from .layout import source_dir

    layout = Layout(data_root)
    to_world = {r.scene: np.asarray(r.lower_to_world, dtype=np.float64) for r in registration.itertuples()}
    rows = []
    # the `upper` rows have no mesh score: their maps lie in the person's frame, and the observed
    # mesh reference is the robot's (claim C16 is judged under the fusion reference only)
    per_scene = per_scene[per_scene["method"] != "upper"]
    for sid, group in per_scene.groupby("scene", sort=False):
        if sid not in to_world:
            raise ValueError(f"{sid}: no registration row (lower_to_world) to place its maps in the world")
        ref_path = layout.mesh_reference(sid)
        if ref_path.is_file():
            ref = read_map(ref_path)
        else:
            sd = layout.scenes / "eval" / sid
            ref = observed_reference(read_map(sd / "scene.ply"), read_sequence(sd / "lower"), spacing=mesh_spacing)
            write_map(ref_path, ref)
        ref = reference_grid(ref, eval_voxel_size)  # voxelised once for every map of the scene
        for r in group.itertuples():
            pred = read_map(real_like_lower_map(data_root, sid, source_dir(r.model), r.method))
            s = compare(ref, pred, eval_voxel_size, transform=to_world[sid], grid_origin=eval_grid_origin(eval_voxel_size))
            rows.append(dict(scene=sid, model=r.model, method=r.method, reference="mesh",
                             **{k: float(s[k]) for k in MEASURES}))
    return pd.DataFrame(rows)
