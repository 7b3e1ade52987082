"""The real-like diagnostics' tables and figure (:mod:`semmatch.experiments.real_diagnostics`).

From the study's per-scene scores, trajectories and registrations: every arm's measures over
scenes with the analysis plan's interval (draws averaged per scene first) and the draw-to-draw
spread; the paired differences that say what each part of the chain costs; the claims'
contrasts within each arm; and one figure (arms, drift sweep, trajectory and registration
errors).
"""

from __future__ import annotations

import json
import re
import textwrap
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..evaluate.metrics import MEASURES

__all__ = ["SHOWN", "DIFFERENCES", "CONTRASTS", "APPEARANCE_ARMS", "PAPER_GAP", "draw_spread", "summarize_arms",
           "arm_differences", "appearance_gap", "plot_appearance_gap", "plot_diagnostics", "write_diagnostics"]


#: rows shown in the summaries and the figure: (model, method); "<net>" is each network
SHOWN = (("ground truth", "3d-neighborhood"), ("<net>", "3d-neighborhood"), ("<net>", "fused"),
         ("<net>", "lower"), ("<net>", "upper"))

#: the paired arm differences of :func:`arm_differences`: (what it measures, arm a, arm b), a - b
DIFFERENCES = (
    ("sensor noise (true poses)", "noisy, true poses", "clean, true poses"),
    ("estimated poses (clean frames)", "clean, estimated poses", "clean, true poses"),
    ("estimated poses (noisy frames)", "chain", "noisy, true poses"),
    ("person tracked visually only", "person visual-only", "chain"),
    ("held-out appearance (true poses)", "held-out appearance, true poses", "noisy, true poses"),
    ("held-out appearance (chain)", "chain, held-out appearance", "chain"),
)

#: the appearance gap's first arms: synthetic frames, the sensor model; the held-out looks at true
#: poses follow, by severity (``held-out appearance xS, true poses``; no ``xS``: severity 1)
APPEARANCE_ARMS = ("clean, true poses", "noisy, true poses")


def _look(arm) -> float | None:
    """The severity of a held-out-look arm at true poses (``held-out appearance xS, true poses``; no
    ``xS``: 1), None for any other arm."""
    m = re.fullmatch(r"held-out appearance(?: x([0-9.]+))?, true poses", str(arm))
    return None if m is None else float(m.group(1) or 1.0)


def _differences(arms) -> list[tuple[str, str, str]]:
    """:data:`DIFFERENCES` and, per held-out look at another severity among ``arms``, its cost at
    true poses and in the chain."""
    out = list(DIFFERENCES)
    for a in arms:
        if _look(a) not in (None, 1.0):
            tag = a.removeprefix("held-out appearance ").removesuffix(", true poses")
            out.append((f"held-out appearance {tag} (true poses)", a, "noisy, true poses"))
            out.append((f"held-out appearance {tag} (chain)", f"chain, held-out appearance {tag}", "chain"))
    return out


def _appearance_arms(arms) -> list[str]:
    """:data:`APPEARANCE_ARMS` and the held-out-look arms at true poses among ``arms``, by severity."""
    held = {a: _look(a) for a in dict.fromkeys(arms) if _look(a) is not None}
    return [*APPEARANCE_ARMS, *sorted(held, key=held.get)]

#: the paper's Mask R-CNN rows (Mean Acc.): synthetic (Table 2) and real (Table 3)
PAPER_GAP = {"lower": (0.766, 0.590), "3d-neighborhood": (0.808, 0.768)}

#: the within-arm contrasts of :func:`arm_differences`: (name, method a, method b), per network
CONTRASTS = (
    ("transfer - lower (C15)", "3d-neighborhood", "lower"),
    ("transfer - upper (C16)", "3d-neighborhood", "upper"),
    ("fused - lower", "fused", "lower"),
)


