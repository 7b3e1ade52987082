"""Table 3 on "real-like" sequences: sensor noise on, poses withheld and estimated, maps registered (07).

The simulator writes, for every evaluation scene, ``upper_noisy`` and ``lower_noisy``: the
person's and the robot's recordings seen through a Kinect-like sensor model (depth noise
growing with distance, dropouts, RGB noise and exposure changes), each with its own drifting,
jittered recorded poses (``poses.txt``: what wheel odometry or an IMU would give). Nothing of the
ground truth enters the chain; it is what a real user can do:

1. each recording's poses are estimated in its *own* frame (the first camera pose is the
   identity) by RGB-D odometry (:func:`semmatch.odometry.estimate_poses`: frame-to-frame
   tracking refined by a pose graph with loop closures), seeded by the frame-to-frame motions
   of its recorded poses (the prior; their absolute placement is never used) and gated by
   ``prior_tolerance`` (to be chosen on validation scenes: :func:`select_prior_tolerance`);
2. each recording is fused in its own frame: the upper maps (labelled by ground truth and by
   each network) and the lower geometry;
3. the lower reconstruction is registered onto the upper map from geometry alone
   (:func:`semmatch.registration.register_maps`: FPFH + RANSAC, point-to-plane ICP), giving
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

import time
from collections.abc import Sequence
from collections.abc import Sequence as _SequenceABC
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..io import (
    Frame,
    InMemorySequence,
    SequenceReader,
    read_map,
    read_sequence,
    read_tum,
    write_json,
    write_tum,
)
from ..progress import tqdm
from .layout import GT, Layout, model_name, source_dir
from .synthetic import MEASURE_COLUMNS, eval_grid_origin

__all__ = [
    "PosedSequence",
    "ODOMETRY_DOWNSAMPLE",
    "DEFAULT_PRIOR_TOLERANCE",
    "gate_name",
    "pose_cache_name",
    "estimate_or_load_poses",
    "world_alignment",
    "registration_errors",
    "real_like_lower_map",
    "evaluate_real_like",
    "select_prior_tolerance",
    "score_real_like_against_mesh",
]


class PosedSequence(_SequenceABC):
    """A sequence whose frames carry other poses (e.g. estimated ones) than the recorded ones."""

    def __init__(self, seq: SequenceReader | InMemorySequence, poses: np.ndarray) -> None:
        if len(poses) != len(seq):
            raise ValueError(f"{seq.path}: {len(poses)} poses for {len(seq)} frames")
        self.seq, self.poses, self.intrinsics, self.path = seq, np.asarray(poses), seq.intrinsics, seq.path

    def __len__(self) -> int:
        return len(self.seq)

    def __getitem__(self, i: int) -> Frame:  # type: ignore[override]
        return replace(self.seq[i], pose=self.poses[i].copy())

    def read_labels(self, i: int):
        return self.seq.read_labels(i)


#: the pipeline tracks on frames shrunk by this factor (:func:`semmatch.odometry.estimate_poses`):
#: on a 640x480 real-like lower sequence 0.17 s instead of 0.75 s a frame, ATE 0.2 cm instead of 0.04 cm
ODOMETRY_DOWNSAMPLE = 2

#: the odometry gate of :func:`semmatch.odometry.estimate_poses` (its default); set it from
#: validation scenes with :func:`select_prior_tolerance`
DEFAULT_PRIOR_TOLERANCE: tuple[float, float] | None = (0.1, 10.0)


def _check_tolerance(prior_tolerance) -> tuple[float, float] | None:
    if prior_tolerance is None:
        return None
    try:
        t, r = (float(v) for v in prior_tolerance)
    except (TypeError, ValueError):
        raise ValueError(f"prior_tolerance must be (metres, degrees) or None, got {prior_tolerance!r}") from None
    if not (t > 0 and r > 0 and np.isfinite(t) and np.isfinite(r)):
        raise ValueError(f"prior_tolerance must be positive (metres, degrees), got {prior_tolerance!r}")
    return t, r


def gate_name(prior_tolerance: tuple[float, float] | None) -> str:
    """File-name tag of an odometry gate: ``gate0.1m10deg`` or ``ungated``."""
    tol = _check_tolerance(prior_tolerance)
    return "ungated" if tol is None else f"gate{tol[0]:g}m{tol[1]:g}deg"


def pose_cache_name(recording: str, prior_tolerance: tuple[float, float] | None) -> str:
    """Cache file name of a recording's estimated poses under the chain's settings.

    ``<recording>_poses_ownframe_posegraph_ds<ODOMETRY_DOWNSAMPLE>_<gate>.txt``: poses in the
    recording's own frame (first pose = identity), pose graph on, tracked at
    :data:`ODOMETRY_DOWNSAMPLE`, gated by ``prior_tolerance`` (:func:`gate_name`); a cache of
    other settings is never reused.
    """
    return f"{recording}_poses_ownframe_posegraph_ds{ODOMETRY_DOWNSAMPLE}_{gate_name(prior_tolerance)}.txt"


def estimate_or_load_poses(
    seq_dir: Path,
    out: Path,
    *,
    seq: _SequenceABC | None = None,
    prior_tolerance: tuple[float, float] | None = DEFAULT_PRIOR_TOLERANCE,
    progress: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Estimated poses of a noisy recording in its own frame (cached in ``out``), and its true poses.

    The poses are :func:`semmatch.odometry.estimate_poses` from the identity (no known start
    pose) with the pose graph on, tracked on frames shrunk by :data:`ODOMETRY_DOWNSAMPLE`,
    seeded by the frame-to-frame motions of the recording's ``poses.txt`` and gated by
    ``prior_tolerance``. Name ``out`` with :func:`pose_cache_name` so that caches of other
    settings are not reused. The true poses (``poses_gt.txt``) are only returned, for the
    report; the estimate does not depend on them.

    Parameters
    ----------
    seq_dir : path
        The noisy sequence folder (with ``poses.txt`` and ``poses_gt.txt``).
    out : path
        Cache file (TUM format, written atomically; the poses returned are those it holds).
    seq : sequence, optional
        The frames of ``seq_dir`` when already read (e.g. an :class:`~semmatch.io.InMemorySequence`).
    prior_tolerance : (metres, degrees) or None
        The odometry gate of :func:`~semmatch.odometry.estimate_poses`.
    progress : bool

    Returns
    -------
    estimated, true : ndarray (N,4,4)
        ``estimated[0]`` is the identity.

    Raises
    ------
    FileNotFoundError
        ``seq_dir`` has no ``poses_gt.txt``.
    """
    from ..odometry import estimate_poses

    seq_dir, out = Path(seq_dir), Path(out)
    tol = _check_tolerance(prior_tolerance)
    seq = read_sequence(seq_dir) if seq is None else seq
    gt_file = seq_dir / "poses_gt.txt"
    if not gt_file.is_file():
        raise FileNotFoundError(f"{gt_file}: no true poses to report the trajectory errors against")
    _, true = read_tum(gt_file)
    if out.is_file():
        _, est = read_tum(out)
        if len(est) == len(seq):
            return est, true
    est = estimate_poses(seq, init_pose=np.eye(4), prior=seq.poses, prior_tolerance=tol,
                         downsample=ODOMETRY_DOWNSAMPLE, progress=progress)
    write_tum(out, np.arange(len(est), dtype=np.float64), est)  # atomic
    # the poses as the cache holds them, so that a fresh and a cached run use the same numbers
    return read_tum(out)[1], true


