"""A direction strictly inside a cone ``{w : N w >= 0}``, cheaply when possible.

Order of attempts: positive combinations of the normals (exact for integer rows), then
Wolfe's min-norm-point algorithm, and only then one small LP. By Gordan's theorem a
strictly interior direction exists iff the region has positive measure; the min-norm point
of ``conv(unit normals)`` is the centre of the largest inscribed cap, so the LP margin and
the Wolfe iterate measure the same thing.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

#: A direction counts as interior when its angular distance to every boundary great
#: sphere exceeds this (radians, via the sine). Regions thinner than this are "empty".
MARGIN_EPS = 1e-12



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
    got = _wolfe(unit)
    if got is not None:
        return got
    return _lp_direction(unit)


def _wolfe(unit: np.ndarray, max_iter: int = 200) -> np.ndarray | None:
    """Wolfe's min-norm-point algorithm on conv(unit rows), stopped at the first iterate
    that is strictly interior to the region. Returns None when it cannot certify one (the
    caller then asks the LP, which also settles emptiness)."""
    k, dim = unit.shape
    g0 = unit @ unit.mean(axis=0)
    s_idx = [int(np.argmax(g0))]
    lam: np.ndarray = np.ones(1)
    x = unit[s_idx[0]].copy()
    for _ in range(max_iter):
        d = unit @ x
        j = int(np.argmin(d))
        xx = float(x @ x)
        if xx < 1e-24:
            return None
        if d[j] > MARGIN_EPS * np.sqrt(xx):
            return x / np.sqrt(xx)
        if xx - d[j] <= 1e-15 or j in s_idx or len(s_idx) > dim:
            return None  # optimal (or stalled) without a positive margin
        s_idx.append(j)
        lam = np.append(lam, 0.0)
        for _ in range(dim + 2):  # minor cycles
            p = unit[s_idx]
            m = len(s_idx)
            a = np.zeros((m + 1, m + 1))
            a[:m, :m] = p @ p.T
            a[:m, m] = 1.0
            a[m, :m] = 1.0
            rhs = np.zeros(m + 1)
            rhs[m] = 1.0
            try:
                mu = np.linalg.solve(a, rhs)[:m]
            except np.linalg.LinAlgError:
                return None
            if np.all(mu > 1e-14):
                lam = mu
                break
            neg = mu <= 1e-14
            theta = float(np.min(lam[neg] / (lam[neg] - mu[neg])))
            lam = lam + theta * (mu - lam)
            keep = lam > 1e-14
            s_idx = [i for i, kp in zip(s_idx, keep, strict=True) if kp]
            lam = lam[keep]
            lam /= lam.sum()
        x = lam @ unit[s_idx]
    return None


def _lp_direction(unit: np.ndarray) -> np.ndarray | None:
    """max t  s.t.  unit @ u >= t, -1 <= u <= 1, t <= 1 (HiGHS)."""
    k, dim = unit.shape
    c = np.zeros(dim + 1)
    c[-1] = -1.0
    a_ub = np.hstack([-unit, np.ones((k, 1))])
    bounds = [(-1.0, 1.0)] * dim + [(None, 1.0)]
    res = linprog(c, A_ub=a_ub, b_ub=np.zeros(k), bounds=bounds, method="highs")
    if res.status != 0 or res.x is None or res.fun is None or -res.fun <= MARGIN_EPS:
        return None
    return _accept(unit, res.x[:dim])
