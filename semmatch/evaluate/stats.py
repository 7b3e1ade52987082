"""Intervals over scenes and the tests behind the claims' verdicts.

Two families of intervals of a mean over scenes (or of a paired mean difference):

* **t intervals** (:func:`stratified_estimate`, :func:`stratified_t_ci`): without strata the
  ordinary one-sample t over scenes (the analysis plan's method, ``docs/analysis_plan.md``);
  with strata (scene kinds: ``office_8001`` -> ``office``) the standard error is computed
  within kinds with Welch-Satterthwaite degrees of freedom (with fewer than two scenes in some
  kind, or one kind only, the plain t). The point estimate is the plain mean over scenes.
  :func:`t_test_pvalue` gives the matching one-sided tests and :func:`holm` Holm's step-down
  adjustment of a family of p-values.
* **Percentile bootstrap** (:func:`bootstrap_ci`, :func:`paired_difference_ci`,
  :func:`ratio_of_means_ci`), by :func:`scipy.stats.bootstrap` with a seeded generator. With 12
  scenes it covers less than its nominal level (``docs/analysis_plan.md``, "Coverage"); the
  ratio interval (share of a gap closed) keeps it; :func:`ratio_lower_bound` is its one-sided
  t analogue (Fieller's bound).

:func:`interval` dispatches between these and BCa / stratified percentile variants (used by the
coverage study, :mod:`semmatch.experiments.coverage`). Degenerate samples (one value, or all
values equal) get the zero-width interval ``(v, v, v)``.

With several trained networks per architecture (training seeds), each comparison has one value
per scene *and* network; :func:`two_level_bootstrap` resamples both (the networks, then the
scenes within their kinds) and :func:`two_component_t_ci` is the matching t interval with a
between-network and a between-scene variance component (checked by simulation in
:mod:`semmatch.experiments.two_level_coverage`).

Size: over 600 lines because it holds every interval the analysis plans name, v1's over scenes
and v2's over scenes and networks, which share their resampling and degenerate-sample rules;
the v2 rules (:mod:`semmatch.experiments.rules_v2`) and their tests look the network intervals
up here. Splitting the network intervals into a module of their own is planned once the v2 plan's
primary interval is settled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats as _st

#: interval methods of :func:`interval` (``t`` is the analysis plan's)
INTERVAL_METHODS = ("t", "stratified-t", "percentile", "stratified-percentile", "bca")

__all__ = [
    "INTERVAL_METHODS",
    "StratifiedEstimate",
    "scene_kind",
    "stratified_estimate",
    "stratified_t_ci",
    "t_test_pvalue",
    "holm",
    "interval",
    "bootstrap_ci",
    "paired_difference_ci",
    "ratio_of_means_ci",
    "ratio_lower_bound",
    "NetworkSceneInterval",
    "network_scene_grid",
    "two_level_bootstrap",
    "two_component_t_ci",
    "grid_bootstrap",
    "grid_two_component_t",
]


def _as_1d(values: ArrayLike, name: str) -> np.ndarray:
    x = np.asarray(values, dtype=np.float64)
    if x.ndim > 1:
        raise ValueError(f"{name}: expected a 1-D sequence of values, got shape {x.shape}")
    return x.ravel()


def _complete_pairs(a: ArrayLike, b: ArrayLike, fn: str, names: tuple[str, str]) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of ``a`` and ``b`` with no NaN on either side (``fn`` and ``names`` for errors)."""
    x, y = _as_1d(a, f"{fn} ({names[0]})"), _as_1d(b, f"{fn} ({names[1]})")
    if x.shape != y.shape:
        raise ValueError(f"{fn}: {names[0]} and {names[1]} must have equal lengths, got {x.size} and {y.size}")
    keep = ~(np.isnan(x) | np.isnan(y))
    if not keep.any():
        raise ValueError(f"{fn}: no complete pair (empty input, or a NaN in every pair)")
    return x[keep], y[keep]


