"""Robustness: the large-k (Qhull) path agrees with the reference LP reduction, the LP-free
interior finder agrees with the LP on emptiness, near-degenerate float input is stable."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

from cfteach.geometry import Region
from cfteach.geometry._interior import MARGIN_EPS, _lp_direction, _wolfe, interior_direction
from cfteach.geometry._normalize import canonical_rows, unit_rows
from cfteach.geometry.sphere3 import SMALL_K


def lp_irredundant(rows: np.ndarray) -> set[tuple[int, ...]]:
    """Reference-spec 5.2 step 4 on already canonical rows."""
    kept = [tuple(int(x) for x in r) for r in rows]
    i = 0
    while i < len(kept):
        others = np.array([r for j, r in enumerate(kept) if j != i], dtype=float)
        res = linprog(np.array(kept[i], dtype=float), A_ub=-others, b_ub=np.zeros(len(others)),
                      bounds=[(-1, 1)] * 3, method="highs")
        if res.fun >= -1e-9:
            kept.pop(i)
        else:
            i += 1
    return set(kept)


@pytest.mark.parametrize("seed", range(4))
def test_large_integer_sets_match_lp_reduction(seed: int) -> None:
    rng = np.random.default_rng(seed)
    w = rng.standard_normal(3)
    base = rng.integers(-9, 10, size=(150, 3))
    s = np.sign(base @ w).astype(np.int64)
    s[s == 0] = 1
    rows, _ = canonical_rows(base * s[:, None])
    assert len(rows) > SMALL_K  # exercises the Qhull path
    got = {tuple(x) for x in Region(rows).reduced().tolist()}
    assert got == lp_irredundant(rows)


def test_large_set_with_many_collinear_rows() -> None:
    # rows on the octant's three boundary planes, many of them redundant (collinear in
    # the gnomonic projection): the region is the octant
    rows = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    rows += [[a, b, 0] for a in range(1, 8) for b in range(1, 8)]
    rows += [[0, a, b] for a in range(1, 5) for b in range(1, 5)]
    r = Region(np.array(rows))
    assert {tuple(x) for x in r.reduced().tolist()} == {(1, 0, 0), (0, 1, 0), (0, 0, 1)}
    assert r.area() == pytest.approx(np.pi / 2, abs=1e-12)


def test_interior_finder_agrees_with_lp_on_emptiness() -> None:
    rng = np.random.default_rng(7)
    n_empty = 0
    for _ in range(150):
        k = int(rng.integers(2, 12))
        rows, _ = canonical_rows(rng.integers(-3, 4, size=(k, 3)))
        if len(rows) == 0:
            continue
        unit = unit_rows(rows)
        u = interior_direction(rows, unit, True)
        lp = _lp_direction(unit)
        assert (u is None) == (lp is None)
        if u is not None:
            assert np.min(unit @ u) > MARGIN_EPS
        else:
            n_empty += 1
        assert Region(rows).is_empty() == (lp is None)
    assert 15 < n_empty < 140  # both outcomes were exercised


def test_wolfe_finds_interior_of_thin_regions() -> None:
    # a lune of width 1e-6 rad tilted away from the mean of its normals
    rng = np.random.default_rng(8)
    hits = 0
    for _ in range(50):
        q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        t = 1e-6
        n = np.array([[1.0, 0, 0], [-np.cos(t), np.sin(t), 0], [0.3, 0.2, 1.0]]) @ q.T
        x = _wolfe(unit_rows(n))
        if x is not None:
            hits += 1
            assert np.min(unit_rows(n) @ x) > MARGIN_EPS
        assert not Region(n).is_empty()
    assert hits == 50


def test_near_degenerate_float_input_is_stable() -> None:
    rng = np.random.default_rng(9)
    exact = Region(np.array([[1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 2, 0]]))
    for _ in range(50):
        noisy = exact.rows.astype(float) + rng.normal(scale=1e-13, size=(5, 3))
        assert Region(noisy).area() == pytest.approx(exact.area(), abs=1e-9)


def test_intersection_reuses_interior_hint() -> None:
    a = Region([[1, 1, 0], [0, -1, -4], [-1, 0, 2]])
    b = Region([[0, 0, -1]])
    a.area(), b.area()
    both = a & b
    u = both.interior_point()
    assert u is not None and both.contains(u)
    assert both.area() == pytest.approx(Region(np.vstack([a.rows, b.rows])).area())


@pytest.mark.parametrize("seed", range(3))
def test_large_sets_of_big_integers_match_exact_determinant_hull(seed: int) -> None:
    from cfteach.geometry.sphere3 import _solve_small

    rng = np.random.default_rng(100 + seed)
    w = rng.standard_normal(3)
    base = rng.integers(-3000, 3001, size=(120, 3))
    # add near-collinear rows: sums of two existing rows lie on segments of the projection
    base = np.vstack([base, base[:30] + base[30:60]])
    s = np.sign(base @ w).astype(np.int64)
    s[s == 0] = 1
    rows, _ = canonical_rows(base * s[:, None])
    assert len(rows) > SMALL_K
    got = Region(rows)
    exact = _solve_small(rows, True, unit_rows(rows), None)  # O(k^3) exact method
    assert {tuple(x) for x in got.reduced().tolist()} == {
        tuple(x) for x in rows[exact.order].tolist()
    }
    assert got.area() == pytest.approx(exact.area, rel=1e-12, abs=1e-15)


def test_exact_hull_check_recovers_missed_and_flat_vertices() -> None:
    from cfteach.geometry.sphere3 import _exact_hull_check

    # square pyramid region: normals (+-1, 0, 1), (0, +-1, 1); plus the redundant (1, 0, 2)
    rows, _ = canonical_rows(np.array([[1, 0, 1], [-1, 0, 1], [0, 1, 1], [0, -1, 1],
                                       [1, 0, 2], [1, 1, 2]]))
    unit = unit_rows(rows)
    u = np.array([0.0, 0.0, 1.0])
    truth = {(1, 0, 1), (-1, 0, 1), (0, 1, 1), (0, -1, 1)}
    idx = {tuple(r): i for i, r in enumerate(rows.tolist())}
    # an "answer" that misses (0, -1, 1) and includes the flat (1, 1, 2)
    bad = np.array([idx[(1, 0, 1)], idx[(1, 1, 2)], idx[(0, 1, 1)], idx[(-1, 0, 1)]])
    fixed = _exact_hull_check(rows, unit, u, bad)
    assert {tuple(x) for x in rows[fixed].tolist()} == truth
    # a complete answer with a collinear extra vertex loses the extra
    flat = np.array([idx[(1, 0, 1)], idx[(1, 1, 2)], idx[(0, 1, 1)], idx[(-1, 0, 1)],
                     idx[(0, -1, 1)]])
    assert {tuple(x) for x in rows[_exact_hull_check(rows, unit, u, flat)].tolist()} == truth
