"""Tied-optimal trajectories of a human model, by dynamic programming (the counterfactual
`pi_w` of the paper's Eq. (3); docs/domains.md, "Benefit of the doubt").

The reference enumerates every trajectory that takes only tied-optimal actions under the
human's weights (depth first, action order, length <= 25 unless it reaches the terminal) and
keeps the one with the highest *true* reward ("benefit of the doubt"). Enumeration is
exponential; here the same choice is a max-plus DP over the horizon:

    U_0(s) = 0,  U_k(s) = max over tied a of  w* . (phi(s, a) + mu_{k-1}(next(s, a)))

where mu_k(s) is the feature count of the chosen length-k continuation. Comparing w* . mu
(the dot product of integer feature counts, like the reference) makes trajectories with equal
feature counts compare exactly equal; such ties go to the first action in action order, which
yields the lexicographically smallest action sequence, i.e. the first one the reference's
depth-first enumeration finds. The DP stops early at a fixed point (longer horizons then
choose the same trajectories), which most (instance, model) pairs reach long before 25.

Where more than 10 tied trajectories start at a state, the reference records only the first
11 in depth-first order and keeps the best of those; `best_tied_mu(..., reference_limit=10)`
reproduces that by unranking exactly those 11 paths from the path counts.

All work is done on flat (instance, model) *pairs*: `best_tied_trajectories` solves a full
``[E, M]`` grid, `best_tied_mu` only the pairs it is given (e.g. the bounded ones).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfteach.mdp.arrays import MDPBatch
from cfteach.mdp.rollout import MAX_STEPS
from cfteach.mdp.vi import TIE_TOL, tied_actions

#: The reference's depth-first enumeration stops expanding after MORE than this many paths.
REFERENCE_TIED_LIMIT = 10


@dataclass(frozen=True, eq=False)
class BestTied:
    """DP result for ``[E, M, S]`` start states.

    Attributes:
        first_action: int8 ``[H, E, M, S]``; ``first_action[k - 1]`` is the action to take
            with k steps of horizon left (-1: terminal sink, or no tied action).
        mu: ``[E, M, S, F]`` feature counts of the chosen trajectory (full horizon H).
        value: ``[E, M, S]`` its true reward ``w_true . mu`` (-inf if none exists).
        length: ``[E, M, S]`` its number of steps.
    """

    first_action: np.ndarray
    mu: np.ndarray
    value: np.ndarray
    length: np.ndarray
    batch: MDPBatch

    @property
    def horizon(self) -> int:
        return self.first_action.shape[0]

    def actions(self, env: int, model: int, state: int) -> list[int]:
        """The chosen trajectory's actions from state index `state`."""
        nxt = self.batch.next_state[env]
        out: list[int] = []
        s = state
        for k in range(self.horizon, 0, -1):
            a = int(self.first_action[k - 1, env, model, s])
            if a < 0:
                break
            out.append(a)
            s = int(nxt[s, a])
        return out


