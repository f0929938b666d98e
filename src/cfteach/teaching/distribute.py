"""Teaching's per-round work spread over a `cfteach.parallel.Executor`, bit for bit.

Two kinds of work are split: planning (value iteration and counterfactual rows for every
instance x human model, `cfteach.bec.constraints.counterfactual_rowset`, chunked by
instances) and geometry on the candidates' row sets (knowledge gains, overlaps, reductions).
For the latter the candidates are first grouped by their row set in this process, so equal
sets are measured once (as in one process) and every chunk sends one representative per
set. Nothing here draws random numbers, and an area depends only on its row set, so the
results do not depend on the chunking or the worker count.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from functools import partial

import numpy as np

from cfteach.bec.constraints import one_action_rows, sub_rowset
from cfteach.bec.demos import DemoSet
from cfteach.bec.gain import gain_estimates, intersected_areas
from cfteach.bec.rows import RowSet, reduce_and_measure, reduce_sets
from cfteach.geometry import Region
from cfteach.parallel import Executor, ParallelConfig

#: Distinct row sets per geometry chunk at most (more chunks than workers balance the load).
SETS_PER_CHUNK = 512


def parallel_config(backend: str = "local", workers: int | None = None,
                    scheduler: str | None = None, executor: Executor | None = None,
                    ) -> ParallelConfig | None:
    """The executor settings of `teach`/`select_tests`, or None for today's one process
    (the local backend with one worker: no pool is started at all)."""
    if executor is not None:
        if (backend, workers, scheduler) != ("local", None, None):
            raise ValueError("give either an executor or backend/workers/scheduler")
        return None
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    if backend == "local" and scheduler is None and workers in (None, 1):
        return None
    return ParallelConfig(backend=backend, n_workers=workers, scheduler=scheduler)


@contextlib.contextmanager
def open_executor(config: ParallelConfig | None, executor: Executor | None = None,
                  ) -> Iterator[Executor | None]:
    """The executor for one whole teach (a cluster starts once): the caller's own if given,
    else one started here from `config` and closed at the end (None: one process)."""
    if executor is not None:
        yield executor if executor.n_workers > 1 else None
        return
    if config is None:
        yield None
        return
    with Executor(config) as ex:
        yield ex


def _per_set(executor: Executor, fn: Callable[[RowSet], np.ndarray], rowset: RowSet,
             demos: np.ndarray) -> np.ndarray:
    """``fn`` of each demo's row set, computed once per distinct set on the workers."""
    demos = np.asarray(demos, dtype=np.int64)
    if not len(demos):
        return np.zeros(0)
    _, slot = rowset.distinct(demos)
    _, first = np.unique(slot, return_index=True)
    reps = demos[first]  # one demo per distinct set, in first-seen order
    n_chunks = max(executor.n_workers, -(-len(reps) // SETS_PER_CHUNK))
    bounds = np.linspace(0, len(reps), min(n_chunks, len(reps)) + 1).round().astype(int)
    chunks = [sub_rowset(rowset, reps[a:b]) for a, b in zip(bounds[:-1], bounds[1:],
                                                            strict=True)]
    per_rep = np.concatenate(executor.map(fn, chunks))
    return per_rep[slot]


def _gains(rowset: RowSet, running: Region) -> np.ndarray:
    return np.stack(gain_estimates(running, rowset), axis=1)  # [n, 2]: gain, error


def _areas(rowset: RowSet, region: Region) -> np.ndarray:
    return intersected_areas(region, rowset)[0]


def _touches(rowset: RowSet, feature: int) -> np.ndarray:
    red = reduce_sets(rowset)
    return np.array([bool(len(red[d]) and np.any(red[d][:, feature] != 0))
                     for d in range(rowset.n_demos)], dtype=bool)


def gains(running: Region, joint: RowSet, executor: Executor | None
          ) -> tuple[np.ndarray, np.ndarray]:
    """`gain_estimates(running, joint)` (gains, standard errors) for every demo, on the
    executor's workers. A demo's estimate depends only on the belief, its rows and the
    seed, never on the other demos of its chunk, so chunking changes nothing."""
    if executor is None:
        return gain_estimates(running, joint)
    out = np.zeros((joint.n_demos, 2))
    has = np.flatnonzero(joint.counts() > 0)
    if len(has):
        out[has] = _per_set(executor, partial(_gains, running=running), joint, has)
    return out[:, 0].copy(), out[:, 1].copy()


def areas(region: Region, rowset: RowSet, executor: Executor | None) -> np.ndarray:
    """``intersected_areas(region, rowset)[0]`` for every demo, on the workers."""
    if executor is None:
        return intersected_areas(region, rowset)[0]
    out = np.full(rowset.n_demos, region.area())
    has = np.flatnonzero(rowset.counts() > 0)
    out[has] = _per_set(executor, partial(_areas, region=region), rowset, has)
    return out


def touches(joint: RowSet, demos: np.ndarray, feature: int,
            executor: Executor | None) -> np.ndarray:
    """bool per demo of `demos`: its reduced row set involves `feature`."""
    if executor is None:
        red = reduce_sets(joint, demos)
        return np.array([bool(len(red[int(d)]) and np.any(red[int(d)][:, feature] != 0))
                         for d in demos], dtype=bool)
    return _per_set(executor, partial(_touches, feature=feature), joint, demos).astype(bool)


def _reduced_and_area(rowset: RowSet) -> np.ndarray:
    red, areas = reduce_and_measure(rowset)
    out = np.empty(rowset.n_demos, dtype=object)
    out[:] = [(red[d], float(areas[d])) for d in range(rowset.n_demos)]
    return out


def one_step_cache(ds: DemoSet, executor: Executor | None) -> None:
    """Fill the demo set's one-step sets and BEC areas (what the masking order and the
    baselines reduce for every demo) on the executor's workers: the same values as
    `reduce_and_measure(one_action_rows(ds))` in one process."""
    if executor is None or ("one_step_sets" in ds.cache and "bec_areas" in ds.cache):
        return
    rows = one_action_rows(ds)
    both = _per_set(executor, _reduced_and_area, rows, np.arange(rows.n_demos))
    ds.cache["one_step_sets"] = {d: both[d][0] for d in range(rows.n_demos)}
    ds.cache["bec_areas"] = np.array([both[d][1] for d in range(rows.n_demos)], dtype=float)
