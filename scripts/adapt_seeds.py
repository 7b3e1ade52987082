"""Seed spread of the adapted networks (issue 38 item 1): stage 09's recipe and sources, fine-tuned
again with other seeds, scored as notebook 09 scores them.

Stage 09 fine-tunes the profile's network once per label source (seed 0, its shipped networks).
This script fine-tunes the same network on the same adaptation scenes with the same recipe (read
from the stage's ``validation_adapt_recipe.csv``) and sources, changing only the recipe's seed
(batch draws, augmentation, update order), then scores every seed on the stage's evaluation
sweeps (0.2 and 1.6 m) like notebook 09: per seed the gap table, and over seeds the mean, spread
and an interval that resamples scenes and seeds together. Nothing is chosen from these numbers.
Three phases, so that the fine-tunings can run as separate processes::

    python scripts/adapt_seeds.py prepare  [--data-root DIR] [--out DIR]           # the labelled robot frames
    python scripts/adapt_seeds.py finetune --seed 1 [--data-root DIR] [--out DIR]  # one seed, every source
    python scripts/adapt_seeds.py score --seeds 0 1 2 [--data-root DIR] [--out DIR] [--figures DIR]
    python scripts/adapt_seeds.py summarize [--figures DIR]   # the spread and bounds again, from score's tables

Seed 0 is the stage's own checkpoints (``DATA/adapted/``, checked to be that recipe and seed).
Checkpoints and the labelled frames go to ``--out`` (default ``<data-root>_adapt_seeds``), tables
and the figure to ``--figures`` (default ``figures/<profile>_adapt_seeds``).
"""

from __future__ import annotations

import argparse
import pickle
import time
from pathlib import Path

import numpy as np
import pandas as pd


def _recipe(p, seed: int):
    from semmatch.experiments.adapt_studies import stage_recipe

    try:
        return stage_recipe(p["stage_figures"], seed=seed)
    except (FileNotFoundError, ValueError) as e:
        raise SystemExit(str(e)) from None


def prepare(args, p) -> None:
    from semmatch.experiments.adapt import robot_views

    t = time.perf_counter()
    robot, quality = robot_views(p["data_root"], p["network"], p["sources"], kinds=p["kinds"],
                                 seeds=p["train_seeds"][:p["adapt_scenes"]], n_frames=p["n_frames"],
                                 voxel_size=p["voxel_size"], fused_base=p["fused_base"], seed=p["seed"])
    args.out.mkdir(parents=True, exist_ok=True)
    tmp = args.out / "robot_views.pkl.tmp"
    tmp.write_bytes(pickle.dumps((robot, quality)))
    tmp.rename(args.out / "robot_views.pkl")
    print(quality.round(3).to_string(), f"\nrobot views: {time.perf_counter() - t:.0f} s", flush=True)


def finetune(args, p) -> None:
    from semmatch.experiments.adapt import adapt_networks

    robot, _ = pickle.loads((args.out / "robot_views.pkl").read_bytes())  # written by `prepare` above
    t, c = time.perf_counter(), time.process_time()
    made = adapt_networks(p["data_root"], p["network"], robot, p["sources"], _recipe(p, args.seed),
                          out_dir=args.out / f"seed_{args.seed}")
    print(f"seed {args.seed}: {len(made)} fine-tunings, {time.perf_counter() - t:.0f} s wall, "
          f"{time.process_time() - c:.0f} s CPU", flush=True)


def _checkpoints(args, p, seed: int) -> dict[str, Path]:
    from semmatch.segment import load_model
    from semmatch.segment.adapt import adapted_name

    folder = Path(p["data_root"]) / "adapted" if seed == 0 else args.out / f"seed_{seed}"
    want = _recipe(p, seed)
    out = {}
    for s in p["sources"]:
        path = folder / f"{adapted_name(p['network'], s)}.pt"
        rec = load_model(path).info.get("adapted", {})
        if int(rec.get("seed", -1)) != seed or int(rec.get("steps", -1)) != want.steps or rec.get("label_source") != s:
            raise SystemExit(f"{path}: not {s} with the stage's recipe at seed {seed} (its record: {rec})")
        out[adapted_name(p["network"], s)] = path
    return out


def two_way_ratio_ci(gain: np.ndarray, gap: np.ndarray, *, n_resamples: int = 10000, seed: int = 0,
                     confidence: float = 0.95) -> tuple[float, float, float]:
    """Mean gain over mean gap of a (seeds, scenes) table, with a percentile interval that
    resamples seeds and scenes together (both with replacement, independently)."""
    rng = np.random.default_rng(seed)
    n_seed, n_scene = gain.shape
    est = float(gain.mean() / gap.mean())
    si = rng.integers(0, n_seed, (n_resamples, n_seed))
    sj = rng.integers(0, n_scene, (n_resamples, n_scene))
    ratios = np.array([gain[np.ix_(a, b)].mean() / gap[np.ix_(a, b)].mean() for a, b in zip(si, sj)])
    lo, hi = np.quantile(ratios, [(1 - confidence) / 2, (1 + confidence) / 2])
    return est, float(lo), float(hi)


def score(args, p) -> None:
    from semmatch.experiments.adapt import adapted_height_study, gap_table
    from semmatch.experiments.tables import save_table

    per_seed, gaps = [], []
    for seed in args.seeds:
        ps = adapted_height_study(p["data_root"], p["network"], _checkpoints(args, p, seed),
                                  frame_step=p["sweep_frame_step"], jobs=p["jobs"])
        per_seed.append(ps.assign(seed=seed))
        gaps.append(gap_table(ps, p["network"]).assign(seed=seed))
    figures = _figures(args, p)
    save_table(pd.concat(per_seed, ignore_index=True), figures, "adapt_seeds_height_per_scene")
    save_table(pd.concat(gaps, ignore_index=True), figures, "adapt_seeds_gap")
    summarize(args, p)


