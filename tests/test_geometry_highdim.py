"""Regions with more than 3 features: exact special cases, estimates within their stated
error of an independent Monte Carlo, LP reduction, hit-and-run sampling."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from cfteach.geometry import Region, infeasible_rows, sphere_area


def mc_fraction(normals: np.ndarray, n: int, seed: int) -> tuple[float, float]:
    rng = np.random.default_rng(seed)
    z = rng.standard_normal((n, normals.shape[1]))
    p = float(np.mean(np.all(z @ normals.T >= 0, axis=1)))
    return p, float(np.sqrt(p * (1 - p) / n))


@pytest.mark.parametrize("dim", [4, 5, 6])
def test_orthant_hemisphere_lune_exact(dim: int) -> None:
    total = sphere_area(dim)
    assert Region(np.eye(dim, dtype=int)).area() == pytest.approx(total / 2**dim, rel=1e-6)
    e = np.eye(dim)
    val, se = Region(e[:1]).area_estimate()
    assert (val, se) == (pytest.approx(total / 2), 0.0)
    theta = 0.7
    lune = np.stack([e[0], np.cos(theta) * e[0] + np.sin(theta) * e[1]])
    val, se = Region(lune).area_estimate()
    assert val == pytest.approx(total * (np.pi - theta) / (2 * np.pi)) and se == 0.0
    assert Region.full(dim).fraction() == pytest.approx(1.0)


def test_three_rows_in_five_dims_exact_vs_monte_carlo() -> None:
    rng = np.random.default_rng(0)
    n = rng.standard_normal((3, 5))
    val, se = Region(n).area_estimate()
    assert se == 0.0
    p, p_se = mc_fraction(n, 1_000_000, 1)
    assert abs(val / sphere_area(5) - p) < 5 * p_se


@pytest.mark.parametrize("seed", [0, 1])
def test_simplicial_cone_vs_monte_carlo(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = rng.standard_normal((4, 4)) + np.array([1.0, 0.5, 0.0, 0.0])
    r = Region(n)
    assert len(r.reduced()) == 4
    val, se = r.area_estimate()
    p, p_se = mc_fraction(n, 1_000_000, seed + 10)
    total = sphere_area(4)
    assert abs(val / total - p) < 5 * np.hypot(p_se, se / total)


@pytest.mark.slow
def test_general_cone_importance_sampling_vs_monte_carlo() -> None:
    rng = np.random.default_rng(2)
    n = rng.standard_normal((12, 4)) + 2.0 * np.array([1.0, 0.0, 0.0, 0.0])
    r = Region(n)
    assert len(r.reduced()) > 4
    val, se = r.area_estimate()
    assert se > 0
    p, p_se = mc_fraction(n, 1_000_000, 3)
    total = sphere_area(4)
    assert abs(val / total - p) < 5 * np.hypot(p_se, se / total)
    # deterministic given the seed
    assert Region(n).area_estimate() == (val, se)


def test_reduction_in_four_dims_keeps_the_region() -> None:
    rng = np.random.default_rng(4)
    w = rng.standard_normal(4)
    base = rng.integers(-3, 4, size=(14, 4))
    s = np.sign(base @ w).astype(np.int64)
    s[s == 0] = 1
    rows = np.vstack([base * s[:, None], [[0, 0, 0, 0]], 2 * base[:2] * s[:2, None]])
    r = Region(rows)
    red = r.reduced()
    assert red.dtype == np.int64 and len(red) < len(rows)
    pts = rng.standard_normal((50_000, 4))
    margin = np.min(np.abs(pts @ rows.T), axis=1)
    clear = margin > 1e-9
    assert np.array_equal(r.contains(pts[clear]), Region(red).contains(pts[clear]))
    # every kept row is needed: dropping it enlarges the region (a witness point exists)
    for i in range(len(red)):
        others = Region(np.delete(red, i, axis=0))
        x = others.sample(300, np.random.default_rng(i))
        assert np.any(x @ red[i] < -1e-6)


def test_empty_in_four_dims() -> None:
    r = Region([[1, 0, 0, 0], [-1, 0, 0, 0], [0, 1, 0, 0]])
    assert r.is_empty() and r.area() == 0.0
    assert np.array_equal(r.reduced(), infeasible_rows(4))


def test_hit_and_run_matches_rejection_sampling() -> None:
    n = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0.2, 0.3, -0.1, 1.0]])
    r = Region(n)
    rng = np.random.default_rng(5)
    h = r.sample(2000, rng)
    assert h.shape == (2000, 4)
    assert np.all(r.contains(h, tol=1e-9))
    z = rng.standard_normal((200_000, 4))
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    rej = z[r.contains(z)]
    for axis in range(4):
        assert stats.ks_2samp(h[:, axis], rej[:, axis]).pvalue > 1e-3
    assert np.array_equal(h, r.sample(2000, np.random.default_rng(5)))


def _lp_reduce(unit: np.ndarray) -> list[int]:
    """The reference's filter, one LP per row over the current kept set (independent code)."""
    from scipy.optimize import linprog

    kept = list(range(len(unit)))
    i = 0
    while i < len(kept):
        others = unit[[j for j in kept if j != kept[i]]]
        res = linprog(unit[kept[i]], A_ub=-others, b_ub=np.zeros(len(others)),
                      bounds=[(-1.0, 1.0)] * unit.shape[1], method="highs")
        if res.status == 0 and res.fun >= -1e-9:
            kept.pop(i)
        else:
            i += 1
    return kept


