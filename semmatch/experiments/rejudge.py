"""A committed run re-judged under another analysis plan's verdict rules, from its per-scene CSVs.

``python -m semmatch.experiments rejudge --rules v2 --figures figures/confirm/seeds-8001-8006
--out docs/results_confirmatory_v1_under_v2.md`` reads the run's committed per-scene tables (no
rescoring, no new scene) and writes one Markdown document: every claim with its verdict under
the v1 plan (:data:`~semmatch.experiments.analysis_plan.PLAN_FILE`) beside its verdict under the
v2 plan (:data:`~semmatch.experiments.analysis_plan.PLAN_V2_FILE`) with the minimum-effect and
kind-cluster columns, the adaptation claims (A3 on the mean over the fine-tuning seeds where the
run has them), the in-home comparisons, the speed claims and every comparison. It is a secondary,
labelled table: the run's confirmatory verdicts stay those of the plan it was run under.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .adapt_claims import SEED_TABLES
from .analysis_plan import PLAN_FILE, PLAN_V2_FILE, AnalysisPlan, load_analysis_plan

__all__ = ["RULE_FILES", "rejudge_claims", "rejudge_adaptation", "rejudge_in_home", "rejudge_markdown",
           "add_rejudge_parser"]

#: the plan file of each set of verdict rules
RULE_FILES = {"v1": PLAN_FILE, "v2": PLAN_V2_FILE}
_SEEDS_TABLE = Path(SEED_TABLES["height sweep"] + ".csv")


def _interval(d: float, lo: float, hi: float) -> str:
    return "-" if pd.isna(d) else f"{d:+.3f}" + ("" if pd.isna(lo) else f" [{lo:+.3f}, {hi:+.3f}]")


def _yes_no(v: object) -> str:
    return "-" if v is None or (isinstance(v, float) and np.isnan(v)) else "yes" if bool(v) else "no"


def rejudge_claims(figures_dir: str | Path, *, plan: AnalysisPlan, baseline: AnalysisPlan | None = None
                   ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The paper's claims (and the plan's other claims) of one run under ``plan``, beside ``baseline``'s.

    Parameters
    ----------
    figures_dir : str or Path
        The run's figures folder (its ``*_per_scene.csv`` and ``depth_noise.csv``).
    plan : AnalysisPlan
        The rules to re-judge with.
    baseline : AnalysisPlan, optional
        The rules the run was judged with (default the v1 plan).

    Returns
    -------
    (DataFrame, DataFrame)
        The claim table (:func:`~semmatch.experiments.claims.verdict_table` of ``plan`` with
        ``verdict_before``: the baseline's verdict, ``-`` for claims it did not have) and every
        comparison under ``plan`` with ``verdict_before``.
    """
    import tempfile

    from .claims import judge_figures

    baseline = load_analysis_plan(PLAN_FILE) if baseline is None else baseline
    with tempfile.TemporaryDirectory() as tmp:  # judge_figures writes its tables: keep the run's folder as it is
        before = judge_figures(figures_dir, Path(tmp) / "before", plan=baseline)
        comps_before = pd.read_csv(Path(tmp) / "before" / "claims_all.csv")
        after = judge_figures(figures_dir, Path(tmp) / "after", plan=plan)
        comps = pd.read_csv(Path(tmp) / "after" / "claims_all.csv")
    key = ["claim", "reference", "model", "comparison"]
    comps = comps.merge(comps_before[key + ["verdict"]].rename(columns={"verdict": "verdict_before"}), on=key,
                        how="left")
    after.insert(after.columns.get_loc("verdict"), "verdict_before",
                 after["claim"].map(dict(zip(before["claim"], before["verdict"]))).fillna("-"))
    return after, comps


