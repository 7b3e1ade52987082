"""The analysis plan's speed claims (P1-P3): on Table 1 (v1) or on ``semmatch bench transfer --repeat`` medians (v2).

:func:`judge_speed_claims` was defined in :mod:`semmatch.experiments.claims` before and is
importable from there as before.
"""

from __future__ import annotations

import pandas as pd

from .analysis_plan import AnalysisPlan, load_analysis_plan

__all__ = ["bench_speed_table", "judge_speed_claims"]


def bench_speed_table(bench: dict, *, map_name: str = "fused") -> pd.DataFrame:
    """Each method's median and lowest CPU rate from ``semmatch bench transfer --repeat N --json``.

    Parameters
    ----------
    bench : dict
        The benchmark's JSON record (``maps -> NAME -> spread -> method -> {median, min, max}``).
    map_name : str, optional
        The map timed (``fused``: the v2 plan's).

    Returns
    -------
    DataFrame
        ``method, median, min, max`` (the reference workload left out).

    Raises
    ------
    ValueError
        If the record has no spread over repeated runs for ``map_name``.
    """
    spread = (bench.get("maps", {}).get(map_name) or {}).get("spread")
    if not spread:
        raise ValueError(f"bench_speed_table: the record has no spread over repeated runs for map {map_name!r} "
                         "(run semmatch bench transfer --map fused --repeat 5 --json)")
    rows = [dict(method=m, median=float(v["median"]), min=float(v["min"]), max=float(v["max"]))
            for m, v in spread.items() if not m.startswith("reference")]
    return pd.DataFrame(rows, columns=["method", "median", "min", "max"])


def judge_speed_claims(table1: pd.DataFrame, *, plan: AnalysisPlan | None = None) -> pd.DataFrame:
    """The plan's speed claims judged on Table 1 (one measurement: holds / does not hold).

    Parameters
    ----------
    table1 : DataFrame
        ``method`` and ``fps`` (frames per second of each transfer method; a ``cpu_fps`` column,
        the rate from the method's CPU time on one core, is used instead when present). Under a
        v2 plan: ``method``, ``median`` and ``min`` (:func:`bench_speed_table`); a table without
        them (Table 1) is not judged.
    plan : AnalysisPlan, optional
        Default the committed plan.

    Returns
    -------
    DataFrame
        ``claim, statement, section, role, rule, evidence, verdict``.
    """
    plan = load_analysis_plan() if plan is None else plan
    v2 = plan.rules == "v2"
    col = "median" if v2 else "cpu_fps" if "cpu_fps" in table1.columns else "fps"
    if v2 and not {"method", "median", "min"} <= set(table1.columns):
        return pd.DataFrame([dict(claim=c["id"], statement=c["statement"], section=c["section"],
                                  role=c.get("role", "primary"), rule=c["rule"],
                                  evidence="no bench transfer --repeat record (Table 1 is descriptive under v2)",
                                  verdict="not judged") for c in plan.speed_claims])
    if "method" not in table1.columns or col not in table1.columns:
        raise ValueError(f"judge_speed_claims: Table 1 needs the columns 'method' and '{col}'")
    fps = dict(zip(table1["method"], table1[col].astype(float)))
    lowest = dict(zip(table1["method"], table1["min"].astype(float))) if v2 else fps
    rows = []
    for c in plan.speed_claims:
        if "min_fps" in c:
            need = float(c.get("median_fps", c["min_fps"]))
            slow = {m for m, f in fps.items() if f < need}
            if "median_fps" in c:
                slow |= {m for m, f in lowest.items() if f < float(c["min_fps"])}
            ok = not slow
            evidence = (f"slowest {min(fps, key=fps.get)} {min(fps.values()):.1f} FPS" if fps else "no rows")
            if v2 and fps:
                evidence += f" (median; lowest run of any method {min(lowest.values()):.1f})"
            evidence += "" if ok else f"; below {c.get('median_fps', c['min_fps']) if v2 else c['min_fps']}" + \
                (" (median) or the lowest run" if "median_fps" in c else "") + f": {', '.join(sorted(slow))}"
        else:
            slowest = [m for m in c["slowest"] if m in fps]
            rest = [f for m, f in fps.items() if m not in c["slowest"]]
            ok = bool(slowest) and bool(rest) and max(fps[m] for m in slowest) < min(rest)
            evidence = ", ".join(f"{m} {f:.1f}" for m, f in sorted(fps.items(), key=lambda kv: kv[1])) + " FPS"
        rows.append(dict(claim=c["id"], statement=c["statement"], section=c["section"],
                         role=c.get("role", "primary"), rule=c["rule"], evidence=evidence,
                         verdict="holds" if ok else "does not hold"))
    return pd.DataFrame(rows, columns=["claim", "statement", "section", "role", "rule", "evidence", "verdict"])
