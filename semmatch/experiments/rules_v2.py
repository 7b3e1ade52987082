"""The analysis plan v2's verdict rules (``rules: v2`` in a plan's YAML; docs/analysis_plan_v2.md).

* :func:`comparison_verdict_v2`: one comparison from its two-sided 95 % interval and the
  Holm-adjusted p-value of the wrong direction: ``against``, ``holds`` (the minimum-effect test:
  the lower bound beyond the SESOI), ``equivalent``, ``inconclusive``.
* :func:`claim_rule_v2`: the intersection-union rule (every comparison holds, no adjustment),
  ``refuted`` when any comparison is against.
* The intervals behind them (:func:`semmatch.experiments.claims.check_claims` calls
  ``_compare_v2``): when a table holds several networks per architecture, the plan's
  ``inference.interval``: the two-component t over networks and scenes
  (``semmatch.evaluate.stats.two_component_t_ci``, the plan's primary interval since the coverage
  study) or the two-level bootstrap (``two_level_bootstrap``); else a t interval over scenes; and
  the kind-cluster sensitivity (a t interval over the four kind means).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..evaluate.stats import (
    grid_two_component_t,
    holm,
    interval,
    network_scene_estimate,
    network_scene_grid,
    stratified_estimate,
    t_test_pvalue,
)
from .analysis_plan import AnalysisPlan

__all__ = ["COMPARISON_VERDICTS_V2", "CLAIM_VERDICTS_V2", "NETWORK_COLUMN", "comparison_verdict_v2",
           "claim_rule_v2"]

#: the v2 rules' comparison verdicts (``against``: significantly in the wrong direction)
COMPARISON_VERDICTS_V2 = ("holds", "against", "equivalent", "inconclusive")
#: the v2 rules' claim verdicts
CLAIM_VERDICTS_V2 = ("holds", "refuted", "equivalent", "inconclusive")
#: the column of per-scene tables naming the network's training seed (several networks per architecture)
NETWORK_COLUMN = "training_seed"


def _t_tests(d: np.ndarray, *, sesoi: float, confidence: float) -> dict:
    """One-sample t interval over ``d`` and the one-sided t p-values the rules read."""
    _, lo, hi = interval(d, None, method="t", confidence=confidence)
    return _estimate_tests(stratified_estimate(d), lo, hi, sesoi=sesoi)


def _two_component_tests(d: np.ndarray, networks: list, scenes: list, *, sesoi: float, confidence: float) -> dict:
    """The two-component t over networks and scenes (``semmatch.evaluate.stats.two_component_t_ci``:
    a network and a scene variance component, Welch-Satterthwaite df) and its one-sided p-values."""
    grid, _ = network_scene_grid(d, networks, scenes, None, fn="check_claims")
    r = grid_two_component_t(grid, confidence=confidence)
    return _estimate_tests(network_scene_estimate(grid), r.lo, r.hi, sesoi=sesoi)


def _estimate_tests(est, lo: float, hi: float, *, sesoi: float) -> dict:
    """The one-sided t p-values the rules read, from a mean with its standard error and df."""
    p = lambda null, alt: t_test_pvalue(est, null, alt)  # noqa: E731
    up, down = p(sesoi, "greater"), p(-sesoi, "less")
    return dict(diff=est.mean, lo=lo, hi=hi, df=est.df, p_pos=p(0.0, "greater"), p_neg=p(0.0, "less"),
                p_eq=max(p(-sesoi, "greater"), p(sesoi, "less")), p_beyond=min(1.0, 2 * min(up, down)),
                p_beyond1=min(up, down))


def _bound_pvalue(rejects, n_resamples: int, steps: int = 14) -> float:
    """The smallest level ``a`` at which ``rejects(a)`` (monotone in ``a``) holds, by bisection."""
    lo, hi = 1.0 / (n_resamples + 1.0), 1.0 - 1.0 / (n_resamples + 1.0)
    if rejects(lo):
        return lo
    if not rejects(hi):
        return 1.0
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if rejects(mid) else (mid, hi)
    return hi


def _bootstrap_tests(d: np.ndarray, strata: list[str], networks: list, scenes: list, *, sesoi: float,
                     plan: AnalysisPlan, seed: int) -> dict:
    """The two-level bootstrap's two-sided percentile interval and the one-sided p-values the rules
    read: ``p_neg`` (mean < 0) and ``p_beyond1`` (beyond the nearer margin), each the smallest level
    whose one-sided bound (the same resamples: a fixed seed) excludes the null. ``p_pos`` / ``p_eq``
    are not computed (the rules read the interval for them)."""
    from ..evaluate import stats

    boot = getattr(stats, "two_level_bootstrap", None)
    if boot is None:
        raise ValueError("check_claims: these per-scene tables hold several networks per architecture (training "
                         f"or fine-tuning seeds, e.g. column {NETWORK_COLUMN!r}); the v2 plan's interval needs "
                         "semmatch.evaluate.stats.two_level_bootstrap, which this code does not have")
    inf = plan.raw.get("inference", {})
    n, seed = int(inf.get("n_resamples", 10000)), int(inf.get("seed", seed))
    args = (np.asarray(d, np.float64), np.asarray(networks), np.asarray(scenes), np.asarray(strata))
    run = lambda confidence: boot(*args, confidence=confidence, n_resamples=n, seed=seed)  # noqa: E731
    main = run(plan.confidence)
    below = lambda null: _bound_pvalue(lambda a: run(1.0 - a).upper < null, n)  # noqa: E731
    above = lambda null: _bound_pvalue(lambda a: run(1.0 - a).lower > null, n)  # noqa: E731
    return dict(diff=float(main.mean), lo=float(main.lo), hi=float(main.hi), df=np.nan, p_pos=np.nan,
                p_neg=below(0.0), p_eq=np.nan, p_beyond=np.nan, p_beyond1=min(above(sesoi), below(-sesoi)))


def _compare_v2(d: np.ndarray, strata: list[str], networks: list | None, scenes: list | None, *, sesoi: float,
                plan: AnalysisPlan, seed: int) -> dict:
    """:func:`_compare` under the v2 plan: the plan's interval (the two-level bootstrap over several
    networks, else ``one_network_interval``) and the kind-cluster sensitivity (t over the kind means)."""
    several = networks is not None and len(set(networks)) > 1
    kind = plan.raw.get("inference", {}).get("interval", "two-component-t")
    if several and kind == "two-component-t":
        out = _two_component_tests(d, networks, scenes, sesoi=sesoi, confidence=plan.confidence)
        method = f"two-component t ({len(set(networks))} networks)"
    elif several:
        out = _bootstrap_tests(d, strata, networks, scenes, sesoi=sesoi, plan=plan, seed=seed)
        method = f"two-level bootstrap ({len(set(networks))} networks)"
    elif plan.one_network_interval == "t":
        out, method = _t_tests(d, sesoi=sesoi, confidence=plan.confidence), "t over scenes (one network)"
    else:
        raise ValueError(f"check_claims: one_network_interval {plan.one_network_interval!r} is not supported by the "
                         "v2 rules (only 't')")
    # rows of the ground truth (networks None) depend on no network: they are never provisional
    if networks is not None and len(set(networks)) < int(plan.raw.get("networks", {}).get("min_networks", 1)):
        method += "; provisional"
    kind_means = pd.Series(d).groupby(np.asarray(strata)).mean().to_numpy()
    cl = _t_tests(kind_means, sesoi=sesoi, confidence=plan.confidence) if len(kind_means) >= 2 else \
        dict(diff=float(kind_means.mean()), lo=np.nan, hi=np.nan, p_neg=np.nan, p_beyond1=np.nan)
    return dict(out, scenes=len(d), interval_method=method, cluster_diff=cl["diff"], cluster_lo=cl["lo"],
                cluster_hi=cl["hi"], cluster_p_neg=cl["p_neg"], cluster_p_beyond1=cl["p_beyond1"])


def comparison_verdict_v2(kind: str, lo: float, hi: float, p_against: float, *, sesoi: float, alpha: float) -> str:
    """One comparison's verdict under the v2 rules (:data:`COMPARISON_VERDICTS_V2`).

    Parameters
    ----------
    kind : str
        The claim's kind (``beats``, ``best``, ``worst`` read as beats; ``similar``).
    lo, hi : float
        The two-sided interval of the difference as the claim states it (positive supports a
        beats claim); NaN: not tested.
    p_against : float
        The Holm-adjusted (within the family) one-sided p-value of the wrong direction: ``A - B < 0``
        (beats) or ``|A - B| > sesoi`` beyond the nearer margin (similar).
    sesoi : float
        The smallest effect size of interest of the measure.
    alpha : float
        The one-sided level (0.025 in the v2 plan: the bounds of the two-sided 95 % interval).

    Returns
    -------
    str
        ``against`` if ``p_against <= alpha``; else ``holds`` if ``lo > sesoi`` (beats: the
        minimum-effect test) or ``-sesoi < lo`` and ``hi < sesoi`` (similar: TOST); else
        ``equivalent`` (beats) if the interval lies inside ``(-sesoi, sesoi)``; else ``inconclusive``.
    """
    if np.isnan(lo) or np.isnan(hi):
        return "inconclusive"
    if not np.isnan(p_against) and p_against <= alpha:
        return "against"
    inside = -sesoi < lo and hi < sesoi
    if kind == "similar":
        return "holds" if inside else "inconclusive"
    return "holds" if lo > sesoi else "equivalent" if inside else "inconclusive"


def claim_rule_v2(verdicts: Sequence[str], kind: str) -> str:
    """A claim's verdict from its comparisons' v2 verdicts (:data:`CLAIM_VERDICTS_V2`).

    ``refuted`` if any comparison is ``against``; ``holds`` if every comparison holds (the
    intersection-union test: each at the plan's level, no adjustment); ``equivalent`` if every
    comparison of a beats/best/worst claim is equivalent; else ``inconclusive``.
    """
    v = list(verdicts)
    if not v:
        return "inconclusive"
    if "against" in v:
        return "refuted"
    if all(x == "holds" for x in v):
        return "holds"
    if kind != "similar" and all(x == "equivalent" for x in v):
        return "equivalent"
    return "inconclusive"


def _judge_family_v2(fam: pd.DataFrame, kind: str, sesoi: float, alpha: float) -> pd.DataFrame:
    """The v2 columns of one family: Holm only in the wrong direction, the verdict, the minimum-effect
    flag and the kind-cluster verdict."""
    similar = kind == "similar"
    fam = fam.copy()
    fam["p_holds"] = fam["p_eq"] if similar else fam["p_pos"]  # unadjusted: intersection-union
    fam["p_against"] = holm(fam["p_beyond1"] if similar else fam["p_neg"])
    fam["p_equivalent"] = fam["p_eq"]
    fam["verdict"] = [comparison_verdict_v2(kind, lo, hi, pa, sesoi=sesoi, alpha=alpha)
                      for lo, hi, pa in zip(fam["lo"], fam["hi"], fam["p_against"])]
    fam["min_effect"] = fam["lo"] > sesoi if not similar else (fam["lo"] > -sesoi) & (fam["hi"] < sesoi)
    fam["beyond_zero"] = fam["lo"] > 0
    cluster_against = holm(fam["cluster_p_beyond1"] if similar else fam["cluster_p_neg"])
    fam["verdict_cluster"] = [comparison_verdict_v2(kind, lo, hi, pa, sesoi=sesoi, alpha=alpha)
                              for lo, hi, pa in zip(fam["cluster_lo"], fam["cluster_hi"], cluster_against)]
    return fam
