"""Poses of the real-like chain: each recording tracked in its own frame, the odometry gate, alignments.

The steps of :mod:`semmatch.experiments.real` that concern poses: RGB-D odometry of a noisy
recording from the identity, seeded by its recorded (drifting) motions and gated
(:func:`estimate_or_load_poses`, cached per gate), the gate chosen on validation scenes
(:func:`select_prior_tolerance`), and, for the report only, the ground-truth alignments of a
recording's frame into the world (:func:`world_alignment`) and the error of the registration
between the two recordings (:func:`registration_errors`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from collections.abc import Sequence as _SequenceABC
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..io import Frame, InMemorySequence, SequenceReader, read_sequence, read_tum, write_tum
from ..runtime.progress import tqdm

__all__ = [
    "PosedSequence",
    "ODOMETRY_DOWNSAMPLE",
    "ODOMETRY_RULE",
    "DEFAULT_PRIOR_TOLERANCE",
    "check_tolerance",
    "finite_frames",
    "mesh_samples",
    "gate_name",
    "pose_cache_name",
    "estimate_or_load_poses",
    "cached_odometry",
    "world_alignment",
    "registration_errors",
    "select_prior_tolerance",
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


#: the pipeline tracks on frames shrunk by this factor (:func:`semmatch.poses.odometry.estimate_poses`;
#: its cost and accuracy: docs/protocol.md, "Odometry")
ODOMETRY_DOWNSAMPLE = 2

#: the real-like chain's odometry residual and selection rule: point-to-plane first, the rule chosen
#: on the simulated validation recordings (the library default, hybrid first, was chosen on real
#: Kinect frames: docs/recordings.md; on simulated validation recordings with the pose graph the
#: earlier rule was better on 2 of 3), kept so that Table 3's chain stays the validated one
ODOMETRY_RULE = dict(residual="point-to-plane", select="misfit")


#: the odometry gate of :func:`semmatch.poses.odometry.estimate_poses` (its default); set it from
#: validation scenes with :func:`select_prior_tolerance`
DEFAULT_PRIOR_TOLERANCE: tuple[float, float] | None = (0.1, 10.0)


def check_tolerance(prior_tolerance) -> tuple[float, float] | None:
    """An odometry gate as ``(metres, degrees)`` of positive floats, or None (no gate).

    Raises
    ------
    ValueError
        Not a pair of positive finite numbers.
    """
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
    tol = check_tolerance(prior_tolerance)
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

    The poses are :func:`semmatch.poses.odometry.estimate_poses` from the identity (no known start
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
        The odometry gate of :func:`~semmatch.poses.odometry.estimate_poses`.
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
    seq_dir, out = Path(seq_dir), Path(out)
    tol = check_tolerance(prior_tolerance)
    seq = read_sequence(seq_dir) if seq is None else seq
    gt_file = seq_dir / "poses_gt.txt"
    if not gt_file.is_file():
        raise FileNotFoundError(f"{gt_file}: no true poses to report the trajectory errors against")
    _, true = read_tum(gt_file)
    return cached_odometry(seq, out, prior=seq.poses, prior_tolerance=tol, progress=progress), true


def cached_odometry(
    seq: _SequenceABC,
    out: Path,
    *,
    prior: np.ndarray | None,
    prior_tolerance: tuple[float, float] | None = DEFAULT_PRIOR_TOLERANCE,
    progress: bool = True,
) -> np.ndarray:
    """The chain's odometry of ``seq`` from the identity, cached in ``out``.

    :func:`semmatch.poses.odometry.estimate_poses` with :data:`ODOMETRY_RULE` on frames shrunk by
    :data:`ODOMETRY_DOWNSAMPLE`, seeded by the frame-to-frame motions of ``prior`` (None: visual
    only) and gated by ``prior_tolerance``. A cache with one pose per frame is returned as it is;
    name it after everything the estimate depends on (:func:`pose_cache_name`).

    Parameters
    ----------
    seq : sequence
        The frames.
    out : path
        Cache file (TUM format, written atomically).
    prior : ndarray (N,4,4) or None
    prior_tolerance : (metres, degrees) or None
    progress : bool

    Returns
    -------
    ndarray (N,4,4)
        The poses as the cache holds them (a fresh and a cached run use the same numbers);
        the first is the identity.
    """
    from ..poses.odometry import estimate_poses

    out = Path(out)
    if out.is_file():
        _, est = read_tum(out)
        if len(est) == len(seq):
            return est
    est = estimate_poses(seq, init_pose=np.eye(4), prior=prior, prior_tolerance=check_tolerance(prior_tolerance),
                         downsample=ODOMETRY_DOWNSAMPLE, progress=progress, **ODOMETRY_RULE)
    write_tum(out, np.arange(len(est), dtype=np.float64), est)  # atomic
    return read_tum(out)[1]


def finite_frames(*arrays: np.ndarray) -> np.ndarray:
    """Boolean mask of the frames where every given (N, 4, 4) pose array is finite."""
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
    (:func:`semmatch.poses.trajectory_metrics.align_trajectory`; frames with a non-finite true pose skipped).
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

    from ..poses.trajectory_metrics import align_trajectory

    ok = finite_frames(est, true)
    A = align_trajectory(est[ok], true[ok])
    if reconstruction is None or scene_mesh is None:
        return A
    reg = o3d.pipelines.registration
    target = mesh_samples(scene_mesh, seed)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(reconstruction.points.astype(np.float64)))
    src = src.voxel_down_sample(0.02)
    for dist in (0.1, 0.05, 0.025):
        A = np.asarray(reg.registration_icp(src, target, dist, A, reg.TransformationEstimationPointToPlane(),
                                            reg.ICPConvergenceCriteria(max_iteration=50)).transformation).copy()
    return A


_MESH_SAMPLES: list = []  # (key, mesh, Open3D point cloud) of the last scene mesh sampled


def mesh_samples(scene_mesh, seed: int, spacing: float = 0.02):
    """Open3D point cloud sampled on a mesh (with the triangles' normals), about one point per ``spacing**2``.

    The last mesh's samples are kept for the next call with the same mesh, seed and spacing.

    Raises
    ------
    ValueError
        ``scene_mesh`` has no triangles.
    """
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
        ``trans_err_m``, ``rot_err_deg`` (:func:`semmatch.poses.registration.transform_error` of
        ``T_reg`` against the truth: the displacement of the lower frame's origin, the first
        lower camera, and the rotation angle), ``lower_in_upper_rmse_m`` (RMSE of the lower
        camera positions mapped into the upper frame, ``T_reg @ est_lower``, against their true
        positions there, ``inv(upper_to_world) @ true_lower``), ``true_transform`` (4, 4).
    """
    from ..poses.registration import transform_error

    truth = np.linalg.inv(upper_to_world) @ lower_to_world
    dt, dr = transform_error(T_reg, truth)
    ok = finite_frames(est_lower, true_lower)
    mapped = (np.asarray(T_reg) @ est_lower[ok])[:, :3, 3]
    there = (np.linalg.inv(upper_to_world) @ true_lower[ok])[:, :3, 3]
    rmse = float(np.sqrt(np.mean(np.sum((mapped - there) ** 2, axis=1))))
    return dict(trans_err_m=dt, rot_err_deg=dr, lower_in_upper_rmse_m=rmse, true_transform=truth)


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
    else (no fusion, no transfer).

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
    from ..poses.odometry import estimate_poses
    from ..poses.trajectory_metrics import trajectory_errors

    cands = [check_tolerance(c) for c in candidates]
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
                                     downsample=ODOMETRY_DOWNSAMPLE, **ODOMETRY_RULE)
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
