"""``semmatch replay RECORDING --map PERSON_MAP --method M --rate 30``: the robot online, on a recording."""

from __future__ import annotations

INITS = ("auto", "align", "register", "first-pose", "identity")


def register(sub) -> None:
    """Add the ``replay`` verb."""
    from semmatch.cli.common import add_index_cache, add_output_flags, add_recording_options, number
    from semmatch.io.outputs import declare_paths
    from semmatch.transfer import DEFAULT_MAX_DISTANCE, available_methods

    p = sub.add_parser(
        "replay",
        help="play a recording through the online robot session (pose, labels, fusion per frame) at its rate",
        description="Play RECORDING (any layout semmatch reads) frame by frame through a robot session: each frame "
        "is localised by frame-to-model tracking against the person's map (the robot's own map where the "
        "person's has no surface; without --map, the robot's own map alone), labelled by transfer from the "
        "person's map and fused into the robot's semantic map. Frames arrive at --rate frames per second; "
        "frames that arrive while the session is busy are dropped, as on a live robot. Reports per-frame "
        "latency (median, p95), dropped frames, tracking losses and, where the recording has ground truth, "
        "the ATE. Lost frames get void labels.",
    )
    p.add_argument("recording", metavar="RECORDING",
                   help="recording: any layout semmatch reads (sequence, TUM RGB-D, 7-Scenes, rgb/+depth/, ROS bag)")
    p.add_argument("--map", default=None, help="the person's semantic map (PLY mesh); omitted: self-tracking, no transfer")
    p.add_argument("--method", default="3d-neighborhood", choices=list(available_methods()),
                   help="transfer method (fused: also --probs)")
    p.add_argument("--probs", default=None, help="fused: folder of per-frame class probabilities 000000.npy (H,W,C)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="method parameter (JSON value); repeatable")
    p.add_argument("--rate", type=number(float, lo=0.0), default=30.0,
                   help="sensor rate in frames per second; 0: every frame, as fast as possible")
    p.add_argument("--clock", default="wall", choices=["wall", "cpu"],
                   help="processing time on the simulated clock that decides the dropped frames: wall time, or "
                        "CPU time (one free core; for a machine shared with other work)")
    p.add_argument("--init", default="auto", choices=INITS,
                   help="first pose: 'align' (semmatch align's checked, floor-levelled alignment of the frame into "
                        "--map; a frame that fails the checks is retried later), 'register' (global registration "
                        "of the first frame onto --map), 'first-pose' "
                        "(the recording's first ground-truth pose), 'identity'; 'auto': register with --map, else "
                        "first-pose where the recording has one, else identity")
    p.add_argument("--true-poses", action="store_true",
                   help="use the recording's own poses instead of tracking (the offline chain's poses)")
    p.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.04,
                   help="the robot map's voxel (metres)")
    p.add_argument("--track-downsample", type=number(int, lo=1), default=None,
                   help="track on frames shrunk by this factor (default: the factor that brings the width nearest "
                        "to 160 pixels, 4 at 640x480)")
    p.add_argument("--track-iterations", default="10,5", metavar="N,N,...",
                   help="tracking iterations per pyramid level, coarsest first")
    p.add_argument("--residual", default="point-to-plane", choices=["hybrid", "point-to-plane", "intensity"],
                   help="tracking residual")
    p.add_argument("--depth-max", type=number(float, lo=0.0, lo_open=True), default=4.0,
                   help="ignore depth beyond this (metres) in tracking and fusion")
    p.add_argument("--max-distance", type=number(float, lo=0.0, lo_open=True), default=DEFAULT_MAX_DISTANCE,
                   help="metres; pixels farther than this from the person's map get 0")
    p.add_argument("--poses-out", default=None, help="write the processed frames' poses (TUM; lost frames left out)")
    p.add_argument("--labels-out", default=None,
                   help="labels folder: one image per frame of the recording (void for lost and dropped frames)")
    p.add_argument("--map-out", default=None, help="write the robot's semantic map (PLY mesh)")
    p.add_argument("--rerun", default=None, metavar="OUT.rrd",
                   help="log colour, depth, labels, tracking status, trajectory and the growing map to a Rerun file")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing labels folder semmatch wrote at --labels-out")
    add_output_flags(p, json_what="the replay summary", quiet="the progress bar")
    add_index_cache(p)
    declare_paths(p, inputs=("recording", "map", "probs"),
                  outputs=("poses_out", "labels_out", "map_out", "rerun"))
    add_recording_options(p, estimate_help="not for replay: it tracks its own poses (refused)")
    p.set_defaults(func=run)


def _iterations(text: str) -> tuple[int, ...]:
    try:
        its = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise ValueError(f"--track-iterations expects counts like 10,5, got {text!r}") from None
    if not its or min(its) < 1:
        raise ValueError(f"--track-iterations expects counts >= 1, got {text!r}")
    return its


