"""``semmatch align ROBOT --to PERSON_MAP --out POSES.txt``: the robot's poses in the person's map."""

from __future__ import annotations

import argparse

import numpy as np


def add_alignment_flags(p: argparse.ArgumentParser) -> None:
    """The flags of the alignment, shared by ``align`` and ``transfer --align``."""
    p.add_argument("--person-up", default="auto", metavar="auto|none|X,Y,Z",
                   help="up direction of the person's map: auto (from its floor-labelled points), none (no floor "
                        "constraint) or a vector, e.g. 0,0,1")
    from semmatch.cli.common import number

    p.add_argument("--align-voxel", type=number(float, lo=0.0, lo_open=True), default=0.1,
                   help="feature voxel of the global search in metres")
    p.add_argument("--map-voxel", type=number(float, lo=0.0, lo_open=True), default=0.04,
                   help="TSDF voxel of the robot's map in metres")
    p.add_argument("--align-seed", type=number(int, lo=0), default=0, help="seed of the global search's first restart")
    p.add_argument("--restarts", type=number(int, lo=1), default=4, help="global search restarts")
    p.add_argument("--accept-weak-alignment", action="store_true",
                   help="use an alignment that fails its checks (every output's metadata says so)")


def register(sub) -> None:
    """Add ``semmatch align``."""
    from semmatch.cli.common import add_output_flags, add_recording_options
    from semmatch.io.outputs import declare_paths

    p = sub.add_parser(
        "align",
        help="place a robot's recording in a person's map (its poses in the map's frame, TUM)",
        description="Fuse the robot's recording on its own poses, register that map into the person's map "
        "(floor-constrained global search + coarse-to-fine ICP), check the alignment and write the robot's "
        "poses in the person's frame (TUM; the report beside it as POSES.txt.json). An alignment below the "
        "checks of docs/recordings.md is refused (exit 2, nothing written) unless --accept-weak-alignment.",
    )
    p.add_argument("robot", metavar="ROBOT",
                   help="the robot's recording (any layout semmatch reads: sequence, TUM RGB-D, 7-Scenes, plain "
                        "folder, ROS bag)")
    p.add_argument("--to", required=True, metavar="PERSON_MAP", help="the person's map (PLY)")
    p.add_argument("--out", required=True, metavar="POSES.txt", help="the robot's poses in the person's frame (TUM)")
    add_alignment_flags(p)
    add_recording_options(p, estimate_help="ignore the robot's recorded poses and estimate them by RGB-D odometry "
                                           "(cached in the user cache folder, keyed by the frames and the settings)")
    add_output_flags(p, json_what="the alignment report", quiet="the progress bars")
    declare_paths(p, inputs=("robot", "to", "intrinsics"), outputs=("out",))
    p.set_defaults(func=run)


def person_up(value: str):
    """The ``--person-up`` value: ``"auto"``, None or a unit 3-vector."""
    if value in ("auto", "none"):
        return None if value == "none" else "auto"
    try:
        v = np.array([float(x) for x in value.split(",")])
    except ValueError:
        v = np.zeros(0)
    if v.shape != (3,) or not np.isfinite(v).all() or not np.linalg.norm(v) > 0:
        raise ValueError(f"--person-up expects auto, none or a non-zero vector X,Y,Z, got {value!r}")
    return v / np.linalg.norm(v)


def align_robot(args: argparse.Namespace, robot: str, person_map_path: str, *, seq=None):
    """Align ``robot`` into the person's map per ``args``: ``(seq, report dict, poses in the person's frame)``.

    ``seq`` is the robot's recording already opened (:func:`semmatch.cli.common.open_sequence`, with
    its recording options: ``--frames``, ``--estimate-poses`` ...); default: opened here.

    Raises
    ------
    ValueError
        A refused alignment (which check failed and by how much), unless ``--accept-weak-alignment``.
    """
    from semmatch.cli.common import open_sequence
    from semmatch.io import read_map
    from semmatch.poses.alignment import align_recording, recording_poses

    up = person_up(args.person_up)
    if seq is None:  # --estimate-poses: the recording's view carries the (cached) odometry poses
        seq = open_sequence(args, robot, needs_poses=True)
    poses = recording_poses(seq)
    person = read_map(person_map_path)
    result, aligned, _ = align_recording(seq, poses, person, person_up=up, map_voxel=args.map_voxel,
                                      progress=not args.quiet, voxel_size=args.align_voxel, seed=args.align_seed,
                                      restarts=args.restarts)
    if not result.accepted and not args.accept_weak_alignment:
        raise ValueError(f"{robot}: the alignment into {person_map_path} is refused: " + "; ".join(result.failures())
                         + " (docs/recordings.md, 'A person and a robot'; --accept-weak-alignment forces it)")
    return seq, result, aligned


def run(args: argparse.Namespace) -> int:
    """Align, write the poses and the report, print the summary."""
    from semmatch.cli.common import emit
    from semmatch.poses.alignment import write_aligned_poses

    seq, result, aligned = align_robot(args, args.robot, args.to)
    report = write_aligned_poses(args.out, getattr(seq, "timestamps", np.arange(len(aligned))), aligned, result,
                                 forced=args.accept_weak_alignment, person_map=str(args.to))
    return emit(report, args.json, summary(report))


def summary(report: dict) -> str:
    """One sentence of the alignment report."""
    floor = report["floor"]
    text = (f"{report['poses']}: {'accepted' if report['accepted'] else 'FORCED (below the checks)'}; fitness "
            f"{report['fitness']:.3f}, structure {report['structure_fitness']:.3f}, overlap {report['overlap']:.3f}, "
            f"inlier RMSE {100 * report['inlier_rmse']:.1f} cm, agreement {report['agreement']:.2f} of "
            f"{report['restarts']} restarts (spread {100 * report['spread_translation_m']:.1f} cm / "
            f"{report['spread_rotation_deg']:.1f} deg)")
    if floor:
        text += f"; floors {floor['angle_deg']:.2f} deg / {100 * floor['offset_m']:.1f} cm apart"
    else:
        text += "; no floor constraint"
    return text
