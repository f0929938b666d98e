"""A direction strictly inside a cone ``{w : N w >= 0}``, cheaply when possible.

Order of attempts: positive combinations of the normals (exact for integer rows), then a
few Gilbert (min-norm-point) steps, and only then one small LP. By Gordan's theorem a
strictly interior direction exists iff the region has positive measure; the min-norm point
of ``conv(unit normals)`` is the centre of the largest inscribed cap, so the LP margin and
the Gilbert iterate measure the same thing.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

#: A direction counts as interior when its angular distance to every boundary great
#: sphere exceeds this (radians, via the sine). Regions thinner than this are "empty".
MARGIN_EPS = 1e-12

_GILBERT_STEPS = 48


def margin(unit: np.ndarray, u: np.ndarray) -> float:
    """min_i n_i . u / |u| for unit normals: the sine of the distance to the nearest wall."""
    nu = float(np.sqrt(u @ u))
    if nu == 0.0:
        return -1.0
    return float(np.min(unit @ u)) / nu


def _accept(unit: np.ndarray, u: np.ndarray) -> np.ndarray | None:
    if margin(unit, u) > MARGIN_EPS:
        return u / np.sqrt(u @ u)
    return None


def interior_direction(
    rows: np.ndarray,
    unit: np.ndarray,
    integral: bool,
    extra: list[np.ndarray] | None = None,
) -> np.ndarray | None:
    """Unit vector ``u`` with ``unit @ u > MARGIN_EPS``, or ``None`` if none exists.

    ``extra`` holds additional candidate directions to try first (e.g. cached interior
    points of a parent region).
    """
    k, dim = unit.shape
    if k == 0:
        u = np.zeros(dim)
        u[-1] = 1.0
        return u
    if extra:
        for cand in extra:
            got = _accept(unit, np.asarray(cand, dtype=np.float64))
            if got is not None:
                return got
    if integral:
        s = rows.sum(axis=0)
        if np.all(rows @ s > 0):
            got = _accept(unit, s.astype(np.float64))
            if got is not None:
                return got
    got = _accept(unit, unit.sum(axis=0))
    if got is not None:
        return got
    got = _gilbert(unit)
    if got is not None:
        return got
    return _lp_direction(unit)


def _gilbert(unit: np.ndarray) -> np.ndarray | None:
    """Gilbert's min-norm-point iteration on conv(unit); stop at the first interior iterate."""
    x = unit.mean(axis=0)
    for _ in range(_GILBERT_STEPS):
        d = unit @ x
        j = int(np.argmin(d))
        nx = float(np.sqrt(x @ x))
        if nx < 1e-13:
            return None
        if d[j] > MARGIN_EPS * nx:
            return x / nx
        diff = x - unit[j]
        denom = float(diff @ diff)
        if denom == 0.0:
            return None
        gamma = min(max(float(x @ diff) / denom, 0.0), 1.0)
        if gamma == 0.0:
            return None
        x = x - gamma * diff
    return None


def _lp_direction(unit: np.ndarray) -> np.ndarray | None:
    """max t  s.t.  unit @ u >= t, -1 <= u <= 1, t <= 1 (HiGHS)."""
    k, dim = unit.shape
    c = np.zeros(dim + 1)
    c[-1] = -1.0
    a_ub = np.hstack([-unit, np.ones((k, 1))])
    bounds = [(-1.0, 1.0)] * dim + [(None, 1.0)]
    res = linprog(c, A_ub=a_ub, b_ub=np.zeros(k), bounds=bounds, method="highs")
    if res.status != 0 or res.x is None or -res.fun <= MARGIN_EPS:
        return None
    return _accept(unit, res.x[:dim])
