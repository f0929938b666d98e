"""Regions on S^(F-1) for F > 3: reduction by LPs, measure by estimation, MCMC sampling.

There is no closed form for the solid angle of a general polyhedral cone beyond three
dimensions. The measure is ``fraction * |S^(F-1)|`` with ``fraction = P(N Z >= 0)`` for
``Z ~ N(0, I_F)`` (an isotropic Gaussian's direction is uniform). It is computed

* exactly for up to 2 irredundant rows (hemisphere, lune) and for 3 linearly independent
  rows (the orthant probability of a 3-D Gaussian equals a spherical triangle's area);
* for up to F linearly independent rows (a simplicial cone) as a Gaussian orthant
  probability with Genz's quasi-Monte Carlo (``scipy.stats.multivariate_normal.cdf``),
  repeated with independent randomisations to give the standard error;
* otherwise by importance sampling of directions (``_importance.shared_sample``: a mixture of
  angular central Gaussians around the cone's centre, with bounded weights); the standard
  error is the sample one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linprog, nnls
from scipy.spatial import ConvexHull, QhullError
from scipy.stats import multivariate_normal

from ._importance import shared_sample
from ._interior import interior_direction
from ._sphere import sphere_area

_REDUNDANT_TOL = 1e-9
_GENZ_REPEATS = 8


@dataclass(frozen=True)
class SolvedND:
    """Reduction result for F > 3 (order = sorted indices of the irredundant rows)."""

    empty: bool
    order: np.ndarray
    interior: np.ndarray | None


def solve_nd(
    rows: np.ndarray, unit: np.ndarray, integral: bool, hint: list[np.ndarray] | None
) -> SolvedND:
    """Interior direction (or emptiness) and irredundant rows of a cone in R^F."""
    k, dim = unit.shape
    u = interior_direction(rows, unit, integral, hint)
    if u is None:
        return SolvedND(True, np.zeros(0, dtype=np.intp), None)
    if k <= 1:
        return SolvedND(False, np.arange(k, dtype=np.intp), u)
    keep = None
    if k > 3 * dim:
        keep = _hull_candidates(unit, u)
    if keep is None:
        keep = np.arange(k)
    return SolvedND(False, _lp_filter(unit, keep), u)


def _hull_candidates(unit: np.ndarray, u: np.ndarray) -> np.ndarray | None:
    """Extreme points of the gnomonic projection (a superset filter before the LPs)."""
    dim = unit.shape[1]
    q, _ = np.linalg.qr(np.column_stack([u, np.eye(dim)]))
    basis = q[:, 1:dim]
    proj = (unit / (unit @ u)[:, None]) @ basis
    try:
        return np.sort(ConvexHull(proj, qhull_options="Qt Qx").vertices)
    except (QhullError, ValueError):
        return None


def _lp_filter(unit: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """Drop row i when it is redundant for the cone of the other kept rows.

    The reference's redundancy check (docs/geometry.md, "More than 3 features"; ``min n_i . w``
    over the other kept rows' cone within the unit box ``>= -1e-9``), run over the current kept
    set so duplicates of a facet direction cannot protect each other. It is decided by Farkas'
    lemma first: ``n_i`` is redundant iff it lies in the cone of the others, and the distance
    ``r`` from ``n_i`` to that cone (non-negative least squares, ~10 us) bounds the LP's
    minimum between ``-r sqrt(F)`` and ``-r``. Only when ``r`` falls in the band where the two
    criteria could disagree (``1e-9 / sqrt(F) < r <= 1e-9``) is the LP itself solved.
    """
    kept = list(int(i) for i in cand)
    dim = unit.shape[1]
    i = 0
    while i < len(kept):
        others = unit[[j for j in kept if j != kept[i]]]
        if _redundant(unit[kept[i]], others, dim):
            kept.pop(i)
        else:
            i += 1
    return np.asarray(kept, dtype=np.intp)


def _redundant(row: np.ndarray, others: np.ndarray, dim: int) -> bool:
    """Whether ``row . w >= 0`` follows from ``others @ w >= 0`` (unit rows), see _lp_filter."""
    if not len(others):
        return False
    try:
        lam, _ = nnls(others.T, row, maxiter=50 * len(others))
        r = float(np.linalg.norm(others.T @ lam - row))
    except RuntimeError:  # no convergence: let the LP decide
        r = _REDUNDANT_TOL
    if r <= _REDUNDANT_TOL / np.sqrt(dim):
        return True
    if r > _REDUNDANT_TOL:
        return False
    return _lp_redundant(row, others, dim)


def _lp_redundant(row: np.ndarray, others: np.ndarray, dim: int) -> bool:
    """The reference's LP: ``min row . w`` s.t. ``others @ w >= 0``, ``-1 <= w <= 1``."""
    res = linprog(row, A_ub=-others, b_ub=np.zeros(len(others)),
                  bounds=[(-1.0, 1.0)] * dim, method="highs")
    return bool(res.status == 0 and res.fun is not None and res.fun >= -_REDUNDANT_TOL)


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.arctan2(np.linalg.norm(a * (b @ b) - b * (a @ b)) / np.linalg.norm(b),
                            a @ b))


