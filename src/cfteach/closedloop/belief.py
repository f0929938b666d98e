"""A particle-filter model of what a learner believes about the robot's reward weights.

Closed-loop teaching (Lee, Admoni & Simmons' 2024 follow-up to the IROS 2022 paper) tracks the
learner's belief as weighted particles on the unit sphere, inside the prior region, and updates
it after every demonstration and every test answer. Both likelihoods are soft (never zero), so
one inconsistent answer cannot wipe the belief out:

* demonstration with constraint rows ``C``: ``L(w) = p_learn * 1[C @ w >= 0] + (1 - p_learn)``;
* test answer: a Boltzmann choice ``P(a | w) ∝ exp(w . mu_a / T)`` among the candidate answers'
  feature counts (the optimal one, the learner's own, the counterfactual alternatives).

When the effective sample size falls below half the particles, the belief is resampled
(systematic) and rejuvenated by a few Metropolis-Hastings moves targeting the full posterior,
which is recomputed from the stored observations (kept as plain arrays, so a belief pickles
and replays). Everything is deterministic given the constructor arguments and the sequence of
observations. Equations: docs/closed-loop.md.
"""

from __future__ import annotations

import math
from typing import Any, Self

import numpy as np
from scipy.special import logsumexp

from cfteach.geometry import Region
from cfteach.geometry.region import sphere_area

TOL = 1e-12  # a constraint row c holds at w when c @ w >= -TOL
_KEY_DECIMALS = 9  # feature counts equal to this many decimals are the same answer

__all__ = ["ParticleBelief", "TOL"]


def _check_rows(value: Any, dim: int, name: str) -> np.ndarray:
    """Constraint rows as float ``[k, dim]`` (a single row may be ``[dim]``)."""
    arr = np.asarray(value if value is not None else np.zeros((0, dim)), dtype=np.float64)
    if arr.size == 0:
        return np.zeros((0, dim))
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"{name}: expected constraint rows of shape [k, {dim}], "
                         f"got shape {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains non-finite values")
    return arr


