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

from collections import OrderedDict
from dataclasses import dataclass
from itertools import combinations
from typing import Any

import numpy as np
from scipy.optimize import nnls

#: A set keeping less of the shared sample than this (effective points) is measured on its
#: own: its fraction would be known to worse than about 5%.
MIN_ESS_INSIDE = 400
#: A set cutting off less than this (effective points): its cut-off part is measured.
MIN_ESS_OUTSIDE = 30
_CHUNK = 50_000
_CONCENTRATIONS = (0.0, 3.0, 15.0, 63.0, 255.0, 1023.0, 4095.0, 16383.0, 65535.0, 1e6)
_PILOT = 10_000
_ADAPT = 3
_MAX_CUT_ROWS = 4  # inclusion-exclusion over at most 2^4 - 1 cones
_TAIL_ESS = 4000  # sample of a tail's own region
_TAIL_DRAWS = 400_000
_SAMPLES: OrderedDict[tuple[Any, ...], SharedSample] = OrderedDict()
_SAMPLE_CACHE = 4


@dataclass(frozen=True)
class SharedSample:
    """Weighted points inside a region: ``points [m, F]``, ``weights [m]`` summing to 1;
    ``frac`` (standard error ``frac_se``) estimates the region's share of the sphere."""

    points: np.ndarray
    weights: np.ndarray
    ess: float
    draws: int
    frac: float
    frac_se: float


def centre(unit: np.ndarray) -> np.ndarray | None:
    """The direction of the min-norm point of ``conv(unit rows)``: the centre of the largest
    cap inside the cone (None if the cone has no interior). Non-negative least squares on
    ``[N^T; M 1^T] lam = [0; M]`` enforces ``sum lam = 1`` through the heavy last row."""
    k, dim = unit.shape
    big = 1e3
    a = np.vstack([unit.T, np.full((1, k), big)])
    b = np.zeros(dim + 1)
    b[-1] = big
    try:
        lam, _ = nnls(a, b, maxiter=50 * k + 100)
    except RuntimeError:
        return None
    x = unit.T @ lam
    nx = float(np.linalg.norm(x))
    if nx == 0.0 or float(np.min(unit @ x)) <= 1e-12 * nx:
        return None
    return x / nx


class _Mixture:
    """Angular central Gaussians (directions of ``N(0, S)``) folded onto the hemisphere
    ``c . x >= 0``: the ladder ``S = I + a c c^T`` (one per concentration, mixed equally)
    and, optionally, one fitted ``S`` with mixture weight ``fitted_pi``. ``weights(x)`` is
    the uniform density over the mixture's, ``1 / (|S^(F-1)| * 2 * sum_l pi_l q_l(x))``,
    with ``q_l(x) = |S_l|^(-1/2) (x^T S_l^-1 x)^(-F/2) / |S^(F-1)|``."""

    def __init__(self, c: np.ndarray, fitted: np.ndarray | None = None,
                 fitted_pi: float = 0.5, fold: bool = True) -> None:
        self.c = c
        self.fold = fold
        self.a = np.asarray(_CONCENTRATIONS)
        lad = 1.0 - (fitted_pi if fitted is not None else 0.0)
        self.pis = np.full(len(self.a), lad / len(self.a))
        self.fitted_pi = 0.0 if fitted is None else fitted_pi
        self.chol = self.inv = None
        self.logdet = 0.0
        if fitted is not None:
            cov = 0.5 * (fitted + fitted.T)
            self.chol = np.linalg.cholesky(cov)
            self.inv = np.linalg.inv(cov)
            self.logdet = float(2 * np.log(np.diag(self.chol)).sum())

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        dim = len(self.c)
        cum = np.cumsum(np.append(self.pis, self.fitted_pi))
        comp = np.minimum(np.searchsorted(cum / cum[-1], rng.random(n), side="right"),
                          len(cum) - 1)
        y = rng.standard_normal((n, dim))
        lad = comp < len(self.a)
        # ladder: sqrt(I + a c c^T) z = z + (sqrt(1 + a) - 1) (c . z) c
        k = np.where(lad, np.sqrt(1.0 + self.a[np.minimum(comp, len(self.a) - 1)]) - 1.0, 0.0)
        y += (k * (y @ self.c))[:, None] * self.c
        if self.chol is not None and not lad.all():
            y[~lad] = y[~lad] @ self.chol.T
        y /= np.linalg.norm(y, axis=1, keepdims=True)
        if self.fold:
            y *= np.where(y @ self.c < 0, -1.0, 1.0)[:, None]
        return y

    def weights(self, x: np.ndarray) -> np.ndarray:
        dim = x.shape[1]
        c2 = (x @ self.c) ** 2
        # ladder: |S| = 1 + a, x^T S^-1 x = 1 - a / (1 + a) (c . x)^2 for unit x
        quad = 1.0 - np.outer(c2, self.a / (1.0 + self.a))
        dens = (quad ** (-0.5 * dim)) @ (self.pis / np.sqrt(1.0 + self.a))
        if self.inv is not None:
            q = np.einsum("ij,ij->i", x @ self.inv, x)
            dens += self.fitted_pi * np.exp(-0.5 * self.logdet) * q ** (-0.5 * dim)
        return (0.5 if self.fold else 1.0) / dens


