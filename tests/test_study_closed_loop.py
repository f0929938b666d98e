"""The live `closed_loop` condition through the API: study init, assignment, the item
sequence decided by the server's teacher, state rebuilt from the stored events, the export
and its offline replay through `ClosedLoopTeacher`."""

from __future__ import annotations

import csv
import json
import uuid
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

import test_study_support
from cfteach.cli import app as cli_app
from cfteach.closedloop import ClosedLoopTeacher
from cfteach.study import create_app, export_csv, load_study
from cfteach.study.bot import run_participant
from cfteach.study.build import init_study, preview_sources, toy_sources
from cfteach.study.games import shortest_path
from cfteach.study.live import ReplayMismatch, pool_from_cell, replay_export, settings_of
from cli_runner import WideRunner

TEACHER = {"n_particles": 300, "max_items": 10}
db_url = test_study_support.db_url  # SQLite, and PostgreSQL when one is given


@pytest.fixture(scope="module")
def cl_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Skateboard (the fastest paper domain's pool), placeholder tests, two conditions."""
    out = tmp_path_factory.mktemp("cl_study")
    init_study(out, preview_sources(["skateboard"]), demo_step_ms=10,
               conditions=["proposed", "closed_loop"], teacher=TEACHER)
    return out


def _rows(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


class Api:
    """One participant driven by hand through the API."""

    def __init__(self, client: TestClient, pid: str) -> None:
        self.c = client
        r = client.post("/api/session", json={"prolific_pid": pid, "study_id": "S1",
                                              "session_id": f"X{pid}"})
        assert r.status_code == 200, r.text
        self.h = {"X-Session-Token": r.json()["token"]}

    def state(self) -> dict:
        return self.c.get("/api/state", headers=self.h).json()

    def ready(self) -> dict:
        """The page once the next item is decided (the page waits the same way)."""
        st = self.c.get("/api/state", headers=self.h, params={"wait": 5}).json()
        assert not st["step"].get("preparing"), st["step"]
        return st

    def send(self, type_: str, payload: dict, step: int | None = None) -> object:
        step = self.state()["step_index"] if step is None else step
        return self.c.post("/api/event", headers=self.h, json={
            "event_id": uuid.uuid4().hex, "step_index": step, "type": type_,
            "payload": payload})

    def to_closed_loop(self) -> dict:
        """Walk the pages before the teaching phase (as the bot does)."""
        run_participant(self.c, None, token=self.h["X-Session-Token"], stop_after=6)
        st = self.state()
        assert st["step"]["kind"] == "closed_loop", st["step"]["kind"]
        return st


def _closed_loop_client(app) -> tuple[TestClient, Api]:  # noqa: ANN001
    """A client and a closed_loop participant (assignment alternates between the two
    conditions, so one of the first two sessions is one)."""
    client = TestClient(app)
    for k in range(2):
        who = Api(client, f"pp{k}{uuid.uuid4().hex[:10]}")
        if _condition(app, who.h["X-Session-Token"]) == "closed_loop":
            return client, who
    raise AssertionError("no closed_loop session among the first two")


def _condition(app, token: str) -> str:  # noqa: ANN001
    from sqlalchemy import select

    from cfteach.study.models import Session
    with app.state.service.Session() as db:
        return db.scalar(select(Session.condition).where(Session.token == token))


def _teacher_seed(app, who: Api) -> int:  # noqa: ANN001
    from sqlalchemy import select

    from cfteach.study.live import teacher_seed
    from cfteach.study.models import Session
    with app.state.service.Session() as db:
        seed = db.scalar(select(Session.seed).where(Session.token == who.h["X-Session-Token"]))
    return teacher_seed(seed, "skateboard")


# -- study init --------------------------------------------------------------------------

def test_init_writes_closed_loop_cells(cl_study: Path) -> None:
    s = load_study(cl_study)
    assert s["conditions"] == ["proposed", "closed_loop"]
    assert list(s["curricula"]["skateboard"]) == ["proposed"]
    cell = s["closed_loop"]["skateboard"]
    assert cell["settings"]["max_items"] == 10 and cell["settings"]["n_particles"] == 300
    # the held-out tests are exactly the tests every condition is tested on
    tests = [t for ts in s["tests"]["skateboard"] for t in ts]
    assert len(cell["held_out"]) == len(tests) == 18
    starts = sorted(json.dumps(t["game"]["states"][0], sort_keys=True) for t in tests)
    assert sorted(json.dumps(h["start_state"], sort_keys=True) for h in cell["held_out"]) \
        == starts
    pool = pool_from_cell(cell)
    assert len(pool.held_out) >= 1


def test_live_teacher_covers_the_proposed_curriculum_first(cl_study: Path) -> None:
    """The live pool carries `proposed` as its backbone, as `cfteach simulate` does: the
    first lesson is the curriculum's first demonstration (same instance, same start)."""
    s = load_study(cl_study)
    cell = s["closed_loop"]["skateboard"]
    shown = s["curricula"]["skateboard"]["proposed"]
    assert [b["start_state"] for b in cell["backbone"]] == [d["states"][0] for d in shown]
    pool = pool_from_cell(cell)
    assert len(pool.backbone) == len(cell["backbone"]) >= 1
    teacher = ClosedLoopTeacher(pool, settings_of(cell), seed=0)
    first = teacher.next()
    assert first is not None and first.purpose == "backbone"
    lesson = first.to_json(pool)
    assert lesson["states"][0] == shown[0]["states"][0]
    legacy = {k: v for k, v in cell.items() if k != "backbone"}
    assert pool_from_cell(legacy).backbone == ()


def test_paper_study_file_is_unchanged_by_default(tmp_path: Path) -> None:
    init_study(tmp_path, toy_sources())
    s = load_study(tmp_path)
    assert s["conditions"] == ["baseline", "feature_only", "counterfactual_only", "proposed"]
    assert "closed_loop" not in s


def test_init_refuses_bad_conditions(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown condition 'nope'"):
        init_study(tmp_path, toy_sources(), conditions=["proposed", "nope"])
    with pytest.raises(ValueError, match="given twice"):
        init_study(tmp_path, toy_sources(), conditions=["proposed", "proposed"])
    with pytest.raises(ValueError, match="closed_loop needs a built-in domain"):
        init_study(tmp_path, toy_sources(), conditions=["closed_loop"])
    with pytest.raises(ValueError, match="max_items must be"):
        init_study(tmp_path, preview_sources(["skateboard"]), conditions=["closed_loop"],
                   teacher={"max_items": 0})


def test_cli_init_conditions(tmp_path: Path) -> None:
    r = WideRunner().invoke(cli_app, [
        "study", "init", "--preview", "--domains", "skateboard", "--out", str(tmp_path / "s"),
        "--conditions", "baseline,closed_loop", "--teacher", "max_items=8,p_learn=0.7"])
    assert r.exit_code == 0, r.output
    s = load_study(tmp_path / "s")
    assert s["conditions"] == ["baseline", "closed_loop"]
    assert s["closed_loop"]["skateboard"]["settings"]["p_learn"] == 0.7
    bad = WideRunner().invoke(cli_app, ["study", "init", "--toy", "--out", str(tmp_path / "t"),
                  "--conditions", "proposed,nope"])
    assert bad.exit_code == 2
    assert "unknown condition 'nope'" in bad.output and "Traceback" not in bad.output


# -- assignment --------------------------------------------------------------------------

def test_assignment_balances_over_chosen_conditions(cl_study: Path, tmp_path: Path) -> None:
    app = create_app(cl_study, f"sqlite:///{tmp_path / 'a.db'}", seed=3)
    with TestClient(app) as client:
        conds = []
        for k in range(6):
            who = Api(client, f"bal{k}xxxxxxxx")
            conds.append(_condition(app, who.h["X-Session-Token"]))
            assert abs(conds.count("proposed") - conds.count("closed_loop")) <= 1
    assert sorted(set(conds)) == ["closed_loop", "proposed"]


# -- the teaching phase ------------------------------------------------------------------

def test_closed_loop_session_items_and_export_replay(cl_study: Path, tmp_path: Path) -> None:
    """A bot answers every diagnostic test naively; the export's items replay offline to
    the same sequence, and feedback follows every wrong answer."""
    db = f"sqlite:///{tmp_path / 'cl.db'}"
    app = create_app(cl_study, db, seed=5)
    study = load_study(cl_study)
    with TestClient(app) as client:
        for k in range(2):
            done = run_participant(client, {"prolific_pid": f"cl{k}yyyyyyyyy", "study_id": "S",
                                            "session_id": f"Y{k}"}, study=study)
            assert done["state"]["step"]["kind"] == "complete"
    counts = export_csv(db, tmp_path / "out")
    assert counts["test_responses.csv"] == 12  # the same 6 post-teaching tests each
    items = _rows(tmp_path / "out" / "closed_loop_items.csv")
    assert items and counts["closed_loop_items.csv"] == len(items)
    (pid,) = {r["participant_id"] for r in items}
    mine = [r for r in items if r["participant_id"] == pid]
    assert [int(r["position"]) for r in mine] == list(range(len(mine)))
    assert {r["kind"] for r in mine} >= {"demonstration", "test"}
    for r in mine:
        assert r["done_at"] and float(r["expected_area"]) > 0
        if r["kind"] == "test":
            assert float(r["regret"]) == pytest.approx(
                float(r["optimal_reward"]) - float(r["reward"]))
            assert 0 <= float(r["predicted_optimal"]) <= 1
    for a, b in zip(mine, mine[1:], strict=False):
        if a["kind"] == "test" and a["optimal"] == "0":
            assert b["kind"] == "feedback" and b["about"] == a["position"]
    # offline: the same teacher, fed the export's answers, picks the same items
    cell = study["closed_loop"]["skateboard"]
    pool = pool_from_cell(cell)
    responses = [{"actions": r["actions"].split()} if r["kind"] == "test" else {}
                 for r in mine]
    t = ClosedLoopTeacher.replay(pool, responses, settings=settings_of(cell),
                                 seed=int(mine[0]["teacher_seed"]))
    assert len(t.items) == len(mine)
    for it, r in zip(t.items, mine, strict=True):
        shown = it.to_json(pool)
        assert (it.kind, it.purpose, shown["env_index"]) == (r["kind"], r["purpose"],
                                                             int(r["env_index"]))
        assert shown["start_state"] == json.loads(r["start_state"])
    assert t.next() is None  # teaching had ended: the participant moved on
    # the same, checked by the library; an export whose items this code would not serve
    # (another cfteach ran the study) is refused, naming the first item that differs
    assert [it.demo for it in replay_export(cell, mine).items] == [it.demo for it in t.items]
    other = [dict(r) for r in mine]
    k = next(i for i, r in enumerate(other) if r["kind"] == "demonstration")
    other[k]["env_index"] = str(int(other[k]["env_index"]) + 1)
    with pytest.raises(ReplayMismatch, match=f"item {k}:"):
        replay_export(cell, other)
    parts = {p["participant_id"]: p for p in _rows(tmp_path / "out" / "participants.csv")}
    assert parts[pid]["condition"] == "closed_loop" and parts[pid]["counterfactual"] == "1"


def test_item_checks_and_state_from_events(cl_study: Path, db_url: str) -> None:
    """On SQLite and PostgreSQL."""
    app = create_app(cl_study, db_url, seed=5)
    client, who = _closed_loop_client(app)
    with client:
        who.to_closed_loop()
        item = who.ready()["step"]["item"]
        assert item["kind"] == "demonstration" and item["position"] == 0
        # not watched yet
        r = who.send("item_done", {"item": 0})
        assert r.status_code == 409 and r.json()["error"] == "demos_unwatched"
        # a stale page (another item), actions on a demonstration
        assert who.send("item_done", {"item": 3}).json()["error"] == "wrong_item"
        r = who.send("item_done", {"item": 0, "actions": ["up"]})
        assert r.status_code == 422
        r = who.send("demo_play_start", {"demo_index": 1})
        assert r.status_code == 422 and r.json()["error"] == "unknown_demo"
        assert who.send("demo_play_start", {"demo_index": 0}).status_code == 200
        assert who.send("demo_play_end", {"demo_index": 0, "completed": True,
                                          "watch_ms": 50}).status_code == 200
        r = who.send("item_done", {"item": 0})
        assert r.status_code == 200, r.text
        nxt = who.ready()["step"]["item"]
        assert nxt["position"] == 1 and nxt["kind"] == "test"
        # an unfinished answer is refused and changes nothing
        r = who.send("item_done", {"item": 1, "actions": []})
        assert r.status_code == 422 and r.json()["error"] == "bad_moves"
        assert who.state()["step"]["item"]["position"] == 1
        # the server forgets every teacher: the next decision is replayed from the events
        app.state.service.live._teachers.clear()
        moves = shortest_path(nxt["game"])
        r = who.send("item_done", {"item": 1, "actions": moves, "time_ms": 5})
        assert r.status_code == 200
        third = who.ready()["step"]["item"]
        assert third["position"] == 2
        study = load_study(cl_study)
        cell = study["closed_loop"]["skateboard"]
        pool = app.state.service.live.pool(study, "skateboard")
        offline = ClosedLoopTeacher.replay(pool, [{}, {"actions": moves}],
                                           settings=settings_of(cell),
                                           seed=_teacher_seed(app, who))
        assert offline.next().kind == third["kind"]
        if third["kind"] == "feedback":  # the naive path was wrong
            assert third["answer"][0] == nxt["game"]["states"][0]
            assert len(third["answer"]) == len(moves) + 1
            assert third["optimal"][0] == nxt["game"]["states"][0]
        final = who.state()["step"]
    # a new server on the same database (a restart): the same page, the same item
    app2 = create_app(cl_study, app.state.service.engine.url.render_as_string(False), seed=5)
    with TestClient(app2) as c2:
        again = c2.get("/api/state", headers=who.h).json()["step"]
    again["item"].pop("elapsed_ms", None)
    final["item"].pop("elapsed_ms", None)
    assert again == final and again["item"]["position"] == 2


@pytest.mark.slow
def test_kill_9_mid_session_lands_on_the_same_item(tmp_path: Path) -> None:
    """`cfteach serve` killed with SIGKILL right after acknowledging an item (while the
    next decision may be running in the background), then restarted: the participant is on
    the same item, finishes, and nothing is lost or stored twice."""
    import httpx
    from sqlalchemy import func, select

    from cfteach.study.db import make_engine
    from cfteach.study.livesrv import serving_process
    from cfteach.study.models import ClosedLoopItem, Event

    study_dir = tmp_path / "study"
    init_study(study_dir, preview_sources(["skateboard"]), demo_step_ms=10,
               conditions=["closed_loop"], teacher=TEACHER)
    db = f"sqlite:///{tmp_path / 'k.db'}"
    with serving_process(study_dir, "--db", db) as (base, proc), \
            httpx.Client(base_url=base, timeout=30) as client:
        r = client.post("/api/session", json={"prolific_pid": "kill9aaaaaaaa",
                                              "study_id": "S", "session_id": "K"})
        token = r.json()["token"]
        # consent .. domain intro (6 pages), then 3 items
        got = run_participant(client, None, token=token, stop_after=9)
        assert got["state"]["step"]["kind"] == "closed_loop"
        acked = client.get("/api/state", headers={"X-Session-Token": token},
                           params={"wait": 5}).json()  # the item decided after them
        assert acked["step"]["kind"] == "closed_loop" and "item" in acked["step"]
        proc.kill()  # SIGKILL: no shutdown of any kind
        proc.wait()
    with serving_process(study_dir, "--db", db) as (base, _), \
            httpx.Client(base_url=base, timeout=30) as client:
        again = client.get("/api/state", headers={"X-Session-Token": token}).json()
        for s in (again, acked):
            s["step"]["item"].pop("elapsed_ms", None)
        assert again["step_index"] == acked["step_index"]
        assert again["step"]["item"] == acked["step"]["item"]
        assert again["step"]["item"]["position"] == 3
        done = run_participant(client, None, token=token)
        assert done["state"]["step"]["kind"] == "complete"
    engine = make_engine(db)
    with engine.connect() as conn:
        n, lo, hi, ids = conn.execute(select(func.count(), func.min(Event.seq),
                                             func.max(Event.seq),
                                             func.count(Event.event_id.distinct()))).one()
        positions = [p for (p,) in conn.execute(select(ClosedLoopItem.position)
                                                .order_by(ClosedLoopItem.position))]
        undone = conn.execute(select(func.count()).where(ClosedLoopItem.done_at.is_(None)))
        undone = undone.scalar()
        answered = conn.execute(select(func.count()).where(Event.type == "item_done")).scalar()
    engine.dispose()
    assert (lo, hi, ids) == (1, n, n)  # gap-free, in order, each event once
    assert positions == list(range(len(positions))) and undone == 0
    assert answered == len(positions)  # one answer per item, none lost, none twice


def test_next_item_decided_in_background_while_a_demonstration_is_watched(
        cl_study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """While item k (a demonstration) is on screen the item after it is decided in the
    background; answering k then needs no replay and no decision of its own."""
    import time

    from cfteach.closedloop import teacher as teacher_mod

    app = create_app(cl_study, f"sqlite:///{tmp_path / 'b.db'}", seed=5)
    client, who = _closed_loop_client(app)
    live = app.state.service.live
    with client:
        who.to_closed_loop()
        assert who.ready()["step"]["item"]["position"] == 0  # on screen (a busy machine
        key = next(iter(live._teachers))                      # may take a while)
        deadline = time.monotonic() + 30
        while not any(len(t.responses) == 1 for t in live._teachers[key]):
            assert time.monotonic() < deadline, "no background decision"
            time.sleep(0.05)
        ahead = next(t for t in live._teachers[key] if len(t.responses) == 1)
        decided = ahead.next()
        calls: list[str] = []
        monkeypatch.setattr(teacher_mod.ClosedLoopTeacher, "replay",
                            classmethod(lambda *a, **k: calls.append("replay")))
        monkeypatch.setattr(teacher_mod.ClosedLoopTeacher, "_decide",
                            lambda self: calls.append("decide"))
        who.send("demo_play_start", {"demo_index": 0})
        who.send("demo_play_end", {"demo_index": 0, "completed": True, "watch_ms": 50})
        r = who.send("item_done", {"item": 0})
        assert r.status_code == 200, r.text
        assert calls == []
        item = who.ready()["step"]["item"]
        assert (item["position"], item["kind"]) == (decided.index, decided.kind)


@pytest.mark.parametrize("name", ["skateboard", "delivery"])
def test_game_from_batch_is_build_game(name: str) -> None:
    """The diagnostic tests' tables, read from the compiled arrays, equal those the domain's
    own `step` builds (what every post-teaching test is played and scored in)."""
    import numpy as np

    from cfteach.bec import demo_set
    from cfteach.domains import load
    from cfteach.study.games import build_game
    from cfteach.study.live import game_from_batch

    ds = demo_set(load(name))
    for d in np.random.default_rng(1).choice(ds.D, 8, replace=False).tolist():
        want = build_game(ds.instance(d), ds.trajectory_states(d)[0], tuple(ds.batch.actions))
        assert game_from_batch(ds, d) == want


def test_held_out_summary_is_the_mass_inside_each_held_out_tests_region(
        cl_study: Path) -> None:
    """The exported `predicted_held_out` (asked of the distinct held-out row sets only) is,
    at every item of a session, the mass of the belief the item was chosen with that
    satisfies every row of each held-out test, test by test, averaged; for feedback that
    belief is the one before the failed answer (the update waits: the server answers at
    once), and the teacher's own summary after the update is the same computation."""
    from cfteach.study.live import item_summary

    def by_test(pool, b) -> float:
        return float(np.mean([b.weights @ np.all(pool.test_rows.of(d) @ b.particles.T
                                                 >= -1e-9, axis=0)
                              for d in sorted(pool.held_out)]))

    cell = load_study(cl_study)["closed_loop"]["skateboard"]
    pool = pool_from_cell(cell)
    t = ClosedLoopTeacher(pool, settings_of(cell), seed=11)
    seen = feedback = 0
    while (item := t.next()) is not None:
        history = len(t.as_chosen[1].history)
        want = by_test(*t.as_chosen)
        summary = item_summary(t, item)
        assert summary["predicted_held_out"] == pytest.approx(want, abs=1e-12)
        assert len(t.as_chosen[1].history) == history  # the summary did not update
        feedback += item.kind == "feedback"
        assert t.predicted_held_out() == pytest.approx(by_test(t.pool, t.belief), abs=1e-12)
        t.observe({"actions": ["up"]} if item.kind == "test" else {})
        seen += 1
    assert seen >= 3 and feedback >= 1


def test_progress_moves_with_every_item_and_is_the_teachers_own(cl_study: Path,
                                                                  tmp_path: Path) -> None:
    """The page's bar reads `step.progress`: stored with each item when it is chosen, it
    rises with every item and is what the same teacher, replayed offline, reports."""
    from sqlalchemy import select

    from cfteach.study.models import ClosedLoopItem

    app = create_app(cl_study, f"sqlite:///{tmp_path / 'p.db'}", seed=5)
    client, who = _closed_loop_client(app)
    with client:
        who.to_closed_loop()
        st = who.ready()
        assert st["step"]["progress"] == pytest.approx(0.0)  # nothing taught yet
        run_participant(client, None, token=who.h["X-Session-Token"], study=load_study(cl_study))
        with app.state.service.Session() as db:
            rows = list(db.scalars(select(ClosedLoopItem).order_by(ClosedLoopItem.position)))
    shown = [r.progress for r in rows]
    assert len(shown) >= 3 and all(p is not None for p in shown)
    assert all(b > a for a, b in zip(shown, shown[1:], strict=False)), shown
    assert all(0.0 <= p <= 1.0 for p in shown)
    study = load_study(cl_study)
    cell = study["closed_loop"]["skateboard"]
    responses = [{"actions": r.actions.split()} if r.kind == "test" else {} for r in rows]
    offline = ClosedLoopTeacher.replay(pool_from_cell(cell), responses,
                                       settings=settings_of(cell), seed=_teacher_seed(app, who))
    assert shown == pytest.approx(offline.state_dict()["progress"][:len(shown)])


def test_a_replay_that_would_serve_other_items_ends_teaching_not_misreads_answers(
        cl_study: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """The teacher is rebuilt from the stored answers; if the rebuilt teacher would have
    served other items than the stored ones (the code changed under a running study), its
    next item would read answers to items the participant never saw. The server ends that
    domain's teaching instead, and says why in its log."""
    from sqlalchemy import select

    from cfteach.study.models import ClosedLoopItem, Session

    app = create_app(cl_study, f"sqlite:///{tmp_path / 'mismatch.db'}", seed=5)
    client, who = _closed_loop_client(app)
    with client:
        start = who.to_closed_loop()
        first = who.ready()["step"]["item"]
        assert first["kind"] == "demonstration" and first["position"] == 0
        who.send("demo_play_start", {"demo_index": 0})
        who.send("demo_play_end", {"demo_index": 0, "completed": True, "watch_ms": 50})
        assert who.send("item_done", {"item": 0}).status_code == 200
        second = who.ready()["step"]["item"]
        assert second["position"] == 1
        service = app.state.service
        with service.Session() as db, db.begin():  # as if an older version had served it
            pk = db.scalar(select(Session.id).where(Session.token == who.h["X-Session-Token"]))
            stored = db.scalar(select(ClosedLoopItem).where(ClosedLoopItem.session_pk == pk,
                                                            ClosedLoopItem.position == 0))
            stored.demo += 1
        service.live._teachers.clear()
        if second["kind"] == "test":
            r = who.send("item_done", {"item": 1, "actions": shortest_path(second["game"]),
                                       "time_ms": 5})
        else:
            who.send("demo_play_start", {"demo_index": 0})
            who.send("demo_play_end", {"demo_index": 0, "completed": True, "watch_ms": 50})
            r = who.send("item_done", {"item": 1})
        assert r.status_code == 200, r.text
        after = who.c.get("/api/state", headers=who.h, params={"wait": 5}).json()
        with service.Session() as db:
            positions = list(db.scalars(select(ClosedLoopItem.position).where(
                ClosedLoopItem.session_pk == pk)))
    assert after["step_index"] == start["step_index"] + 1
    assert after["step"]["kind"] != "closed_loop"
    assert sorted(positions) == [0, 1]  # no item decided from the misread answers
    assert any("item 0" in rec.getMessage() and rec.levelname == "ERROR"
               for rec in caplog.records)