def _check_vector(value: Any, dim: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (dim,):
        raise ValueError(f"{name}: expected feature counts of shape [{dim}], got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains non-finite values")
    return arr


def _satisfied(points: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Mask over points ``[P, F]``: every row ``c`` has ``c @ w >= -TOL``."""
    if len(rows) == 0:
        return np.ones(len(points), dtype=bool)
    return np.all(points @ rows.T >= -TOL, axis=1)


def _grouped_lse(x: np.ndarray, starts: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Log-sum-exp over consecutive column groups of ``x [P, M]``: ``[P, len(starts)]``."""
    mx = np.maximum.reduceat(x, starts, axis=1)
    total = np.add.reduceat(np.exp(x - np.repeat(mx, sizes, axis=1)), starts, axis=1)
    return mx + np.log(total)


def _dedupe(rows: np.ndarray) -> np.ndarray:
    """Rows in first-seen order with equal ones (to ``_KEY_DECIMALS``) dropped."""
    keys = np.round(rows, _KEY_DECIMALS) + 0.0
    _, first = np.unique(keys, axis=0, return_index=True)
    return rows[np.sort(first)]


class ParticleBelief:
    """Weighted particles over the learner's reward weights (unit vectors inside the prior).

    ``prior`` holds constraint rows ``[k, dim]`` (k may be 0). ``particles`` optionally gives the
    starting points ``[P, dim]`` (nonzero, inside the prior; normalised here), else
    ``n_particles`` are drawn uniformly from the prior region with ``default_rng([seed, 0])``.
    ``resample=False`` turns resample-move off (pure importance weighting); ``n_moves`` is the
    number of Metropolis-Hastings moves per particle after each resampling.
    """

    def __init__(
        self,
        prior: np.ndarray,
        dim: int,
        *,
        n_particles: int = 1000,
        seed: int = 0,
        p_learn: float = 0.8,
        temperature: float = 0.5,
        n_reference: int = 4000,
        particles: np.ndarray | None = None,
        resample: bool = True,
        n_moves: int = 3,
    ) -> None:
        if isinstance(dim, bool) or not isinstance(dim, int | np.integer) or dim < 3:
            raise ValueError(f"dim must be an integer >= 3 (number of features), got {dim!r}")
        self.dim = int(dim)
        for name, value, low in (("n_particles", n_particles, 1), ("n_reference", n_reference, 1),
                                 ("n_moves", n_moves, 0), ("seed", seed, 0)):
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
        p = float(p_learn)
        if not (0.0 < p < 1.0):
            raise ValueError(f"p_learn must lie strictly between 0 and 1 (the likelihood of a "
                             f"demonstration is never zero), got {p_learn!r}")
        t = float(temperature)
        if not (t > 0.0 and math.isfinite(t)):
            raise ValueError(f"temperature must be a positive finite number, got {temperature!r}")
        self.prior = _check_rows(prior, self.dim, "prior")
        self.seed = int(seed)
        self.p_learn = p
        self.temperature = t
        self.n_reference = int(n_reference)
        self.resample = bool(resample)
        self.n_moves = int(n_moves)
        region = Region(self.prior, dim=self.dim)
        if region.is_empty():
            raise ValueError("prior: the prior constraints leave an empty region")
        if particles is None:
            start = self._draw_prior(region, int(n_particles), [self.seed, 0])
        else:
            start = np.array(particles, dtype=np.float64)
            if start.ndim != 2 or start.shape[1] != self.dim or len(start) == 0:
                raise ValueError(f"particles: expected shape [P, {self.dim}] with P >= 1, "
                                 f"got {start.shape}")
            norms = np.linalg.norm(start, axis=1, keepdims=True)
            if not np.all(np.isfinite(start)) or np.any(norms == 0):
                raise ValueError("particles: every particle must be finite and nonzero")
            start = start / norms
            if not np.all(_satisfied(start, self.prior)):
                raise ValueError("particles: every particle must lie inside the prior region")
        self.particles: np.ndarray = start
        self.log_weights: np.ndarray = np.full(len(start), -math.log(len(start)))
        self.reference: np.ndarray = self._draw_prior(region, self.n_reference, [self.seed, 1])
        self.reference_loglik: np.ndarray = np.zeros(self.n_reference)
        self.history: list[dict[str, Any]] = []
        self.n_resamples = 0
        self.step_size: float | None = None  # the last resample-move's proposal scale
        self.acceptance: float | None = None  # the last resample-move's mean acceptance
        self._prior_area: float | None = None
        self._stack: dict[str, Any] | None = None

    def _draw_prior(self, region: Region, m: int, seed: list[int]) -> np.ndarray:
        rng = np.random.default_rng(seed)
        if len(self.prior) == 0:  # the whole sphere: normalised Gaussians, any dimension
            g = rng.standard_normal((m, self.dim))
            return g / np.linalg.norm(g, axis=1, keepdims=True)
        pts = region.sample(m, rng)
        return pts / np.linalg.norm(pts, axis=1, keepdims=True)

    # ------------------------------------------------------------------ summaries
    @property
    def weights(self) -> np.ndarray:
        """Normalised particle weights ``[P]`` (sum 1)."""
        return np.exp(self.log_weights)

    def ess(self) -> float:
        """Effective sample size ``1 / sum(w^2)``: P for equal weights, 1 for one survivor."""
        return float(1.0 / np.sum(self.weights**2))

    def mean(self) -> np.ndarray:
        """Belief-weighted mean direction (not normalised; its length shows concentration)."""
        return self.weights @ self.particles

    def p_optimal(self, constraints: np.ndarray) -> float:
        """Probability the learner answers a test optimally: the belief mass inside the test's
        constraint region (a learner with weights w answers optimally iff w lies in it)."""
        rows = _check_rows(constraints, self.dim, "constraints")
        return float(np.sum(self.weights[_satisfied(self.particles, rows)]))

    def p_optimal_many(self, row_sets: list[np.ndarray]) -> np.ndarray:
        """``[p_optimal(rows) for rows in row_sets]`` in one pass over the particles."""
        sets = [_check_rows(r, self.dim, f"row_sets[{i}]") for i, r in enumerate(row_sets)]
        out = np.ones(len(sets))
        used = [i for i, r in enumerate(sets) if len(r)]
        if not used:
            return out
        rows = np.vstack([sets[i] for i in used])
        starts = np.cumsum([0] + [len(sets[i]) for i in used[:-1]])
        ok = np.logical_and.reduceat(self.particles @ rows.T >= -TOL, starts, axis=1)
        out[used] = self.weights @ ok
        return out

    def violation_mass(self, constraints: np.ndarray) -> float:
        """``1 - p_optimal``: the belief mass a lesson with these constraints would correct."""
        return 1.0 - self.p_optimal(constraints)

    def _prior_measure(self) -> float:
        if self._prior_area is None:
            if len(self.prior) == 0:
                self._prior_area = sphere_area(self.dim)
            elif self.dim == 3:
                self._prior_area = Region(self.prior, dim=3).area()
            else:
                self._prior_area = Region(self.prior, dim=self.dim).area_estimate(
                    seed=self.seed)[0]
        return self._prior_area

    def expected_area(self) -> float:
        """Effective area of the belief (steradians for 3 features): ``area(prior) * exp(H(q))
        / G`` with q the exact posterior on the G reference points. A posterior uniform on a
        sub-region gives that sub-region's area; the prior gives the prior's area."""
        q_log = self.reference_loglik - logsumexp(self.reference_loglik)
        q = np.exp(q_log)
        h = -float(np.sum(q[q > 0] * q_log[q > 0]))
        return self._prior_measure() * math.exp(h) / self.n_reference

    def entropy(self) -> float:
        """Differential entropy of the belief in nats (w.r.t. surface measure):
        ``log(expected_area())``."""
        return math.log(self.expected_area())

    # ------------------------------------------------------------------ likelihoods
    def _entry_loglik(self, entry: dict[str, Any], points: np.ndarray) -> np.ndarray:
        """Log-likelihood of one stored observation at ``points [P, F]``."""
        if entry["kind"] == "demonstration":
            ok = _satisfied(points, entry["constraints"])
            return np.where(ok, 0.0, math.log1p(-self.p_learn))
        logits = points @ entry["candidates"].T / self.temperature
        den = logsumexp(logits, axis=1)
        target = int(entry["target"])
        if entry["complement"]:  # log(1 - P(target)) = lse(others) - lse(all), no cancellation
            return logsumexp(np.delete(logits, target, axis=1), axis=1) - den
        return logits[:, target] - den

    def _stacked(self) -> dict[str, Any]:
        """The history as concatenated arrays, for evaluating the full posterior at once."""
        if self._stack is None:
            demos = [e["constraints"] for e in self.history
                     if e["kind"] == "demonstration" and len(e["constraints"])]
            nums: list[np.ndarray] = []
            dens: list[np.ndarray] = []
            for e in self.history:
                if e["kind"] != "answer":
                    continue
                cand, t = e["candidates"], int(e["target"])
                nums.append(np.delete(cand, t, axis=0) if e["complement"] else cand[t:t + 1])
                dens.append(cand)
            st: dict[str, Any] = {"n_demos": len(demos), "n_answers": len(nums)}
            if demos:
                st["demo_rows"] = np.vstack(demos)
                st["demo_starts"] = np.cumsum([0] + [len(d) for d in demos[:-1]])
            if nums:
                for key, group in (("num", nums), ("den", dens)):
                    sizes = np.array([len(g) for g in group])
                    st[key] = np.vstack(group).T / self.temperature
                    st[key + "_sizes"] = sizes
                    st[key + "_starts"] = np.concatenate([[0], np.cumsum(sizes[:-1])])
            self._stack = st
        return self._stack

    def log_posterior(self, points: np.ndarray) -> np.ndarray:
        """Unnormalised log posterior at ``points [P, F]`` (unit vectors): ``-inf`` outside the
        prior, else the sum of every stored observation's log-likelihood."""
        st = self._stacked()
        out = np.zeros(len(points))
        if st["n_demos"]:
            ok = np.logical_and.reduceat(points @ st["demo_rows"].T >= -TOL, st["demo_starts"],
                                         axis=1)
            out += (st["n_demos"] - ok.sum(axis=1)) * math.log1p(-self.p_learn)
        if st["n_answers"]:
            num = _grouped_lse(points @ st["num"], st["num_starts"], st["num_sizes"])
            den = _grouped_lse(points @ st["den"], st["den_starts"], st["den_sizes"])
            out += (num - den).sum(axis=1)
        return np.where(_satisfied(points, self.prior), out, -np.inf)

    # ------------------------------------------------------------------ observations
    def _apply(self, entry: dict[str, Any]) -> None:
        self.history.append(entry)
        self._stack = None
        lw = self.log_weights + self._entry_loglik(entry, self.particles)
        self.log_weights = lw - logsumexp(lw)
        self.reference_loglik = self.reference_loglik + self._entry_loglik(entry, self.reference)
        self.resample_if_needed()

    def observe_demonstration(self, constraints: np.ndarray) -> None:
        """Update after a demonstration whose constraints are ``constraints [k, F]``: the learner
        adopts them with probability ``p_learn``, else ignores the demonstration."""
        rows = _check_rows(constraints, self.dim, "constraints")
        self._apply({"kind": "demonstration", "constraints": rows})

    def observe_answer(
        self,
        optimal_mu: np.ndarray,
        answer_mu: np.ndarray | None,
        alternatives: np.ndarray | None,
        *,
        finished: bool = True,
        correct: bool | None = None,
    ) -> None:
        """Update after a test answer (Boltzmann choice among the candidates' feature counts).

        ``correct`` defaults to whether ``answer_mu`` equals ``optimal_mu``. A correct answer
        scores ``P(mu* | w)``, a finished wrong one ``P(mu_h | w)``, an unfinished one (no valid
        ``mu_h``; ``answer_mu`` may be None) ``1 - P(mu* | w)``.
        """
        opt = _check_vector(optimal_mu, self.dim, "optimal_mu")
        alts = _check_rows(alternatives, self.dim, "alternatives")
        ans = None if answer_mu is None else _check_vector(answer_mu, self.dim, "answer_mu")
        key = np.round(opt, _KEY_DECIMALS) + 0.0
        if finished and ans is None and correct is not True:
            raise ValueError("answer_mu: a finished answer needs its feature counts "
                             "(or correct=True)")
        if correct is None:
            correct = bool(finished and ans is not None
                           and np.array_equal(np.round(ans, _KEY_DECIMALS) + 0.0, key))
        if correct and not finished:
            raise ValueError("correct: an unfinished answer cannot be correct")
        # a finished wrong answer has its feature counts (checked above)
        own = [ans] if finished and not correct and ans is not None else []
        cand = _dedupe(np.vstack([opt[None, :], *[a[None, :] for a in own], alts]))
        keys = np.round(cand, _KEY_DECIMALS) + 0.0
        if own:
            target = int(np.flatnonzero(np.all(keys == np.round(own[0], _KEY_DECIMALS) + 0.0,
                                               axis=1))[0])
        else:
            target = 0
        if not finished and len(cand) < 2:
            raise ValueError("alternatives: an unfinished answer needs at least one candidate "
                             "answer other than the optimal one (else 1 - P(mu*) is 0)")
        self._apply({
            "kind": "answer", "optimal_mu": opt,
            "answer_mu": None if ans is None else ans, "alternatives": alts,
            "finished": bool(finished), "correct": bool(correct),
            "candidates": cand, "target": target, "complement": not finished,
        })

    def observe(self, entry: dict[str, Any]) -> None:
        """Replay one ``history`` entry (e.g. of another belief) as a new observation."""
        if entry["kind"] == "demonstration":
            self.observe_demonstration(entry["constraints"])
        elif entry["kind"] == "answer":
            self.observe_answer(entry["optimal_mu"], entry["answer_mu"], entry["alternatives"],
                                finished=entry["finished"], correct=entry["correct"])
        else:
            raise ValueError(f"entry: unknown observation kind {entry.get('kind')!r}")

    # ------------------------------------------------------------------ resample-move
    def resample_if_needed(self) -> bool:
        """Systematic resampling plus Metropolis-Hastings rejuvenation when the effective
        sample size is below half the particles; returns whether it resampled."""
        n = len(self.particles)
        if not self.resample or self.ess() >= n / 2:
            return False
        rng = np.random.default_rng([self.seed, 2, self.n_resamples])
        idx = systematic_resample(self.weights, rng)
        pts = self.particles[idx]
        self.n_resamples += 1
        self.log_weights = np.full(n, -math.log(n))
        self.particles = self._move(pts, rng)
        return True

    def _move(self, pts: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """``n_moves`` random-walk MH steps in the tangent plane, symmetric (the proposal's
        density depends only on the angle between the two points), targeting the posterior.
        The scale follows the particles' spread, then is halved or grown by the acceptance."""
        n, d = pts.shape
        step = initial_step(pts)
        current = self.log_posterior(pts)
        rates = []
        for _ in range(self.n_moves):
            prop = tangent_proposal(pts, step, rng)
            lp = self.log_posterior(prop)
            accept = np.log(rng.random(n)) < lp - current
            pts = np.where(accept[:, None], prop, pts)
            current = np.where(accept, lp, current)
            rate = float(accept.mean())
            rates.append(rate)
            if rate < 0.15:
                step = max(step * 0.5, 1e-6)
            elif rate > 0.5:
                step = min(step * 1.5, 1.0)
        self.step_size = step
        self.acceptance = float(np.mean(rates)) if rates else None
        return pts

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict[str, Any]:
        """Everything that defines the belief (copies): compare two beliefs key by key."""
        return {
            "dim": self.dim, "seed": self.seed, "p_learn": self.p_learn,
            "temperature": self.temperature, "n_reference": self.n_reference,
            "resample": self.resample, "n_moves": self.n_moves, "prior": self.prior.copy(),
            "particles": self.particles.copy(), "log_weights": self.log_weights.copy(),
            "reference": self.reference.copy(),
            "reference_loglik": self.reference_loglik.copy(),
            "n_resamples": self.n_resamples, "step_size": self.step_size,
            "acceptance": self.acceptance,
            "history": [{k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in e.items()}
                        for e in self.history],
        }

    def copy(self) -> Self:
        """An independent copy of the same class (for what-if updates: simulate an answer
        without committing)."""
        out = type(self).__new__(type(self))
        out.__dict__.update(self.__dict__)
        state = self.state_dict()
        for key in ("prior", "particles", "log_weights", "reference", "reference_loglik",
                    "history"):
            setattr(out, key, state[key])
        out._stack = None
        return out

    def __repr__(self) -> str:
        return (f"ParticleBelief(dim={self.dim}, particles={len(self.particles)}, "
                f"observations={len(self.history)}, ess={self.ess():.1f})")


def systematic_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices of a systematic resample of `weights` (one uniform draw, evenly spaced
    positions): lower variance than multinomial resampling, and one draw keeps it cheap."""
    n = len(weights)
    positions = (rng.random() + np.arange(n)) / n
    cdf = np.cumsum(weights)
    return np.minimum(np.searchsorted(cdf, positions * cdf[-1], side="right"), n - 1)


def initial_step(pts: np.ndarray) -> float:
    """Random-walk scale from the particles' spread on the sphere (2.38 / sqrt(d - 1) times
    it, the usual optimal-scaling rule), kept within [1e-6, 1]."""
    d = pts.shape[1]
    centre = pts.mean(axis=0)
    spread = math.sqrt(max(1.0 - float(centre @ centre), 0.0) / (d - 1))
    return min(max(2.38 / math.sqrt(d - 1) * spread, 1e-6), 1.0)


def tangent_proposal(pts: np.ndarray, step: float, rng: np.random.Generator) -> np.ndarray:
    """A symmetric proposal on the sphere: a Gaussian step in each point's tangent plane,
    projected back to unit length."""
    z = rng.standard_normal(pts.shape)
    z -= np.sum(z * pts, axis=1, keepdims=True) * pts
    prop = pts + step * z
    prop /= np.linalg.norm(prop, axis=1, keepdims=True)
    return prop
