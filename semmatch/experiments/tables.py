"""Tables of results beside the paper's, and the paper's findings checked on our numbers."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..evaluate.metrics import MEASURES
from ..io import atomic_write_text
from .paper import PAPER_MODEL_OF, TABLE1_FPS, table2_frame, table3_frame

__all__ = [
    "MEASURES",
    "Finding",
    "save_table",
    "save_interval_table",
    "format_with_intervals",
    "spread_over_training_seeds",
    "with_paper_columns",
    "speed_table",
    "check_findings",
    "findings_markdown",
]



@dataclass
class Finding:
    """One finding of the paper and whether it holds on our numbers."""

    statement: str
    holds: bool
    evidence: str


def save_table(df: pd.DataFrame, figures_dir: str | Path, name: str, *, floatfmt: str = ".3f") -> tuple[Path, Path]:
    """Write ``<name>.csv`` and ``<name>.md`` into ``figures_dir`` (atomically)."""
    figures_dir = Path(figures_dir)
    figures_dir.mkdir(parents=True, exist_ok=True)
    csv, md = figures_dir / f"{name}.csv", figures_dir / f"{name}.md"
    atomic_write_text(csv, df.to_csv(index=False, float_format="%.4f"))
    atomic_write_text(md, markdown_table(df, floatfmt=floatfmt) + "\n")
    return csv, md


def markdown_table(df: pd.DataFrame, *, floatfmt: str = ".3f") -> str:
    """``df`` as a markdown table: float columns with ``floatfmt``, text exactly as it is.

    ``DataFrame.to_markdown`` re-reads text cells that look like numbers and prints them with
    ``floatfmt`` too (a learning rate kept as the text ``"0.0003"`` came out as ``0.000``);
    here only float columns are formatted, numbers are right-aligned and text left-aligned.

    Parameters
    ----------
    df : DataFrame
    floatfmt : str
        Format of the float columns' cells (``format(value, floatfmt)``).

    Returns
    -------
    str
        The table, without a trailing newline.
    """
    shown = df.copy()
    align = []
    for c in df.columns:
        col = df[c]
        numeric = pd.api.types.is_numeric_dtype(col) and not pd.api.types.is_bool_dtype(col)
        if pd.api.types.is_float_dtype(col):
            shown[c] = col.map(lambda v: format(v, floatfmt))
        align.append("right" if numeric else "left")
    return shown.to_markdown(index=False, disable_numparse=True, colalign=align)


def format_with_intervals(summary: pd.DataFrame, measures: Sequence[str] = MEASURES, *,
                          digits: int = 3) -> pd.DataFrame:
    """Each measure of a summary over scenes as ``"mean [lo, hi]"`` text.

    Parameters
    ----------
    summary : DataFrame
        Output of :func:`semmatch.experiments.summaries.summarize_over_scenes`.
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


def save_interval_table(summary: pd.DataFrame, figures_dir: str | Path, name: str, *,
                        measures: tuple[str, ...] = MEASURES, keep: tuple[str, ...] = ()) -> tuple[Path, Path]:
    """Write a table of means with 95 % intervals: ``<name>.csv`` numeric (``m``, ``m_lo``,
    ``m_hi``), ``<name>.md`` with ``mean [lo, hi]`` cells.

    Parameters
    ----------
    summary : DataFrame
        From :func:`semmatch.experiments.summaries.summarize_over_scenes`, optionally with
        ``paper_<measure>`` columns (:func:`with_paper_columns`).
    figures_dir : path
    name : str
    measures : tuple of str
        Measures shown with their intervals.
    keep : tuple of str
        Further columns shown with three decimals, a missing value blank (``paper_*`` columns
        always are).
    """
    figures_dir = Path(figures_dir)
    figures_dir.mkdir(parents=True, exist_ok=True)
    summary = summary.drop(columns=[c for c in ("paper_model",) if c in summary.columns])
    csv, md = figures_dir / f"{name}.csv", figures_dir / f"{name}.md"
    atomic_write_text(csv, summary.to_csv(index=False, float_format="%.4f"))
    shown = format_with_intervals(summary, measures)
    # the paper's values: a row the paper does not have (e.g. ``fused``) shows a blank
    extra = [c for c in summary.columns if c in keep or str(c).startswith("paper_")]
    for c in extra:
        shown[c] = summary[c].map(lambda v: "" if pd.isna(v) else f"{v:.3f}").values
    atomic_write_text(md, markdown_table(shown) + "\n")  # text cells as written ("0.800", not 0.8)
    return csv, md


