"""Region: exact areas against closed forms and independent formulas, reduction semantics,
degenerate inputs. Every expected value here is computed without cfteach.geometry."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import linprog

from cfteach.geometry import (
    Region,
    clear_cache,
    infeasible_rows,
    overlap,
    reduce_many,
    sphere_area,
)

# ----------------------------------------------------------------- independent helpers


def lhuilier(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """Spherical excess of triangle abc from its side lengths (L'Huilier's theorem)."""

    def ang(x: np.ndarray, y: np.ndarray) -> float:
        return float(np.arccos(np.clip(x @ y, -1.0, 1.0)))

    sa, sb, sc = ang(b, c), ang(a, c), ang(a, b)
    s = (sa + sb + sc) / 2
    t = np.tan(s / 2) * np.tan((s - sa) / 2) * np.tan((s - sb) / 2) * np.tan((s - sc) / 2)
    return float(4 * np.arctan(np.sqrt(max(t, 0.0))))


def random_unit(rng: np.random.Generator, n: int = 1) -> np.ndarray:
    x = rng.standard_normal((n, 3))
    return x / np.linalg.norm(x, axis=1)[:, None]


def brute_vertices(normals: np.ndarray) -> np.ndarray:
    """Corners of a pointed region: every feasible +-(n_i x n_j), sorted around the centre."""
    n = normals / np.linalg.norm(normals, axis=1)[:, None]
    pts = []
    for i, j in itertools.combinations(range(len(n)), 2):
        v = np.cross(n[i], n[j])
        if np.linalg.norm(v) < 1e-12:
            continue
        v /= np.linalg.norm(v)
        for s in (v, -v):
            if np.all(n @ s >= -1e-9):
                pts.append(s)
    pts_a = np.array(pts)
    # merge duplicates
    uniq: list[np.ndarray] = []
    for p in pts_a:
        if not any(np.linalg.norm(p - q) < 1e-9 for q in uniq):
            uniq.append(p)
    pts_a = np.array(uniq)
    c = pts_a.mean(axis=0)
    c /= np.linalg.norm(c)
    e1 = np.cross(c, [1.0, 0.0, 0.0] if abs(c[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(c, e1)
    return pts_a[np.argsort(np.arctan2(pts_a @ e2, pts_a @ e1))]


def reference_reduce(rows: np.ndarray) -> set[tuple[int, ...]]:
    """The authors' LP redundancy method (docs/geometry.md, "More than 3 features"), one LP per
    constraint."""
    rows = np.array([r // np.gcd.reduce(np.abs(r)) for r in rows if np.any(r != 0)])
    kept = [tuple(int(x) for x in r) for r in np.unique(rows, axis=0)]
    i = 0
    while i < len(kept):
        others = np.array([r for j, r in enumerate(kept) if j != i], dtype=float)
        c = np.array(kept[i], dtype=float)
        if len(others):
            res = linprog(c, A_ub=-others, b_ub=np.zeros(len(others)), bounds=[(-1, 1)] * 3,
                          method="highs")
        else:
            res = linprog(c, bounds=[(-1, 1)] * 3, method="highs")
        if res.fun >= -1e-9:
            kept.pop(i)
        else:
            i += 1
    return set(kept)


def feasible_int_set(rng: np.random.Generator, k: int, hi: int = 5) -> np.ndarray:
    """Random small-int constraints all satisfied by a random direction (non-empty)."""
    w = random_unit(rng)[0]
    base = rng.integers(-hi, hi + 1, size=(k, 3))
    s = np.sign(base @ w)
    s[s == 0] = 1
    return base * s.astype(np.int64)[:, None]


# ----------------------------------------------------------------- closed forms


def test_full_sphere_hemisphere_octant() -> None:
    assert Region.full(3).area() == pytest.approx(4 * np.pi, abs=1e-12)
    assert Region(np.zeros((0, 3))).area() == pytest.approx(4 * np.pi)
    assert Region([[0, 0, 1]]).area() == pytest.approx(2 * np.pi, abs=1e-12)
    assert Region([[0.3, -0.2, 0.9]]).area() == pytest.approx(2 * np.pi, abs=1e-12)
    octant = Region(np.eye(3, dtype=int))
    assert octant.area() == pytest.approx(np.pi / 2, abs=1e-12)
    assert octant.fraction() == pytest.approx(1 / 8, abs=1e-14)
    assert Region(-np.eye(3)).area() == pytest.approx(np.pi / 2, abs=1e-12)


@pytest.mark.parametrize("theta", [0.01, 0.5, 1.0, np.pi / 2, 2.5, np.pi - 1e-3])
def test_lune_area(theta: float) -> None:
    rng = np.random.default_rng(int(theta * 1000))
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    n1 = q @ np.array([1.0, 0.0, 0.0])
    n2 = q @ np.array([np.cos(theta), np.sin(theta), 0.0])
    r = Region(np.stack([n1, n2]))
    assert r.area() == pytest.approx(2 * np.pi - 2 * theta, abs=1e-10)
    assert len(r.reduced()) == 2


def test_random_triangles_match_lhuilier() -> None:
    rng = np.random.default_rng(0)
    for _ in range(300):
        a, b, c = random_unit(rng, 3)
        if np.linalg.det(np.stack([a, b, c])) < 0:
            b, c = c, b
        normals = np.stack([np.cross(a, b), np.cross(b, c), np.cross(c, a)])
        normals *= rng.uniform(0.1, 10.0, size=(3, 1))  # scale must not matter
        got = Region(normals).area()
        assert got == pytest.approx(lhuilier(a, b, c), rel=1e-9, abs=1e-12)


def test_tiny_triangle_area() -> None:
    a = np.array([0.0, 0.0, 1.0])
    b = np.array([1e-4, 0.0, 1.0])
    c = np.array([0.0, 1e-4, 1.0])
    a, b, c = (v / np.linalg.norm(v) for v in (a, b, c))
    normals = np.stack([np.cross(a, b), np.cross(b, c), np.cross(c, a)])
    # area ~ planar right triangle 0.5e-8
    assert Region(normals).area() == pytest.approx(0.5e-8, rel=1e-4)


def test_random_polygons_match_fan_of_lhuilier_triangles() -> None:
    rng = np.random.default_rng(1)
    for _ in range(100):
        k = int(rng.integers(3, 25))
        centre = random_unit(rng)[0]
        normals = random_unit(rng, k) + rng.uniform(1.05, 3.0) * centre
        r = Region(normals)
        v = brute_vertices(normals)
        c = v.mean(axis=0)
        c /= np.linalg.norm(c)
        expect = sum(lhuilier(c, v[i], v[(i + 1) % len(v)]) for i in range(len(v)))
        assert r.area() == pytest.approx(expect, rel=1e-8, abs=1e-12)
        assert len(r.reduced()) == len(v)


@pytest.mark.slow
def test_random_polygons_match_monte_carlo() -> None:
    rng = np.random.default_rng(2)
    m = 1_000_000
    pts = random_unit(rng, m)
    for _ in range(6):
        k = int(rng.integers(3, 12))
        centre = random_unit(rng)[0]
        normals = random_unit(rng, k) + rng.uniform(0.3, 1.5) * centre
        p = float(np.mean(np.all(pts @ normals.T >= 0, axis=1)))
        se = np.sqrt(p * (1 - p) / m) * 4 * np.pi
        assert abs(Region(normals).area() - 4 * np.pi * p) < 5 * se + 1e-12


def test_policy_level_bec_sets_are_irredundant() -> None:
    for rows in ([[1, 1, 0], [0, -1, -4], [-1, 0, 2]], [[1, -1, -2], [0, 1, -6], [-1, 0, 6]],
                 [[8, 1, -2], [0, -2, 1], [-6, 4, -1]]):
        r = Region(rows)
        assert not r.is_empty()
        assert {tuple(x) for x in r.reduced().tolist()} == {tuple(x) for x in rows}
        v = brute_vertices(np.array(rows, dtype=float))
        assert r.area() == pytest.approx(lhuilier(*v), rel=1e-10)


# ----------------------------------------------------------------- reduction


def test_reduction_semantics_primitive_dedup_zero() -> None:
    r = Region([[2, 2, 0], [1, 1, 0], [0, 0, 0], [3, 0, 0], [0, -4, 0], [0, 0, 5], [0, 0, 7]])
    red = r.reduced()
    assert red.dtype == np.int64
    # x >= 0 is implied by x + y >= 0 and -y >= 0
    assert {tuple(x) for x in red.tolist()} == {(1, 1, 0), (0, -1, 0), (0, 0, 1)}
    # whole-number floats count as integral
    red_f = Region(np.array([[2.0, 0.0, 0.0], [0.0, 3.0, 0.0]])).reduced()
    assert red_f.dtype == np.int64
    assert {tuple(x) for x in red_f.tolist()} == {(1, 0, 0), (0, 1, 0)}
    # other floats come back as unit vectors
    red_u = Region(np.array([[0.5, 0.5, 0.0], [0.0, 0.0, 2.5]])).reduced()
    assert red_u.dtype == np.float64
    assert np.allclose(np.linalg.norm(red_u, axis=1), 1.0)


def test_reduction_matches_reference_lp_method() -> None:
    rng = np.random.default_rng(3)
    for _ in range(60):
        rows = feasible_int_set(rng, int(rng.integers(2, 16)), hi=int(rng.integers(1, 7)))
        rows = np.vstack([rows, rows[: int(rng.integers(0, 4))] * 2])  # duplicates
        r = Region(rows)
        if r.is_empty():  # thin regions (measure zero) are not compared
            continue
        assert {tuple(x) for x in r.reduced().tolist()} == reference_reduce(rows)


def test_reduced_region_is_the_same_region() -> None:
    rng = np.random.default_rng(4)
    pts = random_unit(rng, 20_000)
    for _ in range(25):
        rows = feasible_int_set(rng, int(rng.integers(3, 30)))
        r = Region(rows)
        red = Region(r.reduced())
        # points clearly off every boundary must agree
        margin = np.min(np.abs(pts @ (rows / np.linalg.norm(rows, axis=1)[:, None]).T), axis=1)
        clear = margin > 1e-9
        assert np.array_equal(r.contains(pts[clear]), red.contains(pts[clear]))
        assert red.area() == pytest.approx(r.area(), abs=1e-12)
        assert np.array_equal(Region(red.reduced()).reduced(), red.reduced())  # idempotent


def test_reduced_order_is_counter_clockwise_around_interior() -> None:
    rng = np.random.default_rng(5)
    for _ in range(50):
        r = Region(feasible_int_set(rng, 12))
        red = r.reduced().astype(float)
        u = r.interior_point()
        assert u is not None and np.all(red @ u > 0)
        if len(red) >= 3:
            for j in range(len(red)):
                assert np.linalg.det(np.stack([red[j], red[(j + 1) % len(red)], u])) > 0
            first = red[0]
            assert all(tuple(first) <= tuple(x) for x in red)


def test_order_does_not_depend_on_input_order() -> None:
    rng = np.random.default_rng(6)
    rows = feasible_int_set(rng, 15)
    a = Region(rows).reduced()
    b = Region(rows[rng.permutation(len(rows))]).reduced()
    assert np.array_equal(a, b)


def test_float_duplicates_collapse() -> None:
    n = np.array([[0.3, 0.4, 0.5], [0.6, 0.8, 1.0], [0.3 + 1e-15, 0.4, 0.5]])
    assert len(Region(n).rows) == 1


# ----------------------------------------------------------------- degenerate & empty


@pytest.mark.parametrize(
    "rows",
    [
        [[1, 0, 0], [-1, 0, 0]],  # c and -c: a great circle
        [[1, 2, 3], [-2, -4, -6]],
        [[1, 0, 0], [0, 1, 0], [-1, -1, 0]],  # coplanar, spanning more than a half-plane
        [[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, -1, -1]],  # origin inside conv(normals)
        [[1, 0, 0], [0, 1, 0], [-1, 0, 1], [0, -1, -1]],  # a single ray / point
        [[0, 0, 1], [1, 0, -1], [-1, 0, -1]],  # only the great-circle point (0, +-1, 0)
    ],
)
def test_empty_regions(rows: list[list[int]]) -> None:
    r = Region(rows)
    assert r.is_empty()
    assert r.area() == 0.0
    assert r.interior_point() is None
    assert np.array_equal(r.reduced(), infeasible_rows(3))
    assert Region(r.reduced()).is_empty()
    with pytest.raises(ValueError, match="empty"):
        r.sample(3, np.random.default_rng(0))


def test_float_thin_region_is_empty_but_thin_nonzero_is_not() -> None:
    assert Region(np.array([[1.0, 0, 0], [-1.0, 1e-14, 0]])).is_empty()
    r = Region(np.array([[1.0, 0, 0], [-1.0, 1e-6, 0]]))
    assert not r.is_empty()
    assert r.area() == pytest.approx(2 * np.arctan(1e-6), rel=1e-6)  # lune 2pi - 2theta


def test_coplanar_normals_in_a_half_plane_make_a_lune() -> None:
    # x >= 0, y >= 0, x + y >= 0, y - x/2 >= 0: all normals in the xy plane
    r = Region([[1, 0, 0], [0, 1, 0], [1, 1, 0], [-1, 2, 0]])
    assert {tuple(x) for x in r.reduced().tolist()} == {(1, 0, 0), (-1, 2, 0)}
    theta = np.arccos(-1 / np.sqrt(5))
    assert r.area() == pytest.approx(2 * np.pi - 2 * theta, abs=1e-12)


def test_all_zero_rows_is_full_sphere() -> None:
    r = Region([[0, 0, 0], [0, 0, 0]])
    assert r.area() == pytest.approx(4 * np.pi)
    assert r.reduced().shape == (0, 3)
    assert not r.is_empty()


def test_bad_input_errors() -> None:
    with pytest.raises(ValueError, match="NaN"):
        Region([[np.nan, 0, 1]])
    with pytest.raises(ValueError, match="at least 3"):
        Region([[1, 0]])
    with pytest.raises(ValueError, match="shape"):
        Region(np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match="dimension"):
        Region([])
    with pytest.raises(ValueError, match="numeric"):
        Region([["a", "b", "c"]])
    with pytest.raises(ValueError, match="dimension"):
        Region(np.eye(3)) & Region(np.eye(4))
    with pytest.raises(ValueError, match="nonzero"):
        Region(np.eye(3)).contains([0, 0, 0])


# ----------------------------------------------------------------- algebra


def test_intersection_and_overlap() -> None:
    a = Region([[1, 0, 0], [0, 1, 0]])  # quarter sphere (lune of pi)
    b = Region([[0, 0, 1]])
    assert (a & b).area() == pytest.approx(np.pi / 2)
    assert overlap(a, b) == pytest.approx(np.pi / 2)
    rng = np.random.default_rng(7)
    for _ in range(30):
        x, y = Region(feasible_int_set(rng, 6)), Region(feasible_int_set(rng, 6))
        o = overlap(x, y)
        assert o <= min(x.area(), y.area()) + 1e-12
    # mixed float/int intersections fall back to unit floats
    m = Region([[1, 0, 0]]) & Region(np.array([[0.0, 0.5, 0.5]]))
    assert not m.integral and m.area() == pytest.approx(np.pi)


def test_contains() -> None:
    octant = Region(np.eye(3, dtype=int))
    assert octant.contains([1, 2, 3])
    assert not octant.contains([1, -2, 3])
    assert octant.contains([1, 0, 0])  # boundary counts
    got = octant.contains(np.array([[1, 1, 1], [-1, 1, 1]]))
    assert got.tolist() == [True, False]


def test_vertices() -> None:
    v = Region(np.eye(3, dtype=int)).vertices()
    assert {tuple(x) for x in np.round(v, 12).tolist()} == {(1, 0, 0), (0, 1, 0), (0, 0, 1)}
    # vertex j is where facets j and j+1 meet
    red = Region(np.eye(3, dtype=int)).reduced()
    for j in range(3):
        assert red[j] @ v[j] == pytest.approx(0) and red[(j + 1) % 3] @ v[j] == pytest.approx(0)
    poles = Region([[1, 0, 0], [0, 1, 0]]).vertices()
    assert np.allclose(np.abs(poles), [[0, 0, 1], [0, 0, 1]])


def test_reduce_many_matches_region() -> None:
    rng = np.random.default_rng(8)
    sets = [feasible_int_set(rng, int(rng.integers(3, 20))) for _ in range(50)]
    sets += sets[:10]
    clear_cache()
    red, areas = reduce_many(sets)
    clear_cache()
    for s, rr, a in zip(sets, red, areas, strict=True):
        assert np.array_equal(rr, Region(s).reduced())
        assert a == Region(s).area()


def test_sphere_area() -> None:
    assert sphere_area(3) == pytest.approx(4 * np.pi)
    assert sphere_area(4) == pytest.approx(2 * np.pi**2)


def test_reduce_many_special_sets() -> None:
    sets = [
        np.zeros((0, 3), dtype=int),
        np.array([[0, 0, 0]]),
        np.array([[1, 0, 0], [-1, 0, 0]]),
        np.array([[2, 4, 0], [1, 2, 0], [0, 0, 3]]),
        np.array([[0.5, 0.2, 0.1]]),
    ]
    red, areas = reduce_many(sets)
    assert red[0].shape == (0, 3) and areas[0] == pytest.approx(4 * np.pi)
    assert red[1].shape == (0, 3) and areas[1] == pytest.approx(4 * np.pi)
    assert np.array_equal(red[2], infeasible_rows(3)) and areas[2] == 0.0
    assert {tuple(x) for x in red[3].tolist()} == {(1, 2, 0), (0, 0, 1)}
    assert areas[3] == pytest.approx(np.pi)
    assert red[4].dtype == np.float64 and areas[4] == pytest.approx(2 * np.pi)
    with pytest.raises(ValueError, match="same number of columns"):
        reduce_many([np.eye(3), np.eye(4)])


def test_batched_solver_matches_single_solver() -> None:
    from cfteach.geometry._normalize import canonical_rows
    from cfteach.geometry.sphere3 import solve3, solve3_batch

    rng = np.random.default_rng(9)
    by_k: dict[int, list[np.ndarray]] = {}
    for _ in range(1500):
        k, hi = int(rng.integers(2, 25)), int(rng.integers(1, 6))
        base = rng.integers(-hi, hi + 1, size=(k, 3))
        if rng.random() < 0.7:  # mostly non-empty, like teaching constraint sets
            s = np.sign(base @ rng.standard_normal(3)).astype(np.int64)
            s[s == 0] = 1
            base = base * s[:, None]
        rows, _ = canonical_rows(base)
        if len(rows) >= 2:
            by_k.setdefault(len(rows), []).append(rows)
    n_batched = n_empty = 0
    for sets in by_k.values():
        for rows, got in zip(sets, solve3_batch(sets), strict=True):
            if got is None:
                continue
            n_batched += 1
            one = solve3(rows, True)
            assert got.empty == one.empty
            n_empty += got.empty
            assert np.array_equal(got.order, one.order)
            assert got.area == one.area
    assert n_batched > 1300 and n_empty > 50


def test_reduce_many_on_mixed_random_sets() -> None:
    rng = np.random.default_rng(10)
    sets = []
    for _ in range(300):
        k, hi = int(rng.integers(1, 30)), int(rng.integers(1, 4))
        sets.append(rng.integers(-hi, hi + 1, size=(k, 3)))
    clear_cache()
    red, areas = reduce_many(sets + sets[:50])
    clear_cache()  # compare with solutions computed one at a time
    for s, rr, a in zip(sets + sets[:50], red, areas, strict=True):
        r = Region(s)
        assert np.array_equal(rr, r.reduced())
        assert a == r.area()  # bit-identical to the one-at-a-time solution


@pytest.mark.parametrize("rad", [1e-4, 1e-6, 1e-8])
def test_tiny_regular_hexagon_area_keeps_relative_accuracy(rad: float) -> None:
    ang = np.arange(6) * np.pi / 3
    r = Region(np.stack([-np.cos(ang), -np.sin(ang), np.full(6, rad)], axis=1))
    # planar hexagon of inradius rad: 2 sqrt(3) rad^2, spherical correction O(rad^2)
    assert r.area() == pytest.approx(2 * np.sqrt(3) * rad**2, rel=1e-7)


@pytest.mark.parametrize("n", [10, 1000, 8000, 10**6])
def test_thin_integer_lunes_and_wedges_are_exact(n: int) -> None:
    lune = Region([[1, 0, 0], [-n, 1, 0]])
    assert not lune.is_empty()
    assert lune.area() == pytest.approx(2 * np.arctan2(1, n), rel=1e-12)
    wedge = Region([[1, 0, 0], [-n, 1, 0], [0, 0, 1]])
    assert wedge.area() == pytest.approx(np.arctan2(1, n), rel=1e-9)
    _, areas = reduce_many([np.array([[1, 0, 0], [-n, 1, 0]])])
    assert areas[0] == lune.area()


@pytest.mark.parametrize("t", [1e-6, 1e-9, 1e-11])
def test_thin_float_lune(t: float) -> None:
    r = Region(np.array([[1.0, 0, 0], [-np.cos(t), np.sin(t), 0]]))
    assert not r.is_empty()
    assert r.area() == pytest.approx(2 * t, rel=1e-6)


def test_regions_pickle_and_do_not_leak_state() -> None:
    import pickle

    r = Region([[1, 1, 0], [0, -1, -4], [-1, 0, 2]])
    area = r.area()
    q = pickle.loads(pickle.dumps(r))
    assert q.area() == area and np.array_equal(q.reduced(), r.reduced())
    red = r.reduced()
    red[0, 0] = 99  # callers get copies
    rows = r.rows
    rows[0, 0] = 99
    u = r.interior_point()
    assert u is not None
    u[0] = 5.0
    assert r.reduced()[0, 0] != 99 and r.rows[0, 0] != 99
    assert r.contains(r.interior_point())


def test_intersection_areas_match_single_regions() -> None:
    from cfteach.geometry import intersection_areas

    rng = np.random.default_rng(11)
    belief = Region([[0, 0, -1], [1, 1, 0]])
    row_sets = [rng.integers(-3, 4, size=(int(rng.integers(0, 6)), 3)) for _ in range(200)]
    clear_cache()
    got = intersection_areas(belief, row_sets)
    clear_cache()
    expect = [Region(np.vstack([belief.reduced(), r])).area() for r in row_sets]
    assert got.tolist() == expect
    assert np.all(got <= belief.area() + 1e-12)
    assert intersection_areas(belief, []).shape == (0,)