def _finite(*arrays: np.ndarray) -> np.ndarray:
    """Rows (frames) where every pose array is finite."""
    return np.logical_and.reduce([np.isfinite(a).all(axis=(1, 2)) for a in arrays])


def world_alignment(
    est: np.ndarray,
    true: np.ndarray,
    *,
    reconstruction=None,
    scene_mesh=None,
    seed: int = 0,
) -> np.ndarray:
    """Rigid transform taking a recording's own frame into the world (ground truth: for reporting only).

    The rigid alignment of the estimated trajectory onto the true one
    (:func:`semmatch.trajectory_metrics.align_trajectory`; frames with a non-finite true pose skipped).
    With ``reconstruction`` and ``scene_mesh`` it is refined by point-to-plane ICP of the
    reconstruction's vertices onto points sampled on the ground-truth mesh (correspondences
    up to 10, 5, then 2.5 cm; about one mesh point per 4 cm^2): where the map actually lies,
    which can differ from the trajectory alignment by about the trajectory's ATE (6 cm on a
    scene whose upper ATE was 4 cm).

    Parameters
    ----------
    est, true : ndarray (N, 4, 4)
        Estimated (own frame) and true (world) poses.
    reconstruction : SemanticMap, optional
        The recording fused at ``est``.
    scene_mesh : SemanticMap, optional
        The ground-truth mesh (``scene.ply``), in the world frame.
    seed : int
        Seed of the mesh sampling.

    Returns
    -------
    ndarray (4, 4)
    """
    import open3d as o3d

    from ..trajectory_metrics import align_trajectory

    ok = _finite(est, true)
    A = align_trajectory(est[ok], true[ok])
    if reconstruction is None or scene_mesh is None:
        return A
    reg = o3d.pipelines.registration
    target = _mesh_samples(scene_mesh, seed)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(reconstruction.points.astype(np.float64)))
    src = src.voxel_down_sample(0.02)
    for dist in (0.1, 0.05, 0.025):
        A = np.asarray(reg.registration_icp(src, target, dist, A, reg.TransformationEstimationPointToPlane(),
                                            reg.ICPConvergenceCriteria(max_iteration=50)).transformation).copy()
    return A


