"""Beliefs on the slice where some reward weights are known (the 2021 work's setting).

With the weights ``w_k`` of the known features fixed at their true values (``w*`` scaled to L1
norm 1, as the 2021 machine-teaching work scales it), a constraint ``c . w >= 0`` becomes an
affine one on the free weights ``u``: ``c_free . u + c_known . w*_known >= 0``. The free
weights live in the L1 ball of radius ``r = 1 - |w*_known|_1``, and the belief is measured on
one of two sets (`MEASURES`):

* ``"edge"``: the ball's boundary ``|u|_1 = r`` (the whole weight vector has L1 norm 1), as the
  2021 work measured. For 3 features with one known the edge is a square's perimeter in the
  plane of the two free weights and a belief is a set of arcs along it: its measure is a
  length.
* ``"ball"``: the whole ball ``|u|_1 <= r`` (a convex set, so each redundancy test is one LP).
  For two free weights the measure is the area of a convex polygon.

Both are exact for two free weights; beyond, the measure is a uniform Monte Carlo estimate with
its standard error (`SliceRegion.measure_estimate`) and the reduction is exact (LPs).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linprog

MEASURES = ("edge", "ball")
#: Tolerance of "a row still cuts the slice" (the rows are small integers; w* is exact).
TOL = 1e-9
#: Samples of the Monte Carlo measure beyond two free weights.
N_SAMPLES = 200_000


@dataclass(frozen=True)
class KnownSlice:
    """Which weights are known, their values and the measure (`MEASURES`)."""

    known: tuple[int, ...]
    w_true: np.ndarray  # [F], L1 norm 1
    measure: str = "ball"

    @classmethod
    def make(cls, w_true: Any, known: Sequence[int], measure: str = "ball") -> KnownSlice:
        w = np.asarray(w_true, dtype=float)
        w = w / np.abs(w).sum()
        k = tuple(sorted({int(i) for i in known}))
        if not k or len(w) - len(k) < 2 or min(k) < 0 or max(k) >= len(w):
            raise ValueError(f"a known-weight slice needs at least one known weight and two "
                             f"unknown ones among {len(w)}, got known={list(known)}")
        if measure not in MEASURES:
            raise ValueError(f"unknown slice measure {measure!r} (allowed: {', '.join(MEASURES)})")
        w.setflags(write=False)
        return cls(known=k, w_true=w, measure=measure)

    @property
    def dim(self) -> int:
        return len(self.w_true)

    @property
    def free(self) -> list[int]:
        return [i for i in range(self.dim) if i not in self.known]

    @property
    def radius(self) -> float:
        return float(1.0 - np.abs(self.w_true[list(self.known)]).sum())

    def affine(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(a, b)``: each row as ``a . u + b >= 0`` in the free weights."""
        rows = np.asarray(rows, dtype=float).reshape(-1, self.dim)
        return rows[:, self.free], rows[:, list(self.known)] @ self.w_true[list(self.known)]

    def lift(self, u: np.ndarray) -> np.ndarray:
        """Free weights ``[n, m]`` -> whole weight vectors ``[n, F]`` (known ones fixed)."""
        u = np.atleast_2d(u)
        w = np.tile(self.w_true, (len(u), 1))
        w[:, self.free] = u
        return w

    def total(self) -> float:
        """The measure of the whole slice (length / area / volume)."""
        n, r = len(self.free), self.radius
        if self.measure == "ball":
            return (2 * r) ** n / math.factorial(n)
        return 2 ** n * math.sqrt(n) * r ** (n - 1) / math.factorial(n - 1)

    def region(self, rows: Any) -> SliceRegion:
        return SliceRegion(self, rows)


def _square(r: float) -> np.ndarray:
    """Corners of the 2-D L1 ball of radius r, counter-clockwise."""
    return np.array([[r, 0.0], [0.0, r], [-r, 0.0], [0.0, -r]])


def _clip(poly: np.ndarray, a: np.ndarray, b: float) -> np.ndarray:
    """Sutherland-Hodgman: the part of a convex polygon where ``a . u + b >= 0``."""
    if not len(poly):
        return poly
    out = []
    val = poly @ a + b
    for i in range(len(poly)):
        j = (i + 1) % len(poly)
        if val[i] >= 0:
            out.append(poly[i])
        if (val[i] >= 0) != (val[j] >= 0):
            t = val[i] / (val[i] - val[j])
            out.append(poly[i] + t * (poly[j] - poly[i]))
    return np.array(out).reshape(-1, 2)


