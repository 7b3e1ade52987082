"""What reading a ROS bag costs: open (index) time, read time a frame, peak memory against the bag's size.

Usage::

    python scripts/rosbag_cost.py [--frames 300] [--version 2] [--storage sqlite3|mcap] [--dir DIR]

Writes a bag of ``--frames`` 640x480 frames (raw ``rgb8`` colour of random pixels, ``16UC1``
depth, ``/odom`` poses) with :func:`semmatch.io.bags.write_rosbag` into a temporary folder (or
``--dir``), then opens it with :class:`semmatch.io.bags.RosBagSequence` in a fresh process and
prints one row: bag size, frames, open time (the index pass; imports excluded), read time a frame
(50 random frames, then all in order), the peak resident set size and the resident size after
the imports. The table in docs/recordings.md ("ROS bags") was measured with this script.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _frames(n: int):
    from semmatch.io import Frame
    from semmatch.io.geometry import DEFAULT_INTRINSICS, look_at

    rng = np.random.default_rng(0)
    h, w = DEFAULT_INTRINSICS.shape
    for i in range(n):
        rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        depth = (1.0 + 3.0 * rng.random((h, w), dtype=np.float32)).astype(np.float32)
        yield Frame(rgb, depth, None, look_at([0.01 * i, 0, 1], [0.01 * i, 3, 1]), DEFAULT_INTRINSICS, index=i)


def _read(path: Path) -> str:
    """Open and read the bag; the row (run in a fresh process)."""
    import rosbags.highlevel  # noqa: F401  imports are not part of the open time
    import scipy.spatial.transform  # noqa: F401

    from semmatch.io.bags import RosBagSequence

    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t = time.perf_counter()
    seq = RosBagSequence(path, pose_topic="/odom")
    t_open = time.perf_counter() - t
    order = np.random.default_rng(1).permutation(len(seq))[:50]
    t = time.perf_counter()
    for i in order:
        seq[int(i)]
    t_random = (time.perf_counter() - t) / len(order)
    t = time.perf_counter()
    for _ in seq:
        pass
    t_order = (time.perf_counter() - t) / len(seq)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    size = sum(f.stat().st_size for f in ([path] if path.is_file() else path.iterdir()))
    return (f"{path.name}: {size / 2**20:.0f} MiB, {len(seq)} frames; open {t_open:.2f} s; random read "
            f"{t_random * 1000:.0f} ms/frame, in order {t_order * 1000:.0f} ms/frame; peak RSS {rss:.0f} MiB "
            f"(after imports {rss0:.0f} MiB)")


def main(argv: list[str] | None = None) -> int:
    """Write the bag, measure the reading in a fresh process, print the row."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300, help="frames in the bag")
    ap.add_argument("--version", type=int, choices=(1, 2), default=2, help="ROS 1 .bag or ROS 2 bag folder")
    ap.add_argument("--storage", choices=("sqlite3", "mcap"), default="sqlite3", help="ROS 2 storage")
    ap.add_argument("--dir", help="folder for the bag (kept); default: a temporary folder, removed")
    ap.add_argument("--read", help=argparse.SUPPRESS)  # the measuring child process
    args = ap.parse_args(argv)
    if args.read:
        print(_read(Path(args.read)), flush=True)
        return 0
    from semmatch.io.bags import write_rosbag

    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        path = Path(tmp) / (f"bag_{args.version}_{args.storage}" + (".bag" if args.version == 1 else ""))
        t = time.perf_counter()
        write_rosbag(path, _frames(args.frames), version=args.version, storage=args.storage,
                     timestamps=1000.0 + np.arange(args.frames) / 30)
        print(f"written in {time.perf_counter() - t:.1f} s", flush=True)
        return subprocess.run([sys.executable, __file__, "--read", str(path)]).returncode


if __name__ == "__main__":
    sys.exit(main())