_MESH_SAMPLES: list = []  # (key, mesh, Open3D point cloud) of the last scene mesh sampled


def _mesh_samples(scene_mesh, seed: int, spacing: float = 0.02):
    """Points (with the triangles' normals) sampled on a mesh, about one per ``spacing**2``; the last one cached."""
    import open3d as o3d

    key = (id(scene_mesh), int(seed), float(spacing))
    if _MESH_SAMPLES and _MESH_SAMPLES[0][0] == key and _MESH_SAMPLES[0][1] is scene_mesh:
        return _MESH_SAMPLES[0][2]
    if not scene_mesh.is_mesh:
        raise ValueError(f"{scene_mesh.source}: the scene's ground truth must be a mesh (triangles)")
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(scene_mesh.points.astype(np.float64)),
                                     o3d.utility.Vector3iVector(scene_mesh.faces))
    mesh.compute_triangle_normals()
    o3d.utility.random.seed(int(seed))
    n = int(np.clip(mesh.get_surface_area() / spacing**2, 10_000, 2_000_000))
    pc = mesh.sample_points_uniformly(n, use_triangle_normal=True)
    _MESH_SAMPLES[:] = [(key, scene_mesh, pc)]
    return pc


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


def registration_errors(
    T_reg: np.ndarray,
    upper_to_world: np.ndarray,
    lower_to_world: np.ndarray,
    est_lower: np.ndarray,
    true_lower: np.ndarray,
) -> dict:
    """Errors of a lower-to-upper registration against the ground truth (for reporting only).

    The true relative transform is ``inv(upper_to_world) @ lower_to_world``
    (:func:`world_alignment` of each recording).

    Parameters
    ----------
    T_reg : (4, 4)
        Estimated transform taking the lower recording's frame into the upper one's.
    upper_to_world, lower_to_world : (4, 4)
        Each recording's frame placed in the world.
    est_lower, true_lower : (N, 4, 4)
        Estimated (own frame) and true (world) lower poses; frames with a non-finite true
        pose are skipped.

    Returns
    -------
    dict
        ``trans_err_m``, ``rot_err_deg`` (:func:`semmatch.registration.transform_error` of
        ``T_reg`` against the truth: the displacement of the lower frame's origin, the first
        lower camera, and the rotation angle), ``lower_in_upper_rmse_m`` (RMSE of the lower
        camera positions mapped into the upper frame, ``T_reg @ est_lower``, against their true
        positions there, ``inv(upper_to_world) @ true_lower``), ``true_transform`` (4, 4).
    """
    from ..registration import transform_error

    truth = np.linalg.inv(upper_to_world) @ lower_to_world
    dt, dr = transform_error(T_reg, truth)
    ok = _finite(est_lower, true_lower)
    mapped = (np.asarray(T_reg) @ est_lower[ok])[:, :3, 3]
    there = (np.linalg.inv(upper_to_world) @ true_lower[ok])[:, :3, 3]
    rmse = float(np.sqrt(np.mean(np.sum((mapped - there) ** 2, axis=1))))
    return dict(trans_err_m=dt, rot_err_deg=dr, lower_in_upper_rmse_m=rmse, true_transform=truth)


