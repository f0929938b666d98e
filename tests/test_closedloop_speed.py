"""The noisy belief's fast answer term gives the long way's numbers bit for bit, and both
agree with an independent log-softmax (scipy) mixed with the lapse by hand
(docs/closed-loop.md, "Speed")."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import log_softmax, logsumexp

from cfteach.closedloop.noisy_belief import NoisyBelief
from cfteach.closedloop.steps import StepData, distinct_steps, log_normaliser, taken_actions


def _random_policy_inputs(seed: int, shape: tuple[int, int, int], lapse: float,
                          scale: float) -> tuple[NoisyBelief, np.ndarray, np.ndarray]:
    """A belief of `shape[0]` particles, `x = w . Psi` of `shape`, and a beta per particle."""
    rng = np.random.default_rng(seed)
    belief = NoisyBelief(np.zeros((0, 3)), 3, n_particles=shape[0], seed=0, lapse=lapse,
                         n_reference=10)
    x = rng.normal(size=shape) * scale
    return belief, x, rng.choice(belief.grids["beta"], size=shape[0])


@pytest.mark.parametrize("lapse", [0.0, 0.01, 0.3])
def test_taken_log_policy_matches_full_policy_bit_for_bit(lapse: float) -> None:
    rng = np.random.default_rng(3)
    P, G, A = 200, 40, 5
    belief, x, beta = _random_policy_inputs(3, (P, G, A), lapse, 0.3)
    counts = np.zeros((G, A))
    counts[np.arange(G), rng.integers(0, A, G)] = rng.integers(1, 4, G)
    counts[::7] += rng.integers(0, 2, (len(counts[::7]), A))  # states with several actions
    counts[5] = 0                                              # a state never left
    taken = taken_actions(counts)
    assert len(taken.one) and len(taken.many)
    fast = belief._taken_log_policy(x, beta, counts, taken_actions(counts))
    slow = (belief._log_policy(x, beta) * counts[None]).sum(2)
    assert fast.tobytes() == slow.tobytes()


@pytest.mark.parametrize("scale", [0.3, 50.0, 2000.0])
def test_log_normaliser_matches_scipy_logsumexp_without_overflow(scale: float) -> None:
    rng = np.random.default_rng(5)
    logits = rng.normal(size=(30, 17, 6)) * scale
    ours = log_normaliser(logits)
    assert np.isfinite(ours).all()
    np.testing.assert_allclose(ours, logsumexp(logits, axis=2), rtol=1e-13, atol=1e-12)


@pytest.mark.parametrize("lapse", [0.0, 0.05])
def test_log_policy_matches_log_softmax_with_lapse_by_hand(lapse: float) -> None:
    rng = np.random.default_rng(8)
    P, G, A = 50, 12, 4
    belief, x, beta = _random_policy_inputs(7, (P, G, A), lapse, 3.0)
    logpi = log_softmax(beta[:, None, None] * x, axis=2)
    expected = np.log((1 - lapse) * np.exp(logpi) + lapse / A) if lapse else logpi
    np.testing.assert_allclose(belief._log_policy(x, beta), expected, rtol=1e-12, atol=1e-12)
    # One action taken in every state: the fast path that neither copies x nor goes the
    # long way for any state.
    counts = np.zeros((G, A))
    counts[np.arange(G), rng.integers(0, A, G)] = rng.integers(1, 4, G)
    fast = belief._taken_log_policy(x, beta, counts, taken_actions(counts))
    np.testing.assert_allclose(fast, (expected * counts[None]).sum(2), rtol=1e-12, atol=1e-12)


def test_answers_sharing_states_give_the_per_state_numbers() -> None:
    """Answers that revisit states share their rows of ``x`` (`distinct_steps`); the answer
    term is that of one row per state, checked against scipy's log-softmax."""
    rng = np.random.default_rng(11)
    P, A, F, lapse = 40, 4, 3, 0.02
    base = rng.normal(size=(6, A, F))
    entries = []
    for n in (5, 4, 6):  # three answers drawing their states from six
        pick = rng.integers(0, 6, n)
        counts = np.zeros((n, A))
        counts[np.arange(n), rng.integers(0, A, n)] = rng.integers(1, 3, n)
        counts[0] += 1  # a state with several actions taken
        e = {"rows": base[pick], "counts": counts}
        if n == 4:  # a finished answer: a known plan for one action of some states
            e["alt"], e["alt_action"] = rng.normal(size=(n, F)), np.array([1, -1, 0, -1])
        entries.append(e)
    points = rng.normal(size=(P, F))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    beta = rng.choice([5.0, 50.0], size=P)
    distinct, group = distinct_steps(entries)
    counts = np.concatenate([e["counts"] for e in entries])
    assert len(distinct.rows) < len(counts)
    belief = NoisyBelief(np.zeros((0, F)), F, n_particles=P, seed=0, lapse=lapse,
                         n_reference=10)
    shared = belief._taken_log_policy(distinct.x(points), beta, counts,
                                      taken_actions(counts, group))
    x = np.concatenate([StepData.of(e).x(points) for e in entries], axis=1)
    pi = np.exp(log_softmax(beta[:, None, None] * x, axis=2))
    expected = (np.log((1 - lapse) * pi + lapse / A) * counts[None]).sum(2)
    np.testing.assert_allclose(shared, expected, rtol=1e-12, atol=1e-12)
