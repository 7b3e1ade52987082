"""Trajectory errors against ground truth, as in the TUM RGB-D benchmark [1]_.

ATE: RMSE of the camera positions after a least-squares rigid (or similarity) alignment
(Umeyama [2]_ / Horn); RPE: the relative motion errors over ``delta`` frames. Frames whose true
pose is not finite are skipped, and an RPE pair is two frames ``delta`` apart in the recording
that both have ground truth (no pair spans a gap in the ground truth).

The numbers equal those of evo [3]_ (``evo_ape tum gt.txt est.txt --align``, ``evo_rpe tum gt.txt
est.txt --delta 1 --delta_unit f``; :func:`evo_trajectory_errors` computes them through evo's
``metrics`` and ``tests/test_align.py`` checks they agree): evo has no notion of frames without
ground truth, so this module keeps its own code and skips them before aligning; trajectories
written by ``semmatch reconstruct --estimate-poses --poses-out`` are TUM files that evo reads.

References
----------
.. [1] J. Sturm et al., "A benchmark for the evaluation of RGB-D SLAM systems", IROS 2012.
.. [2] S. Umeyama, "Least-squares estimation of transformation parameters between two point
   patterns", TPAMI 1991.
.. [3] M. Grupp, "evo: Python package for the evaluation of odometry and SLAM",
   https://github.com/MichaelGrupp/evo, 2017.
"""

from __future__ import annotations

import numpy as np

__all__ = ["align_trajectory", "ate", "rpe", "rpe_pairs", "trajectory_errors", "evo_trajectory_errors", "rotation_deg"]


def rotation_deg(R: np.ndarray) -> float:
    """Angle (degrees) of the rotation matrix ``R``."""
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


def _positions(poses: np.ndarray, what: str) -> np.ndarray:
    P = np.asarray(poses, dtype=np.float64)
    if P.ndim == 3 and P.shape[1:] == (4, 4):
        return P[:, :3, 3]
    if P.ndim == 2 and P.shape[1] == 3:
        return P
    raise ValueError(f"{what}: expected (N,4,4) poses or (N,3) positions, got shape {P.shape}")


def align_trajectory(est: np.ndarray, gt: np.ndarray, *, with_scale: bool = False) -> np.ndarray:
    """Least-squares similarity/rigid transform ``S`` with ``S @ est ≈ gt`` (Umeyama), 4x4.

    With ``with_scale`` the 3x3 block holds ``s * R`` (monocular-style alignment).
    """
    a, b = _positions(est, "est"), _positions(gt, "gt")
    if a.shape != b.shape:
        raise ValueError(f"est has {len(a)} poses, gt has {len(b)}")
    if len(a) < 3:
        raise ValueError("need at least 3 poses to align trajectories")
    ma, mb = a.mean(0), b.mean(0)
    xa, xb = a - ma, b - mb
    U, D, Vt = np.linalg.svd(xb.T @ xa / len(a))
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1
    R = U @ S @ Vt
    s = float(np.trace(np.diag(D) @ S) / xa.var(axis=0).sum()) if with_scale else 1.0
    T = np.eye(4)
    T[:3, :3] = s * R
    T[:3, 3] = mb - s * R @ ma
    return T


