"""Verdicts on the adaptation claims: the shipped adapted networks judged by a plan fixed in advance.

Stage 09 (notebook ``09_adapt_robot_view``) states on the development scenes that the network
adapted on labels transferred from the person's map gains at the robot's height, loses nothing
at the person's, closes most of the viewpoint gap and beats self-training. ``adapt_plan.yaml``
beside this module (explained in ``docs/analysis_plan.md``, "The adaptation claims") turns these
statements into claims with their data, comparison and measure; it was committed before any
adapted network was scored on a confirmatory scene. :func:`judge_adaptation` applies it to one
run's per-scene tables with the analysis plan's inference (paired per scene, t interval, Holm
within each claim, the measure's smallest effect size of interest, the ``beats`` / ``similar``
rules) and the plan's own rule for the share of the gap closed (one-sided Fieller bounds,
:func:`semmatch.evaluate.stats.ratio_lower_bound`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

__all__ = ["ADAPT_PLAN_FILE", "AdaptClaim", "AdaptPlan", "load_adapt_plan", "check_adaptation_claims",
           "judge_adaptation", "adaptation_markdown"]

#: the adaptation claims' plan read by :func:`load_adapt_plan`
ADAPT_PLAN_FILE = Path(__file__).with_name("adapt_plan.yaml")
#: the per-scene tables of notebook 09 that the claims read, by the claims' ``data``
TABLES = {"height sweep": "adapt_height_per_scene", "robot map": "table2_adapted_per_scene"}
_KINDS = ("beats", "similar", "share")
#: the fine-tuning seed's column in per-scene tables of several seeds (``adapt_seeds``)
SEED_COLUMN = "seed"
#: a run's tables over its fine-tuning seeds (every seed, the ``seed`` column), relative to its
#: figures folder, by :data:`TABLES`' keys: notebook 09 writes them under a plan that lists
#: several seeds (:mod:`semmatch.experiments.finetune_seeds`) and :func:`judge_adaptation` reads them
SEED_TABLES = {"height sweep": "adapt_seeds/adapt_seeds_height_per_scene",
               "robot map": "adapt_seeds/table2_adapted_seeds_per_scene"}
_NETWORK = "<network>"
_ADAPTED = "<adapted:"


@dataclass(frozen=True)
class AdaptClaim:
    """One adaptation claim of ``adapt_plan.yaml``.

    Attributes
    ----------
    id, statement : str
    data : str
        ``"height sweep"`` or ``"robot map"`` (:data:`TABLES`).
    kind : str
        ``"beats"``, ``"similar"`` or ``"share"`` (the share of the viewpoint gap closed).
    subject, other : str
        ``"<network>"``, ``"<adapted:SOURCE>"`` or (robot map) a method of the unadapted network's
        Table 2 rows.
    measure : str
    height : float or None
        The camera height compared (height sweep, ``beats`` / ``similar``).
    role : str
        ``"primary"`` or ``"secondary"``.
    """

    id: str
    statement: str
    data: str
    kind: str
    subject: str
    other: str
    measure: str
    height: float | None = None
    role: str = "primary"

    def __post_init__(self) -> None:
        if self.data not in TABLES:
            raise ValueError(f"adaptation claim {self.id}: data must be one of {tuple(TABLES)}, got {self.data!r}")
        if self.kind not in _KINDS:
            raise ValueError(f"adaptation claim {self.id}: kind must be one of {_KINDS}, got {self.kind!r}")
        if self.kind != "share" and self.data == "height sweep" and self.height is None:
            raise ValueError(f"adaptation claim {self.id}: a height-sweep comparison needs a height")
        if self.kind == "share" and self.data != "height sweep":
            raise ValueError(f"adaptation claim {self.id}: the share of the gap is read from the height sweep")


@dataclass(frozen=True)
class AdaptPlan:
    """The adaptation plan (``adapt_plan.yaml``).

    Attributes
    ----------
    claims : tuple of AdaptClaim
    network : str
        The unadapted network.
    adapted : str
        Name template of an adapted network (``{source}``).
    low, high : float
        The robot's and the person's camera heights (m).
    target : float
        The share of the gap closed that the ``share`` claims ask for.
    in_home_max_seeds : int
        A confirmatory run's in-home study uses the homes of its first this many seeds.
    raw : dict
        The whole YAML document.
    """

    claims: tuple[AdaptClaim, ...]
    network: str
    adapted: str
    low: float
    high: float
    target: float
    in_home_max_seeds: int
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    def model(self, token: str) -> str:
        """The network a claim's ``subject`` / ``other`` names (a Table 2 method: the unadapted one)."""
        if token.startswith(_ADAPTED) and token.endswith(">"):
            return self.adapted.format(source=token[len(_ADAPTED):-1])
        return self.network


