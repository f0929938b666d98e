"""One-action-deviation constraints (spec §5.1) and counterfactual constraints (spec §6.2),
for every candidate demonstration at once.

One-action rows of demo d: for every step t and every action b other than the demo's,
``suffix_mu[d, t] - mu(rollout from s_t forcing b, then greedy)``.

Counterfactual rows of demo d under human model w_h (bounded values only): for every step t,
``suffix_mu[d, t] - mu(h*)``, where h* is the human's tied-optimal trajectory from s_t with the
highest true reward ("benefit of the doubt"). The `reference` profile reproduces how the
authors' code picks h* when more than 10 tied trajectories exist (`cfteach.mdp.best_tied_mu`).
"""

from __future__ import annotations

import numpy as np

from cfteach.bec.demos import VI_METHOD, DemoSet
from cfteach.bec.rows import RowSet, group_rows, primitive
from cfteach.mdp import MDPBatch, value_iteration
from cfteach.mdp.tied import REFERENCE_TIED_LIMIT, best_tied_mu

_CF_CACHE_SIZE = 8  # counterfactual row sets kept per DemoSet (keyed by the human models)


def _steps(ds: DemoSet) -> tuple[np.ndarray, np.ndarray]:
    """(demo, t) of every step of every demo."""
    t = np.arange(ds.actions.shape[1])
    d_idx, t_idx = np.nonzero(t[None, :] < ds.length[:, None])
    return d_idx, t_idx


def one_action_rows(ds: DemoSet, *, first_step_only: bool = False) -> RowSet:
    """The one-action-deviation rows of every demo (cached on the DemoSet)."""
    key = "one_action_t0" if first_step_only else "one_action"
    if key in ds.cache:
        return ds.cache[key]
    d_idx, t_idx = _steps(ds)
    if first_step_only:
        keep = t_idx == 0
        d_idx, t_idx = d_idx[keep], t_idx[keep]
    e = ds.env[d_idx]
    s = ds.states[d_idx, t_idx]
    rows = ds.suffix_mu[d_idx, t_idx][:, None, :] - ds.dev_mu[e, s]  # [N, A, F]
    other = np.arange(ds.batch.A)[None, :] != ds.actions[d_idx, t_idx][:, None]
    demo = np.broadcast_to(d_idx[:, None], other.shape)
    out = group_rows(rows[other], demo[other], ds.D)
    ds.cache[key] = out
    return out


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


def counterfactual_rows(ds: DemoSet, W: np.ndarray, *, method: str | None = None,
                        reference_ties: bool | None = None, unbounded: str | None = None,
                        ) -> tuple[RowSet, np.ndarray, np.ndarray]:
    """Joint counterfactual rows of every demo under human models ``W [M, F]``.

    Returns ``(joint RowSet, bounded [E, M], raw)`` where raw = (rows [N, F], demo [N],
    model [N]) before grouping (per-model sets, for callers that need them). `unbounded`:
    what a model with unbounded values in an instance contributes there: ``"skip"`` nothing
    (the reference's rule), ``"loops"`` its positive loops (`loop_rows`); default: the
    profile's rule (`DEFAULT_UNBOUNDED`).
    """
    W = np.atleast_2d(np.asarray(W, dtype=float))
    method = VI_METHOD[ds.profile] if method is None else method
    if reference_ties is None:
        reference_ties = ds.profile == "reference"
    unbounded = check_unbounded(DEFAULT_UNBOUNDED[ds.profile] if unbounded is None
                                else unbounded)
    key = (W.tobytes(), W.shape, method, reference_ties, unbounded)
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
