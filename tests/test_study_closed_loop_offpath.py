"""The closed-loop teacher off the request path (issue 22, items 2, 3, 5, 6): answers are
checked in full before any teacher work, decisions run outside every request's
transaction (worker processes in `cfteach serve`), the page is told while an item is being
prepared, feedback is timed like demonstrations, and a play's acknowledgement says why it
did not count."""

from __future__ import annotations

import threading
import time
import uuid
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select

from cfteach.study import create_app
from cfteach.study.build import init_study, preview_sources
from cfteach.study.games import shortest_path
from cfteach.study.ratelimit import RateLimiter
from test_study_closed_loop import TEACHER, Api


@pytest.fixture(scope="module")
def cl_only(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cl_only")
    init_study(out, preview_sources(["skateboard"]), demo_step_ms=10,
               conditions=["closed_loop"], teacher=TEACHER)
    return out


def _ready(who: Api) -> dict:
    """The page once its item is decided (the page's own wait)."""
    r = who.c.get("/api/state", headers=who.h, params={"wait": 5})
    assert r.status_code == 200, r.text
    st = r.json()
    assert not st["step"].get("preparing"), st["step"]
    return st


def _watch(who: Api, k: int) -> None:
    assert who.send("demo_play_start", {"demo_index": k}).status_code == 200
    time.sleep(0.05)
    r = who.send("demo_play_end", {"demo_index": k, "completed": True, "watch_ms": 50})
    assert r.status_code == 200, r.text


def _quiet(app) -> None:  # noqa: ANN001
    """Wait until no decision is running (background ones included)."""
    decider = app.state.service.decider
    deadline = time.monotonic() + 30
    while not all(f.done() for f in list(decider._futures.values())):
        assert time.monotonic() < deadline
        time.sleep(0.02)
    time.sleep(0.2)  # an ahead decision submitted by the last callback
    while not all(f.done() for f in list(decider._futures.values())):
        time.sleep(0.02)


def _to_test(who: Api) -> dict:
    """Answer items until a test is on screen."""
    st = _ready(who)
    for _ in range(10):
        item = st["step"]["item"]
        if item["kind"] == "test":
            return st
        _watch(who, item["position"])
        assert who.send("item_done", {"item": item["position"]}).status_code == 200
        st = _ready(who)
    raise AssertionError("no test among the first items")


def test_refused_answers_do_no_teacher_work(cl_only: Path, tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    from cfteach.closedloop import teacher as teacher_mod

    app = create_app(cl_only, f"sqlite:///{tmp_path / 'r.db'}", seed=7)
    with TestClient(app) as c:
        who = Api(c, "refused000001")
        who.to_closed_loop()
        st = _to_test(who)
        pos = st["step"]["item"]["position"]
        _quiet(app)
        calls: list[str] = []
        cls = teacher_mod.ClosedLoopTeacher
        for name in ("observe", "next", "_decide"):
            orig = getattr(cls, name)
            monkeypatch.setattr(cls, name, lambda self, *a, _o=orig, _n=name, **k: (
                calls.append(_n), _o(self, *a, **k))[1])
        monkeypatch.setattr(cls, "replay", classmethod(
            lambda *a, **k: calls.append("replay")))
        for body in ({"item": pos, "actions": ["up"] * 3, "time_ms": 5},  # unfinished
                     {"item": pos, "actions": ["fly"], "time_ms": 5},     # not a move
                     {"item": pos + 1, "actions": [], "time_ms": 5},      # not on screen
                     {"item": pos}):                                      # no answer
            r = who.send("item_done", body)
            assert r.status_code in (409, 422), r.text
        time.sleep(0.3)
        assert calls == []  # not in the request, not in the background either


def test_refused_answers_write_nothing(cl_only: Path, tmp_path: Path) -> None:
    """A refused answer is checked before the event row is written: no INSERT or UPDATE
    reaches the database (not even one rolled back), so a refusal costs reads only."""
    from sqlalchemy import event as sa_event

    app = create_app(cl_only, f"sqlite:///{tmp_path / 'w.db'}", seed=7)
    writes: list[str] = []

    def record(_conn, _cursor, statement: str, *_a) -> None:  # noqa: ANN001
        if statement.lstrip().split(None, 1)[0].upper() in ("INSERT", "UPDATE", "DELETE"):
            writes.append(statement.split("(", 1)[0])

    with TestClient(app) as c:
        who = Api(c, "nowrite00001")
        who.to_closed_loop()
        first = _ready(who)["step"]["item"]
        assert first["kind"] == "demonstration"
        _quiet(app)
        sa_event.listen(app.state.service.engine, "before_cursor_execute", record)
        for body in ({"item": first["position"]},                      # not watched
                     {"item": first["position"], "actions": ["up"]},   # actions on a demo
                     {"item": first["position"] + 1}):                 # not on screen
            r = who.send("item_done", body)
            assert r.status_code in (409, 422), r.text
        sa_event.remove(app.state.service.engine, "before_cursor_execute", record)
        assert writes == []
        pos = _to_test(who)["step"]["item"]["position"]
        _quiet(app)
        sa_event.listen(app.state.service.engine, "before_cursor_execute", record)
        for body in ({"item": pos, "actions": ["up"] * 3, "time_ms": 5},  # unfinished
                     {"item": pos, "actions": ["fly"], "time_ms": 5}):    # not a move
            r = who.send("item_done", body)
            assert r.status_code in (409, 422), r.text
        sa_event.remove(app.state.service.engine, "before_cursor_execute", record)
        assert writes == []


def test_page_is_told_while_the_next_item_is_prepared(cl_only: Path, tmp_path: Path) -> None:
    """A decision that takes long never blocks the answer or other pages: the answer is
    acknowledged with ``preparing: true``; `GET /api/state?wait=` then brings the item."""
    app = create_app(cl_only, f"sqlite:///{tmp_path / 'p.db'}", seed=8)
    service = app.state.service
    gate = threading.Event()
    real = service.decider._job

    def slow(*a):  # noqa: ANN002, ANN202
        fn, args = real(*a)

        def held(*x):  # noqa: ANN002, ANN202
            assert gate.wait(30)
            return fn(*x)
        return held, args

    with TestClient(app) as c:
        who = Api(c, "preparing0001")
        other = Api(c, "preparing0002")
        who.to_closed_loop()
        item = _ready(who)["step"]["item"]  # decided (a loaded machine may take a while)
        _watch(who, item["position"])
        _quiet(app)
        service.decider._job = slow
        service.decider._futures.clear()  # the ahead decision is forgotten too
        t0 = time.monotonic()
        r = who.send("item_done", {"item": item["position"]})
        assert r.status_code == 200, r.text
        step = r.json()["state"]["step"]
        assert step["kind"] == "closed_loop" and step["preparing"] is True
        assert "item" not in step and step["retry_ms"] > 0
        # other participants' pages are not held up by it
        assert other.c.get("/api/state", headers=other.h).status_code == 200
        assert time.monotonic() - t0 < 5
        # an answer to the item being prepared is refused, not stored
        r = who.send("item_done", {"item": item["position"] + 1})
        assert r.status_code == 409 and r.json()["error"] == "wrong_item"
        gate.set()
        nxt = _ready(who)["step"]["item"]
        assert nxt["position"] == item["position"] + 1


def test_decisions_run_in_worker_processes(cl_only: Path, tmp_path: Path) -> None:
    """`decision_workers=1`: every teacher lives in the worker process, none in the server."""
    from concurrent.futures import ProcessPoolExecutor

    app = create_app(cl_only, f"sqlite:///{tmp_path / 'w.db'}", seed=9, decision_workers=1)
    service = app.state.service
    try:
        with TestClient(app) as c:
            who = Api(c, "workerproc001")
            who.to_closed_loop()
            st = _to_test(who)
            assert st["step"]["item"]["position"] >= 1
            assert isinstance(service.decider._executors[0], ProcessPoolExecutor)
            assert service.live._teachers == {}  # no teacher in the server process
    finally:
        service.close()


def test_two_servers_share_one_session_exactly_once(cl_only: Path, tmp_path: Path) -> None:
    """Two server instances on one database, a participant's requests alternating between
    them (a proxy without sticky sessions): every event stored once, items in order, the
    same items the teacher replayed offline would choose."""
    from cfteach.study.bot import run_participant
    from cfteach.study.models import ClosedLoopItem, Event

    db = f"sqlite:///{tmp_path / 'two.db'}"
    a, b = (create_app(cl_only, db, seed=s, sessions_per_minute=0) for s in (10, 11))

    class Alternating:
        def __init__(self, clients: list[TestClient]) -> None:
            self.clients, self.n = clients, 0

        def _next(self) -> TestClient:
            self.n += 1
            return self.clients[self.n % 2]

        def get(self, *x, **k):  # noqa: ANN002, ANN003, ANN202
            return self._next().get(*x, **k)

        def post(self, *x, **k):  # noqa: ANN002, ANN003, ANN202
            return self._next().post(*x, **k)

    with TestClient(a) as ca, TestClient(b) as cb:
        out = run_participant(Alternating([ca, cb]), {"prolific_pid": "twoservers01"})
    assert out["state"]["step"]["kind"] == "complete"
    with a.state.service.Session() as db_:
        n, lo, hi = db_.execute(select(func.count(), func.min(Event.seq),
                                       func.max(Event.seq))).one()
        positions = list(db_.scalars(select(ClosedLoopItem.position)
                                     .order_by(ClosedLoopItem.position)))
        answered = db_.scalar(select(func.count()).where(Event.type == "item_done"))
    assert (lo, hi, n) == (1, out["events"], out["events"])
    assert positions == list(range(len(positions))) == list(range(answered))


def test_feedback_is_timed_like_a_demonstration(cl_only: Path, tmp_path: Path) -> None:
    app = create_app(cl_only, f"sqlite:///{tmp_path / 'f.db'}", seed=12)
    with TestClient(app) as c:
        for k in range(6):  # some participant soon fails a test and gets feedback
            who = Api(c, f"feedback{k:05d}")
            who.to_closed_loop()
            st = _ready(who)
            for _ in range(12):
                item = st["step"]["item"]
                if item["kind"] == "feedback":
                    break
                if item["kind"] == "test":
                    body = {"item": item["position"], "actions": shortest_path(item["game"]),
                            "time_ms": 5}
                else:
                    _watch(who, item["position"])
                    body = {"item": item["position"]}
                assert who.send("item_done", body).status_code == 200
                st = _ready(who)
                if st["step"]["kind"] != "closed_loop":
                    break
            else:
                continue
            if st["step"]["kind"] == "closed_loop" and item["kind"] == "feedback":
                break
        else:
            pytest.fail("no feedback item reached")
        k = item["position"]
        assert item["completed"] == 0 and item["n_actions"] >= 1
        r = who.send("item_done", {"item": k})  # not played: refused
        assert r.status_code == 409 and r.json()["error"] == "demos_unwatched"
        _watch(who, k)
        r = who.send("item_done", {"item": k})
        assert r.status_code == 200, r.text


def test_play_ack_says_why_a_play_did_not_count(cl_only: Path, tmp_path: Path) -> None:
    """An end whose start was refused (a network fault) is reported as such, and never
    takes away a play already watched to the end."""
    app = create_app(cl_only, f"sqlite:///{tmp_path / 'a.db'}", seed=13)
    with TestClient(app) as c:
        who = Api(c, "playack000001")
        who.to_closed_loop()
        k = _ready(who)["step"]["item"]["position"]
        r = who.send("demo_play_end", {"demo_index": k, "completed": True, "watch_ms": 900})
        assert r.status_code == 200
        assert r.json()["play"] == {"verified": False, "server_ms": None,
                                    "required_ms": r.json()["play"]["required_ms"],
                                    "reason": "no_start"}
        _watch(who, k)
        r = who.send("demo_play_end", {"demo_index": k, "completed": True, "watch_ms": 9})
        assert r.json()["play"]["reason"] == "no_start"
        assert _ready(who)["step"]["item"]["completed"] == 1
        assert who.send("item_done", {"item": k}).status_code == 200


def test_state_reads_are_limited_and_events_weighted(cl_only: Path, tmp_path: Path) -> None:
    app = create_app(cl_only, f"sqlite:///{tmp_path / 'l.db'}", seed=14, states_per_minute=5,
                     events_per_minute=2)
    with TestClient(app) as c:
        who = Api(c, "limits0000001")
        codes = [c.get("/api/state", headers=who.h).status_code for _ in range(6)]
        assert codes == [200] * 5 + [429]
        # a page_load weighs a half: 4 fit in a limit of 2, the 5th does not
        codes = [c.post("/api/event", headers=who.h, json={
            "event_id": uuid.uuid4().hex, "step_index": 0, "type": "page_load",
            "payload": {}}).status_code for _ in range(5)]
        assert codes == [200] * 4 + [429]


def test_rate_limiter_weights() -> None:
    lim = RateLimiter(2, window=10)
    assert [lim.allow("k", now=0, cost=0.25) for _ in range(8)] == [True] * 8
    assert not lim.allow("k", now=1, cost=0.25)
    assert lim.blocked("k", now=1)
    assert lim.allow("k", now=10.5, cost=2)  # the window has passed
    assert not lim.allow("k", now=10.6, cost=0.5)
    assert lim.allow("j", now=10.6, cost=1) and not lim.allow("j", now=10.7, cost=4)
