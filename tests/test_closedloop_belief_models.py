"""Human models drawn from the learner's belief (`TeacherSettings.belief_models`): the pool
they extend is checked against value iteration, and a session drawing them replays and
stays as it was with the setting off."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from cfteach.closedloop import ClosedLoopTeacher, TeacherSettings, build_pool
from cfteach.mdp import value_iteration
from cfteach.simulate.learners import Learners

TOL = 1e-6


@pytest.fixture(scope="module")
def pool():
    return build_pool("skateboard", human_models=4, seed=3)


def _rules_out(rows, w: np.ndarray) -> bool:
    return bool(len(rows)) and bool((rows.astype(float) @ w < -TOL).any())


def test_added_models_rule_out_exactly_the_demos_they_would_not_have_chosen(pool) -> None:
    """For a model w, a demo's rows hold one that w breaks iff the demo is worse, under w,
    than w's own best plan from the same start (value iteration): the added model's plans
    make every demo w disagrees with say so, and none other."""
    rng = np.random.default_rng(8)
    W = rng.normal(size=(3, pool.F))
    W /= np.linalg.norm(W, axis=1, keepdims=True)
    ds = pool.ds
    vals = value_iteration(ds.batch, W, method="exact")
    grown = pool.with_models(W)
    assert grown.human_models.shape == (len(pool.human_models) + 3, pool.F)
    assert grown.lessons.n_sets >= pool.lessons.n_sets
    checked = missed_before = 0
    for m, w in enumerate(W):
        for d in range(ds.D):
            e = int(ds.env[d])
            if not vals.bounded[e, m]:
                continue
            worse = float(vals.V[e, m, int(ds.start[d])]) > float(ds.mu[d] @ w) + TOL
            assert _rules_out(grown.lesson_rows.of(d), w) == worse, (m, d)
            assert _rules_out(grown.test_rows.of(d), w) == worse, (m, d)
            checked += 1
            missed_before += worse and not _rules_out(pool.lesson_rows.of(d), w)
    assert checked > 1000
    assert missed_before > 0  # the prior's four models alone miss some of them


def test_the_grown_pool_keeps_every_row_it_had_and_what_it_holds_fixed(pool) -> None:
    grown = pool.with_models(np.eye(pool.F)[:1])
    for d in range(0, pool.ds.D, 7):
        old = {tuple(r) for r in pool.lesson_rows.of(d).tolist()}
        assert old <= {tuple(r) for r in grown.lesson_rows.of(d).tolist()}
    assert grown.held_out == pool.held_out and grown.backbone == pool.backbone
    assert pool.with_models(np.zeros((0, pool.F))) is pool


def _session(pool, settings: TeacherSettings, seed: int = 0) -> ClosedLoopTeacher:
    learner = Learners(pool.domain, "noisy", 1, rng=100 + seed)
    t = ClosedLoopTeacher(pool, settings, seed=seed)
    while (item := t.next()) is not None:
        shown = item.to_json(pool)
        if item.kind == "test":
            t.observe({"actions": learner.answer([shown], moves=True)["actions"][0][0]})
        else:
            learner.observe(shown)
            t.observe({})
    return t


def test_a_session_draws_models_from_its_belief_after_each_test_and_replays(pool) -> None:
    settings = TeacherSettings(belief_models=3, n_particles=200, max_items=14)
    t = _session(pool, settings)
    n_tests = t.counts()["test"]
    assert n_tests >= 1
    assert len(t.pool.human_models) == len(pool.human_models) + 3 * n_tests
    drawn = t.pool.human_models[len(pool.human_models):]
    assert np.allclose(np.linalg.norm(drawn, axis=1), 1.0)  # particles are unit vectors
    assert len(pool.human_models) == 4  # the shared pool is left as it was
    again = ClosedLoopTeacher.replay(pool, t.responses, settings=settings, seed=0)
    assert [it.to_json(pool) for it in again.items] == [it.to_json(pool) for it in t.items]
    assert np.array_equal(again.pool.human_models, t.pool.human_models)


def test_models_are_drawn_only_after_a_test_answer_and_not_at_all_when_off(pool) -> None:
    """Up to the first test answer a session drawing models is the session of the default
    teacher (which draws none and keeps the shared pool); the pools part there."""
    off = _session(pool, TeacherSettings(n_particles=200, max_items=10))
    on = _session(pool, TeacherSettings(belief_models=3, n_particles=200, max_items=10))
    first = next(k for k, it in enumerate(off.items) if it.kind == "test")
    assert [it.demo for it in on.items[:first + 1]] == [it.demo for it in off.items[:first + 1]]
    assert off.pool is pool
    assert on.pool is not pool and on.pool.lessons.n_sets >= pool.lessons.n_sets


@pytest.mark.parametrize("bad", [-1, 65, 1.5, True])
def test_belief_models_must_be_a_small_count(bad) -> None:
    with pytest.raises(ValueError, match="closed-loop setting belief_models must be"):
        TeacherSettings(belief_models=bad)


def test_a_live_study_draws_models_and_its_export_replays(tmp_path) -> None:
    """Through the study server (teacher in its decision workers): a bot session with
    `belief_models` completes, and its exported answers replay offline to the same items."""
    from fastapi.testclient import TestClient

    from cfteach.study import create_app, export_csv, load_study
    from cfteach.study.bot import run_participant
    from cfteach.study.build import init_study, preview_sources
    from cfteach.study.live import pool_from_cell, settings_of

    folder = tmp_path / "study"
    init_study(folder, preview_sources(["skateboard"]), demo_step_ms=10,
               conditions=["closed_loop"],
               teacher={"n_particles": 200, "max_items": 10, "belief_models": 2})
    study = load_study(folder)
    cell = study["closed_loop"]["skateboard"]
    assert settings_of(cell).belief_models == 2
    db = f"sqlite:///{tmp_path / 'cl.db'}"
    with TestClient(create_app(folder, db, seed=3)) as client:
        done = run_participant(client, {"prolific_pid": "bm0yyyyyyyyy", "study_id": "S",
                                        "session_id": "B0"}, study=study)
        assert done["state"]["step"]["kind"] == "complete"
    export_csv(db, tmp_path / "out")
    with open(tmp_path / "out" / "closed_loop_items.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert any(r["kind"] == "test" for r in rows)
    pool = pool_from_cell(cell)
    responses = [{"actions": r["actions"].split()} if r["kind"] == "test" else {}
                 for r in rows]
    t = ClosedLoopTeacher.replay(pool, responses, settings=settings_of(cell),
                                 seed=int(rows[0]["teacher_seed"]))
    assert [(it.kind, it.to_json(pool)["start_state"]) for it in t.items] == [
        (r["kind"], json.loads(r["start_state"])) for r in rows]
    assert len(t.pool.human_models) > len(pool.human_models)
