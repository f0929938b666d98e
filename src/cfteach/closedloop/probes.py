"""The teacher's own probe tests: what it predicts success on, and stops by.

The post-teaching tests (`LessonPool.held_out`) score the learner afterwards; the teacher
must not peek at them, neither to stop nor to pick lessons. It predicts on probes instead:
up to `n` candidate tests, never a held-out one, drawn by one of two rules (`PROBE_RULES`):

* ``"levels"`` (the default): by the difficulty the post-tests themselves are drawn by
  (Algorithm 2, `cfteach.teaching.testsel`, with `select_tests`'s defaults): each
  candidate's overlap with the domain's posterior region, k-means into 5 clusters, and a
  third of the probes from each of the low, medium and high levels' clusters, spread evenly
  over overlap inside each. Why: a prediction is checked against the post-tests, and
  probes unlike them miss it whatever the learner model (docs/closed-loop.md, "Predictions
  from the teacher's own probes").
* ``"prior"``: spread evenly over the share of 2,000 prior draws that answer them optimally,
  trivial and impossible ones left out (the rule before; a study file written with it keeps
  it, so its sessions replay unchanged).
"""

from __future__ import annotations

import numpy as np

from cfteach.closedloop.pool import LessonPool
from cfteach.closedloop.steps import StepData, path_steps

#: How the probes are drawn (module docstring); the first is the default.
PROBE_RULES = ("levels", "prior")
#: Tests answered optimally by more (fewer) of the prior than this are trivial (impossible).
EASY, HARD = 0.98, 0.02
#: Draws behind a test's share of the prior (rule "prior").
DRAWS = 2000
#: Human models behind Algorithm 2's overlaps (rule "levels"; `select_tests`'s default).
LEVEL_HUMAN_MODELS = 8


def _prior_draws(pool: LessonPool) -> np.ndarray:
    from cfteach.teaching.sampling import sample_models

    prior = np.asarray(pool.domain.prior, dtype=np.int64).reshape(-1, pool.F)
    return sample_models("default", prior, DRAWS, np.random.default_rng([pool.seed, 11]),
                         pool.F)


def _spread(cand: np.ndarray, share: np.ndarray, n: int) -> np.ndarray:
    """`n` of `cand` spread evenly over their `share` (ties by demo index)."""
    if not len(cand) or n < 1:
        return cand[:0]
    order = cand[np.lexsort((cand, share))]
    pick = np.unique(np.round(np.linspace(0, len(order) - 1, min(n, len(order))))
                     .astype(np.int64))
    return order[pick]


def _by_prior(pool: LessonPool, n: int) -> np.ndarray:
    sets = pool.tests
    mass = sets.satisfied(_prior_draws(pool)).mean(axis=1) \
        if sets.n_sets else np.zeros(0)
    cand = np.array([d for d in range(pool.ds.D) if sets.slot[d] >= 0
                     and HARD < mass[sets.slot[d]] < EASY], dtype=np.int64)
    return _spread(cand, mass[sets.slot[cand]] if len(cand) else np.zeros(0), n)


def _by_levels(pool: LessonPool, n: int) -> np.ndarray:
    from cfteach.bec import DEFAULT_UNBOUNDED
    from cfteach.teaching.testsel import level_clusters, select

    # Algorithm 2 as `select_tests` runs it with its defaults (no training excluded, no
    # test kept: only every candidate's overlap and difficulty cluster are read)
    parts = select(pool.ds, training=(), seed=pool.seed, per_level=0,
                   human_models=LEVEL_HUMAN_MODELS,
                   unbounded=DEFAULT_UNBOUNDED[pool.profile])
    overlap, cluster = parts["overlaps"], parts["clusters"]
    levels = [c for c in level_clusters(len(parts["cluster_centres"])).values()
              if c is not None]
    out = []
    for i, c in enumerate(levels):
        members = np.flatnonzero((cluster == c) & (pool.tests.slot >= 0))
        out.append(_spread(members, overlap[members], n // len(levels) + (i < n % len(levels))))
    return np.unique(np.concatenate(out)) if out else np.zeros(0, dtype=np.int64)


def probe_demos(pool: LessonPool, n: int, rule: str = PROBE_RULES[0]) -> np.ndarray:
    """Up to `n` probe tests (sorted demo indices), never held out, drawn by `rule`."""
    if rule not in PROBE_RULES:
        raise ValueError(f"probe rule must be one of {', '.join(PROBE_RULES)}, got {rule!r}")
    key = ("probes", n, rule)
    if key not in pool.cache:
        picked = (_by_levels if rule == "levels" else _by_prior)(pool, n)
        # chosen among all tests, then the post-tests dropped: which tests are held out
        # changes nothing else
        pool.cache[key] = np.array([d for d in np.sort(picked).tolist()
                                    if d not in pool.held_out], dtype=np.int64)
    return pool.cache[key]


def probe_paths(pool: LessonPool, n: int, rule: str = PROBE_RULES[0]
                ) -> tuple[StepData, np.ndarray]:
    """`path_steps` of the probes (cached per pool)."""
    key = ("probe_paths", n, rule)
    if key not in pool.cache:
        demos = probe_demos(pool, n, rule)
        pool.cache[key] = path_steps(pool.ds, demos) if len(demos) else None
    return pool.cache[key]


def probe_tests(pool: LessonPool, n: int, rule: str = PROBE_RULES[0]) -> list[dict]:
    """The probes as tests a learner can answer (start, environment, optimal reward): lets
    a simulation measure a learner on exactly the items the teacher predicts on."""
    from cfteach.closedloop.items import demo_json

    out = []
    for d in probe_demos(pool, n, rule).tolist():
        shown = demo_json(pool.ds, d)
        out.append({**{k: shown[k] for k in ("env_code", "env_index", "start_state")},
                    "optimal_reward": pool.ds.reward(d)})
    return out


def region_sat(pool: LessonPool, demos: np.ndarray, particles: np.ndarray) -> np.ndarray:
    """``[P, len(demos)]``: particle p answers test d optimally by its weights (BEC')."""
    sets = pool.tests
    slots = sets.slot[demos]
    out = np.ones((len(particles), len(demos)), dtype=bool)
    used = np.unique(slots[slots >= 0])
    if not len(used):
        return out
    inc = sets.incidence[used]
    cols = np.unique(inc.indices)
    broken = (sets.rows[cols] @ particles.T < -1e-9).astype(np.float32)
    sat = np.asarray(inc[:, cols] @ broken) == 0  # [k, P]
    where = {int(k): i for i, k in enumerate(used.tolist())}
    for j, k in enumerate(slots.tolist()):
        if k >= 0:
            out[:, j] = sat[where[k]]
    return out


def lesson_blocked(pool: LessonPool, n: int, rule: str = PROBE_RULES[0]) -> frozenset[int]:
    """Demos never shown as lessons: the held-out tests' starts and the probes (a lesson
    from a test's start would show its answer)."""
    key = ("lesson_blocked", n, rule)
    if key not in pool.cache:
        pool.cache[key] = (frozenset(pool.held_out)
                           | frozenset(probe_demos(pool, n, rule).tolist()))
    return pool.cache[key]