def _initialiser(args, gt):
    import numpy as np

    from semmatch.online import align_frame, given_pose, register_frame

    mode = args.init
    if mode == "auto":
        mode = "register" if args.map else ("first-pose" if gt is not None and np.isfinite(gt[0]).all() else "identity")
    if mode in ("register", "align"):
        if not args.map:
            raise ValueError(f"--init {mode} needs --map (the person's map to place the first frame in)")
        return register_frame if mode == "register" else align_frame
    if mode == "first-pose":
        if gt is None or not np.isfinite(gt[0]).all():
            raise ValueError(f"{args.recording}: --init first-pose, but its first frame has no ground-truth pose")
        return given_pose(gt[0])
    return given_pose(np.eye(4))


def run(args) -> int:
    """Run ``semmatch replay``."""
    import numpy as np

    from semmatch.cli.common import emit, index_cache_options, open_sequence
    from semmatch.cli.transfer import _parse_params
    from semmatch.io import check_output_dir, read_map, write_map
    from semmatch.online import ModelTracker, RobotSession
    from semmatch.online.replay import replay
    from semmatch.poses.odometry import ground_truth_poses
    from semmatch.transfer import load_index

    params = _parse_params(args.param)
    if args.method == "fused" and args.probs is None:
        raise ValueError("--method fused needs --probs DIR (per-frame class probabilities)")
    if args.probs is not None and args.method != "fused":
        raise ValueError("--probs is only used by --method fused")
    iterations = _iterations(args.track_iterations)
    if args.labels_out:
        if not args.map:
            raise ValueError("--labels-out needs --map (labels are transferred from the person's map)")
        check_output_dir(args.labels_out, "labels", overwrite=args.overwrite, inputs=[args.recording, args.map])
    if args.estimate_poses:
        raise ValueError("replay tracks the robot's poses itself; --estimate-poses is for the verbs that need "
                         "recorded poses (to replay the recording's own poses, use --true-poses)")
    frames = open_sequence(args, args.recording)  # any layout; --frames, --intrinsics and bag topics applied
    gt = ground_truth_poses(frames)
    if len(frames) == 0:
        raise ValueError(f"{args.recording}: no frames to play" + (" in --frames" if args.frames else ""))
    if args.true_poses and (gt is None or not np.isfinite(gt).all()):
        raise ValueError(f"{args.recording}: --true-poses, but not every frame has a ground-truth pose")
    person = index = None
    if args.map:
        person = read_map(args.map)
        index = load_index(args.map, max_distance=args.max_distance, semantic_map=person,
                           **index_cache_options(args))
    tracker = ModelTracker(person, downsample=args.track_downsample, iterations=iterations,
                           residual=args.residual, depth_max=args.depth_max)
    session = RobotSession(person, method=args.method, params=params, index=index,
                           max_distance=args.max_distance, voxel_size=args.voxel_size,
                           tsdf_options={"depth_max": args.depth_max}, initialiser=_initialiser(args, gt),
                           tracker=tracker)
    probs = None
    if args.probs is not None:
        from semmatch.transfer.sequence import _frame_params

        def probs(i: int):
            return _frame_params({"probs": args.probs}, i)["probs"]  # indexed like the frames played

    from semmatch.online.outputs import ReplayOutputs

    with ReplayOutputs(labels_out=args.labels_out, poses_out=args.poses_out, rerun=args.rerun, frames=frames,
                       inputs=[p for p in (args.recording, args.map) if p], overwrite=args.overwrite,
                       session=session) as outputs:
        report = replay(session, frames, rate=args.rate, poses=gt if args.true_poses else None, probs=probs,
                        on_frame=outputs.on_frame, clock=args.clock, progress=not args.quiet)
        outputs.finish(report, session)
    s = report.summary(gt)
    s.update(recording=str(args.recording), method=args.method if args.map else None, clock=args.clock,
             mode="true poses" if args.true_poses else ("person's map" if args.map else "self-tracking"))
    if args.map_out:
        write_map(args.map_out, session.semantic_map())
    ate = f"  ATE {s['ate_m'] * 100:.2f} cm" if "ate_m" in s else ""
    text = (f"{s['recording']}: {s['processed']} of {s['frames']} frames processed ({s['dropped']} dropped at "
            f"{args.rate:g} fps), latency median {s['latency_ms_median']:.1f} ms, p95 {s['latency_ms_p95']:.1f} ms, "
            f"{s['frames_per_cpu_second']:.1f} frames per CPU-second, {s['tracking_losses']} tracking losses "
            f"({s['lost_frames']} lost frames){ate}")
    return emit(s, args.json, text)
