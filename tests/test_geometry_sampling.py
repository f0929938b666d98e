"""Region.sample: inside the region, uniform (hit fractions of sub-regions vs area ratios,
KS on heights for lunes and hemispheres), reproducible, fine on tiny slivers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from cfteach.geometry import Region


def chi2_cells(region: Region, cuts: np.ndarray, pts: np.ndarray) -> float:
    """p-value of a chi-square test: hits per cell (sign pattern of the cuts) vs area ratio.

    Cell areas come from Region.area, which test_geometry_region checks independently.
    """
    signs = (pts @ cuts.T >= 0).astype(int)
    codes = signs @ (1 << np.arange(len(cuts)))
    obs, exp = [], []
    total = region.area()
    for code in range(1 << len(cuts)):
        rows = [c if (code >> i) & 1 else -c for i, c in enumerate(cuts)]
        cell = region & Region(np.array(rows))
        p = cell.area() / total
        if p * len(pts) < 5:
            continue
        obs.append(int(np.sum(codes == code)))
        exp.append(p * len(pts))
    obs_a, exp_a = np.array(obs, dtype=float), np.array(exp)
    exp_a *= obs_a.sum() / exp_a.sum()
    return float(stats.chisquare(obs_a, exp_a).pvalue)


def cuts_through(u: np.ndarray, rng: np.random.Generator, n: int) -> np.ndarray:
    """Random planes through the interior direction u (so every cell has some area)."""
    g = rng.standard_normal((n, 3))
    return g - (g @ u)[:, None] * u


@pytest.mark.parametrize(
    "normals",
    [
        np.eye(3),
        np.array([[1, 1, 0], [0, -1, -4], [-1, 0, 2]], dtype=float),
        np.array([[8, 1, -2], [0, -2, 1], [-6, 4, -1]], dtype=float),
        np.array([[1.0, 0.2, 0.1], [0.1, 1.0, -0.3], [-0.2, 0.1, 1.0], [0.5, 0.5, 0.9],
                  [-0.4, -0.3, 1.0]]),
    ],
)
def test_polygon_samples_are_uniform(normals: np.ndarray) -> None:
    r = Region(normals)
    rng = np.random.default_rng(11)
    pts = r.sample(40_000, rng)
    assert pts.shape == (40_000, 3)
    assert np.allclose(np.linalg.norm(pts, axis=1), 1.0)
    assert np.all(r.contains(pts, tol=1e-9))
    u = r.interior_point()
    assert u is not None
    assert chi2_cells(r, cuts_through(u, rng, 3), pts) > 1e-3


def test_tiny_sliver_samples_are_uniform() -> None:
    # a triangle about 1e-5 rad wide and 1 rad long: area ~ 5e-6 sr (fraction 4e-7)
    eps = 1e-5
    r = Region(np.array([[1.0, 0.0, 0.0], [-1.0, eps, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, -1.5]]))
    assert 0 < r.fraction() < 1e-5
    rng = np.random.default_rng(12)
    pts = r.sample(30_000, rng)
    assert np.all(r.contains(pts, tol=1e-12))
    u = r.interior_point()
    assert u is not None
    # cut along the sliver (the planes z = c y) and across it
    cuts = np.array([[0.0, -0.3, 1.0], [0.0, -1.0, 1.0], [-1.0, 2 * eps / 3, 0.0]])
    assert chi2_cells(r, cuts, pts) > 1e-3


def test_tiny_cap_like_polygon() -> None:
    # a regular hexagon of circumradius 1e-4 around the north pole
    ang = np.arange(6) * np.pi / 3
    normals = np.stack([-np.cos(ang), -np.sin(ang), np.full(6, 1e-4)], axis=1)
    r = Region(normals)
    rng = np.random.default_rng(13)
    pts = r.sample(30_000, rng)
    assert np.all(r.contains(pts, tol=1e-12))
    radial = np.hypot(pts[:, 0], pts[:, 1])
    assert radial.max() < 1.2e-4
    # the region is symmetric about the pole: each coordinate sign is a fair coin
    assert stats.binomtest(int(np.sum(pts[:, 0] > 0)), len(pts)).pvalue > 1e-3
    assert chi2_cells(r, cuts_through(np.array([0.0, 0.0, 1.0]), rng, 3), pts) > 1e-3


def test_hemisphere_heights_are_uniform() -> None:
    n = np.array([0.2, -0.5, 0.8])
    n /= np.linalg.norm(n)
    pts = Region(n[None, :]).sample(20_000, np.random.default_rng(14))
    h = pts @ n
    assert h.min() >= 0
    assert stats.kstest(h, "uniform", args=(0, 1)).pvalue > 1e-3


@pytest.mark.parametrize("theta", [0.3, 1.5, 3.0])
def test_lune_samples(theta: float) -> None:
    n1 = np.array([1.0, 0.0, 0.0])
    n2 = np.array([np.cos(theta), np.sin(theta), 0.0])
    r = Region(np.stack([n1, n2]))
    pts = r.sample(20_000, np.random.default_rng(15))
    assert np.all(r.contains(pts, tol=1e-12))
    # height along the lune's axis is uniform on [-1, 1] (Archimedes)
    assert stats.kstest(pts[:, 2], "uniform", args=(-1, 2)).pvalue > 1e-3
    # azimuth is uniform over the wedge of width pi - theta
    az = np.arctan2(pts[:, 1], pts[:, 0])
    lo = theta - np.pi / 2
    assert stats.kstest(az, "uniform", args=(lo, np.pi - theta)).pvalue > 1e-3


def test_full_sphere_samples() -> None:
    pts = Region.full(3).sample(20_000, np.random.default_rng(16))
    assert stats.kstest(pts[:, 0], "uniform", args=(-1, 2)).pvalue > 1e-3


def test_sampling_is_reproducible() -> None:
    r = Region(np.array([[1, 1, 0], [0, -1, -4], [-1, 0, 2]]))
    a = r.sample(100, np.random.default_rng(5))
    b = r.sample(100, np.random.default_rng(5))
    c = r.sample(100, 5)
    assert np.array_equal(a, b) and np.array_equal(a, c)
    assert r.sample(0, 1).shape == (0, 3)
    with pytest.raises(ValueError, match="non-negative"):
        r.sample(-1, 1)
    with pytest.raises(ValueError, match="integer"):
        r.sample(2.5, 1)  # type: ignore[arg-type]
    assert r.sample(np.int64(3), 1).shape == (3, 3)


@pytest.mark.parametrize("rad", [3e-2, 1e-8])
def test_small_polygons_use_exact_gnomonic_rejection(rad: float) -> None:
    # regular hexagon of inradius `rad` around the pole: every fan triangle is small
    ang = np.arange(6) * np.pi / 3
    r = Region(np.stack([-np.cos(ang), -np.sin(ang), np.full(6, rad)], axis=1))
    pts = r.sample(40_000, np.random.default_rng(17))
    assert np.all(r.contains(pts, tol=1e-13))
    # the disc of radius rad/2 (angular) about the pole holds area_disc / area_hexagon
    dist = np.arctan2(np.hypot(pts[:, 0], pts[:, 1]), pts[:, 2])
    disc = 4 * np.pi * np.sin(rad / 4) ** 2  # 2 pi (1 - cos(rad / 2)) without cancellation
    p = disc / r.area()
    assert stats.binomtest(int(np.sum(dist < rad / 2)), len(pts), p).pvalue > 1e-3
    assert chi2_cells(r, cuts_through(np.array([0.0, 0.0, 1.0]),
                                      np.random.default_rng(18), 3), pts) > 1e-3
