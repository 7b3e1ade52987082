"""The robot online on the simulated scenes: its map's Mean Acc. and its trajectory against the offline chain (issue 53).

For each scene folder (``upper_noisy/``, the person's recording at 1.6 m; ``lower_noisy/``, the
robot's at 0.2 m, with ``poses_gt.txt`` and the recording's own drifting odometry in
``poses.txt``), :func:`online_scene`

1. fuses the person's map from ``upper_noisy`` at its true poses with its own labels (the map
   the robot is given; both arms below use it);
2. runs the **offline chain with true poses** as a :class:`~semmatch.online.RobotSession` with
   the true poses given (the session and the batch verbs share their per-frame steps, so this is
   ``transfer`` + ``reconstruct`` at true poses);
3. runs the **online** session: the first pose from a global alignment of a robot frame into the
   person's map (``align``: :func:`~semmatch.online.align_frame`, retried on later frames while it
   refuses; or ``register``), then frame-to-model tracking against the person's map, predicted
   from the recording's odometry (``poses.txt``) as a wheel-odometry prior (``--no-prior``:
   constant velocity), lost frames void and not fused;
4. scores each robot map by Mean Acc. (:func:`semmatch.evaluate.metrics.compare`, 5 cm grid)
   against the reference fused from the robot's frames' own labels at the poses that arm used
   (as the real-like chain scores its lower maps in their own frame), and the trajectories by ATE
   against the true poses: the online one (rigidly aligned, and as it lies, since it is in the
   person's frame), the offline estimate (:func:`semmatch.experiments.real_poses.cached_odometry`,
   the real-like chain's odometry) and the odometry prior alone.

``python -m semmatch.experiments.online_study SCENE ... --out DIR`` writes ``DIR/<scene>/row.json``
(reused when present) and ``DIR/rows.csv``; docs/online.md has the results.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["online_scene", "online_study", "markdown_table", "main"]

#: initialisers of the online arm (first pose in the person's map; ``first-pose``: the true one, as
#: a robot starting from a known dock)
INITS = ("align", "register", "first-pose")


def _run_arm(session, frames, *, poses=None, priors=None):
    """Replay ``frames`` through ``session`` (every frame); ``(report, poses (N,4,4) NaN where none, CPU s)``."""
    from ..online.replay import replay

    c0 = time.process_time()
    report = replay(session, frames, rate=0, poses=poses, priors=priors)
    cpu = time.process_time() - c0
    P = np.full((len(frames), 4, 4), np.nan)
    for r in report.results:
        if r.pose is not None:
            P[r.index] = r.pose
    return report, P, cpu


def _mean_acc(frames, poses: np.ndarray, robot_map, eval_voxel_size: float, voxel_size: float) -> float:
    """Mean Acc. of ``robot_map`` against the frames' own labels fused at ``poses`` (frames without one left out)."""
    from ..evaluate.metrics import compare
    from ..fusion import reconstruct
    from .synthetic import eval_grid_origin, reference_grid

    keep = np.flatnonzero(np.isfinite(poses).all(axis=(1, 2)))
    reference = reconstruct([frames[int(i)] for i in keep], poses=poses[keep], voxel_size=voxel_size)
    s = compare(reference_grid(reference, eval_voxel_size), robot_map, voxel_size=eval_voxel_size,
                grid_origin=eval_grid_origin(eval_voxel_size))
    return float(s["mean_acc"])


