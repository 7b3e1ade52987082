"""Intervals over scenes, and a verdict with an interval for every comparative claim of the paper.

The per-scene tables of the pipeline (Table 2: synthetic, Table 3: real-like, Fig. 3: height
sweep) are summarised as means with 95 % percentile bootstrap intervals over scenes
(:func:`summarize_over_scenes`), and each comparative claim of the paper's §4-5 (:data:`CLAIMS`)
is judged on paired per-scene differences (:func:`check_claims`):

* ``beats`` (A beats B): *holds* if the interval of mean(A - B) lies above 0, *does not hold*
  if it lies below 0, else *not resolved*.
* ``best`` (A is best of a set): A - X for every other member X; *holds* if every interval is
  above 0, *does not hold* if any is below 0, else *not resolved*. ``worst`` (every other member
  beats A) is the same on X - A. One row per claim and model, showing the deciding competitor.
* ``similar`` (A similar to B, equivalence): *holds* if the interval of mean(A - B) lies inside
  ``(-margin, margin)``, *does not hold* if it lies entirely beyond ``margin`` or ``-margin``,
  else *not resolved*.

A comparison with fewer than ``min_scenes`` complete scene pairs is *not resolved* (one scene has
no spread to judge by). Claims whose data or methods are absent give no row.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..metrics import MEASURES
from ..stats import bootstrap_ci, paired_difference_ci

__all__ = [
    "MEASURES",
    "MEASURE_LABELS",
    "VERDICTS",
    "ALL_OTHERS",
    "TOP_HEIGHT",
    "Claim",
    "CLAIMS",
    "summarize_over_scenes",
    "format_with_intervals",
    "check_claims",
    "claims_markdown",
]

MEASURE_LABELS = {
    "jaccard": "Jaccard",
    "sorensen": "Sorensen",
    "color_acc": "Color Acc.",
    "mean_acc": "Mean Acc.",
    "miou": "mIoU",
}
VERDICTS = ("holds", "does not hold", "not resolved")

#: in :attr:`Claim.others`: every other transfer method (tables) or every other height (Fig. 3)
ALL_OTHERS = "<all others>"
#: in :attr:`Claim.others`: the highest camera height of the sweep
TOP_HEIGHT = "<top height>"

_GT = "ground truth"
#: columns that split a per-scene table into separate tables (never pooled)
_SPLITS = ("reference", "route")
_BASELINES = ("lower", "upper")
_DATA = {"synthetic": "table2", "real-like": "table3", "height sweep": "fig3"}
_KINDS = ("beats", "best", "worst", "similar")
_MODELS = ("networks", "ground truth", "all")


@dataclass(frozen=True)
class Claim:
    """One comparative claim of the paper and how it is judged.

    Attributes
    ----------
    id : str
        Short id (``C1`` ...).
    statement : str
        The claim in words.
    section : str
        Where the paper makes it.
    data : str
        ``"synthetic"`` (Table 2), ``"real-like"`` (Table 3) or ``"height sweep"`` (Fig. 3).
    kind : str
        ``"beats"``, ``"best"``, ``"worst"`` or ``"similar"`` (see the module docstring).
    subjects : tuple
        The A of the comparison: methods (``"lower"``, ``"upper"`` or a transfer method) or
        camera heights in metres; one comparison (row) per subject.
    others : tuple
        The B side: methods or heights, :data:`ALL_OTHERS` or :data:`TOP_HEIGHT`.
    measure : str
        The per-scene measure compared.
    models : str
        Upper maps the claim is judged for: ``"networks"``, ``"ground truth"`` or ``"all"``.
    """

    id: str
    statement: str
    section: str
    data: str
    kind: str
    subjects: tuple[str | float, ...]
    others: tuple[str | float, ...]
    measure: str = "mean_acc"
    models: str = "networks"

    def __post_init__(self) -> None:
        if self.data not in _DATA:
            raise ValueError(f"Claim {self.id}: data must be one of {tuple(_DATA)}, got {self.data!r}")
        if self.kind not in _KINDS:
            raise ValueError(f"Claim {self.id}: kind must be one of {_KINDS}, got {self.kind!r}")
        if self.models not in _MODELS:
            raise ValueError(f"Claim {self.id}: models must be one of {_MODELS}, got {self.models!r}")


_SP, _SLIC, _DB, _NB = "3d-projected-sp", "3d-slic", "dbscan", "3d-neighborhood"
_TRANSFER = ("2d-slic", _SLIC, _SP, _DB, _NB)

#: The comparative claims of the paper's §4-5 (and the abstract's summary of them). C16-C18 are
#: the sentences the first fifteen leave out: §5's "similar to the human perspective" on the real
#: recordings, and §4.3's "comparable results" and "fell short with the ground truth mesh".
CLAIMS: tuple[Claim, ...] = (
    Claim("C1", "every transfer method beats the lower-view network", "§4.3", "synthetic",
          "beats", _TRANSFER, ("lower",)),
    Claim("C2", "3D neighbourhood has the best Mean Acc. of the transfer methods, whatever the upper map",
          "§4.3", "synthetic", "best", (_NB,), (ALL_OTHERS,), models="all"),
    Claim("C3", "DBSCAN has the highest Color Acc. with network maps", "Table 2, §4.4", "synthetic",
          "best", (_DB,), (ALL_OTHERS,), measure="color_acc"),
    Claim("C4", "DBSCAN's Color Acc. is similar to the other methods' with network maps", "§4.3",
          "synthetic", "similar", (_DB,), (ALL_OTHERS,), measure="color_acc"),
    Claim("C5", "with the ground-truth map, 3D SLIC and 3D projected SP outperform DBSCAN", "§4.3",
          "synthetic", "beats", (_SLIC, _SP), (_DB,), models="ground truth"),
    Claim("C6", "3D SLIC and 3D projected SP perform similarly with network maps", "§4.3", "synthetic",
          "similar", (_SLIC,), (_SP,)),
    Claim("C7", "the lower-view network is worse than the upper-view one", "§1, abstract, Table 2",
          "synthetic", "beats", ("upper",), ("lower",)),
    Claim("C8", "transfer gives accuracy similar to the human perspective (3D neighbourhood vs upper map)",
          "abstract, §1, §5", "synthetic", "similar", (_NB,), ("upper",)),
    Claim("C9", "the networks perform worst at 0.2 m camera height", "§4.2, Fig. 3", "height sweep",
          "worst", (0.2,), (ALL_OTHERS,)),
    Claim("C10", "the best camera height is 0.8 m, with a slight decay above it", "§4.2, Fig. 3",
          "height sweep", "beats", (0.8,), (TOP_HEIGHT,)),
    Claim("C11", "3D neighbourhood has the best Mean Acc. of the transfer methods", "§4.4", "real-like",
          "best", (_NB,), (ALL_OTHERS,)),
    Claim("C12", "DBSCAN has the highest Color Acc.", "§4.4", "real-like", "best", (_DB,), (ALL_OTHERS,),
          measure="color_acc"),
    Claim("C13", "DBSCAN performs worse than the other methods", "§4.4", "real-like", "worst", (_DB,),
          (ALL_OTHERS,)),
    Claim("C14", "3D projected SP has a significantly higher Mean Acc. than 3D SLIC", "§4.4", "real-like",
          "beats", (_SP,), (_SLIC,)),
    Claim("C15", "every transfer method beats the lower-view network", "§4.4, Table 3", "real-like",
          "beats", _TRANSFER, ("lower",)),
    Claim("C16", "transfer gives accuracy similar to the human perspective (3D neighbourhood vs upper map)",
          "§5", "real-like", "similar", (_NB,), ("upper",)),
    Claim("C17", "3D SLIC and 3D projected SP give results comparable to DBSCAN with network maps",
          "§4.3", "synthetic", "similar", (_SLIC, _SP), (_DB,)),
    Claim("C18", "with the ground-truth map, DBSCAN's Color Acc. falls short of the other methods", "§4.3",
          "synthetic", "worst", (_DB,), (ALL_OTHERS,), measure="color_acc", models="ground truth"),
)


# ------------------------------------------------------------------------------------------------
# summaries over scenes


def summarize_over_scenes(
    df: pd.DataFrame,
    measures: Sequence[str] = MEASURES,
    *,
    by: Sequence[str] = ("model", "method"),
    seed: int = 0,
) -> pd.DataFrame:
    """Mean of each measure over scenes per group, with a 95 % bootstrap interval.

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
        Seed of the bootstrap (see :func:`semmatch.stats.bootstrap_ci`).

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
    rows = []
    for key, g in df.groupby(by, sort=False, dropna=False):
        row = dict(zip(by, key if isinstance(key, tuple) else (key,)))
        row["scenes"] = int(g["scene"].nunique()) if "scene" in g.columns else len(g)
        for m in measures:
            vals = g[m].to_numpy(dtype=np.float64)
            if np.isnan(vals).all():
                row[m] = row[f"{m}_lo"] = row[f"{m}_hi"] = np.nan
            else:
                row[m], row[f"{m}_lo"], row[f"{m}_hi"] = bootstrap_ci(vals, seed=seed)
        rows.append(row)
    cols = [*by, "scenes", *(c for m in measures for c in (m, f"{m}_lo", f"{m}_hi"))]
    return pd.DataFrame(rows, columns=cols)


