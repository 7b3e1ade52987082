"""Write a recording (a simulated sequence folder, 7-Scenes, plain, a bag) as a TUM RGB-D folder, to try the TUM reader.

Usage::

    python scripts/sequence_to_tum.py RECORDING OUT [--fps 30] [--frames N] [--no-poses] [--overwrite]

``OUT`` is a new TUM RGB-D folder (:func:`semmatch.io.readers.tum.write_tum_rgbd`): ``rgb/``,
``depth/`` (16-bit, value / 5000 = metres), ``rgb.txt``, ``depth.txt``, ``groundtruth.txt`` (the
recording's poses, unless ``--no-poses``) and ``intrinsics.json``. Frames are stamped at
``i / FPS`` seconds (``--fps 0``: the recording's own timestamps; a simulated sequence's are its
frame numbers, 1 Hz, and TUM's pose interpolation leaves frames more than 0.1 s from a pose sample
without a pose). Every verb then reads ``OUT`` as a TUM recording.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from itertools import islice


def main(argv: list[str] | None = None) -> int:
    """Read the recording, write the TUM folder, print what was written."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording", help="any recording semmatch reads (sequence folder, TUM, 7-Scenes, plain, bag)")
    ap.add_argument("out", help="the new TUM RGB-D folder")
    ap.add_argument("--fps", type=float, default=30.0,
                    help="stamp frame i at i/FPS seconds; 0 keeps the recording's timestamps (default 30)")
    ap.add_argument("--frames", type=int, default=None, help="write only the first N frames (default all)")
    ap.add_argument("--no-poses", action="store_true", help="write no groundtruth.txt")
    ap.add_argument("--overwrite", action="store_true", help="replace a TUM folder this script wrote at OUT")
    args = ap.parse_args(argv)
    from semmatch.io.readers.tum import write_tum_rgbd
    from semmatch.io.recordings import read_recording

    try:
        seq = read_recording(args.recording)
        frames = islice(iter(seq), args.frames)
        if args.no_poses:
            frames = (dataclasses.replace(f, pose=None) for f in frames)
        path = write_tum_rgbd(args.out, frames, seq.intrinsics, fps=args.fps or None, overwrite=args.overwrite,
                              inputs=[args.recording])
    except (ValueError, FileNotFoundError, FileExistsError) as e:
        print(f"sequence_to_tum: error: {e}", file=sys.stderr)
        return 2
    n = len(seq) if args.frames is None else min(args.frames, len(seq))
    print(f"{path}: {n} frames from {args.recording} (TUM RGB-D, "
          f"{'no poses' if args.no_poses else 'poses in groundtruth.txt'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
