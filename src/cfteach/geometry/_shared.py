"""Fractions of one region (F > 3) cut by many constraint sets, from one shared sample.

A knowledge gain is ``area(B) / area(B & C) = 1 / P(w in C | w uniform in B)``, so ranking
thousands of candidate sets ``C`` against one belief ``B`` needs only conditional fractions.
They are estimated on **one** seeded importance sample of ``B`` (common random numbers):
every candidate is scored on the same points, so two candidates whose regions agree get the
same value, differences between candidates have far less noise than independent estimates,
and no candidate needs an LP reduction or its own volume estimate. The sample depends only
on ``B``'s canonical rows and the seed, so a candidate's estimate does not depend on which
other candidates are scored with it (chunking across workers cannot change it).

The sample: draws ``Z ~ N(s u, I)`` (``u`` the region's interior direction, ``s`` picked by a
pilot like ``area_estimate``'s importance sampler), kept when inside ``B``, with weights
``exp(-s u.Z + s^2/2)`` (the ratio of ``N(0, I)`` to the proposal; the direction of an
isotropic Gaussian is uniform). Draws continue in chunks until the Kish effective sample
size reaches ``ess`` or ``max_draws`` are spent. For a set ``C`` the estimate is the
self-normalised ``p = sum_{Z in C} w / sum w`` with the delta-method standard error.

Tails where a shared sample cannot resolve the fraction are measured on their own:
* fewer than ``MIN_ESS_INSIDE`` effective sample points inside ``C``: the intersection
  ``B & C`` gets a sample of its own (same construction), and ``p = share(B & C) / share(B)``;
* fewer than ``MIN_ESS_OUTSIDE`` effective points outside ``C``: whether ``C`` cuts ``B`` at
  all is decided by the
  redundancy test of each row against ``B``'s irredundant rows (Farkas, as in reduction):
  no cutting row gives exactly 1; otherwise the cut-off part ``B & not C`` (a union of
  cones ``B & {c . w < 0}``) is measured by inclusion-exclusion over its cutting rows, each
  cone with a sample of its own.
"""
from __future__ import annotations

from itertools import combinations
from typing import Any

import numpy as np

from ._highdim import _redundant
from ._importance import SharedSample, shared_sample

#: A set keeping less of the shared sample than this (effective points) is measured on its
#: own: its fraction would be known to worse than about 5%.
MIN_ESS_INSIDE = 400
#: A set cutting off less than this (effective points): its cut-off part is measured.
MIN_ESS_OUTSIDE = 30
_MAX_CUT_ROWS = 4  # inclusion-exclusion over at most 2^4 - 1 cones
_TAIL_ESS = 4000  # sample of a tail's own region
_TAIL_DRAWS = 400_000


def _signs(points_t: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``rows @ points >= 0`` as packed bits ``[r, ceil(m/8)]``, summed feature by feature in
    a fixed order, so a row's bits do not depend on the other rows in the batch (a matrix
    product may round differently for different shapes)."""
    acc = rows[:, :1] * points_t[0]
    for f in range(1, len(points_t)):
        acc += rows[:, f: f + 1] * points_t[f]
    return np.packbits(acc >= 0, axis=1)


def _inside_counts(sample: SharedSample, sets: list[np.ndarray], batch: int = 256,
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Per set: (weight inside, sum of squared weights inside).

    Each set's values are computed from its own bits only, in a fixed order, so they are
    bit-identical whatever other sets share the call.
    """
    m = len(sample.weights)
    n = len(sets)
    w_in, w2_in = np.zeros(n), np.zeros(n)
    w = sample.weights
    w2 = w * w
    points_t = np.ascontiguousarray(sample.points.T)
    for lo in range(0, n, batch):
        chunk = sets[lo: lo + batch]
        sizes = np.array([len(s) for s in chunk])
        uniq, inv = np.unique(np.vstack(chunk).astype(np.float64), axis=0,
                              return_inverse=True)
        bits = np.vstack([_signs(points_t, uniq[a: a + 32]) for a in range(0, len(uniq), 32)])
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        acc = np.bitwise_and.reduceat(bits[inv.ravel()], starts, axis=0)
        for j, packed in enumerate(acc):
            inside = np.unpackbits(packed, count=m).view(bool)
            w_in[lo + j] = w[inside].sum()
            w2_in[lo + j] = w2[inside].sum()
    return w_in, w2_in