def load_adapt_plan(path: str | Path | None = None) -> AdaptPlan:
    """Read the adaptation plan.

    Parameters
    ----------
    path : str or Path, optional
        Default :data:`ADAPT_PLAN_FILE` (the committed plan).

    Returns
    -------
    AdaptPlan

    Raises
    ------
    ValueError
        If the file is not a valid plan (names the file and what is wrong).
    FileNotFoundError
        If the file does not exist.
    """
    p = Path(path) if path is not None else ADAPT_PLAN_FILE
    data = yaml.safe_load(p.read_text(encoding="utf-8"))
    try:
        claims = tuple(AdaptClaim(id=str(c["id"]), statement=str(c["statement"]), data=str(c["data"]),
                                  kind=str(c["kind"]), subject=str(c["subject"]), other=str(c["other"]),
                                  measure=str(c["measure"]),
                                  height=float(c["height"]) if c.get("height") is not None else None,
                                  role=str(c.get("role", "primary"))) for c in data["claims"])
        plan = AdaptPlan(claims=claims, network=str(data["network"]), adapted=str(data["adapted"]),
                         low=float(data["low"]), high=float(data["high"]), target=float(data["target"]),
                         in_home_max_seeds=int(data["in_home_max_seeds"]), raw=data)
    except (KeyError, TypeError, AttributeError) as e:
        raise ValueError(f"{p}: not a valid adaptation plan ({type(e).__name__}: {e})") from e
    ids = [c.id for c in claims]
    if len(set(ids)) != len(ids):
        raise ValueError(f"{p}: claim ids repeat: {sorted({i for i in ids if ids.count(i) > 1})}")
    return plan


def _values(table: pd.DataFrame, claim: AdaptClaim, plan: AdaptPlan, token: str,
            height: float | None, *, by_seed: bool = False) -> pd.Series | None:
    """Per-scene values of one side of a claim (None: the table has no such rows): the mean over
    the fine-tuning seeds when the table has a ``seed`` column, or per scene and seed with ``by_seed``."""
    model = plan.model(token)
    rows = table[table["model"] == model]
    if claim.data == "robot map":
        method = "lower" if token == _NETWORK or token.startswith(_ADAPTED) else token
        rows = rows[rows["method"] == method]
    else:
        rows = rows[np.isclose(rows["height"].astype(float), height)]
    if rows.empty or claim.measure not in rows.columns:
        return None
    return rows.groupby(["scene", SEED_COLUMN] if by_seed else "scene")[claim.measure].mean()


def _share(table: pd.DataFrame, claim: AdaptClaim, plan: AdaptPlan, confidence: float) -> dict | None:
    """The share of the gap closed and its one-sided lower and upper Fieller bounds."""
    from ..evaluate.stats import ratio_lower_bound

    sides = [_values(table, claim, plan, t, h) for t, h in
             ((claim.subject, plan.low), (claim.other, plan.low), (claim.other, plan.high))]
    if any(s is None for s in sides):
        return None
    d = pd.concat(sides, axis=1, keys=["adapted_low", "low", "high"]).dropna()
    gain, gap = (d["adapted_low"] - d["low"]).to_numpy(), (d["high"] - d["low"]).to_numpy()
    n = len(d)
    if n < 2:
        return dict(diff=float(gain.mean() / gap.mean()) if n else np.nan, lo=np.nan, hi=np.nan, scenes=n)
    lo = ratio_lower_bound(gain, gap, confidence=confidence)
    hi = -ratio_lower_bound(-gain, gap, confidence=confidence)
    return dict(diff=float(gain.mean() / gap.mean()), lo=lo, hi=hi, scenes=n)


def _share_verdict(lo: float, hi: float, target: float) -> str:
    if np.isnan(lo) or np.isnan(hi):
        return "inconclusive"
    return "holds" if lo >= target else "does not hold" if hi < target else "inconclusive"


