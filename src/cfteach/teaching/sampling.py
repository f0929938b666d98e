"""Human models sampled from a belief: the profile's sampler.

The paper samples m weights from the belief B(w*) (Section IV, Algorithms 1 and 2) without
saying how. The reference profile uses the authors' deterministic grid
(`cfteach.geometry.sample_reference_grid`, 3 features only); the default profile draws exactly
uniform samples (`cfteach.geometry.sample_uniform`). Why they differ: docs/profiles.md,
difference 1.
"""

from __future__ import annotations

import numpy as np

from cfteach.geometry import Region, sample_reference_grid, sample_uniform


def sample_models(profile: str, constraints: np.ndarray, m: int, rng: np.random.Generator,
                  dim: int) -> np.ndarray:
    """The profile's sampler: reference grid (3 features only) or exact uniform.

    Either returns an empty ``(0, dim)`` array when the region has no area (teaching stops).
    """
    rows = np.asarray(constraints).reshape(-1, dim)
    if profile == "reference" and dim == 3:
        return sample_reference_grid(rows.astype(float), m)
    return sample_uniform(Region(rows, dim=dim), m, rng)
