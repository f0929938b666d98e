"""The noisy belief's fast answer term gives the long way's numbers bit for bit
(docs/closed-loop.md, "Speed")."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.closedloop.noisy_belief import NoisyBelief
from cfteach.closedloop.steps import taken_actions


@pytest.mark.parametrize("lapse", [0.0, 0.01, 0.3])
def test_taken_log_policy_matches_full_policy_bit_for_bit(lapse: float) -> None:
    rng = np.random.default_rng(3)
    P, G, A = 200, 40, 5
    belief = NoisyBelief(np.zeros((0, 3)), 3, n_particles=P, seed=0, lapse=lapse,
                         n_reference=10)
    x = rng.normal(size=(P, G, A)) * 0.3
    beta = rng.choice(belief.grids["beta"], size=P)
    counts = np.zeros((G, A))
    counts[np.arange(G), rng.integers(0, A, G)] = rng.integers(1, 4, G)
    counts[::7] += rng.integers(0, 2, (len(counts[::7]), A))  # states with several actions
    counts[5] = 0                                              # a state never left
    one_g, _, _, many_g = taken_actions(counts)
    assert len(one_g) and len(many_g)
    fast = belief._taken_log_policy(x, beta, counts, taken_actions(counts))
    slow = (belief._log_policy(x, beta) * counts[None]).sum(2)
    assert fast.tobytes() == slow.tobytes()
