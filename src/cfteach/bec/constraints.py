"""One-action-deviation constraints (spec §5.1) and counterfactual constraints (spec §6.2),
for every candidate demonstration at once.

One-action rows of demo d: for every step t and every action b other than the demo's,
``suffix_mu[d, t] - mu(rollout from s_t forcing b, then greedy)``.

Counterfactual rows of demo d under human model w_h (bounded values only): for every step t,
``suffix_mu[d, t] - mu(h*)``, where h* is the human's tied-optimal trajectory from s_t with the
highest true reward ("benefit of the doubt"). The `reference` profile reproduces how the
authors' code picks h* when more than 10 tied trajectories exist (see `_reference_first11`).
"""

from __future__ import annotations

import numpy as np

from cfteach.bec.demos import VI_METHOD, DemoSet
from cfteach.bec.rows import RowSet, group_rows, primitive
from cfteach.mdp import MDPBatch, value_iteration
from cfteach.mdp.rollout import MAX_STEPS
from cfteach.mdp.vi import REFERENCE_MAX_SWEEPS, REFERENCE_TOL, tied_actions

#: The reference's depth-first enumeration stops expanding after MORE than this many paths.
REFERENCE_TIED_LIMIT = 10

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
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Values of the bounded (instance, model) pairs: ``(pair_env, pair_model, Q [P, S, A])``
    plus ``bounded [E, M]``, returned as ``(bounded, (pe, pm), Q)``.

    ``exact`` is `cfteach.mdp.value_iteration`. ``reference`` follows the same rule as
    ``value_iteration(method="reference")`` (V0 = 0, synchronous sweeps, stabilised iff the
    largest change drops to <= 1e-25 within 1000 sweeps), but only on the pairs the exact
    solver finds free of positive-reward cycles: the others grow every sweep and can never
    stabilise, and skipping their 1000 sweeps is most of the reference's planning time.
    tests/test_bec.py checks the result against ``value_iteration`` itself.
    """
    W = np.atleast_2d(np.asarray(W, dtype=float))
    exact = value_iteration(batch, W, method="exact")
    if method == "exact":
        pe, pm = np.nonzero(exact.bounded)
        return exact.bounded, (pe, pm), exact.Q[pe, pm]
    if method != "reference":
        raise ValueError(f"method must be 'exact' or 'reference', got {method!r}")
    pe, pm = np.nonzero(exact.bounded)
    R = np.einsum("psaf,pf->psa", batch.features[pe], W[pm])
    nxt = batch.next_state[pe]
    slow = _too_slow_for_reference(R, nxt, batch.valid[pe], exact.V[pe, pm])
    pe, pm, R, nxt = pe[~slow], pm[~slow], R[~slow], nxt[~slow]
    V, ok = _reference_sweeps(R, nxt)
    bounded = np.zeros_like(exact.bounded)
    bounded[pe[ok], pm[ok]] = True
    flat = nxt + (np.arange(len(pe)) * batch.S)[:, None, None]
    Q = R + V.reshape(-1)[flat]
    return bounded, (pe[ok], pm[ok]), Q[ok]


def _too_slow_for_reference(R: np.ndarray, nxt: np.ndarray, valid: np.ndarray,
                            v_exact: np.ndarray) -> np.ndarray:
    """Pairs the reference cannot stabilise within 1000 sweeps, proven without sweeping.

    From V0 = 0, after k sweeps V_k(s) >= k * (best self-loop reward at s). If every reward
    is negative, every cycle is, so the only fixed point is the true V*; a state with
    V*(s) < 999 * (best self-loop reward) is therefore still above V* at sweep 999, and the
    sweeps cannot have stopped earlier. (Cheap no-ops make exactly these pairs, spec §3.)
    """
    s_n = R.shape[1]
    loop = nxt == np.arange(s_n)[None, :, None]
    r_loop = np.where(loop, R, -np.inf).max(axis=-1)  # [P, S]
    all_neg = np.all(np.where(valid[..., None], R < 0, True), axis=(1, 2))
    bound = (REFERENCE_MAX_SWEEPS - 1) * r_loop
    margin = 1e-6 * (1.0 + np.abs(v_exact))
    with np.errstate(invalid="ignore"):
        stuck = valid & np.isfinite(r_loop) & (v_exact < bound - margin)
    return all_neg & stuck.any(axis=1)


def _reference_sweeps(R: np.ndarray, nxt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """V0 = 0 synchronous sweeps; (V [P, S], stabilised [P])."""
    p_n, s_n, _ = R.shape
    V = np.zeros((p_n, s_n))
    ok = np.zeros(p_n, dtype=bool)
    act = np.arange(p_n)
    Va = V.copy()
    Ra = np.ascontiguousarray(np.moveaxis(R, 2, 0))  # [A, P, S]: maxima over A elementwise
    nxt_a = np.moveaxis(nxt, 2, 0)
    flat = nxt_a + (np.arange(p_n) * s_n)[None, :, None]
    for k in range(1, REFERENCE_MAX_SWEEPS + 1):
        if not act.size:
            break
        v = Va.ravel()
        Vn = Ra[0] + v[flat[0]]
        for a in range(1, Ra.shape[0]):
            np.maximum(Vn, Ra[a] + v[flat[a]], out=Vn)
        done = np.abs(Vn - Va).max(axis=-1) <= REFERENCE_TOL
        Va = Vn
        if done.any():
            V[act[done]] = Va[done]
            ok[act[done]] = k < REFERENCE_MAX_SWEEPS
            keep = ~done
            act, Va, Ra = act[keep], Va[keep], Ra[:, keep]
            flat = nxt_a[:, act] + (np.arange(act.size) * s_n)[None, :, None]
    return V, ok


def human_mu_batch(batch: MDPBatch, w_true: np.ndarray, W: np.ndarray, *, method: str,
                   reference_ties: bool) -> tuple[np.ndarray, np.ndarray]:
    """`human_mu` for any compiled batch (e.g. one instance via ``batch.subset``)."""
    W = np.atleast_2d(np.asarray(W, dtype=float))
    bounded, (pe, pm), Qp = human_values(batch, W, method)
    e_n, m_n = bounded.shape
    mu = np.zeros((e_n, m_n, batch.S, batch.F), dtype=np.int64)
    if not len(pe):
        return mu, bounded
    pairs = _Pairs(batch, pe, Qp)
    mu_p = pairs.best_tied(w_true)
    if reference_ties:
        fix = pairs.reference_first11(w_true)
        if fix is not None:
            p, s, mu_fix = fix
            mu_p[p, s] = mu_fix
    mu[pe, pm] = mu_p
    return mu, bounded


class _Pairs:
    """Planning data of P bounded (instance, model) pairs, flattened for fast gathers."""

    def __init__(self, batch: MDPBatch, env: np.ndarray, Q: np.ndarray) -> None:
        self.P, self.S, self.A, self.F = len(env), batch.S, batch.A, batch.F
        self.sink = batch.sink
        self.real = batch.valid[env]  # [P, S]
        self.tied = tied_actions(Q) & self.real[..., None]  # [P, S, A]
        self.nxt = batch.next_state[env]  # [P, S, A]
        self.flat_nxt = self.nxt + (np.arange(self.P) * self.S)[:, None, None]
        self.phi = batch.features[env]  # [P, S, A, F] float, integer-valued

    def best_tied(self, w_true: np.ndarray) -> np.ndarray:
        """mu [P, S, F] of the tied trajectory (horizon 25) with the highest true reward.

        A max-plus DP over the horizon; ``w . mu`` is evaluated on the integer feature counts
        (like the reference), so equal counts compare equal and ties go to the first action,
        i.e. to the first trajectory of the reference's depth-first enumeration.
        """
        w = np.asarray(w_true, dtype=float)
        n = self.P * self.S
        phi = [np.ascontiguousarray(self.phi[..., f]) for f in range(self.F)]
        mu = [np.zeros(n) for _ in range(self.F)]
        neg = np.where(self.tied, 0.0, -np.inf)
        real = self.real.reshape(-1)
        row = np.arange(n) * self.A
        for _ in range(MAX_STEPS):
            cand = [phi[f] + mu[f][self.flat_nxt] for f in range(self.F)]  # [P, S, A] each
            val = neg.copy()
            for f in range(self.F):
                val += w[f] * cand[f]
            pick = row + np.argmax(val, axis=-1).reshape(-1)
            new = [np.where(real, cand[f].reshape(-1)[pick], 0.0) for f in range(self.F)]
            if all(np.array_equal(a, b) for a, b in zip(new, mu, strict=True)):
                break  # a fixed point: longer horizons choose the same trajectories
            mu = new
        out = np.stack(mu, axis=-1)
        return np.rint(out).astype(np.int64).reshape(self.P, self.S, self.F)

    def path_counts(self, cap: int) -> np.ndarray:
        """N[k, P*S]: tied paths with k steps left (terminal / horizon end = 1), capped."""
        N = np.ones((MAX_STEPS + 1, self.P * self.S), dtype=np.int64)
        real = self.real.reshape(-1)
        for k in range(1, MAX_STEPS + 1):
            tot = np.where(self.tied, N[k - 1][self.flat_nxt], 0).sum(axis=-1).reshape(-1)
            N[k] = np.where(real, np.minimum(tot, cap), 1)
            if np.array_equal(N[k], N[k - 1]):
                N[k + 1 :] = N[k]  # a fixed point of the recursion
                break
        return N

    def reference_first11(self, w_true: np.ndarray):  # noqa: ANN201
        """Where more than 10 tied trajectories start at a state, the reference records only
        the first 11 in depth-first action order (it stops expanding once more than 10 are
        recorded) and keeps the best of those by true reward, first on exact ties. Unrank
        exactly those 11 paths from the path counts; returns ``(pair, state, mu)`` or None.
        """
        R = REFERENCE_TIED_LIMIT + 1
        N = self.path_counts(cap=R)
        idx = np.flatnonzero((N[MAX_STEPS] > REFERENCE_TIED_LIMIT) & self.real.reshape(-1))
        if not len(idx):
            return None
        n = len(idx)
        p = idx // self.S
        cur = np.repeat(idx[:, None], R, axis=1)  # flat p * S + s
        base = np.repeat((p * self.S)[:, None], R, axis=1)
        rank = np.broadcast_to(np.arange(R), (n, R)).copy()
        mu = np.zeros((n, R, self.F))
        tied = self.tied.reshape(-1, self.A)
        flat_nxt = self.flat_nxt.reshape(-1, self.A)
        phi = self.phi.reshape(-1, self.A, self.F)
        sink = self.sink
        for k in range(MAX_STEPS, 0, -1):
            live = (cur - base) != sink
            if not live.any():
                break
            nxt = flat_nxt[cur]  # [n, R, A]
            cnt = np.where(tied[cur], N[k - 1][nxt], 0)
            cum = np.cumsum(cnt, axis=-1)
            a = np.argmax(cum > rank[..., None], axis=-1)
            before = np.where(a > 0, np.take_along_axis(cum, np.maximum(a - 1, 0)[..., None],
                                                        axis=-1)[..., 0], 0)
            mu += np.where(live[..., None],
                           np.take_along_axis(phi[cur], a[..., None, None], axis=2)[:, :, 0],
                           0.0)
            rank = np.where(live, rank - before, rank)
            cur = np.where(live, np.take_along_axis(nxt, a[..., None], axis=-1)[..., 0], cur)
        val = mu @ np.asarray(w_true, dtype=float)
        best = np.argmax(val, axis=1)  # ranks 0..10 all exist since the count exceeds 10
        mu_best = np.rint(mu[np.arange(n), best]).astype(np.int64)
        return p, idx % self.S, mu_best


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