def format_with_intervals(summary: pd.DataFrame, measures: Sequence[str] = MEASURES, *,
                          digits: int = 3) -> pd.DataFrame:
    """Each measure of a :func:`summarize_over_scenes` frame as ``"mean [lo, hi]"`` text.

    Parameters
    ----------
    summary : DataFrame
        Output of :func:`summarize_over_scenes`.
    measures : sequence of str, optional
        Measures to format (those without ``_lo``/``_hi`` columns are left out).
    digits : int, optional
        Decimals shown.

    Returns
    -------
    DataFrame
        The other columns unchanged, each measure as a string like ``0.913 [0.905, 0.921]``
        (``-`` where NaN), ready for ``to_markdown``.
    """
    measures = [m for m in measures if {m, f"{m}_lo", f"{m}_hi"} <= set(summary.columns)]
    out = summary.drop(columns=[c for m in measures for c in (f"{m}_lo", f"{m}_hi")])
    for m in measures:
        out[m] = [
            "-" if np.isnan(v) else f"{v:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"
            for v, lo, hi in zip(summary[m], summary[f"{m}_lo"], summary[f"{m}_hi"])
        ]
    return out


# ------------------------------------------------------------------------------------------------
# claims


def _level_name(level: str | float) -> str:
    return f"{level:g} m" if isinstance(level, float) else str(level)


