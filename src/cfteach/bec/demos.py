"""The universe of candidate demonstrations of a domain (the paper's Xi, Section III), as flat
arrays.

A demonstration is the greedy rollout under the true weights from one reachable state of one
instance (the authors' rollout rules: docs/domains.md, "Policies and rollouts"). Every
(instance, state) pair gives one candidate, so a domain has thousands; keeping them as arrays
lets constraints, gains and overlaps be computed for all of them at once. Demo order:
instance-major, then the instance's state order (BFS, `Instance.states()`), which is portable
(unlike the reference's set order).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cfteach.domains import Domain, Instance, State
from cfteach.mdp import MDPBatch, compile_domain, greedy_actions, value_iteration
from cfteach.mdp.rollout import MAX_STEPS, rollout_features
from cfteach.mdp.soundness import require_sound

PROFILES = ("reference", "default")

#: VI method per profile: the reference's capped Gauss-Seidel flag vs true divergence.
VI_METHOD = {"reference": "reference", "default": "exact"}


def check_profile(profile: str) -> str:
    """Validate a profile name (ValueError names the value and the allowed ones)."""
    if profile not in PROFILES:
        raise ValueError(f"unknown profile {profile!r} (allowed: {', '.join(PROFILES)})")
    return profile


@dataclass(eq=False)
class DemoSet:
    """Every candidate demonstration of a domain, plus the planning data they came from.

    Shapes: D demonstrations, T = 25 (the rollout cap), F features, E instances, S padded
    states, A actions. Feature arrays are int64 (features are small integers).

    Attributes:
        env: ``[D]`` instance index of each demo.
        start: ``[D]`` start state index.
        length: ``[D]`` number of steps.
        states: ``[D, T+1]`` visited state indices (``S - 1`` = terminal sink, -1 after end).
        actions: ``[D, T]`` action indices (-1 after the end).
        step_phi: ``[D, T, F]`` per-step features (0 after the end).
        suffix_mu: ``[D, T+1, F]`` features from step t to the end; ``suffix_mu[:, 0]`` = mu.
        dev_mu: ``[E, S, A, F]`` mu of the rollout from s with forced first action a, then
            greedy (the one-action deviations of the paper's Eq. (2)).
        demo_of: ``[E, S]`` demo index of (instance, state), -1 where there is none.
    """

    domain: Domain
    profile: str
    batch: MDPBatch
    Q: np.ndarray  # [E, S, A] true action values
    policy: np.ndarray  # [E, S]
    env: np.ndarray
    start: np.ndarray
    length: np.ndarray
    states: np.ndarray
    actions: np.ndarray
    step_phi: np.ndarray
    suffix_mu: np.ndarray
    terminal: np.ndarray
    dev_mu: np.ndarray
    demo_of: np.ndarray
    cache: dict[str | tuple[Any, ...], Any] = field(default_factory=dict, repr=False)

    @property
    def D(self) -> int:  # noqa: N802 - array-shape name
        return int(self.env.shape[0])

    @property
    def F(self) -> int:  # noqa: N802
        return self.batch.F

    @property
    def mu(self) -> np.ndarray:
        """``[D, F]`` feature counts of every demo."""
        return self.suffix_mu[:, 0]

    @property
    def weights(self) -> np.ndarray:
        return np.asarray(self.domain.weights, dtype=float)

    def instance(self, d: int) -> Instance:
        return self.batch.instances[int(self.env[d])]

    def start_state(self, d: int) -> State:
        return self.batch.states[int(self.env[d])][int(self.start[d])]

    def index(self, env: int, state: State | int) -> int:
        """Demo index of (instance index, start state or its index); KeyError if none."""
        s = state if isinstance(state, int | np.integer) else self.batch.index_of(env, state)
        d = int(self.demo_of[env, s]) if 0 <= env < self.batch.E else -1
        if d < 0:
            raise KeyError(f"no demonstration starts at state {state} of instance {env}")
        return d

    def trajectory_states(self, d: int) -> list[State]:
        """The real states visited by demo d (the last one may be terminal)."""
        inst = self.instance(d)
        out = [self.start_state(d)]
        for a in self.actions[d, : self.length[d]]:
            out.append(inst.step(out[-1], int(a))[0])
        return out

    def action_names(self, d: int) -> list[str]:
        return [self.batch.actions[int(a)] for a in self.actions[d, : self.length[d]]]

    def reward(self, d: int) -> float:
        """w* . mu, as the reference computes it (dot product of the counts)."""
        return float(self.weights.dot(self.mu[d].astype(float)))


_BUILD_CHUNK = 8192  # demos per chunk while building the per-step arrays

_CACHE: weakref.WeakKeyDictionary[Domain, dict[str, DemoSet]] = weakref.WeakKeyDictionary()


def demo_set(domain: Domain, profile: str = "default") -> DemoSet:
    """All candidate demonstrations of `domain` (cached per domain object and profile)."""
    check_profile(profile)
    per = _CACHE.setdefault(domain, {})
    if profile not in per:
        per[profile] = _build(domain, profile)
    return per[profile]


def _build(domain: Domain, profile: str) -> DemoSet:
    require_sound(domain)  # named errors (unreachable goal, reward loop, ...) before planning
    batch = compile_domain(domain)
    w = np.asarray(domain.weights, dtype=float)
    vals = value_iteration(batch, w[None], method=VI_METHOD[profile])
    if not vals.bounded.all():
        bad = np.flatnonzero(~vals.bounded[:, 0])
        raise ValueError(f"{domain.name}: the true weights give unbounded values in instances "
                         f"{bad.tolist()[:10]}; demonstrations are undefined")
    Q = vals.Q[:, 0]
    policy = greedy_actions(Q)
    ro = rollout_features(batch, policy, return_paths=True)
    assert ro.states is not None and ro.actions is not None  # return_paths gives both
    dev = rollout_features(batch, policy, first_action="all")
    e_idx, s_idx = np.nonzero(batch.valid)  # instance-major, state order
    T = MAX_STEPS
    states = ro.states[e_idx, 0, s_idx].astype(np.int64)
    actions = ro.actions[e_idx, 0, s_idx].astype(np.int64)
    length = ro.length[e_idx, 0, s_idx].astype(np.int64)
    n = len(e_idx)
    step_phi = np.empty((n, T, batch.F), dtype=np.int64)
    suffix = np.zeros((n, T + 1, batch.F), dtype=np.int64)
    for a in range(0, n, _BUILD_CHUNK):  # chunks of demos: the float temporaries stay small
        b = min(n, a + _BUILD_CHUNK)
        live = actions[a:b] >= 0
        a_safe = np.where(live, actions[a:b], 0)
        s_safe = np.where(live, states[a:b, :T], 0)
        phi = batch.features[e_idx[a:b, None], s_safe, a_safe]
        step_phi[a:b] = np.where(live[..., None], np.rint(phi), 0).astype(np.int64)
        suffix[a:b, :T] = np.cumsum(step_phi[a:b, ::-1], axis=1)[:, ::-1]
    demo_of = np.full((batch.E, batch.S), -1, dtype=np.int64)
    demo_of[e_idx, s_idx] = np.arange(len(e_idx))
    dev_mu = np.rint(dev.mu[:, 0]).astype(np.int64)
    return DemoSet(domain=domain, profile=profile, batch=batch, Q=Q, policy=policy,
                   env=e_idx.astype(np.int64), start=s_idx.astype(np.int64), length=length,
                   states=states, actions=actions, step_phi=step_phi, suffix_mu=suffix,
                   terminal=ro.terminal[e_idx, 0, s_idx], dev_mu=dev_mu, demo_of=demo_of)
