"""How much the results move with the networks' training draw: the shipped networks against the
same configuration trained from other seeds, every study run again with each set.

A run is one figures folder written by notebooks 03-07 (``python -m semmatch.experiments run NN
--data-root D --figures-dir F``) with a data root whose ``models/`` holds one training seed's
networks; the shipped networks' run is the profile's own ``figures/<profile>/``. From each run
this module reads the per-scene tables of Table 2 (``table2_per_scene.csv``), Table 3
(``table3_per_scene.csv``) and Fig. 3 (``fig3_height_per_scene.csv``) and the claims' verdicts
(``verdicts_{synthetic,real,height}.csv``), and writes

* ``training_seeds_table2.csv`` / ``_table3`` / ``_fig3``: per network and row, each seed's mean
  over the scenes, their mean, standard deviation and range over the seeds, and beside them the
  half-width of the shipped run's 95 % interval over scenes (how the spread over training draws
  compares with the spread over scenes);
* ``training_seeds_verdicts.csv``: every claim's verdict with each seed's networks, and whether
  they agree;
* ``training_seeds.png``: the per-seed means of Tables 2 and 3, a panel per network.

``python -m semmatch.experiments.training_seeds --run 0=figures/full --run 1=F1 --run 2=F2
--out figures/full_training_seeds`` (``scripts/training_seeds.sh`` makes F1 and F2). The scenes
are the profile's development scenes: the study decides nothing.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["read_seed_runs", "seed_spread", "verdict_agreement", "plot_seed_spread", "write_seed_study", "main"]

#: per-scene tables of a run, with the columns that name a row (besides ``scene``)
PER_SCENE = {
    "table2": ("table2_per_scene.csv", ("model", "method")),
    "table3": ("table3_per_scene.csv", ("model", "method")),
    "fig3": ("fig3_height_per_scene.csv", ("model", "height")),
}
#: the rows every headline uses: Table 2 the robot's own tour, both tables the fusion reference
_HEADLINE = {"route": "own", "reference": "fusion"}
VERDICTS = ("verdicts_synthetic.csv", "verdicts_real.csv", "verdicts_height.csv")


def _headline(df: pd.DataFrame) -> pd.DataFrame:
    for col, keep in _HEADLINE.items():
        if col in df.columns:
            df = df[df[col] == keep]
    return df


def read_seed_runs(runs: Mapping[str, str | Path]) -> dict[str, pd.DataFrame]:
    """The per-scene tables and verdicts of every run, one frame per kind with a ``seed`` column.

    Parameters
    ----------
    runs : mapping
        Seed label (e.g. ``"0"``) -> figures folder of that seed's run.

    Returns
    -------
    dict
        ``table2``, ``table3``, ``fig3`` (headline rows only: own route, fusion reference) and
        ``verdicts``; a kind no run has is absent.

    Raises
    ------
    FileNotFoundError
        A run's folder is missing, or has none of the tables.
    """
    out: dict[str, list[pd.DataFrame]] = {}
    for seed, folder in runs.items():
        folder = Path(folder)
        if not folder.is_dir():
            raise FileNotFoundError(f"{folder}: no such figures folder (training seed {seed})")
        found = 0
        for kind, (name, _) in PER_SCENE.items():
            if (folder / name).is_file():
                out.setdefault(kind, []).append(_headline(pd.read_csv(folder / name)).assign(seed=str(seed)))
                found += 1
        for name in VERDICTS:
            if (folder / name).is_file():
                out.setdefault("verdicts", []).append(pd.read_csv(folder / name).assign(seed=str(seed)))
                found += 1
        if not found:
            raise FileNotFoundError(f"{folder}: none of {', '.join(n for n, _ in PER_SCENE.values())} or "
                                    f"{', '.join(VERDICTS)} (training seed {seed})")
    return {k: pd.concat(v, ignore_index=True) for k, v in out.items()}


def seed_spread(per_scene: pd.DataFrame, keys: Sequence[str], measure: str = "mean_acc", *,
                shipped: str = "0") -> pd.DataFrame:
    """Each seed's mean over scenes, and their spread over seeds, per row ``keys``.

    Parameters
    ----------
    per_scene : DataFrame
        Columns ``seed``, ``scene``, ``keys`` and ``measure``.
    keys : sequence of str
        The columns naming a row (``model, method`` or ``model, height``).
    measure : str
    shipped : str
        The seed label of the shipped networks: the half-width of the 95 % t interval over its
        scenes stands beside the spread (``scene_ci_half``).

    Returns
    -------
    DataFrame
        ``keys``, one column ``seed <label>`` per seed, ``seeds``, ``mean``, ``sd`` (over seeds),
        ``range`` (max - min) and ``scene_ci_half``; rows of the ground-truth map (the same with
        every seed) keep only their single value.
    """
    from scipy import stats

    keys = list(keys)
    means = per_scene.groupby([*keys, "seed"], sort=False)[measure].mean().unstack("seed")
    seeds = [str(s) for s in means.columns]
    out = means.copy()
    out.columns = [f"seed {s}" for s in seeds]
    out["seeds"] = means.notna().sum(axis=1)
    out["mean"] = means.mean(axis=1)
    out["sd"] = means.std(axis=1, ddof=1)
    out["range"] = means.max(axis=1) - means.min(axis=1)
    ship = per_scene[per_scene["seed"] == str(shipped)]

    def half(g: pd.Series) -> float:
        x = g.dropna().to_numpy(float)
        if len(x) < 2:
            return float("nan")
        return float(stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x)))

    out["scene_ci_half"] = ship.groupby(keys, sort=False)[measure].apply(half).reindex(out.index)
    return out.reset_index()


def verdict_agreement(verdicts: pd.DataFrame) -> pd.DataFrame:
    """Every claim's verdict with each seed's networks (``verdict`` and ``verdict_mesh``).

    Returns
    -------
    DataFrame
        ``claim, data, role``, one column per seed and reference (``seed 0``, ``seed 0 (mesh)``,
        ...; ``missing`` where a run has no verdict for the claim), ``agree`` (every seed has the
        same verdict under the fusion reference) and ``agree_mesh``.
    """
    seeds = list(dict.fromkeys(verdicts["seed"]))
    rows = []
    for (claim, data, role), g in verdicts.groupby(["claim", "data", "role"], sort=False):
        row = {"claim": claim, "data": data, "role": role}
        by_seed = g.set_index("seed")
        for s in seeds:
            have = s in by_seed.index
            row[f"seed {s}"] = by_seed.at[s, "verdict"] if have else "missing"
            row[f"seed {s} (mesh)"] = by_seed.at[s, "verdict_mesh"] if have and "verdict_mesh" in g else "-"
        complete = g["seed"].nunique() == len(seeds)  # a run without this claim cannot agree
        row["agree"] = bool(complete and g["verdict"].nunique() == 1)
        row["agree_mesh"] = bool(complete and ("verdict_mesh" not in g or g["verdict_mesh"].nunique() == 1))
        rows.append(row)
    return pd.DataFrame(rows)


def plot_seed_spread(spreads: Mapping[str, pd.DataFrame], path: str | Path):
    """Per-seed means of Table 2 and Table 3 (Mean Acc.), one panel per table and network; the
    bar is the shipped run's 95 % interval half-width over scenes, centred on the seeds' mean."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import save_figure

    panels = [(t, m) for t in ("table2", "table3") if t in spreads
              for m in spreads[t]["model"].unique() if m != "ground truth"]
    fig, axes = plt.subplots(1, max(len(panels), 1), figsize=(4.2 * max(len(panels), 1), 3.6), squeeze=False)
    for ax, (t, model) in zip(axes[0], panels):
        df = spreads[t][spreads[t]["model"] == model].reset_index(drop=True)
        y = np.arange(len(df))
        ax.errorbar(df["mean"], y, xerr=df["scene_ci_half"], fmt="none", ecolor="0.75", elinewidth=6,
                    label="95 % interval over scenes (shipped)")
        for k, col in enumerate(c for c in df.columns if c.startswith("seed ")):
            ax.plot(df[col], y, "o", ms=5, label=col.replace("seed", "training seed"), color=f"C{k}")
        ax.set_yticks(y, df["method"])
        ax.invert_yaxis()
        ax.set_xlabel("Mean Acc.")
        ax.set_title(f"{'Table 2 (synthetic)' if t == 'table2' else 'Table 3 (real-like)'}: {model}", fontsize=10)
        ax.grid(axis="x", alpha=0.3)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    return save_figure(fig, path)


