"""Per-step choice data for the noisy learner model (`cfteach.closedloop.noisy_belief`):
`StepData`, and the helpers that build it.

A learner in state ``s`` weighs each action ``a`` by ``Q_w(s, a) = w . Psi(s, a)`` where
``Psi(s, a)`` is `DemoSet.dev_mu`: the feature counts of taking ``a`` and then following the
robot's optimal policy. These helpers turn an answer's moves, or a test's optimal path,
into those rows, grouped by state; the robot's own action values (`DemoSet.Q`) mark which
actions are optimal.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from cfteach.bec.demos import DemoSet

#: Two action values within this of each other are tied (both optimal).
Q_TIE = 1e-9


class StepData:
    """Per-step choice data of some states: for each state (a group) the rows ``Psi(s, a)``
    of its A actions (``rows [G, A, F]``), how often each was taken (``counts [G, A]``) or
    which are optimal (``optimal [G, A]``). ``alt [G, F]`` / ``alt_action [G]`` (-1: none)
    give a plan the learner is known to have for one action of a group (the rest of their
    own finished answer): ``Q_w(s, a)`` is the better of ``w . Psi(s, a)`` and ``w . alt``,
    as both are plans that start with ``a``."""

    def __init__(self, rows: np.ndarray, counts: np.ndarray | None = None,
                 optimal: np.ndarray | None = None, alt: np.ndarray | None = None,
                 alt_action: np.ndarray | None = None) -> None:
        self.rows = np.asarray(rows, dtype=np.float64)
        if self.rows.ndim != 3:
            raise ValueError(f"StepData rows: expected shape [G, A, F], got {self.rows.shape}")
        self.counts = None if counts is None else np.asarray(counts, dtype=np.float64)
        self.optimal = None if optimal is None else np.asarray(optimal, dtype=bool)
        self.alt = None if alt is None else np.asarray(alt, dtype=np.float64)
        self.alt_action = None if alt_action is None else np.asarray(alt_action, np.int64)

    def x(self, points: np.ndarray) -> np.ndarray:
        """``Q_w(s, a)`` for every point, state and action: ``[P, G, A]``."""
        x = np.einsum("pf,gaf->pga", points, self.rows, optimize=True)
        if self.alt is not None and self.alt_action is not None and len(self.alt):
            g = np.flatnonzero(self.alt_action >= 0)
            a = self.alt_action[g]
            x[:, g, a] = np.maximum(x[:, g, a], points @ self.alt[g].T)
        return x

    @classmethod
    def of(cls, entry: dict[str, Any]) -> StepData:
        return cls(entry["rows"], entry.get("counts"), entry.get("optimal"), entry.get("alt"),
                   entry.get("alt_action"))

    def to_json(self) -> dict[str, Any]:
        return {"rows": self.rows, "counts": self.counts, "optimal": self.optimal,
                "alt": self.alt, "alt_action": self.alt_action}


def log_normaliser(logits: np.ndarray) -> np.ndarray:
    """``log sum_a exp(logits[p, g, a])`` ``[P, G]``: the largest logit taken out first (no
    overflow), then one vectorised exp per action slice. `np.logaddexp.reduce` over the
    short last axis gives the same numbers to about 1e-14 but costs a scalar exp and log1p
    per element, in a strided loop: this is the answer term's whole cost, 2-3x less here."""
    top = logits[:, :, 0].copy()
    for a in range(1, logits.shape[2]):
        np.maximum(top, logits[:, :, a], out=top)
    total = np.zeros_like(top)
    term = np.empty_like(top)
    for a in range(logits.shape[2]):
        np.subtract(logits[:, :, a], top, out=term)
        np.exp(term, out=term)
        total += term
    return top + np.log(total)


class Taken(NamedTuple):
    """Which actions an answer's states saw taken, for `taken_log_policy`: the states where
    one action was taken (``one``: state, action, count) and where several (or none) were
    (``many``); ``need``/``pos`` and ``many_rows`` map them to the rows of ``x`` (the
    distinct groups of `distinct_steps`; without sharing, the states themselves)."""

    one: np.ndarray
    one_action: np.ndarray
    one_count: np.ndarray
    many: np.ndarray
    need: np.ndarray
    pos: np.ndarray
    many_rows: np.ndarray


def taken_actions(counts: np.ndarray, group: np.ndarray | None = None) -> Taken:
    """`Taken` of `counts` ``[G, A]``; `group` ``[G]``: each state's row of ``x`` when
    states share rows (`distinct_steps`), None when ``x`` has one row per state."""
    n_taken = (counts != 0).sum(axis=1)
    one = np.flatnonzero(n_taken == 1)
    many = np.flatnonzero(n_taken != 1)
    act = np.argmax(counts[one] != 0, axis=1) if len(one) else np.zeros(0, np.int64)
    if group is None:
        return Taken(one, act, counts[one, act], many, one, np.arange(len(one)), many)
    need, pos = np.unique(group[one], return_inverse=True)
    return Taken(one, act, counts[one, act], many, need, pos.astype(np.int64), group[many])


