"""The study server through its HTTP API: a whole participant, export, Prolific handling,
tampering, and the database schema. Every test runs on SQLite and PostgreSQL."""

from __future__ import annotations

import csv
import functools
import json
import math
import time
import uuid
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

import test_study_support
from cfteach.study.bot import run_participant
from cfteach.study.build import LEVELS, toy_sources
from cfteach.study.config import load_study
from cfteach.study.export import COLUMNS, export_csv
from cfteach.study.server import create_app
from cfteach.study.steps import demo_required_ms

db_url = test_study_support.db_url  # shared fixtures
toy_study = test_study_support.toy_study

PARAMS = {"prolific_pid": "5f1c0ffee0ddba11c0ffee00", "study_id": "S1", "session_id": "X1"}


@pytest.fixture
def client(toy_study: Path, db_url: str) -> TestClient:
    app = create_app(toy_study, db_url, researcher_token="research-token", seed=7)
    with TestClient(app) as c:
        yield c
    app.state.service.engine.dispose()


@functools.cache
def _toy_sources() -> list:
    return toy_sources()


def _independent_reward(test_id: str, actions: list[str]) -> tuple[float, float]:
    """Replay with the toy domain's own `step` (not the server's table): reward, optimum."""
    dom_name, level, i = test_id.rsplit("-", 2)
    src = next(s for s in _toy_sources() if s.domain.name == dom_name)
    t = src.tests["tests"][level][int(i)]
    inst = src.domain.instances()[t["env_index"]]
    s = inst.state_from_json(t["start_state"])
    mu = [0, 0, 0]
    for a in actions:
        s, phi, _ = inst.step(s, src.domain.actions.index(a))
        mu = [m + f for m, f in zip(mu, phi, strict=True)]
    reward = sum(w * m for w, m in zip(src.domain.weights, mu, strict=True))
    return reward, t["optimal_reward"]


def _stable(state: dict) -> dict:
    """A page state without its clock (`elapsed_ms` grows while a test page is open)."""
    return {**state, "step": {k: v for k, v in state["step"].items() if k != "elapsed_ms"}}


