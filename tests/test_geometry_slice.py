"""Beliefs on a known-weight slice (`cfteach.geometry.slice`), checked by brute force on grids
of the slice: the edge of the L1 ball (a length for 3 features with one known), the whole
ball (an area), and the Monte Carlo measure with its standard error beyond two free weights."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from cfteach.geometry.slice import KnownSlice, SliceRegion, uniform_slice

W3 = np.array([26.0, -3.0, -1.0]) / 30  # the 2021 taxi's weights (step known)


def _random_rows(w: np.ndarray, n: int, rng: np.random.Generator, lo: int = -12,
                 hi: int = 13) -> np.ndarray:
    """Integer rows that w satisfies (so the belief is never empty)."""
    rows = []
    while len(rows) < n:
        r = rng.integers(lo, hi, size=len(w))
        if np.any(r != 0) and r @ w > 1e-9:
            rows.append(r)
    return np.array(rows, dtype=float)


def _edge_grid(sl: KnownSlice, n: int = 200_000) -> tuple[np.ndarray, float]:
    """Evenly spaced points of the square's perimeter (2 free weights) and their spacing."""
    r = sl.radius
    sq = np.array([[r, 0.0], [0.0, r], [-r, 0.0], [0.0, -r]])
    s = (np.arange(n) + 0.5) / n
    pts = np.vstack([sq[j] + s[:, None] * (sq[(j + 1) % 4] - sq[j]) for j in range(4)])
    return pts, r * math.sqrt(2) / n


def _ball_grid(sl: KnownSlice, n: int = 1201) -> tuple[np.ndarray, float]:
    r = sl.radius
    u = (np.arange(n) + 0.5) / n * 2 * r - r
    g = np.stack(np.meshgrid(u, u, indexing="ij"), axis=-1).reshape(-1, 2)
    return g[np.abs(g).sum(axis=1) <= r], (2 * r / n) ** 2


def _grid(sl: KnownSlice) -> tuple[np.ndarray, float]:
    return _edge_grid(sl) if sl.measure == "edge" else _ball_grid(sl)


def _inside(sl: KnownSlice, pts: np.ndarray, rows: np.ndarray) -> np.ndarray:
    a, b = sl.affine(rows)
    return np.all(pts @ a.T + b >= 0, axis=1) if len(a) else np.ones(len(pts), dtype=bool)


@pytest.mark.parametrize("measure", ["edge", "ball"])
@pytest.mark.parametrize("seed", range(6))
def test_measure_of_two_free_weights_equals_a_grid(measure: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    sl = KnownSlice.make(W3 * rng.uniform(0.5, 2), [2], measure)
    rows = _random_rows(sl.w_true, int(rng.integers(1, 6)), rng)
    pts, cell = _grid(sl)
    brute = _inside(sl, pts, rows).sum() * cell
    exact = SliceRegion(sl, rows).area()
    tol = 2e-4 * sl.total() if measure == "edge" else 4e-3 * sl.total()
    assert exact == pytest.approx(brute, abs=tol)
    assert SliceRegion(sl, []).area() == pytest.approx(sl.total())


def test_whole_slice_measures() -> None:
    """The perimeter 4 r sqrt(2) and the area 2 r^2 of the 2-D L1 ball; the 3-D ones."""
    sl = KnownSlice.make(W3, [2], "edge")
    assert sl.radius == pytest.approx(29 / 30)
    assert sl.total() == pytest.approx(4 * math.sqrt(2) * 29 / 30)
    assert KnownSlice.make(W3, [2], "ball").total() == pytest.approx(2 * (29 / 30) ** 2)
    w4 = np.array([4.0, -2.0, 1.0, -3.0])
    r = 0.7
    assert KnownSlice.make(w4, [3], "ball").total() == pytest.approx(8 * r ** 3 / 6)
    assert KnownSlice.make(w4, [3], "edge").total() == pytest.approx(8 * math.sqrt(3)
                                                                     * r ** 2 / 2)


@pytest.mark.parametrize("measure", ["edge", "ball"])
@pytest.mark.parametrize("seed", range(6))
def test_reduction_of_two_free_weights_against_a_grid(measure: str, seed: int) -> None:
    """Every kept row cuts grid points that the other kept rows allow; every dropped row
    holds wherever the kept rows hold."""
    rng = np.random.default_rng(100 + seed)
    sl = KnownSlice.make(W3, [2], measure)
    rows = _random_rows(sl.w_true, 8, rng)
    kept = SliceRegion(sl, rows).reduced()
    pts, _ = _grid(sl)
    a, b = sl.affine(kept)
    vals = pts @ a.T + b
    for i in range(len(kept)):
        others = np.delete(vals, i, axis=1)
        assert np.any((others >= 0).all(axis=1) & (vals[:, i] < -1e-9))
    ok = (vals >= 0).all(axis=1)
    a_all, b_all = sl.affine(rows)
    assert ((pts[ok] @ a_all.T + b_all) >= -1e-9).all()
    assert SliceRegion(sl, kept).area() == pytest.approx(SliceRegion(sl, rows).area())


def test_edge_drops_a_row_that_cuts_only_the_balls_interior() -> None:
    """Where the measures disagree: with u1 >= 0 and u2 <= 0 the belief on the edge is the
    side from (r, 0) to (0, -r); u1 - u2 >= 1/2 cuts only the ball's corner at the origin,
    so the ball keeps it and the edge drops it (and neither measure changes on the edge)."""
    rows = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [1.0, -1.0, 15.0]])
    assert (rows @ W3 > 0).all()
    ball = SliceRegion(KnownSlice.make(W3, [2], "ball"), rows)
    edge = SliceRegion(KnownSlice.make(W3, [2], "edge"), rows)
    assert len(ball.reduced()) == 3
    assert {tuple(r) for r in edge.reduced().tolist()} == {(1, 0, 0), (0, -1, 0)}
    r = 29 / 30
    assert edge.area() == pytest.approx(r * math.sqrt(2))
    assert ball.area() == pytest.approx(r ** 2 / 2 - 0.5 ** 2 / 2)


