"""When a played trajectory counts as optimal: the paper's M1, in one place.

The study scores people with it and the simulation scores simulated learners with it, so
the two can never drift apart. The authors compared rewards with exact float equality;
we compare within a tolerance so that the same path summed in another order still counts.
"""

from __future__ import annotations

import math

import numpy as np

#: Relative and absolute tolerance (as in `math.isclose`) between a reward and the optimum.
OPTIMAL_TOLERANCE = 1e-9


def is_optimal(reward: float, optimal_reward: float, tol: float = OPTIMAL_TOLERANCE) -> bool:
    """Whether a finished trajectory with this true reward equals the optimum (M1)."""
    return math.isclose(float(reward), float(optimal_reward), rel_tol=tol, abs_tol=tol)


def optimal_mask(
    rewards: np.ndarray,
    optimal_reward: np.ndarray | float,
    finished: np.ndarray | bool = True,
    tol: float = OPTIMAL_TOLERANCE,
) -> np.ndarray:
    """`is_optimal` over arrays; an answer that never reaches the end is never optimal."""
    rewards = np.asarray(rewards, dtype=float)
    opt = np.broadcast_to(np.asarray(optimal_reward, dtype=float), rewards.shape)
    gap = np.abs(rewards - opt)
    close = (gap <= tol * np.maximum(np.abs(rewards), np.abs(opt))) | (gap <= tol)
    return np.asarray(finished, dtype=bool) & close
