"""One-action-deviation constraints (the paper's Eq. (2)) and counterfactual constraints (its
Eq. (3)),
for every candidate demonstration at once.

One-action rows of demo d: for every step t and every action b other than the demo's,
``suffix_mu[d, t] - mu(rollout from s_t forcing b, then greedy)``.

Counterfactual rows of demo d under human model w_h (bounded values only): for every step t,
``suffix_mu[d, t] - mu(h*)``, where h* is the human's tied-optimal trajectory from s_t with the
highest true reward ("benefit of the doubt"). The `reference` profile reproduces how the
authors' code picks h* when more than 10 tied trajectories exist (`cfteach.mdp.best_tied_mu`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from cfteach.bec.demos import VI_METHOD, DemoSet
from cfteach.bec.rows import RowSet, group_rows, primitive
from cfteach.mdp import MDPBatch, value_iteration
from cfteach.mdp.tied import REFERENCE_TIED_LIMIT, best_tied_mu
from cfteach.parallel.executor import chunk_slices

_CF_CACHE_SIZE = 8  # counterfactual row sets kept per DemoSet (keyed by the human models)


def _steps(ds: DemoSet, demos: slice | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(demo, t) of every step of every demo (or of a range of demos)."""
    t = np.arange(ds.actions.shape[1])
    sl = demos or slice(0, ds.D)
    d_idx, t_idx = np.nonzero(t[None, :] < ds.length[sl, None])
    return d_idx + sl.start, t_idx


def one_action_rows(ds: DemoSet, *, first_step_only: bool = False) -> RowSet:
    """The one-action-deviation rows of every demo (cached on the DemoSet)."""
    key = "one_action_t0" if first_step_only else "one_action"
    if key in ds.cache:
        return ds.cache[key]
    # in chunks of demos, so the [steps, A, F] temporaries stay small (rows are grouped
    # per demo, so joining the chunks' row sets gives the all-at-once answer)
    parts = []
    for sl in chunk_slices(ds.D, chunk_size=_ONE_ACTION_DEMOS) or [slice(0, 0)]:
        d_idx, t_idx = _steps(ds, sl)
        if first_step_only:
            keep = t_idx == 0
            d_idx, t_idx = d_idx[keep], t_idx[keep]
        e = ds.env[d_idx]
        s = ds.states[d_idx, t_idx]
        rows = ds.suffix_mu[d_idx, t_idx][:, None, :] - ds.dev_mu[e, s]  # [N, A, F]
        other = np.arange(ds.batch.A)[None, :] != ds.actions[d_idx, t_idx][:, None]
        demo = np.broadcast_to(d_idx[:, None] - sl.start, other.shape)
        parts.append(group_rows(rows[other], demo[other], sl.stop - sl.start))
    out = parts[0] if len(parts) == 1 else concat_rowsets(parts, ds.D)
    ds.cache[key] = out
    return out


_ONE_ACTION_DEMOS = 8192  # demos per chunk of `one_action_rows`


