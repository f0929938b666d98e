"""Regions on the unit sphere cut by half-spaces ``w . n >= 0``.

``Region`` reduces constraint sets, measures them (exactly for 3 features), samples them
uniformly, and intersects them; ``sampling`` holds the human-model samplers. See
docs/geometry.md.
"""

from .region import (
    Region,
    clear_cache,
    infeasible_rows,
    intersection_areas,
    intersection_fractions,
    overlap,
    reduce_many,
    sphere_area,
)
from .sampling import sample_reference_grid, sample_uniform

__all__ = [
    "Region",
    "clear_cache",
    "infeasible_rows",
    "intersection_areas",
    "intersection_fractions",
    "overlap",
    "reduce_many",
    "sample_reference_grid",
    "sample_uniform",
    "sphere_area",
]
