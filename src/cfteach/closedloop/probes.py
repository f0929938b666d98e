"""The teacher's own probe tests: what it predicts success on, and stops by.

The post-teaching tests (`LessonPool.held_out`) score the learner afterwards; the teacher
must not peek at them, neither to stop nor to pick lessons. It predicts on probes instead:
up to `n` candidate tests (never a held-out one), spread evenly over difficulty (the share of the
prior whose weights answer them optimally, from 2,000 prior draws), so that they cover easy
and hard tests alike as a post-test selection does.
"""

from __future__ import annotations

import numpy as np

from cfteach.closedloop.pool import LessonPool
from cfteach.closedloop.steps import StepData, path_steps

#: Tests answered optimally by more (fewer) of the prior than this are trivial (impossible).
EASY, HARD = 0.98, 0.02


def _prior_draws(pool: LessonPool, m: int = 2000) -> np.ndarray:
    from cfteach.teaching.sampling import sample_models

    prior = np.asarray(pool.domain.prior, dtype=np.int64).reshape(-1, pool.F)
    return sample_models("default", prior, m, np.random.default_rng([pool.seed, 11]), pool.F)


def probe_demos(pool: LessonPool, n: int) -> np.ndarray:
    """`n` probe tests (demo indices), never held out, evenly spread over difficulty."""
    key = ("probes", n)
    if key not in pool.cache:
        ds = pool.ds
        sets = pool.tests
        mass = sets.satisfied(_prior_draws(pool)).mean(axis=1) if sets.n_sets else np.zeros(0)
        cand = np.array([d for d in range(ds.D) if sets.slot[d] >= 0
                         and HARD < mass[sets.slot[d]] < EASY], dtype=np.int64)
        if not len(cand):
            pool.cache[key] = cand
            return cand
        order = cand[np.lexsort((cand, mass[sets.slot[cand]]))]
        pick = np.unique(np.round(np.linspace(0, len(order) - 1, min(n, len(order))))
                         .astype(np.int64))
        # chosen among all tests, then the post-tests dropped: which tests are held out
        # changes nothing else
        pool.cache[key] = np.array([d for d in np.sort(order[pick]).tolist()
                                    if d not in pool.held_out], dtype=np.int64)
    return pool.cache[key]


def probe_paths(pool: LessonPool, n: int) -> tuple[StepData, np.ndarray]:
    """`path_steps` of the probes (cached per pool)."""
    key = ("probe_paths", n)
    if key not in pool.cache:
        demos = probe_demos(pool, n)
        pool.cache[key] = path_steps(pool.ds, demos) if len(demos) else None
    return pool.cache[key]


def probe_tests(pool: LessonPool, n: int) -> list[dict]:
    """The probes as tests a learner can answer (start, environment, optimal reward): lets
    a simulation measure a learner on exactly the items the teacher predicts on."""
    from cfteach.closedloop.items import demo_json

    out = []
    for d in probe_demos(pool, n).tolist():
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


def lesson_blocked(pool: LessonPool, n: int) -> frozenset[int]:
    """Demos never shown as lessons: the held-out tests' starts and the probes (a lesson
    from a test's start would show its answer)."""
    key = ("lesson_blocked", n)
    if key not in pool.cache:
        pool.cache[key] = frozenset(pool.held_out) | frozenset(probe_demos(pool, n).tolist())
    return pool.cache[key]
