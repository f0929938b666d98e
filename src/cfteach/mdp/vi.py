"""Batched undiscounted value iteration over many instances x many weight vectors.

Rewards are linear in the features, r = phi . w, and gamma = 1, so a weight vector can make a
cycle of positive total reward and the values diverge. Two methods:

* ``"reference"``: what the authors' code does (docs/domains.md, "Value iteration"): V0 = 0,
  sweeps until the largest change is <= 1e-25, at most 1000 sweeps, ``bounded`` = fewer than
  1000 sweeps were needed. This flag is wrong for cheap no-op weights (a bounded fixed point
  that takes > 1000 sweeps to reach from 0), which the reference silently treats as unbounded.
  Pairs with a proven positive cycle are not swept (the reference's sweeps could never settle):
  they get ``bounded = False``, ``sweeps = 1000`` and, unlike the reference, ``V = +inf``. With
  ``skip_unstable=True`` also pairs proven unable to stabilise within 1000 sweeps (cheap
  no-ops, see `_cannot_stabilise`) are not swept: ``bounded = False``, ``sweeps = 1000`` and V
  = their true (exact) values instead of the reference's 1000th sweep. Callers that only use
  the bounded pairs (the counterfactual constraints) save most of the sweeping. We use
  synchronous (Jacobi) sweeps, the reference Gauss-Seidel ones in set order; the fixed point is
  the same, the sweep count can differ only in borderline cases.
* ``"exact"`` (default): Bellman-Ford longest paths to the terminal. V starts at -inf on real
  states (0 at the sink); after ``n + 1`` sweeps (n = real states) any further change proves
  a positive-reward cycle. Bounded pairs get the true optimal values; unbounded pairs get
  ``V = +inf`` on every real state (do not use their Q). A real state that cannot reach the
  terminal keeps ``V = -inf`` (never the case in the built-in domains).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cfteach.mdp.arrays import MDPBatch

REFERENCE_TOL = 1e-25
REFERENCE_MAX_SWEEPS = 1000
TIE_TOL = 1e-5
_EXACT_REL_TOL = 1e-12  # changes below this are float creep, not progress
_CYCLE_CHECK_EVERY = 8  # sweeps between greedy-graph positive-cycle checks


@dataclass(frozen=True, eq=False)
class Values:
    """Result of `value_iteration` for E instances x M weight vectors.

    Attributes:
        Q: ``[E, M, S, A]`` action values (sink and padding rows are 0-ish; ignore them).
        V: ``[E, M, S]`` state values; ``V[..., S-1] = 0`` (terminal sink).
        bounded: ``[E, M]`` see the module docstring for the two methods' meaning.
        sweeps: ``[E, M]`` sweeps run (reference: the reference's iteration count).
        method: ``"exact"`` or ``"reference"``.
        env: ``[E]`` indices of the instances in the batch these values belong to.
        W: ``[M, F]`` the weight vectors.
    """

    Q: np.ndarray
    V: np.ndarray
    bounded: np.ndarray
    sweeps: np.ndarray
    method: str
    env: np.ndarray
    W: np.ndarray


def _as_weights(W: np.ndarray, n_features: int) -> np.ndarray:
    W = np.asarray(W, dtype=float)
    if W.ndim == 1:
        W = W[None, :]
    if W.ndim != 2 or W.shape[1] != n_features:
        raise ValueError(f"weights must have shape [M, {n_features}] (one column per feature), "
                         f"got {W.shape}")
    if W.shape[0] == 0:
        raise ValueError("weights must hold at least one weight vector")
    if not np.isfinite(W).all():
        raise ValueError("weights contain NaN or infinity")
    return W


def _env_indices(batch: MDPBatch, env: int | Sequence[int] | np.ndarray | None) -> np.ndarray:
    if env is None:
        return np.arange(batch.E)
    idx = np.atleast_1d(np.asarray(env, dtype=np.int64))
    if idx.ndim != 1 or idx.size == 0 or idx.min() < 0 or idx.max() >= batch.E:
        raise IndexError(f"env must be instance indices in 0..{batch.E - 1}, got {env!r}")
    return idx


def _progress(total: int, desc: str):  # noqa: ANN202 - tqdm or a no-op
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, disable=total <= 1 or not sys.stderr.isatty(),
                file=sys.stderr, leave=False)


def value_iteration(
    batch: MDPBatch,
    W: np.ndarray,
    *,
    method: str = "exact",
    env: int | Sequence[int] | np.ndarray | None = None,
    chunk_bytes: float = 200e6,
    skip_unstable: bool = False,
) -> Values:
    """Solve every (instance, weight vector) pair at once.

    Args:
        batch: compiled instances (`compile_domain` / `compile_instances`).
        W: ``[M, F]`` (or ``[F]``) weight vectors, used as given (not normalised).
        method: ``"exact"`` (true gamma = 1 answer) or ``"reference"`` (the authors' solver).
        env: optional instance indices to solve (default: all of the batch).
        chunk_bytes: working-memory budget per chunk of pairs.
        skip_unstable: reference only: do not sweep pairs proven unable to stabilise
            (see the module docstring); their flags and sweep counts are unchanged.
    """
    if method not in ("exact", "reference"):
        raise ValueError(f"method must be 'exact' or 'reference', got {method!r}")
    W = _as_weights(W, batch.F)
    idx = _env_indices(batch, env)
    b = batch if env is None else batch.subset(idx)
    e_n, m_n, s_n, a_n = b.E, W.shape[0], b.S, b.A
    Q = np.empty((e_n, m_n, s_n, a_n))
    V = np.empty((e_n, m_n, s_n))
    bounded = np.empty((e_n, m_n), dtype=bool)
    sweeps = np.empty((e_n, m_n), dtype=np.int64)

    per_pair = s_n * a_n * 8 * 4
    pairs = max(1, int(chunk_bytes // per_pair))
    mc = min(m_n, pairs)
    ec = max(1, min(e_n, pairs // mc))
    blocks = [(e0, m0) for e0 in range(0, e_n, ec) for m0 in range(0, m_n, mc)]
    with _progress(len(blocks), f"value iteration ({method})") as bar:
        for e0, m0 in blocks:
            e1, m1 = min(e_n, e0 + ec), min(m_n, m0 + mc)
            ne, nm = e1 - e0, m1 - m0
            # Solvers work in [pair, action, state] layout: the max over actions is then an
            # element-wise max of contiguous rows, ~3x faster than reducing a short last axis.
            R = np.ascontiguousarray(np.einsum("esaf,mf->emas", b.features[e0:e1], W[m0:m1])
                                     ).reshape(ne * nm, a_n, s_n)
            nxt = np.broadcast_to(b.next_state[e0:e1, None].transpose(0, 1, 3, 2),
                                  (ne, nm, a_n, s_n)).reshape(ne * nm, a_n, s_n)
            valid = np.broadcast_to(b.valid[e0:e1, None], (ne, nm, s_n)).reshape(ne * nm, s_n)
            n_valid = np.broadcast_to(b.n_states[e0:e1, None], (ne, nm)).reshape(-1)
            v, bnd, sw = _solve_exact(R, nxt, valid, n_valid)
            if method == "reference":
                # A proven positive cycle never lets the reference's sweeps settle, so only
                # the other pairs need the (up to 1000) reference sweeps.
                ok = np.flatnonzero(bnd)
                sw[:] = REFERENCE_MAX_SWEEPS
                if skip_unstable and ok.size:
                    stuck = _cannot_stabilise(R[ok], nxt[ok], valid[ok], v[ok])
                    bnd[ok[stuck]] = False
                    ok = ok[~stuck]
                if ok.size:
                    v[ok], bnd[ok], sw[ok] = _solve_reference(R[ok], nxt[ok])
            q = R + _gather(v, nxt)
            Q[e0:e1, m0:m1] = q.reshape(ne, nm, a_n, s_n).transpose(0, 1, 3, 2)
            V[e0:e1, m0:m1] = v.reshape(ne, nm, s_n)
            bounded[e0:e1, m0:m1] = bnd.reshape(ne, nm)
            sweeps[e0:e1, m0:m1] = sw.reshape(ne, nm)
            bar.update(1)
    return Values(Q=Q, V=V, bounded=bounded, sweeps=sweeps, method=method, env=idx, W=W)


def _gather(v: np.ndarray, nxt: np.ndarray) -> np.ndarray:
    """v[p, nxt[p, ...]] for every pair p."""
    p, s = v.shape
    flat = nxt + (np.arange(p, dtype=nxt.dtype) * s)[:, None, None]
    return v.ravel()[flat]


def _solve_reference(R: np.ndarray, nxt: np.ndarray) -> tuple[np.ndarray, ...]:
    """Spec §3: V0 = 0, stop at max |dV| <= 1e-25, at most 1000 sweeps. R, nxt: [P, A, S]."""
    p_n, _, s_n = R.shape
    V = np.zeros((p_n, s_n))
    sweeps = np.full(p_n, REFERENCE_MAX_SWEEPS, dtype=np.int64)
    act = np.arange(p_n)
    Ra, Va = R, V.copy()
    flat = nxt + (np.arange(p_n) * s_n)[:, None, None]
    first = np.zeros(p_n, dtype=np.int64)  # sweep at which each active pair converged
    k = 0
    while act.size and k < REFERENCE_MAX_SWEEPS:
        k += 1
        Vn = (Ra + Va.ravel()[flat]).max(axis=1)
        delta = np.abs(Vn - Va).max(axis=-1)
        Va = Vn
        first = np.where((first == 0) & (delta <= REFERENCE_TOL), k, first)
        done = first > 0
        if done.all() or (k % 8 == 0 and done.mean() > 0.1) or k == REFERENCE_MAX_SWEEPS:
            V[act[done]] = Va[done]
            sweeps[act[done]] = first[done]
            keep = ~done
            act, Ra, Va, first = act[keep], Ra[keep], Va[keep], first[keep]
            flat = nxt[act] + (np.arange(act.size) * s_n)[:, None, None]
    if act.size:
        V[act] = Va
    bounded = sweeps < REFERENCE_MAX_SWEEPS
    return V, bounded, sweeps


def _cannot_stabilise(R: np.ndarray, nxt: np.ndarray, valid: np.ndarray,
                      v_exact: np.ndarray) -> np.ndarray:
    """Pairs the reference cannot stabilise within 1000 sweeps, proven without sweeping.

    From V0 = 0, after k sweeps V_k(s) >= k * (best self-loop reward at s). If every reward
    is negative, every cycle is, so the only fixed point is the true V*; a state with
    V*(s) < 999 * (best self-loop reward) is therefore still above V* at sweep 999, and the
    sweeps cannot have stopped earlier. (Cheap no-ops make exactly these pairs: docs/domains.md,
    "Value iteration".)
    R, nxt: ``[P, A, S]``; valid, v_exact: ``[P, S]``.
    """
    s_n = R.shape[2]
    loop = nxt == np.arange(s_n)[None, None, :]
    r_loop = np.where(loop, R, -np.inf).max(axis=1)  # [P, S]
    all_neg = np.all(np.where(valid[:, None, :], R < 0, True), axis=(1, 2))
    bound = (REFERENCE_MAX_SWEEPS - 1) * r_loop
    margin = 1e-6 * (1.0 + np.abs(v_exact))
    with np.errstate(invalid="ignore"):
        stuck = valid & np.isfinite(r_loop) & (v_exact < bound - margin)
    return all_neg & stuck.any(axis=1)


def _solve_exact(R: np.ndarray, nxt: np.ndarray, valid: np.ndarray,
                 n_valid: np.ndarray) -> tuple[np.ndarray, ...]:
    """Bellman-Ford longest paths to the terminal with positive-cycle detection (R: [P, A, S])."""
    p_n, _, s_n = R.shape
    V = np.where(valid, -np.inf, 0.0)
    bounded = np.ones(p_n, dtype=bool)
    sweeps = np.zeros(p_n, dtype=np.int64)
    vmask = valid[:, None, :]
    # A positive-reward self-loop (e.g. a no-op with positive reward) is a positive cycle.
    self_loop = nxt == np.arange(s_n)[None, None, :]
    pos_loop = (self_loop & vmask & (R > 0)).any(axis=(1, 2))
    bounded[pos_loop] = False
    # No simple path to the terminal can earn more than n * (largest reward).
    r_max = np.maximum(np.where(vmask, R, -np.inf).max(axis=(1, 2)), 0.0)
    upper = n_valid * r_max
    upper = upper + 1e-9 * (1.0 + upper)
    limit = n_valid + 1

    act = np.flatnonzero(~pos_loop)
    Ra, Va, lim, up = R[act], V[act], limit[act], upper[act]
    flat = nxt[act] + (np.arange(act.size) * s_n)[:, None, None]
    status = np.zeros(act.size, dtype=np.int8)  # 0 running, 1 converged, 2 unbounded
    stop_at = np.zeros(act.size, dtype=np.int64)
    k = 0
    while act.size:
        k += 1
        Qa = Ra + Va.ravel()[flat]
        Vn = Qa.max(axis=1)
        with np.errstate(invalid="ignore"):
            gain = Vn - Va
            changed = (gain > _EXACT_REL_TOL * np.maximum(1.0, np.abs(Vn))).any(axis=-1)
        Va = Vn
        running = status == 0
        conv = running & ~changed
        diverged = running & changed & ((k >= lim) | (Vn > up[:, None]).any(axis=-1))
        if k % _CYCLE_CHECK_EVERY == 0:
            # A positive cycle in the current greedy policy's graph is a certificate.
            check = running & changed & ~diverged
            if check.any():
                diverged[check] = _greedy_has_positive_cycle(Qa[check], Ra[check],
                                                             flat[check] % s_n)
        status[conv] = 1
        status[diverged] = 2
        stop_at[conv | diverged] = k
        done = status > 0
        if done.all() or (k % 8 == 0 and done.mean() > 0.1):
            ids = act[done]
            V[ids] = Va[done]
            sweeps[ids] = stop_at[done]
            bounded[ids] = status[done] == 1
            keep = ~done
            act, Ra, Va, lim, up = act[keep], Ra[keep], Va[keep], lim[keep], up[keep]
            status, stop_at = status[keep], stop_at[keep]
            flat = nxt[act] + (np.arange(act.size) * s_n)[:, None, None]
    V[~bounded] = np.where(valid[~bounded], np.inf, 0.0)
    return V, bounded, sweeps


def _greedy_has_positive_cycle(Q: np.ndarray, R: np.ndarray, nxt: np.ndarray) -> np.ndarray:
    """Per pair: does the greedy policy's successor graph contain a positive-reward cycle?

    The graph is functional (one successor per state), so pointer doubling finds, for every
    state, a node on the cycle it ends in, and the smallest node of that cycle as its label;
    summing rewards per label gives every cycle's total.
    """
    p_n, _, s_n = Q.shape
    pi = Q.argmax(axis=1)[:, None, :]
    f = np.take_along_axis(nxt, pi, axis=1)[:, 0]  # [P, S] local successor
    g = np.take_along_axis(R, pi, axis=1)[:, 0]  # [P, S] reward
    off = (np.arange(p_n) * s_n)[:, None]
    jump = (f + off).ravel()  # global index after 2^j steps
    low = np.minimum(np.arange(p_n * s_n), jump)  # smallest node seen in 2^j + 1 steps
    for _ in range(max(1, int(np.ceil(np.log2(s_n)))) + 1):
        low = np.minimum(low, low[jump])
        jump = jump[jump]
    on_cycle = np.zeros(p_n * s_n, dtype=bool)
    on_cycle[jump] = True  # after >= S steps every walk is on its cycle
    totals = np.bincount(low[on_cycle], weights=g.ravel()[on_cycle], minlength=p_n * s_n)
    scale = np.bincount(low[on_cycle], weights=np.abs(g.ravel()[on_cycle]),
                        minlength=p_n * s_n)
    positive = totals > 1e-9 * np.maximum(1.0, scale)
    return np.asarray(positive.reshape(p_n, s_n).any(axis=1))


def greedy_actions(Q: np.ndarray) -> np.ndarray:
    """First arg-max in action order under exact float comparison (the reference's rule)."""
    return np.argmax(Q, axis=-1)


def tied_actions(Q: np.ndarray, tol: float = TIE_TOL) -> np.ndarray:
    """bool mask of the actions with |Q - max_a Q| < tol (the reference's tied-optimal set)."""
    with np.errstate(invalid="ignore"):
        return np.abs(Q - Q.max(axis=-1, keepdims=True)) < tol
