"""Exact geometry of ``{w in S^2 : N w >= 0}``.

With a direction ``u`` strictly inside the region, the dual cone ``cone(n_i)`` is pointed
and its cross-section at ``x . u = 1`` is the convex hull of the gnomonic projections
``n_i / (n_i . u)``. Its vertices are the irredundant constraints, in cyclic order, and the
orientation of three projected points is the sign of ``det(n_i, n_j, n_l)`` - so for small
integer inputs the hull is computed with exact integer determinants. The area then follows
from Gauss-Bonnet: ``A = 2 pi - sum_j angle(n_j, n_{j+1})`` (the perimeter of the polar
polygon), which gives 2 pi for one constraint and ``2 pi - 2 theta`` for a lune.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ._interior import MARGIN_EPS, interior_direction
from ._normalize import INT_EXACT_LIMIT, unit_rows

#: Up to this many rows the hull is found with the vectorised O(k^3) determinant test
#: (exact for integers); above it, with Qhull on the gnomonic projection.
SMALL_K = 40
_FLOAT_TOL = 1e-12


@dataclass(frozen=True)
class Solved3:
    """Everything derived from one canonical row set (cached by content)."""

    empty: bool
    order: np.ndarray  # indices of the irredundant rows, counter-clockwise around interior
    interior: np.ndarray | None  # unit vector strictly inside, None if empty
    area: float


def solve3(rows: np.ndarray, integral: bool, hint: list[np.ndarray] | None = None) -> Solved3:
    """Irredundant rows (cyclic order), interior direction and exact area of a region."""
    k = len(rows)
    if k == 0:
        return Solved3(False, np.zeros(0, dtype=np.intp), np.array([0.0, 0.0, 1.0]), 4 * np.pi)
    unit = unit_rows(rows)
    exact = integral and int(np.abs(rows).max()) <= INT_EXACT_LIMIT
    if k == 1:
        return Solved3(False, np.zeros(1, dtype=np.intp), unit[0].copy(), 2 * np.pi)
    if k <= SMALL_K:
        return _solve_small(rows if exact else unit, exact, unit, hint)
    u = interior_direction(rows, unit, exact, hint)
    if u is None:
        return _EMPTY
    order = _order_hull(unit, u, rows if exact else None)
    order = _canonical_start(rows, order)
    return Solved3(False, order, u, polygon_area(unit[order]))


_EMPTY = Solved3(True, np.zeros(0, dtype=np.intp), None, 0.0)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (np.cross without its axis-juggling overhead)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _solve_small(
    p: np.ndarray, exact: bool, unit: np.ndarray, hint: list[np.ndarray] | None
) -> Solved3:
    """Small row sets: one vectorised determinant tensor does emptiness, interior, hull.

    ``d[i, j, l] = det(n_i, n_j, n_l) = n_l . (n_i x n_j)``. A pair with ``d[i, j, :] >= 0``
    is a corner ``n_i x n_j`` of the region. A full-dimensional region cut by two or more
    non-parallel constraints always has such a corner (a vertex, or the axis of a lune),
    so none at all proves emptiness (exactly, for integer rows).
    """
    pf = p.astype(np.float64) if exact else p  # small ints: float64 products are exact
    cr = cross(pf[:, None, :], pf[None, :, :])  # [k, k, 3]
    d = cr @ pf.T
    tol = 0.0 if exact else _FLOAT_TOL
    cand = (d >= -tol).all(axis=2)
    cand &= (np.abs(cr) > tol).any(axis=2) if tol else cr.any(axis=2)  # also drops i == j
    if not cand.any():
        return _EMPTY
    u = None
    if hint:
        for h in hint:
            if np.min(unit @ h) > MARGIN_EPS:
                u = h / np.linalg.norm(h)
                break
    if u is None:
        for cand_u in _interior_candidates(pf, cr, cand, tol):
            norm = float(np.sqrt(cand_u @ cand_u))
            if norm == 0.0:
                continue
            if exact:
                if np.all(pf @ cand_u > 0):  # an exact certificate
                    u = cand_u / norm
                    break
            elif np.min(unit @ cand_u) > MARGIN_EPS * norm:
                u = cand_u / norm
                break
    if u is None:
        if exact:  # a full-dimensional region always passes one of the candidates
            return _EMPTY
        u = interior_direction(p, unit, False, None)
        if u is None:
            return _EMPTY
    order = _order_from_pairs(p, exact, cand, d, unit, u)
    order = _canonical_start(p, order)
    return Solved3(False, order, u, polygon_area(unit[order]))


def _interior_candidates(
    pf: np.ndarray, cr: np.ndarray, cand: np.ndarray, tol: float
) -> Iterator[np.ndarray]:
    """Directions that are strictly inside whenever the region has an interior.

    The sum of the rows; the sum of the corners (for a pointed cone, a positive
    combination of all its extreme rays is interior); and, for a lune (corners only on
    its axis ``a``), the sum of its two boundary directions ``+-(a x n_i)``.
    """
    yield pf.sum(axis=0)
    yield cr[cand].sum(axis=0)
    i, j = np.argwhere(cand)[0]
    e = cross(cr[i, j][None, :], pf)  # directions in the lune's walls
    if tol > 0:  # float rows: compare unit directions against the tolerance
        norm = np.sqrt((e * e).sum(axis=1, keepdims=True))
        e = np.divide(e, norm, out=np.zeros_like(e), where=norm > 0)
    de = e @ pf.T
    pos = (de >= -tol).all(axis=1)
    neg = (de <= tol).all(axis=1)
    yield e[pos].sum(axis=0) - e[neg].sum(axis=0)


def _order_from_pairs(
    p: np.ndarray, exact: bool, cand: np.ndarray, d: np.ndarray, unit: np.ndarray, u: np.ndarray
) -> np.ndarray:
    """Hull edges among corner pairs, then the vertices in cyclic order.

    Directed pair (i, j) is a hull edge iff every l has det(n_i, n_j, n_l) > 0, or = 0 and
    n_l lies in cone(n_i, n_j); Binet-Cauchy on the Gram matrix tells which.
    """
    tol = 0 if exact else _FLOAT_TOL
    ii, jj = np.nonzero(cand)
    dd = d[ii, jj]  # [c, k]
    zero = np.abs(dd) <= tol
    if zero.sum() > 2 * len(ii):  # some pair has collinear extras: check betweenness
        g = p @ p.T
        gd = np.diag(g)
        e1 = gd[ii, None] * g[jj, :] - g[ii, jj][:, None] * g[ii, :]
        e2 = g[ii, :] * gd[jj, None] - g[jj, :] * g[ii, jj][:, None]
        good = np.all(~zero | ((e1 >= -tol) & (e2 >= -tol)), axis=1)
        ii, jj = ii[good], jj[good]
    verts = np.asarray(sorted(set(ii.tolist())), dtype=np.intp)
    if len(verts) <= 2:
        return verts.astype(np.intp)
    if len(ii) == len(verts):
        succ = dict(zip(ii.tolist(), jj.tolist(), strict=True))
        order = [int(verts[0])]
        for _ in range(len(verts)):
            nxt = succ.get(order[-1])
            if nxt is None or nxt == order[0]:
                break
            order.append(nxt)
        if len(order) == len(verts) and succ.get(order[-1]) == order[0]:
            return np.asarray(order, dtype=np.intp)
    return verts[_angular_order(unit[verts], u)].astype(np.intp)


#: Below this area (sr) the Gauss-Bonnet sum ``2 pi - sum(angles)`` has lost digits to
#: cancellation (absolute error ~1e-15); the area is then summed over fan triangles.
SMALL_AREA = 1e-4


def polygon_area(unit_ordered: np.ndarray) -> float:
    """Area from the cyclically ordered irredundant unit normals.

    Gauss-Bonnet: ``2 pi - sum_j angle(n_j, n_{j+1})``; a lune is ``2 (pi - theta)``
    computed as twice the angle between ``n_1`` and ``-n_2`` (no cancellation), and small
    polygons are re-measured as a fan of triangles (``fan_area``) to keep relative accuracy.
    """
    m = len(unit_ordered)
    if m == 0:
        return 4 * np.pi
    if m == 1:
        return 2 * np.pi
    if m == 2:
        return float(2 * _pair_angles(unit_ordered[0], -unit_ordered[1]))
    nxt = np.arange(1, m + 1)
    nxt[-1] = 0
    ang = _pair_angles(unit_ordered, unit_ordered[nxt])
    area = 2 * np.pi - math.fsum(ang.tolist())
    if area < SMALL_AREA:
        area = fan_area(unit_ordered)
    return max(area, 0.0)


def fan_area(unit_ordered: np.ndarray) -> float:
    """Sum of the fan triangles (centre, v_j, v_{j+1}) with a cancellation-free
    Van Oosterom-Strackee formula; accurate in relative terms for tiny polygons."""
    v = polygon_vertices(unit_ordered)
    c = v.sum(axis=0)
    c /= np.sqrt(c @ c)
    w = np.roll(v, -1, axis=0)
    return math.fsum(triangle_area(np.broadcast_to(c, v.shape), v, w).tolist())


def _pair_angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles between unit vectors along the last axis; elementwise arithmetic only, so a
    batched call gives bit-identical values to a single one."""
    cr = cross(a, b)
    sin = np.sqrt(cr[..., 0] ** 2 + cr[..., 1] ** 2 + cr[..., 2] ** 2)
    cos = a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]
    return np.arctan2(sin, cos)


