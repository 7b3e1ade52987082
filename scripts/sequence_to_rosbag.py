"""Write a recording (a simulated sequence folder, TUM, 7-Scenes, plain) as a ROS bag, to try the bag reader.

Usage::

    python scripts/sequence_to_rosbag.py RECORDING OUT [--version 2] [--storage sqlite3|mcap]
        [--compressed jpeg|png] [--depth-encoding 16UC1|32FC1] [--poses odom|tf|pose|none] [--frames N]

``OUT`` is a new ROS 2 bag folder (``--version 2``) or ``.bag`` file (``--version 1``) with a
RealSense driver's topics (:func:`semmatch.io.bags.write_rosbag`): ``/camera/color/image_raw``,
``/camera/color/camera_info``, ``/camera/aligned_depth_to_color/image_raw`` and the frames'
poses (``/odom`` of ``base_link`` with ``/tf_static`` to ``camera_color_optical_frame``; ``tf``:
that chain on ``/tf``; ``pose``: ``/camera/pose``). The header stamps are the recording's
timestamps (a simulated sequence's frame numbers: 1 Hz). Read it back with
``semmatch.io.bags.RosBagSequence`` (``--pose-topic /odom``, ``--pose-topic /tf`` or
``--pose-topic /camera/pose`` on the command line).
"""

from __future__ import annotations

import argparse
import sys
from itertools import islice


def main(argv: list[str] | None = None) -> int:
    """Read the recording, write the bag, print what was written."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording", help="any recording semmatch reads (sequence folder, TUM, 7-Scenes, plain)")
    ap.add_argument("out", help="the new bag: a folder (ROS 2) or a .bag file (ROS 1)")
    ap.add_argument("--version", type=int, choices=(1, 2), default=2, help="ROS 1 .bag or ROS 2 bag folder")
    ap.add_argument("--storage", choices=("sqlite3", "mcap"), default="sqlite3", help="ROS 2 storage")
    ap.add_argument("--compressed", choices=("jpeg", "png"), default=None,
                    help="compressed colour and compressedDepth depth (default: raw images)")
    ap.add_argument("--depth-encoding", choices=("16UC1", "32FC1"), default="16UC1",
                    help="depth in millimetres (16UC1) or metres (32FC1)")
    ap.add_argument("--poses", choices=("odom", "tf", "pose", "none"), default="odom", help="how poses are written")
    ap.add_argument("--frames", type=int, default=None, help="write only the first N frames (default all)")
    args = ap.parse_args(argv)
    from semmatch.io.bags import write_rosbag
    from semmatch.io.recordings import read_recording

    try:
        seq = read_recording(args.recording)
        frames = islice(iter(seq), args.frames)
        path = write_rosbag(args.out, frames, seq.intrinsics, version=args.version, storage=args.storage,
                            compressed=args.compressed or False, depth_encoding=args.depth_encoding,
                            poses=None if args.poses == "none" else args.poses)
    except (ValueError, FileNotFoundError) as e:
        print(f"sequence_to_rosbag: error: {e}", file=sys.stderr)
        return 2
    n = len(seq) if args.frames is None else min(args.frames, len(seq))
    print(f"{path}: {n} frames from {args.recording} (ROS {args.version}"
          f"{', ' + args.storage if args.version == 2 else ''}, poses: {args.poses})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
