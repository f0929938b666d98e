"""How a simulated learner's test answer is scored: exactly as the study scores a person.

The study replays the participant's moves, requires that they reach the end of the game,
and counts the answer optimal iff its reward under `w*` equals the test's optimal reward
within a float tolerance (the paper's M1; the reference compared exact floats). Both use
the one rule in `cfteach.mdp.scoring`, so the two cannot drift apart.
"""

from __future__ import annotations

import numpy as np

from cfteach.mdp.scoring import OPTIMAL_TOLERANCE as TOLERANCE
from cfteach.mdp.scoring import is_optimal, optimal_mask

__all__ = ["TOLERANCE", "is_optimal", "score_answers"]


def score_answers(rewards: np.ndarray, finished: np.ndarray,
                  optimal_reward: np.ndarray | float) -> np.ndarray:
    """Vectorised study scoring: finished and reward within tolerance of the optimum.

    An answer that never reaches the end of the game is wrong, as in the study (which
    does not accept an unfinished move list).
    """
    return optimal_mask(rewards, optimal_reward, finished)
