"""Playable games and scoring, checked against the domains' own `step` and against
`cfteach.mdp` value iteration (a second method), plus the step machine and assignment."""

from __future__ import annotations

import random
import threading
from collections import Counter
from datetime import timedelta

import numpy as np
import pytest
from sqlalchemy import update

import test_study_support
from cfteach.domains import load
from cfteach.mdp import compile_instances, value_iteration
from cfteach.mdp.scoring import is_optimal
from cfteach.study.assignment import all_cells, cell_counts, pick_cell
from cfteach.study.config import load_study
from cfteach.study.db import make_engine, upgrade
from cfteach.study.games import (
    ScoringError,
    best_path,
    build_game,
    optimal_value,
    replay,
    shortest_path,
)
from cfteach.study.layout import instance_layout
from cfteach.study.models import Session, utcnow
from cfteach.study.practice import ACTIONS, PRACTICE, PRACTICE_START_ENERGY, PRACTICE_WEIGHTS
from cfteach.study.schemas import SessionRequest
from cfteach.study.service import StudyService
from cfteach.study.steps import build_steps, shuffled_tests

db_url = test_study_support.db_url
toy_study = test_study_support.toy_study
DOMAINS = ("delivery", "tiles", "skateboard")


@pytest.mark.parametrize("name", DOMAINS)
def test_replay_matches_the_domains_own_step(name: str) -> None:
    dom = load(name)
    rng = random.Random(1)
    insts = dom.instances()
    for inst in rng.sample(insts, 3):
        starts = inst.states()
        for start in rng.sample(starts, min(4, len(starts))):
            game = build_game(inst, start, tuple(dom.actions))
            assert game["states"][0] == inst.state_to_json(start)
            for _ in range(5):
                s, mu, acts, end = start, np.zeros(dom.n_features), [], False
                for _ in range(rng.randint(0, 20)):
                    a = rng.randrange(len(dom.actions))
                    s, phi, end = inst.step(s, a)
                    mu += phi
                    acts.append(dom.actions[a])
                    if end:
                        break
                sc = replay(game, list(dom.weights), acts, require_end=False)
                assert sc.finished == end
                assert game["states"][sc.final_state] == inst.state_to_json(s)
                assert np.allclose(sc.feature_counts, mu)
                assert sc.reward == pytest.approx(float(np.dot(dom.weights, mu)), abs=1e-12)


