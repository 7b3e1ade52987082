"""How often intervals over scenes, or over networks and scenes, cover the truth with three networks.

The analysis plan v2 (issue 52) draws its inference over scenes *and* trained networks (training
seeds 0, 1, 2 of each architecture). This simulation checks the candidate intervals as the v1
coverage study (:mod:`semmatch.experiments.coverage`) checked the v1 ones, on the **development**
scenes' per-scene differences only. A simulated study of one comparison (e.g. Table 3 compact
``3d-neighborhood - lower``) is a networks x scenes grid

    ``d[n, s] = x_s + a_n + e_ns``

with ``x_s`` a plasmode scene value (the comparison's kind mean plus a smoothed development
residual of that kind, :func:`semmatch.experiments.coverage._draw`), ``a_n ~ N(0, network_sd)``
the network's random effect (a training seed's offset, shared by every scene) and
``e_ns ~ N(0, interaction_sd)`` a network x scene interaction. The truth is the mean of the kind
means (the networks' effects average to zero over the population of training seeds).

Methods (:data:`METHODS`): ``v1-t`` (the v1 plan: t over scenes, one network), ``scenes-bootstrap``
(the three networks' average, scenes resampled, networks fixed: a one-level bootstrap),
``two-level-bootstrap`` (networks, then scenes), ``two-level-bootstrap-kinds`` (networks, then
scenes within their kinds) and ``two-component-t``
(:func:`semmatch.evaluate.stats.grid_two_component_t`).

``python -m semmatch.experiments.two_level_coverage [--out figures/inference] [--reps 400]``
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from ..evaluate.stats import grid_bootstrap, grid_two_component_t
from .coverage import _draw, development_comparisons

__all__ = ["METHODS", "NETWORK_SDS", "simulate_grid", "two_level_coverage_study", "two_level_coverage_summary",
           "plot_two_level_coverage", "main"]

#: the intervals compared
METHODS = ("v1-t", "scenes-bootstrap", "two-level-bootstrap", "two-level-bootstrap-kinds", "two-component-t")

#: between-network SDs simulated: none; the development spread of Table 3 compact
#: ``3d-neighborhood - lower`` over training seeds 0/1/2 (-0.072, -0.057, -0.037: SD 0.0176);
#: twice that
NETWORK_SDS = (0.0, 0.0176, 0.0352)


def simulate_grid(frame: pd.DataFrame, *, network_sd: float, interaction_sd: float, n_networks: int,
                  scenes_per_kind: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One simulated study: a networks x scenes grid of differences and each scene's kind.

    Parameters
    ----------
    frame : DataFrame
        One development comparison (:func:`~semmatch.experiments.coverage.development_comparisons`:
        columns ``kind`` and ``diff``).
    network_sd, interaction_sd : float
        SD of the network random effect and of the network x scene interaction.
    n_networks, scenes_per_kind : int
        Networks, and scenes of every kind.
    rng : numpy Generator

    Returns
    -------
    grid : ndarray (n_networks, scenes)
    kinds : ndarray of str (scenes,)
    """
    x, kinds = _draw(frame, "plasmode", scenes_per_kind, rng)
    a = rng.normal(0.0, network_sd, n_networks) if network_sd > 0 else np.zeros(n_networks)
    e = rng.normal(0.0, interaction_sd, (n_networks, x.size)) if interaction_sd > 0 else 0.0
    return x[None, :] + a[:, None] + e, kinds


def _intervals(grid: np.ndarray, kinds: np.ndarray, *, confidence: float, n_resamples: int,
               rng: np.random.Generator) -> dict[str, tuple[float, float, float]]:
    """``(lo, hi, lower)`` of every method of :data:`METHODS` on one simulated grid."""
    out = {}
    for name, networks, strata in (("scenes-bootstrap", False, None), ("two-level-bootstrap", True, None),
                                   ("two-level-bootstrap-kinds", True, kinds)):
        r = grid_bootstrap(grid, strata, confidence=confidence, n_resamples=n_resamples, seed=rng,
                           resample_networks=networks)
        out[name] = (r.lo, r.hi, r.lower)
    for name, rows in (("v1-t", grid[:1]), ("two-component-t", grid)):  # one network: the plain t over scenes
        r = grid_two_component_t(rows, confidence=confidence)
        out[name] = (r.lo, r.hi, r.lower)
    return {m: out[m] for m in METHODS}