def real_like_lower_map(data_root: str | Path, scene_id: str, source: str, method: str) -> Path:
    """Where :func:`evaluate_real_like` stores a lower map: ``real_like/<scene>/lower_maps/<source>/<method>.ply``.

    ``source`` is ``gt`` (ground truth) or a network; ``method`` a transfer method, ``lower``
    (the network on the lower frames) or ``fused``. The reference is ``real_like/<scene>/reference.ply``.
    """
    return Layout(data_root).real_like / scene_id / "lower_maps" / source_dir(source) / f"{method}.ply"


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
        ``voxel_size``, ``seed`` and ``restarts`` of :func:`semmatch.registration.register_maps`.
    jobs : int
        Scenes run as tasks of :func:`semmatch.engine.map_tasks` on ``jobs`` local worker
        processes (with one scene: its label transfer in ``jobs`` processes).
    scheduler : str, optional
        Dask scheduler address instead (default ``SEMMATCH_SCHEDULER``).
    progress : bool

    Returns
    -------
    table : DataFrame
        scene, model, method, jaccard, sorensen, color_acc, mean_acc. ``model`` is
        ``ground truth`` or a network; ``method`` a transfer method, ``lower`` (the network on
        the lower frames) or ``fused``.
    trajectories : DataFrame
        scene, sequence (upper, lower), poses (recorded prior or estimated), ate_rmse (m,
        after rigid alignment), ate_rmse_unaligned (m, the trajectory placed at the true first
        pose: its drift from the start), rpe_trans (m/frame), rpe_rot_deg (deg/frame), n_frames.
    registration : DataFrame
        One row per scene: scene; fitness, inlier_rmse (m), global_fitness, agreement,
        restarts, seconds (:class:`semmatch.registration.Registration`); reg_trans_err_m,
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
    tol = _check_tolerance(prior_tolerance)
    if fused_base is not None and networks and fused_base not in methods:
        raise ValueError(f"fused_base {fused_base!r} is not among the methods {list(methods)}")
    layout = Layout(data_root)
    sources = ([GT] if include_ground_truth else []) + list(networks)
    if not sources:
        raise ValueError("nothing to evaluate: no networks and include_ground_truth=False")
    from functools import partial

    from ..engine import map_tasks, resolve_scheduler

    scenes = [sd.name for sd in layout.scene_dirs("eval")]
    task = partial(_real_like_scene, str(Path(data_root).resolve()), tuple(methods), tuple(networks), tuple(sources),
                   dict(voxel_size=voxel_size, eval_voxel_size=eval_voxel_size, tol=tol, fused_base=fused_base,
                        registration_voxel=registration_voxel, registration_seed=registration_seed,
                        registration_restarts=registration_restarts,
                        frame_jobs=int(jobs) if resolve_scheduler(scheduler) is None and len(scenes) == 1 else 1))
    # scenes are engine tasks (jobs local processes or a scheduler); one scene: its frames in jobs processes
    per_scene = map_tasks(task, scenes, jobs=jobs, scheduler=scheduler, desc="real-like scenes", progress=progress)
    rows = [r for scene_rows, _, _ in per_scene for r in scene_rows]
    traj_rows = [r for _, scene_traj, _ in per_scene for r in scene_traj]
    reg_rows = [reg for _, _, reg in per_scene]
    return pd.DataFrame(rows), pd.DataFrame(traj_rows), pd.DataFrame(reg_rows)