def online_scene(sd: Path, work: Path, *, method: str = "3d-neighborhood", init: str = "align",
                 prior: bool = True, voxel_size: float = 0.04, eval_voxel_size: float = 0.05,
                 pose_dir: Path | None = None, progress: bool = False) -> dict:
    """One scene: the online session against the offline chain with true poses.

    Parameters
    ----------
    sd : path
        Scene folder with ``upper_noisy/`` and ``lower_noisy/`` (each with ``poses_gt.txt``).
    work : path
        Output folder (``row.json``; the odometry cache without ``pose_dir``).
    method : str
        Transfer method.
    init : {"align", "register", "first-pose"}
        The online arm's initialiser.
    prior : bool
        Predict each pose from the recording's odometry (``lower_noisy/poses.txt``).
    voxel_size, eval_voxel_size : float
        The maps' TSDF voxel and the evaluation grid (metres).
    pose_dir : path, optional
        Odometry cache folder shared with the alignment study (``<scene>/lower_noisy.txt``, the
        same :func:`~semmatch.experiments.real_poses.cached_odometry` of the same recording).
    progress : bool

    Returns
    -------
    dict
        scene, frames, ``mean_acc_true`` / ``mean_acc_online`` and their difference, the online
        statuses (``first_posed`` frame, ``lost_frames``, ``tracking_losses``, ``initialising``),
        ``ate_online_m`` (aligned), ``ate_online_abs_m`` (in the person's frame, not aligned),
        ``ate_offline_m``, ``ate_prior_m``, CPU seconds and frames per CPU-second of each arm.

    Raises
    ------
    FileNotFoundError
        A recording or its ``poses_gt.txt`` is missing.
    """
    from ..fusion import reconstruct
    from ..io import read_sequence, read_tum
    from ..online import ModelTracker, RobotSession, align_frame, given_pose, register_frame
    from ..poses.trajectory_metrics import ate
    from ..transfer import MapIndex
    from .real_poses import cached_odometry

    if init not in INITS:
        raise ValueError(f"init must be one of {', '.join(INITS)}, got {init!r}")
    sd, work = Path(sd), Path(work)
    for rec in ("upper_noisy", "lower_noisy"):
        if not (sd / rec / "poses_gt.txt").is_file():
            raise FileNotFoundError(f"{sd / rec / 'poses_gt.txt'}: the scene needs {rec}/ with its true poses")
    work.mkdir(parents=True, exist_ok=True)
    upper, lower = read_sequence(sd / "upper_noisy").load(), read_sequence(sd / "lower_noisy").load()
    true_u, true_l = read_tum(sd / "upper_noisy" / "poses_gt.txt")[1], read_tum(sd / "lower_noisy" / "poses_gt.txt")[1]
    odometry = np.asarray(lower.poses, dtype=np.float64)  # the recording's own drifting estimate
    person = reconstruct(upper, poses=true_u, voxel_size=voxel_size)
    index = MapIndex(person)

    def session(initialiser=None):
        tracker = ModelTracker(person)
        return RobotSession(person, method=method, index=index, voxel_size=voxel_size, initialiser=initialiser,
                            tracker=tracker)

    s_true = session()
    _, P_true, cpu_true = _run_arm(s_true, lower, poses=true_l)
    s_on = session({"align": align_frame, "register": register_frame}.get(init) or given_pose(true_l[0]))
    report, P_on, cpu_on = _run_arm(s_on, lower, priors=odometry if prior else None)
    summ = report.summary(true_l)
    posed = np.isfinite(P_on).all(axis=(1, 2))
    row = {"scene": sd.name, "frames": len(lower), "method": method, "init": init, "prior": prior,
           "mean_acc_true": _mean_acc(lower, P_true, s_true.semantic_map(), eval_voxel_size, voxel_size)}
    try:  # no frame placed, or too few to leave a surface: no map to score
        row["mean_acc_online"] = _mean_acc(lower, P_on, s_on.semantic_map(), eval_voxel_size, voxel_size)
    except ValueError:
        row["mean_acc_online"] = float("nan")
    row["mean_acc_diff"] = row["mean_acc_online"] - row["mean_acc_true"]
    row.update(first_posed=int(np.flatnonzero(posed)[0]) if posed.any() else -1, posed_frames=int(posed.sum()),
               initialising=summ["statuses"].get("initialising", 0), lost_frames=summ["lost_frames"],
               tracking_losses=summ["tracking_losses"], relocalised=summ["statuses"].get("relocalised", 0),
               statuses=json.dumps(summ["statuses"], sort_keys=True))
    nan = float("nan")
    row["ate_online_m"] = summ.get("ate_m", nan)
    row["ate_online_abs_m"] = ate(P_on[posed], true_l[posed], align=False) if posed.sum() >= 3 else nan
    cache = work / "lower_noisy.txt" if pose_dir is None else Path(pose_dir) / sd.name / "lower_noisy.txt"
    cache.parent.mkdir(parents=True, exist_ok=True)
    est = cached_odometry(lower, cache, prior=odometry, progress=progress)
    row["ate_offline_m"] = ate(est, true_l)
    row["ate_prior_m"] = ate(odometry, true_l)
    row.update(cpu_s_true=cpu_true, cpu_s_online=cpu_on, frames_per_cpu_second_online=len(lower) / cpu_on,
               cpu_ms_p95_online=summ["cpu_ms_p95"])
    from ..io import write_json

    write_json(work / "row.json", row)
    return row


