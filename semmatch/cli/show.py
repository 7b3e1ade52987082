"""``semmatch show MAP.ply [--reference GT.ply] --html OUT.html``: an interactive 3D page."""

from __future__ import annotations

import argparse


def register(sub) -> None:
    """Add ``semmatch show``."""
    p = sub.add_parser(
        "show",
        help="write an interactive 3D view (self-contained HTML) of a semantic map",
        description="One self-contained HTML page (plotly) of MAP in label colours, or of its "
        "errors against a reference (correct / wrong / unsupported voxels), optionally with "
        "camera paths. Large maps are decimated for display.",
    )
    p.add_argument("map", help="semantic PLY (mesh or point cloud)")
    p.add_argument("--html", required=True, help="HTML page to write")
    p.add_argument("--reference", help="show the errors of MAP against this semantic PLY instead")
    p.add_argument("--instances", action="store_true", help="colour by instance (panoptic maps)")
    p.add_argument("--trajectory", action="append", default=[], metavar="SEQ",
                   help="add the camera path of a sequence folder (repeatable)")
    p.add_argument("--voxel-size", type=float, default=0.05, help="voxels of --reference (default %(default)s)")
    p.add_argument("--max-vertices", type=int, default=150_000,
                   help="display budget; larger maps are decimated (default %(default)s)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the page."""
    from semmatch.io import read_sequence
    from semmatch.viz import error_figure, map_figure, trajectory_trace, write_html

    if args.reference and args.instances:
        raise ValueError("--instances and --reference cannot be combined")
    if args.reference:
        fig = error_figure(args.map, args.reference, args.voxel_size)
    else:
        fig = map_figure(args.map, color_by="instances" if args.instances else "labels",
                         max_vertices=args.max_vertices)
    for k, seq in enumerate(args.trajectory):
        colour = ("black", "royalblue", "darkorange", "purple")[k % 4]
        fig.add_trace(trajectory_trace(read_sequence(seq).poses, seq, colour))
    write_html(fig, args.html)
    print(f"{args.html}: written")
    return 0
