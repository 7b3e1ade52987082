"""Bootstrap confidence intervals of a mean over scenes, of a paired mean difference, and of a
ratio of paired means (e.g. the share of a gap closed).

All three are percentile bootstrap intervals computed by :func:`scipy.stats.bootstrap`; the
resampling generator is seeded, so the same values and seed give the same interval. Degenerate
samples (one value, or all values equal) have no spread to resample: they get the zero-width
interval ``(v, v, v)`` instead of SciPy's ``DegenerateDataWarning`` and NaN bounds.

With the few scenes of the paper's experiments (3-4 per table) a percentile bootstrap interval
is narrow (it under-covers for small samples); read it as "the spread over these scenes", not
as a population interval.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats as _st

__all__ = ["bootstrap_ci", "paired_difference_ci", "ratio_of_means_ci"]


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
) -> tuple[float, float, float]:
    """Mean of ``values`` and a percentile bootstrap confidence interval of it.

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
        method="percentile",
        vectorized=True,
        axis=-1,
        rng=np.random.default_rng(seed),
    )
    return mean, float(res.confidence_interval.low), float(res.confidence_interval.high)


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