def _real_like_scene(data_root: str, methods: tuple[str, ...], networks: tuple[str, ...], sources: tuple[str, ...],
                     o: dict, sid: str) -> tuple[list[dict], list[dict], dict]:
    """The real-like chain of one scene (a task of :func:`evaluate_real_like`): its score rows,
    trajectory rows and registration row."""
    from ..fusion import reconstruct_many
    from ..metrics import compare
    from ..registration import register_maps
    from ..segment import predict_sequence
    from ..trajectory_metrics import trajectory_errors
    from ..transfer import prepare, transfer_sequence, write_fused_labels

    layout = Layout(data_root)
    models = {net: layout.load_network(net) for net in networks}
    voxel_size, eval_voxel_size, tol, fused_base = o["voxel_size"], o["eval_voxel_size"], o["tol"], o["fused_base"]
    registration_voxel, registration_seed = o["registration_voxel"], o["registration_seed"]
    registration_restarts, jobs, progress = o["registration_restarts"], o["frame_jobs"], False
    sd = layout.scenes / "eval" / sid
    rows, traj_rows = [], []
    for need in ("upper_noisy", "lower_noisy"):
        if not (sd / need).is_dir():
            raise FileNotFoundError(f"{sd / need}: no noisy sequence; run 01_simulate with noise on")
    work = layout.real_like / sid
    work.mkdir(parents=True, exist_ok=True)
    seqs, est, true = {}, {}, {}
    for name in ("upper", "lower"):
        # read once: predicted, transferred and fused from memory
        noisy = read_sequence(sd / f"{name}_noisy").load()
        est[name], true[name] = estimate_or_load_poses(sd / f"{name}_noisy", work / pose_cache_name(name, tol),
                                                       seq=noisy, prior_tolerance=tol, progress=progress)
        for what, poses in (("recorded (drifting prior)", noisy.poses), ("estimated (RGB-D odometry)", est[name])):
            ok = _finite(poses, true[name])
            first = int(np.flatnonzero(ok)[0])
            # placed at the true pose of the first frame: the unaligned errors are the drift
            anchored = true[name][first] @ np.linalg.inv(poses[first]) @ poses
            err = trajectory_errors(anchored, true[name])
            traj_rows.append(dict(scene=sid, sequence=name, poses=what, **{
                k: float(v) for k, v in err.items() if np.isscalar(v)}))
        seqs[name] = PosedSequence(noisy, est[name])
    # upper maps: one fusion of the upper frames (own frame), labelled by ground truth and each network
    upper_labels = {GT: None}
    for net in networks:
        upper_labels[net] = work / f"upper_labels_{net}"
        predict_sequence(models[net], seqs["upper"], upper_labels[net], progress=False)
    upper_maps = reconstruct_many(seqs["upper"], [upper_labels[s] for s in sources], voxel_size,
                                  outs=[work / f"upper_{s}.ply" for s in sources])
    # the lower reference (own frame); its geometry is registered onto the upper map
    (reference,) = reconstruct_many(seqs["lower"], [None], voxel_size, outs=[work / "reference.ply"])
    reg = register_maps(reference, upper_maps[0], voxel_size=registration_voxel, seed=registration_seed,
                        restarts=registration_restarts)
    # the report (ground truth): each recording placed in the world by its trajectory alignment,
    # and by its map fitted onto the scene mesh
    mesh = read_map(sd / "scene.ply") if (sd / "scene.ply").is_file() else None
    placed = {("traj", n): world_alignment(est[n], true[n]) for n in ("upper", "lower")}
    if mesh is not None:
        placed |= {("mesh", n): world_alignment(est[n], true[n], reconstruction=m, scene_mesh=mesh)
                   for n, m in (("upper", upper_maps[0]), ("lower", reference))}
    best = "mesh" if mesh is not None else "traj"
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
    # the transfer works in the upper map's bounding-box frame U (a compact index grid): the
    # map moved by U, the lower frames at U @ T_reg @ est_lower
    U = _compact_frame(upper_maps[0])
    lower_in_upper = U @ reg.transform @ est["lower"]
    # lower labels: each network on the lower frames, each method from each upper map
    lower = []  # (source, method, labels folder)
    for source, upper_map in zip(sources, upper_maps, strict=True):
        if source != GT:
            low_dir = work / f"lower_labels_{source}" / "lower"
            predict_sequence(models[source], seqs["lower"], low_dir, progress=False)
            lower.append((source, "lower", low_dir))
        index = prepare(_moved(upper_map, U))
        for method in methods:
            lab_dir = work / f"lower_labels_{source}" / method
            transfer_sequence(method, seqs["lower"].seq, index, lab_dir, poses=lower_in_upper,
                              jobs=jobs, progress=False)
            lower.append((source, method, lab_dir))
        if source != GT and fused_base is not None:
            fused = write_fused_labels(work / f"lower_labels_{source}" / fused_base, low_dir,
                                  work / f"lower_labels_{source}" / "fused")
            lower.append((source, "fused", fused))
    # one fusion of the lower frames (own frame) for every labeling
    maps = reconstruct_many(seqs["lower"], [d for *_, d in lower], voxel_size,
                            outs=[real_like_lower_map(data_root, sid, s, m) for s, m, _ in lower])
    for (source, method, _), pred in zip(lower, maps, strict=True):
        s = compare(reference, pred, voxel_size=eval_voxel_size, grid_origin=eval_grid_origin(eval_voxel_size))
        rows.append(dict(scene=sid, model=model_name(source), method=method,
                         **{k: float(s[k]) for k in MEASURE_COLUMNS}))
    return rows, traj_rows, reg_row