def spread_over_training_seeds(summary: pd.DataFrame, measure: str = "mean_acc", *,
                               by: tuple[str, ...] = ("method",)) -> pd.DataFrame:
    """The spread of a measure over training seeds of one architecture (``compact``, ``compact@1``, ...).

    Parameters
    ----------
    summary : DataFrame
        Rows per network (column ``model``) and ``by`` with the measure averaged over scenes
        (e.g. :func:`semmatch.experiments.summaries.summarize_over_scenes`).
    measure : str
    by : tuple of str
        Further grouping columns (``method`` for Table 2, ``height`` for Fig. 3).

    Returns
    -------
    DataFrame
        One row per architecture with at least two seeds and ``by``: ``arch, <by>, seeds,
        mean, sd, min, max`` of the measure over the seeds; empty when no architecture has two.
    """
    from ..segment import network_spec

    rows = summary[summary["model"] != "ground truth"].copy()
    rows["arch"] = [network_spec(m)[0] for m in rows["model"]]
    out = rows.groupby(["arch", *by], sort=False)[measure].agg(["count", "mean", "std", "min", "max"]).reset_index()
    out = out.rename(columns={"count": "seeds", "std": "sd"})
    return out[out["seeds"] >= 2].reset_index(drop=True)


def with_paper_columns(ours: pd.DataFrame, table: int = 2) -> pd.DataFrame:
    """Add the paper's values as ``paper_<measure>`` columns.

    ``ours`` has columns ``model`` (ground truth / compact / strong), ``method`` (a transfer
    method, ``upper`` or ``lower``) and the measures; our networks are matched to the paper's
    (compact ~ Mask R-CNN, strong ~ Transfiner).
    """
    ref = (table2_frame() if table == 2 else table3_frame()).rename(
        columns={m: f"paper_{m}" for m in MEASURES}
    )
    ref = ref.rename(columns={"model": "paper_model"})
    out = ours.copy()
    out["paper_model"] = out["model"].map(lambda m: PAPER_MODEL_OF.get(m, m))
    out = out.merge(ref, on=["paper_model", "method"], how="left")
    return out


def speed_table(fps: dict[str, float], reference_fps: float | None = None) -> pd.DataFrame:
    """Table 1: our FPS per method beside the paper's, with the speed-ups."""
    rows = []
    for name, ours in fps.items():
        paper = TABLE1_FPS.get(name)
        rows.append(
            dict(
                method=name,
                fps=ours,
                ms_per_frame=1000.0 / ours if ours else float("nan"),
                paper_fps=paper,
                speedup_vs_paper=ours / paper if paper else float("nan"),
                speedup_vs_reference=ours / reference_fps if reference_fps else float("nan"),
            )
        )
    return pd.DataFrame(rows)


def _mean_acc(df: pd.DataFrame, model: str, method: str) -> float | None:
    sel = df[(df["model"] == model) & (df["method"] == method)]["mean_acc"]
    return float(sel.mean()) if len(sel) else None


def check_findings(df: pd.DataFrame, methods: list[str]) -> list[Finding]:
    """Check the paper's findings on a Table-2/3 style frame (averaged over scenes).

    1. Label transfer beats the lower-view network (for every network and every method).
    2. 3D neighbourhood has the best Mean Acc. among the transfer methods (per upper map).
    3. The lower-view network is worse than the upper-view one.
    """
    out: list[Finding] = []
    nets = [m for m in df["model"].unique() if m != "ground truth"]
    ev, ok = [], True
    for net in nets:
        low = _mean_acc(df, net, "lower")
        if low is None:
            continue
        for meth in methods:
            v = _mean_acc(df, net, meth)
            if v is None:
                continue
            ok &= v > low
            ev.append(f"{net}/{meth} {v:.3f} vs lower {low:.3f}")
    if ev:
        out.append(Finding("label transfer beats the lower-view network", bool(ok), "; ".join(ev)))
    ev, ok = [], True
    for model in df["model"].unique():
        scores = {m: _mean_acc(df, model, m) for m in methods}
        scores = {m: v for m, v in scores.items() if v is not None}
        if "3d-neighborhood" not in scores:
            continue
        best = max(scores, key=scores.get)
        ok &= scores["3d-neighborhood"] >= scores[best] - 1e-9
        ev.append(f"{model}: best {best} {scores[best]:.3f}, 3d-neighborhood {scores['3d-neighborhood']:.3f}")
    if ev:
        out.append(Finding("3D neighbourhood has the best Mean Acc.", bool(ok), "; ".join(ev)))
    ev, ok = [], True
    for net in nets:
        up, low = _mean_acc(df, net, "upper"), _mean_acc(df, net, "lower")
        if up is None or low is None:
            continue
        ok &= low < up
        ev.append(f"{net}: upper {up:.3f}, lower {low:.3f}")
    if ev:
        out.append(Finding("the lower-view network is worse than the upper-view one", bool(ok), "; ".join(ev)))
    return out


def findings_markdown(findings: list[Finding]) -> str:
    """Markdown list: each finding with holds / does not hold and the numbers behind it."""
    lines = []
    for f in findings:
        mark = "holds" if f.holds else "does NOT hold"
        lines.append(f"- **{f.statement}**: {mark} here ({f.evidence})")
    return "\n".join(lines) + "\n"
