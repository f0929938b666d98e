"""MDP arrays and value iteration, checked against independent computations.

Independent checks: scipy's shortest paths (Dijkstra / Bellman-Ford on the state graph with
cost = -reward) and brute-force enumeration of simple paths and simple cycles on a tiny
hand-made domain.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import NegativeCycleError, csgraph_from_dense, shortest_path

from cfteach.domains import from_dict, load
from cfteach.mdp import (
    compile_domain,
    compile_instances,
    greedy_actions,
    tied_actions,
    value_iteration,
)


def _reverse_graph(batch, e: int, w: np.ndarray):
    """Reversed state graph of instance e, cost = -reward; node n is the terminal.

    Keeps the best reward per (s, s'); self-loops are left out (scipy rejects them; they are
    checked separately where they matter).
    """
    n = int(batch.n_states[e])
    r = batch.features[e, :n] @ w
    nxt = np.where(batch.next_state[e, :n] == batch.sink, n, batch.next_state[e, :n])
    cost = np.full((n + 1, n + 1), np.inf)
    src = np.repeat(np.arange(n), batch.A)
    dst = nxt.ravel()
    keep = dst != src
    np.minimum.at(cost, (dst[keep], src[keep]), -r.ravel()[keep])
    return csgraph_from_dense(cost, null_value=np.inf), n, r, nxt


def _graph_values(batch, e: int, w: np.ndarray) -> np.ndarray:
    """Optimal undiscounted values of instance e by scipy shortest paths to the terminal."""
    g, n, r, _ = _reverse_graph(batch, e, w)
    method = "D" if (r <= 0).all() else "BF"
    return -shortest_path(g, method=method, indices=n)[:n]


def _has_positive_cycle(batch, e: int, w: np.ndarray) -> bool:
    g, n, r, nxt = _reverse_graph(batch, e, w)
    if ((nxt == np.arange(n)[:, None]) & (r > 0)).any():
        return True
    try:
        shortest_path(g, method="BF", indices=n)
    except NegativeCycleError:
        return True
    return False


# ------------------------------------------------------------------------- arrays
def test_arrays_match_instance_step() -> None:
    dom = load("delivery")
    b = compile_domain(dom)
    assert compile_domain(dom) is b  # cached
    assert b.next_state.shape == (64, 192, 6) and b.features.shape == (64, 192, 6, 3)
    assert b.n_states.tolist() == [len(i.states()) for i in dom.instances()]
    rng = np.random.default_rng(0)
    for e in rng.choice(64, 6, replace=False):
        inst = b.instances[e]
        for i in rng.choice(int(b.n_states[e]), 20):
            s = b.states[e][i]
            assert b.index_of(e, s) == i
            for a in range(6):
                s2, phi, term = inst.step(s, a)
                assert b.next_state[e, i, a] == (b.sink if term else b.state_index[e][s2])
                assert np.array_equal(b.features[e, i, a], phi)
    # Sink and padding loop on themselves with zero features; they are not valid.
    assert (b.next_state[:, b.sink] == b.sink).all()
    assert not b.features[:, b.sink].any()
    e = 0  # 100 states, padding 100..190
    assert not b.valid[e, 100:].any() and b.valid[e, :100].all()
    assert (b.next_state[e, 150] == 150).all() and not b.features[e, 150].any()


def test_compile_is_deterministic() -> None:
    dom = load("skateboard")
    a = compile_instances(dom.instances())
    b = compile_instances(dom.instances())
    assert np.array_equal(a.next_state, b.next_state)
    assert np.array_equal(a.features, b.features)
    assert a.states == b.states


# -------------------------------------------------------------- value iteration
@pytest.mark.parametrize("name", ["delivery", "tiles", "skateboard"])
def test_exact_vi_matches_shortest_paths(name: str) -> None:
    dom = load(name)
    b = compile_domain(dom)
    rng = np.random.default_rng(1)
    # True weights plus random all-negative weights (always bounded).
    W = np.vstack([dom.weights, -np.abs(rng.normal(size=(3, 3)))])
    envs = rng.choice(b.E, min(b.E, 4), replace=False)
    vals = value_iteration(b, W, env=envs)
    assert vals.Q.shape == (len(envs), 4, b.S, b.A)
    for i, e in enumerate(envs):
        n = int(b.n_states[e])
        for m in range(4):
            if not _has_positive_cycle(b, e, W[m]):
                assert vals.bounded[i, m]
                np.testing.assert_allclose(vals.V[i, m, :n], _graph_values(b, e, W[m]),
                                           rtol=1e-12, atol=1e-12)
                assert vals.V[i, m, b.sink] == 0.0


@pytest.mark.parametrize("name", ["delivery", "tiles", "skateboard"])
def test_reference_and_exact_agree_on_true_weights(name: str) -> None:
    dom = load(name)
    b = compile_domain(dom)
    ex = value_iteration(b, dom.weights)
    ref = value_iteration(b, dom.weights, method="reference")
    assert ex.bounded.all() and ref.bounded.all()
    valid = b.valid[:, None, :]
    assert np.array_equal(np.where(valid, ex.V, 0), np.where(valid, ref.V, 0))
    assert (ref.sweeps < 1000).all()


def test_cheap_noop_weight_reference_says_unbounded_exact_solves() -> None:
    """Spec §3 trap: cheap pickup/dropoff makes the reference hit its sweep cap."""
    dom = load("skateboard")
    b = compile_domain(dom)
    w = np.array([-0.00124, -0.788, -0.616])
    ref = value_iteration(b, w, method="reference")
    ex = value_iteration(b, w)
    assert not ref.bounded[b.n_states > 100].any()  # instances with a skateboard
    assert (ref.sweeps[~ref.bounded] == 1000).all()
    assert ex.bounded.all()
    for e in range(b.E):
        n = int(b.n_states[e])
        np.testing.assert_allclose(ex.V[e, 0, :n], _graph_values(b, e, w), rtol=1e-12)


def test_positive_mud_weight_unbounded_under_both() -> None:
    dom = load("delivery")
    b = compile_domain(dom)
    w = np.array([0.5, 0.1, -0.1])
    ex = value_iteration(b, w)
    ref = value_iteration(b, w, method="reference")
    has_mud = np.array([any(i.env_code[:5]) for i in b.instances])
    truth = np.array([_has_positive_cycle(b, e, w) for e in range(b.E)])
    assert np.array_equal(truth, has_mud)
    assert np.array_equal(ex.bounded[:, 0], ~has_mud)
    assert np.array_equal(ref.bounded[:, 0], ~has_mud)
    assert np.isposinf(ex.V[has_mud, 0][:, 0]).all()


def test_positive_step_weight_unbounded() -> None:
    b = compile_domain(load("tiles"))
    ex = value_iteration(b, np.array([-1.0, -1.0, 0.1]), env=[0, 5])
    assert not ex.bounded.any() and (ex.sweeps == 0).all()


def test_random_weights_boundedness_matches_bellman_ford() -> None:
    dom = load("tiles")
    b = compile_domain(dom)
    rng = np.random.default_rng(7)
    W = rng.normal(size=(12, 3))
    W[:, 2] = -np.abs(W[:, 2])  # keep no-ops non-positive so cycles come from tiles
    envs = rng.choice(b.E, 10, replace=False)
    ex = value_iteration(b, W, env=envs)
    for i, e in enumerate(envs):
        for m in range(len(W)):
            assert ex.bounded[i, m] == (not _has_positive_cycle(b, e, W[m])), (e, W[m])


# ----------------------------------------------------------- brute force, tiny
def _tiny() -> dict:
    return {
        "domain": {"name": "tiny", "width": 3, "height": 2},
        "cells": {"mud": [[2, 1]]},
        "agent": {"start": [1, 1]},
        "goal": {"agent_at": [3, 2]},
        "features": [
            {"name": "mud", "weight": -1.0, "when": {"leaves_cells": "mud"}},
            {"name": "up", "weight": 0.3, "when": {"action": ["up"], "moved": True}},
            {"name": "step", "weight": -1.0},
        ],
    }


def _brute_force(batch, e: int, w: np.ndarray) -> tuple[np.ndarray | None, bool]:
    """Best reward over all simple paths to the terminal; positive simple cycle?"""
    n = int(batch.n_states[e])
    r = batch.features[e, :n] @ w
    nxt = batch.next_state[e, :n]
    best = np.full(n, -np.inf)
    pos_cycle = False

    def dfs(start: int, s: int, visited: tuple[int, ...], total: float) -> None:
        nonlocal pos_cycle
        for a in range(batch.A):
            t = int(nxt[s, a])
            if t == batch.sink:
                best[start] = max(best[start], total + r[s, a])
            elif t == start and total + r[s, a] > 1e-12:
                pos_cycle = True
            elif t not in visited:
                dfs(start, t, (*visited, t), total + r[s, a])

    for s in range(n):
        dfs(s, s, (s,), 0.0)
    return best, pos_cycle


@pytest.mark.parametrize("seed", range(6))
def test_exact_vi_matches_brute_force_on_tiny_domain(seed: int) -> None:
    dom = from_dict(_tiny())
    b = compile_domain(dom)
    rng = np.random.default_rng(seed)
    W = rng.normal(size=(8, 3))
    W[:, 2] = -np.abs(W[:, 2]) - 0.05
    vals = value_iteration(b, W)
    for m in range(len(W)):
        best, cyc = _brute_force(b, 0, W[m])
        assert vals.bounded[0, m] == (not cyc)
        if not cyc:
            np.testing.assert_allclose(vals.V[0, m, : b.n_states[0]], best, rtol=1e-12)


def test_vi_rejects_bad_weights() -> None:
    b = compile_domain(load("skateboard"))
    with pytest.raises(ValueError, match=r"shape \[M, 3\]"):
        value_iteration(b, np.ones((2, 4)))
    with pytest.raises(ValueError, match="NaN"):
        value_iteration(b, np.array([np.nan, 0, -1]))
    with pytest.raises(ValueError, match="method"):
        value_iteration(b, np.array([0, 0, -1.0]), method="fast")
    with pytest.raises(IndexError, match="0..7"):
        value_iteration(b, np.array([0, 0, -1.0]), env=[9])


def test_chunking_gives_identical_results() -> None:
    dom = load("delivery")
    b = compile_domain(dom)
    rng = np.random.default_rng(3)
    W = rng.normal(size=(20, 3))
    big = value_iteration(b, W, env=range(0, 64, 5))
    small = value_iteration(b, W, env=range(0, 64, 5), chunk_bytes=2e5)
    assert np.array_equal(big.bounded, small.bounded)
    assert np.array_equal(big.V, small.V)
    for method in ("reference",):
        a = value_iteration(b, W[:6], env=[1, 2, 40], method=method)
        c = value_iteration(b, W[:6], env=[1, 2, 40], method=method, chunk_bytes=1e5)
        assert np.array_equal(a.V, c.V) and np.array_equal(a.sweeps, c.sweeps)


# --------------------------------------------------------------- policy helpers
def test_greedy_first_argmax_and_ties() -> None:
    Q = np.array([[1.0, 3.0, 3.0, 2.999995, -1.0, 3.0]])
    assert greedy_actions(Q).tolist() == [1]
    assert tied_actions(Q).tolist() == [[False, True, True, True, False, True]]
    Q2 = np.array([3.0, np.nextafter(3.0, 4.0), 3.0])
    assert greedy_actions(Q2) == 1  # the ulp-larger one wins
    assert tied_actions(Q2).all()


def _pair_layout(b, W: np.ndarray) -> tuple[np.ndarray, ...]:  # noqa: ANN001
    """R, nxt ``[P, A, S]`` and valid ``[P, S]`` per (instance, model) pair, built directly."""
    R = np.einsum("esaf,mf->emas", b.features, W).reshape(-1, b.A, b.S)
    nxt = np.broadcast_to(b.next_state[:, None].transpose(0, 1, 3, 2),
                          (b.E, len(W), b.A, b.S)).reshape(-1, b.A, b.S)
    valid = np.broadcast_to(b.valid[:, None], (b.E, len(W), b.S)).reshape(-1, b.S)
    return R, nxt, valid


def test_reference_shortcut_matches_full_reference_sweeps() -> None:
    """Skipping proven-divergent pairs does not change the reference's flags or values."""
    from cfteach.mdp.vi import _solve_reference

    dom = load("delivery")
    b = compile_domain(dom).subset([0, 9, 33, 63])
    rng = np.random.default_rng(11)
    W = rng.normal(size=(10, 3))
    W[:5, 2] = -np.abs(W[:5, 2])
    vals = value_iteration(b, W, method="reference")
    R, nxt, _ = _pair_layout(b, W)
    v, bnd, sw = _solve_reference(R, nxt)
    assert np.array_equal(vals.bounded.ravel(), bnd)
    assert np.array_equal(vals.sweeps.ravel(), sw)
    assert 0 < bnd.mean() < 1
    np.testing.assert_array_equal(vals.V.reshape(-1, b.S)[bnd], v[bnd])