def _polygon(a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    poly = _square(r)
    for ai, bi in zip(a, b, strict=True):
        poly = _clip(poly, ai, bi)
    return poly


def _shoelace(poly: np.ndarray) -> float:
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))


def _intervals(a: np.ndarray, b: np.ndarray, r: float) -> list[tuple[int, float, float]]:
    """The feasible part of the square's perimeter: ``(side, s_lo, s_hi)`` per side, with
    ``u = P_side + s (P_side+1 - P_side)``, ``0 <= s <= 1`` (empty sides left out)."""
    sq = _square(r)
    out = []
    for j in range(4):
        p, q = sq[j], sq[(j + 1) % 4]
        lo, hi = 0.0, 1.0
        for ai, bi in zip(a, b, strict=True):
            v0, slope = float(ai @ p + bi), float(ai @ (q - p))
            if abs(slope) < 1e-300:
                if v0 < 0:
                    lo, hi = 1.0, 0.0
                continue
            s = -v0 / slope
            if slope > 0:
                lo = max(lo, s)
            else:
                hi = min(hi, s)
        if hi >= lo:
            out.append((j, lo, hi))
    return out


class SliceRegion:
    """A belief on a known-weight slice: constraint rows ``c . w >= 0`` (whole-vector rows).

    Offers what teaching needs of a `Region`: `rows`, `dim`, `reduced`, `area` (here the
    slice's measure), `contains`, plus `sample` (uniform on the belief) and `measure_estimate`.
    """

    def __init__(self, sl: KnownSlice, rows: Any) -> None:
        self.slice = sl
        arr = np.asarray(rows, dtype=float).reshape(-1, sl.dim)
        self._rows = arr[np.any(arr != 0, axis=1)]
        self._reduced: np.ndarray | None = None

    @property
    def dim(self) -> int:
        return self.slice.dim

    @property
    def rows(self) -> np.ndarray:
        return self._rows

    def with_rows(self, rows: Any) -> SliceRegion:
        """This belief also cut by `rows`."""
        return SliceRegion(self.slice, np.vstack([self._rows, np.asarray(rows, dtype=float)
                                                  .reshape(-1, self.dim)]))

    # -- reduction -------------------------------------------------------------------------
    def reduced(self) -> np.ndarray:
        """The rows that still cut the slice (each row's removal would change the belief).

        Rows no point of the slice satisfies make it empty: ValueError."""
        if self._reduced is None:
            self._reduced = self._reduce()
        return self._reduced

    def _reduce(self) -> np.ndarray:
        rows = np.unique(self._rows, axis=0) if len(self._rows) else self._rows
        if not len(rows):
            return rows
        a, b = self.slice.affine(rows)
        if self.is_empty():
            raise ValueError("the constraints leave no weights on the known-weight slice")
        keep = np.ones(len(rows), dtype=bool)
        for i in range(len(rows)):
            others = keep.copy()
            others[i] = False
            if self._cuts(a[others], b[others], a[i], float(b[i])):
                continue
            keep[i] = False
        return rows[keep]

    def _cuts(self, a: np.ndarray, b: np.ndarray, ai: np.ndarray, bi: float) -> bool:
        """Does ``ai . u + bi < 0`` somewhere on the slice cut by (a, b)?"""
        sl = self.slice
        r = sl.radius
        if len(sl.free) == 2:
            if sl.measure == "ball":
                poly = _polygon(a, b, r)
                return bool(len(poly)) and float((poly @ ai + bi).min()) < -TOL
            sq = _square(r)
            for j, lo, hi in _intervals(a, b, r):
                p, q = sq[j], sq[(j + 1) % 4]
                for s in (lo, hi):
                    if float(ai @ (p + s * (q - p)) + bi) < -TOL:
                        return True
            return False
        return any(_lp_min(ai, a, b, face, r) + bi < -TOL for face in self._faces())

    def _faces(self) -> list[np.ndarray | None]:
        """The convex pieces the LPs run on: the ball (None) or the edge's orthant facets."""
        if self.slice.measure == "ball":
            return [None]
        n = len(self.slice.free)
        return list(np.array(np.meshgrid(*[[-1.0, 1.0]] * n, indexing="ij"))
                    .reshape(n, -1).T)

    # -- measure ---------------------------------------------------------------------------
    def is_empty(self) -> bool:
        a, b = self.slice.affine(self._rows)
        sl = self.slice
        if len(sl.free) == 2:
            if sl.measure == "ball":
                return len(_polygon(a, b, sl.radius)) == 0
            return not _intervals(a, b, sl.radius)
        return all(math.isinf(_lp_min(np.zeros(len(sl.free)), a, b, f, sl.radius))
                   for f in self._faces())

    def area(self) -> float:
        """The belief's measure on the slice: exact for two free weights (a length on the
        edge, an area in the ball), else the Monte Carlo estimate."""
        if len(self.slice.free) == 2:
            a, b = self.slice.affine(self._rows)
            r = self.slice.radius
            if self.slice.measure == "ball":
                return _shoelace(_polygon(a, b, r))
            side = r * math.sqrt(2)
            return float(sum((hi - lo) * side for _, lo, hi in _intervals(a, b, r)))
        return self.measure_estimate()[0]

    def measure_estimate(self, n_samples: int = N_SAMPLES, seed: int = 0
                         ) -> tuple[float, float]:
        """(measure, standard error) from `n_samples` uniform points of the whole slice."""
        u = uniform_slice(self.slice, n_samples, np.random.default_rng(seed))
        a, b = self.slice.affine(self._rows)
        ok = np.all(u @ a.T + b >= 0, axis=1) if len(a) else np.ones(len(u), dtype=bool)
        p = float(ok.mean())
        tot = self.slice.total()
        return tot * p, tot * math.sqrt(p * (1 - p) / n_samples)

    def contains(self, w: Any, tol: float = 1e-12) -> Any:
        """Whether w (any scale) satisfies every row (``c . w / |c| >= -tol``)."""
        w = np.asarray(w, dtype=float)
        if not len(self._rows):
            return True if w.ndim == 1 else np.ones(len(w), dtype=bool)
        unit = self._rows / np.linalg.norm(self._rows, axis=1, keepdims=True)
        return np.all(np.atleast_2d(w) @ unit.T >= -tol * np.linalg.norm(
            np.atleast_2d(w), axis=1, keepdims=True), axis=1) if w.ndim > 1 else \
            bool(np.all(unit @ w >= -tol * np.linalg.norm(w)))

    # -- sampling --------------------------------------------------------------------------
    def sample(self, m: int, rng: np.random.Generator, *, max_draws: int = 2_000_000
               ) -> np.ndarray:
        """`m` whole weight vectors drawn uniformly from the belief on the slice (rejection
        from the whole slice); ``(0, F)`` if the belief has no measure."""
        a, b = self.slice.affine(self._rows)
        got: list[np.ndarray] = []
        n, drawn = 0, 0
        batch = max(1024, 16 * m)
        while n < m and drawn < max_draws:
            u = uniform_slice(self.slice, batch, rng)
            drawn += batch
            if len(a):
                u = u[np.all(u @ a.T + b >= 0, axis=1)]
            got.append(u)
            n += len(u)
        if n < m:
            return np.zeros((0, self.dim))
        return self.slice.lift(np.vstack(got)[:m])


