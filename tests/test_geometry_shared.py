"""`intersection_fractions` for more than 3 features (one shared seeded sample of the region)
against independent computations: the exact 3-feature formula embedded in 5 dimensions, and
brute-force Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.geometry import Region, clear_cache, intersection_fractions


def embed(rows: np.ndarray, dim: int) -> np.ndarray:
    """3-feature rows as rows in `dim` features: the cone becomes (3-D cone) x R^(dim-3),
    whose Gaussian measure (so its share of the sphere) is the 3-D one."""
    rows = np.asarray(rows)
    return np.hstack([rows, np.zeros((len(rows), dim - 3), dtype=rows.dtype)])


def exact3(belief: np.ndarray, sets: list[np.ndarray]) -> np.ndarray:
    b = Region(belief)
    return np.array([Region(np.vstack([belief, c])).area() / b.area() for c in sets])


def random_sets(rng: np.random.Generator, w: np.ndarray, n: int, k: int) -> list[np.ndarray]:
    """Integer constraint sets satisfied by `w` (like a demonstration's: true w inside)."""
    out = []
    for _ in range(n):
        c = rng.integers(-4, 5, size=(int(rng.integers(1, k + 1)), len(w)))
        s = np.sign(c @ w).astype(np.int64)
        s[s == 0] = 1
        out.append(c * s[:, None])
    return out


@pytest.mark.parametrize("belief", [
    [[0, 0, -1]],                              # a hemisphere
    [[1, 0, 0], [0, 1, 0], [0, 0, 1]],         # an octant
    [[4, -1, 0], [-1, 4, 0], [0, -1, 9], [-1, 0, 9], [1, 1, -1]],  # a small pentagon
])
def test_embedded_three_feature_fractions_match_the_exact_formula(belief: list) -> None:
    rng = np.random.default_rng(len(belief))
    b3 = np.array(belief)
    w = Region(b3).interior_point()
    sets3 = random_sets(rng, w + 0.1 * rng.standard_normal(3), 25, 3)
    want = exact3(b3, sets3)
    clear_cache()
    p, se = intersection_fractions(Region(embed(b3, 5)), [embed(c, 5) for c in sets3])
    assert np.all(np.abs(p - want) <= 5 * se + 1e-12)
    assert np.all(se < 0.02)
    assert np.any((p > 0) & (p < 1))


def brute_force(belief: np.ndarray, sets: list[np.ndarray], n: int, seed: int,
                ) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    z = rng.standard_normal((n, belief.shape[1]))
    z = z[np.all(z @ belief.T >= 0, axis=1)]
    p = np.array([np.mean(np.all(z @ c.T >= 0, axis=1)) for c in sets])
    return p, np.sqrt(p * (1 - p) / len(z))


def test_fractions_in_five_dims_match_brute_force_monte_carlo() -> None:
    rng = np.random.default_rng(5)
    w = rng.standard_normal(5)
    belief = random_sets(rng, w, 1, 4)[0]
    sets = random_sets(rng, w, 30, 4)
    p, se = intersection_fractions(Region(belief), sets)
    q, q_se = brute_force(belief, sets, 2_000_000, 6)
    assert np.all(np.abs(p - q) <= 5 * np.hypot(se, q_se) + 1e-12)


def test_a_set_scores_the_same_alone_or_in_any_company() -> None:
    """What the distribution of candidates over workers relies on."""
    rng = np.random.default_rng(8)
    w = rng.standard_normal(4)
    belief = Region(random_sets(rng, w, 1, 3)[0])
    sets = random_sets(rng, w, 12, 3)
    together, se = intersection_fractions(belief, sets)
    clear_cache()
    alone = [intersection_fractions(belief, [c])[0][0] for c in sets[::-1]][::-1]
    assert together.tolist() == alone
    again = intersection_fractions(belief, sets[6:] + sets[:6])[0]
    assert again.tolist() == together[6:].tolist() + together[:6].tolist()
    other = intersection_fractions(belief, sets, seed=1)[0]
    assert other.tolist() != together.tolist()
    assert np.all(np.abs(other - together) <= 6 * se + 1e-12)


def test_tails_are_measured_on_their_own() -> None:
    """A set that leaves almost nothing, one that cuts off a sliver, and one that cuts
    nothing: far beyond what the shared sample resolves, still right."""
    belief = embed(np.array([[0, 0, 1]]), 4)
    tiny = embed(np.array([[1, 0, 0], [-50, 0, 1], [0, 1, 0], [0, -50, 1]]), 4)
    sliver = embed(np.array([[1, 0, 2000]]), 4)
    harmless = embed(np.array([[0, 0, 1], [0, 0, 2]]), 4)
    want = exact3(belief[:, :3], [tiny[:, :3], sliver[:, :3]])
    p, se = intersection_fractions(Region(belief), [tiny, sliver, harmless])
    assert p[2] == 1.0 and se[2] == 0.0
    assert abs(p[0] - want[0]) <= 5 * se[0] and 0 < p[0] < 1e-4 and se[0] < 0.05 * p[0]
    assert abs(p[1] - want[1]) <= 5 * se[1] and p[1] < 1 and se[1] < 0.05 * (1 - want[1])


def test_three_features_stay_exact() -> None:
    belief = Region([[0, 0, -1]])
    p, se = intersection_fractions(belief, [np.array([[1, 0, 0]]), np.array([[1, 1, 0]])])
    assert p.tolist() == [0.5, 0.5] and se.tolist() == [0.0, 0.0]


def test_the_whole_sphere_is_not_folded_onto_a_hemisphere() -> None:
    sets = [np.array([[1, 0, 0, 0]]), np.array([[0, 0, 0, 1]]), np.array([[0, 0, 0, -1]]),
            np.array([[1, 0, 0, 0], [0, 1, 0, 0]])]
    p, se = intersection_fractions(Region.full(4), sets)
    assert np.all(np.abs(p - [0.5, 0.5, 0.5, 0.25]) <= 5 * se) and np.all(se < 0.01)