def rejudge_adaptation(figures_dir: str | Path, *, plan: AnalysisPlan) -> pd.DataFrame | None:
    """The adaptation claims of one run under ``plan`` (None: the run has no notebook-09 tables).

    The share claims (A3, A3-self, A3-gt) read ``adapt_seeds/adapt_seeds_height_per_scene.csv``
    when the run has it (per scene, the mean over the fine-tuning seeds); the other claims read
    notebook 09's tables (the shipped fine-tuning seed).
    """
    from .adapt_claims import TABLES, check_adaptation_claims, load_adapt_plan

    figures_dir = Path(figures_dir)
    paths = {k: figures_dir / f"{v}.csv" for k, v in TABLES.items()}
    if not any(p.is_file() for p in paths.values()):
        return None
    tables = {k: pd.read_csv(p) if p.is_file() else None for k, p in paths.items()}
    aplan = load_adapt_plan()
    df = check_adaptation_claims(tables, plan=aplan, analysis_plan=plan)
    df["seeds"] = "shipped seed (0)"
    seeds_csv = figures_dir / _SEEDS_TABLE
    if seeds_csv.is_file():
        shares = [c for c in aplan.claims if c.kind == "share"]
        mean = check_adaptation_claims({"height sweep": pd.read_csv(seeds_csv), "robot map": None}, plan=aplan,
                                       analysis_plan=plan, claims=shares)
        n = pd.read_csv(seeds_csv)["seed"].nunique()
        mean["seeds"] = f"mean of {n} seeds"
        df = pd.concat([df[~df["claim"].isin(mean["claim"])], mean]).set_index("claim").loc[df["claim"]].reset_index()
    return df


def rejudge_in_home(figures_dir: str | Path, *, plan: AnalysisPlan) -> pd.DataFrame | None:
    """The in-home study's comparisons of one run under ``plan``'s rules (None: no in-home table).

    A family is one measure's comparisons (as the in-home plan's); the rules are the plan's
    (:func:`~semmatch.experiments.claims.comparison_verdict_v2` under v2)."""
    from .in_home import in_home_comparisons, load_in_home_plan

    csv = Path(figures_dir) / "in_home" / "in_home_per_home.csv"
    if not csv.is_file():
        return None
    return in_home_comparisons(pd.read_csv(csv), load_in_home_plan(), analysis_plan=plan)


