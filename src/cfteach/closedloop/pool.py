"""What a closed-loop teacher works with, computed once per domain and shared by every
learner it teaches: candidate lessons with their counterfactual constraints, candidate tests
with their BEC' constraints (and the alternative answers those constraints come from), and
the held-out tests that are never used during teaching.

Lessons are the paper's counterfactual demonstrations: a demonstration's constraints are
``mu(demo) - mu(human plan)`` for a pool of human models drawn from the prior (Algorithm 1's
rows, `cfteach.bec.counterfactual_rows`). Which of them matter for a learner is decided at
run time by the teacher's particle belief. Tests carry the one-action and counterfactual rows
(Algorithm 2's BEC'): a learner with weights ``w`` answers a test optimally iff ``w`` satisfies
them all.

The few hundred distinct row sets of a domain are built from fewer than a few hundred distinct
rows, so every question the teacher asks of its 1,000 particles is one small matrix product.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy import sparse

from cfteach.bec import counterfactual_rows, demo_set, one_action_rows, resolve_domain
from cfteach.bec.demos import DemoSet
from cfteach.bec.rows import RowSet
from cfteach.domains import Domain
from cfteach.teaching.sampling import sample_models

#: A particle satisfies a row when ``row . w >= -SATISFIED_TOL`` (rows are integer counts).
SATISFIED_TOL = 1e-9


@dataclass(eq=False)
class RowIndex:
    """Distinct row sets of many demonstrations over one table of distinct rows.

    ``incidence[k, u] = 1`` when distinct set k holds row ``rows[u]``; ``slot[d]`` is demo d's
    set (-1 when it has no rows); ``members[k]`` the demos sharing set k.
    """

    rows: np.ndarray          # [U, F] float
    incidence: sparse.csr_matrix  # [K, U]
    slot: np.ndarray          # [D]
    members: list[np.ndarray]

    @classmethod
    def build(cls, rs: RowSet, demos: np.ndarray) -> RowIndex:
        slot = np.full(rs.n_demos, -1, dtype=np.int64)
        keys: dict[bytes, int] = {}
        members: list[list[int]] = []
        set_rows: list[np.ndarray] = []
        for d in demos.tolist():
            r = rs.of(d)
            if not len(r):
                continue
            k = keys.setdefault(r.tobytes(), len(keys))
            if k == len(members):
                members.append([])
                set_rows.append(r)
            members[k].append(d)
            slot[d] = k
        if set_rows:
            stacked = np.vstack(set_rows)
            uniq, inverse = np.unique(stacked, axis=0, return_inverse=True)
            owner = np.repeat(np.arange(len(set_rows)), [len(r) for r in set_rows])
            inc = sparse.csr_matrix((np.ones(len(owner), dtype=np.float32),
                                     (owner, inverse.ravel())), shape=(len(set_rows), len(uniq)))
        else:
            uniq = np.zeros((0, rs.F))
            inc = sparse.csr_matrix(np.zeros((0, 0), dtype=np.float32))
        return cls(uniq.astype(float), inc, slot, [np.asarray(m) for m in members])

    @property
    def n_sets(self) -> int:
        return len(self.members)

    def satisfied(self, particles: np.ndarray) -> np.ndarray:
        """``[K, P]`` bool: particle p satisfies every row of set k."""
        if not self.n_sets:
            return np.zeros((0, len(particles)), dtype=bool)
        broken = (self.rows @ particles.T < -SATISFIED_TOL).astype(np.float32)  # [U, P]
        return np.asarray(self.incidence @ broken) == 0


@dataclass(eq=False)
class LessonPool:
    """Candidate lessons and tests of one domain for closed-loop teaching (module docstring)."""

    domain: Domain
    ds: DemoSet
    profile: str
    seed: int
    human_models: np.ndarray     # [M, F] drawn from the prior
    lesson_rows: RowSet          # counterfactual rows of every demo
    test_rows: RowSet            # one-action + counterfactual rows of every demo
    held_out: frozenset[int]     # demo indices never used as diagnostic tests
    lessons: RowIndex
    tests: RowIndex
    settings: dict[str, Any] = field(default_factory=dict)
    backbone: tuple[int, ...] = ()  # lessons every session covers, in order (build_pool)
    cache: dict[Any, Any] = field(default_factory=dict, repr=False)  # probes, paths

    @property
    def F(self) -> int:  # noqa: N802 - the feature count, as elsewhere
        return self.ds.F

    def with_models(self, W: np.ndarray) -> LessonPool:
        """This pool with more human models ``W [M, F]`` (e.g. drawn from one learner's
        current belief): their counterfactual rows join every demo's lesson and test rows,
        so lessons can target the plans of learners like this one, and tests compare
        against those plans too. The held-out tests, the backbone and the cache (the
        probes were chosen on the first pool and stay) carry over unchanged."""
        W = np.asarray(W, dtype=float).reshape(-1, self.F)
        if not len(W):
            return self
        cf, _, _ = counterfactual_rows(self.ds, W)
        lesson_rows, test_rows = self.lesson_rows.union(cf), self.test_rows.union(cf)
        every = np.arange(self.ds.D)
        return replace(self, human_models=np.vstack([self.human_models, W]),
                       lesson_rows=lesson_rows, test_rows=test_rows,
                       lessons=RowIndex.build(lesson_rows, every),
                       tests=RowIndex.build(test_rows, every), cache=dict(self.cache))

    def held_out_mass(self, particles: np.ndarray, weights: np.ndarray) -> float | None:
        """Belief mass inside the held-out tests' regions, averaged over them (None without
        held-out tests), asking the particles about those tests' rows only (a few dozen of
        the pool's rows instead of all of them). For analysis: no decision reads it."""
        held = np.array(sorted(self.held_out), dtype=np.int64)
        if not len(held):
            return None
        slots = self.tests.slot[held]
        used = np.unique(slots[slots >= 0])
        p = np.ones(len(held))
        if len(used):
            inc = self.tests.incidence[used]
            cols = np.unique(inc.indices)
            broken = (self.tests.rows[cols] @ particles.T < -SATISFIED_TOL).astype(np.float32)
            sat = np.asarray(inc[:, cols] @ broken) == 0  # [sets, P]
            p_set = dict(zip(used.tolist(), (sat.astype(float) @ weights).tolist(),
                             strict=True))
            p = np.array([p_set[int(k)] if k >= 0 else 1.0 for k in slots.tolist()])
        return float(p.mean())

    def test_alternatives(self, d: int) -> np.ndarray:
        """Feature counts of the other answers test d's constraints compare against:
        ``mu* - row`` for every row (one-action deviations and human-model plans)."""
        return self.ds.mu[d][None, :].astype(float) - self.test_rows.of(d).astype(float)


