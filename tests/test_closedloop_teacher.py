"""The closed-loop teacher: its loop, replay from responses, seeds, and simulated learners."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach import teaching
from cfteach.closedloop import ClosedLoopTeacher, TeacherSettings, build_pool
from cfteach.domains import load
from cfteach.simulate.closed_loop import equal_budget_demos, run_session
from cfteach.simulate.learners import Learners

DOMAIN = "skateboard"
SMALL = TeacherSettings(n_particles=300, max_items=14)


@pytest.fixture(scope="module")
def material():
    cur = teaching.teach(DOMAIN, "proposed")
    tests = teaching.select_tests(DOMAIN, training=[cur], per_level=3)
    return cur, tests, build_pool(DOMAIN, human_models=16, held_out=tests)


def _same(a, b) -> bool:
    """Deep equality of nested dicts / lists / arrays (bit-identical arrays)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k])
                                                                   for k in a)
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b))
    return a == b


def _session(pool, seed: int, learner_seed: int, model: str = "inattentive"):
    teacher = ClosedLoopTeacher(pool, SMALL, seed=seed)
    learners = Learners(pool.domain, model, 1, rng=learner_seed)
    run_session(teacher, learners)
    return teacher, learners


def test_replaying_responses_restores_the_same_state(material):
    _, _, pool = material
    teacher, _ = _session(pool, seed=3, learner_seed=11)
    assert len(teacher.responses) >= 3
    again = ClosedLoopTeacher.replay(pool, teacher.responses, settings=SMALL, seed=3)
    a, b = teacher.state_dict(), again.state_dict()
    assert a["items"] == b["items"]
    assert a["responses"] == b["responses"]
    assert _same(a["belief"], b["belief"])
    # and half-way: the next item after a partial replay is the one the session showed
    k = len(teacher.responses) // 2
    half = ClosedLoopTeacher.replay(pool, teacher.responses[:k], settings=SMALL, seed=3)
    assert half.next().to_json(pool) == teacher.items[k].to_json(pool)


def test_same_seed_same_items_and_next_is_idempotent(material):
    _, _, pool = material
    t1, _ = _session(pool, seed=5, learner_seed=2)
    t2, _ = _session(pool, seed=5, learner_seed=2)
    assert [it.to_json(pool) for it in t1.items] == [it.to_json(pool) for it in t2.items]
    fresh = ClosedLoopTeacher(pool, SMALL, seed=5)
    assert fresh.next() is fresh.next()


def test_loop_structure(material):
    _, _, pool = material
    for learner_seed in range(4):
        teacher, _ = _session(pool, seed=learner_seed, learner_seed=100 + learner_seed)
        items = teacher.items
        assert items[0].kind == "demonstration" and items[0].purpose == "lesson"
        assert len(items) <= SMALL.max_items
        shown = set()
        for k, it in enumerate(items):
            if it.kind == "test":
                # never a held-out test, never a start state already demonstrated
                assert it.demo not in pool.held_out
                assert it.demo not in shown
                # a diagnostic test is about a lesson; a check test (at least every
                # test_every items) about the last demonstration, if any
                assert it.about is None or items[it.about].kind == "demonstration"
                assert it.purpose in ("diagnostic", "check")
                wrong = not teacher.outcomes[k].correct
                follow = items[k + 1] if k + 1 < len(items) else None
                if wrong and follow is not None:
                    assert follow.kind == "feedback" and follow.about == k
                if not wrong and follow is not None:
                    assert follow.kind != "feedback"
            if it.kind == "demonstration":
                shown.add(it.demo)
            if it.purpose == "remedial":
                assert items[k - 1].kind == "feedback"
        assert teacher.done == (teacher.next() is None)


def test_wrong_answer_gets_feedback_and_then_a_remedial_lesson(material):
    _, _, pool = material
    teacher = ClosedLoopTeacher(pool, SMALL, seed=1)
    while (item := teacher.next()).kind != "test":
        teacher.observe({})
    # an answer that never finishes: certainly wrong
    teacher.observe({"actions": []})
    fb = teacher.next()
    assert fb.kind == "feedback" and fb.demo == item.demo and fb.answer == {"actions": []}
    before = teacher.belief.p_optimal(pool.test_rows.of(item.demo).astype(float))
    teacher.observe({})
    after = teacher.belief.p_optimal(pool.test_rows.of(item.demo).astype(float))
    assert after > before  # feedback counts as a demonstration of the optimal answer
    nxt = teacher.next()
    assert nxt.kind == "demonstration"
    if after < SMALL.remedial_threshold:
        assert nxt.purpose == "remedial" and nxt.about == item.index


