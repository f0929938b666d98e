"""Simulated learners: how a person might turn demonstrations into a belief over `w*`,
and how they would then play an unseen test.

Four models, each a `LearnerModel` (docs/simulate.md explains the reasoning):

* ``counterfactual`` — the paper's model of the human (§IV, Alg. 1). The belief is a region
  of the weight sphere, starting at the domain's prior. On each demonstration the learner
  samples `m` weight vectors from its *own* current belief, works out what it would have
  done itself under each (its counterfactual: of its tied-optimal plans, the one closest to
  the demonstration — the reference's "benefit of the doubt"), from every state along the
  demonstration as the reference does, and cuts its belief with `mu(demo) - mu(own plan)`.
* ``irl`` — standard IRL (Eq. 2): one-action deviations followed by the robot's optimal
  policy, from every state along the demonstration. Deterministic: all such learners hold
  the same belief and differ only in how they answer tests.
* ``noisy`` — a bounded version of ``counterfactual``: only a few counterfactuals per
  demonstration (`human_models`, default 2, from the demonstration's start only — the
  paper's Eq. 4) and Boltzmann-rational test answers with a temperature.
* ``inattentive`` — ``counterfactual``, but each demonstration it is shown (feedback
  included) is learnt from only with probability `p_absorb` (default 0.5, an independent
  draw per learner and demonstration). A teacher is never told which ones were missed: the
  learner the closed-loop teacher (`cfteach.closedloop`) is built for.

Answering a test: the learner samples one weight vector from its belief for the test's
environment, plans with it (exact value iteration, `cfteach.mdp`) and plays from the test's
start state — greedily, or Boltzmann-rationally for the noisy model. Answers are scored
exactly as the study scores people (`cfteach.simulate.scoring`).

Weights that make a reward-gaining loop in an environment (e.g. a positive path weight in
skateboard) have no finite plan. What a learner does with such a sample is the model's
`unbounded` setting:

* ``"loops"`` (default; the teacher's default profile, `cfteach.bec.loop_rows`): the
  demonstration shows the robot *not* taking the loop that sample would take forever, so
  the learner concludes that the loop does not pay: ``-mu(loop) . w >= 0`` for every paying
  loop of length 1 or 2 under that sample.
* ``"resample"``: the learner imagines only robots that finish their task — it has only
  seen demonstrations that end — and redraws the sample (up to `MAX_REDRAWS` times).
* ``"drop"``: the reference's rule: the sample gives no counterfactual, and a test answered
  with it never finishes (so it is wrong).

When answering tests, ``"loops"`` and ``"resample"`` learners redraw such samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from cfteach.simulate.planning import boltzmann_rollouts
from cfteach.simulate.scoring import score_answers

#: What a learner does with a weight sample that has no finite plan (module docstring).
UNBOUNDED_RULES = ("loops", "resample", "drop")
#: How often a learner redraws a weight sample that has no finite plan in an environment.
MAX_REDRAWS = 20
#: Weight samples drawn from a belief at a time (see `Learners._draw`).
POOL = 64


@dataclass(frozen=True)
class LearnerModel:
    """How a simulated learner learns and answers (see the module docstring)."""

    name: str
    constraints: str = "counterfactual"  # or "one_step" (standard IRL)
    human_models: int = 8
    all_suffixes: bool = True
    temperature: float = 0.0
    unbounded: str = "loops"
    p_absorb: float = 1.0  # chance each shown demonstration is learnt from (inattentive)

    def __post_init__(self) -> None:
        if self.constraints not in ("counterfactual", "one_step"):
            raise ValueError(f"constraints must be 'counterfactual' or 'one_step', "
                             f"got {self.constraints!r}")
        if self.human_models < 1:
            raise ValueError(f"human_models must be at least 1, got {self.human_models}")
        if self.temperature < 0:
            raise ValueError(f"temperature must be >= 0, got {self.temperature}")
        if not 0 < self.p_absorb <= 1:
            raise ValueError(f"p_absorb must lie in (0, 1], got {self.p_absorb}")
        if self.unbounded not in UNBOUNDED_RULES:
            raise ValueError(f"unbounded must be one of {', '.join(UNBOUNDED_RULES)}, "
                             f"got {self.unbounded!r}")


LEARNER_MODELS: dict[str, LearnerModel] = {
    "counterfactual": LearnerModel("counterfactual"),
    "irl": LearnerModel("irl", constraints="one_step", human_models=1),
    "noisy": LearnerModel("noisy", human_models=2, all_suffixes=False, temperature=0.02),
    "inattentive": LearnerModel("inattentive", p_absorb=0.5),
}


_FIELD_TYPES = {"human_models": int, "all_suffixes": bool, "temperature": float,
                "unbounded": str, "p_absorb": float}


def parse_learner(spec: str) -> LearnerModel:
    """A learner model from a command-line spec: a built-in name, optionally followed by
    ``:field=value`` pairs, e.g. ``noisy:temperature=0.1:human_models=3``. The spec itself
    becomes the model's name, so variants are told apart in the results."""
    name, *pairs = spec.split(":")
    overrides: dict[str, Any] = {}
    for pair in pairs:
        key, eq, value = pair.partition("=")
        if not eq or key not in _FIELD_TYPES:
            raise ValueError(f"bad learner option {pair!r} in {spec!r}: write field=value with "
                             f"a field among {', '.join(_FIELD_TYPES)}")
        kind = _FIELD_TYPES[key]
        try:
            if kind is bool:
                if value.lower() not in ("true", "false", "1", "0"):
                    raise ValueError
                overrides[key] = value.lower() in ("true", "1")
            else:
                overrides[key] = kind(value)
        except ValueError:
            raise ValueError(f"bad value {value!r} for {key} in {spec!r} "
                             f"(expected {kind.__name__})") from None
    model = learner_model(name, **overrides)
    return replace(model, name=spec) if pairs else model


