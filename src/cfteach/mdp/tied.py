"""Tied-optimal trajectories of a human model, by dynamic programming (spec §3, §6.2).

The reference enumerates every trajectory that takes only tied-optimal actions under the
human's weights (depth first, action order, length <= 25 unless it reaches the terminal) and
keeps the one with the highest *true* reward ("benefit of the doubt"). Enumeration is
exponential; here the same choice is a max-plus DP over the horizon:

    U_0(s) = 0,  U_k(s) = max over tied a of  w* . (phi(s, a) + mu_{k-1}(next(s, a)))

where mu_k(s) is the feature count of the chosen length-k continuation. Comparing w* . mu
(the dot product of integer feature counts, like the reference) makes trajectories with equal
feature counts compare exactly equal; such ties go to the first action in action order, which
yields the lexicographically smallest action sequence, i.e. the first one the reference's
depth-first enumeration finds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfteach.mdp.arrays import MDPBatch
from cfteach.mdp.rollout import MAX_STEPS
from cfteach.mdp.vi import TIE_TOL, tied_actions


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
    w = np.asarray(w_true, dtype=float)
    if w.shape != (batch.F,):
        raise ValueError(f"w_true must have shape [{batch.F}], got {w.shape}")
    if horizon < 1:
        raise ValueError(f"horizon must be at least 1, got {horizon}")
    e_n, m_n, s_n, a_n = Q_h.shape
    f_n = batch.F
    per_model = e_n * s_n * a_n * f_n * 8 * 3
    step = max(1, int(chunk_bytes // per_model))
    if m_n > step:  # bound the [E, M, S, A, F] working arrays
        parts = [best_tied_trajectories(batch, Q_h[:, i:i + step], w, horizon=horizon, tol=tol,
                                        chunk_bytes=chunk_bytes) for i in range(0, m_n, step)]
        return BestTied(first_action=np.concatenate([p.first_action for p in parts], axis=2),
                        mu=np.concatenate([p.mu for p in parts], axis=1),
                        value=np.concatenate([p.value for p in parts], axis=1),
                        length=np.concatenate([p.length for p in parts], axis=1), batch=batch)
    tied = tied_actions(Q_h, tol) & batch.valid[:, None, :, None]
    feats = batch.features[:, None]  # [E, 1, S, A, F]
    nxt = batch.next_state  # [E, S, A]
    e_idx = np.arange(e_n)[:, None, None, None]
    m_idx = np.arange(m_n)[None, :, None, None]
    nxt_b = nxt[:, None]  # [E, 1, S, A]

    mu = np.zeros((e_n, m_n, s_n, f_n))
    length = np.zeros((e_n, m_n, s_n), dtype=np.int64)
    first = np.full((horizon, e_n, m_n, s_n), -1, dtype=np.int8)
    feasible = np.ones((e_n, m_n, s_n), dtype=bool)  # a trajectory of this length exists
    for k in range(1, horizon + 1):
        cand = feats + mu[e_idx, m_idx, nxt_b]  # [E, M, S, A, F]
        val = cand @ w
        ok = tied & feasible[e_idx, m_idx, nxt_b]
        val = np.where(ok, val, -np.inf)
        a_best = np.argmax(val, axis=-1)  # first arg-max in action order
        has = ok.any(axis=-1)
        new_mu = np.take_along_axis(cand, a_best[..., None, None], axis=3)[..., 0, :]
        new_len = 1 + np.take_along_axis(length[e_idx, m_idx, nxt_b], a_best[..., None],
                                         axis=3)[..., 0]
        real = batch.valid[:, None, :]
        mu = np.where((has & real)[..., None], new_mu, 0.0)
        length = np.where(has & real, new_len, 0)
        first[k - 1] = np.where(has & real, a_best, -1)
        feasible = has | ~real  # the sink (and padding) always "end" fine
    value = np.where(feasible | ~batch.valid[:, None, :], mu @ w, -np.inf)
    return BestTied(first_action=first, mu=mu, value=value, length=length, batch=batch)


def count_tied_trajectories(
    batch: MDPBatch,
    tied: np.ndarray,
    *,
    horizon: int = MAX_STEPS,
    cap: int = 10**12,
) -> np.ndarray:
    """Number of tied-optimal trajectories from every state, ``[E, M, S]`` (capped at `cap`).

    A trajectory ends at the terminal or after `horizon` steps, as in the reference's
    recursive enumeration, which stops collecting after more than 10 (spec §3): where this
    count exceeds 10 the reference saw only a prefix of the depth-first order.
    """
    tied = np.asarray(tied, dtype=bool)
    if tied.ndim != 4 or tied.shape[0] != batch.E or tied.shape[2:] != (batch.S, batch.A):
        raise ValueError(f"tied must have shape [E={batch.E}, M, S={batch.S}, A={batch.A}], "
                         f"got {tied.shape}")
    e_n, m_n, s_n, _ = tied.shape
    e_idx = np.arange(e_n)[:, None, None, None]
    m_idx = np.arange(m_n)[None, :, None, None]
    nxt_b = batch.next_state[:, None]
    real = batch.valid[:, None, :]
    mask = tied & real[..., None]
    count = np.ones((e_n, m_n, s_n), dtype=np.int64)
    for _ in range(horizon):
        nxt_count = count[e_idx, m_idx, nxt_b]
        total = np.where(mask, nxt_count, 0).sum(axis=-1)
        count = np.where(real, np.minimum(total, cap), 1)
    return count
