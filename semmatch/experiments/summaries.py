"""Intervals over scenes, and the analysis plan's secondary analyses that carry no verdict.

* :func:`summarize_over_scenes`: mean of each measure over scenes with the plan's interval
  (a t interval over scenes); :func:`semmatch.experiments.tables.format_with_intervals` writes
  it as text.
* :func:`support_regression` (secondary analysis S1): each method's gain over ``lower`` against
  the person's map's support.
* :func:`per_kind_means` (secondary analysis S3): means per scene kind.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..evaluate.metrics import MEASURES
from ..evaluate.stats import interval, scene_kind
from .analysis_plan import AnalysisPlan, load_analysis_plan

__all__ = ["summarize_over_scenes", "support_regression", "per_kind_means"]

#: columns that split a per-scene table into separate tables (never pooled)
_SPLITS = ("reference", "route")


def summarize_over_scenes(
    df: pd.DataFrame,
    measures: Sequence[str] = MEASURES,
    *,
    by: Sequence[str] = ("model", "method"),
    seed: int = 0,
    method: str | None = None,
    confidence: float | None = None,
) -> pd.DataFrame:
    """Mean of each measure over scenes per group, with the analysis plan's interval.

    Parameters
    ----------
    df : DataFrame
        Per-scene rows: a ``scene`` column, the ``by`` columns and the measures. A ``reference``
        or ``route`` column not in ``by`` that holds several values is added to the grouping
        (rows scored against different references, or on different robot routes, are never
        pooled); one holding a single value is left out.
    measures : sequence of str, optional
        Measure columns to summarise (those absent from ``df`` are left out).
    by : sequence of str, optional
        Grouping columns; groups keep their order of first appearance.
    seed : int, optional
        Seed of the bootstrap (bootstrap interval methods only).
    method : str, optional
        Interval method (:func:`semmatch.evaluate.stats.interval`); default the plan's (``t``). The
        ``stratified-*`` methods take the scene kinds from the ``scene`` column's names.
    confidence : float, optional
        Confidence level; default the plan's (0.95).

    Returns
    -------
    DataFrame
        The ``by`` columns, ``scenes`` (number of distinct scenes) and, per measure, the mean
        and ``<measure>_lo`` / ``<measure>_hi``; NaN where a group has no value of a measure.
    """
    by = list(by)
    by += [c for c in _SPLITS if c in df.columns and c not in by and df[c].nunique(dropna=False) > 1]
    missing = [c for c in by if c not in df.columns]
    if missing:
        raise ValueError(f"summarize_over_scenes: grouping columns {missing} are not in the frame")
    measures = [m for m in measures if m in df.columns]
    plan = load_analysis_plan()
    method = plan.interval if method is None else method
    confidence = plan.confidence if confidence is None else confidence
    rows = []
    for key, g in df.groupby(by, sort=False, dropna=False):
        row = dict(zip(by, key if isinstance(key, tuple) else (key,)))
        row["scenes"] = int(g["scene"].nunique()) if "scene" in g.columns else len(g)
        strata = [scene_kind(s) for s in g["scene"]] if "scene" in g.columns else None
        for m in measures:
            vals = g[m].to_numpy(dtype=np.float64)
            if np.isnan(vals).all():
                row[m] = row[f"{m}_lo"] = row[f"{m}_hi"] = np.nan
            else:
                row[m], row[f"{m}_lo"], row[f"{m}_hi"] = interval(vals, strata, method=method, confidence=confidence,
                                                                 seed=seed)
        rows.append(row)
    cols = [*by, "scenes", *(c for m in measures for c in (m, f"{m}_lo", f"{m}_hi"))]
    return pd.DataFrame(rows, columns=cols)


def support_regression(table2: pd.DataFrame, support: pd.DataFrame, *, plan: AnalysisPlan | None = None,
                       measure: str = "mean_acc") -> pd.DataFrame:
    """Secondary analysis S1: each method's per-scene gain over ``lower`` against the map's support.

    Parameters
    ----------
    table2 : DataFrame
        Per-scene Table 2 rows (``scene, model, method``, the measure; optional ``reference`` /
        ``route``: the plan's primary reference and route are used).
    support : DataFrame
        ``scene``, ``support`` (share of the robot's pixels the person's map supports) and
        optionally ``route``.
    plan : AnalysisPlan, optional
        Default the committed plan.
    measure : str, optional
        The measure of the gain.

    Returns
    -------
    DataFrame
        ``model, method, scenes, slope, slope_lo, slope_hi, intercept``: least-squares slope of
        the gain on support (gain per unit of support share) with its 95 % t interval (n - 2 df).
    """
    from scipy import stats as st

    plan = load_analysis_plan() if plan is None else plan
    t = table2
    if "reference" in t.columns:
        t = t[t["reference"] == plan.primary_reference]
    if "route" in t.columns:
        t = t[t["route"] == plan.route]
    s = support[support["route"] == plan.route] if "route" in support.columns else support
    s = s.set_index("scene")["support"]
    rows = []
    for model, g in t.groupby("model", sort=False):
        wide = g.pivot(index="scene", columns="method", values=measure)
        if "lower" not in wide.columns:
            continue
        for m in (c for c in wide.columns if c not in ("lower", "upper")):
            d = pd.DataFrame({"gain": wide[m] - wide["lower"], "support": s.reindex(wide.index)}).dropna()
            if len(d) < 3 or d["support"].nunique() < 2:
                continue
            fit = st.linregress(d["support"], d["gain"])
            half = float(st.t.ppf(0.5 + plan.confidence / 2, len(d) - 2)) * fit.stderr
            rows.append(dict(model=model, method=m, scenes=len(d), slope=fit.slope, slope_lo=fit.slope - half,
                             slope_hi=fit.slope + half, intercept=fit.intercept))
    return pd.DataFrame(rows, columns=["model", "method", "scenes", "slope", "slope_lo", "slope_hi", "intercept"])


def per_kind_means(per_scene: pd.DataFrame, measures: Sequence[str] = MEASURES,
                   by: Sequence[str] = ("model", "method")) -> pd.DataFrame:
    """Secondary analysis S3: the mean of each measure per scene kind (no verdicts).

    Parameters
    ----------
    per_scene : DataFrame
        Per-scene rows with a ``scene`` column (kinds from the scene names) and the ``by`` columns.
    measures : sequence of str, optional
        Measures averaged (those present).
    by : sequence of str, optional
        Grouping columns besides the kind (plus ``reference`` / ``route`` when present).

    Returns
    -------
    DataFrame
        The grouping columns, ``kind``, ``scenes`` and the measures' means.
    """
    df = per_scene.assign(kind=[scene_kind(s) for s in per_scene["scene"]])
    keys = [c for c in (*by, *_SPLITS) if c in df.columns] + ["kind"]
    measures = [m for m in measures if m in df.columns]
    g = df.groupby(keys, sort=False)
    out = g[measures].mean()
    out.insert(0, "scenes", g["scene"].nunique())
    return out.reset_index()