def _figures(args, p) -> Path:
    return args.figures or Path(f"{p['figures_dir']}_adapt_seeds")  # beside the stage's figures


def summarize(args, p) -> None:
    """The spread over seeds and the one-sided bounds, from the per-scene table that ``score`` wrote.

    Per source: the share of the gap closed by each seed, their SD, the ratio over seeds and
    scenes with an interval resampling both (:func:`two_way_ratio_ci`), and, for the mean over
    seeds, the one-sided 95 % lower bounds of stage 09's ``adapt_gap_bounds`` (Fieller's bound
    from the t over scenes, each scene's gain and gap averaged over the seeds first) and whether
    the gap's bound clears 60 %.
    """
    from semmatch.experiments.adapt import gap_bounds, per_scene_changes
    from semmatch.experiments.tables import save_table

    figures = _figures(args, p)
    per_scene = pd.read_csv(figures / "adapt_seeds_height_per_scene.csv")
    gaps = pd.read_csv(figures / "adapt_seeds_gap.csv")
    seeds = sorted(int(v) for v in per_scene["seed"].unique())
    keys = [c for c in ("model", "scene", "height") if c in per_scene.columns]
    seed_mean = per_scene.groupby(keys, sort=False)["miou"].mean().reset_index()  # gap_bounds measures mIoU
    bounds = gap_bounds(seed_mean, p["network"]).set_index("source")
    rows = []
    for source, g in gaps[gaps["source"] != "none (unadapted)"].groupby("source", sort=False):
        ch = []
        for s in seeds:
            c = per_scene_changes(per_scene[per_scene["seed"] == s], p["network"])
            ch.append(c[c["source"] == source].set_index("scene"))
        gain = np.stack([c["gain_low"].to_numpy() for c in ch])
        gap = np.stack([c["gap"].to_numpy() for c in ch])
        change = np.stack([c["change_high"].to_numpy() for c in ch])
        r = two_way_ratio_ci(gain, gap)
        b = bounds.loc[source]
        rows.append({"source": source, "seeds": len(seeds), "scenes": gain.shape[1],
                     "gap_closed_per_seed": " / ".join(f"{v:.0%}" for v in g["gap_closed"]),
                     "gap_closed_seed_sd": float(g["gap_closed"].std(ddof=1)),
                     "gap_closed": r[0], "gap_closed_lo": r[1], "gap_closed_hi": r[2],
                     "gap_closed_lower": float(b["gap_closed_lower"]), "clears_60": bool(b["clears_target"]),
                     "gain_low": float(gain.mean()), "change_high": float(change.mean()),
                     "change_high_seed_sd": float(change.mean(axis=1).std(ddof=1)),
                     "change_high_lower": float(b["change_high_lower"]), "scenes_losing": int(b["scenes_losing"])})
    spread = pd.DataFrame(rows)
    save_table(spread, figures, "adapt_seeds_spread")
    _plot(gaps, spread, figures / "adapt_seeds.png")
    print(spread.round(3).to_string(), flush=True)


def _plot(gaps: pd.DataFrame, spread: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    for i, row in spread.reset_index(drop=True).iterrows():
        g = gaps[gaps["source"] == row["source"]]
        ax.errorbar(i, row["gap_closed"], yerr=[[row["gap_closed"] - row["gap_closed_lo"]],
                                                [row["gap_closed_hi"] - row["gap_closed"]]],
                    fmt="s", color="#0072B2", ms=7, capsize=4, label="over seeds and scenes" if i == 0 else None)
        ax.scatter(np.full(len(g), i + 0.15), g["gap_closed"], color="#D55E00", s=18, zorder=3,
                   label="one seed" if i == 0 else None)
    ax.axhline(0.6, color="0.5", ls="--", lw=0.8)
    ax.set_xticks(range(len(spread)), spread["source"])
    ax.set_ylabel("share of the gap closed")
    ax.set_title("Adapted networks: fine-tuning seeds (95 % interval)")
    ax.legend(frameon=False, fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("phase", choices=["prepare", "finetune", "score", "summarize"])
    ap.add_argument("--profile", default=None, help="profile of params.yaml (default: its 'profile')")
    ap.add_argument("--data-root", type=Path, default=None, help="the pipeline's data root (default: the profile's)")
    ap.add_argument("--out", type=Path, default=None, help="labelled frames and checkpoints")
    ap.add_argument("--figures", type=Path, default=None, help="tables and figure")
    ap.add_argument("--stage-figures", type=Path, default=None,
                    help="stage 09's figures, with its validation_adapt_recipe.csv (default: the profile's)")
    ap.add_argument("--seed", type=int, default=1, help="finetune: the recipe's seed (default %(default)s)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="score: these seeds (0: the stage's)")
    args = ap.parse_args()
    from semmatch.experiments.adapt_studies import stage_parameters

    p = stage_parameters(args.profile, args.data_root)
    p["stage_figures"] = args.stage_figures or p["figures_dir"]
    args.out = args.out or Path(f"{p['data_root']}_adapt_seeds")
    {"prepare": prepare, "finetune": finetune, "score": score, "summarize": summarize}[args.phase](args, p)


if __name__ == "__main__":
    main()
