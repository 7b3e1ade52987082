"""A verdict for every comparative claim of the paper by the analysis plan.

The analysis plan (:mod:`semmatch.experiments.analysis_plan`) fixes the claims, their
comparisons and measures, the references, the smallest effect size of interest (SESOI) per
measure, the multiplicity rule and the verdict rules; the functions here apply it.

* :func:`check_claims`: every comparison of every claim, under each reference, on paired
  per-scene differences: the mean difference with its 95 % interval, Holm-adjusted one-sided
  tests within the claim's family (its comparisons under one reference), a verdict (``holds``,
  ``does not hold``, ``equivalent`` within the SESOI, ``inconclusive``) and the paper's own
  difference with whether it lies inside our interval.
* :func:`claim_verdicts`: one verdict per claim and reference by the plan's claim rule, and
  :func:`verdict_table` the claims with the primary and the secondary reference side by side.
* :func:`judge_speed_claims`: the paper's speed statements on Table 1.
* :func:`judge_figures`: all of it on one run's per-scene tables, in one verdict table, with the
  secondary analyses of :mod:`semmatch.experiments.summaries`.

The plan's names (:func:`load_analysis_plan`, :class:`Claim` ...), the summaries over scenes
(:func:`summarize_over_scenes` ...) and :func:`~semmatch.experiments.tables.format_with_intervals`
were defined here before; they are importable from here as before.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..evaluate.metrics import MEASURES
from ..evaluate.stats import holm, interval, scene_kind, stratified_estimate, t_test_pvalue
from .analysis_plan import (
    _DATA,
    ALL_OTHERS,
    CLAIMS,
    FRAMES_REFERENCE,
    MEASURE_LABELS,
    PLAN_FILE,
    PLAN_V2_FILE,
    TOP_HEIGHT,
    VERDICTS,
    AnalysisPlan,
    Claim,
    load_analysis_plan,
)
from .paper import FIG3_MEAN_ACC, PAPER_MODEL_OF, TABLE2, TABLE3
from .rules_v2 import (
    CLAIM_VERDICTS_V2,
    COMPARISON_VERDICTS_V2,
    NETWORK_COLUMN,
    _compare_v2,
    _judge_family_v2,
    claim_rule_v2,
    comparison_verdict_v2,
)
from .speed_claims import bench_speed_table, judge_speed_claims
from .summaries import per_kind_means, summarize_over_scenes, support_regression
from .tables import format_with_intervals, save_table

__all__ = [
    "MEASURES",
    "MEASURE_LABELS",
    "VERDICTS",
    "ALL_OTHERS",
    "TOP_HEIGHT",
    "PLAN_FILE",
    "FRAMES_REFERENCE",
    "Claim",
    "AnalysisPlan",
    "load_analysis_plan",
    "CLAIMS",
    "summarize_over_scenes",
    "format_with_intervals",
    "check_claims",
    "claim_verdicts",
    "verdict_table",
    "judge_speed_claims",
    "claims_markdown",
    "judge_figures",
    "PLAN_V2_FILE",
    "COMPARISON_VERDICTS_V2",
    "CLAIM_VERDICTS_V2",
    "comparison_verdict_v2",
    "claim_rule_v2",
    "bench_speed_table",
    "support_regression",
    "per_kind_means",
]

_GT = "ground truth"
# rows a claim may name besides the configured transfer methods (never part of "<all others>")
_BASELINES = ("lower", "upper", "fused")


def _level_name(level: str | float) -> str:
    return f"{level:g} m" if isinstance(level, float) else str(level)


def _per_scene(df: pd.DataFrame, level_col: str, measure: str, route: str | None) -> pd.DataFrame:
    """Rows of ``df`` to judge on: columns scene/reference/model/level/measure, one route."""
    need = ["scene", "model", level_col, measure]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise ValueError(f"check_claims: a per-scene frame needs the columns {need}; {missing} missing")
    if "route" in df.columns and route is not None:
        df = df[(df["route"] == route) | df["route"].isna()]
    extra = [c for c in ("reference", NETWORK_COLUMN) if c in df.columns]
    df = df[need + extra].copy()
    if level_col == "height":
        df["height"] = df["height"].astype(np.float64).round(3)
    key = ["scene", "model", level_col] + extra
    dup = df.duplicated(key)
    if dup.any():
        raise ValueError(
            f"check_claims: several rows per ({', '.join(key)}), e.g. {df.loc[dup, key].iloc[0].tolist()}; pass "
            "per-scene rows of one table (with 'reference' / 'route' columns when the frame holds several)"
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


def _paper_diff(claim: Claim, model: str, first: str | float, second: str | float) -> float:
    """The paper's own value of ``first - second`` for this claim's data and measure (NaN if none)."""
    paper_model = PAPER_MODEL_OF.get(model)
    if paper_model is None:
        return np.nan
    if claim.data == "height sweep":
        curve = FIG3_MEAN_ACC.get(paper_model, {})
        if claim.measure != "mean_acc":
            return np.nan
        a = next((v for h, v in curve.items() if np.isclose(h, float(first))), None)
        b = next((v for h, v in curve.items() if np.isclose(h, float(second))), None)
    else:
        if claim.measure not in MEASURES:
            return np.nan
        table, i = (TABLE2 if claim.data == "synthetic" else TABLE3), list(MEASURES).index(claim.measure)
        a = table.get((paper_model, str(first)), (None,) * 4)[i]
        b = table.get((paper_model, str(second)), (None,) * 4)[i]
    return np.nan if a is None or b is None else float(a - b)


def _compare(x: np.ndarray, y: np.ndarray, strata: list[str], *, sesoi: float, plan: AnalysisPlan,
             seed: int, networks: Sequence | None = None, scenes: Sequence | None = None) -> dict | None:
    """Mean paired difference, its interval and the raw one-sided p-values (None: no pair).

    Under a v2 plan also the one-sided p-value beyond the nearer margin without doubling
    (``p_beyond1``), the interval method used and the kind-cluster sensitivity (``cluster_*``:
    the same numbers over the kinds' mean differences)."""
    keep = ~(np.isnan(x) | np.isnan(y))
    n = int(keep.sum())
    if n == 0:
        return None
    d = (x - y)[keep]
    g = [s for s, k in zip(strata, keep) if k]
    nets = None if networks is None else [v for v, k in zip(networks, keep) if k]
    names = None if scenes is None else [v for v, k in zip(scenes, keep) if k]
    nan = dict(lo=np.nan, hi=np.nan, df=np.nan, p_pos=np.nan, p_neg=np.nan, p_eq=np.nan, p_beyond=np.nan)
    if plan.rules == "v2":
        nan.update(p_beyond1=np.nan, cluster_diff=np.nan, cluster_lo=np.nan, cluster_hi=np.nan, cluster_p_neg=np.nan,
                   cluster_p_beyond1=np.nan)
    if n < plan.min_scenes:
        return dict(diff=float(d.mean()), scenes=n, **nan)
    if plan.rules == "v2":
        return _compare_v2(d, g, nets, names, sesoi=sesoi, plan=plan, seed=seed)
    est = stratified_estimate(d, g if plan.interval == "stratified-t" else None)
    _, lo, hi = interval(d, g, method=plan.interval, confidence=plan.confidence, seed=seed)
    p = lambda null, alt: t_test_pvalue(est, null, alt)  # noqa: E731
    return dict(diff=est.mean, lo=lo, hi=hi, scenes=n, df=est.df, p_pos=p(0.0, "greater"), p_neg=p(0.0, "less"),
                p_eq=max(p(-sesoi, "greater"), p(sesoi, "less")),
                p_beyond=min(1.0, 2 * min(p(sesoi, "greater"), p(-sesoi, "less"))))


def _comparison_verdict(kind: str, holds: float, against: float, equivalent: float, alpha: float) -> str:
    """The plan's comparison rule on Holm-adjusted p-values (NaN: not tested)."""
    if np.isnan(holds):
        return "inconclusive"
    if kind == "similar":
        return "holds" if equivalent <= alpha else "does not hold" if against <= alpha else "inconclusive"
    if equivalent <= alpha:
        return "equivalent"
    return "holds" if holds <= alpha else "does not hold" if against <= alpha else "inconclusive"


def check_claims(
    table2: pd.DataFrame | None = None,
    table3: pd.DataFrame | None = None,
    fig3: pd.DataFrame | None = None,
    noise: pd.DataFrame | None = None,
    *,
    methods: Sequence[str],
    plan: AnalysisPlan | None = None,
    references: Sequence[str] | None = None,
    route: str | None = None,
    seed: int = 0,
    claims: Sequence[Claim] | None = None,
) -> pd.DataFrame:
    """Judge the plan's claims on paired per-scene differences, one row per comparison.

    Parameters
    ----------
    table2, table3 : DataFrame, optional
        Per-scene Table 2 (synthetic) / Table 3 (real-like) rows: ``scene``, ``model``,
        ``method`` (a transfer method, ``lower`` or ``upper``), optionally ``reference`` and
        ``route``, and the measures. Rows of other methods (e.g. ``fused``) are ignored. Without a
        ``reference`` column the rows count as the plan's primary reference.
    fig3 : DataFrame, optional
        Per-scene height sweep: ``model``, ``scene``, ``height`` (m) and the measures (reference
        ``frames``: per-frame scores against the ground-truth label images).
    noise : DataFrame, optional
        Per-scene drops of the depth-noise study (``scene, model, method`` and the measures:
        score clean minus score at the noisiest level; :func:`~semmatch.experiments.depth_noise.noise_drops`).
    methods : sequence of str
        The transfer methods configured; a claim on a method not listed (or without rows) is
        skipped, and "the other methods" are the listed ones.
    plan : AnalysisPlan, optional
        Default :func:`load_analysis_plan` (the committed plan).
    references : sequence of str, optional
        References judged (default the plan's primary and secondary ones); each is its own family.
    route : str, optional
        Robot route judged when a table has a ``route`` column (default the plan's, ``own``).
    seed : int, optional
        Seed of bootstrap intervals (only when the plan's interval method is a bootstrap).
    claims : sequence of Claim, optional
        The claims to judge (default the plan's).

    Returns
    -------
    DataFrame
        ``claim, statement, section, data, role, kind, reference, model, measure, comparison, diff,
        lo, hi, scenes, df, p_holds, p_against, p_equivalent, verdict, paper_diff, paper_in_ci``.
        ``diff`` is the mean paired difference as written in ``comparison`` (positive supports a
        beats/best/worst claim), ``lo``/``hi`` its interval; the p-values are Holm-adjusted within
        the claim and reference; ``paper_diff`` is the paper's own difference (NaN where it has
        none) and ``paper_in_ci`` whether it lies in ``[lo, hi]``. Under a v2 plan (``rules: v2``)
        ``p_holds`` / ``p_equivalent`` are unadjusted (intersection-union), ``p_against`` is
        Holm-adjusted in the wrong direction, ``verdict`` is :func:`comparison_verdict_v2`'s, and
        ``interval_method``, ``min_effect`` (the bound beyond the SESOI), ``beyond_zero``,
        ``cluster_diff`` / ``cluster_lo`` / ``cluster_hi`` (t over the kind means) and
        ``verdict_cluster`` follow. Rows may carry a ``training_seed`` column (several networks
        per architecture: the v2 plan's two-level bootstrap).
    """
    plan = load_analysis_plan() if plan is None else plan
    claims = plan.claims if claims is None else claims
    references = plan.references if references is None else tuple(references)
    route = plan.route if route is None else route
    frames = {"table2": table2, "table3": table3, "fig3": fig3, "noise": noise}
    allowed = set(methods) | set(_BASELINES)
    rows: list[dict] = []
    for claim in claims:
        src = frames[_DATA[claim.data]]
        if src is None or claim.measure not in src.columns:
            continue
        heights = claim.data == "height sweep"
        level_col = "height" if heights else "method"
        df = _per_scene(src, level_col, claim.measure, None if heights else route)
        if "reference" not in df.columns:
            df["reference"] = FRAMES_REFERENCE if heights else plan.primary_reference
        refs = [FRAMES_REFERENCE] if heights else [r for r in references if r in set(df["reference"])]
        sesoi = plan.sesoi[claim.measure]
        for ref in refs:
            family: list[dict] = []
            dref = df[df["reference"] == ref]
            for model in dref["model"].unique():
                if (claim.models == "networks" and model == _GT) or (claim.models == "ground truth" and model != _GT):
                    continue
                mine = dref[dref["model"] == model]  # a model without training seeds (ground truth): one per scene
                seeded = NETWORK_COLUMN in mine and mine[NETWORK_COLUMN].notna().any()
                index = ["scene", NETWORK_COLUMN] if seeded else "scene"
                wide = mine.pivot(index=index, columns=level_col, values=claim.measure)
                wide = wide.dropna(axis=1, how="all")
                scenes = wide.index.get_level_values("scene")
                strata = [scene_kind(s) for s in scenes]
                # the networks behind each row: None for the ground truth (no network: never provisional)
                networks = (list(wide.index.get_level_values(NETWORK_COLUMN)) if index != "scene" else
                            None if model == _GT else [model] * len(wide))
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
                for a in subjects:
                    for b in others:
                        if b == a:
                            continue
                        first, second = (b, a) if claim.kind == "worst" else (a, b)
                        c = _compare(wide[first].to_numpy(dtype=np.float64), wide[second].to_numpy(dtype=np.float64),
                                     strata, sesoi=sesoi, plan=plan, seed=seed, networks=networks,
                                     scenes=list(scenes))
                        if c is None:
                            continue
                        family.append(dict(
                            claim=claim.id, statement=claim.statement, section=claim.section, data=claim.data,
                            role=claim.role, kind=claim.kind, reference=ref, model=model, measure=claim.measure,
                            comparison=f"{_level_name(first)} - {_level_name(second)}",
                            paper_diff=_paper_diff(claim, model, first, second), **c))
            if not family:
                continue
            fam = pd.DataFrame(family)
            if plan.rules == "v2":
                rows.extend(_judge_family_v2(fam, claim.kind, sesoi, plan.alpha).to_dict("records"))
                continue
            similar = claim.kind == "similar"
            fam["p_holds"] = holm(fam["p_eq"] if similar else fam["p_pos"])
            fam["p_against"] = holm(fam["p_beyond"] if similar else fam["p_neg"])
            fam["p_equivalent"] = holm(fam["p_eq"])
            fam["verdict"] = [_comparison_verdict(claim.kind, h, ag, eq, plan.alpha) for h, ag, eq in
                              zip(fam["p_holds"], fam["p_against"], fam["p_equivalent"])]
            rows.extend(fam.to_dict("records"))
    cols = ["claim", "statement", "section", "data", "role", "kind", "reference", "model", "measure", "comparison",
            "diff", "lo", "hi", "scenes", "df", "p_holds", "p_against", "p_equivalent", "verdict", "paper_diff"]
    if plan.rules == "v2":
        cols += ["interval_method", "min_effect", "beyond_zero", "cluster_diff", "cluster_lo", "cluster_hi",
                 "verdict_cluster"]
    out = pd.DataFrame(rows, columns=cols)
    inside = (out["paper_diff"] >= out["lo"]) & (out["paper_diff"] <= out["hi"])
    out["paper_in_ci"] = np.where(out["paper_diff"].isna() | out["lo"].isna(), None, inside)
    return out


def _claim_rule(verdicts: Sequence[str], kind: str) -> str:
    """The plan's claim rule on its comparisons' verdicts."""
    n = len(verdicts)
    count = {v: sum(x == v for x in verdicts) for v in VERDICTS}
    if n and count["holds"] == n:
        return "holds"
    if n and count["does not hold"] * 2 >= n:
        return "does not hold"
    if n and kind != "similar" and count["equivalent"] * 2 >= n:
        return "equivalent"
    return "inconclusive"


def claim_verdicts(comparisons: pd.DataFrame) -> pd.DataFrame:
    """One verdict per claim and reference from :func:`check_claims`' comparisons (the plan's rule).

    Parameters
    ----------
    comparisons : DataFrame
        Output of :func:`check_claims`.

    Returns
    -------
    DataFrame
        ``claim, statement, data, role, reference, verdict, comparisons, counts, paper_in_ci``:
        ``counts`` the comparisons' verdicts (e.g. ``"4 holds, 1 inconclusive"``), ``paper_in_ci``
        how many of the comparisons with a paper value have it inside our interval (``"2 of 5"``).
    """
    v2 = "verdict_cluster" in comparisons.columns
    labels = COMPARISON_VERDICTS_V2 if v2 else VERDICTS
    rows = []
    for (cid, ref), g in comparisons.groupby(["claim", "reference"], sort=False):
        counts = g["verdict"].value_counts()
        with_paper = g["paper_in_ci"].dropna()
        kind = g["kind"].iloc[0]
        row = dict(
            claim=cid, statement=g["statement"].iloc[0], data=g["data"].iloc[0], role=g["role"].iloc[0],
            reference=ref, verdict=(claim_rule_v2 if v2 else _claim_rule)(list(g["verdict"]), kind),
            comparisons=len(g), counts=", ".join(f"{int(counts[v])} {v}" for v in labels if v in counts),
            paper_in_ci=f"{int(with_paper.astype(bool).sum())} of {len(with_paper)}" if len(with_paper) else "-",
        )
        if v2:
            row["verdict_cluster"] = claim_rule_v2(list(g["verdict_cluster"]), kind)
            beyond = f"{int(g['min_effect'].sum())} of {len(g)}"
            row["min_effect"] = f"{beyond} within ±SESOI" if kind == "similar" else \
                f"{beyond} beyond SESOI ({int(g['beyond_zero'].sum())} beyond 0)"
            row["interval"] = ", ".join(dict.fromkeys(g["interval_method"].dropna()))
        rows.append(row)
    cols = ["claim", "statement", "data", "role", "reference", "verdict", "comparisons", "counts", "paper_in_ci"]
    return pd.DataFrame(rows, columns=cols + (["verdict_cluster", "min_effect", "interval"] if v2 else []))


def verdict_table(comparisons: pd.DataFrame, *, plan: AnalysisPlan | None = None,
                  data: Sequence[str] | None = None) -> pd.DataFrame:
    """Every claim of the plan (for the given data) with its verdict under each reference.

    Parameters
    ----------
    comparisons : DataFrame
        Output of :func:`check_claims`.
    plan : AnalysisPlan, optional
        Default the committed plan.
    data : sequence of str, optional
        Which claims to list (``"synthetic"``, ``"real-like"``, ``"height sweep"``); default the
        data present in ``comparisons``.

    Returns
    -------
    DataFrame
        ``claim, statement, data, role, verdict`` (primary reference, or the ground-truth frames
        of Fig. 3), ``verdict_<ref>`` per secondary reference, ``counts`` and ``paper_in_ci`` (of
        the primary reference). A claim without data reads ``not judged (no data)``.
    """
    plan = load_analysis_plan() if plan is None else plan
    per = claim_verdicts(comparisons)
    data = list(dict.fromkeys(comparisons["data"])) if data is None else list(data)
    rows = []
    for claim in plan.claims:
        if claim.data not in data:
            continue
        mine = per[per["claim"] == claim.id]
        primary = mine[mine["reference"].isin([plan.primary_reference, FRAMES_REFERENCE])]
        row = dict(claim=claim.id, statement=claim.statement, data=claim.data, role=claim.role)
        row["verdict"] = primary["verdict"].iloc[0] if len(primary) else "not judged (no data)"
        for ref in plan.secondary_references:
            sec = mine[mine["reference"] == ref]
            row[f"verdict_{ref}"] = sec["verdict"].iloc[0] if len(sec) else "-"
        row["counts"] = primary["counts"].iloc[0] if len(primary) else "-"
        row["paper_in_ci"] = primary["paper_in_ci"].iloc[0] if len(primary) else "-"
        for col in ("min_effect", "verdict_cluster", "interval"):  # the v2 rules' columns
            if col in per.columns:
                row[col] = primary[col].iloc[0] if len(primary) else "-"
        rows.append(row)
    return pd.DataFrame(rows)


def claims_markdown(df: pd.DataFrame, *, digits: int = 3, plan: AnalysisPlan | None = None) -> str:
    """Markdown of :func:`check_claims` results: the verdict per claim, then every comparison.

    Parameters
    ----------
    df : DataFrame
        Output of :func:`check_claims`.
    digits : int, optional
        Decimals of the differences.
    plan : AnalysisPlan, optional
        Default the committed plan.

    Returns
    -------
    str
        The claim table (:func:`verdict_table`), a line counting the claims' verdicts, the
        comparisons (difference with interval, scenes, Holm-adjusted p, verdict, the paper's
        difference) and the claims' statements.
    """
    if df.empty:
        return "No claim could be judged (no per-scene data for any of them).\n"
    plan = load_analysis_plan() if plan is None else plan

    def fmt(v: float) -> str:
        return "-" if pd.isna(v) else f"{v:+.{digits}f}"

    claims = verdict_table(df, plan=plan)
    comps = pd.DataFrame({
        "claim": df["claim"],
        "reference": df["reference"],
        "model": df["model"],
        "measure": df["measure"].map(lambda m: MEASURE_LABELS.get(m, m)),
        "comparison": df["comparison"],
        f"difference [{plan.confidence:.0%} CI]": [f"{fmt(d)} [{fmt(lo)}, {fmt(hi)}]" for d, lo, hi in
                                                    zip(df["diff"], df["lo"], df["hi"])],
        "scenes": df["scenes"],
        "p (Holm)" if plan.rules == "v1" else "p (against: Holm)": [("-" if pd.isna(a) else f"{a:.3f}") for a in
                     np.where(df["verdict"].isin(["does not hold", "against"]), df["p_against"],
                              np.where(df["verdict"] == "equivalent", df["p_equivalent"], df["p_holds"]))],
        "verdict": df["verdict"],
        "paper": [fmt(v) for v in df["paper_diff"]],
        "paper in CI": df["paper_in_ci"].map(lambda v: "-" if v is None or pd.isna(v) else ("yes" if v else "no")),
    })
    counts = claims["verdict"].value_counts()
    summary = ", ".join(f"{int(counts[v])} {v}" for v in (*VERDICTS, "refuted", "not judged (no data)", "not judged")
                        if v in counts)
    legend = df.drop_duplicates("claim")[["claim", "statement", "section", "data"]]
    lines = [claims.to_markdown(index=False), "", f"Claims judged: {len(claims)} ({summary}).", "",
             comps.to_markdown(index=False), "", f"Comparisons: {len(df)}.", ""]
    lines += [f"- **{r.claim}** ({r.data}, {r.section}): {r.statement}" for r in legend.itertuples()]
    return "\n".join(lines) + "\n"


def _network_mean(per_scene: pd.DataFrame) -> pd.DataFrame:
    """Per-scene rows averaged over the networks of an architecture (``training_seed``), for the
    secondary analyses that read one value per scene; a table without that column as it is."""
    if NETWORK_COLUMN not in per_scene.columns:
        return per_scene
    keys = [c for c in per_scene.columns if c != NETWORK_COLUMN and not pd.api.types.is_numeric_dtype(per_scene[c])]
    return per_scene.drop(columns=NETWORK_COLUMN).groupby(keys, sort=False, dropna=False).mean().reset_index()


def _speed_verdicts(figures_dir: Path, out_dir: Path, table1: pd.DataFrame | None,
                    plan: AnalysisPlan) -> tuple[pd.DataFrame | None, str]:
    """The speed claims of a run and what they were judged on: under a v2 plan the speed benchmark's
    record (:data:`~semmatch.experiments.speed_claims.BENCH_RECORD`) when the run has one (its
    verdicts with the machine, load and reference rate written to ``claims_speed_bench``), else
    Table 1 (None without it)."""
    import json

    from .speed_claims import BENCH_RECORD, bench_conditions

    bench = figures_dir / BENCH_RECORD
    if plan.rules == "v2" and bench.is_file():
        record = json.loads(bench.read_text())
        speed = judge_speed_claims(bench_speed_table(record), plan=plan)
        c = bench_conditions(record)
        speed["evidence"] += (f"; {c['cpu']} ({c['cpu_count']} CPUs), load {c['load_min']}-{c['load_max']}, "
                              f"reference {c['reference_fps']:.1f} FPS" if c["reference_fps"] is not None else "")
        save_table(speed, out_dir, "claims_speed_bench")
        return speed, f"speed ({record.get('command', 'bench transfer')})"
    return (None if table1 is None else judge_speed_claims(table1, plan=plan)), "speed (Table 1)"


def judge_figures(figures_dir: str | Path, out_dir: str | Path | None = None, *,
                  methods: Sequence[str] | None = None, plan: AnalysisPlan | None = None) -> pd.DataFrame:
    """Every claim of the plan judged on the per-scene tables of one run, in one verdict table.

    Reads ``table2_per_scene.csv``, ``table3_per_scene.csv``, ``fig3_height_per_scene.csv``,
    ``depth_noise.csv`` and ``table1_speed.csv`` from ``figures_dir`` (those present; under a v2 plan
    the speed benchmark's ``bench_speed.json`` instead of Table 1 when present) and writes into ``out_dir``:
    ``claims_all.csv`` (every comparison), ``verdicts.csv`` / ``verdicts.md`` (one row per claim,
    the speed claims included), ``findings_all.md`` (:func:`claims_markdown`) and the declared
    secondary analyses ``secondary_s1_support`` (:func:`support_regression`, with
    ``support_per_scene.csv``) and ``secondary_s3_<table>_per_kind`` (:func:`per_kind_means`).

    Parameters
    ----------
    figures_dir : str or Path
        A run's figures folder (e.g. ``figures/full`` or ``figures/confirm/<name>``).
    out_dir : str or Path, optional
        Where to write (default ``figures_dir``).
    methods : sequence of str, optional
        The transfer methods (default the plan's claims' methods present in the tables).
    plan : AnalysisPlan, optional
        Default the committed plan.

    Returns
    -------
    DataFrame
        The verdict table (:func:`verdict_table` rows, then the speed claims).

    Raises
    ------
    FileNotFoundError
        If ``figures_dir`` holds none of the per-scene tables.
    """
    plan = load_analysis_plan() if plan is None else plan
    figures_dir = Path(figures_dir)
    out_dir = figures_dir if out_dir is None else Path(out_dir)
    read = {name: (pd.read_csv(figures_dir / f"{name}.csv") if (figures_dir / f"{name}.csv").is_file() else None)
            for name in ("table2_per_scene", "table3_per_scene", "fig3_height_per_scene", "table1_speed",
                         "depth_noise")}
    if all(v is None for k, v in read.items() if k not in ("table1_speed", "depth_noise")):
        raise FileNotFoundError(f"judge_figures: no per-scene table (table2/table3/fig3 _per_scene.csv) in {figures_dir}")
    if methods is None:
        present = set().union(*(set(t["method"]) for k, t in read.items() if t is not None and "method" in t))
        methods = [m for m in ("2d-slic", "3d-projected-sp", "3d-slic", "dbscan", "3d-neighborhood") if m in present]
    from .depth_noise import noise_drops

    drops = noise_drops(read["depth_noise"]) if read["depth_noise"] is not None else None
    comps = check_claims(read["table2_per_scene"], read["table3_per_scene"], read["fig3_height_per_scene"], drops,
                         methods=methods, plan=plan)
    table = verdict_table(comps, plan=plan, data=list(_DATA))
    speed, where = _speed_verdicts(figures_dir, out_dir, read["table1_speed"], plan)
    if speed is not None:
        table = pd.concat([table, speed.assign(data=where)[["claim", "statement", "data", "role", "verdict"]]],
                          ignore_index=True)
    save_table(comps, out_dir, "claims_all")
    save_table(table.fillna("-"), out_dir, "verdicts")
    # declared secondary analyses: S1 (C1 against support), S3 (per-kind means)
    support_csv = figures_dir / "support_per_scene.csv"
    if read["table2_per_scene"] is not None and support_csv.is_file():
        save_table(support_regression(_network_mean(read["table2_per_scene"]), pd.read_csv(support_csv), plan=plan),
                   out_dir, "secondary_s1_support")
    for name, tag in (("table2_per_scene", "table2"), ("table3_per_scene", "table3")):
        if read[name] is not None:
            save_table(per_kind_means(read[name]), out_dir, f"secondary_s3_{tag}_per_kind")
    from ..io import atomic_write_text

    atomic_write_text(out_dir / "findings_all.md", claims_markdown(comps, plan=plan))
    return table