@pytest.mark.parametrize("measure", ["edge", "ball"])
def test_three_free_weights_estimate_and_reduction_against_a_grid(measure: str) -> None:
    """4 features, one known: the Monte Carlo measure lies within 4 standard errors of a
    brute-force grid measure; the LP reduction agrees with the grid."""
    w = np.array([5.0, -2.0, 1.0, -2.0])
    sl = KnownSlice.make(w, [3], measure)
    rng = np.random.default_rng(7)
    rows = _random_rows(sl.w_true, 4, rng, -6, 7)
    reg = SliceRegion(sl, rows)
    est, se = reg.measure_estimate()
    r = sl.radius
    if measure == "ball":
        n = 161
        u = (np.arange(n) + 0.5) / n * 2 * r - r
        g = np.stack(np.meshgrid(u, u, u, indexing="ij"), axis=-1).reshape(-1, 3)
        g = g[np.abs(g).sum(axis=1) <= r]
        cell = (2 * r / n) ** 3
    else:  # each orthant's facet: a triangle gridded by barycentric points
        n = 400
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        keep = i + j < n - 1
        x = np.c_[(i[keep] + 1 / 3) / n, (j[keep] + 1 / 3) / n]
        tri = np.c_[x, 1 - x.sum(axis=1)] * r
        g = np.vstack([tri * np.array(s) for s in itertools.product([-1, 1], repeat=3)])
        cell = sl.total() / len(g)
    brute = _inside(sl, g, rows).sum() * cell
    assert se > 0
    assert abs(est - brute) < 4 * se + 0.01 * sl.total()
    assert reg.area() == est
    kept = reg.reduced()
    a, b = sl.affine(kept)
    vals = g @ a.T + b
    for i in range(len(kept)):
        others = np.delete(vals, i, axis=1)
        assert np.any((others >= 0).all(axis=1) & (vals[:, i] < -1e-9))
    ok = (vals >= 0).all(axis=1)
    a_all, b_all = sl.affine(rows)
    assert ((g[ok] @ a_all.T + b_all) >= -1e-9).all()


@pytest.mark.parametrize("measure", ["edge", "ball"])
def test_samples_are_uniform_on_the_belief(measure: str) -> None:
    """Samples satisfy the belief, keep the known weight, and split across a further row in
    proportion to the exact measures."""
    sl = KnownSlice.make(W3, [2], measure)
    rows = np.array([[1.0, 2.0, 0.0], [1.0, -1.0, 0.0]])
    reg = SliceRegion(sl, rows)
    W = reg.sample(20_000, np.random.default_rng(3))
    assert W.shape == (20_000, 3)
    assert np.allclose(W[:, 2], sl.w_true[2])
    assert (W @ rows.T >= -1e-12).all()
    if measure == "edge":
        assert np.allclose(np.abs(W).sum(axis=1), 1.0)
    extra = np.array([1.0, 0.0, -10.0])
    share = SliceRegion(sl, np.vstack([rows, extra])).area() / reg.area()
    p = float((W @ extra >= 0).mean())
    assert p == pytest.approx(share, abs=4 * math.sqrt(share * (1 - share) / len(W)) + 1e-3)


def test_uniform_slice_points_lie_on_the_slice() -> None:
    sl = KnownSlice.make([1.0, 2.0, -3.0, 4.0], [0], "edge")
    u = uniform_slice(sl, 1000, np.random.default_rng(0))
    assert np.allclose(np.abs(u).sum(axis=1), sl.radius)
    sl = KnownSlice.make([1.0, 2.0, -3.0, 4.0], [0], "ball")
    u = uniform_slice(sl, 1000, np.random.default_rng(0))
    assert (np.abs(u).sum(axis=1) <= sl.radius + 1e-12).all()


def test_bad_slices_and_empty_beliefs() -> None:
    with pytest.raises(ValueError, match="two unknown"):
        KnownSlice.make(W3, [0, 2])
    with pytest.raises(ValueError, match="measure"):
        KnownSlice.make(W3, [2], "sphere")
    sl = KnownSlice.make(W3, [2], "edge")
    with pytest.raises(ValueError, match="no weights"):
        SliceRegion(sl, [[-1, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, -1]]).reduced()
    assert SliceRegion(sl, [[0, 0, 1]]).area() == 0.0  # -1/30 >= 0 fails everywhere