def online_study(scene_dirs: Sequence[Path], out: Path, *, progress: bool = False, **settings) -> pd.DataFrame:
    """:func:`online_scene` of each scene, one row each (``out/rows.csv``; a scene's ``row.json`` is reused).

    Parameters
    ----------
    scene_dirs : sequence of path
    out : path
    progress : bool
    **settings
        Passed to :func:`online_scene`.

    Returns
    -------
    DataFrame
    """
    from ..runtime.progress import tqdm

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for sd in tqdm(list(scene_dirs), desc="online study", disable=not progress, unit="scene"):
        cached = out / Path(sd).name / "row.json"
        rows.append(json.loads(cached.read_text()) if cached.is_file()
                    else online_scene(Path(sd), out / Path(sd).name, progress=False, **settings))
        pd.DataFrame(rows).to_csv(out / "rows.csv", index=False)
    return pd.DataFrame(rows)


def markdown_table(df: pd.DataFrame) -> str:
    """The study's rows as the Markdown table of docs/online.md, with the mean of the scenes.

    Parameters
    ----------
    df : DataFrame
        Rows of :func:`online_study`.

    Returns
    -------
    str
    """
    cm = lambda v: "-" if not np.isfinite(v) else f"{v * 100:.2f}"  # noqa: E731
    lines = ["| scene | Mean Acc. true poses | online | difference | first posed frame | lost frames (losses) "
             "| ATE online, aligned / as placed (cm) | ATE offline estimate (cm) | ATE odometry prior (cm) "
             "| online frames per CPU-s |", "|" + "---|" * 10]
    for r in df.itertuples():
        lines.append(f"| {r.scene} | {r.mean_acc_true:.3f} | {r.mean_acc_online:.3f} | {r.mean_acc_diff:+.3f} "
                     f"| {r.first_posed} | {r.lost_frames} ({r.tracking_losses}) "
                     f"| {cm(r.ate_online_m)} / {cm(r.ate_online_abs_m)} | {cm(r.ate_offline_m)} "
                     f"| {cm(r.ate_prior_m)} | {r.frames_per_cpu_second_online:.1f} |")
    m = df.mean(numeric_only=True)
    lines.append(f"| mean of {len(df)} | {m.mean_acc_true:.3f} | {m.mean_acc_online:.3f} | {m.mean_acc_diff:+.3f} "
                 f"| | {df.lost_frames.sum()} ({df.tracking_losses.sum()}) | {cm(m.ate_online_m)} / "
                 f"{cm(m.ate_online_abs_m)} | {cm(m.ate_offline_m)} | {cm(m.ate_prior_m)} "
                 f"| {m.frames_per_cpu_second_online:.1f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m semmatch.experiments.online_study SCENE ... --out DIR``: run the study, print its table."""
    p = argparse.ArgumentParser(prog="python -m semmatch.experiments.online_study", description=__doc__.split("\n")[0])
    p.add_argument("scenes", nargs="+", help="scene folders (with upper_noisy/ and lower_noisy/)")
    p.add_argument("--out", required=True, help="work folder (rows.csv, <scene>/row.json)")
    p.add_argument("--method", default="3d-neighborhood", help="transfer method (default: %(default)s)")
    p.add_argument("--init", default="align", choices=INITS, help="first pose of the online arm (default: %(default)s)")
    p.add_argument("--poses", default=None, help="odometry cache folder (<scene>/lower_noisy.txt, as the alignment "
                   "study's --poses); default: in each scene's work folder")
    p.add_argument("--no-prior", dest="prior", action="store_false",
                   help="track without the recording's odometry as prior (constant velocity)")
    args = p.parse_args(argv)
    df = online_study([Path(s) for s in args.scenes], Path(args.out), method=args.method, init=args.init,
                      prior=args.prior, pose_dir=args.poses, progress=True)
    print(markdown_table(df))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
