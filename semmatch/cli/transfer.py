"""``semmatch transfer --map MAP.ply --sequence SEQ --method NAME --out DIR``."""

from __future__ import annotations

import argparse
import json


def register(sub) -> None:
    """Add the ``transfer`` verb."""
    from semmatch.cli.common import add_index_cache, add_output_flags, add_sequence, number
    from semmatch.io.outputs import declare_paths
    from semmatch.transfer import DEFAULT_MAX_DISTANCE, available_methods

    p = sub.add_parser(
        "transfer",
        help="transfer the labels of an upper semantic map into a lower sequence (labels folder)",
        description="Give every frame of SEQ a semantic segmentation from the upper map MAP.ply "
        "with one of the paper's label-projection methods; writes DIR/000000.png ... atomically.",
    )
    p.add_argument("--map", required=True, help="upper semantic map or mesh (PLY)")
    add_sequence(p, "the robot's (lower) sequence folder or recording (any registered layout)")
    p.add_argument("--method", required=True, choices=list(available_methods()),
                   help="transfer method (fused: also --probs)")
    p.add_argument("--probs", default=None,
                   help="fused: folder of per-frame class probabilities 000000.npy (H,W,C)")
    p.add_argument("--out", required=True, help="labels folder to write")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing labels folder semmatch wrote at --out (anything else is refused)")
    p.add_argument("--max-distance", type=number(float, lo=0.0, lo_open=True), default=DEFAULT_MAX_DISTANCE,
                   help="metres; pixels farther than this from the map get 0")
    p.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.02, help="map index grid voxel (metres)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="method parameter (JSON value), e.g. --param n_segments=256; repeatable")
    p.add_argument("--jobs", type=number(int, lo=1), default=1, help="worker processes")
    add_output_flags(p, json_what="the statistics", quiet="the progress bar")
    p.add_argument("--strict", action="store_true",
                   help="exit with an error when the map supports (almost) no pixel (default: a warning)")
    add_index_cache(p)
    p.add_argument("--align", metavar="PERSON_MAP_OR_POSES",
                   help="place SEQ in the map's frame first: a person's map (PLY) to align SEQ into as `semmatch "
                        "align` does (refused alignments transfer nothing), or that verb's poses (TUM)")
    p.add_argument("--accept-weak-alignment", action="store_true",
                   help="with --align: use an alignment that fails its checks (the output's metadata says so)")
    declare_paths(p, inputs=("sequence", "sequence_flag", "map", "probs", "intrinsics", "align"), outputs=("out",))
    p.set_defaults(func=run)


def _parse_params(items: list[str]) -> dict:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"--param expects KEY=VALUE, got {item!r}")
        try:
            out[key.replace("-", "_")] = json.loads(value)
        except json.JSONDecodeError:
            out[key.replace("-", "_")] = value
    return out


def run(args) -> int:
    """Run ``semmatch transfer``."""
    from semmatch.cli.common import emit, index_cache_options, open_sequence, sequence_arg
    from semmatch.io import InMemorySequence, SequenceReader, check_output_dir
    from semmatch.transfer import load_index, transfer_sequence
    from semmatch.transfer.registry import check_params

    seq_path = sequence_arg(args)
    # before any work: never replace what semmatch did not write, nor an input
    check_output_dir(args.out, "labels", overwrite=args.overwrite, inputs=[seq_path, args.map])
    params = _parse_params(args.param)
    if args.probs is not None:
        if args.method != "fused":
            raise ValueError("--probs is only used by --method fused")
        params["probs"] = args.probs
    elif args.method == "fused":
        raise ValueError("--method fused needs --probs DIR (per-frame class probabilities)")
    check_params(args.method, params)
    if args.jobs < 1:  # before the map is indexed (and its index cached)
        raise ValueError(f"--jobs must be >= 1, got {args.jobs}")
    seq = open_sequence(args, seq_path, needs_poses=True)
    alignment = None
    if args.align:
        seq, alignment = _aligned(args, seq_path, seq)
    if args.jobs > 1 and type(seq) is not SequenceReader:  # workers share a recording's decoded frames
        seq = InMemorySequence(seq, progress=not args.quiet)
    index = load_index(args.map, max_distance=args.max_distance, voxel_size=args.voxel_size,
                       **index_cache_options(args))
    import warnings

    from semmatch.transfer.sequence import LOW_SUPPORT, LowSupportWarning

    with warnings.catch_warnings():
        if args.strict:
            warnings.simplefilter("error", LowSupportWarning)
        try:
            stats = transfer_sequence(
                args.method, seq, index, args.out, jobs=args.jobs, progress=not args.quiet,
                overwrite=args.overwrite, inputs=[seq_path, args.map], **params
            )
        except LowSupportWarning as e:
            raise ValueError(f"{e} (--strict: coverage below {LOW_SUPPORT:.0%}; the labels were written)") from None
    if alignment is not None:  # the labels folder says which poses it was transferred at
        from semmatch.io import write_json

        write_json(f"{stats['out']}/alignment.json", alignment)
        stats["alignment"] = {k: alignment[k] for k in ("accepted", "forced") if k in alignment}
    return emit(stats, args.json, f"{stats['method']}: {stats['frames']} frames -> {stats['out']}  coverage "
                f"{stats['coverage']:.3f}  median {stats['ms_median']:.1f} ms/frame ({stats['fps']:.1f} FPS)")


def _aligned(args, seq_path: str, seq):
    """``--align``: the sequence at its poses in the map's frame, and the alignment's report."""
    from pathlib import Path

    import numpy as np

    from semmatch.experiments.real_poses import PosedSequence
    from semmatch.io import read_tum

    if Path(args.align).suffix.lower() == ".ply":
        from semmatch.cli.align import align_robot

        defaults = dict(estimate_poses=False, person_up="auto", align_voxel=0.1, map_voxel=0.04, align_seed=0,
                        restarts=4)
        opts = argparse.Namespace(**{**defaults, **vars(args)})
        _, result, poses = align_robot(opts, seq_path, args.align, seq=seq)
        report = {"person_map": str(args.align), "forced": bool(not result.accepted), **result.as_dict()}
    else:
        _, poses = read_tum(args.align)
        header = Path(args.align).read_text().split("\n", 2)[:2]
        forced = any("FORCED" in line for line in header)
        report = {"poses": str(args.align), "accepted": not forced, "forced": forced}
    if len(poses) != len(seq):
        raise ValueError(f"{args.align}: {len(poses)} poses for the {len(seq)} frames of {seq_path}")
    return PosedSequence(seq, np.asarray(poses)), report
