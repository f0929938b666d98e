"""Hostile requests against the study server: session takeover with a known Prolific ID,
bodies without a Content-Length, token floods and spoofed forwarding headers, control
characters, look-alike content types. Database-facing tests run on SQLite and PostgreSQL."""

from __future__ import annotations

import json
import uuid
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select

import test_study_support
from cfteach.study.bot import run_participant
from cfteach.study.livesrv import running, serving_process
from cfteach.study.models import Event, Session
from cfteach.study.probe import peak_rss_mb, post_chunked
from cfteach.study.server import create_app

db_url = test_study_support.db_url
toy_study = test_study_support.toy_study

PARAMS = {"prolific_pid": "5f1c0ffee0ddba11c0ffee00", "study_id": "S1", "session_id": "X1"}


@pytest.fixture
def app(toy_study: Path, db_url: str):  # noqa: ANN201
    app = create_app(toy_study, db_url, researcher_token="research-token", seed=3)
    yield app
    app.state.service.engine.dispose()


@pytest.fixture
def client(app) -> TestClient:  # noqa: ANN001
    with TestClient(app) as c:
        yield c


def _event(c: TestClient, token: str, step: int, type_: str, payload: dict | None = None):  # noqa: ANN202
    return c.post("/api/event", headers={"X-Session-Token": token}, json={
        "event_id": uuid.uuid4().hex, "step_index": step, "type": type_,
        "payload": payload or {}})


def _counts(app) -> tuple[int, int]:  # noqa: ANN001
    with app.state.service.Session() as db:
        return (db.scalar(select(func.count()).select_from(Session)),
                db.scalar(select(func.count()).select_from(Event)))


# -- 1. resuming a session needs proof, not just the Prolific ID ------------------------------

def test_known_pid_without_proof_gets_no_token_and_changes_nothing(client: TestClient,
                                                                   app) -> None:  # noqa: ANN001
    out = run_participant(client, PARAMS, stop_after=3)  # consent..free play: at practice
    tok = out["token"]
    before = client.get("/api/state", headers={"X-Session-Token": tok}).json()
    counts = _counts(app)
    other_token = client.post("/api/session", json={"prolific_pid": "someone2",
                                                    "session_id": "Y1"}).json()["token"]
    for attempt in ({**PARAMS, "session_id": "X2"},          # another Prolific session
                    {**PARAMS, "session_id": None},          # no SESSION_ID at all
                    {"prolific_pid": PARAMS["prolific_pid"], "study_id": "S1",
                     "token": other_token},                  # someone else's token
                    {**PARAMS, "session_id": "{{%SESSION_ID%}}"}):  # placeholder
        r = client.post("/api/session", json=attempt)
        assert r.status_code == 409, (attempt, r.text)
        body = r.json()
        assert body["error"] == "session_elsewhere" and "token" not in body
        assert "already in progress in another browser" in body["detail"]
    assert _counts(app) == (counts[0] + 1, counts[1])  # only someone2's new session
    assert client.get("/api/state", headers={"X-Session-Token": tok}).json() == before
    assert before["step"]["kind"] == "practice" and before["status"] == "in_progress"
    # The real participant still resumes: with the same SESSION_ID, or with the token.
    assert client.post("/api/session", json=PARAMS).json()["token"] == tok
    r = client.post("/api/session", json={**PARAMS, "session_id": "X9", "token": tok})
    assert r.status_code == 200 and r.json()["token"] == tok and r.json()["resumed"]


def test_session_started_without_session_id_resumes_only_with_its_token(
        client: TestClient) -> None:
    params = {"prolific_pid": "nosession01", "study_id": "S1"}
    tok = client.post("/api/session", json=params).json()["token"]
    assert client.post("/api/session", json=params).status_code == 409
    assert client.post("/api/session", json={**params, "session_id": "Z"}).status_code == 409
    assert client.post("/api/session", json={**params, "token": tok}).json()["token"] == tok


# -- 2. bodies without a Content-Length are counted while they stream -----------------------

def test_chunked_body_is_refused_before_it_ends(toy_study: Path, tmp_path: Path) -> None:
    """A chunked body that never ends gets 413 once past 64 KiB: the server must not wait
    for (and hold) the whole body. A small chunked body still works."""
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'c.db'}")
    with running(app) as base:
        port = int(base.rsplit(":", 1)[1])
        r = post_chunked("127.0.0.1", port, "/api/event", 1024 * 1024, finish=False,
                         timeout=15)
        assert r.status == 413, r.response[:200]
        assert b'"too_large"' in r.response
        r = post_chunked("127.0.0.1", port, "/api/session", 300 * 1024, content_type="text/plain")
        assert r.status == 415
    app.state.service.engine.dispose()


