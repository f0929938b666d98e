"""How a simulated learner's test answer is scored: exactly as the study scores a person.

The study (cfteach.study.games) replays the participant's moves, requires that they reach
the end of the game, and counts the answer optimal iff its reward under `w*` equals the
test's optimal reward within a float tolerance (the paper's M1; the reference compared
exact floats). This module is the one place the simulation applies that rule; it calls the
study's own `is_optimal` when the study package is importable so the two cannot drift.
"""

from __future__ import annotations

import math

import numpy as np

#: Relative and absolute tolerance of the study's `is_optimal` (math.isclose).
TOLERANCE = 1e-9


def _rule(reward: float, optimal_reward: float, tol: float = TOLERANCE) -> bool:
    return math.isclose(reward, optimal_reward, rel_tol=tol, abs_tol=tol)


try:  # the study's scorer, if present: same rule, one source of truth
    from cfteach.study.games import is_optimal as _study_is_optimal
except Exception:  # pragma: no cover - the study package is optional for simulation
    _study_is_optimal = None


def is_optimal(reward: float, optimal_reward: float) -> bool:
    """Whether a finished answer with this true reward counts as optimal (study rule)."""
    if _study_is_optimal is not None:
        return bool(_study_is_optimal(float(reward), float(optimal_reward)))
    return _rule(float(reward), float(optimal_reward))


def score_answers(rewards: np.ndarray, finished: np.ndarray,
                  optimal_reward: np.ndarray | float) -> np.ndarray:
    """Vectorised study scoring: finished and reward within tolerance of the optimum.

    An answer that never reaches the end of the game is wrong, as in the study (which
    does not accept an unfinished move list).
    """
    rewards = np.asarray(rewards, dtype=float)
    opt = np.broadcast_to(np.asarray(optimal_reward, dtype=float), rewards.shape)
    close = np.abs(rewards - opt) <= TOLERANCE * np.maximum(np.abs(rewards), np.abs(opt))
    close |= np.abs(rewards - opt) <= TOLERANCE
    return np.asarray(finished, dtype=bool) & close