def write_seed_study(runs: Mapping[str, str | Path], out: str | Path, *, shipped: str = "0") -> dict[str, Path]:
    """Read the runs (:func:`read_seed_runs`), write the spread tables, the verdicts and the figure.

    Returns
    -------
    dict
        Name -> path of every file written.
    """
    from .tables import save_table

    out = Path(out)
    data = read_seed_runs(runs)
    written, spreads = {}, {}
    for kind, (_, keys) in PER_SCENE.items():
        if kind in data:
            spreads[kind] = seed_spread(data[kind], keys, shipped=shipped)
            written[kind] = save_table(spreads[kind], out, f"training_seeds_{kind}")[0]
    if "verdicts" in data:
        written["verdicts"] = save_table(verdict_agreement(data["verdicts"]), out, "training_seeds_verdicts")[0]
    if "table2" in spreads or "table3" in spreads:
        written["figure"] = plot_seed_spread(spreads, out / "training_seeds.png")
    return written


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``--run LABEL=FIGURES_DIR`` (one per training seed), ``--out DIR``."""
    ap = argparse.ArgumentParser(prog="python -m semmatch.experiments.training_seeds",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", action="append", required=True, metavar="SEED=FIGURES_DIR",
                    help="a training seed's figures folder (repeat; the first is the shipped networks' run)")
    ap.add_argument("--out", required=True, help="folder for the tables and the figure")
    args = ap.parse_args(argv)
    runs = {}
    for r in args.run:
        seed, sep, folder = r.partition("=")
        if not sep or not seed or not folder:
            ap.error(f"--run {r!r}: give SEED=FIGURES_DIR")
        if seed in runs:
            ap.error(f"--run: seed {seed} given twice")
        runs[seed] = folder
    try:
        written = write_seed_study(runs, args.out, shipped=next(iter(runs)))
    except FileNotFoundError as e:
        ap.exit(1, f"error: {e}\n")
    for name, path in written.items():
        print(f"{name}: {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
