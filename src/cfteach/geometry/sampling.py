"""Human-model samplers: draw m candidate weight vectors w_h from a belief region B(w).

``sample_reference_grid`` reproduces the reference implementation's deterministic sampler
(docs/geometry.md, "Sampling") bit for bit in structure: a 1000 x 1000 coarse grid to bound the
region, an inverse-CDF fine grid refined until m points survive, then greedy k-centres.
It is biased (grid-aligned, favours the bounding box's corners) and its cost grows as the
region shrinks; ``sample_uniform`` draws exactly uniform samples instead.
"""

from __future__ import annotations

import sys
from functools import lru_cache
from typing import Any

import numpy as np
from tqdm import tqdm

from ._normalize import as_matrix
from .region import Region

_COARSE = 1000
_START_DENSITY = 5
#: Stop refining the fine grid at this density (the reference would loop on forever).
MAX_DENSITY = 400


@lru_cache(maxsize=1)
def _coarse_grid() -> np.ndarray:
    """The reference's 1000 x 1000 (azimuth, polar) grid, u-major; computed once."""
    u = np.linspace(0, 2 * np.pi, _COARSE)
    v = np.linspace(0, np.pi, _COARSE)
    uu, vv = np.meshgrid(u, v, indexing="ij")  # u-major order
    grid = np.stack([np.cos(uu) * np.sin(vv), np.sin(uu) * np.sin(vv), np.cos(vv)], axis=-1)
    grid = grid.reshape(-1, 3)
    grid.setflags(write=False)
    return grid


def _feasible(points: np.ndarray, constraints: np.ndarray) -> np.ndarray:
    """``c . p >= 0`` for every constraint row, one matrix-vector product per row (about 4x
    faster on the 10^6-point coarse grid than one ``[N, k]`` product and a reduction)."""
    ok = np.ones(len(points), dtype=bool)
    for row in constraints:
        ok &= points @ row >= 0
    return ok


def greedy_k_centres(points: np.ndarray, m: int) -> np.ndarray:
    """Indices of m points chosen farthest-first from index 0 (first index on ties)."""
    chosen = [0]
    nearest = np.linalg.norm(points - points[0], axis=1)
    for _ in range(m - 1):
        j = int(np.argmax(nearest))
        chosen.append(j)
        nearest = np.minimum(nearest, np.linalg.norm(points - points[j], axis=1))
    return np.asarray(chosen, dtype=np.intp)


def sample_reference_grid(
    normals: Any, m: int = 8, *, max_density: int = MAX_DENSITY
) -> np.ndarray:
    """The reference's deterministic human-model sampler (3 features only), ``[m, 3]``.

    Returns shape ``(0, 3)`` when no coarse grid point satisfies the constraints (the
    reference then stops teaching). If the region is so thin that even the fine grid of
    ``max_density`` holds fewer than ``m`` points, those few points are returned (the
    reference would refine forever).
    """
    cons = as_matrix(normals, dim=3 if np.size(normals) == 0 else None).astype(np.float64)
    if cons.shape[1] != 3:
        raise ValueError(f"the reference grid sampler works on 3 features, got {cons.shape[1]}")
    if m < 1:
        raise ValueError(f"m must be at least 1, got {m}")
    coarse = _coarse_grid()
    coarse = coarse[_feasible(coarse, cons)]
    if len(coarse) == 0:
        return np.zeros((0, 3))
    azi = np.arctan2(coarse[:, 1], coarse[:, 0])
    ele = np.arccos(coarse[:, 2] / np.linalg.norm(coarse, axis=1))
    u_lo, u_hi = azi.min() / (2 * np.pi), azi.max() / (2 * np.pi)
    v_lo, v_hi = (1 - np.cos(ele.min())) / 2, (1 - np.cos(ele.max())) / 2
    density = _START_DENSITY
    fine = np.zeros((0, 3))
    with tqdm(desc="fine grid density", unit="step", leave=False,
              disable=not sys.stderr.isatty()) as bar:
        while density <= max(max_density, _START_DENSITY):
            bar.update()
            theta = 2 * np.pi * np.linspace(u_lo, u_hi, density * m)
            phi = np.arccos(1 - 2 * np.linspace(v_lo, v_hi, density * m))
            # meshgrid(theta, phi) flattened row-major (phi outer); the trigonometry is done
            # on the axes only, the products are the same floats as on the full mesh
            n = len(theta)
            fine = np.empty((n, n, 3))
            fine[..., 0] = np.sin(phi)[:, None] * np.cos(theta)[None, :]
            fine[..., 1] = np.sin(phi)[:, None] * np.sin(theta)[None, :]
            fine[..., 2] = np.cos(phi)[:, None]
            fine = fine.reshape(-1, 3)
            fine = fine[_feasible(fine, cons)]
            if len(fine) == m:
                return fine
            if len(fine) > m:
                return fine[greedy_k_centres(fine, m)]
            density += 1
    return fine


def sample_uniform(
    normals: Any, m: int, rng: np.random.Generator | int | None = None
) -> np.ndarray:
    """``m`` exactly uniform draws from the region (``Region.sample``), ``[m, F]``.

    Returns shape ``(0, F)`` for an empty (measure-zero) region, like the grid sampler.
    """
    region = normals if isinstance(normals, Region) else Region(normals)
    if region.is_empty():
        return np.zeros((0, region.dim))
    return region.sample(m, rng)