@pytest.mark.parametrize("dim", [4, 5, 6])
def test_least_squares_redundancy_test_matches_one_lp_per_row(dim: int) -> None:
    """The NNLS (Farkas) pre-decision keeps exactly the rows the LP-per-row filter keeps,
    on random integer cones with many redundant, parallel and sum rows, and on the same
    rows jittered to floats."""
    from cfteach.geometry._highdim import _lp_filter

    rng = np.random.default_rng(dim)
    for _ in range(40):
        w = rng.standard_normal(dim)
        base = rng.integers(-3, 4, size=(int(rng.integers(3, 14)), dim))
        s = np.sign(base @ w).astype(np.int64)
        s[s == 0] = 1
        base = base * s[:, None]
        combos = base[rng.integers(0, len(base), 4)] + base[rng.integers(0, len(base), 4)]
        rows = np.vstack([base, combos])
        for r in (Region(rows), Region(rows + 1e-3 * rng.standard_normal(rows.shape))):
            unit = r._units()
            assert _lp_filter(unit, np.arange(len(unit))).tolist() == _lp_reduce(unit)


def test_integer_cones_need_no_linear_program(monkeypatch: pytest.MonkeyPatch) -> None:
    """Integer rows are never in the band where least squares and the LP could disagree,
    so reducing them solves no LP at all (the LP-per-row filter solved one per row)."""
    from cfteach.geometry import _highdim, clear_cache

    calls = []
    real = _highdim.linprog
    monkeypatch.setattr(_highdim, "linprog", lambda *a, **k: calls.append(1) or real(*a, **k))
    clear_cache()
    rng = np.random.default_rng(7)
    w = rng.standard_normal(5)
    base = rng.integers(-3, 4, size=(12, 5))
    s = np.sign(base @ w).astype(np.int64)
    s[s == 0] = 1
    red = Region(base * s[:, None]).reduced()
    assert 0 < len(red) < 12 and calls == []


@pytest.mark.parametrize("k", [50, 1000])
def test_thin_wedge_with_a_free_axis_is_measured(k: int) -> None:
    """A 1/k x 1/k rad wedge times a free fourth axis: not simplicial, so sampled. The
    Gaussian shifted towards an interior direction measured it as 0 +- 0 (k = 1000) or
    4 times too small; the truth is the 3-feature area (exact) scaled to S^3."""
    rows = np.array([[1, 0, 0, 0], [-k, 0, 1, 0], [0, 1, 0, 0], [0, -k, 1, 0]])
    want = Region(rows[:, :3]).fraction() * sphere_area(4)
    val, se = Region(rows).area_estimate()
    assert 0 < se < 0.05 * want and abs(val - want) < 5 * se
