"""Algorithm 2: test difficulty (the paper's Section IV, "Testing") and test selection (how the
candidates become three difficulty levels: docs/teaching.md, "The conditions").

For every candidate demonstration, BEC' = its one-step constraints + its counterfactual
constraints under human models sampled from the post-teaching belief B. The smaller the
overlap area(B & BEC'), the harder the test (difficulty = 1 / overlap). Candidates are
clustered by overlap (k-means, 5 clusters); the smallest-overlap cluster gives the high-
difficulty tests, the middle one medium, the largest low.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from cfteach.bec.constraints import counterfactual_rowset, one_action_rows
from cfteach.bec.demos import DemoSet
from cfteach.bec.rows import reduce_sets
from cfteach.geometry import Region
from cfteach.geometry.slice import KnownSlice
from cfteach.mdp.rollout import MAX_STEPS
from cfteach.mdp.vi import tied_actions
from cfteach.parallel import Executor
from cfteach.teaching import distribute, known
from cfteach.teaching.common import fit_kmeans
from cfteach.teaching.records import TestRecord
from cfteach.teaching.sampling import sample_models

N_CLUSTERS = 5
LEVEL_CLUSTER = {"high": 0, "medium": 2, "low": 4}


def level_clusters(k: int) -> dict[str, int | None]:
    """Which sorted cluster each level takes when only `k` clusters exist.

    With the paper's 5 clusters: the 1st, 3rd and 5th. A domain whose candidates have fewer
    than 5 distinct overlaps keeps the extremes (smallest overlap = high, largest = low)
    and the middle cluster for medium when there is one, instead of leaving `low` empty.
    """
    if k >= N_CLUSTERS:
        return dict(LEVEL_CLUSTER)
    return {"high": 0 if k > 1 else None, "medium": k // 2 if k >= 3 else None,
            "low": k - 1}

#: At most this many tied-optimal action sequences are listed per test.
ALL_OPTIMAL_CAP = 50


def training_keys(ds: DemoSet, training: Iterable[Any]) -> set[tuple[int, tuple[int, ...]]]:
    """(env_index, start state) of every demo of the given curricula (objects or JSON)."""
    keys: set[tuple[int, tuple[int, ...]]] = set()
    for cur in training:
        if hasattr(cur, "keys") and callable(cur.keys) and hasattr(cur, "records"):
            keys.update(cur.keys())
            continue
        if not isinstance(cur, dict) or "demos" not in cur:
            raise ValueError("training entries must be Curriculum objects or curriculum JSON "
                             "dicts (with 'demos')")
        if cur.get("domain") not in (None, ds.domain.name):
            raise ValueError(f"training curriculum is for domain {cur.get('domain')!r}, "
                             f"not {ds.domain.name!r}")
        for j, demo in enumerate(cur["demos"]):
            try:
                inst = ds.domain.instance(int(demo["env_index"]) if "env_index" in demo
                                          else demo["env_code"])
                keys.add((inst.index, inst.state_from_json(demo["start_state"])))
            except (KeyError, IndexError, TypeError) as exc:
                raise ValueError(f"training demo {j}: needs env_index (or env_code) and "
                                 f"start_state ({exc})") from None
    return keys


def all_optimal_actions(ds: DemoSet, d: int, cap: int = ALL_OPTIMAL_CAP) -> list[list[str]]:
    """Tied-optimal action sequences under w* from the demo's start, depth-first in action
    order (ties: |Q - max Q| < 1e-5), ending at the terminal or after 25 steps, at most
    `cap` of them."""
    e = int(ds.env[d])
    tied = tied_actions(ds.Q[e])
    nxt = ds.batch.next_state[e]
    sink = ds.batch.sink
    names = ds.batch.actions
    out: list[list[str]] = []

    def rec(s: int, path: list[int]) -> None:
        if len(out) >= cap:
            return
        if s == sink or len(path) >= MAX_STEPS:
            out.append([names[a] for a in path])
            return
        for a in np.flatnonzero(tied[s]).tolist():
            rec(int(nxt[s, a]), [*path, a])

    rec(int(ds.start[d]), [])
    return out


def overlaps_of(ds: DemoSet, belief: Region, W: np.ndarray,
                unbounded: str | None = None, executor: Executor | None = None,
                ) -> tuple[np.ndarray, Any]:
    """area(B & BEC'(xi)) for every demo, and the joint BEC' row sets (on the executor's
    workers if one is given: the same numbers)."""
    if len(W):
        cf, _ = counterfactual_rowset(ds, W, unbounded=unbounded, executor=executor)
        joint = one_action_rows(ds).union(cf)
    else:
        joint = one_action_rows(ds)
    return distribute.areas(belief, joint, executor), joint


def select(ds: DemoSet, *, training: Iterable[Any], seed: int, per_level: int,
           human_models: int, unbounded: str | None = None,
           executor: Executor | None = None, sl: KnownSlice | None = None
           ) -> dict[str, Any]:
    """Run Algorithm 2; returns the pieces a `TestSet` is made of. With a known-weight
    slice `sl` the belief, its human models and the overlaps are the slice's."""
    F = ds.F
    post = np.asarray(ds.domain.posterior, dtype=np.int64)
    belief: Any = Region(post, dim=F) if sl is None else sl.region(post)
    rng3 = np.random.default_rng([seed, 3])
    W = sample_models(ds.profile, belief.reduced(), human_models, rng3, F) if sl is None \
        else belief.sample(human_models, rng3)
    if sl is None:
        overlaps, joint = overlaps_of(ds, belief, W, unbounded, executor)
    else:
        joint = one_action_rows(ds)
        if len(W):
            joint = joint.union(counterfactual_rowset(ds, W, unbounded=unbounded,
                                                      executor=executor)[0])
        overlaps = known.overlaps(belief, joint)
    excluded = training_keys(ds, training)
    pool_mask = np.ones(ds.D, dtype=bool)
    position = {inst.index: p for p, inst in enumerate(ds.batch.instances)}  # env_index -> e
    for e, s in excluded:
        if e not in position:  # an environment left out of a subset
            continue
        try:
            pool_mask[ds.index(position[e], s)] = False
        except KeyError:
            continue
    pool = np.flatnonzero(pool_mask)
    x = overlaps[pool].reshape(-1, 1)
    k = min(N_CLUSTERS, len(np.unique(x)))
    if k < 1:
        raise ValueError("no candidate demonstrations left for tests")
    km = fit_kmeans(x, k, seed)
    order = np.argsort(km.cluster_centers_[:, 0])
    rank = np.empty(k, dtype=np.int64)
    rank[order] = np.arange(k)
    clusters = np.full(ds.D, -1, dtype=np.int64)
    clusters[pool] = rank[km.labels_]
    rng = np.random.default_rng([seed, 4])
    tests: dict[str, list[TestRecord]] = {}
    for level, c in level_clusters(k).items():
        members = pool[clusters[pool] == c] if c is not None else np.zeros(0, dtype=np.int64)
        pick = rng.choice(members, size=min(per_level, len(members)), replace=False) \
            if len(members) else members
        red = reduce_sets(joint, pick) if sl is None else known.reduce_rowset(sl, joint, pick)
        tests[level] = [TestRecord(demo=int(d), difficulty=level, overlap=float(overlaps[d]),
                                   constraints=red[int(d)],
                                   all_optimal_actions=all_optimal_actions(ds, int(d)))
                        for d in pick.tolist()]
    return {"belief": belief, "human_models": W, "excluded": sorted(excluded),
            "cluster_centres": sorted(float(c) for c in km.cluster_centers_[:, 0]),
            "tests": tests, "overlaps": overlaps, "clusters": clusters}
