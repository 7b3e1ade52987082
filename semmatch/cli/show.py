"""``semmatch show MAP.ply [--reference GT.ply] --html OUT.html [--plotlyjs MODE]``: an interactive 3D page."""

from __future__ import annotations

import argparse


def register(sub) -> None:
    """Add ``semmatch show``."""
    from semmatch.cli.common import add_output_flags, add_recording_options, number
    from semmatch.io.outputs import declare_paths

    p = sub.add_parser(
        "show",
        help="write an interactive 3D view (self-contained HTML) of a semantic map",
        description="One HTML page (plotly) of MAP in label colours with a legend of its categories, "
        "or of its errors against a reference (correct blue / wrong orange / unsupported grey "
        "voxels), optionally with camera paths (a simulated sequence is named person or robot). "
        "Large maps are decimated for display.",
    )
    p.add_argument("map", help="semantic PLY (mesh or point cloud)")
    p.add_argument("--html", required=True, help="HTML page to write")
    p.add_argument("--reference", help="show the errors of MAP against this semantic PLY instead")
    p.add_argument("--instances", action="store_true", help="colour by instance (panoptic maps)")
    p.add_argument("--trajectory", action="append", default=[], metavar="SEQ",
                   help="add the camera path of a sequence folder or recording (repeatable)")
    p.add_argument("--plotlyjs", choices=("inline", "directory", "cdn"), default="inline",
                   help="inline: plotly.js inside the page (self-contained, several MB); directory: one "
                        "shared plotly.min.js beside the pages (small pages, offline); cdn: loaded from "
                        "the internet")
    p.add_argument("--voxel-size", type=number(float, lo=0.0, lo_open=True), default=0.05, help="voxels of --reference")
    p.add_argument("--max-vertices", type=number(int, lo=1), default=150_000,
                   help="display budget; larger maps are decimated")
    add_recording_options(p)
    add_output_flags(p, json_what="the page written")
    declare_paths(p, inputs=("map", "reference", "trajectory", "intrinsics"), outputs=("html",))
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the page."""
    from semmatch.cli.common import emit, open_sequence
    from semmatch.plots.views import error_figure, map_figure, trajectory_name, trajectory_trace, write_html

    if args.reference and args.instances:
        raise ValueError("--instances and --reference cannot be combined")
    if args.reference:
        fig = error_figure(args.map, args.reference, args.voxel_size)
    else:
        fig = map_figure(args.map, color_by="instances" if args.instances else "labels",
                         max_vertices=args.max_vertices)
    for k, seq in enumerate(args.trajectory):
        colour = ("black", "rgb(204,121,167)", "rgb(0,158,115)", "rgb(86,180,233)")[k % 4]
        fig.add_trace(trajectory_trace(open_sequence(args, seq, needs_poses=True).poses, trajectory_name(seq), colour))
    write_html(fig, args.html, plotlyjs=args.plotlyjs)
    return emit({"html": str(args.html), "plotlyjs": args.plotlyjs}, args.json, f"{args.html}: written")