def _valid_pairs(est: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    est = np.asarray(est, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    if est.shape != gt.shape or est.ndim != 3 or est.shape[1:] != (4, 4):
        raise ValueError(f"est {est.shape} and gt {gt.shape} must both be (N,4,4)")
    ok = np.isfinite(gt).all(axis=(1, 2)) & np.isfinite(est).all(axis=(1, 2))
    return (est, gt) if ok.all() else (est[ok], gt[ok])


def ate(est: np.ndarray, gt: np.ndarray, *, align: bool = True) -> float:
    """Absolute trajectory error: RMSE (metres) of positions, after rigid alignment when ``align``.

    Frames whose ground truth is NaN are skipped.
    """
    est, gt = _valid_pairs(est, gt)
    a = _positions(est, "est")
    if align:
        S = align_trajectory(est, gt)
        a = a @ S[:3, :3].T + S[:3, 3]
    return float(np.sqrt(np.mean(np.sum((a - gt[:, :3, 3]) ** 2, axis=1))))


def rpe_pairs(est: np.ndarray, gt: np.ndarray, delta: int = 1) -> np.ndarray:
    """The RPE pairs: indices ``i`` whose frames ``i`` and ``i + delta`` both have finite estimates and ground truth."""
    _valid_pairs(est, gt)  # shape checks
    ok = np.isfinite(np.asarray(gt, dtype=np.float64)).all(axis=(1, 2)) & np.isfinite(
        np.asarray(est, dtype=np.float64)).all(axis=(1, 2))
    return np.flatnonzero(ok[:-delta] & ok[delta:]) if len(ok) > delta else np.zeros(0, np.int64)


def rpe(est: np.ndarray, gt: np.ndarray, *, delta: int = 1) -> tuple[float, float]:
    """Relative pose error over ``delta`` frames: (translation RMSE in metres, mean rotation in degrees).

    Pairs are frames ``i`` and ``i + delta`` of the recording that both have ground truth, so
    that no pair spans a gap in it.

    Raises
    ------
    ValueError
        No such pair.
    """
    est = np.asarray(est, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    i = rpe_pairs(est, gt, delta)
    if len(i) == 0:
        raise ValueError(f"need two frames {delta} apart with ground truth for RPE")
    inv = np.linalg.inv
    d_est = inv(est[i]) @ est[i + delta]
    d_gt = inv(gt[i]) @ gt[i + delta]
    E = inv(d_gt) @ d_est
    trans = float(np.sqrt(np.mean(np.sum(E[:, :3, 3] ** 2, axis=1))))
    cos = np.clip((np.trace(E[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    return trans, float(np.degrees(np.arccos(cos)).mean())


def trajectory_errors(est: np.ndarray, gt: np.ndarray, *, delta: int = 1) -> dict:
    """``ate_rmse`` (aligned), ``ate_rmse_unaligned``, ``rpe_trans``, ``rpe_rot_deg``, ``n_frames`` (with ground truth)."""
    t, r = rpe(est, gt, delta=delta)
    e, g = _valid_pairs(est, gt)
    return {
        "ate_rmse": ate(est, gt, align=True),
        "ate_rmse_unaligned": ate(est, gt, align=False),
        "rpe_trans": t,
        "rpe_rot_deg": r,
        "n_frames": len(e),
    }


def evo_trajectory_errors(est: np.ndarray, gt: np.ndarray, *, delta: int = 1) -> dict:
    """:func:`trajectory_errors` computed by evo (``evo.core.metrics``): the same keys and numbers.

    Frames without a finite estimate or ground truth are dropped first (evo cannot skip them);
    with gaps, RPE pairs may then span a gap, unlike :func:`rpe`.

    Parameters
    ----------
    est, gt : ndarray (N, 4, 4)
    delta : int
        RPE step in frames.

    Returns
    -------
    dict
        ``ate_rmse`` (after evo's rigid Umeyama alignment), ``ate_rmse_unaligned``, ``rpe_trans``
        (RMSE), ``rpe_rot_deg`` (mean), ``n_frames``.
    """
    from evo.core import metrics
    from evo.core.trajectory import PoseTrajectory3D

    e, g = _valid_pairs(est, gt)
    stamps = np.arange(len(e), dtype=np.float64)

    def traj(P: np.ndarray) -> PoseTrajectory3D:
        return PoseTrajectory3D(poses_se3=list(P), timestamps=stamps.copy())

    def ape(ref, estimate) -> float:
        m = metrics.APE(metrics.PoseRelation.translation_part)
        m.process_data((ref, estimate))
        return float(m.get_statistic(metrics.StatisticsType.rmse))

    unaligned = ape(traj(g), traj(e))
    aligned_est = traj(e)
    aligned_est.align(traj(g), correct_scale=False)
    out = {"ate_rmse": ape(traj(g), aligned_est), "ate_rmse_unaligned": unaligned}
    for key, relation, stat in (("rpe_trans", metrics.PoseRelation.translation_part, metrics.StatisticsType.rmse),
                                ("rpe_rot_deg", metrics.PoseRelation.rotation_angle_deg, metrics.StatisticsType.mean)):
        m = metrics.RPE(relation, delta=int(delta), delta_unit=metrics.Unit.frames, all_pairs=False)
        m.process_data((traj(g), traj(e)))
        out[key] = float(m.get_statistic(stat))
    out["n_frames"] = len(e)
    return out
