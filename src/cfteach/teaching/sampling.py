"""Human models sampled from a belief: the reference's deterministic grid (spec §6.1) and
exact uniform sampling (the default profile).

The reference grid sampler is kept here because `cfteach.geometry` does not (yet) provide
it; it only needs the constraint rows.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from cfteach.geometry import Region

#: Give up refining the reference's fine grid after this density (tiny regions).
MAX_DENSITY = 400


def reference_grid_sample(constraints: np.ndarray, m: int) -> np.ndarray:
    """The reference's `sample_human_models_uniform` (spec §6.1): deterministic, ``[k, 3]``.

    Returns an empty ``(0, 3)`` array when the coarse grid has no point inside (the teaching
    loop then stops), and fewer than `m` rows only if the region is so thin that even a fine
    grid of density `MAX_DENSITY` holds fewer than `m` points.
    """
    c = np.asarray(constraints, dtype=float).reshape(-1, 3)
    if m < 1:
        raise ValueError(f"m must be at least 1, got {m}")
    pts = _coarse_grid()
    pts = pts[_inside(pts, c)]
    if not len(pts):
        return np.zeros((0, 3))
    azi = np.arctan2(pts[:, 1], pts[:, 0])
    ele = np.arccos(pts[:, 2] / np.linalg.norm(pts, axis=1))
    u_lo, u_hi = azi.min() / (2 * np.pi), azi.max() / (2 * np.pi)
    v_lo, v_hi = (1 - np.cos(ele.min())) / 2, (1 - np.cos(ele.max())) / 2
    density = 5
    while True:
        n = density * m
        theta = 2 * np.pi * np.linspace(u_lo, u_hi, n)
        phi = np.arccos(1 - 2 * np.linspace(v_lo, v_hi, n))
        th, ph = np.meshgrid(theta, phi)  # rows: phi (outer), columns: theta
        th, ph = th.ravel(), ph.ravel()
        fine = np.stack([np.cos(th) * np.sin(ph), np.sin(th) * np.sin(ph), np.cos(ph)], axis=1)
        fine = fine[_inside(fine, c)]
        if len(fine) == m:
            return fine
        if len(fine) > m:
            return fine[_k_centres(fine, m)]
        if density >= MAX_DENSITY:
            return fine
        density += 1


@cache
def _coarse_grid() -> np.ndarray:
    u = np.linspace(0, 2 * np.pi, 1000)
    v = np.linspace(0, np.pi, 1000)
    uu, vv = np.meshgrid(u, v, indexing="ij")  # u-major
    pts = np.stack([np.cos(uu) * np.sin(vv), np.sin(uu) * np.sin(vv), np.cos(vv)],
                   axis=-1).reshape(-1, 3)
    pts.setflags(write=False)
    return pts


def _inside(pts: np.ndarray, c: np.ndarray) -> np.ndarray:
    """c . p >= 0 for every constraint (evaluated as the dot product ``pts @ c``)."""
    ok = np.ones(len(pts), dtype=bool)
    for row in c:
        ok &= pts @ row >= 0
    return ok


def _k_centres(pts: np.ndarray, m: int) -> np.ndarray:
    """Greedy farthest-point selection starting at index 0 (first index on ties)."""
    chosen = [0]
    dist = np.linalg.norm(pts - pts[0], axis=1)
    for _ in range(m - 1):
        i = int(np.argmax(dist))
        chosen.append(i)
        dist = np.minimum(dist, np.linalg.norm(pts - pts[i], axis=1))
    return np.array(chosen)


def uniform_sample(constraints: np.ndarray, m: int, rng: np.random.Generator,
                   dim: int) -> np.ndarray:
    """`m` models drawn exactly uniformly from the region (empty if it has no area)."""
    region = Region(np.asarray(constraints).reshape(-1, dim), dim=dim)
    if region.is_empty():
        return np.zeros((0, dim))
    return region.sample(m, rng)


def sample_models(profile: str, constraints: np.ndarray, m: int, rng: np.random.Generator,
                  dim: int) -> np.ndarray:
    """The profile's sampler: reference grid (3 features only) or exact uniform."""
    if profile == "reference" and dim == 3:
        return reference_grid_sample(constraints, m)
    return uniform_sample(constraints, m, rng, dim)