def _read(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _event(c: TestClient, token: str, step: int, type_: str, payload: dict | None = None,
           event_id: str | None = None):  # noqa: ANN202
    return c.post("/api/event", headers={"X-Session-Token": token}, json={
        "event_id": event_id or uuid.uuid4().hex, "step_index": step, "type": type_,
        "payload": payload or {}})


def test_full_participant_and_export(client: TestClient, toy_study: Path, db_url: str,
                                     tmp_path: Path) -> None:
    study = load_study(toy_study)
    optimal_bot = run_participant(client, PARAMS, study=study)
    run_participant(client, {**PARAMS, "prolific_pid": "naive0000000000000000001"})
    assert optimal_bot["state"]["step"]["kind"] == "complete"
    assert optimal_bot["state"]["step"]["redirect"].endswith("cc=C0MPL3TE")
    counts = export_csv(db_url, tmp_path)
    assert counts["participants.csv"] == 2
    assert counts["test_responses.csv"] == 36
    for name, cols in COLUMNS.items():
        with open(tmp_path / name, encoding="utf-8") as f:
            assert next(csv.reader(f)) == [c for c, _, _ in cols]
    people = {r["prolific_pid"]: r for r in _read(tmp_path / "participants.csv")}
    p = people[PARAMS["prolific_pid"]]
    assert p["status"] == "completed" and p["is_preview"] == "0"
    assert p["counterfactual"] == str(int(p["condition"] in ("counterfactual_only",
                                                              "proposed")))
    assert p["feature_scaffolding"] == str(int(p["condition"] in ("feature_only", "proposed")))
    assert sorted(p["domain_order"].split(";")) == ["toy_a", "toy_b", "toy_c"]
    assert p["age"] == "30" and p["gender"] == "Female" and p["practice_attempts"] == "1"
    tests = _read(tmp_path / "test_responses.csv")
    naive_optimal = 0
    for row in tests:
        actions = row["actions"].split()
        reward, opt = _independent_reward(row["test_id"], actions)
        assert math.isclose(float(row["reward"]), reward, abs_tol=1e-9)
        assert math.isclose(float(row["optimal_reward"]), opt, abs_tol=1e-12)
        assert row["optimal"] == str(int(math.isclose(reward, opt, abs_tol=1e-9)))
        assert int(row["n_actions"]) == len(actions)
        if row["participant_id"] == p["participant_id"]:
            assert row["optimal"] == "1"
        else:
            naive_optimal += int(row["optimal"])
    assert naive_optimal < 18  # the shortest path is not always the best one
    mine = [r for r in tests if r["participant_id"] == p["participant_id"]]
    for dom in ("toy_a", "toy_b", "toy_c"):
        rows = [r for r in mine if r["domain"] == dom]
        assert sorted(int(r["trial_index"]) for r in rows) == [1, 2, 3, 4, 5, 6]
        assert sorted(r["difficulty"] for r in rows) == sorted(list(LEVELS) * 2)
        assert {int(r["domain_position"]) for r in rows} == {
            p["domain_order"].split(";").index(dom) + 1}
    # The confidence answers are the bot's, in the order it answered them.
    answered = [(d, t, c) for d, t, _, c in optimal_bot["tests"]]
    stored = sorted((r["domain"], int(r["trial_index"]), int(r["confidence"])) for r in mine)
    assert stored == sorted(answered)
    likert = [r for r in _read(tmp_path / "likert.csv") if r["participant_id"] ==
              p["participant_id"]]
    assert len(likert) == 6
    expected = {(d, "informativeness", str(i)) for d, i, _ in optimal_bot["likert"]} | {
        (d, "mental_effort", str(e)) for d, _, e in optimal_bot["likert"]}
    assert {(r["domain"], r["item"], r["value"]) for r in likert} == expected
    views = _read(tmp_path / "demo_views.csv")
    assert len(views) == 2 * 2 * 3  # 2 participants x 2 demos x 3 domains
    assert all(v["plays_completed"] == "1" and v["replays"] == "0" for v in views)
    dictionary = _read(tmp_path / "data_dictionary.csv")
    assert len(dictionary) == sum(len(c) for c in COLUMNS.values())


def test_reload_state_is_stable_and_events_are_counted(client: TestClient) -> None:
    r = client.post("/api/session", json=PARAMS).json()
    tok = r["token"]
    a = client.get("/api/state", headers={"X-Session-Token": tok}).json()
    b = client.get("/api/state", headers={"X-Session-Token": tok}).json()
    assert a == b and a["step"]["kind"] == "consent"
    run_participant(client, PARAMS, stop_after=12)  # resumes the same session by PID
    st = client.get("/api/state", headers={"X-Session-Token": tok}).json()
    assert st["step_index"] == 12
    # A test page shown twice (reload) shows the same test.
    again = client.get("/api/state", headers={"X-Session-Token": tok}).json()
    assert _stable(again) == _stable(st)
    assert again["step"]["elapsed_ms"] >= st["step"]["elapsed_ms"] >= 0


def test_prolific_resume_preview_and_bad_ids(client: TestClient) -> None:
    first = client.post("/api/session", json=PARAMS).json()
    # The same Prolific SESSION_ID (the same link, any browser) resumes; so does the token.
    again = client.post("/api/session", json=PARAMS).json()
    assert again["token"] == first["token"] and again["resumed"] is True
    again = client.post("/api/session", json={**PARAMS, "session_id": None,
                                              "token": first["token"]}).json()
    assert again["token"] == first["token"] and again["resumed"] is True
    other = client.post("/api/session", json={**PARAMS, "prolific_pid": "another1"}).json()
    assert other["token"] != first["token"]
    # Prolific's unfilled placeholders and missing ids give a preview session.
    pv = client.post("/api/session", json={"prolific_pid": "{{%PROLIFIC_PID%}}",
                                           "study_id": "{{%STUDY_ID%}}"}).json()
    st = client.get("/api/state", headers={"X-Session-Token": pv["token"]}).json()
    assert st["is_preview"] is True
    test_mode = client.post("/api/session", json={**PARAMS, "prolific_pid": "tester1",
                                                  "mode": "test"}).json()
    assert client.get("/api/state", headers={"X-Session-Token": test_mode["token"]}).json()[
        "is_preview"]
    prog = client.get("/api/researcher/progress",
                      headers={"X-Researcher-Token": "research-token"}).json()
    assert prog["previews"] == 2
    assert sum(c["occupied"] for c in prog["cells"]) == 2  # previews are not counted
    bad = client.post("/api/session", json={"prolific_pid": "<script>alert(1)</script>"})
    assert bad.status_code == 422 and "PROLIFIC_PID" in bad.json()["detail"]
    long = client.post("/api/session", json={"prolific_pid": "a" * 65})
    assert long.status_code == 422
    extra = client.post("/api/session", json={**PARAMS, "ip": "1.2.3.4"})
    assert extra.status_code == 422


def test_tampered_replayed_and_oversized_requests_change_nothing(client: TestClient,
                                                                 toy_study: Path) -> None:
    tok = client.post("/api/session", json=PARAMS).json()["token"]
    H = {"X-Session-Token": tok}

    def snapshot():  # noqa: ANN202
        return _stable(client.get("/api/state", headers=H).json())

    consent = {"adult": True, "read": True, "agree": True}
    eid = uuid.uuid4().hex
    assert _event(client, tok, 0, "consent", consent, eid).status_code == 200
    before = snapshot()
    # Replaying the same event id: refused, nothing changes.
    r = _event(client, tok, 0, "consent", consent, eid)
    assert r.status_code == 409 and r.json()["error"] == "duplicate_event"
    # An event for a step already done (new id): refused.
    r = _event(client, tok, 0, "consent", consent)
    assert r.status_code == 409 and r.json()["error"] == "wrong_step"
    # Unknown or wrong-step event types, bad payloads, bad tokens.
    assert _event(client, tok, 1, "test_response", {"actions": [], "time_ms": 1,
                                                   "confidence": 3}).status_code == 422
    assert _event(client, tok, 1, "hack").status_code == 422
    assert _event(client, tok, 1, "continue", {"extra": 1}).status_code == 422
    assert _event(client, "not-a-token", 1, "continue").status_code == 401
    r = client.post("/api/event", json={"event_id": uuid.uuid4().hex, "step_index": 1,
                                        "type": "continue", "payload": {}})
    assert r.status_code == 401
    # Oversized body and non-JSON content types.
    big = {"event_id": uuid.uuid4().hex, "step_index": 1, "type": "continue",
           "payload": {"x": "a" * 70_000}}
    assert client.post("/api/event", headers=H, json=big).status_code == 413
    r = client.post("/api/event", headers={**H, "Content-Type": "text/plain"},
                    content=json.dumps({"event_id": uuid.uuid4().hex, "step_index": 1,
                                        "type": "continue", "payload": {}}))
    assert r.status_code == 415 and "application/json" in r.json()["detail"]
    assert client.post("/api/event", headers={**H, "Content-Type": "application/json"},
                       content=b"{not json").status_code == 422
    assert snapshot() == before
    # One participant cannot touch another's session: events go to the token's session only.
    tok2 = client.post("/api/session", json={**PARAMS, "prolific_pid": "other2"}).json()["token"]
    assert _event(client, tok2, 1, "continue").status_code == 409  # its own step 0 != 1
    assert snapshot() == before
    # Skipping the demonstrations is refused.
    run_participant(client, PARAMS, stop_after=4)  # step 1 -> domain intro of domain 1
    st = snapshot()
    assert st["step"]["kind"] == "domain_intro"
    assert _event(client, tok, st["step_index"], "continue").status_code == 200
    st = snapshot()
    assert st["step"]["kind"] == "demos"
    r = _event(client, tok, st["step_index"], "continue")
    assert r.status_code == 409 and r.json()["error"] == "demos_unwatched"
    assert snapshot() == st
    # Tests: moves that do not finish the game, or unknown actions, are refused.
    i = st["step_index"]
    for k, demo in enumerate(st["step"]["demos"]):
        _event(client, tok, i, "demo_play_start", {"demo_index": k})
        time.sleep(demo_required_ms(len(demo["actions"]), st["step"]["step_ms"]) / 1000)
        _event(client, tok, i, "demo_play_end", {"demo_index": k, "completed": True,
                                                 "watch_ms": 5})
    assert _event(client, tok, i, "continue").status_code == 200
    assert _event(client, tok, i + 1, "likert", {"informativeness": 6,
                                                 "mental_effort": 1}).status_code == 422
    assert _event(client, tok, i + 1, "likert", {"informativeness": 3,
                                                 "mental_effort": 1}).status_code == 200
    st = snapshot()
    assert st["step"]["kind"] == "test"
    r = _event(client, tok, st["step_index"], "test_response",
               {"actions": ["up"], "time_ms": 10, "confidence": 2})
    assert r.status_code == 422 and r.json()["error"] == "bad_moves"
    r = _event(client, tok, st["step_index"], "test_response",
               {"actions": ["jump"], "time_ms": 10, "confidence": 2})
    assert r.status_code == 422
    assert snapshot() == st
    # The page never receives feature vectors or rewards of tests.
    assert "phi" not in st["step"]["game"] and "optimal_reward" not in st["step"]
    # Researcher endpoints need the token.
    assert client.get("/api/researcher/progress").status_code == 403
    assert client.get("/researcher?token=wrong").status_code == 403
    assert client.get("/researcher?token=research-token").status_code == 200


def test_practice_screen_out_after_three_failures(client: TestClient, db_url: str,
                                                  tmp_path: Path) -> None:
    out = run_participant(client, PARAMS, fail_practice=True)
    st = out["state"]
    assert st["status"] == "screened_out"
    assert st["step"]["code"] == "SCR33N" and st["step"]["redirect"].endswith("cc=SCR33N")
    tok = out["token"]
    r = _event(client, tok, st["step_index"], "practice_attempt",
               {"actions": [], "time_ms": 1})
    assert r.status_code == 409  # no fourth attempt, even with a reload
    again = client.post("/api/session", json=PARAMS).json()
    assert again["token"] == tok
    export_csv(db_url, tmp_path)
    (p,) = _read(tmp_path / "participants.csv")
    assert p["status"] == "screened_out" and p["practice_attempts"] == "3"


def test_security_headers_and_page(client: TestClient) -> None:
    r = client.get("/")
    assert r.status_code == 200 and 'src="/static/app.js"' in r.text
    assert "default-src 'self'" in r.headers["content-security-policy"]
    assert r.headers["referrer-policy"] == "no-referrer"
    assert client.get("/static/grid.js").status_code == 200


def test_migrations_match_models(db_url: str) -> None:
    """The shipped Alembic migrations build exactly the schema the models declare."""
    from alembic.autogenerate import compare_metadata
    from alembic.migration import MigrationContext

    from cfteach.study.db import make_engine, upgrade
    from cfteach.study.models import Base

    engine = make_engine(db_url)
    upgrade(engine)
    upgrade(engine)  # idempotent
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    engine.dispose()
    assert diff == []


def test_rate_limits(toy_study: Path, tmp_path: Path) -> None:
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'rl.db'}", sessions_per_minute=3,
                     events_per_minute=2)
    with TestClient(app) as c:
        codes = [c.post("/api/session", json={"prolific_pid": f"rl{i}"}).status_code
                 for i in range(5)]
        assert codes == [200, 200, 200, 429, 429]
        tok = c.post("/api/session", json={"prolific_pid": "rl0"}, headers={
            "X-Forwarded-For": "ignored"})
        assert tok.status_code == 429  # keyed by the connection's address only
    app.state.service.engine.dispose()
    from cfteach.study.ratelimit import RateLimiter

    lim = RateLimiter(2, window=10)
    assert [lim.allow("a", t) for t in (0, 1, 2, 10.5, 11.5, 11.6)] == [
        True, True, False, True, True, False]
    assert lim.allow("b", 2)