def area_nd(region: Any, solved: SolvedND, n_samples: int, seed: int) -> tuple[float, float]:
    """``(measure, standard error)`` of a region of S^(F-1), F > 3 (see module doc)."""
    total = sphere_area(region.dim)
    if solved.empty or solved.interior is None:  # an empty cone has no interior direction
        return 0.0, 0.0
    unit = region._units()[solved.order]
    k = len(unit)
    if k == 0:
        return total, 0.0
    if k == 1:
        return total / 2, 0.0
    if k == 2:
        return total * (np.pi - _angle(unit[0], unit[1])) / (2 * np.pi), 0.0
    rank = np.linalg.matrix_rank(unit, tol=1e-10)
    if rank == k == 3:
        t = _angle(unit[0], unit[1]) + _angle(unit[0], unit[2]) + _angle(unit[1], unit[2])
        return total * (2 * np.pi - t) / (4 * np.pi), 0.0
    if rank == k:
        frac, se = _orthant(unit @ unit.T, seed)
        return total * frac, total * se
    smp = shared_sample(unit, solved.interior, region._key(), seed=seed,
                        ess=n_samples / 20, max_draws=5 * n_samples)
    return total * smp.frac, total * smp.frac_se


def _orthant(cov: np.ndarray, seed: int) -> tuple[float, float]:
    """P(X >= 0) for X ~ N(0, cov) by Genz QMC, repeated for an error estimate.

    The target accuracy is relative (1e-4 of a first rough value); the point budget is
    capped so the time is bounded, and the spread of the repeats reports what was reached.
    """
    k = len(cov)
    zero = np.zeros(k)
    rough = multivariate_normal.cdf(zero, mean=zero, cov=cov, abseps=1e-5, releps=1e-5, rng=seed)
    abseps = max(1e-4 * float(rough), 1e-12)
    vals = [
        multivariate_normal.cdf(
            zero, mean=zero, cov=cov, abseps=abseps, releps=1e-4, maxpts=20_000 * k,
            rng=seed + 1 + r,
        )
        for r in range(_GENZ_REPEATS)
    ]
    return float(np.mean(vals)), float(np.std(vals, ddof=1) / np.sqrt(len(vals)))


def hit_and_run(
    unit: np.ndarray, u: np.ndarray, m: int, rng: np.random.Generator, burn: int | None = None
) -> np.ndarray:
    """Approximately uniform directions in the region by hit-and-run, ``[m, F]``.

    Runs ``m`` independent chains in the convex body ``{x : unit @ x >= 0, |x| <= 1}``
    (whose points have uniformly distributed directions), all started at ``u / 2`` and
    advanced ``burn`` steps (default ``100 F``); returns each chain's final direction.
    """
    dim = unit.shape[1]
    steps = 100 * dim if burn is None else burn
    x = np.tile(0.5 * u, (m, 1))
    for _ in range(steps):
        d = rng.standard_normal((m, dim))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        xd = np.einsum("ij,ij->i", x, d)
        xx = np.einsum("ij,ij->i", x, x)
        disc = np.sqrt(np.maximum(xd * xd - xx + 1.0, 0.0))
        lo, hi = -xd - disc, -xd + disc
        if len(unit):
            a = x @ unit.T  # >= 0
            b = d @ unit.T
            with np.errstate(divide="ignore", invalid="ignore"):
                t = -a / b
            lo = np.maximum(lo, np.where(b > 0, t, -np.inf).max(axis=1))
            hi = np.minimum(hi, np.where(b < 0, t, np.inf).min(axis=1))
        hi = np.maximum(hi, lo)
        x = x + (lo + (hi - lo) * rng.random(m))[:, None] * d
    return x / np.linalg.norm(x, axis=1, keepdims=True)