def _per_scene(scores: pd.DataFrame) -> pd.DataFrame:
    """Scores averaged over draws: one row per arm, drift, scene, model and method."""
    key = ["arm", "drift", "scene", "model", "method"]
    out = scores.groupby(key, sort=False)[list(MEASURES)].mean().reset_index()
    out["draws"] = scores.groupby(key, sort=False)["draw"].nunique().to_numpy()
    return out


def draw_spread(scores: pd.DataFrame, measure: str = "mean_acc") -> pd.DataFrame:
    """How much the mean over scenes moves from draw to draw.

    Returns
    -------
    DataFrame
        arm, drift, model, method, draws, ``<measure>`` per draw as ``draw_<d>``, their
        standard deviation ``draw_sd`` and range ``draw_range`` (NaN with one draw).
    """
    means = scores.groupby(["arm", "drift", "model", "method", "draw"], sort=False)[measure].mean()
    wide = means.unstack("draw")
    wide.columns = [f"draw_{int(d)}" for d in wide.columns]
    vals = wide.to_numpy(np.float64)
    n = np.sum(~np.isnan(vals), axis=1)
    out = wide.reset_index()
    out.insert(4, "draws", n)
    sd, rng = np.full(len(vals), np.nan), np.full(len(vals), np.nan)
    for i in np.flatnonzero(n > 1):
        v = vals[i][~np.isnan(vals[i])]
        sd[i], rng[i] = np.std(v, ddof=1), v.max() - v.min()
    out["draw_sd"], out["draw_range"] = sd, rng
    return out


