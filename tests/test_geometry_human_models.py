"""Human-model samplers: the reference grid sampler reproduces the authors' sampler exactly
(docs/geometry.md, "Sampling")."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.geometry import Region
from cfteach.geometry.sampling import greedy_k_centres, sample_reference_grid, sample_uniform

# the authors' sampler's output for the prior [[0, 0, -1]] (docs/geometry.md, "Sampling")
PRIOR_SAMPLES = np.array(
    [
        [-0.99999382, -0.00314473, -0.00157237],
        [0.99676256, 0.0803861, -0.00157237],
        [0.04179665, -0.9991249, -0.00157237],
        [-1.22464074e-16, -3.85118623e-19, -1.0],
        [-0.11821132, 0.98752987, -0.1039752],
        [0.61809503, -0.54678432, -0.56478796],
        [-0.57026783, -0.59649741, -0.56478796],
        [0.4987527, 0.60975637, -0.61598937],
    ]
)


def test_prior_samples_match_reference_exactly() -> None:
    got = sample_reference_grid([[0, 0, -1]], m=8)
    assert got.shape == (8, 3)
    assert np.allclose(got, PRIOR_SAMPLES, atol=1e-8, rtol=0)


def test_grid_samples_lie_in_region_and_are_unit() -> None:
    for rows in ([[1, 1, 0], [0, -1, -4], [-1, 0, 2]], [[0, 0, -1], [1, 0, 0]], np.eye(3)):
        pts = sample_reference_grid(rows, m=8)
        assert pts.shape == (8, 3)
        assert np.allclose(np.linalg.norm(pts, axis=1), 1.0)
        assert np.all(Region(rows).contains(pts, tol=1e-12))
        assert len({tuple(p) for p in pts.tolist()}) == 8


def test_grid_sampler_returns_empty_when_nothing_survives() -> None:
    rows = np.vstack([np.eye(3), -np.eye(3)])
    out = sample_reference_grid(rows, m=8)
    assert out.shape == (0, 3)


def test_greedy_k_centres_against_brute_force() -> None:
    rng = np.random.default_rng(0)
    pts = rng.standard_normal((60, 3))
    chosen = greedy_k_centres(pts, 7)
    # brute force: recompute the farthest-first rule with a full distance matrix
    dist = np.sqrt(((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1))
    expect = [0]
    for _ in range(6):
        expect.append(int(np.argmax(dist[:, expect].min(axis=1))))
    assert chosen.tolist() == expect


def test_sample_uniform() -> None:
    rows = [[1, 1, 0], [0, -1, -4], [-1, 0, 2]]
    pts = sample_uniform(rows, 50, np.random.default_rng(1))
    assert pts.shape == (50, 3)
    assert np.all(Region(rows).contains(pts, tol=1e-9))
    assert np.array_equal(pts, sample_uniform(Region(rows), 50, np.random.default_rng(1)))
    assert sample_uniform([[1, 0, 0], [-1, 0, 0]], 5, 0).shape == (0, 3)


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="3 features"):
        sample_reference_grid(np.eye(4), m=8)
    with pytest.raises(ValueError, match="at least 1"):
        sample_reference_grid([[0, 0, -1]], m=0)


def test_thin_region_stops_at_max_density() -> None:
    # a band 5e-4 rad wide along a tilted great circle: density 5 leaves 3 fine-grid points,
    # density 12 enough for 8
    t = 5e-4
    a = np.array([0.0, 1.0, 1.0]) / np.sqrt(2)
    c = np.cross([1.0, 0.0, 0.0], a)
    rows = np.array([a, -(np.cos(t) * a - np.sin(t) * c), [1.0, 0.0, 0.0]])
    few = sample_reference_grid(rows, m=8, max_density=5)
    assert 0 < len(few) < 8
    assert np.all(Region(rows).contains(few, tol=1e-12))
    full = sample_reference_grid(rows, m=8, max_density=20)
    assert len(full) == 8
    assert np.all(Region(rows).contains(full, tol=1e-12))