def _judge_one(table: pd.DataFrame, claim: AdaptClaim, plan: AdaptPlan, ap) -> dict:
    """One claim's row (its family is itself: Holm over one comparison is the raw p-value)."""
    from ..evaluate.stats import holm
    from .claims import _compare, _comparison_verdict, claim_rule_v2, comparison_verdict_v2

    head = dict(claim=claim.id, statement=claim.statement, role=claim.role, data=claim.data, kind=claim.kind,
                measure=claim.measure)
    if claim.kind == "share":
        where = f"share of the gap closed ({plan.low:g} m vs {plan.high:g} m)"
        # v1: one-sided bounds at the plan's confidence; v2: at 1 - alpha (the ends of a two-sided 95 % interval)
        level = 1.0 - ap.alpha if ap.rules == "v2" else ap.confidence
        c = _share(table, claim, plan, level)
        if c is None:
            return {**head, "comparison": where, "verdict": "not judged", "note": "rows missing"}
        seeds = table[SEED_COLUMN].nunique() if SEED_COLUMN in table.columns else 1
        return {**head, "comparison": f"{plan.model(claim.subject)}: {where}", **c,
                "verdict": _share_verdict(c["lo"], c["hi"], plan.target),
                "note": f"lo/hi: one-sided {level:.1%} Fieller bounds; target {plan.target:.0%}"
                        + (f"; per-scene mean over {seeds} fine-tuning seeds" if seeds > 1 else "")}
    at = f" at {claim.height:g} m" if claim.data == "height sweep" else ""
    name = lambda t: plan.model(t) if t == _NETWORK or t.startswith(_ADAPTED) else f"{plan.network} {t}"  # noqa: E731
    comparison = f"{name(claim.subject)} - {name(claim.other)}{at}"
    by_seed = ap.rules == "v2" and SEED_COLUMN in table.columns
    a, b = (_values(table, claim, plan, t, claim.height, by_seed=by_seed) for t in (claim.subject, claim.other))
    if a is None or b is None:
        return {**head, "comparison": comparison, "verdict": "not judged", "note": "rows missing"}
    pair = pd.concat([a, b], axis=1, keys=["a", "b"])
    scenes = pair.index.get_level_values("scene")
    kinds = [str(s).rsplit("_", 1)[0] for s in scenes]
    sesoi = float(ap.sesoi[claim.measure])
    c = _compare(pair["a"].to_numpy(np.float64), pair["b"].to_numpy(np.float64), kinds, sesoi=sesoi, plan=ap,
                 seed=0, networks=list(pair.index.get_level_values(SEED_COLUMN)) if by_seed else None,
                 scenes=list(scenes))
    if c is None:
        return {**head, "comparison": comparison, "verdict": "not judged", "note": "no scene with both"}
    similar = claim.kind == "similar"
    if ap.rules == "v2":  # a family of one comparison: Holm is the raw p-value
        side = "p_beyond1" if similar else "p_neg"
        rule = lambda lo, hi, p: claim_rule_v2([comparison_verdict_v2(  # noqa: E731
            claim.kind, lo, hi, p, sesoi=sesoi, alpha=ap.alpha)], claim.kind)
        return {**head, "comparison": comparison, "diff": c["diff"], "lo": c["lo"], "hi": c["hi"],
                "scenes": c["scenes"], "p_holds": c["p_eq"] if similar else c["p_pos"], "p_against": c[side],
                "p_equivalent": c["p_eq"], "verdict": rule(c["lo"], c["hi"], c[side]),
                "min_effect": (-sesoi < c["lo"] and c["hi"] < sesoi) if similar else c["lo"] > sesoi,
                "verdict_cluster": rule(c["cluster_lo"], c["cluster_hi"], c[f"cluster_{side}"]),
                "note": f"{c['interval_method']}; sesoi {sesoi:g}; v2 rules"}
    p_holds = holm([c["p_eq"] if similar else c["p_pos"]])[0]
    p_against = holm([c["p_beyond"] if similar else c["p_neg"]])[0]
    p_eq = holm([c["p_eq"]])[0]
    return {**head, "comparison": comparison, "diff": c["diff"], "lo": c["lo"], "hi": c["hi"], "scenes": c["scenes"],
            "p_holds": p_holds, "p_against": p_against, "p_equivalent": p_eq,
            "verdict": _comparison_verdict(claim.kind, p_holds, p_against, p_eq, ap.alpha),
            "note": f"{ap.confidence:.0%} t interval; sesoi {ap.sesoi[claim.measure]:g}"}