def bootstrap_ci(
    values: ArrayLike,
    *,
    confidence: float = 0.95,
    n_resamples: int = 10000,
    seed: int = 0,
    method: str = "percentile",
) -> tuple[float, float, float]:
    """Mean of ``values`` and a bootstrap confidence interval of it (percentile by default).

    Parameters
    ----------
    values : array_like
        One value per unit (e.g. per scene); NaNs are dropped.
    confidence : float, optional
        Confidence level of the two-sided interval, in (0, 1).
    n_resamples : int, optional
        Number of bootstrap resamples.
    seed : int, optional
        Seed of the resampling generator (``numpy.random.default_rng(seed)``).
    method : {"percentile", "BCa"}, optional
        SciPy's interval method; a BCa interval SciPy cannot form (NaN bounds, e.g. a two-valued
        sample) falls back to the percentile one.

    Returns
    -------
    tuple of float
        ``(mean, lo, hi)``. One value, or all values equal, gives ``(v, v, v)``.

    Raises
    ------
    ValueError
        If no value is left after dropping NaNs, or ``confidence`` is not in (0, 1).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"bootstrap_ci: confidence must be in (0, 1), got {confidence}")
    x = _as_1d(values, "bootstrap_ci")
    x = x[~np.isnan(x)]
    if x.size == 0:
        raise ValueError("bootstrap_ci: no values to average (empty input, or every value is NaN)")
    mean = float(np.mean(x))
    if x.size == 1 or np.all(x == x[0]):
        v = float(x[0])
        return v, v, v
    res = _st.bootstrap(
        (x,),
        np.mean,
        n_resamples=n_resamples,
        confidence_level=confidence,
        method=method,
        vectorized=True,
        axis=-1,
        rng=np.random.default_rng(seed),
    )
    lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
    if method != "percentile" and (np.isnan(lo) or np.isnan(hi)):
        return bootstrap_ci(x, confidence=confidence, n_resamples=n_resamples, seed=seed)
    return mean, lo, hi


def paired_difference_ci(
    a: ArrayLike,
    b: ArrayLike,
    *,
    confidence: float = 0.95,
    n_resamples: int = 10000,
    seed: int = 0,
) -> tuple[float, float, float]:
    """Mean of the paired differences ``a - b`` and a percentile bootstrap interval of it.

    Parameters
    ----------
    a, b : array_like
        Paired values (``a[i]`` and ``b[i]`` belong to the same unit, e.g. the same scene), of
        equal length. A pair with a NaN on either side is dropped.
    confidence : float, optional
        Confidence level of the two-sided interval, in (0, 1).
    n_resamples : int, optional
        Number of bootstrap resamples.
    seed : int, optional
        Seed of the resampling generator.

    Returns
    -------
    tuple of float
        ``(mean difference, lo, hi)``, as :func:`bootstrap_ci` on ``a - b``.

    Raises
    ------
    ValueError
        If the lengths differ or no complete pair is left.
    """
    x, y = _complete_pairs(a, b, "paired_difference_ci", ("a", "b"))
    return bootstrap_ci(x - y, confidence=confidence, n_resamples=n_resamples, seed=seed)


def ratio_of_means_ci(
    num: ArrayLike,
    den: ArrayLike,
    *,
    confidence: float = 0.95,
    n_resamples: int = 10000,
    seed: int = 0,
) -> tuple[float, float, float]:
    """``mean(num) / mean(den)`` of paired values and a percentile bootstrap interval of it.

    The units (e.g. scenes) are resampled together, so each resample's ratio keeps the pairing
    (e.g. the share of the viewpoint gap closed: ``num`` the per-scene gain, ``den`` the
    per-scene gap).

    Parameters
    ----------
    num, den : array_like
        Paired values of equal length; a pair with a NaN on either side is dropped.
    confidence : float, optional
        Confidence level of the two-sided interval, in (0, 1).
    n_resamples : int, optional
        Number of bootstrap resamples.
    seed : int, optional
        Seed of the resampling generator.

    Returns
    -------
    tuple of float
        ``(ratio, lo, hi)``. One pair, or every pair equal, gives ``(r, r, r)``.

    Raises
    ------
    ValueError
        If the lengths differ, no complete pair is left, ``mean(den)`` is 0, or ``confidence``
        is not in (0, 1).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"ratio_of_means_ci: confidence must be in (0, 1), got {confidence}")
    x, y = _complete_pairs(num, den, "ratio_of_means_ci", ("num", "den"))
    if float(np.mean(y)) == 0.0:
        raise ValueError("ratio_of_means_ci: the mean of den is 0 (the ratio is undefined)")
    ratio = float(np.mean(x) / np.mean(y))
    if x.size == 1 or (np.all(x == x[0]) and np.all(y == y[0])):
        return ratio, ratio, ratio

    def statistic(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.mean(a, axis=axis) / np.mean(b, axis=axis)

    res = _st.bootstrap(
        (x, y),
        statistic,
        n_resamples=n_resamples,
        confidence_level=confidence,
        method="percentile",
        paired=True,
        vectorized=True,
        axis=-1,
        rng=np.random.default_rng(seed),
    )
    return ratio, float(res.confidence_interval.low), float(res.confidence_interval.high)


# ------------------------------------------------------------------------------------------------
# stratified t intervals and tests


def scene_kind(scene: str) -> str:
    """The kind of a scene from its name: ``"living_room_8001"`` -> ``"living_room"``.

    Parameters
    ----------
    scene : str
        A scene name ``<kind>_<seed>`` as the simulator writes it; a name without a numeric
        suffix is its own kind.

    Returns
    -------
    str
    """
    head, _, tail = str(scene).rpartition("_")
    return head if head and tail.isdigit() else str(scene)


@dataclass(frozen=True)
class StratifiedEstimate:
    """A mean over units with its standard error and degrees of freedom.

    Attributes
    ----------
    mean : float
        Plain mean of the values.
    se : float
        Standard error of the mean (0 for a degenerate sample).
    df : float
        Degrees of freedom of its t reference distribution (Welch-Satterthwaite when stratified;
        ``n - 1`` otherwise; ``inf`` when ``se`` is 0).
    n : int
        Number of values used.
    stratified : bool
        Whether the standard error was computed within strata.
    """

    mean: float
    se: float
    df: float
    n: int
    stratified: bool


def stratified_estimate(values: ArrayLike, strata: ArrayLike | None = None) -> StratifiedEstimate:
    """Mean of ``values`` with a standard error computed within strata.

    With strata weights ``w_k = n_k / n`` the mean over all values is ``sum_k w_k m_k``; its
    variance is ``sum_k w_k^2 s_k^2 / n_k`` (``s_k^2`` the sample variance within stratum ``k``)
    and its degrees of freedom are Welch-Satterthwaite's ``(sum v_k)^2 / sum v_k^2 / (n_k - 1)``
    with ``v_k = w_k^2 s_k^2 / n_k``. Without strata, with a single stratum, or when a stratum
    has fewer than two values, the ordinary ``s / sqrt(n)`` with ``n - 1`` degrees of freedom.

    Parameters
    ----------
    values : array_like
        One value per unit (scene); NaNs are dropped together with their stratum labels.
    strata : array_like, optional
        A stratum label per value (e.g. :func:`scene_kind` of each scene).

    Returns
    -------
    StratifiedEstimate

    Raises
    ------
    ValueError
        If no value is left, or ``strata`` has another length than ``values``.
    """
    x = _as_1d(values, "stratified_estimate")
    keep = ~np.isnan(x)
    if strata is not None:
        g = np.asarray(strata, dtype=object).ravel()
        if g.shape != x.shape:
            raise ValueError(f"stratified_estimate: {x.size} values but {g.size} stratum labels")
        g = g[keep]
    x = x[keep]
    n = int(x.size)
    if n == 0:
        raise ValueError("stratified_estimate: no values (empty input, or every value is NaN)")
    mean = float(np.mean(x))
    if n == 1 or np.all(x == x[0]):
        return StratifiedEstimate(mean, 0.0, float("inf"), n, False)
    if strata is not None:
        labels, inverse, counts = np.unique(g.astype(str), return_inverse=True, return_counts=True)
        if labels.size > 1 and counts.min() >= 2:
            v = np.array([(counts[k] / n) ** 2 * np.var(x[inverse == k], ddof=1) / counts[k]
                          for k in range(labels.size)])
            var = float(v.sum())
            if var == 0.0:
                return StratifiedEstimate(mean, 0.0, float("inf"), n, True)
            df = var**2 / float(np.sum(v[v > 0] ** 2 / (counts[v > 0] - 1)))
            return StratifiedEstimate(mean, float(np.sqrt(var)), float(df), n, True)
    se = float(np.std(x, ddof=1) / np.sqrt(n))
    return StratifiedEstimate(mean, se, float(n - 1), n, False)


def stratified_t_ci(
    values: ArrayLike, strata: ArrayLike | None = None, *, confidence: float = 0.95
) -> tuple[float, float, float]:
    """Mean and two-sided t interval of :func:`stratified_estimate`.

    Parameters
    ----------
    values : array_like
        One value per unit; NaNs dropped.
    strata : array_like, optional
        Stratum label per value.
    confidence : float, optional
        Confidence level in (0, 1).

    Returns
    -------
    tuple of float
        ``(mean, lo, hi)``; ``(v, v, v)`` for a degenerate sample.

    Raises
    ------
    ValueError
        As :func:`stratified_estimate`, or when ``confidence`` is not in (0, 1).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"stratified_t_ci: confidence must be in (0, 1), got {confidence}")
    est = stratified_estimate(values, strata)
    if est.se == 0.0:
        return est.mean, est.mean, est.mean
    half = float(_st.t.ppf(0.5 + confidence / 2, est.df)) * est.se
    return est.mean, est.mean - half, est.mean + half


def t_test_pvalue(est: StratifiedEstimate, null: float = 0.0, alternative: str = "greater") -> float:
    """One-sided p-value of ``H0: mean <= null`` (``greater``) or ``H0: mean >= null`` (``less``).

    Parameters
    ----------
    est : StratifiedEstimate
        From :func:`stratified_estimate`.
    null : float, optional
        The boundary of the null hypothesis.
    alternative : {"greater", "less"}
        The direction the test seeks evidence for.

    Returns
    -------
    float
        The p-value; for a degenerate estimate (``se`` 0) 0 when the mean lies strictly on the
        alternative's side of ``null``, else 1.
    """
    if alternative not in ("greater", "less"):
        raise ValueError(f"t_test_pvalue: alternative must be 'greater' or 'less', got {alternative!r}")
    sign = 1.0 if alternative == "greater" else -1.0
    if est.se == 0.0:
        return 0.0 if sign * (est.mean - null) > 0 else 1.0
    return float(_st.t.sf(sign * (est.mean - null) / est.se, est.df))


def holm(pvalues: ArrayLike) -> np.ndarray:
    """Holm's step-down adjustment of a family of p-values (controls the family-wise error).

    Parameters
    ----------
    pvalues : array_like
        The family's p-values; NaNs stay NaN and do not count as members.

    Returns
    -------
    numpy.ndarray
        Adjusted p-values (reject ``H_i`` at level ``alpha`` iff ``adjusted[i] <= alpha``), in the
        input's order.
    """
    p = _as_1d(pvalues, "holm")
    out = np.full(p.shape, np.nan)
    ok = np.flatnonzero(~np.isnan(p))
    m = ok.size
    if m == 0:
        return out
    order = ok[np.argsort(p[ok], kind="stable")]
    adjusted = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p[order]))
    out[order] = adjusted
    return out


def _stratified_resample_means(x: np.ndarray, g: np.ndarray, n_resamples: int,
                               rng: np.random.Generator) -> np.ndarray:
    """Means of ``n_resamples`` bootstrap resamples drawn within each stratum of ``g``."""
    total = np.zeros(n_resamples)
    for label in np.unique(g):
        xs = x[g == label]
        idx = rng.integers(0, xs.size, size=(n_resamples, xs.size))
        total += xs[idx].sum(axis=1)
    return total / x.size


def interval(
    values: ArrayLike,
    strata: ArrayLike | None = None,
    *,
    method: str = "t",
    confidence: float = 0.95,
    n_resamples: int = 10000,
    seed: int = 0,
) -> tuple[float, float, float]:
    """Mean of ``values`` and a two-sided interval by one of :data:`INTERVAL_METHODS`.

    Parameters
    ----------
    values : array_like
        One value per unit (scene), or paired differences; NaNs dropped.
    strata : array_like, optional
        Stratum label per value (``stratified-*`` methods; ignored by the others).
    method : str, optional
        ``stratified-t`` (:func:`stratified_t_ci`), ``t`` (one-sample t), ``percentile``
        (:func:`bootstrap_ci`), ``stratified-percentile`` (units resampled within their stratum)
        or ``bca`` (SciPy's bias-corrected and accelerated bootstrap).
    confidence : float, optional
        Confidence level in (0, 1).
    n_resamples : int, optional
        Bootstrap resamples (bootstrap methods).
    seed : int, optional
        Seed of the resampling generator (bootstrap methods).

    Returns
    -------
    tuple of float
        ``(mean, lo, hi)``; ``(v, v, v)`` for a degenerate sample.

    Raises
    ------
    ValueError
        For an unknown method, no values, or a bad confidence level.
    """
    if method not in INTERVAL_METHODS:
        raise ValueError(f"interval: method must be one of {INTERVAL_METHODS}, got {method!r}")
    if method == "stratified-t":
        return stratified_t_ci(values, strata, confidence=confidence)
    if method == "t":
        return stratified_t_ci(values, None, confidence=confidence)
    if method in ("percentile", "bca"):
        return bootstrap_ci(values, confidence=confidence, n_resamples=n_resamples, seed=seed,
                            method="BCa" if method == "bca" else "percentile")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"interval: confidence must be in (0, 1), got {confidence}")
    x = _as_1d(values, "interval")
    keep = ~np.isnan(x)
    g = None if strata is None else np.asarray(strata, dtype=object).ravel()[keep].astype(str)
    x = x[keep]
    if x.size == 0:
        raise ValueError("interval: no values (empty input, or every value is NaN)")
    mean = float(np.mean(x))
    if x.size == 1 or np.all(x == x[0]):
        return mean, mean, mean
    # stratified percentile bootstrap: units resampled within their stratum
    means = _stratified_resample_means(x, g if g is not None else np.zeros(x.size, str), n_resamples,
                                       np.random.default_rng(seed))
    lo, hi = np.quantile(means, [(1.0 - confidence) / 2, (1.0 + confidence) / 2])
    return mean, float(lo), float(hi)


def ratio_lower_bound(num: ArrayLike, den: ArrayLike, *, confidence: float = 0.95) -> float:
    """One-sided lower confidence bound of ``mean(num) / mean(den)`` over paired units (Fieller).

    The bound is the smallest ratio ``r`` that the one-sided one-sample t test of the paired
    differences ``num - r * den`` (the analysis plan's t over scenes) does not reject at level
    ``1 - confidence``: "the share of the gap closed is at least ``r``" holds with that
    confidence. It solves ``mean(d_r) = t * sd(d_r) / sqrt(n)`` for ``d_r = num - r * den``, a
    quadratic in ``r``. When the denominator's own mean is not clearly positive (its t test
    does not reject ``mean(den) <= 0``), every ratio is compatible with the data and the bound is
    ``-inf``.

    Parameters
    ----------
    num, den : array_like
        Paired values (e.g. per-scene gain and per-scene gap); a pair with a NaN is dropped.
    confidence : float, optional
        In (0, 1).

    Returns
    -------
    float
        The lower bound (``mean(num) / mean(den)`` itself when every ``num - r * den`` is exact,
        i.e. zero variance at the estimate).

    Raises
    ------
    ValueError
        Fewer than two complete pairs, or ``confidence`` not in (0, 1).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"ratio_lower_bound: confidence must be in (0, 1), got {confidence}")
    a, b = _complete_pairs(num, den, "ratio_lower_bound", ("num", "den"))
    n = len(a)
    if n < 2:
        raise ValueError(f"ratio_lower_bound: need at least 2 complete pairs, got {n}")
    t2 = float(_st.t.ppf(confidence, n - 1)) ** 2 / n
    ma, mb = float(a.mean()), float(b.mean())
    cov = np.cov(np.stack([a, b]), ddof=1)
    saa, sab, sbb = float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1])
    qa = mb * mb - t2 * sbb  # (ma - r mb)^2 = t2 (saa - 2 r sab + r^2 sbb), as qa r^2 - 2 qb r + qc = 0
    if mb <= 0 or qa <= 0:
        return float("-inf")
    qb = ma * mb - t2 * sab
    qc = ma * ma - t2 * saa
    disc = max(qb * qb - qa * qc, 0.0)
    return float((qb - np.sqrt(disc)) / qa)