def uniform_slice(sl: KnownSlice, n: int, rng: np.random.Generator) -> np.ndarray:
    """`n` uniform points of the whole slice in the free weights ``[n, m]``: exponential
    spacings give a uniform simplex point, random signs pick the orthant."""
    m = len(sl.free)
    e = rng.exponential(size=(n, m + (1 if sl.measure == "ball" else 0)))
    x = e[:, :m] / e.sum(axis=1, keepdims=True)
    signs = rng.choice([-1.0, 1.0], size=(n, m))
    return sl.radius * x * signs


def _lp_min(c: np.ndarray, a: np.ndarray, b: np.ndarray, face: np.ndarray | None,
            r: float) -> float:
    """min ``c . u`` over ``a . u + b >= 0`` and the ball (face None) or one facet of its
    edge (``s . u = r``, ``s_i u_i >= 0``); +inf if that set is empty."""
    m = len(c)
    if face is None:
        signs = np.array(np.meshgrid(*[[-1.0, 1.0]] * m, indexing="ij")).reshape(m, -1).T
        a_ub = np.vstack([-a, signs]) if len(a) else signs
        b_ub = np.r_[b, np.full(len(signs), r)]
        res = linprog(c, A_ub=a_ub, b_ub=b_ub, bounds=[(None, None)] * m, method="highs")
    else:
        bounds = [(0, None) if s > 0 else (None, 0) for s in face]
        res = linprog(c, A_ub=-a if len(a) else None, b_ub=b if len(a) else None,
                      A_eq=face[None, :], b_eq=[r], bounds=bounds, method="highs")
    if res.status == 2:
        return math.inf
    if res.status != 0 or res.fun is None:
        raise RuntimeError(f"known-slice LP failed: {res.message}")
    return float(res.fun)
