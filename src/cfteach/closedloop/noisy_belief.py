"""A particle belief for learners who err: weights, rationality and uptake inferred jointly.

`ParticleBelief` models a learner by their reward weights alone, with a fixed temperature and
a fixed chance of absorbing a demonstration. A person who errs then looks like a person with
strange weights. Here every particle carries three things:

* ``w``: the learner's reward weights (a unit vector inside the prior), as before;
* ``beta``: their rationality, one of the values of a grid (`rationality`); they pick action
  ``a`` in state ``s`` with probability ``(1 - lapse) * softmax_a(beta * Q_w(s, a)) +
  lapse / A`` (a per-step Boltzmann policy plus a small lapse rate);
* ``u``: their uptake, one of the values of a grid (`uptake`): the chance that a shown
  demonstration (or feedback) changed what they believe. A demonstration with constraint rows
  ``C`` has likelihood ``u * 1[C w >= 0] + (1 - u)``.

``Q_w(s, a) = w . Psi(s, a)`` with ``Psi(s, a)`` the feature counts of taking ``a`` in ``s``
and then following the robot's optimal policy (the one-action deviations of standard IRL;
`DemoSet.dev_mu`): linear in ``w``, so a whole answer's likelihood under every particle is one
matrix product. A test answer given as moves is scored step by step; one given only as its
outcome (optimal or not) by the chance of an optimal answer, `p_optimal_paths`.

A long wandering answer is then best explained by a low ``beta`` (or weights under which the
moves were nearly free) and lowers the predicted success instead of raising it. Everything
else (resample-move, the reference points behind `expected_area`, determinism given the
seed and the observations) is `ParticleBelief`'s; the discrete parameters move by
Metropolis-Hastings too (a uniform proposal over the other grid values, symmetric).
Equations: docs/closed-loop.md.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cfteach.closedloop.belief import TOL, ParticleBelief, _check_rows

#: Rationality grid: Q-value differences of a domain's actions are about 0.1-0.2 (weights are
#: unit vectors), so beta = 2 is close to random and beta = 300 close to greedy.
RATIONALITY = (2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 300.0)
#: Uptake grid: the chance a shown demonstration is taken in.
UPTAKE = (0.2, 0.4, 0.6, 0.8, 0.95)

__all__ = ["RATIONALITY", "UPTAKE", "NoisyBelief", "StepData"]


class StepData:
    """Per-step choice data of some states: for each state (a group) the rows ``Psi(s, a)``
    of its A actions (``rows [G, A, F]``), how often each was taken (``counts [G, A]``) or
    which are optimal (``optimal [G, A]``)."""

    def __init__(self, rows: np.ndarray, counts: np.ndarray | None = None,
                 optimal: np.ndarray | None = None) -> None:
        self.rows = np.asarray(rows, dtype=np.float64)
        if self.rows.ndim != 3:
            raise ValueError(f"StepData rows: expected shape [G, A, F], got {self.rows.shape}")
        self.counts = None if counts is None else np.asarray(counts, dtype=np.float64)
        self.optimal = None if optimal is None else np.asarray(optimal, dtype=bool)

    def x(self, points: np.ndarray) -> np.ndarray:
        """``w . Psi(s, a)`` for every point, state and action: ``[P, G, A]``."""
        return np.einsum("pf,gaf->pga", points, self.rows, optimize=True)

    def to_json(self) -> dict[str, Any]:
        return {"rows": self.rows, "counts": self.counts, "optimal": self.optimal}


def _as_grid(values: Any, name: str, low: float, high: float) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64).ravel()
    if not len(arr) or not np.all(np.isfinite(arr)) or np.any(arr <= low) or np.any(arr >= high):
        raise ValueError(f"{name}: expected one or more numbers in ({low}, {high}), "
                         f"got {values!r}")
    return arr


class NoisyBelief(ParticleBelief):
    """Weighted particles over (weights, rationality, uptake) (module docstring)."""

    def __init__(self, prior: np.ndarray, dim: int, *, n_particles: int = 1000, seed: int = 0,
                 rationality: Any = RATIONALITY, uptake: Any = UPTAKE, lapse: float = 0.01,
                 n_reference: int = 4000, particles: np.ndarray | None = None,
                 resample: bool = True, n_moves: int = 3) -> None:
        super().__init__(prior, dim, n_particles=n_particles, seed=seed, p_learn=0.5,
                         temperature=1.0, n_reference=n_reference, particles=particles,
                         resample=resample, n_moves=n_moves)
        self.rationality = _as_grid(rationality, "rationality", 0.0, math.inf)
        self.uptake = _as_grid(uptake, "uptake", 0.0, 1.0)
        lapse = float(lapse)
        if not 0.0 <= lapse < 1.0:
            raise ValueError(f"lapse must lie in [0, 1), got {lapse!r}")
        self.lapse = lapse
        rng = np.random.default_rng([self.seed, 5])
        self.beta_idx = self._spread(len(self.particles), len(self.rationality), rng)
        self.uptake_idx = self._spread(len(self.particles), len(self.uptake), rng)
        self.ref_beta_idx = self._spread(self.n_reference, len(self.rationality), rng)
        self.ref_uptake_idx = self._spread(self.n_reference, len(self.uptake), rng)

    @staticmethod
    def _spread(n: int, k: int, rng: np.random.Generator) -> np.ndarray:
        """Grid indices spread evenly over n particles, in random order (a uniform prior)."""
        return rng.permutation(np.arange(n) % k).astype(np.int64)

    # ------------------------------------------------------------------ the policy
    def _log_policy(self, x: np.ndarray, beta: np.ndarray) -> np.ndarray:
        """``log pi(a | s)`` ``[P, G, A]`` from ``x = w . Psi(s, a)`` ``[P, G, A]``."""
        logits = beta[:, None, None] * x
        logp = logits - np.logaddexp.reduce(logits, axis=2, keepdims=True)
        if self.lapse > 0:
            logp = np.logaddexp(math.log1p(-self.lapse) + logp,
                                math.log(self.lapse / x.shape[2]))
        return logp

    def _log_follow(self, x: np.ndarray, beta: np.ndarray, optimal: np.ndarray,
                    test_starts: np.ndarray) -> np.ndarray:
        """``[P, T]``: log chance of taking only optimal actions along each test's path
        (consecutive groups; test t's groups start at ``test_starts[t]``)."""
        logits = beta[:, None, None] * x
        e = np.exp(logits - logits.max(axis=2, keepdims=True))
        frac = (e * optimal[None]).sum(axis=2) / e.sum(axis=2)  # [P, G]
        n_opt = optimal.sum(axis=1) / x.shape[2]
        p = (1 - self.lapse) * frac + self.lapse * n_opt[None]
        return np.add.reduceat(np.log(np.maximum(p, 1e-300)), test_starts, axis=1)

    def p_optimal_paths(self, region_sat: np.ndarray, data: StepData,
                        test_starts: np.ndarray) -> np.ndarray:
        """``[P, T]`` chance that each particle answers each test optimally: its weights lie
        in the test's region (`region_sat` ``[P, T]`` bool; else only by a lapse) and it
        takes only optimal actions along the optimal path."""
        follow = np.exp(self._log_follow(data.x(self.particles),
                                         self.rationality[self.beta_idx], data.optimal,
                                         test_starts))
        return follow * np.where(region_sat, 1.0, self.lapse)

    def predicted(self, region_sat: np.ndarray, data: StepData,
                  test_starts: np.ndarray) -> np.ndarray:
        """``[T]``: the belief's P(optimal answer) on each test (`p_optimal_paths`)."""
        return self.weights @ self.p_optimal_paths(region_sat, data, test_starts)

    def knowledge(self, region_sat: np.ndarray) -> np.ndarray:
        """``[T]``: belief mass whose weights lie in each test's region (`region_sat`
        ``[P, T]``): the share of success teaching can still change."""
        return self.weights @ region_sat.astype(float)

    # ------------------------------------------------------------------ observations
    def observe_steps(self, data: StepData) -> None:
        """Update after a test answer given as moves: the per-step policy's likelihood of
        every action taken (`data.counts`)."""
        self._apply({"kind": "steps", **data.to_json()})

    def observe_outcome(self, data: StepData, region: np.ndarray, correct: bool) -> None:
        """Update after a test answer known only as optimal or not (`data`: the optimal
        path's states with their optimal actions; `region`: the test's constraint rows)."""
        rows = _check_rows(region, self.dim, "region")
        self._apply({"kind": "outcome", **data.to_json(), "region": rows,
                     "correct": bool(correct)})

    def observe_answer(self, *args: Any, **kwargs: Any) -> None:  # noqa: D102
        raise TypeError("NoisyBelief scores answers by their moves (observe_steps) or their "
                        "outcome (observe_outcome)")

    def observe(self, entry: dict[str, Any]) -> None:
        """Replay one ``history`` entry (e.g. of another belief) as a new observation."""
        kind = entry["kind"]
        if kind == "demonstration":
            self.observe_demonstration(entry["constraints"])
        elif kind in ("steps", "outcome"):
            data = StepData(entry["rows"], entry["counts"], entry["optimal"])
            if kind == "steps":
                self.observe_steps(data)
            else:
                self.observe_outcome(data, entry["region"], entry["correct"])
        else:
            raise ValueError(f"entry: unknown observation kind {kind!r}")

    # ------------------------------------------------------------------ likelihoods
    def _entry_ll(self, entry: dict[str, Any], points: np.ndarray, beta: np.ndarray,
                  uptake: np.ndarray) -> np.ndarray:
        if entry["kind"] == "demonstration":
            return np.where(_sat(points, entry["constraints"]), 0.0, np.log1p(-uptake))
        x = StepData(entry["rows"]).x(points)
        if entry["kind"] == "steps":
            return np.einsum("pga,ga->p", self._log_policy(x, beta), entry["counts"])
        return self._outcome_ll(entry, x, beta, _sat(points, entry["region"]))

    def _outcome_ll(self, entry: dict[str, Any], x: np.ndarray, beta: np.ndarray,
                    ok: np.ndarray) -> np.ndarray:
        follow = np.exp(self._log_follow(x, beta, entry["optimal"], np.array([0]))[:, 0])
        p = np.clip(follow * np.where(ok, 1.0, self.lapse), 1e-300, 1 - 1e-12)
        return np.log(p) if entry["correct"] else np.log1p(-p)

    def _apply(self, entry: dict[str, Any]) -> None:
        self.history.append(entry)
        self._stack = None
        lw = self.log_weights + self._entry_ll(entry, self.particles,
                                               self.rationality[self.beta_idx],
                                               self.uptake[self.uptake_idx])
        self.log_weights = lw - np.logaddexp.reduce(lw)
        self.reference_loglik = self.reference_loglik + self._entry_ll(
            entry, self.reference, self.rationality[self.ref_beta_idx],
            self.uptake[self.ref_uptake_idx])
        self.resample_if_needed()

    def _parts(self, points: np.ndarray) -> dict[str, Any]:
        """What the posterior needs of `points` that does not depend on (beta, u)."""
        demos = [e["constraints"] for e in self.history if e["kind"] == "demonstration"
                 and len(e["constraints"])]
        steps = [e for e in self.history if e["kind"] == "steps" and len(e["rows"])]
        out: dict[str, Any] = {"prior_ok": _sat(points, self.prior)}
        out["missed"] = (sum((~_sat(points, c)).astype(float) for c in demos) if demos
                         else np.zeros(len(points)))
        if steps:
            counts = np.concatenate([e["counts"] for e in steps])
            out["steps"] = (counts, StepData(np.concatenate([e["rows"] for e in steps]))
                            .x(points))
        out["outcomes"] = [(e, StepData(e["rows"]).x(points), _sat(points, e["region"]))
                           for e in self.history if e["kind"] == "outcome"]
        return out

    def _posterior_from(self, parts: dict[str, Any], b_idx: np.ndarray,
                        u_idx: np.ndarray) -> np.ndarray:
        beta = self.rationality[b_idx]
        out = parts["missed"] * np.log1p(-self.uptake[u_idx])
        if "steps" in parts:
            counts, x = parts["steps"]
            out = out + np.einsum("pga,ga->p", self._log_policy(x, beta), counts)
        for e, x, ok in parts["outcomes"]:
            out = out + self._outcome_ll(e, x, beta, ok)
        return np.where(parts["prior_ok"], out, -np.inf)

    def log_posterior(self, points: np.ndarray, beta_idx: np.ndarray | None = None,
                      uptake_idx: np.ndarray | None = None) -> np.ndarray:
        """Unnormalised log posterior of (w, beta, u) at ``points [P, F]`` (unit vectors)
        with the given grid indices (default: the particles' own, for P particles)."""
        b = self.beta_idx if beta_idx is None else np.asarray(beta_idx)
        u = self.uptake_idx if uptake_idx is None else np.asarray(uptake_idx)
        return self._posterior_from(self._parts(points), b, u)

    # ------------------------------------------------------------------ resample-move
    def resample_if_needed(self) -> bool:
        """`ParticleBelief.resample_if_needed`, carrying each particle's (beta, u) along."""
        n = len(self.particles)
        if not self.resample or self.ess() >= n / 2:
            return False
        rng = np.random.default_rng([self.seed, 2, self.n_resamples])
        positions = (rng.random() + np.arange(n)) / n
        cdf = np.cumsum(self.weights)
        idx = np.minimum(np.searchsorted(cdf, positions * cdf[-1], side="right"), n - 1)
        self.n_resamples += 1
        self.log_weights = np.full(n, -math.log(n))
        self.beta_idx = self.beta_idx[idx]
        self.uptake_idx = self.uptake_idx[idx]
        self.particles = self._move(self.particles[idx], rng)
        return True

    def _move(self, pts: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Metropolis-Hastings within Gibbs: a tangent-plane random walk for ``w`` (as in
        `ParticleBelief`), then a uniform proposal among the other grid values for beta and
        for u; all symmetric, each accepted by the posterior ratio."""
        n, d = pts.shape
        centre = pts.mean(axis=0)
        spread = math.sqrt(max(1.0 - float(centre @ centre), 0.0) / (d - 1))
        step = min(max(2.38 / math.sqrt(d - 1) * spread, 1e-6), 1.0)
        b, u = self.beta_idx.copy(), self.uptake_idx.copy()
        parts = self._parts(pts)
        current = self._posterior_from(parts, b, u)
        rates = []
        for _ in range(self.n_moves):
            z = rng.standard_normal((n, d))
            z -= np.sum(z * pts, axis=1, keepdims=True) * pts
            prop = pts + step * z
            prop /= np.linalg.norm(prop, axis=1, keepdims=True)
            prop_parts = self._parts(prop)
            lp = self._posterior_from(prop_parts, b, u)
            accept = np.log(rng.random(n)) < lp - current
            pts = np.where(accept[:, None], prop, pts)
            parts = _select_parts(parts, prop_parts, accept)
            current = np.where(accept, lp, current)
            rate = float(accept.mean())
            rates.append(rate)
            if rate < 0.15:
                step = max(step * 0.5, 1e-6)
            elif rate > 0.5:
                step = min(step * 1.5, 1.0)
            for grid, which in ((self.rationality, "b"), (self.uptake, "u")):
                k = len(grid)
                if k < 2:
                    continue
                cur = b if which == "b" else u
                new = (cur + rng.integers(1, k, size=n)) % k  # any other value, uniformly
                lp = self._posterior_from(parts, new, u) if which == "b" \
                    else self._posterior_from(parts, b, new)
                accept = np.log(rng.random(n)) < lp - current
                cur = np.where(accept, new, cur)
                current = np.where(accept, lp, current)
                if which == "b":
                    b = cur
                else:
                    u = cur
        self.beta_idx, self.uptake_idx = b, u
        self.step_size = step
        self.acceptance = float(np.mean(rates)) if rates else None
        return pts

    # ------------------------------------------------------------------ summaries, state
    def rationality_mean(self) -> float:
        """Posterior mean of log10(beta), as beta (a geometric mean)."""
        return float(10 ** (self.weights @ np.log10(self.rationality[self.beta_idx])))

    def uptake_mean(self) -> float:
        return float(self.weights @ self.uptake[self.uptake_idx])

    def state_dict(self) -> dict[str, Any]:
        out = super().state_dict()
        out.update(rationality=self.rationality.copy(), uptake=self.uptake.copy(),
                   lapse=self.lapse, beta_idx=self.beta_idx.copy(),
                   uptake_idx=self.uptake_idx.copy(), ref_beta_idx=self.ref_beta_idx.copy(),
                   ref_uptake_idx=self.ref_uptake_idx.copy())
        return out

    def copy(self) -> NoisyBelief:
        out = super().copy()
        for key in ("beta_idx", "uptake_idx"):
            setattr(out, key, getattr(self, key).copy())
        return out  # type: ignore[return-value]


def _sat(points: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Mask over points: every constraint row holds (all points when there are none)."""
    if not len(rows):
        return np.ones(len(points), dtype=bool)
    return np.all(points @ np.asarray(rows).T >= -TOL, axis=1)


def _select_parts(old: dict[str, Any], new: dict[str, Any], take: np.ndarray) -> dict[str, Any]:
    """Per-point parts: `new`'s where `take`, else `old`'s (after an MH step on w)."""
    out: dict[str, Any] = {"prior_ok": np.where(take, new["prior_ok"], old["prior_ok"]),
                           "missed": np.where(take, new["missed"], old["missed"])}
    if "steps" in old:
        out["steps"] = (old["steps"][0], np.where(take[:, None, None], new["steps"][1],
                                                  old["steps"][1]))
    out["outcomes"] = [(e, np.where(take[:, None, None], xn, xo), np.where(take, okn, oko))
                       for (e, xo, oko), (_, xn, okn) in zip(old["outcomes"], new["outcomes"],
                                                             strict=True)]
    return out