# ------------------------------------------------------------------------------------------------
# several networks per architecture: intervals over networks and scenes


@dataclass(frozen=True)
class NetworkSceneInterval:
    """The mean of a networks x scenes grid of values with its confidence bounds.

    Attributes
    ----------
    mean : float
        Mean over every network and scene (each network and scene weighted equally).
    lo, hi : float
        Two-sided interval at the requested confidence.
    lower, upper : float
        One-sided bounds at the same confidence (``mean >= lower`` and ``mean <= upper``), the
        bounds behind the one-sided tests of the analysis plan.
    n_networks, n_scenes : int
        Networks and scenes used (scenes with a missing network are left out).
    """

    mean: float
    lo: float
    hi: float
    lower: float
    upper: float
    n_networks: int
    n_scenes: int


def network_scene_grid(values: ArrayLike, networks: ArrayLike, scenes: ArrayLike,
                       strata: ArrayLike | None = None, *, fn: str = "network_scene_grid"
                       ) -> tuple[np.ndarray, np.ndarray]:
    """A networks x scenes matrix of long-form values, and each scene's stratum.

    Parameters
    ----------
    values : array_like
        One value per (network, scene) row (e.g. a per-scene paired difference of one network).
    networks, scenes : array_like
        The row's network (e.g. its training seed) and scene labels.
    strata : array_like, optional
        The row's stratum (e.g. :func:`scene_kind` of its scene); must be the same on every row
        of a scene. None: one stratum.
    fn : str, optional
        Function name for error messages.

    Returns
    -------
    grid : ndarray (n_networks, n_scenes)
        Networks and scenes in sorted label order. A scene without a value (or with a NaN) for
        some network is left out.
    scene_strata : ndarray of str (n_scenes,)

    Raises
    ------
    ValueError
        Lengths differ, a (network, scene) pair occurs twice, a scene has two strata, or no
        scene has a value for every network.
    """
    x = _as_1d(values, f"{fn} (values)")
    net = np.asarray(networks, dtype=object).ravel().astype(str)
    sc = np.asarray(scenes, dtype=object).ravel().astype(str)
    g = np.zeros(x.size, dtype=str) if strata is None else np.asarray(strata, dtype=object).ravel().astype(str)
    if not (x.size == net.size == sc.size == g.size):
        raise ValueError(f"{fn}: values, networks, scenes and strata must have equal lengths, got "
                         f"{x.size}, {net.size}, {sc.size} and {g.size}")
    nets, ni = np.unique(net, return_inverse=True)
    scs, si = np.unique(sc, return_inverse=True)
    if np.unique(ni * scs.size + si).size != x.size:
        raise ValueError(f"{fn}: a (network, scene) pair occurs more than once")
    grid = np.full((nets.size, scs.size), np.nan)
    grid[ni, si] = x
    scene_strata = np.empty(scs.size, dtype=object)
    for j in range(scs.size):
        labels = np.unique(g[si == j])
        if labels.size > 1:
            raise ValueError(f"{fn}: scene {scs[j]!r} is in several strata ({', '.join(labels)})")
        scene_strata[j] = labels[0]
    keep = ~np.isnan(grid).any(axis=0)
    if not keep.any():
        raise ValueError(f"{fn}: no scene has a value for every network ({', '.join(nets)})")
    return grid[:, keep], scene_strata[keep].astype(str)