def summarize_arms(result: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """Every arm's measures over scenes (draws averaged per scene) with the analysis plan's interval.

    Beside them: the draws, the draw-to-draw standard deviation of the Mean Acc. over scenes,
    the mean ATE (m, after alignment) of the person's and the robot's estimated poses and the
    median registration error (m, degrees; over scenes and draws: one failed registration would
    dominate a mean), where the arm estimates them.

    Returns
    -------
    DataFrame
        arm, drift, model, method, scenes, draws, each measure with ``_lo``/``_hi``, draw_sd,
        ate_upper_m, ate_lower_m, reg_trans_err_median_m, reg_rot_err_median_deg.
    """
    from .summaries import summarize_over_scenes

    per_scene = _per_scene(result["scores"])
    summary = summarize_over_scenes(per_scene, by=("arm", "drift", "model", "method"))
    summary.insert(5, "draws", per_scene.groupby(["arm", "drift", "model", "method"], sort=False)["draws"].max()
                   .to_numpy())
    spread = draw_spread(result["scores"])[["arm", "drift", "model", "method", "draw_sd"]]
    summary = summary.merge(spread, on=["arm", "drift", "model", "method"], how="left")
    traj = result["trajectories"]
    if len(traj):
        est = traj[traj["poses"] == "estimated"]
        ate = est.pivot_table(index=["arm", "drift"], columns="sequence", values="ate_rmse", aggfunc="mean")
        ate = ate.rename(columns={"upper": "ate_upper_m", "lower": "ate_lower_m"}).reset_index()
        summary = summary.merge(ate, on=["arm", "drift"], how="left")
    reg = result["registration"]
    if len(reg):
        r = reg.groupby(["arm", "drift"], sort=False)[["reg_trans_err_m", "reg_rot_err_deg"]].median().reset_index()
        r = r.rename(columns={"reg_trans_err_m": "reg_trans_err_median_m", "reg_rot_err_deg": "reg_rot_err_median_deg"})
        summary = summary.merge(r, on=["arm", "drift"], how="left")
    return summary


def _paired(a: pd.Series, b: pd.Series) -> dict | None:
    """Mean of the paired differences ``a - b`` over the scenes both have, with the plan's interval."""
    from ..evaluate.stats import interval, scene_kind
    from .analysis_plan import load_analysis_plan

    d = (a - b).dropna()
    if d.empty:
        return None
    plan = load_analysis_plan()
    mean, lo, hi = interval(d.to_numpy(np.float64), [scene_kind(s) for s in d.index], method=plan.interval,
                            confidence=plan.confidence)
    return dict(diff=mean, lo=lo, hi=hi, scenes=int(d.size))


def arm_differences(result: dict[str, pd.DataFrame], measure: str = "mean_acc") -> tuple[pd.DataFrame, pd.DataFrame]:
    """What each part of the chain costs, and the claims' contrasts within each arm, paired per scene.

    Returns
    -------
    differences : DataFrame
        effect, ``a - b`` (:data:`DIFFERENCES`), model, method, diff, lo, hi, scenes: the change
        of ``measure`` of one row between two arms at the simulator's drift.
    contrasts : DataFrame
        arm, drift, model, contrast (:data:`CONTRASTS`), diff, lo, hi, scenes: two rows of one arm.
    """
    per_scene = _per_scene(result["scores"])
    wide = per_scene.pivot_table(index="scene", columns=["arm", "drift", "model", "method"], values=measure)
    diffs = []
    for effect, a, b in _differences(dict.fromkeys(arm for arm, *_ in wide.columns)):
        for model, method in sorted({(m, t) for (arm, _, m, t) in wide.columns if arm == a}):
            ka, kb = (a, 1.0, model, method), (b, 1.0, model, method)
            if ka in wide.columns and kb in wide.columns:
                c = _paired(wide[ka], wide[kb])
                if c is not None:
                    diffs.append(dict(effect=effect, comparison=f"{a} - {b}", model=model, method=method, **c))
    contrasts = []
    for arm, drift in dict.fromkeys((a, d) for (a, d, _, _) in wide.columns):
        for model in dict.fromkeys(m for (a, d, m, _) in wide.columns if (a, d) == (arm, drift)):
            for name, ma, mb in CONTRASTS:
                ka, kb = (arm, drift, model, ma), (arm, drift, model, mb)
                if ka in wide.columns and kb in wide.columns:
                    c = _paired(wide[ka], wide[kb])
                    if c is not None:
                        contrasts.append(dict(arm=arm, drift=drift, model=model, contrast=name, **c))
    return pd.DataFrame(diffs), pd.DataFrame(contrasts)


def _shown_rows(summary: pd.DataFrame) -> list[tuple[str, str]]:
    nets = [m for m in dict.fromkeys(summary["model"]) if m != "ground truth"]
    rows = []
    for model, method in SHOWN:
        for m in (nets if model == "<net>" else [model]):
            if ((summary["model"] == m) & (summary["method"] == method)).any():
                rows.append((m, method))
    return rows


def plot_diagnostics(summary: pd.DataFrame, path: str | Path, *, measure: str = "mean_acc",
                     arms: Sequence[str] | None = None) -> Path:
    """Three panels: ``measure`` per arm (simulator's drift; ``arms`` gives their order, default
    the summary's), ``measure`` against the drift level (``chain``), and the estimated
    trajectories' ATE against the drift level; means over scenes with the analysis plan's
    interval."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import save_figure

    rows = _shown_rows(summary)
    arms = [a for a in (arms or dict.fromkeys(summary["arm"])) if (summary["arm"] == a).any()]
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.0), gridspec_kw=dict(width_ratios=[2, 1, 1]))
    width = 0.8 / max(len(rows), 1)
    base = summary[summary["drift"] == 1.0]
    for i, (model, method) in enumerate(rows):
        g = base[(base["model"] == model) & (base["method"] == method)].set_index("arm").reindex(arms)
        x = np.arange(len(arms)) + (i - (len(rows) - 1) / 2) * width
        y = g[measure].to_numpy(np.float64)
        err = np.vstack([y - g[f"{measure}_lo"].to_numpy(np.float64), g[f"{measure}_hi"].to_numpy(np.float64) - y])
        axes[0].bar(x, y, width, yerr=err, capsize=2, label=f"{model}: {method}")
    axes[0].set_xticks(np.arange(len(arms)), [textwrap.fill(a, 18) for a in arms], fontsize="x-small", rotation=35,
                       ha="right", rotation_mode="anchor")
    axes[0].set_ylabel(f"{measure.replace('_', ' ')} (mean over scenes, 95 % interval)")
    axes[0].set_title("arms (simulator's drift)")
    lo = np.nanmin(base[f"{measure}_lo"].to_numpy(np.float64)) if len(base) else 0.0
    axes[0].set_ylim(max(0.0, lo - 0.05), 1.0)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(rows), fontsize="small", frameon=False)
    sweep = summary[summary["arm"] == "chain"].sort_values("drift")
    for model, method in rows:
        g = sweep[(sweep["model"] == model) & (sweep["method"] == method)]
        (line,) = axes[1].plot(g["drift"], g[measure], marker="o", label=f"{model}: {method}")
        axes[1].fill_between(g["drift"], g[f"{measure}_lo"], g[f"{measure}_hi"], color=line.get_color(), alpha=0.15)
    axes[1].set_xlabel("prior drift (x the simulator's)")
    axes[1].set_title("chain: drift of the priors")
    per_drift = sweep.drop_duplicates("drift")
    for col, label in (("ate_upper_m", "person (estimated)"), ("ate_lower_m", "robot (estimated)")):
        if col in per_drift.columns:
            axes[2].plot(per_drift["drift"], per_drift[col] * 100, marker="o", label=label)
    if "reg_trans_err_median_m" in per_drift.columns:
        axes[2].plot(per_drift["drift"], per_drift["reg_trans_err_median_m"] * 100, marker="s", ls="--",
                     label="registration error (median)")
    axes[2].set_xlabel("prior drift (x the simulator's)")
    axes[2].set_ylabel("cm (ATE: mean over scenes and draws)")
    axes[2].set_title("trajectory ATE and registration error")
    axes[2].legend(fontsize="small")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return save_figure(fig, path)


def appearance_gap(summary: pd.DataFrame, measure: str = "mean_acc") -> pd.DataFrame:
    """The appearance gap: each shown row's ``measure`` on synthetic frames, Kinect-like frames and
    Kinect-like frames with the held-out look at each severity (true poses), and the drops from
    synthetic to each look beside the paper's drop from its synthetic to its real data
    (:data:`PAPER_GAP`, Mask R-CNN; empty where the paper has no such row).

    Returns
    -------
    DataFrame
        model, method, one column per arm (``measure`` and its interval), ``drop xS`` per look
        (synthetic minus that look), ``paper_synthetic``, ``paper_real``, ``paper_drop``; empty
        when the clean, noisy or every held-out arm is missing.
    """
    arms = _appearance_arms(summary["arm"])
    base = summary[(summary["drift"] == 1.0) & summary["arm"].isin(arms)]
    if not set(APPEARANCE_ARMS) <= set(base["arm"]) or len(arms) == len(APPEARANCE_ARMS):
        return pd.DataFrame()
    rows = []
    for model, method in _shown_rows(base):
        if method == "upper":
            continue
        g = base[(base["model"] == model) & (base["method"] == method)].set_index("arm")
        row = {"model": model, "method": method}
        for arm in arms:
            for suffix in ("", "_lo", "_hi"):
                row[f"{arm}{suffix}"] = float(g.loc[arm, f"{measure}{suffix}"])
        for arm in arms[len(APPEARANCE_ARMS):]:
            row[f"drop {arm.removeprefix('held-out appearance').removesuffix(', true poses').strip() or 'x1'}"] = (
                row[arms[0]] - row[arm])
        paper = PAPER_GAP.get(method) if model != "ground truth" else None
        row.update(paper_synthetic=paper[0] if paper else np.nan, paper_real=paper[1] if paper else np.nan,
                   paper_drop=paper[0] - paper[1] if paper else np.nan)
        rows.append(row)
    return pd.DataFrame(rows)


def plot_appearance_gap(gap: pd.DataFrame, path: str | Path, *, measure: str = "mean_acc") -> Path:
    """``measure`` from synthetic frames to the held-out looks per row (95 % intervals), with the
    paper's synthetic-to-real change of its lower view and 3D neighborhood rows beside them, its
    real end at the mildest look when there are several (the one sized like the paper's gap)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import save_figure

    arms = _appearance_arms(c.removesuffix("_lo") for c in gap.columns if c.endswith("_lo"))
    fig, ax = plt.subplots(figsize=(8.5, 4.4))
    x = np.arange(len(arms))
    real = len(APPEARANCE_ARMS) if len(arms) > len(APPEARANCE_ARMS) + 1 else len(arms) - 1  # the look sized like the paper's
    for _, r in gap.iterrows():
        y = np.array([r[a] for a in arms])
        err = np.vstack([y - [r[f"{a}_lo"] for a in arms], [r[f"{a}_hi"] for a in arms] - y])
        (line,) = ax.plot(x, y, marker="o", label=f"{r['model']}: {r['method']}")
        ax.errorbar(x, y, yerr=err, fmt="none", ecolor=line.get_color(), capsize=3)
        if np.isfinite(r["paper_synthetic"]):
            ax.plot([x[0] - 0.15, x[real] + 0.15], [r["paper_synthetic"], r["paper_real"]], ls=":", marker="s",
                    color=line.get_color(), alpha=0.8, label=f"paper (Mask R-CNN): {r['method']}, synthetic -> real")
    looks = [a.removeprefix("held-out appearance").removesuffix(", true poses").strip() or "x1" for a in arms[2:]]
    ax.set_xticks(x, ["synthetic\n(clean)", "Kinect-like\nnoise", *(f"noise +\nheld-out look {v}" for v in looks)])
    ax.set_ylabel(f"{measure.replace('_', ' ')} (mean over scenes, 95 % interval)")
    ax.set_title("The appearance gap (true poses)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="x-small", loc="lower left")
    fig.tight_layout()
    return save_figure(fig, path)


def write_diagnostics(result: dict[str, pd.DataFrame], figures: str | Path, *, minutes: float,
                      settings: dict, arms: Sequence[str] | None = None) -> list[Path]:
    """Write the study's tables (CSV and Markdown), its figure (arms in the order ``arms``) and
    ``run.json`` into ``figures``."""
    from ..io import atomic_write_text
    from .tables import save_interval_table, save_table

    figures = Path(figures)
    figures.mkdir(parents=True, exist_ok=True)
    summary = summarize_arms(result)
    differences, contrasts = arm_differences(result)
    out = list(save_interval_table(summary, figures, "real_diagnostics_arms",
                                   keep=("draw_sd", "ate_upper_m", "ate_lower_m", "reg_trans_err_median_m",
                                         "reg_rot_err_median_deg")))
    for name, df in (("real_diagnostics_differences", differences), ("real_diagnostics_contrasts", contrasts),
                     ("real_diagnostics_draw_spread", draw_spread(result["scores"])),
                     ("real_diagnostics_per_scene", result["scores"]),
                     ("real_diagnostics_trajectories", result["trajectories"]),
                     ("real_diagnostics_registration", result["registration"])):
        out += list(save_table(df, figures, name))
    out.append(plot_diagnostics(summary, figures / "real_diagnostics.png", arms=arms))
    gap = appearance_gap(summary)
    if len(gap):
        out += list(save_table(gap, figures, "real_diagnostics_appearance_gap"))
        out.append(plot_appearance_gap(gap, figures / "real_diagnostics_appearance_gap.png"))
    atomic_write_text(figures / "run.json", json.dumps(
        dict(settings, scenes=int(result["scores"]["scene"].nunique()), minutes=round(minutes, 1),
             tasks=len(result["tasks"]), tasks_reused=int(result["tasks"]["reused"].sum()),
             finished=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())), indent=1))
    out.append(figures / "run.json")
    return out