def human_mu(ds: DemoSet, W: np.ndarray, *, method: str | None = None,
             reference_ties: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Feature counts of the human's best tied trajectory from every state of every instance.

    Returns ``(mu_h [E, M, S, F] int64, bounded [E, M])``. `method` defaults to the profile's
    VI method; `reference_ties` (default: the reference profile) emulates the reference's
    capped depth-first enumeration where more than 10 tied trajectories exist.
    """
    method = VI_METHOD[ds.profile] if method is None else method
    if reference_ties is None:
        reference_ties = ds.profile == "reference"
    return human_mu_batch(ds.batch, ds.weights, W, method=method, reference_ties=reference_ties)


def human_values(batch: MDPBatch, W: np.ndarray, method: str,
                 ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray], np.ndarray]:
    """Values of the bounded (instance, model) pairs, returned as
    ``(bounded [E, M], (pair_env, pair_model), Q [P, S, A])``.

    `cfteach.mdp.value_iteration` with `method`; for ``reference`` without sweeping the pairs
    that provably cannot stabilise (``skip_unstable``): only bounded pairs are used here.
    """
    vals = value_iteration(batch, W, method=method, skip_unstable=True)
    pe, pm = np.nonzero(vals.bounded)
    return vals.bounded, (pe, pm), vals.Q[pe, pm]


def human_mu_batch(batch: MDPBatch, w_true: np.ndarray, W: np.ndarray, *, method: str,
                   reference_ties: bool) -> tuple[np.ndarray, np.ndarray]:
    """`human_mu` for any compiled batch (e.g. one instance via ``batch.subset``)."""
    W = np.atleast_2d(np.asarray(W, dtype=float))
    bounded, (pe, pm), Qp = human_values(batch, W, method)
    e_n, m_n = bounded.shape
    mu = np.zeros((e_n, m_n, batch.S, batch.F), dtype=np.int64)
    if len(pe):
        mu[pe, pm] = best_tied_mu(batch, pe, Qp, w_true, reference_limit=(
            REFERENCE_TIED_LIMIT if reference_ties else None))
    return mu, bounded


UNBOUNDED_RULES = ("skip", "loops")

#: The rule for human models with unbounded values, per profile.
DEFAULT_UNBOUNDED = {"reference": "skip", "default": "loops"}


def check_unbounded(rule: str) -> str:
    if rule not in UNBOUNDED_RULES:
        raise ValueError(f"unknown rule for unbounded human models {rule!r} "
                         f"(allowed: {', '.join(UNBOUNDED_RULES)})")
    return rule


def loop_rows(batch: MDPBatch, W: np.ndarray, env: np.ndarray, model: np.ndarray,
              ) -> list[np.ndarray]:
    """For each (instance, model) pair: ``-mu(loop)`` for every positive-reward loop of
    length 1 (a no-op or blocked move) or 2 (there and back) under that model.

    A human model with such a loop would loop forever in that instance (unbounded values).
    Every demonstration there shows the robot not looping, i.e. that the loop is not
    rewarding: ``-mu(loop) . w >= 0``. The true weights satisfy it (they make no loop
    positive, otherwise the demonstrations would be unbounded too). Longer loops are not
    enumerated. Returns one primitive, deduplicated ``[k, F]`` int array per pair.
    """
    W = np.atleast_2d(np.asarray(W, dtype=float))
    out = []
    S = batch.S
    ar = np.arange(S)
    for e, m in zip(np.asarray(env).tolist(), np.asarray(model).tolist(), strict=True):
        feats = np.rint(batch.features[e]).astype(np.int64)  # [S, A, F]
        R = batch.features[e] @ W[m]
        nxt = batch.next_state[e]
        valid = batch.valid[e]
        one = (nxt == ar[:, None]) & valid[:, None] & (R > 0)
        back = nxt[nxt]  # [S, A, A]: s -a-> s2 -b-> back
        two = (valid[:, None, None] & valid[nxt][:, :, None] & (nxt != ar[:, None])[:, :, None]
               & (back == ar[:, None, None]) & (R[:, :, None] + R[nxt] > 0))
        rows = np.vstack([-feats[one], -(feats[:, :, None, :] + feats[nxt])[two]])
        rows = primitive(rows)
        rows = rows[np.any(rows != 0, axis=1)]
        out.append(np.unique(rows, axis=0) if len(rows) else rows.reshape(0, batch.F))
    return out


def _cf_settings(ds: DemoSet, W: np.ndarray, method: str | None, reference_ties: bool | None,
                 unbounded: str | None) -> tuple[np.ndarray, str, bool, str, tuple]:
    """The counterfactual settings with the profile's defaults filled in, and their cache key."""
    W = np.atleast_2d(np.asarray(W, dtype=float))
    method = VI_METHOD[ds.profile] if method is None else method
    if reference_ties is None:
        reference_ties = ds.profile == "reference"
    unbounded = check_unbounded(DEFAULT_UNBOUNDED[ds.profile] if unbounded is None
                                else unbounded)
    return W, method, reference_ties, unbounded, (W.tobytes(), W.shape, method,
                                                  reference_ties, unbounded)


def counterfactual_rows(ds: DemoSet, W: np.ndarray, *, method: str | None = None,
                        reference_ties: bool | None = None, unbounded: str | None = None,
                        ) -> tuple[RowSet, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Joint counterfactual rows of every demo under human models ``W [M, F]``.

    Returns ``(joint RowSet, bounded [E, M], raw)`` where raw = (rows [N, F], demo [N],
    model [N]) before grouping (per-model sets, for callers that need them). `unbounded`:
    what a model with unbounded values in an instance contributes there: ``"skip"`` nothing
    (the reference's rule), ``"loops"`` its positive loops (`loop_rows`); default: the
    profile's rule (`DEFAULT_UNBOUNDED`).
    """
    W, method, reference_ties, unbounded, key = _cf_settings(ds, W, method, reference_ties,
                                                             unbounded)
    memo = ds.cache.setdefault("counterfactual", {})
    if key in memo:
        return memo[key]
    mu_h, bounded = human_mu(ds, W, method=method, reference_ties=reference_ties)
    d_idx, t_idx = _steps(ds)
    e = ds.env[d_idx]
    s = ds.states[d_idx, t_idx]
    rows = ds.suffix_mu[d_idx, t_idx][:, None, :] - mu_h[e, :, s]  # [N, M, F]
    ok = bounded[e]  # [N, M]
    demo = np.broadcast_to(d_idx[:, None], ok.shape)
    model = np.broadcast_to(np.arange(mu_h.shape[1])[None, :], ok.shape)
    flat_rows, flat_demo, flat_model = rows[ok], demo[ok], model[ok]
    if unbounded == "loops":
        ue, um = np.nonzero(~bounded)
        extra_r, extra_d, extra_m = [flat_rows], [flat_demo], [flat_model]
        for e, m, lr in zip(ue.tolist(), um.tolist(), loop_rows(ds.batch, W, ue, um),
                            strict=True):
            if not len(lr):
                continue
            demos_e = np.flatnonzero(ds.env == e)
            extra_r.append(np.tile(lr, (len(demos_e), 1)))
            extra_d.append(np.repeat(demos_e, len(lr)))
            extra_m.append(np.full(len(demos_e) * len(lr), m))
        flat_rows, flat_demo = np.vstack(extra_r), np.concatenate(extra_d)
        flat_model = np.concatenate(extra_m)
    out = group_rows(flat_rows, flat_demo, ds.D), bounded, (flat_rows, flat_demo, flat_model)
    if len(memo) >= _CF_CACHE_SIZE:
        memo.pop(next(iter(memo)))
    memo[key] = out
    return out


# -- chunked (streamed, optionally distributed) counterfactual rows ------------------------

#: Planning chunk budget: (instance, state, human model) triples per chunk. A chunk's working
#: memory is about ``steps x M x F x 8`` bytes a few times over (see docs/parallel.md).
CHUNK_STATE_MODELS = 1 << 16


@dataclass(frozen=True, eq=False)
class PlanChunk:
    """What one worker needs to compute the counterfactual rows of a contiguous range of
    instances: their planning arrays and their demos (views, so building one is free)."""

    batch: MDPBatch  # arrays only (no instances/states: they would pickle the domain)
    w_true: np.ndarray
    demo0: int  # global index of the chunk's first demo
    env: np.ndarray  # [n] local instance index of each demo
    states: np.ndarray  # [n, T+1]
    length: np.ndarray  # [n]
    suffix_mu: np.ndarray  # [n, T+1, F]

    @property
    def n_demos(self) -> int:
        return int(self.env.shape[0])


def plan_chunks(ds: DemoSet, n_models: int, *, min_chunks: int = 1,
                budget: int = CHUNK_STATE_MODELS) -> list[PlanChunk]:
    """Contiguous instance ranges of `ds`, each with at most about `budget` (instance, state,
    model) triples (at least one instance), cut into at least `min_chunks` pieces.

    The rows do not depend on the cut (planning is per instance and model, rows are grouped
    per demo), so the cut may follow the worker count.
    """
    b = ds.batch
    per_instance = max(1, b.S * n_models)
    size = max(1, budget // per_instance)
    n = max(-(-b.E // size), min(min_chunks, b.E))
    bounds = np.linspace(0, b.E, n + 1).round().astype(np.int64)
    first = np.searchsorted(ds.env, bounds)  # demos are instance-major
    out = []
    for e0, e1, d0, d1 in zip(bounds[:-1].tolist(), bounds[1:].tolist(), first[:-1].tolist(),
                              first[1:].tolist(), strict=True):
        sub = MDPBatch(next_state=b.next_state[e0:e1], features=b.features[e0:e1],
                       valid=b.valid[e0:e1], n_states=b.n_states[e0:e1], states=(),
                       state_index=(), instances=(), actions=b.actions,
                       feature_names=b.feature_names)
        out.append(PlanChunk(batch=sub, w_true=ds.weights, demo0=d0, env=ds.env[d0:d1] - e0,
                             states=ds.states[d0:d1], length=ds.length[d0:d1],
                             suffix_mu=ds.suffix_mu[d0:d1]))
    return out


def chunk_rows(chunk: PlanChunk, W: np.ndarray, method: str, reference_ties: bool,
               unbounded: str) -> tuple[RowSet, np.ndarray]:
    """The grouped counterfactual rows of one chunk's demos (local demo indices) and its
    ``bounded [e, M]``: `counterfactual_rows` restricted to a range of instances."""
    mu_h, bounded = human_mu_batch(chunk.batch, chunk.w_true, W, method=method,
                                   reference_ties=reference_ties)
    t = np.arange(chunk.states.shape[1] - 1)
    d_idx, t_idx = np.nonzero(t[None, :] < chunk.length[:, None])
    e = chunk.env[d_idx]
    s = chunk.states[d_idx, t_idx]
    rows = chunk.suffix_mu[d_idx, t_idx][:, None, :] - mu_h[e, :, s]  # [N, M, F]
    del mu_h
    ok = bounded[e]
    flat_rows = [rows[ok]]
    del rows
    flat_demo = [np.broadcast_to(d_idx[:, None], ok.shape)[ok]]
    if unbounded == "loops":
        ue, um = np.nonzero(~bounded)
        for e1, lr in zip(ue.tolist(), loop_rows(chunk.batch, W, ue, um), strict=True):
            if not len(lr):
                continue
            demos_e = np.flatnonzero(chunk.env == e1)
            flat_rows.append(np.tile(lr, (len(demos_e), 1)))
            flat_demo.append(np.repeat(demos_e, len(lr)))
    return group_rows(np.vstack(flat_rows), np.concatenate(flat_demo), chunk.n_demos), bounded


def concat_rowsets(parts: list[RowSet], n_demos: int) -> RowSet:
    """Join RowSets of consecutive demo ranges (in order) into one over all `n_demos`."""
    starts = np.cumsum([0] + [p.n_demos for p in parts])
    if starts[-1] != n_demos:
        raise ValueError(f"the parts cover {starts[-1]} demos, not {n_demos}")
    F = parts[0].F
    rows = np.vstack([p.rows for p in parts]) if parts else np.zeros((0, F), dtype=np.int64)
    demo = np.concatenate([p.demo + s for p, s in zip(parts, starts[:-1].tolist(),
                                                      strict=True)])
    offsets = np.zeros(n_demos + 1, dtype=np.int64)
    np.cumsum(np.bincount(demo, minlength=n_demos), out=offsets[1:])
    return RowSet(rows=rows, demo=demo.astype(np.int64), offsets=offsets)


def sub_rowset(rowset: RowSet, demos: np.ndarray) -> RowSet:
    """The rows of some demos, renumbered ``0..len(demos)-1`` (what a worker is sent)."""
    demos = np.asarray(demos, dtype=np.int64)
    lo, hi = rowset.offsets[demos], rowset.offsets[demos + 1]
    counts = hi - lo
    offsets = np.zeros(len(demos) + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    idx = np.repeat(lo - offsets[:-1], counts) + np.arange(offsets[-1])
    return RowSet(rows=rowset.rows[idx], demo=np.repeat(np.arange(len(demos)), counts),
                  offsets=offsets)


def counterfactual_rowset(ds: DemoSet, W: np.ndarray, *, method: str | None = None,
                          reference_ties: bool | None = None, unbounded: str | None = None,
                          executor: Any = None, budget: int = CHUNK_STATE_MODELS,
                          ) -> tuple[RowSet, np.ndarray]:
    """`counterfactual_rows` without the raw rows, streamed over instance chunks.

    Identical ``(joint RowSet, bounded [E, M])``, but peak memory grows with a chunk
    (`budget` instance-state-model triples), not with the number of demos. With a
    `cfteach.parallel.Executor`, the chunks run on its workers.
    """
    W, method, reference_ties, unbounded, key = _cf_settings(ds, W, method, reference_ties,
                                                             unbounded)
    memo = ds.cache.setdefault("counterfactual_rowset", {})
    if key in memo:
        return memo[key]
    workers = 1 if executor is None else executor.n_workers
    chunks = plan_chunks(ds, len(W), min_chunks=workers, budget=budget)
    fn = partial(chunk_rows, W=W, method=method, reference_ties=reference_ties,
                 unbounded=unbounded)
    parts = [fn(c) for c in chunks] if workers == 1 else executor.map(fn, chunks)
    out = (concat_rowsets([p[0] for p in parts], ds.D),
           np.vstack([p[1] for p in parts]))
    if out[0].rows.nbytes <= _CF_MEMO_BYTES:  # small domains: the conditions share round 1
        if len(memo) >= _CF_CACHE_SIZE:
            memo.pop(next(iter(memo)))
        memo[key] = out
    return out


_CF_MEMO_BYTES = 16 << 20
