"""Per-step choice data for the noisy learner model (`cfteach.closedloop.noisy_belief`).

A learner in state ``s`` weighs each action ``a`` by ``Q_w(s, a) = w . Psi(s, a)`` where
``Psi(s, a)`` is `DemoSet.dev_mu`: the feature counts of taking ``a`` and then following the
robot's optimal policy. These helpers turn an answer's moves, or a test's optimal path,
into those rows, grouped by state; the robot's own action values (`DemoSet.Q`) mark which
actions are optimal.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cfteach.bec.demos import DemoSet
from cfteach.closedloop.noisy_belief import StepData

#: Two action values within this of each other are tied (both optimal).
Q_TIE = 1e-9


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
