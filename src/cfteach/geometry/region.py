"""``Region``: the part of the unit sphere where every constraint ``n . w >= 0`` holds.

A region is immutable. Its canonical rows (see ``_normalize``) are computed on
construction; everything else (interior direction, irredundant rows, area) is computed on
first use and memoised in a process-wide cache keyed by the canonical rows, so the many
repeated constraint sets of a teaching run are solved once.
"""

from __future__ import annotations

import sys
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from ._importance import _SAMPLES
from ._normalize import INT_EXACT_LIMIT, as_matrix, canonical_rows, unit_rows
from ._sphere import sphere_area
from .sphere3 import SMALL_K, Solved3, polygon_vertices, solve3, solve3_batch

_CACHE: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
_CACHE_SIZE = 65536
_AREA_CACHE: dict[tuple[Any, ...], tuple[float, float]] = {}  # F > 3 estimates


def clear_cache() -> None:
    """Forget all memoised region solutions (for memory or benchmarking)."""
    _CACHE.clear()
    _AREA_CACHE.clear()
    _SAMPLES.clear()


def infeasible_rows(dim: int, integral: bool = True) -> np.ndarray:
    """Canonical constraints of an empty region: ``e_1 . w >= 0`` and ``-e_1 . w >= 0``.

    They leave only a measure-zero great sphere, which this package treats as empty.
    """
    out = np.zeros((2, dim), dtype=np.int64 if integral else np.float64)
    out[0, 0], out[1, 0] = 1, -1
    return out