def test_domain_intro_shows_wording_and_unplayed_examples(client: TestClient,
                                                          toy_study: Path) -> None:
    out = run_participant(client, PARAMS, stop_after=5)
    st = out["state"]["step"]
    assert st["kind"] == "domain_intro"
    study = load_study(toy_study)
    # Toy domains get the generic wording built from their feature names.
    assert st["info"]["actions"] == ["mud", "battery", "step"]
    assert 1 <= len(st["examples"]) <= 3
    starts = [(d["layout"], d["states"][0]) for cur in study["curricula"][st["domain"]].values()
              for d in cur]
    assert all((ex["layout"], ex["state"]) in starts for ex in st["examples"])


def test_export_reads_back_in_the_analysis_and_marks_abandoned(toy_study: Path,
                                                               tmp_path: Path) -> None:
    from datetime import timedelta

    from sqlalchemy import update

    from cfteach.analysis.io import load_export
    from cfteach.study.models import Session, utcnow

    db = f"sqlite:///{tmp_path / 'a.db'}"
    app = create_app(toy_study, db, seed=1)
    with TestClient(app) as c:
        run_participant(c, PARAMS)
        run_participant(c, {**PARAMS, "prolific_pid": "idle01"}, stop_after=8)
        run_participant(c, {**PARAMS, "prolific_pid": "busy01"}, stop_after=8)
    svc = app.state.service
    with svc.Session() as s, s.begin():
        s.execute(update(Session).where(Session.prolific_pid == "idle01")
                  .values(last_active_at=utcnow() - timedelta(hours=3)))
    svc.engine.dispose()
    export_csv(db, tmp_path / "out")
    status = {r["prolific_pid"]: r["status"] for r in _read(tmp_path / "out" /
                                                            "participants.csv")}
    assert status == {PARAMS["prolific_pid"]: "completed", "idle01": "abandoned",
                      "busy01": "in_progress"}
    ex = load_export(tmp_path / "out")  # the analysis side's loader and validator
    assert len(ex.participants) == 3 and len(ex.tests) == 18