def two_level_coverage_study(
    comparisons: dict[str, pd.DataFrame],
    *,
    network_sds: Sequence[float] = NETWORK_SDS,
    interaction_sd: float = 0.02,
    n_networks: int = 3,
    scenes_per_kind: int = 6,
    reps: int = 400,
    n_resamples: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
    progress: bool = True,
) -> pd.DataFrame:
    """Coverage of each interval of :data:`METHODS` on simulated networks x scenes studies.

    Parameters
    ----------
    comparisons : dict of str to DataFrame
        Development comparisons (:func:`~semmatch.experiments.coverage.development_comparisons`).
    network_sds : sequence of float, optional
        Between-network SDs simulated (:data:`NETWORK_SDS`).
    interaction_sd : float, optional
        SD of the network x scene interaction.
    n_networks : int, optional
        Trained networks per study (3: training seeds 0, 1, 2).
    scenes_per_kind : int, optional
        Scenes of each kind (6: the 24 scenes of a confirmatory run of four kinds).
    reps : int, optional
        Simulated studies per comparison and network SD.
    n_resamples : int, optional
        Resamples of each bootstrap interval.
    confidence : float, optional
        Nominal level of the two-sided intervals and of the one-sided lower bounds.
    seed : int, optional
        Seed of the simulation and of the resampling.
    progress : bool, optional
        Show a progress bar.

    Returns
    -------
    DataFrame
        One row per comparison, network SD and method: ``comparison, network_sd, method,
        coverage`` (two-sided interval contains the truth), ``lower_coverage`` (the one-sided
        lower bound lies at or below it), ``mean_width``.

    Raises
    ------
    ValueError
        Fewer than one network, a negative SD, or fewer than 2 scenes per kind.
    """
    if n_networks < 1 or scenes_per_kind < 2 or interaction_sd < 0 or min(network_sds, default=0) < 0:
        raise ValueError(f"two_level_coverage_study: need n_networks >= 1 (got {n_networks}), scenes_per_kind "
                         f">= 2 (got {scenes_per_kind}) and SDs >= 0 (got {list(network_sds)}, {interaction_sd})")
    rng = np.random.default_rng(seed)
    rows = []
    jobs = [(c, sd) for c in comparisons for sd in network_sds]
    for name, sd in tqdm(jobs, desc="two-level coverage", disable=not progress):
        frame = comparisons[name]
        truth = float(frame.groupby("kind")["diff"].mean().mean())
        hits = np.zeros((len(METHODS), 3))  # two-sided hit, one-sided hit, width
        for _ in range(reps):
            grid, kinds = simulate_grid(frame, network_sd=sd, interaction_sd=interaction_sd, n_networks=n_networks,
                                        scenes_per_kind=scenes_per_kind, rng=rng)
            for i, (lo, hi, lower) in enumerate(_intervals(grid, kinds, confidence=confidence,
                                                           n_resamples=n_resamples, rng=rng).values()):
                hits[i] += (lo <= truth <= hi, lower <= truth, hi - lo)
        rows += [dict(comparison=name, network_sd=sd, method=m, coverage=hits[i, 0] / reps,
                      lower_coverage=hits[i, 1] / reps, mean_width=hits[i, 2] / reps) for i, m in enumerate(METHODS)]
    return pd.DataFrame(rows)


def two_level_coverage_summary(study: pd.DataFrame) -> pd.DataFrame:
    """Mean and lowest coverage over comparisons, per network SD and method.

    Parameters
    ----------
    study : DataFrame
        From :func:`two_level_coverage_study`.

    Returns
    -------
    DataFrame
        ``network_sd, method, coverage_mean, coverage_min, lower_coverage_mean,
        lower_coverage_min, width_mean``.
    """
    g = study.groupby(["network_sd", "method"], sort=False)
    return g.agg(coverage_mean=("coverage", "mean"), coverage_min=("coverage", "min"),
                 lower_coverage_mean=("lower_coverage", "mean"), lower_coverage_min=("lower_coverage", "min"),
                 width_mean=("mean_width", "mean")).reset_index()


def plot_two_level_coverage(summary: pd.DataFrame, path: str | Path, *, confidence: float = 0.95) -> Path:
    """Coverage of each method against the between-network SD (two-sided and one-sided panels).

    Parameters
    ----------
    summary : DataFrame
        From :func:`two_level_coverage_summary`.
    path : path
        The figure (PNG), written atomically.
    confidence : float, optional
        The nominal level, drawn as a dashed line.

    Returns
    -------
    Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import save_figure

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, col, title in ((axes[0], "coverage_mean", "two-sided interval"),
                           (axes[1], "lower_coverage_mean", "one-sided lower bound")):
        for method, g in summary.groupby("method", sort=False):
            ax.plot(g["network_sd"], g[col], marker="o", label=method)
        ax.axhline(confidence, color="k", ls="--", lw=1)
        ax.set_xlabel("between-network SD (training seeds)")
        ax.set_title(f"{title}, nominal {confidence:.0%}")
    axes[0].set_ylabel("coverage (mean over comparisons)")
    axes[1].legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv: Sequence[str] | None = None) -> None:
    """``python -m semmatch.experiments.two_level_coverage``: the study on the development Table 3."""
    import argparse

    from .pipeline import ROOT
    from .tables import save_table

    ap = argparse.ArgumentParser(prog="python -m semmatch.experiments.two_level_coverage",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--tables", type=Path, default=ROOT / "figures" / "full",
                    help="folder with the development scenes' table3_per_scene.csv (default %(default)s)")
    ap.add_argument("--out", type=Path, default=ROOT / "figures" / "inference",
                    help="where the tables and the figure go (default %(default)s)")
    ap.add_argument("--reps", type=int, default=400, help="simulated studies per comparison and SD (default %(default)s)")
    ap.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples (default %(default)s)")
    ap.add_argument("--interaction-sd", type=float, default=0.02,
                    help="SD of the network x scene interaction (default %(default)s)")
    ap.add_argument("--seed", type=int, default=0, help="simulation seed (default %(default)s)")
    args = ap.parse_args(argv)
    f = args.tables / "table3_per_scene.csv"
    if not f.is_file():
        raise SystemExit(f"two_level_coverage: {f} is missing (run the full profile's notebook 07 first)")
    pairs = [(m, "lower") for m in ("2d-slic", "3d-slic", "3d-projected-sp", "dbscan", "3d-neighborhood")]
    comps = development_comparisons(pd.read_csv(f), pairs, label="table3")
    study = two_level_coverage_study(comps, reps=args.reps, n_resamples=args.resamples,
                                     interaction_sd=args.interaction_sd, seed=args.seed)
    save_table(study, args.out, "two_level_coverage_per_comparison")
    summary = two_level_coverage_summary(study)
    save_table(summary, args.out, "two_level_coverage")
    plot_two_level_coverage(summary, args.out / "two_level_coverage.png")
    print(summary.to_string(index=False))


if __name__ == "__main__":
    main()
