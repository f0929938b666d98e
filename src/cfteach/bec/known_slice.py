"""Redundancy on the slice where some weights are known (how the 2021 work's BECs read).

The 2021 machine-teaching work's published BECs are what remains once the step weight is
treated as known: the weights live on the slice
``{w : w_k = w*_k for the known k, |w|_1 <= 1}`` of the L1 ball, with ``w*`` scaled to L1
norm 1. On the full sphere the same rows can keep more facets, so a faithful comparison needs
this reduction, not the sphere's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize import linprog

_TOL = 1e-9


def _slice_polytope(n_free: int) -> tuple[np.ndarray, np.ndarray]:
    """The L1 ball in the free coordinates, |u|_1 <= r, as 2^n sign rows (a_ub u <= r)."""
    signs = np.array(np.meshgrid(*[[-1.0, 1.0]] * n_free, indexing="ij")).reshape(n_free, -1).T
    return signs, np.ones(len(signs))


def reduce_on_known_slice(rows: np.ndarray, w_true: np.ndarray, known: Sequence[int]
                          ) -> np.ndarray:
    """The rows of ``rows . w >= 0`` that still cut the known-weight slice of the L1 ball.

    `w_true` gives the known weights (scaled to L1 norm 1 here); a row is redundant when the
    LP minimum of ``row . w`` over the slice, subject to the other kept rows, is >= 0. Rows
    that no point of the slice satisfies make the slice empty: a ValueError names them.
    """
    rows = np.unique(np.asarray(rows, dtype=float), axis=0)
    rows = rows[np.any(rows != 0, axis=1)]
    w = np.asarray(w_true, dtype=float)
    w = w / np.abs(w).sum()
    known = sorted(set(int(k) for k in known))
    free = [i for i in range(len(w)) if i not in known]
    if not known or not free:
        raise ValueError("a known-weight slice needs at least one known and one free weight")
    radius = 1.0 - np.abs(w[known]).sum()
    ball, ball_b = _slice_polytope(len(free))
    offset = rows[:, known] @ w[known]  # row . w = row_free . u + offset
    keep = np.ones(len(rows), dtype=bool)
    for i in range(len(rows)):
        others = keep.copy()
        others[i] = False
        a_ub = np.vstack([-rows[others][:, free], ball])
        b_ub = np.r_[offset[others], ball_b * radius]
        res = linprog(c=rows[i, free], A_ub=a_ub, b_ub=b_ub, bounds=[(None, None)] * len(free),
                      method="highs")
        if res.status == 2:
            raise ValueError("the constraints leave no weights on the known-weight slice")
        if res.status != 0:
            raise RuntimeError(f"known-slice LP failed: {res.message}")
        if res.fun + offset[i] >= -_TOL:
            keep[i] = False
    return rows[keep].astype(np.int64)