def distinct_steps(entries: Sequence[dict[str, Any]]) -> tuple[StepData, np.ndarray]:
    """The distinct groups (rows and known plan) of several answers' step data, and each
    group's index among them ``[G]``. A noisy learner revisits the same states in answer
    after answer: 10-30% of the groups of a long session repeat, and ``x`` and its
    normaliser need computing once per distinct group."""
    rows = np.concatenate([np.asarray(e["rows"], np.float64) for e in entries])
    G, A, F = rows.shape
    alt = np.zeros((G, F))
    act = np.full(G, -1, np.int64)
    at = 0
    for e in entries:
        n = len(e["rows"])
        if e.get("alt") is not None and e.get("alt_action") is not None:
            alt[at:at + n], act[at:at + n] = e["alt"], e["alt_action"]
        at += n
    alt[act < 0] = 0.0  # a plan for no action is no plan
    key = np.hstack([rows.reshape(G, A * F), alt, act[:, None].astype(np.float64)])
    _, first, group = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return StepData(rows[first], alt=alt[first], alt_action=act[first]), group.ravel()


def with_lapse(logp: np.ndarray, n_actions: int, lapse: float) -> np.ndarray:
    """``log((1 - lapse) * pi + lapse / A)`` from ``log pi`` (<= 0): vectorised exp and
    log, a few times cheaper than `np.logaddexp` and as exact (``pi`` lies in [0, 1])."""
    return np.log((1 - lapse) * np.exp(logp) + lapse / n_actions)


def log_policy(x: np.ndarray, beta: np.ndarray, lapse: float) -> np.ndarray:
    """``log pi(a | s)`` ``[P, G, A]`` from ``x = w . Psi(s, a)`` ``[P, G, A]``: Boltzmann at
    rationality ``beta [P]``, mixed with a random move at rate `lapse`."""
    logits = beta[:, None, None] * x
    logp = logits - log_normaliser(logits)[:, :, None]
    return with_lapse(logp, x.shape[2], lapse) if lapse > 0 else logp


def taken_log_policy(x: np.ndarray, beta: np.ndarray, counts: np.ndarray, taken: Taken,
                     lapse: float) -> np.ndarray:
    """``[P, G]``: ``sum_a counts[g, a] * log pi(a | s_g)``, the same numbers as
    ``(log_policy(x, beta, lapse) * counts).sum(2)`` (bit for bit) at a fraction of the
    cost: the lapse mixture only at the actions taken in a state where one action was
    taken (the other terms are zeros), the normaliser once per row of `x` those states
    use; states with several actions taken go the long way."""
    out = np.empty((len(x), len(counts)))
    if len(taken.one):
        # `need` is sorted: all of x's rows means no copy of x.
        xs = x if len(taken.need) == x.shape[1] else x[:, taken.need, :]
        logits = beta[:, None, None] * xs
        logp = logits[:, taken.pos, taken.one_action] - log_normaliser(logits)[:, taken.pos]
        if lapse > 0:
            logp = with_lapse(logp, x.shape[2], lapse)
        if not len(taken.many):
            return logp * taken.one_count[None]
        out[:, taken.one] = logp * taken.one_count[None]
    if len(taken.many):
        out[:, taken.many] = (log_policy(x[:, taken.many_rows], beta, lapse)
                              * counts[taken.many][None]).sum(2)
    return out


def answer_steps(ds: DemoSet, env: int, states: Sequence[int], actions: Sequence[int],
                 finished: bool = False) -> StepData:
    """The moves of one answer in instance `env`. A finished answer is scored step by
    step, each move's value also seen through the rest of the learner's own path (a plan
    they had: `StepData.alt`); an unfinished one (a wander) by one group per distinct
    state visited, counting how often each action was taken there."""
    if len(states) != len(actions):
        raise ValueError(f"{len(states)} states for {len(actions)} actions")
    A = ds.batch.A
    if finished and len(states):
        st, ac = np.asarray(states, np.int64), np.asarray(actions, np.int64)
        phi = ds.batch.features[env, st, ac].astype(float)          # [T, F]
        suffix = np.cumsum(phi[::-1], axis=0)[::-1]
        counts = np.zeros((len(st), A))
        counts[np.arange(len(st)), ac] = 1
        return StepData(ds.dev_mu[env, st].astype(float), counts, alt=suffix, alt_action=ac)
    order: dict[int, int] = {}
    counts_l: list[np.ndarray] = []
    for s, a in zip(states, actions, strict=True):
        g = order.setdefault(int(s), len(order))
        if g == len(counts_l):
            counts_l.append(np.zeros(A))
        counts_l[g][int(a)] += 1
    if not order:
        return StepData(np.zeros((0, A, ds.F)), np.zeros((0, A)))
    visited = np.fromiter(order, dtype=np.int64)
    return StepData(ds.dev_mu[env, visited].astype(float), np.vstack(counts_l))


def path_steps(ds: DemoSet, demos: Sequence[int] | np.ndarray
               ) -> tuple[StepData, np.ndarray]:
    """The robot's optimal path of each demo (a test's start): one group per state along
    it, with its optimal actions marked; and where each demo's groups start."""
    rows: list[np.ndarray] = []
    optimal: list[np.ndarray] = []
    test_starts: list[int] = []
    for d in demos:
        env = int(ds.env[d])
        states = ds.states[d, :int(ds.length[d])]
        test_starts.append(len(rows))
        for s in states.tolist():
            q = ds.Q[env, s]
            rows.append(ds.dev_mu[env, s])
            optimal.append(q >= q.max() - Q_TIE * max(1.0, abs(q.max())))
    if not rows:
        raise ValueError("path_steps: no state to score (empty demos)")
    return (StepData(np.stack(rows).astype(float), None, np.stack(optimal)),
            np.array(test_starts, dtype=np.int64))
