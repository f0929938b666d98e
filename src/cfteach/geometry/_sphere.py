"""The measure of the whole unit sphere S^(dim-1): what a region's fraction scales by, both in
`Region.fraction` and in the estimators for more than 3 features (`_highdim.area_nd`)."""

from __future__ import annotations

from math import gamma, pi


def sphere_area(dim: int) -> float:
    """Surface measure of the unit sphere S^(dim-1) in R^dim: 4 pi for dim = 3."""
    return 2 * pi ** (dim / 2) / gamma(dim / 2)
