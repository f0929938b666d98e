"""The closed-loop teacher: lessons, diagnostic tests and feedback, chosen one at a time from
a particle belief over the learner's reward weights.

    pool = build_pool("delivery", held_out=tests)        # once per domain
    teacher = ClosedLoopTeacher(pool, seed=0)
    while (item := teacher.next()) is not None:
        ...show item to the learner...
        teacher.observe(response)                        # {} after a demonstration/feedback,
                                                         # {"actions": [...]} after a test

The loop (docs/closed-loop.md):

1. A *lesson*: the counterfactual demonstration whose constraints would cut a share of the
   belief closest to ``zpd_proportion`` of the largest share any lesson would cut, inside the
   band ``zpd_band`` (the zone of proximal development: not what the learner already knows,
   not the most surprising).
2. A *diagnostic test* on what the lesson taught: the test whose chance of an optimal answer
   differs most between particles that absorbed the lesson and particles that did not.
3. A right answer moves on; a wrong one gets *feedback* (the learner's answer beside the
   optimal one, which the belief treats as a demonstration) and, while the belief still
   predicts a wrong answer on that test, a *remedial lesson* aimed at the particles that
   fail it.
4. Stop when the belief predicts optimal answers to the held-out tests with probability at
   least ``stop_threshold``, when no lesson would teach anything, or at ``max_items``.

The state is a pure function of (pool, settings, seed, responses): `replay` rebuilds it, so a
server can restore a session from its event log and a simulation can be re-run exactly.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from cfteach.closedloop.belief import ParticleBelief
from cfteach.closedloop.pool import LessonPool
from cfteach.mdp.scoring import optimal_mask
from cfteach.teaching.records import demo_json
from cfteach.teaching.visual import tie_break

KINDS = ("demonstration", "test", "feedback")


@dataclass(frozen=True)
class TeacherSettings:
    """How the closed-loop teacher models the learner and picks items."""

    n_particles: int = 1000
    p_learn: float = 0.8          # chance a shown demonstration is absorbed (belief model)
    temperature: float = 0.5      # Boltzmann temperature of test answers (belief model)
    zpd_proportion: float = 1.0   # target cut, as a share of the largest (paper's cf: 0.7)
    zpd_band: tuple[float, float] = (0.3, 1.0)  # admissible cuts, as shares of the largest
    min_gain: float = 0.02        # a lesson cutting less belief than this teaches nothing
    stop_threshold: float = 0.95  # predicted P(optimal) on held-out tests that ends teaching
    remedial_threshold: float = 0.8  # below this P(optimal) on a failed test: remedial lesson
    min_discrimination: float = 0.05  # a diagnostic test must split the particles this much
    max_items: int = 40           # demonstrations + tests + feedback

    def __post_init__(self) -> None:
        checks = [
            ("n_particles", isinstance(self.n_particles, int) and self.n_particles >= 10,
             "an integer >= 10"),
            ("p_learn", 0 < self.p_learn < 1, "in (0, 1)"),
            ("temperature", self.temperature > 0, "> 0"),
            ("zpd_proportion", 0 < self.zpd_proportion <= 1, "in (0, 1]"),
            ("zpd_band", len(self.zpd_band) == 2
             and 0 <= self.zpd_band[0] <= self.zpd_proportion <= self.zpd_band[1] <= 1,
             "(low, high) with 0 <= low <= zpd_proportion <= high <= 1"),
            ("min_gain", 0 <= self.min_gain < 1, "in [0, 1)"),
            ("stop_threshold", 0 < self.stop_threshold <= 1, "in (0, 1]"),
            ("remedial_threshold", 0 <= self.remedial_threshold <= 1, "in [0, 1]"),
            ("min_discrimination", 0 <= self.min_discrimination < 1, "in [0, 1)"),
            ("max_items", isinstance(self.max_items, int) and self.max_items >= 1,
             "an integer >= 1"),
        ]
        for name, ok, want in checks:
            if not ok:
                raise ValueError(f"closed-loop setting {name} must be {want}, "
                                 f"got {getattr(self, name)!r}")

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["zpd_band"] = list(self.zpd_band)
        return out


@dataclass(frozen=True)
class Item:
    """One step of the conversation.

    `kind`: ``demonstration`` (purpose ``lesson`` or ``remedial``), ``test`` (``diagnostic``)
    or ``feedback``. `demo`: the DemoSet index shown (for a test: its start; for feedback:
    the optimal answer from the failed test's start). `about`: for a diagnostic test the
    lesson's item index, for feedback and remedial lessons the failed test's item index.
    `answer`: for feedback, the learner's answer to that test (as observed).
    """

    index: int
    kind: str
    purpose: str
    demo: int
    about: int | None = None
    answer: dict[str, Any] | None = None
    predicted_optimal: float | None = None  # belief's P(optimal) for a test, when chosen
    gain: float | None = None               # share of the belief a lesson would cut

    def to_json(self, pool: LessonPool) -> dict[str, Any]:
        """What a learner (or the study page) is shown, plus the bookkeeping fields."""
        shown = demo_json(pool.ds, self.demo)
        if self.kind == "test":
            shown = {k: shown[k] for k in ("env_code", "env_index", "start_state")}
            shown["optimal_reward"] = pool.ds.reward(self.demo)
        out = {"index": self.index, "kind": self.kind, "purpose": self.purpose,
               "demo": self.demo, "about": self.about, **shown}
        if self.answer is not None:
            out["answer"] = self.answer
        if self.predicted_optimal is not None:
            out["predicted_optimal"] = self.predicted_optimal
        if self.gain is not None:
            out["gain"] = self.gain
        return out


@dataclass
class _Outcome:
    correct: bool
    finished: bool
    mu: np.ndarray


@dataclass(eq=False)
class ClosedLoopTeacher:
    """A closed-loop teaching session for one learner (module docstring)."""

    pool: LessonPool
    settings: TeacherSettings = field(default_factory=TeacherSettings)
    seed: int = 0

    def __post_init__(self) -> None:
        ds = self.pool.ds
        self.belief = ParticleBelief(np.asarray(self.pool.domain.prior).reshape(-1, ds.F),
                                     ds.F, n_particles=self.settings.n_particles,
                                     seed=self.seed, p_learn=self.settings.p_learn,
                                     temperature=self.settings.temperature)
        self.items: list[Item] = []
        self.responses: list[dict[str, Any]] = []
        self.outcomes: dict[int, _Outcome] = {}
        self.stop_reason: str | None = None
        self._pending: Item | None = None
        self._used_tests: set[int] = set()
        self._held = np.array(sorted(self.pool.held_out), dtype=np.int64)
        held_slots = self.pool.tests.slot[self._held] if len(self._held) else self._held
        self._held_slots = held_slots[held_slots >= 0]

    # -- the public loop -------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return self.stop_reason is not None

    def next(self) -> Item | None:
        """The item to show now (the same one until it is observed), or None when done."""
        if self._pending is not None or self.done:
            return self._pending
        if len(self.items) >= self.settings.max_items:
            self.stop_reason = "item budget reached"
            return None
        item = self._decide()
        if item is None:
            return None
        self._pending = item
        return item

    def observe(self, response: dict[str, Any] | None = None) -> None:
        """Record the learner's response to the pending item: nothing (or ``{}``) after a
        demonstration or feedback; ``{"actions": [...]}`` or ``{"feature_counts": [...],
        "finished": bool}`` after a test."""
        item = self._pending
        if item is None:
            raise RuntimeError("observe() without a pending item: call next() first")
        response = dict(response or {})
        ds = self.pool.ds
        if item.kind == "test":
            outcome = self._score(item.demo, response)
            self.belief.observe_answer(ds.mu[item.demo].astype(float), outcome.mu,
                                       self.pool.test_alternatives(item.demo),
                                       finished=outcome.finished, correct=outcome.correct)
            self.outcomes[item.index] = outcome
            self._used_tests.add(item.demo)
        elif item.kind == "feedback":
            rows = [self.pool.lesson_rows.of(item.demo)]
            wrong = self.outcomes[item.about]
            if wrong.finished:  # the optimal answer beats the learner's own
                rows.append((ds.mu[item.demo] - wrong.mu)[None])
            self.belief.observe_demonstration(np.vstack(rows).astype(float))
        else:
            self.belief.observe_demonstration(
                self.pool.lesson_rows.of(item.demo).astype(float))
        self.items.append(item)
        self.responses.append(response)
        self._pending = None

    @classmethod
    def replay(cls, pool: LessonPool, responses: list[dict[str, Any]], *,
               settings: TeacherSettings | None = None, seed: int = 0) -> ClosedLoopTeacher:
        """Rebuild a session from its responses (in order): the same items, the same belief."""
        t = cls(pool, settings or TeacherSettings(), seed)
        for k, r in enumerate(responses):
            if t.next() is None:
                raise ValueError(f"response {k} has no item: the session ended after {k} items")
            t.observe(r)
        return t

    # -- summaries -------------------------------------------------------------------------
    def predicted_held_out(self) -> float | None:
        """Belief's mean P(optimal) over the held-out tests (None without held-out tests)."""
        if not len(self._held):
            return None
        sat = self.pool.tests.satisfied(self.belief.particles)  # [K, P]
        p_set = sat.astype(float) @ self.belief.weights
        slots = self.pool.tests.slot[self._held]
        p = np.where(slots >= 0, p_set[np.maximum(slots, 0)], 1.0)
        return float(p.mean())

    def counts(self) -> dict[str, int]:
        """Items shown so far by kind."""
        out = dict.fromkeys(KINDS, 0)
        for it in self.items:
            out[it.kind] += 1
        return out

    def state_dict(self) -> dict[str, Any]:
        """Everything that defines the session (for equality checks and logs)."""
        return {"settings": self.settings.to_json(), "seed": self.seed,
                "items": [it.to_json(self.pool) for it in self.items],
                "responses": self.responses, "stop_reason": self.stop_reason,
                "pending": None if self._pending is None else self._pending.to_json(self.pool),
                "belief": self.belief.state_dict()}

    # -- decisions -------------------------------------------------------------------------
    def _rng(self) -> np.random.Generator:
        return np.random.default_rng([self.seed, 3, len(self.items)])

    def _decide(self) -> Item | None:
        last = self.items[-1] if self.items else None
        k = len(self.items)
        if last is not None and last.kind == "test" and not self.outcomes[last.index].correct:
            return Item(k, "feedback", "feedback", last.demo, about=last.index,
                        answer=self.responses[-1])
        if last is not None and last.kind == "demonstration":
            diag = self._diagnostic(last)
            if diag is not None:
                return diag
        failed = self._open_failure()
        if failed is None:
            p = self.predicted_held_out()
            if p is not None and p >= self.settings.stop_threshold:
                self.stop_reason = f"predicted P(optimal) on held-out tests {p:.3f}"
                return None
        lesson = self._lesson(failed)
        if lesson is None:
            self.stop_reason = "no lesson would cut the belief"
        return lesson

    def _open_failure(self) -> Item | None:
        """The last test, if it was failed and the belief still predicts a wrong answer."""
        tests = [it for it in self.items if it.kind == "test"]
        if not tests or self.outcomes[tests[-1].index].correct:
            return None
        t = tests[-1]
        if any(it.purpose == "remedial" and it.about == t.index for it in self.items):
            return None  # one remedial lesson per failed test; its diagnostic decides again
        rows = self.pool.test_rows.of(t.demo).astype(float)
        return t if self.belief.p_optimal(rows) < self.settings.remedial_threshold else None

    def _pick(self, slots: np.ndarray, shown: set[int]) -> int:
        """One demo among those of the given row sets: unseen first, then tie-break."""
        members = np.concatenate([self.pool.lessons.members[s] for s in slots.tolist()])
        fresh = [int(d) for d in members if int(d) not in shown]
        prev = next((it.demo for it in reversed(self.items) if it.kind == "demonstration"),
                    None)
        return tie_break(self.pool.ds, fresh or members.tolist(), prev, self._rng())

    def _lesson(self, failed: Item | None) -> Item | None:
        st = self.settings
        sat = self.pool.lessons.satisfied(self.belief.particles)  # [K, P]
        w = self.belief.weights
        if not sat.shape[0]:
            return None
        if failed is not None:  # aim at the particles that still fail the test
            fails = self._failing(failed.demo)
            mass = (~sat & fails[None]).astype(float) @ w
            if mass.max() > 0:
                best = np.flatnonzero(mass >= mass.max() - 1e-12)
                d = self._pick(best, self._shown())
                return Item(len(self.items), "demonstration", "remedial", d,
                            about=failed.index, gain=float((~sat[best[0]]).astype(float) @ w))
        gain = (~sat).astype(float) @ w
        top = gain.max()
        if top < st.min_gain:
            return None
        lo, hi = st.zpd_band
        inside = np.flatnonzero((gain >= max(lo * top, st.min_gain)) & (gain <= hi * top + 1e-12))
        target = st.zpd_proportion * top
        dist = np.abs(gain[inside] - target)
        best = inside[dist <= dist.min() + 1e-12]
        d = self._pick(best, self._shown())
        return Item(len(self.items), "demonstration", "lesson", d, gain=float(gain[best[0]]))

    def _failing(self, test_demo: int) -> np.ndarray:
        """bool [P]: particles under which test `test_demo` is not answered optimally."""
        rows = self.pool.test_rows.of(test_demo).astype(float)
        return ~np.all(rows @ self.belief.particles.T >= -1e-9, axis=0)

    def _shown(self) -> set[int]:
        return {it.demo for it in self.items if it.kind == "demonstration"}

    def _diagnostic(self, lesson: Item) -> Item | None:
        """The test that best tells particles that absorbed `lesson` from those that did not."""
        P = self.belief.particles
        w = self.belief.weights
        rows = self.pool.lesson_rows.of(lesson.demo).astype(float)
        absorbed = np.all(rows @ P.T >= -1e-9, axis=0) if len(rows) else np.ones(len(P), bool)
        m_in, m_out = float(w[absorbed].sum()), float(w[~absorbed].sum())
        if m_in <= 0 or m_out <= 0:
            return None
        sat = self.pool.tests.satisfied(P).astype(float)  # [K, P]
        p_in = sat[:, absorbed] @ w[absorbed] / m_in
        p_out = sat[:, ~absorbed] @ w[~absorbed] / m_out
        score = p_in - p_out
        usable = np.zeros(self.pool.tests.n_sets, dtype=bool)
        # never a held-out test, a test already given, or a start already demonstrated
        blocked = self.pool.held_out | self._used_tests | self._shown()
        for k, members in enumerate(self.pool.tests.members):
            usable[k] = any(int(d) not in blocked for d in members)
        score = np.where(usable, score, -np.inf)
        if not np.isfinite(score).any() or score.max() < self.settings.min_discrimination:
            return None
        best = np.flatnonzero(score >= score.max() - 1e-12)
        cands = [int(d) for k in best.tolist() for d in self.pool.tests.members[k]
                 if int(d) not in blocked]
        d = tie_break(self.pool.ds, cands, lesson.demo, self._rng())
        p_opt = float(sat[self.pool.tests.slot[d]] @ w)
        return Item(len(self.items), "test", "diagnostic", d, about=lesson.index,
                    predicted_optimal=p_opt)

    # -- scoring ---------------------------------------------------------------------------
    def _score(self, d: int, response: dict[str, Any]) -> _Outcome:
        """Replay a test answer from the test's start and score it as the study does (M1)."""
        ds = self.pool.ds
        b = ds.batch
        e = int(ds.env[d])
        if "actions" in response:
            s = int(ds.start[d])
            mu = np.zeros(ds.F)
            for t, name in enumerate(response["actions"]):
                if name not in b.actions:
                    raise ValueError(f"test answer: unknown action {name!r} at step {t} "
                                     f"(actions: {', '.join(b.actions)})")
                if s == b.sink:
                    raise ValueError(f"test answer continues after the end (step {t})")
                a = b.actions.index(name)
                mu += b.features[e, s, a]
                s = int(b.next_state[e, s, a])
            finished = s == b.sink
        elif "feature_counts" in response:
            mu = np.asarray(response["feature_counts"], dtype=float)
            if mu.shape != (ds.F,):
                raise ValueError(f"test answer: feature_counts needs {ds.F} numbers, "
                                 f"got {response['feature_counts']!r}")
            finished = bool(response.get("finished", True))
        else:
            raise ValueError("a test answer needs 'actions' or 'feature_counts'")
        reward = float(ds.weights @ mu)
        correct = bool(optimal_mask(reward, ds.reward(d), finished))
        return _Outcome(correct, finished, mu)