class Region:
    """``{w on the unit sphere S^(F-1) : normals @ w >= 0}``.

    ``normals`` is ``[k, F]`` with F >= 3 (a single row may be given as ``[F]``; an empty
    set needs ``dim=F`` or shape ``(0, F)``). Integral input (ints, or whole-number
    floats) is handled exactly and reduced to primitive integer rows; other input to unit
    vectors. Zero rows are dropped and duplicates collapse.

    Measure-zero regions (e.g. ``c`` and ``-c`` together, which leave a great circle, or
    constraints meeting in a single ray) count as empty: ``is_empty()`` is True, ``area()``
    is 0, and ``reduced()`` returns ``infeasible_rows``.
    """

    __slots__ = ("_rows", "_integral", "_dim", "_solved", "_hint", "_unit", "__weakref__")

    def __init__(self, normals: Any, *, dim: int | None = None) -> None:
        arr = as_matrix(normals, dim)
        self._dim = int(arr.shape[1])
        self._rows, self._integral = canonical_rows(arr)
        self._solved: Any = None
        self._hint: list[np.ndarray] | None = None
        self._unit: np.ndarray | None = None

    @classmethod
    def _from_canonical(cls, rows: np.ndarray, integral: bool) -> Region:
        """Wrap rows already in canonical form (internal: skips validation)."""
        out = cls.__new__(cls)
        out._dim = int(rows.shape[1])
        out._rows, out._integral = rows, integral
        out._solved, out._hint, out._unit = None, None, None
        return out

    @classmethod
    def full(cls, dim: int = 3) -> Region:
        """The whole sphere (no constraints)."""
        return cls(np.zeros((0, dim), dtype=np.int64))

    # ------------------------------------------------------------------ basics
    @property
    def dim(self) -> int:
        """Number of features F (the sphere is S^(F-1))."""
        return self._dim

    @property
    def rows(self) -> np.ndarray:
        """Canonical rows: primitive ints or unit floats, deduplicated, sorted (a copy)."""
        return self._rows.copy()

    @property
    def integral(self) -> bool:
        """Whether the input was integral (and rows/reduced() are primitive int64)."""
        return self._integral

    def _units(self) -> np.ndarray:
        if self._unit is None:
            self._unit = unit_rows(self._rows)
        return self._unit

    def _key(self) -> tuple[Any, ...]:
        return (self._dim, self._integral, len(self._rows), self._rows.tobytes())

    def _solve(self) -> Any:
        if self._solved is not None:
            return self._solved
        key = self._key()
        hit = _CACHE.get(key)
        if hit is None:
            if self._dim == 3:
                hit = solve3(self._rows, self._integral, self._hint)
            else:
                from ._highdim import solve_nd

                hit = solve_nd(self._rows, self._units(), self._integral, self._hint)
            _cache_put(key, hit)
        self._solved = hit
        return hit

    # ------------------------------------------------------------------ queries
    def is_empty(self) -> bool:
        """True when the region has zero measure (no strictly interior direction)."""
        return bool(self._solve().empty)

    def interior_point(self) -> np.ndarray | None:
        """A unit vector strictly inside, or None when empty (strictness is exact for
        3-feature integer rows, a margin above 1e-12 otherwise)."""
        u = self._solve().interior
        return None if u is None else u.copy()

    def reduced(self) -> np.ndarray:
        """The irredundant constraints (the facets of the cone).

        Primitive ``int64`` rows for integral input, unit ``float64`` rows otherwise. For
        F = 3 the rows are in cyclic order, counter-clockwise seen from outside the sphere
        looking at the region (``det(n_j, n_{j+1}, u) > 0`` for an interior ``u``),
        starting at the lexicographically smallest row. For F > 3 they are in sorted order.
        The whole sphere gives shape ``(0, F)``; an empty region gives ``infeasible_rows``.
        """
        s = self._solve()
        if s.empty:
            return infeasible_rows(self._dim, self._integral)
        return self._rows[s.order].copy()

    def area(self) -> float:
        """Surface measure of the region: exact for F = 3, an estimate for F > 3.

        See ``area_estimate`` for the standard error of the F > 3 estimate.
        """
        return self.area_estimate()[0]

    def area_estimate(self, n_samples: int = 200_000, seed: int = 0) -> tuple[float, float]:
        """``(area, standard_error)``; the error is 0.0 where the value is exact."""
        s = self._solve()
        if isinstance(s, Solved3):
            return float(s.area), 0.0
        from ._highdim import area_nd

        key = (*self._key(), n_samples, seed)
        hit = _AREA_CACHE.get(key)
        if hit is None:
            hit = _AREA_CACHE[key] = area_nd(self, s, n_samples=n_samples, seed=seed)
            if len(_AREA_CACHE) > _CACHE_SIZE:
                _AREA_CACHE.pop(next(iter(_AREA_CACHE)))
        return hit

    def fraction(self) -> float:
        """Area as a fraction of the whole sphere (1.0 for no constraints)."""
        return self.area() / sphere_area(self._dim)

    def contains(self, w: Any, tol: float = 1e-12) -> Any:
        """Whether direction(s) ``w`` (``[F]`` or ``[m, F]``, any positive length) satisfy
        every constraint, to within ``tol`` in the cosine. Tests the constraints literally,
        so points of a measure-zero ("empty") region still count as contained."""
        arr = np.asarray(w, dtype=np.float64)
        single = arr.ndim == 1
        pts = arr[None, :] if single else arr
        if pts.ndim != 2 or pts.shape[1] != self._dim:
            raise ValueError(
                f"w must have shape [{self._dim}] or [m, {self._dim}], got {arr.shape}"
            )
        norms = np.linalg.norm(pts, axis=1)
        if np.any(norms == 0) or not np.all(np.isfinite(norms)):
            raise ValueError("w must be finite and nonzero (a direction on the sphere)")
        if len(self._rows) == 0:
            inside = np.ones(len(pts), dtype=bool)
        else:
            inside = np.all(self._units() @ (pts / norms[:, None]).T >= -tol, axis=0)
        return bool(inside[0]) if single else inside

    def vertices(self) -> np.ndarray:
        """Corners (F = 3): ``[m, 3]`` unit vectors in the order of ``reduced()``; vertex j is
        where facets j and j+1 meet. A lune gives its two poles; a hemisphere or the whole
        sphere none. Raises for F > 3 and for empty regions."""
        if self._dim != 3:
            raise ValueError("vertices() is only defined for 3 features")
        s = self._solve()
        if s.empty:
            raise ValueError("an empty region has no vertices")
        return polygon_vertices(self._units()[s.order])

    def sample(self, m: int, rng: np.random.Generator | int | None = None) -> np.ndarray:
        """``m`` unit vectors drawn uniformly from the region, shape ``[m, F]``.

        Exact and O(1) per sample for F = 3 (triangle fan + Arvo's map); hit-and-run
        (approximate, MCMC) for F > 3. Reproducible for a given ``rng`` seed/Generator.
        """
        if isinstance(m, bool) or not isinstance(m, int | np.integer) or m < 0:
            raise ValueError(f"m must be a non-negative integer, got {m!r}")
        m = int(m)
        rng = np.random.default_rng(rng)
        s = self._solve()
        if s.empty:
            raise ValueError("cannot sample from an empty (measure-zero) region")
        if m == 0:
            return np.zeros((0, self._dim))
        if self._dim != 3:
            from ._highdim import hit_and_run

            return hit_and_run(self._units()[s.order], s.interior, m, rng)
        from . import _sample3

        unit = self._units()[s.order]
        if len(unit) == 0:
            return _sample3.sample_sphere(m, rng)
        if len(unit) == 1:
            return _sample3.sample_hemisphere(unit[0], m, rng)
        if len(unit) == 2:
            return _sample3.sample_lune(unit[0], unit[1], m, rng)
        return _sample3.sample_polygon(unit, s.interior, m, rng)

    # ------------------------------------------------------------------ algebra
    def __and__(self, other: Region) -> Region:
        if not isinstance(other, Region):
            return NotImplemented
        if other._dim != self._dim:
            raise ValueError(f"cannot intersect regions of dimension {self._dim} and {other._dim}")
        if self._integral and other._integral:
            stacked: np.ndarray = np.vstack([self._rows, other._rows])
        else:
            stacked = np.vstack([self._units(), other._units()])
        out = Region(stacked, dim=self._dim)
        hints = [r._solved.interior for r in (self, other)
                 if r._solved is not None and r._solved.interior is not None]
        out._hint = hints or None
        return out

    def __repr__(self) -> str:
        kind = "int" if self._integral else "float"
        return f"Region(dim={self._dim}, rows={len(self._rows)}, {kind})"