@pytest.mark.parametrize("name", DOMAINS)
def test_best_reward_matches_mdp_value_iteration(name: str) -> None:
    dom = load(name)
    insts = dom.instances()[:: max(1, len(dom.instances()) // 4)]
    batch = compile_instances(insts)
    vals = value_iteration(batch, np.asarray(dom.weights)[None, :], method="exact")
    rng = random.Random(2)
    for e, inst in enumerate(insts):
        for start in rng.sample(inst.states(), 3):
            game = build_game(inst, start, tuple(dom.actions))
            expected = float(vals.V[e, 0, batch.state_index[e][start]])
            assert optimal_value(game, list(dom.weights)) == pytest.approx(expected, abs=1e-9)
            path = best_path(game, list(dom.weights))
            assert replay(game, list(dom.weights), path).reward == pytest.approx(expected,
                                                                                 abs=1e-9)


def test_layout_is_read_from_the_domain_file() -> None:
    inst = load("delivery").instance((1, 0, 0, 0, 0, 1))
    lay = instance_layout("delivery", inst)
    assert lay["walls"] == [[1, 2], [1, 3]] and (lay["width"], lay["height"]) == (4, 3)
    assert lay["regions"] == [{"name": "mud", "style": "mud", "cells": [[3, 3]]}]
    assert lay["consumables"] == [{"key": "station", "style": "station", "cell": [4, 3]}]
    assert lay["markers"] == [{"name": "destination", "style": "destination", "cell": [1, 1]}]
    sk = instance_layout("skateboard", load("skateboard").instance((1, 0, 0)))
    assert sk["cargo"] is None and sk["markers"][0]["cell"] == [6, 4]
    tiles = instance_layout("tiles", load("tiles").instance((0,) * 8 + (1,)))
    assert [r["cells"] for r in tiles["regions"]] == [[], [[5, 3]]]


def test_practice_target_by_hand() -> None:
    game = build_game(PRACTICE, PRACTICE.initial_state, ACTIONS)
    # Worked out on paper: fetch the pentagon, go round the wall through the diamond.
    hand = ["right", "up", "pickup", "down", "down", "right", "right", "right", "right",
            "up", "up", "dropoff"]
    sc = replay(game, list(PRACTICE_WEIGHTS), hand)
    assert PRACTICE_START_ENERGY + sc.reward == 50.0  # 12 actions x -5%, diamond +10%
    assert len(shortest_path(game)) == 12
    assert PRACTICE_START_ENERGY + optimal_value(game, list(PRACTICE_WEIGHTS)) == 50.0


def test_scoring_errors_name_the_problem() -> None:
    game = build_game(PRACTICE, PRACTICE.initial_state, ACTIONS)
    with pytest.raises(ScoringError, match="unknown action 'jump' at position 1"):
        replay(game, [10, -5], ["up", "jump"])
    with pytest.raises(ScoringError, match="does not reach the end"):
        replay(game, [10, -5], ["up"])
    path = shortest_path(game)
    with pytest.raises(ScoringError, match="after the game ended"):
        replay(game, [10, -5], [*path, "up"])
    with pytest.raises(ScoringError, match="too many actions"):
        replay(game, [10, -5], ["up"] * 501)
    assert is_optimal(-1.6959999999999997, -1.696) and not is_optimal(-1.69, -1.696)


def test_step_list_and_test_order(toy_study) -> None:  # noqa: ANN001
    study = load_study(toy_study)
    steps = build_steps(study, ["toy_b", "toy_a", "toy_c"], 1, seed=5)
    kinds = [s["kind"] for s in steps]
    assert kinds[:5] == ["consent", "instructions", "free_play", "practice", "post_practice"]
    assert kinds[-2:] == ["demographics", "complete"]
    assert kinds.count("test") == 18 and kinds.count("demos") == 3
    for dom in ("toy_a", "toy_b", "toy_c"):
        order = [s["test_index"] for s in steps if s.get("domain") == dom and "trial" in s]
        assert sorted(order) == list(range(6))
    assert build_steps(study, ["toy_b", "toy_a", "toy_c"], 1, seed=5) == steps
    orders = {tuple(shuffled_tests(seed, "toy_a", 6)) for seed in range(30)}
    assert len(orders) > 10  # really shuffled across participants


def _service(toy_study, db_url: str, seed: int = 0) -> StudyService:  # noqa: ANN001
    engine = make_engine(db_url)
    upgrade(engine)
    return StudyService(engine, load_study(toy_study), seed=seed)


def test_assignment_balances_216_sessions(toy_study, db_url: str) -> None:  # noqa: ANN001
    svc = _service(toy_study, db_url)
    study = svc.study
    assert len(all_cells(study)) == 72
    for i in range(216):
        svc.start(SessionRequest(prolific_pid=f"P{i:05d}", study_id="S"))
        if i in (71, 143):
            with svc.Session() as db:
                assert set(cell_counts(db, study, utcnow()).values()) == {(i + 1) // 72}
    with svc.Session() as db:
        counts = cell_counts(db, study, utcnow())
    assert set(counts.values()) == {3}
    svc.engine.dispose()


def test_assignment_is_balanced_under_concurrency(toy_study, db_url: str) -> None:  # noqa: ANN001
    svc = _service(toy_study, db_url, seed=3)
    errors: list[Exception] = []

    def worker(k: int) -> None:
        try:
            for i in range(18):
                svc.start(SessionRequest(prolific_pid=f"T{k}x{i}", study_id="S"))
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    with svc.Session() as db:
        assert set(cell_counts(db, svc.study, utcnow()).values()) == {2}  # 144 / 72
    svc.engine.dispose()


def test_abandoned_sessions_free_their_cell(toy_study, db_url: str) -> None:  # noqa: ANN001
    svc = _service(toy_study, db_url, seed=4)
    for i in range(72):
        svc.start(SessionRequest(prolific_pid=f"A{i}", study_id="S"))
    with svc.Session() as db, db.begin():
        # Half of them completed long ago, the other half went idle past the cutoff.
        old = utcnow() - timedelta(minutes=svc.study["cutoff_minutes"] + 5)
        db.execute(update(Session).values(last_active_at=old))
        db.execute(update(Session).where(Session.id % 2 == 0).values(status="completed"))
    with svc.Session() as db:
        counts = cell_counts(db, svc.study, utcnow())
    assert sum(counts.values()) == 36 and set(counts.values()) == {0, 1}
    prog = svc.progress()  # the researcher's page: only the completed half, cell by cell
    assert sum(c["completed"] for c in prog["cells"]) == 36
    assert all(c["completed"] == c["occupied"] for c in prog["cells"])
    assert prog["status"] == {"completed": 36, "in_progress": 36}
    for i in range(36):
        svc.start(SessionRequest(prolific_pid=f"B{i}", study_id="S"))
    with svc.Session() as db:
        assert set(cell_counts(db, svc.study, utcnow()).values()) == {1}
    svc.engine.dispose()


def _conditions(svc: StudyService) -> Counter:
    with svc.Session() as db:
        counts = cell_counts(db, svc.study, utcnow())
    out: Counter = Counter()
    for (cond, _, _), n in counts.items():
        out[cond] += n
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_conditions_stay_balanced_from_the_first_participant(toy_study, db_url: str,  # noqa: ANN001
                                                              seed: int) -> None:
    svc = _service(toy_study, db_url, seed=seed)
    for i in range(24):
        svc.start(SessionRequest(prolific_pid=f"E{seed}x{i}", study_id="S"))
        by_cond = _conditions(svc)
        assert max(by_cond.values()) - min(by_cond.values()) <= 1, (i, by_cond)
        if i == 19:
            assert sorted(by_cond.values()) == [5, 5, 5, 5]
    svc.engine.dispose()


def test_pick_cell_fills_condition_then_order_then_test_set(toy_study) -> None:  # noqa: ANN001
    study = load_study(toy_study)
    cells = all_cells(study)
    counts = dict.fromkeys(cells, 1)
    base, feat, cf = study["conditions"][:3]
    orders = sorted({o for _, o, _ in cells})
    # baseline is one participant behind (17 vs 18): it goes first, although feature_only
    # has an empty cell too; within baseline, orders 0 and 2 are least filled, and order 0
    # is the less used over all conditions; in it, test set 0 is the empty one.
    counts[(base, orders[0], 0)] = 0
    counts[(base, orders[2], 0)] = 0
    counts[(base, orders[3], 0)] = 2
    counts[(feat, orders[1], 0)] = 0
    counts[(feat, orders[1], 1)] = 2
    counts[(cf, orders[2], 1)] = 2
    picks = {pick_cell(counts, random.Random(s)) for s in range(40)}
    assert picks == {(base, orders[0], 0)}


def test_concurrent_starts_share_fsyncs(toy_study, tmp_path,  # noqa: ANN001
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """New sessions take turns on the database's lock only, which their commit releases
    before its fsync: starts arriving together share fsyncs instead of queueing behind
    each other's (200 arrivals in 2 s waited up to 3.5 s: docs/study.md, "Load")."""
    svc = _service(toy_study, f"sqlite:///{tmp_path / 'starts.db'}")
    with svc.engine.connect() as conn:
        sync = conn.connection.dbapi_connection.wal_sync

    def start(k: int) -> None:
        svc.start(SessionRequest(prolific_pid=f"F{k:04d}", study_id="S"))

    # the first start's fsync, then one for the other seven; with a process lock held
    # through each commit they could not commit meanwhile (8 fsyncs, after 3 s)
    assert test_study_support.fsyncs_sharing_the_first(monkeypatch, sync, start,
                                                       seconds=3) == 2
    with svc.Session() as db:
        assert sum(cell_counts(db, svc.study, utcnow()).values()) == 8
    svc.engine.dispose()