def _resample_counts(n_resamples: int, groups: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """How often each unit is drawn in ``n_resamples`` resamples drawn within each group of ``groups``
    (shape ``(n_resamples, groups.size)``)."""
    n = groups.size
    drawn = np.empty((n_resamples, n), dtype=np.int64)
    for label in np.unique(groups):
        members = np.flatnonzero(groups == label)
        drawn[:, members] = members[rng.integers(0, members.size, size=(n_resamples, members.size))]
    flat = (np.arange(n_resamples)[:, None] * n + drawn).ravel()
    return np.bincount(flat, minlength=n_resamples * n).reshape(n_resamples, n).astype(np.float64)


def two_level_bootstrap(
    values: ArrayLike,
    networks: ArrayLike,
    scenes: ArrayLike,
    strata: ArrayLike | None = None,
    *,
    confidence: float = 0.95,
    n_resamples: int = 10000,
    seed: int = 0,
    resample_networks: bool = True,
) -> NetworkSceneInterval:
    """Percentile bootstrap of the mean over networks and scenes, resampling both.

    Each resample draws the networks with replacement, then the scenes with replacement within
    their stratum (the same scene draw for every network: the scenes are shared), and takes the
    mean of the resampled grid. ``resample_networks=False`` keeps the networks fixed: the
    one-level (scenes only) bootstrap, the analysis plan v1's view of a single network.

    Parameters
    ----------
    values, networks, scenes, strata : array_like
        Long form, one row per network and scene (:func:`network_scene_grid`); ``strata`` e.g.
        the scene kinds (None: scenes resampled as one group).
    confidence : float, optional
        Level of the two-sided interval and of each one-sided bound, in (0, 1).
    n_resamples : int, optional
        Bootstrap resamples.
    seed : int, optional
        Seed of the resampling generator.
    resample_networks : bool, optional
        Resample the networks too (the two-level bootstrap).

    Returns
    -------
    NetworkSceneInterval
        A grid with a single value, or all values equal, gives zero-width bounds.

    Raises
    ------
    ValueError
        As :func:`network_scene_grid`, or ``confidence`` not in (0, 1), or ``n_resamples`` < 1.

    Notes
    -----
    With few networks the bootstrap under-states the between-network variance by the factor
    ``(N - 1) / N`` (2/3 for three networks) and its percentiles come from at most
    ``N^N`` network draws; docs/analysis_plan_v2_coverage.md measures the coverage this gives.
    """
    grid, g = network_scene_grid(values, networks, scenes, strata, fn="two_level_bootstrap")
    return grid_bootstrap(grid, g, confidence=confidence, n_resamples=n_resamples, seed=seed,
                          resample_networks=resample_networks)


def grid_bootstrap(
    grid: np.ndarray,
    scene_strata: ArrayLike | None = None,
    *,
    confidence: float = 0.95,
    n_resamples: int = 10000,
    seed: int | np.random.Generator = 0,
    resample_networks: bool = True,
) -> NetworkSceneInterval:
    """:func:`two_level_bootstrap` on a networks x scenes matrix (:func:`network_scene_grid`).

    Parameters
    ----------
    grid : ndarray (n_networks, n_scenes)
        No NaN.
    scene_strata : array_like, optional
        Stratum of each scene (column); None: one stratum.
    confidence, n_resamples, resample_networks
        As in :func:`two_level_bootstrap`.
    seed : int or numpy Generator
        Seed of (or the) resampling generator.

    Returns
    -------
    NetworkSceneInterval

    Raises
    ------
    ValueError
        ``confidence`` not in (0, 1), ``n_resamples`` < 1, a NaN or an empty grid, or
        ``scene_strata`` not one label per column.
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"two_level_bootstrap: confidence must be in (0, 1), got {confidence}")
    if n_resamples < 1:
        raise ValueError(f"two_level_bootstrap: n_resamples must be >= 1, got {n_resamples}")
    grid = np.asarray(grid, dtype=np.float64)
    if grid.ndim != 2 or grid.size == 0 or np.isnan(grid).any():
        raise ValueError(f"two_level_bootstrap: expected a non-empty networks x scenes matrix without NaN, "
                         f"got shape {grid.shape}")
    n_net, n_sc = grid.shape
    g = np.zeros(n_sc, dtype=int) if scene_strata is None else np.asarray(scene_strata, dtype=object).ravel().astype(str)
    if g.size != n_sc:
        raise ValueError(f"two_level_bootstrap: {n_sc} scenes but {g.size} stratum labels")
    mean = float(grid.mean())
    if grid.size == 1 or np.all(grid == grid.flat[0]):
        return NetworkSceneInterval(mean, mean, mean, mean, mean, n_net, n_sc)
    rng = np.random.default_rng(seed)
    net_w = (_resample_counts(n_resamples, np.zeros(n_net, dtype=int), rng) if resample_networks
             else np.ones((n_resamples, n_net)))
    scene_w = _resample_counts(n_resamples, g, rng)
    means = np.einsum("bn,ns,bs->b", net_w, grid, scene_w) / (n_net * n_sc)
    alpha = 1.0 - confidence
    lo, hi, lower, upper = np.quantile(means, [alpha / 2, 1 - alpha / 2, alpha, 1 - alpha])
    return NetworkSceneInterval(mean, float(lo), float(hi), float(lower), float(upper), n_net, n_sc)

def two_component_t_ci(
    values: ArrayLike,
    networks: ArrayLike,
    scenes: ArrayLike,
    *,
    confidence: float = 0.95,
) -> NetworkSceneInterval:
    """t interval of the mean over networks and scenes with a network and a scene variance component.

    For a grid ``d[n, s] = mu + a_n + b_s + e_ns`` (network, scene and interaction effects), the
    grid mean has variance ``var(a)/N + var(b)/S + var(e)/(N S)``. Its estimate here is
    ``v_net + v_scene`` with ``v_net`` the variance of the N network means over N and ``v_scene``
    the variance of the S network-averaged scene values over S (the v1 plan's t over scenes,
    applied to the network average). Each term also holds ``var(e)/(N S)``, so the sum counts the
    interaction twice (conservative). Degrees of freedom: Welch-Satterthwaite, ``(v_net +
    v_scene)^2 / (v_net^2/(N-1) + v_scene^2/(S-1))``; with one network, the plain t over scenes.

    Parameters
    ----------
    values, networks, scenes : array_like
        Long form, one row per network and scene (:func:`network_scene_grid`).
    confidence : float, optional
        Level of the two-sided interval and of each one-sided bound, in (0, 1).

    Returns
    -------
    NetworkSceneInterval

    Raises
    ------
    ValueError
        As :func:`network_scene_grid`, or ``confidence`` not in (0, 1).
    """
    grid, _ = network_scene_grid(values, networks, scenes, None, fn="two_component_t_ci")
    return grid_two_component_t(grid, confidence=confidence)


def grid_two_component_t(grid: np.ndarray, *, confidence: float = 0.95) -> NetworkSceneInterval:
    """:func:`two_component_t_ci` on a networks x scenes matrix (:func:`network_scene_grid`).

    Raises
    ------
    ValueError
        ``confidence`` not in (0, 1), or a NaN or an empty grid.
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"two_component_t_ci: confidence must be in (0, 1), got {confidence}")
    est = network_scene_estimate(grid)
    n_net, n_sc = np.asarray(grid).shape
    mean, se, df = est.mean, est.se, est.df
    if se == 0.0:
        return NetworkSceneInterval(mean, mean, mean, mean, mean, n_net, n_sc)
    two, one = (float(_st.t.ppf(q, df)) * se for q in (0.5 + confidence / 2, confidence))
    return NetworkSceneInterval(mean, mean - two, mean + two, mean - one, mean + one, n_net, n_sc)


