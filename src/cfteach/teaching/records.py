"""`Curriculum` and `TestSet`: results of teaching and test selection, and their JSON."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cfteach.bec.demos import DemoSet
from cfteach.domains import Domain
from cfteach.geometry import Region
from cfteach.geometry.slice import SliceRegion
from cfteach.teaching.common import DemoRecord

CURRICULUM_SCHEMA = "cfteach.curriculum/1"
TESTS_SCHEMA = "cfteach.tests/1"


def _ints(rows: np.ndarray) -> list[list[int]]:
    return [[int(x) for x in r] for r in np.asarray(rows)]


def demo_json(ds: DemoSet, d: int) -> dict[str, Any]:
    """The schema's demonstration fields (docs/schemas.md) of demo d, without constraints."""
    inst = ds.instance(d)
    states = ds.trajectory_states(d)
    return {
        "env_code": [int(b) for b in inst.env_code],
        "env_index": int(inst.index),
        "start_state": inst.state_to_json(states[0]),
        "actions": ds.action_names(d),
        "states": [inst.state_to_json(s) for s in states],
        "feature_counts": [int(x) for x in ds.mu[d]],
        "reward": ds.reward(d),
    }


class BeliefError(RuntimeError):
    """A curriculum's final belief lost w* (a bug or a domain the checks did not catch)."""


#: Cosine tolerance of the "final belief contains w*" assertion (float rows).
BELIEF_TOL = 1e-9


@dataclass
class Curriculum:
    """The demonstrations one condition shows, in order, and the learner's final belief."""

    domain: Domain
    condition: str
    profile: str
    seed: int
    settings: dict[str, Any]
    records: list[DemoRecord]
    final_belief: Region | SliceRegion  # on a known-weight slice, the slice's belief
    demo_set: DemoSet = field(repr=False)
    log: list[dict[str, Any]] = field(default_factory=list, repr=False)

    def __post_init__(self) -> None:
        # Every constraint a demonstration adds holds for w* (the robot's own choice is
        # optimal under w*), so a final belief without w* means a wrong curriculum.
        if not self.final_belief.contains(self.domain.weights, tol=BELIEF_TOL):
            raise BeliefError(
                f"{self.domain.name} {self.condition}: the final belief "
                f"{_ints(self.final_belief.rows)} does not contain w* "
                f"{[round(float(x), 3) for x in self.domain.weights]}; this curriculum would "
                "teach a wrong reward (please report it with the domain file)")

    def __len__(self) -> int:
        return len(self.records)

    @property
    def demo_indices(self) -> list[int]:
        """Indices into the DemoSet of the demonstrations shown."""
        return [r.demo for r in self.records]

    def keys(self) -> list[tuple[int, tuple[int, ...]]]:
        """(env_index, start state) of every demonstration (the instance's own index, also
        on a domain restricted to some environments)."""
        ds = self.demo_set
        return [(int(ds.instance(r.demo).index), ds.start_state(r.demo)) for r in self.records]

    def to_json(self) -> dict[str, Any]:
        ds = self.demo_set
        demos = []
        for r in self.records:
            j = demo_json(ds, r.demo)
            j["constraints"] = _ints(r.constraints)
            j["knowledge_gain"] = float(r.knowledge_gain)
            j["belief_area_after"] = float(r.belief_area_after)
            j["masked_feature"] = r.masked_feature
            demos.append(j)
        return {
            "schema": CURRICULUM_SCHEMA,
            "domain": self.domain.name,
            "condition": self.condition,
            "profile": self.profile,
            "seed": int(self.seed),
            "settings": dict(self.settings),
            "feature_names": list(self.domain.feature_names),
            "weights": [float(x) for x in self.domain.weights],
            "prior": _ints(self.domain.prior),
            "demos": demos,
            "final_belief": {"constraints": _ints(self.final_belief.reduced()),
                             "area": float(self.final_belief.area())},
        }


@dataclass
class TestRecord:
    demo: int
    difficulty: str
    overlap: float
    constraints: np.ndarray
    all_optimal_actions: list[list[str]]


@dataclass
class TestSet:
    """Tests of three difficulties picked by the overlap of their BEC' with the belief."""

    domain: Domain
    profile: str
    seed: int
    settings: dict[str, Any]
    belief: Region
    human_models: np.ndarray
    excluded: list[tuple[int, tuple[int, ...]]]
    cluster_centres: list[float]
    tests: dict[str, list[TestRecord]]
    demo_set: DemoSet = field(repr=False)
    overlaps: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    clusters: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    include_candidates: bool = False

    def to_json(self) -> dict[str, Any]:
        ds = self.demo_set
        tests: dict[str, list[dict[str, Any]]] = {}
        for level in ("low", "medium", "high"):
            out = []
            for t in self.tests.get(level, []):
                j = demo_json(ds, t.demo)
                j["constraints"] = _ints(t.constraints)
                j["overlap"] = float(t.overlap)
                j["difficulty"] = t.difficulty
                j["all_optimal_actions"] = t.all_optimal_actions
                j["optimal_reward"] = ds.reward(t.demo)
                out.append(j)
            tests[level] = out
        res: dict[str, Any] = {
            "schema": TESTS_SCHEMA,
            "domain": self.domain.name,
            "profile": self.profile,
            "seed": int(self.seed),
            "settings": dict(self.settings),
            "feature_names": list(self.domain.feature_names),
            "weights": [float(x) for x in self.domain.weights],
            "belief": {"constraints": _ints(self.belief.reduced()),
                       "area": float(self.belief.area())},
            "human_models": [[float(x) for x in w] for w in self.human_models],
            "excluded": [[e, ds.domain.instance(e).state_to_json(s)] for e, s in self.excluded],
            "cluster_centres": [float(c) for c in self.cluster_centres],
            "tests": tests,
        }
        if self.include_candidates:
            cands = []
            for d in np.flatnonzero(self.clusters >= 0).tolist():
                inst = ds.instance(d)
                cands.append({"env_code": [int(b) for b in inst.env_code],
                              "env_index": int(inst.index),
                              "start_state": inst.state_to_json(ds.start_state(d)),
                              "overlap": float(self.overlaps[d]),
                              "cluster": int(self.clusters[d])})
            res["candidates"] = cands
        return res
