"""Adaptation on held-out scenes (issue 38 item 2): stage 09's recipe and sources, on scenes the
network never saw, scored as notebook 09 scores them and paired with the stage's own adaptation.

Stage 09 adapts on the network's own training scenes, where the person's maps come from in-sample
predictions. Here the adaptation scenes are :data:`semmatch.experiments.protocol.HELDOUT_ADAPT_SEEDS`
(24 scenes, 6 per kind, used by no profile and refused by ``make confirm``), so the person's maps
come from out-of-sample predictions. Everything else is the stage's: network, sources, frames per
tour, voxel size and the chosen recipe (``validation_adapt_recipe.csv``, seed 0); the human-height
share of each batch still comes from the network's training views. Nothing is chosen from these
numbers. Three phases::

    python scripts/adapt_heldout.py prepare  [--data-root DIR] [--out DIR] [--figures DIR]  # labelled frames, label quality
    python scripts/adapt_heldout.py finetune [--data-root DIR] [--out DIR]                  # one checkpoint per source
    python scripts/adapt_heldout.py score    [--data-root DIR] [--out DIR] [--figures DIR]  # height study, gap, pairing

``prepare`` writes the labels' quality per source and per class, beside the same for the stage's
adaptation scenes when ``--in-sample-views`` (``scripts/adapt_seeds.py prepare``'s
``robot_views.pkl``) exists. ``score`` scores the held-out checkpoints on the stage's evaluation
sweeps (0.2 and 1.6 m, the stage's frame step) and joins the stage's own per-scene table
(``adapt_height_per_scene.csv``; its unadapted rows must match these). Checkpoints and frames go to
``--out`` (default ``<data-root>_adapt_heldout``), tables and the figure to ``--figures`` (default
``figures/<profile>_adapt_heldout``).
"""

from __future__ import annotations

import argparse
import pickle
import time
from pathlib import Path

import numpy as np
import pandas as pd


def _figures(args, p) -> Path:
    return args.figures or Path(f"{p['figures_dir']}_adapt_heldout")


