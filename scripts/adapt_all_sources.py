"""Which transfer method gives the best training labels? Every label source with the profile's recipe.

The full profile's stage 09 adapts with three sources (``3d-neighborhood``, self-training,
ground truth) to fit its time budget. This script adapts the profile's network with **every**
source (:data:`semmatch.segment.adapt.LABEL_SOURCES`), with the recipe stage 09 used (the profile's
``steps``, ``batch_size`` and the chosen ``lr`` / ``upper_share`` / ``distill`` read from the
stage's ``validation_adapt_recipe.csv``), on the same adaptation scenes, and scores them as
notebook 09 does on the **evaluation** scenes: the gap table (paired per-scene differences, 95 %
intervals) and the adapted networks' own lower maps against transfer and ``fused``. Nothing is
chosen from these numbers; they are reported (docs/adapt.md). Run after ``dvc repro`` (stage 09
must have run: its checkpoints of the three sources are reused after a provenance check)::

    python scripts/adapt_all_sources.py [--profile full]

Checkpoints go to ``data/<profile>_adapt_sources/`` (not the stage's outputs), tables and the
figure to ``figures/<profile>_adapt_sources/``. About 40 minutes on 2 cores (five fine-tunings).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def main() -> None:
    import pandas as pd

    from semmatch.experiments.adapt import (
        adapt_networks,
        adapted_height_study,
        adapted_lower_maps,
        gap_table,
        load_adapted,
        robot_map_comparison,
        robot_views,
    )
    from semmatch.experiments.pipeline import notebook_parameters
    from semmatch.experiments.summaries import summarize_over_scenes
    from semmatch.experiments.tables import save_interval_table, save_table
    from semmatch.plots import plot_height_study
    from semmatch.segment.adapt import LABEL_SOURCES, AdaptRecipe, adapted_name

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default=None, help="profile of params.yaml (default: its 'profile')")
    args = ap.parse_args()
    p = notebook_parameters("09_adapt_robot_view", args.profile)
    root, network, stage_figures = Path(p["data_root"]), p["network"], Path(p["figures_dir"])
    out = Path(f"{root}_adapt_sources")
    figures = Path(f"{stage_figures}_adapt_sources")
    recipe_csv = stage_figures / "validation_adapt_recipe.csv"
    if not recipe_csv.is_file():
        raise FileNotFoundError(f"{recipe_csv}: run stage 09 (dvc repro -s adapt_robot_view) first")
    chosen = pd.read_csv(recipe_csv)
    chosen = chosen[chosen["chosen"].astype(bool)].iloc[0]
    recipe = AdaptRecipe.from_mapping(chosen, seed=p["seed"])
    print("recipe (stage 09's):", recipe, flush=True)

    t0 = time.time()
    robot, quality = robot_views(root, network, LABEL_SOURCES, kinds=p["kinds"],
                                 seeds=p["train_seeds"][:p["adapt_scenes"]], n_frames=p["n_frames"],
                                 voxel_size=p["voxel_size"], fused_base=p["fused_base"], seed=p["seed"])
    save_table(quality, figures, "adapt_label_quality")
    print(f"robot views: {time.time() - t0:.0f} s", flush=True)
    stage = {s: root / "adapted" / f"{adapted_name(network, s)}.pt" for s in LABEL_SOURCES}
    reuse = {s: path for s, path in stage.items() if path.is_file()}
    t0 = time.time()
    checkpoints = adapt_networks(root, network, robot, LABEL_SOURCES, recipe, reuse=reuse, out_dir=out)
    print(f"fine-tunings ({len(LABEL_SOURCES) - len(reuse)} new, {len(reuse)} reused): {time.time() - t0:.0f} s",
          flush=True)

    per_scene = adapted_height_study(root, network, checkpoints, frame_step=p["sweep_frame_step"], jobs=p["jobs"])
    save_table(per_scene, figures, "adapt_height_per_scene")
    summary = summarize_over_scenes(per_scene, ("mean_acc", "miou"), by=("model", "height"))
    plot_height_study(summary, figures / "adapt_height.png",
                      title="Adapted with every label source (evaluation scenes, 95% interval)")
    gaps = gap_table(per_scene, network)
    save_interval_table(gaps, figures, "adapt_gap",
                        measures=("miou@0.2", "miou@1.6", "gain_low", "change_high", "gap_closed"))
    print(gaps.round(3).to_string(), flush=True)

    rows = adapted_lower_maps(root, load_adapted(root, network, checkpoints), voxel_size=p["voxel_size"],
                              eval_voxel_size=p["eval_voxel_size"], jobs=p["jobs"])
    t2 = pd.read_csv(stage_figures / "table2_per_scene.csv")
    t2 = t2[(t2["model"] == network) & (t2["reference"] == "fusion") & (t2["route"] == "own")
            & t2["method"].isin(["lower", p["fused_base"], "fused"])]
    both = pd.concat([t2[["scene", "model", "method", "jaccard", "sorensen", "color_acc", "mean_acc"]], rows])
    save_table(both, figures, "table2_adapted_per_scene")
    save_interval_table(summarize_over_scenes(both, by=("model", "method")), figures, "table2_adapted")
    comparison = robot_map_comparison(both, network, against=(p["fused_base"], "fused"))
    save_table(comparison, figures, "table2_adapted_vs_transfer")
    print(comparison.round(3).to_string(), flush=True)


if __name__ == "__main__":
    main()
