"""The refusal thresholds of ``semmatch align`` chosen on validation pairs by a rule fixed in advance.

The rule (written down before the validation run; docs/recordings.md, "How the thresholds were
chosen", states it in words):

1. **Pairs.** Each validation scene's robot recording aligned into its own person's map (a
   *right* pair) and into the next scene's person's map (a *wrong* pair: two different rooms,
   scenes in the order given, the last one's robot into the first one's map).
2. **Labels.** A pair *must be refused* when it is a wrong pair, or a right pair whose error
   against the mesh-fit truth exceeds ``max_trans_m`` (5 cm) or ``max_rot_deg`` (2 degrees);
   every other right pair is *good* (:func:`must_refuse`).
3. **Cost** of a set of thresholds, every check applied as ``semmatch align`` applies them
   (:func:`semmatch.poses.alignment.check_alignment`): first the number of pairs that must be
   refused and are accepted, then the number of good pairs refused, compared in that order (a
   wrong acceptance writes wrong labels without a word; a refusal is said).
4. **Search.** For one check, every threshold between two consecutive values that the validation
   pairs took acts alike (an *interval*). Every combination of one interval per check is
   costed; among the lowest-cost combinations the one that moves the fewest checks off the
   interval holding their current value (:data:`~semmatch.poses.alignment.DEFAULT_CHECKS`) is
   kept, then the one that moves them by the fewest intervals. Each check's threshold is then
   placed in the middle of its *run* (the consecutive intervals around the kept one that give
   every pair the same verdict, the other checks as chosen): the current value stays where
   the run is open (beyond every validation value) and holds it; an open run that does not
   hold it puts the threshold 10 % beyond the last validation value.

:func:`choose_thresholds` applies the rule and says per check what it saw; :func:`judge_rows`
re-judges stored alignments under other thresholds (an alignment does not depend on its
thresholds, only its verdict does).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pandas as pd

__all__ = ["CHECK_VALUES", "TRUTHS", "must_refuse", "judge_rows", "choose_thresholds", "threshold_figure"]

#: the column of a study row (:func:`semmatch.experiments.alignment_study.two_height_scene`) each check reads
CHECK_VALUES: dict[str, str] = {
    "min_structure_fitness": "structure_fitness",
    "min_agreement": "agreement",
    "max_inlier_rmse": "inlier_rmse",
    "max_floor_angle": "floor_angle_deg",
    "max_floor_offset": "floor_offset_m",
}


#: the errors that can label right pairs (:func:`must_refuse`)
TRUTHS = ("mesh", "trajectory", "mesh-or-trajectory")


def must_refuse(rows: pd.DataFrame, *, max_trans_m: float = 0.05, max_rot_deg: float = 2.0,
                truth: str = "mesh") -> np.ndarray:
    """Per pair: whether it must be refused (a wrong pair, or a right pair off by more than the target).

    Parameters
    ----------
    rows : DataFrame
        ``scene``, ``person`` (another scene: a wrong pair), ``trans_err_mesh_m``, ``rot_err_mesh_deg``
        (``trans_err_m``, ``rot_err_deg`` with ``truth="trajectory"``).
    max_trans_m, max_rot_deg : float
        The target: a right pair within both is good.
    truth : {"mesh", "trajectory", "mesh-or-trajectory"}
        The errors that label right pairs: against each map fitted onto the scene's mesh (the
        rule's), against the trajectories aligned onto their true ones (pairs run without a
        mesh fit; a weaker truth, off by the odometry's drift), or the mesh fit where a pair has
        one and the trajectory truth elsewhere.

    Returns
    -------
    ndarray of bool

    Raises
    ------
    ValueError
        A right pair without its mesh-fit error (the label would be a guess).
    """
    if truth not in TRUTHS:
        raise ValueError(f"truth must be one of {TRUTHS}, got {truth!r}")
    wrong = (rows["person"] != rows["scene"]).to_numpy()

    def col(c):
        return rows[c].to_numpy(float) if c in rows else np.full(len(rows), np.nan)

    t, r = col("trans_err_mesh_m"), col("rot_err_mesh_deg")
    if truth != "mesh":
        use = ~(np.isfinite(t) & np.isfinite(r)) if truth == "mesh-or-trajectory" else np.ones(len(rows), bool)
        t, r = np.where(use, col("trans_err_m"), t), np.where(use, col("rot_err_deg"), r)
    unknown = ~wrong & ~(np.isfinite(t) & np.isfinite(r))
    if unknown.any():
        raise ValueError(f"right pairs without a {truth} error: {list(rows['scene'][unknown])}"
                         + (" (a scene.ply is needed)" if truth == "mesh" else ""))
    return wrong | (~wrong & ((t > max_trans_m) | (r > max_rot_deg)))


def judge_rows(rows: pd.DataFrame, thresholds: Mapping[str, float]) -> np.ndarray:
    """Per pair: whether its alignment passes ``thresholds`` (as ``semmatch align`` judges it).

    Parameters
    ----------
    rows : DataFrame
        The columns of :data:`CHECK_VALUES` (the floor columns NaN where no floors were found).
    thresholds : mapping
        Keys of :data:`~semmatch.poses.alignment.DEFAULT_CHECKS` (missing ones: the defaults).

    Returns
    -------
    ndarray of bool
    """
    from ..poses.alignment import check_alignment

    out = []
    for _, r in rows.iterrows():
        values = {v: float(r[v]) if v in r and pd.notna(r[v]) else float("nan") for v in CHECK_VALUES.values()}
        out.append(all(c["passed"] for c in check_alignment(values, dict(thresholds)).values()))
    return np.array(out, dtype=bool)


def _intervals(values: np.ndarray) -> list[tuple[float, float]]:
    """The intervals between consecutive distinct values, open at both ends."""
    u = np.unique(values[np.isfinite(values)])
    edges = [-math.inf, *u.tolist(), math.inf]
    return list(zip(edges[:-1], edges[1:], strict=True))


def _holds(t: float, lo: float, hi: float, minimum: bool) -> bool:
    """Whether threshold ``t`` acts as the interval (lo, hi) does: a minimum passes v >= t, a maximum v <= t."""
    return (lo < t <= hi) if minimum else (lo <= t < hi)


def _check_table(rows: pd.DataFrame, name: str, current: float) -> dict:
    """One check's intervals, the pairs each passes, and the interval that holds ``current``."""
    minimum = name.startswith("min_")
    col = rows[CHECK_VALUES[name]].to_numpy(float) if CHECK_VALUES[name] in rows else np.full(len(rows), np.nan)
    if name == "max_floor_offset":
        col = np.abs(col)
    skipped = ~np.isfinite(col) if name.startswith("max_floor") else np.zeros(len(col), bool)  # no floors: no check
    intervals = _intervals(col)
    masks = []
    for lo, hi in intervals:
        with np.errstate(invalid="ignore"):
            passes = (col >= hi) if minimum else (col <= lo)
        masks.append(passes | skipped)
    home = next(k for k, (lo, hi) in enumerate(intervals) if _holds(current, lo, hi, minimum))
    return {"minimum": minimum, "values": col, "intervals": intervals, "masks": masks, "home": home}


