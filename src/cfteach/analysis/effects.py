"""Confidence intervals of effect sizes, so a reader sees how precisely each one is known.

Partial eta squared gets the interval of the noncentrality of its F (Steiger, 2004): the
lambdas at which the observed F is the 97.5th and 2.5th percentile of a noncentral F,
mapped by eta2 = lambda / (lambda + df1 + df2 + 1). Hedges' g gets pingouin's interval.
"""

from __future__ import annotations

import math

from scipy import optimize
from scipy import stats as sps


def _lambda_at(f: float, df1: float, df2: float, prob: float) -> float:
    """The noncentrality at which P(F' <= f) = prob (0 if even lambda = 0 is below)."""

    def gap(lam: float) -> float:
        return float(sps.ncf.cdf(f, df1, df2, lam)) - prob

    if gap(0.0) <= 0:
        return 0.0
    hi = max(10.0, f * df1 * 4)
    while gap(hi) > 0:
        hi *= 2
        if hi > 1e7:
            return hi
    return float(optimize.brentq(gap, 0.0, hi, xtol=1e-10))


def eta2_partial_ci(
    f: float | None, df1: float | None, df2: float | None, level: float = 0.95
) -> list[float | None]:
    """[low, high] of partial eta squared from F(df1, df2)."""
    if f is None or df1 is None or df2 is None or not math.isfinite(f) or df2 <= 0:
        return [None, None]
    tail = (1 - level) / 2
    lo = _lambda_at(f, df1, df2, 1 - tail)
    hi = _lambda_at(f, df1, df2, tail)
    denom = df1 + df2 + 1
    return [lo / (lo + denom), hi / (hi + denom)]


def hedges_ci(g: float | None, nx: int, ny: int, paired: bool) -> list[float | None]:
    """pingouin's 95% CI of Hedges' g (paired: nx = ny = number of pairs)."""
    import pingouin as pg

    if g is None or not math.isfinite(g) or nx < 2 or ny < 2:
        return [None, None]
    ci = pg.compute_esci(stat=g, nx=nx, ny=ny, paired=paired, eftype="hedges", decimals=6)
    return [float(ci[0]), float(ci[1])]
