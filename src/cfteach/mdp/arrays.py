"""Compile domain instances to padded numpy arrays (`MDPBatch`) that planning works on.

All instances of a batch share one state axis of length `S` = (most states of any instance)
+ 1. Index `S - 1` is a shared *terminal sink*: every transition into a terminal state points
at it, and it loops on itself with zero features, so a terminal has value 0 without special
cases. Padding states (between an instance's last state and the sink) also loop on
themselves with zero features and are marked invalid.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cfteach.domains import Domain, Instance, State
from cfteach.domains.dynamics import Layout, explore


@dataclass(frozen=True, eq=False)
class MDPBatch:
    """E deterministic MDPs over a common padded state axis.

    Attributes:
        next_state: int64 ``[E, S, A]`` successor index (``S - 1`` = terminal sink).
        features: float64 ``[E, S, A, F]`` per-transition features phi(s, a, s').
        valid: bool ``[E, S]`` real (reachable, non-terminal) states.
        n_states: int64 ``[E]`` number of real states; they occupy indices ``0..n-1``.
        states: per instance, the list of states (position = state index).
        state_index: per instance, a dict State -> index.
        instances: the compiled instances, in batch order.
    """

    next_state: np.ndarray
    features: np.ndarray
    valid: np.ndarray
    n_states: np.ndarray
    states: tuple[tuple[State, ...], ...]
    state_index: tuple[dict[State, int], ...]
    instances: tuple[Instance, ...]
    actions: tuple[str, ...]
    feature_names: tuple[str, ...]

    @property
    def E(self) -> int:  # noqa: N802 - array-shape names read best in capitals
        return self.next_state.shape[0]

    @property
    def S(self) -> int:  # noqa: N802
        return self.next_state.shape[1]

    @property
    def A(self) -> int:  # noqa: N802
        return self.next_state.shape[2]

    @property
    def F(self) -> int:  # noqa: N802
        return self.features.shape[3]

    @property
    def sink(self) -> int:
        """Index of the shared terminal sink state."""
        return self.S - 1

    def index_of(self, env: int, state: State) -> int:
        """State index of a non-terminal state of instance `env` (KeyError if not reachable)."""
        try:
            return self.state_index[env][state]
        except KeyError:
            raise KeyError(f"state {state} is not a reachable non-terminal state of "
                           f"{self.instances[env]!r}") from None

    def subset(self, env: int | Sequence[int] | np.ndarray) -> MDPBatch:
        """The batch restricted to some instances (same padded S, so indices stay valid)."""
        idx = np.atleast_1d(np.asarray(env, dtype=np.int64))
        if idx.ndim != 1 or (idx.size and (idx.min() < 0 or idx.max() >= self.E)):
            raise IndexError(f"instance indices must lie in 0..{self.E - 1}, got {env!r}")
        return MDPBatch(
            next_state=self.next_state[idx], features=self.features[idx],
            valid=self.valid[idx], n_states=self.n_states[idx],
            states=tuple(self.states[i] for i in idx),
            state_index=tuple(self.state_index[i] for i in idx),
            instances=tuple(self.instances[i] for i in idx),
            actions=self.actions, feature_names=self.feature_names,
        )

    def rewards(self, w: np.ndarray) -> np.ndarray:
        """r[E, S, A] = features . w for one weight vector."""
        return self.features @ np.asarray(w, dtype=float)


#: Instances explored together: bounds the search's working memory (cell masks, one layer).
CHUNK_INSTANCES = 1024


def compile_instances(instances: Sequence[Instance]) -> MDPBatch:
    """Tabulate successors and features of every reachable state of every instance.

    The reachable states and their transitions come from one vectorised breadth-first search
    per chunk of instances (`cfteach.domains.dynamics.explore`): same state order, indices
    and features as stepping `Instance.step` state by state, each transition computed once.
    """
    if not instances:
        raise ValueError("compile_instances needs at least one instance")
    dom = instances[0].domain
    if any(inst.domain is not dom for inst in instances):
        raise ValueError("all instances of a batch must come from the same domain object")
    parts = []
    for lo in range(0, len(instances), CHUNK_INSTANCES):
        chunk = instances[lo:lo + CHUNK_INSTANCES]
        lay = Layout(chunk)
        parts.append((lo, explore(lay, np.array([i.initial_state for i in chunk],
                                                dtype=np.int64))))
    n = np.array([len(st) for _, found in parts for st in found.states], dtype=np.int64)
    e_count, s_count, a_count, f_count = len(instances), int(n.max()) + 1, len(dom.actions), \
        dom.n_features
    sink = s_count - 1
    nxt = np.tile(np.arange(s_count, dtype=np.int64)[None, :, None], (e_count, 1, a_count))
    feats = np.zeros((e_count, s_count, a_count, f_count))
    valid = np.arange(s_count)[None, :] < n[:, None]
    states: list[tuple[State, ...]] = []
    for lo, found in parts:
        e = found.row + lo
        nxt[e, found.src, found.action] = np.where(found.dest < 0, sink, found.dest)
        feats[e, found.src, found.action] = found.phi
        for r, st in enumerate(found.states):
            tup = tuple(map(tuple, st.tolist()))
            states.append(tup)
            instances[lo + r].__dict__.setdefault("_states", tup)  # Instance.states() cache
    index = [{s: i for i, s in enumerate(st)} for st in states]
    for arr in (nxt, feats, valid, n):
        arr.setflags(write=False)
    return MDPBatch(next_state=nxt, features=feats, valid=valid, n_states=n,
                    states=tuple(states), state_index=tuple(index),
                    instances=tuple(instances), actions=dom.actions,
                    feature_names=dom.feature_names)


_CACHE: weakref.WeakKeyDictionary[Domain, MDPBatch] = weakref.WeakKeyDictionary()


def compile_domain(domain: Domain) -> MDPBatch:
    """All instances of a domain as one batch, cached per domain object."""
    batch = _CACHE.get(domain)
    if batch is None:
        batch = compile_instances(domain.instances())
        _CACHE[domain] = batch
    return batch