def fractions(region: Any, sets: list[np.ndarray], *, seed: int, ess: float,
              max_draws: int, separate: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(p, se)``: the fraction of ``region`` (F > 3, non-empty) inside each row set.

    ``separate``: every set's intersection gets a sample of its own (``ess``, ``max_draws``)
    instead of sharing the region's, for the few candidates whose ranking the shared
    sample leaves open.
    """
    s = region._solve()
    unit = region._units()[s.order]
    sample = shared_sample(unit, s.interior, region._key(), seed=seed, ess=ess,
                           max_draws=max_draws)
    p = np.ones(len(sets))
    se = np.zeros(len(sets))
    todo = [i for i, c in enumerate(sets) if len(c)]
    if not todo:
        return p, se
    if separate:
        for i in todo:
            p[i], se[i] = _direct(region, sets[i], seed, sample, ess, max_draws)
        return p, se
    w_in, w2_in = _inside_counts(sample, [sets[i] for i in todo])
    w2_all = float((sample.weights ** 2).sum())
    for j, i in enumerate(todo):
        pj = float(w_in[j])
        # delta-method error of the self-normalised estimate
        var = (1 - pj) ** 2 * w2_in[j] + pj * pj * (w2_all - w2_in[j])
        p[i], se[i] = pj, float(np.sqrt(max(var, 0.0)))
        ess_in = pj * pj / w2_in[j] if w2_in[j] > 0 else 0.0
        w2_out = w2_all - w2_in[j]
        ess_out = (1 - pj) ** 2 / w2_out if w2_out > 0 else 0.0
        if ess_in < MIN_ESS_INSIDE:
            p[i], se[i] = _direct(region, sets[i], seed, sample)
        elif ess_out < MIN_ESS_OUTSIDE:
            p[i], se[i] = _cut_off(region, unit, sets[i], seed, sample)
    return p, se


def _share(like: Any, rows: np.ndarray, seed: int, ess: float = _TAIL_ESS,
           max_draws: int = _TAIL_DRAWS) -> tuple[float, float]:
    """The share of the sphere of the region ``rows`` (built as a region of the same class and
    dimension as ``like``, so this module needs no import of `Region`) and its error, from a
    (smaller) sample of its own."""
    r = type(like)(rows, dim=like.dim)
    if r.is_empty():
        return 0.0, 0.0
    s = r._solve()
    unit = r._units()[s.order]
    if len(unit) == 0:
        return 1.0, 0.0
    smp = shared_sample(unit, s.interior, r._key(), seed=seed, ess=ess,
                        max_draws=max_draws, cache=False)
    return smp.frac, smp.frac_se


def _direct(region: Any, rows: np.ndarray, seed: int, base: SharedSample,
            ess: float = _TAIL_ESS, max_draws: int = _TAIL_DRAWS) -> tuple[float, float]:
    """``share(B & C) / share(B)``, the intersection sampled on its own."""
    a, a_se = _share(region, _stack(region, rows), seed, ess, max_draws)
    if a <= 0 or base.frac <= 0:
        return 0.0, 0.0
    r = a / base.frac
    return min(r, 1.0), r * float(np.hypot(a_se / a, base.frac_se / base.frac))


def _cut_off(region: Any, unit: np.ndarray, rows: np.ndarray, seed: int,
             base: SharedSample) -> tuple[float, float]:
    """``1 - share(B & not C) / share(B)`` when almost no sample point lies outside ``C``."""
    c = np.asarray(rows, dtype=np.float64)
    c = c / np.linalg.norm(c, axis=1, keepdims=True)
    cutting = [r for r in c if not _redundant(r, unit, unit.shape[1])]
    if not cutting:
        return 1.0, 0.0
    if len(cutting) > _MAX_CUT_ROWS:
        return _direct(region, rows, seed, base)
    q, q_var = 0.0, 0.0
    for k in range(1, len(cutting) + 1):
        for sub in combinations(cutting, k):
            a, a_se = _share(region, np.vstack([unit, -np.array(sub)]), seed)
            q += (-1) ** (k + 1) * a
            q_var += a_se * a_se
    q = min(max(q / base.frac, 0.0), 1.0)
    return 1.0 - q, float(np.sqrt(q_var) / base.frac + q * base.frac_se / base.frac)


def _stack(region: Any, rows: np.ndarray) -> np.ndarray:
    base = region.reduced()
    rows = np.asarray(rows).reshape(-1, region.dim)
    if region.integral and np.issubdtype(rows.dtype, np.integer):
        return np.vstack([base, rows])
    return np.vstack([region._units()[region._solve().order], rows.astype(np.float64)])