@pytest.fixture(scope="module")
def served(toy_study: Path, tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201
    """`cfteach serve` in its own process, with its default proxy settings."""
    db = f"sqlite:///{tmp_path_factory.mktemp('served') / 's.db'}"
    with serving_process(toy_study, "--db", db, "--sessions-per-minute", "3") as (base, proc):
        yield base, proc


def test_chunked_40_mb_body_does_not_grow_the_server(served) -> None:  # noqa: ANN001
    base, proc = served
    port = int(base.rsplit(":", 1)[1])
    assert httpx.get(base + "/").status_code == 200
    before = peak_rss_mb(proc.pid)
    r = post_chunked("127.0.0.1", port, "/api/event", 40 * 1024 * 1024, timeout=60)
    after = peak_rss_mb(proc.pid)
    assert r.status == 413
    assert after - before < 20, f"peak RSS {before:.0f} -> {after:.0f} MiB"
    assert httpx.get(base + "/").status_code == 200  # still serving


# -- 5. rate limits: malformed tokens, failed authentications, forwarded addresses -----------

def test_default_serve_trusts_no_forwarded_header(served) -> None:  # noqa: ANN001
    """`cfteach serve` on loopback: a rotating X-Forwarded-For does not make new clients."""
    base, _ = served
    codes = [httpx.post(base + "/api/session", json={"prolific_pid": f"fw{i}"},
                        headers={"X-Forwarded-For": f"10.0.0.{i}"}).status_code
             for i in range(6)]
    assert codes[:3] == [200, 200, 200] and codes[3:] == [429, 429, 429]


def test_forwarded_header_from_a_named_proxy_is_used(toy_study: Path, tmp_path: Path) -> None:
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'p.db'}", sessions_per_minute=1)
    with running(app, forwarded_allow_ips="127.0.0.1") as base:
        codes = [httpx.post(base + "/api/session", json={"prolific_pid": f"px{i}"},
                            headers={"X-Forwarded-For": f"10.0.0.{i % 2}"}).status_code
                 for i in range(4)]
    assert codes == [200, 200, 429, 429]  # one each for 10.0.0.0 and 10.0.0.1
    app.state.service.engine.dispose()


def test_malformed_tokens_are_refused_before_lookup_and_not_stored(toy_study: Path,
                                                                    tmp_path: Path) -> None:
    app = create_app(toy_study, f"sqlite:///{tmp_path / 't.db'}", auth_failures_per_minute=0)
    limits = app.state.limits
    with TestClient(app) as c:
        for i in range(50):
            r = _event(c, f"{i:05d}" + "x" * 15_000, 0, "continue")
            assert r.status_code == 401 and r.json()["error"] == "no_session"
        assert len(limits["events"]) == 0  # nothing was keyed by those tokens
        r = c.get("/api/state", headers={"X-Session-Token": "a" * 42 + "\x00"})
        assert r.status_code == 401
        assert c.get("/researcher", params={"token": "caf\u00e9"}).status_code == 403
    app.state.service.engine.dispose()


def test_failed_authentications_are_limited_per_address(toy_study: Path,
                                                        tmp_path: Path) -> None:
    app = create_app(toy_study, f"sqlite:///{tmp_path / 'a.db'}", auth_failures_per_minute=5)
    with TestClient(app) as c:
        good = c.post("/api/session", json=PARAMS).json()["token"]
        unknown = "A" * 43  # well formed, no such session
        codes = [_event(c, unknown, 0, "continue").status_code for _ in range(3)]
        codes += [c.get("/api/state", headers={"X-Session-Token": "bad"}).status_code]
        codes += [c.get("/api/researcher/progress",
                        headers={"X-Researcher-Token": "guess"}).status_code]
        assert codes == [401, 401, 401, 401, 403]
        # Now the address is over its limit: refused before any lookup, valid token or not.
        assert _event(c, unknown, 0, "continue").status_code == 429
        r = c.get("/api/state", headers={"X-Session-Token": good})
        assert r.status_code == 429 and r.json()["error"] == "rate_limited"
        assert c.post("/api/session", json={**PARAMS, "session_id": "X2"}).status_code == 429
    assert len(app.state.limits["auth"]) == 1
    app.state.service.engine.dispose()


