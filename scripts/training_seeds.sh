#!/usr/bin/env bash
# Every study again with networks from other training seeds (issue 35 item 8).
#
#   bash scripts/training_seeds.sh DATA CHECKPOINTS OUT SEED...
#
# DATA: the profile's data root after `make repro` (data/full): its scenes, its models/recipe.json
# (the mirror-averaging choice, applied to every seed) and the real-like chain's pose caches are
# reused (hard links / copies; nothing in DATA is written). CHECKPOINTS holds compact_sSEED.pt and
# strong_sSEED.pt, the full profile's configuration trained with seed SEED (e.g. by
# scripts/device_training/train_from_packed.py). For each SEED, notebooks 03-07 run with those
# networks on a data root OUT/sSEED and write OUT/figures_sSEED; then
#   python -m semmatch.experiments.training_seeds --run 0=figures/full --run 1=OUT/figures_s1 ...
# compares them with the shipped networks' run.
set -euo pipefail
[ $# -ge 4 ] || { sed -n 2,14p "$0" >&2; exit 2; }
data=$1 ckpts=$2 out=$3; shift 3
for s in "$@"; do
  for arch in compact strong; do
    [ -f "$ckpts/${arch}_s$s.pt" ] || { echo "error: $ckpts/${arch}_s$s.pt: no such checkpoint" >&2; exit 1; }
  done
done
[ -d "$data/scenes" ] && [ -f "$data/models/recipe.json" ] || { echo "error: $data: no scenes/ or models/recipe.json (run make repro first)" >&2; exit 1; }
for s in "$@"; do
  d=$out/s$s
  mkdir -p "$d/models" "$out/logs"
  [ -d "$d/scenes" ] || cp -al "$data/scenes" "$d/scenes"   # hard links: the stages replace files, never edit them
  cp "$ckpts/compact_s$s.pt" "$d/models/compact.pt"
  cp "$ckpts/strong_s$s.pt" "$d/models/strong.pt"
  cp "$data/models/recipe.json" "$d/models/"
  for sc in "$data"/real_like/*/; do   # the chain's odometry does not depend on the networks
    mkdir -p "$d/real_like/$(basename "$sc")"
    cp "$sc"/*_poses_*.txt "$d/real_like/$(basename "$sc")/" 2>/dev/null || true
  done
  for nb in 03_reconstruct_upper 04_label_transfer 05_evaluate_synthetic 06_height_study 07_real_data; do
    t=$(date +%s)
    python -m semmatch.experiments run "$nb" --profile full --data-root "$d" --figures-dir "$out/figures_s$s" \
      --reports-dir "$out/reports_s$s" --quiet > "$out/logs/s${s}_$nb.log" 2>&1
    echo "seed $s $nb: $(( $(date +%s) - t )) s" | tee -a "$out/logs/times.txt"
  done
done
