"""A person and a robot: the robot's recording placed in the person's map, measured (issue 51).

Two studies of :func:`semmatch.poses.alignment.align_to_map`, each recording posed by its own
odometry from the identity (no ground truth enters the chain; it only scores):

- **real** (:func:`kitchen_study`): the development frames of the 7-Scenes red kitchen split
  into two sessions, frames 0-249 ("person") and 250-499 ("robot"), each tracked by
  :func:`semmatch.poses.odometry.estimate_poses` (hybrid residual, chained, no pose graph: the
  better trajectory on these frames, docs/recordings.md) and fused; the robot's map aligned
  into the person's; the alignment's error against the 7-Scenes poses, and the share of the
  robot session's pixels that land within 5 cm of the person's map;
- **two heights** (:func:`two_height_study`): simulated scenes, the person's (1.6 m) and the
  robot's (0.2 m) noisy recordings tracked as the real-like chain tracks them
  (:func:`semmatch.experiments.real_poses.cached_odometry`: seeded by their own drifting
  odometry), aligned, labels transferred and fused
  (:func:`semmatch.experiments.real.chain_from_poses`), against the same chain at true poses.

The refusal thresholds of :data:`semmatch.poses.alignment.DEFAULT_CHECKS` are chosen on
validation scenes (:func:`simulate_validation_pairs`, seeds of ``val_seeds``) and the kitchen's
development frames, never on the evaluation scenes. ``python -m semmatch.experiments.alignment_study
--help`` runs each part; docs/recordings.md ("A person and a robot") has the results.

Size: over 600 lines because the two studies, the validation run and their command line share
the posing, alignment and scoring helpers of one chain; splitting the validation run off
(``alignment_thresholds`` holds its rule already) is the natural next cut.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from ..io import read_tum, write_json, write_tum

__all__ = [
    "session_poses",
    "simulate_validation_pairs",
    "kitchen_study",
    "two_height_scene",
    "two_height_study",
    "pixels_near_map",
    "alignment_figure",
    "validation_seed_check",
    "validate_thresholds",
    "choose_on_rows",
    "main",
]

#: the kitchen's two sessions (development frames only: 500-999 are held out), every second frame
#: (the shared 2-core machine's budget; 15 frames a second of a hand-held Kinect)
KITCHEN_SESSIONS = {"person": slice(0, 250, 2), "robot": slice(250, 500, 2)}


def session_poses(seq, cache: Path, *, pose_graph: bool = False, downsample: int = 1,
                  progress: bool = True) -> tuple[np.ndarray, float]:
    """A recording's poses by its own RGB-D odometry from the identity, cached as TUM in ``cache``.

    Parameters
    ----------
    seq : sequence of Frame
        E.g. a :class:`~semmatch.io.recordings.SevenScenesSequence`.
    cache : path
        TUM file (written atomically); ``cache.with_suffix(".json")`` keeps the settings and the
        odometry's wall time. A cache of other settings or another frame count is recomputed.
    pose_graph, downsample, progress
        As :func:`semmatch.poses.odometry.estimate_poses` (hybrid residual, its default).

    Returns
    -------
    poses : ndarray (N, 4, 4)
        ``poses[0]`` is the identity.
    seconds : float
        Wall time of the odometry (of the run that wrote the cache).
    """
    from ..poses.odometry import estimate_poses

    cache = Path(cache)
    info_file = cache.with_suffix(".json")
    settings = {"pose_graph": bool(pose_graph), "downsample": int(downsample), "frames": len(seq)}
    if cache.is_file() and info_file.is_file():
        info = json.loads(info_file.read_text())
        if info.get("settings") == settings:
            return read_tum(cache)[1], float(info["seconds"])
    t0 = time.perf_counter()
    est = estimate_poses(seq, init_pose=np.eye(4), pose_graph=pose_graph, downsample=downsample, progress=progress)
    seconds = time.perf_counter() - t0
    write_tum(cache, np.asarray(getattr(seq, "timestamps", np.arange(len(est))), dtype=np.float64), est)
    write_json(info_file, {"settings": settings, "seconds": seconds})
    return read_tum(cache)[1], seconds


def simulate_validation_pairs(out: Path, seeds: Sequence[int], *, params: dict | None = None,
                              progress: bool = False) -> list[Path]:
    """Validation scenes for choosing the refusal thresholds: noisy person/robot pairs of ``val_seeds``.

    Seed ``s`` gives one scene of kind ``kinds[s % len(kinds)]`` (as the pipeline's validation
    split does); its person's (1.6 m) and robot's (0.2 m) tours rendered with the full
    profile's image size, frame count, camera step and Kinect-like noise (``poses.txt`` a
    drifting simulated odometry, ``poses_gt.txt`` the truth) into ``out/<scene>/upper_noisy`` and
    ``lower_noisy`` (the layout of the pipeline's scenes). Complete scenes are skipped.

    Parameters
    ----------
    out : path
    seeds : sequence of int
        Validation seeds (``val_seeds`` of params.yaml); never evaluation seeds.
    params : dict, optional
        A profile of params.yaml (:func:`semmatch.experiments.pipeline.load_params`; default ``full``).
    progress : bool

    Returns
    -------
    list of Path
        The scene folders.
    """
    from ..io.geometry import DEFAULT_INTRINSICS
    from ..sim import generate_scene
    from ..sim.noise import NoiseConfig
    from ..sim.simulate import simulate_pair
    from .pipeline import load_params

    p = params or load_params(profile="full")
    common, sim = p["common"], p["simulate"]
    bad = sorted(set(int(s) for s in seeds) - set(int(s) for s in common["val_seeds"]))
    if bad:
        raise ValueError(f"seeds {bad} are not validation seeds ({common['val_seeds']}); thresholds are "
                         "chosen on validation scenes only")
    kinds = list(common["kinds"])
    intrinsics = DEFAULT_INTRINSICS.scaled(sim["image_width"], sim["image_height"])
    dirs = []
    for s in seeds:
        scene = generate_scene(kinds[int(s) % len(kinds)], int(s))
        sdir = Path(out) / scene.name
        dirs.append(sdir)
        if all((sdir / n / "poses_gt.txt").is_file() for n in ("upper_noisy", "lower_noisy")):
            continue
        tmp = sdir / ".pair"
        simulate_pair(scene, tmp, n_frames=int(sim["n_frames_upper"]), seed=int(s), intrinsics=intrinsics,
                      noise=NoiseConfig.from_dict(sim["noise"]), overwrite=True, progress=progress,
                      camera_step=float(sim["camera_step"]))
        scene.save(sdir / "scene.ply")
        for n in ("upper", "lower"):
            (tmp / n).rename(sdir / f"{n}_noisy")
        tmp.rmdir()
    return dirs


def pixels_near_map(seq, poses: np.ndarray, target, *, distance: float = 0.05, stride: int = 4,
                    frame_step: int = 5, depth_max: float = 4.0) -> float:
    """Share of a recording's depth pixels that land within ``distance`` of a map at the given poses.

    Every ``frame_step``-th frame, every ``stride``-th pixel with depth in (0, ``depth_max``].

    Parameters
    ----------
    seq : sequence of Frame
    poses : ndarray (N, 4, 4)
        The frames' poses in the map's frame.
    target : SemanticMap
    distance, stride, frame_step, depth_max : float, int, int, float

    Returns
    -------
    float
    """
    from scipy.spatial import cKDTree

    tree = cKDTree(np.asarray(target.points, dtype=np.float64))
    near = total = 0
    for i in range(0, len(seq), int(frame_step)):
        f = seq[i]
        d = f.depth[::stride, ::stride]
        v, u = np.nonzero((d > 0) & (d <= depth_max))
        z = d[v, u].astype(np.float64)
        K = f.intrinsics
        cam = np.c_[(stride * u - K.cx) * z / K.fx, (stride * v - K.cy) * z / K.fy, z]
        P = cam @ poses[i][:3, :3].T + poses[i][:3, 3]
        dist = tree.query(P, k=1, distance_upper_bound=distance)[0]
        near += int(np.isfinite(dist).sum())
        total += len(P)
    return near / total if total else float("nan")


def _timed(fn, *args, **kwargs):
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


def kitchen_study(data: str | Path, out: str | Path, *, progress: bool = False, **settings) -> dict:
    """The real pair: the kitchen's two development sessions, the second aligned into the first's map.

    Parameters
    ----------
    data : path
        The 7-Scenes red-kitchen folder (``scripts/fetch_7scenes_kitchen.sh``); only frames 0-499 are read.
    out : path
        Work folder: the sessions' poses (cached), the person's map, ``kitchen.json``.
    progress : bool
    **settings
        Passed to :func:`semmatch.poses.alignment.align_to_map`.

    Returns
    -------
    dict
        Alignment report, its errors against the 7-Scenes poses (``trans_err_m``, ``rot_err_deg``:
        each session's map fitted onto both sessions fused at the true poses;
        ``trajectory_truth_*``: each trajectory aligned onto the true one; ``first_frame_*``: the
        sessions' first true poses), the share of the robot's pixels within 5 cm of the person's map (aligned and
        at the true poses), each session's ATE, wall seconds per step.
    """
    from ..fusion import extract, fuse_sequence
    from ..io import write_map
    from ..io.recordings import SevenScenesSequence
    from ..poses.alignment import align_recording, camera_up
    from ..poses.registration import transform_error
    from ..poses.trajectory_metrics import trajectory_errors
    from .real_poses import registration_errors, world_alignment

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    seqs = {n: SevenScenesSequence(data, frames=sl) for n, sl in KITCHEN_SESSIONS.items()}
    est, seconds = {}, {}
    for n, seq in seqs.items():
        est[n], seconds[f"odometry_{n}"] = session_poses(seq, out / f"{n}_poses.txt", downsample=2, progress=progress)
    true = {n: seqs[n].poses for n in seqs}
    vol, seconds["person_map"] = _timed(fuse_sequence, seqs["person"], poses=est["person"], voxel_size=0.04,
                                        progress=progress)
    person_map = extract(vol, "mesh")
    write_map(out / "person_map.ply", person_map)
    (result, aligned, robot_map), seconds["align"] = _timed(
        align_recording, seqs["robot"], est["robot"], person_map, person_up=camera_up(est["person"]),
        progress=progress, **settings)
    # the truth: each session's map fitted onto the map of both sessions fused at the 7-Scenes poses
    # (where the maps lie; a trajectory alignment alone leaves the rotation of a short, straight
    # session uncertain); the trajectory alignment's errors are reported beside
    both = (f for n in seqs for f in seqs[n])  # the frames at their 7-Scenes poses
    truth_map = extract(fuse_sequence(both, voxel_size=0.04, progress=progress), "mesh")
    maps = {"person": person_map, "robot": robot_map}
    A = {n: world_alignment(est[n], true[n], reconstruction=maps[n], scene_mesh=truth_map) for n in seqs}
    err = registration_errors(result.transform, A["person"], A["robot"], est["robot"], true["robot"])
    A_traj = {n: world_alignment(est[n], true[n]) for n in seqs}
    err_traj = registration_errors(result.transform, A_traj["person"], A_traj["robot"], est["robot"], true["robot"])
    first_t, first_r = transform_error(result.transform, np.linalg.inv(true["person"][0]) @ true["robot"][0])
    true_in_person = np.linalg.inv(A["person"]) @ true["robot"]
    maps_fit = {n: transform_error(A[n], A_traj[n]) for n in seqs}
    report = {
        "sessions": {n: [sl.start, sl.stop, sl.step] for n, sl in KITCHEN_SESSIONS.items()},
        "alignment": result.as_dict(),
        "trans_err_m": err["trans_err_m"], "rot_err_deg": err["rot_err_deg"],
        "robot_cameras_rmse_m": err["lower_in_upper_rmse_m"],
        "trajectory_truth_trans_err_m": err_traj["trans_err_m"], "trajectory_truth_rot_err_deg": err_traj["rot_err_deg"],
        "first_frame_trans_err_m": first_t, "first_frame_rot_err_deg": first_r,
        "pixels_within_5cm": pixels_near_map(seqs["robot"], aligned, person_map),
        "pixels_within_5cm_true_poses": pixels_near_map(seqs["robot"], true_in_person, person_map),
        "ate": {n: trajectory_errors(est[n], true[n]) for n in seqs},
        "map_vs_trajectory_truth": {n: list(v) for n, v in maps_fit.items()},
        "seconds": seconds,
    }
    write_json(out / "kitchen.json", report)
    return report


def two_height_scene(sd: Path, pose_dir: Path, work: Path, *, methods: Sequence[str] = ("3d-neighborhood",),
                     chain: bool = True, person_scene: Path | None = None, network: str | None = None,
                     progress: bool = False, **settings) -> dict:
    """One scene of :func:`two_height_study`: alignment, its error, and the chain's Mean Acc. (estimated and true poses).

    With ``person_scene`` (another scene) the robot of ``sd`` is aligned into that scene's
    person's map: a wrong pair, which :func:`~semmatch.poses.alignment.align_to_map` must refuse
    (no errors, no chain). With ``network`` (a shipped network of ``models/full``, e.g.
    ``compact``) the chain also runs the real-like chain's network rows: the network's own labels
    of the robot's frames (``lower``), each method from the network's person's map, and
    ``fused`` (``methods[0]``'s label where the map has one, the robot's own network's elsewhere;
    :func:`semmatch.transfer.write_fused_labels`); the network runs once per recording, its
    labels shared by both arms.

    Returns
    -------
    dict
        scene, the alignment report's numbers, ``trans_err_m`` / ``rot_err_deg`` (against the
        trajectory-aligned truth), ``trans_err_mesh_m`` / ``rot_err_mesh_deg`` (each map fitted onto
        the scene's mesh; NaN without ``scene.ply``), and with ``chain`` per method ``mean_acc:METHOD`` at the
        aligned estimated poses and ``mean_acc_true:METHOD`` at the true poses (from the ground-truth
        labelled person's map), with ``network`` also ``mean_acc:NETWORK:METHOD`` (``lower``, the
        methods, ``fused``) and their ``mean_acc_true`` twins.
    """
    from ..fusion import reconstruct_many
    from ..io import read_sequence
    from ..poses.alignment import align_recording
    from .layout import GT, model_name
    from .real import chain_from_poses
    from .real_poses import PosedSequence, cached_odometry, registration_errors, world_alignment

    work.mkdir(parents=True, exist_ok=True)
    seqs, est, true = {}, {}, {}
    for n, d in (("upper", Path(person_scene or sd)), ("lower", sd)):
        seqs[n] = read_sequence(d / f"{n}_noisy").load()
        (pose_dir / d.name).mkdir(parents=True, exist_ok=True)
        est[n] = cached_odometry(seqs[n], pose_dir / d.name / f"{n}_noisy.txt", prior=seqs[n].poses, progress=progress)
        true[n] = read_tum(d / f"{n}_noisy" / "poses_gt.txt")[1]
    t0 = time.perf_counter()
    (person_map,) = reconstruct_many(PosedSequence(seqs["upper"], est["upper"]), [None], 0.04)
    result, _, robot_map = align_recording(seqs["lower"], est["lower"], person_map, person_up="auto", **settings)
    seconds = time.perf_counter() - t0
    A = {n: world_alignment(est[n], true[n]) for n in seqs}
    err = registration_errors(result.transform, A["upper"], A["lower"], est["lower"], true["lower"])
    # the truth where the maps lie: each map fitted onto the scene's mesh (as the real-like chain's report)
    err_mesh = {"trans_err_m": float("nan"), "rot_err_deg": float("nan")}
    if person_scene is None and (sd / "scene.ply").is_file():
        from ..io import read_map

        mesh, maps = read_map(sd / "scene.ply"), {"upper": person_map, "lower": robot_map}
        A_mesh = {n: world_alignment(est[n], true[n], reconstruction=maps[n], scene_mesh=mesh) for n in seqs}
        err_mesh = registration_errors(result.transform, A_mesh["upper"], A_mesh["lower"], est["lower"], true["lower"])
    if person_scene is not None:
        err, chain = {"trans_err_m": float("nan"), "rot_err_deg": float("nan")}, False
    row = {"scene": sd.name, "person": Path(person_scene or sd).name, "accepted": result.accepted, "constrained": result.constrained,
           "trans_err_m": err["trans_err_m"], "rot_err_deg": err["rot_err_deg"],
           "trans_err_mesh_m": err_mesh["trans_err_m"], "rot_err_mesh_deg": err_mesh["rot_err_deg"],
           **{k: v for k, v in result.as_dict().items() if isinstance(v, float | int | bool) and k != "accepted"},
           "floor_angle_deg": result.floor_angle_deg, "floor_offset_m": result.floor_offset_m,
           "failures": "; ".join(result.failures()), "align_seconds": seconds}
    if chain:
        models, sources, predicted = {}, (GT,), {}
        if network is not None:
            from ..segment.shipping import load_shipped_network
            from .pipeline import ROOT

            models, sources = {network: load_shipped_network(ROOT / "models" / "full", network)}, (GT, network)
        o = dict(voxel_size=0.04, eval_voxel_size=0.05, tol=None, fused_base=None if network is None else methods[0],
                 registration_voxel=0.1, registration_seed=0, registration_restarts=4, frame_jobs=1,
                 world_truth="traj")
        for arm, poses, T in (("", est, result.transform), ("_true", true, np.eye(4))):
            posed = {n: PosedSequence(seqs[n], poses[n]) for n in seqs}
            arm_work = work / f"chain{arm or '_est'}"
            rows, _ = chain_from_poses(sd, arm_work, posed, poses, true, models, methods, sources, o, transform=T,
                                       predicted=predicted)
            if network is not None and not predicted:  # labels do not depend on poses: the network runs once
                predicted = {("upper", network): arm_work / f"upper_labels_{network}",
                             ("lower", network): arm_work / f"lower_labels_{network}" / "lower"}
            for r in rows:
                if r["method"] != "upper":  # the person's own map: no alignment in it
                    key = r["method"] if r["model"] == model_name(GT) else f"{r['model']}:{r['method']}"
                    row[f"mean_acc{arm}:{key}"] = float(r["mean_acc"])
    write_json(work / "row.json", row)
    return row


def two_height_study(scene_dirs: Sequence[Path], pose_dir: Path, out: Path, *, chain: bool = True,
                     wrong_pairs: bool = False, network: str | None = None, progress: bool = False,
                     **settings) -> pd.DataFrame:
    """The two-height pairs of ``scene_dirs`` (:func:`two_height_scene` each), one row per pair (``rows.csv``).

    Parameters
    ----------
    scene_dirs : sequence of path
        Scene folders with ``upper_noisy/`` and ``lower_noisy/``.
    pose_dir : path
        Cache of the recordings' odometry (``<scene>/<recording>.txt``).
    out : path
    chain : bool
        Also transfer and fuse (Mean Acc. at estimated and at true poses; right pairs only).
    wrong_pairs : bool
        Also align each scene's robot into the next scene's person's map (the last one's into the
        first one's): pairs of two different rooms, which must be refused.
    network : str, optional
        Also the network rows and ``fused`` (:func:`two_height_scene`).
    progress : bool
    **settings
        Passed to :func:`semmatch.poses.alignment.align_to_map` (e.g. ``checks``).
    """
    from ..io import atomic_write_text

    out, scene_dirs = Path(out), [Path(sd) for sd in scene_dirs]
    pairs = [(sd, None) for sd in scene_dirs]
    if wrong_pairs:
        if len(scene_dirs) < 2:
            raise ValueError("wrong pairs need at least two scenes")
        pairs += [(sd, scene_dirs[(k + 1) % len(scene_dirs)]) for k, sd in enumerate(scene_dirs)]
    rows = []
    for sd, person in tqdm(pairs, desc="alignment pairs", disable=not progress):
        work = out / (sd.name if person is None else f"{sd.name}_into_{person.name}")
        cached = work / "row.json"
        if cached.is_file():
            rows.append(json.loads(cached.read_text()))
            continue
        rows.append(two_height_scene(sd, Path(pose_dir), work, chain=chain and person is None, person_scene=person,
                                     network=network, **settings))
        atomic_write_text(out / "rows.csv", pd.DataFrame(rows).to_csv(index=False))
    df = pd.DataFrame(rows)
    atomic_write_text(out / "rows.csv", df.to_csv(index=False))
    return df


def validation_seed_check(scene_dirs: Sequence[Path]) -> None:
    """Refuse scenes that are not validation scenes (the seed ending the folder's name, or its ``scene.json``'s).

    Raises
    ------
    ValueError
        A scene whose seed is not among the full profile's ``val_seeds``, or has none.
    """
    from .pipeline import load_params

    val = {int(s) for s in load_params(profile="full")["common"]["val_seeds"]}
    for sd in scene_dirs:
        info = Path(sd) / "scene.json"
        seed = json.loads(info.read_text()).get("seed") if info.is_file() else None
        if seed is None:
            tail = Path(sd).name.rsplit("_", 1)[-1]
            seed = int(tail) if tail.isdigit() else None
        if seed is None or int(seed) not in val:
            raise ValueError(f"{sd}: seed {seed} is not a validation seed ({sorted(val)}); the refusal thresholds "
                             "are chosen on validation scenes only")


def validate_thresholds(scene_dirs: Sequence[Path], pose_dir: Path, out: Path, *, figures: str | Path | None = None,
                        truth: str = "mesh", progress: bool = True) -> dict:
    """Choose the refusal thresholds on validation scenes (:mod:`semmatch.experiments.alignment_thresholds`).

    Every scene's robot aligned into its own person's map and into the next scene's
    (:func:`two_height_study` with ``wrong_pairs``, alignment only, under the current
    :data:`~semmatch.poses.alignment.DEFAULT_CHECKS`), then the rule of
    :func:`~semmatch.experiments.alignment_thresholds.choose_thresholds`.

    Parameters
    ----------
    scene_dirs : sequence of path
        Validation scenes (``upper_noisy/``, ``lower_noisy/``, ``scene.ply``; seeds of ``val_seeds``).
    pose_dir, out : path
        Odometry cache; work folder (``rows.csv``, ``thresholds.json``).
    figures : path, optional
        Also ``alignment_validation.csv``/``.md`` (one row per pair, with its label and its verdict
        under the default and the chosen thresholds) and ``alignment_validation.png`` there.
    truth : {"mesh", "trajectory"}
        The errors that label right pairs (:func:`~semmatch.experiments.alignment_thresholds.must_refuse`):
        the mesh fit (the rule's), or the trajectory truth for pairs stored without a mesh fit.
    progress : bool

    Returns
    -------
    dict
        ``thresholds`` (chosen), ``defaults``, ``steps`` (the rule's steps), ``under_defaults`` and
        ``under_chosen`` (pairs that must be refused but were accepted, good pairs refused), as
        written to ``thresholds.json``.
    """
    validation_seed_check(scene_dirs)
    rows = two_height_study(scene_dirs, pose_dir, out, chain=False, wrong_pairs=True, progress=progress)
    return choose_on_rows(rows, Path(out) / "thresholds.json", figures=figures, truth=truth)


def choose_on_rows(rows: pd.DataFrame, report_file: Path, *, figures: str | Path | None = None,
                   truth: str = "mesh") -> dict:
    """The rule of :mod:`semmatch.experiments.alignment_thresholds` on stored validation pairs.

    Parameters
    ----------
    rows : DataFrame
        Pairs of :func:`two_height_study` runs with ``wrong_pairs`` (validation scenes only).
    report_file : path
        ``thresholds.json`` to write.
    figures, truth
        As :func:`validate_thresholds`.

    Returns
    -------
    dict
        As :func:`validate_thresholds`.
    """
    from ..poses.alignment import DEFAULT_CHECKS
    from .alignment_thresholds import choose_thresholds, judge_rows, must_refuse, threshold_figure
    from .tables import save_table

    chosen, steps = choose_thresholds(rows, truth=truth)
    refuse = must_refuse(rows, truth=truth)

    def counts(th):
        acc = judge_rows(rows, th)
        return {"bad_accepted": int((acc & refuse).sum()), "good_refused": int((~acc & ~refuse).sum()),
                "pairs": len(rows), "must_refuse": int(refuse.sum())}

    scenes = sorted(set(rows["scene"]))
    report = {"thresholds": chosen, "defaults": dict(DEFAULT_CHECKS), "steps": steps, "truth": truth,
              "under_defaults": counts(DEFAULT_CHECKS), "under_chosen": counts(chosen), "scenes": scenes}
    write_json(Path(report_file), report)
    if figures is not None:
        cols = ["scene", "person", "trans_err_m", "rot_err_deg", "trans_err_mesh_m", "rot_err_mesh_deg",
                "structure_fitness", "agreement", "inlier_rmse", "floor_angle_deg", "floor_offset_m", "constrained"]
        table = rows.reindex(columns=cols).copy()
        table.insert(2, "must_refuse", refuse)
        table["accepted_defaults"] = judge_rows(rows, DEFAULT_CHECKS)
        table["accepted_chosen"] = judge_rows(rows, chosen)
        save_table(table, figures, "alignment_validation", floatfmt=".4f")
        threshold_figure(rows, chosen, Path(figures) / "alignment_validation.png", truth=truth,
                         title=f"validation pairs ({len(scenes)} scenes, {truth} truth): structure_fitness")
    return report


def alignment_figure(rows: pd.DataFrame, out: str | Path, *, kitchen: dict | None = None,
                     max_trans_m: float = 0.05, max_rot_deg: float = 2.0) -> Path:
    """Alignment errors per pair (translation against rotation), accepted and refused, with the target box.

    Parameters
    ----------
    rows : DataFrame
        :func:`two_height_study`'s rows (``scene``, ``person``, ``accepted``, ``trans_err_m``,
        ``rot_err_deg``, and ``trans_err_mesh_m`` / ``rot_err_mesh_deg`` used instead where
        present); wrong pairs (``person`` differs from ``scene``) are left out.
    out : path
        PNG (written atomically).
    kitchen : dict, optional
        :func:`kitchen_study`'s report, drawn as a star.
    max_trans_m, max_rot_deg : float
        The target (a dashed box).

    Returns
    -------
    Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import save_figure

    fig, ax = plt.subplots(figsize=(4.6, 3.4))
    right = rows[rows.get("person", rows["scene"]) == rows["scene"]].copy() if len(rows) else rows
    if "trans_err_mesh_m" in right:  # the mesh-fit truth where it was measured
        mesh = right["trans_err_mesh_m"].notna()
        right.loc[mesh, "trans_err_m"] = right.loc[mesh, "trans_err_mesh_m"]
        right.loc[mesh, "rot_err_deg"] = right.loc[mesh, "rot_err_mesh_deg"]
    for acc, marker, label in ((True, "o", "accepted"), (False, "x", "refused")):
        r = right[right["accepted"] == acc] if len(right) else right
        if len(r):
            ax.scatter(100 * r["trans_err_m"].clip(upper=1.0), r["rot_err_deg"].clip(upper=20), marker=marker,
                       label=f"two heights, {label} ({len(r)})")
    if kitchen is not None:
        ax.scatter([100 * kitchen["trans_err_m"]], [kitchen["rot_err_deg"]], marker="*", s=160, color="k",
                   label="real kitchen (accepted)" if kitchen["alignment"]["accepted"] else "real kitchen (refused)")
    ax.plot([0, 100 * max_trans_m, 100 * max_trans_m], [max_rot_deg, max_rot_deg, 0], "k--", lw=0.8,
            label=f"target ({100 * max_trans_m:g} cm, {max_rot_deg:g} deg)")
    ax.set_xlabel("translation error (cm)")
    ax.set_ylabel("rotation error (degrees)")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    return save_figure(fig, out)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m semmatch.experiments.alignment_study {kitchen,two-heights,validate,choose,figure,simulate-val}``."""
    p = argparse.ArgumentParser(prog="python -m semmatch.experiments.alignment_study", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="what", required=True)
    k = sub.add_parser("kitchen", help="the real pair (7-Scenes red kitchen, development frames)")
    k.add_argument("data", help="the kitchen folder (scripts/fetch_7scenes_kitchen.sh)")
    k.add_argument("--out", required=True, help="work folder")
    t = sub.add_parser("two-heights", help="person (1.6 m) and robot (0.2 m) noisy recordings of simulated scenes")
    t.add_argument("scenes", nargs="+", help="scene folders (with upper_noisy/, lower_noisy/)")
    t.add_argument("--poses", required=True, help="odometry cache folder")
    t.add_argument("--out", required=True, help="work folder (rows.csv)")
    t.add_argument("--no-chain", dest="chain", action="store_false", help="alignment only (no transfer, no Mean Acc.)")
    t.add_argument("--checks", help="thresholds.json of a validate run (default: DEFAULT_CHECKS)")
    t.add_argument("--network", help="also the shipped network's rows and fused (e.g. compact)")
    c = sub.add_parser("validate", help="choose the refusal thresholds on validation scenes: right and wrong pairs, "
                                        "the rule of semmatch.experiments.alignment_thresholds")
    c.add_argument("scenes", nargs="+", help="validation scene folders (seeds of val_seeds only)")
    c.add_argument("--poses", required=True, help="odometry cache folder")
    c.add_argument("--out", required=True, help="work folder (rows.csv, thresholds.json)")
    c.add_argument("--figures", help="also write alignment_validation.csv/.md and .png there")
    c.add_argument("--truth", choices=("mesh", "trajectory", "mesh-or-trajectory"), default="mesh",
                   help="errors that label right pairs: the mesh fit (the rule's) or the trajectory truth "
                        "(pairs stored without a mesh fit)")
    h = sub.add_parser("choose", help="the threshold rule on stored validation pairs (work folders of validate runs)")
    h.add_argument("work", nargs="+", help="validate work folders (their <pair>/row.json)")
    h.add_argument("--out", required=True, help="thresholds.json to write")
    h.add_argument("--figures", help="also write alignment_validation.csv/.md and .png there")
    h.add_argument("--truth", choices=("mesh", "trajectory", "mesh-or-trajectory"), default="mesh",
                   help="errors that label right pairs (mesh-or-trajectory: the mesh fit where a pair has one)")
    f = sub.add_parser("figure", help="the figure of docs/recordings.md from the studies' outputs")
    f.add_argument("rows", nargs="+", help="rows.csv of two-heights runs")
    f.add_argument("--kitchen", help="kitchen.json")
    f.add_argument("--out", required=True, help="PNG")
    v = sub.add_parser("simulate-val", help="validation pairs for the thresholds")
    v.add_argument("--out", required=True, help="folder of the scenes")
    v.add_argument("--seeds", type=int, nargs="+", default=[501, 502, 503, 504], help="validation seeds")
    args = p.parse_args(argv)
    if args.what == "kitchen":
        print(json.dumps(kitchen_study(args.data, args.out, progress=True), indent=2))
    elif args.what == "two-heights":
        checks = None
        if args.checks:
            checks = json.loads(Path(args.checks).read_text())
            checks = checks.get("thresholds", checks)
        df = two_height_study([Path(s) for s in args.scenes], Path(args.poses), Path(args.out), chain=args.chain,
                              network=args.network, progress=True, checks=checks)
        print(df.to_string())
    elif args.what == "validate":
        report = validate_thresholds([Path(s) for s in args.scenes], Path(args.poses), Path(args.out),
                                     figures=args.figures, truth=args.truth)
        print(json.dumps({k: report[k] for k in ("thresholds", "defaults", "under_defaults", "under_chosen")},
                         indent=2))
    elif args.what == "choose":
        rows = pd.DataFrame([json.loads(f.read_text()) for w in args.work for f in sorted(Path(w).glob("*/row.json"))])
        validation_seed_check([Path(s) for s in sorted(set(rows["scene"]) | set(rows["person"]))])  # seeds by name
        report = choose_on_rows(rows, Path(args.out), figures=args.figures, truth=args.truth)
        print(json.dumps({k: report[k] for k in ("thresholds", "under_defaults", "under_chosen")}, indent=2))
    elif args.what == "figure":
        rows = pd.concat([pd.read_csv(r) for r in args.rows], ignore_index=True)
        kitchen = json.loads(Path(args.kitchen).read_text()) if args.kitchen else None
        print(alignment_figure(rows, args.out, kitchen=kitchen))
    else:
        print("\n".join(str(d) for d in simulate_validation_pairs(Path(args.out), args.seeds)))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