def held_out_demos(ds: DemoSet, tests: Any) -> list[int]:
    """Demo indices of a test set (a `TestSet`, its JSON, or ``(env_index, state)`` pairs)."""
    if tests is None:
        return []
    if hasattr(tests, "to_json"):
        tests = tests.to_json()
    pairs: Iterable[Any]
    if isinstance(tests, dict):
        pairs = [t for level in tests.get("tests", {}).values() for t in level]
    else:
        pairs = list(tests)
    return sorted(set(demo_indices(ds, pairs)))


def demo_indices(ds: DemoSet, items: Iterable[Any]) -> list[int]:
    """Demo indices of demonstrations or tests (JSON with ``env_index``/``env_code`` and
    ``start_state``, ``(env_index, state)`` pairs or indices), in order."""
    out = []
    for t in items:
        if isinstance(t, int | np.integer):
            if not 0 <= int(t) < ds.D:
                raise ValueError(f"held-out demo index {t} outside 0..{ds.D - 1}")
            out.append(int(t))
            continue
        if isinstance(t, dict):
            inst = ds.domain.instance(int(t["env_index"]) if "env_index" in t else t["env_code"])
            state = inst.state_from_json(t["start_state"])
            out.append(ds.index(inst.index, state))
            continue
        env, state = t
        out.append(ds.index(int(env), tuple(state)))
    return out


def build_pool(domain: Domain | str, *, profile: str = "default", human_models: int = 32,
               seed: int = 0, held_out: Any = None, backbone: Any = None) -> LessonPool:
    """Precompute a domain's lessons and tests (see the module docstring).

    `held_out`: the post-teaching tests (a `TestSet`, its JSON or demo indices); they are
    never lessons nor diagnostic tests. `backbone`: an open-loop curriculum's
    demonstrations (its JSON ``demos``, or demo indices), in order: the lessons every
    session covers before the teacher may stop (docs/closed-loop.md, "The backbone").
    """
    if isinstance(human_models, bool) or not isinstance(human_models, int) or human_models < 1:
        raise ValueError(f"human_models must be an integer >= 1, got {human_models!r}")
    dom = resolve_domain(domain)
    ds = demo_set(dom, profile)
    prior = np.asarray(dom.prior, dtype=np.int64).reshape(-1, ds.F)
    W = sample_models(profile, prior, human_models, np.random.default_rng([seed, 7]), ds.F)
    if not len(W):
        raise ValueError(f"{dom.name}: the prior region has no area; no human model to draw")
    cf, _, _ = counterfactual_rows(ds, W)
    joint = one_action_rows(ds).union(cf)
    held = frozenset(held_out_demos(ds, held_out))
    every = np.arange(ds.D)
    return LessonPool(domain=dom, ds=ds, profile=profile, seed=seed, human_models=W,
                      lesson_rows=cf, test_rows=joint, held_out=held,
                      lessons=RowIndex.build(cf, every), tests=RowIndex.build(joint, every),
                      settings={"human_models": human_models, "profile": profile,
                                "seed": seed},
                      backbone=tuple(demo_indices(ds, backbone or ())))