def test_rate_limiter_memory_is_bounded() -> None:
    from cfteach.study.ratelimit import RateLimiter

    lim = RateLimiter(3, window=10, max_keys=100)
    for i in range(1000):
        assert lim.allow(f"k{i}", now=1.0)
    assert len(lim) <= 100
    lim.hit("x", now=1.0)
    assert not lim.blocked("x", now=1.0)
    for _ in range(10):
        lim.hit("x", now=2.0)
    assert lim.blocked("x", now=2.0) and not lim.blocked("x", now=12.5)


# -- 6. control characters are refused in validation, on both databases ---------------------

def test_control_characters_get_422_on_every_database(client: TestClient) -> None:
    for field in ("prolific_pid", "study_id", "session_id"):
        r = client.post("/api/session", json={**PARAMS, field: "ab\x00cd"})
        assert r.status_code == 422, (field, r.text)
        assert "control characters" in r.json()["detail"]
    pv = client.post("/api/session", json={"prolific_pid": "{{%PROLIFIC\x00PID%}}"})
    assert pv.status_code == 422
    assert client.post("/api/session", json={"token": "a" * 42 + "\x00"}).status_code == 422
    tok = client.post("/api/session", json={**PARAMS, "prolific_pid": "ctrl01"}).json()["token"]
    while (st := client.get("/api/state", headers={"X-Session-Token": tok}).json())[
            "step"]["kind"] != "survey":
        run_participant(client, None, token=tok, stop_after=1)
    i = st["step_index"]
    likert = {"informativeness": 3, "mental_effort": 2}
    for bad in ("nul\x00here", "bell\x07", "esc\x1b[31m", "c1\x85"):
        r = _event(client, tok, i, "likert", {**likert, "comment": bad})
        assert r.status_code == 422, (bad, r.text)
    r = client.post("/api/event", headers={"X-Session-Token": tok,
                                           "Content-Type": "application/json"},
                    content=b'{"event_id": "%s", "step_index": %d, "type": "likert", '
                            b'"payload": {"informativeness": 3, "mental_effort": 2, '
                            b'"comment": "\\ud800"}}' % (uuid.uuid4().hex.encode(), i))
    assert r.status_code == 422
    assert _event(client, tok, i, "lik\x00ert", likert).status_code == 422
    assert client.get("/api/state", headers={"X-Session-Token": tok}).json()["step_index"] == i
    r = _event(client, tok, i, "likert", {**likert, "comment": "two\nlines\tand a tab"})
    assert r.status_code == 200, r.text


# -- 7. look-alike content types ---------------------------------------------------------------

def test_only_application_json_is_accepted(client: TestClient) -> None:
    body = json.dumps(PARAMS)
    for ctype in ("application/jsonfoo", "application/json-patch", "text/json",
                  "application/x-www-form-urlencoded", "", "application/jsonp; charset=utf-8"):
        r = client.post("/api/session", content=body, headers={"Content-Type": ctype})
        assert r.status_code == 415, (ctype, r.status_code)
        assert r.json()["error"] == "json_only"
    for ctype in ("application/json", "application/json; charset=utf-8", "Application/JSON"):
        r = client.post("/api/session", content=body, headers={"Content-Type": ctype})
        assert r.status_code == 200, (ctype, r.text)


# -- 1, in the browser: the page says so -------------------------------------------------------

@pytest.mark.browser
def test_browser_shows_already_in_progress_page(toy_study: Path, tmp_path: Path) -> None:
    playwright = pytest.importorskip("playwright.sync_api")
    from cfteach.study.screenshots import ARGS, CHROMIUM

    app = create_app(toy_study, f"sqlite:///{tmp_path / 'b.db'}")
    pid = "60aa0bb0cc0dd0ee0ff00999"
    with running(app) as base, playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        first = browser.new_context().new_page()
        first.goto(f"{base}/?PROLIFIC_PID={pid}&STUDY_ID=st1&SESSION_ID=se1")
        first.wait_for_selector("main[data-step='consent']")
        other = browser.new_context().new_page()  # another browser, another Prolific session
        other.goto(f"{base}/?PROLIFIC_PID={pid}&STUDY_ID=st1&SESSION_ID=se2")
        other.wait_for_selector("main[data-step='elsewhere']")
        assert "already in progress in another browser" in other.inner_text("#elsewhere")
        assert other.evaluate("sessionStorage.getItem('cfteach-token')") is None
        first.reload()  # the first browser still resumes (its token, its SESSION_ID)
        first.wait_for_selector("main[data-step='consent']")
        browser.close()
    app.state.service.engine.dispose()
