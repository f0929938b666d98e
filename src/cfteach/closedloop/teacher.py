"""The closed-loop teacher: lessons, diagnostic tests and feedback, chosen one at a time from
a particle belief over the learner's reward weights (and, by default, their rationality and
uptake: `cfteach.closedloop.noisy_belief`).

    pool = build_pool("delivery", held_out=tests)        # once per domain
    teacher = ClosedLoopTeacher(pool, seed=0)
    while (item := teacher.next()) is not None:
        ...show item to the learner...
        teacher.observe(response)                        # {} after a demonstration/feedback,
                                                         # {"actions": [...]} after a test

The loop (docs/closed-loop.md):

1. A *lesson*: the counterfactual demonstration whose constraints would cut a share of the
   belief closest to ``zpd_proportion`` of the largest share any lesson would cut, inside the
   band ``zpd_band``; never from a post-test's or a probe's start, never the same one more
   than ``max_repeat`` times in a row.
2. A *diagnostic test* on what the lesson taught: the test whose chance of an optimal answer
   differs most between particles that absorbed the lesson and particles that did not.
3. A right answer moves on; a wrong one gets *feedback* (the learner's answer beside the
   optimal one, which the belief treats as a demonstration; chosen at once, the answer's
   update waits until something reads the belief: `_settle`) and, while the belief still
   predicts a wrong answer on that test, a *remedial lesson* aimed at the particles that
   fail it.
4. After the first test, a test at least every ``test_every`` items; when no lesson would
   cut the belief, a test, or stop.
5. Stop, after ``min_passes`` passed tests in a row, when the belief's mass inside the
   regions of the teacher's own probe tests reaches ``stop_threshold`` (never the
   post-tests), or at ``max_items``.

The state is a pure function of (pool, settings, seed, responses): `replay` rebuilds it, so a
server can restore a session from its event log and a simulation can be re-run exactly.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cfteach.closedloop import backbone, probes
from cfteach.closedloop.belief import ParticleBelief
from cfteach.closedloop.items import KINDS, Item, Outcome, score_answer
from cfteach.closedloop.noisy_belief import NoisyBelief
from cfteach.closedloop.pool import LessonPool
from cfteach.closedloop.settings import TeacherSettings
from cfteach.closedloop.steps import answer_steps, path_steps
from cfteach.teaching.visual import tie_break

__all__ = ["ClosedLoopTeacher", "Item", "TeacherSettings"]

class ClosedLoopTeacher:
    """A closed-loop teaching session for one learner (module docstring)."""

    def __init__(self, pool: LessonPool, settings: TeacherSettings | None = None,
                 seed: int = 0) -> None:
        self._unsettled: tuple[int, Outcome, int] | None = None  # a test answer not in yet
        self._pool, self.settings, self.seed = pool, settings or TeacherSettings(), seed
        ds = self.pool.ds
        st = self.settings
        prior = np.asarray(self.pool.domain.prior).reshape(-1, ds.F)
        if st.model == "noisy":
            self._belief: ParticleBelief = NoisyBelief(
                prior, ds.F, n_particles=st.n_particles, seed=self.seed,
                rationality=st.rationality, uptake=st.uptake, disengaged=st.disengaged,
                confused=st.confused, confusion=st.confusion, lapse=st.lapse)
        else:
            self._belief = ParticleBelief(prior, ds.F, n_particles=st.n_particles,
                                          seed=self.seed, p_learn=st.p_learn,
                                          temperature=st.temperature)
        self.items: list[Item] = []
        self.responses: list[dict[str, Any]] = []
        self.outcomes: dict[int, Outcome] = {}
        self.stop_reason: str | None = None
        self._pending: Item | None = None
        self._used_tests: set[int] = set()
        self._probes = probes.probe_demos(self.pool, st.n_probes, st.probes)
        self._no_lesson = probes.lesson_blocked(self.pool, st.n_probes, st.probes)
        self._usable_lessons = self._lessons_allowed()
        self._backbone = backbone.lessons(self.pool, self._no_lesson)
        self._progress = [0.0]
        self._prediction_memo: tuple[Any, dict[str, float | None]] = (None, {})

    # -- the public loop -------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return self.stop_reason is not None

    @property
    def belief(self) -> ParticleBelief:
        """The belief after every response so far (a deferred answer folded in first)."""
        self._settle()
        return self._belief

    @belief.setter
    def belief(self, value: ParticleBelief) -> None:
        self._settle()
        self._belief = value

    @property
    def pool(self) -> LessonPool:
        """The pool with the human models drawn from the belief so far (`_draw_models`)."""
        self._settle()
        return self._pool

    @property
    def as_chosen(self) -> tuple[LessonPool, ParticleBelief]:
        """The pool and belief the pending item was chosen with (feedback: before `_settle`)."""
        return self._pool, self._belief

    def next(self) -> Item | None:
        """The item to show now (the same one until it is observed), or None when done."""
        if self._pending is not None or self.done:
            return self._pending
        if len(self.items) >= self.settings.max_items:
            self._settle()
            self.stop_reason = "item budget reached"
            return None
        item = self._feedback() or self._decide()
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
        self._settle()
        response = dict(response or {})
        ds = self.pool.ds
        if item.kind == "test":
            outcome = score_answer(self.pool, item.demo, response)
            self.outcomes[item.index] = outcome
            self._used_tests.add(item.demo)
            self._unsettled = (item.demo, outcome, len(self.items))
        elif item.kind == "feedback":
            rows = [self.pool.lesson_rows.of(item.demo)]
            assert item.about is not None  # feedback is always about a test
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
        if self._unsettled is None:
            self._progress.append(self._next_progress())
        elif not self._unsettled[1].correct:  # nothing learnt: one item's share, no jump
            self._progress.append(self._step_progress())

    def _settle(self) -> None:
        """Fold a deferred test answer into the belief. A failed answer's feedback needs no
        belief, so the update (a decision's costly part) waits until something reads the
        belief: a server shows the feedback at once. Same operations, same order, same result."""
        if self._unsettled is None:
            return
        (demo, outcome, k), self._unsettled = self._unsettled, None
        self._observe_answer(demo, outcome)
        self._draw_models(k)
        if outcome.correct:
            self._progress.append(self._next_progress())

    def _feedback(self) -> Item | None:
        """Feedback after a failed test (it needs no belief: `_settle`)."""
        last = self.items[-1] if self.items else None
        if last is None or last.kind != "test" or self.outcomes[last.index].correct:
            return None
        return Item(len(self.items), "feedback", "feedback", last.demo, about=last.index,
                    answer=self.responses[-1])

    def _draw_models(self, k: int) -> None:
        """After a test answer, `belief_models` weighted particles join this session's pool
        as human models, so lessons and tests reach the plans of learners like this one
        (docs/closed-loop.md, "Human models from the belief"). Seeded by the test's index."""
        n, w = self.settings.belief_models, self._belief.weights
        live = np.flatnonzero(w > 0) if n > 0 else ()
        if not len(live):
            return
        rng = np.random.default_rng([self.seed, 5, k])
        pick = rng.choice(live, size=min(n, len(live)), replace=False,
                          p=w[live] / w[live].sum())
        probes.probe_paths(self.pool, self.settings.n_probes, self.settings.probes)  # pre-growth
        self._pool = self._pool.with_models(self._belief.particles[np.sort(pick)])
        self._usable_lessons = self._lessons_allowed()

    def _lessons_allowed(self) -> np.ndarray:
        """bool per lesson row set: a member is not a post-test's or a probe's start."""
        return np.array([any(int(d) not in self._no_lesson for d in m)
                         for m in self.pool.lessons.members], dtype=bool)

    def _observe_answer(self, d: int, outcome: Outcome) -> None:
        ds, belief = self.pool.ds, self._belief
        if isinstance(belief, NoisyBelief):
            if outcome.actions is not None and outcome.states is not None:
                belief.observe_steps(answer_steps(ds, int(ds.env[d]), outcome.states,
                                                  outcome.actions, outcome.finished))
            else:
                data, _ = path_steps(ds, [d])
                belief.observe_outcome(data, self.pool.test_rows.of(d).astype(float),
                                       outcome.correct)
            return
        belief.observe_answer(ds.mu[d].astype(float), outcome.mu,
                              self.pool.test_alternatives(d),
                              finished=outcome.finished, correct=outcome.correct)

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
        """Belief mass inside the held-out tests' regions, averaged over them (None without
        held-out tests; the study exports it). For analysis only: no decision reads it."""
        return self.pool.held_out_mass(self.belief.particles, self.belief.weights)

    def prediction(self) -> dict[str, float | None]:
        """The belief's mean P(optimal) on the teacher's probes (`predicted`, with the
        learner's noise) and the mass whose weights answer them optimally (`knowledge`)."""
        if not len(self._probes):
            return {"predicted": None, "knowledge": None}
        key = (len(self.belief.history), self.belief.n_resamples)
        if self._prediction_memo[0] != key:
            p, k = self._predict(self._probes)
            self._prediction_memo = (key, {"predicted": float(p.mean()),
                                           "knowledge": float(k.mean())})
        return dict(self._prediction_memo[1])

    def knowledge(self) -> float | None:
        """The belief's mass inside the probes' regions (mean over probes): what teaching
        can still change. Cheaper than `prediction` (no per-step policy)."""
        if not len(self._probes):
            return None
        sat = probes.region_sat(self.pool, self._probes, self.belief.particles)
        return float((self.belief.weights @ sat.astype(float)).mean())

    def _predict(self, demos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per test: P(optimal answer) and the belief mass inside its region."""
        sat = probes.region_sat(self.pool, demos, self.belief.particles)
        know = self.belief.weights @ sat.astype(float)
        if not isinstance(self.belief, NoisyBelief):
            return know, know
        if np.array_equal(demos, self._probes):
            data, starts = probes.probe_paths(self.pool, self.settings.n_probes,
                                              self.settings.probes)
        else:
            data, starts = path_steps(self.pool.ds, demos.tolist())
        return self.belief.predicted(sat, data, starts), know

    def progress(self) -> float:
        """Share of the session done, for a progress bar: grows with every item (towards
        1 at `max_items`), jumping ahead as the probes' knowledge nears the stop (not on a
        failed test: `_settle`); 1 when done. A function of the items and the beliefs."""
        if self._unsettled is not None and self._unsettled[1].correct:
            self._settle()
        return 1.0 if self.done else self._progress[-1]

    def _step_progress(self) -> float:
        """The progress after one more item, knowledge aside: an equal share of what is left."""
        prev = self._progress[-1]
        left = max(self.settings.max_items - len(self.items) + 1, 1)
        return prev + (1.0 - prev) / left

    def _next_progress(self) -> float:
        know = self.knowledge()
        ahead = 0.0 if know is None else min(0.95, know / self.settings.stop_threshold)
        return float(min(1.0, max(self._step_progress(), ahead)))

    def counts(self) -> dict[str, int]:
        """Items shown so far by kind."""
        return {kind: sum(it.kind == kind for it in self.items) for kind in KINDS}

    def state_dict(self) -> dict[str, Any]:
        """Everything that defines the session (for equality checks and logs)."""
        return {"settings": self.settings.to_json(), "seed": self.seed,
                "items": [it.to_json(self.pool) for it in self.items],
                "responses": self.responses, "stop_reason": self.stop_reason,
                "pending": None if self._pending is None else self._pending.to_json(self.pool),
                "progress": list(self._progress),
                "belief": self.belief.state_dict()}

    # -- decisions -------------------------------------------------------------------------
    def _rng(self) -> np.random.Generator:
        return np.random.default_rng([self.seed, 3, len(self.items)])

    def _since_test(self) -> int | None:
        """Items shown since the last test (None before the first test)."""
        return next((b for b, it in enumerate(reversed(self.items)) if it.kind == "test"), None)

    def _decide(self) -> Item | None:
        """The next item but feedback (docs/closed-loop.md, "The conversation"): a
        diagnostic test after a lesson; a test at least every `test_every` items
        after the first; else stop when the probes say so, or a lesson; when no lesson
        would cut the belief, a test, or stop. Never the same lesson more than
        `max_repeat` times in a row."""
        st = self.settings
        self._settle()
        last = self.items[-1] if self.items else None
        if last is not None and last.kind == "demonstration":
            diag = self._diagnostic(last)
            if diag is not None:
                return diag
        since = self._since_test()
        if since is not None and since >= st.test_every:
            check = self._check_test()
            if check is not None:
                return check
            self.stop_reason = "no diagnostic test left"
            return None
        backbone_item = backbone.next_lesson(self.items, self._backbone,
                                            self._blocked_lessons())
        if backbone_item is None and self._passes_in_a_row() >= st.min_passes:
            know = self.knowledge()
            if know is not None and know >= st.stop_threshold:
                self.stop_reason = f"knowledge on the probes {know:.3f}"
                return None
        failed = self._open_failure()
        if failed is not None and not backbone.may_remediate(self.items, self._backbone,
                                                             failed, st.max_items):
            failed = None  # the backbone's remaining lessons come first
        lesson = self._remedial(failed) if failed is not None else None
        lesson = lesson or backbone_item or self._lesson()
        if lesson is not None:
            return lesson
        if last is None or last.kind != "test":
            check = self._check_test()
            if check is not None:
                return check
        self.stop_reason = "no lesson would cut the belief"
        return None

    def _passes_in_a_row(self) -> int:
        """Tests passed since the last failed one and the last backbone lesson: the
        backbone's own diagnostics do not end a session (the teacher checks on fresh tests
        once it is covered)."""
        n = 0
        for it in reversed(self.items):
            if it.purpose == "backbone":
                break
            if it.kind == "test":
                if not self.outcomes[it.index].correct:
                    break
                n += 1
        return n

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

    def _blocked_lessons(self) -> set[int]:
        """Demos not to show now: held-out and probe starts, and a demonstration already
        shown `max_repeat` times in a row."""
        demos = [it.demo for it in self.items if it.kind == "demonstration"]
        r = self.settings.max_repeat
        out = set(self._no_lesson)
        if len(demos) >= r and len(set(demos[-r:])) == 1:
            out.add(demos[-1])
        return out

    def _pick(self, slots: np.ndarray, blocked: set[int]) -> int:
        """One demo among those of the given row sets: unseen first, then tie-break."""
        members = [int(d) for s in slots.tolist() for d in self.pool.lessons.members[s]
                   if int(d) not in blocked]
        shown = self._shown()
        fresh = [d for d in members if d not in shown]
        prev = next((it.demo for it in reversed(self.items) if it.kind == "demonstration"),
                    None)
        return tie_break(self.pool.ds, fresh or members, prev, self._rng())

    def _usable(self, blocked: set[int]) -> np.ndarray:
        """bool per lesson row set: it has a member that may be shown now."""
        usable = self._usable_lessons.copy()
        for d in blocked - self._no_lesson:  # a repeated demo's set, if it has no other
            s = int(self.pool.lessons.slot[d])
            if s >= 0 and all(int(m) in blocked for m in self.pool.lessons.members[s]):
                usable[s] = False
        return usable

    def _candidates(self) -> tuple[set[int], np.ndarray, np.ndarray, np.ndarray] | None:
        """What a lesson choice starts from: the blocked demonstrations, which lesson sets
        may be shown, which particles satisfy each set ``[K, P]`` and the belief's weights
        (None when no lesson may be shown)."""
        if not self.pool.lessons.n_sets:
            return None
        blocked = self._blocked_lessons()
        usable = self._usable(blocked)
        if not usable.any():
            return None
        return (blocked, usable, self.pool.lessons.satisfied(self.belief.particles),
                self.belief.weights)

    def _remedial(self, failed: Item) -> Item | None:
        """A lesson aimed at the particles that still fail test `failed`."""
        if (cand := self._candidates()) is None:
            return None
        blocked, usable, sat, w = cand
        fails = self._failing(failed.demo)
        mass = np.where(usable, (~sat & fails[None]).astype(float) @ w, -1.0)
        if mass.max() <= self.settings.min_gain:
            return None
        best = np.flatnonzero(mass >= mass.max() - 1e-12)
        d = self._pick(best, blocked)
        return Item(len(self.items), "demonstration", "remedial", d,
                    about=failed.index, gain=float((~sat[best[0]]).astype(float) @ w))

    def _lesson(self) -> Item | None:
        st = self.settings
        if (cand := self._candidates()) is None:
            return None
        blocked, usable, sat, w = cand
        gain = np.where(usable, (~sat).astype(float) @ w, -1.0)
        top = gain.max()
        if top < st.min_gain:
            return None
        lo, hi = st.zpd_band
        inside = np.flatnonzero((gain >= max(lo * top, st.min_gain)) & (gain <= hi * top + 1e-12))
        target = st.zpd_proportion * top
        dist = np.abs(gain[inside] - target)
        best = inside[dist <= dist.min() + 1e-12]
        d = self._pick(best, blocked)
        return Item(len(self.items), "demonstration", "lesson", d, gain=float(gain[best[0]]))

    def _failing(self, test_demo: int) -> np.ndarray:
        """bool [P]: particles under which test `test_demo` is not answered optimally."""
        rows = self.pool.test_rows.of(test_demo).astype(float)
        return ~np.all(rows @ self.belief.particles.T >= -1e-9, axis=0)

    def _shown(self) -> set[int]:
        return {it.demo for it in self.items if it.kind == "demonstration"}

    def _test_usable(self) -> np.ndarray:
        """bool per test row set: it has a member that may be given as a test now (never a
        held-out test, a probe, a test already given, or a start already demonstrated)."""
        blocked = self._test_blocked()
        return np.array([any(int(d) not in blocked for d in m)
                         for m in self.pool.tests.members], dtype=bool)

    def _test_blocked(self) -> set[int]:
        return (set(self.pool.held_out) | set(self._probes.tolist()) | self._used_tests
                | self._shown())

    def _test_item(self, best: np.ndarray, about: int | None, purpose: str,
                   prev: int | None) -> Item:
        blocked = self._test_blocked()
        cands = [int(d) for k in best.tolist() for d in self.pool.tests.members[k]
                 if int(d) not in blocked]
        d = tie_break(self.pool.ds, cands, prev, self._rng())
        p_opt = float(self._predict(np.array([d]))[0][0])
        return Item(len(self.items), "test", purpose, d, about=about, predicted_optimal=p_opt)

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
        score = np.where(self._test_usable(), p_in - p_out, -np.inf)
        if not np.isfinite(score).any() or score.max() < self.settings.min_discrimination:
            return None
        best = np.flatnonzero(score >= score.max() - 1e-12)
        return self._test_item(best, lesson.index, "diagnostic", lesson.demo)

    def _check_test(self) -> Item | None:
        """A test whose outcome the belief is least sure of (P(optimal) closest to 1/2):
        the regular check between lessons, and the step after a lesson that cut nothing."""
        usable = self._test_usable()
        if not usable.any():
            return None
        p = self.pool.tests.satisfied(self.belief.particles).astype(float) @ self.belief.weights
        score = np.where(usable, p * (1 - p), -np.inf)
        best = np.flatnonzero(score >= score.max() - 1e-12)
        last = next((it for it in reversed(self.items) if it.kind == "demonstration"), None)
        return self._test_item(best, None if last is None else last.index, "check",
                               None if last is None else last.demo)
