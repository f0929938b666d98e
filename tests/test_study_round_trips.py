"""What an event asks of the database. On PostgreSQL every statement is a round trip to
another process, and under load the round trips, not the server's CPU, made most of an
event's time (docs/study.md, "Load"): a closed-loop event runs each lookup once, and the
copy of a stored event is still refused as a copy on every path, though it is no longer
looked up before an event is accepted. SQLite and PostgreSQL."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from sqlalchemy import event, func, select

import test_study_support
from cfteach.study import create_app
from cfteach.study.build import init_study, preview_sources
from cfteach.study.games import shortest_path
from cfteach.study.models import Event
from test_study_closed_loop import Api, _closed_loop_client

db_url = test_study_support.db_url  # SQLite, and PostgreSQL when one is given


@pytest.fixture(scope="module")
def small_cl_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("rt_study")
    init_study(out, preview_sources(["skateboard"]), demo_step_ms=10,
               conditions=["proposed", "closed_loop"],
               teacher={"n_particles": 200, "max_items": 8})
    return out


@contextmanager
def statements(app) -> Iterator[list[str]]:  # noqa: ANN001
    """The SQL statements the app sends while the block runs (its own engine only)."""
    seen: list[str] = []
    engine = app.state.service.engine

    def count(_conn, _cursor, statement, *_a) -> None:  # noqa: ANN001
        seen.append(statement.split(None, 1)[0].upper())

    event.listen(engine, "before_cursor_execute", count)
    try:
        yield seen
    finally:
        event.remove(engine, "before_cursor_execute", count)


def _send(who: Api, type_: str, payload: dict, event_id: str, step: int) -> dict:
    r = who.c.post("/api/event", headers=who.h, json={
        "event_id": event_id, "step_index": step, "type": type_, "payload": payload})
    return {"status": r.status_code, **r.json()}


def _stored(app, event_id: str) -> int:  # noqa: ANN001
    with app.state.service.Session() as db:
        return db.scalar(select(func.count()).select_from(Event)
                         .where(Event.event_id == event_id)) or 0


def test_a_closed_loop_play_asks_for_the_item_on_screen_once(small_cl_study: Path,
                                                             db_url: str) -> None:
    """A play of the demonstration on screen: the session, the item on screen, the play's
    start, the event and one update of the session, and the page's replay count; no lookup
    twice, no second update of the session, no search for a copy of the event."""
    app = create_app(small_cl_study, db_url, seed=5)
    client, who = _closed_loop_client(app)
    with client:
        who.to_closed_loop()
        item = who.ready()["step"]["item"]
        assert item["kind"] == "demonstration"
        step = who.state()["step_index"]
        with statements(app) as sent:
            r = _send(who, "demo_play_start", {"demo_index": item["position"]},
                      uuid.uuid4().hex, step)
        assert r["status"] == 200, r
        selects, writes = sent.count("SELECT"), sent.count("INSERT") + sent.count("UPDATE")
        # session (locked), item on screen, the page's replay count
        assert selects == 3, sent
        assert writes == 2, sent  # the event, the session's event_seq and last_active_at
        with statements(app) as sent:
            r = _send(who, "demo_play_end", {"demo_index": item["position"],
                                              "completed": True, "watch_ms": 50},
                      uuid.uuid4().hex, step)
        assert r["status"] == 200 and r["play"]["verified"], r
        # + the play's start
        assert sent.count("SELECT") == 4 and sent.count("INSERT") + sent.count("UPDATE") == 2


def test_copies_of_stored_events_are_refused_as_copies_on_every_path(
        small_cl_study: Path, db_url: str) -> None:
    app = create_app(small_cl_study, db_url, seed=5)
    client, who = _closed_loop_client(app)
    with client:
        who.to_closed_loop()
        item = who.ready()["step"]["item"]
        step, pos = who.state()["step_index"], item["position"]
        start, end, done = (uuid.uuid4().hex for _ in range(3))
        assert _send(who, "demo_play_start", {"demo_index": pos}, start, step)["status"] == 200
        # a copy the page's checks would accept (the same item is on screen): refused by
        # the events' unique id at its insert, and nothing of it stays
        copy = _send(who, "demo_play_start", {"demo_index": pos}, start, step)
        assert (copy["status"], copy["error"]) == (409, "duplicate_event")
        assert _stored(app, start) == 1
        assert _send(who, "demo_play_end", {"demo_index": pos, "completed": True,
                                             "watch_ms": 50}, end, step)["play"]["verified"]
        assert _send(who, "item_done", {"item": pos}, done, step)["status"] == 200
        test = who.ready()["step"]["item"]
        assert test["position"] == pos + 1
        # copies the checks would now refuse (item answered, another item on screen, a
        # payload that no longer fits): still refused as copies, not as wrong items
        for type_, payload, eid in (("item_done", {"item": pos}, done),
                                    ("demo_play_start", {"demo_index": pos}, start),
                                    ("item_done", {"item": pos, "actions": ["up"]}, done)):
            copy = _send(who, type_, payload, eid, step)
            assert (copy["status"], copy["error"]) == (409, "duplicate_event"), (type_, copy)
            assert _stored(app, eid) == 1
        # and a refusal of a new event is what it is
        fresh = _send(who, "item_done", {"item": pos}, uuid.uuid4().hex, step)
        assert (fresh["status"], fresh["error"]) == (409, "wrong_item")
        # a copy of the answer that moved the session on: the session's state is unchanged
        answer = uuid.uuid4().hex
        moves = {"item": test["position"], "actions": shortest_path(test["game"]),
                 "time_ms": 5}
        assert _send(who, "item_done", moves, answer, step)["status"] == 200
        before = who.state()
        copy = _send(who, "item_done", moves, answer, step)
        assert (copy["status"], copy["error"]) == (409, "duplicate_event")
        assert _stored(app, answer) == 1
        after = who.state()
        assert (after["step_index"], after["step"].get("item", {}).get("position")) == (
            before["step_index"], before["step"].get("item", {}).get("position"))