def _per_scene(df: pd.DataFrame, level_col: str, measure: str, select: dict[str, str | None]) -> pd.DataFrame:
    """Rows of ``df`` to judge on: the chosen reference and route, columns scene/model/level/measure."""
    need = ["scene", "model", level_col, measure]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise ValueError(f"check_claims: a per-scene frame needs the columns {need}; {missing} missing")
    for col, value in select.items():
        if col in df.columns and value is not None:
            df = df[(df[col] == value) | df[col].isna()]
    df = df[need].copy()
    if level_col == "height":
        df["height"] = df["height"].astype(np.float64).round(3)
    dup = df.duplicated(["scene", "model", level_col])
    if dup.any():
        raise ValueError(
            f"check_claims: several rows per (scene, model, {level_col}), e.g. "
            f"{df.loc[dup, ['scene', 'model', level_col]].iloc[0].tolist()}; pass per-scene rows of "
            "one table (with 'reference' / 'route' columns when the frame holds several)"
        )
    return df


def _resolve(levels: tuple, available: list, *, top: float | None) -> list:
    out = []
    for lv in levels:
        if lv == ALL_OTHERS:
            out.extend(available)
        elif lv == TOP_HEIGHT:
            if top is not None:
                out.append(top)
        elif isinstance(lv, float):
            out.extend(a for a in available if np.isclose(a, lv))
        elif lv in available:
            out.append(lv)
    return list(dict.fromkeys(out))