def check_adaptation_claims(tables: dict[str, pd.DataFrame | None], *, plan: AdaptPlan | None = None,
                            analysis_plan=None, claims: Sequence[AdaptClaim] | None = None) -> pd.DataFrame:
    """Judge the adaptation claims on notebook 09's per-scene tables, one row per claim.

    Parameters
    ----------
    tables : dict
        ``{"height sweep": adapt_height_per_scene, "robot map": table2_adapted_per_scene}`` (a
        missing table: its claims are ``not judged``).
    plan : AdaptPlan, optional
        Default the committed plan.
    analysis_plan : AnalysisPlan, optional
        The inference settings (default the committed analysis plan).
    claims : sequence of AdaptClaim, optional
        Default the plan's.

    Returns
    -------
    DataFrame
        ``claim, statement, role, data, kind, measure, comparison, diff, lo, hi, scenes, p_holds,
        p_against, p_equivalent, verdict, note``; for ``share`` claims ``diff`` is the share and
        ``lo`` / ``hi`` its one-sided bounds. Under a v2 analysis plan (``rules: v2``): the v2
        verdicts (``refuted`` for a comparison against the claim; the share at one-sided
        ``1 - alpha``, on the mean over fine-tuning seeds when the table has a ``seed`` column, the
        other claims by the two-level bootstrap over those seeds) with ``min_effect`` and
        ``verdict_cluster`` after ``verdict``.
    """
    from .analysis_plan import load_analysis_plan

    plan = plan or load_adapt_plan()
    ap = analysis_plan or load_analysis_plan()
    rows = []
    for claim in claims if claims is not None else plan.claims:
        table = tables.get(claim.data)
        if table is None:
            rows.append(dict(claim=claim.id, statement=claim.statement, role=claim.role, data=claim.data,
                             kind=claim.kind, measure=claim.measure, verdict="not judged",
                             note=f"no {TABLES[claim.data]}.csv"))
            continue
        rows.append(_judge_one(table, claim, plan, ap))
    cols = ["claim", "statement", "role", "data", "kind", "measure", "comparison", "diff", "lo", "hi", "scenes",
            "p_holds", "p_against", "p_equivalent", "verdict", "note"]
    if ap.rules == "v2":  # the minimum-effect and kind-cluster columns beside the verdict
        cols[cols.index("verdict") + 1:cols.index("verdict") + 1] = ["min_effect", "verdict_cluster"]
    return pd.DataFrame(rows).reindex(columns=cols)


def adaptation_markdown(df: pd.DataFrame, *, digits: int = 3) -> str:
    """The verdict table as Markdown: one row per claim, the difference with its interval."""
    def cell(r) -> str:
        if pd.isna(r.get("diff")):
            return "-"
        if r["kind"] == "share":
            return f"{r['diff']:.0%} (>= {r['lo']:.0%}, <= {r['hi']:.0%})"
        return f"{r['diff']:+.{digits}f} [{r['lo']:+.{digits}f}, {r['hi']:+.{digits}f}]"

    shown = pd.DataFrame({"claim": df["claim"], "role": df["role"], "statement": df["statement"],
                          "comparison": df["comparison"].fillna("-"), "measure": df["measure"],
                          "difference": [cell(r) for _, r in df.iterrows()],
                          "scenes": df["scenes"].map(lambda v: "-" if pd.isna(v) else f"{int(v)}"),
                          "verdict": df["verdict"]})
    return shown.to_markdown(index=False) + "\n"


def judge_adaptation(figures_dir: str | Path, out_dir: str | Path | None = None, *,
                     plan: AdaptPlan | None = None, analysis_plan=None) -> pd.DataFrame:
    """The adaptation claims judged on one run's notebook-09 tables.

    Reads ``adapt_height_per_scene.csv`` and ``table2_adapted_per_scene.csv`` from ``figures_dir``
    (under a v2 plan each one's table over the fine-tuning seeds instead where the run has it:
    :data:`SEED_TABLES`) and writes ``adapt_claims.csv`` and ``adapt_verdicts.md`` into
    ``out_dir`` (default ``figures_dir``).

    Parameters
    ----------
    figures_dir : str or Path
        A run's figures (``figures/full`` or ``figures/confirm/<name>``).
    out_dir : str or Path, optional
    plan : AdaptPlan, optional
    analysis_plan : AnalysisPlan, optional

    Returns
    -------
    DataFrame
        :func:`check_adaptation_claims`' table.

    Raises
    ------
    FileNotFoundError
        If ``figures_dir`` holds neither table (stage 09 did not run there).
    """
    from ..io import atomic_write_text
    from .tables import save_table

    figures_dir = Path(figures_dir)
    out_dir = figures_dir if out_dir is None else Path(out_dir)
    paths = {k: figures_dir / f"{v}.csv" for k, v in TABLES.items()}
    if not any(p.is_file() for p in paths.values()):
        raise FileNotFoundError(f"judge_adaptation: neither {' nor '.join(p.name for p in paths.values())} in "
                                f"{figures_dir} (notebook 09 did not run there)")
    if analysis_plan is not None and analysis_plan.rules == "v2":  # every fine-tuning seed, where scored
        paths.update({k: figures_dir / f"{v}.csv" for k, v in SEED_TABLES.items()
                      if (figures_dir / f"{v}.csv").is_file()})
    tables = {k: pd.read_csv(p) if p.is_file() else None for k, p in paths.items()}
    df = check_adaptation_claims(tables, plan=plan, analysis_plan=analysis_plan)
    save_table(df, out_dir, "adapt_claims")
    atomic_write_text(out_dir / "adapt_verdicts.md", adaptation_markdown(df))
    return df