def overlap(a: Region, b: Region) -> float:
    """Area of the intersection of two regions (both are cones, so it is one region)."""
    return (a & b).area()


def intersection_areas(region: Region, row_sets: Iterable[Any]) -> np.ndarray:
    """``[area(region & Region(rows)) for rows in row_sets]``, batched through reduce_many.

    Each value equals ``Region(np.vstack([region.reduced(), rows])).area()`` bit for bit;
    typical use: the knowledge gain or overlap of thousands of demonstrations against one
    belief.
    """
    base = region.reduced()
    stacked = [np.vstack([base, np.asarray(r).reshape(-1, region.dim)]) for r in row_sets]
    if not stacked:
        return np.zeros(0)
    return reduce_many(stacked, dim=region.dim)[1]


#: Defaults of ``intersection_fractions`` for F > 3 (effective sample size, draw budget).
SHARED_ESS = 40_000
SHARED_MAX_DRAWS = 2_000_000


def intersection_fractions(
    region: Region,
    row_sets: Sequence[Any],
    *,
    seed: int = 0,
    ess: float = SHARED_ESS,
    max_draws: int = SHARED_MAX_DRAWS,
    separate: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """``(fractions, standard_errors)``: ``area(region & Region(rows)) / area(region)`` for
    many row sets, the ratio a knowledge gain inverts.

    F = 3: exact (``intersection_areas / region.area()``, errors 0). F > 3: every set is
    scored on one shared, seeded importance sample of ``region`` (common random numbers; see
    docs/geometry.md), so the value of a set depends only on ``region``, the set's rows and
    ``seed`` -- never on the other sets passed with it. An empty region gives zeros.
    ``separate=True`` samples each intersection on its own instead (F > 3; slower, and the
    estimates are independent): the escalation for candidates the shared sample cannot rank.
    """
    sets = [np.asarray(r).reshape(-1, region.dim) for r in row_sets]
    if not sets or region.is_empty():
        return np.zeros(len(sets)), np.zeros(len(sets))
    if region.dim == 3:
        return intersection_areas(region, sets) / region.area(), np.zeros(len(sets))
    from ._shared import fractions

    return fractions(region, sets, seed=seed, ess=ess, max_draws=max_draws, separate=separate)


def reduce_many(
    arrays: Iterable[Any] | Sequence[Any],
    dim: int | None = None,
    *,
    progress: bool | None = None,
    measure: bool = True,
) -> tuple[list[np.ndarray], np.ndarray]:
    """Reduce and measure many constraint sets: ``(reduced arrays, areas)``.

    Same answers as ``Region(a).reduced()`` and ``Region(a).area()`` for each ``a``, faster:
    integral sets are canonicalised all at once (one vectorised gcd / de-duplication over
    the concatenated rows), distinct small 3-feature integer sets are solved together in
    vectorised batches of equal size, and each distinct set is solved once (shared with
    ``Region`` through the process-wide cache). ``progress`` shows a tqdm bar on stderr
    (default: when stderr is a terminal and there are more than 5,000 sets).
    ``measure=False`` skips the areas (returned as NaN): for callers that only need the
    irredundant rows, which matters for more than 3 features where an area is an estimate.
    """
    mats = [as_matrix(a, dim) for a in arrays]
    if not mats:
        return [], np.zeros(0)
    dims = {m.shape[1] for m in mats}
    if len(dims) != 1:
        raise ValueError(f"all constraint sets must have the same number of columns, got {dims}")
    canon = _canonical_batch(mats)
    if dims == {3}:
        _presolve3(canon)
    reduced: list[np.ndarray] = []
    areas = np.empty(len(mats))
    seen: dict[bytes, tuple[np.ndarray, float]] = {}
    if progress is None:
        progress = sys.stderr.isatty() and len(canon) > 5000
    from tqdm import tqdm

    bar = tqdm(canon, desc="regions", unit="set", disable=not progress, leave=False)
    for i, (rows, integral) in enumerate(bar):
        key = rows.tobytes() + (b"i" if integral else b"f") + bytes([rows.shape[1]])
        hit = seen.get(key)
        if hit is None:
            r = Region._from_canonical(rows, integral)
            hit = (r.reduced(), r.area() if measure else np.nan)
            seen[key] = hit
        reduced.append(hit[0].copy())
        areas[i] = hit[1]
    return reduced, areas


def _presolve3(canon: list[tuple[np.ndarray, bool]]) -> None:
    """Solve the distinct small exact-integer sets not yet cached, batched by row count."""
    groups: dict[int, dict[tuple[Any, ...], np.ndarray]] = {}
    for rows, integral in canon:
        k = len(rows)
        if not integral or k < 2 or k > SMALL_K or int(np.abs(rows).max()) > INT_EXACT_LIMIT:
            continue
        key = (3, True, k, rows.tobytes())
        if key not in _CACHE:
            groups.setdefault(k, {})[key] = rows
    for sets in groups.values():
        keys = list(sets)
        for key, res in zip(keys, solve3_batch([sets[q] for q in keys]), strict=True):
            if res is not None:
                _cache_put(key, res)


def _cache_put(key: tuple[Any, ...], value: Any) -> None:
    _CACHE[key] = value
    if len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)


