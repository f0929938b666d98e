"""Learner planning on arrays, against brute-force enumeration on small random MDPs."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.simulate.planning import best_finishing_tied, boltzmann_rollouts, follow


def _random_mdp(rng: np.random.Generator, S: int = 7, A: int = 3, F: int = 3):
    nxt = rng.integers(0, S, size=(S, A))
    nxt[S - 1] = S - 1
    feats = rng.integers(0, 2, size=(S, A, F)).astype(float)
    feats[..., -1] = 1.0  # a step feature, as every domain has
    feats[S - 1] = 0.0
    return nxt, feats


def _brute_best(nxt, feats, tied, w, s, depth):
    """Enumerate every tied path of length <= depth that reaches the sink."""
    sink = nxt.shape[0] - 1
    best = None
    stack = [(s, np.zeros(feats.shape[-1]), 0)]
    while stack:
        st, mu, d = stack.pop()
        if st == sink:
            val = float(mu @ w)
            if best is None or val > best[0] + 1e-12:
                best = (val, mu)
            continue
        if d == depth:
            continue
        for a in np.flatnonzero(tied[st]):
            stack.append((int(nxt[st, a]), mu + feats[st, a], d + 1))
    return best


@pytest.mark.parametrize("seed", range(25))
def test_best_finishing_tied_matches_enumeration(seed: int) -> None:
    rng = np.random.default_rng(seed)
    nxt, feats = _random_mdp(rng)
    S, A, _ = feats.shape
    M = 3
    tied = rng.random((M, S, A)) < 0.6
    tied[:, S - 1] = True
    w = -rng.uniform(0.1, 1.0, size=3)
    starts = np.tile(np.arange(S - 1), (M, 1))
    mu, found = best_finishing_tied(nxt, feats, tied, w, starts, max_steps=S)
    for m in range(M):
        for k, s in enumerate(range(S - 1)):
            best = _brute_best(nxt, feats, tied[m], w, s, depth=S)
            assert found[m, k] == (best is not None)
            if best is not None:
                assert mu[m, k] @ w == pytest.approx(best[0])


def test_follow_forced_first_action_and_unfinished() -> None:
    # chain 0 -> 1 -> sink(3) with action 0; action 1 loops in place; state 2 loops forever
    nxt = np.array([[1, 0], [3, 1], [2, 2], [3, 3]])
    feats = np.zeros((4, 2, 2))
    feats[:3, :, 1] = 1.0
    feats[0, 0, 0] = 1.0
    policy = np.array([[0, 0, 0, 0]])
    mu, fin, length = follow(nxt, feats, policy, np.array([[0, 2]]), max_steps=10)
    assert fin.tolist() == [[True, False]]
    assert mu[0, 0].tolist() == [1.0, 2.0] and length[0].tolist() == [2, 10]
    mu, fin, length = follow(nxt, feats, policy, np.array([[0]]),
                             first_action=np.array([[1]]), max_steps=10)
    assert fin[0, 0] and length[0, 0] == 3 and mu[0, 0].tolist() == [1.0, 3.0]


def test_boltzmann_cold_is_greedy_hot_is_uniform() -> None:
    rng = np.random.default_rng(0)
    nxt = np.array([[1, 1, 1], [1, 1, 1]])  # one decision, then the sink
    feats = np.zeros((2, 3, 3))
    feats[0, np.arange(3), np.arange(3)] = 1.0  # action a fires feature a
    q = np.array([[[0.0, 1.0, 0.5], [0.0, 0.0, 0.0]]]).repeat(4000, axis=0)
    starts = np.zeros((4000, 1), dtype=int)
    mu, fin, _ = boltzmann_rollouts(nxt, feats, q, starts, 1e-3, rng, max_steps=5)
    assert fin.all() and (mu[:, 0, 1] == 1).all()
    mu, _, _ = boltzmann_rollouts(nxt, feats, q, starts, 1.0, rng, max_steps=5)
    freq = mu[:, 0].mean(axis=0)
    expected = np.exp([0.0, 1.0, 0.5]) / np.exp([0.0, 1.0, 0.5]).sum()
    np.testing.assert_allclose(freq, expected, atol=0.03)
    with pytest.raises(ValueError, match="temperature must be positive"):
        boltzmann_rollouts(nxt, feats, q, starts, 0.0, rng, max_steps=5)