def learner_model(name: str | LearnerModel, **overrides: Any) -> LearnerModel:
    """A built-in learner model by name, optionally with some fields changed."""
    if isinstance(name, LearnerModel):
        return replace(name, **overrides) if overrides else name
    if ":" in name and not overrides:
        return parse_learner(name)
    if name not in LEARNER_MODELS:
        raise ValueError(f"unknown learner model {name!r}; choose one of "
                         f"{', '.join(LEARNER_MODELS)}")
    return replace(LEARNER_MODELS[name], **overrides) if overrides else LEARNER_MODELS[name]


def _as_constraints(rows: np.ndarray) -> np.ndarray:
    """Feature-count differences are integral: keep them integer (exact geometry)."""
    r = np.round(rows)
    return r.astype(np.int64) if np.allclose(rows, r, atol=1e-9) else rows


@dataclass(frozen=True)
class Replay:
    """A demonstration or test replayed in the compiled instance."""

    env: int
    states: np.ndarray       # state indices visited, len(actions) + 1 (the last may be the sink)
    actions: np.ndarray
    mu_suffix: np.ndarray    # [T, F] feature counts from step t to the end
    finished: bool


class Learners:
    """`n` simulated learners of one model, learning one domain side by side.

    All planning is batched over the learners (one value iteration per demonstration for
    everyone's sampled weights), so a block of learners costs little more than one.
    """

    def __init__(self, domain: Any, model: str | LearnerModel, n: int,
                 rng: np.random.Generator | int | None = None) -> None:
        from cfteach.mdp import compile_domain

        if n < 1:
            raise ValueError(f"need at least one learner, got n={n}")
        self.domain = domain
        self.model = learner_model(model)
        self.n = int(n)
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.batch = compile_domain(domain)
        self.w_true = np.asarray(domain.weights, dtype=float)
        prior = np.asarray(domain.prior)
        prior = prior.reshape(-1, self.batch.F) if prior.size else np.zeros((0, self.batch.F))
        self.beliefs: list[np.ndarray] = [_as_constraints(prior) for _ in range(self.n)]
        self.ignored = np.zeros(self.n, dtype=np.int64)  # updates that would empty a belief
        self._star: dict[int, np.ndarray] = {}
        self._pool: dict[int, np.ndarray] = {}  # pre-drawn samples per learner's belief

    def _draw(self, i: int, k: int) -> np.ndarray:
        """`k` weight vectors from learner `i`'s belief. Drawn in batches of at least
        `POOL` and kept until the belief changes (beyond 3 features every `sample` call
        starts a hit-and-run chain, which costs far more than the draws themselves)."""
        pool = self._pool.get(i)
        if pool is None or len(pool) < k:
            extra = self._region(self.beliefs[i]).sample(max(POOL, k), self.rng)
            pool = extra if pool is None else np.vstack([pool, extra])
        self._pool[i] = pool[k:]
        return pool[:k]

    # -- helpers -----------------------------------------------------------------------
    def _region(self, normals: np.ndarray):
        from cfteach.geometry import Region

        return Region(normals, dim=self.batch.F)

    def _optimal_q(self, env: int) -> np.ndarray:
        """Q under the true weights for one instance, cached: the robot's own planning."""
        if env not in self._star:
            from cfteach.mdp import value_iteration

            vals = value_iteration(self.batch, self.w_true[None], env=[env])
            if not vals.bounded[0, 0]:
                raise ValueError(f"the true weights make instance {env} unbounded")
            self._star[env] = vals.Q[0, 0]
        return self._star[env]

    def _plan_samples(self, env: int, m: int, redraw: bool
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Draw `m` weight vectors from every learner's belief and plan with them in one
        instance: `W[n*m, F]`, `Q[n*m, S, A]` (learner i owns rows i*m .. i*m+m-1) and
        `bounded[n*m]`.

        With `redraw`, samples with no finite plan are replaced: each round draws
        a batch of candidates (twice as many as still needed, growing) for every learner
        still short, plans them all in one value iteration, and keeps the first bounded
        ones in draw order; after `MAX_REDRAWS` candidates per needed sample the remaining
        slots keep unbounded samples.
        """
        from cfteach.mdp import value_iteration

        S, A, F = self.batch.S, self.batch.A, self.batch.F
        w_out = np.zeros((self.n * m, F))
        q = np.zeros((self.n * m, S, A))
        bounded = np.zeros(self.n * m, dtype=bool)
        filled = np.zeros(self.n, dtype=np.int64)
        spare: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
        budget = m * (MAX_REDRAWS + 1) if redraw else m
        drawn = np.zeros(self.n, dtype=np.int64)
        factor = 2 if redraw else 1
        while True:
            short = [i for i in range(self.n) if filled[i] < m and drawn[i] < budget]
            if not short:
                break
            counts = [min(budget - drawn[i], factor * (m - filled[i])) for i in short]
            W = np.vstack([self._draw(i, int(k)) for i, k in zip(short, counts, strict=True)])
            vals = value_iteration(self.batch, W, env=[env])
            row = 0
            for i, k in zip(short, counts, strict=True):
                drawn[i] += k
                for j in range(row, row + k):
                    if filled[i] < m and vals.bounded[0, j]:
                        w_out[i * m + filled[i]] = W[j]
                        q[i * m + filled[i]] = vals.Q[0, j]
                        bounded[i * m + filled[i]] = True
                        filled[i] += 1
                    elif not vals.bounded[0, j]:
                        spare.setdefault(i, []).append((W[j], vals.Q[0, j]))
                row += k
            factor *= 2
        for i in range(self.n):  # out of draws: keep unbounded samples (no finite plan)
            while filled[i] < m:
                w_out[i * m + filled[i]], q[i * m + filled[i]] = spare[i].pop(0)
                filled[i] += 1
        return w_out, q, bounded

    def replay(self, item: dict[str, Any]) -> Replay:
        """Replay a demonstration/test dict (docs/schemas.md) in the compiled instance."""
        env = _env_of(self.domain, item)
        inst = self.batch.instances[env]
        try:
            start = inst.state_from_json(item["start_state"])
        except KeyError as err:
            raise ValueError(f"demonstration lacks {err.args[0]!r}") from None
        s = self.batch.index_of(env, start)
        acts = [_action_index(self.batch.actions, a) for a in item.get("actions", [])]
        nxt, feats = self.batch.next_state[env], self.batch.features[env]
        states, phis = [s], []
        for t, a in enumerate(acts):
            if s == self.batch.sink:
                raise ValueError(f"demonstration continues after the end (action {t})")
            phis.append(feats[s, a])
            s = int(nxt[s, a])
            states.append(s)
        phis_arr = np.asarray(phis, dtype=float).reshape(len(acts), self.batch.F)
        mu_suffix = np.cumsum(phis_arr[::-1], axis=0)[::-1] if len(acts) else phis_arr
        if "feature_counts" in item and len(acts):
            if not np.allclose(mu_suffix[0], item["feature_counts"]):
                raise ValueError(f"demonstration's feature_counts {item['feature_counts']} do "
                                 f"not match its replay {mu_suffix[0].tolist()}")
        return Replay(env, np.asarray(states), np.asarray(acts, dtype=np.intp), mu_suffix,
                      states[-1] == self.batch.sink)

    # -- learning ----------------------------------------------------------------------
    def observe(self, demo: dict[str, Any]) -> np.ndarray:
        """Update every learner's belief from one demonstration; returns the number of
        new constraints each learner formed."""
        rep = self.replay(demo)
        if not rep.finished or len(rep.actions) == 0:
            return np.zeros(self.n, dtype=np.int64)  # an unfinished demo proves nothing
        # inattentive learners miss a demonstration with probability 1 - p_absorb (one
        # independent draw per learner and demonstration; none for attentive models, so
        # their random streams are unchanged)
        absorbed = self.rng.random(self.n) < self.model.p_absorb if self.model.p_absorb < 1 \
            else np.ones(self.n, dtype=bool)
        if self.model.constraints == "one_step":
            rows = self._one_step_constraints(rep)
            per = [rows] * self.n
        else:
            per = self._counterfactual_constraints(rep)
        added = np.zeros(self.n, dtype=np.int64)
        for i, rows in enumerate(per):
            rows = rows[np.any(rows != 0, axis=1)]
            if not len(rows) or not absorbed[i]:
                continue
            added[i] = len(rows)
            new = self._region(np.vstack([self.beliefs[i], rows]).astype(rows.dtype))
            if new.is_empty():
                self.ignored[i] += 1  # contradictory evidence: keep the old belief
                continue
            self.beliefs[i] = _as_constraints(np.asarray(new.reduced()))
            self._pool.pop(i, None)
        return added

    def _one_step_constraints(self, rep: Replay) -> np.ndarray:
        from cfteach.mdp import greedy_actions, rollout_from

        policy = greedy_actions(self._optimal_q(rep.env))[None]
        T, A = len(rep.actions), self.batch.A
        starts = np.repeat(rep.states[:T], A)[None]
        first = np.tile(np.arange(A), T)[None]
        ro = rollout_from(self.batch, policy, rep.env, starts, first,
                          max_steps=self.batch.S + 1, max_self_loops=None)
        mu, fin = ro.mu[0].reshape(T, A, -1), ro.terminal[0].reshape(T, A)
        keep = fin & (np.arange(A)[None] != rep.actions[:, None])
        rows = (rep.mu_suffix[:, None] - mu)[keep]
        return _as_constraints(rows)

    def _counterfactual_constraints(self, rep: Replay) -> list[np.ndarray]:
        from cfteach.mdp import best_tied_policy, rollout_from

        m = self.model.human_models
        W, q, bounded = self._plan_samples(rep.env, m, self.model.unbounded == "resample")
        T = len(rep.actions) if self.model.all_suffixes else 1
        starts = rep.states[:T]
        # The benefit-of-the-doubt plan among tied trajectories that reach the end within S
        # steps: the DP's first actions with S steps of continuation, followed as a
        # stationary policy; a rollout that ends took tied actions only (cfteach.mdp).
        # Only bounded samples can yield a counterfactual: plan for those alone (-1 = none).
        S = self.batch.S
        policy = np.full((len(q), S), -1, dtype=np.int64)
        policy[bounded] = best_tied_policy(self.batch, np.full(int(bounded.sum()), rep.env),
                                           q[bounded], self.w_true, horizon=S + 1,
                                           must_finish=True)
        ro = rollout_from(self.batch, policy, rep.env, starts, max_steps=S,
                          max_self_loops=None)
        mu_h, found = ro.mu, ro.terminal & bounded[:, None]
        diffs = rep.mu_suffix[None, :T] - mu_h                 # [N*m, T, F]
        loops: dict[int, np.ndarray] = {}
        if self.model.unbounded == "loops" and not bounded.all():
            from cfteach.bec import loop_rows

            bad = np.flatnonzero(~bounded)
            rows = loop_rows(self.batch, W, np.full(bad.size, rep.env), bad)
            loops = dict(zip(bad.tolist(), rows, strict=True))
        out = []
        for i in range(self.n):
            sl = slice(i * m, (i + 1) * m)
            mine = [diffs[sl][found[sl]]]
            mine += [loops[j] for j in range(i * m, (i + 1) * m) if j in loops]
            out.append(_as_constraints(np.vstack(mine)))
        return out

    def teach(self, demos: Sequence[dict[str, Any]]) -> None:
        """Show a whole curriculum, in order."""
        for d in demos:
            self.observe(d)

    def contains(self, w: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """Whether each learner's belief holds `w` (up to `tol` on the boundary)."""
        w = np.asarray(w, dtype=float)
        return np.array([bool(np.all(np.asarray(b, float) @ w >= -tol)) if len(b) else True
                         for b in self.beliefs])

    def belief_areas(self) -> np.ndarray:
        """Measure of each learner's belief on the sphere (estimated beyond 3 features)."""
        return self.belief_area_estimates()[0]

    def belief_area_estimates(self, n_samples: int = 20_000) -> tuple[np.ndarray, np.ndarray]:
        """Belief measures and their standard errors: exact (error 0) for 3 features, a
        seeded estimate with its standard error beyond (`Region.area_estimate`)."""
        if self.batch.F == 3:
            return np.array([self._region(b).area() for b in self.beliefs]), np.zeros(self.n)
        est = [self._region(b).area_estimate(n_samples, seed=0) for b in self.beliefs]
        return np.array([e[0] for e in est]), np.array([e[1] for e in est])

    # -- testing -----------------------------------------------------------------------
    def answer(self, tests: Sequence[dict[str, Any]], *, moves: bool = False
               ) -> dict[str, Any]:
        """Every learner plays every test. Returns `reward`, `finished`, `correct` (all
        `[n, len(tests)]`), `feature_counts` `[n, len(tests), F]` of the answers and
        `optimal_reward` `[len(tests)]`; with `moves`, also `actions[i][j]`: learner i's
        moves on test j (action names), drawn with the same random numbers."""
        out = self._play(tests, 1, moves=moves)
        for k in ("reward", "finished", "correct", "feature_counts"):
            out[k] = out[k][:, 0]
        return out

    def expected_correct(self, tests: Sequence[dict[str, Any]], draws: int = 64
                         ) -> np.ndarray:
        """Each learner's expected P(optimal) on `tests` `[n]` over `draws` plays of each
        (own weight sample each): what an observed score only samples, so the best any
        per-learner prediction can match. Consumes random numbers: call it last."""
        if draws < 1:
            raise ValueError(f"draws must be >= 1, got {draws}")
        if not tests:
            return np.full(self.n, np.nan)
        return self._play(tests, int(draws))["correct"].mean(axis=(1, 2))

    def _play(self, tests: Sequence[dict[str, Any]], m: int, *, moves: bool = False
              ) -> dict[str, Any]:
        """`m` plays of every test by every learner: `reward`, `finished`, `correct`
        `[n, m, T]`, `feature_counts` `[n, m, T, F]`, `optimal_reward` `[T]` and, with
        `moves` (m = 1 only), `actions`. With m = 1 the draws are those `answer` makes."""
        from cfteach.mdp import greedy_actions, rollout_from
        from cfteach.simulate.planning import policy_paths

        if moves and m != 1:
            raise ValueError("moves are recorded for one play per test only")
        T, nm = len(tests), self.n * m
        reward = np.zeros((nm, T))
        counts = np.zeros((nm, T, self.batch.F))
        finished = np.zeros((nm, T), dtype=bool)
        optimal = np.zeros(T)
        by_env: dict[int, list[int]] = {}
        paths: list[list[list[str]]] = [[[] for _ in range(T)] for _ in range(self.n)]
        starts = np.zeros(T, dtype=np.intp)
        for j, t in enumerate(tests):
            env = _env_of(self.domain, t)
            inst = self.batch.instances[env]
            starts[j] = self.batch.index_of(env, inst.state_from_json(t["start_state"]))
            by_env.setdefault(env, []).append(j)
        for env, js in by_env.items():
            q_star = self._optimal_q(env)
            v_star = q_star.max(axis=-1)
            for j in js:
                opt = tests[j].get("optimal_reward")
                optimal[j] = float(v_star[starts[j]]) if opt is None else float(opt)
            _, q, bounded = self._plan_samples(env, m, self.model.unbounded != "drop")
            st = np.broadcast_to(starts[js], (nm, len(js)))
            nxt, feats = self.batch.next_state[env], self.batch.features[env]
            max_steps = 4 * int(self.batch.n_states[env]) + 4
            record: list = []
            if self.model.temperature > 0:
                mu, fin, _ = boltzmann_rollouts(nxt, feats, q, st, self.model.temperature,
                                                self.rng, max_steps=max_steps,
                                                record=record if moves else None)
            else:
                policy = greedy_actions(q)
                ro = rollout_from(self.batch, policy, env, st, max_steps=max_steps,
                                  max_self_loops=None)
                mu, fin = ro.mu, ro.terminal
                if moves:
                    record.append(policy_paths(nxt, policy, st, max_steps=max_steps))
            if moves:
                for i in range(self.n):
                    for jj, j in enumerate(js):
                        acts = record[0][i, jj]
                        paths[i][j] = [self.batch.actions[int(a)] for a in acts[acts >= 0]]
            fin &= bounded[:, None]
            reward[:, js] = mu @ self.w_true
            counts[:, js] = mu
            finished[:, js] = fin
        correct = score_answers(reward, finished, optimal[None, :])
        out: dict[str, Any] = {"reward": reward.reshape(self.n, m, T),
                               "finished": finished.reshape(self.n, m, T),
                               "correct": correct.reshape(self.n, m, T),
                               "optimal_reward": optimal,
                               "feature_counts": counts.reshape(self.n, m, T, -1)}
        if moves:
            out["actions"] = paths
        return out


def _env_of(domain: Any, item: dict[str, Any]) -> int:
    """Instance index of a demonstration/test dict, checked against its env_code."""
    n = len(domain.instances())
    if "env_index" in item:
        env = int(item["env_index"])
    elif "env_code" in item:
        env = int("".join(str(int(b)) for b in item["env_code"]) or "0", 2)
    else:
        raise ValueError("demonstration/test lacks both 'env_index' and 'env_code'")
    if not 0 <= env < n:
        raise ValueError(f"env_index {env} out of range for domain {domain.name!r} ({n} instances)")
    if "env_code" in item and tuple(int(b) for b in item["env_code"]) != \
            tuple(domain.instances()[env].env_code):
        raise ValueError(f"env_code {item['env_code']} does not match env_index {env}")
    return env


def _action_index(actions: Sequence[str], name: str) -> int:
    try:
        return list(actions).index(name)
    except ValueError:
        raise ValueError(f"unknown action {name!r}; the domain's actions are "
                         f"{list(actions)}") from None
