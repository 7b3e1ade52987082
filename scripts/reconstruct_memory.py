"""Peak memory of ``semmatch reconstruct --estimate-poses`` on a recording, measured by ``/usr/bin/time -v``.

Usage::

    python scripts/reconstruct_memory.py RECORDING [--out DIR] [-- extra reconstruct flags]

Runs the command once (tracking, pose graph, fusion, mesh) and prints one benchmark row:
frames, image size, peak resident set size (GiB), wall time, and the command's JSON summary
(ATE/RPE when the recording has ground truth). The row in docs/recordings.md was measured
with this script on the 1000 frames of the 7-Scenes red kitchen
(``scripts/fetch_7scenes_kitchen.sh``).
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    """Run the measurement and print the row."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording", help="recording folder (7-Scenes, TUM, plain or sequence folder)")
    ap.add_argument("--out", help="folder for the mesh (default: a temporary folder, removed)")
    ap.add_argument("extra", nargs="*", help="further flags of semmatch reconstruct (after --)")
    args = ap.parse_args(argv)
    timer = shutil.which("time") if not Path("/usr/bin/time").is_file() else "/usr/bin/time"
    if timer is None:
        print("error: /usr/bin/time (GNU time) is needed for the peak memory", file=sys.stderr)
        return 2
    from semmatch.io.recordings import read_recording

    seq = read_recording(args.recording)
    h, w = seq[0].depth.shape
    tmp = Path(tempfile.mkdtemp(prefix="semmatch-mem-")) if args.out is None else Path(args.out)
    tmp.mkdir(parents=True, exist_ok=True)
    cmd = [timer, "-v", sys.executable, "-m", "semmatch", "reconstruct", str(args.recording), "--estimate-poses",
           "--out", str(tmp / "map.ply"), "--quiet", "--json", *args.extra]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if args.out is None:
        shutil.rmtree(tmp, ignore_errors=True)
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
    if proc.returncode != 0 or m is None:
        print(proc.stderr[-3000:], file=sys.stderr)
        print(f"error: semmatch reconstruct exited with {proc.returncode}", file=sys.stderr)
        return 1
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    row = {"recording": str(args.recording), "frames": len(seq), "size": f"{w}x{h}",
           "peak_rss_gib": round(int(m.group(1)) * 1024 / 2**30, 3), "wall_s": round(wall, 1),
           "flags": " ".join(args.extra), **{k: summary[k] for k in ("ate_rmse", "rpe_trans", "rpe_rot_deg", "vertices")
                                            if k in summary}}
    print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