def test_racing_duplicates_are_stored_once(client: TestClient) -> None:
    """Eight simultaneous copies of one event (a retry storm), then eight different events
    for the same step (a double click): one is stored, the rest refused."""
    import threading

    from cfteach.study.schemas import EventRequest
    from cfteach.study.service import ApiError

    svc = client.app.state.service
    tok = client.post("/api/session", json=PARAMS).json()["token"]
    consent = {"adult": True, "read": True, "agree": True}

    def race(requests: list[EventRequest]) -> list[str]:
        out: list[str] = []
        barrier = threading.Barrier(len(requests))

        def go(req: EventRequest) -> None:
            barrier.wait()
            try:
                svc.post_event(tok, req)
                out.append("ok")
            except ApiError as e:
                out.append(e.code)

        threads = [threading.Thread(target=go, args=(r,)) for r in requests]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        return sorted(out)

    same = EventRequest(event_id="same-event-0001", step_index=0, type="consent",
                        payload=consent)
    assert race([same] * 8) == ["duplicate_event"] * 7 + ["ok"]
    clicks = [EventRequest(event_id=f"click-{i:04d}", step_index=1, type="continue")
              for i in range(8)]
    assert race(clicks) == ["ok"] + ["wrong_step"] * 7
    st = client.get("/api/state", headers={"X-Session-Token": tok}).json()
    assert st["step_index"] == 2
    from sqlalchemy import func, select

    from cfteach.study.models import Event

    with svc.Session() as db:
        assert db.scalar(select(func.count()).select_from(Event)) == 2
