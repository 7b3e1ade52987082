"""``semmatch evaluate GT.ply PRED.ply [PRED.ply ...]``: the paper's measures as a table."""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np


def register(sub) -> None:
    """Add ``semmatch evaluate``."""
    from semmatch.cli.common import add_output_flags, number
    from semmatch.io.outputs import declare_paths

    p = sub.add_parser(
        "evaluate",
        help="compare semantic maps with ground truth (Jaccard, Sorensen, Color Acc., Mean Acc.)",
        description="Voxelise ground truth and predictions (majority label per voxel) and print "
        "the paper's measures per prediction; optionally write CSV/Markdown tables and a "
        "confusion-matrix figure.",
    )
    p.add_argument("gt", help="ground-truth semantic PLY (mesh or point cloud)")
    p.add_argument("pred", nargs="+", help="predicted semantic PLY files")
    p.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.05, help="voxel edge in metres")
    p.add_argument("--union", choices=("restrict", "plain"), default="restrict",
                   help="Jaccard union: the authors' 'restrict' or plain |G u P|")
    p.add_argument("--min-overlap", type=number(float, lo=0.0, hi=1.0), default=0.1,
                   help="refuse maps whose occupied voxels overlap less than this")
    p.add_argument("--transform", help="4x4 rigid transform (text/.npy) applied to every prediction")
    p.add_argument("--per-class", action="store_true", help="add per-class IoU columns")
    p.add_argument("--csv", help="write the table as CSV")
    p.add_argument("--markdown", help="write the table as Markdown")
    p.add_argument("--figure", help="write the confusion matrix (of the first prediction, or one "
                   "panel per prediction) as an image (PNG/PDF/SVG)")
    p.add_argument("--strict", action="store_true",
                   help="exit with an error (2) when a prediction shares no evaluated voxel with the ground "
                        "truth (default: a warning; its scores are 0 by construction, not by measurement)")
    add_output_flags(p, json_what="the table (prediction -> measure -> value)")
    declare_paths(p, inputs=("gt", "pred", "transform"), outputs=("csv", "markdown", "figure"))
    p.set_defaults(func=run)


def _load_transform(path: str) -> np.ndarray:
    from semmatch.io.geometry import check_pose

    if not Path(path).is_file():
        raise FileNotFoundError(f"{path}: no such transform file (--transform)")
    try:
        T = np.load(path) if path.endswith(".npy") else np.loadtxt(path)
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: not a 4x4 transform, as text or .npy (--transform): {e}") from None
    return check_pose(T, what=f"{path} (--transform)")


def results_table(results: dict[str, dict], *, per_class: bool = False):
    """A pandas DataFrame (one row per prediction) from :func:`semmatch.evaluate.metrics.compare` results."""
    import pandas as pd

    from semmatch.evaluate.metrics import MEASURES

    rows = []
    for name, s in results.items():
        row = {"prediction": name, **{k: s[k] for k in MEASURES}}
        row.update({"gt_voxels": s["counts"]["gt"], "pred_voxels": s["counts"]["pred"],
                    "overlap": s["overlap"]})
        if per_class:
            row.update({f"iou_{k}": v for k, v in s["per_class_iou"].items()})
        rows.append(row)
    return pd.DataFrame(rows).set_index("prediction")


def check_scorable(gt: str, results: dict[str, dict]) -> list[str]:
    """Why scores of :func:`semmatch.evaluate.metrics.compare` would be zeros that measure nothing.

    Parameters
    ----------
    gt : str
        The ground-truth file (for messages).
    results : dict
        Prediction name -> ``compare`` result.

    Returns
    -------
    list of str
        One message per prediction without a single evaluated voxel in common with the ground
        truth (another label table, a map of void, another scene).

    Raises
    ------
    ValueError
        The ground truth has no voxel of an evaluated class (all void, or another label table):
        no prediction can be scored against it.
    """
    from semmatch.evaluate.metrics import EVAL_CLASSES

    first = next(iter(results.values()), None)
    if first is not None and first["counts"]["gt"] == 0:
        raise ValueError(f"{gt}: the ground truth has no voxel of an evaluated class ({len(EVAL_CLASSES)} classes; "
                         "all void, or a map of another label table): nothing can be scored against it")
    return [f"{name}: no voxel with an evaluated class where {gt} has one ({s['counts']['pred']} evaluated voxels in "
            "all): its scores are 0 by construction (a map of void, another label table or another scene?)"
            for name, s in results.items() if s["counts"]["intersection"] == 0]


def check_label_sets(gt: str, gt_labels: np.ndarray, pred: str, pred_labels: np.ndarray) -> None:
    """Refuse a prediction whose evaluated labels share none with the ground truth's (another label table).

    A map labelled in another category table scores 0 on every measure at full occupancy
    overlap: the zeros measure the table, not the transfer.

    Parameters
    ----------
    gt, pred : str
        The files, for the message.
    gt_labels, pred_labels : ndarray
        The voxel labels of each (:func:`semmatch.evaluate.metrics.voxelize`).

    Raises
    ------
    ValueError
        Both maps have evaluated labels and no label is in both sets (the message lists them).
    """
    from semmatch.evaluate.metrics import EVAL_CLASSES
    from semmatch.io.labels import NAMES

    g = set(np.unique(gt_labels).tolist()) & set(EVAL_CLASSES)
    p = set(np.unique(pred_labels).tolist()) & set(EVAL_CLASSES)
    if g and p and not g & p:
        def names(s: set) -> str:
            return ", ".join(f"{NAMES[c]} ({c})" for c in sorted(s))

        raise ValueError(f"{pred}: its labels ({names(p)}) and those of the ground truth {gt} ({names(g)}) have no "
                         "label in common: a map of another label table (or of another scene) cannot be scored; "
                         "map its labels into semmatch's category table first")


def run(args: argparse.Namespace) -> int:
    """Evaluate every prediction and print the table."""
    from semmatch.cli.common import emit_table
    from semmatch.evaluate.metrics import compare, voxelize
    from semmatch.io import atomic_write_text

    T = _load_transform(args.transform) if args.transform else None
    gt = voxelize(args.gt, args.voxel_size)
    results = {}
    for pred in args.pred:
        pv = voxelize(pred, args.voxel_size, transform_matrix=T)
        check_label_sets(args.gt, gt.labels, pred, pv.labels)
        results[pred] = compare(gt, pv, args.voxel_size, union=args.union, min_overlap=args.min_overlap)
    empty = check_scorable(args.gt, results)
    if empty and args.strict:
        raise ValueError("; ".join(empty) + " (--strict)")
    for msg in empty:
        warnings.warn(msg, UserWarning, stacklevel=1)
    # short unique names: file names when they are unique
    names = [Path(p).name for p in results]
    if len(set(names)) == len(names):
        results = dict(zip(names, results.values()))
    df = results_table(results, per_class=args.per_class)
    emit_table(df, args.json)
    if args.csv:
        atomic_write_text(args.csv, df.to_csv(float_format="%.6f"))
    if args.markdown:
        fmt = ["g"] + [".4f" if df[c].dtype.kind == "f" else ".0f" for c in df.columns]
        atomic_write_text(args.markdown, df.to_markdown(floatfmt=fmt) + "\n")
    if args.figure:
        from semmatch.plots import confusion_figure

        confusion_figure(results, args.figure)
    return 0