def _canonical_batch(mats: list[np.ndarray]) -> list[tuple[np.ndarray, bool]]:
    """canonical_rows for many matrices; vectorised when all are small-integer valued."""
    dim = mats[0].shape[1]
    try:
        big = np.concatenate(mats)
    except ValueError:
        return [canonical_rows(m) for m in mats]
    if big.dtype.kind == "f" and not (
        np.all(big == np.round(big)) and np.all(np.abs(big) < 2.0**31)
    ):
        return [canonical_rows(m) for m in mats]
    ints = big.astype(np.int64)
    sizes = np.array([len(m) for m in mats])
    set_id = np.repeat(np.arange(len(mats)), sizes)
    nonzero = np.any(ints != 0, axis=1)
    ints, set_id = ints[nonzero], set_id[nonzero]
    if len(ints) == 0:
        return [(np.zeros((0, dim), dtype=np.int64), True) for _ in mats]
    g = np.gcd.reduce(ints, axis=1)
    ints = ints // g[:, None]
    lo = int(ints.min())
    span = int(ints.max()) - lo + 1
    if span**dim * len(mats) >= 2**62:
        return [canonical_rows(m) for m in mats]
    weights = span ** np.arange(dim - 1, -1, -1, dtype=np.int64)
    key = set_id * span**dim + (ints - lo) @ weights
    _, first = np.unique(key, return_index=True)  # sorted by set, then row
    ints, set_id = ints[first], set_id[first]
    bounds = np.searchsorted(set_id, np.arange(len(mats) + 1))
    return [(ints[bounds[i] : bounds[i + 1]], True) for i in range(len(mats))]
