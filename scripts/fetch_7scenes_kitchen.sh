#!/usr/bin/env bash
# Fetch 1000 real Kinect frames of the Microsoft 7-Scenes "red kitchen" for trying semmatch on real data.
#
# Usage: scripts/fetch_7scenes_kitchen.sh [DEST]
#
# The frames (frame-XXXXXX.color.jpg, .depth.png in millimetres, .pose.txt camera-to-world, and
# camera-intrinsics.txt; about 120 MB) are the data/ folder of the public repository
# andyzeng/tsdf-fusion-python. They are Microsoft's, not ours to redistribute: the script clones
# them into DEST, outside this repository (default: $SEMMATCH_7SCENES_HOME, else
# ~/.cache/semmatch/tsdf-fusion-python), and refuses a DEST inside it. It prints the data folder,
# which semmatch reads as a 7-Scenes recording:
#
#   semmatch reconstruct "$(scripts/fetch_7scenes_kitchen.sh)" --estimate-poses --out kitchen.ply
#
# Tests that need the frames look for them in $SEMMATCH_7SCENES (the data folder), else in
# ~/.cache/semmatch/tsdf-fusion-python/data, and are skipped when they are absent.
set -euo pipefail

dest="${1:-${SEMMATCH_7SCENES_HOME:-$HOME/.cache/semmatch/tsdf-fusion-python}}"
here="$(cd "$(dirname "$0")/.." && pwd -P)"
abs="$(realpath -m "$dest")"
case "$abs/" in
  "$here"/*) echo "error: $dest is inside the repository ($here); the frames must not be committed, choose a folder outside it" >&2
             exit 2 ;;
esac
if [ -f "$abs/data/frame-000999.depth.png" ]; then
  echo "$abs/data"
  exit 0
fi
if [ -e "$abs" ]; then
  echo "error: $abs exists but holds no complete data/ folder; remove it or choose another DEST" >&2
  exit 2
fi
mkdir -p "$(dirname "$abs")"
# only data/ (a sparse, shallow clone: the repository's other large files are not downloaded)
git clone --quiet --depth 1 --filter=blob:none --sparse https://github.com/andyzeng/tsdf-fusion-python "$abs" >&2
git -C "$abs" sparse-checkout set data >&2
if [ ! -f "$abs/data/frame-000999.depth.png" ]; then
  echo "error: the clone in $abs has no data/frame-000999.depth.png; the repository's layout changed?" >&2
  exit 1
fi
echo "$abs/data"
