"""How often each interval method covers the truth with few scenes of four kinds (a simulation).

The analysis plan (``docs/analysis_plan.md``) chose its interval method from this study, run on
the **development** scenes' per-scene tables only. Each simulated "truth" is one paired
comparison of the development tables (e.g. ``3d-neighborhood - lower`` of the compact network
against the fusion reference): its per-kind means and its within-kind residuals. A simulated
study draws ``scenes_per_kind`` new scenes of every kind, each the kind's mean plus a residual:

* ``plasmode``: a development residual of that kind (centred, rescaled by ``sqrt(n/(n-1))`` to
  undo the centring's shrinkage) plus a Gaussian jitter of half the kind's spread (a smoothed
  bootstrap, so three development scenes per kind do not give a three-point distribution);
* ``heavy-tailed``: Student t with 3 degrees of freedom scaled to the kind's spread.

The true mean is the mean of the kind means (kinds in equal numbers, as every run simulates
them). Coverage is the share of simulated studies whose interval contains it.

``python -m semmatch.experiments.coverage [--out figures/inference] [--reps 1000]``
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from ..evaluate.stats import INTERVAL_METHODS, interval, scene_kind

__all__ = ["SCENARIOS", "development_comparisons", "coverage_study", "coverage_summary"]

SCENARIOS = ("plasmode", "heavy-tailed")


def development_comparisons(
    per_scene: pd.DataFrame,
    pairs: Sequence[tuple[str, str]],
    *,
    measure: str = "mean_acc",
    reference: str = "fusion",
    route: str = "own",
    label: str = "",
) -> dict[str, pd.DataFrame]:
    """Per-scene paired differences ``A - B`` of a per-scene table, one frame per comparison.

    Parameters
    ----------
    per_scene : DataFrame
        Columns ``scene, model, method`` and ``measure``; optional ``reference`` / ``route``.
    pairs : sequence of (str, str)
        The ``(A, B)`` methods compared, within each model.
    measure : str, optional
        The measure differenced.
    reference, route : str, optional
        Rows kept when the table has these columns.
    label : str, optional
        Prefix of the comparison names (e.g. ``"table2"``).

    Returns
    -------
    dict of str to DataFrame
        ``"<label> <model> A - B"`` -> columns ``scene, kind, diff``; comparisons without two
        scenes in every kind are left out.
    """
    df = per_scene
    if "reference" in df.columns:
        df = df[df["reference"] == reference]
    if "route" in df.columns:
        df = df[df["route"] == route]
    out: dict[str, pd.DataFrame] = {}
    for model, g in df.groupby("model", sort=False):
        wide = g.pivot(index="scene", columns="method", values=measure)
        for a, b in pairs:
            if a not in wide.columns or b not in wide.columns:
                continue
            d = (wide[a] - wide[b]).dropna()
            frame = pd.DataFrame({"scene": d.index, "kind": [scene_kind(s) for s in d.index], "diff": d.to_numpy()})
            if frame.groupby("kind").size().min() >= 2:
                out[f"{label} {model} {a} - {b}".strip()] = frame
    return out


def _draw(frame: pd.DataFrame, scenario: str, scenes_per_kind: int, rng: np.random.Generator
          ) -> tuple[np.ndarray, np.ndarray]:
    values, kinds = [], []
    for kind, g in frame.groupby("kind", sort=True):
        x = g["diff"].to_numpy(dtype=np.float64)
        m, s = x.mean(), x.std(ddof=1)
        if scenario == "plasmode":
            resid = (x - m) * np.sqrt(x.size / (x.size - 1))
            r = rng.choice(resid, scenes_per_kind) + rng.normal(0.0, 0.5 * s, scenes_per_kind)
        else:
            r = s * rng.standard_t(3, scenes_per_kind) / np.sqrt(3.0)  # t3 has variance 3
        values.append(m + r)
        kinds += [kind] * scenes_per_kind
    return np.concatenate(values), np.asarray(kinds)


def coverage_study(
    comparisons: dict[str, pd.DataFrame],
    *,
    scenes_per_kind: Sequence[int] = (3, 6),
    scenarios: Sequence[str] = SCENARIOS,
    methods: Sequence[str] = INTERVAL_METHODS,
    reps: int = 1000,
    n_resamples: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
    progress: bool = True,
) -> pd.DataFrame:
    """Coverage and width of each interval method on simulated studies.

    Parameters
    ----------
    comparisons : dict of str to DataFrame
        From :func:`development_comparisons` (columns ``kind`` and ``diff``).
    scenes_per_kind : sequence of int, optional
        Scenes of each kind per simulated study (3 and 6: 12 and 24 scenes of four kinds).
    scenarios : sequence of str, optional
        Residual models (:data:`SCENARIOS`).
    methods : sequence of str, optional
        Interval methods (:data:`semmatch.evaluate.stats.INTERVAL_METHODS`).
    reps : int, optional
        Simulated studies per comparison, scenario and size.
    n_resamples : int, optional
        Bootstrap resamples per interval (bootstrap methods).
    confidence : float, optional
        Nominal level.
    seed : int, optional
        Seed of the simulation (the bootstrap seeds derive from it).
    progress : bool, optional
        Show a progress bar.

    Returns
    -------
    DataFrame
        One row per comparison, scenario, size and method: ``comparison, scenario, scenes,
        method, coverage, mean_width``.
    """
    bad = [s for s in scenarios if s not in SCENARIOS]
    if bad:
        raise ValueError(f"coverage_study: unknown scenarios {bad}; valid: {SCENARIOS}")
    rng = np.random.default_rng(seed)
    rows = []
    jobs = [(c, sc, k) for c in comparisons for sc in scenarios for k in scenes_per_kind]
    for name, scenario, k in tqdm(jobs, desc="coverage", disable=not progress):
        frame = comparisons[name]
        truth = float(frame.groupby("kind")["diff"].mean().mean())
        hits = {m: 0 for m in methods}
        width = {m: 0.0 for m in methods}
        for r in range(reps):
            x, g = _draw(frame, scenario, k, rng)
            for m in methods:
                _, lo, hi = interval(x, g, method=m, confidence=confidence, n_resamples=n_resamples, seed=r)
                hits[m] += lo <= truth <= hi
                width[m] += hi - lo
        n_kinds = frame["kind"].nunique()
        rows += [dict(comparison=name, scenario=scenario, scenes=k * n_kinds, method=m,
                      coverage=hits[m] / reps, mean_width=width[m] / reps) for m in methods]
    return pd.DataFrame(rows)


def coverage_summary(study: pd.DataFrame) -> pd.DataFrame:
    """Mean and lowest coverage over comparisons, per scenario, study size and method.

    Parameters
    ----------
    study : DataFrame
        From :func:`coverage_study`.

    Returns
    -------
    DataFrame
        ``scenario, scenes, method, coverage_mean, coverage_min, width_mean``.
    """
    g = study.groupby(["scenario", "scenes", "method"], sort=False)
    return g.agg(coverage_mean=("coverage", "mean"), coverage_min=("coverage", "min"),
                 width_mean=("mean_width", "mean")).reset_index()


def main(argv: Sequence[str] | None = None) -> None:
    """``python -m semmatch.experiments.coverage``: the study on the development tables."""
    import argparse

    from .pipeline import ROOT
    from .tables import save_table

    ap = argparse.ArgumentParser(prog="python -m semmatch.experiments.coverage", description=__doc__.splitlines()[0])
    ap.add_argument("--tables", type=Path, default=ROOT / "figures" / "full",
                    help="folder with the development scenes' table2/table3 per-scene CSVs")
    ap.add_argument("--out", type=Path, default=ROOT / "figures" / "inference")
    ap.add_argument("--reps", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    pairs = [(m, "lower") for m in ("2d-slic", "3d-slic", "3d-projected-sp", "dbscan", "3d-neighborhood")]
    pairs += [("3d-neighborhood", "3d-projected-sp"), ("3d-projected-sp", "3d-slic"), ("3d-slic", "dbscan"),
              ("upper", "lower"), ("3d-neighborhood", "upper")]
    comps: dict[str, pd.DataFrame] = {}
    for table in ("table2", "table3"):
        f = args.tables / f"{table}_per_scene.csv"
        if not f.is_file():
            raise SystemExit(f"coverage: {f} is missing (run the full profile's notebooks 05 and 07 first)")
        comps.update(development_comparisons(pd.read_csv(f), pairs, label=table))
    study = coverage_study(comps, reps=args.reps, seed=args.seed)
    save_table(study, args.out, "coverage_per_comparison")
    summary = coverage_summary(study)
    save_table(summary, args.out, "coverage")
    print(summary.to_string(index=False))


if __name__ == "__main__":
    main()
