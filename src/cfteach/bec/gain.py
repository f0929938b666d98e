"""Knowledge gain (the paper's Algorithm 1) and overlap (its Algorithm 2, `measureOverlap`) of
thousands of demonstrations against one region.

gain(xi) = area(running) / area(running & C(xi)); overlap(xi) = area(B & BEC'(xi)). Both only
depend on the rows that actually *cut* the region: a row c is redundant w.r.t. a convex cone
iff ``c . g >= 0`` for every generator g of the cone (its extreme rays, plus both directions
of its lineality space), an exact integer test for 3 features. Demos without a cutting row
need no geometry at all; the rest are deduplicated by their set of cutting rows, so each
distinct region is measured once.
"""

from __future__ import annotations

import numpy as np

from cfteach.bec.rows import RowSet
from cfteach.geometry import Region, intersection_areas, intersection_fractions


def cone_generators(region: Region) -> np.ndarray | None:
    """Integer generators ``[G, 3]`` of the cone of an integral 3-feature region.

    ``c`` is redundant for the region iff ``generators @ c >= 0`` everywhere. Returns None
    when the test is not available (more than 3 features, or non-integral rows); callers
    then treat every nonzero row as cutting, which is slower but still exact.
    """
    if region.dim != 3 or not region.integral:
        return None
    n = region.reduced().astype(np.int64)
    eye = np.eye(3, dtype=np.int64)
    if region.is_empty():
        return np.zeros((0, 3), dtype=np.int64)
    k = len(n)
    if k == 0:
        return np.vstack([eye, -eye])
    if k == 1:
        a = n[0]
        e1 = np.cross(a, eye[0])
        if not e1.any():
            e1 = np.cross(a, eye[1])
        e2 = np.cross(a, e1)
        return np.vstack([a, e1, -e1, e2, -e2])
    if k == 2:
        d = np.cross(n[0], n[1])
        g1 = np.cross(d, n[0])
        g1 = g1 if g1 @ n[1] > 0 else -g1
        g2 = np.cross(d, n[1])
        g2 = g2 if g2 @ n[0] > 0 else -g2
        return np.vstack([d, -d, g1, g2])
    u = region.interior_point()
    assert u is not None  # the region is not empty (checked above)
    v = np.cross(n, np.roll(n, -1, axis=0))
    sign = np.where(v @ u >= 0, 1, -1)
    return v * sign[:, None]


def cutting(rows: np.ndarray, gens: np.ndarray | None) -> np.ndarray:
    """bool ``[R]``: rows that cut the region (are negative on some generator)."""
    if gens is None:
        return np.any(rows != 0, axis=1)
    if not len(rows):
        return np.zeros(0, dtype=bool)
    return np.any(rows @ gens.T < 0, axis=1)


def intersected_areas(region: Region, rowset: RowSet, demos: np.ndarray | None = None,
                      ) -> tuple[np.ndarray, np.ndarray]:
    """``(area(region & rows(d)) [n], has_rows [n])`` for the demos asked (default all).

    Only the rows that cut the region count; `geometry.intersection_areas` measures them
    (each distinct set once, against ``region.reduced()`` as it is: no integer cast, so
    non-integral regions are measured right too).
    """
    ids = np.arange(rowset.n_demos) if demos is None else np.asarray(demos, dtype=np.int64)
    gens = cone_generators(region)
    cut = rowset.select(cutting(rowset.rows, gens))
    has = rowset.counts()[ids] > 0
    out = np.full(len(ids), region.area())
    todo = np.flatnonzero(cut.counts()[ids] > 0)
    if len(todo):  # each distinct cutting set once; geometry batches the small ones
        sets, slot = cut.distinct(ids[todo])
        out[todo] = intersection_areas(region, sets)[slot]
    return out, has