def rejudge_markdown(figures_dir: str | Path, *, rules: str = "v2", command: str = "") -> str:
    """The whole re-judged document of one run (see the module docstring).

    Parameters
    ----------
    figures_dir : str or Path
        The run's figures folder.
    rules : str
        ``"v2"`` (or ``"v1"``: the run's own rules again, a check).
    command : str
        The command line written into the document's header.

    Returns
    -------
    str

    Raises
    ------
    ValueError
        An unknown ``rules``.
    FileNotFoundError
        If ``figures_dir`` holds no per-scene table.
    """
    if rules not in RULE_FILES:
        raise ValueError(f"rejudge: --rules must be one of {sorted(RULE_FILES)}, got {rules!r}")
    plan = load_analysis_plan(RULE_FILES[rules])
    claims, comps = rejudge_claims(figures_dir, plan=plan)
    name = Path(figures_dir).name
    v2 = plan.rules == "v2"
    lines = [f"# Run `{name}` re-judged under the {rules} rules (secondary, labelled)", "",
             f"Generated by `{command}` from the run's committed per-scene CSVs (`{Path(figures_dir).as_posix()}/`): "
             "no rescoring, no new scene. **This is a secondary table.** The run's confirmatory verdicts are "
             "those of the plan it was run under (v1: [analysis_plan.md](analysis_plan.md), "
             "[results_confirmatory.md](results_confirmatory.md)); the rules used here "
             "([analysis_plan_v2.md](analysis_plan_v2.md)) were written after that run was published, in "
             "part from what it showed, so this table decides nothing about it.", ""]
    if v2:
        lines += ["Reading: `verdict (v1)` is the run's verdict under the v1 rules; `verdict` the v2 rules' "
                  "(primary reference `fusion`, or Fig. 3's ground-truth frames); `verdict_mesh` the v2 verdict "
                  "under the `mesh` reference; `min_effect` how many comparisons have the lower end of the "
                  "two-sided 95 % interval beyond the SESOI (0.02); `verdict_cluster` the same rules on the "
                  "t interval over the four kind means (3 df); `interval` the method (this run has one network "
                  "per architecture: v2's one-network interval, conditional on that network, so `provisional`). Claims F1-F2-real "
                  "are new in v2 and were not in the v1 plan: on this run they are exploratory.", ""]
    shown = claims.rename(columns={"verdict_before": "verdict (v1)"}).drop(columns=["statement"]).fillna("-")
    lines += ["## Claims", "", shown.to_markdown(index=False), ""]
    counts = claims["verdict"].value_counts()
    lines += ["Verdicts: " + ", ".join(f"{int(n)} {v}" for v, n in counts.items()) + ".", ""]
    adapt = rejudge_adaptation(figures_dir, plan=plan)
    if adapt is not None:
        before = rejudge_adaptation(figures_dir, plan=load_analysis_plan(PLAN_FILE))
        adapt["verdict_before"] = adapt["claim"].map(dict(zip(before["claim"], before["verdict"])))
        lines += ["## Adaptation claims", "",
                  "The share claims (A3, A3-self, A3-gt) on the per-scene mean over the fine-tuning seeds the run "
                  "scored (`adapt_seeds/`), with one-sided 97.5 % Fieller bounds under v2; the other claims on the "
                  "shipped fine-tuning seed (the only one notebook 09 scored on this run). `verdict (v1)`: the same "
                  "tables under the v1 rules (for A3 on the seed mean, so it differs from the published "
                  "shipped-seed verdict).", "",
                  pd.DataFrame({"claim": adapt["claim"], "role": adapt["role"], "comparison": adapt["comparison"],
                                "measure": adapt["measure"],
                                "difference": [(f"{d:.0%} (>= {lo:.0%}, <= {hi:.0%})" if k == "share" else
                                                _interval(d, lo, hi)) if not pd.isna(d) else "-" for d, lo, hi, k in
                                               zip(adapt["diff"], adapt["lo"], adapt["hi"], adapt["kind"])],
                                "seeds": adapt["seeds"], "verdict (v1)": adapt["verdict_before"],
                                "verdict": adapt["verdict"],
                                **({"beyond SESOI": adapt["min_effect"].map(_yes_no),
                                    "verdict_cluster": adapt["verdict_cluster"].fillna("-")} if v2 else {})}
                               ).to_markdown(index=False), ""]
    home = rejudge_in_home(figures_dir, plan=plan)
    if home is not None:
        home = home.assign(min_effect=home["min_effect"].map(_yes_no)) if v2 else home
        before = rejudge_in_home(figures_dir, plan=load_analysis_plan(PLAN_FILE))
        home["verdict (v1)"] = before["verdict"].to_numpy()  # the same comparisons in the same order
        cols = ["measure", "role", "comparison", "homes", "verdict (v1)", "verdict"] + \
            (["min_effect", "verdict_cluster"] if v2 else [])
        lines += ["## In-home study", "", "The in-home plan's comparisons (a family per measure).", "",
                  home.assign(difference=[_interval(d, lo, hi) for d, lo, hi in zip(home["diff"], home["lo"],
                                                                                      home["hi"])])
                  [cols[:3] + ["difference"] + cols[3:]].to_markdown(index=False), ""]
    comps_shown = pd.DataFrame({
        "claim": comps["claim"], "reference": comps["reference"], "model": comps["model"],
        "comparison": comps["comparison"],
        "difference [95 % CI]": [_interval(d, lo, hi) for d, lo, hi in zip(comps["diff"], comps["lo"], comps["hi"])],
        "verdict (v1)": comps["verdict_before"].fillna("-"), "verdict": comps["verdict"]})
    if v2:
        comps_shown["beyond SESOI"] = comps["min_effect"].map(_yes_no)
        comps_shown["kind clusters [95 % CI]"] = [_interval(d, lo, hi) for d, lo, hi in
                                                  zip(comps["cluster_diff"], comps["cluster_lo"], comps["cluster_hi"])]
        comps_shown["verdict_cluster"] = comps["verdict_cluster"]
    lines += ["## Every comparison", "", comps_shown.to_markdown(index=False), "", f"Comparisons: {len(comps)}.", ""]
    return "\n".join(lines)


def add_rejudge_parser(sub) -> None:
    """The ``rejudge`` subcommand of ``python -m semmatch.experiments``."""
    r = sub.add_parser("rejudge", help="a committed run's per-scene CSVs judged again under another plan's "
                                       "verdict rules (a secondary, labelled Markdown table)")
    r.add_argument("--rules", choices=sorted(RULE_FILES), default="v2", help="the verdict rules (default v2)")
    r.add_argument("--figures", default="figures/confirm/seeds-8001-8006",
                   help="the run's figures folder (default figures/confirm/seeds-8001-8006)")
    r.add_argument("--out", default="docs/results_confirmatory_v1_under_v2.md",
                   help="the Markdown file to write (default docs/results_confirmatory_v1_under_v2.md)")
    r.set_defaults(handler=_rejudge_main)


def _rejudge_main(args) -> int:
    from ..io import atomic_write_text

    command = (f"python -m semmatch.experiments rejudge --rules {args.rules} --figures {args.figures} "
               f"--out {args.out}")
    atomic_write_text(Path(args.out), rejudge_markdown(args.figures, rules=args.rules, command=command))
    print(args.out)
    return 0