class _Pairs:
    """Planning data of P (instance, model) pairs, flattened to ``P * S`` rows for gathers."""

    def __init__(self, batch: MDPBatch, env: np.ndarray, tied: np.ndarray) -> None:
        self.P, self.S, self.A, self.F = len(env), batch.S, batch.A, batch.F
        self.n = self.P * self.S
        self.sink = batch.sink
        self.real = batch.valid[env].reshape(-1)  # [n]
        self.tied = (tied & batch.valid[env][..., None]).reshape(self.n, self.A)
        self.flat_nxt = (batch.next_state[env]
                         + (np.arange(self.P) * self.S)[:, None, None]).reshape(self.n, self.A)
        self._env = env
        self._batch = batch
        feats = batch.features  # [E, S, A, F] float, integer-valued
        self.phi_f = [feats[..., f][env].reshape(self.n, self.A) for f in range(self.F)]

    @property
    def phi(self) -> np.ndarray:
        """``[n, A, F]`` features (only the reference unranking needs this layout)."""
        return self._batch.features[self._env].reshape(self.n, self.A, self.F)

    def best(self, w: np.ndarray, horizon: int, record_first: bool | str,
             must_finish: bool = False,
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """The max-plus DP: (mu [n, F] float, length [n], feasible [n], first [H, n] | None).

        Per-feature arrays instead of a trailing F axis keep every gather contiguous.
        Lengths and first actions are tracked only when `record_first`; feasibility only
        when some real state has no tied action (otherwise every state stays feasible).
        With `must_finish`, only trajectories that reach the terminal sink count: at horizon
        0 only the sink (and padding) is feasible, so feasibility is always tracked.
        ``record_first="last"`` keeps only the first actions with the full horizon left
        (``first`` is then ``[1, n]``) and does not track lengths.
        """
        last = record_first == "last"
        if last:
            record_first = False
        n, f_n = self.n, self.F
        mu = [np.zeros(n) for _ in range(f_n)]
        length = np.zeros(n, dtype=np.int64)
        # feasible: a trajectory of the current length (that ends at the sink) exists
        feasible = ~self.real if must_finish else np.ones(n, dtype=bool)
        track_feasible = must_finish or not np.all(self.tied.any(axis=-1) | ~self.real)
        first = np.full((horizon, n), -1, dtype=np.int8) if record_first else None
        row = np.arange(n) * self.A
        flat = self.flat_nxt
        flat1 = flat.reshape(-1)
        neg = np.where(self.tied, 0.0, -np.inf)
        take = self.real
        for k in range(horizon):
            if track_feasible:
                ok = self.tied & feasible[flat]
                neg = np.where(ok, 0.0, -np.inf)
                take = ok.any(axis=-1) & self.real
            cand = [self.phi_f[f] + mu[f][flat] for f in range(f_n)]  # [n, A] each
            val = neg.copy()
            for f in range(f_n):
                val += w[f] * cand[f]
            a = np.argmax(val, axis=-1)  # first arg-max in action order
            pick = row + a
            new_mu = [np.where(take, cand[f].reshape(-1)[pick], 0.0) for f in range(f_n)]
            same = all(np.array_equal(x, y) for x, y in zip(new_mu, mu, strict=True))
            if track_feasible:
                new_feas = take | ~self.real  # the sink (and padding) always "end" fine
                same = same and np.array_equal(new_feas, feasible)
                feasible = new_feas
            if first is not None:
                first[k] = np.where(take, a, -1)
                new_len = np.where(take, 1 + length[flat1[pick]], 0)
                same = same and np.array_equal(new_len, length)
                length = new_len
            mu = new_mu
            if same:  # a fixed point: longer horizons choose the same trajectories
                if first is not None:
                    first[k + 1:] = first[k]
                break
        if last:  # the first actions of the final step (or of the fixed point)
            first = np.where(take, a, -1).astype(np.int8)[None]
        return np.stack(mu, axis=-1), length, feasible, first

    def path_counts(self, horizon: int, cap: int) -> np.ndarray:
        """N[k, n]: tied paths with k steps left (terminal / horizon end = 1), capped."""
        N = np.ones((horizon + 1, self.n), dtype=np.int64)
        for k in range(1, horizon + 1):
            tot = np.where(self.tied, N[k - 1][self.flat_nxt], 0).sum(axis=-1)
            N[k] = np.where(self.real, np.minimum(tot, cap), 1)
            if np.array_equal(N[k], N[k - 1]):
                N[k + 1:] = N[k]  # a fixed point of the recursion
                break
        return N

    def reference_firsts(self, w: np.ndarray, horizon: int, limit: int,
                         ) -> tuple[np.ndarray, np.ndarray] | None:
        """Where more than `limit` tied trajectories start at a state, the reference records
        only the first ``limit + 1`` in depth-first action order (it stops expanding once more
        than `limit` are recorded) and keeps the best of those by true reward, first on exact
        ties. Unrank exactly those paths from the path counts; returns ``(row, mu)`` or None.
        """
        R = limit + 1
        N = self.path_counts(horizon, cap=R)
        idx = np.flatnonzero((N[horizon] > limit) & self.real)
        if not len(idx):
            return None
        n = len(idx)
        cur = np.repeat(idx[:, None], R, axis=1)  # flat p * S + s
        base = np.repeat(((idx // self.S) * self.S)[:, None], R, axis=1)
        rank = np.broadcast_to(np.arange(R), (n, R)).copy()
        mu = np.zeros((n, R, self.F))
        for k in range(horizon, 0, -1):
            live = (cur - base) != self.sink
            if not live.any():
                break
            nxt = self.flat_nxt[cur]  # [n, R, A]
            cnt = np.where(self.tied[cur], N[k - 1][nxt], 0)
            cum = np.cumsum(cnt, axis=-1)
            a = np.argmax(cum > rank[..., None], axis=-1)
            before = np.where(a > 0, np.take_along_axis(cum, np.maximum(a - 1, 0)[..., None],
                                                        axis=-1)[..., 0], 0)
            mu += np.where(live[..., None],
                           np.take_along_axis(self.phi[cur], a[..., None, None], axis=2)[:, :, 0],
                           0.0)
            rank = np.where(live, rank - before, rank)
            cur = np.where(live, np.take_along_axis(nxt, a[..., None], axis=-1)[..., 0], cur)
        best = np.argmax(mu @ w, axis=1)  # ranks 0..limit all exist since the count exceeds it
        return idx, mu[np.arange(n), best]


def _check_w(batch: MDPBatch, w_true: np.ndarray, horizon: int) -> np.ndarray:
    w = np.asarray(w_true, dtype=float)
    if w.shape != (batch.F,):
        raise ValueError(f"w_true must have shape [{batch.F}], got {w.shape}")
    if horizon < 1:
        raise ValueError(f"horizon must be at least 1, got {horizon}")
    return w


def best_tied_trajectories(
    batch: MDPBatch,
    Q_h: np.ndarray,
    w_true: np.ndarray,
    *,
    horizon: int = MAX_STEPS,
    tol: float = TIE_TOL,
    chunk_bytes: float = 200e6,
) -> BestTied:
    """From every state: the human-tied-optimal trajectory with the highest true reward.

    Args:
        batch: the compiled instances (E of them).
        Q_h: ``[E, M, S, A]`` the human models' action values (e.g. `Values.Q`).
        w_true: ``[F]`` the true weights that score the trajectories.
        horizon: maximum trajectory length (the reference's 25).
        tol: tie tolerance for the human's tied-optimal action sets.
    """
    Q_h = np.asarray(Q_h, dtype=float)
    if Q_h.ndim != 4 or Q_h.shape[0] != batch.E or Q_h.shape[2:] != (batch.S, batch.A):
        raise ValueError(f"Q_h must have shape [E={batch.E}, M, S={batch.S}, A={batch.A}], "
                         f"got {Q_h.shape}")
    w = _check_w(batch, w_true, horizon)
    e_n, m_n, s_n, a_n = Q_h.shape
    per_model = e_n * s_n * a_n * batch.F * 8 * 3
    step = max(1, int(chunk_bytes // per_model))
    if m_n > step:  # bound the working arrays
        parts = [best_tied_trajectories(batch, Q_h[:, i:i + step], w, horizon=horizon, tol=tol,
                                        chunk_bytes=chunk_bytes) for i in range(0, m_n, step)]
        return BestTied(first_action=np.concatenate([p.first_action for p in parts], axis=2),
                        mu=np.concatenate([p.mu for p in parts], axis=1),
                        value=np.concatenate([p.value for p in parts], axis=1),
                        length=np.concatenate([p.length for p in parts], axis=1), batch=batch)
    env = np.repeat(np.arange(e_n), m_n)
    pairs = _Pairs(batch, env, tied_actions(Q_h, tol).reshape(e_n * m_n, s_n, a_n))
    mu, length, feasible, first = pairs.best(w, horizon, record_first=True)
    assert first is not None  # record_first gives the first actions
    value = np.where(feasible | ~pairs.real, mu @ w, -np.inf)
    return BestTied(first_action=first.reshape(horizon, e_n, m_n, s_n),
                    mu=mu.reshape(e_n, m_n, s_n, batch.F), value=value.reshape(e_n, m_n, s_n),
                    length=length.reshape(e_n, m_n, s_n), batch=batch)


def _pair_inputs(batch: MDPBatch, env: np.ndarray, Q: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Validate the (instance, model) pairs `env[P]` and their action values `Q[P, S, A]`."""
    env = np.asarray(env, dtype=np.int64).reshape(-1)
    if env.size and (env.min() < 0 or env.max() >= batch.E):
        raise ValueError(f"env must be instance indices in 0..{batch.E - 1}, "
                         f"got {env.min()}..{env.max()}")
    Q = np.asarray(Q, dtype=float)
    if Q.shape != (len(env), batch.S, batch.A):
        raise ValueError(f"Q must have shape [P={len(env)}, S={batch.S}, A={batch.A}], "
                         f"got {Q.shape}")
    return env, Q


def best_tied_mu(
    batch: MDPBatch,
    env: np.ndarray,
    Q: np.ndarray,
    w_true: np.ndarray,
    *,
    horizon: int = MAX_STEPS,
    tol: float = TIE_TOL,
    reference_limit: int | None = None,
) -> np.ndarray:
    """Integer feature counts ``[P, S, F]`` of the best tied trajectory from every state, for
    P (instance, model) pairs: instance ``env[p]`` with action values ``Q[p]`` (``[P, S, A]``).

    The same DP as `best_tied_trajectories`, on just the pairs given (e.g. the bounded ones).
    `reference_limit` (the reference's 10): where more tied trajectories than that start at a
    state, choose among the first ``limit + 1`` in depth-first order only, like the reference.
    """
    env, Q = _pair_inputs(batch, env, Q)
    w = _check_w(batch, w_true, horizon)
    if not len(env):
        return np.zeros((0, batch.S, batch.F), dtype=np.int64)
    pairs = _Pairs(batch, env, tied_actions(Q, tol))
    mu = pairs.best(w, horizon, record_first=False)[0]
    if reference_limit is not None:
        fix = pairs.reference_firsts(w, horizon, reference_limit)
        if fix is not None:
            mu[fix[0]] = fix[1]
    return np.rint(mu).astype(np.int64).reshape(len(env), batch.S, batch.F)


def best_tied_policy(
    batch: MDPBatch,
    env: np.ndarray,
    Q: np.ndarray,
    w_true: np.ndarray,
    *,
    horizon: int = MAX_STEPS,
    tol: float = TIE_TOL,
    must_finish: bool = False,
) -> np.ndarray:
    """First actions ``[P, S]`` of the best tied trajectories with `horizon` steps left, for P
    (instance, model) pairs (as in `best_tied_mu`); -1 at the sink, padding, and where no
    tied trajectory (with `must_finish`: none that reaches the terminal within
    ``horizon - 1`` further steps) exists.

    Used as a stationary policy it is the simulated learners' counterfactual plan
    (`cfteach.simulate`): follow it with `rollout_from`; a rollout that reaches the terminal
    took tied actions only, so it exists within the horizon. Past the DP's fixed point the
    policy no longer depends on `horizon`.
    """
    env, Q = _pair_inputs(batch, env, Q)
    w = _check_w(batch, w_true, horizon)
    if not len(env):
        return np.zeros((0, batch.S), dtype=np.int64)
    pairs = _Pairs(batch, env, tied_actions(Q, tol))
    first = pairs.best(w, horizon, record_first="last", must_finish=must_finish)[3]
    assert first is not None  # record_first="last" gives the first actions
    return first[0].astype(np.int64).reshape(len(env), batch.S)


def count_tied_trajectories(
    batch: MDPBatch,
    tied: np.ndarray,
    *,
    horizon: int = MAX_STEPS,
    cap: int = 10**12,
) -> np.ndarray:
    """Number of tied-optimal trajectories from every state, ``[E, M, S]`` (capped at `cap`).

    A trajectory ends at the terminal or after `horizon` steps, as in the reference's
    recursive enumeration, which stops collecting after more than 10 (docs/domains.md,
    "Benefit of the doubt"): where this
    count exceeds 10 the reference saw only a prefix of the depth-first order.
    """
    tied = np.asarray(tied, dtype=bool)
    if tied.ndim != 4 or tied.shape[0] != batch.E or tied.shape[2:] != (batch.S, batch.A):
        raise ValueError(f"tied must have shape [E={batch.E}, M, S={batch.S}, A={batch.A}], "
                         f"got {tied.shape}")
    e_n, m_n, s_n, a_n = tied.shape
    pairs = _Pairs(batch, np.repeat(np.arange(e_n), m_n), tied.reshape(e_n * m_n, s_n, a_n))
    return pairs.path_counts(horizon, cap)[horizon].reshape(e_n, m_n, s_n)
