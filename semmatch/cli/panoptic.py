"""``semmatch panoptic segment|reference|transfer|evaluate``: instance-level label transfer.

* ``segment MAP.ply --out OUT.ply``: give a semantic map an instance layer by clustering each
  thing class in 3D;
* ``reference SEQ --out OUT.ply``: fuse a sequence with its own ground-truth classes
  and instances (``instances/``) into a panoptic map;
* ``transfer SEQ --map UPPER.ply --method M --out OUT.ply``: transfer classes and
  instances into every frame of SEQ and fuse them into the lower panoptic map;
* ``evaluate GT.ply PRED.ply ...``: panoptic quality (PQ, SQ, RQ) on voxels.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub) -> None:
    """Add the ``panoptic`` verb and its sub-commands."""
    from semmatch.cli.common import add_index_cache, add_output_flags, add_sequence, number
    from semmatch.io.outputs import declare_paths
    from semmatch.transfer import DEFAULT_MAX_DISTANCE, available_methods

    p = sub.add_parser(
        "panoptic",
        help="instance-level transfer: cluster instances, fuse, transfer, panoptic quality",
        description="Panoptic label transfer (the paper's future work): maps with an 'instance' "
        "vertex property, carried from the upper map into the robot's frames and map.",
    )
    s = p.add_subparsers(dest="action", metavar="ACTION")
    s.required = True

    seg = s.add_parser("segment", help="add an instance layer to a semantic map by 3D clustering",
                       description="Cluster each thing class of MAP (Open3D DBSCAN) into instances.")
    seg.add_argument("map", help="semantic PLY (mesh or point cloud)")
    seg.add_argument("--out", required=True, help="panoptic PLY to write")
    seg.add_argument("--eps", type=number(float, lo=0.0, lo_open=True), default=0.16,
                     help="clustering radius in metres; notebook 10 chooses it on validation scenes: "
                     "figures/<profile>/validation_panoptic_clustering.csv")
    seg.add_argument("--min-vertices", type=number(int, lo=1), default=50, help="smallest instance kept")
    add_output_flags(seg, json_what="the instances written")
    declare_paths(seg, inputs=("map",), outputs=("out",))
    seg.set_defaults(func=run_segment)

    ref = s.add_parser("reference", help="fuse a sequence with its ground-truth classes and instances",
                       description="TSDF-fuse SEQ with its own labels, then vote its instances/ images "
                       "onto the map's vertices (the panoptic reference of a robot sequence).")
    add_sequence(ref, "sequence folder with labels/ and instances/ (any registered layout that has them)")
    ref.add_argument("--out", required=True, help="panoptic PLY to write")
    ref.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.04, help="TSDF voxel in metres")
    ref.add_argument("--step", type=number(int, lo=1), default=1, help="use every n-th frame for the instances")
    add_output_flags(ref, json_what="the map written", quiet="the progress bars")
    declare_paths(ref, inputs=("sequence", "sequence_flag", "intrinsics"), outputs=("out",))
    ref.set_defaults(func=run_reference)

    tr = s.add_parser("transfer", help="transfer classes and instances into a sequence and fuse its panoptic map",
                      description="Transfer the classes and instances of the upper panoptic map into "
                      "every frame of SEQ, fuse the classes (TSDF) and vote the instances onto the map.")
    tr.add_argument("--map", required=True, help="upper panoptic PLY (with an 'instance' property)")
    add_index_cache(tr)
    add_sequence(tr, "the robot's (lower) sequence folder or recording (any registered layout)")
    tr.add_argument("--method", required=True, choices=[m for m in available_methods() if m != "fused"],
                    help="transfer method")
    tr.add_argument("--out", required=True, help="lower panoptic PLY to write")
    tr.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.04, help="TSDF voxel in metres")
    tr.add_argument("--max-distance", type=number(float, lo=0.0, lo_open=True), default=DEFAULT_MAX_DISTANCE,
                    help="metres; pixels farther than this from the map get 0")
    tr.add_argument("--eps", type=number(float, lo=0.0, lo_open=True), default=0.05,
                    help="fragments joining a touching instance: linking radius, metres")
    tr.add_argument("--min-vertices", type=number(int, lo=1), default=50,
                    help="fragments smaller than this may join a touching instance")
    add_output_flags(tr, json_what="the map written", quiet="the progress bars")
    declare_paths(tr, inputs=("map", "sequence", "sequence_flag", "intrinsics"), outputs=("out",))
    tr.set_defaults(func=run_transfer)

    ev = s.add_parser("evaluate", help="panoptic quality of panoptic maps against ground truth",
                      description="Voxelise both maps (majority class, then majority instance) and "
                      "print PQ = SQ x RQ over thing classes, stuff classes and all classes.")
    ev.add_argument("gt", help="ground-truth panoptic PLY")
    ev.add_argument("pred", nargs="+", help="predicted panoptic PLY files")
    ev.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.05, help="voxel edge in metres")
    ev.add_argument("--per-class", action="store_true", help="add PQ per class")
    ev.add_argument("--csv", help="write the table as CSV")
    ev.add_argument("--warn-overlap", type=number(float, lo=0.0, hi=1.0), default=0.5, metavar="FRACTION",
                    help="warn when the occupied voxels of a prediction and the ground truth overlap less than "
                         "this (partial maps score low PQ for want of overlap)")
    add_output_flags(ev, json_what="the table (prediction -> measure -> value)")
    declare_paths(ev, inputs=("gt", "pred"), outputs=("csv",))
    ev.set_defaults(func=run_evaluate)


def run_segment(args: argparse.Namespace) -> int:
    """Cluster the thing classes of a map into instances."""
    import numpy as np

    from semmatch.cli.common import emit
    from semmatch.io import read_map, write_map
    from semmatch.io.labels import NAMES
    from semmatch.transfer.panoptic import segment_instances

    m = segment_instances(read_map(args.map), eps=args.eps, min_vertices=args.min_vertices)
    write_map(args.out, m)
    ids = np.unique(m.instances[m.instances > 0])
    per = {NAMES[c]: len(np.unique(m.instances[(m.labels == c) & (m.instances > 0)]))
           for c in np.unique(m.labels[m.instances > 0])}
    return emit({"out": str(args.out), "instances": len(ids), "per_class": per}, args.json,
                f"{args.out}: {len(ids)} instances " + ", ".join(f"{k} {v}" for k, v in per.items()))


def _map_written(args: argparse.Namespace, m) -> int:
    """Print what ``reference`` and ``transfer`` wrote (a sentence, or JSON with ``--json``)."""
    from semmatch.cli.common import emit

    n = len(set(m.instances[m.instances > 0].tolist()))
    return emit({"out": str(args.out), "vertices": len(m), "instances": n}, args.json,
                f"{args.out}: {len(m)} vertices, {n} instances")


def run_reference(args: argparse.Namespace) -> int:
    """Fuse a sequence with its ground-truth classes and instances."""
    from semmatch.cli.common import open_sequence, sequence_arg
    from semmatch.fusion import reconstruct
    from semmatch.io import write_map
    from semmatch.transfer.panoptic import fuse_instances, sequence_panoptic_frames

    from ..runtime.progress import tqdm

    seq_path = sequence_arg(args)
    seq = open_sequence(args, seq_path, needs_poses=True)
    if not getattr(seq, "has_labels", False):
        raise ValueError(f"{seq_path}: the sequence has no labels/ folder")
    seq.read_instances(0)  # a clear error before the fusion when instances/ is missing
    m = reconstruct(seq, voxel_size=args.voxel_size, progress=not args.quiet)
    frames = tqdm(sequence_panoptic_frames(seq, step=args.step), total=len(range(0, len(seq), args.step)),
                  desc="instances", disable=args.quiet)
    m = fuse_instances(m, frames, clean=False)
    write_map(args.out, m)
    return _map_written(args, m)


def run_transfer(args: argparse.Namespace) -> int:
    """Transfer classes and instances into a sequence and fuse its panoptic map."""
    from semmatch.cli.common import index_cache_options, open_sequence, sequence_arg
    from semmatch.fusion import reconstruct
    from semmatch.io import read_map, require_instances, write_map
    from semmatch.transfer import load_index
    from semmatch.transfer.panoptic import PanopticFrame, fuse_instances, transfer_panoptic

    from ..runtime.progress import tqdm

    seq_path = sequence_arg(args)
    upper = require_instances(read_map(args.map), "panoptic transfer")
    seq = open_sequence(args, seq_path, needs_poses=True)
    index = load_index(args.map, max_distance=args.max_distance, **index_cache_options(args), semantic_map=upper)
    labels, evidence = [], []
    for i in tqdm(range(len(seq)), desc=f"panoptic {args.method}", disable=args.quiet):
        f = seq[i]
        lab, inst = transfer_panoptic(args.method, f, index)
        labels.append(lab)
        evidence.append(PanopticFrame.of(f, lab, inst, f"{seq_path} frame {i}"))
    m = reconstruct(seq, labels, args.voxel_size, progress=not args.quiet)
    m = fuse_instances(m, evidence, eps=args.eps, min_vertices=args.min_vertices)
    write_map(args.out, m)
    return _map_written(args, m)


def run_evaluate(args: argparse.Namespace) -> int:
    """Print panoptic quality per prediction."""
    import warnings

    import numpy as np
    import pandas as pd

    from semmatch.cli.common import emit_table
    from semmatch.io import atomic_write_text
    from semmatch.transfer.panoptic import panoptic_quality, panoptic_voxels

    gt = panoptic_voxels(args.gt, args.voxel_size)
    rows = []
    for pred in args.pred:
        pv = panoptic_voxels(pred, args.voxel_size)
        both = int(np.isin(pv.keys, gt.keys).sum())
        overlap = both / max(min(len(gt.keys), len(pv.keys)), 1)
        if overlap < args.warn_overlap:
            warnings.warn(f"{pred} vs {args.gt}: only {both} of min({len(gt.keys)}, {len(pv.keys)}) occupied voxels "
                          f"overlap ({overlap:.1%}); a low PQ here measures the missing overlap (a partial map, "
                          "another frame or units?) more than the instances", UserWarning, stacklevel=1)
        q = panoptic_quality(gt, pv, args.voxel_size)
        row = {"prediction": Path(pred).name, **{k: q[k] for k in
               ("pq", "sq", "rq", "pq_things", "sq_things", "rq_things", "pq_stuff")}, "overlap": overlap}
        if args.per_class:
            row.update({f"pq_{k}": v["pq"] for k, v in q["per_class"].items()})
        rows.append(row)
    df = pd.DataFrame(rows).set_index("prediction")
    emit_table(df, args.json)
    if args.csv:
        atomic_write_text(args.csv, df.to_csv(float_format="%.6f"))
    return 0
