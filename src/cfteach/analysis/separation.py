"""Complete and quasi-complete separation of a binary outcome, per fixed-effect term.

A logistic likelihood has no finite maximum when some direction d of the coefficients
never lowers the fit: s_i x_i'd >= 0 for every observation (s_i = +1 for a success, -1 for
a failure). Such a d exists with strict inequality everywhere (complete separation) or with
equality for some rows (quasi-complete separation, e.g. a cell where everybody was right).
Random intercepts do not help: they are penalised, so only the fixed effects can run off to
infinity. Following Konis (2007, the linear programs behind R's `detectseparation`), the
directions form a convex cone; one LP (maximise sum_i s_i x_i'd over the cone within the
unit box) says whether the cone is more than {0}, and then two LPs per coefficient (max and
min of d_j) say which coefficients can diverge and in which direction. scipy's HiGHS solves
them; all run before any fit.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import linprog

_TOL = 1e-7


def _lp(c: np.ndarray, a_ub: np.ndarray) -> float:
    """max c'd subject to a_ub d <= 0 and -1 <= d <= 1 (0 when infeasible/failed)."""
    res = linprog(
        -c,
        A_ub=a_ub,
        b_ub=np.zeros(a_ub.shape[0]),
        bounds=[(-1.0, 1.0)] * len(c),
        method="highs",
    )
    return float(-res.fun) if res.status == 0 and res.fun is not None else 0.0


def separation(y: np.ndarray, x: np.ndarray, names: list[str]) -> dict[str, Any]:
    """Which coefficients of a logistic regression of y on x have an infinite MLE.

    Returns {"separated": bool, "kind": "complete" | "quasi-complete" | None,
    "terms": {name: "+inf" | "-inf"}}. x must have full column rank.
    """
    s = np.where(np.asarray(y) > 0.5, 1.0, -1.0)
    sx = x * s[:, None]
    scale = np.max(np.abs(sx)) or 1.0
    a_ub = -sx / scale  # s_i x_i'd >= 0
    total = _lp(sx.sum(axis=0) / scale, a_ub)
    if total <= _TOL:
        return {"separated": False, "kind": None, "terms": {}}
    terms: dict[str, str] = {}
    for j, name in enumerate(names):
        e = np.zeros(x.shape[1])
        e[j] = 1.0
        up, down = _lp(e, a_ub), _lp(-e, a_ub)
        if up > _TOL or down > _TOL:
            terms[name] = "+inf" if up >= down else "-inf"
    # complete separation: a direction with every s_i x_i'd > 0 (margin LP: max t, s x'd >= t)
    a_ub2 = np.column_stack([a_ub, np.ones(len(y))])
    res = linprog(
        np.r_[np.zeros(x.shape[1]), -1.0],
        A_ub=a_ub2,
        b_ub=np.zeros(len(y)),
        bounds=[(-1.0, 1.0)] * x.shape[1] + [(0.0, 1.0)],
        method="highs",
    )
    complete = res.status == 0 and res.fun is not None and -res.fun > _TOL
    return {
        "separated": True,
        "kind": "complete" if complete else "quasi-complete",
        "terms": terms,
    }
