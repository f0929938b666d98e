"""Boltzmann-rational (noisy) rollouts for simulated learners, vectorised over many learners.

Deterministic planning (the benefit-of-the-doubt counterfactual, greedy and forced-first
rollouts) is `cfteach.mdp`'s (`best_tied_policy`, `rollout_from`); only the stochastic
answers live here, since mdp has no sampling. Inputs are one instance's compiled arrays:
`next_state[S, A]` (the last index `S - 1` is the terminal sink, absorbing with zero
features) and `features[S, A, F]`, for `M` learners and `K` start states.
"""

from __future__ import annotations

import numpy as np


def boltzmann_rollouts(next_state: np.ndarray, features: np.ndarray, q: np.ndarray,
                       starts: np.ndarray, temperature: float, rng: np.random.Generator,
                       *, max_steps: int, record: list | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noisy answers: at each step pick action `a` with probability proportional to
    `exp(Q[m, s, a] / temperature)` (Boltzmann rationality), from `starts[M, K]`.
    Non-finite Q rows (no bounded plan) fall back to the first action. With `record` (a
    list), the actions taken are appended to it as ``[M, K, steps]`` (-1 once finished);
    the random draws are the same either way."""
    if temperature <= 0:
        raise ValueError(f"temperature must be positive, got {temperature}")
    M, K = starts.shape
    sink = next_state.shape[0] - 1  # the terminal sink, by the MDPBatch contract
    F = features.shape[-1]
    logits = q / temperature
    finite = np.isfinite(logits).all(axis=2, keepdims=True)
    logits = np.where(finite, logits, 0.0)
    logits = logits - logits.max(axis=2, keepdims=True)
    p = np.exp(logits)
    p /= p.sum(axis=2, keepdims=True)
    cdf = np.cumsum(p, axis=2)                                          # [M, S, A]
    pos = starts.astype(np.intp).copy()
    mu = np.zeros((M, K, F))
    length = np.zeros((M, K), dtype=np.intp)
    rows = np.arange(M)[:, None]
    A = next_state.shape[1]
    taken = []
    for _ in range(max_steps):
        live = pos != sink
        if not live.any():
            break
        u = rng.random((M, K))
        a = (cdf[rows, pos] < u[..., None]).sum(axis=2)
        a = np.minimum(a, A - 1)
        mu += features[pos, a] * live[..., None]
        length += live
        taken.append(np.where(live, a, -1))
        pos = np.where(live, next_state[pos, a], pos)
    if record is not None:
        record.append(np.stack(taken, axis=2) if taken else np.zeros((M, K, 0), np.intp))
    return mu, pos == sink, length


def policy_paths(next_state: np.ndarray, policy: np.ndarray, starts: np.ndarray, *,
                 max_steps: int) -> np.ndarray:
    """Actions ``[M, K, steps]`` (-1 once finished) of deterministic policies
    ``policy[M, S]`` from ``starts[M, K]``: the moves of a greedy answer."""
    M, K = starts.shape
    sink = next_state.shape[0] - 1
    pos = starts.astype(np.intp).copy()
    rows = np.arange(M)[:, None]
    taken = []
    for _ in range(max_steps):
        live = pos != sink
        if not live.any():
            break
        a = policy[rows, pos]
        taken.append(np.where(live, a, -1))
        pos = np.where(live, next_state[pos, np.maximum(a, 0)], pos)
    return np.stack(taken, axis=2) if taken else np.zeros((M, K, 0), np.intp)
