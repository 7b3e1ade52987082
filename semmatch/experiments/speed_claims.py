"""The analysis plan's speed claims (P1-P3): on Table 1 (v1) or on ``semmatch bench transfer --repeat`` medians (v2).

:func:`judge_speed_claims` was defined in :mod:`semmatch.experiments.claims` before and is
importable from there as before. :func:`run_speed_bench` runs the v2 plan's benchmark
(``speed.command``: ``semmatch bench transfer --map fused --repeat 5``) in a fresh process and
keeps its JSON record with the machine and its load (:data:`BENCH_RECORD` in a run's figures
folder, where :func:`semmatch.experiments.claims.judge_figures` reads it under a v2 plan).
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import pandas as pd

from .analysis_plan import AnalysisPlan, load_analysis_plan

__all__ = ["BENCH_RECORD", "bench_speed_table", "judge_speed_claims", "lever_settings", "speed_bench_command",
           "run_speed_bench", "bench_conditions"]

#: the speed benchmark's record in a run's figures folder (:func:`run_speed_bench`)
BENCH_RECORD = "bench_speed.json"
#: the reference workload's row in the benchmark's spread (the published closest-point backend)
_REFERENCE = "reference (closest point)"


def lever_settings(plan: AnalysisPlan, params: Mapping, where: str = "the run's parameters") -> dict[str, dict]:
    """The plan's speed lever as a run states it: ``{method: {parameter: value}}``.

    The plan's ``speed.lever`` names the method and ``params_key``, the dotted path of the
    setting in a run's parameters ``params`` (``profiles.full.common.slic_2d``; the profiles as
    :func:`~semmatch.experiments.pipeline.read_params` composes them); the value found there
    must be the plan's ``chosen_value``, so a run cannot be judged under a lever its plan did not
    choose. A plan without a lever gives ``{}``.

    Raises
    ------
    ValueError
        The parameters lack the key, or its value is not the plan's chosen value (naming ``where``).
    """
    lever = (plan.raw.get("speed") or {}).get("lever")
    if not lever:
        return {}
    value: object = params
    for part in str(lever["params_key"]).split("."):
        if not isinstance(value, dict) or part not in value:
            raise ValueError(f"{where}: analysis plan v{plan.version}'s speed lever is read from "
                             f"{lever['params_key']}, which is not there")
        value = value[part]
    chosen = lever.get("chosen_value")
    if chosen is not None and value != chosen:
        raise ValueError(f"{where}: {lever['params_key']} is {value!r}, but analysis plan v{plan.version} "
                         f"chose {chosen!r} for {lever['method']}")
    return {str(lever["method"]): dict(value or {})}


def speed_bench_command(plan: AnalysisPlan, settings: Mapping[str, Mapping] | None = None) -> list[str]:
    """The plan's speed benchmark (``speed.command``) as an argument list with ``--json``, run by
    this Python (``python -m semmatch ...``); ``settings`` (:func:`lever_settings`) become its
    ``--param METHOD:KEY=VALUE`` options.

    Raises
    ------
    ValueError
        If the plan states no ``speed.command`` or it is not a ``semmatch`` command.
    """
    words = shlex.split(str((plan.raw.get("speed") or {}).get("command") or ""))
    if not words or words[0] != "semmatch":
        raise ValueError(f"analysis plan v{plan.version}: speed.command must be a semmatch command "
                         f"(e.g. 'semmatch bench transfer --map fused --repeat 5'), got {words or None}")
    params = [f"--param={m}:" + ",".join(f"{k}={json.dumps(v)}" for k, v in kv.items())
              for m, kv in (settings or {}).items() if kv]
    return [sys.executable, "-m", "semmatch", *words[1:], *params, *([] if "--json" in words else ["--json"])]


def run_speed_bench(out_dir: str | os.PathLike, plan: AnalysisPlan, *, cwd: str | os.PathLike | None = None,
                    settings: Mapping[str, Mapping] | None = None) -> dict:
    """Run the plan's speed benchmark once in a fresh (otherwise idle) process and keep its record.

    Parameters
    ----------
    out_dir : path
        Where :data:`BENCH_RECORD` is written (a run's figures folder).
    plan : AnalysisPlan
        Its ``speed.command`` is run (:func:`speed_bench_command`).
    cwd : path, optional
        Working directory of the benchmark.
    settings : mapping, optional
        The methods' settings passed to the benchmark: the plan's speed lever as the run states
        it (:func:`lever_settings`).

    Returns
    -------
    dict
        The benchmark's JSON record with ``command``, ``machine``
        (:func:`semmatch.segment.training.machine_record` of the CPU), ``load_average_before``,
        ``started``, ``wall_seconds`` and ``conditions`` (:func:`bench_conditions`) added.

    Raises
    ------
    RuntimeError
        If the benchmark fails or prints no JSON record (its command and the end of its output).
    """
    from ..io import atomic_write_text
    from ..segment.training import machine_record

    cmd = speed_bench_command(plan, settings)
    shown = " ".join(["semmatch", *cmd[3:]])
    load = [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None
    started, t = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), time.perf_counter()
    print(f"[speed] {shown} (load {load})", file=sys.stderr)
    done = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    lines = [x for x in done.stdout.splitlines() if x.strip()]
    try:
        bench = json.loads(lines[-1]) if done.returncode == 0 and lines else None
    except json.JSONDecodeError:
        bench = None
    if not isinstance(bench, dict):
        raise RuntimeError(f"{shown}: exit status {done.returncode}, no JSON record; its output ends: "
                           f"{(done.stderr or done.stdout)[-800:]}")
    record = {**bench, "command": shown, "machine": machine_record("cpu"), "load_average_before": load,
              "started": started, "wall_seconds": round(time.perf_counter() - t, 1)}
    record["conditions"] = bench_conditions(record)
    atomic_write_text(Path(out_dir) / BENCH_RECORD, json.dumps(record, indent=2) + "\n")
    return record


def bench_conditions(bench: dict, *, map_name: str = "fused") -> dict:
    """The conditions of a benchmark record the v2 plan asks to state: the machine (CPU model and
    count), the 1-minute load average over the repeated runs and the reference workload's rate.

    Parameters
    ----------
    bench : dict
        A :func:`run_speed_bench` record (or the bare benchmark JSON: no machine then).
    map_name : str, optional

    Returns
    -------
    dict
        ``cpu``, ``cpu_count``, ``load_min``, ``load_max`` and ``reference_fps`` (the reference's
        median CPU rate; min and max beside it); None where the record lacks them.
    """
    result = (bench.get("maps") or {}).get(map_name) or {}
    loads = [float(r["load_average"]) for r in result.get("runs", []) if r.get("load_average") is not None]
    ref = (result.get("spread") or {}).get(_REFERENCE) or {}
    machine = bench.get("machine") or {}
    return {"cpu": machine.get("device_name"), "cpu_count": machine.get("cpu_count"),
            "load_min": min(loads) if loads else None, "load_max": max(loads) if loads else None,
            "reference_fps": ref.get("median"), "reference_fps_min": ref.get("min"),
            "reference_fps_max": ref.get("max")}


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
        ``method, median, min, max`` of the transfer methods (``fused`` included); the reference
        workload and the variant rows (``3d-neighborhood (exact)``, ``--variant`` rows) left out.

    Raises
    ------
    ValueError
        If the record has no spread over repeated runs for ``map_name``.
    """
    spread = (bench.get("maps", {}).get(map_name) or {}).get("spread")
    if not spread:
        raise ValueError(f"bench_speed_table: the record has no spread over repeated runs for map {map_name!r} "
                         "(run semmatch bench transfer --map fused --repeat 5 --json)")
    from ..transfer import available_methods

    rows = [dict(method=m, median=float(v["median"]), min=float(v["min"]), max=float(v["max"]))
            for m, v in spread.items() if m in available_methods()]
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