def select_prior_tolerance(
    scene_dirs: Sequence[str | Path],
    candidates: Sequence[tuple[float, float] | None] = ((0.1, 10.0), None),
    *,
    recordings: Sequence[str] = ("upper_noisy", "lower_noisy"),
    progress: bool = True,
) -> tuple[tuple[float, float] | None, pd.DataFrame]:
    """Choose the odometry gate on validation scenes: the candidate with the lowest mean ATE.

    Every noisy recording of every scene is tracked as :func:`estimate_or_load_poses` does
    (own frame, pose graph, :data:`ODOMETRY_DOWNSAMPLE`, the recorded motions as prior) once per
    candidate, and its ATE (after rigid alignment) is measured against ``poses_gt.txt``; the
    candidate with the lowest mean ATE over all recordings wins (ties: the first listed).
    Pass *validation* scenes (``Layout(root).scene_dirs("val")``), never evaluation scenes.

    Cost: ``len(candidates) * len(scene_dirs) * len(recordings)`` odometry runs and nothing
    else (no fusion, no transfer). One run of a 60-frame 320x240 noisy recording (pose graph
    included) took 5-18 s on the 2-core development machine under load (16 recordings of eight
    scenes), so two candidates on four validation scenes cost about 16 runs, 1.5-5 minutes there.

    Parameters
    ----------
    scene_dirs : sequence of path
        Scene folders with the noisy recordings (``upper_noisy/``, ``lower_noisy/``).
    candidates : sequence of (metres, degrees) or None
        Gates to compare (None: no gate, the prior only seeds the tracker).
    recordings : sequence of str
        Recording folders of each scene to track.
    progress : bool

    Returns
    -------
    chosen : (metres, degrees) or None
    table : DataFrame
        One row per scene, recording and candidate: scene, recording, prior_tolerance
        (:func:`gate_name`), ate_rmse (m), rpe_trans (m/frame), rpe_rot_deg (deg/frame),
        n_frames, seconds (odometry wall time).

    Raises
    ------
    ValueError
        No scenes or no candidates, a bad candidate.
    FileNotFoundError
        A scene without a recording or its ``poses_gt.txt``.
    """
    from ..odometry import estimate_poses
    from ..trajectory_metrics import trajectory_errors

    cands = [_check_tolerance(c) for c in candidates]
    if not cands:
        raise ValueError("no candidate gates to choose from")
    dirs = [Path(d) for d in scene_dirs]
    if not dirs:
        raise ValueError("no validation scenes to choose the gate on")
    for d in dirs:
        for rec in recordings:
            if not (d / rec / "poses_gt.txt").is_file():
                raise FileNotFoundError(f"{d / rec}: no noisy recording with poses_gt.txt")
    rows = []
    bar = tqdm(total=len(dirs) * len(recordings) * len(cands), desc="odometry gate", disable=not progress)
    for d in dirs:
        for rec in recordings:
            seq = read_sequence(d / rec).load()
            _, true = read_tum(d / rec / "poses_gt.txt")
            for c in cands:
                t0 = time.perf_counter()
                est = estimate_poses(seq, init_pose=np.eye(4), prior=seq.poses, prior_tolerance=c,
                                     downsample=ODOMETRY_DOWNSAMPLE)
                err = trajectory_errors(est, true)
                rows.append(dict(scene=d.name, recording=rec, prior_tolerance=gate_name(c),
                                 ate_rmse=float(err["ate_rmse"]), rpe_trans=float(err["rpe_trans"]),
                                 rpe_rot_deg=float(err["rpe_rot_deg"]), n_frames=int(err["n_frames"]),
                                 seconds=time.perf_counter() - t0))
                bar.update()
    bar.close()
    table = pd.DataFrame(rows)
    means = table.groupby("prior_tolerance", sort=False)["ate_rmse"].mean()
    chosen = min(cands, key=lambda c: (means[gate_name(c)], cands.index(c)))
    return chosen, table


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
    where the robot's camera observed it (:func:`semmatch.reference.observed_reference` on the
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
    from ..io import read_map, write_map
    from ..metrics import compare
    from ..reference import observed_reference
    from .layout import source_dir

    layout = Layout(data_root)
    to_world = {r.scene: np.asarray(r.lower_to_world, dtype=np.float64) for r in registration.itertuples()}
    rows = []
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
        for r in group.itertuples():
            pred = read_map(real_like_lower_map(data_root, sid, source_dir(r.model), r.method))
            s = compare(ref, pred, eval_voxel_size, transform=to_world[sid], grid_origin=eval_grid_origin(eval_voxel_size))
            rows.append(dict(scene=sid, model=r.model, method=r.method, reference="mesh",
                             **{k: float(s[k]) for k in MEASURE_COLUMNS}))
    return pd.DataFrame(rows)
