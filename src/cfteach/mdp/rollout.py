"""Greedy rollouts the way the authors' code makes them (docs/domains.md, "Policies and
rollouts"), batched and one at a time.

A rollout starts at a state, optionally takes one forced first action, then follows the
greedy policy. It stops at a terminal state, after `max_steps` steps in total (the forced
step counts), or once the policy has stepped onto the same state more than `max_self_loops`
times (the reference's self-loop counter, counted over the whole rollout).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cfteach.domains import Instance, State
from cfteach.mdp.arrays import MDPBatch

MAX_STEPS = 25
MAX_SELF_LOOPS = 5


@dataclass(frozen=True, eq=False)
class Rollouts:
    """Batched rollouts from every state (and every forced first action, if asked).

    Shapes use ``...`` = ``[E, M, S]``, or ``[E, M, S, A]`` with ``first_action="all"``.

    Attributes:
        mu: ``[..., F]`` summed features of each rollout (integer-valued floats).
        length: ``[...]`` number of steps taken (0 for padding and sink start states).
        terminal: ``[...]`` whether the rollout ended in a terminal state.
        states: ``[..., max_steps + 1]`` visited state indices (``S - 1`` = terminal sink,
            -1 after the end); only with ``return_paths=True``.
        actions: ``[..., max_steps]`` actions taken (-1 after the end); only with paths.
    """

    mu: np.ndarray
    length: np.ndarray
    terminal: np.ndarray
    states: np.ndarray | None = None
    actions: np.ndarray | None = None


def rollout_features(
    batch: MDPBatch,
    policy: np.ndarray,
    first_action: int | str | None = None,
    max_steps: int = MAX_STEPS,
    *,
    max_self_loops: int = MAX_SELF_LOOPS,
    return_paths: bool = False,
) -> Rollouts:
    """Roll out the greedy `policy[E, M, S]` (or ``[E, S]``) from every state at once.

    `first_action`: None (pure policy), an action index forced first, or ``"all"`` for one
    rollout per forced first action (an extra axis A before F).
    """
    policy = np.asarray(policy)
    squeeze_m = policy.ndim == 2
    if squeeze_m:
        policy = policy[:, None, :]
    if policy.ndim != 3 or policy.shape[0] != batch.E or policy.shape[2] != batch.S:
        raise ValueError(f"policy must have shape [E={batch.E}, M, S={batch.S}] or [E, S], "
                         f"got {np.shape(policy)}")
    if max_steps < 1:
        raise ValueError(f"max_steps must be at least 1, got {max_steps}")
    e_n, m_n, s_n = policy.shape
    a_n, f_n = batch.A, batch.F
    if first_action is None:
        extra: tuple[int, ...] = ()
        forced = None
    elif first_action == "all":
        extra = (a_n,)
        forced = np.broadcast_to(np.arange(a_n), (e_n, m_n, s_n, a_n))
    else:
        if not (isinstance(first_action, int | np.integer) and 0 <= first_action < a_n):
            raise ValueError(f"first_action must be None, 'all' or an action index 0..{a_n - 1}"
                             f", got {first_action!r}")
        extra = ()
        forced = np.full((e_n, m_n, s_n), int(first_action))
    shape = (e_n, m_n, s_n, *extra)
    n = int(np.prod(shape))
    grid = np.indices(shape).reshape(len(shape), n)
    e, m, cur = grid[0], grid[1], grid[2].copy()
    out = _roll(batch, policy.reshape(e_n * m_n, s_n), e, e * m_n + m, cur,
                None if forced is None else forced.reshape(n), max_steps, max_self_loops,
                return_paths)
    return _shaped(out, shape, f_n, max_steps)


def rollout_from(
    batch: MDPBatch,
    policy: np.ndarray,
    env: int,
    starts: np.ndarray,
    first_action: np.ndarray | None = None,
    max_steps: int = MAX_STEPS,
    *,
    max_self_loops: int | None = MAX_SELF_LOOPS,
) -> Rollouts:
    """Rollouts of M policies ``policy[M, S]`` in ONE instance `env`, from chosen start
    states ``starts[M, K]`` (or ``[K]`` for every policy), optionally forcing
    ``first_action[M, K]``. Same rules as `rollout_features` (shapes ``[M, K]``), plus:
    a negative policy entry ends the rollout there (not terminal), and
    ``max_self_loops=None`` turns the self-loop counter off."""
    policy = np.asarray(policy)
    if policy.ndim != 2 or policy.shape[1] != batch.S:
        raise ValueError(f"policy must have shape [M, S={batch.S}], got {policy.shape}")
    if not 0 <= int(env) < batch.E:
        raise ValueError(f"env must be an instance index 0..{batch.E - 1}, got {env}")
    if max_steps < 1:
        raise ValueError(f"max_steps must be at least 1, got {max_steps}")
    m_n = policy.shape[0]
    starts = np.asarray(starts, dtype=np.int64)
    if starts.ndim == 1:
        starts = np.broadcast_to(starts, (m_n, starts.size))
    if starts.ndim != 2 or starts.shape[0] != m_n:
        raise ValueError(f"starts must have shape [M={m_n}, K] or [K], got {starts.shape}")
    if starts.size and (starts.min() < 0 or starts.max() >= batch.S):
        raise ValueError(f"start state indices must lie in 0..{batch.S - 1}")
    shape = starts.shape
    n = starts.size
    forced = None
    if first_action is not None:
        forced = np.broadcast_to(np.asarray(first_action, dtype=np.int64), shape).reshape(n)
        if n and (forced.min() < 0 or forced.max() >= batch.A):
            raise ValueError(f"first actions must lie in 0..{batch.A - 1}")
    e = np.full(n, int(env), dtype=np.int64)
    em = np.repeat(np.arange(m_n), shape[1])
    out = _roll(batch, policy, e, em, starts.reshape(n).copy(), forced, max_steps,
                max_self_loops, False)
    return _shaped(out, shape, batch.F, max_steps)


def _roll(batch: MDPBatch, pol: np.ndarray, e: np.ndarray, em: np.ndarray, cur: np.ndarray,
          forced: np.ndarray | None, max_steps: int, max_self_loops: int | None,
          return_paths: bool) -> tuple:
    """The rollout loop on n flat rollouts: instance ``e[n]``, policy row ``em[n]`` of
    ``pol[rows, S]``, start ``cur[n]`` (updated in place), forced first action ``forced[n]``.
    Returns ``(mu [n, F], length [n], terminal [n], states | None, actions | None)``."""
    n, f_n, sink = len(cur), batch.F, batch.sink
    nxt_tab, feat_tab = batch.next_state, batch.features
    stops = bool(pol.size) and pol.min() < 0  # negative entries end a rollout
    mu = np.zeros((n, f_n))
    length = np.zeros(n, dtype=np.int64)
    loops = np.zeros(n, dtype=np.int64)
    alive = batch.valid[e, cur].copy()
    paths_s = paths_a = None
    if return_paths:
        paths_s = np.full((n, max_steps + 1), -1, dtype=np.int32)
        paths_a = np.full((n, max_steps), -1, dtype=np.int8)
        paths_s[alive, 0] = cur[alive]

    def take(ids: np.ndarray, act: np.ndarray, count_loops: bool) -> None:
        s = cur[ids]
        s2 = nxt_tab[e[ids], s, act]
        mu[ids] += feat_tab[e[ids], s, act]
        if paths_s is not None and paths_a is not None:  # return_paths
            paths_a[ids, length[ids]] = act
            paths_s[ids, length[ids] + 1] = s2
        length[ids] += 1
        if count_loops:
            loops[ids] += s2 == s
        cur[ids] = s2

    ids = np.flatnonzero(alive)
    if forced is not None:
        take(ids, forced[ids], count_loops=False)
    while True:
        keep = (cur[ids] != sink) & (length[ids] < max_steps)
        if max_self_loops is not None:
            keep &= loops[ids] <= max_self_loops
        ids = ids[keep]
        if not ids.size:
            break
        act = pol[em[ids], cur[ids]]
        if stops:
            go = act >= 0
            ids, act = ids[go], act[go]
            if not ids.size:
                break
        take(ids, act, count_loops=max_self_loops is not None)
    return mu, length, cur == sink, paths_s, paths_a


def _shaped(out: tuple, shape: tuple[int, ...], f_n: int, max_steps: int) -> Rollouts:
    mu, length, terminal, paths_s, paths_a = out
    return Rollouts(
        mu=mu.reshape(*shape, f_n), length=length.reshape(shape),
        terminal=terminal.reshape(shape),
        states=None if paths_s is None else paths_s.reshape(*shape, max_steps + 1),
        actions=None if paths_a is None else paths_a.reshape(*shape, max_steps),
    )


@dataclass(frozen=True, eq=False)
class Trajectory:
    """One trajectory with its real states (terminal states included, not the sink)."""

    instance: Instance
    states: tuple[State, ...]  # len(actions) + 1
    actions: tuple[int, ...]
    phi: np.ndarray  # [T, F] per-step features
    terminal: bool

    @property
    def mu(self) -> np.ndarray:
        """Summed features (feature counts)."""
        return self.phi.sum(axis=0) if len(self.actions) else np.zeros(self.phi.shape[1])

    @property
    def action_names(self) -> list[str]:
        return [self.instance.domain.actions[a] for a in self.actions]

    def reward(self, w: np.ndarray) -> float:
        """w . mu, computed like the reference (dot product of the feature counts)."""
        return float(np.asarray(w, dtype=float).dot(self.mu))


def replay(instance: Instance, start: State, actions: Sequence[int | str]) -> Trajectory:
    """Replay actions (indices or names) from a state; stops early at a terminal state."""
    names = instance.domain.actions
    states = [start]
    acts: list[int] = []
    phis: list[np.ndarray] = []
    terminal = instance.is_terminal(start)
    for a in actions:
        if terminal:
            break
        ai = names.index(a) if isinstance(a, str) else int(a)
        if not 0 <= ai < len(names):
            raise ValueError(f"action index {ai} out of range 0..{len(names) - 1}")
        s2, phi, terminal = instance.step(states[-1], ai)
        states.append(s2)
        acts.append(ai)
        phis.append(phi)
    phi_arr = np.array(phis) if phis else np.zeros((0, instance.domain.n_features))
    return Trajectory(instance, tuple(states), tuple(acts), phi_arr, terminal)


def rollout(
    batch: MDPBatch,
    policy: np.ndarray,
    env: int,
    start: State | int,
    first_action: int | str | None = None,
    *,
    model: int = 0,
    max_steps: int = MAX_STEPS,
    max_self_loops: int = MAX_SELF_LOOPS,
) -> Trajectory:
    """One reference rollout from `start` in instance `env` of the batch.

    `policy` is ``[S]``, ``[E, S]`` or ``[E, M, S]`` (then `model` picks M); `start` is a State
    or its index; `first_action` an action index or name.
    """
    policy = np.asarray(policy)
    if policy.ndim == 3:
        policy = policy[env, model]
    elif policy.ndim == 2:
        policy = policy[env]
    inst = batch.instances[env]
    names = batch.actions
    state = batch.states[env][start] if isinstance(start, int | np.integer) else tuple(start)
    if isinstance(first_action, str):
        first_action = names.index(first_action)
    states, acts, phis = [state], [], []
    terminal = inst.is_terminal(state)

    def step(a: int) -> None:
        nonlocal terminal
        s2, phi, terminal = inst.step(states[-1], a)
        states.append(s2)
        acts.append(a)
        phis.append(phi)

    if first_action is not None and not terminal:
        step(int(first_action))
    loops = 0
    while not terminal and len(acts) < max_steps and loops <= max_self_loops:
        s = states[-1]
        step(int(policy[batch.index_of(env, s)]))
        loops += states[-1] == s
    phi_arr = np.array(phis) if phis else np.zeros((0, batch.F))
    return Trajectory(inst, tuple(states), tuple(acts), phi_arr, terminal)