def network_scene_estimate(grid: np.ndarray) -> StratifiedEstimate:
    """The grid mean of a networks x scenes matrix with the two-component standard error and
    Welch-Satterthwaite degrees of freedom of :func:`two_component_t_ci` (for its t tests:
    :func:`t_test_pvalue`).

    Parameters
    ----------
    grid : ndarray (N, S)
        One value per network and scene (:func:`network_scene_grid`).

    Returns
    -------
    StratifiedEstimate
        ``mean``, ``se`` (0 and ``df`` inf for a degenerate grid), ``df``, ``n`` (cells) and
        ``stratified`` False.

    Raises
    ------
    ValueError
        A NaN or an empty grid.
    """
    grid = np.asarray(grid, dtype=np.float64)
    if grid.ndim != 2 or grid.size == 0 or np.isnan(grid).any():
        raise ValueError(f"two_component_t_ci: expected a non-empty networks x scenes matrix without NaN, "
                         f"got shape {grid.shape}")
    n_net, n_sc = grid.shape
    mean = float(grid.mean())
    parts = []  # (variance term, degrees of freedom)
    if n_net > 1:
        parts.append((float(np.var(grid.mean(axis=1), ddof=1)) / n_net, n_net - 1))
    if n_sc > 1:
        parts.append((float(np.var(grid.mean(axis=0), ddof=1)) / n_sc, n_sc - 1))
    var = sum(v for v, _ in parts)
    if var == 0.0:
        return StratifiedEstimate(mean, 0.0, float("inf"), int(grid.size), False)
    df = var**2 / sum(v**2 / d for v, d in parts if v > 0)
    return StratifiedEstimate(mean, float(np.sqrt(var)), float(df), int(grid.size), False)