def _canonical_start(rows: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Rotate the cycle so it starts at the smallest row (canonical rows are sorted)."""
    if len(order) <= 1 or order[0] == order.min():
        return order
    first = int(np.argmin(order))
    return np.concatenate([order[first:], order[:first]])


def _plane_basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal e1, e2 with e1 x e2 = u."""
    a = np.zeros(3)
    a[int(np.argmin(np.abs(u)))] = 1.0
    e1 = cross(a, u)
    e1 /= np.sqrt(e1 @ e1)
    return e1, cross(u, e1)


def _project(unit: np.ndarray, u: np.ndarray) -> np.ndarray:
    e1, e2 = _plane_basis(u)
    p = unit / (unit @ u)[:, None]
    return np.stack([p @ e1, p @ e2], axis=1)


def _angular_order(unit: np.ndarray, u: np.ndarray) -> np.ndarray:
    xy = _project(unit, u)
    c = xy.mean(axis=0)
    return np.argsort(np.arctan2(xy[:, 1] - c[1], xy[:, 0] - c[0]), kind="stable")


def _order_hull(unit: np.ndarray, u: np.ndarray, exact_rows: np.ndarray | None) -> np.ndarray:
    """Qhull on the gnomonic projection (counter-clockwise for 2-D input)."""
    xy = _project(unit, u)
    centred = xy - xy.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[0] == 0.0:
        return np.zeros(1, dtype=np.intp)
    if sv[1] <= 1e-12 * sv[0]:
        return _line_extremes(centred)
    try:
        order = ConvexHull(xy).vertices.astype(np.intp)
    except QhullError:
        return _line_extremes(centred)
    if exact_rows is not None:
        order = _exact_hull_check(exact_rows, unit, u, order)
    return order


def _exact_hull_check(
    rows: np.ndarray, unit: np.ndarray, u: np.ndarray, order: np.ndarray
) -> np.ndarray:
    """Make Qhull's answer exact for integer rows.

    Every true vertex missed by Qhull lies strictly outside one of its edges (exact
    determinant < 0); the true hull is then that of Qhull's vertices plus those points,
    solved with the exact determinant test. Collinear vertices are dropped.
    """
    pf = rows.astype(np.float64)
    a, b = pf[order], pf[np.roll(order, -1)]
    outside = np.any(cross(a, b) @ pf.T < 0, axis=0)
    if outside.any():
        sub = np.union1d(order, np.flatnonzero(outside))
        solved = _solve_small(rows[sub], True, unit[sub], [u])
        if not solved.empty:
            return sub[solved.order]
    return _drop_flat_vertices(rows, order)


def _line_extremes(centred: np.ndarray) -> np.ndarray:
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    t = centred @ vt[0]
    return np.array([int(np.argmin(t)), int(np.argmax(t))], dtype=np.intp)


def _drop_flat_vertices(rows: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Remove hull vertices whose exact turn det(prev, cur, next) is not positive."""
    while len(order) > 2:
        p = rows[order].astype(np.float64)  # small ints: exact
        turn = np.einsum("ij,ij->i", cross(np.roll(p, 1, axis=0), p), np.roll(p, -1, axis=0))
        flat = turn <= 0
        if not flat.any():
            break
        order = np.delete(order, int(np.argmax(flat)))
    return order


def polygon_vertices(unit_ordered: np.ndarray) -> np.ndarray:
    """Corners of the region: ``normalise(n_j x n_{j+1})``; a lune gives its two poles."""
    m = len(unit_ordered)
    if m < 2:
        return np.zeros((0, 3))
    if m == 2:
        v = np.cross(unit_ordered[0], unit_ordered[1])
        v /= np.linalg.norm(v)
        return np.stack([v, -v])
    v = np.cross(unit_ordered, np.roll(unit_ordered, -1, axis=0))
    return v / np.linalg.norm(v, axis=1)[:, None]


def triangle_area(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Solid angle of spherical triangles (Van Oosterom & Strackee 1983), vectorised.

    The triple product is taken as ``a . ((b - a) x (c - a))``: the differences of nearly
    equal unit vectors are exact, so tiny triangles keep their relative accuracy.
    """
    num = np.abs(np.einsum("...i,...i->...", a, cross(b - a, c - a)))
    den = 1.0 + np.einsum("...i,...i->...", a, b) + np.einsum("...i,...i->...", b, c)
    den = den + np.einsum("...i,...i->...", c, a)
    return 2.0 * np.arctan2(num, den)


def solve3_batch(sets: list[np.ndarray]) -> list[Solved3 | None]:
    """``_solve_small`` for many canonical integer row sets of one size k at once.

    All sets must share the row count ``k`` (2 <= k <= SMALL_K) and have entries of at
    most ``INT_EXACT_LIMIT``. Sets the vectorised path cannot settle (no cheap interior
    direction, inconsistent successor cycle) come back as None for the caller to solve one
    at a time; every other answer equals ``solve3``'s.
    """
    out: list[Solved3 | None] = [None] * len(sets)
    if not sets:
        return out
    k = sets[0].shape[0]
    chunk = max(1, 1_000_000 // (k**3))
    for start in range(0, len(sets), chunk):
        part = sets[start : start + chunk]
        for off, res in enumerate(_batch_chunk(np.stack(part))):
            out[start + off] = res
    return out


def _batch_chunk(pi: np.ndarray) -> list[Solved3 | None]:
    b, k, _ = pi.shape
    p = pi.astype(np.float64)  # exact for entries <= INT_EXACT_LIMIT
    cr = cross(p[:, :, None, :], p[:, None, :, :])  # [b, k, k, 3]
    d = cr @ p.transpose(0, 2, 1)[:, None, :, :]  # [b, k, k, k]
    eye = np.eye(k, dtype=bool)
    cand = (d >= 0).all(axis=3) & ~eye & (cr != 0).any(axis=3)
    has = cand.any(axis=(1, 2))
    # the candidates of _interior_candidates, checked exactly
    s1 = p.sum(axis=1)
    ok1 = (np.einsum("bkc,bc->bk", p, s1) > 0).all(axis=1)
    s2 = (cr * cand[..., None]).sum(axis=(1, 2))
    ok2 = (np.einsum("bkc,bc->bk", p, s2) > 0).all(axis=1)
    pair0 = np.argmax(cand.reshape(b, -1), axis=1)
    axis = cr.reshape(b, -1, 3)[np.arange(b), pair0]  # a corner: the axis if a lune
    e = cross(axis[:, None, :], p)  # [b, k, 3]
    de = np.einsum("bmc,blc->bml", e, p)
    pos = (de >= 0).all(axis=2)
    neg = (de <= 0).all(axis=2)
    s3 = (e * pos[..., None]).sum(axis=1) - (e * neg[..., None]).sum(axis=1)
    ok3 = (np.einsum("bkc,bc->bk", p, s3) > 0).all(axis=1)
    u = np.where(ok1[:, None], s1, np.where(ok2[:, None], s2, s3))
    u /= np.maximum(np.sqrt((u * u).sum(axis=1, keepdims=True)), 1e-300)
    unit = p / np.sqrt(p[..., 0] ** 2 + p[..., 1] ** 2 + p[..., 2] ** 2)[..., None]
    nonempty = has & (ok1 | ok2 | ok3)
    good = nonempty.copy()
    # hull edges: Binet-Cauchy betweenness, only on candidate pairs with extra zero dets
    bi, ii, jj = np.nonzero(cand)
    dd = d[bi, ii, jj]  # [P, k]
    zero = dd == 0
    valid = cand.copy()
    extra = zero.sum(axis=1) > 2
    if extra.any():
        bx, ix, jx, zx = bi[extra], ii[extra], jj[extra], zero[extra]
        g = np.einsum("bic,bjc->bij", pi, pi)  # int64, exact
        gi, gj = g[bx, ix], g[bx, jx]  # [Q, k]: G[i, l], G[j, l]
        gii, gjj, gij = gi[np.arange(len(ix)), ix], gj[np.arange(len(jx)), jx], gi[
            np.arange(len(ix)), jx]
        e1 = gii[:, None] * gj - gij[:, None] * gi
        e2 = gi * gjj[:, None] - gj * gij[:, None]
        ok = (~zx | ((e1 >= 0) & (e2 >= 0))).all(axis=1)
        valid[bx[~ok], ix[~ok], jx[~ok]] = False
    is_vert = valid.any(axis=2)
    nverts = is_vert.sum(axis=1)
    outdeg = valid.sum(axis=2)
    succ = np.argmax(valid, axis=2)
    first = np.argmax(is_vert, axis=1)
    rows_b = np.arange(b)
    order = np.zeros((b, k), dtype=np.intp)
    order[:, 0] = first
    for t in range(1, k):
        order[:, t] = succ[rows_b, order[:, t - 1]]
    pos = np.arange(k)[None, :]
    in_cycle = pos < nverts[:, None]
    # a proper cycle: each vertex has one successor, and the walk returns to the start
    # exactly after nverts steps, visiting distinct vertices
    back = succ[rows_b, order[rows_b, np.maximum(nverts - 1, 0)]] == first
    walk = np.sort(np.where(in_cycle, order, k + pos), axis=1)
    distinct = (np.diff(walk, axis=1) != 0).all(axis=1)
    proper = (
        ((outdeg == 1) | ~is_vert).all(axis=1) & back & distinct & (nverts >= 3)
    ) | (nverts == 2)
    good &= proper
    # areas: 2 pi - sum of angles between cyclically consecutive irredundant normals
    nxt_pos = np.where(pos + 1 < nverts[:, None], pos + 1, 0)
    two = nverts == 2
    order_fix = order.copy()
    if two.any():
        vv = np.argsort(~is_vert[two], axis=1, kind="stable")[:, :2]
        order_fix[two, :2] = vv
    a = unit[rows_b[:, None], order_fix]
    nb = unit[rows_b[:, None], order_fix[rows_b[:, None], nxt_pos]]
    ang = _pair_angles(a, nb)
    res: list[Solved3 | None] = []
    for i in range(b):
        if not nonempty[i]:
            res.append(_EMPTY)
        elif good[i]:
            area = 2 * np.pi - math.fsum(ang[i, : nverts[i]].tolist())
            if nverts[i] == 2 or area < SMALL_AREA:  # same branches as polygon_area
                area = polygon_area(unit[i, order_fix[i, : nverts[i]]])
            res.append(Solved3(False, order_fix[i, : nverts[i]].copy(), u[i].copy(), area))
        else:
            res.append(None)
    return res