def test_skip_unstable_keeps_reference_flags_and_sweeps() -> None:
    """Cheap no-op models take > 1000 reference sweeps; skipping them changes no flag or
    sweep count, and bounded pairs keep exactly the swept values."""
    from cfteach.mdp.vi import _cannot_stabilise

    dom = load("delivery")
    b = compile_domain(dom).subset([0, 9, 33, 63])
    W = np.array([[-0.00124, -0.788, -0.616], [-0.999, -0.003, -0.0016], [-0.3, -0.3, -0.9],
                  [0.2, -0.5, -0.8]])
    full = value_iteration(b, W, method="reference")
    fast = value_iteration(b, W, method="reference", skip_unstable=True)
    assert np.array_equal(full.bounded, fast.bounded)
    assert np.array_equal(full.sweeps, fast.sweeps)
    np.testing.assert_array_equal(fast.V[fast.bounded], full.V[full.bounded])
    exact = value_iteration(b, W, method="exact")
    R, nxt, valid = _pair_layout(b, W)
    stuck = _cannot_stabilise(R, nxt, valid, exact.V.reshape(-1, b.S)).reshape(b.E, len(W))
    assert stuck.any() and exact.bounded[stuck].all()  # the shortcut is exercised
    assert not full.bounded[stuck].any() and (full.sweeps[stuck] == 1000).all()
    np.testing.assert_array_equal(fast.V[stuck], exact.V[stuck])  # documented: true values
