"""A JSON's known-weight slice and the prior's measure on it: what both the slice pictures
(`render/belief_slice.py`) and the belief-area curves (`render/belief.py`) read, without
drawing anything."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from cfteach.geometry.slice import KnownSlice


def slice_of(known: Mapping[str, Any], weights: Sequence[float],
             feature_names: Sequence[str]) -> KnownSlice:
    """The KnownSlice a JSON's ``settings.known`` describes (`weights`: the JSON's w*)."""
    idx = [list(feature_names).index(k) for k in known["features"]]
    return KnownSlice.make(np.asarray(weights, dtype=float), idx, known.get("measure", "ball"))


def prior_measure(curriculum: Mapping[str, Any]) -> float | None:
    """The prior's measure on the curriculum's slice (None when nothing is known)."""
    known = (curriculum.get("settings") or {}).get("known")
    if not known or curriculum.get("prior") is None:
        return None
    sl = slice_of(known, curriculum["weights"], curriculum["feature_names"])
    return float(sl.region(curriculum["prior"]).area())
