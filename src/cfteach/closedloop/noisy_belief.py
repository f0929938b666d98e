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
  ``C`` has likelihood ``u * 1[C w >= 0] + (1 - u)``;
* ``lambda``: their disengagement, one of the values of a grid (`disengaged`): the chance
  that a whole answer was not an attempt at all (uniformly random moves). An answer's
  likelihood is ``(1 - lambda) * L_engaged + lambda * L_random``, so one wild answer among
  good ones does not make the learner irrational for good.
* ``c``: their confusion: the chance that an attempt was planned under weights the learner
  might *then* have held rather than the particle's own, taken from the belief at the time
  of the answer: ``L_engaged = (1 - c) * L_policy(w) + c * E_belief[L_policy(w')]``. By
  default (`confusion="since"`, `cfteach.closedloop.since`) ``c = 1 - (1 - u) ** k`` for
  an answer ``k`` demonstrations back; with ``"grid"``, one value per learner from a grid
  (`confused`, in [0, 1)). Errors made while the belief was wide are then explained by the
  width of what the learner knew, which teaching narrows, and not by a low rationality for
  good (Lee, Simmons & Admoni's 2024 model is ``c = 1``).

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
from typing import Any, Self

import numpy as np

from cfteach.closedloop.belief import (
    TOL,
    ParticleBelief,
    _check_rows,
    initial_step,
    systematic_resample,
    tangent_proposal,
)
from cfteach.closedloop.mh_parts import select_parts, select_rows
from cfteach.closedloop.noisy_params import (
    CONFUSED,
    DISENGAGED,
    LAPSE,
    RATIONALITY,
    UPTAKE,
    as_grid,
)
from cfteach.closedloop.since import CONFUSION_MODELS, demos_after, log_shares, share
from cfteach.closedloop.steps import (
    StepData,
    Taken,
    distinct_steps,
    log_policy,
    taken_actions,
    taken_log_policy,
)

__all__ = ["NoisyBelief"]


class NoisyBelief(ParticleBelief):
    """Weighted particles over (weights, rationality, uptake, disengagement) (module
    docstring). ``idx[name]`` holds each particle's index into ``grids[name]``."""

    def __init__(self, prior: np.ndarray, dim: int, *, n_particles: int = 1000, seed: int = 0,
                 rationality: Any = RATIONALITY, uptake: Any = UPTAKE,
                 disengaged: Any = DISENGAGED, confused: Any = CONFUSED,
                 confusion: str = "grid", lapse: float = LAPSE, n_reference: int = 4000,
                 particles: np.ndarray | None = None, resample: bool = True,
                 n_moves: int = 3) -> None:
        super().__init__(prior, dim, n_particles=n_particles, seed=seed, p_learn=0.5,
                         temperature=1.0, n_reference=n_reference, particles=particles,
                         resample=resample, n_moves=n_moves)
        self.grids = {"beta": as_grid(rationality, "rationality", 0.0, math.inf),
                      "uptake": as_grid(uptake, "uptake", 0.0, 1.0),
                      "disengaged": as_grid(disengaged, "disengaged", 0.0, 1.0)}
        lapse = float(lapse)
        if not 0.0 <= lapse < 1.0:
            raise ValueError(f"lapse must lie in [0, 1), got {lapse!r}")
        self.lapse = lapse
        if confusion not in CONFUSION_MODELS:
            raise ValueError(f"confusion must be one of {', '.join(CONFUSION_MODELS)}, "
                             f"got {confusion!r}")
        self.confusion = confusion
        # model "since": the log posterior the particles were drawn at; the answers' policy
        # terms at the particles and at the reference points (`_apply`)
        self._base = np.zeros(len(self.particles))
        self._policy = (np.zeros((len(self.particles), 0)), np.zeros((len(self.reference), 0)))
        rng = np.random.default_rng([self.seed, 5])
        self.idx = {k: self._spread(len(self.particles), len(g), rng)
                    for k, g in self.grids.items()}
        self.ref_idx = {k: self._spread(self.n_reference, len(g), rng)
                        for k, g in self.grids.items()}
        # Confusion comes last and from a stream of its own, so that with the grid (0.0,)
        # every other draw (and so every result) is the one of the model without it.
        conf = as_grid(confused, "confused", 0.0, 1.0, low_included=True)
        self.grids["confused"] = conf
        rng_c = np.random.default_rng([self.seed, 6])
        self.idx["confused"] = self._spread(len(self.particles), len(conf), rng_c)
        self.ref_idx["confused"] = self._spread(self.n_reference, len(conf), rng_c)

    @staticmethod
    def _spread(n: int, k: int, rng: np.random.Generator) -> np.ndarray:
        """Grid indices spread evenly over n particles, in random order (a uniform prior)."""
        return rng.permutation(np.arange(n) % k).astype(np.int64)

    def _values(self, idx: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = {k: self.grids[k][i] for k, i in idx.items()}
        out["beta_index"] = idx["beta"]
        return out

    @property
    def confusion_on(self) -> bool:
        """Whether the confusion term can matter (model "since", or a grid value above 0)."""
        return self.confusion == "since" or bool(np.any(self.grids["confused"] > 0))

    def _shares(self, v: dict[str, np.ndarray], k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``[P, E]`` logs of the kept and confused shares of answers followed by `k`
        demonstrations (`since.log_shares`)."""
        return log_shares(self.confusion, v["uptake"], v["confused"], k)

    # ------------------------------------------------------------------ the policy
    def _log_policy(self, x: np.ndarray, beta: np.ndarray) -> np.ndarray:
        """``log pi(a | s)`` ``[P, G, A]`` from ``x = w . Psi(s, a)`` ``[P, G, A]``."""
        return log_policy(x, beta, self.lapse)

    def _follow(self, x: np.ndarray, beta: np.ndarray, optimal: np.ndarray,
                test_starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Chance of taking only optimal actions along each test's path (consecutive
        groups; test t's groups start at ``test_starts[t]``): ``[P, T]`` under the policy
        and ``[T]`` under uniformly random moves."""
        logits = beta[:, None, None] * x
        e = np.exp(logits - logits.max(axis=2, keepdims=True))
        frac = (e * optimal[None]).sum(axis=2) / e.sum(axis=2)  # [P, G]
        n_opt = optimal.sum(axis=1) / x.shape[2]
        p = (1 - self.lapse) * frac + self.lapse * n_opt[None]
        pol = np.exp(np.add.reduceat(np.log(np.maximum(p, 1e-300)), test_starts, axis=1))
        rand = np.exp(np.add.reduceat(np.log(n_opt), test_starts))
        return pol, rand

    def _p_optimal(self, x: np.ndarray, v: dict[str, np.ndarray], optimal: np.ndarray,
                   test_starts: np.ndarray, sat: np.ndarray,
                   confused_p: np.ndarray | None = None, k: float = 0.0) -> np.ndarray:
        """``[P, T]``: engaged, the weights lie in the test's region (`sat`; else only by
        a lapse) and every move is optimal; disengaged, random moves happen to be.
        `confused_p` ``[B, T]``: the belief's engaged chance per rationality value, for the
        confused share of attempts (None: no confusion term) of an answer followed by `k`
        demonstrations."""
        pol, rand = self._follow(x, v["beta"], optimal, test_starts)
        lam = v["disengaged"][:, None]
        engaged = pol * np.where(sat, 1.0, self.lapse)
        if confused_p is not None:
            c = share(self.confusion, v["uptake"], v["confused"], k)
            engaged = (1 - c) * engaged + c * confused_p[v["beta_index"]]
        return (1 - lam) * engaged + lam * rand[None]

    def _engaged_by_beta(self, x: np.ndarray, optimal: np.ndarray, test_starts: np.ndarray,
                         sat: np.ndarray) -> np.ndarray:
        """``[B, T]``: the belief's chance of an optimal engaged attempt on each test, for
        every rationality value of the grid (what a confused attempt achieves)."""
        inside = np.where(sat, 1.0, self.lapse)
        return np.array([self.weights @ (self._follow(x, np.full(len(x), b), optimal,
                                                      test_starts)[0] * inside)
                         for b in self.grids["beta"]])

    def p_optimal_paths(self, region_sat: np.ndarray, data: StepData,
                        test_starts: np.ndarray) -> np.ndarray:
        """``[P, T]`` chance that each particle answers each test optimally (`region_sat`
        ``[P, T]``: its weights lie in the test's region; `data`: the optimal paths)."""
        if data.optimal is None:
            raise ValueError("p_optimal_paths: data needs the optimal actions (path_steps)")
        x = data.x(self.particles)
        # a prediction has no demonstration before it: model "since" uses the weights now
        conf = (self._engaged_by_beta(x, data.optimal, test_starts, region_sat)
                if self.confusion_on and self.confusion == "grid" else None)
        return self._p_optimal(x, self._values(self.idx), data.optimal, test_starts,
                               region_sat, conf)

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
        every action taken (`data.counts`), mixed with random moves (disengagement)."""
        entry: dict[str, Any] = {"kind": "steps", **data.to_json()}
        if self.confusion_on and data.counts is not None and len(data.rows):
            entry["confused_ll"] = self._belief_answer_ll(data)
        self._apply(entry)

    def _belief_answer_ll(self, data: StepData) -> np.ndarray:
        """``[B]``: log of the belief's mean likelihood of an answer's moves under the
        engaged policy, per rationality value (the confused share of an attempt)."""
        assert data.counts is not None
        x = data.x(self.particles)
        taken = taken_actions(data.counts)
        out = []
        for b in self.grids["beta"]:
            pol = self._taken_log_policy(x, np.full(len(x), b), data.counts, taken).sum(1)
            out.append(np.logaddexp.reduce(self.log_weights + pol))
        return np.array(out)

    def observe_outcome(self, data: StepData, region: np.ndarray, correct: bool) -> None:
        """Update after a test answer known only as optimal or not (`data`: the optimal
        path's states with their optimal actions; `region`: the test's constraint rows)."""
        rows = _check_rows(region, self.dim, "region")
        entry: dict[str, Any] = {"kind": "outcome", **data.to_json(), "region": rows,
                                 "correct": bool(correct)}
        if self.confusion_on:
            if data.optimal is None:
                raise ValueError("observe_outcome: data needs the optimal actions")
            entry["confused_p"] = self._engaged_by_beta(
                data.x(self.particles), data.optimal, np.array([0]),
                _sat(self.particles, rows)[:, None])
        self._apply(entry)

    def observe_answer(self, *args: Any, **kwargs: Any) -> None:  # noqa: D102
        raise TypeError("NoisyBelief scores answers by their moves (observe_steps) or their "
                        "outcome (observe_outcome)")

    def observe(self, entry: dict[str, Any]) -> None:
        """Replay one ``history`` entry (e.g. of another belief) as a new observation."""
        kind = entry["kind"]
        if kind == "demonstration":
            self.observe_demonstration(entry["constraints"])
        elif kind == "steps":
            self.observe_steps(StepData.of(entry))
        elif kind == "outcome":
            self.observe_outcome(StepData(entry["rows"], None, entry["optimal"]),
                                 entry["region"], entry["correct"])
        else:
            raise ValueError(f"entry: unknown observation kind {kind!r}")

    # ------------------------------------------------------------------ likelihoods
    def _steps_ll(self, per_move: np.ndarray, n_moves: np.ndarray, n_actions: int,
                  lam: np.ndarray, v: dict[str, np.ndarray] | None = None,
                  confused_ll: np.ndarray | None = None,
                  k: np.ndarray | None = None) -> np.ndarray:
        """``[P, E]`` answers' log-likelihoods: `per_move` ``[P, E]`` the policy's summed
        log pi, mixed with random moves (``-n log A``) by disengagement `lam` ``[P]``;
        with `confused_ll` ``[E, B]`` (the belief's log-likelihood of each answer per
        rationality value), the confused share of each attempt (`_shares`; `k` ``[E]``:
        demonstrations after each answer, default none) is scored by it."""
        rand = -n_moves * math.log(n_actions)
        if confused_ll is not None and v is not None:
            log_keep, log_c = self._shares(v, np.zeros(per_move.shape[1]) if k is None else k)
            per_move = np.logaddexp(log_keep + per_move,
                                    log_c + confused_ll[:, v["beta_index"]].T)
        return np.logaddexp(np.log1p(-lam)[:, None] + per_move,
                            np.log(lam)[:, None] + rand[None, :])

    def _entry_ll(self, entry: dict[str, Any], points: np.ndarray, v: dict[str, np.ndarray],
                  policy_out: list | None = None) -> np.ndarray:
        """One entry's log-likelihood at `points` (an answer's with no demonstration after
        it); a steps answer's policy term is appended to `policy_out` if given."""
        if entry["kind"] == "demonstration":
            return np.where(_sat(points, entry["constraints"]), 0.0, np.log1p(-v["uptake"]))
        x = StepData.of(entry).x(points)
        if entry["kind"] == "steps":
            counts = entry["counts"]
            pol = self._taken_log_policy(x, v["beta"], counts, taken_actions(counts)).sum(1)
            if policy_out is not None:
                policy_out.append(pol)
            conf = entry.get("confused_ll")
            return self._steps_ll(pol[:, None], np.array([counts.sum()]), x.shape[2],
                                  v["disengaged"], v,
                                  None if conf is None else conf[None])[:, 0]
        return self._outcome_ll(entry, x, v, _sat(points, entry["region"]))

    def _outcome_ll(self, entry: dict[str, Any], x: np.ndarray, v: dict[str, np.ndarray],
                    ok: np.ndarray, k: float = 0.0) -> np.ndarray:
        conf = entry.get("confused_p")
        # `confused_p` is stored as ``[B, 1]`` (one test); a history read back from JSON
        # may hold it flat.
        p = self._p_optimal(x, v, entry["optimal"], np.array([0]), ok[:, None],
                            None if conf is None
                            else np.asarray(conf, dtype=float).reshape(-1, 1), k)[:, 0]
        p = np.clip(p, 1e-300, 1 - 1e-12)
        return np.log(p) if entry["correct"] else np.log1p(-p)

    def _apply(self, entry: dict[str, Any]) -> None:
        self.history.append(entry)
        self._stack = None
        since = self.confusion == "since"
        if (since and entry["kind"] == "demonstration"
                and any(e["kind"] != "demonstration" for e in self.history)):
            # every earlier answer is one more demonstration back (`since`): the posterior
            # is evaluated afresh (the answers' costly policy terms kept from when they
            # came) and the particles weighted by it over the one they were drawn at
            lw = self._posterior_from(self._parts(self.particles, policy=False), self.idx,
                                      self._policy[0]) - self._base
            self.reference_loglik = self._posterior_from(
                self._parts(self.reference, policy=False), self.ref_idx, self._policy[1])
        else:
            got: list[np.ndarray] = []
            lw = self.log_weights + self._entry_ll(entry, self.particles,
                                                   self._values(self.idx), got)
            self.reference_loglik = self.reference_loglik + self._entry_ll(
                entry, self.reference, self._values(self.ref_idx), got)
            if since and got:
                self._policy = (np.column_stack([self._policy[0], got[0]]),
                                np.column_stack([self._policy[1], got[1]]))
        self.log_weights = lw - np.logaddexp.reduce(lw)
        self.resample_if_needed()

    def _parts(self, points: np.ndarray, policy: bool = True) -> dict[str, Any]:
        """What the posterior needs of `points` that does not depend on the grid values
        (without `policy`, not what the answers' policy term needs: the caller has it)."""
        demos = [e["constraints"] for e in self.history if e["kind"] == "demonstration"
                 and len(e["constraints"])]
        steps = [e for e in self.history if e["kind"] == "steps"]
        out: dict[str, Any] = {"prior_ok": _sat(points, self.prior)}
        out["missed"] = (sum((~_sat(points, c)).astype(float) for c in demos) if demos
                         else np.zeros(len(points)))
        if steps:
            sizes = np.array([len(e["rows"]) for e in steps])
            keep = sizes > 0
            counts = np.concatenate([e["counts"] for e in steps]) if keep.any() \
                else np.zeros((0, self.dim))
            # x once per distinct group: answers revisit the same states
            distinct, group = (distinct_steps([e for e in steps if len(e["rows"])])
                               if keep.any() and policy else (None, None))
            x = distinct.x(points) if distinct is not None else None
            # An answer with no moves has likelihood 1 under either share of an attempt.
            conf = [e.get("confused_ll", None if len(e["rows"])
                          else np.zeros(len(self.grids["beta"]))) for e in steps]
            out["steps"] = {
                "confused_ll": (np.array(conf) if conf and all(c is not None for c in conf)
                                else None),
                "counts": counts, "x": x,
                "taken": taken_actions(counts, group) if policy else None,
                "starts": np.concatenate([[0], np.cumsum(sizes[keep])[:-1]]).astype(np.int64),
                "keep": keep, "n_moves": np.array([e["counts"].sum() for e in steps])}
        out["outcomes"] = [(e, StepData.of(e).x(points), _sat(points, e["region"]))
                           for e in self.history if e["kind"] == "outcome"]
        out["after_steps"], out["after_outcomes"] = demos_after(self.history)
        return out

    def _answers_policy(self, parts: dict[str, Any], beta: np.ndarray) -> np.ndarray | None:
        """``[P, answers]``: log-likelihood of each answer's moves under the engaged policy
        (None without answers). It depends on the points and the rationality only, so the
        uptake and disengagement moves of `_move` reuse it."""
        if "steps" not in parts:
            return None
        st = parts["steps"]
        pol = np.zeros((len(parts["missed"]), len(st["keep"])))
        if st["x"] is not None:
            per_state = self._taken_log_policy(st["x"], beta, st["counts"], st["taken"])
            pol[:, st["keep"]] = np.add.reduceat(per_state, st["starts"], axis=1)
        return pol

    def _taken_log_policy(self, x: np.ndarray, beta: np.ndarray, counts: np.ndarray,
                          taken: Taken) -> np.ndarray:
        """``[P, G]``: ``sum_a counts[g, a] * log pi(a | s_g)`` (`steps.taken_log_policy`)."""
        return taken_log_policy(x, beta, counts, taken, self.lapse)

    def _posterior_from(self, parts: dict[str, Any], idx: dict[str, np.ndarray],
                        pol: np.ndarray | None = None) -> np.ndarray:
        """Unnormalised log posterior; `pol`: `_answers_policy` for these parts and this
        rationality, when the caller already has it."""
        v = self._values(idx)
        out = parts["missed"] * np.log1p(-v["uptake"])
        if "steps" in parts:
            st = parts["steps"]
            if pol is None:
                pol = self._answers_policy(parts, v["beta"])
            assert pol is not None  # there are answers ("steps" in parts)
            out = out + self._steps_ll(pol, st["n_moves"], self.batch_actions(st),
                                       v["disengaged"], v, st["confused_ll"],
                                       parts["after_steps"]).sum(axis=1)
        for (e, x, ok), k in zip(parts["outcomes"], parts["after_outcomes"], strict=True):
            out = out + self._outcome_ll(e, x, v, ok, float(k))
        return np.where(parts["prior_ok"], out, -np.inf)

    @staticmethod
    def batch_actions(st: dict[str, Any]) -> int:
        """The number of actions per state (the width of the step rows)."""
        return int(st["counts"].shape[1]) if st["counts"].ndim == 2 and len(st["counts"]) \
            else 1

    def log_posterior(self, points: np.ndarray, idx: dict[str, np.ndarray] | None = None
                      ) -> np.ndarray:
        """Unnormalised log posterior at ``points [P, F]`` (unit vectors) with the given
        grid indices (default: the particles' own, for P particles)."""
        return self._posterior_from(self._parts(points), self.idx if idx is None else idx)

    # ------------------------------------------------------------------ resample-move
    def resample_if_needed(self) -> bool:
        """`ParticleBelief.resample_if_needed`, carrying each particle's grid values along."""
        n = len(self.particles)
        if not self.resample or self.ess() >= n / 2:
            return False
        rng = np.random.default_rng([self.seed, 2, self.n_resamples])
        pick = systematic_resample(self.weights, rng)
        self.n_resamples += 1
        self.log_weights = np.full(n, -math.log(n))
        self.idx = {k: i[pick] for k, i in self.idx.items()}
        self.particles = self._move(self.particles[pick], rng)
        return True

    def _move(self, pts: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Metropolis-Hastings within Gibbs: a tangent-plane random walk for ``w`` (as in
        `ParticleBelief`), then for each grid a uniform proposal among its other values;
        all symmetric, each accepted by the posterior ratio."""
        n, d = pts.shape
        step = initial_step(pts)
        idx = {k: i.copy() for k, i in self.idx.items()}
        parts = self._parts(pts)
        # The answers' policy term is the costly one; it changes with w and beta only, so
        # it is carried along (row by row, as accepted) instead of recomputed per grid.
        pol = self._answers_policy(parts, self._values(idx)["beta"])
        current = self._posterior_from(parts, idx, pol)
        rates = []
        for _ in range(self.n_moves):
            prop = tangent_proposal(pts, step, rng)
            prop_parts = self._parts(prop)
            prop_pol = self._answers_policy(prop_parts, self._values(idx)["beta"])
            lp = self._posterior_from(prop_parts, idx, prop_pol)
            accept = np.log(rng.random(n)) < lp - current
            pts = np.where(accept[:, None], prop, pts)
            parts = select_parts(parts, prop_parts, accept)
            pol = select_rows(pol, prop_pol, accept)
            current = np.where(accept, lp, current)
            rate = float(accept.mean())
            rates.append(rate)
            if rate < 0.15:
                step = max(step * 0.5, 1e-6)
            elif rate > 0.5:
                step = min(step * 1.5, 1.0)
            for name, grid in self.grids.items():
                k = len(grid)
                if k < 2:
                    continue
                trial = dict(idx)
                trial[name] = (idx[name] + rng.integers(1, k, size=n)) % k  # another value
                trial_pol = (self._answers_policy(parts, self._values(trial)["beta"])
                             if name == "beta" else pol)
                lp = self._posterior_from(parts, trial, trial_pol)
                accept = np.log(rng.random(n)) < lp - current
                idx[name] = np.where(accept, trial[name], idx[name])
                pol = select_rows(pol, trial_pol, accept)
                current = np.where(accept, lp, current)
        self.idx = idx
        self._base = current  # the posterior the moved particles are drawn from
        if pol is not None:
            self._policy = (pol, self._policy[1])
        self.step_size = step
        self.acceptance = float(np.mean(rates)) if rates else None
        return pts

    # ------------------------------------------------------------------ summaries, state
    def mean_of(self, name: str) -> float:
        """Posterior mean of one grid parameter (``beta``: geometric mean)."""
        v = self.grids[name][self.idx[name]]
        if name == "beta":
            return float(10 ** (self.weights @ np.log10(v)))
        return float(self.weights @ v)

    def state_dict(self) -> dict[str, Any]:
        out = super().state_dict()
        out.update(grids={k: g.copy() for k, g in self.grids.items()}, lapse=self.lapse,
                   idx={k: i.copy() for k, i in self.idx.items()},
                   ref_idx={k: i.copy() for k, i in self.ref_idx.items()})
        return out

    def copy(self) -> Self:
        out = super().copy()
        out.idx = {k: i.copy() for k, i in self.idx.items()}
        return out


def _sat(points: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Mask over points: every constraint row holds (all points when there are none)."""
    if not len(rows):
        return np.ones(len(points), dtype=bool)
    return np.all(points @ np.asarray(rows).T >= -TOL, axis=1)