def test_feedback_is_chosen_before_the_failed_answers_update(material):
    """A failed answer's feedback needs no belief, so `next()` returns it without the
    answer's update (the costly part of a decision: a server shows feedback at once); the
    update runs when the belief is next read, and the session is bit-identical to one whose
    belief was read (updated) after every response."""
    _, _, pool = material
    lazy, eager = (ClosedLoopTeacher(pool, SMALL, seed=2) for _ in range(2))
    deferred = 0
    while (item := lazy.next()) is not None:
        assert eager.next().to_json(pool) == item.to_json(pool)
        response = {"actions": []} if item.kind == "test" else {}  # every test failed
        seen = len(lazy.as_chosen[1].history)
        lazy.observe(response)
        eager.observe(response)
        eager.belief.history  # noqa: B018 - reading the belief folds the answer in
        if item.kind == "test" and len(lazy.items) < SMALL.max_items:
            feedback = lazy.next()
            assert feedback is not None and feedback.kind == "feedback"
            assert len(lazy.as_chosen[1].history) == seen  # not updated yet
            deferred += 1
    assert deferred >= 2 and eager.next() is None
    a, b = lazy.state_dict(), eager.state_dict()
    assert a["items"] == b["items"] and a["stop_reason"] == b["stop_reason"]
    assert _same(a["belief"], b["belief"]) and a["progress"] == b["progress"]
    # a failed test moves the progress bar one item's share: no jump, never backwards
    steps = np.diff(a["progress"])
    assert np.all(steps > 0)


def test_optimal_answer_is_scored_correct(material):
    _, _, pool = material
    teacher = ClosedLoopTeacher(pool, SMALL, seed=1)
    while (item := teacher.next()).kind != "test":
        teacher.observe({})
    teacher.observe({"actions": pool.ds.action_names(item.demo)})
    assert teacher.outcomes[item.index].correct
    assert teacher.next().kind == "demonstration"


def test_bad_responses_and_settings_are_named(material):
    _, _, pool = material
    teacher = ClosedLoopTeacher(pool, SMALL, seed=1)
    with pytest.raises(RuntimeError, match="next"):
        teacher.observe({})
    while teacher.next().kind != "test":
        teacher.observe({})
    with pytest.raises(ValueError, match="unknown action 'jump'"):
        teacher.observe({"actions": ["jump"]})
    with pytest.raises(ValueError, match="feature_counts"):
        teacher.observe({"feature_counts": [1, 2]})
    with pytest.raises(ValueError, match="p_learn"):
        TeacherSettings(p_learn=1.0)
    with pytest.raises(ValueError, match="zpd_band"):
        TeacherSettings(zpd_band=(0.8, 0.9))
    done, _ = _session(pool, seed=2, learner_seed=5)
    with pytest.raises(ValueError, match="ended"):
        ClosedLoopTeacher.replay(pool, [*done.responses, {}], settings=SMALL, seed=2)


def test_noiseless_learners_end_with_w_star_in_their_belief(material):
    _, _, pool = material
    for s in range(3):
        _, learners = _session(pool, seed=s, learner_seed=40 + s, model="counterfactual")
        assert learners.contains(pool.domain.weights).all()


def test_inattentive_learner_absorbs_about_half():
    cur = teaching.teach(DOMAIN, "proposed")
    demo = cur.to_json()["demos"][0]
    n = 400
    dom = load(DOMAIN)
    learners = Learners(dom, "inattentive", n, rng=0)
    before = [b.copy() for b in learners.beliefs]
    learners.observe(demo)
    changed = np.array([not np.array_equal(a, b) for a, b in zip(before, learners.beliefs,
                                                                   strict=True)])
    # Binomial(400, 0.5) (minus the few learners whose counterfactuals add nothing)
    assert 0.40 < changed.mean() < 0.56
    # p_absorb = 1 is exactly the paper's counterfactual learner
    a = Learners(dom, "inattentive:p_absorb=1", 6, rng=9)
    b = Learners(dom, "counterfactual", 6, rng=9)
    for d in cur.to_json()["demos"]:
        a.observe(d)
        b.observe(d)
    for x, y in zip(a.beliefs, b.beliefs, strict=True):
        np.testing.assert_array_equal(x, y)


def test_equal_budget_repeats_the_curriculum_from_the_start():
    cur = {"demos": [{"n": 0}, {"n": 1}, {"n": 2}]}
    assert [d["n"] for d in equal_budget_demos(cur, 7)] == [0, 1, 2, 0, 1, 2, 0]
    assert [d["n"] for d in equal_budget_demos(cur, 2)] == [0, 1]
    assert equal_budget_demos({"demos": []}, 4) == []


def test_probe_tests_are_the_probes_never_a_held_out_test(material):
    """The tests a simulation measures learners on are exactly the teacher's probes: their
    starts are the probes' starts, none is a post-test's, and their optimal reward equals
    the robot's value at that start from value iteration (an independent computation)."""
    from cfteach.closedloop.items import demo_json
    from cfteach.closedloop.probes import probe_demos, probe_tests

    _, tests, pool = material
    n = TeacherSettings().n_probes
    demos, shown = probe_demos(pool, n), probe_tests(pool, n)
    assert len(shown) == len(demos) > 0
    held = {(demo_json(pool.ds, d)["env_index"], json_key(demo_json(pool.ds, d)["start_state"]))
            for d in pool.held_out}
    for d, t in zip(demos.tolist(), shown, strict=True):
        ref = demo_json(pool.ds, d)
        assert t["env_index"] == ref["env_index"] and t["start_state"] == ref["start_state"]
        assert (t["env_index"], json_key(t["start_state"])) not in held
    learner = Learners(load(DOMAIN), "counterfactual", 1, rng=np.random.default_rng(0))
    unscored = [{k: v for k, v in t.items() if k != "optimal_reward"} for t in shown]
    np.testing.assert_allclose(learner.answer(unscored)["optimal_reward"],
                               [t["optimal_reward"] for t in shown], atol=1e-9)


def json_key(state) -> str:
    import json

    return json.dumps(state, sort_keys=True)