def knowledge_gains(running: Region, rowset: RowSet, demos: np.ndarray | None = None,
                    *, seed: int = 0) -> np.ndarray:
    """Spec §7 for every demo: area(running) / area(running & C); 0 when C is empty.

    A zero-area intersection (never observed) also gives 0 rather than infinity, so such a
    demo is never chosen. Exact for 3 features; for more, see `gain_estimates` (``seed``
    picks its shared sample; a demo's gain depends only on the belief, its rows and the
    seed, not on which other demos are asked in the same call).
    """
    return gain_estimates(running, rowset, demos, seed=seed)[0]


def gain_estimates(running: Region, rowset: RowSet, demos: np.ndarray | None = None,
                   *, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``(gains [n], standard_errors [n])`` of `knowledge_gains`; errors are 0 when exact.

    3 features: exact areas of the intersections (errors 0). More features: the gain is
    ``1 / p`` with ``p`` the fraction of the belief inside C, estimated for every demo on
    one shared seeded sample of the belief (`geometry.intersection_fractions`), so no
    intersection is reduced by LPs or measured on its own; the error is the delta method's
    ``se(p) / p^2``.
    """
    ids = np.arange(rowset.n_demos) if demos is None else np.asarray(demos, dtype=np.int64)
    if running.dim == 3:
        areas, has = intersected_areas(running, rowset, ids)
        base = running.area()
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(areas > 0, base / np.where(areas > 0, areas, 1.0), 0.0)
        return np.where(has, g, 0.0), np.zeros(len(ids))
    gains, errors = np.zeros(len(ids)), np.zeros(len(ids))
    todo = np.flatnonzero(rowset.counts()[ids] > 0)
    if len(todo):
        sets, slot = rowset.distinct(ids[todo])
        p, p_se = intersection_fractions(running, sets, seed=seed)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(p > 0, 1.0 / np.where(p > 0, p, 1.0), 0.0)
            e = np.where(p > 0, p_se / np.where(p > 0, p * p, 1.0), 0.0)
        gains[todo], errors[todo] = g[slot], e[slot]
    return gains, errors


#: At most this many distinct contenders are re-estimated on samples of their own.
REFINE_MAX = 16
#: Standard errors within which a demo still contends for the best gain (`refine_top`).
REFINE_Z = 3.0


def refine_top(running: Region, rowset: RowSet, gains: np.ndarray, errors: np.ndarray,
               *, z: float = REFINE_Z, seed: int = 0) -> np.ndarray:
    """Gains (over all demos of `rowset`) with the possible best ones measured more precisely.

    A demo is a contender when its gain is above 1 and within ``z`` standard errors of the
    best lower bound ``max(gain - z error)``. When the contenders have more than one
    distinct row set, the (up to ``REFINE_MAX``, highest upper bounds first) sets are
    re-estimated each on a sample of its own (``intersection_fractions(separate=True)``,
    effective size 40,000): independent estimates with a relative error near 0.5%, where the
    shared sample's error grows as the candidate's share of the belief shrinks. Exact gains
    (errors all 0, e.g. 3 features) come back unchanged. Run it once on the gains of all
    demos (not per chunk): which demos contend depends on all of them, and each refined
    value depends only on the belief, the demo's rows and ``seed``.
    """
    live = gains > 1
    if not np.any(errors[live] > 0):
        return gains
    hi = gains + z * errors
    best_lo = float(np.max((gains - z * errors)[live]))
    cand = np.flatnonzero(live & (hi >= best_lo))
    sets, slot = rowset.distinct(cand)
    if len(sets) <= 1:
        return gains
    first_hi = np.full(len(sets), -np.inf)
    np.maximum.at(first_hi, slot, hi[cand])
    chosen = np.argsort(-first_hi, kind="stable")[:REFINE_MAX]
    p, _ = intersection_fractions(running, [sets[i] for i in chosen], seed=seed, separate=True)
    new = np.full(len(sets), np.nan)
    with np.errstate(divide="ignore"):
        new[chosen] = np.where(p > 0, 1.0 / np.where(p > 0, p, 1.0), 0.0)
    out = gains.copy()
    hit = ~np.isnan(new[slot])
    out[cand[hit]] = new[slot[hit]]
    return out