def _verdict_pair(kind: str, lo: float, hi: float, n: int, margin: float, min_scenes: int) -> str:
    if n < min_scenes:
        return "not resolved"
    if kind == "similar":
        if lo > -margin and hi < margin:
            return "holds"
        if lo > margin or hi < -margin:
            return "does not hold"
        return "not resolved"
    if lo > 0:
        return "holds"
    if hi < 0:
        return "does not hold"
    return "not resolved"


def check_claims(
    table2: pd.DataFrame | None = None,
    table3: pd.DataFrame | None = None,
    fig3: pd.DataFrame | None = None,
    *,
    methods: Sequence[str],
    margin: float = 0.02,
    seed: int = 0,
    reference: str | None = "fusion",
    route: str | None = "own",
    confidence: float = 0.95,
    n_resamples: int = 10000,
    min_scenes: int = 2,
    claims: Sequence[Claim] = CLAIMS,
) -> pd.DataFrame:
    """Judge the paper's comparative claims on paired per-scene differences.

    Parameters
    ----------
    table2, table3 : DataFrame, optional
        Per-scene Table 2 (synthetic) / Table 3 (real-like) rows: ``scene``, ``model``,
        ``method`` (a transfer method, ``lower`` or ``upper``), optionally ``reference``, and
        the measures. Rows of other methods (e.g. ``fused``) are ignored.
    fig3 : DataFrame, optional
        Per-scene height sweep: ``model``, ``scene``, ``height`` (m) and ``mean_acc``.
    methods : sequence of str
        The transfer methods configured; a claim on a method not listed (or without rows) is
        skipped, and "the other methods" are the listed ones.
    margin : float, optional
        Equivalence margin of the ``similar`` claims, in units of the measure.
    seed : int, optional
        Seed of the bootstrap.
    reference : str or None, optional
        When a table has a ``reference`` column, judge on rows with this reference (and rows
        whose reference is missing); None keeps every row.
    route : str or None, optional
        The same for a ``route`` column (``own``: the robot's own tour, the main protocol).
    confidence : float, optional
        Confidence level of the intervals.
    n_resamples : int, optional
        Bootstrap resamples per interval.
    min_scenes : int, optional
        A comparison over fewer complete scene pairs is "not resolved".
    claims : sequence of Claim, optional
        The claims to judge (default: :data:`CLAIMS`).

    Returns
    -------
    DataFrame
        One row per claim and model (and per subject/other pair for ``beats``/``similar``):
        ``claim, statement, section, data, model, measure, comparison, diff, lo, hi, scenes,
        verdict``. ``diff`` is the mean paired difference as written in ``comparison`` (positive
        supports a beats/best/worst claim), ``lo``/``hi`` its interval, ``scenes`` the pairs used.
    """
    frames = {"table2": table2, "table3": table3, "fig3": fig3}
    kw = dict(confidence=confidence, n_resamples=n_resamples, seed=seed)
    allowed = set(methods) | set(_BASELINES)
    rows: list[dict] = []
    for claim in claims:
        src = frames[_DATA[claim.data]]
        if src is None or claim.measure not in src.columns:
            continue
        heights = claim.data == "height sweep"
        level_col = "height" if heights else "method"
        df = _per_scene(src, level_col, claim.measure, {} if heights else {"reference": reference, "route": route})
        for model in df["model"].unique():
            if (claim.models == "networks" and model == _GT) or (claim.models == "ground truth" and model != _GT):
                continue
            wide = df[df["model"] == model].pivot(index="scene", columns=level_col, values=claim.measure)
            wide = wide.dropna(axis=1, how="all")
            if heights:
                available = sorted(float(h) for h in wide.columns)
                top = available[-1] if available else None
                pool = available
            else:
                available = [m for m in wide.columns if m in allowed]
                top = None
                pool = [m for m in methods if m in available]  # "the other methods"
            subjects = _resolve(claim.subjects, available, top=top)
            others = _resolve(claim.others, pool if ALL_OTHERS in claim.others else available, top=top)
            base = dict(claim=claim.id, statement=claim.statement, section=claim.section, data=claim.data,
                        model=model, measure=claim.measure)
            extra = ""
            if heights and available:
                means = wide.mean(axis=0)
                extra = f"; highest mean at {_level_name(float(means.idxmax()))}"
            for a in subjects:
                comps = []
                for b in others:
                    if b == a:
                        continue
                    first, second = (b, a) if claim.kind == "worst" else (a, b)
                    x = wide[first].to_numpy(dtype=np.float64)
                    y = wide[second].to_numpy(dtype=np.float64)
                    n = int((~(np.isnan(x) | np.isnan(y))).sum())
                    if n == 0:
                        continue
                    d, lo, hi = paired_difference_ci(x, y, **kw)
                    text = f"{_level_name(first)} - {_level_name(second)}"
                    comps.append(dict(comparison=text, diff=d, lo=lo, hi=hi, scenes=n,
                                      verdict=_verdict_pair(claim.kind, lo, hi, n, margin, min_scenes)))
                if not comps:
                    continue
                if claim.kind in ("beats", "similar"):
                    for c in comps:
                        rows.append({**base, **c, "comparison": c["comparison"] + extra})
                    continue
                # best / worst: every comparison must hold; show the deciding one
                k = len(comps)
                against = [c for c in comps if c["verdict"] == "does not hold"]
                open_ = [c for c in comps if c["verdict"] == "not resolved"]
                if against:
                    verdict, pick = "does not hold", min(against, key=lambda c: c["diff"])
                    note = f"{len(against)} of {k} against the claim"
                elif open_:
                    verdict, pick = "not resolved", min(open_, key=lambda c: c["diff"])
                    note = f"closest unresolved of {k}"
                else:
                    verdict, pick = "holds", min(comps, key=lambda c: c["diff"])
                    note = f"closest of {k}"
                rows.append({**base, **pick, "comparison": f"{pick['comparison']} ({note}){extra}",
                             "verdict": verdict})
    cols = ["claim", "statement", "section", "data", "model", "measure", "comparison", "diff", "lo", "hi",
            "scenes", "verdict"]
    return pd.DataFrame(rows, columns=cols)