def _quality(robot, quality: pd.DataFrame, sources, where: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    """``robot_views``' coverage and agreement per source, and the per-class table, tagged ``where``."""
    from semmatch.experiments.adapt_studies import label_quality_by_class

    return (quality.assign(scenes=where)[["scenes", "source", "coverage", "agreement"]],
            label_quality_by_class(robot, sources).assign(scenes=where))


def prepare(args, p) -> None:
    from semmatch.experiments.adapt import robot_views
    from semmatch.experiments.adapt_studies import HELDOUT_ADAPT_SEEDS, check_heldout_seeds
    from semmatch.experiments.layout import Layout
    from semmatch.experiments.tables import save_table
    from semmatch.segment import load_model

    check_heldout_seeds(HELDOUT_ADAPT_SEEDS, load_model(Layout(p["data_root"]).model(p["network"])).info.get("train_config") or {})
    t = time.perf_counter()
    robot, quality = robot_views(p["data_root"], p["network"], p["sources"], kinds=p["kinds"], seeds=HELDOUT_ADAPT_SEEDS,
                           n_frames=p["n_frames"], voxel_size=p["voxel_size"], fused_base=p["fused_base"], seed=p["seed"])
    args.out.mkdir(parents=True, exist_ok=True)
    tmp = args.out / "robot_views.pkl.tmp"
    tmp.write_bytes(pickle.dumps(robot))
    tmp.rename(args.out / "robot_views.pkl")
    summary, per_class = _quality(robot, quality, p["sources"], "held-out")
    if args.in_sample_views.is_file():
        inside, inside_quality = pickle.loads(args.in_sample_views.read_bytes())  # our own scripts/adapt_seeds.py prepare
        s2, c2 = _quality(inside, inside_quality, p["sources"], "in-sample")
        summary, per_class = pd.concat([s2, summary], ignore_index=True), pd.concat([c2, per_class], ignore_index=True)
    else:
        print(f"{args.in_sample_views} absent: label quality of the held-out scenes only", flush=True)
    figures = _figures(args, p)
    save_table(summary, figures, "heldout_label_quality")
    save_table(per_class, figures, "heldout_label_quality_per_class")
    print(summary.round(3).to_string(), f"\nrobot views: {time.perf_counter() - t:.0f} s", flush=True)


def finetune(args, p) -> None:
    from semmatch.experiments.adapt import adapt_networks
    from semmatch.experiments.adapt_studies import stage_recipe

    robot = pickle.loads((args.out / "robot_views.pkl").read_bytes())  # written by `prepare` above
    t, c = time.perf_counter(), time.process_time()
    made = adapt_networks(p["data_root"], p["network"], robot, p["sources"], stage_recipe(p["figures_dir"]),
                          out_dir=args.out / "adapted")
    print(f"{len(made)} fine-tunings, {time.perf_counter() - t:.0f} s wall, {time.process_time() - c:.0f} s CPU",
          flush=True)


def _checkpoints(args, p) -> dict[str, Path]:
    from semmatch.experiments.adapt_studies import HELDOUT_ADAPT_SEEDS, HELDOUT_SUFFIX, stage_recipe
    from semmatch.segment import load_model
    from semmatch.segment.adapt import adapted_name

    want = stage_recipe(p["figures_dir"])
    out = {}
    for s in p["sources"]:
        path = args.out / "adapted" / f"{adapted_name(p['network'], s)}.pt"
        if not path.is_file():
            raise SystemExit(f"{path} is missing: run the finetune phase first")
        info = load_model(path).info
        rec = info.get("adapted", {})
        scenes = {int(n.rsplit("_", 1)[-1]) for n in rec.get("scenes", [])}  # scene names: KIND_SEED
        if rec.get("label_source") != s or int(rec.get("steps", -1)) != want.steps or int(rec.get("seed", -1)) != want.seed:
            raise SystemExit(f"{path}: not {s} with the stage's recipe (its record: {rec})")
        if scenes != set(HELDOUT_ADAPT_SEEDS):
            raise SystemExit(f"{path}: adapted on scenes {sorted(scenes)}, not the held-out ones")
        out[adapted_name(p["network"], s) + HELDOUT_SUFFIX] = path
    return out


def score(args, p) -> None:
    from semmatch.experiments.adapt import adapted_height_study, gap_bounds, gap_table
    from semmatch.experiments.adapt_studies import heldout_vs_in_sample
    from semmatch.experiments.tables import save_table
    from semmatch.segment.adapt import adapted_name

    stage_table = Path(p["figures_dir"]) / "adapt_height_per_scene.csv"
    if not stage_table.is_file():
        raise SystemExit(f"{stage_table}: run stage 09 (dvc repro -s adapt_robot_view) first")
    t = time.perf_counter()
    ps = adapted_height_study(p["data_root"], p["network"], _checkpoints(args, p), frame_step=p["sweep_frame_step"],
                              jobs=p["jobs"])
    stage = pd.read_csv(stage_table)
    stage = stage[stage["model"].isin([p["network"], *(adapted_name(p["network"], s) for s in p["sources"])])]
    mine, theirs = (x[x["model"] == p["network"]].set_index(["scene", "height"]).sort_index() for x in (ps, stage))
    if not np.allclose(mine.loc[theirs.index, "miou"], theirs["miou"], atol=6e-4):  # the stage's CSV rounds to 4 places
        raise SystemExit(f"{stage_table}: its unadapted rows differ from this scoring; it was made on other sweeps")
    both = pd.concat([stage, ps[ps["model"] != p["network"]]], ignore_index=True)
    figures = _figures(args, p)
    save_table(both, figures, "heldout_height_per_scene")
    save_table(gap_table(both, p["network"]), figures, "heldout_gap")
    save_table(gap_bounds(both, p["network"]), figures, "heldout_gap_bounds")
    pair = heldout_vs_in_sample(both, p["network"], p["sources"])
    save_table(pair, figures, "heldout_vs_in_sample")
    _plot(figures)
    print(pair.round(3).to_string(), f"\nscoring: {time.perf_counter() - t:.0f} s", flush=True)


def _plot(figures: Path) -> None:
    """Gap closed in-sample and held-out per source (95 % intervals), and the 3d-neighborhood labels'
    precision per class in both kinds of scenes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    gap = pd.read_csv(figures / "heldout_gap.csv")
    gap = gap[gap["source"] != "none (unadapted)"].reset_index(drop=True)
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 3.8), gridspec_kw={"width_ratios": [1, 1.6]})
    for i, row in gap.iterrows():
        held = row["source"].endswith("(held-out scenes)")
        a.errorbar(i, row["gap_closed"], yerr=[[row["gap_closed"] - row["gap_closed_lo"]], [row["gap_closed_hi"] - row["gap_closed"]]],
                   fmt="s" if held else "o", color="#D55E00" if held else "#0072B2", capsize=4)
    a.axhline(0.6, color="0.5", ls="--", lw=0.8)
    a.set_xticks(range(len(gap)), [s.replace(" (held-out scenes)", "\n(held-out)") for s in gap["source"]],
                 fontsize=7, rotation=30, ha="right")
    a.set_ylabel("share of the gap closed (mIoU)")
    a.set_title("in-sample (o) vs held-out (s) adaptation scenes", fontsize=9)
    q = figures / "heldout_label_quality_per_class.csv"
    per_class = pd.read_csv(q) if q.is_file() else pd.DataFrame(columns=["source", "category", "precision", "scenes"])
    nb = per_class[per_class["source"] == "3d-neighborhood"].pivot_table(index="category", columns="scenes", values="precision")
    if len(nb):
        nb.plot.bar(ax=b, color={"in-sample": "#0072B2", "held-out": "#D55E00"}, width=0.8)
        b.set_ylabel("precision of the labels")
        b.set_title("3d-neighborhood labels of the robot's frames, per class", fontsize=9)
        b.tick_params(axis="x", labelsize=7)
        b.legend(frameon=False, fontsize=8)
    fig.tight_layout()
    fig.savefig(figures / "heldout_adaptation.png", dpi=120)
    plt.close(fig)


def main() -> None:
    from semmatch.experiments.adapt_studies import stage_parameters

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("phase", choices=["prepare", "finetune", "score"])
    ap.add_argument("--profile", default=None, help="profile of params.yaml (default: its 'profile')")
    ap.add_argument("--data-root", type=Path, default=None, help="the pipeline's data root (default: the profile's)")
    ap.add_argument("--out", type=Path, default=None, help="labelled frames and checkpoints")
    ap.add_argument("--figures", type=Path, default=None, help="tables and figure")
    ap.add_argument("--in-sample-views", type=Path, default=None,
                    help="scripts/adapt_seeds.py prepare's robot_views.pkl (default <data-root>_adapt_seeds/robot_views.pkl)")
    args = ap.parse_args()
    p = stage_parameters(args.profile, args.data_root)
    root = Path(p["data_root"])
    args.out = args.out or root.with_name(root.name + "_adapt_heldout")
    args.in_sample_views = args.in_sample_views or root.with_name(root.name + "_adapt_seeds") / "robot_views.pkl"
    try:
        {"prepare": prepare, "finetune": finetune, "score": score}[args.phase](args, p)
    except (FileNotFoundError, ValueError) as e:
        raise SystemExit(f"adapt_heldout {args.phase}: {e}") from None


if __name__ == "__main__":
    main()
