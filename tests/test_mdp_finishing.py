"""`best_tied_policy(must_finish=True)` + `rollout_from`: the simulated learners' counterfactual
plan, against brute-force enumeration of tied paths that reach the terminal, on small random
MDPs; `rollout_from` against `rollout_features` on a real domain."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.domains import load
from cfteach.mdp import (
    MDPBatch,
    best_tied_policy,
    compile_domain,
    greedy_actions,
    rollout_features,
    rollout_from,
    value_iteration,
)


def _batch(nxt: np.ndarray, feats: np.ndarray) -> MDPBatch:
    """One-instance batch over raw arrays (last state = terminal sink)."""
    S, A, F = feats.shape
    valid = np.ones((1, S), dtype=bool)
    valid[0, S - 1] = False
    return MDPBatch(nxt[None].astype(np.int64), feats[None].astype(float), valid,
                    np.array([S - 1]), ((),), ({},), (), tuple(f"a{i}" for i in range(A)),
                    tuple(f"f{i}" for i in range(F)))


def _random_mdp(rng: np.random.Generator, S: int = 7, A: int = 3, F: int = 3):
    nxt = rng.integers(0, S, size=(S, A))
    nxt[S - 1] = S - 1
    feats = rng.integers(0, 2, size=(S, A, F)).astype(float)
    feats[..., -1] = 1.0  # a step feature, as every domain has
    feats[S - 1] = 0.0
    return nxt, feats


def _q_of(tied: np.ndarray) -> np.ndarray:
    """Action values whose tied-optimal set is exactly `tied` (-inf never ties)."""
    return np.where(tied, 0.0, -np.inf)


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


def _finishing(b: MDPBatch, q: np.ndarray, w: np.ndarray, starts: np.ndarray):
    S = b.S
    pol = best_tied_policy(b, np.zeros(len(q), dtype=int), q, w, horizon=S + 1,
                           must_finish=True)
    ro = rollout_from(b, pol, 0, starts, max_steps=S, max_self_loops=None)
    return ro.mu, ro.terminal


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
    mu, found = _finishing(_batch(nxt, feats), _q_of(tied), w, starts)
    for m in range(M):
        for k, s in enumerate(range(S - 1)):
            best = _brute_best(nxt, feats, tied[m], w, s, depth=S)
            assert found[m, k] == (best is not None)
            if best is not None:
                assert mu[m, k] @ w == pytest.approx(best[0])


def _finishing_mus(nxt, feats, tied, s, depth) -> set[tuple[float, ...]]:
    """Feature counts of every tied path of length <= depth from s that reaches the sink."""
    sink = nxt.shape[0] - 1
    out, stack = set(), [(s, np.zeros(feats.shape[-1]), 0)]
    while stack:
        st, mu, d = stack.pop()
        if st == sink:
            out.add(tuple(mu))
        elif d < depth:
            stack += [(int(nxt[st, a]), mu + feats[st, a], d + 1) for a in np.flatnonzero(tied[st])]
    return out


@pytest.mark.parametrize("seed", range(25))
def test_finishing_policy_with_reward_loops_is_a_real_tied_path(seed: int) -> None:
    """Mixed-sign true weights can make tied loops pay (the DP then runs to its horizon):
    wherever the plan ends it is a real tied path to the terminal within S steps, and where
    no such path exists it never claims one."""
    rng = np.random.default_rng(100 + seed)
    nxt, feats = _random_mdp(rng, S=6)
    S, A, _ = feats.shape
    tied = rng.random((2, S, A)) < 0.6
    w = rng.normal(size=3)
    starts = np.tile(np.arange(S - 1), (2, 1))
    mu, found = _finishing(_batch(nxt, feats), _q_of(tied), w, starts)
    for m in range(2):
        for s in range(S - 1):
            paths = _finishing_mus(nxt, feats, tied[m], s, depth=S)
            if found[m, s]:  # found implies such a path exists
                assert tuple(mu[m, s]) in paths


def test_must_finish_policy_marks_dead_ends() -> None:
    # 0 -a0-> 1 -a0-> sink(3); state 2 only loops on itself (tied), so it never finishes
    nxt = np.array([[1, 2], [3, 1], [2, 2], [3, 3]])
    feats = np.zeros((4, 2, 2))
    feats[:3, :, 1] = 1.0
    b = _batch(nxt, feats)
    q = _q_of(np.array([[[True, True], [True, False], [True, False], [True, True]]]))
    w = np.array([0.0, -1.0])
    pol = best_tied_policy(b, [0], q, w, horizon=5, must_finish=True)
    assert pol.tolist() == [[0, 0, -1, -1]]
    pol = best_tied_policy(b, [0], q, w, horizon=5)  # any tied path of 5 steps will do
    assert pol[0, 2] == 0 and pol[0, 3] == -1
    with pytest.raises(ValueError, match="Q must have shape"):
        best_tied_policy(b, [0, 0], q, w)
    for bad in ([1], [-1]):  # one instance only; -1 must not wrap around to the last one
        with pytest.raises(ValueError, match=r"env must be instance indices in 0\.\.0"):
            best_tied_policy(b, bad, q, w)


def test_follow_forced_first_action_and_unfinished() -> None:
    # chain 0 -> 1 -> sink(3) with action 0; action 1 loops in place; state 2 loops forever
    nxt = np.array([[1, 0], [3, 1], [2, 2], [3, 3]])
    feats = np.zeros((4, 2, 2))
    feats[:3, :, 1] = 1.0
    feats[0, 0, 0] = 1.0
    b = _batch(nxt, feats)
    policy = np.array([[0, 0, 0, 0]])
    ro = rollout_from(b, policy, 0, np.array([[0, 2]]), max_steps=10, max_self_loops=None)
    assert ro.terminal.tolist() == [[True, False]]
    assert ro.mu[0, 0].tolist() == [1.0, 2.0] and ro.length[0].tolist() == [2, 10]
    ro = rollout_from(b, policy, 0, np.array([[0]]), np.array([[1]]), max_steps=10,
                      max_self_loops=None)
    assert ro.terminal[0, 0] and ro.length[0, 0] == 3 and ro.mu[0, 0].tolist() == [1.0, 3.0]
    # the reference's self-loop counter stops the looping rollout after 6 self-loops
    ro = rollout_from(b, policy, 0, np.array([2]), max_steps=10)
    assert ro.length[0, 0] == 6 and not ro.terminal[0, 0]
    # a negative policy entry ends the rollout there
    ro = rollout_from(b, np.array([[0, -1, 0, 0]]), 0, np.array([0]), max_steps=10)
    assert ro.length[0, 0] == 1 and not ro.terminal[0, 0] and ro.mu[0, 0].tolist() == [1, 1]


def test_rollout_from_rejects_bad_input() -> None:
    nxt, feats = _random_mdp(np.random.default_rng(0))
    b = _batch(nxt, feats)
    pol = np.zeros((2, b.S), dtype=int)
    with pytest.raises(ValueError, match="policy must have shape"):
        rollout_from(b, pol[:, :3], 0, [0])
    with pytest.raises(ValueError, match="env must be"):
        rollout_from(b, pol, 1, [0])
    with pytest.raises(ValueError, match="starts must have shape"):
        rollout_from(b, pol, 0, np.zeros((3, 1), dtype=int))
    with pytest.raises(ValueError, match="start state indices"):
        rollout_from(b, pol, 0, [b.S])
    with pytest.raises(ValueError, match="first actions"):
        rollout_from(b, pol, 0, [0], np.array([b.A]))


def test_rollout_from_matches_rollout_features_on_a_domain() -> None:
    d = load("skateboard")
    b = compile_domain(d)
    W = np.vstack([d.weights, [-0.2, -0.5, -0.84]])
    policy = greedy_actions(value_iteration(b, W).Q)  # [E, M, S]
    full = rollout_features(b, policy, first_action="all")
    env = b.E // 2
    n = int(b.n_states[env])
    starts = np.tile(np.repeat(np.arange(n), b.A), (2, 1))
    first = np.tile(np.arange(b.A), n)
    ro = rollout_from(b, policy[env], env, starts, first)
    np.testing.assert_array_equal(ro.mu.reshape(2, n, b.A, b.F), full.mu[env, :, :n])
    np.testing.assert_array_equal(ro.terminal.reshape(2, n, b.A), full.terminal[env, :, :n])
    np.testing.assert_array_equal(ro.length.reshape(2, n, b.A), full.length[env, :, :n])


@pytest.mark.parametrize("horizon", [3, 25])
def test_best_tied_policy_is_the_grid_dps_first_action(horizon: int) -> None:
    """Without must_finish, the policy equals `best_tied_trajectories`' first actions with the
    full horizon left (the same DP recording every horizon)."""
    from cfteach.mdp import best_tied_trajectories

    d = load("skateboard")
    b = compile_domain(d)
    W = np.array([[0.0, 0.0, -1.0], [-0.3, -0.3, -0.9]])
    vals = value_iteration(b, W)
    grid = best_tied_trajectories(b, vals.Q, d.weights, horizon=horizon)
    env = np.repeat(np.arange(b.E), 2)
    pol = best_tied_policy(b, env, vals.Q.reshape(-1, b.S, b.A), d.weights, horizon=horizon)
    np.testing.assert_array_equal(pol.reshape(b.E, 2, b.S), grid.first_action[horizon - 1])