def claims_markdown(df: pd.DataFrame, *, digits: int = 3) -> str:
    """A Markdown table of :func:`check_claims` results, the claims' wording and a verdict count.

    Parameters
    ----------
    df : DataFrame
        Output of :func:`check_claims`.
    digits : int, optional
        Decimals of the differences.

    Returns
    -------
    str
        The table (claim, data, model, measure, comparison, difference with interval, scenes,
        verdict), a line counting the verdicts and a list of the claims' statements.
    """
    if df.empty:
        return "No claim could be judged (no per-scene data for any of them).\n"

    def fmt(v: float) -> str:
        return f"{v:+.{digits}f}"

    table = pd.DataFrame({
        "claim": df["claim"],
        "data": df["data"],
        "model": df["model"],
        "measure": df["measure"].map(lambda m: MEASURE_LABELS.get(m, m)),
        "comparison": df["comparison"],
        "difference [95% CI]": [f"{fmt(d)} [{fmt(lo)}, {fmt(hi)}]" for d, lo, hi in
                                zip(df["diff"], df["lo"], df["hi"])],
        "scenes": df["scenes"],
        "verdict": df["verdict"],
    })
    counts = df["verdict"].value_counts()
    summary = ", ".join(f"{int(counts.get(v, 0))} {v}" for v in VERDICTS)
    legend = df.drop_duplicates("claim")[["claim", "statement", "section", "data"]]
    lines = [table.to_markdown(index=False), "", f"Verdicts over {len(df)} rows: {summary}.", ""]
    lines += [f"- **{r.claim}** ({r.data}, {r.section}): {r.statement}" for r in legend.itertuples()]
    return "\n".join(lines) + "\n"
