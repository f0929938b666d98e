"""The seeded importance sample of a cone on S^(F-1), F > 3: weighted points inside it, from
which both a single region's measure (`_highdim.area_nd`) and many sets' fractions of one
region (`_shared.fractions`) are estimated. Samples are cached by the region's canonical
rows and the seed (`_SAMPLES`, cleared by `clear_cache`).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import nnls

_CHUNK = 50_000
_CONCENTRATIONS = (0.0, 3.0, 15.0, 63.0, 255.0, 1023.0, 4095.0, 16383.0, 65535.0, 1e6)
_PILOT = 10_000
_ADAPT = 3
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