def _place(table: dict, run: tuple[int, int], current: float) -> float:
    """The threshold in a run of equivalent intervals (rule 4): its middle, or the current value
    where the run is open and holds it, or 10 % beyond the last value of an open run."""
    lo, hi = table["intervals"][run[0]][0], table["intervals"][run[1]][1]
    if math.isfinite(lo) and math.isfinite(hi):
        return (lo + hi) / 2
    if _holds(current, lo, hi, table["minimum"]):
        return float(current)
    if math.isfinite(lo):
        return lo + 0.1 * abs(lo) if lo else 0.0
    if math.isfinite(hi):
        return hi - 0.1 * abs(hi) if hi else 0.0
    return float(current)


def choose_thresholds(rows: pd.DataFrame, defaults: Mapping[str, float] | None = None, *,
                      max_trans_m: float = 0.05, max_rot_deg: float = 2.0, truth: str = "mesh") -> tuple[dict, list[dict]]:
    """The thresholds the rule of the module documentation chooses on validation pairs.

    Parameters
    ----------
    rows : DataFrame
        One row per pair (:func:`semmatch.experiments.alignment_study.two_height_study` with
        ``wrong_pairs``): ``scene``, ``person``, the mesh-fit errors and the columns of
        :data:`CHECK_VALUES`.
    defaults : mapping, optional
        Current thresholds (default :data:`~semmatch.poses.alignment.DEFAULT_CHECKS`).
    max_trans_m, max_rot_deg, truth
        The target that labels right pairs good, and the errors it reads (:func:`must_refuse`).

    Returns
    -------
    thresholds : dict
        The chosen thresholds (keys of ``DEFAULT_CHECKS``).
    steps : list of dict
        Per check: its threshold before and after, whether it moved off its current interval,
        the run of equivalent thresholds it was placed in, and the cost of the chosen set
        (``bad_accepted``, ``good_refused``).

    Raises
    ------
    ValueError
        No rows, or a right pair without its mesh-fit error.
    """
    from ..poses.alignment import DEFAULT_CHECKS

    if not len(rows):
        raise ValueError("no validation pairs to choose thresholds on")
    refuse = must_refuse(rows, max_trans_m=max_trans_m, max_rot_deg=max_rot_deg, truth=truth)
    current = dict(defaults or DEFAULT_CHECKS)
    names = list(DEFAULT_CHECKS)
    tables = {n: _check_table(rows, n, float(current[n])) for n in names}
    # every combination of intervals, by dynamic programming over the checks: per set of accepted
    # pairs the combination with the fewest checks moved off their current interval, then the
    # smallest total move (in intervals)
    states = {np.ones(len(rows), bool).tobytes(): ((0, 0), [])}
    for n in names:
        t, nxt = tables[n], {}
        for acc_bytes, (key, picks) in states.items():
            acc = np.frombuffer(acc_bytes, dtype=bool)
            for k, m in enumerate(t["masks"]):
                new = (acc & m).tobytes()
                cand = ((key[0] + int(k != t["home"]), key[1] + abs(k - t["home"])), [*picks, k])
                if new not in nxt or cand[0] < nxt[new][0]:
                    nxt[new] = cand
        states = nxt

    def cost(acc_bytes):
        acc = np.frombuffer(acc_bytes, dtype=bool)
        return int((acc & refuse).sum()), int((~acc & ~refuse).sum())

    best = min(states, key=lambda a: (cost(a), states[a][0]))
    picks = dict(zip(names, states[best][1], strict=True))
    final = np.frombuffer(best, dtype=bool)
    thresholds, steps = {}, []
    for n in names:
        t = tables[n]
        others = np.ones(len(rows), bool)
        for o in names:
            if o != n:
                others &= tables[o]["masks"][picks[o]]
        # the run: consecutive intervals that give the same verdicts with the other checks as chosen
        same = [np.array_equal(others & m, final) for m in t["masks"]]
        a = b = picks[n]
        while a > 0 and same[a - 1]:
            a -= 1
        while b < len(same) - 1 and same[b + 1]:
            b += 1
        thresholds[n] = _place(t, (a, b), float(current[n]))
        steps.append({"check": n, "before": float(current[n]), "threshold": thresholds[n],
                      "moved": picks[n] != t["home"], "run": [t["intervals"][a][0], t["intervals"][b][1]],
                      "bad_accepted": cost(best)[0], "good_refused": cost(best)[1]})
    assert np.array_equal(judge_rows(rows, thresholds), final), "threshold placement changed the verdicts"
    return thresholds, steps