def _hits(rng: np.random.Generator, mix: _Mixture, unit: np.ndarray, n: int,
          ) -> tuple[np.ndarray, np.ndarray]:
    x = mix.draw(rng, n)
    x = x[np.all(x @ unit.T >= 0, axis=1)]
    return x, mix.weights(x)


def shared_sample(unit: np.ndarray, u: np.ndarray, key: tuple[Any, ...], *, seed: int,
                  ess: float, max_draws: int, cache: bool = True) -> SharedSample:
    """The seeded importance sample of the cone ``unit @ w >= 0`` (cached by ``key`` unless
    ``cache`` is False, as for the one-off samples of tails, which would push out beliefs).

    Proposal: a mixture of angular central Gaussians folded onto the hemisphere around the
    cone's centre ``c`` (``centre``; the cone lies in ``c . x >= 0`` because ``c`` is a
    non-negative combination of its normals). Half of it is a ladder of concentrations
    ``S = I + a c c^T`` (``a`` from 0, the uniform distribution, to 10^6), which keeps every
    importance weight below ``2 * len(ladder)``; the other half is fitted to the region:
    ``S`` = the weighted second moment of the pilot's hits, refitted ``_ADAPT`` times.
    """
    ckey = (*key, seed, ess, max_draws)
    hit = _SAMPLES.get(ckey)
    if hit is not None:
        _SAMPLES.move_to_end(ckey)
        return hit
    rng = np.random.default_rng(seed)
    dim = unit.shape[1]
    c = centre(unit) if len(unit) else None
    c = u if c is None else c
    fold = len(unit) > 0  # the whole sphere is not inside a hemisphere
    mix = _Mixture(c, fold=fold)
    for _ in range(_ADAPT):
        hx, hw = _hits(rng, mix, unit, _PILOT)
        if len(hw) <= 4 * dim:
            break
        m2 = (hx * hw[:, None]).T @ hx / hw.sum()
        fitted = m2 / np.trace(m2) + 1e-6 * np.eye(dim)
        mix = _Mixture(c, fitted, fold=fold)
    pts, wts, draws = [], [], 0
    sw = sw2 = 0.0
    while draws < max_draws:
        x, w = _hits(rng, mix, unit, _CHUNK)
        draws += _CHUNK
        pts.append(x)
        wts.append(w)
        sw += float(w.sum())
        sw2 += float((w * w).sum())
        if sw > 0 and sw * sw / sw2 >= ess:
            break
    points = np.concatenate(pts)
    weights = np.concatenate(wts)
    total = weights.sum()
    weights = weights / total if total > 0 else weights
    frac = sw / draws
    frac_se = float(np.sqrt(max(sw2 / draws - frac * frac, 0.0) / draws))
    out = SharedSample(points, weights, (sw * sw / sw2) if sw2 > 0 else 0.0, draws, frac,
                       frac_se)
    if cache:
        _SAMPLES[ckey] = out
        if len(_SAMPLES) > _SAMPLE_CACHE:
            _SAMPLES.popitem(last=False)
    return out


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


def _share(rows: np.ndarray, dim: int, seed: int, ess: float = _TAIL_ESS,
           max_draws: int = _TAIL_DRAWS) -> tuple[float, float]:
    """A region's share of the sphere and its error, from a (smaller) sample of its own."""
    from .region import Region

    r = Region(rows, dim=dim)
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
    a, a_se = _share(_stack(region, rows), region.dim, seed, ess, max_draws)
    if a <= 0 or base.frac <= 0:
        return 0.0, 0.0
    r = a / base.frac
    return min(r, 1.0), r * float(np.hypot(a_se / a, base.frac_se / base.frac))


def _cut_off(region: Any, unit: np.ndarray, rows: np.ndarray, seed: int,
             base: SharedSample) -> tuple[float, float]:
    """``1 - share(B & not C) / share(B)`` when almost no sample point lies outside ``C``."""
    from ._highdim import _redundant

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
            a, a_se = _share(np.vstack([unit, -np.array(sub)]), region.dim, seed)
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
