"""Rollouts follow the reference's rules; the benefit-of-the-doubt DP equals brute force."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.domains import load
from cfteach.mdp import (
    best_tied_trajectories,
    compile_domain,
    count_tied_trajectories,
    greedy_actions,
    replay,
    rollout,
    rollout_features,
    tied_actions,
    value_iteration,
)

UP, DOWN, LEFT, RIGHT, PICKUP, DROPOFF = range(6)


@pytest.mark.parametrize("name", ["delivery", "tiles", "skateboard"])
def test_greedy_rollouts_realise_the_values(name: str) -> None:
    dom = load(name)
    b = compile_domain(dom)
    vals = value_iteration(b, dom.weights)
    ro = rollout_features(b, greedy_actions(vals.Q))
    valid = b.valid[:, None, :]
    assert ro.terminal[valid].all()
    assert (ro.length[valid] <= 25).all() and (ro.length[~valid] == 0).all()
    assert (ro.mu == np.round(ro.mu)).all()
    np.testing.assert_allclose((ro.mu @ dom.weights)[valid], vals.V[valid], atol=1e-12)


@pytest.mark.parametrize("name", ["delivery", "skateboard"])
def test_batched_rollouts_match_single_rollouts(name: str) -> None:
    dom = load(name)
    b = compile_domain(dom)
    rng = np.random.default_rng(0)
    W = np.vstack([dom.weights, rng.normal(size=(2, 3))])
    W[1:, 2] = -np.abs(W[1:, 2])
    pol = greedy_actions(value_iteration(b, W, method="reference").Q)
    plain = rollout_features(b, pol, return_paths=True)
    forced = rollout_features(b, pol, first_action="all", return_paths=True)
    for e in rng.choice(b.E, 3, replace=False):
        for s in rng.choice(int(b.n_states[e]), 8, replace=False):
            for m in range(3):
                tr = rollout(b, pol, e, int(s), model=m)
                assert np.array_equal(tr.mu, plain.mu[e, m, s])
                assert len(tr.actions) == plain.length[e, m, s]
                assert list(tr.actions) == plain.actions[e, m, s, : len(tr.actions)].tolist()
                assert tr.terminal == plain.terminal[e, m, s]
                for a in range(b.A):
                    tf = rollout(b, pol, e, b.states[e][s], first_action=a, model=m)
                    assert tf.actions[0] == a
                    assert np.array_equal(tf.mu, forced.mu[e, m, s, a])
                    assert len(tf.actions) == forced.length[e, m, s, a]
                    # Replaying the actions reproduces the rollout's real states.
                    rp = replay(b.instances[e], b.states[e][s], tf.action_names)
                    assert rp.states == tf.states and np.array_equal(rp.mu, tf.mu)


def test_rollout_paths_follow_next_state() -> None:
    b = compile_domain(load("tiles"))
    pol = greedy_actions(value_iteration(b, load("tiles").weights, env=range(8)).Q)
    sub = b.subset(range(8))
    ro = rollout_features(sub, pol, return_paths=True)
    for e in range(8):
        for s in range(int(sub.n_states[e])):
            n = ro.length[e, 0, s]
            st, ac = ro.states[e, 0, s], ro.actions[e, 0, s]
            assert st[0] == s and (st[n + 1:] == -1).all() and (ac[n:] == -1).all()
            for t in range(n):
                assert st[t + 1] == sub.next_state[e, st[t], ac[t]]


def test_self_loop_counter_and_step_cap() -> None:
    b = compile_domain(load("tiles")).subset([0])
    idx = b.state_index[0]
    # Always "pickup" (a no-op): 6 policy self-loops, then the counter exceeds 5.
    pol = np.full((1, b.S), PICKUP)
    ro = rollout_features(b, pol)
    assert (ro.length[0, 0, : b.n_states[0]] == 6).all()
    assert (ro.mu[0, 0, 0] == [0, 0, 6]).all()
    # A forced first step does not count as a self-loop, but counts towards the 25 steps.
    ro = rollout_features(b, pol, first_action=UP)
    assert ro.length[0, 0, idx[(1, 1)]] == 7
    ro = rollout_features(b, pol, first_action=PICKUP)
    assert ro.length[0, 0, idx[(1, 1)]] == 7
    # "left" everywhere: walk to x = 1 (moves), then bump the edge 6 times; the counter is
    # cumulative over the rollout.
    pol = np.full((1, b.S), LEFT)
    ro = rollout_features(b, pol)
    assert ro.length[0, 0, idx[(4, 3)]] == 3 + 6
    # Up/down forever never loops on one state: the 25-step cap ends it.
    pol = np.array([[UP if s[1] % 2 else DOWN for s in b.states[0]] + [0] * (b.S - 24)])
    ro = rollout_features(b, pol)
    assert ro.length[0, 0, idx[(2, 3)]] == 25 and not ro.terminal[0, 0, idx[(2, 3)]]
    tr = rollout(b, pol, 0, (2, 3))
    assert len(tr.actions) == 25 and not tr.terminal


def test_rollout_rejects_bad_input() -> None:
    b = compile_domain(load("skateboard"))
    with pytest.raises(ValueError, match="policy must have shape"):
        rollout_features(b, np.zeros((3, b.S), dtype=int))
    with pytest.raises(ValueError, match="first_action"):
        rollout_features(b, np.zeros((b.E, b.S), dtype=int), first_action=9)


# ------------------------------------------------------------ benefit of the doubt
def _brute_force_tied(b, tied, e: int, m: int, s: int, w: np.ndarray, horizon: int):
    """All tied trajectories depth first (action order) -> (count, best actions, best mu)."""
    nxt, feats = b.next_state[e], b.features[e]
    found: list[tuple[list[int], np.ndarray]] = []

    def dfs(state: int, acts: list[int], mu: np.ndarray) -> None:
        if state == b.sink or len(acts) >= horizon:
            found.append((acts, mu))
            return
        for a in np.flatnonzero(tied[e, m, state]):
            dfs(int(nxt[state, a]), [*acts, int(a)], mu + feats[state, a])

    dfs(s, [], np.zeros(b.F))
    best_val, best = -np.inf, None
    for acts, mu in found:
        v = w.dot(mu)
        if v > best_val:  # first enumerated wins exact ties, like the reference
            best_val, best = v, (acts, mu)
    return len(found), best


@pytest.mark.parametrize(("name", "envs", "horizon"), [
    ("skateboard", [0, 1, 3], 25), ("tiles", [0, 77, 300, 511], 25), ("delivery", [0, 33], 12)])
def test_best_tied_matches_brute_force(name: str, envs: list[int], horizon: int) -> None:
    dom = load(name)
    b = compile_domain(dom).subset(envs)
    # Human models with many ties (zero weights) and generic ones from the prior.
    W = np.array([[0.0, 0.0, -1.0], [-0.3, 0.0, -0.6], [0.0, -0.5, -0.5],
                  [-0.2, -0.1, -0.9], list(dom.weights)])
    vals = value_iteration(b, W, method="reference")
    tied = tied_actions(vals.Q)
    best = best_tied_trajectories(b, vals.Q, dom.weights, horizon=horizon)
    counts = count_tied_trajectories(b, tied, horizon=horizon)
    rng = np.random.default_rng(5)
    checked = 0
    for e in range(len(envs)):
        for m in range(len(W)):
            if not vals.bounded[e, m]:
                continue
            for s in rng.choice(int(b.n_states[e]), 12, replace=False):
                if counts[e, m, s] > 3000:
                    continue
                n, (acts, mu) = _brute_force_tied(b, tied, e, m, int(s), dom.weights, horizon)
                assert counts[e, m, s] == n
                assert best.actions(e, m, int(s)) == acts
                assert np.array_equal(best.mu[e, m, s], mu)
                # same sum, other order of additions: equal up to rounding
                assert best.value[e, m, s] == pytest.approx(dom.weights.dot(mu), rel=1e-12,
                                                            abs=1e-12)
                assert best.length[e, m, s] == len(acts)
                checked += 1
    assert checked > 40
    assert counts.max() > 10  # the reference's enumeration cap bites somewhere


def test_best_tied_under_true_weights_is_optimal() -> None:
    dom = load("delivery")
    b = compile_domain(dom)
    vals = value_iteration(b, dom.weights)
    best = best_tied_trajectories(b, vals.Q, dom.weights)
    valid = b.valid[:, None, :]
    np.testing.assert_allclose(best.value[valid], vals.V[valid], atol=1e-9)


def test_best_tied_chunking_over_models() -> None:
    dom = load("skateboard")
    b = compile_domain(dom)
    W = np.array([[0.0, 0.0, -1.0], [-0.3, 0.0, -0.6], [-0.2, -0.1, -0.9]])
    q = value_iteration(b, W).Q
    a = best_tied_trajectories(b, q, dom.weights)
    c = best_tied_trajectories(b, q, dom.weights, chunk_bytes=1.0)
    assert np.array_equal(a.first_action, c.first_action) and np.array_equal(a.mu, c.mu)


def test_best_tied_rejects_bad_shapes() -> None:
    b = compile_domain(load("skateboard"))
    with pytest.raises(ValueError, match="Q_h must have shape"):
        best_tied_trajectories(b, np.zeros((b.E, b.S, b.A)), np.ones(3))
    with pytest.raises(ValueError, match="w_true"):
        best_tied_trajectories(b, np.zeros((b.E, 1, b.S, b.A)), np.ones(4))


def test_best_tied_mu_on_pairs_matches_grid() -> None:
    from cfteach.mdp import best_tied_mu

    dom = load("tiles")
    b = compile_domain(dom).subset([0, 77, 300])
    W = np.array([[0.0, 0.0, -1.0], [-0.3, 0.0, -0.6], [0.5, 0.2, 0.1], list(dom.weights)])
    vals = value_iteration(b, W)
    grid = best_tied_trajectories(b, vals.Q, dom.weights)
    pe, pm = np.nonzero(vals.bounded)
    assert 0 < len(pe) < vals.bounded.size
    mu = best_tied_mu(b, pe, vals.Q[pe, pm], dom.weights)
    assert mu.dtype == np.int64
    assert np.array_equal(mu, grid.mu[pe, pm])
    with pytest.raises(ValueError, match="Q must have shape"):
        best_tied_mu(b, pe, vals.Q[pe, pm][:, :, :2], dom.weights)
