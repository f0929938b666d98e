"""The noisy learner model's parameter grids, their defaults, and the check of a grid.

`NoisyBelief` infers each of these per learner from a small grid of values; `TeacherSettings`
stores the grids a study uses. They live here, below both, so that the settings need not
import the belief to know its defaults.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Rationality grid: Q-value differences of a domain's actions are about 0.1-0.2 (weights are
#: unit vectors), so beta = 2 is close to random and beta = 300 close to greedy.
RATIONALITY = (5.0, 10.0, 20.0, 50.0, 100.0, 300.0)
#: Uptake grid: the chance a shown demonstration is taken in.
UPTAKE = (0.2, 0.4, 0.6, 0.8, 0.95)
#: Disengagement grid: the chance a whole answer is random moves. Its uniform prior has mean
#: 0.042; the earlier (0.01, 0.05, 0.2), mean 0.087, kept every prediction about 0.05 under
#: what engaged learners then scored (docs/closed-loop.md, "Measured").
DISENGAGED = (0.005, 0.02, 0.1)
#: Confusion grid: the chance an attempt used weights drawn from the belief of its time.
#: ``(0.0,)`` turns the term off (the model before it, bit for bit). With the term, errors
#: made while the learner's own belief was wide are not read as a low rationality for good:
#: that was the noisy learners' under-prediction of 0.14-0.28 (docs/closed-loop.md).
CONFUSED = (0.0, 0.25, 0.5, 0.75)
#: Chance of a random move at any step, so that no move has likelihood 0. It caps every
#: prediction of a T-step answer near (1 - lapse)^T (0.01 caps a 15-step answer at 0.89);
#: 0.002 caps it at 0.97.
LAPSE = 0.002


def as_grid(values: Any, name: str, low: float, high: float, *,
            low_included: bool = False) -> np.ndarray:
    """`values` as a 1-d float grid inside ``(low, high)`` (``[low, high)`` if
    `low_included`), or a ValueError naming `name`: a bad grid fails before any work."""
    arr = np.asarray(values, dtype=np.float64).ravel()
    below = arr < low if low_included else arr <= low
    if not len(arr) or not np.all(np.isfinite(arr)) or np.any(below) or np.any(arr >= high):
        raise ValueError(f"{name}: expected one or more numbers in "
                         f"{'[' if low_included else '('}{low}, {high}), got {values!r}")
    return arr