def threshold_figure(rows: pd.DataFrame, thresholds: Mapping[str, float], out, *, title: str = "",
                     max_trans_m: float = 0.05, max_rot_deg: float = 2.0, truth: str = "mesh"):
    """``structure_fitness`` per pair (right good, right off target, wrong) with the chosen minimum.

    Parameters
    ----------
    rows : DataFrame
        As :func:`choose_thresholds`.
    thresholds : mapping
        The chosen thresholds (``min_structure_fitness`` drawn as a line).
    out : path
        PNG, written atomically.
    title : str
    max_trans_m, max_rot_deg, truth
        As :func:`must_refuse`.

    Returns
    -------
    Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import save_figure

    refuse = must_refuse(rows, max_trans_m=max_trans_m, max_rot_deg=max_rot_deg, truth=truth)
    wrong = (rows["person"] != rows["scene"]).to_numpy()
    accepted = judge_rows(rows, thresholds)
    fig, ax = plt.subplots(figsize=(5.6, 3.2))
    groups = (("right pair, within target", ~refuse, "o", "tab:blue"),
              ("right pair, off target", refuse & ~wrong, "s", "tab:orange"),
              ("wrong pair", wrong, "x", "tab:red"))
    y = np.arange(len(rows))
    for label, sel, marker, colour in groups:
        if sel.any():
            ax.scatter(rows["structure_fitness"].to_numpy(float)[sel], y[sel], marker=marker, color=colour,
                       label=f"{label} ({int(sel.sum())})")
    for k in np.flatnonzero(accepted != ~refuse):
        ax.annotate("wrongly " + ("accepted" if accepted[k] else "refused"), (rows["structure_fitness"].iloc[k], y[k]),
                    fontsize=6, xytext=(4, 2), textcoords="offset points")
    ax.axvline(thresholds["min_structure_fitness"], color="k", ls="--", lw=0.8,
               label=f"minimum {thresholds['min_structure_fitness']:.3f}")
    ax.set_yticks(y, [f"{s} -> {p}" if s != p else s for s, p in zip(rows["scene"], rows["person"], strict=True)],
                  fontsize=5)
    ax.set_xlabel("structure_fitness")
    ax.legend(fontsize=6, loc="lower right")
    if title:
        ax.set_title(title, fontsize=8)
    fig.tight_layout()
    return save_figure(fig, out)
