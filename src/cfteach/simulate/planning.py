"""Array-level planning for simulated learners, vectorised over many learners at once.

Inputs are one instance's compiled arrays (`cfteach.mdp`): `next_state[S, A]` (the last
index `S - 1` is the terminal sink, absorbing with zero features) and `features[S, A, F]`.
Everything here works on a batch of `M` learners/weight vectors and `K` start states.
"""

from __future__ import annotations

import numpy as np


def sink_index(next_state: np.ndarray) -> int:
    """Index of the terminal sink (the last state, by the MDPBatch contract)."""
    return next_state.shape[0] - 1


def best_finishing_tied(next_state: np.ndarray, features: np.ndarray, tied: np.ndarray,
                        w_true: np.ndarray, starts: np.ndarray, *,
                        max_steps: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A learner's counterfactual: from each start, among the trajectories that take only
    actions tied-optimal under the learner's own weights (`tied[M, S, A]`) and reach the
    end, the one with the highest true reward `w_true . mu` (the reference's "benefit of
    the doubt": of its equally good plans, the learner compares the demonstration with the
    one closest to it). Exact ties go to the first action in action order.

    Returns `mu[M, K, F]` and `found[M, K]` (False where no tied plan reaches the end
    within `max_steps`, default `S`; such starts yield no constraint).
    """
    S, A = next_state.shape
    M = tied.shape[0]
    sink = sink_index(next_state)
    steps = S if max_steps is None else int(max_steps)
    r = features @ np.asarray(w_true, dtype=float)                      # [S, A]
    u = np.full((M, S), -np.inf)
    u[:, sink] = 0.0
    for _ in range(steps):
        cand = np.where(tied, r[None] + u[:, next_state], -np.inf)      # [M, S, A]
        new = cand.max(axis=2)
        new[:, sink] = 0.0
        if np.array_equal(new, u):
            break
        u = new
    cand = np.where(tied, r[None] + u[:, next_state], -np.inf)
    policy = cand.argmax(axis=2)                                        # first arg-max
    starts = np.asarray(starts)
    if starts.ndim == 1:
        starts = np.broadcast_to(starts, (M, starts.size))
    found = np.isfinite(np.take_along_axis(u, starts, axis=1))
    mu, finished, _ = follow(next_state, features, policy, starts, max_steps=steps)
    return mu, found & finished


def follow(next_state: np.ndarray, features: np.ndarray, policy: np.ndarray,
           starts: np.ndarray, *, first_action: np.ndarray | None = None,
           max_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Deterministic rollouts of `policy[M, S]` from `starts[M, K]` (optionally forcing
    `first_action[M, K]`): feature counts `mu[M, K, F]`, `finished[M, K]` (reached the
    sink within `max_steps`) and `length[M, K]`."""
    M, K = starts.shape
    sink = sink_index(next_state)
    F = features.shape[-1]
    pos = starts.astype(np.intp).copy()
    mu = np.zeros((M, K, F))
    length = np.zeros((M, K), dtype=np.intp)
    rows = np.arange(M)[:, None]
    for t in range(max_steps):
        live = pos != sink
        if not live.any():
            break
        a = policy[rows, pos]
        if t == 0 and first_action is not None:
            a = np.asarray(first_action)
        mu += features[pos, a] * live[..., None]
        length += live
        pos = np.where(live, next_state[pos, a], pos)
    return mu, pos == sink, length


def boltzmann_rollouts(next_state: np.ndarray, features: np.ndarray, q: np.ndarray,
                       starts: np.ndarray, temperature: float, rng: np.random.Generator,
                       *, max_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noisy answers: at each step pick action `a` with probability proportional to
    `exp(Q[m, s, a] / temperature)` (Boltzmann rationality), from `starts[M, K]`.
    Non-finite Q rows (no bounded plan) fall back to the first action."""
    if temperature <= 0:
        raise ValueError(f"temperature must be positive, got {temperature}")
    M, K = starts.shape
    sink = sink_index(next_state)
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
    for _ in range(max_steps):
        live = pos != sink
        if not live.any():
            break
        u = rng.random((M, K))
        a = (cdf[rows, pos] < u[..., None]).sum(axis=2)
        a = np.minimum(a, A - 1)
        mu += features[pos, a] * live[..., None]
        length += live
        pos = np.where(live, next_state[pos, a], pos)
    return mu, pos == sink, length
